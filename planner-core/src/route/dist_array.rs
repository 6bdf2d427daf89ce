//! A dense array of path costs that starts out at +∞ for free.

/// Bit pattern of +∞; stored values are XOR-ed with it so that the zeroed
/// allocation reads as ∞ everywhere: the kernel's fresh zeroed pages
/// (`pages`) need no 8-byte-per-cell fill before a search starts.
const INFINITY_BITS: u64 = 0x7ff0_0000_0000_0000;

/// f64 per cell: g (and rhs-derived) values must match an independent
/// Dijkstra to 1e-9 relative over paths of millions of steps, beyond f32.
#[derive(Clone)]
pub(crate) struct DistArray {
    bits: Vec<u64>,
}

impl DistArray {
    pub(crate) fn new(len: usize) -> DistArray {
        DistArray {
            bits: super::pages::fresh_zeroed(len),
        }
    }

    #[inline]
    pub(crate) fn get(&self, i: usize) -> f64 {
        f64::from_bits(self.bits[i] ^ INFINITY_BITS)
    }

    #[inline]
    pub(crate) fn set(&mut self, i: usize, value: f64) {
        self.bits[i] = value.to_bits() ^ INFINITY_BITS;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn starts_infinite_and_round_trips() {
        let mut d = DistArray::new(4);
        assert!((0..4).all(|i| d.get(i) == f64::INFINITY));
        assert_eq!(INFINITY_BITS, f64::INFINITY.to_bits());
        d.set(2, 0.0);
        d.set(3, 1.25e300);
        assert_eq!(d.get(2), 0.0);
        assert_eq!(d.get(3), 1.25e300);
        d.set(3, f64::INFINITY);
        assert_eq!(d.get(3), f64::INFINITY);
    }
}
