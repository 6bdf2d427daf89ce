//! The route searches kept for replanning: an LRU of D* Lite searches by
//! route id, and the searches still being built in the background.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use planner_core::route::DStarLite;

use crate::config::ServeConfig;

/// `--route-cache-mb` by default.
const ROUTE_CACHE_BYTES: usize = 512 * 1024 * 1024;

/// `--route-coarse-cells` by default: 4000 × 4000 (plain A* then holds
/// 16 B × 16 M = 256 MB), as `terraplan route --coarse-to-fine-above`.
pub const COARSE_CELLS: u64 = 16_000_000;

/// The D* Lite searches kept in memory so that a replan repairs the
/// previous search instead of starting over.
pub struct RouteStore {
    pub searches: SearchCache,
    /// Costmaps with more cells are routed coarse to fine
    /// (`--route-coarse-cells`).
    pub coarse_cells: u64,
    /// Routes whose D* Lite search is being built in the background: a
    /// receiver that turns true when it is done (or dropped if it failed).
    warming: Mutex<HashMap<String, tokio::sync::watch::Receiver<bool>>>,
}

/// Marks route `id`'s search as being built until dropped.
pub struct Warming {
    store: Arc<RouteStore>,
    id: String,
    done: tokio::sync::watch::Sender<bool>,
}

impl Drop for Warming {
    fn drop(&mut self) {
        let _ = self.done.send(true);
        lock(&self.store.warming).remove(&self.id);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // The maps guard no invariant a panic could break half-way.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl RouteStore {
    pub fn new(cache_bytes: usize) -> RouteStore {
        RouteStore {
            searches: SearchCache::new(cache_bytes),
            coarse_cells: COARSE_CELLS,
            warming: Mutex::new(HashMap::new()),
        }
    }

    /// Route `id`'s search is being built: replans of `id` wait for it
    /// (see [`warmed`](Self::warmed)) until the returned guard is dropped.
    pub fn begin_warming(self: &Arc<Self>, id: &str) -> Warming {
        let (done, rx) = tokio::sync::watch::channel(false);
        lock(&self.warming).insert(id.to_string(), rx);
        Warming {
            store: self.clone(),
            id: id.to_string(),
            done,
        }
    }

    /// Wait until no search of route `id` is being built. The one being
    /// built started earlier than a rebuild would, so it is never slower
    /// to wait for it.
    pub async fn warmed(&self, id: &str) {
        let rx = lock(&self.warming).get(id).cloned();
        if let Some(mut rx) = rx {
            let _ = rx.wait_for(|done| *done).await;
        }
    }

    pub fn from_config(config: &ServeConfig) -> RouteStore {
        RouteStore {
            coarse_cells: config.route_coarse_cells,
            ..RouteStore::new(config.route_cache_bytes())
        }
    }
}

impl Default for RouteStore {
    fn default() -> Self {
        RouteStore::new(ROUTE_CACHE_BYTES)
    }
}

/// The D* Lite search of each recent route (its grid with every change
/// applied so far, its g values and queue), by route id: an LRU bounded
/// by an estimate of the memory held. A replan takes its parent's search
/// out (so two replans of one route never share it), repairs it and puts
/// it back under the new route's id.
pub struct SearchCache {
    /// Most recently used first: (route id, search, estimated bytes).
    entries: Mutex<Vec<(String, DStarLite, usize)>>,
    max_bytes: usize,
}

impl SearchCache {
    pub fn new(max_bytes: usize) -> SearchCache {
        SearchCache {
            entries: Mutex::new(Vec::new()),
            max_bytes,
        }
    }

    /// Estimated memory of a search ([`DStarLite::estimated_bytes`]: its
    /// costs, g, state and landmark, per cell, and slack for its queue).
    pub fn estimate_bytes(search: &DStarLite) -> usize {
        search.estimated_bytes()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(String, DStarLite, usize)>> {
        // The list guards no invariant a panic could break half-way.
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Take the search of route `id` out of the cache.
    pub fn take(&self, id: &str) -> Option<DStarLite> {
        let mut entries = self.lock();
        let i = entries.iter().position(|(k, _, _)| k == id)?;
        Some(entries.remove(i).1)
    }

    /// Keep `search` as route `id`'s, the most recently used, evicting the
    /// least recently used beyond the memory budget; a search alone over
    /// the budget is not kept.
    pub fn put(&self, id: &str, search: DStarLite) {
        let size = Self::estimate_bytes(&search);
        if size > self.max_bytes {
            return;
        }
        let mut entries = self.lock();
        entries.retain(|(k, _, _)| k != id);
        entries.insert(0, (id.to_string(), search, size));
        let mut total = 0usize;
        let keep = entries
            .iter()
            .take_while(|(_, _, bytes)| {
                total = total.saturating_add(*bytes);
                total <= self.max_bytes
            })
            .count();
        entries.truncate(keep);
    }

    /// Forget route `id`'s search.
    pub fn remove(&self, id: &str) {
        self.lock().retain(|(k, _, _)| k != id);
    }

    /// Searches held, and their estimated bytes.
    #[cfg(test)]
    pub fn usage(&self) -> (usize, usize) {
        let entries = self.lock();
        (entries.len(), entries.iter().map(|(_, _, b)| b).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A D* Lite search on a `cells`-cell strip.
    fn search(cells: usize) -> DStarLite {
        let grid =
            planner_core::route::CostGrid::with_cell_size(cells, 1, vec![1.0; cells], 1.0, 1.0)
                .unwrap();
        DStarLite::new(grid, (0, 0), (0, cells - 1), Default::default()).unwrap()
    }

    #[test]
    fn search_cache_is_lru_by_estimated_bytes() {
        // 17 bytes a cell, 8 a row, and the landmark's 8 bytes a cell of
        // the grid padded to 16 × 16 tiles (7 tiles here): 100 cells.
        let one = 100 * 17 + 8 + 7 * 256 * 8;
        assert_eq!(SearchCache::estimate_bytes(&search(100)), one);
        let cache = SearchCache::new(3 * one);
        for id in ["a", "b", "c"] {
            cache.put(id, search(100));
        }
        assert_eq!(cache.usage(), (3, 3 * one));
        let a = cache.take("a").expect("held");
        assert_eq!(a.grid().cell_count(), 100);
        assert!(cache.take("a").is_none(), "taken out");
        cache.put("d", a); // a's search, moved to d
        cache.put("e", search(100)); // b, the least recently used, goes
        assert!(cache.take("b").is_none());
        assert!(cache.take("c").is_some() && cache.take("d").is_some());
        // A search alone over the budget is not kept.
        cache.put("huge", search(1000));
        assert!(cache.take("huge").is_none());
        cache.remove("e");
        assert_eq!(cache.usage(), (0, 0));
        let none = SearchCache::new(0);
        none.put("a", search(10));
        assert!(none.take("a").is_none());
    }
}
