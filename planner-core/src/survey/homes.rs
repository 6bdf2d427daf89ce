//! The flock on the ground: the keep-out area round the no-fly zones and
//! the flyable space it leaves, the default start of a survey given no
//! UAV, and the checks of given starts (SPEC §3.3: every flown point keeps
//! `nfz_clearance_m` from the NFZs, except the vertical take-off and
//! landing at home).

use geo::{Area, BooleanOps, Closest, ClosestPoint, Distance, Euclidean, Intersects};
use geo_types::{Coord, Line, MultiLineString, MultiPolygon, Point, Polygon};

use super::cells::{MIN_FREE_AREA_M2, dist, nfz_union, roi_minus};
use super::request::{PlanError, SurveyRequest, UavSpec, cancelled_or};
use crate::flock::ObstacleMap;
use crate::geo::{Issue, SurveyArea, UtmProjection, distance_to_zones};

/// The UAVs at their starts and the space they may fly in.
pub(super) struct FlockSetup {
    /// The UAVs given, or the default one.
    pub specs: Vec<UavSpec>,
    /// Whether the request gave no UAV (faults of the default one are
    /// reported at `/uavs`).
    pub default_uav: bool,
    /// Every UAV's start in planning coordinates.
    pub homes: Vec<Coord<f64>>,
    /// The free space less the keep-out area: where lanes, links and
    /// transits run.
    pub flyable: MultiPolygon<f64>,
    pub obstacles: ObstacleMap,
    /// `nfz_clearance_m`.
    pub clearance: f64,
    /// Free area enclosed by the keep-out area and not flown, m².
    pub enclosed_m2: f64,
    pub warnings: Vec<String>,
}

impl FlockSetup {
    /// The flock of `req` over `area`, whose free space is `free`, and
    /// with `keep_out` the [`keep_out_area`] of `area`.
    pub(super) fn new(
        req: &SurveyRequest,
        area: &SurveyArea,
        free: &MultiPolygon<f64>,
        keep_out: MultiPolygon<f64>,
    ) -> Result<FlockSetup, PlanError> {
        let params = &req.params;
        let proj = &area.projection;
        let clearance = params.nfz_clearance_m;
        let flyable_of = |keep_out: &MultiPolygon<f64>| -> Result<MultiPolygon<f64>, PlanError> {
            let flyable = if clearance > 0.0 {
                roi_minus(area, &keep_out.0)
            } else {
                free.clone()
            };
            crate::cancel::check()?;
            if flyable.unsigned_area() < MIN_FREE_AREA_M2 {
                return Err(nothing_flyable(clearance));
            }
            Ok(flyable)
        };
        let mut warnings = Vec::new();
        let default_uav = params.uavs.is_empty();
        // The default start is looked for outside the keep-out area: only
        // once there is flyable space (that fault is the one to report).
        let mut flyable_before_fill = None;
        let specs = if default_uav {
            flyable_before_fill = Some(flyable_of(&keep_out)?);
            let (start, note) = default_start(&req.roi[0].polygon, area, &keep_out, clearance)?;
            warnings.extend(note);
            vec![UavSpec {
                id: "uav1".to_string(),
                start,
                speed_m_s: None,
                max_flight_time_s: None,
            }]
        } else {
            params.uavs.clone()
        };
        let homes: Vec<Coord<f64>> = specs
            .iter()
            .map(|u| {
                proj.to_utm(Coord {
                    x: u.start[0],
                    y: u.start[1],
                })
            })
            .collect::<Result<_, _>>()?;
        // Pockets the keep-out area encloses cannot be reached (gaps between
        // NFZs narrower than twice the clearance): not flown, unless a UAV
        // takes off inside.
        let (keep_out, enclosed_m2) = crate::geo::fill_enclosed(&keep_out, &homes);
        // The flyable space and the transit planner's map of the keep-out
        // area are independent: each on its own core.
        let (flyable, obstacles) = crate::cancel::join(
            || match flyable_before_fill {
                Some(flyable) if enclosed_m2 == 0.0 => Ok(flyable),
                _ => flyable_of(&keep_out),
            },
            || ObstacleMap::new(&keep_out, 0.0),
        );
        let mut flock = FlockSetup {
            specs,
            default_uav,
            homes,
            flyable: flyable?,
            obstacles,
            clearance,
            enclosed_m2,
            warnings,
        };
        let ids: Vec<String> = flock.specs.iter().map(|u| u.id.clone()).collect();
        let pointer = |i: usize, field: &str| uav_pointer(default_uav, i, field);
        let notes = check_homes(
            &flock.homes,
            &ids,
            &pointer,
            &area.no_fly,
            clearance,
            &mut flock.obstacles,
            proj,
        )
        .map_err(cancelled_or)?;
        flock.warnings.extend(notes);
        Ok(flock)
    }

    /// JSON pointer of `field` of UAV `i`: `/uavs` for the default UAV.
    pub(super) fn pointer(&self, i: usize, field: &str) -> String {
        uav_pointer(self.default_uav, i, field)
    }
}

/// The area every flown point keeps out of: the union of the NFZs grown
/// by `nfz_clearance_m` (everything flown keeps that clearance, as the NFZs
/// are exported as exclusion fences; coverage is still measured over the
/// free space). It needs no free space, so it is made beside it.
pub(super) fn keep_out_area(no_fly: &[Polygon<f64>], clearance: f64) -> MultiPolygon<f64> {
    crate::geo::keep_out_area(&nfz_union(no_fly), clearance)
}

fn uav_pointer(default_uav: bool, i: usize, field: &str) -> String {
    if default_uav {
        "/uavs".to_string()
    } else {
        format!("/uavs/{i}/{field}")
    }
}

/// Where a survey given no UAV takes off, in lon/lat, and a note for the
/// plan's warnings when that is not the ROI's first vertex.
///
/// The first vertex of the ROI (as given) that lies outside the keep-out
/// area; else the point of the ROI's boundary outside it nearest to the
/// first vertex. A default must never make a valid survey fail.
fn default_start(
    roi_wgs84: &Polygon<f64>,
    area: &SurveyArea,
    keep_out: &MultiPolygon<f64>,
    clearance_m: f64,
) -> Result<([f64; 2], Option<String>), PlanError> {
    let proj = &area.projection;
    let ring = &roi_wgs84.exterior().0;
    let first = ring[0];
    // Rings may be closed: the last vertex repeats the first.
    let vertices = ring.len() - usize::from(ring.len() > 1 && ring.first() == ring.last());
    for (i, &v) in ring.iter().take(vertices).enumerate() {
        if !keep_out.intersects(&Point(proj.to_utm(v)?)) {
            let note = (i > 0).then(|| {
                format!(
                    "no UAV given: uav1 takes off at the ROI's vertex {} ({:.7}, {:.7}), the \
                     first one {clearance_m} m clear of the no-fly zones",
                    i + 1,
                    v.x,
                    v.y
                )
            });
            return Ok(([v.x, v.y], note));
        }
    }
    // Every vertex is too close: the nearest clear point of the boundary.
    let origin = proj.to_utm(first)?;
    let boundary = MultiLineString(
        area.roi
            .0
            .iter()
            .flat_map(|p| std::iter::once(p.exterior().clone()).chain(p.interiors().to_vec()))
            .collect(),
    );
    let clear = keep_out.clip(&boundary, true);
    let nearest = clear
        .0
        .iter()
        .filter_map(|line| match line.closest_point(&Point(origin)) {
            Closest::Intersection(p) | Closest::SinglePoint(p) => Some(p.0),
            Closest::Indeterminate => None,
        })
        .min_by(|a, b| dist(*a, origin).total_cmp(&dist(*b, origin)));
    let Some(point) = nearest else {
        return Err(PlanError::Invalid(vec![Issue::new(
            "/uavs",
            &format!(
                "no UAV given, and no point of the region's boundary is {clearance_m} m clear of \
                 the no-fly zones to take off from: give the UAVs' start positions"
            ),
        )]));
    };
    let ll = proj.to_wgs84(point)?;
    let note = format!(
        "no UAV given: uav1 takes off at ({:.7}, {:.7}) on the ROI's boundary, the point \
         nearest its first vertex that is {clearance_m} m clear of the no-fly zones",
        ll.x, ll.y
    );
    Ok(([ll.x, ll.y], Some(note)))
}

/// Checks every take-off point (UTM) against the no-fly zones and lets
/// transits leave the ones inside the keep-out area: `obstacles` is the
/// keep-out area's map, and a home in it gets a straight exit leg to its
/// nearest point outside. Refused, each naming the UAV and the distance: a
/// home inside an NFZ, and a home whose way out would run closer than the
/// clearance to an NFZ once away from home (hemmed in between NFZs).
/// Returns a note per home within the clearance.
fn check_homes(
    homes: &[Coord<f64>],
    ids: &[String],
    pointer: &dyn Fn(usize, &str) -> String,
    no_fly: &[Polygon<f64>],
    clearance_m: f64,
    obstacles: &mut ObstacleMap,
    proj: &UtmProjection,
) -> Result<Vec<String>, PlanError> {
    let mut issues = Vec::new();
    let mut notes = Vec::new();
    for (i, &home) in homes.iter().enumerate() {
        let d = distance_to_zones(home, no_fly);
        if d == 0.0 {
            let depth = no_fly
                .iter()
                .filter(|z| z.intersects(&Point(home)))
                .map(|z| Euclidean.distance(&Point(home), z.exterior()))
                .fold(0.0, f64::max);
            issues.push(Issue::new(
                &pointer(i, "start"),
                &format!(
                    "UAV {}'s start position is inside a no-fly zone, {depth:.1} m from its edge",
                    ids[i]
                ),
            ));
            continue;
        }
        if d >= clearance_m {
            continue;
        }
        let Some(exit) = obstacles.allow_endpoint(home) else {
            continue;
        };
        // Beyond a disc of the clearance round home the exit leg is an
        // ordinary flown segment and must keep the clearance.
        let leg = exit - home;
        let len = leg.x.hypot(leg.y);
        let outer = (len > clearance_m).then(|| Line::new(home + leg * (clearance_m / len), exit));
        let closest = outer.map_or(f64::INFINITY, |l| {
            no_fly
                .iter()
                .map(|z| Euclidean.distance(&l, z))
                .fold(f64::INFINITY, f64::min)
        });
        if closest < clearance_m - 0.005 {
            issues.push(Issue::new(
                &pointer(i, "start"),
                &format!(
                    "UAV {}'s start position is {d:.1} m from a no-fly zone and hemmed in by no-fly \
                     zones: no way out keeps nfz_clearance_m ({clearance_m} m) from them; move the \
                     start or lower nfz_clearance_m",
                    ids[i]
                ),
            ));
            continue;
        }
        let ll = proj.to_wgs84(exit)?;
        notes.push(format!(
            "UAV {} takes off {d:.1} m from a no-fly zone, within nfz_clearance_m ({clearance_m} \
             m): it climbs and lands vertically there and leaves by the nearest point {clearance_m} \
             m clear ({:.7}, {:.7})",
            ids[i], ll.x, ll.y
        ));
    }
    if issues.is_empty() {
        Ok(notes)
    } else {
        Err(PlanError::Invalid(issues))
    }
}

/// The error of a keep-out area that leaves nothing to fly over.
fn nothing_flyable(clearance_m: f64) -> PlanError {
    PlanError::Invalid(vec![Issue::new(
        "/nfz_clearance_m",
        &format!(
            "the no-fly zones and the {clearance_m} m kept from them (nfz_clearance_m) leave \
             nothing of the region of interest to fly over: lower nfz_clearance_m"
        ),
    )])
}

#[cfg(test)]
mod tests {
    use super::super::{SurveyPlan, SurveyRequest, plan_survey};
    use crate::geo::{Limits, UtmProjection};
    use geo::{Distance, Euclidean};
    use geo_types::{Coord, Line, Point, Polygon, polygon};
    use serde_json::{Value, json};

    fn try_plan(doc: Value) -> Result<SurveyPlan, super::PlanError> {
        plan_survey(
            &SurveyRequest::from_document(&doc).unwrap(),
            &Limits::default(),
        )
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
        json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
    }

    /// Least distance from the flown polyline (home, waypoints, home),
    /// outside a disc of `clearance` round home, to `zone` (lon/lat).
    fn least_distance(plan: &SurveyPlan, zone: &[[f64; 2]], clearance: f64) -> f64 {
        let proj = UtmProjection::new((plan.utm_epsg % 100) as u8, true).unwrap();
        let utm = |x: f64, y: f64| proj.to_utm(Coord { x, y }).unwrap();
        let zone = Polygon::new(
            zone.iter()
                .map(|p| utm(p[0], p[1]))
                .collect::<Vec<_>>()
                .into(),
            vec![],
        );
        let mut least = f64::INFINITY;
        for uav in &plan.uavs {
            let home = utm(uav.start[0], uav.start[1]);
            for sortie in &uav.sorties {
                let mut pts = vec![home];
                pts.extend(sortie.mission.waypoints().map(|w| utm(w.lon, w.lat)));
                pts.push(home);
                for w in pts.windows(2) {
                    let len = (w[1] - w[0]).x.hypot((w[1] - w[0]).y);
                    let n = (len / 0.5).ceil().max(1.0) as usize;
                    for k in 0..=n {
                        let p = w[0] + (w[1] - w[0]) * (k as f64 / n as f64);
                        if (p - home).x.hypot((p - home).y) > clearance {
                            least = least.min(Euclidean.distance(&Point(p), &zone));
                        }
                    }
                }
            }
        }
        least
    }

    const ROI: [[f64; 2]; 4] = [[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]];

    fn roi() -> Value {
        json!({"type": "Polygon", "coordinates": [ROI]})
    }

    #[test]
    fn everything_flown_keeps_the_clearance_and_left_out_coverage_is_said() {
        let nfz = [
            [5.001, 52.001],
            [5.002, 52.001],
            [5.002, 52.002],
            [5.001, 52.002],
        ];
        for clearance in [None, Some(12.0)] {
            let mut doc = json!({
                "roi": roi(),
                "no_fly_zones": [{"type": "Polygon", "coordinates": [nfz]}],
                "uavs": [{"id": "a", "start": [4.999, 51.999]}, {"id": "b", "start": [5.0045, 52.0031]}],
            });
            if let Some(c) = clearance {
                doc["nfz_clearance_m"] = json!(c);
            }
            let plan = try_plan(doc).unwrap();
            let c = clearance.unwrap_or(5.0);
            assert_eq!(plan.stats.nfz_clearance_m, c);
            let least = least_distance(&plan, &nfz, c);
            assert!(least >= c - 1e-3, "clearance {c}: {least}");
            // The lanes run next to the NFZ, not far off it.
            assert!(least < c + 10.0, "clearance {c}: {least}");
            // Lane ends facing the NFZ stop at the clearance, so the flat-
            // ended swaths (SPEC §3.3) miss a strip there: on this small
            // field it is under 1 %, and below 99.5 % the plan says so.
            let ratio = plan.stats.coverage_ratio;
            assert!(ratio >= 0.98, "clearance {c}: {ratio}");
            let said = plan.warnings.iter().any(|w| w.contains("are left out"));
            assert_eq!(said, ratio < 0.995, "{ratio} {:?}", plan.warnings);
            assert!(plan.stats.flyable_area_m2 < plan.stats.free_area_m2);
        }
    }

    #[test]
    fn default_start_is_the_first_vertex_clear_of_the_nfzs() {
        // An NFZ over the ROI's first corner: vertex 1 is taken.
        let doc = json!({
            "roi": roi(),
            "no_fly_zones": [rect(4.9995, 51.9995, 5.0005, 52.0005)],
        });
        let plan = try_plan(doc).unwrap();
        assert_eq!(plan.uavs[0].start, ROI[1]);
        assert!(
            plan.warnings.iter().any(|w| w.contains("vertex 2")),
            "{:?}",
            plan.warnings
        );
        // Clear of the NFZ: nothing said.
        let plan = plan_clear();
        assert_eq!(plan.uavs[0].start, ROI[0]);
        assert!(!plan.warnings.iter().any(|w| w.contains("takes off")));
    }

    fn plan_clear() -> SurveyPlan {
        try_plan(json!({"roi": roi(), "no_fly_zones": [rect(5.001, 52.001, 5.002, 52.002)]}))
            .unwrap()
    }

    #[test]
    fn default_start_falls_back_to_the_nearest_clear_boundary_point() {
        // An NFZ at every corner (and one within 3 m of the first, closer
        // than the clearance): the start is on the south edge, clear of the
        // corner zone's keep-out area by a hair.
        let zones: Vec<Value> = ROI
            .iter()
            .map(|c| rect(c[0] - 0.0003, c[1] - 0.0003, c[0] + 0.0003, c[1] + 0.0003))
            .collect();
        let plan = try_plan(json!({"roi": roi(), "no_fly_zones": zones})).unwrap();
        let start = plan.uavs[0].start;
        assert!(
            (start[1] - 52.0).abs() < 1e-7 || (start[0] - 5.0).abs() < 1e-7,
            "{start:?}"
        );
        let proj = UtmProjection::new((plan.utm_epsg % 100) as u8, true).unwrap();
        let utm = |p: [f64; 2]| proj.to_utm(Coord { x: p[0], y: p[1] }).unwrap();
        let corner = utm(ROI[0]);
        let s = utm(start);
        let nfz = Polygon::new(
            [
                [-0.0003, -0.0003],
                [0.0003, -0.0003],
                [0.0003, 0.0003],
                [-0.0003, 0.0003],
            ]
            .iter()
            .map(|d| utm([ROI[0][0] + d[0], ROI[0][1] + d[1]]))
            .collect::<Vec<_>>()
            .into(),
            vec![],
        );
        let d = Euclidean.distance(&Point(s), &nfz);
        assert!((5.0..5.01).contains(&d), "{d}");
        // Nearest to the first vertex: along an edge, 0.0003° (≈ 21 or
        // 33 m) + 5 m from it.
        let along = (s - corner).x.hypot((s - corner).y);
        assert!(along < 40.0, "{along}");
        assert!(
            plan.warnings
                .iter()
                .any(|w| w.contains("on the ROI's boundary"))
        );

        // The whole boundary within the clearance: the fault names /uavs.
        let doc = json!({"roi": roi(), "no_fly_zones": [rect(4.9999, 51.9999, 5.0041, 52.0001), rect(4.9999, 52.0029, 5.0041, 52.0031), rect(4.9999, 51.9999, 5.0001, 52.0031), rect(5.0039, 51.9999, 5.0041, 52.0031)]});
        match try_plan(doc) {
            Err(super::PlanError::Invalid(issues)) => {
                assert_eq!(issues[0].pointer, "/uavs", "{issues:?}");
                assert!(issues[0].message.contains("clear"), "{issues:?}");
            }
            other => panic!("expected a 422, got {other:?}"),
        }
    }

    #[test]
    fn starts_inside_near_and_hemmed_in() {
        let nfz = rect(5.001, 52.001, 5.002, 52.002);
        let with_start = |start: [f64; 2]| {
            try_plan(json!({"roi": roi(), "no_fly_zones": [nfz.clone()],
                        "uavs": [{"id": "u7", "start": start}]}))
        };
        // Inside: the UAV and the depth are named.
        match with_start([5.0011, 52.0015]) {
            Err(super::PlanError::Invalid(issues)) => {
                assert_eq!(issues[0].pointer, "/uavs/0/start");
                let m = &issues[0].message;
                assert!(
                    m.contains("u7") && m.contains("inside a no-fly zone"),
                    "{m}"
                );
                assert!(m.contains(" m from its edge"), "{m}");
            }
            other => panic!("expected a 422, got {other:?}"),
        }
        // 2 m west of the NFZ: accepted, leaves straight west to the
        // clearance, and says so.
        let proj = UtmProjection::new(31, true).unwrap();
        let edge = proj
            .to_utm(Coord {
                x: 5.001,
                y: 52.0015,
            })
            .unwrap();
        let start = proj.to_wgs84(edge - Coord { x: 2.0, y: 0.0 }).unwrap();
        let plan = with_start([start.x, start.y]).unwrap();
        assert!(
            plan.warnings
                .iter()
                .any(|w| w.contains("u7 takes off 2.0 m from a no-fly zone")),
            "{:?}",
            plan.warnings
        );
        let first = plan.uavs[0].sorties[0].mission.waypoints().next().unwrap();
        let exit = proj
            .to_utm(Coord {
                x: first.lon,
                y: first.lat,
            })
            .unwrap();
        let home = proj.to_utm(start).unwrap();
        let leg = Line::new(home, exit);
        // 3 m out (the NFZ's edge is a meridian, not UTM north: the leg
        // is west within the grid convergence of about 1.6°).
        let len = leg.dx().hypot(leg.dy());
        assert!((len - 3.0).abs() < 0.05 && leg.dx() < -2.9, "{leg:?}");
        let ring: Vec<[f64; 2]> = [
            [5.001, 52.001],
            [5.002, 52.001],
            [5.002, 52.002],
            [5.001, 52.002],
        ]
        .to_vec();
        assert!(least_distance(&plan, &ring, 5.0) >= 5.0 - 1e-3);

        // Hemmed in: between two NFZs 4 m apart, in a long corridor.
        let west = edge;
        let a = proj.to_wgs84(west - Coord { x: 4.0, y: 60.0 }).unwrap();
        let b = proj.to_wgs84(west + Coord { x: 0.0, y: 60.0 }).unwrap();
        let c = proj.to_wgs84(west - Coord { x: 100.0, y: 60.0 }).unwrap();
        let bar = polygon![(x: c.x, y: c.y), (x: a.x, y: a.y), (x: a.x, y: b.y), (x: c.x, y: b.y)];
        let ring: Vec<Vec<f64>> = bar.exterior().0.iter().map(|p| vec![p.x, p.y]).collect();
        let start = proj.to_wgs84(west - Coord { x: 2.0, y: 0.0 }).unwrap();
        let r = try_plan(
            json!({"roi": roi(), "no_fly_zones": [nfz, {"type": "Polygon", "coordinates": [ring]}],
                            "uavs": [{"id": "u7", "start": [start.x, start.y]}]}),
        );
        match r {
            Err(super::PlanError::Invalid(issues)) => {
                let m = &issues[0].message;
                assert!(
                    m.contains("u7") && m.contains("2.0 m") && m.contains("hemmed in"),
                    "{m}"
                );
            }
            other => panic!("expected a 422, got {other:?}"),
        }
    }

    #[test]
    fn an_empty_nfz_collection_is_no_nfz() {
        for empty in [
            json!({"type": "FeatureCollection", "features": []}),
            json!({"type": "GeometryCollection", "geometries": []}),
        ] {
            let plan = try_plan(json!({"roi": roi(), "no_fly_zones": [empty]})).unwrap();
            assert_eq!(plan.fences.len(), 1, "only the inclusion fence");
            assert_eq!(plan.stats.flyable_area_m2, plan.stats.free_area_m2);
            assert_eq!(plan.uavs[0].start, ROI[0]);
        }
        let plan = try_plan(json!({"roi": roi(), "no_fly_zones": []})).unwrap();
        assert_eq!(plan.fences.len(), 1);
        // A collection that holds something else is still a fault.
        let doc = json!({"roi": roi(), "no_fly_zones": [{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [5.0, 52.0]}}]}]});
        assert!(SurveyRequest::from_document(&doc).is_err());
    }
}
