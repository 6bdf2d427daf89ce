//! A picture of a costmap and its legend.
//!
//! Like the thesis' figures 3.7–3.8, traversable cells are a grey ramp
//! from black (cheapest) to light grey (dearest); obstacles are coloured
//! by class so a slope, a step and an enclosed pocket can be told apart;
//! unknown cells are transparent. When the map is shrunk, a pixel shows
//! the worst obstacle in its block, so one-cell walls stay visible.

use rayon::prelude::*;

use super::{Class, Costmap};
use crate::xml::xml_escape;

/// RGB of each obstacle class and of unknown cells (drawn transparent).
pub fn class_colour(class: Class) -> [u8; 3] {
    match class {
        Class::Unknown => [255, 255, 255],
        Class::Traversable => [128, 128, 128],
        Class::Slope => [235, 140, 30],
        Class::Step => [205, 25, 30],
        Class::Enclosed => [140, 70, 170],
        Class::Other => [40, 100, 210],
    }
}

/// Grey level of a traversable cost in [lo, hi]: 15 (cheap) … 215.
fn grey(cost: f64, [lo, hi]: [f64; 2]) -> u8 {
    let t = ((cost - lo) / (hi - lo).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    (15.0 + 200.0 * t).round() as u8
}

/// Which obstacle a shrunk pixel shows when its block holds several.
fn priority(class: Class) -> u8 {
    match class {
        Class::Step => 4,
        Class::Slope => 3,
        Class::Other => 2,
        Class::Enclosed => 1,
        _ => 0,
    }
}

/// RGBA PNG of `map`, at most `max_side` pixels on its longer side (never
/// enlarged).
pub fn preview_png(map: &Costmap, max_side: usize) -> Vec<u8> {
    let (pw, ph) = preview_size(map.width, map.height, max_side);
    let range = map.stats.cost_range;
    let mut pixels = vec![0u8; pw * ph * 4];
    // Pixel rows in parallel: each reads its own band of the map.
    pixels
        .par_chunks_mut(pw * 4)
        .enumerate()
        .for_each(|(py, line)| {
            let r0 = py * map.height / ph;
            let r1 = ((py + 1) * map.height / ph).max(r0 + 1);
            for px in 0..pw {
                let c0 = px * map.width / pw;
                let c1 = ((px + 1) * map.width / pw).max(c0 + 1);
                let (mut worst, mut sum, mut n) = (Class::Unknown, 0.0, 0usize);
                for r in r0..r1 {
                    for c in c0..c1 {
                        let i = r * map.width + c;
                        let k = Class::from_code(map.class[i]).unwrap_or(Class::Unknown);
                        if k == Class::Traversable {
                            sum += f64::from(map.cost[i]);
                            n += 1;
                        } else if priority(k) > priority(worst) {
                            worst = k;
                        }
                    }
                }
                line[px * 4..px * 4 + 4].copy_from_slice(&pixel(worst, sum, n, range));
            }
        });
    encode_png(&pixels, pw, ph)
}

/// The preview's size for a `width`×`height` map: at most `max_side`
/// pixels on its longer side, never enlarged.
pub(super) fn preview_size(width: usize, height: usize, max_side: usize) -> (usize, usize) {
    let scale = (width.max(height) as f64 / max_side.max(1) as f64).max(1.0);
    let pw = ((width as f64 / scale).round() as usize).max(1);
    let ph = ((height as f64 / scale).round() as usize).max(1);
    (pw, ph)
}

/// A pixel's colour: the worst obstacle of its block, else the grey of
/// its mean traversable cost (`sum` / `n`), else transparent.
pub(super) fn pixel(worst: Class, sum: f64, n: usize, range: [f64; 2]) -> [u8; 4] {
    if worst != Class::Unknown {
        let [r, g, b] = class_colour(worst);
        [r, g, b, 255]
    } else if n > 0 {
        let v = grey(sum / n as f64, range);
        [v, v, v, 255]
    } else {
        [0, 0, 0, 0]
    }
}

/// Which obstacle a block shows: the one of higher priority.
pub(super) fn worse(a: Class, b: Class) -> Class {
    if priority(b) > priority(a) { b } else { a }
}

/// RGBA pixels as a PNG.
pub(super) fn encode_png(pixels: &[u8], pw: usize, ph: usize) -> Vec<u8> {
    let mut buf = Vec::new();
    {
        // Writing to memory only fails on sizes beyond u32, excluded above.
        let mut enc = png::Encoder::new(&mut buf, pw as u32, ph as u32);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().expect("PNG header in memory");
        writer.write_image_data(pixels).expect("PNG data in memory");
        writer.finish().expect("PNG end in memory");
    }
    buf
}

/// An SVG legend for [`preview_png`]: the cost ramp with its range, and
/// each obstacle class with its share of the map.
pub fn legend_svg(map: &Costmap) -> String {
    legend_svg_of(&map.stats, &map.vehicle.name)
}

/// [`legend_svg`] from a costmap's statistics and its vehicle's name.
pub fn legend_svg_of(stats: &super::CostmapStats, vehicle_name: &str) -> String {
    let [lo, hi] = stats.cost_range;
    let f = &stats.class_fractions;
    let rows = [
        (Class::Slope, "slope > max", f.slope),
        (Class::Step, "step > max", f.step),
        (Class::Enclosed, "enclosed pocket", f.enclosed),
        (Class::Other, "land cover / rough", f.other),
    ];
    let (g0, g1) = (grey(lo, [lo, hi]), grey(hi, [lo, hi]));
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"220\" height=\"{h}\" \
         font-family=\"sans-serif\" font-size=\"12\">\n\
         <defs><linearGradient id=\"ramp\"><stop offset=\"0\" stop-color=\"rgb({g0},{g0},{g0})\"/>\
         <stop offset=\"1\" stop-color=\"rgb({g1},{g1},{g1})\"/></linearGradient></defs>\n\
         <rect width=\"220\" height=\"{h}\" fill=\"white\"/>\n\
         <text x=\"8\" y=\"16\">traversing cost ({vehicle})</text>\n\
         <rect x=\"8\" y=\"24\" width=\"204\" height=\"14\" fill=\"url(#ramp)\"/>\n\
         <text x=\"8\" y=\"52\">{lo:.1}</text><text x=\"212\" y=\"52\" text-anchor=\"end\">{hi:.1}</text>\n",
        h = 74 + 20 * rows.len() + 20,
        vehicle = xml_escape(vehicle_name),
    );
    let mut y = 70;
    for (class, label, frac) in rows {
        let [r, g, b] = class_colour(class);
        s += &format!(
            "<rect x=\"8\" y=\"{}\" width=\"14\" height=\"14\" fill=\"rgb({r},{g},{b})\"/>\
             <text x=\"28\" y=\"{}\">{label} ({:.1} %)</text>\n",
            y - 11,
            y,
            100.0 * frac
        );
        y += 20;
    }
    s += &format!(
        "<rect x=\"8\" y=\"{}\" width=\"14\" height=\"14\" fill=\"none\" stroke=\"#999\"/>\
         <text x=\"28\" y=\"{y}\">unknown, transparent ({:.1} %)</text>\n</svg>\n",
        y - 11,
        100.0 * f.unknown
    );
    s
}
