//! Hillshade preview of a DEM as an 8-bit grey + alpha PNG.
//!
//! GDAL's `gdaldem hillshade` defaults: sun azimuth 315° (north-west),
//! altitude 45°, Horn's 3×3 gradient, z-factor 1. The grey level is GDAL's
//!
//! ```text
//! cang  = (sin(alt) − cos(alt)·(∂z/∂N·cos(az) + ∂z/∂E·sin(az))) / √(1 + |∇z|²)
//!       = sin(alt)·cos(slope) + cos(alt)·sin(slope)·cos(az − aspect)
//! value = 1 + 254·cang, or 1 where cang ≤ 0,   rounded to the nearest integer
//! ```
//!
//! (the cosine of the angle between the surface normal and the sun; a flat
//! cell is `round(1 + 254·sin 45°)` = 181). The gradient is in metres per
//! metre: cell sizes of a geographic DEM are converted from degrees with the
//! local metres per degree of each row, and rotated geotransforms are
//! handled through the full Jacobian.
//!
//! Nodata cells are transparent (alpha 0, grey 0). Like GDAL's
//! `-compute_edges`, a nodata neighbour in the 3×3 window takes the centre
//! cell's height, and neighbours beyond the raster's edge are extrapolated
//! linearly from the two nearest cells (so a plane shades uniformly up to
//! the edges).
//!
//! Large DEMs are first reduced by an integer factor `f` (the smallest with
//! the longer side ≤ `max_side`) by averaging f×f blocks over their valid
//! cells; a block with fewer than half of its cells valid is nodata.

use super::cell_size::metres_per_degree;
use super::{Dem, GeoTransform};
use crate::cancel::Cancelled;

/// Largest `max_side` honoured (PNG previews beyond this are not useful).
const MAX_SIDE_LIMIT: usize = 16_384;

const AZIMUTH_DEG: f64 = 315.0;
const ALTITUDE_DEG: f64 = 45.0;

/// Hillshade of `dem` as a PNG (8-bit grey + alpha), at most `max_side`
/// pixels on its longer side (`max_side` is clamped to 1 ..= 16384). An
/// empty DEM gives a 1×1 transparent image. Checks the current thread's
/// cancellation token every row ([`crate::cancel`]).
pub fn hillshade_png(dem: &Dem, max_side: usize) -> Result<Vec<u8>, Cancelled> {
    let (grid, gw, gh, t) = downsample(dem, max_side.clamp(1, MAX_SIDE_LIMIT))?;
    let pixels = shade(&grid, gw, gh, &t, dem.crs.geographic)?;
    Ok(encode_png(gw, gh, &pixels).unwrap_or_default())
}

/// Grey + alpha pixels of the hillshade of `dem` at full resolution
/// (row-major, two bytes per cell).
#[cfg(test)]
fn hillshade_pixels(dem: &Dem) -> Vec<u8> {
    if dem.width == 0 || dem.height == 0 || dem.values.len() != dem.width * dem.height {
        return Vec::new();
    }
    shade(
        &dem.values,
        dem.width,
        dem.height,
        &dem.transform,
        dem.crs.geographic,
    )
    .expect("no cancellation token in tests")
}

/// A grid of heights: (values, width, height, geotransform).
type Grid = (Vec<f64>, usize, usize, GeoTransform);

/// The DEM reduced by block averaging so that its longer side is at most
/// `max_side`: (values, width, height, geotransform). Never empty.
fn downsample(dem: &Dem, max_side: usize) -> Result<Grid, Cancelled> {
    let (w, h) = (dem.width, dem.height);
    if w == 0 || h == 0 || dem.values.len() != w * h {
        return Ok((vec![f64::NAN], 1, 1, dem.transform));
    }
    let f = w.max(h).div_ceil(max_side).max(1);
    if f == 1 {
        return Ok((dem.values.clone(), w, h, dem.transform));
    }
    let (gw, gh) = (w.div_ceil(f), h.div_ceil(f));
    let mut sum = vec![0.0f64; gw];
    let mut count = vec![0u32; gw];
    let mut out = Vec::with_capacity(gw * gh);
    for by in 0..gh {
        crate::cancel::check()?;
        sum.fill(0.0);
        count.fill(0);
        let rows = by * f..((by + 1) * f).min(h);
        let n_rows = rows.len();
        for r in rows {
            for (c, &v) in dem.values[r * w..(r + 1) * w].iter().enumerate() {
                if !v.is_nan() {
                    sum[c / f] += v;
                    count[c / f] += 1;
                }
            }
        }
        for bx in 0..gw {
            let cells = (((bx + 1) * f).min(w) - bx * f) * n_rows;
            let valid = count[bx] as usize;
            out.push(if valid > 0 && 2 * valid >= cells {
                sum[bx] / valid as f64
            } else {
                f64::NAN
            });
        }
    }
    let t = dem.transform;
    let k = f as f64;
    let t = GeoTransform {
        origin_x: t.origin_x,
        pixel_width: t.pixel_width * k,
        row_rotation: t.row_rotation * k,
        origin_y: t.origin_y,
        col_rotation: t.col_rotation * k,
        pixel_height: t.pixel_height * k,
    };
    Ok((out, gw, gh, t))
}

/// Hillshade of a `w`×`h` grid (w, h ≥ 1) as grey + alpha bytes.
fn shade(
    g: &[f64],
    w: usize,
    h: usize,
    t: &GeoTransform,
    geographic: bool,
) -> Result<Vec<u8>, Cancelled> {
    let az = AZIMUTH_DEG.to_radians();
    let alt = ALTITUDE_DEG.to_radians();
    let (sin_alt, cos_alt) = alt.sin_cos();
    let (sin_az, cos_az) = az.sin_cos();
    let mut px = Vec::with_capacity(2 * w * h);

    // Height at (c, r), which may be one cell outside the grid: linear
    // extrapolation from the two nearest cells along each axis (the
    // nearest alone when the grid is one cell wide). NaN for nodata.
    let inside = |c: usize, r: usize| g[r * w + c];
    let along_row = |c: isize, r: usize| -> f64 {
        if c < 0 {
            if w >= 2 {
                2.0 * inside(0, r) - inside(1, r)
            } else {
                inside(0, r)
            }
        } else if c as usize >= w {
            if w >= 2 {
                2.0 * inside(w - 1, r) - inside(w - 2, r)
            } else {
                inside(w - 1, r)
            }
        } else {
            inside(c as usize, r)
        }
    };
    let at = |c: isize, r: isize| -> f64 {
        if r < 0 {
            if h >= 2 {
                2.0 * along_row(c, 0) - along_row(c, 1)
            } else {
                along_row(c, 0)
            }
        } else if r as usize >= h {
            if h >= 2 {
                2.0 * along_row(c, h - 1) - along_row(c, h - 2)
            } else {
                along_row(c, h - 1)
            }
        } else {
            along_row(c, r as usize)
        }
    };

    for r in 0..h {
        crate::cancel::check()?;
        // Jacobian of (col, row) → (east, north) metres at this row:
        // [[a, b], [cc, d]] with a = ∂E/∂col, b = ∂E/∂row, cc = ∂N/∂col,
        // d = ∂N/∂row.
        let [me, mn] = if geographic {
            metres_per_degree(t.apply(w as f64 / 2.0, r as f64 + 0.5).1)
        } else {
            [1.0, 1.0]
        };
        let (a, b) = (t.pixel_width * me, t.row_rotation * me);
        let (cc, d) = (t.col_rotation * mn, t.pixel_height * mn);
        let det = a * d - b * cc;
        let usable = det != 0.0 && det.is_finite();
        for c in 0..w {
            let z = inside(c, r);
            if z.is_nan() {
                px.extend_from_slice(&[0, 0]);
                continue;
            }
            let mut win = [0.0f64; 9];
            for (i, v) in win.iter_mut().enumerate() {
                let (dc, dr) = ((i % 3) as isize - 1, (i / 3) as isize - 1);
                let x = if dc == 0 && dr == 0 {
                    z
                } else {
                    at(c as isize + dc, r as isize + dr)
                };
                *v = if x.is_nan() { z } else { x };
            }
            // Horn: derivatives per column and per row.
            let dz_dc = ((win[2] + 2.0 * win[5] + win[8]) - (win[0] + 2.0 * win[3] + win[6])) / 8.0;
            let dz_dr = ((win[6] + 2.0 * win[7] + win[8]) - (win[0] + 2.0 * win[1] + win[2])) / 8.0;
            // [dz_dc, dz_dr] = Jᵀ·[∂z/∂E, ∂z/∂N]  ⇒ solve for the gradient.
            let (ge, gn) = if usable {
                (
                    (d * dz_dc - cc * dz_dr) / det,
                    (a * dz_dr - b * dz_dc) / det,
                )
            } else {
                (0.0, 0.0)
            };
            let cang = (sin_alt - cos_alt * (gn * cos_az + ge * sin_az))
                / (1.0 + ge * ge + gn * gn).sqrt();
            let v = if cang > 0.0 { 1.0 + 254.0 * cang } else { 1.0 };
            // NaN (overflowing gradients) → 1 through the clamp below.
            let v = if v.is_nan() {
                1.0
            } else {
                v.round().clamp(1.0, 255.0)
            };
            px.extend_from_slice(&[v as u8, 255]);
        }
    }
    Ok(px)
}

/// 8-bit grey + alpha PNG.
fn encode_png(w: usize, h: usize, pixels: &[u8]) -> Option<Vec<u8>> {
    let mut buf = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut buf, u32::try_from(w).ok()?, u32::try_from(h).ok()?);
        enc.set_color(png::ColorType::GrayscaleAlpha);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().ok()?;
        writer.write_image_data(pixels).ok()?;
        writer.finish().ok()?;
    }
    Some(buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::test_support::{dem, north_up};

    /// A `w`×`h` DEM of 10 m cells with height `f(east, north)` in metres.
    fn plane(w: usize, h: usize, f: impl Fn(f64, f64) -> f64) -> Dem {
        let t = north_up(0.0, 0.0, 10.0, 10.0);
        let mut v = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let (x, y) = t.apply(c as f64 + 0.5, r as f64 + 0.5);
                v.push(f(x, y));
            }
        }
        dem(w, h, v, t, false)
    }

    /// (width, height, grey+alpha bytes) of a PNG.
    fn decode(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::GrayscaleAlpha);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    /// GDAL's shade for a gradient (∂z/∂E, ∂z/∂N), for reference.
    fn expected(ge: f64, gn: f64) -> u8 {
        let (sa, ca) = 45f64.to_radians().sin_cos();
        let (sz, cz) = 315f64.to_radians().sin_cos();
        let cang = (sa - ca * (gn * cz + ge * sz)) / (1.0 + ge * ge + gn * gn).sqrt();
        if cang <= 0.0 {
            1
        } else {
            (1.0 + 254.0 * cang).round() as u8
        }
    }

    #[test]
    fn flat_is_181_everywhere_including_edges() {
        let d = plane(7, 5, |_, _| 250.0);
        let (w, h, px) = decode(&hillshade_png(&d, 100).unwrap());
        assert_eq!((w, h), (7, 5));
        assert_eq!(expected(0.0, 0.0), 181);
        assert!(px.chunks(2).all(|p| p == [181, 255]), "{px:?}");
    }

    #[test]
    fn slopes_facing_the_sun_are_bright() {
        // Rising to the south-east (facing north-west, towards the sun) at
        // 1 m/m on each axis, and the opposite.
        let nw = plane(6, 6, |x, y| x - y);
        let se = plane(6, 6, |x, y| y - x);
        let (_, _, a) = decode(&hillshade_png(&nw, 64).unwrap());
        let (_, _, b) = decode(&hillshade_png(&se, 64).unwrap());
        assert_eq!(expected(1.0, -1.0), 251);
        assert_eq!(expected(-1.0, 1.0), 1);
        // Planes shade uniformly, edges included (linear extrapolation).
        assert!(a.chunks(2).all(|p| p == [251, 255]), "{a:?}");
        assert!(b.chunks(2).all(|p| p == [1, 255]), "{b:?}");
        // A gentler slope towards the east: ∂z/∂E = −0.2.
        let east = plane(5, 4, |x, _| -0.2 * x);
        let (_, _, c) = decode(&hillshade_png(&east, 64).unwrap());
        assert!(c.chunks(2).all(|p| p == [expected(-0.2, 0.0), 255]));
        assert!(expected(-0.2, 0.0) < 181);
    }

    #[test]
    fn nodata_is_transparent_and_neighbours_still_shade() {
        let mut d = plane(5, 5, |x, y| 0.5 * x + 0.1 * y);
        d.values[2 * 5 + 2] = f64::NAN;
        d.values[0] = f64::NAN;
        let (_, _, px) = decode(&hillshade_png(&d, 5).unwrap());
        for (i, p) in px.chunks(2).enumerate() {
            if i == 12 || i == 0 {
                assert_eq!(p, [0, 0], "cell {i}");
            } else {
                assert_eq!(p[1], 255, "cell {i}");
                assert!(p[0] >= 1, "cell {i}");
            }
        }
        // A cell far from the hole keeps the plane's shade.
        let plane_shade = expected(0.5, 0.1);
        assert_eq!(px[2 * (4 * 5 + 4)], plane_shade);
    }

    #[test]
    fn downsampled_to_max_side() {
        // 300×200 → factor 3 → 100×67.
        let mut d = plane(300, 200, |x, y| (x * 0.01).sin() * 30.0 + y * 0.05);
        // Top-left 6×6 block fully nodata; a 3×3 block two-thirds nodata.
        for r in 0..6 {
            for c in 0..6 {
                d.values[r * 300 + c] = f64::NAN;
            }
        }
        for r in 9..12 {
            for c in 9..11 {
                d.values[r * 300 + c] = f64::NAN;
            }
        }
        let (w, h, px) = decode(&hillshade_png(&d, 100).unwrap());
        assert_eq!((w, h), (100, 67));
        let alpha = |c: usize, r: usize| px[2 * (r * 100 + c) + 1];
        assert_eq!(alpha(0, 0), 0);
        assert_eq!(alpha(1, 1), 0);
        assert_eq!(alpha(3, 3), 0);
        assert_eq!(alpha(2, 2), 255);
        assert_eq!(alpha(99, 66), 255);
        // Larger than the DEM: full size; silly values clamped.
        let (w, h, _) = decode(&hillshade_png(&d, 10_000).unwrap());
        assert_eq!((w, h), (300, 200));
        let (w, h, px) = decode(&hillshade_png(&d, 0).unwrap());
        assert_eq!((w, h), (1, 1));
        assert_eq!(px[1], 255);
        let (w, h, _) = decode(&hillshade_png(&d, 7).unwrap());
        assert_eq!((w, h), (7, 5));
    }

    #[test]
    fn downsampled_plane_keeps_its_shade() {
        // Block averages of a plane are the plane on the coarser grid.
        let d = plane(90, 60, |x, y| 0.3 * x - 0.2 * y);
        let (w, h, px) = decode(&hillshade_png(&d, 30).unwrap());
        assert_eq!((w, h), (30, 20));
        let e = expected(0.3, -0.2);
        assert!(px.chunks(2).all(|p| p == [e, 255]), "{e} {px:?}");
    }

    #[test]
    fn geographic_cells_are_converted_to_metres() {
        // 0.001° cells at 60°N; heights rising 5 m per column (east) and
        // 3 m per row southwards.
        let (w, h) = (8, 8);
        let t = north_up(10.0, 60.004, 0.001, 0.001);
        let mut v = Vec::new();
        for r in 0..h {
            for c in 0..w {
                v.push(5.0 * c as f64 + 3.0 * r as f64);
            }
        }
        let d = dem(w, h, v, t, true);
        let px = hillshade_pixels(&d);
        for r in 0..h {
            let lat = t.apply(4.0, r as f64 + 0.5).1;
            let [me, mn] = metres_per_degree(lat);
            let e = expected(5.0 / (0.001 * me), -3.0 / (0.001 * mn));
            for c in 0..w {
                assert_eq!(px[2 * (r * w + c)], e, "({c}, {r})");
            }
        }
        // Taken as metres the slope would be ~1000× steeper: nearly black
        // or white, not this moderate grey.
        assert!((px[0] as i32 - 181).abs() < 60, "{}", px[0]);
    }

    #[test]
    fn rotated_transform_uses_the_jacobian() {
        // Rows run east, columns run south (90° rotation); the plane
        // z = 0.4·E + 0.1·N must shade like the north-up one.
        let t = GeoTransform {
            origin_x: 0.0,
            pixel_width: 0.0,
            row_rotation: 10.0,
            origin_y: 0.0,
            col_rotation: -10.0,
            pixel_height: 0.0,
        };
        let (w, h) = (6, 5);
        let mut v = Vec::new();
        for r in 0..h {
            for c in 0..w {
                let (x, y) = t.apply(c as f64 + 0.5, r as f64 + 0.5);
                v.push(0.4 * x + 0.1 * y);
            }
        }
        let px = hillshade_pixels(&dem(w, h, v, t, false));
        let e = expected(0.4, 0.1);
        assert!(px.chunks(2).all(|p| p == [e, 255]), "{e} {px:?}");
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let empty = dem(0, 0, vec![], north_up(0.0, 0.0, 1.0, 1.0), false);
        let (w, h, px) = decode(&hillshade_png(&empty, 256).unwrap());
        assert_eq!((w, h, px), (1, 1, vec![0, 0]));
        let one = dem(1, 1, vec![3.0], north_up(0.0, 0.0, 1.0, 1.0), false);
        let (_, _, px) = decode(&hillshade_png(&one, 256).unwrap());
        assert_eq!(px, vec![181, 255]);
        let line = dem(
            4,
            1,
            vec![0.0, 1.0, 2.0, 3.0],
            north_up(0.0, 0.0, 1.0, 1.0),
            false,
        );
        let (w, h, _) = decode(&hillshade_png(&line, 256).unwrap());
        assert_eq!((w, h), (4, 1));
        let nodata = dem(3, 2, vec![f64::NAN; 6], north_up(0.0, 0.0, 1.0, 1.0), false);
        let (_, _, px) = decode(&hillshade_png(&nodata, 256).unwrap());
        assert!(px.iter().all(|&b| b == 0));
        let singular = dem(
            2,
            2,
            vec![1.0, 2.0, 3.0, 4.0],
            north_up(0.0, 0.0, 0.0, 0.0),
            false,
        );
        let (_, _, px) = decode(&hillshade_png(&singular, 256).unwrap());
        assert!(px.chunks(2).all(|p| p == [181, 255]));
    }
}
