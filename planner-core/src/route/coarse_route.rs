//! Where a big-map search looks first: A* over the block minima (each
//! block a cell of B × B cells' size, its least cost as its cost, lethal
//! blocks blocked), and the corridor of blocks within k blocks of that
//! coarse route. The coarse route only places the corridor; optimality is
//! proven by `coarse_bound`, not assumed from it. It is a sound test of
//! reachability though: consecutive cells of any fine path lie in equal or
//! 8-adjacent traversable blocks, and a fine diagonal step between blocks
//! passes two traversable cells of the blocks beside it, so no fine path
//! exists when no coarse one does.

use super::block_minima::BlockMinima;
use super::{CostGrid, RouteError, RouteOptions, astar};

/// The blocks (row-major indices) of the cheapest coarse route from the
/// block of `start` to the block of `goal`.
pub(crate) fn coarse_route(
    minima: &BlockMinima,
    dx_per_row: &[f64],
    dy: f64,
    start: (usize, usize),
    goal: (usize, usize),
    cancel: &dyn Fn() -> bool,
) -> Result<Vec<usize>, RouteError> {
    let b = minima.block;
    let height = dx_per_row.len();
    // A block row is as wide as its middle row's cells.
    let dx: Vec<f64> = (0..minima.down)
        .map(|br| b as f64 * dx_per_row[(br * b + b / 2).min(height - 1)])
        .collect();
    let grid = CostGrid::new(
        minima.across,
        minima.down,
        minima.min.clone(),
        dx,
        dy * b as f64,
    )
    .map_err(|_| RouteError::Unreachable)?;
    let options = RouteOptions {
        smooth: false,
        ..RouteOptions::default()
    };
    let s = (start.0 / b, start.1 / b);
    let g = (goal.0 / b, goal.1 / b);
    let route = astar(&grid, s, g, &options, cancel).map_err(|e| match e {
        // The endpoints' blocks hold the endpoints: never blocked.
        RouteError::StartBlocked { .. } | RouteError::GoalBlocked { .. } => RouteError::Unreachable,
        other => other,
    })?;
    Ok(route
        .cells
        .iter()
        .map(|&(r, c)| minima.index(r, c))
        .collect())
}

/// The corridor: traversable blocks within Chebyshev distance `halfwidth`
/// (in blocks) of a block of `route`, one flag per block.
pub(crate) fn corridor(minima: &BlockMinima, route: &[usize], halfwidth: usize) -> Vec<bool> {
    let (across, down) = (minima.across, minima.down);
    let mut marked = vec![false; across * down];
    for &b in route {
        marked[b] = true;
    }
    // Separable dilation: along rows, then along columns, each with a
    // running count of marked blocks in the window.
    let dilate = |src: &[bool], len: usize, lines: usize, at: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![false; across * down];
        for line in 0..lines {
            let mut prefix = vec![0u32; len + 1];
            for i in 0..len {
                prefix[i + 1] = prefix[i] + u32::from(src[at(line, i)]);
            }
            for i in 0..len {
                let lo = i.saturating_sub(halfwidth);
                let hi = (i + halfwidth + 1).min(len);
                out[at(line, i)] = prefix[hi] > prefix[lo];
            }
        }
        out
    };
    let rows = dilate(&marked, across, down, &|line, i| line * across + i);
    let both = dilate(&rows, down, across, &|line, i| i * across + line);
    both.iter()
        .enumerate()
        .map(|(b, &m)| m && !minima.is_lethal(b))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn minima(across: usize, down: usize, lethal: &[usize]) -> BlockMinima {
        let mut min = vec![1.0f32; across * down];
        for &b in lethal {
            min[b] = f32::NAN;
        }
        BlockMinima {
            block: 4,
            across,
            down,
            max: min.clone(),
            min,
        }
    }

    #[test]
    fn the_corridor_is_the_route_dilated_without_lethal_blocks() {
        let m = minima(10, 6, &[2 * 10 + 5]);
        let c = corridor(&m, &[2 * 10 + 3], 2);
        for r in 0..6 {
            for col in 0..10 {
                let inside = (0..=4).contains(&r) && (1..=5).contains(&col) && (r, col) != (2, 5);
                assert_eq!(c[r * 10 + col], inside, "({r}, {col})");
            }
        }
        assert!(corridor(&m, &[0], 100).iter().filter(|&&x| x).count() == 59);
    }

    #[test]
    fn coarse_route_goes_round_lethal_blocks_and_reports_unreachable() {
        // A wall of lethal blocks in column 4 with a gap in row 5.
        let wall: Vec<usize> = (0..5).map(|r| r * 10 + 4).collect();
        let m = minima(10, 6, &wall);
        let dx = vec![0.5; 24];
        let route = coarse_route(&m, &dx, 0.5, (0, 0), (0, 39), &|| false).unwrap();
        assert_eq!(route[0], 0);
        assert_eq!(*route.last().unwrap(), 9);
        assert!(route.contains(&(5 * 10 + 4)), "{route:?}");
        let closed: Vec<usize> = (0..6).map(|r| r * 10 + 4).collect();
        let m = minima(10, 6, &closed);
        assert_eq!(
            coarse_route(&m, &dx, 0.5, (0, 0), (0, 39), &|| false),
            Err(RouteError::Unreachable)
        );
    }
}
