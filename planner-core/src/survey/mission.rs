//! The missions: each UAV's sorties flown as tours (flat, or over the
//! terrain), their waypoints, camera triggers and statistics, and the
//! fences round everything flown.

use geo::{ConvexHull, MultiPoint};
use geo_types::{Coord, Point, Polygon};

use super::capture::Capture;
use super::cells::dist;
use super::flock_plan::SortieTour;
use super::homes::FlockSetup;
use super::photos::{PhotoCamera, PhotoPlanner, SortiePhotos};
use super::request::{Flight, PlanError, SurveyParams};
use super::result::{SortiePlan, UavPlan, UavStats};
use super::terrain_flight::{UavTerrain, fly_tour};
use super::terrain_prep::OverDem;
use crate::export::{FencePolygon, GeoPoint, Mission, MissionItem};
use crate::flock::{Piece, Tour, count_turns};
use crate::geo::{GeoError, SurveyArea, UtmProjection};
use crate::terrain::Point3;

/// The UAVs' plans, every point flown and a plane's lanes flown.
type FlownPlans = (Vec<UavPlan>, Vec<Coord<f64>>, Vec<crate::coverage::Lane>);

/// Every UAV's plan from the tours of its sorties (`flights`, one list
/// per UAV), every point flown (for the fence) and, for a plane, the lanes
/// it flies with the camera on (pulled back from the no-fly zones).
pub(super) fn uav_plans(
    flock: &FlockSetup,
    flights: Vec<Vec<SortieTour>>,
    over_dem: Option<&OverDem>,
    params: &SurveyParams,
    flight: &Flight,
    proj: &UtmProjection,
) -> Result<FlownPlans, PlanError> {
    let mut uav_plans = Vec::with_capacity(flock.specs.len());
    let mut all_paths: Vec<Coord<f64>> = Vec::new();
    let mut plane_lanes = Vec::new();
    let photo_camera = PhotoCamera::new(
        &params.camera(),
        params
            .camera_pitch_deg
            .unwrap_or(crate::coverage::NADIR_PITCH_DEG),
    );
    let plane = params
        .plane()
        .map(|a| super::plane_flight::PlaneFlight::new(a, flight.altitude, &flock.obstacles));
    for (i, (spec, tours)) in flock.specs.iter().zip(flights).enumerate() {
        let speed = spec.speed_m_s.unwrap_or(params.speed_m_s);
        let several = tours.len() > 1;
        let mut sorties = Vec::with_capacity(tours.len());
        for (k, sortie) in tours.into_iter().enumerate() {
            crate::cancel::check()?;
            let tour = &sortie.tour;
            let home_amsl = over_dem.map(|o| (o, o.homes_amsl[i]));
            let capture = Capture::new(params, &flight.geometry, speed);
            let photo_planner = PhotoPlanner {
                camera: photo_camera,
                capture: &capture,
                speed_m_s: speed,
                // A plane's turns are flown arcs, in its length.
                turn_penalty_s: if plane.is_some() {
                    0.0
                } else {
                    params.turn_penalty_s
                },
                model: home_amsl.map(|(o, h)| (&o.terrain.model, h)),
            };
            let (mission, stats, uav_terrain, photos) = if let Some(plane) = &plane {
                let home = flock.homes[i];
                let trigger = flight.geometry.trigger_distance_m;
                let frame = params.altitude_frame;
                let terrain = home_amsl.map(|(o, h)| (&o.terrain.model, &flight.rules, h));
                let (mission, flown) =
                    plane.sortie(tour, home, spec.start, speed, trigger, frame, terrain, proj)?;
                all_paths.extend(flown.points);
                plane_lanes.extend(flown.lanes);
                let photos = photo_planner.of_mission(&mission, tour, proj)?;
                (mission, flown.stats, None, Some(photos))
            } else {
                let (mission, length_3d, uav_terrain, photos) = fly(
                    tour,
                    spec.start,
                    home_amsl,
                    speed,
                    &photo_planner,
                    params,
                    flight,
                    proj,
                )?;
                let path = tour.path();
                let stats = tour_stats(tour, &path, length_3d, speed, params, &capture);
                all_paths.extend(path);
                (mission, stats, uav_terrain, Some(photos))
            };
            sorties.push(SortiePlan {
                file_stem: if several {
                    format!("{}.sortie{}", spec.id, k + 1)
                } else {
                    spec.id.clone()
                },
                cells: visited_cells(&sortie.pieces),
                pieces: sortie.pieces,
                stats,
                mission,
                terrain: uav_terrain,
                photos,
            });
        }
        let pieces: Vec<Piece> = sorties.iter().flat_map(|s| s.pieces.clone()).collect();
        let cells_flown = visited_cells(&pieces);
        let stats = UavStats::total(&sorties, &cells_flown);
        uav_plans.push(UavPlan {
            id: spec.id.clone(),
            start: spec.start,
            speed_m_s: speed,
            max_flight_time_s: spec.max_flight_time_s,
            cells: cells_flown,
            pieces,
            stats,
            sorties,
        });
    }
    Ok((uav_plans, all_paths, plane_lanes))
}

/// One tour flown from `start`: flat at the altitude, or over the DEM
/// from a home at `home_amsl`. The mission, its 3D length, the flight
/// over the terrain and the photos.
#[allow(clippy::too_many_arguments)]
fn fly(
    tour: &Tour,
    start: [f64; 2],
    home_amsl: Option<(&OverDem, f64)>,
    speed: f64,
    photos: &PhotoPlanner,
    params: &SurveyParams,
    flight: &Flight,
    proj: &UtmProjection,
) -> Result<(Mission, f64, Option<UavTerrain>, SortiePhotos), PlanError> {
    let altitude = flight.altitude;
    let capture = photos.capture;
    Ok(match home_amsl {
        None => {
            let home = GeoPoint {
                lon: start[0],
                lat: start[1],
                alt: 0.0,
            };
            let mission = build_mission(tour, home, altitude, speed, capture, params, proj)?;
            // Flat survey: 3D adds the climb after take-off and the
            // descent home.
            let photos = photos.flat(tour, altitude);
            (mission, tour.length_m() + 2.0 * altitude, None, photos)
        }
        Some((o, home_amsl)) => {
            let flown = fly_tour(
                tour,
                &o.terrain.model,
                &flight.rules,
                start,
                home_amsl,
                params.altitude_frame,
                speed,
                capture,
                proj,
            )?;
            let climb = flown.legs.iter().flat_map(|(_, p)| p.first()).next();
            let climb = climb.map_or(0.0, |p| (p.z - home_amsl).abs());
            let photos = photos.over_dem(tour, &flown.legs, climb);
            (
                flown.mission,
                flown.length_3d_m,
                Some(flown.terrain),
                photos,
            )
        }
    })
}

/// Statistics of one flown tour.
fn tour_stats(
    tour: &Tour,
    path: &[Coord<f64>],
    length_3d: f64,
    speed: f64,
    params: &SurveyParams,
    capture: &Capture,
) -> UavStats {
    let lane_lengths: Vec<f64> = tour
        .visits
        .iter()
        .flat_map(|v| &v.lanes)
        .map(|l| dist(l.start, l.end))
        .collect();
    let turns = count_turns(path);
    let photos = lane_lengths.iter().map(|&len| capture.photos(len)).sum();
    let mut cells: Vec<usize> = tour.visits.iter().map(|v| v.cell_index).collect();
    cells.sort_unstable();
    cells.dedup();
    UavStats {
        length_m: tour.length_m(),
        length_3d_m: length_3d,
        survey_length_m: lane_lengths.iter().sum(),
        transit_length_m: tour.transit_length_m(),
        turns,
        flight_time_s: length_3d / speed
            + turns as f64 * params.turn_penalty_s
            + capture.stop_time_s(photos),
        photos,
        cells: cells.len(),
        sorties: 1,
    }
}

/// Cell ids in the order the pieces are flown, a cell once per run of its
/// pieces.
fn visited_cells(pieces: &[Piece]) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    for p in pieces {
        if out.last() != Some(&p.cell) {
            out.push(p.cell);
        }
    }
    out
}

/// The mission: take-off, speed, then every transit and lane in order, with
/// the camera triggering by distance along each lane, back above home, RTL.
fn build_mission(
    tour: &Tour,
    home: GeoPoint,
    altitude: f64,
    speed_m_s: f64,
    capture: &Capture,
    params: &SurveyParams,
    proj: &UtmProjection,
) -> Result<Mission, GeoError> {
    let wp = |c: Coord<f64>| -> Result<MissionItem, GeoError> {
        let ll = proj.to_wgs84(c)?;
        Ok(MissionItem::Waypoint(GeoPoint {
            lon: ll.x,
            lat: ll.y,
            alt: altitude,
        }))
    };
    let mut items = vec![
        MissionItem::Takeoff { alt: altitude },
        MissionItem::ChangeSpeed { speed_m_s },
    ];
    items.extend(capture.start_items());
    let to_geo = |p: &Point3| -> Result<GeoPoint, GeoError> {
        let ll = proj.to_wgs84(p.xy())?;
        Ok(GeoPoint {
            lon: ll.x,
            lat: ll.y,
            alt: p.z,
        })
    };
    let at_altitude = |c: Coord<f64>| Point3 {
        x: c.x,
        y: c.y,
        z: altitude,
    };
    let transit =
        |items: &mut Vec<MissionItem>, t: &[Coord<f64>], keep_last: bool| -> Result<(), GeoError> {
            // The first point is where we already are; the last is the next lane
            // start, written by the lane itself, except on the way home.
            let end = if keep_last {
                t.len()
            } else {
                t.len().saturating_sub(1)
            };
            for &c in t.iter().take(end).skip(1) {
                items.push(wp(c)?);
            }
            Ok(())
        };
    for (i, visit) in tour.visits.iter().enumerate() {
        transit(&mut items, &tour.transits[i], false)?;
        for (k, lane) in visit.lanes.iter().enumerate() {
            // A corridor's lane going on round a bend: the UAV is there already.
            let goes_on =
                k > 0 && visit.lanes[k - 1].end == lane.start && visit.links[k - 1].is_empty();
            let pts = [at_altitude(lane.start), at_altitude(lane.end)];
            items.extend(capture.lane_items(&pts, goes_on, &to_geo)?.0);
            if let Some(link) = visit.links.get(k) {
                for &c in link {
                    items.push(wp(c)?);
                }
            }
        }
    }
    if let Some(last) = tour.transits.last() {
        transit(&mut items, last, true)?;
    }
    items.push(MissionItem::ReturnToLaunch);
    Ok(Mission {
        home,
        frame: params.altitude_frame,
        cruise_speed_m_s: speed_m_s,
        items,
        over_terrain: false,
    })
}

/// The inclusion fence (convex hull of the ROI and the flown path, grown by
/// at least `margin`) followed by every no-fly zone as an exclusion fence.
pub(super) fn fences(
    area: &SurveyArea,
    path: &[Coord<f64>],
    margin: f64,
) -> Result<Vec<FencePolygon>, GeoError> {
    let proj = &area.projection;
    let mut pts: Vec<Point<f64>> = area
        .roi
        .0
        .iter()
        .flat_map(|p| p.exterior().0.iter().map(|&c| Point(c)))
        .collect();
    pts.extend(path.iter().map(|&c| Point(c)));
    // Grow the hull by `margin`: a 16-gon circumscribed about a circle of
    // that radius round every hull vertex, hulled again. Its edges touch
    // the circles, so every flown point is at least `margin` inside.
    let hull = MultiPoint(pts).convex_hull();
    let radius = margin / (std::f64::consts::PI / 16.0).cos();
    let mut grown = Vec::new();
    for c in &hull.exterior().0 {
        for k in 0..16 {
            let t = f64::from(k) * std::f64::consts::TAU / 16.0;
            grown.push(Point::new(c.x + radius * t.cos(), c.y + radius * t.sin()));
        }
    }
    let hull = MultiPoint(grown).convex_hull();
    let mut out = vec![FencePolygon {
        inclusion: true,
        vertices: ring_lonlat(&proj.polygon_to_wgs84(&hull)?),
    }];
    for nfz in &area.no_fly_wgs84 {
        out.push(FencePolygon {
            inclusion: false,
            vertices: ring_lonlat(nfz),
        });
    }
    Ok(out)
}

fn ring_lonlat(p: &Polygon<f64>) -> Vec<[f64; 2]> {
    let ring = &p.exterior().0;
    let n = if ring.len() > 1 && ring.first() == ring.last() {
        ring.len() - 1
    } else {
        ring.len()
    };
    ring[..n].iter().map(|c| [c.x, c.y]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turns_are_heading_changes() {
        let c = |x: f64, y: f64| Coord { x, y };
        // A lawnmower with two lane changes: four 90° turns.
        let path = [
            c(0., 0.),
            c(10., 0.),
            c(10., 1.),
            c(0., 1.),
            c(0., 2.),
            c(10., 2.),
        ];
        assert_eq!(count_turns(&path), 4);
        assert_eq!(count_turns(&[c(0., 0.), c(1., 0.), c(2., 0.01)]), 0);
    }
}
