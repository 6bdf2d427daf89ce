//! Property tests for `planner_core::decompose`: on random regions of
//! interest with random no-fly zones, and on random slice angles, every
//! output invariant of SPEC §3.2 must hold.

use std::time::Instant;

use geo::{Area, BoundingRect, Validation, Winding, unary_union};
use geo_types::{Coord, LineString, MultiPolygon, Polygon};
use planner_core::coverage::{self, CellLayouts, FreeSpace};
use planner_core::decompose::{
    DecomposeError, PreparedFree, decompose, decompose_merged, free_space,
};
use proptest::prelude::*;

fn poly(v: Vec<(f64, f64)>) -> Polygon<f64> {
    Polygon::new(LineString::from(v), vec![])
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
    poly(vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
}

/// A star-shaped polygon around `c`: vertex k at angle 2πk/n (plus jitter)
/// and the given radius, so it is simple.
fn star(c: (f64, f64), radii: &[f64], jitter: &[f64], phase: f64) -> Polygon<f64> {
    let n = radii.len();
    let step = std::f64::consts::TAU / n as f64;
    poly(
        radii
            .iter()
            .zip(jitter)
            .enumerate()
            .map(|(k, (&r, &j))| {
                let a = phase + step * (k as f64 + 0.8 * j);
                (c.0 + r * a.cos(), c.1 + r * a.sin())
            })
            .collect(),
    )
}

/// Position across slice lines of bearing `deg`; slice lines are its level sets.
fn across(deg: f64) -> impl Fn(Coord<f64>) -> f64 {
    let (s, c) = deg.to_radians().sin_cos();
    move |p| p.x * c - p.y * s
}

/// Number of times the slice line `h = level` crosses the cell's boundary.
fn crossings(cell: &Polygon<f64>, h: &impl Fn(Coord<f64>) -> f64, level: f64) -> usize {
    cell.exterior()
        .lines()
        .filter(|l| (h(l.start) - level) * (h(l.end) - level) < 0.0)
        .count()
}

/// Asserts all invariants of SPEC §3.2 for `cells` = decompose(free, deg);
/// `lines` are random slice lines as fractions of the free space's extent.
fn assert_invariants(free: &MultiPolygon<f64>, cells: &[Polygon<f64>], deg: f64, lines: &[f64]) {
    let free_area = free.unsigned_area();
    let bbox = free.bounding_rect().unwrap();
    let size = bbox.width().max(bbox.height());
    let h = across(deg);

    for (i, cell) in cells.iter().enumerate() {
        assert!(cell.interiors().is_empty(), "cell {i} has a hole");
        let ring = &cell.exterior().0;
        assert!(ring.len() >= 4);
        assert_eq!(ring.first(), ring.last(), "cell {i} not closed");
        assert!(cell.exterior().is_ccw(), "cell {i} not CCW: {cell:?}");
        assert!(
            cell.is_valid(),
            "cell {i} not simple: {:?} {cell:?}",
            cell.validation_errors()
        );
        let open = &ring[..ring.len() - 1];
        let n = open.len();
        for k in 0..n {
            let (a, b, c) = (open[k], open[(k + 1) % n], open[(k + 2) % n]);
            assert_ne!(a, b, "cell {i} has a duplicate vertex");
            let (u, v) = (c - a, b - a);
            let dist = (u.x * v.y - u.y * v.x).abs() / u.x.hypot(u.y);
            assert!(
                dist > 1e-12 * size,
                "cell {i}: {b:?} is collinear with its neighbours"
            );
        }
        // Monotone: just beside every vertex (where a fold would show) a
        // slice line meets the boundary at most twice.
        let hs: Vec<f64> = open.iter().map(|&p| h(p)).collect();
        let (lo, hi) = min_max(hs.iter().copied());
        for &v in &hs {
            for level in [v - 1e-7 * (hi - lo), v + 1e-7 * (hi - lo)] {
                if level > lo && level < hi {
                    assert!(
                        crossings(cell, &h, level) <= 2,
                        "cell {i} folds at h={level}: {cell:?}"
                    );
                }
            }
        }
    }

    // Pairwise overlap, integrated along the sweep (see `overlap_area`).
    let frames: Vec<Vec<(f64, f64)>> = cells
        .iter()
        .map(|c| slice_frame(c.exterior(), deg, bbox.min()))
        .collect();
    for i in 0..cells.len() {
        for j in i + 1..cells.len() {
            let overlap = overlap_area(&frames[i], &frames[j]);
            assert!(
                overlap <= 1e-9 * free_area,
                "cells {i} and {j} overlap by {overlap}"
            );
        }
    }

    let total: f64 = cells.iter().map(|c| c.unsigned_area()).sum();
    assert!(
        (total - free_area).abs() <= 1e-6 * free_area,
        "cells {total} vs free space {free_area}"
    );

    // Monotone and covering, line by line: on random slice lines and just
    // beside every vertex of the free space each cell meets the line in at
    // most one segment.
    let free_rings: Vec<Vec<(f64, f64)>> = free
        .iter()
        .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
        .map(|r| slice_frame(r, deg, bbox.min()))
        .collect();
    let (lo, hi) = h_range(free_rings.iter().flatten());
    let d = 1e-7 * (hi - lo);
    let mut levels: Vec<f64> = lines.iter().map(|t| lo + t * (hi - lo)).collect();
    levels.extend(free_rings.iter().flatten().flat_map(|v| [v.0 - d, v.0 + d]));
    for level in levels.into_iter().filter(|&l| l > lo && l < hi) {
        for (i, cell) in frames.iter().enumerate() {
            let k = cut(cell, level).count();
            assert!(
                k == 0 || k == 2,
                "slice line h={level} meets cell {i} {k} times"
            );
        }
    }
    // The union of the cells is the free space: the length of the symmetric
    // difference on each slice line, integrated across the sweep, is an area.
    // (Measured along single lines it would be ill-conditioned: where the
    // boundary is nearly parallel to the slice, the clean-up grid of
    // `decompose` moves crossings a long way along the line.)
    let mismatch = integrate_between_vertices(free_rings.iter().chain(&frames), |h| {
        line_mismatch(&free_rings, &frames, h)
    });
    assert!(
        mismatch <= 1e-6 * free_area,
        "cells differ from the free space by {mismatch}"
    );
}

/// Smallest and largest of `values`; (∞, −∞) if there are none.
fn min_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), v| {
        (l.min(v), u.max(v))
    })
}

/// Range of h (the first slice coordinate) over `vertices`.
fn h_range<'a>(vertices: impl Iterator<Item = &'a (f64, f64)>) -> (f64, f64) {
    min_max(vertices.map(|v| v.0))
}

/// ∫ f(h) dh over the h-range of `rings`, for f piecewise smooth between
/// their vertices: eight trapezoids per span, sampled just inside it so that
/// no sample line passes through a vertex. Spans shorter than 10⁻⁹ of the
/// range (vertices level with each other up to rounding) are skipped.
fn integrate_between_vertices<'a>(
    rings: impl Iterator<Item = &'a Vec<(f64, f64)>>,
    f: impl Fn(f64) -> f64,
) -> f64 {
    let mut breaks: Vec<f64> = rings.flatten().map(|v| v.0).collect();
    breaks.sort_by(f64::total_cmp);
    let Some((&lo, &hi)) = breaks.first().zip(breaks.last()) else {
        return 0.0;
    };
    let tiny = 1e-9 * (hi - lo);
    breaks.dedup_by(|b, a| *b - *a <= tiny);
    let mut total = 0.0;
    for w in breaks.windows(2) {
        let (a, b) = (w[0], w[1]);
        let d = 1e-3 * (b - a);
        let samples: Vec<f64> = (0..=8)
            .map(|k| f((a + (b - a) * k as f64 / 8.0).clamp(a + d, b - d)))
            .collect();
        total += samples.windows(2).map(|s| (s[0] + s[1]) / 2.0).sum::<f64>() * (b - a) / 8.0;
    }
    total
}

/// Where the line h = level crosses the edges of a ring in slice
/// coordinates. Half-open (an end counts on the side h ≤ level), so a closed
/// ring is always crossed an even number of times, even through a vertex.
fn cut(ring: &[(f64, f64)], level: f64) -> impl Iterator<Item = f64> + '_ {
    let n = ring.len();
    (0..n).filter_map(move |k| {
        let (a, b) = (ring[k], ring[(k + 1) % n]);
        ((a.0 <= level) != (b.0 <= level)).then(|| a.1 + (b.1 - a.1) * (level - a.0) / (b.0 - a.0))
    })
}

/// Length of the symmetric difference, on the line h = level, between the
/// free space (even–odd over all its rings) and the union of the cells.
fn line_mismatch(free_rings: &[Vec<(f64, f64)>], cells: &[Vec<(f64, f64)>], level: f64) -> f64 {
    let mut free: Vec<f64> = free_rings.iter().flat_map(|r| cut(r, level)).collect();
    free.sort_by(f64::total_cmp);
    assert!(free.len().is_multiple_of(2));
    // (position, change of free-space cover, change of cell cover)
    let mut events: Vec<(f64, i32, i32)> = free
        .chunks(2)
        .flat_map(|p| [(p[0], 1, 0), (p[1], -1, 0)])
        .collect();
    for cell in cells {
        if let Some((a, b)) = extent(cell, level) {
            events.extend([(a, 0, 1), (b, 0, -1)]);
        }
    }
    events.sort_by(|p, q| p.0.total_cmp(&q.0));
    let (mut in_free, mut in_cells, mut mismatch) = (0, 0, 0.0);
    for w in 0..events.len() {
        in_free += events[w].1;
        in_cells += events[w].2;
        if let Some(next) = events.get(w + 1)
            && (in_free > 0) != (in_cells > 0)
        {
            mismatch += next.0 - events[w].0;
        }
    }
    mismatch
}

/// An open ring in slice coordinates (h across the slice lines, g along
/// them), relative to `origin` to keep UTM-sized values precise.
fn slice_frame(ring: &LineString<f64>, deg: f64, origin: Coord<f64>) -> Vec<(f64, f64)> {
    let (s, c) = deg.to_radians().sin_cos();
    let ring = &ring.0;
    ring[..ring.len() - 1]
        .iter()
        .map(|&p| {
            let d = p - origin;
            (d.x * c - d.y * s, d.x * s + d.y * c)
        })
        .collect()
}

/// Extent (min g, max g) of a slice-monotone ring on the line h = level.
fn extent(ring: &[(f64, f64)], level: f64) -> Option<(f64, f64)> {
    cut(ring, level).fold(None, |acc, g| match acc {
        None => Some((g, g)),
        Some((lo, hi)) => Some((f64::min(lo, g), f64::max(hi, g))),
    })
}

/// Area of the intersection of two slice-monotone rings: the overlap of
/// their extents on each slice line, integrated across the sweep. (The
/// boolean-ops intersection is not used: its integer snapping leaves slivers
/// of ~10⁻⁹ of the extent along shared edges, right at the tolerance.)
fn overlap_area(p: &Vec<(f64, f64)>, q: &Vec<(f64, f64)>) -> f64 {
    let ((pl, ph), (ql, qh)) = (h_range(p.iter()), h_range(q.iter()));
    if pl.max(ql) >= ph.min(qh) {
        return 0.0;
    }
    integrate_between_vertices([p, q].into_iter(), |h| match (extent(p, h), extent(q, h)) {
        (Some(a), Some(b)) => (a.1.min(b.1) - a.0.max(b.0)).max(0.0),
        _ => 0.0,
    })
}

/// A random no-fly zone near a region of radius `r` around `c`: a (possibly
/// rotated) rectangle or a small star, anywhere from well inside to outside.
fn nfz(c: (f64, f64), r: f64) -> impl Strategy<Value = Polygon<f64>> {
    let centre = (-1.3f64..1.3, -1.3f64..1.3).prop_map(move |(u, v)| (c.0 + u * r, c.1 + v * r));
    prop_oneof![
        (
            centre.clone(),
            0.02f64..0.4,
            0.02f64..0.4,
            prop_oneof![Just(0.0), 0.0f64..3.2]
        )
            .prop_map(move |(m, w, hgt, rot)| {
                let (s, co) = rot.sin_cos();
                let pts = [(-w, -hgt), (w, -hgt), (w, hgt), (-w, hgt)]
                    .map(|(x, y)| (m.0 + r * (x * co - y * s), m.1 + r * (x * s + y * co)));
                poly(pts.to_vec())
            }),
        (
            centre,
            prop::collection::vec((0.03f64..0.3, 0.0f64..1.0), 3..9),
            0.0f64..6.3
        )
            .prop_map(move |(m, v, phase)| {
                let radii: Vec<f64> = v.iter().map(|p| p.0 * r).collect();
                let jitter: Vec<f64> = v.iter().map(|p| p.1).collect();
                star(m, &radii, &jitter, phase)
            }),
    ]
}

fn angle() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => 0.0f64..180.0,
        1 => prop::sample::select(vec![0.0, 45.0, 90.0, 135.0]),
    ]
}

/// Random star-shaped ROI (at the origin or at UTM-sized coordinates), random
/// zones, random slice angle.
fn survey() -> impl Strategy<Value = (Polygon<f64>, Vec<Polygon<f64>>, f64)> {
    (
        prop::sample::select(vec![(0.0, 0.0), (500_000.0, 5_000_000.0)]),
        3usize..20,
        0.0f64..6.3,
    )
        .prop_flat_map(|(c, n, phase)| {
            let r = 1000.0;
            (
                prop::collection::vec(0.3f64..1.0, n),
                prop::collection::vec(0.0f64..1.0, n),
                prop::collection::vec(nfz(c, r), 0..8),
                angle(),
            )
                .prop_map(move |(radii, jitter, zones, a)| {
                    let radii: Vec<f64> = radii.iter().map(|q| q * r).collect();
                    (star(c, &radii, &jitter, phase), zones, a)
                })
        })
}

/// Rectilinear inputs on an integer grid: many vertices share slice lines,
/// zones touch, overlap, share edges with each other and with the border.
/// Corners are sometimes nudged by 10⁻¹²…10⁻⁵ (slivers, near-touches), the
/// slice is often (nearly) parallel to the edges, and the whole scene is
/// sometimes moved to UTM-sized coordinates.
fn grid_survey() -> impl Strategy<Value = (Polygon<f64>, Vec<Polygon<f64>>, f64)> {
    let nudge = || {
        prop::sample::select(vec![
            0.0, 0.0, 0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5,
        ])
    };
    let zone = (
        (-1i32..11, -1i32..9, 1i32..5, 1i32..5),
        (nudge(), nudge(), nudge(), nudge()),
    )
        .prop_map(|((x, y, w, h), (a, b, c, d))| {
            let (x0, y0, x1, y1) = (x as f64, y as f64, (x + w) as f64, (y + h) as f64);
            poly(vec![
                (x0 + a, y0 + b),
                (x1 + c, y0 + d),
                (x1 - b, y1 + a),
                (x0 - d, y1 - c),
            ])
        });
    let angle = prop_oneof![
        prop::sample::select(vec![
            0.0,
            90.0,
            45.0,
            135.0,
            1e-9,
            179.99999999,
            90.0000001,
            89.99999
        ]),
        0.0f64..180.0,
    ];
    (prop::collection::vec(zone, 0..10), angle, any::<bool>()).prop_map(|(zones, deg, utm)| {
        let (o, scale) = if utm {
            ((500_000.0, 5_000_000.0), 30.0)
        } else {
            ((0.0, 0.0), 1.0)
        };
        let place = |p: Polygon<f64>| {
            poly(
                p.exterior().0[..4]
                    .iter()
                    .map(|c| (o.0 + scale * c.x, o.1 + scale * c.y))
                    .collect(),
            )
        };
        (
            place(rect(0.0, 0.0, 10.0, 8.0)),
            zones.into_iter().map(place).collect(),
            deg,
        )
    })
}

/// Bearing (degrees clockwise from north) of the line through a and b.
fn bearing(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let d = b - a;
    d.x.atan2(d.y).to_degrees().rem_euclid(180.0)
}

/// Slices (nearly) parallel to an edge of the ROI — what an automatic angle
/// choice produces — with zones whose corner touches an ROI edge mid-way.
fn edge_aligned_survey() -> impl Strategy<Value = (Polygon<f64>, Vec<Polygon<f64>>, f64)> {
    let touching = (
        any::<prop::sample::Index>(),
        0.05f64..0.95,
        -0.3f64..0.3,
        0.02f64..0.2,
        0.02f64..0.2,
    );
    (
        survey(),
        any::<prop::sample::Index>(),
        prop::sample::select(vec![
            0.0, 0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5,
        ]),
        prop::collection::vec(touching, 0..4),
    )
        .prop_map(|((roi, mut zones, _), edge, nudge, touching)| {
            let ring = &roi.exterior().0;
            let n = ring.len() - 1;
            let k = edge.index(n);
            let deg = bearing(ring[k], ring[k + 1]) + nudge;
            for (j, t, skew, a, b) in touching {
                let j = j.index(n);
                let d = ring[j + 1] - ring[j];
                let v = ring[j] + d * t;
                // The ROI is CCW, so its inside is to the left of d.
                let inward = Coord { x: -d.y, y: d.x };
                let w1 = v + inward * a + d * (skew * a);
                let w2 = v + inward * b - d * (0.5 * b);
                zones.push(Polygon::new(LineString::from(vec![v, w1, w2]), vec![]));
            }
            (roi, zones, deg)
        })
}

/// Eight random slice lines, as fractions of the free space's extent.
fn slice_lines() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(0.0f64..1.0, 8)
}

/// Decomposes `roi` minus `zones` at `deg` and asserts all invariants on the
/// cells. Zones may cover the whole ROI; that is the one allowed error, and
/// then the free space is returned for the caller's own checks.
fn check_survey(
    roi: &Polygon<f64>,
    zones: &[Polygon<f64>],
    deg: f64,
    lines: &[f64],
) -> Result<Option<MultiPolygon<f64>>, TestCaseError> {
    let free = free_space(roi, zones);
    match decompose(&free, deg) {
        Ok(cells) => {
            assert_invariants(&free, &cells, deg, lines);
            // Prepared once for many angles: the same invariants.
            let prepared = PreparedFree::new(&free).unwrap().decompose(deg).unwrap();
            assert_invariants(&free, &prepared, deg, lines);
            Ok(None)
        }
        Err(e) => {
            prop_assert_eq!(e, DecomposeError::EmptyFreeSpace);
            Ok(Some(free))
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn random_surveys_decompose_validly(
        (roi, zones, deg) in survey(),
        lines in slice_lines(),
    ) {
        if let Some(free) = check_survey(&roi, &zones, deg, &lines)? {
            prop_assert!(free.unsigned_area() <= 1e-9 * roi.unsigned_area());
        }
    }

    #[test]
    fn rectilinear_grid_surveys_decompose_validly(
        (roi, zones, deg) in grid_survey(),
        lines in slice_lines(),
    ) {
        check_survey(&roi, &zones, deg, &lines)?;
    }

    #[test]
    fn edge_aligned_slices_decompose_validly(
        (roi, zones, deg) in edge_aligned_survey(),
        lines in slice_lines(),
    ) {
        check_survey(&roi, &zones, deg, &lines)?;
    }

    /// Unit squares of a small grid given directly as a multipolygon: parts
    /// touch at corners and share edges (not valid OGC), and count as their union.
    #[test]
    fn touching_parts_decompose_as_their_union(
        squares in prop::collection::btree_set((0i32..6, 0i32..6), 1..20),
        deg in angle(),
        lines in slice_lines(),
    ) {
        let parts = MultiPolygon::new(
            squares.iter().map(|&(x, y)| rect(x as f64, y as f64, x as f64 + 1.0, y as f64 + 1.0)).collect(),
        );
        let union = unary_union(&parts.0);
        let cells = decompose(&parts, deg).unwrap();
        prop_assert!((union.unsigned_area() - squares.len() as f64).abs() < 1e-9);
        assert_invariants(&union, &cells, deg, &lines);
    }
}

/// Joins the cells of `roi` minus `zones` at `deg` for lanes `spacing`
/// apart and asserts every invariant on them, that they are no more than
/// the unjoined cells, and that no joined cell loses coverage: the lanes
/// the survey plans in it (its lanes across the slice) cover at least as
/// much of it, by strips as wide as the spacing, as all lanes planned in
/// the unjoined cells do (up to 10⁻⁶ for the overlay's rounding).
fn check_merged(
    roi: &Polygon<f64>,
    zones: &[Polygon<f64>],
    deg: f64,
    spacing: f64,
    lines: &[f64],
) -> Result<(), TestCaseError> {
    let free = free_space(roi, zones);
    let Ok(cells) = decompose(&free, deg) else {
        return Ok(()); // only an empty free space, checked above
    };
    let merged = decompose_merged(&free, deg, spacing).unwrap();
    let polygons: Vec<Polygon<f64>> = merged.iter().map(|c| c.polygon.clone()).collect();
    assert_invariants(&free, &polygons, deg, lines);
    prop_assert!(merged.len() <= cells.len());
    let index = FreeSpace::new(&free);
    let unjoined: Vec<coverage::Lane> = cells
        .iter()
        .enumerate()
        .filter_map(|(i, c)| CellLayouts::new(i, c, spacing, deg)?.best_plan(c, &index))
        .flat_map(|p| p.lanes)
        .collect();
    for (i, cell) in merged.iter().enumerate().filter(|(_, c)| c.joined) {
        let own: Vec<coverage::Lane> = CellLayouts::along(i, &cell.polygon, spacing, deg + 90.0)
            .and_then(|l| l.best_plan(&cell.polygon, &index))
            .map_or_else(Vec::new, |p| p.lanes);
        let area = MultiPolygon::new(vec![cell.polygon.clone()]);
        let (before, after) = (
            coverage::coverage_ratio(&unjoined, spacing, &area),
            coverage::coverage_ratio(&own, spacing, &area),
        );
        prop_assert!(
            after >= before - 1e-6,
            "joined cell {i}: its lanes cover {after}, the unjoined cells' {before}"
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn merged_cells_keep_invariants_and_coverage(
        (roi, zones, deg) in survey(),
        spacing in prop_oneof![20.0f64..120.0, 120.0f64..600.0],
        lines in slice_lines(),
    ) {
        check_merged(&roi, &zones, deg, spacing, &lines)?;
    }

    /// A long strip with small zones, the spacing near its width: lanes
    /// along the strip pass beside most zones, so many cells are joined.
    #[test]
    fn merged_strip_cells_keep_invariants_and_coverage(
        height in 50.0f64..300.0,
        zones in prop::collection::vec((0.0f64..1000.0, 0.0f64..300.0, 2.0f64..30.0), 1..25),
        spacing in 40.0f64..400.0,
        deg in prop_oneof![Just(0.0), 0.0f64..180.0],
        lines in slice_lines(),
    ) {
        // Lanes across north–south slices run east–west, along the strip.
        let roi = rect(0.0, 0.0, 1000.0, height);
        let zones: Vec<Polygon<f64>> = zones
            .iter()
            .map(|&(x, y, r)| rect(x - r, y * height / 300.0 - r, x + r, y * height / 300.0 + r))
            .collect();
        check_merged(&roi, &zones, deg, spacing, &lines)?;
    }

    #[test]
    fn merged_grid_cells_keep_invariants_and_coverage(
        (roi, zones, deg) in grid_survey(),
        spacing in 0.3f64..6.0,
        lines in slice_lines(),
    ) {
        check_merged(&roi, &zones, deg, spacing, &lines)?;
    }
}

#[test]
fn merging_needs_a_positive_spacing() {
    let free = MultiPolygon::new(vec![rect(0.0, 0.0, 1.0, 1.0)]);
    for spacing in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(
            decompose_merged(&free, 0.0, spacing),
            Err(DecomposeError::NonPositiveSpacing)
        );
    }
}

/// The benchmark's scale: 1000 zones (8000 vertices) in a 10 km ROI.
#[test]
fn thousand_zones() {
    // Deterministic xorshift so the test needs no extra dependency.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (e, n) = (400_000.0, 4_500_000.0);
    let roi = rect(e, n, e + 10_000.0, n + 10_000.0);
    let zones: Vec<Polygon<f64>> = (0..1000)
        .map(|_| {
            let (cx, cy) = (e + 10_000.0 * next(), n + 10_000.0 * next());
            let radii: Vec<f64> = (0..8).map(|_| 20.0 + 100.0 * next()).collect();
            let jitter: Vec<f64> = (0..8).map(|_| next()).collect();
            star((cx, cy), &radii, &jitter, next() * 6.3)
        })
        .collect();

    let t = Instant::now();
    let free = free_space(&roi, &zones);
    let t_free = t.elapsed();
    let vertices: usize = free
        .iter()
        .map(|p| p.exterior().0.len() + p.interiors().iter().map(|r| r.0.len()).sum::<usize>())
        .sum();
    for deg in [0.0, 37.0, 90.0] {
        let t = Instant::now();
        let cells = decompose(&free, deg).unwrap();
        let t_dec = t.elapsed();
        eprintln!(
            "1000 zones: free space {t_free:?} ({vertices} vertices), decompose at {deg}° {t_dec:?} ({} cells)",
            cells.len()
        );
        let h = across(deg);
        for cell in &cells {
            assert!(cell.is_valid() && cell.exterior().is_ccw() && cell.interiors().is_empty());
            let hs: Vec<f64> = cell.exterior().0.iter().map(|&p| h(p)).collect();
            let (lo, hi) = min_max(hs.iter().copied());
            for t in [0.1, 0.5, 0.9] {
                assert!(crossings(cell, &h, lo + t * (hi - lo)) <= 2);
            }
        }
        let total: f64 = cells.iter().map(|c| c.unsigned_area()).sum();
        assert!((total - free.unsigned_area()).abs() <= 1e-6 * free.unsigned_area());
        // Coverage: a stratified Monte Carlo estimate, over 200 slice lines,
        // of the area of the symmetric difference.
        let origin = free.bounding_rect().unwrap().min();
        let free_rings: Vec<Vec<(f64, f64)>> = free
            .iter()
            .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
            .map(|r| slice_frame(r, deg, origin))
            .collect();
        let frames: Vec<Vec<(f64, f64)>> = cells
            .iter()
            .map(|c| slice_frame(c.exterior(), deg, origin))
            .collect();
        let (lo, hi) = h_range(free_rings.iter().flatten());
        let estimate: f64 = (0..200)
            .map(|k| {
                line_mismatch(
                    &free_rings,
                    &frames,
                    lo + (hi - lo) * (k as f64 + next()) / 200.0,
                )
            })
            .sum::<f64>()
            * (hi - lo)
            / 200.0;
        assert!(estimate <= 1e-6 * free.unsigned_area(), "{estimate}");
    }
}
