//! What an uploaded raster declares about its size, read from its header
//! alone (a few hundred bytes, by seeking in the spooled file), so that the
//! memory reading it takes is known before anything of that size is
//! allocated: a 486 KB Float64 TIFF may declare 64 M pixels.
//!
//! Only the numbers the estimate needs are read; the file is checked in
//! full by `planner_core::terrain::read_dem` afterwards.

use std::io::{Read, Seek, SeekFrom};

/// A raster's declared size.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Declared {
    pub width: u64,
    pub height: u64,
    /// Bytes of the largest strip or tile decoded at once (0 for text).
    pub chunk_bytes: u64,
    /// The sample type, for messages ("Float64", "Int16", "text").
    pub sample: String,
}

impl Declared {
    pub fn pixels(&self) -> u64 {
        self.width.saturating_mul(self.height)
    }
}

const IMAGE_WIDTH: u16 = 256;
const IMAGE_LENGTH: u16 = 257;
const BITS_PER_SAMPLE: u16 = 258;
const SAMPLES_PER_PIXEL: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const PLANAR_CONFIG: u16 = 284;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const SAMPLE_FORMAT: u16 = 339;
/// More entries than any real first directory has.
const MAX_ENTRIES: u64 = 4096;

/// The declared size of the raster in `file` (`len` bytes, named
/// `file_name` when the client gave a name): a TIFF's first image, an
/// ESRI ASCII grid's `ncols` × `nrows`, an SRTM `.hgt` tile's size.
/// `None` when the header cannot be read (the full read then says why).
pub fn declared<R: Read + Seek>(
    file: &mut R,
    len: u64,
    file_name: Option<&str>,
) -> Option<Declared> {
    let mut head = [0u8; 16];
    let n = read_up_to(file, 0, &mut head)?;
    let head = &head[..n];
    if head.starts_with(b"II") || head.starts_with(b"MM") {
        return tiff(file, head);
    }
    if file_name.is_some_and(|n| n.to_ascii_lowercase().ends_with(".hgt")) {
        // Square tiles of big-endian 16-bit samples.
        let side = ((len / 2) as f64).sqrt().round() as u64;
        return Some(Declared {
            width: side,
            height: side,
            chunk_bytes: 0,
            sample: "Int16".into(),
        });
    }
    asc(file)
}

/// Fill `buf` from `at` as far as the file goes; the bytes read.
fn read_up_to<R: Read + Seek>(file: &mut R, at: u64, buf: &mut [u8]) -> Option<usize> {
    file.seek(SeekFrom::Start(at)).ok()?;
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return None,
        }
    }
    Some(n)
}

fn read_exact_at<R: Read + Seek>(file: &mut R, at: u64, buf: &mut [u8]) -> Option<()> {
    (read_up_to(file, at, buf)? == buf.len()).then_some(())
}

fn tiff<R: Read + Seek>(file: &mut R, head: &[u8]) -> Option<Declared> {
    let le = head.starts_with(b"II");
    let u16_at = |b: &[u8], i: usize| -> Option<u64> {
        let a: [u8; 2] = b.get(i..i + 2)?.try_into().ok()?;
        Some(u64::from(if le {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        }))
    };
    let u32_at = |b: &[u8], i: usize| -> Option<u64> {
        let a: [u8; 4] = b.get(i..i + 4)?.try_into().ok()?;
        Some(u64::from(if le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        }))
    };
    let u64_at = |b: &[u8], i: usize| -> Option<u64> {
        let a: [u8; 8] = b.get(i..i + 8)?.try_into().ok()?;
        Some(if le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        })
    };
    let big = match u16_at(head, 2)? {
        42 => false,
        43 => true,
        _ => return None,
    };
    let ifd = if big {
        u64_at(head, 8)?
    } else {
        u32_at(head, 4)?
    };
    // Entry count, entry size, and where an entry's value field starts.
    let (count_len, entry_len, value_at, value_len) =
        if big { (8, 20, 12, 8) } else { (2, 12, 8, 4) };
    let mut count_buf = [0u8; 8];
    read_exact_at(file, ifd, &mut count_buf[..count_len])?;
    let count = if big {
        u64_at(&count_buf, 0)?
    } else {
        u16_at(&count_buf, 0)?
    };
    if count > MAX_ENTRIES {
        return None;
    }
    let mut entries = vec![0u8; usize::try_from(count).ok()? * entry_len];
    read_exact_at(file, ifd + count_len as u64, &mut entries)?;

    // The first value of each tag wanted (all are SHORT, LONG or LONG8).
    let mut first = |tag: u16| -> Option<u64> {
        let e = entries
            .chunks_exact(entry_len)
            .find(|e| u16_at(e, 0) == Some(u64::from(tag)))?;
        let typ = u16_at(e, 2)?;
        let size = match typ {
            3 => 2,
            4 => 4,
            16 => 8,
            _ => return None,
        };
        let n = if big { u64_at(e, 4)? } else { u32_at(e, 4)? };
        if n == 0 {
            return None;
        }
        let mut value = [0u8; 8];
        if n.saturating_mul(size) <= value_len as u64 {
            value[..size as usize].copy_from_slice(e.get(value_at..value_at + size as usize)?);
        } else {
            let at = if big {
                u64_at(e, value_at)?
            } else {
                u32_at(e, value_at)?
            };
            read_exact_at(file, at, &mut value[..size as usize])?;
        }
        match size {
            2 => u16_at(&value, 0),
            4 => u32_at(&value, 0),
            _ => u64_at(&value, 0),
        }
    };
    let width = first(IMAGE_WIDTH)?;
    let height = first(IMAGE_LENGTH)?;
    let bits = first(BITS_PER_SAMPLE).unwrap_or(1);
    let format = first(SAMPLE_FORMAT).unwrap_or(1);
    let spp = first(SAMPLES_PER_PIXEL).unwrap_or(1).max(1);
    let planar = first(PLANAR_CONFIG).unwrap_or(1) == 2;
    let (cw, ch) = match (first(TILE_WIDTH), first(TILE_LENGTH)) {
        (Some(w), Some(h)) => (w, h),
        _ => (width, first(ROWS_PER_STRIP).unwrap_or(height).min(height)),
    };
    let samples = if planar { 1 } else { spp };
    let chunk_bytes = cw
        .saturating_mul(ch)
        .saturating_mul(samples)
        .saturating_mul(bits.div_ceil(8).max(1));
    let sample = match format {
        3 => format!("Float{bits}"),
        2 => format!("Int{bits}"),
        _ => format!("UInt{bits}"),
    };
    Some(Declared {
        width,
        height,
        chunk_bytes,
        sample,
    })
}

/// `ncols` and `nrows` from the first lines of an ESRI ASCII grid.
fn asc<R: Read + Seek>(file: &mut R) -> Option<Declared> {
    let mut head = vec![0u8; 4096];
    let n = read_up_to(file, 0, &mut head)?;
    let text = String::from_utf8_lossy(&head[..n]);
    let mut dims = (None, None);
    for line in text.lines().take(12) {
        let mut words = line.split_whitespace();
        let (Some(key), Some(value)) = (words.next(), words.next()) else {
            continue;
        };
        let key = key.trim_start_matches('\u{feff}').to_ascii_lowercase();
        match key.as_str() {
            "ncols" => dims.0 = value.parse::<u64>().ok(),
            "nrows" => dims.1 = value.parse::<u64>().ok(),
            _ => {}
        }
    }
    Some(Declared {
        width: dims.0?,
        height: dims.1?,
        chunk_bytes: 0,
        sample: "text".into(),
    })
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    /// A little- or big-endian classic TIFF with `entries` (tag, type,
    /// count, value) in its first directory at offset 8, and `tail`
    /// after it.
    fn tiff_bytes(le: bool, entries: &[(u16, u16, u32, u32)], tail: &[u8]) -> Vec<u8> {
        let u16b = |v: u16| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        let u32b = |v: u32| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        let mut b = Vec::new();
        b.extend_from_slice(if le { b"II" } else { b"MM" });
        b.extend_from_slice(&u16b(42));
        b.extend_from_slice(&u32b(8));
        b.extend_from_slice(&u16b(entries.len() as u16));
        for &(tag, kind, count, value) in entries {
            b.extend_from_slice(&u16b(tag));
            b.extend_from_slice(&u16b(kind));
            b.extend_from_slice(&u32b(count));
            if kind == 3 && count == 1 {
                b.extend_from_slice(&u16b(value as u16));
                b.extend_from_slice(&[0, 0]);
            } else {
                b.extend_from_slice(&u32b(value));
            }
        }
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(tail);
        b
    }

    fn probe(bytes: &[u8], name: Option<&str>) -> Option<Declared> {
        declared(&mut Cursor::new(bytes), bytes.len() as u64, name)
    }

    #[test]
    fn float64_single_strip_bomb() {
        let b = tiff_bytes(
            true,
            &[
                (256, 4, 1, 8000),
                (257, 4, 1, 8000),
                (258, 3, 1, 64),
                (339, 3, 1, 3),
            ],
            &[],
        );
        let d = probe(&b, None).unwrap();
        assert_eq!(
            (d.width, d.height, d.sample.as_str()),
            (8000, 8000, "Float64")
        );
        // No RowsPerStrip: one strip of the whole image.
        assert_eq!(d.chunk_bytes, 8000 * 8000 * 8);
        assert_eq!(d.pixels(), 64_000_000);
    }

    #[test]
    fn tiles_strips_and_bands() {
        // Big-endian, 3 interleaved UInt16 bands (BitsPerSample is an array
        // of 3 SHORTs, stored after the directory), 256 × 128 tiles.
        // The tail starts after the header, the count, the entries and
        // the next directory's offset.
        let tail_at = |entries: usize| (8 + 2 + entries * 12 + 4) as u32;
        let entries = [
            (256, 3, 1, 1000),
            (257, 3, 1, 700),
            (258, 3, 3, tail_at(7)),
            (277, 3, 1, 3),
            (322, 3, 1, 256),
            (323, 3, 1, 128),
            (339, 3, 1, 1),
        ];
        let b = tiff_bytes(false, &entries, &[0, 16, 0, 16, 0, 16]);
        let d = probe(&b, None).unwrap();
        assert_eq!(
            (d.width, d.height, d.sample.as_str()),
            (1000, 700, "UInt16")
        );
        assert_eq!(d.chunk_bytes, 256 * 128 * 3 * 2);
        // Separate planes: one band a chunk.
        let mut planar = entries.to_vec();
        planar.push((284, 3, 1, 2));
        planar[2].3 = tail_at(8);
        let b = tiff_bytes(false, &planar, &[0, 16, 0, 16, 0, 16]);
        assert_eq!(probe(&b, None).unwrap().chunk_bytes, 256 * 128 * 2);
        // Strips of 16 rows of Int32.
        let b = tiff_bytes(
            true,
            &[
                (256, 4, 1, 500),
                (257, 4, 1, 400),
                (258, 3, 1, 32),
                (278, 4, 1, 16),
                (339, 3, 1, 2),
            ],
            &[],
        );
        let d = probe(&b, None).unwrap();
        assert_eq!((d.sample.as_str(), d.chunk_bytes), ("Int32", 500 * 16 * 4));
    }

    #[test]
    fn bigtiff() {
        let mut b = Vec::new();
        b.extend_from_slice(b"II");
        b.extend_from_slice(&43u16.to_le_bytes());
        b.extend_from_slice(&8u16.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&16u64.to_le_bytes());
        b.extend_from_slice(&3u64.to_le_bytes());
        for (tag, kind, value) in [(256u16, 16u16, 70_000u64), (257, 4, 50_000), (258, 3, 32)] {
            b.extend_from_slice(&tag.to_le_bytes());
            b.extend_from_slice(&kind.to_le_bytes());
            b.extend_from_slice(&1u64.to_le_bytes());
            b.extend_from_slice(&value.to_le_bytes());
        }
        let d = probe(&b, None).unwrap();
        assert_eq!(
            (d.width, d.height, d.sample.as_str()),
            (70_000, 50_000, "UInt32")
        );
    }

    #[test]
    fn text_and_hgt() {
        let asc = b"\xEF\xBB\xBFNCOLS 300\nnrows\t200\nxllcorner 0\n";
        let d = probe(asc, Some("x.asc")).unwrap();
        assert_eq!((d.width, d.height, d.chunk_bytes), (300, 200, 0));
        let hgt = vec![0u8; 1201 * 1201 * 2];
        let d = probe(&hgt, Some("N45E006.HGT")).unwrap();
        assert_eq!((d.width, d.height), (1201, 1201));
        // Not a raster at all, a truncated TIFF, a directory past the end.
        assert_eq!(probe(b"hello, world", None), None);
        assert_eq!(probe(b"II*\0", None), None);
        assert_eq!(probe(b"II*\0\xff\0\0\0", None), None);
    }
}
