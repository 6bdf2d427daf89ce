//! Survey patterns: the grid (one set of lanes per cell) and the crosshatch,
//! which flies each cell a second time with lanes at 90° to the first.

use geo_types::{MultiPolygon, Polygon};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::links::LinkRouter;
use super::region::{FreeSpace, dist};
use super::{CellLayouts, CellPlan};

/// How each cell is flown.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Pattern {
    /// One set of back-and-forth lanes.
    #[default]
    Grid,
    /// The grid's lanes, then a second set at 90° to them over the same
    /// cell (a double grid, for 3D models).
    Crosshatch,
}

/// Every plan of `plans` (each covering `cells[plan.cell_index]`) with a
/// second set of lanes across its own, `spacing` apart, laid, clipped and
/// linked in `free` like the first (see [`crosshatch`]).
pub fn crosshatch_all(
    plans: &[CellPlan],
    cells: &[Polygon<f64>],
    free: &MultiPolygon<f64>,
    spacing: f64,
) -> Vec<CellPlan> {
    let free = FreeSpace::new(free);
    let token = crate::cancel::current();
    plans
        .par_iter()
        .map(|p| token.scope(|| crosshatch(p, &cells[p.cell_index], &free, spacing)))
        .collect()
}

/// `plan` followed by a second set of lanes at 90° to its own over `cell`:
/// the layout of [`CellLayouts::along`] (every piece of every lane line
/// where the cell is not monotone across), extended and clipped in `free`
/// as the first set's lanes are. Of the four ways to fly the second set,
/// the one whose first lane starts nearest the first set's end; the link
/// between the two sets is routed like any link of the cell. The plan
/// unchanged when no second set can be laid (a degenerate cell).
pub fn crosshatch(
    plan: &CellPlan,
    cell: &Polygon<f64>,
    free: &FreeSpace,
    spacing: f64,
) -> CellPlan {
    let Some(last) = plan.lanes.last() else {
        return plan.clone();
    };
    let Some(second) =
        CellLayouts::along(plan.cell_index, cell, spacing, plan.direction_deg + 90.0)
            .and_then(|l| l.best_plan(cell, free))
    else {
        return plan.clone();
    };
    let ways = [(false, false), (false, true), (true, false), (true, true)];
    let start_of = |(rev, flip): (bool, bool)| {
        let lane = if rev {
            second.lanes.last()
        } else {
            second.lanes.first()
        };
        lane.map(|l| if flip { l.end } else { l.start })
    };
    let Some(&(rev, flip)) = ways.iter().min_by(|a, b| {
        let da = start_of(**a).map_or(f64::INFINITY, |s| dist(last.end, s));
        let db = start_of(**b).map_or(f64::INFINITY, |s| dist(last.end, s));
        da.total_cmp(&db)
    }) else {
        return plan.clone();
    };
    let second = if (rev, flip) == (false, false) {
        second
    } else {
        second.reoriented_in(rev, flip, cell, free)
    };
    let router = LinkRouter::new(cell, free);
    let mut out = plan.clone();
    out.links.push(router.link(last, &second.lanes[0]));
    out.lanes.extend_from_slice(&second.lanes);
    out.links.extend(second.links);
    out
}

#[cfg(test)]
mod tests {
    use super::super::Lane;
    use super::super::{coverage_ratio, plan_cell_in};
    use super::*;
    use crate::coverage::region::tests::field_with_nfzs;
    use geo::{Distance, Euclidean};
    use geo_types::Point;

    fn bearing_mod_180(l: &Lane) -> f64 {
        let d = l.end - l.start;
        d.x.atan2(d.y).to_degrees().rem_euclid(180.0)
    }

    fn same_way(l: &Lane, bearing: f64) -> bool {
        let gap = (bearing_mod_180(l) - bearing).rem_euclid(180.0);
        gap.min(180.0 - gap) < 1e-6
    }

    #[test]
    fn crosshatch_adds_a_covering_set_at_right_angles() {
        let free = field_with_nfzs(3);
        let prepared = FreeSpace::new(&free);
        let spacing = 40.0;
        let cells = crate::decompose::decompose(&free, 30.0).unwrap();
        let mut checked = 0;
        for (i, cell) in cells.iter().enumerate() {
            let Some(plan) = plan_cell_in(i, cell, &prepared, spacing, 30.0) else {
                continue;
            };
            let both = crosshatch(&plan, cell, &prepared, spacing);
            let n = plan.lanes.len();
            assert!(both.lanes.len() > n, "cell {i}: no second set");
            assert_eq!(both.links.len(), both.lanes.len() - 1);
            assert_eq!(&both.lanes[..n], &plan.lanes[..]);
            for lane in &both.lanes[n..] {
                let gap = (bearing_mod_180(lane) - plan.direction_deg - 90.0).rem_euclid(180.0);
                assert!(gap.min(180.0 - gap) < 1e-6, "cell {i}: {gap}");
            }
            // Every flown segment stays in free space (sampled: segments
            // along an NFZ's edge defeat exact predicates by rounding).
            for w in both.path().windows(2) {
                for k in 0..=20 {
                    let t = f64::from(k) / 20.0;
                    let q = Point::new(
                        w[0].x + (w[1].x - w[0].x) * t,
                        w[0].y + (w[1].y - w[0].y) * t,
                    );
                    let off = Euclidean.distance(&free, &q);
                    assert!(off < 1e-6, "cell {i}: {w:?} leaves free space by {off}");
                }
            }
            checked += 1;
        }
        assert!(checked > 3, "{checked}");
        // The whole field: both sets fly inside it.
        let all = crosshatch_all(
            &cells
                .iter()
                .enumerate()
                .filter_map(|(i, c)| plan_cell_in(i, c, &prepared, spacing, 30.0))
                .collect::<Vec<_>>(),
            &cells,
            &free,
            spacing,
        );
        // Each set alone covers the field (footprints of a 70 % side overlap).
        for second in [false, true] {
            let lanes: Vec<Lane> = all
                .iter()
                .flat_map(|p| {
                    let n = p
                        .lanes
                        .iter()
                        .take_while(|l| same_way(l, p.direction_deg))
                        .count();
                    if second {
                        p.lanes[n..].to_vec()
                    } else {
                        p.lanes[..n].to_vec()
                    }
                })
                .collect();
            let r = coverage_ratio(&lanes, spacing / 0.3, &free);
            assert!(r > 0.995, "set {}: {r}", u8::from(second) + 1);
        }
    }
}
