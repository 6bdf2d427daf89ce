//! A tour flown by a plane (fixed wing or VTOL): lanes entered straight
//! (lead-in, overshoot; a lane end facing a no-fly zone pulled back until
//! the plane can turn before it), Dubins turns between lanes and Dubins
//! transits smoothed along the NFZ-avoiding path, every piece checked
//! against the keep-out area, written as waypoints under the turn rule.

use geo_types::Coord;

use super::aircraft::{Aircraft, AircraftType};
use super::cells::dist;
use super::plane_clearance::ClearanceGrid;
use super::plane_heights::{heights, split_lanes};
use super::request::PlanError;
use super::result::UavStats;
use super::terrain_flight::FlightRules;
use crate::coverage::airframe::{PlaneTurns, lane_poses};
use crate::coverage::arcs::{self, ARC_SLACK, Mark, SLIGHT_SWEEP, Waypoint};
use std::f64::consts::PI;

use crate::coverage::dubins::{Piece, Pose, dubins_iter};
use crate::coverage::{Lane, photo_count};
use crate::export::{AltitudeFrame, GeoPoint, MissionItem};
use crate::flock::{ObstacleMap, Tour};
use crate::geo::{Issue, UtmProjection};
use crate::terrain::TerrainModel;

/// Arc samples for clearance checks, radians (the polygon corners are
/// never wider than 30°; the rounded path flown keeps within a few cm
/// of the arc, well inside [`PLAN_MARGIN_M`]).
const CHECK_STEP: f64 = 0.13;
/// Lane ends are pulled back in steps of this share of the turn radius.
const TRIM_STEP: f64 = 0.25;
/// The shortest lead-in or overshoot by a no-fly zone, in turn radii.
const MIN_RUN: f64 = 0.15;
/// A lane shorter than this after trimming is left out, m.
const MIN_LANE_M: f64 = 1.0;
/// How much wider than the keep-out area pieces are planned clear of, m.
const PLAN_MARGIN_M: f64 = 1.0;

/// How a plane flies: its turns and the keep-out area it stays out of.
pub(super) struct PlaneFlight<'a> {
    pub kind: AircraftType,
    /// Turn radius of the autopilot (the turn rule's).
    pub radius: f64,
    /// Planned arcs: a little wider (see [`ARC_SLACK`]).
    pub turns: PlaneTurns,
    pub climb_angle_deg: f64,
    /// The last straight before the landing: a plane descends on it from
    /// the survey altitude at its climb angle; a VTOL flies it level.
    pub final_m: f64,
    pub altitude: f64,
    pub obstacles: &'a ObstacleMap,
    /// The same obstacles with the transit search's corners a turn radius
    /// out, so that the arcs round them keep clear.
    pub routes: ObstacleMap,
    /// The keep-out area [`PLAN_MARGIN_M`] wider: every piece is planned
    /// clear of it, so that the waypoints written (which may leave out a
    /// Dubins word's micro-jog) still keep the clearance.
    planning: ObstacleMap,
    /// How far each spot keeps from the wider area, for quick checks.
    grid: Option<ClearanceGrid>,
}

/// One sortie as a plane flies it.
pub(super) struct PlaneSortie {
    pub items: Vec<MissionItem>,
    pub stats: UavStats,
    /// Every point of the rounded path (for the fence).
    pub points: Vec<Coord<f64>>,
    /// The lanes flown with the camera on, as pulled back (for the
    /// coverage figure).
    pub lanes: Vec<Lane>,
}

impl<'a> PlaneFlight<'a> {
    pub(super) fn new(
        aircraft: &Aircraft,
        altitude: f64,
        obstacles: &'a ObstacleMap,
    ) -> PlaneFlight<'a> {
        let radius = aircraft.turn_radius();
        let lead = aircraft.lead_in();
        let climb_angle_deg = aircraft.max_climb_angle_deg();
        let final_m = match aircraft.kind {
            AircraftType::Vtol => radius * ARC_SLACK,
            _ => (altitude / climb_angle_deg.to_radians().tan()).max(radius * ARC_SLACK),
        };
        let wider = crate::geo::keep_out_area(&obstacles.polygons(), PLAN_MARGIN_M);
        PlaneFlight {
            kind: aircraft.kind,
            radius,
            turns: PlaneTurns {
                radius_m: radius * ARC_SLACK,
                lead_in_m: lead,
                overshoot_m: lead,
            },
            climb_angle_deg,
            final_m,
            altitude,
            obstacles,
            routes: obstacles.pushed(radius * ARC_SLACK),
            planning: ObstacleMap::new(&wider, 0.0),
            grid: ClearanceGrid::new(&wider),
        }
    }

    pub(super) fn fault(&self, at: Coord<f64>, what: &str) -> PlanError {
        PlanError::Invalid(vec![Issue::new(
            "/aircraft/turn_radius_m",
            &format!(
                "{what} near ({:.0}, {:.0}) (UTM) cannot keep nfz_clearance_m from the no-fly zones \
                 at a turn radius of {} m: lower turn_radius_m or lead_in_m, or move the start",
                at.x, at.y, self.radius
            ),
        )])
    }

    /// Is the segment `a`–`b` clear of the wider keep-out area pieces are
    /// planned in? The raster answers far from it, the obstacle map near it.
    pub(super) fn segment_clear(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        self.surely_clear(a, b) || self.planning.is_clear(a, b)
    }

    /// Is the segment `a`–`b` far from the (wider) keep-out area by the
    /// raster alone?
    fn surely_clear(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        self.grid.as_ref().is_some_and(|g| g.sure_clear(a, b))
    }

    /// Is the point `p` inside the wider keep-out area?
    pub(super) fn blocked_at(&self, p: Coord<f64>) -> bool {
        self.planning.contains_point(p)
    }

    /// Is every point of `piece` outside the keep-out area? Arcs are
    /// checked along their chords and along the polygon round them (the
    /// rounded path flown runs between the two).
    pub(super) fn clear(&self, piece: &Piece) -> bool {
        match *piece {
            Piece::Line { from, to } => self.segment_clear(from, to),
            Piece::Arc {
                centre,
                radius,
                start,
                sweep,
            } => {
                let n = ((sweep.abs() / CHECK_STEP).ceil() as usize).max(1);
                let step = sweep / n as f64;
                let at = |a: f64, r: f64| {
                    centre
                        + Coord {
                            x: r * a.cos(),
                            y: r * a.sin(),
                        }
                };
                let outer = radius / (step.abs() / 2.0).cos();
                // The arc and the polygon round it lie within `outer` of
                // the centre: clear at once where the raster keeps the
                // centre farther than that from the keep-out area.
                if let Some(g) = &self.grid {
                    if g.sure(centre) > outer {
                        return true;
                    }
                    // Both polylines lie between radius·cos(step/2) and
                    // `outer` from the centre: within `reach` of the arc
                    // radially, and within half a sample's spacing of a
                    // sample along it. Clear where every sample keeps
                    // that far (one pass instead of two).
                    let reach = outer - radius * (step.abs() / 2.0).cos();
                    let m = ((sweep.abs() * outer / g.cell()).ceil() as usize).max(1);
                    let d = sweep / m as f64;
                    let need = reach + outer * d.abs() / 2.0;
                    if (0..=m).all(|j| g.sure(at(start + d * j as f64, radius)) > need) {
                        return true;
                    }
                }
                let mut inner = vec![piece.start()];
                let mut around = vec![piece.start()];
                for k in 0..n {
                    inner.push(at(start + step * (k + 1) as f64, radius));
                    around.push(at(start + step * (k as f64 + 0.5), outer));
                }
                around.push(piece.end());
                [inner, around]
                    .iter()
                    .all(|p| p.windows(2).all(|w| self.segment_clear(w[0], w[1])))
            }
        }
    }

    pub(super) fn all_clear(&self, pieces: &[Piece]) -> bool {
        pieces.iter().all(|p| self.clear(p))
    }

    /// The first clear Dubins word from `a` to `b`, one without a
    /// micro-jog (an arc under [`SLIGHT_SWEEP`]) if there is one: a jog
    /// next to another arc leaves too short a leg for the turn rule.
    pub(super) fn dubins_clear(&self, a: Pose, b: Pose) -> Option<Vec<Piece>> {
        let mut jog = None;
        for word in dubins_iter(a, b, self.turns.radius_m) {
            let jogs = word
                .iter()
                .any(|p| matches!(p, Piece::Arc { sweep, .. } if sweep.abs() < SLIGHT_SWEEP));
            if jogs {
                if jog.is_none() && self.all_clear(&word) {
                    jog = Some(word);
                }
            } else if self.all_clear(&word) {
                return Some(word);
            }
        }
        jog
    }

    /// The lane pulled back at either end until the run beyond it is
    /// clear: the straight (the full lead-in or overshoot, else half, else
    /// [`MIN_RUN`]) and then a half turn to either side; the least pulled back,
    /// then the longest straight. `None` when nothing of it is left.
    pub(super) fn trim(&self, lane: &Lane) -> Option<Entered> {
        self.trim_ends(lane, true, true)
    }

    /// [`PlaneFlight::trim`] at the start and/or the end only (a bent
    /// lane's end at a bend it rounds is left where it is).
    pub(super) fn trim_ends(&self, lane: &Lane, at_start: bool, at_end: bool) -> Option<Entered> {
        let len = dist(lane.start, lane.end);
        let (start, end) = lane_poses(lane);
        let step = (self.radius * TRIM_STEP).max(1.0);
        // From `pose` (facing away from the lane) the straight run, then a
        // half turn to either side.
        let room = |pose: Pose, run: f64| {
            let beyond = pose.ahead(run);
            self.segment_clear(pose.at, beyond.at)
                && [1.0, -1.0]
                    .iter()
                    .any(|&side| self.clear(&self.half_turn(beyond, side)))
        };
        let pull = |pose: Pose, full: f64, sign: f64| -> Option<(f64, f64)> {
            let mut t = 0.0;
            while t <= len {
                let at = pose.ahead(sign * t);
                // Backwards from a start: the facing pose is turned round.
                let probe = if sign > 0.0 {
                    Pose::new(at.at, at.heading + std::f64::consts::PI)
                } else {
                    at
                };
                // The shortest run still leaves room for the first corner of
                // the turn's polygon (the turn rule).
                for run in [full, full / 2.0, (MIN_RUN * self.radius).min(full)] {
                    if room(probe, run) {
                        return Some((t, run));
                    }
                }
                t += step;
            }
            None
        };
        // A bend's end keeps its place (the run is the shortest straight,
        // should the bend not be rounded after all).
        let bend_run = (0.0, (MIN_RUN * self.radius).min(self.turns.lead_in_m));
        let (cut_end, over) = if at_end {
            pull(end, self.turns.overshoot_m, -1.0)?
        } else {
            bend_run
        };
        let (cut_start, lead) = if at_start {
            pull(start, self.turns.lead_in_m, 1.0)?
        } else {
            bend_run
        };
        (len - cut_end - cut_start >= MIN_LANE_M).then(|| Entered {
            lane: Lane {
                start: start.ahead(cut_start).at,
                end: end.ahead(-cut_end).at,
            },
            lead,
            over,
            bend: None,
        })
    }

    /// A half turn from `pose` to the left (`side` 1) or right (−1).
    fn half_turn(&self, pose: Pose, side: f64) -> Piece {
        self.arc_from(pose, side, PI)
    }

    /// An arc of `sweep` radians from `pose` to the left (`side` 1) or
    /// right (−1).
    pub(super) fn arc_from(&self, pose: Pose, side: f64, sweep: f64) -> Piece {
        let r = self.turns.radius_m;
        let normal = pose.heading + side * std::f64::consts::FRAC_PI_2;
        Piece::Arc {
            centre: pose.at
                + Coord {
                    x: r * normal.cos(),
                    y: r * normal.sin(),
                },
            radius: r,
            start: normal + PI,
            sweep: side * sweep,
        }
    }

    /// The way from the end of lane `a` to the start of lane `b`: the
    /// shortest clear turn, else a transit from the overshoot's end to the
    /// lead-in's start.
    pub(super) fn lane_turn(&self, a: &Entered, b: &Entered) -> Result<Vec<Piece>, PlanError> {
        let turns = PlaneTurns {
            overshoot_m: a.over,
            lead_in_m: b.lead,
            ..self.turns
        };
        if let Some(t) = turns
            .between(&a.lane, &b.lane)
            .into_iter()
            .find(|t| self.all_clear(t))
        {
            return Ok(t);
        }
        let (_, end) = lane_poses(&a.lane);
        let (start, _) = lane_poses(&b.lane);
        self.around(end, a.over, start, b.lead)
    }

    /// Overshoot, transit, lead-in from a lane's end pose to a lane's
    /// start pose.
    pub(super) fn around(
        &self,
        end: Pose,
        over: f64,
        start: Pose,
        lead_in: f64,
    ) -> Result<Vec<Piece>, PlanError> {
        let out = end.ahead(over);
        let lead = start.ahead(-lead_in);
        let mut pieces = vec![Piece::Line {
            from: end.at,
            to: out.at,
        }];
        pieces.extend(self.connect(out, lead)?);
        pieces.push(Piece::Line {
            from: lead.at,
            to: start.at,
        });
        pieces.retain(|p| p.length() > 1e-9);
        Ok(pieces)
    }

    /// The sortie flying `tour` from `home` at `altitude` (flat): mission
    /// items (take-off and landing of the type, the camera on along each
    /// lane only), statistics and the rounded path's points. `to_geo`
    /// writes a planning point as a mission position at an altitude.
    pub(super) fn fly(
        &self,
        tour: &Tour,
        home: Coord<f64>,
        speed_m_s: f64,
        trigger_distance_m: f64,
        over: Option<&Over>,
        to_geo: &dyn Fn(Coord<f64>, f64) -> Result<GeoPoint, PlanError>,
    ) -> Result<PlaneSortie, PlanError> {
        let f = self.pieces(tour, home)?;
        let wps = arcs::waypoints(&f.path, self.radius).map_err(|e| self.fault(e.at, "a turn"))?;
        let pts: Vec<Coord<f64>> = wps.iter().map(|w| w.at).collect();
        let rounded = arcs::rounded(&pts, self.radius);
        // The climb-out and the final touch home, which may lie within the
        // clearance (the final was checked on its own).
        let n = rounded.len();
        for (i, w) in rounded.windows(2).enumerate() {
            if i > 0
                && i + 2 < n
                && !(self.surely_clear(w[0], w[1]) || self.obstacles.is_clear(w[0], w[1]))
            {
                return Err(self.fault(w[0], "the rounded path"));
            }
        }
        let length_m = arcs::rounded_length(&pts, self.radius);
        let angle = self.climb_angle_deg.to_radians();
        let (wps, alts, length_3d_m) = match over {
            None => {
                let alt = self.altitude;
                let mut alts = vec![alt; wps.len()];
                alts[0] = 0.0;
                alts[wps.len() - 1] = 0.0;
                let vertical = match self.kind {
                    AircraftType::Vtol => 2.0 * alt,
                    // The climb at the take-off pitch, and the final's slope.
                    _ => alt / angle.sin() + (self.final_m.hypot(alt) - self.final_m),
                };
                (wps, alts, length_m + vertical)
            }
            Some(o) => self.over_terrain(&wps, o, length_m)?,
        };
        let items = self.items(&wps, &alts, speed_m_s, trigger_distance_m, to_geo)?;
        let turns = f
            .path
            .iter()
            .filter(
                |p| matches!(p.piece, Piece::Arc { sweep, .. } if sweep.abs() > 10f64.to_radians()),
            )
            .count();
        let mut cells: Vec<usize> = tour.visits.iter().map(|v| v.cell_index).collect();
        cells.sort_unstable();
        cells.dedup();
        let stats = UavStats {
            length_m,
            length_3d_m,
            survey_length_m: f.lanes.iter().map(|l| dist(l.start, l.end)).sum(),
            transit_length_m: f.transit_m,
            turns,
            flight_time_s: length_3d_m / speed_m_s,
            photos: f
                .lanes
                .iter()
                .map(|l| photo_count(dist(l.start, l.end), trigger_distance_m))
                .sum(),
            cells: cells.len(),
            sorties: 1,
        };
        let mut points = rounded;
        points.extend(pts);
        Ok(PlaneSortie {
            items,
            stats,
            points,
            lanes: f.lanes,
        })
    }

    /// The mission items: take-off, speed, the waypoints between home and
    /// home with the camera switched at lane ends, and the landing.
    fn items(
        &self,
        wps: &[Waypoint],
        alts: &[f64],
        speed_m_s: f64,
        trigger_distance_m: f64,
        to_geo: &dyn Fn(Coord<f64>, f64) -> Result<GeoPoint, PlanError>,
    ) -> Result<Vec<MissionItem>, PlanError> {
        let alt = alts[1.min(alts.len() - 1)];
        let mut items = vec![
            match self.kind {
                AircraftType::Vtol => MissionItem::VtolTakeoff { alt },
                _ => MissionItem::PlaneTakeoff {
                    alt,
                    pitch_deg: self.climb_angle_deg,
                },
            },
            MissionItem::ChangeSpeed { speed_m_s },
        ];
        let inner = 1..wps.len().saturating_sub(1);
        let last = inner.end.saturating_sub(1);
        for i in inner {
            let w = &wps[i];
            if i == last {
                // The landing sequence: the last waypoint is its approach.
                items.push(MissionItem::LandStart);
            }
            items.push(MissionItem::Waypoint(to_geo(w.at, alts[i])?));
            match w.mark {
                Mark::LaneStart => items.push(MissionItem::CameraTriggerDistance {
                    distance_m: trigger_distance_m,
                }),
                Mark::LaneEnd => items.push(MissionItem::CameraTriggerDistance { distance_m: 0.0 }),
                Mark::Point | Mark::Corner => {}
            }
        }
        let home = to_geo(wps[wps.len() - 1].at, alts[alts.len() - 1])?;
        items.push(match self.kind {
            AircraftType::Vtol => MissionItem::VtolLand(home),
            _ => MissionItem::Land(home),
        });
        Ok(items)
    }
}

/// The terrain a sortie is flown over and the mission's altitude frame.
pub(super) struct Over<'a> {
    model: &'a TerrainModel,
    rules: &'a FlightRules,
    home_amsl: f64,
    frame: AltitudeFrame,
}

impl PlaneFlight<'_> {
    /// The waypoints over the terrain (lanes split to follow it), their
    /// altitudes in the mission's frame and the 3D length flown (`length_m`
    /// the horizontal one).
    fn over_terrain(
        &self,
        wps: &[Waypoint],
        o: &Over,
        length_m: f64,
    ) -> Result<(Vec<Waypoint>, Vec<f64>, f64), PlanError> {
        let wps = split_lanes(wps);
        // A hair under the limit, against rounding in the mission files.
        let tan = self.climb_angle_deg.to_radians().tan() * (1.0 - 1e-6);
        let landing = self.kind != AircraftType::Vtol;
        let z = heights(&wps, o.model, o.rules, o.home_amsl, tan, landing).map_err(|slope| {
            PlanError::Invalid(vec![Issue::new(
                "/aircraft/max_climb_angle_deg",
                &format!(
                    "the terrain under the landing approach needs a descent of {:.1}°, steeper \
                     than max_climb_angle_deg: move the start or fly lower",
                    slope.atan().to_degrees()
                ),
            )])
        })?;
        let alts = wps
            .iter()
            .zip(&z)
            .map(|(w, &h)| match o.frame {
                AltitudeFrame::Amsl => h,
                AltitudeFrame::Relative => h - o.home_amsl,
                AltitudeFrame::Terrain => {
                    h - o
                        .model
                        .terrain(w.at)
                        .or_else(|| o.model.safe_terrain(w.at))
                        .unwrap_or(o.home_amsl)
                }
            })
            .collect();
        // 3D: the horizontal length with each leg's climb; the take-off's
        // climb (at its pitch) or a VTOL's vertical climb and descent.
        let n = wps.len();
        let extra: f64 = (0..n - 1)
            .map(|k| {
                let d = dist(wps[k].at, wps[k + 1].at);
                let dz = if k == 0 { 0.0 } else { z[k + 1] - z[k] };
                d.hypot(dz) - d
            })
            .sum();
        let climb = z[1.min(n - 1)] - o.home_amsl;
        let vertical = match self.kind {
            AircraftType::Vtol => climb + (z[n.saturating_sub(2)] - o.home_amsl),
            _ => climb / self.climb_angle_deg.to_radians().sin(),
        };
        Ok((wps, alts, length_m + extra + vertical))
    }
}

/// A lane as flown (pulled back from the NFZs it faces) and the straight
/// runs before and after it; for a leg of a corridor's bent lane, the way
/// round the bend to the next leg (camera off).
#[derive(Clone)]
pub(super) struct Entered {
    pub lane: Lane,
    pub lead: f64,
    pub over: f64,
    pub bend: Option<Vec<Piece>>,
}

impl Entered {
    /// The same lane flown the other way.
    pub(super) fn reversed(&self) -> Entered {
        Entered {
            lane: Lane {
                start: self.lane.end,
                end: self.lane.start,
            },
            lead: self.over,
            over: self.lead,
            bend: None,
        }
    }
}

impl PlaneFlight<'_> {
    /// The mission of one sortie flown from UAV home `home` (planning
    /// coordinates; `start` the same in lon/lat), and the sortie flown
    /// (its items moved into the mission); over `terrain` (the model, the height
    /// rules and the DEM height at home) when given.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn sortie(
        &self,
        tour: &Tour,
        home: Coord<f64>,
        start: [f64; 2],
        speed_m_s: f64,
        trigger_distance_m: f64,
        frame: AltitudeFrame,
        terrain: Option<(&TerrainModel, &FlightRules, f64)>,
        proj: &UtmProjection,
    ) -> Result<(crate::export::Mission, PlaneSortie), PlanError> {
        let over = terrain.map(|(model, rules, home_amsl)| Over {
            model,
            rules,
            home_amsl,
            frame,
        });
        let to_geo = |c: Coord<f64>, alt: f64| -> Result<GeoPoint, PlanError> {
            let ll = proj.to_wgs84(c)?;
            Ok(GeoPoint {
                lon: ll.x,
                lat: ll.y,
                alt,
            })
        };
        let mut flown = self.fly(
            tour,
            home,
            speed_m_s,
            trigger_distance_m,
            over.as_ref(),
            &to_geo,
        )?;
        let mission = crate::export::Mission {
            home: GeoPoint {
                lon: start[0],
                lat: start[1],
                alt: over.as_ref().map_or(0.0, |o| o.home_amsl),
            },
            frame,
            cruise_speed_m_s: speed_m_s,
            items: std::mem::take(&mut flown.items),
            over_terrain: over.is_some(),
        };
        Ok((mission, flown))
    }
}
