//! Safe links between consecutive lanes of a cell, and the four ways to fly
//! the same lanes ([`CellPlan::reoriented`]).
//!
//! A straight link is used whenever it stays in free space. Otherwise (a
//! concave cell, or lanes extended round an NFZ corner) the link goes back
//! along the lane to where it leaves the cell, follows the cell boundary the
//! shorter way round (safe: the cell lies in free space) and comes back along
//! the next lane; the result is then shortened by "string pulling" (dropping
//! corners whenever the straight shortcut is itself in free space).

use geo_types::{Coord, MultiPolygon, Polygon};

use super::region::{EPS, FreeSpace, Region, closest_on_segment, dist};
use super::{CellPlan, Lane};

impl CellPlan {
    /// The same lanes flown another way: `reverse_order` starts from the last
    /// lane, `flip_lanes` flies every lane the other way round (so the cell is
    /// entered at the other end of the first lane). Links are recomputed for
    /// the new order against `cell` (the polygon this plan covers) and `free`
    /// (free space: ROI minus NFZs).
    ///
    /// `reoriented(false, false, ..)` on a plan from
    /// [`plan_cell`](super::plan_cell) gives back the same plan.
    ///
    /// Prepares `free` on every call; to re-orient many plans in the same
    /// free space, prepare it once and use [`CellPlan::reoriented_in`].
    pub fn reoriented(
        &self,
        reverse_order: bool,
        flip_lanes: bool,
        cell: &Polygon<f64>,
        free: &MultiPolygon<f64>,
    ) -> CellPlan {
        self.reoriented_in(reverse_order, flip_lanes, cell, &FreeSpace::new(free))
    }

    /// [`CellPlan::reoriented`] against free space prepared once
    /// ([`FreeSpace::new`]); same result.
    pub fn reoriented_in(
        &self,
        reverse_order: bool,
        flip_lanes: bool,
        cell: &Polygon<f64>,
        free: &FreeSpace,
    ) -> CellPlan {
        // A run of lanes (a corridor's lane round its bends) moves and
        // turns as one lane.
        let mut runs = self.runs();
        if reverse_order {
            runs.reverse();
        }
        let mut lanes = Vec::with_capacity(self.lanes.len());
        for run in runs {
            let run = &self.lanes[run];
            if flip_lanes {
                lanes.extend(run.iter().rev().map(|lane| Lane {
                    start: lane.end,
                    end: lane.start,
                }));
            } else {
                lanes.extend_from_slice(run);
            }
        }
        let links = LinkRouter::new(cell, free).links(&lanes);
        CellPlan {
            cell_index: self.cell_index,
            direction_deg: self.direction_deg,
            lanes,
            links,
        }
    }
}

/// Computes links inside one cell; holds the prepared cell and free space.
pub(crate) struct LinkRouter<'a> {
    cell: Region,
    free: &'a Region,
    /// Exterior ring of the cell without the closing point.
    ring: Vec<Coord<f64>>,
}

impl<'a> LinkRouter<'a> {
    pub(crate) fn new(cell: &Polygon<f64>, free: &'a FreeSpace) -> Self {
        let mut ring: Vec<Coord<f64>> = Vec::with_capacity(cell.exterior().0.len());
        for &c in &cell.exterior().0 {
            if ring.last().is_none_or(|l| dist(*l, c) > 0.0) {
                ring.push(c);
            }
        }
        while ring.len() > 1 && ring[0] == ring[ring.len() - 1] {
            ring.pop();
        }
        LinkRouter {
            cell: Region::from_polygon(cell),
            free: free.region(),
            ring,
        }
    }

    /// `links[i]` for every consecutive pair of `lanes`.
    pub(crate) fn links(&self, lanes: &[Lane]) -> Vec<Vec<Coord<f64>>> {
        // Cancelled: fewer links; the caller checks again and drops them.
        lanes
            .windows(2)
            .map_while(|w| {
                crate::cancel::check()
                    .ok()
                    .map(|()| self.link(&w[0], &w[1]))
            })
            .collect()
    }

    /// Intermediate points from `from.end` to `to.start`.
    pub(crate) fn link(&self, from: &Lane, to: &Lane) -> Vec<Coord<f64>> {
        let (a, b) = (from.end, to.start);
        if self.free.covers_segment(a, b) || self.ring.len() < 3 {
            return Vec::new();
        }
        // Where the lanes meet the cell boundary nearest to a and b: the
        // stretch of lane between is flown already, so it is in free space.
        let p = self.exit_point(from);
        let q = self.entry_point(to);
        let (ep, tp) = self.locate(p);
        let (eq, tq) = self.locate(q);
        let forward = self.walk(p, ep, tp, q, eq, tq, true);
        let backward = self.walk(p, ep, tp, q, eq, tq, false);
        let candidates = [forward, backward].map(|mid| {
            let mut path = Vec::with_capacity(mid.len() + 2);
            path.push(a);
            path.extend(mid);
            path.push(b);
            dedup_close(&mut path);
            self.pull_string(&path)
        });
        let best = candidates
            .into_iter()
            .min_by(|x, y| path_length(x).total_cmp(&path_length(y)))
            .unwrap_or_default();
        // Intermediate points only.
        match best.len() {
            0..=2 => Vec::new(),
            n => best[1..n - 1].to_vec(),
        }
    }

    /// Last point where `lane` is in the cell (walking back from its end).
    fn exit_point(&self, lane: &Lane) -> Coord<f64> {
        let len = dist(lane.start, lane.end);
        if len > EPS {
            let d = (lane.end - lane.start) / len;
            if let Some(&(_, e)) = self.cell.intervals(lane.start, d, 0.0, len).last() {
                return lane.start + d * e;
            }
        }
        self.nearest_on_ring(lane.end)
    }

    /// First point where `lane` is in the cell.
    fn entry_point(&self, lane: &Lane) -> Coord<f64> {
        let len = dist(lane.start, lane.end);
        if len > EPS {
            let d = (lane.end - lane.start) / len;
            if let Some(&(s, _)) = self.cell.intervals(lane.start, d, 0.0, len).first() {
                return lane.start + d * s;
            }
        }
        self.nearest_on_ring(lane.start)
    }

    fn nearest_on_ring(&self, p: Coord<f64>) -> Coord<f64> {
        let (e, t) = self.locate(p);
        let n = self.ring.len();
        let (a, b) = (self.ring[e], self.ring[(e + 1) % n]);
        a + (b - a) * t
    }

    /// Ring edge nearest to `p` and the parameter of the closest point on it.
    fn locate(&self, p: Coord<f64>) -> (usize, f64) {
        let n = self.ring.len();
        let mut best = (0, 0.0, f64::INFINITY);
        for k in 0..n {
            let (c, t) = closest_on_segment(p, self.ring[k], self.ring[(k + 1) % n]);
            let d = dist(p, c);
            if d < best.2 {
                best = (k, t, d);
            }
        }
        (best.0, best.1)
    }

    /// Points along the ring from `p` (on edge `ep` at `tp`) to `q`, going
    /// with the ring's vertex order when `forward`, against it otherwise.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        p: Coord<f64>,
        ep: usize,
        tp: f64,
        q: Coord<f64>,
        eq: usize,
        tq: f64,
        forward: bool,
    ) -> Vec<Coord<f64>> {
        let n = self.ring.len();
        let mut out = vec![p];
        // Same edge and already in the right order: no vertex in between.
        let direct = ep == eq && if forward { tq >= tp } else { tq <= tp };
        if !direct {
            if forward {
                let mut k = (ep + 1) % n;
                for _ in 0..n {
                    out.push(self.ring[k]);
                    if k == eq {
                        break;
                    }
                    k = (k + 1) % n;
                }
            } else {
                let mut k = ep;
                for _ in 0..n {
                    out.push(self.ring[k]);
                    if k == (eq + 1) % n {
                        break;
                    }
                    k = (k + n - 1) % n;
                }
            }
        }
        out.push(q);
        out
    }

    /// Greedy shortcutting: from each kept point jump to the farthest later
    /// point that is reachable by a straight segment in free space.
    fn pull_string(&self, path: &[Coord<f64>]) -> Vec<Coord<f64>> {
        if path.len() <= 2 {
            return path.to_vec();
        }
        let mut out = vec![path[0]];
        let mut i = 0;
        while i + 1 < path.len() {
            let mut j = path.len() - 1;
            while j > i + 1 && !self.free.covers_segment(path[i], path[j]) {
                j -= 1;
            }
            out.push(path[j]);
            i = j;
        }
        out
    }
}

fn dedup_close(path: &mut Vec<Coord<f64>>) {
    path.dedup_by(|b, a| dist(*a, *b) <= EPS);
}

fn path_length(path: &[Coord<f64>]) -> f64 {
    path.windows(2).map(|w| dist(w[0], w[1])).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::{coord, polygon};

    /// A "C"-shaped cell open to the east; its notch is outside free space.
    fn c_cell() -> Polygon<f64> {
        polygon![
            (x: 0., y: 0.), (x: 100., y: 0.), (x: 100., y: 30.), (x: 30., y: 30.),
            (x: 30., y: 70.), (x: 100., y: 70.), (x: 100., y: 100.), (x: 0., y: 100.),
        ]
    }

    #[test]
    fn straight_link_when_free() {
        let cell = c_cell();
        let free = MultiPolygon(vec![cell.clone()]);
        let free_space = FreeSpace::new(&free);
        let router = LinkRouter::new(&cell, &free_space);
        let from = Lane {
            start: coord! { x: 10., y: 10. },
            end: coord! { x: 10., y: 90. },
        };
        let to = Lane {
            start: coord! { x: 20., y: 90. },
            end: coord! { x: 20., y: 10. },
        };
        assert!(router.link(&from, &to).is_empty());
    }

    #[test]
    fn link_round_the_notch() {
        let cell = c_cell();
        let free = MultiPolygon(vec![cell.clone()]);
        let free_space = FreeSpace::new(&free);
        let router = LinkRouter::new(&cell, &free_space);
        // Lane along the bottom arm flown west to east, next lane along the
        // top arm: the straight link would cross the notch.
        let from = Lane {
            start: coord! { x: 0., y: 15. },
            end: coord! { x: 100., y: 15. },
        };
        let to = Lane {
            start: coord! { x: 100., y: 85. },
            end: coord! { x: 0., y: 85. },
        };
        let link = router.link(&from, &to);
        assert!(!link.is_empty());
        let mut path = vec![from.end];
        path.extend(link.iter().copied());
        path.push(to.start);
        for w in path.windows(2) {
            assert!(router.free.covers_segment(w[0], w[1]), "{w:?}");
        }
        // String pulling leaves the two inner corners of the notch.
        assert_eq!(
            link,
            vec![coord! { x: 30., y: 30. }, coord! { x: 30., y: 70. }]
        );
    }

    #[test]
    fn reoriented_variants_keep_lanes() {
        let cell = c_cell();
        let free = MultiPolygon(vec![cell.clone()]);
        let lanes = vec![
            Lane {
                start: coord! { x: 0., y: 15. },
                end: coord! { x: 100., y: 15. },
            },
            Lane {
                start: coord! { x: 100., y: 85. },
                end: coord! { x: 0., y: 85. },
            },
        ];
        let plan = CellPlan {
            cell_index: 3,
            direction_deg: 90.0,
            links: LinkRouter::new(&cell, &FreeSpace::new(&free)).links(&lanes),
            lanes,
        };
        let flipped = plan.reoriented(false, true, &cell, &free);
        assert_eq!(flipped.entry(), Some(coord! { x: 100., y: 15. }));
        assert_eq!(flipped.exit(), Some(coord! { x: 100., y: 85. }));
        // West ends are joined by a straight link along x = 0.
        assert_eq!(flipped.links, vec![Vec::<Coord<f64>>::new()]);
        let back = plan.reoriented(true, true, &cell, &free);
        assert_eq!(back.entry(), plan.exit().map(|_| coord! { x: 0., y: 85. }));
        assert_eq!(back.links[0].len(), 2);
        assert_eq!(plan.reoriented(false, false, &cell, &free), plan);
        assert_eq!(back.cell_index, 3);
    }
}
