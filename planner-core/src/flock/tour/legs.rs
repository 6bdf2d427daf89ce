//! Leg costs for the tour search: Euclidean, or the NFZ-avoiding length
//! with memoised shortest paths under query and effort budgets.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use geo_types::Coord;
use rayon::prelude::*;

use crate::flock::transit::{ObstacleMap, TransitError, polyline_length};

/// Search effort (closed nodes plus obstacle edges tested) the second
/// phase's queries may spend in all: among thousands of NFZs one long query
/// can cost a second, and the query count alone would let the phase take
/// minutes. About 0.25 s among 5 000 NFZs on the reference machine
/// (release build); twice as much shortens that tour by 0.14 % (861 m of
/// 602 km) for a fifth of its planning time, and a survey among 1 000 NFZs
/// gains nothing more from a larger one.
const SEARCH_WORK_BUDGET: usize = 500_000;
/// Cost of a leg that has no NFZ-free path: huge but finite, so gains stay
/// comparable.
const NO_PATH_PENALTY: f64 = 1e9;

/// A leg's end points as bits, the smaller point first: a leg and its
/// reverse share one entry.
type LegKey = [u64; 4];

fn leg_key(p: Coord<f64>, q: Coord<f64>) -> (LegKey, bool) {
    let (a, b) = (
        [p.x.to_bits(), p.y.to_bits()],
        [q.x.to_bits(), q.y.to_bits()],
    );
    if a <= b {
        ([a[0], a[1], b[0], b[1]], false)
    } else {
        ([b[0], b[1], a[0], a[1]], true)
    }
}

/// Multiply-rotate hasher for [`LegKey`]s: the default SipHash dominated
/// the second search phase, which looks legs up millions of times.
#[derive(Default)]
struct LegHasher(u64);

impl Hasher for LegHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// A priced leg: its length (with [`NO_PATH_PENALTY`] when impossible)
/// and its polyline from the key's first point.
struct Leg {
    length: f64,
    path: Result<Vec<Coord<f64>>, TransitError>,
}

impl Leg {
    fn new(a: Coord<f64>, b: Coord<f64>, path: Result<Vec<Coord<f64>>, TransitError>) -> Leg {
        let length = path
            .as_ref()
            .map_or(dist(a, b) + NO_PATH_PENALTY, |path| polyline_length(path));
        Leg { length, path }
    }
}

/// Leg costs: Euclidean, or (when `exact`) the NFZ-avoiding length, with
/// memoised shortest paths and query and effort budgets.
pub(super) struct Legs<'a> {
    map: &'a ObstacleMap,
    pub(super) exact: bool,
    pub(super) budget: usize,
    /// Nodes the budgeted queries' searches may still close.
    pub(super) work_budget: usize,
    priced: HashMap<LegKey, Leg, BuildHasherDefault<LegHasher>>,
}

impl<'a> Legs<'a> {
    pub(super) fn new(map: &'a ObstacleMap) -> Self {
        Legs {
            map,
            exact: false,
            budget: 0,
            work_budget: SEARCH_WORK_BUDGET,
            priced: HashMap::default(),
        }
    }

    /// A lower bound of the leg cost that never queries.
    pub(super) fn lower(&self, p: Coord<f64>, q: Coord<f64>) -> f64 {
        if !self.exact {
            return dist(p, q);
        }
        self.priced
            .get(&leg_key(p, q).0)
            .map_or_else(|| dist(p, q), |leg| leg.length)
    }

    /// Queries and stores the leg `p → q`.
    fn price(&mut self, p: Coord<f64>, q: Coord<f64>) -> &Leg {
        let (key, reversed) = leg_key(p, q);
        let map = self.map;
        self.priced.entry(key).or_insert_with(|| {
            let (a, b) = if reversed { (q, p) } else { (p, q) };
            Leg::new(a, b, map.shortest_path(a, b))
        })
    }

    /// The leg cost; `None` when it would need a query beyond the budgets
    /// (query count, and search effort: one long transit through thousands
    /// of NFZs can cost as much as thousands of short ones).
    pub(super) fn cost(&mut self, p: Coord<f64>, q: Coord<f64>) -> Option<f64> {
        if !self.exact {
            return Some(dist(p, q));
        }
        let (key, reversed) = leg_key(p, q);
        if let Some(leg) = self.priced.get(&key) {
            return Some(leg.length);
        }
        if self.budget == 0 || self.work_budget == 0 {
            return None;
        }
        self.budget -= 1;
        let (a, b) = if reversed { (q, p) } else { (p, q) };
        let mut work = 0;
        let path = self
            .map
            .shortest_path_counted(a, b, &mut work, self.work_budget);
        self.work_budget = self.work_budget.saturating_sub(work);
        if matches!(path, Err(TransitError::OverBudget)) {
            self.work_budget = 0;
            return None;
        }
        Some(
            self.priced
                .entry(key)
                .or_insert(Leg::new(a, b, path))
                .length,
        )
    }

    /// Prices every leg of `pairs` not yet priced, without budget, the
    /// queries spread over the cores (each is independent; among thousands
    /// of NFZs pricing a tour of thousands of cells takes a third of a
    /// second on one core). Cancelled: the rest is left unpriced.
    pub(super) fn price_all(&mut self, pairs: &[(Coord<f64>, Coord<f64>)]) {
        let mut todo: Vec<(LegKey, Coord<f64>, Coord<f64>)> = pairs
            .iter()
            .filter_map(|&(p, q)| {
                let (key, reversed) = leg_key(p, q);
                let (a, b) = if reversed { (q, p) } else { (p, q) };
                (!self.priced.contains_key(&key)).then_some((key, a, b))
            })
            .collect();
        todo.sort_unstable_by_key(|t| t.0);
        todo.dedup_by_key(|t| t.0);
        let token = crate::cancel::current();
        let map = self.map;
        let priced: Vec<(LegKey, Leg)> = todo
            .par_iter()
            .filter_map(|&(key, a, b)| {
                token.scope(|| {
                    crate::cancel::check().ok()?;
                    Some((key, Leg::new(a, b, map.shortest_path(a, b))))
                })
            })
            .collect();
        self.priced.extend(priced);
    }

    /// The leg's polyline from `p` to `q` (queried without budget: final
    /// legs must exist).
    pub(super) fn path(
        &mut self,
        p: Coord<f64>,
        q: Coord<f64>,
    ) -> Result<Vec<Coord<f64>>, TransitError> {
        let reversed = leg_key(p, q).1;
        match &self.price(p, q).path {
            Ok(path) if reversed => Ok(path.iter().rev().copied().collect()),
            Ok(path) => Ok(path.clone()),
            // Errors name the requested direction's endpoints.
            Err(_) if reversed => self.map.shortest_path(p, q),
            Err(e) => Err(e.clone()),
        }
    }
}

pub(super) fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    (dx * dx + dy * dy).sqrt()
}
