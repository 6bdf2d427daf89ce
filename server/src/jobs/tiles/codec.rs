//! A tile's cells as stored between stages and for the finish: class
//! bytes or little-endian f32 values, zlib-compressed (as the DEM tiles
//! are, see `state::dem_store::tiles`). Decoding checks the cell count,
//! so damaged bytes give an error, never a short tile or a huge buffer.

use std::io::{Read, Write};

/// `cells` compressed.
pub fn encode_classes(cells: &[u8]) -> std::io::Result<Vec<u8>> {
    compress(cells)
}

/// `values` as little-endian f32, compressed.
pub fn encode_values(values: &[f32]) -> std::io::Result<Vec<u8>> {
    let mut raw = Vec::with_capacity(values.len() * 4);
    for v in values {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    compress(&raw)
}

fn compress(raw: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut z = flate2::write::ZlibEncoder::new(
        Vec::with_capacity(raw.len() / 4 + 64),
        flate2::Compression::fast(),
    );
    z.write_all(raw)?;
    z.finish()
}

/// The `cells` class bytes of a stored tile.
pub fn decode_classes(data: &[u8], cells: usize) -> Result<Vec<u8>, String> {
    inflate(data, cells)
}

/// The `cells` f32 values of a stored tile.
pub fn decode_values(data: &[u8], cells: usize) -> Result<Vec<f32>, String> {
    let raw = inflate(data, cells.saturating_mul(4))?;
    Ok(raw
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// Exactly `want` bytes inflated from `data`.
fn inflate(data: &[u8], want: usize) -> Result<Vec<u8>, String> {
    let mut raw = Vec::with_capacity(want);
    flate2::read::ZlibDecoder::new(data)
        .take(want as u64 + 1)
        .read_to_end(&mut raw)
        .map_err(|e| format!("a stored costmap tile is corrupt: {e}"))?;
    if raw.len() != want {
        return Err(format!(
            "a stored costmap tile holds {} bytes, {want} expected",
            raw.len()
        ));
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_read_back_as_written_and_damage_is_an_error() {
        let classes: Vec<u8> = (0..300).map(|i| (i % 7) as u8).collect();
        let z = encode_classes(&classes).unwrap();
        assert_eq!(decode_classes(&z, 300).unwrap(), classes);
        assert!(decode_classes(&z, 299).unwrap_err().contains("300 bytes"));
        assert!(decode_classes(&z, 301).is_err());
        let values = [1.5f32, f32::NAN, -0.0, 3e38];
        let z = encode_values(&values).unwrap();
        let back = decode_values(&z, 4).unwrap();
        for (a, b) in back.iter().zip(values) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        assert!(decode_values(&z[..z.len() - 3], 4).is_err());
        assert!(decode_values(b"not zlib", 4).is_err());
    }
}
