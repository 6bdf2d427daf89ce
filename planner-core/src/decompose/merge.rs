//! Joins boustrophedon cells that one sweep of lanes flies as one: cells
//! that meet on a slice line and whose lanes, laid across the slice, run on
//! through both (issue 21: fewer, longer lanes). Works in the slice frame on
//! the sweep's cells, before lanes are laid.
//!
//! A chain of cells, each meeting the next on a slice line, is still met by
//! every slice line in one segment and is a simple polygon, so it is a cell
//! like any other. A chain grows while lanes across the slice (along the
//! sweep), spaced as the survey spaces them, run on through the whole chain
//! from end to end (each lies between the highest point of the chain's
//! lower boundary and the lowest of its upper one) and are fewer than the
//! lanes its parts need on their own (each the fewer of its lanes along the
//! slice and, where they run through it, across it). Those lanes cover the
//! whole chain, so a joined cell is flown with them (another layout of as
//! many lanes could leave a corner out where its lane ends are clipped).

use geo_types::Coord;

use super::sweep::{Cell, Swept};

/// Where a cell lies along the sweep (`x`), how far along the slice it
/// reaches (`ext`), and the band every slice line of it covers (`core`:
/// from the highest point of its lower boundary to the lowest of its upper
/// one; empty when `core.0 > core.1`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Span {
    x: (f64, f64),
    ext: (f64, f64),
    core: (f64, f64),
}

impl Span {
    fn of(cell: &Cell) -> Span {
        let min = |c: &[Coord<f64>]| c.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let max = |c: &[Coord<f64>]| c.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
        let x = |c: Option<&Coord<f64>>| c.map_or(f64::NAN, |p| p.x);
        Span {
            x: (x(cell.lower.first()), x(cell.lower.last())),
            ext: (min(&cell.lower), max(&cell.upper)),
            core: (max(&cell.lower), min(&cell.upper)),
        }
    }

    fn join(self, other: Span) -> Span {
        Span {
            x: (self.x.0.min(other.x.0), self.x.1.max(other.x.1)),
            ext: (self.ext.0.min(other.ext.0), self.ext.1.max(other.ext.1)),
            core: (self.core.0.max(other.core.0), self.core.1.min(other.core.1)),
        }
    }

    /// The fewest lanes at most `spacing` apart that fly the cell on its
    /// own: along the slice, or across it where [`Span::lanes_cross`].
    fn lanes(&self, spacing: f64, eps: f64) -> usize {
        let along = lane_count(self.x.1 - self.x.0, spacing);
        if self.lanes_cross(spacing, eps) {
            along.min(lane_count(self.ext.1 - self.ext.0, spacing))
        } else {
            along
        }
    }

    /// Whether every lane across the slice (as many as [`lane_count`] of the
    /// extent, laid as a cell's lanes are) lies inside the core by more than
    /// `eps`, so that each crosses the whole cell in one piece.
    fn lanes_cross(&self, spacing: f64, eps: f64) -> bool {
        let h = self.ext.1 - self.ext.0;
        let (first, last) = if h <= spacing {
            let mid = (self.ext.0 + self.ext.1) / 2.0;
            (mid, mid)
        } else {
            (self.ext.0 + spacing / 2.0, self.ext.1 - spacing / 2.0)
        };
        first - self.core.0 > eps && self.core.1 - last > eps
    }
}

/// Lanes at most `spacing` apart over a width `w`: one in the middle of a
/// narrow cell, else the outer ones half a spacing inside.
fn lane_count(w: f64, spacing: f64) -> usize {
    if w <= spacing {
        1
    } else {
        // Not above the layout's count, whose rounding adds a tolerance.
        (w / spacing - 1e-9).ceil().max(2.0) as usize
    }
}

/// A growing chain of cells, by their ids in the sweep.
struct Chain {
    members: Vec<u32>,
    span: Span,
    /// The number of lanes its parts would be flown with on their own.
    parts_lanes: usize,
}

/// The cells of `swept` with every chain that lanes `spacing` apart fly as
/// one joined into one cell, in the order of their first cell, each with
/// whether it joins several. `eps` is the sweep's tolerance.
pub(crate) fn merge_cells(swept: Swept, spacing: f64, eps: f64) -> Vec<(Cell, bool)> {
    let Swept { cells, links } = swept;
    let n = cells.len();
    let spans: Vec<Span> = cells.iter().map(Span::of).collect();
    // The cells each cell meets on its left side, by cell.
    let mut left_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    for &(a, b) in &links {
        left_of[b as usize].push(a);
    }
    let mut chain_of: Vec<u32> = vec![u32::MAX; n];
    let mut chains: Vec<Chain> = Vec::new();
    // Cells open in sweep order, so a cell's left neighbours come first.
    for c in 0..n {
        let span = spans[c];
        let own = span.lanes(spacing, eps);
        let best =
            left_of[c]
                .iter()
                .map(|&a| (a, chain_of[a as usize]))
                // Only a chain's last cell may be continued, and only once.
                .filter(|&(a, k)| chains[k as usize].members.last() == Some(&a))
                .filter_map(|(_, k)| {
                    let chain = &chains[k as usize];
                    let joined = chain.span.join(span);
                    let across = lane_count(joined.ext.1 - joined.ext.0, spacing);
                    (joined.lanes_cross(spacing, eps) && across < chain.parts_lanes + own)
                        .then_some((joined.ext.1 - joined.ext.0, k, joined))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        match best {
            Some((_, k, joined)) => {
                let chain = &mut chains[k as usize];
                chain.members.push(c as u32);
                chain.span = joined;
                chain.parts_lanes += own;
                chain_of[c] = k;
            }
            None => {
                chain_of[c] = chains.len() as u32;
                chains.push(Chain {
                    members: vec![c as u32],
                    span,
                    parts_lanes: own,
                });
            }
        }
    }
    chains
        .into_iter()
        .map(|chain| {
            // Consecutive members meet on a slice line: their boundaries
            // join with a step along it, which the cell clean-up keeps
            // (or drops when the members' sides line up).
            let mut joined = Cell::default();
            let several = chain.members.len() > 1;
            for m in chain.members {
                let cell = &cells[m as usize];
                joined.lower.extend_from_slice(&cell.lower);
                joined.upper.extend_from_slice(&cell.upper);
            }
            (joined, several)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decompose::sweep::sweep_linked;

    fn ring(v: &[(f64, f64)]) -> Vec<Coord<f64>> {
        v.iter().map(|&(x, y)| Coord { x, y }).collect()
    }

    /// A 10 × 4 strip with a 1 wide hole from y = `y0` to `y1` in the
    /// middle: four cells (west, below, above, east of it).
    fn strip_with_hole(y0: f64, y1: f64) -> Vec<Vec<Coord<f64>>> {
        vec![
            ring(&[(0.0, 0.0), (10.0, 0.0), (10.0, 4.0), (0.0, 4.0)]),
            ring(&[(4.5, y0), (4.5, y1), (5.5, y1), (5.5, y0)]),
        ]
    }

    #[test]
    fn lane_counts() {
        assert_eq!(lane_count(3.0, 4.0), 1);
        assert_eq!(lane_count(4.0, 4.0), 1);
        assert_eq!(lane_count(4.1, 4.0), 2);
        assert_eq!(lane_count(8.0, 4.0), 2);
        assert_eq!(lane_count(8.1, 4.0), 3);
    }

    #[test]
    fn cells_crossed_by_the_same_lanes_are_joined() {
        let swept = sweep_linked(&strip_with_hole(3.0, 3.5), 1e-9).unwrap();
        assert_eq!(swept.cells.len(), 4);
        // West meets below and above, both meet east.
        let mut links = swept.links.clone();
        links.sort();
        assert_eq!(links, vec![(0, 1), (0, 2), (1, 3), (2, 3)]);
        // Spacing 4: one lane at y = 2 runs under the hole from the west
        // end to the east end: west, below and east are joined, the cell
        // above stays.
        let merged = merge_cells(swept.clone(), 4.0, 1e-9);
        assert_eq!(merged.len(), 2);
        let xs = |c: &Cell| (c.lower[0].x, c.lower.last().unwrap().x);
        assert_eq!(xs(&merged[0].0), (0.0, 10.0));
        assert_eq!(xs(&merged[1].0), (4.5, 5.5));
        assert_eq!((merged[0].1, merged[1].1), (true, false));
        // Spacing 1.4: the lanes from y = 0.7 to 3.3 do not all pass under
        // the hole: nothing is joined.
        assert_eq!(merge_cells(swept, 1.4, 1e-9).len(), 4);
        // A hole in the middle is in the way of the one lane at y = 2.
        let swept = sweep_linked(&strip_with_hole(1.5, 2.5), 1e-9).unwrap();
        assert_eq!(merge_cells(swept, 4.0, 1e-9).len(), 4);
    }
}
