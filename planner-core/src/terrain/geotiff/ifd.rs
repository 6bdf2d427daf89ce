//! Reading image file directories: a bounds-checked view of a TIFF's
//! bytes (classic and BigTIFF, either byte order), its chain of IFDs and
//! their entries' values, allocating no more than the file's size.

use super::invalid;
use super::tags::{
    IMAGE_LENGTH, IMAGE_WIDTH, NEW_SUBFILE_TYPE, SAMPLES_PER_PIXEL, tag_name, type_size,
};
use crate::terrain::TerrainError;

/// The most entries an IFD may have: libtiff refuses more ("Sanity check
/// on directory count failed"), and so GDAL cannot open such a file.
pub(super) const MAX_IFD_ENTRIES: u64 = 4096;

/// The error for an IFD claiming `n` entries, more than [`MAX_IFD_ENTRIES`].
pub(super) fn too_many_entries(ifd: u64, n: u64) -> TerrainError {
    invalid(format!(
        "the TIFF's image directory at offset {ifd} claims {n} entries, more than the \
         {MAX_IFD_ENTRIES} a TIFF reader accepts: the file is corrupt"
    ))
}

/// One IFD entry: where its `count` values of `typ` are in the file.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry {
    pub(super) tag: u16,
    pub(super) typ: u16,
    pub(super) count: u64,
    /// Absolute offset of the first value.
    pub(super) data: u64,
    /// Absolute offset of the entry itself.
    pub(super) pos: u64,
}

/// The bytes a [`TiffBytes`] sees: the whole file, or the pieces of a
/// file on disk that its header, IFDs and tag values occupy (read by
/// `windows::read_header_pieces`), with the file's length.
#[derive(Clone, Copy)]
pub(super) enum Source<'a> {
    Whole(&'a [u8]),
    /// (offset, bytes) pieces of a file of `len` bytes.
    Pieces {
        pieces: &'a [(u64, Vec<u8>)],
        len: u64,
    },
}

/// A bounds-checked view of a TIFF file's bytes.
#[derive(Clone, Copy)]
pub(super) struct TiffBytes<'a> {
    pub(super) b: Source<'a>,
    pub(super) le: bool,
    pub(super) big: bool,
}

impl<'a> TiffBytes<'a> {
    pub(super) fn slice(&self, off: u64, len: u64) -> Option<&'a [u8]> {
        match self.b {
            Source::Whole(b) => {
                let start = usize::try_from(off).ok()?;
                let end = start.checked_add(usize::try_from(len).ok()?)?;
                b.get(start..end)
            }
            Source::Pieces { pieces, .. } => {
                let end = off.checked_add(len)?;
                pieces.iter().find_map(|(at, piece)| {
                    let piece_end = at.checked_add(piece.len() as u64)?;
                    if *at <= off && end <= piece_end {
                        let start = usize::try_from(off - at).ok()?;
                        piece.get(start..start + usize::try_from(len).ok()?)
                    } else {
                        None
                    }
                })
            }
        }
    }

    /// The file's length in bytes.
    pub(super) fn len(&self) -> u64 {
        match self.b {
            Source::Whole(b) => b.len() as u64,
            Source::Pieces { len, .. } => len,
        }
    }

    pub(super) fn arr<const N: usize>(&self, off: u64) -> Option<[u8; N]> {
        self.slice(off, N as u64)?.try_into().ok()
    }

    pub(super) fn u16(&self, off: u64) -> Option<u16> {
        let a = self.arr::<2>(off)?;
        Some(if self.le {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        })
    }

    pub(super) fn u32(&self, off: u64) -> Option<u32> {
        let a = self.arr::<4>(off)?;
        Some(if self.le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    }

    pub(super) fn u64(&self, off: u64) -> Option<u64> {
        let a = self.arr::<8>(off)?;
        Some(if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        })
    }

    /// An offset field: 4 bytes in classic TIFF, 8 in BigTIFF.
    pub(super) fn offset(&self, off: u64) -> Option<u64> {
        if self.big {
            self.u64(off)
        } else {
            self.u32(off).map(u64::from)
        }
    }

    /// The offset of the first IFD.
    pub(super) fn first_ifd_offset(&self) -> Result<u64, TerrainError> {
        self.offset(if self.big { 8 } else { 4 })
            .ok_or_else(|| invalid("the TIFF header is truncated"))
    }

    /// The number of entries of the IFD at `ifd`, where they start, and
    /// the sizes of an entry and of its inline value; the table (and the
    /// next-IFD pointer after it) checked to lie within the file.
    pub(super) fn ifd_table(&self, ifd: u64) -> Result<(u64, u64, u64, u64), TerrainError> {
        let (n, first, entry_len, inline_len) = if self.big {
            let n = self.u64(ifd).ok_or_else(|| self.ifd_outside(ifd))?;
            (n, ifd.checked_add(8), 20u64, 8u64)
        } else {
            let n = self.u16(ifd).ok_or_else(|| self.ifd_outside(ifd))?;
            (u64::from(n), ifd.checked_add(2), 12u64, 4u64)
        };
        let first = first.ok_or_else(|| self.ifd_outside(ifd))?;
        if n == 0 {
            return Err(invalid(format!(
                "the TIFF's image directory at offset {ifd} is empty"
            )));
        }
        if n > MAX_IFD_ENTRIES {
            return Err(too_many_entries(ifd, n));
        }
        let table_end = n.checked_mul(entry_len).and_then(|l| l.checked_add(first));
        if table_end.is_none_or(|end| end > self.len()) {
            return Err(invalid(format!(
                "the TIFF's image directory ({n} entries at offset {ifd}) runs past the \
                 end of the file ({} bytes): the file is truncated or corrupt",
                self.len()
            )));
        }
        Ok((n, first, entry_len, inline_len))
    }

    /// The offsets of the first `limit` IFDs (or all, if fewer), following
    /// the next-IFD pointers; a loop or a pointer outside the file is an
    /// error.
    pub(super) fn ifd_offsets(&self, limit: usize) -> Result<Vec<u64>, TerrainError> {
        let mut ifd = self.first_ifd_offset()?;
        let mut seen = std::collections::HashSet::new();
        let mut out = Vec::new();
        while out.len() < limit {
            if !seen.insert(ifd) {
                return Err(invalid(format!(
                    "the TIFF's image directories loop back to offset {ifd}: the file is corrupt"
                )));
            }
            out.push(ifd);
            let (n, first, entry_len, _) = self.ifd_table(ifd)?;
            // Within the file's length (checked by `ifd_table`), so no overflow.
            let next = self.offset(first + n * entry_len).ok_or_else(|| {
                invalid(format!(
                    "the TIFF's image directory at offset {ifd} ends without the pointer to \
                     the next one: the file is truncated or corrupt"
                ))
            })?;
            if next == 0 {
                break;
            }
            ifd = next;
        }
        Ok(out)
    }

    /// The entries of the IFD at `ifd`.
    pub(super) fn ifd_entries(&self, ifd: u64) -> Result<Vec<Entry>, TerrainError> {
        let truncated = || invalid("the TIFF header is truncated");
        let (n, first, entry_len, inline_len) = self.ifd_table(ifd)?;
        let mut entries = Vec::new();
        for i in 0..n {
            let e = first + i * entry_len; // within the file, checked above
            let (Some(tag), Some(typ)) = (self.u16(e), self.u16(e + 2)) else {
                return Err(truncated());
            };
            let count = if self.big {
                self.u64(e + 4)
            } else {
                self.u32(e + 4).map(u64::from)
            };
            let Some(count) = count else {
                return Err(truncated());
            };
            let field = e + if self.big { 12 } else { 8 };
            let Some(size) = type_size(typ) else {
                continue;
            };
            let data = match size.checked_mul(count) {
                Some(len) if len <= inline_len => field,
                Some(_) => self.offset(field).ok_or_else(truncated)?,
                None => u64::MAX, // reported if the tag is used
            };
            if !entries.iter().any(|x: &Entry| x.tag == tag) {
                entries.push(Entry {
                    tag,
                    typ,
                    count,
                    data,
                    pos: e,
                });
            }
        }
        Ok(entries)
    }

    pub(super) fn ifd_outside(&self, ifd: u64) -> TerrainError {
        invalid(format!(
            "the TIFF's image directory offset ({ifd}) is outside the file ({} bytes)",
            self.len()
        ))
    }

    /// The raw bytes of an entry's values (all inside the file).
    pub(super) fn raw(&self, e: &Entry) -> Result<&'a [u8], TerrainError> {
        let len = type_size(e.typ).and_then(|s| s.checked_mul(e.count));
        len.and_then(|len| self.slice(e.data, len)).ok_or_else(|| {
            let inside = len
                .and_then(|len| e.data.checked_add(len))
                .is_some_and(|end| end <= self.len());
            if inside {
                // Only pieces of a file on disk are missing a value that
                // lies inside the file: those too large to read.
                return invalid(format!(
                    "the TIFF's {} ({} values) is too large to read",
                    tag_name(e.tag),
                    e.count
                ));
            }
            invalid(format!(
                "the TIFF's {} ({} values) lies outside the file ({} bytes): the file is \
                 truncated or corrupt",
                tag_name(e.tag),
                e.count,
                self.len()
            ))
        })
    }

    /// The values of an integer-typed entry.
    pub(super) fn uints(&self, e: &Entry) -> Result<Vec<u64>, TerrainError> {
        let raw = self.raw(e)?;
        let bad = || {
            invalid(format!(
                "the TIFF's {} has a non-integer type {}",
                tag_name(e.tag),
                e.typ
            ))
        };
        let signed_neg = || {
            invalid(format!(
                "the TIFF's {} holds a negative value",
                tag_name(e.tag)
            ))
        };
        let mut out = Vec::with_capacity(raw.len() / 2);
        match e.typ {
            1 | 7 => out.extend(raw.iter().map(|&b| u64::from(b))),
            6 => {
                for &b in raw {
                    out.push(u64::try_from(b as i8).map_err(|_| signed_neg())?);
                }
            }
            3 | 8 => {
                for c in raw.chunks_exact(2) {
                    let v = self.u16_of(c);
                    if e.typ == 8 && (v as i16) < 0 {
                        return Err(signed_neg());
                    }
                    out.push(u64::from(v));
                }
            }
            4 | 9 | 13 => {
                for c in raw.chunks_exact(4) {
                    let v = self.u32_of(c);
                    if e.typ == 9 && (v as i32) < 0 {
                        return Err(signed_neg());
                    }
                    out.push(u64::from(v));
                }
            }
            16..=18 => {
                for c in raw.chunks_exact(8) {
                    let v = self.u64_of(c);
                    if e.typ == 17 && (v as i64) < 0 {
                        return Err(signed_neg());
                    }
                    out.push(v);
                }
            }
            _ => return Err(bad()),
        }
        Ok(out)
    }

    /// The values of a numeric entry as f64.
    pub(super) fn floats(&self, e: &Entry) -> Result<Vec<f64>, TerrainError> {
        let raw = self.raw(e)?;
        let mut out = Vec::with_capacity(raw.len() / 2);
        match e.typ {
            11 => out.extend(
                raw.chunks_exact(4)
                    .map(|c| f64::from(f32::from_bits(self.u32_of(c)))),
            ),
            12 => out.extend(raw.chunks_exact(8).map(|c| f64::from_bits(self.u64_of(c)))),
            5 | 10 => {
                for c in raw.chunks_exact(8) {
                    let (n, d) = (
                        self.u32_of(c.get(..4).unwrap_or(&[])),
                        self.u32_of(c.get(4..).unwrap_or(&[])),
                    );
                    out.push(if e.typ == 5 {
                        f64::from(n) / f64::from(d)
                    } else {
                        f64::from(n as i32) / f64::from(d as i32)
                    });
                }
            }
            8 => out.extend(
                raw.chunks_exact(2)
                    .map(|c| f64::from(self.u16_of(c) as i16)),
            ),
            9 => out.extend(
                raw.chunks_exact(4)
                    .map(|c| f64::from(self.u32_of(c) as i32)),
            ),
            _ => out.extend(self.uints(e)?.into_iter().map(|v| v as f64)),
        }
        Ok(out)
    }

    /// An ASCII entry's text (up to the first NUL), lossily decoded.
    pub(super) fn ascii(&self, e: &Entry) -> Result<String, TerrainError> {
        let raw = self.raw(e)?;
        Ok(String::from_utf8_lossy(raw).into_owned())
    }

    pub(super) fn u16_of(&self, c: &[u8]) -> u16 {
        let a: [u8; 2] = c.try_into().unwrap_or_default();
        if self.le {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        }
    }

    pub(super) fn u32_of(&self, c: &[u8]) -> u32 {
        let a: [u8; 4] = c.try_into().unwrap_or_default();
        if self.le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        }
    }

    pub(super) fn u64_of(&self, c: &[u8]) -> u64 {
        let a: [u8; 8] = c.try_into().unwrap_or_default();
        if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        }
    }
}

/// The first IFD, with typed accessors.
pub(super) struct Ifd<'a> {
    pub(super) file: TiffBytes<'a>,
    pub(super) entries: Vec<Entry>,
}

impl Ifd<'_> {
    pub(super) fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries.iter().find(|e| e.tag == tag)
    }

    /// The first value of an integer tag, or `default` when absent.
    pub(super) fn uint(&self, tag: u16, default: Option<u64>) -> Result<u64, TerrainError> {
        match self.entry(tag) {
            Some(e) => {
                let v = self.file.uints(e)?;
                v.first()
                    .copied()
                    .ok_or_else(|| invalid(format!("the TIFF's {} is empty", tag_name(tag))))
            }
            None => {
                default.ok_or_else(|| invalid(format!("the TIFF has no {} tag", tag_name(tag))))
            }
        }
    }

    pub(super) fn uints(&self, tag: u16) -> Result<Option<Vec<u64>>, TerrainError> {
        self.entry(tag).map(|e| self.file.uints(e)).transpose()
    }

    pub(super) fn floats(&self, tag: u16) -> Result<Option<Vec<f64>>, TerrainError> {
        self.entry(tag).map(|e| self.file.floats(e)).transpose()
    }

    pub(super) fn ascii(&self, tag: u16) -> Result<Option<String>, TerrainError> {
        self.entry(tag).map(|e| self.file.ascii(e)).transpose()
    }
}

/// A bounds-checked view of `bytes`, with the BigTIFF header checked.
pub(super) fn tiff_bytes(bytes: &[u8]) -> Result<TiffBytes<'_>, TerrainError> {
    let le = bytes.first() == Some(&b'I');
    let big = matches!(bytes.get(2..4), Some(b"+\0" | b"\0+"));
    let file = TiffBytes {
        b: Source::Whole(bytes),
        le,
        big,
    };
    check_bigtiff(file)?;
    Ok(file)
}

/// A bounds-checked view of the `pieces` of a TIFF file of `len` bytes
/// (the first starting at offset 0 with the header).
pub(super) fn tiff_pieces(
    pieces: &[(u64, Vec<u8>)],
    len: u64,
) -> Result<TiffBytes<'_>, TerrainError> {
    let start = pieces
        .iter()
        .find(|(at, _)| *at == 0)
        .map_or(&[][..], |(_, b)| &b[..]);
    let le = start.first() == Some(&b'I');
    let big = matches!(start.get(2..4), Some(b"+\0" | b"\0+"));
    let file = TiffBytes {
        b: Source::Pieces { pieces, len },
        le,
        big,
    };
    check_bigtiff(file)?;
    Ok(file)
}

fn check_bigtiff(file: TiffBytes<'_>) -> Result<(), TerrainError> {
    let big = file.big;
    if big && (file.u16(4) != Some(8) || file.u16(6) != Some(0)) {
        return Err(invalid(
            "the BigTIFF header is corrupt (offset size is not 8)",
        ));
    }
    Ok(())
}

/// A page of a TIFF (an IFD of its main chain; page n is GDAL's
/// `GTIFF_DIR:n`), as far as choosing which to read needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TiffPage {
    pub width: u64,
    pub height: u64,
    /// SamplesPerPixel.
    pub bands: u64,
    /// Not an overview (a reduced-resolution copy of another page) nor a
    /// transparency mask (`NewSubfileType` bits 0 and 2 clear): an image of
    /// its own, which GDAL lists as a subdataset.
    pub full_resolution: bool,
}

/// The first `limit` pages of a TIFF (or all, if fewer).
pub(in crate::terrain) fn pages(bytes: &[u8], limit: usize) -> Result<Vec<TiffPage>, TerrainError> {
    let file = tiff_bytes(bytes)?;
    let mut out = Vec::new();
    for at in file.ifd_offsets(limit)? {
        let ifd = Ifd {
            file,
            entries: file.ifd_entries(at)?,
        };
        out.push(TiffPage {
            width: ifd.uint(IMAGE_WIDTH, None)?,
            height: ifd.uint(IMAGE_LENGTH, None)?,
            bands: ifd.uint(SAMPLES_PER_PIXEL, Some(1))?,
            full_resolution: ifd.uint(NEW_SUBFILE_TYPE, Some(0))? & 0b101 == 0,
        });
    }
    Ok(out)
}
