//! Statistics of a finished costmap: how much of it is of each class, and
//! how the costs of the traversable cells are spread.

use serde::{Deserialize, Serialize};

use rayon::prelude::*;

use super::Class;
use super::tile_bytes::{ByteReader, ByteWriter, PieceError};

/// Cells per parallel task of the statistics pass.
const CHUNK: usize = 1 << 16;

/// Class counts, cost bins, min, max, sum and count of traversable costs.
type Tally = ([u64; 6], [u64; HISTOGRAM_BINS], f64, f64, f64, u64);

fn empty_tally() -> Tally {
    (
        [0; 6],
        [0; HISTOGRAM_BINS],
        f64::INFINITY,
        f64::NEG_INFINITY,
        0.0,
        0,
    )
}

/// Bins of the cost histogram.
pub const HISTOGRAM_BINS: usize = 20;

/// Fractions of all cells, [0, 1], summing to 1.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClassFractions {
    pub unknown: f64,
    pub traversable: f64,
    pub slope: f64,
    pub step: f64,
    pub enclosed: f64,
    pub other: f64,
}

/// Counts of traversable cells by cost, in equal bins from `min` to `max`.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CostHistogram {
    /// `HISTOGRAM_BINS + 1` bin edges, ascending.
    pub edges: Vec<f64>,
    pub counts: Vec<u64>,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CostmapStats {
    pub width: usize,
    pub height: usize,
    pub cells: u64,
    pub class_fractions: ClassFractions,
    /// Traversable cells' area, m².
    pub traversable_area_m2: f64,
    /// Cost over the traversable cells; `None` when there is none.
    pub cost_min: Option<f64>,
    pub cost_max: Option<f64>,
    pub cost_mean: Option<f64>,
    /// The range the weights allow: [w_slope, w_infl + 10·w_slope (+ the
    /// roughness weight and the dearest non-lethal land-cover cost)]; the
    /// histogram spans it.
    pub cost_range: [f64; 2],
    pub histogram: CostHistogram,
}

/// Statistics of `cost` / `class` (same length). `cell_area_m2`: area of
/// one cell; `cost_range`: the range the weights allow.
pub fn costmap_stats(
    width: usize,
    height: usize,
    cost: &[f32],
    class: &[u8],
    cell_area_m2: f64,
    cost_range: [f64; 2],
) -> CostmapStats {
    let bins = Bins::new(cost_range);
    // One parallel pass: class counts, and min / max / sum / bins of the
    // traversable costs.
    let tally = cost
        .par_chunks(CHUNK)
        .zip(class.par_chunks(CHUNK))
        .map(|(costs, classes)| {
            let mut t = empty_tally();
            bins.add(&mut t, costs, classes);
            t
        })
        .reduce(empty_tally, merge);
    finish(tally, width, height, cell_area_m2, cost_range)
}

/// Where a cost falls in the histogram.
#[derive(Clone, Copy)]
struct Bins {
    lo: f64,
    per_cost: f64,
}

impl Bins {
    fn new([lo, hi]: [f64; 2]) -> Bins {
        let span = (hi - lo).max(f64::MIN_POSITIVE);
        Bins {
            lo,
            per_cost: HISTOGRAM_BINS as f64 / span,
        }
    }

    fn add(self, t: &mut Tally, costs: &[f32], classes: &[u8]) {
        for (&c, &k) in costs.iter().zip(classes) {
            t.0[usize::from(k.min(5))] += 1;
            if k == Class::Traversable as u8 && c.is_finite() {
                let c = f64::from(c);
                t.2 = t.2.min(c);
                t.3 = t.3.max(c);
                t.4 += c;
                t.5 += 1;
                // Truncation is floor here: below 0 is bin 0 anyway.
                let b = (c - self.lo) * self.per_cost;
                let bin = if b > 0.0 { b as usize } else { 0 };
                t.1[bin.min(HISTOGRAM_BINS - 1)] += 1;
            }
        }
    }
}

fn merge(mut a: Tally, b: Tally) -> Tally {
    a.0.iter_mut().zip(b.0).for_each(|(x, y)| *x += y);
    a.1.iter_mut().zip(b.1).for_each(|(x, y)| *x += y);
    (a.0, a.1, a.2.min(b.2), a.3.max(b.3), a.4 + b.4, a.5 + b.5)
}

/// Statistics gathered a piece of the map at a time (a tiled run): the
/// same counts, extremes and histogram as [`costmap_stats`]; the mean
/// differs from it only by the order its sum was added in.
pub struct StatsTally {
    bins: Bins,
    tally: Tally,
}

/// The tally of one piece of a map (a tile), to be merged into the
/// map's by [`StatsTally::merge`].
#[derive(Clone, Debug, PartialEq)]
pub struct TallyPart {
    tally: Tally,
}

impl StatsTally {
    pub fn new(cost_range: [f64; 2]) -> StatsTally {
        StatsTally {
            bins: Bins::new(cost_range),
            tally: empty_tally(),
        }
    }

    /// Adds the cells of a piece (`cost` and `class` of the same cells).
    pub fn add(&mut self, cost: &[f32], class: &[u8]) {
        self.bins.add(&mut self.tally, cost, class);
    }

    /// What was added, as a part to merge elsewhere.
    pub fn into_part(self) -> TallyPart {
        TallyPart { tally: self.tally }
    }

    /// Adds a part tallied over the same cost range. Parts merged in the
    /// same order give the same statistics, bit for bit.
    pub fn merge(&mut self, part: &TallyPart) {
        self.tally = merge(self.tally, part.tally);
    }

    pub fn finish(
        self,
        width: usize,
        height: usize,
        cell_area_m2: f64,
        cost_range: [f64; 2],
    ) -> CostmapStats {
        finish(self.tally, width, height, cell_area_m2, cost_range)
    }
}

impl TallyPart {
    const KIND: u8 = b'T';
    const WHAT: &'static str = "stats tally";

    /// The cells tallied.
    pub fn cells(&self) -> u64 {
        self.tally.0.iter().sum()
    }

    /// The byte form: class counts, histogram counts, min, max, sum and
    /// count of the traversable costs.
    pub fn to_bytes(&self) -> Vec<u8> {
        let (counts, bins, min, max, sum, n) = &self.tally;
        let mut b = ByteWriter::new(Self::KIND);
        counts.iter().chain(bins).for_each(|&c| b.u64(c));
        [*min, *max, *sum].into_iter().for_each(|v| b.f64(v));
        b.u64(*n);
        b.finish()
    }

    /// Reads [`TallyPart::to_bytes`], checking that the counts agree.
    pub fn from_bytes(bytes: &[u8]) -> Result<TallyPart, PieceError> {
        let mut r = ByteReader::new(bytes, Self::KIND, Self::WHAT)?;
        let mut counts = [0u64; 6];
        for c in &mut counts {
            *c = r.u64()?;
        }
        let mut bins = [0u64; HISTOGRAM_BINS];
        for c in &mut bins {
            *c = r.u64()?;
        }
        let (min, max, sum) = (r.f64()?, r.f64()?, r.f64()?);
        let n = r.u64()?;
        r.end()?;
        let fault = |why: &str| PieceError {
            what: Self::WHAT,
            why: why.to_string(),
        };
        let checked_sum = |c: &[u64]| c.iter().try_fold(0u64, |a, &x| a.checked_add(x));
        if checked_sum(&counts).is_none() {
            return Err(fault("the class counts overflow"));
        }
        if checked_sum(&bins) != Some(n) || n > counts[Class::Traversable as usize] {
            return Err(fault(
                "the histogram, the costs' count and the traversable cells disagree",
            ));
        }
        let consistent = if n == 0 {
            min == f64::INFINITY && max == f64::NEG_INFINITY && sum == 0.0
        } else {
            min.is_finite() && max.is_finite() && sum.is_finite() && min <= max
        };
        if !consistent {
            return Err(fault("the costs' extremes and sum are not those of costs"));
        }
        Ok(TallyPart {
            tally: (counts, bins, min, max, sum, n),
        })
    }
}

fn finish(
    (counts, bins, min, max, sum, n): Tally,
    width: usize,
    height: usize,
    cell_area_m2: f64,
    cost_range: [f64; 2],
) -> CostmapStats {
    let [lo, hi] = cost_range;
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let cells: u64 = counts.iter().sum();
    let frac = |c: Class| {
        if cells == 0 {
            0.0
        } else {
            counts[c as usize] as f64 / cells as f64
        }
    };
    let edges = (0..=HISTOGRAM_BINS)
        .map(|i| lo + span * i as f64 / HISTOGRAM_BINS as f64)
        .collect();
    CostmapStats {
        width,
        height,
        cells,
        class_fractions: ClassFractions {
            unknown: frac(Class::Unknown),
            traversable: frac(Class::Traversable),
            slope: frac(Class::Slope),
            step: frac(Class::Step),
            enclosed: frac(Class::Enclosed),
            other: frac(Class::Other),
        },
        traversable_area_m2: counts[Class::Traversable as usize] as f64 * cell_area_m2,
        cost_min: (n > 0).then_some(min),
        cost_max: (n > 0).then_some(max),
        cost_mean: (n > 0).then(|| sum / n as f64),
        cost_range,
        histogram: CostHistogram {
            edges,
            counts: bins.to_vec(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractions_and_histogram_count_every_cell_once() {
        let class = [1u8, 1, 1, 2, 3, 0, 4, 5];
        let cost = [
            1.0f32,
            10.5,
            20.0,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
        ];
        let s = costmap_stats(4, 2, &cost, &class, 2.0, [1.0, 20.0]);
        let f = &s.class_fractions;
        assert_eq!(f.traversable, 3.0 / 8.0);
        let total = f.unknown + f.traversable + f.slope + f.step + f.enclosed + f.other;
        assert!((total - 1.0).abs() < 1e-12);
        assert_eq!(s.histogram.counts.iter().sum::<u64>(), 3);
        assert_eq!(s.histogram.counts[0], 1);
        assert_eq!(s.histogram.counts[HISTOGRAM_BINS - 1], 1);
        assert_eq!(s.cost_min, Some(1.0));
        assert_eq!(s.cost_max, Some(20.0));
        assert_eq!(s.traversable_area_m2, 6.0);
        assert_eq!(s.histogram.edges.len(), HISTOGRAM_BINS + 1);
    }

    #[test]
    fn parts_merged_in_order_are_the_whole_tally_and_damaged_bytes_are_refused() {
        let class = [1u8, 1, 0, 1, 2, 1, 4, 1, 1];
        let cost = [
            1.5f32,
            3.25,
            f32::NAN,
            7.0,
            f32::NAN,
            19.5,
            f32::NAN,
            2.0,
            11.0,
        ];
        let range = [1.0, 20.0];
        let mut whole = StatsTally::new(range);
        whole.add(&cost, &class);
        let mut merged = StatsTally::new(range);
        for (c, k) in cost.chunks(4).zip(class.chunks(4)) {
            let mut t = StatsTally::new(range);
            t.add(c, k);
            let part = t.into_part();
            let bytes = part.to_bytes();
            let back = TallyPart::from_bytes(&bytes).unwrap();
            assert_eq!(back, part);
            crate::costmap::tile_bytes::testing::assert_refuses_damage(
                &bytes,
                TallyPart::from_bytes,
                7,
            );
            merged.merge(&back);
        }
        let (a, b) = (
            whole.finish(3, 3, 1.0, range),
            merged.finish(3, 3, 1.0, range),
        );
        assert_eq!(a, b);
        // Sums of these costs are exact, so even the mean is the same.
        assert_eq!(
            a.cost_mean,
            Some((1.5 + 3.25 + 7.0 + 19.5 + 2.0 + 11.0) / 6.0)
        );
        // An empty part reads back; a part whose counts disagree does not.
        let empty = StatsTally::new(range).into_part();
        assert_eq!(TallyPart::from_bytes(&empty.to_bytes()).unwrap(), empty);
        let mut bad = empty.to_bytes();
        bad[2 + 8] = 1; // a traversable cell
        bad[2 + 6 * 8] = 1; // in the first bin, without a cost counted
        assert!(TallyPart::from_bytes(&bad).is_err());
    }
}
