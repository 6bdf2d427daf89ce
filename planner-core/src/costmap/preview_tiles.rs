//! The costmap's preview built from its tiles (a tiled run never holds
//! the whole map): each map cell belongs to one preview pixel's block, as
//! in [`super::preview_png`], and a pixel keeps only its block's worst
//! obstacle and its traversable costs' sum and count. Each tile makes a
//! [`PreviewPart`] of the pixels its cells fall in (on its own, on any
//! process); the parts merged in tile order make the preview.

use super::Class;
use super::halo::TileWindow;
use super::preview::{encode_png, pixel, preview_size, worse};
use super::tile_bytes::{ByteReader, ByteWriter, PieceError};

/// The pixel whose block holds map cell `i` of `cells` when they are
/// shown as `pixels` blocks (`pixels` ≤ `cells`): pixel p covers cells
/// ⌊p·cells/pixels⌋ up to ⌊(p+1)·cells/pixels⌋, so the pixel of i is the
/// last p whose first cell is at most i.
fn pixel_of(i: usize, cells: usize, pixels: usize) -> usize {
    (((i as u128 + 1) * pixels as u128 - 1) / cells as u128) as usize
}

/// The preview of a `width`×`height` map: its size, and which pixels a
/// block of cells falls in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PreviewGrid {
    width: usize,
    height: usize,
    pw: usize,
    ph: usize,
}

impl PreviewGrid {
    /// At most `max_side` pixels on the longer side (never enlarged).
    pub fn new(width: usize, height: usize, max_side: usize) -> PreviewGrid {
        let (pw, ph) = preview_size(width, height, max_side);
        PreviewGrid {
            width,
            height,
            pw,
            ph,
        }
    }

    /// The preview's [width, height], pixels.
    pub fn size(&self) -> [usize; 2] {
        [self.pw, self.ph]
    }

    /// The pixels [px0, py0, width, height] the cells of `t` fall in.
    fn rect(&self, t: &TileWindow) -> [usize; 4] {
        let px0 = pixel_of(t.col0, self.width, self.pw);
        let py0 = pixel_of(t.row0, self.height, self.ph);
        let px1 = pixel_of(t.col0 + t.width - 1, self.width, self.pw);
        let py1 = pixel_of(t.row0 + t.height - 1, self.height, self.ph);
        [px0, py0, px1 - px0 + 1, py1 - py0 + 1]
    }

    /// Tile `t`'s part of the preview, from its cells' costs and classes
    /// (row-major, `t.width` wide): bounded by the tile, not the map.
    pub fn part(&self, t: &TileWindow, cost: &[f32], class: &[u8]) -> PreviewPart {
        let rect = self.rect(t);
        let [px0, py0, w, h] = rect;
        let mut part = PreviewPart {
            rect,
            worst: vec![Class::Unknown; w * h],
            sum: vec![0.0; w * h],
            n: vec![0; w * h],
        };
        let col_px: Vec<usize> = (t.col0..t.col0 + t.width)
            .map(|c| pixel_of(c, self.width, self.pw) - px0)
            .collect();
        for (r, (costs, classes)) in cost
            .chunks(t.width.max(1))
            .zip(class.chunks(t.width.max(1)))
            .enumerate()
        {
            let py = pixel_of(t.row0 + r, self.height, self.ph) - py0;
            for ((&v, &k), &px) in costs.iter().zip(classes).zip(&col_px) {
                let p = py * w + px;
                let k = Class::from_code(k).unwrap_or(Class::Unknown);
                if k == Class::Traversable {
                    part.sum[p] += f64::from(v);
                    part.n[p] += 1;
                } else {
                    part.worst[p] = worse(part.worst[p], k);
                }
            }
        }
        part
    }
}

/// One tile's pixels of the preview: per pixel of the block of pixels its
/// cells fall in, their worst obstacle and their traversable costs' sum
/// and count.
#[derive(Clone, Debug, PartialEq)]
pub struct PreviewPart {
    /// [px0, py0, width, height] of the pixels.
    rect: [usize; 4],
    worst: Vec<Class>,
    sum: Vec<f64>,
    n: Vec<u32>,
}

impl PreviewPart {
    const KIND: u8 = b'P';
    const WHAT: &'static str = "preview part";

    /// The byte form: the pixels' rectangle, then per pixel the worst
    /// class, the count and the sum.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = ByteWriter::new(Self::KIND);
        self.rect.iter().for_each(|&v| b.len32(v));
        for ((&k, &n), &s) in self.worst.iter().zip(&self.n).zip(&self.sum) {
            b.u8(k as u8);
            b.u32(n);
            b.f64(s);
        }
        b.finish()
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<PreviewPart, PieceError> {
        let mut r = ByteReader::new(bytes, Self::KIND, Self::WHAT)?;
        let rect = [r.u32()?, r.u32()?, r.u32()?, r.u32()?].map(|v| v as usize);
        let pixels = rect[2].saturating_mul(rect[3]);
        if pixels == 0 {
            return Err(r.fault(format!("an empty {}×{} block of pixels", rect[2], rect[3])));
        }
        r.expect_items(pixels, 13)?;
        let (mut worst, mut sum, mut n) = (
            Vec::with_capacity(pixels),
            Vec::with_capacity(pixels),
            Vec::with_capacity(pixels),
        );
        for _ in 0..pixels {
            let code = r.u8()?;
            let k = Class::from_code(code)
                .filter(|&k| k != Class::Traversable)
                .ok_or_else(|| r.fault(format!("{code} is not an obstacle class's code")))?;
            let (count, s) = (r.u32()?, r.f64()?);
            if !s.is_finite() || (count == 0 && s != 0.0) {
                return Err(r.fault(format!("a sum of {s} over {count} costs")));
            }
            worst.push(k);
            n.push(count);
            sum.push(s);
        }
        r.end()?;
        Ok(PreviewPart {
            rect,
            worst,
            sum,
            n,
        })
    }
}

/// A preview of a map being filled from its tiles' parts.
pub struct PreviewTiles {
    grid: PreviewGrid,
    worst: Vec<Class>,
    sum: Vec<f64>,
    n: Vec<u32>,
}

impl PreviewTiles {
    pub fn new(grid: PreviewGrid) -> PreviewTiles {
        let pixels = grid.pw * grid.ph;
        PreviewTiles {
            grid,
            worst: vec![Class::Unknown; pixels],
            sum: vec![0.0; pixels],
            n: vec![0; pixels],
        }
    }

    /// Adds tile `t`'s part; an error when the part is not of the pixels
    /// `t` falls in. Parts merged in the same order give the same
    /// preview, bit for bit.
    pub fn merge(&mut self, t: &TileWindow, part: &PreviewPart) -> Result<(), PieceError> {
        let want = self.grid.rect(t);
        if part.rect != want {
            return Err(PieceError {
                what: PreviewPart::WHAT,
                why: format!(
                    "of pixels {:?}, tile ({}, {}) falls in {want:?}",
                    part.rect, t.tx, t.ty
                ),
            });
        }
        let [px0, py0, w, _] = want;
        for (i, ((&k, &s), &n)) in part.worst.iter().zip(&part.sum).zip(&part.n).enumerate() {
            let p = (py0 + i / w) * self.grid.pw + px0 + i % w;
            self.worst[p] = worse(self.worst[p], k);
            self.sum[p] += s;
            self.n[p] = self.n[p].saturating_add(n);
        }
        Ok(())
    }

    /// The PNG, greys over `cost_range`.
    pub fn finish(&self, cost_range: [f64; 2]) -> Vec<u8> {
        let (pw, ph) = (self.grid.pw, self.grid.ph);
        let mut pixels = Vec::with_capacity(pw * ph * 4);
        for p in 0..pw * ph {
            pixels.extend_from_slice(&pixel(
                self.worst[p],
                self.sum[p],
                self.n[p] as usize,
                cost_range,
            ));
        }
        encode_png(&pixels, pw, ph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::halo::TileLayout;
    use crate::costmap::tile_bytes::testing::assert_refuses_damage;

    #[test]
    fn each_cell_falls_in_the_block_the_preview_averages() {
        for (cells, pixels) in [(10, 3), (7, 7), (1000, 64), (5, 1), (1024, 1000), (3, 2)] {
            for i in 0..cells {
                let p = pixel_of(i, cells, pixels);
                let (r0, r1) = (p * cells / pixels, (p + 1) * cells / pixels);
                assert!(r0 <= i && i < r1, "{cells} {pixels}: cell {i} in pixel {p}");
            }
        }
    }

    #[test]
    fn parts_cover_their_tiles_and_damaged_bytes_are_refused() {
        let (w, h) = (37, 23);
        let grid = PreviewGrid::new(w, h, 10);
        let layout = TileLayout::new(w, h, 6);
        let mut seen = 0;
        for k in 0..layout.count() {
            let t = layout.tile(k);
            let class: Vec<u8> = (0..t.width * t.height).map(|i| (i % 6) as u8).collect();
            let cost: Vec<f32> = (0..t.width * t.height).map(|i| 1.0 + i as f32).collect();
            let part = grid.part(&t, &cost, &class);
            seen += part.n.iter().map(|&n| n as usize).sum::<usize>();
            let bytes = part.to_bytes();
            assert_eq!(PreviewPart::from_bytes(&bytes).unwrap(), part);
            if k == 3 {
                assert_refuses_damage(&bytes, PreviewPart::from_bytes, 3);
            }
            // Another tile's part does not merge.
            let mut all = PreviewTiles::new(grid);
            all.merge(&t, &part).unwrap();
            let other = layout.tile((k + 1) % layout.count());
            assert!(all.merge(&other, &part).is_err());
        }
        // Every traversable cell was counted once.
        assert_eq!(
            seen,
            (0..layout.count())
                .map(|k| {
                    let t = layout.tile(k);
                    (0..t.width * t.height).filter(|i| i % 6 == 1).count()
                })
                .sum::<usize>()
        );
    }
}
