//! Decoded raster blocks (a GeoTIFF's strips or tiles, a stored DEM's
//! tiles) kept for the next window that needs them: least recently used
//! dropped first once they take more than a byte budget.

use std::collections::{BTreeMap, HashMap};
use std::hash::Hash;
use std::sync::Arc;

/// Blocks of f64 cells by key, within `capacity_bytes` (the newest block
/// is always kept, whatever its size).
pub struct CellCache<K> {
    /// (last use, cells) by key.
    by_key: HashMap<K, (u64, Arc<Vec<f64>>)>,
    by_use: BTreeMap<u64, K>,
    tick: u64,
    bytes: usize,
    capacity_bytes: usize,
}

impl<K: Copy + Eq + Hash> CellCache<K> {
    pub fn new(capacity_bytes: usize) -> CellCache<K> {
        CellCache {
            by_key: HashMap::new(),
            by_use: BTreeMap::new(),
            tick: 0,
            bytes: 0,
            capacity_bytes,
        }
    }

    /// The block under `key`, now the most recently used.
    pub fn get(&mut self, key: K) -> Option<Arc<Vec<f64>>> {
        self.tick += 1;
        let tick = self.tick;
        let (used, cells) = self.by_key.get_mut(&key)?;
        self.by_use.remove(used);
        *used = tick;
        self.by_use.insert(tick, key);
        Some(Arc::clone(cells))
    }

    /// Keeps `cells` under `key`, dropping the least recently used blocks
    /// past the budget.
    pub fn put(&mut self, key: K, cells: Arc<Vec<f64>>) {
        self.tick += 1;
        let size = cells.len() * 8;
        if let Some((used, old)) = self.by_key.insert(key, (self.tick, cells)) {
            self.by_use.remove(&used);
            self.bytes -= old.len() * 8;
        }
        self.by_use.insert(self.tick, key);
        self.bytes += size;
        while self.bytes > self.capacity_bytes && self.by_use.len() > 1 {
            let Some((_, oldest)) = self.by_use.pop_first() else {
                break;
            };
            if let Some((_, old)) = self.by_key.remove(&oldest) {
                self.bytes -= old.len() * 8;
            }
        }
    }

    /// Bytes of cells kept now.
    pub fn bytes(&self) -> usize {
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(n: usize, v: f64) -> Arc<Vec<f64>> {
        Arc::new(vec![v; n])
    }

    #[test]
    fn the_least_recently_used_block_goes_first() {
        // Room for two blocks of 4 cells (32 bytes each).
        let mut cache = CellCache::new(64);
        cache.put(1u64, block(4, 1.0));
        cache.put(2, block(4, 2.0));
        assert_eq!(cache.get(1).unwrap()[0], 1.0);
        cache.put(3, block(4, 3.0));
        assert!(cache.get(2).is_none(), "2 was the least recently used");
        assert_eq!(cache.get(1).unwrap()[0], 1.0);
        assert_eq!(cache.get(3).unwrap()[0], 3.0);
        assert_eq!(cache.bytes(), 64);
    }

    #[test]
    fn a_block_over_the_budget_is_kept_alone_and_a_key_replaced_counts_once() {
        let mut cache = CellCache::new(16);
        cache.put((0usize, 0usize), block(4, 1.0));
        assert_eq!(cache.get((0, 0)).unwrap().len(), 4);
        cache.put((0, 0), block(2, 5.0));
        assert_eq!(cache.bytes(), 16);
        assert_eq!(cache.get((0, 0)).unwrap()[0], 5.0);
        cache.put((1, 0), block(8, 2.0));
        assert!(cache.get((0, 0)).is_none());
        assert_eq!(cache.bytes(), 64);
    }
}
