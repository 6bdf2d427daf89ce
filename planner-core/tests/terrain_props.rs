//! Terrain following on random terrain (smooth hills, sharp spikes, walls):
//! along every flown segment, checked with a bilinear sampler written here,
//! lanes and links stay at least `altitude_m − agl_tolerance_m` above the
//! DEM and transits at least `transit_clearance_m`; rate limits hold
//! between waypoints of a leg; the mission's waypoints are the legs' points
//! in the requested frame.

use geo::{Distance, Euclidean};
use geo_types::{Coord, Line, LineString, Polygon};
use planner_core::export::{AltitudeFrame, MissionItem};
use planner_core::geo::{Limits, ParsedPolygon, UtmProjection};
use planner_core::survey::{
    LegKind, SliceAngle, SurveyParams, SurveyRequest, UavSpec, plan_survey_over,
};
use planner_core::terrain::{Crs, Dem, DemFormat, GeoTransform};
use proptest::prelude::*;

/// UTM zone 32N around 9°E 47°N.
const EPSG: u32 = 32632;
const E0: f64 = 500_000.0;
const N0: f64 = 5_205_000.0;

/// The DEM: `w`×`h` cells of `cell` metres, north-up, top-left at
/// (E0 − w·cell/2, N0 + h·cell/2).
fn terrain(
    w: usize,
    h: usize,
    cell: f64,
    hills: &[(f64, f64, f64, f64)],
    spikes: &[(usize, usize, f64)],
) -> Dem {
    let t = GeoTransform {
        origin_x: E0 - w as f64 * cell / 2.0,
        pixel_width: cell,
        row_rotation: 0.0,
        origin_y: N0 + h as f64 * cell / 2.0,
        col_rotation: 0.0,
        pixel_height: -cell,
    };
    let mut values = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            let (x, y) = t.apply(c as f64 + 0.5, r as f64 + 0.5);
            let z: f64 = hills
                .iter()
                .map(|&(hx, hy, amp, sigma)| {
                    let d2 = (x - E0 - hx).powi(2) + (y - N0 - hy).powi(2);
                    amp * (-d2 / (2.0 * sigma * sigma)).exp()
                })
                .sum();
            values.push(300.0 + z);
        }
    }
    for &(c, r, dz) in spikes {
        if c < w && r < h {
            values[r * w + c] += dz;
        }
    }
    Dem {
        width: w,
        height: h,
        values,
        nodata: None,
        transform: t,
        crs: Crs {
            epsg: EPSG,
            name: "WGS 84 / UTM zone 32N".into(),
            geographic: false,
            proj4: String::new(),
        },
        format: DemFormat::GeoTiff,
    }
}

/// Bilinear between cell centres, clamped in the outer half cell (the
/// convention of GDAL and of the service), written independently here.
fn height(dem: &Dem, x: f64, y: f64) -> Option<f64> {
    let t = &dem.transform;
    let col = (x - t.origin_x) / t.pixel_width - 0.5;
    let row = (y - t.origin_y) / t.pixel_height - 0.5;
    let (w, h) = (dem.width as f64, dem.height as f64);
    if col < -0.5 || row < -0.5 || col > w - 0.5 || row > h - 0.5 {
        return None;
    }
    let col = col.clamp(0.0, w - 1.0);
    let row = row.clamp(0.0, h - 1.0);
    let (c0, r0) = (col.floor() as usize, row.floor() as usize);
    let (c1, r1) = ((c0 + 1).min(dem.width - 1), (r0 + 1).min(dem.height - 1));
    let (fc, fr) = (col - c0 as f64, row - r0 as f64);
    let v = |c: usize, r: usize| dem.values[r * dem.width + c];
    Some(
        v(c0, r0) * (1.0 - fc) * (1.0 - fr)
            + v(c1, r0) * fc * (1.0 - fr)
            + v(c0, r1) * (1.0 - fc) * fr
            + v(c1, r1) * fc * fr,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn flights_keep_their_heights_above_random_terrain(
        cell in prop_oneof![Just(1.0f64), Just(2.5), Just(10.0)],
        hills in prop::collection::vec((-300.0f64..300.0, -300.0f64..300.0, -40.0f64..120.0, 15.0f64..150.0), 0..6),
        spikes in prop::collection::vec((0usize..400, 0usize..400, 5.0f64..60.0), 0..8),
        size in (150.0f64..450.0, 150.0f64..450.0),
        altitude in 25.0f64..120.0,
        tolerance in 0.5f64..10.0,
        clearance in prop_oneof![Just(None), (10.0f64..150.0).prop_map(Some)],
        rates in prop_oneof![Just(None), (1.0f64..6.0, 1.0f64..6.0).prop_map(Some)],
        frame in prop_oneof![Just(AltitudeFrame::Relative), Just(AltitudeFrame::Amsl), Just(AltitudeFrame::Terrain)],
        nfz in prop::bool::ANY,
        narrow in prop::bool::ANY,
    ) {
        prop_assume!(tolerance < altitude);
        // DEM of 1.2 km × 1.2 km (or its cell count's worth), ROI inside.
        let n = ((1200.0 / cell) as usize).min(400);
        let span = n as f64 * cell / 2.0 - 20.0;
        let dem = terrain(n, n, cell, &hills, &spikes);
        let proj = UtmProjection::new(32, true).unwrap();
        let ll = |x: f64, y: f64| proj.to_wgs84(Coord { x: E0 + x, y: N0 + y }).unwrap();
        let (hx, hy) = (size.0.min(span) / 2.0, size.1.min(span) / 2.0);
        let ring = vec![ll(-hx, -hy), ll(hx, -hy), ll(hx, hy), ll(-hx, hy)];
        let roi = Polygon::new(LineString::new(ring), vec![]);
        let no_fly = if nfz {
            let z = vec![ll(0.0, 0.0), ll(hx / 2.0, 0.0), ll(hx / 2.0, hy / 2.0), ll(0.0, hy / 2.0)];
            vec![ParsedPolygon { polygon: Polygon::new(LineString::new(z), vec![]), pointer: "/no_fly_zones/0".into() }]
        } else {
            Vec::new()
        };
        let start = ll(-hx - 10.0, -hy - 10.0);
        // A narrow footprint leaves almost no dilation, so the band itself
        // is what keeps the lanes up.
        let (camera, spacing) = if narrow {
            let c = planner_core::coverage::Camera {
                sensor_width_mm: 2.0,
                sensor_height_mm: 1.5,
                focal_length_mm: 400.0,
                image_width_px: 2000,
                image_height_px: 1500,
                orientation: Default::default(),
            };
            (Some(c), Some(30.0))
        } else {
            (None, None)
        };
        let params = SurveyParams {
            altitude_m: Some(altitude),
            camera,
            line_spacing_m: spacing,
            slice_angle_deg: SliceAngle::Degrees(0.0),
            agl_tolerance_m: tolerance,
            transit_clearance_m: clearance,
            max_climb_rate_m_s: rates.map(|r| r.0),
            max_descent_rate_m_s: rates.map(|r| r.1),
            altitude_frame: frame,
            uavs: vec![UavSpec { id: "u".into(), start: [start.x, start.y], speed_m_s: None, max_flight_time_s: None }],
            ..SurveyParams::default()
        };
        let req = SurveyRequest {
            roi: vec![ParsedPolygon { polygon: roi, pointer: "/roi".into() }],
            corridor: None,
            no_fly,
            params: params.clone(),
        };
        let plan = match plan_survey_over(&req, &Limits::default(), Some(&dem)) {
            Ok(p) => p,
            Err(planner_core::survey::PlanError::Invalid(i)) if i.iter().any(|i| i.message.contains("too small or too thin")) => return Ok(()),
            Err(e) => return Err(TestCaseError::fail(format!("planning failed: {e}"))),
        };
        let uav = &plan.uavs[0].sorties[0];
        let t = uav.terrain.as_ref().unwrap();
        let clearance = clearance.unwrap_or(altitude);
        let speed = params.speed_m_s;
        let utm = |p: &[f64; 3]| {
            let c = proj.to_utm(Coord { x: p[0], y: p[1] }).unwrap();
            (c.x, c.y, p[2])
        };
        for leg in &t.legs {
            let need = match leg.kind {
                LegKind::Transit => clearance,
                LegKind::Lane | LegKind::Link => altitude - tolerance,
            };
            let pts: Vec<(f64, f64, f64)> = leg.points.iter().map(utm).collect();
            for w in pts.windows(2) {
                let (a, b) = (w[0], w[1]);
                let d = (b.0 - a.0).hypot(b.1 - a.1);
                let steps = ((d / (cell / 4.0)).ceil() as usize).max(1);
                for k in 0..=steps {
                    let s = k as f64 / steps as f64;
                    let (x, y, z) = (a.0 + (b.0 - a.0) * s, a.1 + (b.1 - a.1) * s, a.2 + (b.2 - a.2) * s);
                    let ground = height(&dem, x, y).expect("the survey lies inside the DEM");
                    // 1 mm for the lon/lat round trip of the legs.
                    prop_assert!(z - ground >= need - 1e-3,
                        "{:?} at ({x:.2}, {y:.2}): {:.3} m above the DEM, needs {need:.3}", leg.kind, z - ground);
                }
                if let Some((climb, descent)) = rates && d > 1e-6 {
                    let slope = (b.2 - a.2) / d;
                    prop_assert!(slope <= climb / speed + 1e-6 && slope >= -descent / speed - 1e-6,
                        "{:?}: slope {slope} beyond the rate limits", leg.kind);
                }
            }
        }
        // The mission flies the legs (the first point is the take-off's).
        let mut leg_pts: Vec<[f64; 3]> = Vec::new();
        for p in t.legs.iter().flat_map(|l| l.points.iter()) {
            let same = leg_pts.last().is_some_and(|q: &[f64; 3]| q[0] == p[0] && q[1] == p[1] && (q[2] - p[2]).abs() < 0.01);
            if !same {
                leg_pts.push(*p);
            }
        }
        let home = uav.mission.home.alt;
        prop_assert!((home - height(&dem, proj.to_utm(start).unwrap().x, proj.to_utm(start).unwrap().y).unwrap()).abs() < 1e-6);
        let wps: Vec<_> = uav.mission.items.iter().filter_map(|i| match i {
            MissionItem::Waypoint(p) => Some(*p),
            _ => None,
        }).collect();
        prop_assert_eq!(wps.len(), leg_pts.len() - 1);
        for (w, p) in wps.iter().zip(&leg_pts[1..]) {
            let c = proj.to_utm(Coord { x: w.lon, y: w.lat }).unwrap();
            let z = match frame {
                AltitudeFrame::Relative => w.alt + home,
                AltitudeFrame::Amsl => w.alt,
                AltitudeFrame::Terrain => w.alt + height(&dem, c.x, c.y).unwrap(),
            };
            prop_assert!((w.lon - p[0]).abs() < 1e-12 && (w.lat - p[1]).abs() < 1e-12);
            prop_assert!((z - p[2]).abs() < 1e-6, "waypoint height {z} vs leg {}", p[2]);
        }
        prop_assert!(narrow || plan.stats.coverage_ratio > 0.97);
        // Horizontally, every leg keeps the NFZ clearance (the start lies
        // outside the ROI, far from the NFZ).
        if let Some(zone) = req.no_fly.first() {
            let zone = proj.polygon_to_utm(&zone.polygon).unwrap();
            let keep = plan.stats.nfz_clearance_m;
            prop_assert_eq!(keep, 5.0);
            for leg in &t.legs {
                for w in leg.points.windows(2) {
                    let (a, b) = (utm(&w[0]), utm(&w[1]));
                    let line = Line::new(Coord { x: a.0, y: a.1 }, Coord { x: b.0, y: b.1 });
                    let d = Euclidean.distance(&line, &zone);
                    prop_assert!(d >= keep - 0.01, "{:?} leg {d:.3} m from the NFZ", leg.kind);
                }
            }
        }
    }
}
