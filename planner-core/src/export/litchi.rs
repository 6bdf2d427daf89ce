//! Litchi waypoint missions (CSV, metric columns) for consumer DJI aircraft:
//! at most 99 waypoints a file, so a longer route is split into numbered
//! files, each a complete mission starting where the one before ended.

use std::fmt::Write as _;

use super::mission::{AltitudeFrame, Mission};
use super::wpml_route::{DjiRoute, DjiRouteError, DjiWaypoint, Interval, bearing_deg};

/// Most waypoints of one Litchi mission (DJI's waypoint missions on the
/// aircraft Litchi flies them on).
pub const MAX_WAYPOINTS: usize = 99;
/// Action slots of a row (`actiontype1,actionparam1` … 15).
pub const ACTIONS: usize = 15;
/// Litchi's waypoint altitude range, m.
const ALTITUDE_M: (f64, f64) = (-200.0, 500.0);
/// Litchi action types used here.
const ACTION_NONE: i32 = -1;
const ACTION_STAY_MS: i32 = 0;
const ACTION_PHOTO: i32 = 1;
/// `gimbalmode` 2: interpolate the pitch between waypoints.
const GIMBAL_INTERPOLATE: u8 = 2;

/// The header row: Litchi's columns in its order (metric units).
pub fn header() -> String {
    let mut h = String::from(
        "latitude,longitude,altitude(m),heading(deg),curvesize(m),rotationdir,gimbalmode,\
         gimbalpitchangle",
    );
    for k in 1..=ACTIONS {
        let _ = write!(h, ",actiontype{k},actionparam{k}");
    }
    h.push_str(
        ",altitudemode,speed(m/s),poi_latitude,poi_longitude,poi_altitude(m),poi_altitudemode,\
         photo_timeinterval,photo_distinterval",
    );
    h
}

/// Why a mission cannot be a Litchi mission.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LitchiError {
    #[error(transparent)]
    Route(#[from] DjiRouteError),
    #[error(
        "waypoint {index} is {alt:.1} m above the take-off point, outside the -200 to 500 m \
         Litchi flies"
    )]
    Altitude { index: usize, alt: f64 },
    #[error("there is no part {0} of this mission")]
    NoPart(usize),
}

/// A mission as Litchi files: its route and the altitudes Litchi flies.
pub struct LitchiMission {
    route: DjiRoute,
    /// `altitudemode`: 0 above the take-off point, 1 above the ground.
    altitude_mode: u8,
    /// Per waypoint, the altitude in that mode, m.
    altitudes: Vec<f64>,
}

impl LitchiMission {
    /// The route of `mission` with its altitudes above the take-off point
    /// (relative frame; AMSL less home's height) or above the ground
    /// (terrain frame, which Litchi follows with its own elevation data).
    pub fn of(mission: &Mission) -> Result<LitchiMission, LitchiError> {
        let route = DjiRoute::of(mission)?;
        let (altitude_mode, less) = match mission.frame {
            AltitudeFrame::Relative => (0, 0.0),
            AltitudeFrame::Amsl => (0, mission.home.alt),
            AltitudeFrame::Terrain => (1, 0.0),
        };
        let altitudes: Vec<f64> = route.waypoints.iter().map(|w| w.point.alt - less).collect();
        if let Some((index, &alt)) = altitudes
            .iter()
            .enumerate()
            .find(|(_, a)| !(ALTITUDE_M.0..=ALTITUDE_M.1).contains(*a))
        {
            return Err(LitchiError::Altitude { index, alt });
        }
        Ok(LitchiMission {
            route,
            altitude_mode,
            altitudes,
        })
    }

    /// Files the mission takes: one up to 99 waypoints; beyond, each file
    /// starts at the last waypoint of the one before, so 98 more a file.
    pub fn parts(&self) -> usize {
        let n = self.route.waypoints.len();
        if n <= MAX_WAYPOINTS {
            1
        } else {
            (n - 1).div_ceil(MAX_WAYPOINTS - 1)
        }
    }

    /// Part `k` (from 0) as a CSV file: the header and a row per waypoint,
    /// LF line ends. A part's first waypoint repeats the last of the part
    /// before (where that mission ended): its hover and photo were taken
    /// there, so only a run of photos passing through it carries on.
    pub fn csv(&self, k: usize) -> Result<String, LitchiError> {
        if k >= self.parts() {
            return Err(LitchiError::NoPart(k + 1));
        }
        let n = self.route.waypoints.len();
        let first = k * (MAX_WAYPOINTS - 1);
        let last = (first + MAX_WAYPOINTS - 1).min(n - 1);
        let mut out = header();
        out.push('\n');
        for i in first..=last {
            self.row(&mut out, i, i == first && k > 0, i == last);
        }
        Ok(out)
    }

    /// The row of waypoint `i`; `resumed`: the first of a later part;
    /// `end`: the last of its part (no leg after it).
    fn row(&self, out: &mut String, i: usize, resumed: bool, end: bool) {
        let wps = &self.route.waypoints;
        let w: &DjiWaypoint = &wps[i];
        // Towards the next waypoint, used when the mission's heading mode
        // is "custom" (Litchi's default flies towards it anyway).
        let heading = match (wps.get(i + 1), i.checked_sub(1)) {
            (Some(next), _) => bearing_deg(&w.point, &next.point),
            (None, Some(p)) => bearing_deg(&wps[p].point, &w.point),
            (None, None) => 0.0,
        };
        let _ = write!(
            out,
            "{:.8},{:.8},{:.3},{:.1},0,0,{GIMBAL_INTERPOLATE},{:.1}",
            w.point.lat, w.point.lon, self.altitudes[i], heading, w.gimbal_pitch_deg
        );
        let mut actions: Vec<(i32, f64)> = Vec::new();
        if !resumed {
            if let Some(s) = w.hold_s.filter(|s| *s > 0.0) {
                actions.push((ACTION_STAY_MS, (s * 1000.0).round()));
            }
            if w.photo {
                actions.push((ACTION_PHOTO, 0.0));
            }
        }
        actions.resize(ACTIONS, (ACTION_NONE, 0.0));
        for (t, p) in actions {
            let _ = write!(out, ",{t},{p}");
        }
        // Photos every so often on the leg from here to the next waypoint.
        let run = self
            .route
            .runs
            .iter()
            .find(|r| r.start <= i && i < r.end)
            .filter(|_| !end);
        let (time, dist) = match run.map(|r| r.every) {
            Some(Interval::Time(s)) => (s, -1.0),
            Some(Interval::Distance(d)) => (-1.0, d),
            None => (-1.0, -1.0),
        };
        let _ = writeln!(
            out,
            ",{},{:.2},0,0,0,0,{},{}",
            self.altitude_mode, w.speed_m_s, time, dist
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::mission::{GeoPoint, MissionItem};
    use crate::export::wpml_route::sample_dji_mission;

    fn rows(csv: &str) -> Vec<Vec<String>> {
        csv.lines()
            .map(|l| l.split(',').map(str::to_string).collect())
            .collect()
    }

    #[test]
    fn columns_altitudes_and_actions() {
        let l = LitchiMission::of(&sample_dji_mission()).unwrap();
        assert_eq!(l.parts(), 1);
        let csv = l.csv(0).unwrap();
        assert!(!csv.contains('\r'));
        let r = rows(&csv);
        let cols = 8 + 2 * ACTIONS + 8;
        assert_eq!(r[0].len(), cols);
        assert_eq!(r[0][2], "altitude(m)");
        assert_eq!(r[0][38], "altitudemode");
        assert_eq!(r[0][45], "photo_distinterval");
        assert_eq!(r.len(), 1 + 5);
        assert!(r.iter().all(|row| row.len() == cols));
        // First waypoint: 50 m over take-off, heading north to the next,
        // gimbal -80, photos every 12 m on its leg.
        assert_eq!(
            &r[1][..8],
            [
                "52.00100000",
                "5.00100000",
                "50.000",
                "0.0",
                "0",
                "0",
                "2",
                "-80.0"
            ]
        );
        assert_eq!((r[1][38].as_str(), r[1][39].as_str()), ("0", "8.00"));
        assert_eq!((r[1][44].as_str(), r[1][45].as_str()), ("-1", "12"));
        // The hover photo: stay 2000 ms, then a photo; then photos every
        // 1.5 s to the end.
        assert_eq!(&r[4][8..12], ["0", "2000", "1", "0"]);
        assert_eq!((r[4][44].as_str(), r[4][45].as_str()), ("1.5", "-1"));
        assert_eq!((r[5][44].as_str(), r[5][45].as_str()), ("-1", "-1"));
        assert_eq!(l.csv(1), Err(LitchiError::NoPart(2)));
    }

    #[test]
    fn long_routes_split_into_complete_missions_of_99() {
        let mut m = sample_dji_mission();
        m.items.truncate(3);
        m.items
            .push(MissionItem::CameraTriggerDistance { distance_m: 10.0 });
        for k in 0..250 {
            m.items.push(MissionItem::Waypoint(GeoPoint {
                lon: 5.0 + k as f64 * 1e-4,
                lat: 52.0,
                alt: 40.0,
            }));
        }
        m.items.push(MissionItem::ReturnToLaunch);
        let l = LitchiMission::of(&m).unwrap();
        // 99 + 98 + 53 waypoints, each part from the last of the one before.
        assert_eq!(l.parts(), 3);
        let parts: Vec<Vec<Vec<String>>> = (0..3).map(|k| rows(&l.csv(k).unwrap())).collect();
        assert_eq!(
            parts.iter().map(|p| p.len() - 1).collect::<Vec<_>>(),
            [99, 99, 54]
        );
        assert_eq!(parts[0][99][1], parts[1][1][1]);
        assert_eq!(parts[1][99][1], parts[2][1][1]);
        let mut lons: Vec<String> = parts[0][1..].iter().map(|r| r[1].clone()).collect();
        for p in &parts[1..] {
            lons.extend(p[2..].iter().map(|r| r[1].clone()));
        }
        assert_eq!(lons.len(), 250);
        assert_eq!(lons[249], "5.02490000");
        // The photo run carries on through the joins and stops at the end.
        assert_eq!(parts[1][1][45], "10");
        assert_eq!(parts[0][99][45], "-1");
    }

    #[test]
    fn amsl_is_flown_over_take_off_and_terrain_over_ground() {
        let mut m = sample_dji_mission();
        m.frame = AltitudeFrame::Amsl;
        m.home.alt = 30.0;
        let csv = LitchiMission::of(&m).unwrap().csv(0).unwrap();
        let r = rows(&csv);
        assert_eq!((r[1][2].as_str(), r[1][38].as_str()), ("20.000", "0"));
        m.frame = AltitudeFrame::Terrain;
        let r = rows(&LitchiMission::of(&m).unwrap().csv(0).unwrap());
        assert_eq!((r[1][2].as_str(), r[1][38].as_str()), ("50.000", "1"));
        m.frame = AltitudeFrame::Amsl;
        m.home.alt = 600.0;
        assert!(matches!(
            LitchiMission::of(&m),
            Err(LitchiError::Altitude { index: 0, .. })
        ));
    }
}
