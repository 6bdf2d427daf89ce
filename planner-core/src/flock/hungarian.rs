//! Exact minimum-cost rectangular assignment (Hungarian method).
//!
//! Used by the `min_reach` flock policy (thesis policy 1): each UAV gets a
//! distinct cell so that the summed reach distance (UAV → assigned cell) is
//! minimal. A greedy nearest-cell choice can be arbitrarily worse, so the
//! assignment is solved exactly.
//!
//! Algorithm: Kuhn–Munkres with dual potentials in the shortest augmenting
//! path formulation (Jonker–Volgenant; the variant of Crouse, "On
//! implementing 2D rectangular assignment algorithms", 2016, also used by
//! SciPy). Rows are added one at a time; for each, a Dijkstra search over
//! reduced costs `c[i][j] − u[i] − v[j] ≥ 0` finds the cheapest augmenting
//! path to a free column, then the potentials are updated so reduced costs
//! stay non-negative and are zero on the matching. Each row costs
//! O(rows · cols), O(rows² · cols) in total, with O(rows + cols) memory.
//!
//! Numerics: path lengths inside one search are kept as absolute distances
//! from the new row (not repeatedly decremented), so rounding does not
//! accumulate over the search; costs near `f64::MAX` are scaled by an exact
//! power of two so potentials cannot overflow. Ties are broken by a fixed
//! rule (free column first, then search order), so the result is
//! deterministic.

/// Errors of the assignment solver.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssignmentError {
    /// `cost.len()` is not `rows × cols` (or that product overflows).
    #[error("cost matrix has {len} entries, expected {rows} × {cols}")]
    DimensionMismatch {
        /// Length of the given slice.
        len: usize,
        /// Declared number of rows.
        rows: usize,
        /// Declared number of columns.
        cols: usize,
    },
    /// More rows than columns: some row would stay unassigned.
    #[error("cannot assign {rows} rows to only {cols} columns")]
    TooFewColumns {
        /// Number of rows.
        rows: usize,
        /// Number of columns.
        cols: usize,
    },
    /// A cost is NaN or infinite; "forbidden" pairs must be given a large
    /// finite cost instead, so that optimality stays well defined.
    #[error("cost at row {row}, column {col} is not finite")]
    NotFinite {
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
    },
}

/// Above this magnitude costs are scaled down by [`HUGE_SCALE`] so that the
/// potentials (sums and differences of up to ~rows costs) cannot overflow.
const HUGE_COST: f64 = 1.0e288; // ≈ 2^957
/// 2^-64: a power of two, so scaling is exact (except for values that
/// underflow, which are negligible next to costs above [`HUGE_COST`]) and
/// does not change which assignment is optimal.
const HUGE_SCALE: f64 = 1.0 / 18_446_744_073_709_551_616.0;

/// Marks an unmatched row or column.
const NONE: usize = usize::MAX;

/// Assigns each of `rows` rows a distinct column (rows ≤ cols) so that the
/// summed cost is minimal. `cost` is row-major, `rows × cols`. Returns the
/// column of each row.
///
/// The result is optimal up to floating-point rounding and deterministic.
/// Runs in O(rows² · cols) time.
pub fn min_cost_assignment(
    cost: &[f64],
    rows: usize,
    cols: usize,
) -> Result<Vec<usize>, AssignmentError> {
    if rows.checked_mul(cols) != Some(cost.len()) {
        return Err(AssignmentError::DimensionMismatch {
            len: cost.len(),
            rows,
            cols,
        });
    }
    if rows == 0 {
        return Ok(Vec::new());
    }
    if rows > cols {
        return Err(AssignmentError::TooFewColumns { rows, cols });
    }
    let mut max_abs = 0.0_f64;
    for (k, &c) in cost.iter().enumerate() {
        if !c.is_finite() {
            return Err(AssignmentError::NotFinite {
                row: k / cols,
                col: k % cols,
            });
        }
        max_abs = max_abs.max(c.abs());
    }
    let scale = if max_abs > HUGE_COST { HUGE_SCALE } else { 1.0 };

    // Row potentials, column potentials and the current matching.
    let mut u = vec![0.0_f64; rows];
    let mut v = vec![0.0_f64; cols];
    let mut col4row = vec![NONE; rows];
    let mut row4col = vec![NONE; cols];
    // Per-search scratch: predecessor row of each column on its shortest
    // path, that path's length, the rows/columns reached, and the columns
    // not yet settled (swap-removed, so settling is O(1)).
    let mut path = vec![NONE; cols];
    let mut dist = vec![f64::INFINITY; cols];
    let mut row_seen = vec![false; rows];
    let mut col_seen = vec![false; cols];
    let mut remaining: Vec<usize> = Vec::with_capacity(cols);

    for cur_row in 0..rows {
        dist.fill(f64::INFINITY);
        row_seen.fill(false);
        col_seen.fill(false);
        remaining.clear();
        remaining.extend(0..cols);

        // Dijkstra from `cur_row` until a free column is settled.
        let mut min_val = 0.0_f64;
        let mut i = cur_row;
        let sink = loop {
            row_seen[i] = true;
            let row_cost = &cost[i * cols..(i + 1) * cols];
            let mut lowest = f64::INFINITY;
            let mut best = 0;
            for (slot, &j) in remaining.iter().enumerate() {
                let r = min_val + (row_cost[j] * scale - u[i] - v[j]);
                if r < dist[j] {
                    path[j] = i;
                    dist[j] = r;
                }
                // Prefer free columns on ties: the search can stop earlier.
                if dist[j] < lowest || (dist[j] == lowest && row4col[j] == NONE) {
                    lowest = dist[j];
                    best = slot;
                }
            }
            // Finite costs, rows ≤ cols and the scaling keep every distance
            // finite, so a column is always found.
            debug_assert!(lowest.is_finite(), "assignment search diverged");
            min_val = lowest;
            let j = remaining.swap_remove(best);
            col_seen[j] = true;
            if row4col[j] == NONE {
                break j;
            }
            i = row4col[j];
        };

        // Potentials: keep reduced costs ≥ 0 and zero along the matching.
        u[cur_row] += min_val;
        for (r, &seen) in row_seen.iter().enumerate() {
            if seen && r != cur_row {
                u[r] += min_val - dist[col4row[r]];
            }
        }
        for (j, &seen) in col_seen.iter().enumerate() {
            if seen {
                v[j] -= min_val - dist[j];
            }
        }

        // Augment along the path back from the sink.
        let mut j = sink;
        loop {
            let r = path[j];
            row4col[j] = r;
            std::mem::swap(&mut col4row[r], &mut j);
            if r == cur_row {
                break;
            }
        }
    }
    Ok(col4row)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Small deterministic generator (64-bit LCG, Knuth's constants).
    struct Lcg(u64);

    impl Lcg {
        fn next_u64(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            self.0 >> 11
        }
        /// Uniform in [0, 1).
        fn unit(&mut self) -> f64 {
            self.next_u64() as f64 / (1u64 << 53) as f64
        }
        /// Uniform in 0..n.
        fn below(&mut self, n: u64) -> u64 {
            self.next_u64() % n
        }
    }

    fn total(cost: &[f64], cols: usize, assignment: &[usize]) -> f64 {
        assignment
            .iter()
            .enumerate()
            .map(|(r, &c)| cost[r * cols + c])
            .sum()
    }

    fn assert_distinct(assignment: &[usize], cols: usize) {
        let mut used = vec![false; cols];
        for &c in assignment {
            assert!(c < cols, "column {c} out of range");
            assert!(!used[c], "column {c} assigned twice");
            used[c] = true;
        }
    }

    /// Minimum over all injections rows → cols, by depth-first enumeration.
    fn brute_force(cost: &[f64], rows: usize, cols: usize) -> f64 {
        fn rec(cost: &[f64], rows: usize, cols: usize, r: usize, used: &mut [bool]) -> f64 {
            if r == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for c in 0..cols {
                if !used[c] {
                    used[c] = true;
                    let s = cost[r * cols + c] + rec(cost, rows, cols, r + 1, used);
                    used[c] = false;
                    best = best.min(s);
                }
            }
            best
        }
        rec(cost, rows, cols, 0, &mut vec![false; cols])
    }

    fn check_optimal(cost: &[f64], rows: usize, cols: usize) {
        let a = min_cost_assignment(cost, rows, cols).unwrap();
        assert_eq!(a.len(), rows);
        assert_distinct(&a, cols);
        let got = total(cost, cols, &a);
        let want = brute_force(cost, rows, cols);
        let tol = 1e-9 * want.abs().max(f64::MIN_POSITIVE);
        assert!(
            (got - want).abs() <= tol,
            "{rows}×{cols}: got {got}, brute force {want}, cost {cost:?}"
        );
    }

    /// One random matrix; `kind` picks the distribution.
    fn random_matrix(rng: &mut Lcg, rows: usize, cols: usize, kind: u64) -> Vec<f64> {
        (0..rows * cols)
            .map(|_| match kind {
                // Uniform reach-like distances.
                0 => 1000.0 * rng.unit(),
                // Few distinct small integers: many ties (sums stay exact).
                1 => rng.below(3) as f64,
                // Mixed magnitudes 1e-3 … 1e6.
                2 => {
                    let exp = rng.below(10) as i32 - 3;
                    (1.0 + 9.0 * rng.unit()) * 10f64.powi(exp)
                }
                // Signed, with exactly repeated values.
                _ => (rng.below(7) as f64 - 3.0) * 0.25 + if rng.below(2) == 0 { 0.0 } else { 1e6 },
            })
            .collect()
    }

    #[test]
    fn hand_computed_3x3() {
        // Greedy by row (0→1, 1→0, 2→2) costs 6; the unique optimum is
        // 0→2, 1→1, 2→0 = 3 + 0 + 2 = 5.
        #[rustfmt::skip]
        let cost = [
            4.0, 1.0, 3.0,
            2.0, 0.0, 5.0,
            2.0, 2.0, 3.0,
        ];
        let a = min_cost_assignment(&cost, 3, 3).unwrap();
        assert_eq!(a, vec![2, 1, 0]);
        assert_eq!(total(&cost, 3, &a), 5.0);

        // Textbook instance: unique optimum 0→1, 1→2, 2→0 = 950.
        #[rustfmt::skip]
        let cost = [
            250.0, 400.0, 350.0,
            400.0, 600.0, 350.0,
            200.0, 400.0, 250.0,
        ];
        let a = min_cost_assignment(&cost, 3, 3).unwrap();
        assert_eq!(a, vec![1, 2, 0]);
        assert_eq!(total(&cost, 3, &a), 950.0);
    }

    #[test]
    fn hand_computed_2x4() {
        // Both rows prefer column 0. Greedy (0→0, 1→1) costs 8; row 0
        // giving it up is cheaper: 0→1, 1→0 = 4 + 0.5 = 4.5.
        #[rustfmt::skip]
        let cost = [
            1.0, 4.0, 6.0, 5.0,
            0.5, 7.0, 8.0, 9.0,
        ];
        let a = min_cost_assignment(&cost, 2, 4).unwrap();
        assert_eq!(a, vec![1, 0]);
        assert_eq!(total(&cost, 4, &a), 4.5);
    }

    #[test]
    fn single_row_takes_cheapest_column() {
        let cost = [3.0, -1.0, 2.0, -1.0];
        // Ties resolve deterministically; either −1 column is optimal.
        let a = min_cost_assignment(&cost, 1, 4).unwrap();
        assert_eq!(cost[a[0]], -1.0);
        assert_eq!(a, min_cost_assignment(&cost, 1, 4).unwrap());
    }

    #[test]
    fn random_square_matches_brute_force() {
        let mut rng = Lcg(0x5eed_1234);
        for n in 1..=7 {
            for trial in 0..40 {
                let cost = random_matrix(&mut rng, n, n, trial % 4);
                check_optimal(&cost, n, n);
            }
        }
    }

    #[test]
    fn random_rectangular_matches_brute_force() {
        let mut rng = Lcg(0xc0ffee);
        for rows in 1..=7 {
            for cols in rows + 1..=9 {
                for trial in 0..8 {
                    let cost = random_matrix(&mut rng, rows, cols, trial % 4);
                    check_optimal(&cost, rows, cols);
                }
            }
        }
    }

    #[test]
    fn all_equal_costs() {
        let cost = vec![7.0; 5 * 6];
        let a = min_cost_assignment(&cost, 5, 6).unwrap();
        assert_distinct(&a, 6);
        assert_eq!(total(&cost, 6, &a), 35.0);
    }

    #[test]
    fn huge_magnitudes_do_not_overflow() {
        let mut rng = Lcg(42);
        for _ in 0..200 {
            // Near ±f64::MAX: unscaled, reduced costs would overflow to ±inf.
            let cost: Vec<f64> = (0..4 * 5)
                .map(|_| {
                    if rng.below(2) == 0 {
                        (rng.below(5) as f64 - 2.0) * 0.5 * f64::MAX
                    } else {
                        (2.0 * rng.unit() - 1.0) * f64::MAX
                    }
                })
                .collect();
            let a = min_cost_assignment(&cost, 4, 5).unwrap();
            assert_distinct(&a, 5);
            // Sums of such costs overflow, so judge optimality on a copy
            // scaled by an exact power of two.
            let scaled: Vec<f64> = cost.iter().map(|c| c * HUGE_SCALE).collect();
            let got = total(&scaled, 5, &a);
            let want = brute_force(&scaled, 4, 5);
            assert!((got - want).abs() <= 1e-9 * want.abs(), "{got} vs {want}");
        }
    }

    #[test]
    fn deterministic() {
        let mut rng = Lcg(7);
        let cost = random_matrix(&mut rng, 6, 8, 1);
        let a = min_cost_assignment(&cost, 6, 8).unwrap();
        for _ in 0..3 {
            assert_eq!(min_cost_assignment(&cost, 6, 8).unwrap(), a);
        }
    }

    #[test]
    fn empty_rows() {
        assert_eq!(min_cost_assignment(&[], 0, 0), Ok(vec![]));
        assert_eq!(min_cost_assignment(&[], 0, 5), Ok(vec![]));
    }

    #[test]
    fn errors() {
        assert_eq!(
            min_cost_assignment(&[1.0; 6], 3, 2),
            Err(AssignmentError::TooFewColumns { rows: 3, cols: 2 })
        );
        assert_eq!(
            min_cost_assignment(&[1.0; 5], 2, 3),
            Err(AssignmentError::DimensionMismatch {
                len: 5,
                rows: 2,
                cols: 3
            })
        );
        assert_eq!(
            min_cost_assignment(&[1.0], 0, 3),
            Err(AssignmentError::DimensionMismatch {
                len: 1,
                rows: 0,
                cols: 3
            })
        );
        assert_eq!(
            min_cost_assignment(&[1.0], usize::MAX, 2),
            Err(AssignmentError::DimensionMismatch {
                len: 1,
                rows: usize::MAX,
                cols: 2
            })
        );
        let mut cost = [0.0; 6];
        cost[5] = f64::NAN;
        assert_eq!(
            min_cost_assignment(&cost, 2, 3),
            Err(AssignmentError::NotFinite { row: 1, col: 2 })
        );
        cost[5] = 0.0;
        cost[1] = f64::NEG_INFINITY;
        assert_eq!(
            min_cost_assignment(&cost, 2, 3),
            Err(AssignmentError::NotFinite { row: 0, col: 1 })
        );
        cost[1] = f64::INFINITY;
        assert_eq!(
            min_cost_assignment(&cost, 2, 3),
            Err(AssignmentError::NotFinite { row: 0, col: 1 })
        );
    }
}
