//! A 4-ary min-heap.
//!
//! The searches' open lists pop millions of 16-byte entries. With four
//! children per node the heap is half as deep as a binary one and the
//! children of a node share one or two cache lines, so a pop costs about
//! half the cache misses and mispredicted branches of `std`'s binary heap.

#[derive(Clone)]
pub(crate) struct QuaternaryHeap<T> {
    items: Vec<T>,
}

impl<T: Ord + Copy> QuaternaryHeap<T> {
    pub(crate) fn new() -> Self {
        QuaternaryHeap { items: Vec::new() }
    }

    pub(crate) fn peek(&self) -> Option<&T> {
        self.items.first()
    }

    #[inline]
    pub(crate) fn push(&mut self, item: T) {
        let mut i = self.items.len();
        self.items.push(item);
        // Move the hole up while the parent is larger.
        while i > 0 {
            let parent = (i - 1) / 4;
            if self.items[parent] <= item {
                break;
            }
            self.items[i] = self.items[parent];
            i = parent;
        }
        self.items[i] = item;
    }

    #[inline]
    pub(crate) fn pop(&mut self) -> Option<T> {
        let last = self.items.pop()?;
        let Some(&top) = self.items.first() else {
            return Some(last);
        };
        // Move the hole from the root down to where `last` fits.
        let n = self.items.len();
        let mut i = 0;
        loop {
            let first = 4 * i + 1;
            if first >= n {
                break;
            }
            let mut child = first;
            for c in first + 1..(first + 4).min(n) {
                if self.items[c] < self.items[child] {
                    child = c;
                }
            }
            if self.items[child] >= last {
                break;
            }
            self.items[i] = self.items[child];
            i = child;
        }
        self.items[i] = last;
        Some(top)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::Rng;

    #[test]
    fn pops_in_order_like_a_binary_heap() {
        let mut rng = Rng::new(23);
        let mut heap = QuaternaryHeap::new();
        let mut reference = std::collections::BinaryHeap::new();
        for round in 0..50_000u32 {
            for _ in 0..rng.below(4) {
                let key = rng.below(1000);
                heap.push((key, round));
                reference.push(std::cmp::Reverse((key, round)));
            }
            if rng.below(3) > 0 {
                assert_eq!(heap.peek().copied(), reference.peek().map(|r| r.0));
                assert_eq!(heap.pop(), reference.pop().map(|r| r.0));
            }
            assert_eq!(heap.items.len(), reference.len());
        }
        while let Some(x) = heap.pop() {
            assert_eq!(Some(x), reference.pop().map(|r| r.0));
        }
        assert!(reference.is_empty());
        assert_eq!(heap.pop(), None);
    }
}
