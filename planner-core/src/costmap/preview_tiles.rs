//! The costmap's preview built from its tiles as they are made (a tiled
//! run never holds the whole map): each map cell belongs to one preview
//! pixel's block, as in [`super::preview_png`], and a pixel keeps only
//! its block's worst obstacle and its traversable costs' sum and count.

use super::Class;
use super::preview::{encode_png, pixel, preview_size, worse};

/// A preview of a `width`×`height` map being filled tile by tile.
pub struct PreviewTiles {
    pw: usize,
    ph: usize,
    /// The pixel column of each map column, and row of each map row.
    col_px: Vec<u32>,
    row_px: Vec<u32>,
    worst: Vec<Class>,
    sum: Vec<f64>,
    n: Vec<u32>,
}

/// Which of `pixels` blocks each of `cells` map cells falls in (the
/// blocks [`super::preview_png`] averages: pixel p covers cells
/// p·cells/pixels up to (p+1)·cells/pixels).
fn blocks(cells: usize, pixels: usize) -> Vec<u32> {
    let mut out = vec![0u32; cells];
    for p in 0..pixels {
        let (a, b) = (
            p * cells / pixels,
            ((p + 1) * cells / pixels).max(p * cells / pixels + 1),
        );
        for o in &mut out[a.min(cells)..b.min(cells)] {
            *o = p as u32;
        }
    }
    out
}

impl PreviewTiles {
    /// At most `max_side` pixels on the longer side.
    pub fn new(width: usize, height: usize, max_side: usize) -> PreviewTiles {
        let (pw, ph) = preview_size(width, height, max_side);
        PreviewTiles {
            pw,
            ph,
            col_px: blocks(width, pw),
            row_px: blocks(height, ph),
            worst: vec![Class::Unknown; pw * ph],
            sum: vec![0.0; pw * ph],
            n: vec![0; pw * ph],
        }
    }

    /// Adds the `w`-wide block of cells whose top-left is (`col0`, `row0`).
    pub fn add(&mut self, col0: usize, row0: usize, w: usize, cost: &[f32], class: &[u8]) {
        for (r, (costs, classes)) in cost.chunks(w).zip(class.chunks(w)).enumerate() {
            let py = self.row_px[row0 + r] as usize;
            for (c, (&v, &k)) in costs.iter().zip(classes).enumerate() {
                let p = py * self.pw + self.col_px[col0 + c] as usize;
                let k = Class::from_code(k).unwrap_or(Class::Unknown);
                if k == Class::Traversable {
                    self.sum[p] += f64::from(v);
                    self.n[p] += 1;
                } else {
                    self.worst[p] = worse(self.worst[p], k);
                }
            }
        }
    }

    /// The PNG, greys over `cost_range`.
    pub fn finish(&self, cost_range: [f64; 2]) -> Vec<u8> {
        let mut pixels = Vec::with_capacity(self.pw * self.ph * 4);
        for p in 0..self.pw * self.ph {
            pixels.extend_from_slice(&pixel(
                self.worst[p],
                self.sum[p],
                self.n[p] as usize,
                cost_range,
            ));
        }
        encode_png(&pixels, self.pw, self.ph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_partition_the_cells_like_the_preview() {
        for (cells, pixels) in [(10, 3), (7, 7), (1000, 64), (5, 1)] {
            let b = blocks(cells, pixels);
            for p in 0..pixels {
                let r0 = p * cells / pixels;
                let r1 = ((p + 1) * cells / pixels).max(r0 + 1);
                assert!((r0..r1).all(|i| b[i] == p as u32), "{cells} {pixels} {p}");
            }
        }
    }
}
