//! Rally points: where a UAV may return to instead of home (ArduPilot's
//! rally points, PX4's safe points). Given as `rally_points: [[lon, lat]]`,
//! checked against the no-fly zones, added to the inclusion fence and
//! exported in each `.plan` and as a rally file per UAV.

use geo::{Distance, Euclidean, Intersects};
use geo_types::{Coord, Point, Polygon};

use super::files::PlanFile;
use super::request::{DEM_POINTER, PlanError};
use super::result::{RallyPoint, SurveyPlan, UavPlan};
use crate::export::{GeoPoint, waypoints::write_rally};
use crate::geo::{Issue, SurveyArea};
use crate::terrain::{Dem, TerrainSampler};

/// Farthest a rally point may lie from the survey area: it is where a UAV
/// lands or loiters instead of home, so one farther off is a mistake
/// (longitude and latitude swapped, say), not a plan.
pub const MAX_RALLY_DISTANCE_M: f64 = 50_000.0;

/// Suffix of each UAV's rally file, after `<uav id>.`.
pub(super) const RALLY_FILE_SUFFIX: &str = "rally.waypoints";

/// Checks the requested rally points (`/rally_points/i`) and returns them
/// with their UTM positions (for the inclusion fence). Refused, each naming
/// the point and the distance: a point inside a no-fly zone or closer to
/// one than `clearance_m` (the vehicle loiters and lands there, and the
/// zone is an exclusion fence), and a point farther than
/// [`MAX_RALLY_DISTANCE_M`] from the survey area. Over a DEM each point
/// keeps the DEM height under it, for its altitude.
pub(super) fn check_rally_points(
    points: &[[f64; 2]],
    area: &SurveyArea,
    clearance_m: f64,
    dem: Option<&Dem>,
) -> Result<(Vec<RallyPoint>, Vec<Coord<f64>>), PlanError> {
    let sampler = match dem {
        Some(d) if !points.is_empty() => Some(
            TerrainSampler::wgs84(d)
                .map_err(|e| PlanError::Invalid(vec![Issue::new(DEM_POINTER, &e.to_string())]))?,
        ),
        _ => None,
    };
    let mut issues = Vec::new();
    let mut out = Vec::with_capacity(points.len());
    let mut utm = Vec::with_capacity(points.len());
    for (i, &[lon, lat]) in points.iter().enumerate() {
        let pointer = format!("/rally_points/{i}");
        // A point PROJ cannot put in the survey's UTM zone is far away.
        let (p, from_area) = match area.projection.to_utm(Coord { x: lon, y: lat }) {
            Ok(p) => (p, Euclidean.distance(&Point(p), &area.roi)),
            Err(_) => (Coord { x: 0.0, y: 0.0 }, f64::INFINITY),
        };
        if from_area > MAX_RALLY_DISTANCE_M {
            issues.push(Issue::new(
                &pointer,
                &format!(
                    "rally point {} ({lon}, {lat}) is {} from the survey area, more than {} km: is \
                     it [longitude, latitude]?",
                    i + 1,
                    if from_area.is_finite() {
                        format!("{:.1} km", from_area / 1000.0)
                    } else {
                        "too far".to_string()
                    },
                    MAX_RALLY_DISTANCE_M / 1000.0
                ),
            ));
            continue;
        }
        if let Some(msg) = nfz_fault(p, &area.no_fly, clearance_m) {
            issues.push(Issue::new(
                &pointer,
                &format!("rally point {} ({lon}, {lat}) {msg}", i + 1),
            ));
            continue;
        }
        out.push(RallyPoint {
            lon,
            lat,
            ground_amsl_m: sampler
                .as_ref()
                .and_then(|s| s.height(Coord { x: lon, y: lat })),
        });
        utm.push(p);
    }
    if issues.is_empty() {
        Ok((out, utm))
    } else {
        Err(PlanError::Invalid(issues))
    }
}

/// What is wrong with a rally point at `p` (UTM) next to the no-fly zones.
fn nfz_fault(p: Coord<f64>, no_fly: &[Polygon<f64>], clearance_m: f64) -> Option<String> {
    let point = Point(p);
    if let Some(zone) = no_fly.iter().find(|z| z.intersects(&point)) {
        let depth = Euclidean.distance(&point, zone.exterior());
        return Some(format!(
            "is inside a no-fly zone, {depth:.1} m from its edge"
        ));
    }
    let d = no_fly
        .iter()
        .map(|z| Euclidean.distance(&point, z))
        .fold(f64::INFINITY, f64::min);
    (d < clearance_m).then(|| {
        format!(
            "is {d:.1} m from a no-fly zone, closer than nfz_clearance_m ({clearance_m} m): a \
             UAV loitering or landing there would breach the zone's fence"
        )
    })
}

impl SurveyPlan {
    /// The survey's rally points for `uav`, altitudes above its home (the
    /// frame of MAVLink rally points, MAV_FRAME_GLOBAL_RELATIVE_ALT): the
    /// highest altitude its sorties fly, and over a DEM at least
    /// `altitude_m` above the ground at the point. So a UAV sent to a rally
    /// point never has to descend on the way.
    pub fn rally_for(&self, uav: &UavPlan) -> Vec<GeoPoint> {
        let highest = self.return_height_m(uav);
        let home_amsl = uav
            .sorties
            .iter()
            .rev()
            .find_map(|s| s.terrain.as_ref().map(|t| t.home_amsl_m));
        self.rally_points
            .iter()
            .map(|r| {
                let over_ground = match (r.ground_amsl_m, home_amsl) {
                    (Some(g), Some(h)) => g + self.stats.altitude_m - h,
                    _ => f64::NEG_INFINITY,
                };
                GeoPoint {
                    lon: r.lon,
                    lat: r.lat,
                    alt: highest.max(over_ground),
                }
            })
            .collect()
    }

    /// The highest altitude `uav`'s sorties fly above its home, m (at
    /// least the survey's `altitude_m`): where it flies to a rally point,
    /// and the return-home height of its DJI missions.
    pub fn return_height_m(&self, uav: &UavPlan) -> f64 {
        uav.sorties
            .iter()
            .filter_map(|s| s.terrain.as_ref())
            .fold(self.stats.altitude_m, |h, t| {
                h.max(t.max_altitude_m - t.home_amsl_m)
            })
    }

    /// Names of the rally files: `<uav id>.rally.waypoints` per UAV, when
    /// the survey has rally points.
    pub(super) fn rally_file_names(&self) -> Vec<String> {
        if self.rally_points.is_empty() {
            return Vec::new();
        }
        self.uavs
            .iter()
            .map(|u| format!("{}.{RALLY_FILE_SUFFIX}", u.id))
            .collect()
    }

    /// The rally file `name` (`<uav id or sortie stem>.rally.waypoints`),
    /// or `None` when it is not one or the survey has no rally points.
    pub(super) fn rally_file(&self, name: &str) -> Option<PlanFile> {
        if self.rally_points.is_empty() {
            return None;
        }
        let stem = name.strip_suffix(RALLY_FILE_SUFFIX)?.strip_suffix('.')?;
        let uav = self
            .uavs
            .iter()
            .find(|u| u.id == stem || u.sorties.iter().any(|s| s.file_stem == stem))?;
        Some(PlanFile {
            name: name.to_string(),
            content_type: "text/plain; charset=utf-8",
            content: write_rally(&self.rally_for(uav)).into_bytes(),
        })
    }
}

#[cfg(test)]
mod tests {
    use geo::Contains;
    use geo_types::{LineString, Polygon};
    use serde_json::{Value, json};

    use super::super::{MAX_RALLY_POINTS, SurveyRequest, plan_survey};
    use super::*;
    use crate::geo::Limits;

    /// A 280 m × 330 m field with a 70 m × 110 m no-fly zone, one UAV.
    fn plan(rally: Value) -> Result<SurveyPlan, PlanError> {
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "no_fly_zones": [{"type": "Polygon", "coordinates": [[[5.001, 52.001], [5.002, 52.001], [5.002, 52.002], [5.001, 52.002]]]}],
            "altitude_m": 70,
            "uavs": [{"id": "a", "start": [4.9995, 51.9995]}],
            "rally_points": rally,
        });
        plan_survey(&SurveyRequest::from_document(&doc)?, &Limits::default())
    }

    fn pointers(e: PlanError) -> Vec<(String, String)> {
        match e {
            PlanError::Invalid(issues) => {
                issues.into_iter().map(|i| (i.pointer, i.message)).collect()
            }
            e => panic!("not a request fault: {e}"),
        }
    }

    #[test]
    fn rally_points_are_in_the_fence_and_every_file() {
        // 0.0065° east is ≈ 170 m outside the field: the fence grows to it.
        let p = plan(json!([[5.0105, 52.0015], [4.9990, 52.0030]])).unwrap();
        assert_eq!(p.rally_points.len(), 2);
        assert_eq!(p.rally_points[0].ground_amsl_m, None);
        let inclusion = &p.fences[0];
        assert!(inclusion.inclusion);
        let ring: Vec<(f64, f64)> = inclusion.vertices.iter().map(|v| (v[0], v[1])).collect();
        let fence = Polygon::new(LineString::from(ring), vec![]);
        for r in &p.rally_points {
            assert!(
                fence.contains(&geo_types::Point::new(r.lon, r.lat)),
                "{r:?}"
            );
        }
        // Flat survey: the rally altitude is the flight altitude above home.
        let rally = p.rally_for(&p.uavs[0]);
        assert_eq!(rally.len(), 2);
        assert!(
            rally.iter().all(|g| (g.alt - 70.0).abs() < 1e-9),
            "{rally:?}"
        );
        assert!(p.file_names().contains(&"a.rally.waypoints".to_string()));
        let file = p.file("a.rally.waypoints").unwrap();
        assert_eq!(file.text().lines().count(), 3);
        assert!(
            file.text()
                .lines()
                .nth(1)
                .unwrap()
                .starts_with("0\t0\t3\t5100\t")
        );
        let plan_doc: Value = serde_json::from_slice(&p.file("a.plan").unwrap().content).unwrap();
        assert_eq!(
            plan_doc["rallyPoints"]["points"][0],
            json!([52.0015, 5.0105, 70.0])
        );
        // Stored plans without rally points still read, and have no rally file.
        let mut stored = serde_json::to_value(&p).unwrap();
        stored.as_object_mut().unwrap().remove("rally_points");
        let old: SurveyPlan = serde_json::from_value(stored).unwrap();
        assert!(old.rally_points.is_empty());
        assert!(old.file("a.rally.waypoints").is_none());
        assert!(!old.file_names().iter().any(|n| n.contains("rally")));
    }

    #[test]
    fn rally_points_in_or_near_a_no_fly_zone_or_far_away_are_refused() {
        // Inside the NFZ, 1 m from it (clearance 5 m by default or more),
        // and ~790 km away (lon and lat swapped).
        let e = pointers(
            plan(json!([
                [5.0015, 52.0015],
                [5.002_015, 52.0015],
                [52.0, 5.0]
            ]))
            .unwrap_err(),
        );
        assert_eq!(e.len(), 3, "{e:?}");
        assert_eq!(e[0].0, "/rally_points/0");
        assert!(e[0].1.contains("inside a no-fly zone"), "{}", e[0].1);
        assert_eq!(e[1].0, "/rally_points/1");
        assert!(e[1].1.contains("m from a no-fly zone"), "{}", e[1].1);
        assert_eq!(e[2].0, "/rally_points/2");
        assert!(e[2].1.contains("longitude, latitude"), "{}", e[2].1);
        // Out-of-range coordinates and too many points, by pointer.
        let e = pointers(plan(json!([[181.0, 52.0], [5.0, -91.0]])).unwrap_err());
        let ptrs: Vec<&str> = e.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(ptrs, ["/rally_points/0/0", "/rally_points/1/1"]);
        let many: Vec<[f64; 2]> = vec![[5.0, 52.0]; MAX_RALLY_POINTS + 1];
        let e = pointers(plan(json!(many)).unwrap_err());
        assert_eq!(e[0].0, "/rally_points");
        // Where PROJ cannot go from the survey's UTM zone: still a 422.
        let e = pointers(plan(json!([[-175.0, -89.9]])).unwrap_err());
        assert_eq!(e[0].0, "/rally_points/0", "{e:?}");
        let e = pointers(plan(json!([[5.0]])).unwrap_err());
        assert!(e[0].0.starts_with("/rally_points"), "{e:?}");
    }
}
