//! Streaming writer of GeoTIFFs (SPEC §4.2 output: the costmap "in the
//! DEM's CRS, readable by GDAL/QGIS"), of Float32 and Byte bands.
//!
//! A file holds one or more *pages* (TIFF images, GDAL's subdatasets
//! `GTIFF_DIR:1:file.tif`, `GTIFF_DIR:2:file.tif`, …; opening the file
//! itself gives the first). All bands of a page share one sample type and
//! one nodata value, as GDAL's GTiff driver and libtiff require: a band
//! that needs another type or nodata goes on a page of its own. Every page
//! is a little-endian, uncompressed, stripped image with
//! `PlanarConfiguration = 2` (one plane per band, written one after the
//! other), `SampleFormat` 3 / `BitsPerSample` 32 (Float32) or 1 / 8 (Byte),
//! and the tags GDAL reads back:
//!
//! - georeferencing: `ModelPixelScale` + `ModelTiepoint` for a north-up
//!   raster (no rotation, `pixel_width > 0`, `pixel_height < 0`), otherwise
//!   `ModelTransformation`; `GTRasterTypeGeoKey = 1` (PixelIsArea), so the
//!   transform's origin is the outer corner of pixel (0, 0) as in GDAL;
//! - the CRS as an EPSG code in the `GeoKeyDirectory`
//!   (`GeographicTypeGeoKey` or `ProjectedCSTypeGeoKey`), with the CRS name
//!   as `GTCitationGeoKey`;
//! - the page's `GDAL_NODATA` (`"nan"` for NaN, as GDAL writes it), and in
//!   `GDAL_METADATA` each band's description, unit (GDAL's `GetUnitType`,
//!   e.g. `m`, `deg`) and further metadata items.
//!
//! Layout: header, the pages' IFDs and tag values first, then the image
//! data, page after page and band after band, in strips of about 256 KiB.
//! Everything is known before the first byte is written, so the output is
//! written strictly sequentially with one `write_all` per strip and no
//! seeking: only one strip is held in memory besides the caller's bands,
//! and an unbuffered `File` is as fast as a `BufWriter`. A file larger than
//! 4 GiB is written as BigTIFF automatically (GDAL, QGIS and terraplan's own
//! reader read it).

use std::io::{self, Seek, Write};
use std::ops::Range;

use super::xml_escape;
use crate::terrain::{Crs, GeoTransform};

/// The cells of one band, row-major with row 0 first (the top row of a
/// north-up raster), `width × height` of them. The variant is the band's
/// sample type in the file.
#[derive(Clone, Copy, Debug)]
pub enum BandData<'a> {
    /// Written as Float32, as they are (NaN included).
    F32(&'a [f32]),
    /// Written as Byte (GDAL's UInt8), e.g. class codes.
    U8(&'a [u8]),
}

/// The sample types the writer writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleType {
    Float32,
    Byte,
}

impl SampleType {
    /// GDAL's name for it.
    pub fn name(self) -> &'static str {
        match self {
            SampleType::Float32 => "Float32",
            SampleType::Byte => "Byte",
        }
    }

    fn bytes(self) -> usize {
        match self {
            SampleType::Float32 => 4,
            SampleType::Byte => 1,
        }
    }

    /// (BitsPerSample, SampleFormat).
    fn tiff_tags(self) -> (u16, u16) {
        match self {
            // IEEE floating point.
            SampleType::Float32 => (32, 3),
            // Unsigned integer.
            SampleType::Byte => (8, 1),
        }
    }
}

impl BandData<'_> {
    fn len(&self) -> usize {
        match self {
            BandData::F32(v) => v.len(),
            BandData::U8(v) => v.len(),
        }
    }

    pub fn sample_type(&self) -> SampleType {
        match self {
            BandData::F32(_) => SampleType::Float32,
            BandData::U8(_) => SampleType::Byte,
        }
    }

    /// Cells `range` as little-endian samples in `buf` (replacing its
    /// contents).
    fn encode(&self, range: Range<usize>, buf: &mut Vec<u8>) -> io::Result<()> {
        let short = || invalid_input("a band is shorter than width × height");
        buf.clear();
        match self {
            BandData::F32(v) => {
                let src = v.get(range).ok_or_else(short)?;
                buf.resize(src.len() * 4, 0);
                for (dst, x) in buf.chunks_exact_mut(4).zip(src) {
                    dst.copy_from_slice(&x.to_le_bytes());
                }
            }
            BandData::U8(v) => {
                buf.extend_from_slice(v.get(range).ok_or_else(short)?);
            }
        }
        Ok(())
    }
}

/// One band of a page: its cells and what GDAL shows about it.
#[derive(Clone, Copy, Debug)]
pub struct Band<'a> {
    /// `gdalinfo`'s `Description = ...`, QGIS's band name; not written
    /// when empty.
    pub description: &'a str,
    /// The unit of the values, GDAL's `GetUnitType()` (`m`, `deg`, ...);
    /// not written when empty (e.g. class codes, which have none).
    pub unit: &'a str,
    /// Further band metadata items (name, value), shown by `gdalinfo`
    /// under the band's `Metadata:`. Names are ASCII letters, digits and
    /// `_`, starting with a letter.
    pub metadata: &'a [(&'a str, &'a str)],
    pub data: BandData<'a>,
}

impl<'a> Band<'a> {
    /// A band with a description and a unit and no other metadata.
    pub fn new(description: &'a str, unit: &'a str, data: BandData<'a>) -> Band<'a> {
        Band {
            description,
            unit,
            metadata: &[],
            data,
        }
    }
}

/// One page (TIFF image) of the file: bands of one sample type sharing
/// one nodata value (`GDAL_NODATA`), which must fit that type (an integer
/// in 0..=255 for Byte; NaN, ±inf or a Float32 value for Float32).
#[derive(Clone, Copy, Debug)]
pub struct Page<'a> {
    pub bands: &'a [Band<'a>],
    pub nodata: Option<f64>,
}

/// Write `pages` (each band `width × height` cells, row-major) as a
/// GeoTIFF georeferenced by `transform` (GDAL's convention, corner of pixel
/// (0, 0) at the origin) in `crs`. The first page is what GDAL opens as
/// the file; page n is GDAL's `GTIFF_DIR:n:file` and terraplan's
/// `read_geotiff_page_band(bytes, n, …)`.
///
/// `out` must be positioned at the start of the file (a fresh `File`,
/// `BufWriter<File>` or `Cursor`); it is flushed before returning. The
/// values are not checked against the nodata value: NaN cells stay NaN
/// whatever it is.
///
/// # Errors
///
/// `io::ErrorKind::InvalidInput` (nothing written) when the width or height
/// is 0 or above `u32::MAX`, there are no pages, a page has no bands or
/// more than 65 535, mixes sample types, or has a nodata value its type
/// cannot hold, a band's length is not `width × height`, a metadata name is
/// not a plain identifier, the transform is not finite or not invertible,
/// the EPSG code does not fit a GeoKey (1..=65535, not 32767), or `out` is
/// not at position 0; any error of `out`.
pub fn write_geotiff<W: Write + Seek>(
    out: W,
    width: usize,
    height: usize,
    transform: &GeoTransform,
    crs: &Crs,
    pages: &[Page<'_>],
) -> io::Result<()> {
    let raster = Raster {
        width,
        height,
        transform,
        crs,
        pages,
    };
    write_raster(out, &raster, Options::default())
}

/// Bytes per strip aimed at (a strip holds at least one row).
const STRIP_TARGET_BYTES: usize = 256 * 1024;

/// Pages a file may hold (each IFD is written before any data).
const MAX_PAGES: usize = 1024;

// TIFF tags.
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
const EXTRA_SAMPLES: u16 = 338;
const SAMPLE_FORMAT: u16 = 339;
// GeoTIFF and GDAL tags.
const MODEL_PIXEL_SCALE: u16 = 33550;
const MODEL_TIEPOINT: u16 = 33922;
const MODEL_TRANSFORMATION: u16 = 34264;
const GEO_KEY_DIRECTORY: u16 = 34735;
const GEO_ASCII_PARAMS: u16 = 34737;
const GDAL_METADATA: u16 = 42112;
const GDAL_NODATA: u16 = 42113;

// GeoKeys.
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GT_CITATION: u16 = 1026;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;

// TIFF field types.
const ASCII: u16 = 2;
const SHORT: u16 = 3;
const LONG: u16 = 4;
const DOUBLE: u16 = 12;
const LONG8: u16 = 16;

/// The arguments of [`write_geotiff`].
struct Raster<'a> {
    width: usize,
    height: usize,
    transform: &'a GeoTransform,
    crs: &'a Crs,
    pages: &'a [Page<'a>],
}

/// Knobs the tests turn to exercise many strips and BigTIFF on small files.
#[derive(Clone, Copy, Debug)]
struct Options {
    strip_target_bytes: usize,
    force_bigtiff: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            strip_target_bytes: STRIP_TARGET_BYTES,
            force_bigtiff: false,
        }
    }
}

fn invalid_input(msg: impl Into<String>) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg.into())
}

fn too_large() -> io::Error {
    invalid_input("the raster is too large to address")
}

/// Strip geometry of one page, in bytes and rows.
#[derive(Clone, Copy, Debug)]
struct Strips {
    rows_per_strip: usize,
    per_band: usize,
    /// Bytes of one row of one band.
    row_bytes: u64,
    /// Bytes of one band.
    band_bytes: u64,
}

impl Strips {
    fn new(width: usize, height: usize, sample: SampleType, target: usize) -> io::Result<Strips> {
        let row = width.checked_mul(sample.bytes()).ok_or_else(too_large)?;
        let rows_per_strip = (target / row).clamp(1, height);
        let row_bytes = u64::try_from(row).map_err(|_| too_large())?;
        let band_bytes = u64::try_from(height)
            .ok()
            .and_then(|h| h.checked_mul(row_bytes))
            .ok_or_else(too_large)?;
        Ok(Strips {
            rows_per_strip,
            per_band: height.div_ceil(rows_per_strip),
            row_bytes,
            band_bytes,
        })
    }

    /// Rows `[start, end)` of strip `s` (of any band).
    fn rows(&self, s: usize, height: usize) -> Range<usize> {
        let start = s * self.rows_per_strip;
        start..(start + self.rows_per_strip).min(height)
    }
}

/// A page's sample type (its bands share it; checked by `validate`).
fn page_sample(page: &Page<'_>) -> SampleType {
    page.bands
        .first()
        .map_or(SampleType::Float32, |b| b.data.sample_type())
}

/// Where everything goes: the head (header and IFDs) and the byte at
/// which each page's image data starts.
struct Layout {
    head: Vec<u8>,
    data_starts: Vec<u64>,
}

fn write_raster<W: Write + Seek>(mut out: W, r: &Raster<'_>, opts: Options) -> io::Result<()> {
    validate(r)?;
    let position = out.stream_position()?;
    if position != 0 {
        return Err(invalid_input(format!(
            "the GeoTIFF must be written at the start of the file, not at byte {position}"
        )));
    }
    let strips = r
        .pages
        .iter()
        .map(|p| Strips::new(r.width, r.height, page_sample(p), opts.strip_target_bytes))
        .collect::<io::Result<Vec<_>>>()?;
    let classic = if opts.force_bigtiff {
        None
    } else {
        layout(r, &strips, false)?
    };
    let laid = match classic {
        Some(l) => l,
        None => layout(r, &strips, true)?.ok_or_else(too_large)?,
    };
    out.write_all(&laid.head)?;
    let mut written = len_u64(laid.head.len())?;

    let largest = strips
        .iter()
        .map(|s| s.row_bytes.saturating_mul(s.rows_per_strip as u64))
        .max()
        .unwrap_or(0);
    let mut buf = Vec::with_capacity(usize::try_from(largest).unwrap_or(0));
    for ((page, st), &start) in r.pages.iter().zip(&strips).zip(&laid.data_starts) {
        // Padding to the page's 8-byte aligned start.
        let pad = start.checked_sub(written).ok_or_else(too_large)?;
        out.write_all(&vec![0; usize::try_from(pad).map_err(|_| too_large())?])?;
        written = start;
        for band in page.bands {
            for s in 0..st.per_band {
                let rows = st.rows(s, r.height);
                band.data
                    .encode(rows.start * r.width..rows.end * r.width, &mut buf)?;
                out.write_all(&buf)?;
                written += len_u64(buf.len())?;
            }
        }
    }
    out.flush()
}

/// Everything that goes before the image data (header, the pages' IFDs
/// with their tag values, padding) and where each page's data starts.
/// `None` when a classic TIFF cannot hold the file (> 4 GiB).
fn layout(r: &Raster<'_>, strips: &[Strips], big: bool) -> io::Result<Option<Layout>> {
    let header_len: u64 = if big { 16 } else { 8 };
    let mut data_lens = Vec::with_capacity(r.pages.len());
    for (page, st) in r.pages.iter().zip(strips) {
        let n_bands = len_u64(page.bands.len())?;
        data_lens.push(st.band_bytes.checked_mul(n_bands).ok_or_else(too_large)?);
    }
    // A classic TIFF's offsets are 32-bit: check before laying out IFDs
    // that could not hold them.
    let total = data_lens
        .iter()
        .try_fold(0u64, |a, &l| a.checked_add(l))
        .ok_or_else(too_large)?;
    if !big && total > u64::from(u32::MAX) {
        return Ok(None);
    }
    // An IFD's size does not depend on the values of the strip offsets or
    // of the next-IFD pointer, nor (IFDs starting 8-byte aligned) on where
    // it starts: measure each with zeros, then lay them out for real.
    let mut ifd_starts = Vec::with_capacity(r.pages.len());
    let mut at = header_len;
    for (page, st) in r.pages.iter().zip(strips) {
        ifd_starts.push(at);
        let probe = serialize_ifd(&ifd_entries(r, page, st, 0, big)?, big, at, 0)?;
        at = align8(at.checked_add(len_u64(probe.len())?))?;
    }
    let mut data_starts = Vec::with_capacity(r.pages.len());
    for len in &data_lens {
        data_starts.push(at);
        at = align8(at.checked_add(*len))?;
    }
    // Where the last page's data ends (no padding after it).
    let end = data_starts[data_starts.len() - 1] + data_lens[data_lens.len() - 1];
    if !big && end > u64::from(u32::MAX) {
        return Ok(None);
    }

    let head_len = usize::try_from(data_starts[0]).map_err(|_| too_large())?;
    let mut head = Vec::with_capacity(head_len);
    if big {
        head.extend_from_slice(b"II");
        head.extend_from_slice(&43u16.to_le_bytes());
        head.extend_from_slice(&8u16.to_le_bytes());
        head.extend_from_slice(&0u16.to_le_bytes());
        head.extend_from_slice(&header_len.to_le_bytes());
    } else {
        head.extend_from_slice(b"II");
        head.extend_from_slice(&42u16.to_le_bytes());
        head.extend_from_slice(&8u32.to_le_bytes());
    }
    for (i, (page, st)) in r.pages.iter().zip(strips).enumerate() {
        let next = ifd_starts.get(i + 1).copied().unwrap_or(0);
        let entries = ifd_entries(r, page, st, data_starts[i], big)?;
        let ifd = serialize_ifd(&entries, big, ifd_starts[i], next)?;
        debug_assert_eq!(len_u64(head.len())?, ifd_starts[i]);
        head.extend_from_slice(&ifd);
        head.resize(head.len().next_multiple_of(8), 0);
    }
    debug_assert_eq!(head.len(), head_len);
    head.resize(head_len, 0);
    Ok(Some(Layout { head, data_starts }))
}

/// `v` rounded up to a multiple of 8; an error on overflow (of `v` too).
fn align8(v: Option<u64>) -> io::Result<u64> {
    v.and_then(|v| v.checked_next_multiple_of(8))
        .ok_or_else(too_large)
}

fn len_u64(n: usize) -> io::Result<u64> {
    u64::try_from(n).map_err(|_| too_large())
}

/// A metadata item name GDAL's XML and `gdalinfo` show as is.
fn plain_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn validate(r: &Raster<'_>) -> io::Result<()> {
    if r.width == 0 || r.height == 0 {
        return Err(invalid_input(format!(
            "cannot write a {}×{} GeoTIFF: width and height must be positive",
            r.width, r.height
        )));
    }
    if u32::try_from(r.width).is_err() || u32::try_from(r.height).is_err() {
        return Err(invalid_input(format!(
            "cannot write a {}×{} GeoTIFF: a TIFF's width and height are at most {}",
            r.width,
            r.height,
            u32::MAX
        )));
    }
    if r.pages.is_empty() {
        return Err(invalid_input("cannot write a GeoTIFF without pages"));
    }
    if r.pages.len() > MAX_PAGES {
        return Err(invalid_input(format!(
            "cannot write {} pages: at most {MAX_PAGES}",
            r.pages.len()
        )));
    }
    let cells = r.width.checked_mul(r.height).ok_or_else(too_large)?;
    for (p, page) in r.pages.iter().enumerate() {
        let p = p + 1;
        if page.bands.is_empty() {
            return Err(invalid_input(format!(
                "page {p} has no bands: a TIFF image has at least one"
            )));
        }
        if page.bands.len() > usize::from(u16::MAX) {
            return Err(invalid_input(format!(
                "cannot write {} bands on page {p}: a TIFF has at most {} samples per pixel",
                page.bands.len(),
                u16::MAX
            )));
        }
        let sample = page_sample(page);
        for (i, band) in page.bands.iter().enumerate() {
            let b = i + 1;
            if band.data.len() != cells {
                return Err(invalid_input(format!(
                    "page {p} band {b} ({:?}) has {} values, expected {}×{} = {cells}",
                    band.description,
                    band.data.len(),
                    r.width,
                    r.height
                )));
            }
            let own = band.data.sample_type();
            if own != sample {
                return Err(invalid_input(format!(
                    "page {p} band {b} ({:?}) is {} but band 1 is {}: the bands of a TIFF \
                     image share one sample type; put it on a page of its own",
                    band.description,
                    own.name(),
                    sample.name()
                )));
            }
            if let Some((name, _)) = band.metadata.iter().find(|(n, _)| !plain_name(n)) {
                return Err(invalid_input(format!(
                    "page {p} band {b}: the metadata name {name:?} is not letters, digits and \
                     '_' starting with a letter"
                )));
            }
        }
        if let Some(v) = page.nodata {
            let fits = match sample {
                SampleType::Float32 => !v.is_finite() || (v as f32).is_finite(),
                SampleType::Byte => v.fract() == 0.0 && (0.0..=255.0).contains(&v),
            };
            if !fits {
                return Err(invalid_input(format!(
                    "page {p}: the nodata value {v} does not fit its {} samples",
                    sample.name()
                )));
            }
        }
    }
    let t = r.transform;
    let all = t.coefficients();
    if !t.is_regular() {
        return Err(invalid_input(format!(
            "the geotransform {all:?} is not finite and invertible"
        )));
    }
    if geokey_epsg(r.crs).is_none() {
        return Err(invalid_input(format!(
            "EPSG:{} cannot be written as a GeoTIFF CRS code (1..=65535, not 32767)",
            r.crs.epsg
        )));
    }
    Ok(())
}

/// The CRS code as a GeoKey value (SHORT; 32767 means user-defined).
fn geokey_epsg(crs: &Crs) -> Option<u16> {
    u16::try_from(crs.epsg)
        .ok()
        .filter(|&c| c != 0 && c != 32767)
}

/// One IFD entry with its value already little-endian encoded.
struct Entry {
    tag: u16,
    kind: u16,
    count: u64,
    bytes: Vec<u8>,
}

impl Entry {
    fn shorts(tag: u16, values: &[u16]) -> Entry {
        Entry {
            tag,
            kind: SHORT,
            count: values.len() as u64,
            bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    fn long(tag: u16, value: u32) -> Entry {
        Entry {
            tag,
            kind: LONG,
            count: 1,
            bytes: value.to_le_bytes().to_vec(),
        }
    }

    /// LONG values in a classic TIFF, LONG8 in a BigTIFF.
    fn offsets(tag: u16, values: &[u64], big: bool) -> io::Result<Entry> {
        let bytes = if big {
            values.iter().flat_map(|v| v.to_le_bytes()).collect()
        } else {
            let mut bytes = Vec::with_capacity(values.len() * 4);
            for &v in values {
                let v = u32::try_from(v).map_err(|_| too_large())?;
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes
        };
        Ok(Entry {
            tag,
            kind: if big { LONG8 } else { LONG },
            count: len_u64(values.len())?,
            bytes,
        })
    }

    fn doubles(tag: u16, values: &[f64]) -> Entry {
        Entry {
            tag,
            kind: DOUBLE,
            count: values.len() as u64,
            bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    /// NUL-terminated text (the text itself must not contain NUL).
    fn ascii(tag: u16, text: &str) -> Entry {
        let mut bytes = text.as_bytes().to_vec();
        bytes.push(0);
        Entry {
            tag,
            kind: ASCII,
            count: bytes.len() as u64,
            bytes,
        }
    }
}

/// The IFD entries of `page`, sorted by tag, for its image data starting
/// at byte `data_start`.
fn ifd_entries(
    r: &Raster<'_>,
    page: &Page<'_>,
    strips: &Strips,
    data_start: u64,
    big: bool,
) -> io::Result<Vec<Entry>> {
    let n = page.bands.len();
    let samples = u16::try_from(n).map_err(|_| too_large())?;
    let height = r.height;
    let dim = |v: usize| u32::try_from(v).map_err(|_| too_large());
    let (bits, format) = page_sample(page).tiff_tags();

    let mut offsets = Vec::with_capacity(n * strips.per_band);
    let mut counts = Vec::with_capacity(n * strips.per_band);
    let mut band_start = data_start;
    for _ in 0..n {
        for s in 0..strips.per_band {
            let rows = strips.rows(s, height);
            let first = len_u64(rows.start)? * strips.row_bytes;
            offsets.push(band_start + first);
            counts.push(len_u64(rows.len())? * strips.row_bytes);
        }
        band_start += strips.band_bytes;
    }

    let mut entries = vec![
        Entry::long(IMAGE_WIDTH, dim(r.width)?),
        Entry::long(IMAGE_LENGTH, dim(height)?),
        Entry::shorts(BITS_PER_SAMPLE, &vec![bits; n]),
        // No compression.
        Entry::shorts(COMPRESSION, &[1]),
        // BlackIsZero.
        Entry::shorts(PHOTOMETRIC, &[1]),
        Entry::offsets(STRIP_OFFSETS, &offsets, big)?,
        Entry::shorts(SAMPLES_PER_PIXEL, &[samples]),
        Entry::long(ROWS_PER_STRIP, dim(strips.rows_per_strip)?),
        Entry::offsets(STRIP_BYTE_COUNTS, &counts, big)?,
        // Separate planes.
        Entry::shorts(PLANAR_CONFIG, &[2]),
        Entry::shorts(SAMPLE_FORMAT, &vec![format; n]),
    ];
    if n > 1 {
        // The bands after the first are unspecified extra samples, as GDAL
        // writes them (libtiff warns otherwise).
        entries.push(Entry::shorts(EXTRA_SAMPLES, &vec![0; n - 1]));
    }

    let t = r.transform;
    if t.row_rotation == 0.0 && t.col_rotation == 0.0 && t.pixel_width > 0.0 && t.pixel_height < 0.0
    {
        entries.push(Entry::doubles(
            MODEL_PIXEL_SCALE,
            &[t.pixel_width, -t.pixel_height, 0.0],
        ));
        entries.push(Entry::doubles(
            MODEL_TIEPOINT,
            &[0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0],
        ));
    } else {
        // Rotated, sheared or flipped: ModelPixelScale cannot say it.
        #[rustfmt::skip]
        let matrix = [
            t.pixel_width, t.row_rotation, 0.0, t.origin_x,
            t.col_rotation, t.pixel_height, 0.0, t.origin_y,
            0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        entries.push(Entry::doubles(MODEL_TRANSFORMATION, &matrix));
    }

    let (keys, ascii) = geokeys(r.crs)?;
    entries.push(Entry::shorts(GEO_KEY_DIRECTORY, &keys));
    if let Some(ascii) = ascii {
        entries.push(Entry::ascii(GEO_ASCII_PARAMS, &ascii));
    }
    if let Some(xml) = gdal_metadata(page.bands) {
        entries.push(Entry::ascii(GDAL_METADATA, &xml));
    }
    if let Some(v) = page.nodata {
        entries.push(Entry::ascii(GDAL_NODATA, &format_nodata(v)));
    }
    entries.sort_by_key(|e| e.tag);
    Ok(entries)
}

/// The GeoKeyDirectory (version 1.1.0) and the GeoAsciiParams it refers to.
fn geokeys(crs: &Crs) -> io::Result<(Vec<u16>, Option<String>)> {
    let code = geokey_epsg(crs).ok_or_else(|| invalid_input("bad EPSG code"))?;
    let citation: String = crs
        .name
        .chars()
        .filter(|c| c.is_ascii() && !c.is_ascii_control() && *c != '|')
        .collect();
    let citation = citation.trim();
    // (key, location, count, value)
    let mut keys: Vec<[u16; 4]> = vec![
        [GT_MODEL_TYPE, 0, 1, if crs.geographic { 2 } else { 1 }],
        // PixelIsArea.
        [GT_RASTER_TYPE, 0, 1, 1],
    ];
    let ascii = if citation.is_empty() {
        None
    } else {
        // Strings in GeoAsciiParams end with '|', which the count includes.
        let text = format!("{citation}|");
        let count = u16::try_from(text.len()).map_err(|_| invalid_input("CRS name too long"))?;
        keys.push([GT_CITATION, GEO_ASCII_PARAMS, count, 0]);
        Some(text)
    };
    keys.push(if crs.geographic {
        [GEOGRAPHIC_TYPE, 0, 1, code]
    } else {
        [PROJECTED_CS_TYPE, 0, 1, code]
    });
    let n = u16::try_from(keys.len()).map_err(|_| too_large())?;
    let mut dir = vec![1, 1, 0, n];
    dir.extend(keys.iter().flatten());
    Ok((dir, ascii))
}

/// `GDAL_METADATA` holding the bands' metadata items, descriptions and
/// units (the non-empty ones), as GDAL writes them: `sample` is the band's
/// index (from 0) on its page, and the `description` and `unittype` roles
/// are what GDAL's `GetDescription()` and `GetUnitType()` return.
fn gdal_metadata(bands: &[Band<'_>]) -> Option<String> {
    let mut xml = String::from("<GDALMetadata>\n");
    let mut any = false;
    for (i, band) in bands.iter().enumerate() {
        for (name, value) in band.metadata {
            any = true;
            xml.push_str(&format!(
                "  <Item name=\"{name}\" sample=\"{i}\">{}</Item>\n",
                xml_escape(value)
            ));
        }
        for (name, role, text) in [
            ("DESCRIPTION", "description", band.description),
            ("UNITTYPE", "unittype", band.unit),
        ] {
            let text = xml_escape(text);
            if text.is_empty() {
                continue;
            }
            any = true;
            xml.push_str(&format!(
                "  <Item name=\"{name}\" sample=\"{i}\" role=\"{role}\">{text}</Item>\n"
            ));
        }
    }
    xml.push_str("</GDALMetadata>");
    any.then_some(xml)
}

/// The `GDAL_NODATA` text: `nan`, `inf`, `-inf` as GDAL writes them,
/// otherwise the shortest decimal that reads back as exactly `v`.
fn format_nodata(v: f64) -> String {
    if v.is_nan() {
        "nan".to_string()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_string()
    } else if v != 0.0 && !(1e-4..1e16).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The IFD (entry table, the next-IFD pointer `next`, then the values
/// that do not fit an entry, 8-byte aligned) for an IFD at byte
/// `ifd_offset`.
fn serialize_ifd(entries: &[Entry], big: bool, ifd_offset: u64, next: u64) -> io::Result<Vec<u8>> {
    let (count_len, entry_len, inline) = if big { (8, 20, 8) } else { (2, 12, 4) };
    let next_len = inline;
    let table_len = count_len + entries.len() * entry_len + next_len;
    let mut table = Vec::with_capacity(table_len);
    let mut values: Vec<u8> = Vec::new();
    let put = |buf: &mut Vec<u8>, v: u64| -> io::Result<()> {
        if big {
            buf.extend_from_slice(&v.to_le_bytes());
        } else {
            let v = u32::try_from(v).map_err(|_| too_large())?;
            buf.extend_from_slice(&v.to_le_bytes());
        }
        Ok(())
    };
    let n = len_u64(entries.len())?;
    if big {
        table.extend_from_slice(&n.to_le_bytes());
    } else {
        let n = u16::try_from(n).map_err(|_| too_large())?;
        table.extend_from_slice(&n.to_le_bytes());
    }
    let values_start = ifd_offset + len_u64(table_len)?;
    for e in entries {
        table.extend_from_slice(&e.tag.to_le_bytes());
        table.extend_from_slice(&e.kind.to_le_bytes());
        put(&mut table, e.count)?;
        if e.bytes.len() <= inline {
            table.extend_from_slice(&e.bytes);
            table.resize(table.len() + inline - e.bytes.len(), 0);
        } else {
            let misalign = (values_start + len_u64(values.len())?) % 8;
            if misalign != 0 {
                values.resize(values.len() + (8 - misalign) as usize, 0);
            }
            put(&mut table, values_start + len_u64(values.len())?)?;
            values.extend_from_slice(&e.bytes);
        }
    }
    put(&mut table, next)?;
    debug_assert_eq!(table.len(), table_len);
    table.extend_from_slice(&values);
    Ok(table)
}

#[cfg(test)]
mod tests {
    use std::io::{Cursor, SeekFrom};

    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::tags::Tag;

    use super::*;
    use crate::terrain::{DemLimits, geotiff_pages, read_dem, read_geotiff_page_band};

    fn utm33() -> Crs {
        Crs {
            epsg: 32633,
            name: "WGS 84 / UTM zone 33N".to_string(),
            geographic: false,
            proj4: String::new(),
        }
    }

    fn wgs84() -> Crs {
        Crs {
            epsg: 4326,
            name: "WGS 84".to_string(),
            geographic: true,
            proj4: String::new(),
        }
    }

    fn north_up(origin_x: f64, origin_y: f64, res_x: f64, res_y: f64) -> GeoTransform {
        GeoTransform {
            origin_x,
            pixel_width: res_x,
            row_rotation: 0.0,
            origin_y,
            col_rotation: 0.0,
            pixel_height: -res_y,
        }
    }

    fn write(
        w: usize,
        h: usize,
        t: &GeoTransform,
        crs: &Crs,
        pages: &[Page<'_>],
        opts: Options,
    ) -> io::Result<Vec<u8>> {
        let mut cur = Cursor::new(Vec::new());
        let raster = Raster {
            width: w,
            height: h,
            transform: t,
            crs,
            pages,
        };
        write_raster(&mut cur, &raster, opts)?;
        Ok(cur.into_inner())
    }

    fn page<'a>(bands: &'a [Band<'a>], nodata: Option<f64>) -> Page<'a> {
        Page { bands, nodata }
    }

    fn small_strips() -> Options {
        Options {
            strip_target_bytes: 100,
            force_bigtiff: false,
        }
    }

    /// A cost-like band: NaN on a diagonal, otherwise distinct values.
    fn cost_band(w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                if c == r {
                    f32::NAN
                } else {
                    1.0 + (i as f32) * 0.25
                }
            })
            .collect()
    }

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// The cells of every band of page `page` (0-based), decoded with the
    /// `tiff` crate strip by strip, as f32 (exact for Byte samples), and
    /// whether they were Byte.
    fn decode_page(bytes: &[u8], page: usize) -> (Vec<Vec<f32>>, bool) {
        let mut d = Decoder::new(Cursor::new(bytes)).unwrap();
        d.seek_to_image(page).unwrap();
        let (w, h) = d.dimensions().unwrap();
        let (n, bits) = match d.colortype().unwrap() {
            tiff::ColorType::Gray(bits) => (1, bits),
            tiff::ColorType::Multiband {
                bit_depth,
                num_samples,
            } => (usize::from(num_samples), bit_depth),
            other => panic!("unexpected colour type {other:?}"),
        };
        let strips = d.strip_count().unwrap() as usize;
        assert_eq!(strips % n, 0);
        let per_band = strips / n;
        let mut bands = vec![Vec::new(); n];
        let mut byte = None;
        for (b, band) in bands.iter_mut().enumerate() {
            for s in 0..per_band {
                match d.read_chunk((b * per_band + s) as u32).unwrap() {
                    DecodingResult::F32(v) => {
                        assert!(byte != Some(true) && bits == 32);
                        byte = Some(false);
                        band.extend(v);
                    }
                    DecodingResult::U8(v) => {
                        assert!(byte != Some(false) && bits == 8);
                        byte = Some(true);
                        band.extend(v.into_iter().map(f32::from));
                    }
                    _ => panic!("neither Float32 nor Byte"),
                }
            }
            assert_eq!(band.len(), (w * h) as usize);
        }
        (bands, byte.unwrap())
    }

    fn decoder_at(bytes: &[u8], page: usize) -> Decoder<Cursor<&[u8]>> {
        let mut d = Decoder::new(Cursor::new(bytes)).unwrap();
        d.seek_to_image(page).unwrap();
        d
    }

    fn ascii_tag(bytes: &[u8], page: usize, tag: u16) -> Option<String> {
        decoder_at(bytes, page)
            .find_tag(Tag::Unknown(tag))
            .unwrap()
            .map(|v| v.into_string().unwrap())
    }

    fn u16_tag(bytes: &[u8], page: usize, tag: u16) -> Vec<u16> {
        decoder_at(bytes, page)
            .get_tag_u16_vec(Tag::Unknown(tag))
            .unwrap()
    }

    #[test]
    fn projected_single_band_round_trips_through_read_dem() {
        let (w, h) = (37, 23);
        let cost = cost_band(w, h);
        let t = north_up(500_000.0, 5_000_000.0, 0.5, 0.25);
        let page = Page {
            bands: &[Band::new("cost", "cost", BandData::F32(&cost))],
            nodata: Some(f64::NAN),
        };
        let bytes = write(w, h, &t, &utm33(), &[page], small_strips()).unwrap();
        assert_eq!(&bytes[..4], b"II*\0");

        let dem = read_dem(&bytes, Some("x.tif"), None, &DemLimits::default()).unwrap();
        assert_eq!((dem.width, dem.height), (w, h));
        assert_eq!(dem.transform, t);
        assert_eq!(dem.crs.epsg, 32633);
        assert!(!dem.crs.geographic);
        assert!(dem.nodata.is_some_and(f64::is_nan));
        for (i, (&got, &want)) in dem.values.iter().zip(&cost).enumerate() {
            if want.is_nan() {
                assert!(got.is_nan(), "cell {i}: {got}");
            } else {
                assert_eq!(got, f64::from(want), "cell {i}");
            }
        }
        assert_eq!(ascii_tag(&bytes, 0, GDAL_NODATA).as_deref(), Some("nan"));
        assert_eq!(geotiff_pages(&bytes, 10).unwrap().len(), 1);
        // Many strips, the last one partial.
        let mut d = decoder_at(&bytes, 0);
        assert_eq!(d.get_tag_u32(Tag::RowsPerStrip).unwrap(), 1);
        assert_eq!(d.strip_count().unwrap(), 23);
        assert!(!d.more_images());
    }

    #[test]
    fn geographic_byte_page_round_trips_with_numeric_nodata() {
        let (w, h) = (10, 7);
        let class: Vec<u8> = (0..w * h).map(|i| (i % 5) as u8 * 50).collect();
        let t = north_up(14.25, 50.5, 1.0 / 3600.0, 1.0 / 3600.0);
        let page = Page {
            bands: &[Band::new("class", "", BandData::U8(&class))],
            nodata: Some(200.0),
        };
        // 200 is nodata: those cells come back as NaN.
        let bytes = write(w, h, &t, &wgs84(), &[page], Options::default()).unwrap();
        let dem = read_dem(&bytes, Some("x.tif"), None, &DemLimits::default()).unwrap();
        assert_eq!(dem.transform, t);
        assert_eq!(dem.crs.epsg, 4326);
        assert!(dem.crs.geographic);
        assert_eq!(dem.nodata, Some(200.0));
        for (&got, &want) in dem.values.iter().zip(&class) {
            if want == 200 {
                assert!(got.is_nan());
            } else {
                assert_eq!(got, f64::from(want));
            }
        }
        assert_eq!(ascii_tag(&bytes, 0, GDAL_NODATA).as_deref(), Some("200"));
        assert_eq!(u16_tag(&bytes, 0, BITS_PER_SAMPLE), vec![8]);
        assert_eq!(u16_tag(&bytes, 0, SAMPLE_FORMAT), vec![1]);
        // One byte a cell.
        let (bands, byte) = decode_page(&bytes, 0);
        assert!(byte);
        assert!(
            bands[0]
                .iter()
                .zip(&class)
                .all(|(&a, &b)| a == f32::from(b))
        );
        assert_eq!(
            u16_tag(&bytes, 0, GEO_KEY_DIRECTORY),
            vec![
                1, 1, 0, 4, 1024, 0, 1, 2, 1025, 0, 1, 1, 1026, 34737, 7, 0, 2048, 0, 1, 4326
            ]
        );
        assert_eq!(
            ascii_tag(&bytes, 0, GEO_ASCII_PARAMS).as_deref(),
            Some("WGS 84|")
        );
        // A description and no unit: only the description is written.
        assert_eq!(
            ascii_tag(&bytes, 0, GDAL_METADATA).as_deref(),
            Some(
                "<GDALMetadata>\n  <Item name=\"DESCRIPTION\" sample=\"0\" \
                 role=\"description\">class</Item>\n</GDALMetadata>"
            )
        );
        // One strip holds the whole small image.
        assert_eq!(decoder_at(&bytes, 0).strip_count().unwrap(), 1);
    }

    #[test]
    fn two_float_bands_decode_with_the_tiff_crate() {
        let (w, h) = (41, 19);
        let cost = cost_band(w, h);
        let slope: Vec<f32> = (0..w * h).map(|i| (i % 90) as f32 * 0.5).collect();
        let t = north_up(600_000.0, 4_000_000.0, 2.0, 2.0);
        let page = Page {
            bands: &[
                Band::new("cost", "cost", BandData::F32(&cost)),
                Band::new("slope", "deg", BandData::F32(&slope)),
            ],
            nodata: Some(f64::NAN),
        };
        let opts = Options {
            strip_target_bytes: 3 * w * 4,
            force_bigtiff: false,
        };
        let bytes = write(w, h, &t, &utm33(), &[page], opts).unwrap();
        let (got, byte) = decode_page(&bytes, 0);
        assert!(!byte);
        assert_eq!(got.len(), 2);
        assert!(got[0].iter().zip(&cost).all(|(&a, &b)| same(a, b)));
        assert!(got[1].iter().zip(&slope).all(|(&a, &b)| same(a, b)));

        let mut d = decoder_at(&bytes, 0);
        assert_eq!(d.get_tag_u32(Tag::PlanarConfiguration).unwrap(), 2);
        assert_eq!(d.get_tag_u16_vec(Tag::SampleFormat).unwrap(), vec![3, 3]);
        assert_eq!(d.get_tag_u16_vec(Tag::BitsPerSample).unwrap(), vec![32, 32]);
        assert_eq!(d.get_tag_u16_vec(Tag::ExtraSamples).unwrap(), vec![0]);
        assert_eq!(d.get_tag_u32(Tag::RowsPerStrip).unwrap(), 3);
        // 7 strips per band, the last one a single row.
        assert_eq!(d.strip_count().unwrap(), 14);
        let counts = d.get_tag_u64_vec(Tag::StripByteCounts).unwrap();
        assert_eq!(counts[6], (w * 4) as u64);
        assert_eq!(
            d.get_tag_f64_vec(Tag::ModelPixelScaleTag).unwrap(),
            vec![2.0, 2.0, 0.0]
        );
        assert_eq!(
            d.get_tag_f64_vec(Tag::ModelTiepointTag).unwrap(),
            vec![0.0, 0.0, 0.0, 600_000.0, 4_000_000.0, 0.0]
        );
        assert!(d.find_tag(Tag::ModelTransformationTag).unwrap().is_none());
        assert_eq!(
            ascii_tag(&bytes, 0, GDAL_METADATA).as_deref(),
            Some(
                "<GDALMetadata>\n  \
                 <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">cost</Item>\n  \
                 <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">cost</Item>\n  \
                 <Item name=\"DESCRIPTION\" sample=\"1\" role=\"description\">slope</Item>\n  \
                 <Item name=\"UNITTYPE\" sample=\"1\" role=\"unittype\">deg</Item>\n\
                 </GDALMetadata>"
            )
        );
        assert_eq!(
            u16_tag(&bytes, 0, GEO_KEY_DIRECTORY),
            vec![
                1, 1, 0, 4, 1024, 0, 1, 1, 1025, 0, 1, 1, 1026, 34737, 22, 0, 3072, 0, 1, 32633
            ]
        );
        assert_eq!(
            ascii_tag(&bytes, 0, GEO_ASCII_PARAMS).as_deref(),
            Some("WGS 84 / UTM zone 33N|")
        );
    }

    /// A costmap's bands: a Float32 cost band, and a Byte class band with
    /// metadata items.
    fn costmap_bands<'a>(cost: &'a [f32], class: &'a [u8]) -> [[Band<'a>; 1]; 2] {
        const NAMES: &[(&str, &str)] = &[("CLASS_0", "unknown"), ("CLASS_1", "a < b & \"c\"")];
        [
            [Band::new("cost", "cost", BandData::F32(cost))],
            [Band {
                description: "class",
                unit: "",
                metadata: NAMES,
                data: BandData::U8(class),
            }],
        ]
    }

    /// A costmap's pages: the cost with NaN nodata, the class with 0.
    fn costmap_pages<'a>(bands: &'a [[Band<'a>; 1]; 2]) -> [Page<'a>; 2] {
        [
            Page {
                bands: &bands[0],
                nodata: Some(f64::NAN),
            },
            Page {
                bands: &bands[1],
                nodata: Some(0.0),
            },
        ]
    }

    #[test]
    fn float_and_byte_pages_each_with_their_own_type_and_nodata() {
        let (w, h) = (23, 17);
        let cost = cost_band(w, h);
        let class: Vec<u8> = (0..w * h).map(|i| (i * 7 % 6) as u8).collect();
        let t = north_up(500_000.0, 5_000_000.0, 1.0, 1.0);
        let bands = costmap_bands(&cost, &class);
        for opts in [small_strips(), Options::default()] {
            let bytes = write(w, h, &t, &utm33(), &costmap_pages(&bands), opts).unwrap();
            assert_eq!(geotiff_pages(&bytes, 10).unwrap().len(), 2);
            let (got, byte) = decode_page(&bytes, 0);
            assert!(!byte);
            assert!(got[0].iter().zip(&cost).all(|(&a, &b)| same(a, b)));
            let (got, byte) = decode_page(&bytes, 1);
            assert!(byte);
            assert!(got[0].iter().zip(&class).all(|(&a, &b)| a == f32::from(b)));

            assert_eq!(u16_tag(&bytes, 0, SAMPLE_FORMAT), vec![3]);
            assert_eq!(u16_tag(&bytes, 0, BITS_PER_SAMPLE), vec![32]);
            assert_eq!(u16_tag(&bytes, 1, SAMPLE_FORMAT), vec![1]);
            assert_eq!(u16_tag(&bytes, 1, BITS_PER_SAMPLE), vec![8]);
            assert_eq!(ascii_tag(&bytes, 0, GDAL_NODATA).as_deref(), Some("nan"));
            assert_eq!(ascii_tag(&bytes, 1, GDAL_NODATA).as_deref(), Some("0"));
            // Both pages georeferenced alike.
            for tag in [GEO_KEY_DIRECTORY, PHOTOMETRIC] {
                assert_eq!(u16_tag(&bytes, 0, tag), u16_tag(&bytes, 1, tag));
            }
            assert_eq!(
                ascii_tag(&bytes, 1, GDAL_METADATA).as_deref(),
                Some(
                    "<GDALMetadata>\n  \
                     <Item name=\"CLASS_0\" sample=\"0\">unknown</Item>\n  \
                     <Item name=\"CLASS_1\" sample=\"0\">a &lt; b &amp; &quot;c&quot;</Item>\n  \
                     <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">class</Item>\n\
                     </GDALMetadata>"
                )
            );

            // terraplan's reader reads each page with its own nodata.
            let limits = DemLimits::default();
            let c = read_geotiff_page_band(&bytes, 1, 1, None, &limits).unwrap();
            let k = read_geotiff_page_band(&bytes, 2, 1, None, &limits).unwrap();
            assert!(c.nodata.is_some_and(f64::is_nan));
            assert_eq!(k.nodata, Some(0.0));
            for dem in [&c, &k] {
                assert_eq!((dem.transform, dem.crs.epsg), (t, 32633));
            }
            for i in 0..w * h {
                assert!(same(c.values[i] as f32, cost[i]), "cost {i}");
                let want = if class[i] == 0 {
                    f64::NAN
                } else {
                    f64::from(class[i])
                };
                assert!(same(k.values[i] as f32, want as f32), "class {i}");
            }
        }
        // Byte data after Float32 data: 4 bytes a cell, then 1, with the
        // page starts 8-byte aligned.
        let bytes = write(
            w,
            h,
            &t,
            &utm33(),
            &costmap_pages(&bands),
            Options::default(),
        )
        .unwrap();
        let offsets = |page| {
            decoder_at(&bytes, page)
                .get_tag_u64_vec(Tag::StripOffsets)
                .unwrap()
        };
        let (o1, o2) = (offsets(0), offsets(1));
        assert_eq!(o1.len(), 1);
        assert_eq!(o1[0] % 8, 0);
        assert_eq!(o2[0], (o1[0] + (w * h * 4) as u64).next_multiple_of(8));
        assert_eq!(bytes.len() as u64, o2[0] + (w * h) as u64);
    }

    #[test]
    fn rotated_and_south_up_rasters_use_model_transformation() {
        let (w, h) = (5, 4);
        let v: Vec<f32> = (0..w * h).map(|i| i as f32).collect();
        let page = Page {
            bands: &[Band::new("", "", BandData::F32(&v))],
            nodata: None,
        };
        let rotated = GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 0.8,
            row_rotation: 0.6,
            origin_y: 5_000_000.0,
            col_rotation: 0.6,
            pixel_height: -0.8,
        };
        let south_up = north_up(500_000.0, 4_000_000.0, 1.0, -1.0);
        for t in [rotated, south_up] {
            let bytes = write(w, h, &t, &utm33(), &[page], Options::default()).unwrap();
            let dem = read_dem(&bytes, Some("x.tif"), None, &DemLimits::default()).unwrap();
            assert_eq!(dem.transform, t);
            assert_eq!(dem.nodata, None);
            let mut d = decoder_at(&bytes, 0);
            assert!(d.find_tag(Tag::ModelPixelScaleTag).unwrap().is_none());
            let m = d.get_tag_f64_vec(Tag::ModelTransformationTag).unwrap();
            assert_eq!(m.len(), 16);
            assert_eq!(m[15], 1.0);
            // No descriptions, units or nodata: no GDAL tags.
            assert_eq!(ascii_tag(&bytes, 0, GDAL_METADATA), None);
            assert_eq!(ascii_tag(&bytes, 0, GDAL_NODATA), None);
        }
    }

    #[test]
    fn bigtiff_is_readable() {
        let (w, h) = (13, 11);
        let cost = cost_band(w, h);
        let class: Vec<u8> = (0..w * h).map(|i| (i % 3) as u8).collect();
        let t = north_up(500_000.0, 5_000_000.0, 1.0, 1.0);
        let opts = Options {
            strip_target_bytes: 2 * w * 4,
            force_bigtiff: true,
        };
        let one = Page {
            bands: &[Band::new("cost", "cost", BandData::F32(&cost))],
            nodata: Some(-9999.0),
        };
        let bytes = write(w, h, &t, &utm33(), &[one], opts).unwrap();
        assert_eq!(&bytes[..4], b"II+\0");
        let dem = read_dem(&bytes, Some("x.tif"), None, &DemLimits::default()).unwrap();
        assert_eq!(dem.transform, t);
        assert_eq!(dem.nodata, Some(-9999.0));
        for (&got, &want) in dem.values.iter().zip(&cost) {
            assert!(same(got as f32, want));
        }

        let bands = costmap_bands(&cost, &class);
        let bytes = write(w, h, &t, &utm33(), &costmap_pages(&bands), opts).unwrap();
        assert_eq!(&bytes[..4], b"II+\0");
        assert_eq!(geotiff_pages(&bytes, 10).unwrap().len(), 2);
        let (got, _) = decode_page(&bytes, 0);
        assert!(got[0].iter().zip(&cost).all(|(&a, &b)| same(a, b)));
        let (got, byte) = decode_page(&bytes, 1);
        assert!(byte);
        assert!(got[0].iter().zip(&class).all(|(&a, &b)| a == f32::from(b)));
        let k = read_geotiff_page_band(&bytes, 2, 1, None, &DemLimits::default()).unwrap();
        assert_eq!(k.values[1], 1.0);
        assert!(k.values[0].is_nan());
    }

    #[test]
    fn classic_tiff_below_4_gib() {
        // 16000 × 16000 × 2 bands of Float32 = 2.048 GB: still classic.
        // Only the head is built, from bands that are never read.
        let t = north_up(0.0, 0.0, 1.0, 1.0);
        let crs = utm33();
        // Whether a classic TIFF holds `pages` (a BigTIFF always does).
        let r = |pages: &[Page<'_>]| -> io::Result<bool> {
            let raster = Raster {
                width: 16_000,
                height: 16_000,
                transform: &t,
                crs: &crs,
                pages,
            };
            let strips: Vec<Strips> = pages
                .iter()
                .map(|p| Strips::new(16_000, 16_000, page_sample(p), STRIP_TARGET_BYTES))
                .collect::<io::Result<_>>()?;
            let classic = layout(&raster, &strips, false)?;
            let big = layout(&raster, &strips, true)?.unwrap();
            assert_eq!(&big.head[..4], b"II+\0");
            if let Some(c) = &classic {
                assert_eq!(&c.head[..4], b"II*\0");
            }
            // Pages' data follow one another, 8-byte aligned.
            for i in 1..pages.len() {
                let prev = &pages[i - 1];
                let len = (prev.bands.len() * 16_000 * 16_000 * page_sample(prev).bytes()) as u64;
                assert_eq!(
                    big.data_starts[i],
                    (big.data_starts[i - 1] + len).next_multiple_of(8)
                );
            }
            Ok(classic.is_some())
        };
        let float = Strips::new(16_000, 16_000, SampleType::Float32, STRIP_TARGET_BYTES).unwrap();
        let byte = Strips::new(16_000, 16_000, SampleType::Byte, STRIP_TARGET_BYTES).unwrap();
        assert_eq!(float.rows_per_strip, 4);
        assert_eq!(byte.rows_per_strip, 16);
        // The head depends on the bands only through their count and type.
        let none: Vec<f32> = Vec::new();
        let b = Band::new("", "", BandData::F32(&none));
        let none8: Vec<u8> = Vec::new();
        let b8 = Band::new("", "", BandData::U8(&none8));
        let (two, four, five) = ([b, b], [b, b, b, b], [b, b, b, b, b]);
        let (one8, three8) = ([b8], [b8, b8, b8]);
        assert!(r(&[page(&two, None)]).unwrap());
        assert!(!r(&[page(&five, None)]).unwrap());
        // 2.048 GB of Float32 + 3 × 256 MB of Byte = 2.816 GB: classic;
        // 4.096 + 0.256 GB: BigTIFF.
        assert!(r(&[page(&two, None), page(&three8, Some(0.0))]).unwrap());
        assert!(!r(&[page(&four, None), page(&one8, Some(0.0))]).unwrap());
    }

    #[test]
    fn bad_input_is_rejected() {
        let t = north_up(0.0, 0.0, 1.0, 1.0);
        let v = vec![0.0f32; 12];
        let bytes = vec![0u8; 12];
        let short = vec![0u8; 11];
        fn err(w: usize, h: usize, pages: &[Page<'_>], t: &GeoTransform, crs: &Crs) -> String {
            let e = write(w, h, t, crs, pages, Options::default()).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::InvalidInput, "{e}");
            e.to_string()
        }
        let good = Band::new("cost", "cost", BandData::F32(&v));
        let class = Band::new("class", "", BandData::U8(&bytes));
        let bad = Band::new("class", "", BandData::U8(&short));
        let crs = utm33();
        let g = [good];
        let gp = page(&g, None);

        let e = err(4, 3, &[gp, page(&[class, bad], None)], &t, &crs);
        assert!(
            e.contains("page 2 band 2") && e.contains("11 values"),
            "{e}"
        );
        let e = err(4, 3, &[page(&[good, class], None)], &t, &crs);
        assert!(
            e.contains("page 1 band 2") && e.contains("Byte") && e.contains("Float32"),
            "{e}"
        );
        let e = err(0, 3, &[gp], &t, &crs);
        assert!(e.contains("0×3"), "{e}");
        let e = err(4, 0, &[gp], &t, &crs);
        assert!(e.contains("4×0"), "{e}");
        let e = err(4, 3, &[], &t, &crs);
        assert!(e.contains("without pages"), "{e}");
        let e = err(4, 3, &[gp, page(&[], None)], &t, &crs);
        assert!(e.contains("page 2 has no bands"), "{e}");
        let many = vec![gp; MAX_PAGES + 1];
        let e = err(4, 3, &many, &t, &crs);
        assert!(e.contains("pages"), "{e}");
        let singular = GeoTransform {
            pixel_width: 0.0,
            ..t
        };
        let e = err(4, 3, &[gp], &singular, &crs);
        assert!(e.contains("geotransform"), "{e}");
        let nan = GeoTransform {
            origin_x: f64::NAN,
            ..t
        };
        err(4, 3, &[gp], &nan, &crs);
        for epsg in [0, 32767, 102_100] {
            let crs = Crs { epsg, ..utm33() };
            let e = err(4, 3, &[gp], &t, &crs);
            assert!(e.contains(&format!("EPSG:{epsg}")), "{e}");
        }
        // Nodata values the page's type cannot hold.
        let e = err(4, 3, &[page(&g, Some(1e39))], &t, &crs);
        assert!(e.contains("nodata") && e.contains("Float32"), "{e}");
        let c = [class];
        for nodata in [f64::NAN, 256.0, -1.0, 1.5, f64::INFINITY] {
            let e = err(4, 3, &[page(&c, Some(nodata))], &t, &crs);
            assert!(e.contains("page 1") && e.contains("Byte"), "{nodata}: {e}");
        }
        for nodata in [0.0, 255.0] {
            write(
                4,
                3,
                &t,
                &crs,
                &[page(&c, Some(nodata))],
                Options::default(),
            )
            .unwrap();
        }
        // Metadata names GDAL would not show as they are.
        for name in ["", "1A", "A B", "A<", "É"] {
            let meta = [(name, "x")];
            let b = Band {
                metadata: &meta,
                ..good
            };
            let e = err(4, 3, &[page(&[b], None)], &t, &crs);
            assert!(e.contains("metadata name"), "{name:?}: {e}");
        }

        // Not at the start of the file.
        let mut cur = Cursor::new(Vec::new());
        cur.seek(SeekFrom::Start(10)).unwrap();
        let e = write_geotiff(&mut cur, 4, 3, &t, &crs, &[gp]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(cur.get_ref().is_empty());
    }

    #[test]
    fn public_entry_point_writes_a_file() {
        let (w, h) = (300, 200);
        let cost = cost_band(w, h);
        let t = north_up(500_000.0, 5_000_000.0, 0.1, 0.1);
        let page = Page {
            bands: &[Band::new("cost", "cost", BandData::F32(&cost))],
            nodata: Some(f64::NAN),
        };
        let mut cur = Cursor::new(Vec::new());
        write_geotiff(&mut cur, w, h, &t, &utm33(), &[page]).unwrap();
        let bytes = cur.into_inner();
        let dem = read_dem(&bytes, Some("x.tif"), None, &DemLimits::default()).unwrap();
        assert_eq!((dem.width, dem.height), (w, h));
        // 300 × 4 bytes a row: 218 rows (≤ 256 KiB) a strip.
        let mut d = decoder_at(&bytes, 0);
        assert_eq!(d.get_tag_u32(Tag::RowsPerStrip).unwrap(), 200);
        assert_eq!(bytes.len() % 4, 0);
    }

    #[test]
    fn nodata_and_descriptions_are_formatted_for_gdal() {
        assert_eq!(format_nodata(f64::NAN), "nan");
        assert_eq!(format_nodata(f64::INFINITY), "inf");
        assert_eq!(format_nodata(f64::NEG_INFINITY), "-inf");
        assert_eq!(format_nodata(-9999.0), "-9999");
        assert_eq!(format_nodata(0.0), "0");
        assert_eq!(format_nodata(255.0), "255");
        assert_eq!(format_nodata(0.1), "0.1");
        for v in [
            f64::from(f32::MIN),
            f64::from(f32::MAX),
            1e-30,
            0.1f32 as f64,
        ] {
            let s = format_nodata(v);
            assert_eq!(s.parse::<f64>().unwrap(), v, "{s}");
        }
        assert_eq!(format_nodata(f64::from(f32::MIN)), "-3.4028234663852886e38");
        assert_eq!(xml_escape("a<b & \"c\"\0"), "a&lt;b &amp; &quot;c&quot;");
        // Units and descriptions are escaped like any text; empty ones and
        // bands without either are left out, keeping the sample numbers.
        let none: Vec<f32> = Vec::new();
        let bands = [
            Band::new("", "", BandData::F32(&none)),
            Band::new("h<", "m & more", BandData::F32(&none)),
        ];
        assert_eq!(
            gdal_metadata(&bands).as_deref(),
            Some(
                "<GDALMetadata>\n  \
                 <Item name=\"DESCRIPTION\" sample=\"1\" role=\"description\">h&lt;</Item>\n  \
                 <Item name=\"UNITTYPE\" sample=\"1\" role=\"unittype\">m &amp; more</Item>\n\
                 </GDALMetadata>"
            )
        );
        assert_eq!(gdal_metadata(&bands[..1]), None);
        assert!(plain_name("CLASS_0") && plain_name("a") && !plain_name("_a"));
    }

    /// A `Write + Seek` that only counts bytes.
    struct Counter(u64);

    impl Write for Counter {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0 += buf.len() as u64;
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Seek for Counter {
        fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
            match pos {
                SeekFrom::Current(0) => Ok(self.0),
                _ => Err(io::Error::other("not seekable")),
            }
        }
    }

    /// `cargo test -p planner-core --release --lib export::geotiff -- --ignored --nocapture`
    #[test]
    #[ignore = "timing, run by hand"]
    fn speed_4000_square_cost_and_class() {
        let n = 4000;
        let cost: Vec<f32> = (0..n * n).map(|i| (i % 1000) as f32).collect();
        let class: Vec<u8> = (0..n * n).map(|i| (i % 6) as u8).collect();
        let t = north_up(0.0, 0.0, 1.0, 1.0);
        let mut out = Counter(0);
        let start = std::time::Instant::now();
        let bands = costmap_bands(&cost, &class);
        write_geotiff(&mut out, n, n, &t, &utm33(), &costmap_pages(&bands)).unwrap();
        eprintln!("{} bytes in {:?}", out.0, start.elapsed());
        assert!(out.0 > 80_000_000);
    }

    /// Writes sample files for checking with GDAL by hand:
    /// `GEOTIFF_SAMPLE_DIR=/tmp cargo test -p planner-core --lib
    /// export::geotiff -- --ignored write_samples_for_gdal`, then
    /// `gdalinfo -stats /tmp/terraplan-{utm,wgs84,rotated,bigtiff}.tif` and
    /// `gdalinfo -json GTIFF_DIR:2:/tmp/terraplan-utm.tif`.
    #[test]
    #[ignore = "writes files for manual GDAL checks"]
    fn write_samples_for_gdal() {
        let Some(dir) = std::env::var_os("GEOTIFF_SAMPLE_DIR") else {
            return;
        };
        let dir = std::path::PathBuf::from(dir);
        let (w, h) = (4000, 4000);
        let cost: Vec<f32> = (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                if c < 100 && r < 100 {
                    f32::NAN
                } else {
                    1.0 + (c + r) as f32 / 8000.0 * 19.0
                }
            })
            .collect();
        let class: Vec<u8> = (0..w * h).map(|i| ((i % w) / 1000) as u8).collect();
        let rotated = GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 0.08,
            row_rotation: 0.06,
            origin_y: 5_000_000.0,
            col_rotation: 0.06,
            pixel_height: -0.08,
        };
        let cases = [
            (
                "utm",
                north_up(500_000.0, 5_000_000.0, 0.1, 0.1),
                utm33(),
                false,
            ),
            ("wgs84", north_up(14.0, 50.0, 1e-6, 1e-6), wgs84(), false),
            ("rotated", rotated, utm33(), false),
            (
                "bigtiff",
                north_up(500_000.0, 5_000_000.0, 0.1, 0.1),
                utm33(),
                true,
            ),
        ];
        let bands = costmap_bands(&cost, &class);
        for (name, t, crs, big) in cases {
            let path = dir.join(format!("terraplan-{name}.tif"));
            let file = io::BufWriter::new(std::fs::File::create(&path).unwrap());
            let start = std::time::Instant::now();
            let opts = Options {
                force_bigtiff: big,
                ..Options::default()
            };
            let raster = Raster {
                width: w,
                height: h,
                transform: &t,
                crs: &crs,
                pages: &costmap_pages(&bands),
            };
            write_raster(file, &raster, opts).unwrap();
            eprintln!("{} in {:?}", path.display(), start.elapsed());
        }
    }
}
