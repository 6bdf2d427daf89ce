//! Arc costs ([`ArcCost`]) evaluated for one grid, and the heuristic that
//! stays admissible under them.

use super::ArcCost;
use super::neighbourhood::Neighbourhood;

/// An [`ArcCost`] rule bound to the cost range it normalises with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ArcModel {
    rule: Rule,
    /// Smallest finite cost the model was built for.
    min_cost: f32,
    /// Largest finite cost the model was built for.
    max_cost: f32,
}

/// The arc rule alone, for searches that specialise their inner loop on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Rule {
    Integrated(IntegratedArc),
    Thesis(ThesisArc),
}

/// One arc cost rule.
pub(crate) trait ArcRule: Copy {
    /// Cost of a step of `len` metres from a cell of cost `from` to one of
    /// cost `to` (both finite).
    fn arc(self, len: f64, from: f32, to: f32) -> f64;
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct IntegratedArc;

impl ArcRule for IntegratedArc {
    #[inline]
    fn arc(self, len: f64, from: f32, to: f32) -> f64 {
        len * (0.5 * (f64::from(from) + f64::from(to)))
    }
}

/// Algorithm 1's factor c ∈ [1, d_max]: δ = to − from shifted by the range
/// R into [0, 2R], normalised to [0, 1] and remapped onto [1, d_max].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ThesisArc {
    d_max: f64,
    range: f64,
}

impl ArcRule for ThesisArc {
    #[inline]
    fn arc(self, len: f64, from: f32, to: f32) -> f64 {
        let t = if self.range > 0.0 {
            (f64::from(to) - f64::from(from) + self.range) / (2.0 * self.range)
        } else {
            0.5
        };
        // The clamp only absorbs rounding: t ∈ [0, 1] for costs in the range.
        len * (1.0 + (self.d_max - 1.0) * t).clamp(1.0, self.d_max)
    }
}

impl ArcModel {
    /// The model for costs in `range` (min, max of the finite costs; `None`
    /// when nothing is traversable).
    pub(crate) fn new(arc: ArcCost, range: Option<(f32, f32)>) -> ArcModel {
        let (min_cost, max_cost) = range.unwrap_or((1.0, 1.0));
        let rule = match arc {
            ArcCost::Integrated => Rule::Integrated(IntegratedArc),
            ArcCost::Thesis { d_max } => Rule::Thesis(ThesisArc {
                d_max,
                range: f64::from(max_cost) - f64::from(min_cost),
            }),
        };
        ArcModel {
            rule,
            min_cost,
            max_cost,
        }
    }

    /// Cost of a step of `len` metres from a cell of cost `from` to one of
    /// cost `to` (both finite).
    #[inline]
    pub(crate) fn arc(&self, len: f64, from: f32, to: f32) -> f64 {
        match self.rule {
            Rule::Integrated(rule) => rule.arc(len, from, to),
            Rule::Thesis(rule) => rule.arc(len, from, to),
        }
    }

    pub(crate) fn rule(&self) -> Rule {
        self.rule
    }

    /// The smallest arc cost per metre: the heuristic's scale.
    pub(crate) fn heuristic_factor(&self) -> f64 {
        match self.rule {
            Rule::Integrated(_) => f64::from(self.min_cost),
            Rule::Thesis(_) => 1.0,
        }
    }

    /// The largest arc cost per metre.
    pub(crate) fn largest_factor(&self) -> f64 {
        match self.rule {
            Rule::Integrated(_) => f64::from(self.max_cost),
            Rule::Thesis(rule) => rule.d_max,
        }
    }

    pub(crate) fn is_thesis(&self) -> bool {
        matches!(self.rule, Rule::Thesis(_))
    }
}

/// Octile distance to a target cell times a factor: with the factor at most
/// the smallest arc cost per metre it never overestimates and is consistent
/// (it is an exact distance on a relaxed graph), so A* closes each cell once.
#[derive(Clone)]
pub(crate) struct Heuristic {
    width: usize,
    target_row: usize,
    target_col: usize,
    factor: f64,
}

impl Heuristic {
    pub(crate) fn new(hood: &Neighbourhood, target: usize, factor: f64) -> Heuristic {
        Heuristic {
            width: hood.width(),
            target_row: target / hood.width(),
            target_col: target % hood.width(),
            factor,
        }
    }

    #[inline]
    pub(crate) fn at(&self, hood: &Neighbourhood, row: usize, col: usize) -> f64 {
        self.factor * hood.octile(row.abs_diff(self.target_row), col.abs_diff(self.target_col))
    }

    #[inline]
    pub(crate) fn at_index(&self, hood: &Neighbourhood, i: usize) -> f64 {
        self.at(hood, i / self.width, i % self.width)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::{Rng, random_grid};
    use crate::route::{CostGrid, RouteOptions, astar};

    #[test]
    fn thesis_factor_matches_the_thesis_numbers() {
        // Costs in [1, 20]: δ ∈ [−19, 19] → [1, 39] → [0, 1] → [1, 10].
        let m = ArcModel::new(ArcCost::thesis(), Some((1.0, 20.0)));
        assert!((m.arc(1.0, 20.0, 1.0) - 1.0).abs() < 1e-12);
        assert!((m.arc(1.0, 1.0, 20.0) - 10.0).abs() < 1e-12);
        assert!((m.arc(1.0, 7.0, 7.0) - 5.5).abs() < 1e-12);
        // δ + max = 1 + 20 = 21 sits at (21 − 1)/38 of [1, 39].
        let expected = 1.0 + 9.0 * (21.0 - 1.0) / 38.0;
        assert!((m.arc(1.0, 4.0, 5.0) - expected).abs() < 1e-12);
        assert!((m.arc(2.5, 4.0, 5.0) - 2.5 * expected).abs() < 1e-12);
        assert_eq!(m.heuristic_factor(), 1.0);
        // Uniform map: the midpoint.
        let flat = ArcModel::new(ArcCost::Thesis { d_max: 3.0 }, Some((2.0, 2.0)));
        assert_eq!(flat.arc(1.0, 2.0, 2.0), 2.0);
        // c ∈ [1, d_max] on any pair of costs in range.
        let mut rng = Rng::new(3);
        let m = ArcModel::new(ArcCost::Thesis { d_max: 7.0 }, Some((0.25, 3.0)));
        for _ in 0..10_000 {
            let (a, b) = (rng.range_f32(0.25, 3.0), rng.range_f32(0.25, 3.0));
            let c = m.arc(1.0, a, b);
            assert!((1.0..=7.0).contains(&c), "{a} {b} {c}");
        }
    }

    #[test]
    fn integrated_is_the_mean_cost_times_length() {
        let m = ArcModel::new(ArcCost::Integrated, Some((1.0, 20.0)));
        assert_eq!(m.arc(2.0, 1.0, 4.0), 5.0);
        assert_eq!(m.heuristic_factor(), 1.0);
        let m = ArcModel::new(ArcCost::Integrated, Some((1.5, 20.0)));
        assert_eq!(m.heuristic_factor(), 1.5);
    }

    /// The step lengths of a random 8-connected walk (no obstacles needed:
    /// this is about the arc rule, not the search).
    fn random_walk(rng: &mut Rng, grid: &CostGrid, steps: usize) -> Vec<(usize, usize)> {
        let (h, w) = (grid.height() as isize, grid.width() as isize);
        let mut cell = (rng.below(h as u64) as isize, rng.below(w as u64) as isize);
        let mut walk = vec![(cell.0 as usize, cell.1 as usize)];
        // Persist in a direction for a while, like real routes do.
        let mut dir = (1isize, 1isize);
        while walk.len() <= steps {
            if rng.below(4) == 0 {
                dir = crate::route::neighbourhood::DIRECTIONS[rng.below(8) as usize];
            }
            let next = (cell.0 + dir.0, cell.1 + dir.1);
            if next.0 < 0 || next.0 >= h || next.1 < 0 || next.1 >= w {
                dir = (-dir.0, -dir.1);
                continue;
            }
            cell = next;
            walk.push((cell.0 as usize, cell.1 as usize));
        }
        walk
    }

    fn step_len(grid: &CostGrid, a: (usize, usize), b: (usize, usize)) -> f64 {
        match (a.0 != b.0, a.1 != b.1) {
            (false, true) => grid.dx(a.0),
            (true, false) => grid.dy(),
            _ => (0.5 * (grid.dx(a.0) + grid.dx(b.0))).hypot(grid.dy()),
        }
    }

    /// The telescoping of the thesis rule, checked numerically. For a path
    /// q_0 … q_n with steps L_1 … L_n, c = A + K·δ gives
    ///
    ///   cost = A·ΣL_i + K·ΣL_i(q_i − q_{i−1})
    ///        = A·ΣL_i + K·(L_n q_n − L_1 q_0 + Σ_{0<j<n} q_j (L_j − L_{j+1})),
    ///
    /// so interior cells count only where the step length changes. We check
    /// the identity on random walks over random grids, and that the
    /// interior ("steering") term is bounded by the number of length changes
    /// × max|ΔL|·max cost — not by the path length, as the integrated cost
    /// of the same cells is.
    #[test]
    fn thesis_cost_difference_telescopes_along_any_path() {
        let mut rng = Rng::new(42);
        let mut worst_ratio: f64 = 0.0;
        for trial in 0..300 {
            let grid = random_grid(&mut rng, 30, 30, 0.0, trial % 3 == 0);
            let (lo, hi) = grid.finite_cost_range().unwrap();
            if hi <= lo {
                continue;
            }
            let d_max = 1.0 + 20.0 * rng.unit();
            let model = ArcModel::new(ArcCost::Thesis { d_max }, Some((lo, hi)));
            let (a, k) = (
                0.5 * (1.0 + d_max),
                (d_max - 1.0) / (2.0 * (f64::from(hi) - f64::from(lo))),
            );
            let steps = 20 + rng.below(200) as usize;
            let walk = random_walk(&mut rng, &grid, steps);
            let q = |c: (usize, usize)| f64::from(grid.cost(c).unwrap());
            let lens: Vec<f64> = walk
                .windows(2)
                .map(|p| step_len(&grid, p[0], p[1]))
                .collect();
            let cost: f64 = walk
                .windows(2)
                .zip(&lens)
                .map(|(p, &l)| model.arc(l, grid.cost(p[0]).unwrap(), grid.cost(p[1]).unwrap()))
                .sum();
            let length: f64 = lens.iter().sum();
            let n = lens.len();
            let endpoints = lens[n - 1] * q(walk[n]) - lens[0] * q(walk[0]);
            let interior: f64 = (1..n).map(|j| q(walk[j]) * (lens[j - 1] - lens[j])).sum();
            let identity = a * length + k * (endpoints + interior);
            assert!(
                (cost - identity).abs() <= 1e-9 * cost,
                "trial {trial}: {cost} vs {identity}"
            );
            // The steering term only picks up cells where the step changes.
            let changes = (1..n).filter(|&j| lens[j - 1] != lens[j]).count();
            let max_jump = (1..n)
                .map(|j| (lens[j - 1] - lens[j]).abs())
                .fold(0.0, f64::max);
            assert!(interior.abs() <= changes as f64 * max_jump * f64::from(hi) + 1e-9);
            // Against the length term, the steering term is small.
            worst_ratio = worst_ratio.max(k * interior.abs() / (a * length));
            // A straight run telescopes exactly to its end points.
            let straight: Vec<(usize, usize)> = (0..grid.width()).map(|c| (3, c)).collect();
            let s: f64 = straight
                .windows(2)
                .map(|p| {
                    model.arc(
                        grid.dx(3),
                        grid.cost(p[0]).unwrap(),
                        grid.cost(p[1]).unwrap(),
                    )
                })
                .sum();
            let l = grid.dx(3) * (grid.width() - 1) as f64;
            let ends = grid.dx(3) * (q(*straight.last().unwrap()) - q(straight[0]));
            assert!(
                (s - (a * l + k * ends)).abs() <= 1e-9 * s,
                "{s} {} {a} {k} {l} {ends}",
                a * l + k * ends
            );
        }
        // Random costs, frequent turns: the cells' costs still move the total
        // by under a tenth of what the length alone costs (about 4 % here).
        // (The integrated rule's cost term is the whole cost.)
        assert!(worst_ratio < 0.1, "{worst_ratio}");
    }

    /// What the telescoping means for routes: a band of the most expensive
    /// traversable cost across the map, with a cheap gap far to the side.
    /// The integrated rule detours through the gap; the thesis rule crosses
    /// the band, its route as short as the shortest traversable path.
    #[test]
    fn thesis_routes_barely_steer_away_from_costly_cells() {
        let (w, h) = (41, 41);
        let mut costs = vec![1.0f32; w * h];
        for r in 15..26 {
            for c in 0..w {
                costs[r * w + c] = if c >= 38 { 1.0 } else { 20.0 };
            }
        }
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        let (start, goal) = ((0, 5), (40, 5));
        let integrated = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
        let thesis = astar(
            &grid,
            start,
            goal,
            &RouteOptions {
                arc_cost: ArcCost::thesis(),
                ..RouteOptions::default()
            },
            &|| false,
        )
        .unwrap();
        let crosses_band =
            |cells: &[(usize, usize)]| cells.iter().any(|&(r, c)| (15..26).contains(&r) && c < 38);
        assert!(!crosses_band(&integrated.cells));
        assert!(crosses_band(&thesis.cells));
        assert!((thesis.length_m - 40.0).abs() < 1e-9, "{}", thesis.length_m);
        assert!(integrated.length_m > 70.0);

        // On random maps without obstacles, thesis routes stay within 1 % of
        // the straight-line (octile) length (about 0.2 % here); integrated
        // routes detour for cheaper ground (about 16 % longer).
        let mut rng = Rng::new(9);
        let (mut thesis_excess, mut integrated_excess) = (0.0, 0.0);
        for _ in 0..40 {
            let grid = random_grid(&mut rng, 40, 40, 0.0, false);
            let start = (rng.below(40) as usize, rng.below(5) as usize);
            let goal = (rng.below(40) as usize, 35 + rng.below(5) as usize);
            let (rows, cols) = (start.0.abs_diff(goal.0), start.1.abs_diff(goal.1));
            let octile =
                (rows.max(cols) - rows.min(cols)) as f64 + rows.min(cols) as f64 * 2f64.sqrt();
            let opts = |arc_cost| RouteOptions {
                arc_cost,
                ..RouteOptions::default()
            };
            let t = astar(&grid, start, goal, &opts(ArcCost::thesis()), &|| false).unwrap();
            let i = astar(&grid, start, goal, &opts(ArcCost::Integrated), &|| false).unwrap();
            thesis_excess += t.length_m / octile - 1.0;
            integrated_excess += i.length_m / octile - 1.0;
        }
        thesis_excess /= 40.0;
        integrated_excess /= 40.0;
        assert!(thesis_excess < 0.01, "thesis {thesis_excess}");
        assert!(
            integrated_excess > 10.0 * thesis_excess,
            "integrated {integrated_excess} vs thesis {thesis_excess}"
        );
    }
}
