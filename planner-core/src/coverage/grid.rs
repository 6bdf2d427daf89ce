//! One grid of lane lines over the whole free space (issue 21: fewer,
//! longer lanes). A cell planned on its own lays its lanes from its own
//! sides, half a spacing in, so cells side by side across the slice (round
//! a no-fly zone, or in a concave field) each round their lane count up:
//! three cells 50 m wide need 3 + 3 + 3 lanes at 20 m where the 150 m they
//! span need 8. On one grid, every cell flies the grid lines that cross it;
//! a grid line just outside a cell flies its neighbour, and its strip
//! covers the cell's sliver when the free space runs on along that line
//! past the sliver (then the neighbour's lane there covers it); otherwise
//! the cell flies its own lane in the sliver, so every cell stays covered.

use geo_types::{Coord, MultiPolygon};

use super::lanes::{Frame, MAX_ROWS, RowOffset, axes};
use super::region::{EPS, Region, dot, is_positive};

/// A grid line closer than this to a cell's side is flown this far above
/// that side, by the cell above it: along the side itself the free space
/// is ambiguous (a no-fly zone may touch it at one point).
const SIDE_TOLERANCE_M: f64 = 1e-3;

/// How far (in spacings) a cell's part of a neighbour's strip may reach
/// past the free space along the neighbour's line at either end and still
/// be left to it: a boundary slanted 45° or more to the lanes leaves at most
/// that triangle out, as it does in every strip along it.
const SLIVER_OVERHANG: f64 = 0.5;

/// Lane lines of one bearing, `spacing` apart, the first half a spacing
/// inside the free space's extent across them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneGrid {
    bearing: f64,
    spacing: f64,
    /// World offset (along the frame's normal) of grid line 0.
    first: f64,
}

impl LaneGrid {
    /// The grid of lanes of bearing `bearing_deg` over `free`; `None` for
    /// a spacing that is not a positive number, a bearing or coordinate
    /// that is not finite, or an empty free space.
    pub fn new(free: &MultiPolygon<f64>, spacing: f64, bearing_deg: f64) -> Option<LaneGrid> {
        if !is_positive(spacing) || !bearing_deg.is_finite() {
            return None;
        }
        let bearing = bearing_deg.rem_euclid(180.0);
        let bearing = if bearing >= 180.0 - 1e-9 {
            0.0
        } else {
            bearing
        };
        let (_, n) = axes(bearing);
        let lowest = free
            .0
            .iter()
            .flat_map(|p| p.exterior().0.iter())
            .map(|&c| dot(c, n))
            .fold(f64::INFINITY, f64::min);
        lowest.is_finite().then_some(LaneGrid {
            bearing,
            spacing,
            first: lowest + spacing / 2.0,
        })
    }

    /// The same lines moved back across the lanes by `fraction` of a
    /// spacing (in [0, 1)): the first then lies less than half a spacing
    /// inside the free space's extent, and the lines fall elsewhere
    /// against the cells' sides (where a line just misses a cell, the cell
    /// may need a lane of its own for the sliver).
    pub fn shifted(self, fraction: f64) -> LaneGrid {
        LaneGrid {
            first: self.first - fraction.clamp(0.0, 1.0) * self.spacing,
            ..self
        }
    }

    /// Bearing of the lanes, degrees clockwise from grid north, in [0, 180).
    pub fn bearing(&self) -> f64 {
        self.bearing
    }

    /// The lane offsets of the cell `ring` (in `frame`, of the grid's
    /// bearing) and the band each must cover: the grid lines inside the
    /// cell, and for a strip that reaches into the cell from a line outside
    /// it, nothing if the free space `free` along that line spans the
    /// cell's part of the strip, else a lane in the middle of that part.
    /// `None` for a cell with no extent or more than [`MAX_ROWS`] lines.
    pub(super) fn rows(
        &self,
        frame: &Frame,
        ring: &[Coord<f64>],
        free: &Region,
        flown: &dyn Fn(Coord<f64>) -> bool,
    ) -> Option<Vec<RowOffset>> {
        let s = self.spacing;
        let (vmin, vmax) = frame.v;
        if vmax - vmin <= EPS || vmax.is_nan() || vmin.is_nan() {
            return None;
        }
        // Grid line 0 in the cell's frame.
        let first = self.first - dot(frame.origin, frame.n);
        // The lines whose strips (v ± s/2) meet the cell by more than EPS.
        let k_lo = ((vmin + EPS - s / 2.0 - first) / s).floor() + 1.0;
        let k_hi = ((vmax - EPS + s / 2.0 - first) / s).ceil() - 1.0;
        // NaN (a non-finite offset) counts as too many.
        let count = k_hi - k_lo + 1.0;
        if count.is_nan() || count > MAX_ROWS as f64 {
            return None;
        }
        let mut rows = Vec::new();
        let mut k = k_lo;
        while k <= k_hi {
            let v = first + k * s;
            k += 1.0;
            if (v - vmin).abs() <= SIDE_TOLERANCE_M {
                // A line on the cell's lower side (a cut it shares with the
                // cell below, or its own edge): flown just inside.
                let v = vmin + SIDE_TOLERANCE_M;
                rows.push((v, (vmin, (v + s / 2.0).min(vmax))));
                continue;
            }
            let band = ((v - s / 2.0).max(vmin), (v + s / 2.0).min(vmax));
            if v > vmin && v < vmax - SIDE_TOLERANCE_M {
                rows.push((v, band));
                continue;
            }
            // Outside the cell, or on its upper side: the line is flown by
            // the cell beyond, just past this side if on it.
            let flown_at = if v < vmin {
                v
            } else {
                v.max(vmax + SIDE_TOLERANCE_M)
            };
            if line_covers_band(frame, ring, free, flown_at, band, s, flown) {
                continue;
            }
            rows.push(((band.0 + band.1) / 2.0, band));
        }
        (!rows.is_empty()).then_some(rows)
    }
}

/// Whether a lane along the line at offset `v`, through the free space,
/// covers the part of the cell `ring` whose offsets lie in `band` as well
/// as the cell's own lane could: the free space along the line spans that
/// part lengthwise but for at most [`SLIVER_OVERHANG`] spacings `spacing`
/// at either end, where a slanted boundary leaves a corner that no lane
/// of the band could reach whole either; and the line is `flown` there
/// (by the cell beyond, on the grid).
fn line_covers_band(
    frame: &Frame,
    ring: &[Coord<f64>],
    free: &Region,
    v: f64,
    (lo, hi): (f64, f64),
    spacing: f64,
    flown: &dyn Fn(Coord<f64>) -> bool,
) -> bool {
    let Some((u0, u1)) = extent_in_band(frame, ring, (lo, hi)) else {
        return true; // nothing of the cell there
    };
    if !flown(frame.point((u0 + u1) / 2.0, v)) {
        return false;
    }
    let slack = SLIVER_OVERHANG * spacing;
    let length = u1 - u0 + 2.0 * slack;
    let pieces = free.intervals(frame.point(u0 - slack, v), frame.d, 0.0, length);
    // The run of free space along the line that holds the part's middle.
    let middle = length / 2.0;
    pieces
        .iter()
        .find(|(a, b)| *a <= middle + EPS && *b >= middle - EPS)
        .is_some_and(|(a, b)| *a <= slack + EPS && *b >= length - slack - EPS)
}

/// The lengthwise (`u`) extent of the part of the cell `ring` whose
/// offsets (`v`) lie in `band`; `None` if no part does.
fn extent_in_band(frame: &Frame, ring: &[Coord<f64>], (lo, hi): (f64, f64)) -> Option<(f64, f64)> {
    let (mut u_lo, mut u_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let m = ring.len();
    for k in 0..m {
        let (p, q) = (ring[k] - frame.origin, ring[(k + 1) % m] - frame.origin);
        let (u1, v1, u2, v2) = (
            dot(p, frame.d),
            dot(p, frame.n),
            dot(q, frame.d),
            dot(q, frame.n),
        );
        let mut take = |u: f64| {
            u_lo = u_lo.min(u);
            u_hi = u_hi.max(u);
        };
        if (v2 - v1).abs() <= f64::EPSILON * (v1.abs() + v2.abs()) {
            if v1 >= lo - EPS && v1 <= hi + EPS {
                take(u1);
                take(u2);
            }
            continue;
        }
        let ta = ((lo - v1) / (v2 - v1)).clamp(0.0, 1.0);
        let tb = ((hi - v1) / (v2 - v1)).clamp(0.0, 1.0);
        let (t0, t1) = (ta.min(tb), ta.max(tb));
        let v_at = v1 + (v2 - v1) * t0;
        if v_at < lo - EPS || v_at > hi + EPS {
            continue; // the edge misses the band
        }
        take(u1 + (u2 - u1) * t0);
        take(u1 + (u2 - u1) * t1);
    }
    (u_lo <= u_hi).then_some((u_lo, u_hi))
}

#[cfg(test)]
mod tests {
    use super::super::{CellLayouts, FreeSpace, coverage_ratio};
    use super::*;
    use geo_types::{LineString, Polygon};

    const X0: f64 = 480_000.0;
    const Y0: f64 = 5_200_000.0;

    fn poly(pts: &[(f64, f64)]) -> Polygon<f64> {
        Polygon::new(
            LineString(
                pts.iter()
                    .map(|&(x, y)| Coord {
                        x: X0 + x,
                        y: Y0 + y,
                    })
                    .collect(),
            ),
            vec![],
        )
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
        poly(&[(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
    }

    /// Lanes of every cell, each planned on its own or on one grid.
    fn lanes_of(
        cells: &[Polygon<f64>],
        free: &MultiPolygon<f64>,
        spacing: f64,
        on_grid: bool,
    ) -> Vec<super::super::Lane> {
        let prepared = FreeSpace::new(free);
        let grid = LaneGrid::new(free, spacing, 0.0).unwrap();
        cells
            .iter()
            .enumerate()
            .flat_map(|(i, c)| {
                let layouts = if on_grid {
                    CellLayouts::on_grid(i, c, &grid, &prepared, &|_| true)
                } else {
                    CellLayouts::along(i, c, spacing, 0.0)
                };
                layouts.unwrap().best_plan(c, &prepared).unwrap().lanes
            })
            .collect()
    }

    /// A 150 × 100 m field cut into three cells 50 m wide side by side
    /// (as round a no-fly zone): on their own they need 3 lanes each at
    /// 20 m; on one grid the 8 lines of the 150 m, and they still cover it.
    #[test]
    fn cells_side_by_side_share_the_grid_lines() {
        let cells = [
            rect(0.0, 0.0, 50.0, 100.0),
            rect(50.0, 0.0, 100.0, 100.0),
            rect(100.0, 0.0, 150.0, 100.0),
        ];
        let free = MultiPolygon(vec![rect(0.0, 0.0, 150.0, 100.0)]);
        let own = lanes_of(&cells, &free, 20.0, false);
        let grid = lanes_of(&cells, &free, 20.0, true);
        assert_eq!(own.len(), 9);
        assert_eq!(grid.len(), 8);
        // The lines are the field's grid, 10, 30, …, 130 m from its side
        // (50 and 90 on the cuts, flown by the cell above, 1 mm in); the
        // last, on the far side, moves in to the middle of its strip's part
        // in the field (145 m).
        let mut xs: Vec<f64> = grid.iter().map(|l| l.start.x - X0).collect();
        xs.sort_by(f64::total_cmp);
        let want = [10.0, 30.0, 50.0, 70.0, 90.0, 110.0, 130.0, 145.0];
        for (x, w) in xs.iter().zip(want) {
            assert!((x - w).abs() < 2e-3, "{xs:?}");
        }
        // All but the 1 mm between the cut at 50 m and the lane flown 1 mm
        // above it (0.1 m² of 15 000).
        let ratio = coverage_ratio(&grid, 20.0, &free);
        assert!(ratio > 1.0 - 1e-5, "coverage {ratio}");
    }

    /// A cell beside a no-fly zone: the grid line just past its side runs
    /// into the zone, so the cell flies its own lane in the sliver.
    #[test]
    fn a_sliver_against_a_no_fly_zone_gets_its_own_lane() {
        // A 150 × 100 m field with a no-fly zone from x = 65 to 100 m
        // between y = 20 and 80; cells split at its sides.
        let free_poly = Polygon::new(
            LineString(
                [(0., 0.), (150., 0.), (150., 100.), (0., 100.), (0., 0.)]
                    .iter()
                    .map(|&(x, y)| Coord {
                        x: X0 + x,
                        y: Y0 + y,
                    })
                    .collect(),
            ),
            vec![LineString(
                [(65., 20.), (100., 20.), (100., 80.), (65., 80.), (65., 20.)]
                    .iter()
                    .map(|&(x, y)| Coord {
                        x: X0 + x,
                        y: Y0 + y,
                    })
                    .collect(),
            )],
        );
        let free = MultiPolygon(vec![free_poly]);
        let cells = [
            rect(0.0, 0.0, 65.0, 100.0),
            rect(65.0, 0.0, 100.0, 20.0),
            rect(65.0, 80.0, 100.0, 100.0),
            rect(100.0, 0.0, 150.0, 100.0),
        ];
        let lanes = lanes_of(&cells, &free, 20.0, true);
        let ratio = coverage_ratio(&lanes, 20.0, &free);
        assert!(ratio > 1.0 - 1e-9, "coverage {ratio}");
        // The first cell's part of line 70's strip, 60..65 m: line 70 runs
        // into the zone, so the cell flies a lane of its own at 62.5 m.
        let mut first: Vec<f64> = lanes
            .iter()
            .map(|l| l.start.x - X0)
            .filter(|x| *x < 65.0)
            .collect();
        first.sort_by(f64::total_cmp);
        assert_eq!(first.len(), 4, "{first:?}");
        assert!((first[3] - 62.5).abs() < 1e-6, "{first:?}");
    }

    #[test]
    fn bad_input_gives_no_grid() {
        let free = MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]);
        assert!(LaneGrid::new(&free, 0.0, 0.0).is_none());
        assert!(LaneGrid::new(&free, f64::NAN, 0.0).is_none());
        assert!(LaneGrid::new(&free, 5.0, f64::INFINITY).is_none());
        assert!(LaneGrid::new(&MultiPolygon(vec![]), 5.0, 0.0).is_none());
        assert_eq!(LaneGrid::new(&free, 5.0, 180.0).unwrap().bearing(), 0.0);
    }
}
