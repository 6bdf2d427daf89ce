//! Test helpers shared by the transit and tour tests and timing runs:
//! rectangles, lawnmower plans, a small deterministic random generator and
//! random NFZ fields.

use geo_types::{Coord, LineString, Polygon, coord};

use crate::coverage::{CellPlan, Lane};

/// The CCW rectangle [x0, x1] × [y0, y1].
pub(crate) fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
    Polygon::new(
        LineString::from(vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]),
        vec![],
    )
}

/// A cell `[x0, x1] × [y0, y1]` with `n` north–south lanes, the first
/// flown northwards.
pub(crate) fn lawnmower(cell_index: usize, cell: &Polygon<f64>, n: usize) -> CellPlan {
    let r = cell.exterior().0.clone();
    let (x0, y0, x1, y1) = (r[0].x, r[0].y, r[2].x, r[2].y);
    let spacing = (x1 - x0) / n as f64;
    let lanes: Vec<Lane> = (0..n)
        .map(|k| {
            let x = x0 + (k as f64 + 0.5) * spacing;
            let (s, e) = (coord! { x: x, y: y0 + 1.0 }, coord! { x: x, y: y1 - 1.0 });
            if k % 2 == 0 {
                Lane { start: s, end: e }
            } else {
                Lane { start: e, end: s }
            }
        })
        .collect();
    CellPlan {
        cell_index,
        direction_deg: 0.0,
        links: vec![Vec::new(); n - 1],
        lanes,
    }
}

pub(crate) use crate::test_rng::Lcg;

/// One random star-shaped 8-gon per block of a `blocks` × `blocks` grid of
/// `block`-sized squares whose corner is at `origin`: centres jittered by up
/// to ±10 % of a block, radii 10–40 % of a block.
pub(crate) fn octagon_field(
    rng: &mut Lcg,
    blocks: usize,
    block: f64,
    origin: Coord<f64>,
) -> Vec<Polygon<f64>> {
    let mut polys = Vec::new();
    for i in 0..blocks {
        for j in 0..blocks {
            let cx = (i as f64 + 0.5) * block + (rng.next() - 0.5) * 0.2 * block;
            let cy = (j as f64 + 0.5) * block + (rng.next() - 0.5) * 0.2 * block;
            let pts: Vec<(f64, f64)> = (0..8)
                .map(|m| {
                    let ang = (m as f64 + 0.8 * rng.next()) / 8.0 * std::f64::consts::TAU;
                    let r = block * (0.1 + 0.3 * rng.next());
                    (origin.x + cx + r * ang.cos(), origin.y + cy + r * ang.sin())
                })
                .collect();
            polys.push(Polygon::new(LineString::from(pts), vec![]));
        }
    }
    polys
}
