//! The route a DJI aircraft flies, read off a mission: its waypoints with
//! the speed, gimbal pitch and photos at each, and the stretches photographed
//! every so many metres or seconds, as DJI's WPML and Litchi's CSV both
//! describe a waypoint mission.

use geo::{Bearing, Distance, Haversine};
use geo_types::Point;

use super::mission::{GeoPoint, Mission, MissionItem};

/// Slowest and fastest DJI waypoint missions fly, m/s (WPML's
/// `autoFlightSpeed` and `waypointSpeed` are in [1, 15]; Litchi's speed too).
pub const MIN_SPEED_M_S: f64 = 1.0;
pub const MAX_SPEED_M_S: f64 = 15.0;
/// Gimbal pitch where the mission sets none: nadir, as the plan's photos
/// assume (a DJI gimbal stays where the pilot left it otherwise).
pub const NADIR_PITCH_DEG: f64 = -90.0;

/// One waypoint of a DJI route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DjiWaypoint {
    /// Position; `alt` in the mission's frame.
    pub point: GeoPoint,
    /// Speed from this waypoint to the next, m/s.
    pub speed_m_s: f64,
    /// Gimbal pitch from this waypoint on, degrees (negative: down).
    pub gimbal_pitch_deg: f64,
    /// Hover here this long before the photo, s (hover-triggered photos).
    pub hold_s: Option<f64>,
    /// One photo here.
    pub photo: bool,
}

/// How often photos are taken along a [`PhotoRun`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Interval {
    /// Every so many metres flown.
    Distance(f64),
    /// Every so many seconds.
    Time(f64),
}

/// Photos every interval from waypoint `start` to waypoint `end` (indices
/// into [`DjiRoute::waypoints`], `start < end`), the first at `start`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotoRun {
    pub start: usize,
    pub end: usize,
    pub every: Interval,
}

/// A mission as a DJI waypoint route.
#[derive(Clone, Debug, PartialEq)]
pub struct DjiRoute {
    pub waypoints: Vec<DjiWaypoint>,
    pub runs: Vec<PhotoRun>,
    /// Take-off climb, m above the launch point.
    pub takeoff_alt_m: f64,
    /// The mission ends by flying home (RTL).
    pub return_home: bool,
    /// The mission's speed, m/s.
    pub cruise_speed_m_s: f64,
}

/// Why a mission is no DJI route.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DjiRouteError {
    #[error(
        "DJI waypoint missions are flown by multirotors, and this is a plane's or a VTOL's \
         mission (it has a {0})"
    )]
    NotMultirotor(&'static str),
    #[error("the mission has no waypoints")]
    NoWaypoints,
    #[error(
        "its speed of {0} m/s is outside the {MIN_SPEED_M_S}-{MAX_SPEED_M_S} m/s DJI waypoint \
         missions fly (speed_m_s of the UAV)"
    )]
    Speed(f64),
}

/// Whether a mission is a multirotor's (no plane or VTOL take-off or
/// landing): only those become DJI missions.
pub fn is_multirotor(mission: &Mission) -> bool {
    fixed_wing_item(mission).is_none()
}

fn fixed_wing_item(mission: &Mission) -> Option<&'static str> {
    mission.items.iter().find_map(|i| match i {
        MissionItem::PlaneTakeoff { .. } => Some("plane take-off"),
        MissionItem::VtolTakeoff { .. } => Some("VTOL take-off"),
        MissionItem::Land(_) | MissionItem::LandStart => Some("plane landing"),
        MissionItem::VtolLand(_) => Some("VTOL landing"),
        _ => None,
    })
}

impl DjiRoute {
    /// The route of a multirotor's mission: each waypoint (held ones too)
    /// with the speed and gimbal pitch in force when it is left, a photo
    /// where the mission takes one image, and a run of photos for every
    /// stretch the mission triggers the camera by distance or by time.
    pub fn of(mission: &Mission) -> Result<DjiRoute, DjiRouteError> {
        if let Some(what) = fixed_wing_item(mission) {
            return Err(DjiRouteError::NotMultirotor(what));
        }
        let mut route = DjiRoute {
            waypoints: Vec::new(),
            runs: Vec::new(),
            takeoff_alt_m: 0.0,
            return_home: false,
            cruise_speed_m_s: mission.cruise_speed_m_s,
        };
        let mut speed = mission.cruise_speed_m_s;
        let mut pitch = NADIR_PITCH_DEG;
        let mut interval_s = 0.0;
        let mut open: Option<(usize, Interval)> = None;
        for item in &mission.items {
            let last = route.waypoints.len().checked_sub(1);
            match *item {
                MissionItem::Takeoff { alt } => route.takeoff_alt_m = alt,
                MissionItem::ChangeSpeed { speed_m_s } => {
                    speed = speed_m_s;
                    if let Some(w) = route.waypoints.last_mut() {
                        w.speed_m_s = speed;
                    }
                }
                MissionItem::GimbalPitch { deg } => {
                    pitch = deg;
                    if let Some(w) = route.waypoints.last_mut() {
                        w.gimbal_pitch_deg = pitch;
                    }
                }
                MissionItem::Waypoint(point) => {
                    route.waypoints.push(DjiWaypoint {
                        point,
                        speed_m_s: speed,
                        gimbal_pitch_deg: pitch,
                        hold_s: None,
                        photo: false,
                    });
                }
                MissionItem::HoldWaypoint { point, hold_s } => {
                    route.waypoints.push(DjiWaypoint {
                        point,
                        speed_m_s: speed,
                        gimbal_pitch_deg: pitch,
                        hold_s: Some(hold_s),
                        photo: false,
                    });
                }
                MissionItem::ImageStartCapture => {
                    if let Some(w) = route.waypoints.last_mut() {
                        w.photo = true;
                    }
                }
                MissionItem::CameraTriggerDistance { distance_m } if distance_m > 0.0 => {
                    route.close(open.take(), last);
                    open = Some((last.unwrap_or(0), Interval::Distance(distance_m)));
                }
                MissionItem::CameraTriggerInterval { interval_s: s } => interval_s = s,
                MissionItem::CameraTriggerControl { on: true } if interval_s > 0.0 => {
                    route.close(open.take(), last);
                    open = Some((last.unwrap_or(0), Interval::Time(interval_s)));
                }
                MissionItem::CameraTriggerDistance { .. }
                | MissionItem::CameraTriggerControl { .. } => route.close(open.take(), last),
                MissionItem::ReturnToLaunch => route.return_home = true,
                // Refused above.
                MissionItem::PlaneTakeoff { .. }
                | MissionItem::VtolTakeoff { .. }
                | MissionItem::LandStart
                | MissionItem::Land(_)
                | MissionItem::VtolLand(_) => {}
            }
        }
        let last = route.waypoints.len().checked_sub(1);
        route.close(open, last);
        if route.waypoints.is_empty() {
            return Err(DjiRouteError::NoWaypoints);
        }
        let speeds = std::iter::once(route.cruise_speed_m_s)
            .chain(route.waypoints.iter().map(|w| w.speed_m_s));
        for s in speeds {
            if !(MIN_SPEED_M_S..=MAX_SPEED_M_S).contains(&s) {
                return Err(DjiRouteError::Speed(s));
            }
        }
        Ok(route)
    }

    /// Ends the run `open` at waypoint `last`: a run over one waypoint is
    /// one photo there (what a trigger at a point takes).
    fn close(&mut self, open: Option<(usize, Interval)>, last: Option<usize>) {
        let (Some((start, every)), Some(end)) = (open, last) else {
            return;
        };
        if end > start {
            self.runs.push(PhotoRun { start, end, every });
        } else if let Some(w) = self.waypoints.get_mut(start) {
            w.photo = true;
        }
    }

    /// Photos the route takes: one per photo waypoint, and along each run
    /// one at its start and one every interval of its horizontal length
    /// (time intervals flown at the run's speed), as the plan counts them.
    pub fn photo_count(&self) -> usize {
        let at_points = self.waypoints.iter().filter(|w| w.photo).count();
        let runs: usize = self
            .runs
            .iter()
            .map(|r| {
                let length: f64 = (r.start..r.end)
                    .map(|i| {
                        ground_distance_m(&self.waypoints[i].point, &self.waypoints[i + 1].point)
                    })
                    .sum();
                let spacing = match r.every {
                    Interval::Distance(d) => d,
                    Interval::Time(s) => s * self.waypoints[r.start].speed_m_s,
                };
                crate::coverage::photo_count(length, spacing)
            })
            .sum();
        at_points + runs
    }

    /// Length flown from the first waypoint to the last, m (3D), and the
    /// time it takes at the waypoints' speeds with their hovers, s.
    pub fn length_and_duration(&self) -> (f64, f64) {
        let mut length = 0.0;
        let mut time: f64 = self.waypoints.iter().filter_map(|w| w.hold_s).sum();
        for w in self.waypoints.windows(2) {
            let flat = ground_distance_m(&w[0].point, &w[1].point);
            let d = flat.hypot(w[1].point.alt - w[0].point.alt);
            length += d;
            time += d / w[0].speed_m_s;
        }
        (length, time)
    }
}

/// Great-circle distance between two points, m (haversine, mean Earth
/// radius; within 0.5 % of the ellipsoidal distance, which is what DJI's
/// duration estimate needs).
pub fn ground_distance_m(a: &GeoPoint, b: &GeoPoint) -> f64 {
    Haversine.distance(Point::new(a.lon, a.lat), Point::new(b.lon, b.lat))
}

/// Initial bearing from `a` to `b`, degrees clockwise from north in [0, 360).
pub fn bearing_deg(a: &GeoPoint, b: &GeoPoint) -> f64 {
    Haversine.bearing(Point::new(a.lon, a.lat), Point::new(b.lon, b.lat))
}

/// A multirotor survey mission for the DJI writers' tests: take-off to
/// 50 m, speed 8, gimbal -80°, a lane photographed by distance (12 m), a
/// hover photo, and a lane photographed by time (1.5 s), then home.
#[cfg(test)]
pub(crate) fn sample_dji_mission() -> Mission {
    use super::mission::AltitudeFrame;
    let p = |lon: f64, lat: f64| GeoPoint {
        lon,
        lat,
        alt: 50.0,
    };
    Mission {
        home: GeoPoint {
            lon: 5.0,
            lat: 52.0,
            alt: 10.0,
        },
        frame: AltitudeFrame::Relative,
        cruise_speed_m_s: 8.0,
        over_terrain: false,
        items: vec![
            MissionItem::Takeoff { alt: 50.0 },
            MissionItem::ChangeSpeed { speed_m_s: 8.0 },
            MissionItem::GimbalPitch { deg: -80.0 },
            MissionItem::Waypoint(p(5.001, 52.001)),
            MissionItem::CameraTriggerDistance { distance_m: 12.0 },
            MissionItem::Waypoint(p(5.001, 52.002)),
            MissionItem::Waypoint(p(5.001, 52.003)),
            MissionItem::CameraTriggerDistance { distance_m: 0.0 },
            MissionItem::HoldWaypoint {
                point: p(5.002, 52.003),
                hold_s: 2.0,
            },
            MissionItem::ImageStartCapture,
            MissionItem::CameraTriggerInterval { interval_s: 1.5 },
            MissionItem::CameraTriggerControl { on: true },
            MissionItem::Waypoint(p(5.002, 52.001)),
            MissionItem::CameraTriggerControl { on: false },
            MissionItem::ReturnToLaunch,
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_waypoints_runs_and_photos_off_the_mission() {
        let m = sample_dji_mission();
        let r = DjiRoute::of(&m).unwrap();
        assert_eq!(r.waypoints.len(), 5);
        assert_eq!(r.takeoff_alt_m, 50.0);
        assert!(r.return_home);
        assert!(r.waypoints.iter().all(|w| w.gimbal_pitch_deg == -80.0));
        assert_eq!(r.waypoints[3].hold_s, Some(2.0));
        assert!(r.waypoints[3].photo);
        assert_eq!(r.waypoints.iter().filter(|w| w.photo).count(), 1);
        assert_eq!(
            r.runs,
            [
                PhotoRun {
                    start: 0,
                    end: 2,
                    every: Interval::Distance(12.0)
                },
                PhotoRun {
                    start: 3,
                    end: 4,
                    every: Interval::Time(1.5)
                }
            ]
        );
        // 222.4 m by 12 m: 19 photos; the hover photo; 222.4 m by 1.5 s at
        // 8 m/s (12 m): 19.
        let lane = ground_distance_m(&r.waypoints[0].point, &r.waypoints[2].point);
        assert!((lane - 222.39).abs() < 0.05, "{lane}");
        assert_eq!(r.photo_count(), 19 + 1 + 19);
        let (length, duration) = r.length_and_duration();
        assert!((length - (222.39 + 68.46 + 222.39)).abs() < 0.2, "{length}");
        assert!((duration - (length / 8.0 + 2.0)).abs() < 1e-9);
    }

    #[test]
    fn planes_and_bad_speeds_are_refused() {
        let mut m = sample_dji_mission();
        m.items[0] = MissionItem::PlaneTakeoff {
            alt: 50.0,
            pitch_deg: 10.0,
        };
        assert!(!is_multirotor(&m));
        assert_eq!(
            DjiRoute::of(&m),
            Err(DjiRouteError::NotMultirotor("plane take-off"))
        );
        let mut m = sample_dji_mission();
        m.items[1] = MissionItem::ChangeSpeed { speed_m_s: 16.0 };
        let e = DjiRoute::of(&m).unwrap_err();
        assert_eq!(e, DjiRouteError::Speed(16.0));
        assert!(e.to_string().contains("1-15 m/s"), "{e}");
        let mut m = sample_dji_mission();
        m.items.retain(|i| {
            !matches!(
                i,
                MissionItem::Waypoint(_) | MissionItem::HoldWaypoint { .. }
            )
        });
        assert_eq!(DjiRoute::of(&m), Err(DjiRouteError::NoWaypoints));
    }

    #[test]
    fn bearings_and_distances() {
        let a = GeoPoint {
            lon: 0.0,
            lat: 0.0,
            alt: 0.0,
        };
        let east = GeoPoint { lon: 0.001, ..a };
        let north = GeoPoint { lat: 0.001, ..a };
        assert!((bearing_deg(&a, &east) - 90.0).abs() < 1e-9);
        assert!(bearing_deg(&a, &north).abs() < 1e-9);
        assert!((bearing_deg(&east, &a) - 270.0).abs() < 1e-9);
        // 0.001° of a great circle: 111.195 m.
        assert!((ground_distance_m(&a, &north) - 111.195).abs() < 1e-3);
    }
}
