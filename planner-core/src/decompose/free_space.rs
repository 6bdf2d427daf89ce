//! Free space: the region of interest minus the union of the no-fly zones.

use geo::algorithm::bool_ops::FillRule;

use crate::overlay;
use geo::orient::Direction;
use geo::{Area, BoundingRect, CoordsIter, Intersects, Orient};
use geo_types::{MultiPolygon, Polygon};

use super::ring::signed_area;

/// ROI minus the union of the NFZs. NFZs may overlap each other, touch, cross
/// the ROI border or lie outside it.
///
/// Rings may have either orientation. Pieces and holes whose area is below
/// 10⁻¹² of the ROI's bounding box (rounding debris of the boolean
/// operations) are dropped.
///
/// A non-finite coordinate in the ROI or in any NFZ yields an empty free
/// space: an NFZ that cannot be read must not be ignored, so nothing is
/// planned rather than something unsafe. Inputs are expected to have been
/// validated before (see `crate::geo`).
pub fn free_space(roi: &Polygon<f64>, nfzs: &[Polygon<f64>]) -> MultiPolygon<f64> {
    let finite = |p: &Polygon<f64>| p.coords_iter().all(|c| c.x.is_finite() && c.y.is_finite());
    if !finite(roi) || !nfzs.iter().all(finite) {
        return MultiPolygon::new(vec![]);
    }
    let Some(bbox) = roi.bounding_rect() else {
        return MultiPolygon::new(vec![]);
    };
    let min_area = 1e-12 * bbox.width().max(bbox.height()).powi(2);

    // Zones clear of the ROI's bounding box cannot matter; leaving them out
    // also keeps the boolean operations' integer grid, which is relative to
    // the extent of their input, as fine as the ROI allows.
    let relevant = nfzs
        .iter()
        .filter(|z| z.bounding_rect().is_some_and(|b| b.intersects(&bbox)));
    // Non-zero union of consistently oriented zones: overlaps count once,
    // and a self-crossing zone still blocks all of its lobes.
    let zones: Vec<Polygon<f64>> = relevant.map(|z| z.orient(Direction::Default)).collect();
    let blocked = overlay::union_with_fill_rule(&zones, FillRule::NonZero);
    let free = overlay::difference(
        &MultiPolygon(vec![roi.orient(Direction::Default)]),
        &blocked,
    );

    free.into_iter()
        .filter(|p| p.unsigned_area() > min_area)
        .map(|p| {
            let (exterior, holes) = p.into_inner();
            let holes = holes
                .into_iter()
                .filter(|h| signed_area(&h.0).abs() > min_area)
                .collect();
            Polygon::new(exterior, holes)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decompose::decompose;
    use crate::decompose::test_support::{assert_valid_decomposition, poly, rect};
    use geo::{Contains, Point};

    fn roi() -> Polygon<f64> {
        rect(0.0, 0.0, 10.0, 10.0)
    }

    /// Decomposes at a few angles and checks the invariants.
    fn decomposes(free: &MultiPolygon<f64>) {
        for angle in [0.0, 30.0, 90.0, 135.0] {
            let cells = decompose(free, angle).unwrap();
            assert_valid_decomposition(free, &cells, angle);
        }
    }

    #[test]
    fn no_zones_is_the_roi() {
        let free = free_space(&roi(), &[]);
        assert_eq!(free.0.len(), 1);
        assert_eq!(free.unsigned_area(), 100.0);
        assert_eq!(decompose(&free, 0.0).unwrap().len(), 1);
    }

    #[test]
    fn zone_inside_becomes_a_hole() {
        let free = free_space(&roi(), &[rect(2.0, 2.0, 4.0, 5.0)]);
        assert_eq!(free.0.len(), 1);
        assert_eq!(free.0[0].interiors().len(), 1);
        assert!((free.unsigned_area() - 94.0).abs() < 1e-9);
        assert_eq!(decompose(&free, 0.0).unwrap().len(), 4);
        decomposes(&free);
    }

    #[test]
    fn zone_crossing_the_border_cuts_a_notch() {
        let free = free_space(&roi(), &[rect(8.0, 3.0, 12.0, 6.0)]);
        assert_eq!(free.0.len(), 1);
        assert!(free.0[0].interiors().is_empty());
        assert!((free.unsigned_area() - 94.0).abs() < 1e-9);
        assert!(!free.contains(&Point::new(9.0, 4.5)));
        // West of the notch, then south and north of it.
        assert_eq!(decompose(&free, 0.0).unwrap().len(), 3);
        decomposes(&free);
    }

    #[test]
    fn overlapping_zones_are_removed_once() {
        let zones = [rect(2.0, 2.0, 5.0, 5.0), rect(4.0, 4.0, 7.0, 7.0)];
        let free = free_space(&roi(), &zones);
        assert!((free.unsigned_area() - (100.0 - 17.0)).abs() < 1e-9);
        assert_eq!(free.0[0].interiors().len(), 1);
        decomposes(&free);
    }

    #[test]
    fn zone_touching_the_border() {
        // Touching from inside along the west side, and from outside at a corner.
        let zones = [rect(0.0, 4.0, 2.0, 6.0), rect(10.0, 10.0, 12.0, 12.0)];
        let free = free_space(&roi(), &zones);
        assert_eq!(free.0.len(), 1);
        assert!((free.unsigned_area() - 96.0).abs() < 1e-9);
        decomposes(&free);
        // The notch splits the north–south sweep in two west of x = 2.
        assert_eq!(decompose(&free, 0.0).unwrap().len(), 3);
    }

    #[test]
    fn zone_outside_the_roi_changes_nothing() {
        let free = free_space(&roi(), &[rect(20.0, 20.0, 30.0, 30.0)]);
        assert_eq!(free.0.len(), 1);
        assert_eq!(free.unsigned_area(), 100.0);
        assert_eq!(decompose(&free, 0.0).unwrap().len(), 1);
    }

    #[test]
    fn far_away_zone_does_not_coarsen_the_result() {
        // The boolean operations snap to an integer grid relative to the
        // extent of their input: with a zone 10 000 km away in it, that grid
        // would be 1/64 m. Left out, the ROI keeps its shape to ~10⁻⁸ m.
        let roi = poly(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (3.123_456_789, 10.0)]);
        let far = rect(1e7, 1e7, 1e7 + 1.0, 1e7 + 1.0);
        let free = free_space(&roi, &[far, rect(4.0, 4.0, 5.0, 5.0)]);
        let corner = free.0[0]
            .exterior()
            .0
            .iter()
            .find(|c| c.y > 9.0 && c.x < 5.0)
            .unwrap();
        assert!((corner.x - 3.123_456_789).abs() < 1e-7, "{corner:?}");
    }

    #[test]
    fn zone_splitting_the_roi_gives_two_components() {
        let free = free_space(&roi(), &[rect(4.0, -1.0, 6.0, 11.0)]);
        assert_eq!(free.0.len(), 2);
        assert!((free.unsigned_area() - 80.0).abs() < 1e-9);
        decomposes(&free);
    }

    #[test]
    fn zones_touching_each_other_and_hole_touching_the_border() {
        // Two zones sharing an edge, one of them touching the south border at
        // a single point: the hole touches the exterior.
        let zones = [
            poly(&[(3.0, 0.0), (5.0, 3.0), (1.0, 3.0)]),
            rect(1.0, 3.0, 5.0, 5.0),
            poly(&[(7.0, 7.0), (8.0, 7.0), (8.0, 8.0)]),
        ];
        let free = free_space(&roi(), &zones);
        assert!((free.unsigned_area() - (100.0 - 6.0 - 8.0 - 0.5)).abs() < 1e-9);
        decomposes(&free);
    }

    #[test]
    fn clockwise_and_self_crossing_zones() {
        let mut cw = rect(2.0, 2.0, 4.0, 4.0);
        cw.exterior_mut(|r| r.0.reverse());
        // A bow-tie: both lobes are no-fly.
        let bowtie = poly(&[(6.0, 6.0), (8.0, 8.0), (8.0, 6.0), (6.0, 8.0)]);
        let free = free_space(&roi(), &[cw, bowtie]);
        assert!((free.unsigned_area() - (100.0 - 4.0 - 2.0)).abs() < 1e-9);
        assert!(!free.contains(&Point::new(6.2, 7.0)));
        assert!(!free.contains(&Point::new(7.8, 7.0)));
    }

    #[test]
    fn zone_covering_everything_leaves_nothing() {
        let free = free_space(&roi(), &[rect(-1.0, -1.0, 11.0, 11.0)]);
        assert!(free.0.is_empty());
        assert_eq!(
            decompose(&free, 0.0),
            Err(crate::decompose::DecomposeError::EmptyFreeSpace)
        );
    }

    #[test]
    fn non_finite_input_is_empty() {
        let bad = poly(&[(1.0, 1.0), (f64::NAN, 2.0), (1.0, 3.0)]);
        assert!(free_space(&roi(), std::slice::from_ref(&bad)).0.is_empty());
        assert!(free_space(&bad, &[]).0.is_empty());
    }
}
