//! GeoTIFF elevation rasters.
//!
//! The first IFD is parsed here (bounds-checked, allocation bounded by the
//! file size) to check the size limits, the sample layout, the
//! georeferencing (ModelPixelScale + ModelTiepoint or ModelTransformation,
//! PixelIsArea/PixelIsPoint), the GeoKeys' CRS and `GDAL_NODATA` — all before
//! any pixel is allocated. Strips and tiles are then decompressed and
//! un-predicted by the `tiff` crate, one chunk at a time, into `f64`s.
//!
//! The rules follow GDAL's GTiff driver so that values, nodata and corner
//! coordinates equal `gdalinfo`'s / `gdallocationinfo`'s:
//! - a PixelIsPoint raster's transform is shifted by half a pixel up-left
//!   (GDAL's default, `GTIFF_POINT_GEO_IGNORE=NO`);
//! - the nodata text is read like `atof`, then compared in the sample type:
//!   truncated to an integer for integer samples (and ignored when out of the
//!   type's range), rounded to f32 for Float32; NaN samples are always nodata,
//!   and so are infinite ones (GDAL reads them as heights; no ground is
//!   infinitely high, and an infinite height would poison every slope,
//!   mean and hillshade computed over it);
//! - sparse chunks (offset and byte count 0) read as nodata (0 if none).
//!
//! A DEM has one band; `read_geotiff_band` reads one band of a file with
//! several through the same path: PlanarConfiguration 1 chunks hold every
//! band of their pixels (the decoder undoes the predictor across pixels,
//! SamplesPerPixel samples apart), PlanarConfiguration 2 stores band b's
//! chunks after all of band b−1's.

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};

use tiff::TiffError;
use tiff::decoder::{Decoder, DecodingResult, Limits};

use super::read::{c_atof, check_limits, resolve_crs};
use super::{Dem, DemFormat, DemLimits, GeoTransform, TerrainError};

// Baseline and extension tags.
const NEW_SUBFILE_TYPE: u16 = 254;
const IMAGE_WIDTH: u16 = 256;
const IMAGE_LENGTH: u16 = 257;
const BITS_PER_SAMPLE: u16 = 258;
const COMPRESSION: u16 = 259;
const PHOTOMETRIC: u16 = 262;
const STRIP_OFFSETS: u16 = 273;
const SAMPLES_PER_PIXEL: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const STRIP_BYTE_COUNTS: u16 = 279;
const PLANAR_CONFIG: u16 = 284;
const PREDICTOR: u16 = 317;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const TILE_OFFSETS: u16 = 324;
const TILE_BYTE_COUNTS: u16 = 325;
const SAMPLE_FORMAT: u16 = 339;
// GeoTIFF and GDAL tags.
const MODEL_PIXEL_SCALE: u16 = 33550;
const MODEL_TIEPOINT: u16 = 33922;
const MODEL_TRANSFORMATION: u16 = 34264;
const GEO_KEY_DIRECTORY: u16 = 34735;
const GEO_DOUBLE_PARAMS: u16 = 34736;
const GEO_ASCII_PARAMS: u16 = 34737;
const GDAL_NODATA: u16 = 42113;

// GeoKeys.
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const GEOG_GEODETIC_DATUM: u16 = 2050;
const PROJECTED_CS_TYPE: u16 = 3072;
const PROJECTION: u16 = 3074;
const VERTICAL_UNITS: u16 = 4099;

/// GeoKey value "user-defined".
const USER_DEFINED: u16 = 32767;

pub(super) fn is_tiff(bytes: &[u8]) -> bool {
    matches!(
        bytes.get(..4),
        Some(b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+")
    )
}

fn invalid(msg: impl Into<String>) -> TerrainError {
    TerrainError::Invalid(msg.into())
}

fn unsupported(msg: impl Into<String>) -> TerrainError {
    TerrainError::Unsupported(msg.into())
}

fn tag_name(tag: u16) -> String {
    let name = match tag {
        NEW_SUBFILE_TYPE => "NewSubfileType",
        IMAGE_WIDTH => "ImageWidth",
        IMAGE_LENGTH => "ImageLength",
        BITS_PER_SAMPLE => "BitsPerSample",
        COMPRESSION => "Compression",
        PHOTOMETRIC => "PhotometricInterpretation",
        STRIP_OFFSETS => "StripOffsets",
        SAMPLES_PER_PIXEL => "SamplesPerPixel",
        ROWS_PER_STRIP => "RowsPerStrip",
        STRIP_BYTE_COUNTS => "StripByteCounts",
        PLANAR_CONFIG => "PlanarConfiguration",
        PREDICTOR => "Predictor",
        TILE_WIDTH => "TileWidth",
        TILE_LENGTH => "TileLength",
        TILE_OFFSETS => "TileOffsets",
        TILE_BYTE_COUNTS => "TileByteCounts",
        SAMPLE_FORMAT => "SampleFormat",
        MODEL_PIXEL_SCALE => "ModelPixelScale",
        MODEL_TIEPOINT => "ModelTiepoint",
        MODEL_TRANSFORMATION => "ModelTransformation",
        GEO_KEY_DIRECTORY => "GeoKeyDirectory",
        GEO_DOUBLE_PARAMS => "GeoDoubleParams",
        GEO_ASCII_PARAMS => "GeoAsciiParams",
        GDAL_NODATA => "GDAL_NODATA",
        _ => return format!("tag {tag}"),
    };
    format!("{name} ({tag})")
}

/// One IFD entry: where its `count` values of `typ` are in the file.
#[derive(Clone, Copy, Debug)]
struct Entry {
    tag: u16,
    typ: u16,
    count: u64,
    /// Absolute offset of the first value.
    data: u64,
    /// Absolute offset of the entry itself.
    pos: u64,
}

/// Size in bytes of one value of a TIFF field type; `None` for unknown
/// types (such entries are skipped, as the TIFF spec says).
fn type_size(typ: u16) -> Option<u64> {
    Some(match typ {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 | 16 | 17 | 18 => 8,
        _ => return None,
    })
}

/// A bounds-checked view of a TIFF file's bytes.
#[derive(Clone, Copy)]
struct TiffBytes<'a> {
    b: &'a [u8],
    le: bool,
    big: bool,
}

impl<'a> TiffBytes<'a> {
    fn slice(&self, off: u64, len: u64) -> Option<&'a [u8]> {
        let start = usize::try_from(off).ok()?;
        let end = start.checked_add(usize::try_from(len).ok()?)?;
        self.b.get(start..end)
    }

    fn arr<const N: usize>(&self, off: u64) -> Option<[u8; N]> {
        self.slice(off, N as u64)?.try_into().ok()
    }

    fn u16(&self, off: u64) -> Option<u16> {
        let a = self.arr::<2>(off)?;
        Some(if self.le {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        })
    }

    fn u32(&self, off: u64) -> Option<u32> {
        let a = self.arr::<4>(off)?;
        Some(if self.le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    }

    fn u64(&self, off: u64) -> Option<u64> {
        let a = self.arr::<8>(off)?;
        Some(if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        })
    }

    /// An offset field: 4 bytes in classic TIFF, 8 in BigTIFF.
    fn offset(&self, off: u64) -> Option<u64> {
        if self.big {
            self.u64(off)
        } else {
            self.u32(off).map(u64::from)
        }
    }

    /// The offset of the first IFD.
    fn first_ifd_offset(&self) -> Result<u64, TerrainError> {
        self.offset(if self.big { 8 } else { 4 })
            .ok_or_else(|| invalid("the TIFF header is truncated"))
    }

    /// The number of entries of the IFD at `ifd`, where they start, and
    /// the sizes of an entry and of its inline value; the table (and the
    /// next-IFD pointer after it) checked to lie within the file.
    fn ifd_table(&self, ifd: u64) -> Result<(u64, u64, u64, u64), TerrainError> {
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
        let table_end = n.checked_mul(entry_len).and_then(|l| l.checked_add(first));
        if table_end.is_none_or(|end| end > self.b.len() as u64) {
            return Err(invalid(format!(
                "the TIFF's image directory ({n} entries at offset {ifd}) runs past the \
                 end of the file ({} bytes): the file is truncated or corrupt",
                self.b.len()
            )));
        }
        Ok((n, first, entry_len, inline_len))
    }

    /// The offsets of the first `limit` IFDs (or all, if fewer), following
    /// the next-IFD pointers; a loop or a pointer outside the file is an
    /// error.
    fn ifd_offsets(&self, limit: usize) -> Result<Vec<u64>, TerrainError> {
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
    fn ifd_entries(&self, ifd: u64) -> Result<Vec<Entry>, TerrainError> {
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

    fn ifd_outside(&self, ifd: u64) -> TerrainError {
        invalid(format!(
            "the TIFF's image directory offset ({ifd}) is outside the file ({} bytes)",
            self.b.len()
        ))
    }

    /// The raw bytes of an entry's values (all inside the file).
    fn raw(&self, e: &Entry) -> Result<&'a [u8], TerrainError> {
        let len = type_size(e.typ).and_then(|s| s.checked_mul(e.count));
        len.and_then(|len| self.slice(e.data, len)).ok_or_else(|| {
            invalid(format!(
                "the TIFF's {} ({} values) lies outside the file ({} bytes): the file is \
                 truncated or corrupt",
                tag_name(e.tag),
                e.count,
                self.b.len()
            ))
        })
    }

    /// The values of an integer-typed entry.
    fn uints(&self, e: &Entry) -> Result<Vec<u64>, TerrainError> {
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
    fn floats(&self, e: &Entry) -> Result<Vec<f64>, TerrainError> {
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
    fn ascii(&self, e: &Entry) -> Result<String, TerrainError> {
        let raw = self.raw(e)?;
        Ok(String::from_utf8_lossy(raw).into_owned())
    }

    fn u16_of(&self, c: &[u8]) -> u16 {
        let a: [u8; 2] = c.try_into().unwrap_or_default();
        if self.le {
            u16::from_le_bytes(a)
        } else {
            u16::from_be_bytes(a)
        }
    }

    fn u32_of(&self, c: &[u8]) -> u32 {
        let a: [u8; 4] = c.try_into().unwrap_or_default();
        if self.le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        }
    }

    fn u64_of(&self, c: &[u8]) -> u64 {
        let a: [u8; 8] = c.try_into().unwrap_or_default();
        if self.le {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        }
    }
}

/// The first IFD, with typed accessors.
struct Ifd<'a> {
    file: TiffBytes<'a>,
    entries: Vec<Entry>,
}

impl Ifd<'_> {
    fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries.iter().find(|e| e.tag == tag)
    }

    /// The first value of an integer tag, or `default` when absent.
    fn uint(&self, tag: u16, default: Option<u64>) -> Result<u64, TerrainError> {
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

    fn uints(&self, tag: u16) -> Result<Option<Vec<u64>>, TerrainError> {
        self.entry(tag).map(|e| self.file.uints(e)).transpose()
    }

    fn floats(&self, tag: u16) -> Result<Option<Vec<f64>>, TerrainError> {
        self.entry(tag).map(|e| self.file.floats(e)).transpose()
    }

    fn ascii(&self, tag: u16) -> Result<Option<String>, TerrainError> {
        self.entry(tag).map(|e| self.file.ascii(e)).transpose()
    }
}

/// Sample types terraplan reads; each converts exactly to f64.
#[derive(Clone, Copy, Debug, PartialEq)]
enum SampleType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl SampleType {
    fn from_tags(format: u64, bits: u64) -> Result<SampleType, TerrainError> {
        use SampleType::*;
        Ok(match (format, bits) {
            (1, 8) => U8,
            (2, 8) => I8,
            (1, 16) => U16,
            (2, 16) => I16,
            (1, 32) => U32,
            (2, 32) => I32,
            (3, 32) => F32,
            (3, 64) => F64,
            _ => {
                let kind = match format {
                    1 => "unsigned integer",
                    2 => "signed integer",
                    3 => "floating-point",
                    5 => "complex integer",
                    6 => "complex floating-point",
                    4 => "untyped",
                    _ => "unknown-format",
                };
                return Err(unsupported(format!(
                    "{bits}-bit {kind} samples (SampleFormat {format}, BitsPerSample {bits}) \
                     are not supported; a DEM must be Int8/UInt8, Int16/UInt16, Int32/UInt32, \
                     Float32 or Float64"
                )));
            }
        })
    }

    fn bytes(self) -> u64 {
        use SampleType::*;
        match self {
            U8 | I8 => 1,
            U16 | I16 => 2,
            U32 | I32 | F32 => 4,
            F64 => 8,
        }
    }

    /// The range of an integer type.
    fn int_range(self) -> Option<(f64, f64)> {
        use SampleType::*;
        Some(match self {
            U8 => (0.0, 255.0),
            I8 => (-128.0, 127.0),
            U16 => (0.0, 65535.0),
            I16 => (-32768.0, 32767.0),
            U32 => (0.0, 4_294_967_295.0),
            I32 => (-2_147_483_648.0, 2_147_483_647.0),
            F32 | F64 => return None,
        })
    }
}

/// How cells equal to the nodata value are recognised, in the sample type.
#[derive(Clone, Copy, Debug)]
enum NoDataMatch {
    None,
    Int(i64),
    F32(f32),
    F64(f64),
}

impl NoDataMatch {
    fn new(nodata: Option<f64>, st: SampleType) -> NoDataMatch {
        let Some(v) = nodata else {
            return NoDataMatch::None;
        };
        match st {
            SampleType::F32 => NoDataMatch::F32(v as f32),
            SampleType::F64 => NoDataMatch::F64(v),
            _ => match st.int_range() {
                Some((lo, hi)) if v >= lo && v <= hi => NoDataMatch::Int(v.trunc() as i64),
                _ => NoDataMatch::None,
            },
        }
    }

    /// The value of a sparse (absent) chunk's cells.
    fn fill(self) -> f64 {
        match self {
            NoDataMatch::None => 0.0,
            _ => f64::NAN,
        }
    }
}

/// Strips or tiles, with their count along each axis.
#[derive(Clone, Copy, Debug)]
struct ChunkGrid {
    /// Chunk width and height in pixels.
    cw: u64,
    ch: u64,
    across: u64,
    down: u64,
    tiled: bool,
}

impl ChunkGrid {
    fn count(&self) -> u64 {
        self.across * self.down
    }

    fn kind(&self) -> &'static str {
        if self.tiled { "tile" } else { "strip" }
    }
}

/// Everything learnt from the header.
struct Header {
    width: u64,
    height: u64,
    sample: SampleType,
    white_is_zero: bool,
    grid: ChunkGrid,
    /// The band read, as the decoder sees it: samples per pixel in a
    /// decoded chunk (SamplesPerPixel for PlanarConfiguration 1, else 1),
    /// the band's index among them, and the index of its first chunk in
    /// the offsets (PlanarConfiguration 2: band b's chunks follow all of
    /// band b−1's). A single-band raster is (1, 0, 0).
    chunk_samples: usize,
    sample_index: usize,
    /// SamplesPerPixel.
    bands: u64,
    first_chunk: u64,
    /// Rows the decoder produces for a chunk, at most (see `parse_header`).
    decoded_rows: u64,
    offsets: Vec<u64>,
    byte_counts: Vec<u64>,
    transform: GeoTransform,
    crs_code: Result<u32, String>,
    nodata: Option<f64>,
    /// Metres per unit of the heights (VerticalUnitsGeoKey; 1 when absent).
    vertical_scale: f64,
    /// Where the ImageWidth entry is (to widen a tiled image, see `decode`).
    width_entry: Option<u64>,
    le: bool,
    big: bool,
}

/// A bounds-checked view of `bytes`, with the BigTIFF header checked.
fn tiff_bytes(bytes: &[u8]) -> Result<TiffBytes<'_>, TerrainError> {
    let le = bytes.first() == Some(&b'I');
    let big = matches!(bytes.get(2..4), Some(b"+\0" | b"\0+"));
    let file = TiffBytes { b: bytes, le, big };
    if big && (file.u16(4) != Some(8) || file.u16(6) != Some(0)) {
        return Err(invalid(
            "the BigTIFF header is corrupt (offset size is not 8)",
        ));
    }
    Ok(file)
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
pub(super) fn pages(bytes: &[u8], limit: usize) -> Result<Vec<TiffPage>, TerrainError> {
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

/// The header of page `page` (0-based) of a GeoTIFF, for reading band
/// `band` (1-based) of it, or with `None` for reading it as a DEM (which
/// must have a single band).
fn parse_header(
    bytes: &[u8],
    limits: &DemLimits,
    page: usize,
    band: Option<usize>,
) -> Result<Header, TerrainError> {
    let file = tiff_bytes(bytes)?;
    let (le, big) = (file.le, file.big);
    let offsets = file.ifd_offsets(page.saturating_add(1))?;
    let Some(&at) = offsets.get(page) else {
        let n = offsets.len();
        return Err(invalid(format!(
            "page {} does not exist: the TIFF has {n} page{} (image directories), numbered \
             from 1",
            page + 1,
            if n == 1 { "" } else { "s" }
        )));
    };
    let entries = file.ifd_entries(at)?;
    let ifd = Ifd { file, entries };

    // Size first: nothing below allocates more than the file's size.
    let width = ifd.uint(IMAGE_WIDTH, None)?;
    let height = ifd.uint(IMAGE_LENGTH, None)?;
    if width == 0 || height == 0 {
        return Err(invalid(format!(
            "the TIFF's image is {width}×{height} pixels"
        )));
    }
    check_limits(width, height, limits)?;

    let spp = ifd.uint(SAMPLES_PER_PIXEL, Some(1))?;
    let sample_index = match band {
        None if spp != 1 => {
            return Err(unsupported(format!(
                "the TIFF has {spp} samples per pixel (SamplesPerPixel={spp}); a DEM must have a \
                 single band"
            )));
        }
        None => 0,
        Some(_) if spp == 0 || spp > u64::from(u16::MAX) => {
            return Err(invalid(format!("the TIFF's SamplesPerPixel is {spp}")));
        }
        Some(b) if b == 0 || b as u64 > spp => {
            return Err(invalid(format!(
                "band {b} does not exist: the TIFF has {spp} band{} (SamplesPerPixel={spp}), \
                 numbered from 1",
                if spp == 1 { "" } else { "s" }
            )));
        }
        Some(b) => b - 1,
    };
    let bits = ifd.uint(BITS_PER_SAMPLE, Some(1))?;
    let format = ifd.uint(SAMPLE_FORMAT, Some(1))?;
    let sample = SampleType::from_tags(format, bits)?;
    // Several bands: one sample type for all (as libtiff and the decoder
    // require), and the PlanarConfiguration.
    let planar = if spp > 1 {
        let bits_all = ifd.uints(BITS_PER_SAMPLE)?.unwrap_or_default();
        let format_all = ifd.uints(SAMPLE_FORMAT)?.unwrap_or_default();
        if bits_all.len() != 1 && bits_all.len() as u64 != spp {
            return Err(invalid(format!(
                "the TIFF has {spp} samples per pixel but {} BitsPerSample values",
                bits_all.len()
            )));
        }
        if bits_all.iter().any(|&b| b != bits) || format_all.iter().any(|&f| f != format) {
            return Err(unsupported(format!(
                "the TIFF's bands have different sample types (BitsPerSample {bits_all:?}, \
                 SampleFormat {format_all:?}); terraplan reads bands of one type"
            )));
        }
        match ifd.uint(PLANAR_CONFIG, Some(1))? {
            1 => false,
            2 => true,
            p => {
                return Err(invalid(format!(
                    "the TIFF's PlanarConfiguration is {p} (1 or 2 expected)"
                )));
            }
        }
    } else {
        false
    };
    let compression = ifd.uint(COMPRESSION, Some(1))?;
    let compression_name = match compression {
        1 | 5 | 8 | 32946 | 32773 => None,
        2 => Some("CCITT RLE"),
        3 | 4 => Some("CCITT fax"),
        6 | 7 => Some("JPEG"),
        34887 => Some("LERC"),
        34925 => Some("LZMA"),
        50000 => Some("ZSTD"),
        50001 => Some("WebP"),
        50002 => Some("JPEG-XL"),
        _ => Some("unknown"),
    };
    if let Some(name) = compression_name {
        return Err(unsupported(format!(
            "the TIFF uses {name} compression (Compression={compression}); supported are \
             none, LZW, Deflate and PackBits"
        )));
    }
    let predictor = ifd.uint(PREDICTOR, Some(1))?;
    match predictor {
        1 | 2 => {}
        3 if matches!(sample, SampleType::F32 | SampleType::F64) => {}
        3 => {
            return Err(invalid(format!(
                "the TIFF uses the floating-point predictor (Predictor=3) on {sample:?} samples"
            )));
        }
        p => {
            return Err(unsupported(format!(
                "the TIFF uses an unknown predictor (Predictor={p})"
            )));
        }
    }
    let photometric = ifd.uint(PHOTOMETRIC, None).map_err(|_| {
        unsupported("the TIFF has no PhotometricInterpretation tag (MinIsBlack expected)")
    })?;
    let white_is_zero = match photometric {
        1 => false,
        0 if matches!(sample, SampleType::U8 | SampleType::U16 | SampleType::U32) => true,
        p => {
            return Err(unsupported(format!(
                "the TIFF's PhotometricInterpretation is {p} ({}); an elevation raster is \
                 MinIsBlack (1)",
                match p {
                    0 => "WhiteIsZero on signed or float samples",
                    2 => "RGB",
                    3 => "palette colour",
                    4 => "transparency mask",
                    5 => "CMYK",
                    6 => "YCbCr",
                    _ => "not a grey-level image",
                }
            )));
        }
    };

    if white_is_zero && spp > 1 {
        return Err(unsupported(format!(
            "the TIFF's {spp} bands are WhiteIsZero (PhotometricInterpretation=0); terraplan \
             reads several bands only as MinIsBlack (1)"
        )));
    }

    let grid = chunk_grid(&ifd, width, height)?;
    // One decoded chunk (a tile, cut at the bottom) must fit the limits too.
    if grid.tiled && grid.cw.saturating_mul(grid.ch.min(height)) > limits.max_pixels {
        return Err(invalid(format!(
            "the TIFF's {}×{} tiles are larger than the limit of {} pixels",
            grid.cw, grid.ch, limits.max_pixels
        )));
    }
    let (chunk_samples, planes) = if planar { (1, spp) } else { (spp, 1) };
    // The decoder (tiff 0.11.3) cuts the bottom tiles of the first plane
    // only: a later plane's bottom tiles come out whole.
    let decoded_rows = if planar && grid.tiled && sample_index > 0 {
        grid.ch
    } else {
        grid.ch.min(height)
    };
    if spp > 1 {
        // A decoded chunk holds every band of its pixels (PlanarConfiguration
        // 1): it may take at most as many bytes as the Float64 raster read.
        let chunk = grid
            .cw
            .saturating_mul(decoded_rows)
            .saturating_mul(chunk_samples)
            .saturating_mul(sample.bytes());
        let budget = limits.max_pixels.saturating_mul(8);
        if chunk > budget {
            return Err(invalid(format!(
                "the TIFF's {}×{} {}s of {} sample{} of {} bytes take {chunk} bytes decoded, \
                 more than the limit of {budget} ({} pixels × 8 bytes)",
                grid.cw,
                decoded_rows,
                grid.kind(),
                chunk_samples,
                if chunk_samples == 1 { "" } else { "s" },
                sample.bytes(),
                limits.max_pixels
            )));
        }
    }
    let (off_tag, cnt_tag) = if grid.tiled {
        (TILE_OFFSETS, TILE_BYTE_COUNTS)
    } else {
        (STRIP_OFFSETS, STRIP_BYTE_COUNTS)
    };
    let offsets = ifd.uints(off_tag)?.unwrap_or_default();
    let byte_counts = ifd
        .uints(cnt_tag)?
        .ok_or_else(|| invalid(format!("the TIFF has no {} tag", tag_name(cnt_tag))))?;
    let n = grid.count();
    let all = n.saturating_mul(planes);
    if offsets.len() as u64 != all || byte_counts.len() as u64 != all {
        let per_band = if planes > 1 {
            format!(" ({n} for each of its {planes} separate bands)")
        } else {
            String::new()
        };
        return Err(invalid(format!(
            "the TIFF's {width}×{height} image needs {all} {}s{per_band} but {} lists {} and {} \
             lists {}",
            grid.kind(),
            tag_name(off_tag),
            offsets.len(),
            tag_name(cnt_tag),
            byte_counts.len()
        )));
    }
    let len = bytes.len() as u64;
    for (i, (&o, &c)) in offsets.iter().zip(&byte_counts).enumerate() {
        if o.checked_add(c).is_none_or(|end| end > len) {
            return Err(invalid(format!(
                "{} {i} of {all} (offset {o}, {c} bytes) extends past the end of the file \
                 ({len} bytes): the file is truncated",
                grid.kind()
            )));
        }
    }

    let mut transform = georeferencing(&ifd)?;
    let keys = GeoKeys::parse(&ifd)?;
    if keys.as_ref().and_then(|k| k.short(GT_RASTER_TYPE)) == Some(2) {
        shift_pixel_is_point(&mut transform);
    }
    let crs_code = match &keys {
        Some(k) => k.epsg(),
        None => Err("the TIFF has no GeoKeyDirectory tag, so no coordinate system".to_string()),
    };
    let nodata = ifd
        .ascii(GDAL_NODATA)?
        .map(|t| c_atof(t.split('\0').next().unwrap_or("")).0);
    // Heights in feet would be flown as metres: convert them.
    let vertical_scale = match keys.as_ref().and_then(|k| k.short(VERTICAL_UNITS)) {
        None | Some(9001) | Some(USER_DEFINED) => 1.0,
        Some(9002) => 0.3048,
        Some(9003) => 1200.0 / 3937.0,
        Some(u) => {
            return Err(TerrainError::Unsupported(format!(
                "the heights are in unit EPSG:{u} (VerticalUnitsGeoKey); terraplan reads \
                 metres (9001), feet (9002) and US survey feet (9003)"
            )));
        }
    };

    Ok(Header {
        width,
        height,
        sample,
        white_is_zero,
        grid,
        chunk_samples: usize::try_from(chunk_samples)
            .map_err(|_| invalid("the TIFF has too many samples per pixel"))?,
        sample_index: if planar { 0 } else { sample_index },
        bands: spp,
        first_chunk: if planar {
            n.saturating_mul(sample_index as u64)
        } else {
            0
        },
        decoded_rows,
        offsets,
        byte_counts,
        transform,
        crs_code,
        nodata,
        vertical_scale,
        width_entry: ifd.entry(IMAGE_WIDTH).map(|e| e.pos),
        le,
        big,
    })
}

fn chunk_grid(ifd: &Ifd, width: u64, height: u64) -> Result<ChunkGrid, TerrainError> {
    let tiled = ifd.entry(TILE_OFFSETS).is_some();
    if tiled {
        if ifd.entry(STRIP_OFFSETS).is_some() {
            return Err(invalid("the TIFF has both strips and tiles"));
        }
        let tw = ifd.uint(TILE_WIDTH, None)?;
        let th = ifd.uint(TILE_LENGTH, None)?;
        if tw == 0 || th == 0 || tw > u64::from(u32::MAX) || th > u64::from(u32::MAX) {
            return Err(invalid(format!("the TIFF's tiles are {tw}×{th} pixels")));
        }
        Ok(ChunkGrid {
            cw: tw,
            ch: th,
            across: width.div_ceil(tw),
            down: height.div_ceil(th),
            tiled,
        })
    } else {
        if ifd.entry(STRIP_OFFSETS).is_none() {
            return Err(invalid("the TIFF has neither StripOffsets nor TileOffsets"));
        }
        let rps = ifd.uint(ROWS_PER_STRIP, Some(height))?;
        if rps == 0 {
            return Err(invalid("the TIFF's RowsPerStrip is 0"));
        }
        let rps = rps.min(height);
        Ok(ChunkGrid {
            cw: width,
            ch: rps,
            across: 1,
            down: height.div_ceil(rps),
            tiled,
        })
    }
}

/// The affine transform from ModelPixelScale + ModelTiepoint, else
/// ModelTransformation (GDAL's order of preference).
fn georeferencing(ifd: &Ifd) -> Result<GeoTransform, TerrainError> {
    let scale = ifd.floats(MODEL_PIXEL_SCALE)?;
    let tie = ifd.floats(MODEL_TIEPOINT)?;
    let matrix = ifd.floats(MODEL_TRANSFORMATION)?;
    let t = match (&scale, &tie, &matrix) {
        (Some(s), Some(t), _)
            if s.len() >= 2
                && t.len() >= 6
                && s.first().is_some_and(|v| *v != 0.0)
                && s.get(1).is_some_and(|v| *v != 0.0) =>
        {
            let g = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(0.0);
            let pixel_width = g(s, 0);
            let pixel_height = -g(s, 1).abs();
            GeoTransform {
                origin_x: g(t, 3) - g(t, 0) * pixel_width,
                pixel_width,
                row_rotation: 0.0,
                origin_y: g(t, 4) - g(t, 1) * pixel_height,
                col_rotation: 0.0,
                pixel_height,
            }
        }
        (_, _, Some(m)) if m.len() == 16 => {
            let g = |i: usize| m.get(i).copied().unwrap_or(0.0);
            GeoTransform {
                origin_x: g(3),
                pixel_width: g(0),
                row_rotation: g(1),
                origin_y: g(7),
                col_rotation: g(4),
                pixel_height: g(5),
            }
        }
        (_, Some(t), _) if t.len() >= 6 => {
            return Err(unsupported(format!(
                "the TIFF is georeferenced by {} ground control points (ModelTiepoint without \
                 ModelPixelScale), not an affine transform",
                t.len() / 6
            )));
        }
        _ => {
            return Err(invalid(
                "the TIFF has no georeferencing (ModelPixelScale + ModelTiepoint or \
                 ModelTransformation): it is not a GeoTIFF",
            ));
        }
    };
    let all = t.coefficients();
    if !t.is_regular() {
        return Err(invalid(format!(
            "the TIFF's georeferencing is degenerate (transform {all:?})"
        )));
    }
    Ok(t)
}

/// GDAL's half-pixel shift of a PixelIsPoint raster: the tie point is the
/// centre of the first pixel, the transform gives its corner.
fn shift_pixel_is_point(t: &mut GeoTransform) {
    t.origin_x -= t.pixel_width * 0.5 + t.row_rotation * 0.5;
    t.origin_y -= t.col_rotation * 0.5 + t.pixel_height * 0.5;
}

/// A parsed GeoKeyDirectory.
struct GeoKeys {
    shorts: Vec<(u16, u16)>,
}

impl GeoKeys {
    fn parse(ifd: &Ifd) -> Result<Option<GeoKeys>, TerrainError> {
        let Some(dir) = ifd.uints(GEO_KEY_DIRECTORY)? else {
            return Ok(None);
        };
        let bad = || invalid("the TIFF's GeoKeyDirectory is corrupt");
        let n = usize::try_from(*dir.get(3).ok_or_else(bad)?).map_err(|_| bad())?;
        let mut shorts = Vec::new();
        for i in 0..n {
            let k = dir.get(4 + 4 * i..8 + 4 * i).ok_or_else(bad)?;
            let (id, loc, _count, value) = match k {
                [a, b, c, d] => (*a, *b, *c, *d),
                _ => return Err(bad()),
            };
            // Only keys stored in the directory itself matter for the CRS.
            if loc == 0 {
                let (Ok(id), Ok(value)) = (u16::try_from(id), u16::try_from(value)) else {
                    return Err(bad());
                };
                shorts.push((id, value));
            }
        }
        Ok(Some(GeoKeys { shorts }))
    }

    fn short(&self, id: u16) -> Option<u16> {
        self.shorts.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }

    /// The horizontal EPSG code, or why there is none.
    fn epsg(&self) -> Result<u32, String> {
        let pcs = self.short(PROJECTED_CS_TYPE);
        let gcs = self.short(GEOGRAPHIC_TYPE);
        match self.short(GT_MODEL_TYPE) {
            Some(1) => self.projected(),
            Some(2) => self.geographic(),
            Some(3) => Err("the GeoKeys declare a geocentric model (GTModelTypeGeoKey=3)".into()),
            Some(0) | None if pcs.is_some() => self.projected(),
            Some(0) | None if gcs.is_some() => self.geographic(),
            None => Err(
                "the GeoKeys declare no model type, projected or geographic CRS (GDAL reads \
                 such a file as a local engineering CRS)"
                    .into(),
            ),
            Some(m) => Err(format!(
                "the GeoKeys declare an unknown model type (GTModelTypeGeoKey={m})"
            )),
        }
    }

    fn projected(&self) -> Result<u32, String> {
        match self.short(PROJECTED_CS_TYPE) {
            Some(code) if code != USER_DEFINED && code != 0 => Ok(u32::from(code)),
            _ => {
                // User-defined: a UTM zone from ProjectionGeoKey and the datum.
                let Some(proj) = self.short(PROJECTION) else {
                    return Err(
                        "the projected CRS is user-defined (ProjectedCSTypeGeoKey=32767 or \
                         absent) without a ProjectionGeoKey"
                            .into(),
                    );
                };
                let (zone, north) = match proj {
                    16001..=16060 => (proj - 16000, true),
                    16101..=16160 => (proj - 16100, false),
                    _ => {
                        return Err(format!(
                            "the projected CRS is user-defined with ProjectionGeoKey={proj}, \
                             which is not a UTM zone"
                        ));
                    }
                };
                let geog = self.geographic()?;
                let zone = u32::from(zone);
                let code = match (geog, north) {
                    (4326, true) => 32600 + zone,
                    (4326, false) => 32700 + zone,
                    (4322, true) => 32200 + zone,
                    (4322, false) => 32300 + zone,
                    (4269, true) if (1..=23).contains(&zone) => 26900 + zone,
                    (4267, true) if (1..=22).contains(&zone) => 26700 + zone,
                    (4258, true) if (28..=38).contains(&zone) => 25800 + zone,
                    _ => {
                        return Err(format!(
                            "the projected CRS is UTM zone {zone}{} on EPSG:{geog}, which has \
                             no EPSG code terraplan knows",
                            if north { "N" } else { "S" }
                        ));
                    }
                };
                Ok(code)
            }
        }
    }

    fn geographic(&self) -> Result<u32, String> {
        match self.short(GEOGRAPHIC_TYPE) {
            Some(code) if code != USER_DEFINED && code != 0 => Ok(u32::from(code)),
            _ => match self.short(GEOG_GEODETIC_DATUM) {
                Some(6326) => Ok(4326),
                Some(6269) => Ok(4269),
                Some(6267) => Ok(4267),
                Some(6258) => Ok(4258),
                Some(6322) => Ok(4322),
                Some(d) => Err(format!(
                    "the geographic CRS is user-defined with datum {d} (GeogGeodeticDatumGeoKey), \
                     which has no EPSG code terraplan knows"
                )),
                None => Err(
                    "the geographic CRS is user-defined (GeographicTypeGeoKey=32767 or absent) \
                     without a known datum"
                        .into(),
                ),
            },
        }
    }
}

fn tiff_error(e: TiffError) -> TerrainError {
    match e {
        TiffError::UnsupportedError(u) => {
            unsupported(format!("the TIFF uses an unsupported feature: {u}"))
        }
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => invalid(
            format!("the TIFF's image data ends early ({io}): the file is truncated or corrupt"),
        ),
        TiffError::LimitsExceeded => {
            invalid("the TIFF's image data is larger than its header declares")
        }
        other => invalid(format!("the TIFF's image data is corrupt: {other}")),
    }
}

/// Read a single-band GeoTIFF as a DEM (its first page).
pub(super) fn read(
    bytes: &[u8],
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    read_raster(bytes, 0, None, crs, limits)
}

/// Read band `band` (1-based) of page `page` (1-based) of a GeoTIFF with
/// any number of pages and bands.
pub(super) fn read_band(
    bytes: &[u8],
    page: usize,
    band: usize,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    if page == 0 {
        return Err(invalid("page 0 does not exist: pages are numbered from 1"));
    }
    read_raster(bytes, page - 1, Some(band), crs, limits)
}

/// The one reading path: on page `page` (0-based), band `band`
/// (1-based), or with `None` the only band of a single-band page.
fn read_raster(
    bytes: &[u8],
    page: usize,
    band: Option<usize>,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    let h = parse_header(bytes, limits, page, band)?;
    let crs = resolve_crs(h.crs_code.clone(), crs)?;
    let width = usize::try_from(h.width).map_err(|_| invalid("the TIFF is too wide"))?;
    let height = usize::try_from(h.height).map_err(|_| invalid("the TIFF is too high"))?;
    let n = width
        .checked_mul(height)
        .ok_or_else(|| invalid("the TIFF's pixel count overflows"))?;
    let matcher = NoDataMatch::new(h.nodata, h.sample);
    let mut values = crate::buffer::filled(n, 0.0f64);

    let decoded = catch_unwind(AssertUnwindSafe(|| {
        decode(bytes, &h, page, matcher, width, &mut values)
    }));
    match decoded {
        Ok(r) => r?,
        Err(_) => {
            return Err(invalid(
                "the TIFF's image data is corrupt (the decoder failed)",
            ));
        }
    }
    if h.vertical_scale != 1.0 {
        for v in &mut values {
            *v *= h.vertical_scale;
        }
    }
    Ok(Dem {
        width,
        height,
        values,
        nodata: h.nodata,
        transform: h.transform,
        crs,
        format: DemFormat::GeoTiff,
    })
}

/// Decode every chunk into `out` (row-major, `width` wide).
fn decode(
    bytes: &[u8],
    h: &Header,
    page: usize,
    nd: NoDataMatch,
    width: usize,
    out: &mut [f64],
) -> Result<(), TerrainError> {
    // The tiff crate (0.11.3) reads the right-hand tiles of an image whose
    // width is not a multiple of the tile width row by row, and its LZW
    // reader then fails on valid streams ("no lzw end code found" when the
    // last bytes come out of the decoder's buffer after the input is
    // consumed). Declaring the image as wide as its tiles makes every tile a
    // whole-tile read; the padding columns are dropped below.
    let padded_width = if h.grid.tiled {
        h.grid.across * h.grid.cw
    } else {
        h.width
    };
    let widened;
    let bytes = match h.width_entry {
        Some(pos) if padded_width != h.width => {
            widened = widen(bytes, h, pos, padded_width)?;
            &widened[..]
        }
        _ => bytes,
    };
    let mut dec = Decoder::new(Cursor::new(bytes)).map_err(tiff_error)?;
    // Before the limits below, which are sized for the image data: the
    // decoder reads the page's tags (GDAL_METADATA, ...) when it seeks, as
    // it read the first page's in `new`.
    if page > 0 {
        dec.seek_to_image(page).map_err(tiff_error)?;
    }
    let mut limits = Limits::default();
    // The largest decoded chunk: a whole strip or tile (cut at the bottom).
    let chunk_bytes = h
        .grid
        .cw
        .saturating_mul(h.decoded_rows)
        .saturating_mul(h.chunk_samples as u64)
        .saturating_mul(h.sample.bytes());
    limits.decoding_buffer_size = usize::try_from(chunk_bytes).unwrap_or(usize::MAX).max(1);
    limits.intermediate_buffer_size = bytes.len().max(1);
    dec = dec.with_limits(limits);
    let inconsistent = || {
        invalid(format!(
            "the TIFF's image directory {} is inconsistent",
            page + 1
        ))
    };
    let (dw, dh) = dec.dimensions().map_err(tiff_error)?;
    if (u64::from(dw), u64::from(dh)) != (padded_width, h.height) {
        return Err(inconsistent());
    }
    if h.bands > 1 {
        // The decoder parses the IFD itself: it must see the same bands.
        let samples = match dec.colortype().map_err(tiff_error)? {
            tiff::ColorType::Multiband { num_samples, .. } => u64::from(num_samples),
            _ => 0,
        };
        if samples != h.bands {
            return Err(inconsistent());
        }
    }

    let n = h.grid.count();
    for i in 0..n {
        let (cx, cy) = (i % h.grid.across, i / h.grid.across);
        let x0 = cx * h.grid.cw;
        let y0 = cy * h.grid.ch;
        let cw = h.grid.cw.min(h.width - x0);
        let ch = h.grid.ch.min(h.height - y0);
        let (x0, y0, cw, ch) = (x0 as usize, y0 as usize, cw as usize, ch as usize);
        let chunk = h.first_chunk + i;
        let idx = usize::try_from(chunk).map_err(|_| invalid("the TIFF has too many chunks"))?;
        if h.byte_counts.get(idx) == Some(&0) && h.offsets.get(idx) == Some(&0) {
            // Sparse chunk: GDAL reads nodata (or 0).
            for r in 0..ch {
                let start = (y0 + r) * width + x0;
                if let Some(row) = out.get_mut(start..start + cw) {
                    row.fill(nd.fill());
                }
            }
            continue;
        }
        let chunk_index =
            u32::try_from(chunk).map_err(|_| invalid("the TIFF has too many chunks"))?;
        let res = dec.read_chunk(chunk_index).map_err(|e| {
            let e = tiff_error(e);
            invalid(format!("{} {i} of {n}: {e}", h.grid.kind()))
        })?;
        let src_width = if h.grid.tiled { h.grid.cw as usize } else { cw };
        put_chunk(
            res,
            h.white_is_zero,
            nd,
            out,
            width,
            (src_width, h.chunk_samples, h.sample_index),
            x0,
            y0,
            cw,
            ch,
        )
        .map_err(|e| invalid(format!("{} {i} of {n}: {e}", h.grid.kind())))?;
    }
    Ok(())
}

/// A copy of the file whose ImageWidth entry says `new_width` (as a LONG).
fn widen(bytes: &[u8], h: &Header, pos: u64, new_width: u64) -> Result<Vec<u8>, TerrainError> {
    let value = u32::try_from(new_width).map_err(|_| invalid("the TIFF's tiles are too wide"))?;
    let mut b = bytes.to_vec();
    let mut put = |at: u64, data: &[u8]| -> Option<()> {
        let at = usize::try_from(at).ok()?;
        b.get_mut(at..at.checked_add(data.len())?)?
            .copy_from_slice(data);
        Some(())
    };
    let (typ, count, v) = if h.le {
        (4u16.to_le_bytes(), 1u64.to_le_bytes(), value.to_le_bytes())
    } else {
        (4u16.to_be_bytes(), 1u64.to_be_bytes(), value.to_be_bytes())
    };
    let ok = if h.big {
        put(pos + 2, &typ)
            .and_then(|_| put(pos + 4, &count))
            .and_then(|_| put(pos + 12, &[0; 8]))
            .and_then(|_| put(pos + 12, &v))
    } else {
        let count32 = if h.le {
            1u32.to_le_bytes()
        } else {
            1u32.to_be_bytes()
        };
        put(pos + 2, &typ)
            .and_then(|_| put(pos + 4, &count32))
            .and_then(|_| put(pos + 8, &v))
    };
    ok.ok_or_else(|| invalid("the TIFF's ImageWidth entry is outside the file"))?;
    Ok(b)
}

/// Copy sample `sample` of every pixel of one decoded chunk (`cw`×`ch`
/// pixels of `spp` interleaved samples, rows `src_width` pixels apart)
/// into the output.
#[allow(clippy::too_many_arguments)]
fn put_chunk(
    res: DecodingResult,
    white_is_zero: bool,
    nd: NoDataMatch,
    out: &mut [f64],
    width: usize,
    (src_width, spp, sample): (usize, usize, usize),
    x0: usize,
    y0: usize,
    cw: usize,
    ch: usize,
) -> Result<(), String> {
    #[allow(clippy::type_complexity)]
    fn copy<T: Copy>(
        src: &[T],
        out: &mut [f64],
        width: usize,
        (x0, y0, cw, ch, sw, spp, sample): (usize, usize, usize, usize, usize, usize, usize),
        conv: impl Fn(T) -> f64,
    ) -> Result<(), String> {
        let row_len = sw.checked_mul(spp).ok_or("chunk too large")?;
        let need = row_len.checked_mul(ch).ok_or("chunk too large")?;
        if src.len() < need || sw < cw || sample >= spp {
            return Err(format!("decoded {} samples, expected {need}", src.len()));
        }
        for r in 0..ch {
            let s = src
                .get(r * row_len..r * row_len + cw * spp)
                .ok_or("chunk row out of range")?;
            let start = (y0 + r) * width + x0;
            let d = out
                .get_mut(start..start + cw)
                .ok_or("chunk outside the image")?;
            if spp == 1 {
                for (d, &s) in d.iter_mut().zip(s) {
                    *d = conv(s);
                }
            } else {
                for (d, &s) in d.iter_mut().zip(s.iter().skip(sample).step_by(spp)) {
                    *d = conv(s);
                }
            }
        }
        Ok(())
    }
    let area = (x0, y0, cw, ch, src_width, spp, sample);
    let int = move |v: i64| -> f64 {
        match nd {
            NoDataMatch::Int(n) if n == v => f64::NAN,
            _ => v as f64,
        }
    };
    match res {
        DecodingResult::U8(v) => copy(&v, out, width, area, |x: u8| {
            int(i64::from(if white_is_zero { !x } else { x }))
        }),
        DecodingResult::I8(v) => copy(&v, out, width, area, |x: i8| int(i64::from(x))),
        DecodingResult::U16(v) => copy(&v, out, width, area, |x: u16| {
            int(i64::from(if white_is_zero { !x } else { x }))
        }),
        DecodingResult::I16(v) => copy(&v, out, width, area, |x: i16| int(i64::from(x))),
        DecodingResult::U32(v) => copy(&v, out, width, area, |x: u32| {
            int(i64::from(if white_is_zero { !x } else { x }))
        }),
        DecodingResult::I32(v) => copy(&v, out, width, area, |x: i32| int(i64::from(x))),
        DecodingResult::F32(v) => copy(&v, out, width, area, |x: f32| match nd {
            _ if !x.is_finite() => f64::NAN,
            NoDataMatch::F32(n) if n == x => f64::NAN,
            _ => f64::from(x),
        }),
        DecodingResult::F64(v) => copy(&v, out, width, area, |x: f64| match nd {
            _ if !x.is_finite() => f64::NAN,
            NoDataMatch::F64(n) if n == x => f64::NAN,
            _ => x,
        }),
        _ => Err("the decoder returned an unexpected sample type".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::read_dem;
    use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
    use tiff::tags::{Predictor, Tag};

    /// A tag value for the hand-made TIFFs.
    #[derive(Clone, Debug)]
    enum V {
        Short(Vec<u16>),
        Long(Vec<u32>),
        Double(Vec<f64>),
        Ascii(&'static str),
        /// A raw entry: type, count, value bytes (as stored).
        Raw(u16, u64, Vec<u8>),
    }

    /// Writes a one-IFD TIFF by hand: header, chunks, tag data, IFD.
    /// StripOffsets/TileOffsets and the byte counts are added from `chunks`
    /// (tiled if `tiled`).
    struct Builder {
        le: bool,
        big: bool,
        tags: Vec<(u16, V)>,
        chunks: Vec<Vec<u8>>,
        tiled: bool,
    }

    impl Builder {
        fn new() -> Builder {
            Builder {
                le: true,
                big: false,
                tags: Vec::new(),
                chunks: Vec::new(),
                tiled: false,
            }
        }

        fn tag(mut self, tag: u16, v: V) -> Builder {
            self.tags.retain(|(t, _)| *t != tag);
            self.tags.push((tag, v));
            self
        }

        /// A north-up single-band image with the usual tags.
        fn image(width: u32, height: u32, format: u16, bits: u16) -> Builder {
            Builder::new()
                .tag(IMAGE_WIDTH, V::Long(vec![width]))
                .tag(IMAGE_LENGTH, V::Long(vec![height]))
                .tag(BITS_PER_SAMPLE, V::Short(vec![bits]))
                .tag(COMPRESSION, V::Short(vec![1]))
                .tag(PHOTOMETRIC, V::Short(vec![1]))
                .tag(SAMPLES_PER_PIXEL, V::Short(vec![1]))
                .tag(SAMPLE_FORMAT, V::Short(vec![format]))
                .tag(MODEL_PIXEL_SCALE, V::Double(vec![10.0, 10.0, 0.0]))
                .tag(
                    MODEL_TIEPOINT,
                    V::Double(vec![0.0, 0.0, 0.0, 500000.0, 4000000.0, 0.0]),
                )
                .tag(
                    GEO_KEY_DIRECTORY,
                    V::Short(geokeys(&[(1024, 1), (1025, 1), (3072, 32633)])),
                )
        }

        fn strips(mut self, rows_per_strip: u32, chunks: Vec<Vec<u8>>) -> Builder {
            self.chunks = chunks;
            self.tiled = false;
            self.tag(ROWS_PER_STRIP, V::Long(vec![rows_per_strip]))
        }

        fn tiles(mut self, tw: u32, th: u32, chunks: Vec<Vec<u8>>) -> Builder {
            self.chunks = chunks;
            self.tiled = true;
            self.tag(TILE_WIDTH, V::Long(vec![tw]))
                .tag(TILE_LENGTH, V::Long(vec![th]))
        }

        fn u16b(&self, v: u16) -> [u8; 2] {
            if self.le {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            }
        }
        fn u32b(&self, v: u32) -> [u8; 4] {
            if self.le {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            }
        }
        fn u64b(&self, v: u64) -> [u8; 8] {
            if self.le {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            }
        }

        fn encode(&self, v: &V) -> (u16, u64, Vec<u8>) {
            match v {
                V::Short(s) => (
                    3,
                    s.len() as u64,
                    s.iter().flat_map(|x| self.u16b(*x)).collect(),
                ),
                V::Long(s) => (
                    4,
                    s.len() as u64,
                    s.iter().flat_map(|x| self.u32b(*x)).collect(),
                ),
                V::Double(s) => (
                    12,
                    s.len() as u64,
                    s.iter().flat_map(|x| self.u64b(x.to_bits())).collect(),
                ),
                V::Ascii(s) => {
                    let mut b = s.as_bytes().to_vec();
                    b.push(0);
                    (2, b.len() as u64, b)
                }
                V::Raw(t, c, b) => (*t, *c, b.clone()),
            }
        }

        fn build(&self) -> Vec<u8> {
            let mut out = Vec::new();
            if self.le {
                out.extend(b"II")
            } else {
                out.extend(b"MM")
            }
            if self.big {
                out.extend(self.u16b(43));
                out.extend(self.u16b(8));
                out.extend(self.u16b(0));
                out.extend(self.u64b(0)); // patched below
            } else {
                out.extend(self.u16b(42));
                out.extend(self.u32b(0));
            }
            let mut offsets = Vec::new();
            for c in &self.chunks {
                offsets.push(out.len() as u32);
                out.extend(c);
            }
            let mut tags = self.tags.clone();
            let (ot, ct) = if self.tiled {
                (TILE_OFFSETS, TILE_BYTE_COUNTS)
            } else {
                (STRIP_OFFSETS, STRIP_BYTE_COUNTS)
            };
            if !tags.iter().any(|(t, _)| *t == ot) {
                tags.push((ot, V::Long(offsets)));
            }
            if !tags.iter().any(|(t, _)| *t == ct) {
                tags.push((
                    ct,
                    V::Long(self.chunks.iter().map(|c| c.len() as u32).collect()),
                ));
            }
            tags.sort_by_key(|(t, _)| *t);
            // Out-of-line values.
            let inline = if self.big { 8 } else { 4 };
            let mut fields = Vec::new();
            for (tag, v) in &tags {
                let (typ, count, bytes) = self.encode(v);
                if bytes.len() > inline {
                    if out.len() % 2 == 1 {
                        out.push(0);
                    }
                    let off = out.len() as u64;
                    out.extend(&bytes);
                    let field = if self.big {
                        self.u64b(off).to_vec()
                    } else {
                        self.u32b(off as u32).to_vec()
                    };
                    fields.push((*tag, typ, count, field));
                } else {
                    let mut field = bytes.clone();
                    field.resize(inline, 0);
                    fields.push((*tag, typ, count, field));
                }
            }
            if out.len() % 2 == 1 {
                out.push(0);
            }
            let ifd = out.len() as u64;
            if self.big {
                out.extend(self.u64b(fields.len() as u64));
            } else {
                out.extend(self.u16b(fields.len() as u16));
            }
            for (tag, typ, count, field) in fields {
                out.extend(self.u16b(tag));
                out.extend(self.u16b(typ));
                if self.big {
                    out.extend(self.u64b(count));
                } else {
                    out.extend(self.u32b(count as u32));
                }
                out.extend(field);
            }
            if self.big {
                out.extend(self.u64b(0));
                let b = self.u64b(ifd);
                out[8..16].copy_from_slice(&b);
            } else {
                out.extend(self.u32b(0));
                let b = self.u32b(ifd as u32);
                out[4..8].copy_from_slice(&b);
            }
            out
        }
    }

    fn geokeys(keys: &[(u16, u16)]) -> Vec<u16> {
        let mut v = vec![1, 1, 0, keys.len() as u16];
        for (k, val) in keys {
            v.extend([*k, 0, 1, *val]);
        }
        v
    }

    fn i16_le(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    /// The GeoTIFF reader itself (`read_dem` adds format detection and a
    /// degrees check that these synthetic rasters need not pass).
    fn read(bytes: &[u8]) -> Result<Dem, TerrainError> {
        assert!(is_tiff(bytes));
        super::read(bytes, None, &DemLimits::default())
    }

    #[test]
    fn int16_strips_with_nodata() {
        // 3×3, two strips (2 rows + 1 row).
        let b = Builder::image(3, 3, 2, 16)
            .tag(GDAL_NODATA, V::Ascii("-9999"))
            .strips(
                2,
                vec![i16_le(&[1, 2, 3, -9999, 5, 6]), i16_le(&[7, 8, -32768])],
            )
            .build();
        let dem = read(&b).unwrap();
        assert_eq!((dem.width, dem.height), (3, 3));
        assert_eq!(dem.crs.epsg, 32633);
        assert_eq!(dem.format, DemFormat::GeoTiff);
        assert_eq!(dem.nodata, Some(-9999.0));
        assert_eq!(dem.value(0, 0), Some(1.0));
        assert_eq!(dem.value(0, 1), None);
        assert_eq!(dem.value(2, 2), Some(-32768.0));
        let t = dem.transform;
        assert_eq!(
            (t.origin_x, t.origin_y, t.pixel_width, t.pixel_height),
            (500000.0, 4000000.0, 10.0, -10.0)
        );
    }

    #[test]
    fn big_endian_float32_pixel_is_point_nan_nodata() {
        let mut bld = Builder::image(2, 2, 3, 32)
            .tag(GDAL_NODATA, V::Ascii("nan"))
            .tag(MODEL_PIXEL_SCALE, V::Double(vec![0.5, 0.25, 0.0]))
            .tag(
                MODEL_TIEPOINT,
                V::Double(vec![0.0, 0.0, 0.0, 5.0, 46.0, 0.0]),
            )
            .tag(
                GEO_KEY_DIRECTORY,
                V::Short(geokeys(&[(1024, 2), (1025, 2), (2048, 4326)])),
            );
        bld.le = false;
        let px: Vec<u8> = [1.5f32, f32::NAN, -3.25, 1e30]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        let b = bld.strips(2, vec![px]).build();
        let dem = read(&b).unwrap();
        assert_eq!(dem.crs.epsg, 4326);
        assert_eq!(dem.values[0], 1.5);
        assert!(dem.values[1].is_nan());
        assert_eq!(dem.values[2], -3.25);
        assert_eq!(dem.values[3], f64::from(1e30f32));
        assert!(dem.nodata.unwrap().is_nan());
        let t = dem.transform;
        assert_eq!((t.origin_x, t.origin_y), (4.75, 46.125));
    }

    /// Infinite samples are nodata, in Float32 and Float64 alike; an
    /// all-infinite raster has no height at all, as an all-nodata one.
    #[test]
    fn infinite_samples_are_nodata() {
        let px: Vec<u8> = [f32::INFINITY, 2.5, f32::NEG_INFINITY, f32::MAX]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let dem = read(&Builder::image(2, 2, 3, 32).strips(2, vec![px]).build()).unwrap();
        assert!(dem.values[0].is_nan() && dem.values[2].is_nan());
        assert_eq!(dem.values[1], 2.5);
        assert_eq!(dem.values[3], f64::from(f32::MAX), "finite, however high");
        let px: Vec<u8> = [f64::INFINITY, -1.0, f64::NEG_INFINITY, 1e300]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let dem = read(&Builder::image(2, 2, 3, 64).strips(2, vec![px]).build()).unwrap();
        assert!(dem.values[0].is_nan() && dem.values[2].is_nan());
        assert_eq!((dem.values[1], dem.values[3]), (-1.0, 1e300));
        let px: Vec<u8> = [f32::INFINITY; 4]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let dem = read(&Builder::image(2, 2, 3, 32).strips(2, vec![px]).build()).unwrap();
        let info = dem.info().unwrap();
        assert_eq!(
            (info.min, info.max, info.nodata_fraction),
            (None, None, 1.0)
        );
    }

    #[test]
    fn bigtiff_tiles_with_padding_and_rotation() {
        // 20×18 UInt16 in 16×16 tiles (2×2 tiles, padded), BigTIFF.
        let (w, h) = (20usize, 18usize);
        let value = |x: usize, y: usize| (y * 100 + x) as u16;
        let mut chunks = Vec::new();
        for ty in 0..2 {
            for tx in 0..2 {
                let mut c = Vec::new();
                for y in 0..16 {
                    for x in 0..16 {
                        let (gx, gy) = (tx * 16 + x, ty * 16 + y);
                        let v = if gx < w && gy < h {
                            value(gx, gy)
                        } else {
                            0xABCD
                        };
                        c.extend(v.to_le_bytes());
                    }
                }
                chunks.push(c);
            }
        }
        let mut bld = Builder::image(w as u32, h as u32, 1, 16)
            .tag(MODEL_PIXEL_SCALE, V::Double(vec![]))
            .tag(MODEL_TIEPOINT, V::Double(vec![]))
            .tag(
                MODEL_TRANSFORMATION,
                V::Double(vec![
                    3.0, 4.0, 0.0, 1000.0, 4.0, -3.0, 0.0, 2000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                    0.0, 1.0,
                ]),
            )
            .tiles(16, 16, chunks);
        bld.tags
            .retain(|(t, _)| *t != MODEL_PIXEL_SCALE && *t != MODEL_TIEPOINT);
        bld.big = true;
        let dem = read(&bld.build()).unwrap();
        for y in 0..h {
            for x in 0..w {
                assert_eq!(dem.value(x, y), Some(f64::from(value(x, y))), "({x},{y})");
            }
        }
        let t = dem.transform;
        assert_eq!(
            (
                t.origin_x,
                t.pixel_width,
                t.row_rotation,
                t.origin_y,
                t.col_rotation,
                t.pixel_height
            ),
            (1000.0, 3.0, 4.0, 2000.0, 4.0, -3.0)
        );
    }

    #[test]
    fn compressed_tiles_with_padding() {
        use tiff::encoder::compression::{CompressionAlgorithm, Deflate, Lzw, Packbits};
        // 20×18 Int16 in 16×16 tiles: the right and bottom tiles are padded
        // with zeros, which compress to a long run at the end of the stream.
        let (w, h) = (20usize, 18usize);
        let value = |x: usize, y: usize| (y * 100 + x) as i16 - 700;
        for method in [5u16, 8, 32773] {
            for predictor in [1u16, 2] {
                let mut chunks = Vec::new();
                for ty in 0..2 {
                    for tx in 0..2 {
                        let mut raw: Vec<i16> = Vec::new();
                        for y in 0..16 {
                            for x in 0..16 {
                                let (gx, gy) = (tx * 16 + x, ty * 16 + y);
                                raw.push(if gx < w && gy < h { value(gx, gy) } else { 0 });
                            }
                        }
                        if predictor == 2 {
                            for row in raw.chunks_mut(16) {
                                for i in (1..16).rev() {
                                    row[i] = row[i].wrapping_sub(row[i - 1]);
                                }
                            }
                        }
                        let bytes: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
                        let mut out = Vec::new();
                        match method {
                            5 => Lzw.write_to(&mut out, &bytes),
                            8 => Deflate::default().write_to(&mut out, &bytes),
                            _ => Packbits.write_to(&mut out, &bytes),
                        }
                        .unwrap();
                        chunks.push(out);
                    }
                }
                let b = Builder::image(w as u32, h as u32, 2, 16)
                    .tag(COMPRESSION, V::Short(vec![method]))
                    .tag(PREDICTOR, V::Short(vec![predictor]))
                    .tiles(16, 16, chunks)
                    .build();
                let dem = read(&b)
                    .unwrap_or_else(|e| panic!("compression {method} predictor {predictor}: {e}"));
                for y in 0..h {
                    for x in 0..w {
                        assert_eq!(dem.value(x, y), Some(f64::from(value(x, y))), "({x},{y})");
                    }
                }
            }
        }
    }

    #[test]
    fn tiles_larger_than_the_image() {
        use tiff::encoder::compression::{CompressionAlgorithm, Lzw};
        // A 3×2 image in one 64×32 LZW tile (zero padding).
        let mut raw = vec![0i16; 64 * 32];
        raw[..3].copy_from_slice(&[1, 2, 3]);
        raw[64..67].copy_from_slice(&[4, 5, 6]);
        let bytes: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut tile = Vec::new();
        Lzw.write_to(&mut tile, &bytes).unwrap();
        let b = Builder::image(3, 2, 2, 16)
            .tag(COMPRESSION, V::Short(vec![5]))
            .tiles(64, 32, vec![tile])
            .build();
        assert_eq!(read(&b).unwrap().values, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // Tiles far larger than the image: their data is missing here...
        let b = Builder::image(3, 2, 2, 16)
            .tiles(65536, 65536, vec![vec![0; 16]])
            .build();
        let e = read(&b).unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
        // ...and a decoded tile must fit the limits.
        let small = DemLimits {
            max_pixels: 1000,
            max_side: 100,
        };
        let b = Builder::image(3, 2, 2, 16)
            .tiles(4096, 16, vec![vec![0; 16]])
            .build();
        let e = read_dem(&b, None, None, &small).unwrap_err();
        assert!(e.to_string().contains("4096×16 tiles"), "{e}");
    }

    #[test]
    fn sparse_chunk_reads_as_nodata() {
        let b = Builder::image(2, 2, 2, 16)
            .tag(GDAL_NODATA, V::Ascii("-1"))
            .strips(1, vec![i16_le(&[4, 5]), vec![]])
            .tag(STRIP_OFFSETS, V::Long(vec![8, 0]))
            .build();
        let dem = read(&b).unwrap();
        assert_eq!(dem.value(0, 0), Some(4.0));
        assert_eq!(dem.value(1, 0), Some(5.0));
        assert_eq!((dem.value(0, 1), dem.value(1, 1)), (None, None));
    }

    #[test]
    fn nodata_compared_in_the_sample_type() {
        // Integer samples: the nodata value is truncated (GDAL: 1.5 masks 1).
        let b = Builder::image(3, 1, 2, 16)
            .tag(GDAL_NODATA, V::Ascii("1.5"))
            .strips(1, vec![i16_le(&[1, 2, 3])])
            .build();
        let v = read(&b).unwrap().values;
        assert!(v[0].is_nan() && v[1..] == [2.0, 3.0]);
        // Out of the type's range: nothing is nodata.
        let b = Builder::image(2, 1, 1, 16)
            .tag(GDAL_NODATA, V::Ascii("-1"))
            .strips(
                1,
                vec![[65535u16, 0].iter().flat_map(|x| x.to_le_bytes()).collect()],
            )
            .build();
        assert_eq!(read(&b).unwrap().values, vec![65535.0, 0.0]);
        // Float32: compared as f32 (GDAL writes -FLT_MAX as this text).
        let px: Vec<u8> = [-f32::MAX, 0.1f32]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let b = Builder::image(2, 1, 3, 32)
            .tag(GDAL_NODATA, V::Ascii("-3.4028234663852886e+38"))
            .strips(1, vec![px])
            .build();
        let v = read(&b).unwrap().values;
        assert!(v[0].is_nan());
        assert_eq!(v[1], f64::from(0.1f32));
        // Float64 with "0.1" exactly.
        let px: Vec<u8> = [0.1f64, 0.2].iter().flat_map(|x| x.to_le_bytes()).collect();
        let b = Builder::image(2, 1, 3, 64)
            .tag(GDAL_NODATA, V::Ascii("0.1"))
            .strips(1, vec![px])
            .build();
        let v = read(&b).unwrap().values;
        assert!(v[0].is_nan() && v[1] == 0.2);
    }

    #[test]
    fn other_sample_types() {
        for (format, bits, px, want) in [
            (1u16, 8u16, vec![200u8, 7], vec![200.0, 7.0]),
            (2, 8, vec![0xFF, 7], vec![-1.0, 7.0]),
            (
                2,
                32,
                [-70000i32, 5]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect(),
                vec![-70000.0, 5.0],
            ),
            (
                1,
                32,
                [4_000_000_000u32, 5]
                    .iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect(),
                vec![4e9, 5.0],
            ),
        ] {
            let b = Builder::image(2, 1, format, bits)
                .strips(1, vec![px])
                .build();
            assert_eq!(
                read(&b).unwrap().values,
                want,
                "format {format} bits {bits}"
            );
        }
    }

    /// A GeoTIFF written by the tiff crate's encoder (compressed strips).
    fn encoded(compression: Compression, predictor: Predictor, big: bool) -> Vec<u8> {
        let (w, h) = (37u32, 23u32);
        let data: Vec<i16> = (0..w * h).map(|i| ((i * 37) % 1000) as i16 - 300).collect();
        let mut cur = std::io::Cursor::new(Vec::new());
        macro_rules! write {
            ($enc:expr) => {{
                let mut enc = $enc.with_compression(compression).with_predictor(predictor);
                let mut img = enc.new_image::<colortype::GrayI16>(w, h).unwrap();
                let d = img.encoder();
                d.write_tag(Tag::Unknown(MODEL_PIXEL_SCALE), &[2.0f64, 2.0, 0.0][..])
                    .unwrap();
                d.write_tag(
                    Tag::Unknown(MODEL_TIEPOINT),
                    &[0.0f64, 0.0, 0.0, 100.0, 200.0, 0.0][..],
                )
                .unwrap();
                d.write_tag(
                    Tag::Unknown(GEO_KEY_DIRECTORY),
                    &geokeys(&[(1024, 2), (2048, 4326)])[..],
                )
                .unwrap();
                d.write_tag(Tag::Unknown(GDAL_NODATA), "-300").unwrap();
                img.rows_per_strip(5).unwrap();
                img.write_data(&data).unwrap();
            }};
        }
        if big {
            write!(TiffEncoder::new_big(&mut cur).unwrap());
        } else {
            write!(TiffEncoder::new(&mut cur).unwrap());
        }
        cur.into_inner()
    }

    #[test]
    fn compressed_strips_and_predictor() {
        let want: Vec<f64> = (0..37u32 * 23)
            .map(|i| ((i * 37) % 1000) as f64 - 300.0)
            .map(|v| if v == -300.0 { f64::NAN } else { v })
            .collect();
        for compression in [
            Compression::Uncompressed,
            Compression::Lzw,
            Compression::Deflate(DeflateLevel::default()),
            Compression::Packbits,
        ] {
            for predictor in [Predictor::None, Predictor::Horizontal] {
                for big in [false, true] {
                    let b = encoded(compression, predictor, big);
                    let dem = read(&b).unwrap_or_else(|e| panic!("{e}"));
                    assert_eq!(dem.crs.epsg, 4326);
                    assert_eq!(dem.values.len(), want.len());
                    for (a, b) in dem.values.iter().zip(&want) {
                        assert!(a == b || (a.is_nan() && b.is_nan()));
                    }
                }
            }
        }
    }

    #[test]
    fn every_truncation_is_an_error_not_a_panic() {
        let full = encoded(Compression::Lzw, Predictor::Horizontal, false);
        for len in 0..full.len() {
            let r = read_dem(&full[..len], None, None, &DemLimits::default());
            assert!(r.is_err(), "prefix of {len} bytes read");
        }
        // Strips before the IFD: cutting into them is "truncated".
        let b = Builder::image(3, 3, 2, 16)
            .strips(3, vec![i16_le(&[1, 2, 3, 4, 5, 6, 7, 8, 9])])
            .tag(STRIP_BYTE_COUNTS, V::Long(vec![1000]))
            .build();
        let e = read(&b).unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
    }

    #[test]
    fn huge_header_is_too_large_fast() {
        let b = Builder::image(1_000_000, 1_000_000, 2, 16)
            .strips(1, vec![])
            .tag(STRIP_OFFSETS, V::Long(vec![8]))
            .tag(STRIP_BYTE_COUNTS, V::Long(vec![2]))
            .build();
        assert!(b.len() < 400, "{}", b.len());
        let t = std::time::Instant::now();
        let e = read(&b).unwrap_err();
        assert!(
            matches!(
                e,
                TerrainError::TooLarge {
                    width: 1_000_000,
                    height: 1_000_000,
                    ..
                }
            ),
            "{e}"
        );
        assert!(t.elapsed().as_millis() < 200);
        let small = DemLimits {
            max_pixels: 4,
            max_side: 100,
        };
        let b = Builder::image(3, 3, 2, 16)
            .strips(3, vec![i16_le(&[0; 9])])
            .build();
        assert!(matches!(
            read_dem(&b, None, None, &small),
            Err(TerrainError::TooLarge { .. })
        ));
    }

    #[test]
    fn crs_from_geokeys() {
        let with = |keys: &[(u16, u16)]| {
            let b = Builder::image(1, 1, 2, 16)
                .tag(GEO_KEY_DIRECTORY, V::Short(geokeys(keys)))
                .strips(1, vec![i16_le(&[1])])
                .build();
            read(&b)
        };
        // Heights in feet are converted to metres; other units are refused.
        let feet = with(&[(1024, 1), (3072, 32616), (4099, 9002)]).unwrap();
        assert!((feet.values[0] - 0.3048).abs() < 1e-15);
        let survey_feet = with(&[(1024, 1), (3072, 32616), (4099, 9003)]).unwrap();
        assert!((survey_feet.values[0] - 1200.0 / 3937.0).abs() < 1e-15);
        assert_eq!(
            with(&[(1024, 1), (3072, 32616), (4099, 9001)])
                .unwrap()
                .values[0],
            1.0
        );
        assert!(matches!(
            with(&[(1024, 1), (3072, 32616), (4099, 9036)]),
            Err(TerrainError::Unsupported(_))
        ));
        // Compound: projected + vertical → the horizontal code.
        assert_eq!(
            with(&[(1024, 1), (1025, 1), (3072, 32616), (4096, 3855)])
                .unwrap()
                .crs
                .epsg,
            32616
        );
        // User-defined projected: UTM zone from ProjectionGeoKey and the datum.
        assert_eq!(
            with(&[(1024, 1), (2048, 4326), (3072, 32767), (3074, 16016)])
                .unwrap()
                .crs
                .epsg,
            32616
        );
        assert_eq!(
            with(&[(1024, 1), (2048, 4269), (3072, 32767), (3074, 16016)])
                .unwrap()
                .crs
                .epsg,
            26916
        );
        assert_eq!(
            with(&[(1024, 1), (2048, 32767), (2050, 6326), (3074, 16133)])
                .unwrap()
                .crs
                .epsg,
            32733
        );
        // Geographic, also without a model type.
        assert_eq!(with(&[(1024, 2), (2048, 4258)]).unwrap().crs.epsg, 4258);
        assert_eq!(with(&[(2048, 4326)]).unwrap().crs.epsg, 4326);
        for keys in [
            &[(1025u16, 2u16)][..],      // whitebox: no CRS at all
            &[(1024, 3)],                // geocentric
            &[(1024, 1), (3072, 32767)], // user-defined, no projection
            &[(1024, 1), (3072, 32767), (3074, 12345), (2048, 4326)],
            &[(1024, 1), (3072, 60000)], // not an EPSG CRS
            &[(1024, 2), (2048, 32767), (2050, 6999)],
        ] {
            let e = with(keys).unwrap_err();
            assert!(matches!(e, TerrainError::UnknownCrs(_)), "{keys:?}: {e}");
        }
        // No GeoKeyDirectory: unknown CRS, unless given.
        let mut bld = Builder::image(1, 1, 2, 16).strips(1, vec![i16_le(&[1])]);
        bld.tags.retain(|(t, _)| *t != GEO_KEY_DIRECTORY);
        let b = bld.build();
        assert!(matches!(read(&b), Err(TerrainError::UnknownCrs(_))));
        assert_eq!(
            read_dem(&b, None, Some(32613), &DemLimits::default())
                .unwrap()
                .crs
                .epsg,
            32613
        );
        assert!(matches!(
            read_dem(&b, None, Some(5773), &DemLimits::default()),
            Err(TerrainError::Crs(_))
        ));
    }

    #[test]
    fn unsupported_and_invalid_layouts() {
        let base = || Builder::image(2, 1, 2, 16).strips(1, vec![i16_le(&[1, 2])]);
        let cases: Vec<(Builder, &str, bool)> = vec![
            (
                base().tag(SAMPLES_PER_PIXEL, V::Short(vec![3])),
                "SamplesPerPixel=3",
                false,
            ),
            (base().tag(COMPRESSION, V::Short(vec![7])), "JPEG", false),
            (
                base().tag(COMPRESSION, V::Short(vec![50000])),
                "ZSTD",
                false,
            ),
            (
                base().tag(BITS_PER_SAMPLE, V::Short(vec![12])),
                "12-bit",
                false,
            ),
            (
                base().tag(SAMPLE_FORMAT, V::Short(vec![6])),
                "complex",
                false,
            ),
            (base().tag(PHOTOMETRIC, V::Short(vec![2])), "RGB", false),
            (
                base().tag(PREDICTOR, V::Short(vec![3])),
                "Predictor=3",
                true,
            ),
            (
                base().tag(MODEL_PIXEL_SCALE, V::Double(vec![0.0, 0.0, 0.0])),
                "ground control",
                false,
            ),
            (
                base().tag(ROWS_PER_STRIP, V::Long(vec![0])),
                "RowsPerStrip",
                true,
            ),
            (
                base().tag(STRIP_OFFSETS, V::Long(vec![8, 8])),
                "needs 1 strip",
                true,
            ),
            (base().tag(IMAGE_WIDTH, V::Long(vec![0])), "0×1", true),
            (
                base().tag(
                    MODEL_TIEPOINT,
                    V::Double(vec![0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0]),
                ),
                "degenerate",
                true,
            ),
        ];
        for (bld, needle, is_invalid) in cases {
            let e = read(&bld.build()).unwrap_err();
            assert!(e.to_string().contains(needle), "{needle}: {e}");
            assert_eq!(
                matches!(e, TerrainError::Invalid(_)),
                is_invalid,
                "{needle}: {e:?}"
            );
            if !is_invalid {
                assert!(matches!(e, TerrainError::Unsupported(_)), "{needle}: {e:?}");
            }
        }
        let mut bld = base();
        bld.tags
            .retain(|(t, _)| *t != MODEL_PIXEL_SCALE && *t != MODEL_TIEPOINT);
        let e = read(&bld.build()).unwrap_err();
        assert!(e.to_string().contains("no georeferencing"), "{e}");
    }

    #[test]
    fn hostile_ifds() {
        let good = Builder::image(2, 1, 2, 16)
            .strips(1, vec![i16_le(&[1, 2])])
            .build();
        let ifd = u32::from_le_bytes(good[4..8].try_into().unwrap()) as usize;
        // IFD offset outside the file.
        let mut b = good.clone();
        b[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            read(&b)
                .unwrap_err()
                .to_string()
                .contains("outside the file")
        );
        // Entry count beyond the file.
        let mut b = good.clone();
        b[ifd..ifd + 2].copy_from_slice(&u16::MAX.to_le_bytes());
        assert!(read(&b).unwrap_err().to_string().contains("past the end"));
        // A tag whose count overflows and one whose values lie outside.
        for count in [u32::MAX, 1 << 30] {
            let b = Builder::image(2, 1, 2, 16)
                .strips(1, vec![i16_le(&[1, 2])])
                .tag(
                    MODEL_TIEPOINT,
                    V::Raw(12, u64::from(count), 100u32.to_le_bytes().to_vec()),
                )
                .build();
            let e = read(&b).unwrap_err();
            assert!(e.to_string().contains("ModelTiepoint"), "{e}");
        }
        // BigTIFF with a huge entry count.
        let mut bld = Builder::image(2, 1, 2, 16).strips(1, vec![i16_le(&[1, 2])]);
        bld.big = true;
        let mut b = bld.build();
        let ifd = u64::from_le_bytes(b[8..16].try_into().unwrap()) as usize;
        b[ifd..ifd + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(matches!(read(&b), Err(TerrainError::Invalid(_))));
        // A corrupt GeoKeyDirectory.
        let b = Builder::image(2, 1, 2, 16)
            .strips(1, vec![i16_le(&[1, 2])])
            .tag(
                GEO_KEY_DIRECTORY,
                V::Short(vec![1, 1, 0, 50, 1024, 0, 1, 1]),
            )
            .build();
        assert!(
            read(&b)
                .unwrap_err()
                .to_string()
                .contains("GeoKeyDirectory")
        );
        // Garbage LZW data.
        let b = Builder::image(2, 2, 2, 16)
            .tag(COMPRESSION, V::Short(vec![5]))
            .strips(2, vec![vec![0xFF; 7]])
            .build();
        assert!(matches!(read(&b), Err(TerrainError::Invalid(_))));
    }

    // ---- Reading one band of a multi-band GeoTIFF. ----

    use crate::terrain::read_geotiff_band;

    const EXTRA_SAMPLES: u16 = 338;

    /// Band `b` (0-based) of the test rasters at (x, y): distinct Float32
    /// values, -9999 (the nodata value) and NaN at a few cells.
    fn band_value(b: usize, x: usize, y: usize) -> f32 {
        match (b, x, y) {
            (0, 1, 0) | (1, 2, 3) => -9999.0,
            (0, 3, 2) | (1, 0, 4) => f32::NAN,
            (0, ..) => 100.0 + x as f32 * 1.25 - y as f32 * 7.5 + 0.1,
            _ => -(x as f32) * 0.3 - y as f32 * 1000.0 + b as f32,
        }
    }

    /// What the reader must give for `band_value`.
    fn expected(b: usize, x: usize, y: usize) -> Option<f64> {
        let v = band_value(b, x, y);
        (!v.is_nan() && v != -9999.0).then_some(f64::from(v))
    }

    #[derive(Clone, Copy, Debug)]
    enum Chunks {
        Strips(usize),
        Tiles(usize, usize),
    }

    /// Encode one chunk: `rows` rows of `row_px` pixels of `spp`
    /// interleaved samples each (`value(x, y, s)`), with a predictor
    /// (as libtiff's horDiff32 / fpDiff on a little-endian host) and a
    /// compression.
    fn encode_f32_chunk(
        rows: usize,
        row_px: usize,
        spp: usize,
        value: impl Fn(usize, usize, usize) -> f32,
        predictor: u16,
        compression: u16,
    ) -> Vec<u8> {
        use tiff::encoder::compression::{CompressionAlgorithm, Deflate, Lzw};
        let mut raw = Vec::new();
        for y in 0..rows {
            let vals: Vec<f32> = (0..row_px * spp)
                .map(|i| value(i / spp, y, i % spp))
                .collect();
            match predictor {
                1 => raw.extend(vals.iter().flat_map(|v| v.to_le_bytes())),
                2 => {
                    let mut u: Vec<u32> = vals.iter().map(|v| v.to_bits()).collect();
                    for i in (spp..u.len()).rev() {
                        u[i] = u[i].wrapping_sub(u[i - spp]);
                    }
                    raw.extend(u.iter().flat_map(|v| v.to_le_bytes()));
                }
                3 => {
                    // Bytes of every value, most significant first, in four
                    // planes; then byte differences `spp` apart.
                    let wc = vals.len();
                    let mut b = vec![0u8; wc * 4];
                    for (i, v) in vals.iter().enumerate() {
                        for (k, byte) in v.to_be_bytes().into_iter().enumerate() {
                            b[k * wc + i] = byte;
                        }
                    }
                    for i in (spp..b.len()).rev() {
                        b[i] = b[i].wrapping_sub(b[i - spp]);
                    }
                    raw.extend(b);
                }
                _ => unreachable!(),
            }
        }
        let mut out = Vec::new();
        match compression {
            1 => return raw,
            5 => Lzw.write_to(&mut out, &raw).unwrap(),
            8 => Deflate::default().write_to(&mut out, &raw).unwrap(),
            _ => unreachable!(),
        };
        out
    }

    /// A `w`×`h` GeoTIFF of `spp` Float32 bands (`band_value`) with
    /// GDAL_NODATA -9999, interleaved per pixel or in separate planes.
    fn multiband_f32(
        (w, h, spp): (usize, usize, usize),
        planar: bool,
        chunks: Chunks,
        predictor: u16,
        compression: u16,
    ) -> Vec<u8> {
        let (cw, ch, across, down) = match chunks {
            Chunks::Strips(rps) => (w, rps, 1, h.div_ceil(rps)),
            Chunks::Tiles(tw, th) => (tw, th, w.div_ceil(tw), h.div_ceil(th)),
        };
        let tiled = matches!(chunks, Chunks::Tiles(..));
        let mut data = Vec::new();
        let planes: Vec<Option<usize>> = if planar {
            (0..spp).map(Some).collect()
        } else {
            vec![None]
        };
        for plane in planes {
            for i in 0..across * down {
                let (x0, y0) = ((i % across) * cw, (i / across) * ch);
                // Strips are cut at the bottom, tiles are padded (with 0).
                let rows = if tiled { ch } else { ch.min(h - y0) };
                let value = |x: usize, y: usize, s: usize| {
                    let (gx, gy) = (x0 + x, y0 + y);
                    if gx < w && gy < h {
                        band_value(plane.unwrap_or(s), gx, gy)
                    } else {
                        0.0
                    }
                };
                let n = if planar { 1 } else { spp };
                data.push(encode_f32_chunk(rows, cw, n, value, predictor, compression));
            }
        }
        let bld = Builder::image(w as u32, h as u32, 3, 32)
            .tag(SAMPLES_PER_PIXEL, V::Short(vec![spp as u16]))
            .tag(BITS_PER_SAMPLE, V::Short(vec![32; spp]))
            .tag(SAMPLE_FORMAT, V::Short(vec![3; spp]))
            .tag(EXTRA_SAMPLES, V::Short(vec![0; spp - 1]))
            .tag(PLANAR_CONFIG, V::Short(vec![if planar { 2 } else { 1 }]))
            .tag(COMPRESSION, V::Short(vec![compression]))
            .tag(PREDICTOR, V::Short(vec![predictor]))
            .tag(GDAL_NODATA, V::Ascii("-9999"));
        match chunks {
            Chunks::Strips(rps) => bld.strips(rps as u32, data),
            Chunks::Tiles(tw, th) => bld.tiles(tw as u32, th as u32, data),
        }
        .build()
    }

    fn band(bytes: &[u8], b: usize) -> Result<Dem, TerrainError> {
        read_geotiff_band(bytes, b, None, &DemLimits::default())
    }

    fn assert_band(dem: &Dem, b: usize, what: &str) {
        assert_eq!((dem.width, dem.height), (7, 5), "{what}");
        assert_eq!(dem.nodata, Some(-9999.0), "{what}");
        assert_eq!(dem.crs.epsg, 32633, "{what}");
        let t = dem.transform;
        assert_eq!(
            (t.origin_x, t.origin_y, t.pixel_width, t.pixel_height),
            (500000.0, 4000000.0, 10.0, -10.0),
            "{what}"
        );
        for y in 0..5 {
            for x in 0..7 {
                let got = dem.value(x, y);
                let want = expected(b, x, y);
                assert!(
                    got.map(f64::to_bits) == want.map(f64::to_bits),
                    "{what}, band {}, ({x},{y}): {got:?} != {want:?}",
                    b + 1
                );
            }
        }
    }

    #[test]
    fn float32_bands_chunky_and_planar_strips_and_tiles() {
        // 7×5 in strips of 2 rows (the last one cut) or 4×4 tiles (padded
        // right and below), every predictor with each compression.
        for planar in [false, true] {
            for chunks in [
                Chunks::Strips(2),
                Chunks::Tiles(4, 4),
                Chunks::Tiles(16, 16),
            ] {
                for (predictor, compression) in [(1, 1), (1, 8), (2, 5), (2, 8), (3, 1), (3, 8)] {
                    let what = format!(
                        "planar {planar}, {chunks:?}, predictor {predictor}, compression \
                         {compression}"
                    );
                    let b = multiband_f32((7, 5, 2), planar, chunks, predictor, compression);
                    for bn in [1, 2] {
                        let dem = band(&b, bn).unwrap_or_else(|e| panic!("{what}: {e}"));
                        assert_band(&dem, bn - 1, &what);
                    }
                    // A DEM upload must still have a single band.
                    let e = read_dem(&b, None, None, &DemLimits::default()).unwrap_err();
                    assert!(
                        matches!(e, TerrainError::Unsupported(ref m)
                            if m.contains("SamplesPerPixel=2")
                                && m.contains("a DEM must have a single band")),
                        "{what}: {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn three_bands_and_big_endian() {
        // Three bands, band 2 and 3 read, interleaved and planar; also a
        // big-endian file (predictor 3 output does not depend on it).
        for planar in [false, true] {
            for (predictor, compression) in [(2, 8), (3, 5)] {
                let b = multiband_f32(
                    (7, 5, 3),
                    planar,
                    Chunks::Tiles(4, 4),
                    predictor,
                    compression,
                );
                for bn in 1..=3 {
                    let what = format!("planar {planar} predictor {predictor}");
                    assert_band(&band(&b, bn).unwrap(), bn - 1, &what);
                }
            }
        }
        // Big-endian, uncompressed, chunky strips.
        let mut data = Vec::new();
        for y in 0..5 {
            for x in 0..7 {
                for s in 0..2 {
                    data.extend(band_value(s, x, y).to_be_bytes());
                }
            }
        }
        let mut bld = Builder::image(7, 5, 3, 32)
            .tag(SAMPLES_PER_PIXEL, V::Short(vec![2]))
            .tag(BITS_PER_SAMPLE, V::Short(vec![32]))
            .tag(GDAL_NODATA, V::Ascii("-9999"))
            .strips(5, vec![data]);
        bld.le = false;
        let b = bld.build();
        for bn in [1, 2] {
            assert_band(&band(&b, bn).unwrap(), bn - 1, "big-endian");
        }
    }

    #[test]
    fn int16_bands_with_horizontal_predictor() {
        use tiff::encoder::compression::{CompressionAlgorithm, Lzw};
        // 5×3 Int16, 3 bands interleaved, LZW + predictor 2: the
        // differences are taken between the same band of neighbours.
        let v = |x: usize, y: usize, s: usize| (x * 300 + y * 7) as i16 * (s as i16 + 1) - 1000;
        let mut raw: Vec<i16> = Vec::new();
        for y in 0..3 {
            let mut row: Vec<i16> = (0..15).map(|i| v(i / 3, y, i % 3)).collect();
            for i in (3..15).rev() {
                row[i] = row[i].wrapping_sub(row[i - 3]);
            }
            raw.extend(row);
        }
        let mut strip = Vec::new();
        Lzw.write_to(&mut strip, &i16_le(&raw)).unwrap();
        let b = Builder::image(5, 3, 2, 16)
            .tag(SAMPLES_PER_PIXEL, V::Short(vec![3]))
            .tag(BITS_PER_SAMPLE, V::Short(vec![16, 16, 16]))
            .tag(COMPRESSION, V::Short(vec![5]))
            .tag(PREDICTOR, V::Short(vec![2]))
            .tag(GDAL_NODATA, V::Ascii("-1000"))
            .strips(3, vec![strip])
            .build();
        for bn in 1..=3 {
            let dem = band(&b, bn).unwrap();
            for y in 0..3 {
                for x in 0..5 {
                    let want = v(x, y, bn - 1);
                    let want = (want != -1000).then_some(f64::from(want));
                    assert_eq!(dem.value(x, y), want, "band {bn} ({x},{y})");
                }
            }
        }
    }

    #[test]
    fn single_band_file_is_band_one() {
        let b = Builder::image(3, 3, 2, 16)
            .tag(GDAL_NODATA, V::Ascii("-9999"))
            .strips(
                2,
                vec![i16_le(&[1, 2, 3, -9999, 5, 6]), i16_le(&[7, 8, -32768])],
            )
            .build();
        let dem = read_dem(&b, None, None, &DemLimits::default()).unwrap();
        let one = band(&b, 1).unwrap();
        assert_eq!(
            one.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            dem.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(
            (one.transform, one.crs, one.nodata, one.format),
            (dem.transform, dem.crs, dem.nodata, dem.format)
        );
        let e = band(&b, 2).unwrap_err();
        assert!(
            e.to_string().contains("band 2") && e.to_string().contains("has 1 band "),
            "{e}"
        );
    }

    #[test]
    fn band_numbers_and_bad_multiband_layouts() {
        let b = multiband_f32((7, 5, 2), true, Chunks::Strips(2), 1, 1);
        for bn in [0, 3, usize::MAX] {
            let e = band(&b, bn).unwrap_err();
            let m = e.to_string();
            assert!(
                m.contains(&format!("band {bn} ")) && m.contains("has 2 bands"),
                "{bn}: {m}"
            );
        }
        let e = read_geotiff_band(b"not a tiff", 1, None, &DemLimits::default()).unwrap_err();
        assert!(e.to_string().contains("not a TIFF"), "{e}");

        let base = || {
            Builder::image(2, 1, 3, 32)
                .tag(SAMPLES_PER_PIXEL, V::Short(vec![2]))
                .tag(BITS_PER_SAMPLE, V::Short(vec![32, 32]))
                .tag(SAMPLE_FORMAT, V::Short(vec![3, 3]))
                .strips(1, vec![vec![0; 16]])
        };
        assert_eq!(band(&base().build(), 2).unwrap().values, vec![0.0, 0.0]);
        let cases: Vec<(Builder, &str)> = vec![
            (
                base().tag(SAMPLE_FORMAT, V::Short(vec![3, 1])),
                "different sample types",
            ),
            (
                base().tag(BITS_PER_SAMPLE, V::Short(vec![32, 32, 32])),
                "3 BitsPerSample",
            ),
            (
                base().tag(PLANAR_CONFIG, V::Short(vec![3])),
                "PlanarConfiguration is 3",
            ),
            // Separate planes need a strip per band.
            (
                base().tag(PLANAR_CONFIG, V::Short(vec![2])),
                "needs 2 strips (1 for each of its 2 separate bands)",
            ),
            (
                base().tag(PHOTOMETRIC, V::Short(vec![0])),
                "PhotometricInterpretation is 0",
            ),
            (
                base()
                    .tag(BITS_PER_SAMPLE, V::Short(vec![16, 16]))
                    .tag(SAMPLE_FORMAT, V::Short(vec![1, 1]))
                    .tag(PHOTOMETRIC, V::Short(vec![0])),
                "WhiteIsZero",
            ),
            (
                base().tag(SAMPLES_PER_PIXEL, V::Short(vec![0])),
                "SamplesPerPixel is 0",
            ),
        ];
        for (bld, needle) in cases {
            let e = band(&bld.build(), 1).unwrap_err();
            assert!(e.to_string().contains(needle), "{needle}: {e}");
        }
        // A decoded chunk of many samples must fit the limits: 4 × 4
        // pixels of 100 Float64 samples is 12 800 bytes.
        let b = Builder::image(4, 4, 3, 64)
            .tag(SAMPLES_PER_PIXEL, V::Short(vec![100]))
            .strips(4, vec![vec![0; 16]])
            .build();
        let small = DemLimits {
            max_pixels: 1000,
            max_side: 100,
        };
        let e = read_geotiff_band(&b, 1, None, &small).unwrap_err();
        assert!(e.to_string().contains("12800 bytes"), "{e}");
    }

    #[test]
    fn every_truncation_of_a_multiband_file_is_an_error() {
        for planar in [false, true] {
            let full = multiband_f32((7, 5, 2), planar, Chunks::Tiles(4, 4), 3, 8);
            for len in 0..full.len() {
                for bn in [1, 2] {
                    assert!(
                        band(&full[..len], bn).is_err(),
                        "prefix of {len} bytes read"
                    );
                }
            }
        }
    }

    #[test]
    fn costmap_written_by_our_writer_round_trips() {
        use crate::export::geotiff::{Band, BandData, Page, write_geotiff};
        use crate::terrain::{Crs, geotiff_pages, read_geotiff_page_band};
        // 300×250: two strips of about 256 KiB per Float32 band, one for
        // the Byte page.
        let (w, h) = (300usize, 250usize);
        let cost: Vec<f32> = (0..w * h)
            .map(|i| match i % 97 {
                0 => f32::NAN,
                k => 1.0 + k as f32 * 0.37 + (i / w) as f32 * 1e-3,
            })
            .collect();
        let slope: Vec<f32> = (0..w * h).map(|i| (i % 45) as f32).collect();
        let class: Vec<u8> = (0..w * h).map(|i| (i % 6) as u8).collect();
        let transform = GeoTransform {
            origin_x: 500000.0,
            pixel_width: 2.0,
            row_rotation: 0.0,
            origin_y: 4000000.0,
            col_rotation: 0.0,
            pixel_height: -2.0,
        };
        let crs = Crs {
            epsg: 32633,
            name: "WGS 84 / UTM zone 33N".into(),
            geographic: false,
            proj4: String::new(),
        };
        let mut cur = std::io::Cursor::new(Vec::new());
        write_geotiff(
            &mut cur,
            w,
            h,
            &transform,
            &crs,
            &[
                Page {
                    bands: &[
                        Band::new("cost", "cost", BandData::F32(&cost)),
                        Band::new("slope", "deg", BandData::F32(&slope)),
                    ],
                    nodata: Some(f64::NAN),
                },
                Page {
                    bands: &[Band::new("class", "", BandData::U8(&class))],
                    nodata: Some(0.0),
                },
            ],
        )
        .unwrap();
        let bytes = cur.into_inner();
        let page = |bands| crate::terrain::TiffPage {
            width: w as u64,
            height: h as u64,
            bands,
            full_resolution: true,
        };
        assert_eq!(geotiff_pages(&bytes, 100).unwrap(), vec![page(2), page(1)]);
        assert_eq!(geotiff_pages(&bytes, 1).unwrap(), vec![page(2)]);
        let page_band = |p, b| read_geotiff_page_band(&bytes, p, b, None, &DemLimits::default());
        let c = band(&bytes, 1).unwrap();
        assert_eq!(page_band(1, 1).unwrap().values.len(), w * h);
        let s = page_band(1, 2).unwrap();
        let k = page_band(2, 1).unwrap();
        for dem in [&c, &s, &k] {
            assert_eq!((dem.width, dem.height), (w, h));
            assert_eq!(dem.transform, transform);
            assert_eq!(dem.crs.epsg, 32633);
        }
        assert!(c.nodata.is_some_and(f64::is_nan));
        assert_eq!(k.nodata, Some(0.0));
        for i in 0..w * h {
            let want = f64::from(cost[i]);
            assert!(
                c.values[i] == want || (want.is_nan() && c.values[i].is_nan()),
                "cost {i}"
            );
            assert_eq!(s.values[i], f64::from(slope[i]), "slope {i}");
            if class[i] == 0 {
                assert!(k.values[i].is_nan(), "class {i} is nodata");
            } else {
                assert_eq!(k.values[i], f64::from(class[i]), "class {i}");
            }
        }
        let msg = |r: Result<Dem, TerrainError>| r.unwrap_err().to_string();
        assert!(msg(band(&bytes, 3)).contains("has 2 bands"));
        assert!(msg(page_band(2, 2)).contains("band 2 does not exist"));
        let e = msg(page_band(3, 1));
        assert!(
            e.contains("page 3 does not exist") && e.contains("2 pages"),
            "{e}"
        );
        assert!(msg(page_band(0, 1)).contains("page 0"));
        // A DEM is the first page's single band.
        assert!(msg(super::read(&bytes, None, &DemLimits::default())).contains("single band"));

        // A chain that loops back (page 2's next-IFD pointer to page 1) or
        // leaves the file is refused, not followed forever.
        let u16_at = |b: &[u8], at: usize| usize::from(u16::from_le_bytes([b[at], b[at + 1]]));
        let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        // A classic IFD: 2-byte count, 12-byte entries, 4-byte pointer.
        let next_of = |b: &[u8], ifd: usize| ifd + 2 + 12 * u16_at(b, ifd);
        let first = u32_at(&bytes, 4);
        let second = u32_at(&bytes, next_of(&bytes, first as usize));
        let at = next_of(&bytes, second as usize);
        assert_eq!(u32_at(&bytes, at), 0);
        // Page 2 as an overview (NewSubfileType 1, in place of its
        // Compression entry, whose default is the same "none").
        let mut overview = bytes.clone();
        let entries = second as usize + 2;
        let compression = (0..u16_at(&bytes, second as usize))
            .map(|i| entries + 12 * i)
            .find(|&e| u16_at(&bytes, e) == usize::from(COMPRESSION))
            .unwrap();
        overview[compression..compression + 2].copy_from_slice(&NEW_SUBFILE_TYPE.to_le_bytes());
        let pages = geotiff_pages(&overview, 100).unwrap();
        assert!(pages[0].full_resolution && !pages[1].full_resolution);

        for (pointer, what) in [(first, "loop"), (u32::MAX, "outside the file")] {
            let mut bad = bytes.clone();
            bad[at..at + 4].copy_from_slice(&pointer.to_le_bytes());
            let e = geotiff_pages(&bad, 100).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
            // The first page still reads; the second ends, either way.
            let limits = DemLimits::default();
            assert!(read_geotiff_page_band(&bad, 1, 1, None, &limits).is_ok());
            let _ = read_geotiff_page_band(&bad, 2, 1, None, &limits);
        }
    }
}
