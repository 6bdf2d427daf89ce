//! D* Lite's heuristic with a landmark: the optimal costs from the route's
//! start that an A* search found (a differential heuristic), which make
//! D* Lite's first, backward search follow the route instead of flooding
//! the map, and keep its replans on a close bound.
//!
//! For a start s₀ and goal t, A* (ε = 1) closes every cell u with
//! d(s₀, u) + h_t(u) < C* with its exact cost d(s₀, u), and no cell it
//! left open or unseen is cheaper than C* − h_t(u) (h_t the octile bound to
//! t). So D(u) = min(d(s₀, u) if closed, C* − h_t(u)) is known everywhere,
//! and as the minimum of two functions that rise by at most the arc cost
//! along any arc, D(v) ≤ D(u) + c(u, v). Then for any start s,
//! D(u) − D(s) ≤ d(s, u): an admissible, consistent heuristic, and
//! h_s(u) = max(octile(s, u), D(u) − D(s)) obeys D* Lite's condition for
//! moving the start, h_a(u) ≤ h_a(b) + h_b(u) (both terms do). Blocking
//! cells or raising costs keeps D(v) ≤ D(u) + c(u, v); lowering them may
//! not, which the planner checks around the changed cells.
//!
//! A*'s labels keep g to 48 significant bits and round it down, so the
//! stored D breaks the arc inequality by up to (C*/c_min)² · 2⁻⁴⁸ (c_min the
//! cheapest arc); D is scaled by 1 − λ with λ · c_min above that, which
//! restores it exactly (a landmark that would need λ > 1/2 is not used).

use std::sync::Arc;

use super::arc_model::Heuristic;
use super::astar::SearchTree;
use super::neighbourhood::Neighbourhood;

/// The landmark's costs D (see the module docs), scaled by 1 − λ.
pub(crate) struct Landmark {
    tree: SearchTree,
    width: usize,
    to_goal: Heuristic,
    /// C* less a rounding margin.
    bound: f64,
    scale: f64,
}

impl Landmark {
    /// The landmark of a finished A* search towards `goal` whose heuristic
    /// factor was `factor`; `cheapest_arc` is the least cost of any arc.
    /// `None` when the costs are too long for its rounding margin.
    pub(crate) fn new(
        tree: SearchTree,
        hood: &Neighbourhood,
        goal: usize,
        factor: f64,
        cheapest_arc: f64,
    ) -> Option<Landmark> {
        let cost = tree.goal_cost();
        let steps = cost / cheapest_arc;
        let lambda = 4.0 * (steps * steps * 2f64.powi(-48) + steps * 2f64.powi(-50));
        if !(lambda.is_finite() && lambda <= 0.5 && cost.is_finite()) {
            return None;
        }
        Some(Landmark {
            tree,
            width: hood.width(),
            to_goal: Heuristic::new(hood, goal, factor),
            bound: cost * (1.0 - 1e-12),
            scale: 1.0 - lambda,
        })
    }

    /// (1 − λ) · D(i) of row-major cell `i`.
    #[inline]
    pub(crate) fn value(&self, hood: &Neighbourhood, i: usize) -> f64 {
        let (r, c) = (i / self.width, i % self.width);
        let bound = self.bound - self.to_goal.at(hood, r, c);
        let d = match self.tree.closed_g(r, c) {
            Some(g) => g.min(bound),
            None => bound,
        };
        self.scale * d
    }

    /// Bytes held per (padded) cell.
    pub(crate) const BYTES_PER_CELL: usize = SearchTree::BYTES_PER_CELL;
}

/// D* Lite's heuristic for one start `s`: the octile bound, and with a
/// landmark max(octile(s, u), D(u) − D(s)).
#[derive(Clone)]
pub(crate) struct StartHeuristic {
    octile: Heuristic,
    /// The landmark, and D(s).
    landmark: Option<(Arc<Landmark>, f64)>,
}

impl StartHeuristic {
    pub(crate) fn new(
        hood: &Neighbourhood,
        start: usize,
        factor: f64,
        landmark: Option<&Arc<Landmark>>,
    ) -> StartHeuristic {
        StartHeuristic {
            octile: Heuristic::new(hood, start, factor),
            landmark: landmark.map(|l| (l.clone(), l.value(hood, start))),
        }
    }

    #[inline]
    pub(crate) fn at(&self, hood: &Neighbourhood, i: usize) -> f64 {
        let h = self.octile.at_index(hood, i);
        match &self.landmark {
            Some((landmark, at_start)) => h.max(landmark.value(hood, i) - at_start),
            None => h,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::arc_model::ArcModel;
    use crate::route::astar::search_tree;
    use crate::route::testing::{Rng, dijkstra, random_endpoints, random_grid};
    use crate::route::{ArcCost, CostGrid, RouteOptions};

    fn landmark_of(grid: &CostGrid, arc: ArcCost, start: usize, goal: usize) -> Option<Landmark> {
        let hood = Neighbourhood::new(grid);
        let model = ArcModel::new(arc, grid.finite_cost_range());
        let options = RouteOptions::default();
        let (_, _, tree) =
            search_tree(grid, &hood, &model, (start, goal), &options, &|| false).ok()?;
        let factor = model.heuristic_factor();
        Landmark::new(tree, &hood, goal, factor, hood.shortest_step() * factor)
    }

    /// The two properties D* Lite relies on, on random grids with both arc
    /// rules: D(v) ≤ D(u) + c(u, v) on every move, exactly in floating
    /// point (consistency), and D(u) − D(s) ≤ the cheapest cost from s to
    /// u for any s (admissibility, against the reference Dijkstra).
    #[test]
    fn landmark_is_consistent_and_admissible() {
        let mut rng = Rng::new(41);
        let mut checked = 0;
        for trial in 0..120 {
            let (w, h) = (5 + rng.below(40) as usize, 5 + rng.below(40) as usize);
            let grid = random_grid(&mut rng, w, h, [0.0, 0.15, 0.3][trial % 3], trial % 2 == 0);
            let Some(((sr, sc), (gr, gc))) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let arc = if trial % 4 == 3 {
                ArcCost::thesis()
            } else {
                ArcCost::Integrated
            };
            let (s, g) = (sr * w + sc, gr * w + gc);
            if s == g {
                continue;
            }
            let Some(landmark) = landmark_of(&grid, arc, s, g) else {
                continue;
            };
            let hood = Neighbourhood::new(&grid);
            let model = ArcModel::new(arc, grid.finite_cost_range());
            let costs = grid.costs();
            for u in 0..w * h {
                let mut moves = hood.moves(costs, u, u / w, u % w);
                while moves != 0 {
                    let d = moves.trailing_zeros() as usize;
                    moves &= moves - 1;
                    let v = hood.neighbour(u, d);
                    let arc_cost = model.arc(hood.step_len(u / w, d), costs[u], costs[v]);
                    assert!(
                        landmark.value(&hood, v) <= landmark.value(&hood, u) + arc_cost,
                        "trial {trial}: move {u} -> {v}"
                    );
                }
            }
            for _ in 0..5 {
                let Some((a, b)) = random_endpoints(&mut rng, &grid) else {
                    continue;
                };
                let Some(best) = dijkstra(&grid, a, b, arc) else {
                    continue;
                };
                let (ia, ib) = (a.0 * w + a.1, b.0 * w + b.1);
                let bound = landmark.value(&hood, ib) - landmark.value(&hood, ia);
                assert!(
                    bound <= best + 1e-9 * best,
                    "trial {trial}: {bound} > {best}"
                );
                checked += 1;
            }
        }
        assert!(checked > 300, "{checked}");
    }

    #[test]
    fn landmark_is_exact_along_the_route() {
        // On the route the landmark is the cost from the start (less λ).
        let mut rng = Rng::new(2);
        let grid = crate::route::testing::smooth_costmap(&mut rng, 120, 90, 0.05);
        let (start, goal) = crate::route::testing::far_corners(&grid);
        let w = grid.width();
        let (s, g) = (start.0 * w + start.1, goal.0 * w + goal.1);
        let landmark = landmark_of(&grid, ArcCost::Integrated, s, g).unwrap();
        let hood = Neighbourhood::new(&grid);
        let route =
            crate::route::astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
        let model = ArcModel::new(ArcCost::Integrated, grid.finite_cost_range());
        let mut cost = 0.0;
        for pair in route.cells.windows(2) {
            let (a, b) = (pair[0].0 * w + pair[0].1, pair[1].0 * w + pair[1].1);
            let d = hood.direction(a, b).unwrap();
            cost += model.arc(hood.step_len(a / w, d), grid.costs()[a], grid.costs()[b]);
            let value = landmark.value(&hood, b);
            assert!(
                (value - cost).abs() <= 1e-6 * route.cost,
                "{value} vs {cost}"
            );
        }
    }
}
