//! The survey pipeline: area → free space → cells → lanes → tour → mission,
//! stage by stage (SPEC §3). The CLI and the service both call
//! [`plan_survey`] and write [`SurveyPlan::files`].
//!
//! Each stage has its module: `request` (the parameters and their checks),
//! `cells` (free space, decomposition, lane plans), `homes` (the flock's
//! starts and the flyable space), `terrain_prep` (the DEM under the
//! survey), `flock_plan` (sharing the cells), `mission` (each UAV's
//! missions and the fences), `result` (the plan) and `files` (its files).

use geo::Area;

use crate::geo::Limits;
use crate::terrain::Dem;

mod aircraft;
mod capture;
mod cells;
mod corridor;
mod dji_files;
mod files;
mod flock_plan;
mod homes;
mod mission;
mod oblique_lanes;
mod photo_overlap;
mod photos;
mod photos_file;
mod photos_mission;
mod plane_bends;
mod plane_clearance;
mod plane_escape;
mod plane_flight;
mod plane_heights;
mod plane_pieces;
mod plane_transit;
mod rally;
mod request;
mod result;
mod slice_angle;
mod terrain_flight;
mod terrain_prep;

pub use aircraft::{Aircraft, AircraftType};
pub use capture::{DEFAULT_HOLD_S, Trigger, TriggerMode};
pub use corridor::{CORRIDOR_POINTER, CORRIDOR_WIDTH_RANGE_M};
pub use files::{PlanFile, content_type_of};
pub use photo_overlap::CellPhotos;
pub use photos::{Photo, PhotoCamera, PhotoLane, SortiePhotos};
pub use rally::MAX_RALLY_DISTANCE_M;
pub use request::{
    DEFAULT_ALTITUDE_M, DEFAULT_NFZ_CLEARANCE_M, DEM_POINTER, MAX_RALLY_POINTS, MAX_UAVS,
    NO_FLY_POINTER, PlanError, ROI_POINTER, SliceAngle, SurveyParams, SurveyRequest, UavSpec,
};
pub use result::{
    CellOut, RallyPoint, SortiePlan, SurveyPlan, SurveyStats, SurveyTerrainStats, UavPlan, UavStats,
};
pub use terrain_flight::{FlightLeg, LegKind, ProfilePoint, UavTerrain};

/// Plan a survey end to end, flat (no DEM).
pub fn plan_survey(req: &SurveyRequest, limits: &Limits) -> Result<SurveyPlan, PlanError> {
    plan_survey_over(req, limits, None)
}

/// Plan a survey end to end, following the terrain of `dem` when given
/// (the service resolves the `dem_id` of its requests into it; faults of
/// the DEM are reported at [`DEM_POINTER`]).
pub fn plan_survey_over(
    req: &SurveyRequest,
    limits: &Limits,
    dem: Option<&Dem>,
) -> Result<SurveyPlan, PlanError> {
    let flown_params = req.params.as_flown();
    let params = &flown_params;
    params.validate("").map_err(PlanError::Invalid)?;
    params.check_dem(dem)?;
    let prepared = corridor::prepare(req, limits)?;
    let req = prepared.as_area.as_ref().unwrap_or(req);
    let area = prepared.area;
    // The keep-out area round the NFZs needs no free space: both at once.
    let (free, keep_out) = crate::cancel::join(
        || cells::free_space(&area),
        || homes::keep_out_area(&area.no_fly, req.params.nfz_clearance_m),
    );
    let free = free?;
    let free_area = free.unsigned_area();
    let flight = params.flight(free_area, limits, dem.is_some())?;
    let setup = homes::FlockSetup::new(req, &area, &free, keep_out)?;
    crate::cancel::check()?;
    let mut d = if let Some((line, width)) = &prepared.centre {
        corridor::lay_corridor(line, *width, &setup.flyable, flight.geometry.line_spacing_m)?
    } else {
        let compare = match (params.plane(), setup.homes.first()) {
            (None, Some(&start)) => slice_angle::Compare::WholePlan {
                start,
                obstacles: &setup.obstacles,
                free: &free,
                footprint_side_m: flight.geometry.footprint_side_m,
            },
            _ => slice_angle::Compare::FewestTurns,
        };
        slice_angle::decompose_and_cover(
            &setup.flyable,
            params.slice_angle_deg,
            flight.geometry.line_spacing_m,
            &compare,
        )?
    };
    let over_dem = match dem {
        None => None,
        Some(dem) => Some(terrain_prep::follow_terrain(
            dem, &area, &free, &setup, params, &flight, &mut d,
        )?),
    };
    cells::lay_pattern(
        &mut d,
        params.pattern,
        &setup.flyable,
        flight.geometry.line_spacing_m,
    )?;
    oblique_lanes::lengthen_lanes(
        &mut d,
        oblique_lanes::near_offset_m(params, flight.altitude),
        &setup.obstacles,
    );
    aircraft::order_lanes(&mut d, params);
    let (rally_points, rally_utm) =
        rally::check_rally_points(&params.rally_points, &area, setup.clearance, dem)?;
    // The coverage figure needs only the lanes: measured on another core
    // while the flock shares the cells (a plane's once it has flown them).
    let (outcome, planned_coverage) = crate::cancel::join(
        || flock_plan::share_cells(&setup, &d, params, &flight, over_dem.as_ref()),
        || {
            (params.plane().is_none())
                .then(|| cells::coverage(&d.plans, flight.geometry.footprint_side_m, &free))
        },
    );
    let outcome = outcome?;
    let proj = &area.projection;
    let (uavs, flown, plane_lanes) = mission::uav_plans(
        &setup,
        outcome.sorties,
        over_dem.as_ref(),
        params,
        &flight,
        proj,
    )?;
    crate::cancel::check()?;
    // A plane's coverage (of the lanes it flies) on another core while
    // the cells' figures and the fences are made.
    let side = flight.geometry.footprint_side_m;
    let (made, flown_coverage) = crate::cancel::join(
        || cells_and_fences(&d, &area, &uavs, flown, rally_utm, params),
        || {
            let fly = planned_coverage.is_none();
            fly.then(|| aircraft::flown_coverage(&plane_lanes, side, &free))
        },
    );
    let (cells_out, fences) = made?;
    let (lane_count, coverage_ratio) = planned_coverage.or(flown_coverage).unwrap_or_default();
    let mut warnings = setup.warnings.clone();
    warnings.extend(aircraft::battery_warnings(params, &uavs));
    warnings.extend(over_dem.as_ref().and_then(|o| o.terrain.warning()));
    let lanes = (&d.plans[..], &plane_lanes[..]);
    warnings.extend(aircraft::left_out_warnings(
        params,
        &setup,
        lanes,
        coverage_ratio,
        free_area,
    ));
    let figures = result::Figures {
        area_m2: area.roi.unsigned_area(),
        free_area_m2: free_area,
        flyable_area_m2: setup.flyable.unsigned_area(),
        nfz_clearance_m: setup.clearance,
        altitude_m: flight.altitude,
        geometry: &flight.geometry,
        slice_angle_deg: d.slice_angle_deg,
        cell_count: d.cells.len(),
        lane_count,
        coverage_ratio,
        assignment: params.assignment,
        makespan_lower_bound_s: outcome.lower_bound_s,
        terrain: over_dem.as_ref().map(|o| SurveyTerrainStats {
            dem_known_fraction: o.terrain.known_fraction,
            dilation_radius_m: o.terrain.model.dilation_radius_m(),
            agl_tolerance_m: flight.rules.tolerance_m,
            transit_clearance_m: flight.rules.transit_clearance_m,
        }),
    };
    let mut plan = SurveyPlan {
        utm_epsg: proj.epsg(),
        altitude_frame: params.altitude_frame,
        stats: SurveyStats::new(figures, &uavs),
        cells: cells_out,
        uavs,
        fences,
        rally_points,
        warnings,
        dji_aircraft: params.dji_aircraft,
        max_photo_features: limits.max_photo_features,
    };
    // Multirotor sorties DJI cannot fly (too fast, say) get no DJI files.
    let dji = plan.dji_warnings();
    plan.warnings.extend(dji);
    Ok(plan)
}

/// The cells as planned with the overlaps their photos achieve, and the
/// fences: the inclusion fence round everything `flown` and the rally
/// points (a UAV flies there on RTL), keeping the NFZs' clearance too (a
/// vehicle flying on its edge would breach it with ordinary GPS error).
fn cells_and_fences(
    d: &cells::Decomposition,
    area: &crate::geo::SurveyArea,
    uavs: &[UavPlan],
    mut flown: Vec<geo_types::Coord<f64>>,
    rally_utm: Vec<geo_types::Coord<f64>>,
    params: &SurveyParams,
) -> Result<(Vec<CellOut>, Vec<crate::export::FencePolygon>), PlanError> {
    let mut cells_out = cells::cells_out(d, &area.projection)?;
    photo_overlap::fill(&mut cells_out, uavs);
    flown.extend(rally_utm);
    let margin = params.fence_margin_m.max(params.nfz_clearance_m);
    let fences = mission::fences(area, &flown, margin)?;
    Ok((cells_out, fences))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    /// A geographic DEM (EPSG:4326, 0.0001° cells) rising 0.02 m per metre
    /// eastwards, over the square of `plans_a_square…`.
    fn slope_dem() -> crate::terrain::Dem {
        use crate::terrain::{Crs, Dem, DemFormat, GeoTransform};
        let (w, h) = (80usize, 70usize);
        let t = GeoTransform {
            origin_x: 4.997,
            pixel_width: 1e-4,
            row_rotation: 0.0,
            origin_y: 52.005,
            col_rotation: 0.0,
            pixel_height: -1e-4,
        };
        let m_per_deg_lon = 111_320.0 * 52.0f64.to_radians().cos();
        let mut values = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let (lon, _) = t.apply(c as f64 + 0.5, r as f64 + 0.5);
                values.push(100.0 + (lon - 4.997) * m_per_deg_lon * 0.02);
            }
        }
        Dem {
            width: w,
            height: h,
            values,
            nodata: None,
            transform: t,
            crs: Crs {
                epsg: 4326,
                name: "WGS 84".into(),
                geographic: true,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    #[test]
    fn follows_terrain_in_every_altitude_frame() {
        let dem = slope_dem();
        let start = [4.999, 51.999];
        let home_amsl = dem.sample(start[0], start[1]).unwrap();
        let mut route_heights = Vec::new();
        for frame in ["relative", "amsl", "terrain"] {
            let doc = json!({
                "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
                "slice_angle_deg": 0,
                "altitude_m": 50,
                "agl_tolerance_m": 2,
                "transit_clearance_m": 60,
                "altitude_frame": frame,
                "uavs": [{"id": "a", "start": start}],
            });
            let req = SurveyRequest::from_document(&doc).unwrap();
            let plan = plan_survey_over(&req, &Limits::default(), Some(&dem)).unwrap();
            let uav = &plan.uavs[0].sorties[0];
            let t = uav.terrain.as_ref().unwrap();
            assert!((uav.mission.home.alt - home_amsl).abs() < 1e-9);
            assert!((t.home_amsl_m - home_amsl).abs() < 1e-9);
            assert!(
                t.min_lane_agl_m.unwrap() >= 48.0 - 1e-6,
                "{:?}",
                t.min_lane_agl_m
            );
            assert!(t.min_transit_clearance_m.unwrap() >= 60.0 - 1e-6);
            let stats = plan.stats.terrain.as_ref().unwrap();
            assert_eq!(stats.dem_known_fraction, 1.0);
            // Every mission waypoint, back in the DEM's datum, is a leg point.
            let leg_z: Vec<f64> = t
                .legs
                .iter()
                .flat_map(|l| l.points.iter().map(|p| p[2]))
                .collect();
            let mut amsl = vec![home_amsl];
            for p in uav.mission.waypoints() {
                let ground = dem.sample(p.lon, p.lat).unwrap();
                let z = match frame {
                    "relative" => p.alt + home_amsl,
                    "amsl" => p.alt,
                    _ => p.alt + ground,
                };
                assert!(leg_z.iter().any(|lz| (lz - z).abs() < 1e-6), "{frame}: {z}");
                amsl.push(z);
                assert!(
                    z - ground >= 48.0 - 1e-6,
                    "{frame}: {} above ground",
                    z - ground
                );
            }
            // The slope makes the 3D length longer than the 2D one.
            assert!(uav.stats.length_3d_m > uav.stats.length_m);
            let wpl = plan.file("a.waypoints").unwrap().text().to_string();
            let want = match frame {
                "relative" => "\t3\t16\t",
                "amsl" => "\t0\t16\t",
                _ => "\t10\t16\t",
            };
            assert!(wpl.lines().skip(2).any(|l| l.contains(want)), "{frame}");
            // route.geojson: those heights above mean sea level, home at
            // both ends, plus the EGM96 undulation above the ellipsoid.
            amsl.push(home_amsl);
            let route: Value =
                serde_json::from_slice(&plan.file("a.route.geojson").unwrap().content).unwrap();
            let f = &route["features"][0];
            let got: Vec<f64> =
                serde_json::from_value(f["properties"]["heights_amsl_m"].clone()).unwrap();
            assert_eq!(got.len(), amsl.len(), "{frame}");
            assert!(
                got.iter().zip(&amsl).all(|(a, b)| (a - b).abs() < 1e-3),
                "{frame}"
            );
            let h: Vec<f64> = f["geometry"]["coordinates"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c[2].as_f64().unwrap())
                .collect();
            route_heights.push(h);
        }
        // The same flight in every frame: the same GeoJSON heights.
        for h in &route_heights[1..] {
            assert_eq!(h.len(), route_heights[0].len());
            assert!(
                h.iter()
                    .zip(&route_heights[0])
                    .all(|(a, b)| (a - b).abs() < 1e-3)
            );
        }
        // Without the DEM, a dem_id cannot be planned: DEM ids are the
        // service's (it resolves them), the planner takes none.
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "dem_id": "x",
        });
        assert!(
            matches!(SurveyRequest::from_document(&doc), Err(PlanError::Invalid(i)) if i[0].pointer == DEM_POINTER)
        );
    }
}
