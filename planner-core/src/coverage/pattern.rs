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

/// Cuts a cell into parts monotone along lines of a bearing.
pub type SplitCell = dyn Fn(&Polygon<f64>, f64) -> Vec<Polygon<f64>> + Sync;

/// Every plan of `plans` (each covering `cells[plan.cell_index]`) with a
/// second set of lanes across its own, `spacing` apart, laid, clipped and
/// linked in `free` like the first (see [`crosshatch`]); `split(cell,
/// bearing)` cuts a cell into parts monotone along lines of that bearing
/// (the decomposition at that slice angle).
pub fn crosshatch_all(
    plans: &[CellPlan],
    cells: &[Polygon<f64>],
    free: &MultiPolygon<f64>,
    spacing: f64,
    split: &SplitCell,
) -> Vec<CellPlan> {
    let free = FreeSpace::new(free);
    let token = crate::cancel::current();
    plans
        .par_iter()
        .map(|p| {
            token.scope(|| {
                let cell = &cells[p.cell_index];
                let parts = split(cell, across(p));
                crosshatch(p, cell, &parts, &free, spacing)
            })
        })
        .collect()
}

/// The bearing of a plan's second set: 90° to its lanes, in [0, 180).
pub fn across(plan: &CellPlan) -> f64 {
    (plan.direction_deg + 90.0).rem_euclid(180.0)
}

/// `plan` followed by a second set of lanes at 90° to its own over `cell`,
/// laid part by part over `parts` (the cell cut into pieces monotone across
/// it, so that every lane is one segment whose ends reach the slanted
/// edges of its strip, as the first set's do), each part's lanes extended
/// and clipped in `free` and linked as the first set's are. The parts are
/// flown nearest first, each the way round that starts nearest; the links
/// between parts and sets are routed like any link of the cell. The plan
/// unchanged when no second set can be laid (a degenerate cell).
pub fn crosshatch(
    plan: &CellPlan,
    cell: &Polygon<f64>,
    parts: &[Polygon<f64>],
    free: &FreeSpace,
    spacing: f64,
) -> CellPlan {
    let bearing = across(plan);
    let mut pending: Vec<(&Polygon<f64>, CellPlan)> = parts
        .iter()
        .filter_map(|part| {
            let laid = CellLayouts::along(plan.cell_index, part, spacing, bearing)?;
            Some((part, laid.best_plan(part, free)?))
        })
        .filter(|(_, p)| !p.lanes.is_empty())
        .collect();
    let router = LinkRouter::new(cell, free);
    let mut out = plan.clone();
    let ways = [(false, false), (false, true), (true, false), (true, true)];
    while let Some(last) = out.lanes.last().copied() {
        // The part, and the way round it, that starts nearest.
        let Some((k, way, _)) = pending
            .iter()
            .enumerate()
            .flat_map(|(k, (_, p))| ways.iter().map(move |&w| (k, w, start_of(p, w))))
            .map(|(k, w, s)| (k, w, dist(last.end, s)))
            .min_by(|a, b| a.2.total_cmp(&b.2))
        else {
            break;
        };
        let (part, second) = pending.swap_remove(k);
        let second = if way == (false, false) {
            second
        } else {
            second.reoriented_in(way.0, way.1, part, free)
        };
        out.links.push(router.link(&last, &second.lanes[0]));
        out.lanes.extend_from_slice(&second.lanes);
        out.links.extend(second.links);
    }
    out
}

/// Where `plan` starts when flown from its last lane (`rev`) and/or with
/// every lane the other way round (`flip`).
fn start_of(plan: &CellPlan, (rev, flip): (bool, bool)) -> geo_types::Coord<f64> {
    let lane = if rev {
        plan.lanes[plan.lanes.len() - 1]
    } else {
        plan.lanes[0]
    };
    if flip { lane.end } else { lane.start }
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

    fn split(cell: &Polygon<f64>, bearing: f64) -> Vec<Polygon<f64>> {
        crate::decompose::decompose(&MultiPolygon(vec![cell.clone()]), bearing).unwrap()
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
            let parts = split(cell, across(&plan));
            let both = crosshatch(&plan, cell, &parts, &prepared, spacing);
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
            &split,
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
