//! Boolean operations on polygons: geo's semantics, through i_overlay with
//! a coarser integer grid for very large inputs.
//!
//! i_overlay maps the input's extent onto ±2²⁹ integers. Past 16 000
//! segments it splits them with its fragment solver, whose grid walk
//! (`FragmentBuffer::add_segment`, i_overlay 4.5) steps through a long
//! slanted segment in about width²·height / 2⁶³ increments: a field edge
//! crossing the whole extent at an angle costs ~10⁸ steps, and a survey with
//! 1 000 NFZs spent 75 % of its time there. For such inputs the grid is made
//! 2⁴ times coarser (still ~2⁻²⁵ of the extent: 0.03 mm over 2 km), which
//! divides those steps by 2¹²; smaller inputs are handled exactly as geo's
//! `BooleanOps` does.

use geo::winding_order::{Winding, WindingOrder};
use geo_types::{Coord, LineString, MultiPolygon, Polygon};
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::overlay::{FloatOverlay, OverlayOptions};
use i_overlay::i_float::adapter::FloatPointAdapter;
use i_overlay::i_float::float::rect::FloatRect;

/// Segments beyond which i_overlay uses its fragment solver.
const FRAGMENT_SEGMENTS: usize = 16_000;
/// Binary orders of magnitude by which the grid is coarsened beyond it.
const COARSEN_BITS: i32 = 4;

type Path = Vec<[f64; 2]>;

/// A ring as an implicitly closed path (i_overlay's form).
fn path(ring: &LineString<f64>) -> Path {
    let coords = match ring.0.as_slice() {
        [] => &[][..],
        c if c.len() > 1 && c[0] == c[c.len() - 1] => &c[..c.len() - 1],
        c => c,
    };
    coords.iter().map(|c| [c.x, c.y]).collect()
}

fn rings<'a>(polygons: impl IntoIterator<Item = &'a Polygon<f64>>) -> Vec<Path> {
    polygons
        .into_iter()
        .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
        .map(path)
        .filter(|p| !p.is_empty())
        .collect()
}

fn to_multi_polygon(shapes: Vec<Vec<Path>>) -> MultiPolygon<f64> {
    MultiPolygon(
        shapes
            .into_iter()
            .map(|shape| {
                let mut rings = shape.into_iter().map(|p| {
                    let mut ring = LineString(p.into_iter().map(|[x, y]| Coord { x, y }).collect());
                    ring.close();
                    ring
                });
                let exterior = rings.next().unwrap_or_else(|| LineString(vec![]));
                Polygon::new(exterior, rings.collect())
            })
            .collect(),
    )
}

fn overlay(
    subject: &[Path],
    clip: &[Path],
    rule: OverlayRule,
    fill: FillRule,
) -> MultiPolygon<f64> {
    if subject.is_empty() && clip.is_empty() {
        return MultiPolygon(vec![]);
    }
    let segments: usize = subject.iter().chain(clip).map(Vec::len).sum();
    let options = OverlayOptions::<f64>::ogc();
    let shapes = if segments > FRAGMENT_SEGMENTS {
        let points = subject.iter().chain(clip).flatten();
        let rect = FloatRect::with_iter(points).unwrap_or(FloatRect::zero());
        let half = (rect.width().max(rect.height()) / 2.0).max(f64::MIN_POSITIVE);
        // i_overlay's own scale is 2^(29 − ⌊log₂ half⌋).
        let scale = f64::from(29 - half.log2() as i32 - COARSEN_BITS);
        let adapter = FloatPointAdapter::with_scale(rect, scale.exp2());
        FloatOverlay::new_custom(adapter, options, Default::default(), segments)
            .unsafe_add_source(subject, ShapeType::Subject)
            .unsafe_add_source(clip, ShapeType::Clip)
            .overlay(rule, fill)
    } else {
        FloatOverlay::with_subj_and_clip_custom(subject, clip, options, Default::default())
            .overlay(rule, fill)
    };
    to_multi_polygon(shapes)
}

/// The union of `polygons` under `fill` (geo's
/// `union_with_fill_rule(&empty, fill)`).
pub fn union_with_fill_rule<'a>(
    polygons: impl IntoIterator<Item = &'a Polygon<f64>>,
    fill: FillRule,
) -> MultiPolygon<f64> {
    overlay(&rings(polygons), &[], OverlayRule::Union, fill)
}

/// geo's `unary_union`: rings counted with the orientation of the first one.
pub fn unary_union<'a>(polygons: impl IntoIterator<Item = &'a Polygon<f64>>) -> MultiPolygon<f64> {
    let polygons: Vec<&Polygon<f64>> = polygons.into_iter().collect();
    let first = polygons
        .iter()
        .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
        .find_map(|r| r.winding_order());
    let fill = if first == Some(WindingOrder::CounterClockwise) {
        FillRule::Positive
    } else {
        FillRule::Negative
    };
    overlay(&rings(polygons), &[], OverlayRule::Subject, fill)
}

/// `a − b` with the even-odd rule (geo's `difference`).
pub fn difference(a: &MultiPolygon<f64>, b: &MultiPolygon<f64>) -> MultiPolygon<f64> {
    overlay(
        &rings(a),
        &rings(b),
        OverlayRule::Difference,
        FillRule::EvenOdd,
    )
}

/// `a ∩ b` with the even-odd rule (geo's `intersection`).
pub fn intersection(a: &MultiPolygon<f64>, b: &MultiPolygon<f64>) -> MultiPolygon<f64> {
    overlay(
        &rings(a),
        &rings(b),
        OverlayRule::Intersect,
        FillRule::EvenOdd,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::{Area, BooleanOps};
    use geo_types::polygon;

    fn square(x: f64, y: f64, s: f64) -> Polygon<f64> {
        polygon![(x: x, y: y), (x: x + s, y: y), (x: x + s, y: y + s), (x: x, y: y + s)]
    }

    /// Many zones on a field whose edges are slanted (rotated by a small
    /// angle), enough segments for geo's automatic choice to use the
    /// fragment solver: both must give the same areas.
    fn slanted_field(zones: usize) -> (MultiPolygon<f64>, MultiPolygon<f64>) {
        let (s, c) = 0.37f64.to_radians().sin_cos();
        let turn = |p: &Polygon<f64>| {
            use geo::MapCoords;
            p.map_coords(|q| Coord {
                x: q.x * c - q.y * s,
                y: q.x * s + q.y * c,
            })
        };
        let field = MultiPolygon(vec![turn(&square(0.0, 0.0, 2000.0))]);
        let mut holes = Vec::new();
        let mut seed = 7u64;
        for _ in 0..zones {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let x = (seed >> 33) as f64 / (1u64 << 31) as f64 * 1990.0;
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let y = (seed >> 33) as f64 / (1u64 << 31) as f64 * 1990.0;
            let n = 12;
            let ring: Vec<Coord<f64>> = (0..n)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / n as f64;
                    Coord {
                        x: x + 4.0 * a.cos(),
                        y: y + 4.0 * a.sin(),
                    }
                })
                .collect();
            holes.push(turn(&Polygon::new(LineString(ring), vec![])));
        }
        (field, MultiPolygon(holes))
    }

    #[test]
    fn same_areas_as_geo() {
        let (field, zones) = slanted_field(1500);
        let ours = difference(&field, &union_with_fill_rule(&zones, FillRule::NonZero));
        let theirs =
            field.difference(&zones.union_with_fill_rule(&MultiPolygon(vec![]), FillRule::NonZero));
        let (a, b) = (ours.unsigned_area(), theirs.unsigned_area());
        assert!((a - b).abs() < 1e-6 * b, "{a} vs {b}");
        assert!(a < 4e6 && a > 3.9e6, "{a}");
        // The coarser grid moves vertices by ~3e-5 m: relative 1e-5 over
        // 1 500 zones' perimeters.
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * b;
        let cut = intersection(&field, &zones).unsigned_area();
        let want = field.intersection(&zones).unsigned_area();
        assert!(cut > 5e4 && close(cut, want), "{cut} vs {want}");
        let all = unary_union(zones.0.iter().chain(field.0.iter())).unsigned_area();
        let want = geo::unary_union(zones.0.iter().chain(field.0.iter())).unsigned_area();
        assert!(close(all, want), "{all} vs {want}");
    }

    #[test]
    fn overlapping_polygons_and_empty_input() {
        let a = square(0.0, 0.0, 10.0);
        let b = square(5.0, 5.0, 10.0);
        assert!((unary_union([&a, &b]).unsigned_area() - 175.0).abs() < 1e-9);
        assert!(
            (union_with_fill_rule([&a, &b], FillRule::NonZero).unsigned_area() - 175.0).abs()
                < 1e-9
        );
        assert!(unary_union(std::iter::empty()).0.is_empty());
        let one = MultiPolygon(vec![a.clone()]);
        assert!(
            (difference(&one, &MultiPolygon(vec![b.clone()])).unsigned_area() - 75.0).abs() < 1e-9
        );
        assert!((intersection(&one, &MultiPolygon(vec![b])).unsigned_area() - 25.0).abs() < 1e-9);
    }
}
