//! The byte form of the pieces a tiled costmap's stages hand each other
//! when they run as jobs on different processes ([`super::tile_stages`]):
//! a kind byte, a version byte, then little-endian fields.
//!
//! The bytes come back from storage, so they are read as hostile: every
//! length is checked against the bytes that are left before anything is
//! allocated, and trailing bytes are refused; a fault is an error, never
//! a panic.

/// The version of every piece's byte form.
pub(crate) const VERSION: u8 = 1;

/// Why a piece's bytes were refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what}: {why}")]
pub struct PieceError {
    /// The piece: "tile edges", "tally", …
    pub what: &'static str,
    pub why: String,
}

/// Writes a piece's fields.
pub(crate) struct ByteWriter(Vec<u8>);

impl ByteWriter {
    pub(crate) fn new(kind: u8) -> ByteWriter {
        ByteWriter(vec![kind, VERSION])
    }

    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    /// A count or size that the stages keep far below 2^32 (tile sides,
    /// labels of a tile, pixels of a preview).
    pub(crate) fn len32(&mut self, v: usize) {
        self.u32(u32::try_from(v).unwrap_or(u32::MAX));
    }

    pub(crate) fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_bits().to_le_bytes());
    }

    pub(crate) fn bytes(&mut self, v: &[u8]) {
        self.0.extend_from_slice(v);
    }

    pub(crate) fn u32s(&mut self, v: &[u32]) {
        self.0.reserve(v.len() * 4);
        for &x in v {
            self.u32(x);
        }
    }

    pub(crate) fn finish(self) -> Vec<u8> {
        self.0
    }
}

/// Reads a piece's fields, each checked against what is left.
pub(crate) struct ByteReader<'a> {
    bytes: &'a [u8],
    at: usize,
    what: &'static str,
}

impl<'a> ByteReader<'a> {
    /// Checks the kind and version bytes.
    pub(crate) fn new(
        bytes: &'a [u8],
        kind: u8,
        what: &'static str,
    ) -> Result<ByteReader<'a>, PieceError> {
        let mut r = ByteReader { bytes, at: 0, what };
        let (k, v) = (r.u8()?, r.u8()?);
        if k != kind {
            return Err(r.fault(format!(
                "kind byte {k:#04x}, expected {kind:#04x} (another piece's bytes?)"
            )));
        }
        if v != VERSION {
            return Err(r.fault(format!("version {v}, this build reads {VERSION}")));
        }
        Ok(r)
    }

    pub(crate) fn fault(&self, why: String) -> PieceError {
        PieceError {
            what: self.what,
            why,
        }
    }

    /// The next `n` bytes.
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], PieceError> {
        let left = self.bytes.len() - self.at;
        if n > left {
            return Err(self.fault(format!(
                "cut short: {n} bytes needed at byte {}, {left} left",
                self.at
            )));
        }
        let out = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(out)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, PieceError> {
        Ok(self.take(1)?[0])
    }

    pub(crate) fn u32(&mut self) -> Result<u32, PieceError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub(crate) fn u64(&mut self) -> Result<u64, PieceError> {
        let b = self.take(8)?;
        let mut a = [0; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    pub(crate) fn f64(&mut self) -> Result<f64, PieceError> {
        self.u64().map(f64::from_bits)
    }

    pub(crate) fn bool(&mut self) -> Result<bool, PieceError> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(self.fault(format!("byte {b} where a flag (0 or 1) was expected"))),
        }
    }

    /// Fails unless at least `count` items of `item_bytes` each are left,
    /// so a hostile count cannot make a huge allocation.
    pub(crate) fn expect_items(&self, count: usize, item_bytes: usize) -> Result<(), PieceError> {
        let left = self.bytes.len() - self.at;
        match count.checked_mul(item_bytes) {
            Some(n) if n <= left => Ok(()),
            _ => Err(self.fault(format!(
                "{count} items of {item_bytes} bytes announced at byte {}, {left} bytes left",
                self.at
            ))),
        }
    }

    pub(crate) fn u32s(&mut self, count: usize) -> Result<Vec<u32>, PieceError> {
        self.expect_items(count, 4)?;
        (0..count).map(|_| self.u32()).collect()
    }

    /// Fails on bytes after the piece.
    pub(crate) fn end(self) -> Result<(), PieceError> {
        let left = self.bytes.len() - self.at;
        if left > 0 {
            return Err(self.fault(format!("{left} bytes after the end")));
        }
        Ok(())
    }
}

/// Test helpers: every cut of a piece's bytes, and random bytes, are
/// refused with an error.
#[cfg(test)]
pub(crate) mod testing {
    use crate::test_rng::Lcg;

    /// `parse` fails on every proper prefix of `bytes`, on `bytes` with a
    /// byte added, and on random bytes (some behind the right kind and
    /// version bytes); none of it panics.
    pub(crate) fn assert_refuses_damage<T: std::fmt::Debug, E>(
        bytes: &[u8],
        parse: impl Fn(&[u8]) -> Result<T, E>,
        seed: u64,
    ) {
        for n in 0..bytes.len() {
            assert!(parse(&bytes[..n]).is_err(), "a cut to {n} bytes was read");
        }
        let mut longer = bytes.to_vec();
        longer.push(0);
        assert!(parse(&longer).is_err(), "a trailing byte was read");
        let mut s = Lcg(seed);
        for case in 0..2000 {
            let len = (s.next() * 2.0 * bytes.len().max(8) as f64) as usize;
            let mut junk: Vec<u8> = (0..len).map(|_| (s.next() * 256.0) as u8).collect();
            if case % 2 == 0 && junk.len() >= 2 {
                // Behind the right kind and version, random fields may by
                // chance form a valid piece: what matters is that reading
                // them returns.
                junk[..2].copy_from_slice(&bytes[..2]);
                let _ = parse(&junk);
            } else if junk.get(..2) != Some(&bytes[..2]) {
                assert!(parse(&junk).is_err(), "random bytes were read: {junk:?}");
            }
        }
        // Flipped bytes of the real piece: each read returns.
        for i in 0..bytes.len() {
            let mut flipped = bytes.to_vec();
            flipped[i] ^= 0xff;
            let _ = parse(&flipped);
        }
    }
}
