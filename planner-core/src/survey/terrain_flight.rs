//! The flight of one UAV over a DEM (SPEC §3.3–3.4): lanes and the links
//! between them `altitude_m` above the dilated terrain within
//! ±`agl_tolerance_m`, transits at least `transit_clearance_m` above it,
//! waypoints added wherever a straight segment would leave its band, and the
//! mission altitudes written in the requested frame.

use geo_types::Coord;
use serde::{Deserialize, Serialize};

use super::capture::Capture;
use crate::export::{AltitudeFrame, GeoPoint, Mission, MissionItem};
use crate::flock::Tour;
use crate::geo::{GeoError, UtmProjection};
use crate::terrain::{HeightRule, Point3, TerrainModel, length_3d};

/// Most points in a returned altitude profile (enough for a chart).
const PROFILE_POINTS: f64 = 1500.0;
/// Consecutive waypoints closer than this (3D, metres) are written once.
pub(super) const SAME_POINT_M: f64 = 0.01;

/// What a stretch of the flight is for.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LegKind {
    /// Start → cell, cell → cell, cell → home: `transit_clearance_m` above
    /// the dilated terrain.
    Transit,
    /// A survey lane (camera on): `altitude_m` above the dilated terrain.
    Lane,
    /// The turn from one lane to the next, flown like a lane.
    Link,
}

/// One stretch of the flight as flown: [lon, lat, altitude] per waypoint,
/// altitudes in metres in the DEM's vertical datum (AMSL for an
/// orthometric DEM), whatever the mission's frame.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlightLeg {
    pub kind: LegKind,
    pub points: Vec<[f64; 3]>,
}

/// One point of the altitude profile: distance flown (2D, from take-off),
/// flown altitude and terrain height there (`None` without DEM data).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfilePoint {
    pub distance_m: f64,
    pub altitude_m: f64,
    pub terrain_m: Option<f64>,
}

/// Terrain-following results of one UAV.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UavTerrain {
    /// DEM height under the start position (the `relative` frame's zero).
    pub home_amsl_m: f64,
    /// Highest altitude flown.
    pub max_altitude_m: f64,
    /// Lowest height above the (undilated) DEM along lanes and links,
    /// checked every half block of the safe surface; `None` where the DEM
    /// has no data.
    pub min_lane_agl_m: Option<f64>,
    /// Lowest height above the DEM along transits.
    pub min_transit_clearance_m: Option<f64>,
    /// Share of the lane length flown within ±`agl_tolerance_m` of
    /// `altitude_m` above the DEM (the rest is higher: over ridges narrower
    /// than the footprint, or where a rate limit holds the UAV up).
    pub lane_within_tolerance_fraction: f64,
    pub legs: Vec<FlightLeg>,
    /// Flown altitude and terrain along the route, evenly spaced, for a chart.
    pub profile: Vec<ProfilePoint>,
}

/// Heights and rates requested for a terrain-following flight.
#[derive(Clone, Copy, Debug)]
pub(super) struct FlightRules {
    pub agl_m: f64,
    pub tolerance_m: f64,
    pub transit_clearance_m: f64,
    /// Metres of climb / descent allowed per metre flown.
    pub max_climb_per_m: Option<f64>,
    pub max_descent_per_m: Option<f64>,
}

impl FlightRules {
    fn lane(&self) -> HeightRule {
        HeightRule {
            offset_m: self.agl_m,
            band_m: self.tolerance_m,
            max_climb_per_m: self.max_climb_per_m,
            max_descent_per_m: self.max_descent_per_m,
        }
    }

    /// Transits aim `tolerance` above their clearance, so the band's lower
    /// edge is the clearance itself.
    fn transit(&self) -> HeightRule {
        HeightRule {
            offset_m: self.transit_clearance_m + self.tolerance_m,
            band_m: self.tolerance_m,
            max_climb_per_m: self.max_climb_per_m,
            max_descent_per_m: self.max_descent_per_m,
        }
    }
}

/// The flown 3D length of a cell's lanes and links (for choosing its lane
/// direction: fewest turns, then shortest 3D length).
pub(super) fn cell_length_3d(
    model: &TerrainModel,
    plan: &crate::coverage::CellPlan,
    rules: &FlightRules,
) -> f64 {
    length_3d(&model.follow(&plan.path(), &rules.lane()))
}

/// The 3D length of a transit as [`fly_tour`] flies it: along `path` at
/// transit height, plus the climb from and descent to each end (a home on
/// the ground, or a job end at lane height).
pub(super) fn transit_length_3d(
    model: &TerrainModel,
    rules: &FlightRules,
    path: &[Coord<f64>],
    homes: [bool; 2],
) -> f64 {
    let pts = model.follow(path, &rules.transit());
    let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
        return 0.0;
    };
    let end_height = |p: Coord<f64>, home: bool| -> Option<f64> {
        if home {
            model.terrain(p)
        } else {
            model.safe_terrain(p).map(|s| s + rules.agl_m)
        }
    };
    let climb = |p: &Point3, home: bool| end_height(p.xy(), home).map_or(0.0, |h| (p.z - h).abs());
    length_3d(&pts) + climb(first, homes[0]) + climb(last, homes[1])
}

/// Fraction of the lanes' length with DEM heights under it, in [0, 1].
pub(super) fn lanes_known_fraction(model: &TerrainModel, lanes: &[crate::coverage::Lane]) -> f64 {
    let mut known = 0usize;
    let mut total = 0usize;
    for lane in lanes {
        for (_, p) in model.densify(&[lane.start, lane.end]) {
            total += 1;
            if model.terrain(p).is_some() {
                known += 1;
            }
        }
    }
    if total == 0 {
        1.0
    } else {
        known as f64 / total as f64
    }
}

pub(super) struct TerrainFlight {
    pub mission: Mission,
    pub length_3d_m: f64,
    pub terrain: UavTerrain,
    /// The flight's 3D legs in planning coordinates (for its photos).
    pub legs: Vec<(LegKind, Vec<Point3>)>,
}

/// Flies `tour` over `model` under `rules`: the legs in 3D, the mission in
/// `frame`, and the figures of [`UavTerrain`].
#[allow(clippy::too_many_arguments)]
pub(super) fn fly_tour(
    tour: &Tour,
    model: &TerrainModel,
    rules: &FlightRules,
    home_lonlat: [f64; 2],
    home_amsl_m: f64,
    frame: AltitudeFrame,
    speed_m_s: f64,
    capture: &Capture,
    proj: &UtmProjection,
) -> Result<TerrainFlight, GeoError> {
    let legs: Vec<(LegKind, Vec<Point3>)> = legs_3d(tour, model, rules)
        .into_iter()
        .map(|(kind, pts)| match kind {
            LegKind::Lane => (kind, capture.lane_points(&pts)),
            _ => (kind, pts),
        })
        .collect();
    let alt_in_frame = |p: &Point3| -> f64 {
        match frame {
            AltitudeFrame::Amsl => p.z,
            AltitudeFrame::Relative => p.z - home_amsl_m,
            // Height above the DEM at the waypoint: the autopilot holds it
            // over its own terrain data between waypoints.
            AltitudeFrame::Terrain => {
                p.z - model
                    .terrain(p.xy())
                    .or_else(|| model.safe_terrain(p.xy()))
                    .unwrap_or(home_amsl_m)
            }
        }
    };
    let to_geo = |p: &Point3| -> Result<GeoPoint, GeoError> {
        let ll = proj.to_wgs84(p.xy())?;
        Ok(GeoPoint {
            lon: ll.x,
            lat: ll.y,
            alt: alt_in_frame(p),
        })
    };

    let all: Vec<Point3> = legs
        .iter()
        .flat_map(|(_, pts)| pts.iter().copied())
        .collect();
    let (Some(first), Some(last)) = (all.first().copied(), all.last().copied()) else {
        return Err(GeoError::Projection("the tour has no waypoints".into()));
    };
    let mut items = vec![
        MissionItem::Takeoff {
            alt: alt_in_frame(&first),
        },
        MissionItem::ChangeSpeed { speed_m_s },
    ];
    items.extend(capture.start_items());
    // The take-off climbs to the first point (above home): not written again.
    let mut previous = first;
    for (kind, pts) in &legs {
        if *kind == LegKind::Lane && !pts.is_empty() {
            let mut skip_first = dist3(&pts[0], &previous) < SAME_POINT_M;
            // A hover lane holds and shoots at its start: the waypoint
            // already written there becomes the held one.
            if skip_first
                && capture.holds_at_start()
                && matches!(items.last(), Some(MissionItem::Waypoint(_)))
            {
                items.pop();
                skip_first = false;
            }
            let (lane, last) = capture.lane_items(pts, skip_first, &to_geo)?;
            items.extend(lane);
            previous = last.unwrap_or(previous);
            continue;
        }
        for p in pts {
            if dist3(p, &previous) >= SAME_POINT_M {
                items.push(MissionItem::Waypoint(to_geo(p)?));
                previous = *p;
            }
        }
    }
    items.push(MissionItem::ReturnToLaunch);

    let length_3d_m =
        (first.z - home_amsl_m).abs() + length_3d(&all) + (last.z - home_amsl_m).abs();
    let (figures, profile) = measure(model, &legs, rules);
    let terrain = UavTerrain {
        home_amsl_m,
        max_altitude_m: all.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max),
        min_lane_agl_m: figures.min_lane_agl,
        min_transit_clearance_m: figures.min_transit_clearance,
        lane_within_tolerance_fraction: figures.lane_within_fraction,
        legs: legs
            .iter()
            .map(|(kind, pts)| {
                Ok(FlightLeg {
                    kind: *kind,
                    points: pts
                        .iter()
                        .map(|p| {
                            let ll = proj.to_wgs84(p.xy())?;
                            Ok([ll.x, ll.y, p.z])
                        })
                        .collect::<Result<_, GeoError>>()?,
                })
            })
            .collect::<Result<_, GeoError>>()?,
        profile,
    };
    Ok(TerrainFlight {
        mission: Mission {
            home: GeoPoint {
                lon: home_lonlat[0],
                lat: home_lonlat[1],
                alt: home_amsl_m,
            },
            frame,
            cruise_speed_m_s: speed_m_s,
            items,
            over_terrain: true,
        },
        length_3d_m,
        terrain,
        legs,
    })
}

/// Role of a vertex of a cell's flown path.
#[derive(Clone, Copy, PartialEq)]
enum Vertex {
    LaneStart,
    LaneEnd,
    /// The end of a lane and the start of the next, which goes on from
    /// there (a corridor's lane round a bend): no link between.
    LaneJoint,
    LinkPoint,
}

/// The tour as 3D legs in flight order.
fn legs_3d(tour: &Tour, model: &TerrainModel, rules: &FlightRules) -> Vec<(LegKind, Vec<Point3>)> {
    let transit_rule = rules.transit();
    let lane_rule = rules.lane();
    let mut legs = Vec::new();
    for (i, transit) in tour.transits.iter().enumerate() {
        legs.push((LegKind::Transit, model.follow(transit, &transit_rule)));
        let Some(visit) = tour.visits.get(i) else {
            continue;
        };
        // The cell's lanes and links as one path, so rate limits carry over
        // from one lane to the next.
        let mut path = Vec::new();
        let mut roles = Vec::new();
        for (k, lane) in visit.lanes.iter().enumerate() {
            let goes_on =
                k > 0 && visit.lanes[k - 1].end == lane.start && visit.links[k - 1].is_empty();
            match roles.last_mut() {
                Some(last) if goes_on => *last = Vertex::LaneJoint,
                _ => {
                    path.push(lane.start);
                    roles.push(Vertex::LaneStart);
                }
            }
            path.push(lane.end);
            roles.push(Vertex::LaneEnd);
            if let Some(link) = visit.links.get(k) {
                path.extend_from_slice(link);
                roles.extend(std::iter::repeat_n(Vertex::LinkPoint, link.len()));
            }
        }
        let (pts, marks) = model.follow_marked(&path, &lane_rule);
        let mut from = None::<usize>;
        for (v, role) in roles.iter().enumerate() {
            let at = marks[v];
            match role {
                Vertex::LaneStart => {
                    if let Some(f) = from {
                        legs.push((LegKind::Link, pts[f..=at].to_vec()));
                    }
                    from = Some(at);
                }
                Vertex::LaneEnd | Vertex::LaneJoint => {
                    let f = from.unwrap_or(at);
                    legs.push((LegKind::Lane, pts[f..=at].to_vec()));
                    from = Some(at);
                }
                Vertex::LinkPoint => {}
            }
        }
    }
    legs
}

struct Figures {
    min_lane_agl: Option<f64>,
    min_transit_clearance: Option<f64>,
    lane_within_fraction: f64,
}

/// Heights above the DEM along every leg, checked at the model's step, and the
/// altitude profile.
fn measure(
    model: &TerrainModel,
    legs: &[(LegKind, Vec<Point3>)],
    rules: &FlightRules,
) -> (Figures, Vec<ProfilePoint>) {
    let mut min_lane: Option<f64> = None;
    let mut min_transit: Option<f64> = None;
    let mut lane_len = 0.0;
    let mut lane_within = 0.0;
    // The profile is thinned while it is sampled: evenly spaced points for
    // a chart, the first and the last kept.
    let total: f64 = legs
        .iter()
        .flat_map(|(_, pts)| pts.windows(2))
        .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
        .sum();
    let spacing = total.max(1e-9) / PROFILE_POINTS;
    let mut profile: Vec<ProfilePoint> = Vec::new();
    let mut last_point = None;
    let mut offset = 0.0;
    for (kind, pts) in legs {
        let xy: Vec<Coord<f64>> = pts.iter().map(Point3::xy).collect();
        let dense = model.densify(&xy);
        // Distance of each waypoint along the leg, to interpolate altitudes.
        let mut wp_s = Vec::with_capacity(pts.len());
        let mut s = 0.0;
        for (i, p) in xy.iter().enumerate() {
            if i > 0 {
                s += (p.x - xy[i - 1].x).hypot(p.y - xy[i - 1].y);
            }
            wp_s.push(s);
        }
        let mut seg = 0;
        let mut prev_s = 0.0;
        for &(s, p) in &dense {
            while seg + 2 < wp_s.len() && wp_s[seg + 1] < s {
                seg += 1;
            }
            let z = if pts.len() == 1 {
                pts[0].z
            } else {
                let (s0, s1) = (wp_s[seg], wp_s[seg + 1]);
                let t = if s1 > s0 {
                    ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                pts[seg].z + (pts[seg + 1].z - pts[seg].z) * t
            };
            let terrain = model.terrain(p);
            if let Some(t) = terrain {
                let h = z - t;
                match kind {
                    LegKind::Transit => min_transit = Some(min_transit.map_or(h, |m| m.min(h))),
                    LegKind::Lane | LegKind::Link => {
                        min_lane = Some(min_lane.map_or(h, |m| m.min(h)));
                    }
                }
                if *kind == LegKind::Lane {
                    let ds = s - prev_s;
                    lane_len += ds;
                    if (h - rules.agl_m).abs() <= rules.tolerance_m {
                        lane_within += ds;
                    }
                }
            }
            prev_s = s;
            let point = ProfilePoint {
                distance_m: offset + s,
                altitude_m: z,
                terrain_m: terrain,
            };
            if profile
                .last()
                .is_none_or(|p: &ProfilePoint| point.distance_m - p.distance_m >= spacing)
            {
                profile.push(point);
                last_point = None;
            } else {
                last_point = Some(point);
            }
        }
        offset += wp_s.last().copied().unwrap_or(0.0);
    }
    profile.extend(last_point);
    (
        Figures {
            min_lane_agl: min_lane,
            min_transit_clearance: min_transit,
            lane_within_fraction: if lane_len > 0.0 {
                lane_within / lane_len
            } else {
                1.0
            },
        },
        profile,
    )
}

pub(super) fn dist3(a: &Point3, b: &Point3) -> f64 {
    ((b.x - a.x).powi(2) + (b.y - a.y).powi(2) + (b.z - a.z).powi(2)).sqrt()
}
