//! Costs of a [`CostSource`] read on demand through a small LRU of square
//! tiles, so that a search over a big map holds only the tiles around its
//! frontier: each tile is read once while it stays in use, and the least
//! recently used one makes room for the next.

use std::collections::HashMap;

use super::cost_source::{CostSource, CostSourceError};

/// Default tile side in cells (a tile of f32 costs is 256 KiB).
pub(crate) const DEFAULT_TILE: usize = 256;

struct CachedTile {
    key: (u32, u32),
    /// Row-major costs of the tile, clipped to the raster.
    costs: Vec<f32>,
    width: usize,
    used: u64,
}

/// Reads and counts: how the cache served a search.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Tiles read from the source (misses).
    pub tiles_read: u64,
    /// Most tiles held at once.
    pub tiles_held: usize,
}

pub(crate) struct TileCache<'a> {
    source: &'a dyn CostSource,
    tile: usize,
    capacity: usize,
    slots: HashMap<(u32, u32), usize>,
    tiles: Vec<CachedTile>,
    clock: u64,
    stats: CacheStats,
}

impl<'a> TileCache<'a> {
    /// A cache of at most `capacity` (≥ 1) tiles of `tile` × `tile` cells.
    pub(crate) fn new(source: &'a dyn CostSource, tile: usize, capacity: usize) -> TileCache<'a> {
        TileCache {
            source,
            tile: tile.max(1),
            capacity: capacity.max(1),
            slots: HashMap::new(),
            tiles: Vec::new(),
            clock: 0,
            stats: CacheStats::default(),
        }
    }

    pub(crate) fn source(&self) -> &'a dyn CostSource {
        self.source
    }

    pub(crate) fn stats(&self) -> CacheStats {
        self.stats
    }

    /// Bytes of costs the cache may hold at most.
    pub(crate) fn capacity_bytes(&self) -> usize {
        self.capacity * self.tile * self.tile * 4
    }

    /// The slot of the tile holding cell (r, c), read if missing.
    fn slot(&mut self, r: usize, c: usize) -> Result<usize, CostSourceError> {
        let key = ((r / self.tile) as u32, (c / self.tile) as u32);
        self.clock += 1;
        if let Some(&slot) = self.slots.get(&key) {
            self.tiles[slot].used = self.clock;
            return Ok(slot);
        }
        let (r0, c0) = (key.0 as usize * self.tile, key.1 as usize * self.tile);
        let h = self.tile.min(self.source.height() - r0);
        let w = self.tile.min(self.source.width() - c0);
        let slot = if self.tiles.len() < self.capacity {
            self.tiles.push(CachedTile {
                key,
                costs: Vec::new(),
                width: 0,
                used: 0,
            });
            self.tiles.len() - 1
        } else {
            // The least recently used tile makes room (a scan: few tiles).
            let slot = (0..self.tiles.len())
                .min_by_key(|&i| self.tiles[i].used)
                .expect("capacity ≥ 1");
            self.slots.remove(&self.tiles[slot].key);
            slot
        };
        let t = &mut self.tiles[slot];
        t.costs.resize(w * h, 0.0);
        if let Err(e) = self.source.read_costs(r0, c0, w, h, &mut t.costs) {
            // Leave no half-read tile behind.
            t.costs.clear();
            t.used = 0;
            return Err(e);
        }
        t.key = key;
        t.width = w;
        t.used = self.clock;
        self.slots.insert(key, slot);
        self.stats.tiles_read += 1;
        self.stats.tiles_held = self.stats.tiles_held.max(self.tiles.len());
        Ok(slot)
    }

    /// The cost of cell (r, c), which must be inside the raster.
    pub(crate) fn cost(&mut self, r: usize, c: usize) -> Result<f32, CostSourceError> {
        let slot = self.slot(r, c)?;
        let t = &self.tiles[slot];
        Ok(t.costs[(r % self.tile) * t.width + c % self.tile])
    }

    /// Copies the window of `h` × `w` cells at (r0, c0), which must lie
    /// inside one tile, into `out` (row-major).
    pub(crate) fn copy_window(
        &mut self,
        r0: usize,
        c0: usize,
        h: usize,
        w: usize,
        out: &mut [f32],
    ) -> Result<(), CostSourceError> {
        debug_assert_eq!(r0 / self.tile, (r0 + h - 1) / self.tile);
        debug_assert_eq!(c0 / self.tile, (c0 + w - 1) / self.tile);
        let slot = self.slot(r0, c0)?;
        let t = &self.tiles[slot];
        let (tr, tc) = (r0 % self.tile, c0 % self.tile);
        for (i, dst) in out.chunks_exact_mut(w).take(h).enumerate() {
            let start = (tr + i) * t.width + tc;
            dst.copy_from_slice(&t.costs[start..start + w]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::CostGrid;

    fn ramp(w: usize, h: usize) -> CostGrid {
        let costs = (0..w * h).map(|i| 1.0 + i as f32).collect();
        CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap()
    }

    #[test]
    fn cells_read_through_the_cache_equal_the_grid() {
        let grid = ramp(37, 29);
        let mut cache = TileCache::new(&grid, 8, 3);
        for r in 0..29 {
            for c in 0..37 {
                assert_eq!(cache.cost(r, c).unwrap(), grid.cost((r, c)).unwrap());
            }
        }
        let mut out = vec![0.0; 6];
        cache.copy_window(33 - 8, 32, 2, 3, &mut out).unwrap();
        assert_eq!(out[0], grid.cost((25, 32)).unwrap());
        assert_eq!(out[5], grid.cost((26, 34)).unwrap());
        // Row by row, each tile is read once per row of tiles.
        assert_eq!(cache.stats().tiles_held, 3);
    }

    #[test]
    fn the_least_recently_used_tile_is_evicted() {
        let grid = ramp(32, 8);
        let mut cache = TileCache::new(&grid, 8, 2);
        cache.cost(0, 0).unwrap(); // tile A
        cache.cost(0, 8).unwrap(); // tile B
        cache.cost(0, 1).unwrap(); // A again: B is now the oldest
        cache.cost(0, 16).unwrap(); // C evicts B
        assert_eq!(cache.stats().tiles_read, 3);
        cache.cost(0, 2).unwrap(); // A still held
        assert_eq!(cache.stats().tiles_read, 3);
        cache.cost(0, 9).unwrap(); // B read again
        assert_eq!(cache.stats().tiles_read, 4);
        assert_eq!(cache.stats().tiles_held, 2);
        assert_eq!(cache.capacity_bytes(), 2 * 64 * 4);
    }
}
