//! Statistics of a finished costmap: how much of it is of each class, and
//! how the costs of the traversable cells are spread.

use serde::{Deserialize, Serialize};

use rayon::prelude::*;

use super::Class;

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
}
