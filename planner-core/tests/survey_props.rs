//! The whole survey pipeline on random fields with random no-fly zones:
//! no flown segment enters an NFZ, survey lanes stay in the ROI, every
//! cell with lanes is flown exactly once, cells tile the free space, and
//! the mission's waypoints are the tour's points.

use geo::{Contains, Distance, Euclidean, Intersects};
use geo_types::{Coord, LineString, Point, Polygon};
use planner_core::geo::{Limits, ParsedPolygon, UtmProjection};
use planner_core::survey::{SliceAngle, SurveyParams, SurveyRequest, UavSpec, plan_survey};
use proptest::prelude::*;

/// Metres per degree near the test latitude, to build shapes in metres.
const LAT0: f64 = 47.0;
const LON0: f64 = 8.5;

fn to_lonlat(x: f64, y: f64) -> Coord<f64> {
    let m_per_deg_lat = 111_132.0;
    let m_per_deg_lon = 111_320.0 * LAT0.to_radians().cos();
    Coord {
        x: LON0 + x / m_per_deg_lon,
        y: LAT0 + y / m_per_deg_lat,
    }
}

fn star(cx: f64, cy: f64, radii: &[f64], phase: f64) -> Polygon<f64> {
    let n = radii.len();
    let ring: Vec<Coord<f64>> = radii
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let t = phase + i as f64 * std::f64::consts::TAU / n as f64;
            to_lonlat(cx + r * t.cos(), cy + r * t.sin())
        })
        .collect();
    Polygon::new(LineString::new(ring), vec![])
}

fn parsed(p: Polygon<f64>, ptr: &str) -> ParsedPolygon {
    ParsedPolygon {
        polygon: p,
        pointer: ptr.to_string(),
    }
}

/// Inside `zone` and more than 1 cm from its border: rounding of points
/// that lie on a border (lane ends, corners) is not an incursion.
fn deep_inside(zone: &Polygon<f64>, p: Coord<f64>) -> bool {
    let pt = Point(p);
    zone.contains(&pt) && Euclidean.distance(&pt, zone.exterior()) > 0.01
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_fields_are_planned_safely(
        roi_radii in prop::collection::vec(250.0f64..500.0, 5..12),
        nfz in prop::collection::vec((-300.0f64..300.0, -300.0f64..300.0, 20.0f64..90.0, 0.0f64..1.0), 0..5),
        angle in prop_oneof![Just(None), (0.0f64..180.0).prop_map(Some)],
        altitude in 40.0f64..120.0,
    ) {
        let roi = star(0.0, 0.0, &roi_radii, 0.1);
        let zones: Vec<Polygon<f64>> = nfz.iter().map(|&(x, y, r, ph)| star(x, y, &[r; 6], ph)).collect();
        let params = SurveyParams {
            altitude_m: Some(altitude),
            slice_angle_deg: angle.map_or(SliceAngle::Auto, SliceAngle::Degrees),
            uavs: vec![UavSpec { id: "u".into(), start: [LON0 - 0.01, LAT0 - 0.01] }],
            ..SurveyParams::default()
        };
        let req = SurveyRequest {
            roi: vec![parsed(roi, "/roi")],
            no_fly: zones.iter().enumerate().map(|(i, z)| parsed(z.clone(), &format!("/no_fly_zones/{i}"))).collect(),
            params,
        };
        let plan = match plan_survey(&req, &Limits::default()) {
            Ok(p) => p,
            // NFZs may swallow the whole field: that must be the clear 4xx-type error.
            Err(planner_core::survey::PlanError::Invalid(issues)) => {
                prop_assert!(issues.iter().any(|i| i.message.contains("cover the whole")), "{issues:?}");
                return Ok(());
            }
            Err(e) => return Err(TestCaseError::fail(format!("planning failed: {e}"))),
        };
        let proj = UtmProjection::new((plan.utm_epsg - 32600) as u8, true).unwrap();
        let utm = |c: Coord<f64>| proj.to_utm(c).unwrap();
        let zones_utm: Vec<Polygon<f64>> = zones.iter().map(|z| proj.polygon_to_utm(z).unwrap()).collect();
        let roi_utm = proj.polygon_to_utm(&req.roi[0].polygon).unwrap();

        // The flown polyline, sampled every metre, never goes deep into an NFZ.
        let uav = &plan.uavs[0];
        let mut pts = vec![utm(Coord { x: uav.start[0], y: uav.start[1] })];
        pts.extend(uav.mission.waypoints().map(|w| utm(Coord { x: w.lon, y: w.lat })));
        pts.push(pts[0]);
        for w in pts.windows(2) {
            let len = ((w[1].x - w[0].x).powi(2) + (w[1].y - w[0].y).powi(2)).sqrt();
            let steps = (len.ceil() as usize).max(1);
            for k in 0..=steps {
                let t = k as f64 / steps as f64;
                let p = Coord { x: w[0].x + t * (w[1].x - w[0].x), y: w[0].y + t * (w[1].y - w[0].y) };
                for z in &zones_utm {
                    prop_assert!(!deep_inside(z, p), "flown point {p:?} inside an NFZ");
                }
            }
        }
        // Survey lanes stay in the ROI (within 1 cm).
        let mut last = None;
        let mut lane_start = None;
        for item in &uav.mission.items {
            match item {
                planner_core::export::MissionItem::Waypoint(w) => last = Some(utm(Coord { x: w.lon, y: w.lat })),
                planner_core::export::MissionItem::CameraTriggerDistance { distance_m } if *distance_m > 0.0 => lane_start = last,
                planner_core::export::MissionItem::CameraTriggerDistance { .. } => {
                    let (a, b) = (lane_start.take().unwrap(), last.unwrap());
                    for p in [a, b, Coord { x: (a.x + b.x) / 2.0, y: (a.y + b.y) / 2.0 }] {
                        let pt = Point(p);
                        prop_assert!(roi_utm.intersects(&pt) || Euclidean.distance(&pt, roi_utm.exterior()) < 0.01,
                            "lane point {p:?} outside the ROI");
                    }
                }
                _ => {}
            }
        }
        // Every cell with lanes is flown exactly once; cells tile the free area.
        let mut flown = uav.cells.clone();
        flown.sort_unstable();
        let with_lanes: Vec<usize> = plan.cells.iter().filter(|c| c.lanes > 0).map(|c| c.id).collect();
        prop_assert_eq!(flown, with_lanes);
        let cell_area: f64 = plan.cells.iter().map(|c| c.area_m2).sum();
        prop_assert!((cell_area - plan.stats.free_area_m2).abs() <= 1e-6 * plan.stats.free_area_m2);
        prop_assert!(plan.stats.coverage_ratio > 0.97, "coverage {}", plan.stats.coverage_ratio);
    }
}
