//! Checking a Deflate-compressed strip or tile before it is decoded, as
//! libtiff (with libdeflate, as GDAL builds it) decodes it: the zlib
//! stream must lie within the chunk's byte count, end there with a valid
//! Adler-32 checksum, and inflate to at least the chunk's size and no
//! more than a whole chunk's.
//!
//! The `tiff` crate's decoder reads a Deflate chunk past its byte count
//! and stops inflating as soon as the chunk is full, so a stream cut
//! short by a lying byte count, a checksum failure or a stream longer
//! than the chunk (the header's sizes do not match the data) would still
//! be decoded: where GDAL refuses such a chunk or reads bytes left
//! half-written by libdeflate, the reader refuses it too.

use flate2::{Decompress, FlushDecompress, Status};

/// Inflated bytes looked at per step (the output is only counted).
const SCRATCH_BYTES: usize = 64 * 1024;

/// Whether `compressed` (a chunk's bytes, exactly its byte count) is one
/// whole zlib stream inflating to `wanted..=most` bytes; else why not.
pub(super) fn check_deflate_chunk(compressed: &[u8], wanted: u64, most: u64) -> Result<(), String> {
    let mut inflater = Decompress::new(true);
    let mut scratch = vec![0u8; SCRATCH_BYTES];
    loop {
        let (in_before, out_before) = (inflater.total_in(), inflater.total_out());
        let rest = usize::try_from(in_before)
            .ok()
            .and_then(|at| compressed.get(at..))
            .unwrap_or(&[]);
        let status = inflater
            .decompress(rest, &mut scratch, FlushDecompress::None)
            .map_err(|e| {
                format!(
                    "its Deflate data is corrupt ({}) after {} of its {} bytes",
                    e.message().unwrap_or("bad data or checksum"),
                    inflater.total_in(),
                    compressed.len()
                )
            })?;
        let out = inflater.total_out();
        if out > most {
            return Err(format!(
                "its Deflate data inflates to more than the {most} bytes it holds: the TIFF's \
                 header does not match its image data"
            ));
        }
        if status == Status::StreamEnd {
            break;
        }
        if inflater.total_in() == in_before && out == out_before {
            return Err(format!(
                "its Deflate data ends early: its byte count ({}) cuts the stream after {out} of \
                 the {wanted} bytes it holds",
                compressed.len()
            ));
        }
    }
    let out = inflater.total_out();
    if out < wanted {
        return Err(format!(
            "its Deflate data inflates to {out} bytes, fewer than the {wanted} it holds"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::Compression;
    use flate2::write::ZlibEncoder;
    use std::io::Write;

    fn zlib(data: &[u8]) -> Vec<u8> {
        let mut e = ZlibEncoder::new(Vec::new(), Compression::default());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    fn data(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 7 % 251) as u8).collect()
    }

    #[test]
    fn a_whole_stream_of_the_right_size_passes() {
        let z = zlib(&data(100_000));
        assert_eq!(check_deflate_chunk(&z, 100_000, 100_000), Ok(()));
        // A last strip cut at the bottom may inflate to a whole strip.
        assert_eq!(check_deflate_chunk(&z, 60_000, 100_000), Ok(()));
    }

    #[test]
    fn a_stream_cut_by_its_byte_count_is_refused() {
        let z = zlib(&data(100_000));
        for len in [0, 1, 2, z.len() / 2, z.len() - 1] {
            let e = check_deflate_chunk(&z[..len], 100_000, 100_000).unwrap_err();
            assert!(
                e.contains("ends early") || e.contains("corrupt"),
                "{len}: {e}"
            );
        }
    }

    #[test]
    fn a_checksum_failure_is_refused() {
        let mut z = zlib(&data(1000));
        let last = z.len() - 1;
        z[last] ^= 1;
        let e = check_deflate_chunk(&z, 1000, 1000).unwrap_err();
        assert!(e.contains("corrupt"), "{e}");
    }

    #[test]
    fn a_stream_longer_or_shorter_than_the_chunk_is_refused() {
        let z = zlib(&data(1000));
        let e = check_deflate_chunk(&z, 996, 996).unwrap_err();
        assert!(e.contains("more than the 996 bytes"), "{e}");
        let e = check_deflate_chunk(&z, 1004, 1004).unwrap_err();
        assert!(
            e.contains("inflates to 1000 bytes, fewer than the 1004"),
            "{e}"
        );
    }

    #[test]
    fn noise_that_still_inflates_is_refused_by_its_checksum() {
        // Literal bytes overwritten in a stored (uncompressed) block: the
        // stream still inflates to the right size, only the checksum
        // tells.
        let raw = data(2000);
        let mut e = ZlibEncoder::new(Vec::new(), Compression::none());
        e.write_all(&raw).unwrap();
        let mut z = e.finish().unwrap();
        z[100] ^= 0x5A;
        let err = check_deflate_chunk(&z, 2000, 2000).unwrap_err();
        assert!(err.contains("corrupt"), "{err}");
    }
}
