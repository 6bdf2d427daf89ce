//! The whole survey pipeline on random fields with random no-fly zones:
//! no flown segment enters an NFZ or comes closer than the clearance to
//! one (away from home), survey lanes stay in the ROI, every
//! cell with lanes is flown exactly once, cells tile the free space, and
//! the mission's waypoints are the tour's points.

use geo::{Contains, Distance, Euclidean, Intersects};
use geo_types::{Coord, LineString, Point, Polygon};
use planner_core::flock::Policy;
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
        starts in prop::collection::vec((-500.0f64..500.0, -500.0f64..500.0), 1..7),
        policy in prop_oneof![Just(Policy::Balanced), Just(Policy::Competition), Just(Policy::MinReach)],
        battery in prop_oneof![Just(None), (300.0f64..1500.0).prop_map(Some)],
    ) {
        let roi = star(0.0, 0.0, &roi_radii, 0.1);
        let zones: Vec<Polygon<f64>> = nfz.iter().map(|&(x, y, r, ph)| star(x, y, &[r; 6], ph)).collect();
        let params = SurveyParams {
            altitude_m: Some(altitude),
            slice_angle_deg: angle.map_or(SliceAngle::Auto, SliceAngle::Degrees),
            // Starts in metres around the field's centre, as lon/lat.
            uavs: starts.iter().enumerate().map(|(i, &(x, y))| UavSpec {
                id: format!("u{i}"),
                start: [LON0 + x / 111_320.0 / LAT0.to_radians().cos(), LAT0 + y / 110_574.0],
                speed_m_s: Some(6.0 + i as f64),
                max_flight_time_s: battery,
            }).collect(),
            assignment: policy,
            ..SurveyParams::default()
        };
        let req = SurveyRequest {
            roi: vec![parsed(roi, "/roi")],
            corridor: None,
            no_fly: zones.iter().enumerate().map(|(i, z)| parsed(z.clone(), &format!("/no_fly_zones/{i}"))).collect(),
            params,
        };
        let plan = match plan_survey(&req, &Limits::default()) {
            Ok(p) => p,
            // NFZs may swallow the whole field: that must be the clear 4xx-type error.
            // A start inside an NFZ, or a battery too small to reach a
            // cell, must be that clear error too.
            Err(planner_core::survey::PlanError::Invalid(issues)) => {
                prop_assert!(issues.iter().any(|i| i.message.contains("cover the whole")
                    || i.message.contains("inside a no-fly zone")
                    || i.message.contains("hemmed in")
                    || i.message.contains("leave nothing")
                    || i.message.contains("within its battery")), "{issues:?}");
                return Ok(());
            }
            Err(e) => return Err(TestCaseError::fail(format!("planning failed: {e}"))),
        };
        let proj = UtmProjection::new((plan.utm_epsg - 32600) as u8, true).unwrap();
        let utm = |c: Coord<f64>| proj.to_utm(c).unwrap();
        let zones_utm: Vec<Polygon<f64>> = zones.iter().map(|z| proj.polygon_to_utm(z).unwrap()).collect();
        let roi_utm = proj.polygon_to_utm(&req.roi[0].polygon).unwrap();

        let clearance = req.params.nfz_clearance_m;
        prop_assert_eq!(clearance, 5.0, "the default clearance");
        prop_assert_eq!(plan.uavs.len(), starts.len());
        let mut pieces: Vec<Vec<(usize, f64, f64)>> = vec![Vec::new(); plan.cells.len()];
        let mut flown_lanes = 0.0;
        for uav in &plan.uavs {
            prop_assert!(!uav.sorties.is_empty());
            for sortie in &uav.sorties {
                // The flown polyline, sampled every metre, never goes deep
                // into an NFZ, and keeps the clearance from every NFZ once
                // away from home (take-off and landing are vertical there).
                let home = utm(Coord { x: uav.start[0], y: uav.start[1] });
                let mut pts = vec![home];
                pts.extend(sortie.mission.waypoints().map(|w| utm(Coord { x: w.lon, y: w.lat })));
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
                        if (p.x - home.x).hypot(p.y - home.y) > clearance {
                            for z in &zones_utm {
                                let d = Euclidean.distance(&Point(p), z);
                                prop_assert!(d >= clearance - 0.01,
                                    "flown point {p:?} {d:.3} m from an NFZ, clearance {clearance} m");
                            }
                        }
                    }
                }
                // Survey lanes stay in the ROI (within 1 cm).
                let mut last = None;
                let mut lane_start = None;
                for item in &sortie.mission.items {
                    match item {
                        planner_core::export::MissionItem::Waypoint(w) => last = Some(utm(Coord { x: w.lon, y: w.lat })),
                        planner_core::export::MissionItem::CameraTriggerDistance { distance_m } if *distance_m > 0.0 => lane_start = last,
                        planner_core::export::MissionItem::CameraTriggerDistance { .. } => {
                            let (a, b) = (lane_start.take().unwrap(), last.unwrap());
                            flown_lanes += ((b.x - a.x).powi(2) + (b.y - a.y).powi(2)).sqrt();
                            for p in [a, b, Coord { x: (a.x + b.x) / 2.0, y: (a.y + b.y) / 2.0 }] {
                                let pt = Point(p);
                                prop_assert!(roi_utm.intersects(&pt) || Euclidean.distance(&pt, roi_utm.exterior()) < 0.01,
                                    "lane point {p:?} outside the ROI");
                            }
                        }
                        _ => {}
                    }
                }
                if let Some(limit) = battery {
                    // Within the battery, up to the model's small differences
                    // from the flown path.
                    prop_assert!(sortie.stats.flight_time_s <= limit * (1.0 + 1e-6),
                        "sortie {} takes {} s > battery {limit} s", sortie.file_stem, sortie.stats.flight_time_s);
                }
                for p in &sortie.pieces {
                    for lane in p.first_lane..p.first_lane + p.lanes {
                        pieces[p.cell].push((lane, p.lane_from, p.lane_to));
                    }
                }
            }
        }
        // Every lane of every cell is flown exactly once, whole or in
        // pieces that add up to it without overlap.
        for cell in &plan.cells {
            let mut got = pieces[cell.id].clone();
            got.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let mut at = (0usize, 0.0f64);
            for &(lane, from, to) in &got {
                if at.1 >= 1.0 - 1e-12 { at = (at.0 + 1, 0.0); }
                prop_assert_eq!(lane, at.0, "cell {} lanes {:?}", cell.id, got);
                prop_assert!((from - at.1).abs() < 1e-12, "cell {} gap or overlap {:?}", cell.id, got);
                at = (lane, to);
            }
            let complete = if cell.lanes == 0 { got.is_empty() } else { at.0 + 1 == cell.lanes && at.1 >= 1.0 - 1e-12 };
            prop_assert!(complete, "cell {} with {} lanes flown as {:?}", cell.id, cell.lanes, got);
        }
        // The camera-on length flown equals the cells' lanes.
        let planned: f64 = plan.cells.iter().map(|c| c.lane_length_m).sum();
        prop_assert!((flown_lanes - planned).abs() <= 1e-3 * planned, "{flown_lanes} vs {planned}");
        // The cells tile the flyable space: the free space less the
        // clearance band, so between the two.
        let cell_area: f64 = plan.cells.iter().map(|c| c.area_m2).sum();
        let flyable = plan.stats.flyable_area_m2;
        prop_assert!((cell_area - flyable).abs() <= 1e-6 * flyable, "{cell_area} vs {flyable}");
        // Up to the boolean operations' snapping (about 1e-9 of the extent).
        prop_assert!(flyable <= plan.stats.free_area_m2 * (1.0 + 1e-6), "{flyable} vs {}", plan.stats.free_area_m2);
        prop_assert!(plan.stats.coverage_ratio > 0.97, "coverage {}", plan.stats.coverage_ratio);
        // Below 99.5 % the plan says how much is left out.
        if plan.stats.coverage_ratio < 0.995 {
            prop_assert!(plan.warnings.iter().any(|w| w.contains("are left out")), "{:?}", plan.warnings);
        }
    }
}
