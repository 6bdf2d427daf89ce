//! The searches' open list (A*'s and D* Lite's): an exact priority queue
//! that keeps only a thin slice of the frontier in a heap.
//!
//! Entries are `u128`s whose top 64 bits are a non-negative f64 key (whose
//! bit pattern orders like the number) and whose low bits break ties; they
//! pop in increasing `u128` order. The key axis is cut into buckets of a
//! fixed width: entries of the current bucket (and any below it) sit in a
//! ring of buckets, appended unsorted; when the search reaches a bucket it
//! is sorted once and consumed in order, and the few entries pushed into
//! it (or below it) meanwhile go to a small binary heap. A* keys stay within a
//! bounded distance of the smallest one (an arc cost plus the heuristic's
//! change along it), so the ring covers them all; anything beyond waits in
//! an overflow list. The order is exact whatever the keys; only speed
//! depends on the width: sorting a bucket of a few hundred entries and
//! reading it in order is much cheaper than sifting them through a heap of
//! the whole frontier.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

#[derive(Clone)]
pub(crate) struct BucketQueue {
    inverse_width: f64,
    /// The current bucket as it was reached, sorted descending.
    sorted: Vec<u128>,
    /// Entries pushed into the current bucket or below since then.
    heap: BinaryHeap<Reverse<u128>>,
    current: u64,
    /// Bucket i (current < i ≤ current + ring.len()) at ring[i & mask].
    ring: Vec<Vec<u128>>,
    mask: u64,
    in_ring: usize,
    /// Entries beyond the ring.
    overflow: Vec<u128>,
}

#[inline]
fn key(entry: u128) -> f64 {
    f64::from_bits((entry >> 64) as u64)
}

impl BucketQueue {
    /// Buckets `width` wide (> 0), at least `slots` of them ahead of the
    /// current one (rounded up to a power of two).
    pub(crate) fn new(width: f64, slots: usize) -> BucketQueue {
        let slots = slots.max(1).next_power_of_two();
        BucketQueue {
            inverse_width: 1.0 / width,
            sorted: Vec::new(),
            heap: BinaryHeap::new(),
            current: 0,
            ring: (0..slots).map(|_| Vec::new()).collect(),
            mask: slots as u64 - 1,
            in_ring: 0,
            overflow: Vec::new(),
        }
    }

    #[inline]
    fn bucket(&self, entry: u128) -> u64 {
        // Saturating: +∞ and huge keys land in the last bucket.
        (key(entry) * self.inverse_width) as u64
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, entry: u128) {
        let b = self.bucket(entry);
        if b <= self.current {
            self.heap.push(Reverse(entry));
        } else if b - self.current <= self.ring.len() as u64 {
            let slot = (b & self.mask) as usize;
            self.ring[slot].push(entry);
            self.in_ring += 1;
        } else {
            self.overflow.push(entry);
        }
    }

    #[inline]
    pub(crate) fn pop(&mut self) -> Option<u128> {
        self.pop_live(|_| true)
    }

    /// `pop`, for a search that skips the entries `live` rejects anyway
    /// (A*'s of closed cells): those of a bucket reached from the ring are
    /// dropped before it is sorted instead of popped one by one. About half
    /// of A*'s entries are such stale duplicates.
    #[inline]
    pub(crate) fn pop_live(&mut self, live: impl Fn(u128) -> bool) -> Option<u128> {
        loop {
            match (self.sorted.last(), self.heap.peek()) {
                (Some(&a), Some(&Reverse(b))) if b < a => {
                    self.heap.pop();
                    return Some(b);
                }
                (Some(_), _) => return self.sorted.pop(),
                (None, Some(_)) => return self.heap.pop().map(|e| e.0),
                (None, None) => {
                    if !self.advance(&live) {
                        return None;
                    }
                }
            }
        }
    }

    /// An entry `k` + 1 pops away in the current bucket, if it has that
    /// many left (entries pushed into it meanwhile may come first): a hint
    /// for prefetching.
    #[inline(always)]
    pub(crate) fn ahead(&self, k: usize) -> Option<u128> {
        let left = self.sorted.len();
        (left > k).then(|| self.sorted[left - 1 - k])
    }

    /// The entry `pop` would return, left in the queue.
    #[inline]
    pub(crate) fn peek(&mut self) -> Option<u128> {
        self.peek_live(|_| true)
    }

    /// `peek`, dropping the entries `live` rejects as `pop_live` does.
    #[inline]
    pub(crate) fn peek_live(&mut self, live: impl Fn(u128) -> bool) -> Option<u128> {
        loop {
            match (self.sorted.last(), self.heap.peek()) {
                (Some(&a), Some(&Reverse(b))) => return Some(a.min(b)),
                (Some(&a), None) => return Some(a),
                (None, Some(&Reverse(b))) => return Some(b),
                (None, None) => {
                    if !self.advance(&live) {
                        return None;
                    }
                }
            }
        }
    }

    /// Moves on to the next non-empty bucket (the current one is used up);
    /// false when all are empty.
    fn advance(&mut self, live: &impl Fn(u128) -> bool) -> bool {
        if self.in_ring == 0 {
            // Jump straight to the overflow's first bucket, if any.
            let Some(first) = self.overflow.iter().map(|&e| self.bucket(e)).min() else {
                return false;
            };
            self.current = first - 1;
        }
        let slots = self.ring.len() as u64;
        loop {
            self.current += 1;
            let slot = (self.current & self.mask) as usize;
            if !self.ring[slot].is_empty() {
                let bucket = &mut self.ring[slot];
                self.in_ring -= bucket.len();
                self.sorted.clear();
                self.sorted.append(bucket);
                self.sorted.retain(|&e| live(e));
                self.sorted.sort_unstable_by(|a, b| b.cmp(a));
                break;
            }
            if self.in_ring == 0 && !self.overflow.is_empty() {
                break;
            }
        }
        if !self.overflow.is_empty() {
            // The window moved: bring in what now falls inside it.
            let horizon = self.current.saturating_add(slots);
            let mut i = 0;
            while i < self.overflow.len() {
                let b = self.bucket(self.overflow[i]);
                if b <= horizon {
                    let entry = self.overflow.swap_remove(i);
                    if b <= self.current {
                        self.heap.push(Reverse(entry));
                    } else {
                        self.ring[(b & self.mask) as usize].push(entry);
                        self.in_ring += 1;
                    }
                } else {
                    i += 1;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::Rng;

    fn entry(key: f64, tie: u64) -> u128 {
        (u128::from(key.to_bits()) << 64) | u128::from(tie)
    }

    #[test]
    fn pops_in_order_for_any_keys() {
        let mut rng = Rng::new(31);
        for (width, slots) in [(0.5, 8usize), (0.01, 3), (100.0, 1), (1.0, 64)] {
            let mut queue = BucketQueue::new(width, slots);
            let mut reference = BinaryHeap::new();
            let mut floor = 0.0f64;
            for round in 0..30_000u64 {
                for _ in 0..rng.below(4) {
                    // Mostly A*-like (a little above the last pop), some far
                    // ahead, some below it, some infinite.
                    let key = match rng.below(20) {
                        0 => floor + 1000.0 * rng.unit(),
                        1 => floor * rng.unit(),
                        2 => f64::INFINITY,
                        _ => floor + 3.0 * rng.unit(),
                    };
                    let e = entry(key, round);
                    queue.push(e);
                    reference.push(Reverse(e));
                }
                if rng.below(3) > 0 {
                    let peeked = queue.peek();
                    let (got, want) = (queue.pop(), reference.pop().map(|r| r.0));
                    assert_eq!(peeked, got, "peek shows what pop takes");
                    assert_eq!(got, want, "width {width} slots {slots} round {round}");
                    if let Some(e) = got
                        && key(e).is_finite()
                    {
                        floor = key(e);
                    }
                }
            }
            while let Some(Reverse(want)) = reference.pop() {
                assert_eq!(queue.pop(), Some(want));
            }
            assert_eq!(queue.pop(), None);
        }
    }

    #[test]
    fn pop_live_keeps_the_order_of_live_entries_and_may_drop_the_rest() {
        let mut rng = Rng::new(32);
        let live = |e: u128| !e.is_multiple_of(3);
        let mut queue = BucketQueue::new(0.25, 16);
        let mut reference = BinaryHeap::new();
        let mut floor = 0.0f64;
        let mut dropped = 0;
        for round in 0..20_000u64 {
            for _ in 0..rng.below(4) {
                let e = entry(floor + 3.0 * rng.unit(), round * 8 + rng.below(8));
                queue.push(e);
                reference.push(Reverse(e));
            }
            if rng.below(3) > 0
                && let Some(got) = queue.pop_live(live)
            {
                // Every entry the reference pops before it is one the
                // queue was allowed to drop.
                loop {
                    let Reverse(want) = reference.pop().expect("the reference holds it");
                    if want == got {
                        break;
                    }
                    assert!(!live(want), "round {round}: live entry {want} skipped");
                    dropped += 1;
                }
                floor = key(got);
            }
        }
        while let Some(got) = queue.pop_live(live) {
            while let Some(Reverse(want)) = reference.pop()
                && want != got
            {
                assert!(!live(want));
            }
        }
        assert!(reference.into_iter().all(|Reverse(e)| !live(e)));
        assert!(dropped > 1000, "dead entries are dropped: {dropped}");
    }

    #[test]
    fn ties_break_on_the_low_bits() {
        let mut queue = BucketQueue::new(1.0, 4);
        queue.push(entry(2.0, 7));
        queue.push(entry(2.0, 3));
        queue.push(entry(0.5, 9));
        assert_eq!(queue.pop(), Some(entry(0.5, 9)));
        assert_eq!(queue.pop(), Some(entry(2.0, 3)));
        assert_eq!(queue.pop(), Some(entry(2.0, 7)));
        assert_eq!(queue.pop(), None);
    }
}
