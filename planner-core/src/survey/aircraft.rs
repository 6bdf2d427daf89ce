//! The `aircraft` member of a survey request: the airframe type and the
//! numbers its turns and climbs are planned with, their defaults per type
//! and their checks.

use serde::{Deserialize, Serialize};

use geo_types::MultiPolygon;

use super::cells::Decomposition;
use super::homes::FlockSetup;
use super::request::SurveyParams;
use crate::coverage::airframe::PlaneTurns;
use crate::coverage::arcs::ARC_SLACK;
use crate::coverage::{CellPlan, Lane};
use crate::geo::Issue;
use crate::num::readable;

/// What flies the survey.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AircraftType {
    /// Turns on the spot, climbs vertically: today's plans.
    #[default]
    Multirotor,
    /// A plane: enters every lane straight, turns on arcs, takes off with
    /// NAV_TAKEOFF and lands on a straight descending approach.
    FixedWing,
    /// A quadplane: flies as a plane, takes off and lands vertically.
    Vtol,
}

/// `aircraft`: the airframe and its flight envelope. Absent numbers take
/// the type's defaults ([`Aircraft::turn_radius`] and the others).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aircraft {
    /// `multirotor` (default), `fixed_wing` or `vtol`.
    #[serde(rename = "type", default)]
    pub kind: AircraftType,
    /// Smallest turn radius flown, m, in [5, 1000]; default 40 (fixed
    /// wing), 60 (VTOL). Planes only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(minimum = 5, maximum = 1000))]
    pub turn_radius_m: Option<f64>,
    /// Steepest climb or descent along the track, degrees, in (0, 45];
    /// default 10 (fixed wing), 8 (VTOL). Planes only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 45))]
    pub max_climb_angle_deg: Option<f64>,
    /// Cruise speed, m/s, in (0, 50]; replaces `speed_m_s` (a UAV's own
    /// `speed_m_s` still wins); default 16 (fixed wing), 20 (VTOL), the
    /// survey's `speed_m_s` for a multirotor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 50))]
    pub cruise_speed_m_s: Option<f64>,
    /// Straight run before and after every lane (lead-in and overshoot),
    /// m, in [0, 2000]; default the turn radius. Planes only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 2000))]
    pub lead_in_m: Option<f64>,
}

impl Aircraft {
    /// Planes (fixed wing and VTOL) fly turns on arcs.
    pub fn is_plane(&self) -> bool {
        self.kind != AircraftType::Multirotor
    }

    pub fn turn_radius(&self) -> f64 {
        self.turn_radius_m.unwrap_or(match self.kind {
            AircraftType::Vtol => 60.0,
            _ => 40.0,
        })
    }

    pub fn max_climb_angle_deg(&self) -> f64 {
        self.max_climb_angle_deg.unwrap_or(match self.kind {
            AircraftType::Vtol => 8.0,
            _ => 10.0,
        })
    }

    /// The cruise speed, `None` for a multirotor without one (the survey's
    /// `speed_m_s` then).
    pub fn cruise_speed(&self) -> Option<f64> {
        self.cruise_speed_m_s.or(match self.kind {
            AircraftType::Multirotor => None,
            AircraftType::FixedWing => Some(16.0),
            AircraftType::Vtol => Some(20.0),
        })
    }

    pub fn lead_in(&self) -> f64 {
        self.lead_in_m.unwrap_or_else(|| self.turn_radius())
    }

    /// Range checks at `pointer` (the member's own pointer, `/aircraft`).
    pub fn check(&self, issues: &mut Vec<Issue>, pointer: &str) {
        let p = |f: &str| format!("{pointer}/{f}");
        let mut range = |name: &str, v: Option<f64>, lo: f64, hi: f64, lo_open: bool| {
            let Some(v) = v else { return };
            let ok = v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi;
            if !ok {
                let (open, close) = (if lo_open { "(" } else { "[" }, "]");
                issues.push(Issue::new(
                    &p(name),
                    &format!(
                        "{} is outside the allowed range {open}{}, {}{close}",
                        readable(v),
                        readable(lo),
                        readable(hi)
                    ),
                ));
            }
        };
        range("turn_radius_m", self.turn_radius_m, 5.0, 1000.0, false);
        range(
            "max_climb_angle_deg",
            self.max_climb_angle_deg,
            0.0,
            45.0,
            true,
        );
        range("cruise_speed_m_s", self.cruise_speed_m_s, 0.0, 50.0, true);
        range("lead_in_m", self.lead_in_m, 0.0, 2000.0, false);
        if !self.is_plane() {
            for (name, v) in [
                ("turn_radius_m", self.turn_radius_m),
                ("max_climb_angle_deg", self.max_climb_angle_deg),
                ("lead_in_m", self.lead_in_m),
            ] {
                if v.is_some() {
                    issues.push(Issue::new(
                        &p(name),
                        "only planes (type fixed_wing or vtol) take this: a multirotor turns on \
                         the spot and climbs vertically",
                    ));
                }
            }
        }
    }
}

impl SurveyParams {
    /// The aircraft if it is a plane.
    pub(super) fn plane(&self) -> Option<&Aircraft> {
        self.aircraft.as_ref().filter(|a| a.is_plane())
    }

    /// The parameters as the aircraft flies them: its cruise speed for
    /// `speed_m_s` and, for planes, the time a turn adds to the sharing's
    /// estimates as `turn_penalty_s` (the plan's own figures are the
    /// flown lengths, without a penalty). Without `aircraft`, the same
    /// parameters.
    pub(super) fn as_flown(&self) -> SurveyParams {
        let mut out = self.clone();
        if let Some(a) = &self.aircraft {
            if let Some(v) = a.cruise_speed().filter(|v| *v > 0.0 && *v <= 50.0) {
                out.speed_m_s = v;
            }
            if a.is_plane() {
                // What a turn adds to a plane's flight over the turn the
                // sharing sees (a lane's end or a transit's bend): a
                // straight run and the arc's excess over the corner. The
                // figures of the plan are the flown lengths.
                let r = a.turn_radius() * ARC_SLACK;
                out.turn_penalty_s =
                    (a.lead_in() + (std::f64::consts::FRAC_PI_2 - 1.0) * r) / out.speed_m_s;
            }
        }
        out
    }

    /// The height a flock's leg from or to home is charged for (the climb
    /// or descent): for a plane also its climb-out and its final, at the
    /// climb angle.
    pub(super) fn home_leg_m(&self, altitude: f64) -> f64 {
        self.plane().map_or(altitude, |a| {
            let angle = a.max_climb_angle_deg().to_radians();
            altitude / angle.sin() + altitude / angle.tan() + 2.0 * a.turn_radius() * ARC_SLACK
        })
    }

    /// How a plane turns between lanes (arcs planned [`ARC_SLACK`] wider
    /// than its turn radius).
    pub(super) fn plane_turns(&self) -> Option<PlaneTurns> {
        self.plane().map(|a| PlaneTurns {
            radius_m: a.turn_radius() * ARC_SLACK,
            lead_in_m: a.lead_in(),
            overshoot_m: a.lead_in(),
        })
    }
}

/// Sorties of planes that outlast their battery: the sharing prices a
/// transit as the NFZ-avoiding polyline, without the turns at its ends
/// that the flown one has, so a sortie cut close to the battery may run
/// over (the figures are the flown ones).
pub(super) fn battery_warnings(params: &SurveyParams, uavs: &[super::UavPlan]) -> Vec<String> {
    if params.plane().is_none() {
        return Vec::new();
    }
    let mut out = Vec::new();
    for u in uavs {
        let Some(limit) = u.max_flight_time_s else {
            continue;
        };
        for s in u.sorties.iter().filter(|s| s.stats.flight_time_s > limit) {
            out.push(format!(
                "{} flies {:.0} s with its turns, over its battery of {limit:.0} s: give it a \
                 longer max_flight_time_s, or more UAVs",
                s.file_stem, s.stats.flight_time_s
            ));
        }
    }
    out
}

/// A plane's lane count and coverage ratio (see [`crate::coverage::coverage_ratio`]):
/// of the lanes it flies with the camera on, which lanes facing no-fly
/// zones are pulled back from (or dropped) to leave room for its turns.
pub(super) fn flown_coverage(
    lanes: &[Lane],
    footprint_side_m: f64,
    free: &MultiPolygon<f64>,
) -> (usize, f64) {
    (
        lanes.len(),
        crate::coverage::coverage_ratio(lanes, footprint_side_m, free),
    )
}

/// What the footprints leave out of the free area (`free_area_m2`): the
/// pockets enclosed by the keep-out area and, under 99.5 %, the shortfall
/// of the coverage figure, for a plane with what of the lanes laid
/// (`lanes.0`) it flies (`lanes.1`) and why.
pub(super) fn left_out_warnings(
    params: &SurveyParams,
    setup: &FlockSetup,
    lanes: (&[CellPlan], &[Lane]),
    coverage_ratio: f64,
    free_area_m2: f64,
) -> Vec<String> {
    let plane = pulled_back_warning(params, lanes.0, lanes.1, coverage_ratio, free_area_m2);
    // A plane's shortfall is explained by its own warning.
    let ratio = if params.plane().is_some() {
        1.0
    } else {
        coverage_ratio
    };
    let mut out =
        super::cells::left_out_warnings(setup.enclosed_m2, setup.clearance, ratio, free_area_m2);
    out.extend(plane);
    out
}

/// Why a plane's lanes sweep less than 99.5 % of the free area (the
/// coverage figure): what of the `planned` lanes it flies (`flown`), why,
/// and what helps.
fn pulled_back_warning(
    params: &SurveyParams,
    planned: &[CellPlan],
    flown: &[Lane],
    coverage_ratio: f64,
    free_area_m2: f64,
) -> Option<String> {
    let a = params.plane()?;
    let length = |l: &Lane| (l.end.x - l.start.x).hypot(l.end.y - l.start.y);
    let planned_m: f64 = planned.iter().flat_map(|p| &p.lanes).map(length).sum();
    let flown_m: f64 = flown.iter().map(length).sum();
    (coverage_ratio < 0.995).then(|| {
        format!(
            "the lanes the plane flies sweep {:.2} % of the free area ({:.0} m² left out; \
             strips a footprint wide with flat ends, the coverage figure: the photos reach half \
             a footprint further at each lane's ends): it flies {:.2} of the {:.2} km of lanes \
             laid, as lane ends facing no-fly zones are pulled back so that it can turn at \
             turn_radius_m = {} m with lead_in_m = {} m, lanes it cannot reach are left out \
             and the camera is off round a corridor's bends; lower turn_radius_m or lead_in_m, \
             or fly higher for wider footprints",
            coverage_ratio * 100.0,
            (1.0 - coverage_ratio) * free_area_m2,
            flown_m / 1000.0,
            planned_m / 1000.0,
            a.turn_radius(),
            a.lead_in(),
        )
    })
}

/// A plane flies each cell's lanes in the order its turns are shortest in:
/// a grid's lanes as one set; a crosshatch's first set, then each part of
/// its second set (see [`sets`]) on its own. A corridor's lanes keep their
/// order (a bent lane's legs follow one another).
pub(super) fn order_lanes(d: &mut Decomposition, params: &SurveyParams) {
    let Some(turns) = params.plane_turns() else {
        return;
    };
    if d.along_line {
        return;
    }
    for plan in &mut d.plans {
        let mut lanes = Vec::with_capacity(plan.lanes.len());
        for run in sets(&plan.lanes) {
            let part = CellPlan {
                lanes: plan.lanes[run].to_vec(),
                links: Vec::new(),
                ..plan.clone()
            };
            lanes.extend(turns.order(&part).lanes);
        }
        plan.links = vec![Vec::new(); lanes.len().saturating_sub(1)];
        plan.lanes = lanes;
    }
}

/// Lanes whose directions differ by less than this are of one set, radians.
const SAME_SET_RAD: f64 = 0.01;

/// The runs of `lanes` that are laid as one set: the lanes up to the first
/// in another direction (a cell's own lanes, a grid's all), then each part
/// of a crosshatch's second set, told apart by the step across from lane
/// to lane (even within a part, changing where the next part starts).
fn sets(lanes: &[Lane]) -> Vec<std::ops::Range<usize>> {
    let heading = |l: &Lane| (l.end.y - l.start.y).atan2(l.end.x - l.start.x);
    let parallel = |a: &Lane, b: &Lane| {
        let d = (heading(a) - heading(b)).rem_euclid(std::f64::consts::PI);
        d.min(std::f64::consts::PI - d) < SAME_SET_RAD
    };
    // The step across the lanes from `a` to `b`, along the normal of `a`'s
    // line (the same for both ways along it).
    let step = |a: &Lane, b: &Lane| {
        let h = heading(a).rem_euclid(std::f64::consts::PI);
        let (nx, ny) = (-h.sin(), h.cos());
        let mid = |l: &Lane| ((l.start.x + l.end.x) / 2.0, (l.start.y + l.end.y) / 2.0);
        let ((ax, ay), (bx, by)) = (mid(a), mid(b));
        (bx - ax) * nx + (by - ay) * ny
    };
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..lanes.len() {
        let new = if !parallel(&lanes[k - 1], &lanes[k]) {
            true
        } else if parallel(&lanes[0], &lanes[k]) || k - start < 2 {
            false
        } else {
            let s0 = step(&lanes[k - 2], &lanes[k - 1]);
            let s1 = step(&lanes[k - 2], &lanes[k]) - s0;
            (s1 - s0).abs() > 0.01 * s0.abs() + 0.01
        };
        if new {
            out.push(start..k);
            start = k;
        }
    }
    if !lanes.is_empty() {
        out.push(start..lanes.len());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_crosshatch_is_ordered_set_by_set_and_part_by_part() {
        let lane = |x0: f64, y0: f64, x1: f64, y1: f64| Lane {
            start: geo_types::coord! {x: x0, y: y0},
            end: geo_types::coord! {x: x1, y: y1},
        };
        // First set: 4 lanes north-south, 20 m apart, back and forth.
        let mut lanes: Vec<Lane> = (0..4)
            .map(|i| {
                let x = 20.0 * f64::from(i);
                if i % 2 == 0 {
                    lane(x, 0.0, x, 300.0)
                } else {
                    lane(x, 300.0, x, 0.0)
                }
            })
            .collect();
        // Second set in two parts: 3 lanes east-west at y = 0, 20, 40, then
        // 3 at y = 200, 220, 240.
        for base in [0.0, 200.0] {
            for i in 0..3 {
                let y = base + 20.0 * f64::from(i);
                lanes.push(if i % 2 == 0 {
                    lane(0.0, y, 60.0, y)
                } else {
                    lane(60.0, y, 0.0, y)
                });
            }
        }
        assert_eq!(sets(&lanes), vec![0..4, 4..7, 7..10]);
        assert_eq!(sets(&lanes[..4]), vec![0..4]);
        assert!(sets(&[]).is_empty());
    }

    #[test]
    fn defaults_per_type_and_checks() {
        let a: Aircraft = serde_json::from_value(json!({"type": "fixed_wing"})).unwrap();
        assert_eq!(
            (a.turn_radius(), a.max_climb_angle_deg(), a.cruise_speed()),
            (40.0, 10.0, Some(16.0))
        );
        assert_eq!(a.lead_in(), 40.0);
        let v: Aircraft =
            serde_json::from_value(json!({"type": "vtol", "turn_radius_m": 80})).unwrap();
        assert_eq!((v.turn_radius(), v.lead_in()), (80.0, 80.0));
        let m = Aircraft::default();
        assert!(!m.is_plane());
        assert_eq!(m.cruise_speed(), None);
        assert!(serde_json::from_value::<Aircraft>(json!({"type": "glider"})).is_err());

        let mut issues = Vec::new();
        let bad = Aircraft {
            kind: AircraftType::FixedWing,
            turn_radius_m: Some(2.0),
            max_climb_angle_deg: Some(0.0),
            cruise_speed_m_s: Some(60.0),
            lead_in_m: Some(-1.0),
        };
        bad.check(&mut issues, "/aircraft");
        let ptrs: Vec<&str> = issues.iter().map(|i| i.pointer.as_str()).collect();
        assert_eq!(
            ptrs,
            [
                "/aircraft/turn_radius_m",
                "/aircraft/max_climb_angle_deg",
                "/aircraft/cruise_speed_m_s",
                "/aircraft/lead_in_m"
            ]
        );
        assert!(
            issues[0].message.contains("[5, 1000]"),
            "{}",
            issues[0].message
        );
        let mut issues = Vec::new();
        Aircraft {
            turn_radius_m: Some(30.0),
            ..Aircraft::default()
        }
        .check(&mut issues, "/aircraft");
        assert_eq!(issues[0].pointer, "/aircraft/turn_radius_m");
    }
}
