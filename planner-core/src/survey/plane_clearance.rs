//! A raster of how far each spot keeps from the keep-out area, for a
//! plane's many short clearance checks: a segment far enough from every
//! obstacle is clear without asking the obstacle map; the rest are asked.

use std::f64::consts::SQRT_2;

use geo_types::{Coord, MultiPolygon};

use crate::costmap::distance::squared_distance_f32;

/// Most cells of the raster (4 MB of `f32`).
const MAX_CELLS: f64 = (1 << 20) as f64;
/// The finest cell, m.
const MIN_CELL_M: f64 = 1.0;
/// Cells of margin round the obstacles' box: a point off the raster keeps
/// at least this many cells from every obstacle.
const PAD_CELLS: usize = 4;

/// Distances from the keep-out area on a square grid. Every cell touched by
/// an obstacle's boundary or whose centre lies inside one is marked; for any
/// point `p`, the distance from `p` to the keep-out area is then at least
/// the distance between the centres of `p`'s cell and of the nearest marked
/// cell less a cell's diagonal (what [`ClearanceGrid::sure`] holds).
pub(super) struct ClearanceGrid {
    x0: f64,
    y0: f64,
    cell: f64,
    width: usize,
    height: usize,
    /// Per cell, a distance every point of it keeps from the keep-out area
    /// (≤ 0: none known).
    sure: Vec<f32>,
}

impl ClearanceGrid {
    /// The raster of `area`; `None` when it is empty.
    pub(super) fn new(area: &MultiPolygon<f64>) -> Option<ClearanceGrid> {
        // Each ring with the winding it adds inside itself: +1 for an
        // exterior, −1 for a hole, whichever way it runs.
        let rings: Vec<(&[Coord<f64>], i32)> = area
            .iter()
            .flat_map(|p| {
                std::iter::once((p.exterior(), 1)).chain(p.interiors().iter().map(|h| (h, -1)))
            })
            .filter(|(r, _)| r.0.len() >= 3)
            .map(|(r, role)| {
                let turning = if signed_area(&r.0) >= 0.0 { 1 } else { -1 };
                (r.0.as_slice(), role * turning)
            })
            .collect();
        let mut lo = Coord {
            x: f64::INFINITY,
            y: f64::INFINITY,
        };
        let mut hi = Coord {
            x: f64::NEG_INFINITY,
            y: f64::NEG_INFINITY,
        };
        for p in rings.iter().flat_map(|(r, _)| r.iter()) {
            lo = Coord {
                x: lo.x.min(p.x),
                y: lo.y.min(p.y),
            };
            hi = Coord {
                x: hi.x.max(p.x),
                y: hi.y.max(p.y),
            };
        }
        if !(lo.x.is_finite() && hi.x.is_finite() && lo.y.is_finite() && hi.y.is_finite()) {
            return None;
        }
        let span = hi - lo;
        let cell = ((span.x + 1.0) * (span.y + 1.0) / MAX_CELLS)
            .sqrt()
            .max(MIN_CELL_M);
        let width = (span.x / cell).ceil() as usize + 1 + 2 * PAD_CELLS;
        let height = (span.y / cell).ceil() as usize + 1 + 2 * PAD_CELLS;
        let mut grid = ClearanceGrid {
            x0: lo.x - PAD_CELLS as f64 * cell,
            y0: lo.y - PAD_CELLS as f64 * cell,
            cell,
            width,
            height,
            sure: Vec::new(),
        };
        let mut marked = vec![false; width * height];
        for (ring, _) in &rings {
            for (i, &p) in ring.iter().enumerate() {
                grid.mark_edge(&mut marked, p, ring[(i + 1) % ring.len()]);
            }
        }
        grid.fill_inside(&mut marked, &rings);
        let sq = squared_distance_f32(&marked, width, height, cell, cell);
        // A millimetre less, against rounding.
        let diagonal = cell * SQRT_2 + 1e-3;
        grid.sure = sq
            .into_iter()
            .map(|s| (f64::from(s).sqrt() - diagonal) as f32)
            .collect();
        Some(grid)
    }

    fn col(&self, x: f64) -> isize {
        ((x - self.x0) / self.cell).floor() as isize
    }

    fn row(&self, y: f64) -> isize {
        ((y - self.y0) / self.cell).floor() as isize
    }

    /// The raster's cell size, m.
    pub(super) fn cell(&self) -> f64 {
        self.cell
    }

    /// A distance `p` surely keeps from the keep-out area (≤ 0: unknown).
    pub(super) fn sure(&self, p: Coord<f64>) -> f64 {
        let (c, r) = (self.col(p.x), self.row(p.y));
        if c < 0 || r < 0 || c as usize >= self.width || r as usize >= self.height {
            // Off the raster: at least the margin from the obstacles' box.
            return if p.x.is_finite() && p.y.is_finite() {
                PAD_CELLS as f64 * self.cell
            } else {
                0.0
            };
        }
        f64::from(self.sure[r as usize * self.width + c as usize])
    }

    /// Is the segment `a`–`b` surely clear of the keep-out area? Points
    /// every cell or closer, each keeping more than half the gap to the
    /// next; `false` means "ask the obstacle map".
    pub(super) fn sure_clear(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        let d = b - a;
        let len = d.x.hypot(d.y);
        let n = (len / self.cell).ceil().max(1.0);
        let need = len / (2.0 * n);
        let n = n as usize;
        (0..=n).all(|k| self.sure(a + d * (k as f64 / n as f64)) > need)
    }

    /// Marks every cell the segment `p`–`q` touches, column by column.
    fn mark_edge(&self, marked: &mut [bool], p: Coord<f64>, q: Coord<f64>) {
        let (a, b) = if p.x <= q.x { (p, q) } else { (q, p) };
        let last_col = self.width as isize - 1;
        let (c0, c1) = (self.col(a.x).max(0), self.col(b.x).min(last_col));
        for c in c0..=c1 {
            let left = (self.x0 + c as f64 * self.cell).max(a.x);
            let right = (self.x0 + (c + 1) as f64 * self.cell).min(b.x);
            let y_at = |x: f64| {
                if b.x - a.x > 1e-12 {
                    a.y + (b.y - a.y) * ((x - a.x) / (b.x - a.x))
                } else {
                    a.y
                }
            };
            let (mut y_lo, mut y_hi) = (y_at(left), y_at(right));
            if b.x - a.x <= 1e-12 {
                (y_lo, y_hi) = (a.y, b.y);
            }
            if y_lo > y_hi {
                std::mem::swap(&mut y_lo, &mut y_hi);
            }
            let last_row = self.height as isize - 1;
            for r in self.row(y_lo).max(0)..=self.row(y_hi).min(last_row) {
                marked[r as usize * self.width + c as usize] = true;
            }
        }
    }

    /// Marks the cells whose centre is inside the area (non-zero winding
    /// over all rings, each counted with its sign: overlapping polygons
    /// stay inside).
    fn fill_inside(&self, marked: &mut [bool], rings: &[(&[Coord<f64>], i32)]) {
        let mut rows: Vec<Vec<(f64, i32)>> = vec![Vec::new(); self.height];
        let centre_index = |v: f64, origin: f64| ((v - origin) / self.cell - 0.5).ceil();
        for &(ring, sign) in rings {
            for (i, &p) in ring.iter().enumerate() {
                let q = ring[(i + 1) % ring.len()];
                if p.y == q.y {
                    continue;
                }
                let (ylo, yhi) = (p.y.min(q.y), p.y.max(q.y));
                let wind = if q.y > p.y { sign } else { -sign };
                let r0 = centre_index(ylo, self.y0).max(0.0) as usize;
                let r1 = (centre_index(yhi, self.y0).max(0.0) as usize).min(self.height);
                for (r, row) in rows.iter_mut().enumerate().take(r1).skip(r0) {
                    let y = self.y0 + (r as f64 + 0.5) * self.cell;
                    row.push((p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y), wind));
                }
            }
        }
        for (r, row) in rows.iter_mut().enumerate() {
            row.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut winding = 0;
            for k in 0..row.len() {
                winding += row[k].1;
                if winding == 0 || k + 1 == row.len() {
                    continue;
                }
                let from = centre_index(row[k].0, self.x0).max(0.0) as usize;
                let to = (centre_index(row[k + 1].0, self.x0).max(0.0) as usize).min(self.width);
                for c in from..to {
                    marked[r * self.width + c] = true;
                }
            }
        }
    }
}

/// Twice the signed area of a ring (positive counter-clockwise).
fn signed_area(ring: &[Coord<f64>]) -> f64 {
    (0..ring.len())
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
            a.x * b.y - b.x * a.y
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::ObstacleMap;
    use geo_types::{Polygon, coord};

    fn square(x: f64, y: f64, s: f64) -> Polygon<f64> {
        Polygon::new(
            vec![
                coord! {x: x, y: y},
                coord! {x: x + s, y: y},
                coord! {x: x + s, y: y + s},
                coord! {x: x, y: y + s},
                coord! {x: x, y: y},
            ]
            .into(),
            vec![],
        )
    }

    /// What the raster says is surely clear is clear: every sampled point's
    /// sure distance is at most its true distance, and segments it passes
    /// are clear by the exact test; far from the obstacles it passes most.
    #[test]
    fn sure_distances_never_exceed_the_true_ones() {
        let polys = MultiPolygon(vec![
            square(0.0, 0.0, 10.0),
            square(40.0, 5.0, 3.0),
            // A thin sliver no cell centre lies in.
            Polygon::new(
                vec![
                    coord! {x: 0.0, y: 30.0},
                    coord! {x: 60.0, y: 30.2},
                    coord! {x: 0.0, y: 30.3},
                    coord! {x: 0.0, y: 30.0},
                ]
                .into(),
                vec![],
            ),
        ]);
        let map = ObstacleMap::new(&polys, 0.0);
        let grid = ClearanceGrid::new(&map.polygons()).unwrap();
        let true_dist = |p: Coord<f64>| {
            if map.contains_point(p) {
                return 0.0;
            }
            let to_edge = |a: Coord<f64>, b: Coord<f64>| {
                let d = b - a;
                let t =
                    (((p - a).x * d.x + (p - a).y * d.y) / (d.x * d.x + d.y * d.y)).clamp(0.0, 1.0);
                let c = a + d * t;
                (p.x - c.x).hypot(p.y - c.y)
            };
            polys
                .iter()
                .flat_map(|poly| poly.exterior().lines())
                .map(|l| to_edge(l.start, l.end))
                .fold(f64::INFINITY, f64::min)
        };
        let mut sure_points = 0;
        for i in 0..120 {
            for j in 0..90 {
                let p = coord! {x: -20.0 + i as f64 * 0.77, y: -20.0 + j as f64 * 0.81};
                let s = grid.sure(p);
                assert!(s <= true_dist(p) + 1e-9, "{p:?}: {s} > {}", true_dist(p));
                sure_points += usize::from(s > 0.0);
            }
        }
        assert!(sure_points > 120 * 90 / 2, "{sure_points}");
        let mut passed = 0;
        for k in 0..400 {
            let a = coord! {x: -20.0 + (k * 37 % 90) as f64, y: -20.0 + (k * 53 % 70) as f64};
            let b = a + coord! {x: (k % 7) as f64 * 3.0 - 9.0, y: (k % 5) as f64 * 4.0 - 8.0};
            if grid.sure_clear(a, b) {
                passed += 1;
                assert!(map.is_clear(a, b), "{a:?} {b:?}");
            }
        }
        assert!(passed > 100, "{passed}");
        // A hole is free (either way round), its ring is not.
        for hole_ring in [
            vec![(70.0, 50.0), (90.0, 50.0), (90.0, 70.0), (70.0, 70.0)],
            vec![(70.0, 50.0), (70.0, 70.0), (90.0, 70.0), (90.0, 50.0)],
        ] {
            let hole: Vec<Coord<f64>> = hole_ring
                .iter()
                .map(|&(x, y)| coord! {x: x, y: y})
                .collect();
            let donut = Polygon::new(
                square(60.0, 40.0, 40.0).exterior().clone(),
                vec![hole.into()],
            );
            let grid = ClearanceGrid::new(&MultiPolygon(vec![donut])).unwrap();
            let s = grid.sure(coord! {x: 80.0, y: 60.0});
            assert!(s > 5.0 && s <= 10.0, "{s}");
            assert!(grid.sure(coord! {x: 65.0, y: 60.0}) <= 0.0);
            // Off the raster: the margin round it, no more than the truth.
            let far = grid.sure(coord! {x: 130.0, y: 60.0});
            assert!(far > 0.0 && far <= 30.0, "{far}");
        }
        assert!(ClearanceGrid::new(&MultiPolygon(vec![])).is_none());
    }
}
