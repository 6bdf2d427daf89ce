//! Sharing a survey among the flock (SPEC §3.4–3.5): the cells' plans
//! become jobs (halved while there are more UAVs than cells), the chosen
//! policy shares them into routes, each route is cut into battery sorties,
//! and each sortie is flown as one tour from home and back.
//!
//! A single UAV with `balanced` (and no battery) is ordered by the tour
//! optimiser ([`plan_tour`], which may also enter a cell at its other two
//! corners); flocks keep to the two ends of each path, which the lower
//! bound and the balanced search price exactly. With a battery, balanced
//! keeps the competition's sorties if they turn out quicker once cut.

use geo_types::{Coord, MultiPolygon, Polygon};

use super::capture::Capture;
use super::cells::{Decomposition, dist};
use super::homes::FlockSetup;
use super::request::{Flight, PlanError, SurveyParams, cancelled_or};
use super::terrain_flight::{FlightRules, cell_length_3d, transit_length_3d};
use super::terrain_prep::OverDem;
use crate::coverage::CellPlan;
use crate::flock::{
    Flock, FlockJob, FlockUav, ObstacleMap, Part, Piece, Policy, Stop, Tour, Visit, assign,
    halve_until, makespan_lower_bound, plan_tour,
};
use crate::geo::Issue;
use crate::terrain::TerrainModel;

/// Most pieces a battery split may cut one UAV's work into.
const MAX_PIECES_PER_UAV: usize = 10_000;
/// Most sorties one UAV may fly.
const MAX_SORTIES_PER_UAV: usize = 100;

/// What the flock stage needs from the survey.
struct FlockInput<'a> {
    pub plans: &'a [CellPlan],
    pub cells: &'a [Polygon<f64>],
    /// Where lanes and links may run: the ROI less the NFZs' keep-out area.
    pub free: &'a MultiPolygon<f64>,
    pub obstacles: &'a ObstacleMap,
    pub uavs: Vec<FlockUav>,
    /// Battery endurance of each UAV, seconds.
    pub batteries: Vec<Option<f64>>,
    /// UAV ids, for messages.
    pub ids: Vec<String>,
    /// JSON pointer of UAV `i`'s member `field`.
    pub pointer: &'a dyn Fn(usize, &str) -> String,
    pub policy: Policy,
    pub turn_penalty_s: f64,
    /// Flight height of a flat survey.
    pub altitude_m: f64,
    pub terrain: Option<(&'a TerrainModel, FlightRules)>,
    /// A plane's turns, flown between the lanes (flat surveys).
    pub plane: Option<crate::coverage::airframe::PlaneTurns>,
    /// Length charged for a path's hover stops (see [`Capture::stop_length_m`]).
    pub stops: &'a dyn Fn(&CellPlan) -> f64,
}

/// One sortie: its tour and the pieces it flies, in order.
pub(super) struct SortieTour {
    pub tour: Tour,
    pub pieces: Vec<Piece>,
}

pub(super) struct FlockOutcome {
    /// Per UAV, its sorties.
    pub sorties: Vec<Vec<SortieTour>>,
    /// Lower bound of the makespan, seconds (before battery splits).
    pub lower_bound_s: f64,
}

impl FlockInput<'_> {
    /// The 3D length flown along a cell's (or piece's) path.
    /// With hover photos, the length flown in the time their stops take.
    fn cell_length_3d(&self, plan: &CellPlan) -> f64 {
        (self.stops)(plan)
            + match &self.terrain {
                Some((model, rules)) => cell_length_3d(model, plan, rules),
                None => self
                    .plane
                    .map_or_else(|| plan.length_m(), |t| t.plan_length(plan)),
            }
    }
}

/// Adds a part (a re-oriented or split piece) as a new job of the flock;
/// returns its index, the same in `parts` and `flock.jobs`.
fn add_part(
    input: &FlockInput,
    flock: &mut Flock,
    parts: &mut Vec<Part>,
    part: Part,
) -> Result<usize, PlanError> {
    let job = FlockJob::from_plan(&part.plan, input.cell_length_3d(&part.plan))
        .ok_or_else(|| PlanError::Internal("a piece without lanes".into()))?;
    flock.jobs.push(job);
    parts.push(part);
    Ok(parts.len() - 1)
}

/// Shares the cells of `d` among the UAVs of `setup` (flying in its
/// flyable space) by the request's policy, and flies each share.
pub(super) fn share_cells(
    setup: &FlockSetup,
    d: &Decomposition,
    params: &SurveyParams,
    flight: &Flight,
    over_dem: Option<&OverDem>,
) -> Result<FlockOutcome, PlanError> {
    let pointer = |i: usize, field: &str| setup.pointer(i, field);
    // Hover stops priced at the fastest UAV's speed: no UAV's time is
    // under-charged (exact when all fly at one speed), so no sortie
    // outlasts its battery.
    let fastest = setup
        .specs
        .iter()
        .filter_map(|u| u.speed_m_s)
        .fold(params.speed_m_s, f64::max);
    let capture = Capture::new(params, &flight.geometry, fastest);
    let stops = |plan: &CellPlan| {
        let lanes = plan.lanes.iter().map(|l| dist(l.start, l.end));
        capture.stop_length_m(lanes, fastest)
    };
    let input = FlockInput {
        plans: &d.plans,
        cells: &d.cells,
        free: &setup.flyable,
        obstacles: &setup.obstacles,
        uavs: setup
            .homes
            .iter()
            .zip(&setup.specs)
            .map(|(&home, u)| FlockUav {
                home,
                speed_m_s: u.speed_m_s.unwrap_or(params.speed_m_s),
            })
            .collect(),
        batteries: setup.specs.iter().map(|u| u.max_flight_time_s).collect(),
        ids: setup.specs.iter().map(|u| u.id.clone()).collect(),
        pointer: &pointer,
        policy: params.assignment,
        turn_penalty_s: params.turn_penalty_s,
        altitude_m: params.home_leg_m(flight.altitude),
        terrain: over_dem.map(|o| (&o.terrain.model, flight.rules)),
        plane: params.plane_turns(),
        stops: &stops,
    };
    let outcome = share(&input).map_err(cancelled_or)?;
    crate::cancel::check()?;
    Ok(outcome)
}

/// Shares the survey among the UAVs and flies each share.
fn share(input: &FlockInput) -> Result<FlockOutcome, PlanError> {
    let internal = |e: crate::flock::FlockError| PlanError::Internal(e.to_string());
    let cell_3d = |plan: &CellPlan| input.cell_length_3d(plan);
    let whole: Vec<Part> = input
        .plans
        .iter()
        .filter(|p| !p.lanes.is_empty())
        .cloned()
        .map(Part::whole)
        .collect();
    let mut parts = halve_until(whole, input.uavs.len(), cell_3d);
    let jobs = parts
        .iter()
        .filter_map(|p| FlockJob::from_plan(&p.plan, cell_3d(&p.plan)))
        .collect();

    let lift;
    let mut flock = match &input.terrain {
        None => Flock::flat(
            input.uavs.clone(),
            jobs,
            input.turn_penalty_s,
            input.obstacles,
            input.altitude_m,
        ),
        Some((model, rules)) => {
            let (model, rules) = (*model, *rules);
            lift = move |path: &[Coord<f64>], homes: [bool; 2]| {
                transit_length_3d(model, &rules, path, homes)
            };
            Flock::over_terrain(
                input.uavs.clone(),
                jobs,
                input.turn_penalty_s,
                input.obstacles,
                &lift,
            )
        }
    };

    flock.batteries = input.batteries.clone();
    let any_battery = input.batteries.iter().any(Option::is_some);
    // The tour optimiser knows no battery: with one, the local search
    // orders the work.
    let single_tour = input.uavs.len() == 1 && input.policy == Policy::Balanced && !any_battery;
    let solving = crate::flock::instance::Solving::start();
    // Before any policy prices legs, so that the bound is the same for all.
    // Only the single-UAV tour optimiser enters cells at their other corners.
    let lower_bound_s =
        makespan_lower_bound(&mut flock, single_tour).map_err(|e| internal(e.into()))?;
    // The competition's routes are kept to compare sorties with (below).
    let mut competition_routes = None;
    let mut routes = if single_tour {
        vec![(0..parts.len()).map(|j| Visit::new(j, 0)).collect()]
    } else if input.policy == Policy::Balanced {
        let (start, _) =
            crate::flock::competition::competition(&mut flock).map_err(|e| internal(e.into()))?;
        competition_routes = Some(start.clone());
        crate::flock::balanced::balanced(&mut flock, start).map_err(|e| internal(e.into()))?
    } else {
        assign(&mut flock, input.policy).map_err(internal)?
    };

    if single_tour {
        reorder_by_tour(input, &mut flock, &mut parts, 0, &mut routes[0])?;
    }
    // The flock problem as solved, for `terraplan experiment flock --instances`.
    solving.done(&mut flock, &routes, lower_bound_s);

    // The balanced search prices a job too long for one battery as ideal
    // round trips, while the cut halves it between lanes: on the sorties
    // actually cut, keep the competition's if they are quicker (or if only
    // they can be cut), so that balanced is never worse.
    let first = cut_all(input, &mut flock, &mut parts, routes);
    let cut = match competition_routes.filter(|_| any_battery) {
        None => first?,
        Some(start) => match (first, cut_all(input, &mut flock, &mut parts, start)) {
            (Ok(a), Ok(b)) => {
                if b.1 < a.1 {
                    b
                } else {
                    a
                }
            }
            (Ok(a), Err(_)) => a,
            (Err(_), Ok(b)) => b,
            (Err(e), Err(_)) => return Err(e),
        },
    };

    let mut sorties = Vec::with_capacity(cut.0.len());
    for (u, cut) in cut.0.into_iter().enumerate() {
        let mut flights = Vec::with_capacity(cut.len());
        for s in cut {
            let tour = tour_of(&mut flock, &parts, u, &s).map_err(|e| internal(e.into()))?;
            flights.push(SortieTour {
                tour,
                pieces: s.iter().map(|v| parts[v.job].piece.clone()).collect(),
            });
        }
        sorties.push(flights);
    }
    Ok(FlockOutcome {
        sorties,
        lower_bound_s,
    })
}

/// Every UAV's sorties (see [`cut_sorties`]) and the makespan they make.
#[allow(clippy::type_complexity)]
fn cut_all(
    input: &FlockInput,
    flock: &mut Flock,
    parts: &mut Vec<Part>,
    routes: Vec<Vec<Visit>>,
) -> Result<(Vec<Vec<Vec<Visit>>>, f64), PlanError> {
    let mut out = Vec::with_capacity(routes.len());
    let mut makespan: f64 = 0.0;
    for (u, route) in routes.into_iter().enumerate() {
        let sorties = cut_sorties(input, flock, parts, u, route)?;
        let mut time = 0.0;
        for s in &sorties {
            time += flock
                .flight_time(u, s)
                .map_err(|e| PlanError::Internal(e.to_string()))?;
        }
        makespan = makespan.max(time);
        out.push(sorties);
    }
    Ok((out, makespan))
}

/// The tour flying `route` from UAV `u`'s home and back.
fn tour_of(
    flock: &mut Flock,
    parts: &[Part],
    u: usize,
    route: &[Visit],
) -> Result<Tour, crate::flock::TransitError> {
    let visits: Vec<CellPlan> = route
        .iter()
        .map(|v| {
            let plan = &parts[v.job].plan;
            if v.way == 0 {
                plan.clone()
            } else {
                plan.reversed()
            }
        })
        .collect();
    let mut transits = Vec::with_capacity(route.len() + 1);
    for (a, b) in Flock::legs_of(u, route) {
        transits.push(flock.leg_path(a, b)?);
    }
    Ok(Tour { visits, transits })
}

/// Orders a single UAV's jobs by the tour optimiser. The cells' plans, as
/// the tour flies them, become new parts flown as planned (way 0). Not for
/// a UAV with a battery: the optimiser knows none, and a re-oriented part
/// must not be halved later (its piece is described in planned lane order).
fn reorder_by_tour(
    input: &FlockInput,
    flock: &mut Flock,
    parts: &mut Vec<Part>,
    u: usize,
    route: &mut Vec<Visit>,
) -> Result<(), PlanError> {
    if route.len() < 2 || flock.has_battery(u) {
        return Ok(());
    }
    // Pieces are matched back by cell, so each cell may appear once.
    let mut cells: Vec<usize> = route.iter().map(|v| parts[v.job].piece.cell).collect();
    cells.sort_unstable();
    if cells.windows(2).any(|w| w[0] == w[1]) {
        return Ok(());
    }
    let plans: Vec<CellPlan> = route.iter().map(|v| parts[v.job].plan.clone()).collect();
    let home = input.uavs[u].home;
    let candidate = plan_tour(home, &plans, input.cells, input.free, input.obstacles)
        .map_err(|e| PlanError::Internal(e.to_string()))?;
    // The job flying each cell, found by cell (a tour has thousands).
    let job_of: std::collections::HashMap<usize, usize> = route
        .iter()
        .map(|v| (parts[v.job].piece.cell, v.job))
        .collect();
    let mut new_route = Vec::with_capacity(candidate.visits.len());
    for visit in candidate.visits {
        let Some(&old_job) = job_of.get(&visit.cell_index) else {
            return Err(PlanError::Internal("tour lost a cell".into()));
        };
        let piece = parts[old_job].piece.clone();
        let job = add_part(input, flock, parts, Part { piece, plan: visit })?;
        new_route.push(Visit::new(job, 0));
    }
    // The tour's transits are the legs of the new route: known already.
    for ((a, b), path) in Flock::legs_of(u, &new_route)
        .into_iter()
        .zip(candidate.transits)
    {
        flock.know_leg(a, b, path);
    }
    *route = new_route;
    Ok(())
}

/// Cuts UAV `u`'s route into sorties that each fit its battery, in flight
/// order, returning home between them. A job too long for one battery is
/// halved until its pieces fit.
fn cut_sorties(
    input: &FlockInput,
    flock: &mut Flock,
    parts: &mut Vec<Part>,
    u: usize,
    route: Vec<Visit>,
) -> Result<Vec<Vec<Visit>>, PlanError> {
    let internal = |e: crate::flock::TransitError| PlanError::Internal(e.to_string());
    let Some(limit) = input.batteries[u] else {
        return Ok(vec![route]);
    };
    let mut sorties: Vec<Vec<Visit>> = Vec::new();
    let mut current: Vec<Visit> = Vec::new();
    let mut queue: std::collections::VecDeque<Visit> = route.into();
    let mut splits = 0usize;
    while let Some(v) = queue.pop_front() {
        if sorties.len() >= MAX_SORTIES_PER_UAV {
            return Err(PlanError::Invalid(vec![Issue::new(
                &(input.pointer)(u, "max_flight_time_s"),
                &format!(
                    "UAV {} would need more than {MAX_SORTIES_PER_UAV} sorties with a battery of \
                     {limit:.0} s: give it a longer max_flight_time_s, start it nearer or add UAVs",
                    input.ids[u]
                ),
            )]));
        }
        current.push(v);
        if flock.flight_time(u, &current).map_err(internal)? <= limit {
            continue;
        }
        current.pop();
        if !current.is_empty() {
            sorties.push(std::mem::take(&mut current));
            queue.push_front(v);
            continue;
        }
        // Alone it is too long: halve it, unless even getting there and
        // back takes the whole battery.
        let there_and_back = flock
            .leg_time_of(u, Stop::Home(u), Stop::entry_of(v))
            .map_err(internal)?
            + flock
                .leg_time_of(u, Stop::exit_of(v), Stop::Home(u))
                .map_err(internal)?;
        let piece = &parts[v.job].piece;
        let halves = parts[v.job].halve();
        splits += 1;
        let (Some((a, b)), true) = (
            halves,
            splits < MAX_PIECES_PER_UAV && there_and_back < limit,
        ) else {
            return Err(PlanError::Invalid(vec![Issue::new(
                &(input.pointer)(u, "max_flight_time_s"),
                &format!(
                    "UAV {} cannot fly cell {} within its battery of {limit:.0} s: getting there \
                     and back alone takes {there_and_back:.0} s; start it nearer or give it a \
                     longer max_flight_time_s{}",
                    input.ids[u],
                    piece.cell,
                    if input.policy == Policy::Balanced {
                        ""
                    } else {
                        " (the balanced assignment shares cells with the batteries in mind)"
                    }
                ),
            )]));
        };
        let halves = [
            add_part(input, flock, parts, a)?,
            add_part(input, flock, parts, b)?,
        ];
        // Flown in the direction the whole job was: backwards means the
        // second half first.
        let (first, second) = if v.way == 0 {
            (Visit::new(halves[0], 0), Visit::new(halves[1], 0))
        } else {
            (Visit::new(halves[1], 1), Visit::new(halves[0], 1))
        };
        queue.push_front(second);
        queue.push_front(first);
    }
    if !current.is_empty() {
        sorties.push(current);
    }
    Ok(sorties)
}
