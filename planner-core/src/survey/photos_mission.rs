//! The photos of a plane's sortie, read off its mission: a plane lays its
//! own lanes (entered straight, pulled back from the no-fly zones), so each
//! lane is the stretch from the waypoint where the camera starts triggering
//! by distance to the one where it stops.

use geo::{Distance, Euclidean};
use geo_types::{Coord, Line, Point};

use super::photos::{Clock, PhotoPlanner, SortiePhotos};
use crate::coverage::Lane;
use crate::export::{AltitudeFrame, GeoPoint, Mission, MissionItem};
use crate::flock::Tour;
use crate::geo::{GeoError, UtmProjection};
use crate::terrain::Point3;

/// A mission lane lies on a tour lane when its middle is this close to it, m.
const ON_LANE_M: f64 = 1.0;

impl PhotoPlanner<'_> {
    /// The photos of `mission` (a plane's sortie flying `tour`), timed
    /// along its waypoints from home; each lane's cell is that of the
    /// tour's lane it lies on.
    pub(super) fn of_mission(
        &self,
        mission: &Mission,
        tour: &Tour,
        proj: &UtmProjection,
    ) -> Result<SortiePhotos, GeoError> {
        let lanes: Vec<(usize, Lane)> = tour
            .visits
            .iter()
            .flat_map(|v| v.lanes.iter().map(move |l| (v.cell_index, *l)))
            .collect();
        let at = |p: &GeoPoint| -> Result<Point3, GeoError> {
            let xy = proj.to_utm(Coord { x: p.lon, y: p.lat })?;
            Ok(Point3 {
                x: xy.x,
                y: xy.y,
                z: self.height(mission, p, xy),
            })
        };
        let home = at(&GeoPoint {
            alt: 0.0,
            ..mission.home
        })?;
        let mut clock = Clock::new(0.0);
        clock.fly(
            self,
            std::iter::once(Point3 {
                z: mission.home.alt,
                ..home
            }),
        );
        let mut out = SortiePhotos {
            camera: self.camera,
            lanes: Vec::new(),
        };
        let mut last: Option<Point3> = None;
        let mut lane: Option<Vec<Point3>> = None;
        let mut next = 0;
        for item in &mission.items {
            match item {
                MissionItem::Waypoint(p) | MissionItem::Land(p) | MissionItem::VtolLand(p) => {
                    let q = at(p)?;
                    match lane.as_mut() {
                        Some(pts) => pts.push(q),
                        None => clock.fly(self, std::iter::once(q)),
                    }
                    last = Some(q);
                }
                MissionItem::CameraTriggerDistance { distance_m } if *distance_m > 0.0 => {
                    lane = Some(last.into_iter().collect());
                }
                MissionItem::CameraTriggerDistance { .. } => {
                    let Some(pts) = lane.take().filter(|p| p.len() >= 2) else {
                        continue;
                    };
                    let cell = cell_of(&lanes, &mut next, &pts);
                    self.lane(&mut out, &mut clock, cell, &pts);
                }
                _ => {}
            }
        }
        Ok(out)
    }

    /// The height of mission position `p` (at `xy`): in the DEM's datum
    /// over a DEM, above the take-off point without one.
    fn height(&self, mission: &Mission, p: &GeoPoint, xy: Coord<f64>) -> f64 {
        match mission.frame {
            AltitudeFrame::Amsl => p.alt,
            AltitudeFrame::Relative => p.alt + mission.home.alt,
            AltitudeFrame::Terrain => {
                let ground = self.model.and_then(|(m, _)| m.terrain(xy));
                p.alt + ground.unwrap_or(mission.home.alt)
            }
        }
    }
}

/// The cell of the tour lane `pts` lies on: looked for from `next` on (the
/// lanes are flown in order), else among all; the last found where none.
fn cell_of(lanes: &[(usize, Lane)], next: &mut usize, pts: &[Point3]) -> usize {
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    let mid = Coord {
        x: (a.x + b.x) / 2.0,
        y: (a.y + b.y) / 2.0,
    };
    let on = |l: &Lane| Euclidean.distance(&Point(mid), &Line::new(l.start, l.end)) <= ON_LANE_M;
    let found = (*next..lanes.len())
        .chain(0..*next)
        .find(|&k| on(&lanes[k].1));
    match found {
        Some(k) => {
            *next = k + 1;
            lanes[k].0
        }
        None => lanes
            .get(next.saturating_sub(1))
            .map_or(usize::MAX, |l| l.0),
    }
}
