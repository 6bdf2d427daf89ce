//! Post-smoothing: turn a cell path into a few waypoints.
//!
//! Straight segments between cell centres are measured by their *line
//! integral*: Σ over the cells the segment crosses of (length inside the
//! cell × cell cost), found by an exact grid traversal ([`segment_cost`]).
//! A cell step's line integral is exactly its `integrated` arc cost (half
//! the step in each cell; a diagonal crosses the shared corner), so the
//! same rule measures the cell path and its shortcuts.
//!
//! [`smooth_path`] first drops the cells inside straight runs (lossless),
//! then pulls the string greedily: from each waypoint it takes the farthest
//! later turning point it can reach by one segment that crosses only
//! traversable cells — passing exactly through a grid corner needs all four
//! cells there traversable, the segment version of "no corner cutting" —
//! and whose line integral is not higher than that of the path section it
//! replaces. Hence the smoothed polyline never costs more than the cell
//! path, and `Route::waypoints_cost` is this line integral.
//!
//! On grids with a different dx per row the length of a piece inside a
//! cell uses that cell's row width; a UTM grid (one dx) gives plain
//! Euclidean lengths.

use super::{Cell, CostGrid};

/// Line integral of cost and length in metres of a segment or polyline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentCost {
    pub cost: f64,
    pub length_m: f64,
}

/// The straight segment between the centres of `a` and `b`: its line
/// integral of cost and its length, or `None` when it leaves the grid,
/// crosses a blocked cell or passes a grid corner next to a blocked cell.
pub fn segment_cost(grid: &CostGrid, a: Cell, b: Cell) -> Option<SegmentCost> {
    if !grid.contains(a) || !grid.contains(b) {
        return None;
    }
    let costs = grid.costs();
    let width = grid.width();
    let (dr, dc) = (b.0 as i64 - a.0 as i64, b.1 as i64 - a.1 as i64);
    let (rows, cols) = (dr.unsigned_abs(), dc.unsigned_abs());
    let (step_r, step_c) = (dr.signum() as isize, dc.signum() as isize);
    // The whole segment's length measured with row r's cell width.
    let row_length = |r: usize| (cols as f64 * grid.dx(r)).hypot(rows as f64 * grid.dy());
    let (mut r, mut c) = a;
    let (mut crossed_cols, mut crossed_rows) = (0u64, 0u64);
    let mut t_prev = 0.0;
    let mut total = SegmentCost {
        cost: 0.0,
        length_m: 0.0,
    };
    loop {
        // From a centre, the k-th vertical grid line is crossed at
        // t = (2k + 1) / (2·cols), the k-th horizontal one at
        // (2k + 1) / (2·rows); compare them exactly in integers.
        let col_next = crossed_cols < cols;
        let row_next = crossed_rows < rows;
        let order = match (col_next, row_next) {
            (false, false) => None,
            (true, false) => Some(std::cmp::Ordering::Less),
            (false, true) => Some(std::cmp::Ordering::Greater),
            (true, true) => {
                Some(((2 * crossed_cols + 1) * rows).cmp(&((2 * crossed_rows + 1) * cols)))
            }
        };
        let t = match order {
            None => 1.0,
            Some(std::cmp::Ordering::Greater) => (2 * crossed_rows + 1) as f64 / (2 * rows) as f64,
            Some(_) => (2 * crossed_cols + 1) as f64 / (2 * cols) as f64,
        };
        let cost = costs[r * width + c];
        if !cost.is_finite() {
            return None;
        }
        let piece = (t - t_prev) * row_length(r);
        total.cost += piece * f64::from(cost);
        total.length_m += piece;
        t_prev = t;
        match order {
            None => return Some(total),
            Some(std::cmp::Ordering::Less) => {
                c = c.wrapping_add_signed(step_c);
                crossed_cols += 1;
            }
            Some(std::cmp::Ordering::Greater) => {
                r = r.wrapping_add_signed(step_r);
                crossed_rows += 1;
            }
            Some(std::cmp::Ordering::Equal) => {
                // Through a grid corner: the two side cells are touched too.
                let (nr, nc) = (r.wrapping_add_signed(step_r), c.wrapping_add_signed(step_c));
                if !costs[r * width + nc].is_finite() || !costs[nr * width + c].is_finite() {
                    return None;
                }
                (r, c) = (nr, nc);
                crossed_cols += 1;
                crossed_rows += 1;
            }
        }
    }
}

/// Line integral and length of a polyline through cell centres, `None` if
/// any segment is not traversable ([`segment_cost`]).
pub fn polyline_cost(grid: &CostGrid, points: &[Cell]) -> Option<SegmentCost> {
    let mut total = SegmentCost {
        cost: 0.0,
        length_m: 0.0,
    };
    if let Some(&first) = points.first()
        && !grid.is_traversable(first)
    {
        return None;
    }
    for p in points.windows(2) {
        let s = segment_cost(grid, p[0], p[1])?;
        total.cost += s.cost;
        total.length_m += s.length_m;
    }
    Some(total)
}

/// The same polyline without repeated points and without points inside
/// straight runs (lossless): first, last and every turn.
pub fn turning_points(cells: &[Cell]) -> Vec<Cell> {
    let mut out: Vec<Cell> = Vec::with_capacity(cells.len().min(64));
    for &p in cells {
        if out.last() == Some(&p) {
            continue;
        }
        if let [.., a, b] = out[..] {
            let (ux, uy) = (b.1 as i64 - a.1 as i64, b.0 as i64 - a.0 as i64);
            let (vx, vy) = (p.1 as i64 - b.1 as i64, p.0 as i64 - b.0 as i64);
            if ux * vy == uy * vx && ux * vx + uy * vy > 0 {
                out.pop();
            }
        }
        out.push(p);
    }
    out
}

/// Smoothed waypoints for a cell path (see the module docs): a
/// subsequence of `cells` from the first to the last cell whose polyline
/// crosses only traversable cells and costs no more than `cells` (line
/// integrals). `cells` should be a route's path (traversable steps); if a
/// step is not, the turning points are returned unsmoothed.
pub fn smooth_path(grid: &CostGrid, cells: &[Cell]) -> Vec<Cell> {
    let points = turning_points(cells);
    if points.len() <= 2 {
        return points;
    }
    let Some(pieces) = points
        .windows(2)
        .map(|p| segment_cost(grid, p[0], p[1]).map(|s| s.cost))
        .collect::<Option<Vec<f64>>>()
    else {
        return points;
    };
    let last = points.len() - 1;
    let mut out = vec![points[0]];
    let mut anchor = 0;
    while anchor < last {
        // The next turning point is always reachable: it is the path itself.
        let mut best = anchor + 1;
        let mut section = pieces[anchor];
        for b in anchor + 2..=last {
            section += pieces[b - 1];
            match segment_cost(grid, points[anchor], points[b]) {
                // "Not higher", allowing only for rounding.
                Some(s) if s.cost <= section * (1.0 + 1e-12) => best = b,
                _ => break,
            }
        }
        out.push(points[best]);
        anchor = best;
    }
    turning_points(&out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::{Rng, random_endpoints, random_grid, segment_touches_blocked};
    use crate::route::{ArcCost, RouteOptions, astar};

    const X: f32 = f32::NAN;

    fn unit_grid(width: usize, height: usize, costs: Vec<f32>) -> CostGrid {
        CostGrid::with_cell_size(width, height, costs, 1.0, 1.0).unwrap()
    }

    #[test]
    fn segment_cost_is_the_line_integral() {
        // Horizontal across three cells: half of the first, all of the
        // middle, half of the last.
        let g = CostGrid::with_cell_size(3, 1, vec![1.0, 2.0, 4.0], 2.0, 1.0).unwrap();
        let s = segment_cost(&g, (0, 0), (0, 2)).unwrap();
        assert!((s.length_m - 4.0).abs() < 1e-12);
        assert!((s.cost - (1.0 * 1.0 + 2.0 * 2.0 + 1.0 * 4.0)).abs() < 1e-12);
        // A knight's move (1 row, 2 cols) in unit cells: length √5, a
        // quarter of it in each of (0,0), (0,1), (1,1) and (1,2).
        let g = unit_grid(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let s = segment_cost(&g, (0, 0), (1, 2)).unwrap();
        let l = 5f64.sqrt();
        assert!((s.length_m - l).abs() < 1e-12);
        assert!((s.cost - l * (0.25 * 1.0 + 0.25 * 2.0 + 0.25 * 5.0 + 0.25 * 6.0)).abs() < 1e-12);
        // Same cell: zero.
        assert_eq!(
            segment_cost(&g, (1, 1), (1, 1)),
            Some(SegmentCost {
                cost: 0.0,
                length_m: 0.0
            })
        );
        assert_eq!(segment_cost(&g, (1, 1), (2, 1)), None, "outside");
        // Direction does not matter.
        let back = segment_cost(&g, (1, 2), (0, 0)).unwrap();
        assert!((back.cost - s.cost).abs() < 1e-12);
    }

    #[test]
    fn a_step_costs_its_integrated_arc() {
        let g = CostGrid::new(2, 2, vec![1.0, 3.0, 5.0, 7.0], vec![2.0, 2.0], 3.0).unwrap();
        let diag = 13f64.sqrt();
        let s = segment_cost(&g, (0, 0), (1, 1)).unwrap();
        assert!((s.cost - diag * (1.0 + 7.0) / 2.0).abs() < 1e-12);
        let s = segment_cost(&g, (0, 1), (1, 1)).unwrap();
        assert!((s.cost - 3.0 * (3.0 + 7.0) / 2.0).abs() < 1e-12);
    }

    #[test]
    fn corners_and_obstacles_block_segments() {
        #[rustfmt::skip]
        let g = unit_grid(3, 3, vec![
            1.0, X,   1.0,
            1.0, 1.0, 1.0,
            1.0, 1.0, 1.0,
        ]);
        assert_eq!(
            segment_cost(&g, (0, 0), (0, 2)),
            None,
            "through the obstacle"
        );
        assert_eq!(segment_cost(&g, (1, 0), (0, 1)), None, "ends on it");
        assert_eq!(segment_cost(&g, (0, 0), (1, 1)), None, "cuts its corner");
        assert_eq!(segment_cost(&g, (2, 0), (0, 2)), None, "passes its corner");
        assert!(segment_cost(&g, (2, 0), (1, 2)).is_some());
        assert!(segment_cost(&g, (0, 0), (2, 0)).is_some());
    }

    #[test]
    fn turning_points_are_lossless() {
        let cells = [
            (0, 0),
            (0, 1),
            (0, 2),
            (1, 3),
            (2, 4),
            (2, 4),
            (3, 4),
            (4, 4),
        ];
        assert_eq!(turning_points(&cells), vec![(0, 0), (0, 2), (2, 4), (4, 4)]);
        assert_eq!(turning_points(&[(1, 1)]), vec![(1, 1)]);
        assert!(turning_points(&[]).is_empty());
        // Going back on itself is a turn.
        assert_eq!(
            turning_points(&[(0, 0), (0, 1), (0, 0)]),
            vec![(0, 0), (0, 1), (0, 0)]
        );
    }

    #[test]
    fn shortcuts_only_when_not_costlier() {
        // A cheap corridor along the edge of an expensive field: cutting the
        // corner through the field would be shorter but costlier.
        let (w, h) = (12, 12);
        let mut costs = vec![20.0f32; w * h];
        for i in 0..w {
            costs[i] = 1.0; // top row
            costs[i * w + (w - 1)] = 1.0; // right column
        }
        let g = unit_grid(w, h, costs);
        let route = astar(&g, (0, 0), (11, 11), &RouteOptions::default(), &|| false).unwrap();
        // The path turns diagonally at the corner, (0,10) → (1,11). No
        // shortcut may cross the expensive field: (0,10) → (11,11) would
        // run half its length in column 10.
        assert_eq!(route.waypoints, vec![(0, 0), (0, 10), (1, 11), (11, 11)]);
        assert!((route.waypoints_cost - route.cost).abs() < 1e-9);
        // On uniform ground the same cells are shortcut to one segment.
        let flat = unit_grid(w, h, vec![1.0; w * h]);
        let path: Vec<Cell> = (0..12)
            .map(|c| (0, c))
            .chain((1..12).map(|r| (r, 11)))
            .collect();
        assert_eq!(smooth_path(&flat, &path), vec![(0, 0), (11, 11)]);
    }

    #[test]
    fn smoothing_never_costs_more_nor_touches_obstacles() {
        let mut rng = Rng::new(21);
        let (mut fewer, mut routes) = (0, 0);
        for trial in 0..400 {
            let density = [0.0, 0.1, 0.2, 0.35][trial % 4];
            let (w, h) = (10 + rng.below(40) as usize, 10 + rng.below(40) as usize);
            let g = random_grid(&mut rng, w, h, density, trial % 2 == 0);
            let Some((start, goal)) = random_endpoints(&mut rng, &g) else {
                continue;
            };
            let arc = if trial % 3 == 0 {
                ArcCost::thesis()
            } else {
                ArcCost::Integrated
            };
            let opts = RouteOptions {
                arc_cost: arc,
                ..RouteOptions::default()
            };
            let Ok(route) = astar(&g, start, goal, &opts, &|| false) else {
                continue;
            };
            routes += 1;
            let raw = polyline_cost(&g, &route.cells).unwrap();
            let smooth = polyline_cost(&g, &route.waypoints).unwrap();
            assert!(smooth.cost <= raw.cost * (1.0 + 1e-9), "trial {trial}");
            assert!((smooth.cost - route.waypoints_cost).abs() <= 1e-9 * raw.cost.max(1.0));
            assert_eq!(route.waypoints.first(), route.cells.first());
            assert_eq!(route.waypoints.last(), route.cells.last());
            // A subsequence of the cells, in order.
            let mut it = route.cells.iter();
            for w in &route.waypoints {
                assert!(it.any(|c| c == w), "trial {trial}: {w:?} not in order");
            }
            for p in route.waypoints.windows(2) {
                assert!(
                    !segment_touches_blocked(&g, p[0], p[1]),
                    "trial {trial}: {:?} → {:?} touches an obstacle",
                    p[0],
                    p[1]
                );
            }
            if route.waypoints.len() < turning_points(&route.cells).len() {
                fewer += 1;
            }
        }
        assert!(routes > 250 && fewer * 2 > routes, "{fewer} of {routes}");
    }

    #[test]
    fn smoothing_is_lossless_geometry_when_off() {
        let mut rng = Rng::new(4);
        let g = random_grid(&mut rng, 30, 30, 0.1, false);
        let (start, goal) = random_endpoints(&mut rng, &g).unwrap();
        let o = RouteOptions {
            smooth: false,
            ..RouteOptions::default()
        };
        if let Ok(route) = astar(&g, start, goal, &o, &|| false) {
            assert_eq!(route.waypoints, turning_points(&route.cells));
            assert!((route.waypoints_cost - route.cost).abs() <= 1e-9 * route.cost.max(1.0));
        }
    }
}
