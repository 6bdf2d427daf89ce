//! How photos are taken along the lanes (the `trigger` and
//! `camera_pitch_deg` members): the mission items of one lane in each
//! trigger mode, the gimbal pitch set at the start, and the photo count and
//! hover time each mode gives.

use serde::{Deserialize, Serialize};

use super::request::{PlanError, SurveyParams, check_range};
use super::terrain_flight::{SAME_POINT_M, dist3};
use crate::coverage::{self, Camera, Pattern, SurveyGeometry};
use crate::export::{GeoPoint, MissionItem};
use crate::geo::{GeoError, Issue};
use crate::terrain::Point3;

/// Default hover at each photo of `hover` triggering, s.
pub const DEFAULT_HOLD_S: f64 = 2.0;

/// When the camera fires along a lane.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TriggerMode {
    /// Every trigger distance flown (DO_SET_CAM_TRIGG_DIST).
    #[default]
    Distance,
    /// Every `interval_s` seconds (DO_SET_CAM_TRIGG_INTERVAL, started and
    /// stopped with DO_TRIGGER_CONTROL).
    Time,
    /// Stop at every photo, hover `hold_s`, take one image
    /// (IMAGE_START_CAPTURE).
    Hover,
}

/// Camera triggering of a survey.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Trigger {
    /// Default `distance`.
    pub mode: TriggerMode,
    /// Seconds between photos, [0.1, 3600], `time` mode only; default the
    /// trigger distance over the UAV's speed.
    #[cfg_attr(feature = "openapi", schema(minimum = 0.1, maximum = 3600))]
    pub interval_s: Option<f64>,
    /// Hover at each photo, s, [0, 60], `hover` mode only; default 2.
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 60))]
    pub hold_s: Option<f64>,
}

impl SurveyParams {
    /// The members of the survey patterns: camera pitch, trigger, and the
    /// pattern where the airframe or a corridor rules one out.
    pub(super) fn check_patterns(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        if let Some(pitch) = self.camera_pitch_deg {
            check_range(
                issues,
                &p("camera_pitch_deg"),
                pitch,
                coverage::NADIR_PITCH_DEG,
                coverage::MIN_PITCH_DEG,
                false,
            );
        }
        let t = &self.trigger;
        // A plane's mission is written by its own flight (survey/plane_flight.rs),
        // which triggers by distance and points no gimbal; and it cannot hover.
        if self.aircraft.as_ref().is_some_and(|a| a.is_plane()) {
            if t.mode != TriggerMode::Distance {
                issues.push(Issue::new(
                    &p("trigger/mode"),
                    "fixed_wing and vtol aircraft trigger the camera by distance (\"time\" and \"hover\" are for multirotors)",
                ));
            }
            if self.camera_pitch_deg.is_some() {
                issues.push(Issue::new(
                    &p("camera_pitch_deg"),
                    "an oblique camera is not yet planned for fixed_wing and vtol aircraft",
                ));
            }
        }
        if self.pattern == Pattern::Crosshatch && self.corridor_width_m.is_some() {
            issues.push(Issue::new(
                &p("pattern"),
                "a corridor is flown along its line: \"crosshatch\" is for areas (roi)",
            ));
        }
        if let Some(i) = t.interval_s {
            if t.mode == TriggerMode::Time {
                check_range(issues, &p("trigger/interval_s"), i, 0.1, 3600.0, false);
            } else {
                issues.push(Issue::new(
                    &p("trigger/interval_s"),
                    "interval_s is only for trigger mode \"time\"",
                ));
            }
        }
        if let Some(h) = t.hold_s {
            if t.mode == TriggerMode::Hover {
                check_range(issues, &p("trigger/hold_s"), h, 0.0, 60.0, false);
            } else {
                issues.push(Issue::new(
                    &p("trigger/hold_s"),
                    "hold_s is only for trigger mode \"hover\"",
                ));
            }
        }
    }

    /// Footprint, spacing and trigger distance of `camera` at `altitude`,
    /// pitched by `camera_pitch_deg` (see [`coverage::pitched_geometry`]).
    pub(super) fn camera_geometry(
        &self,
        camera: &Camera,
        altitude: f64,
    ) -> Result<SurveyGeometry, PlanError> {
        coverage::pitched_geometry(
            camera,
            altitude,
            self.camera_pitch_deg.unwrap_or(coverage::NADIR_PITCH_DEG),
            self.side_overlap,
            self.front_overlap,
            self.line_spacing_m,
        )
        .map_err(|e| PlanError::Invalid(vec![Issue::new("/camera_pitch_deg", &e.to_string())]))
    }
}

/// How one UAV takes its photos: the request's trigger at its speed.
#[derive(Clone, Copy, Debug)]
pub(super) struct Capture {
    mode: TriggerMode,
    /// Ground distance between photos along a lane, m.
    spacing_m: f64,
    /// Time between photos in `time` mode, s.
    interval_s: f64,
    hold_s: f64,
    /// Time a hover photo adds: the hold and a stop and start, charged
    /// like a turn (`turn_penalty_s`).
    stop_s: f64,
    gimbal_pitch_deg: Option<f64>,
}

impl Capture {
    /// The capture of a UAV flying lanes at `speed` m/s.
    pub(super) fn new(params: &SurveyParams, geometry: &SurveyGeometry, speed: f64) -> Capture {
        let t = &params.trigger;
        let d = geometry.trigger_distance_m;
        let (spacing_m, interval_s) = match (t.mode, t.interval_s) {
            (TriggerMode::Time, Some(i)) => (i * speed, i),
            _ => (d, d / speed),
        };
        let hold_s = t.hold_s.unwrap_or(DEFAULT_HOLD_S);
        Capture {
            mode: t.mode,
            spacing_m,
            interval_s,
            hold_s,
            stop_s: hold_s + params.turn_penalty_s,
            gimbal_pitch_deg: params.camera_pitch_deg,
        }
    }

    /// Photos taken along a lane `length_m` long.
    pub(super) fn photos(&self, length_m: f64) -> usize {
        coverage::photo_count(length_m, self.spacing_m)
    }

    /// Ground distance between photos along a lane, m.
    pub(super) fn spacing_m(&self) -> f64 {
        self.spacing_m
    }

    /// Time the stops of `photos` hover photos add to the flight, s.
    pub(super) fn stop_time_s(&self, photos: usize) -> f64 {
        match self.mode {
            TriggerMode::Hover => photos as f64 * self.stop_s,
            _ => 0.0,
        }
    }

    /// Length flown at `speed` in the time the hover stops of a path with
    /// `lane_lengths` take: what the flock's sharing, which prices work by
    /// length, charges for them.
    pub(super) fn stop_length_m(&self, lane_lengths: impl Iterator<Item = f64>, speed: f64) -> f64 {
        let photos: usize = lane_lengths.map(|l| self.photos(l)).sum();
        self.stop_time_s(photos) * speed
    }

    /// A lane's flown points with its hover photo stations among them (the
    /// stations lie on the lane's segments: the flight is the same, and
    /// every waypoint the mission writes is one of these points).
    pub(super) fn lane_points(&self, pts: &[Point3]) -> Vec<Point3> {
        if self.mode != TriggerMode::Hover || pts.is_empty() {
            return pts.to_vec();
        }
        let stations = photo_stations(pts, self.spacing_m, self.photos(length_2d(pts)));
        let mut out: Vec<Point3> = Vec::with_capacity(pts.len() + stations.len());
        let mut next = 0;
        for (i, p) in pts.iter().enumerate() {
            let s = distance_along(pts, i);
            while next < stations.len() && stations[next].0 < s - SAME_POINT_M {
                out.push(stations[next].1);
                next += 1;
            }
            while next < stations.len() && stations[next].0 <= s + SAME_POINT_M {
                next += 1; // on this vertex
            }
            out.push(*p);
        }
        out.extend(stations[next..].iter().map(|(_, p)| *p));
        out
    }

    /// Whether a lane's first point is a photo stop (hover mode).
    pub(super) fn holds_at_start(&self) -> bool {
        self.mode == TriggerMode::Hover
    }

    /// Items at the start of the mission, after the take-off: the gimbal's
    /// pitch when the request sets one.
    pub(super) fn start_items(&self) -> Option<MissionItem> {
        self.gimbal_pitch_deg
            .map(|deg| MissionItem::GimbalPitch { deg })
    }

    /// The items of one lane flown through `pts` (its 3D points in flight
    /// order), each point written by `to_geo`; the first left out when
    /// `skip_first` (the UAV is there already), later ones when they repeat
    /// the point before. Returns the items and the last point written.
    pub(super) fn lane_items(
        &self,
        pts: &[Point3],
        skip_first: bool,
        to_geo: &dyn Fn(&Point3) -> Result<GeoPoint, GeoError>,
    ) -> Result<(Vec<MissionItem>, Option<Point3>), GeoError> {
        let mut items = Vec::with_capacity(pts.len() + 3);
        let Some(first) = pts.first() else {
            return Ok((items, None));
        };
        if self.mode == TriggerMode::Hover {
            return self.hover_items(pts, to_geo);
        }
        let mut last = None;
        if !skip_first {
            items.push(MissionItem::Waypoint(to_geo(first)?));
            last = Some(*first);
        }
        match self.mode {
            TriggerMode::Time => {
                items.push(MissionItem::CameraTriggerInterval {
                    interval_s: self.interval_s,
                });
                items.push(MissionItem::CameraTriggerControl { on: true });
            }
            _ => items.push(MissionItem::CameraTriggerDistance {
                distance_m: self.spacing_m,
            }),
        }
        let mut previous = *first;
        for p in &pts[1..] {
            if dist3(p, &previous) >= SAME_POINT_M {
                items.push(MissionItem::Waypoint(to_geo(p)?));
                previous = *p;
                last = Some(*p);
            }
        }
        items.push(match self.mode {
            TriggerMode::Time => MissionItem::CameraTriggerControl { on: false },
            _ => MissionItem::CameraTriggerDistance { distance_m: 0.0 },
        });
        Ok((items, last))
    }

    /// Hover mode: a held waypoint and one image at every photo station
    /// (every `spacing_m` from the lane's start, as many as
    /// [`Capture::photos`]), the lane's own points between them, and its
    /// end.
    fn hover_items(
        &self,
        pts: &[Point3],
        to_geo: &dyn Fn(&Point3) -> Result<GeoPoint, GeoError>,
    ) -> Result<(Vec<MissionItem>, Option<Point3>), GeoError> {
        let stations = photo_stations(pts, self.spacing_m, self.photos(length_2d(pts)));
        let mut items = Vec::with_capacity(pts.len() + 2 * stations.len());
        let mut last: Option<Point3> = None;
        let mut next_vertex = 1;
        for (s, station) in &stations {
            // The lane's points before this station, unless on it.
            while next_vertex < pts.len() && distance_along(pts, next_vertex) < *s - SAME_POINT_M {
                let p = pts[next_vertex];
                if last.is_none_or(|l| dist3(&l, &p) >= SAME_POINT_M) {
                    items.push(MissionItem::Waypoint(to_geo(&p)?));
                    last = Some(p);
                }
                next_vertex += 1;
            }
            items.push(MissionItem::HoldWaypoint {
                point: to_geo(station)?,
                hold_s: self.hold_s,
            });
            items.push(MissionItem::ImageStartCapture);
            last = Some(*station);
        }
        for p in &pts[next_vertex.min(pts.len())..] {
            if last.is_none_or(|l| dist3(&l, p) >= SAME_POINT_M) {
                items.push(MissionItem::Waypoint(to_geo(p)?));
                last = Some(*p);
            }
        }
        Ok((items, last))
    }
}

/// Horizontal distance along `pts` to its point `i`.
fn distance_along(pts: &[Point3], i: usize) -> f64 {
    length_2d(&pts[..=i])
}

fn length_2d(pts: &[Point3]) -> f64 {
    pts.windows(2)
        .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
        .sum()
}

/// The 3D length of `pts` up to the horizontal distance `s` along it.
pub(super) fn distance_3d_to(pts: &[Point3], s: f64) -> f64 {
    let mut left = s;
    let mut out = 0.0;
    for w in pts.windows(2) {
        let flat = (w[1].x - w[0].x).hypot(w[1].y - w[0].y);
        let full = dist3(&w[0], &w[1]);
        if left <= flat {
            return out + if flat > 0.0 { full * left / flat } else { 0.0 };
        }
        left -= flat;
        out += full;
    }
    out
}

/// `count` points every `spacing` metres (horizontally) along `pts` from
/// its start, heights interpolated, each with its distance along.
pub(super) fn photo_stations(pts: &[Point3], spacing: f64, count: usize) -> Vec<(f64, Point3)> {
    let mut out = Vec::with_capacity(count);
    let mut seg = 0;
    let mut seg_start = 0.0;
    for k in 0..count {
        let s = k as f64 * spacing;
        // Find the segment holding s (the last one for rounding past it).
        while seg + 2 < pts.len() {
            let len = (pts[seg + 1].x - pts[seg].x).hypot(pts[seg + 1].y - pts[seg].y);
            if seg_start + len >= s {
                break;
            }
            seg_start += len;
            seg += 1;
        }
        let (a, b) = (pts[seg], pts.get(seg + 1).copied().unwrap_or(pts[seg]));
        let len = (b.x - a.x).hypot(b.y - a.y);
        let t = if len > 0.0 {
            ((s - seg_start) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = Point3 {
            x: a.x + (b.x - a.x) * t,
            y: a.y + (b.y - a.y) * t,
            z: a.z + (b.z - a.z) * t,
        };
        out.push((s, p));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn p(x: f64, y: f64, z: f64) -> Point3 {
        Point3 { x, y, z }
    }

    fn geo(q: &Point3) -> Result<GeoPoint, GeoError> {
        Ok(GeoPoint {
            lon: q.x,
            lat: q.y,
            alt: q.z,
        })
    }

    /// The capture at 5 m/s of a 20 m trigger distance.
    fn capture(trigger: serde_json::Value) -> Capture {
        let params = SurveyParams::from_json(&json!({"trigger": trigger}), "").unwrap();
        let mut geometry = coverage::survey_geometry(&Camera::default(), 100.0, 0.7, 0.8, None);
        geometry.trigger_distance_m = 20.0;
        Capture::new(&params, &geometry, 5.0)
    }

    #[test]
    fn distance_mode_is_todays_lane() {
        let c = capture(json!({}));
        let (items, last) = c
            .lane_items(&[p(0., 0., 60.), p(100., 0., 60.)], false, &geo)
            .unwrap();
        assert_eq!(
            items,
            vec![
                MissionItem::Waypoint(geo(&p(0., 0., 60.)).unwrap()),
                MissionItem::CameraTriggerDistance { distance_m: 20.0 },
                MissionItem::Waypoint(geo(&p(100., 0., 60.)).unwrap()),
                MissionItem::CameraTriggerDistance { distance_m: 0.0 },
            ]
        );
        assert_eq!(last, Some(p(100., 0., 60.)));
        assert_eq!(c.photos(100.0), 6);
        assert_eq!(c.stop_time_s(6), 0.0);
    }

    #[test]
    fn time_mode_starts_and_stops_an_interval() {
        // Default interval: 20 m at 5 m/s.
        let c = capture(json!({"mode": "time"}));
        let (items, _) = c
            .lane_items(&[p(0., 0., 60.), p(100., 0., 60.)], true, &geo)
            .unwrap();
        assert_eq!(
            items,
            vec![
                MissionItem::CameraTriggerInterval { interval_s: 4.0 },
                MissionItem::CameraTriggerControl { on: true },
                MissionItem::Waypoint(geo(&p(100., 0., 60.)).unwrap()),
                MissionItem::CameraTriggerControl { on: false },
            ]
        );
        // 3 s at 5 m/s: a photo every 15 m, 7 on 100 m.
        let c = capture(json!({"mode": "time", "interval_s": 3}));
        assert_eq!(c.photos(100.0), 7);
    }

    #[test]
    fn hover_mode_holds_at_every_photo() {
        let c = capture(json!({"mode": "hover", "hold_s": 3}));
        // A lane of 50 m over a slope, with a terrain point at 30 m.
        let pts = [p(0., 0., 60.), p(30., 0., 63.), p(50., 0., 65.)];
        let (items, last) = c.lane_items(&pts, true, &geo).unwrap();
        let holds: Vec<GeoPoint> = items
            .iter()
            .filter_map(|i| match i {
                MissionItem::HoldWaypoint { point, hold_s } => {
                    assert_eq!(*hold_s, 3.0);
                    Some(*point)
                }
                _ => None,
            })
            .collect();
        // Photos at 0, 20 and 40 m, heights on the path.
        assert_eq!(holds.len(), c.photos(50.0));
        assert_eq!(holds.len(), 3);
        for (h, (x, z)) in holds.iter().zip([(0.0, 60.0), (20.0, 62.0), (40.0, 64.0)]) {
            assert!(
                (h.lon - x).abs() < 1e-9 && (h.alt - z).abs() < 1e-9,
                "{h:?}"
            );
        }
        let captures = items
            .iter()
            .filter(|i| **i == MissionItem::ImageStartCapture)
            .count();
        assert_eq!(captures, 3);
        // The terrain point between the 2nd and 3rd photo, then the end.
        let plain: Vec<f64> = items
            .iter()
            .filter_map(|i| match i {
                MissionItem::Waypoint(g) => Some(g.lon),
                _ => None,
            })
            .collect();
        assert_eq!(plain, vec![30.0, 50.0]);
        assert_eq!(last, Some(p(50., 0., 65.)));
        // Each stop: the hold and a turn's penalty (2 s).
        assert_eq!(c.stop_time_s(3), 15.0);
        // The stations among the lane's points: the points written.
        let merged = c.lane_points(&pts);
        let xs: Vec<f64> = merged.iter().map(|q| q.x).collect();
        assert_eq!(xs, vec![0.0, 20.0, 30.0, 40.0, 50.0]);
        let (again, _) = c.lane_items(&merged, true, &geo).unwrap();
        assert_eq!(again, items);
    }

    #[test]
    fn members_out_of_place_or_range_are_refused() {
        let e = SurveyParams::from_json(
            &json!({"camera_pitch_deg": -20, "trigger": {"interval_s": 2, "hold_s": 90, "mode": "hover"}}),
            "",
        )
        .unwrap_err();
        let ptrs: Vec<&str> = e.iter().map(|i| i.pointer.as_str()).collect();
        assert_eq!(
            ptrs,
            [
                "/camera_pitch_deg",
                "/trigger/interval_s",
                "/trigger/hold_s"
            ]
        );
        assert!(e[0].message.contains("[-90, -30]"), "{}", e[0].message);
        let e =
            SurveyParams::from_json(&json!({"trigger": {"mode": "sometimes"}}), "").unwrap_err();
        assert!(e[0].pointer.starts_with("/trigger"), "{e:?}");
        let e = SurveyParams::from_json(&json!({"pattern": "spiral"}), "").unwrap_err();
        assert_eq!(e[0].pointer, "/pattern");
    }
}
