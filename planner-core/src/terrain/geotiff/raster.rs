//! What the GeoTIFF writer is given: pages of bands of one sample type,
//! the raster they make up, and the strip geometry of a page.

use std::io;
use std::ops::Range;

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

    pub(super) fn bytes(self) -> usize {
        match self {
            SampleType::Float32 => 4,
            SampleType::Byte => 1,
        }
    }

    /// (BitsPerSample, SampleFormat).
    pub(super) fn tiff_tags(self) -> (u16, u16) {
        match self {
            // IEEE floating point.
            SampleType::Float32 => (32, 3),
            // Unsigned integer.
            SampleType::Byte => (8, 1),
        }
    }
}

impl BandData<'_> {
    pub(super) fn len(&self) -> usize {
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

    /// The whole band as the file's little-endian samples, without a copy:
    /// on a little-endian machine a band's memory is those bytes already.
    /// `None` elsewhere (then [`BandData::encode`] converts strip by strip).
    pub(super) fn le_bytes(&self) -> Option<&[u8]> {
        if cfg!(target_endian = "big") {
            return None;
        }
        Some(match self {
            // SAFETY: an f32 is 4 initialised bytes without padding, any
            // byte is a valid u8, and u8's alignment (1) divides f32's; the
            // slice covers exactly the band's memory, borrowed as long as
            // the band.
            BandData::F32(v) => unsafe {
                std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(*v))
            },
            BandData::U8(v) => v,
        })
    }

    /// Cells `range` as little-endian samples in `buf` (replacing its
    /// contents).
    pub(super) fn encode(&self, range: Range<usize>, buf: &mut Vec<u8>) -> io::Result<()> {
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

/// The arguments of [`write_geotiff`].
pub(super) struct Raster<'a> {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) transform: &'a GeoTransform,
    pub(super) crs: &'a Crs,
    pub(super) pages: &'a [Page<'a>],
}

pub(super) fn invalid_input(msg: impl Into<String>) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg.into())
}

pub(super) fn too_large() -> io::Error {
    invalid_input("the raster is too large to address")
}

/// Strip geometry of one page, in bytes and rows.
#[derive(Clone, Copy, Debug)]
pub(super) struct Strips {
    pub(super) rows_per_strip: usize,
    pub(super) per_band: usize,
    /// Bytes of one row of one band.
    pub(super) row_bytes: u64,
    /// Bytes of one band.
    pub(super) band_bytes: u64,
}

impl Strips {
    pub(super) fn new(
        width: usize,
        height: usize,
        sample: SampleType,
        target: usize,
    ) -> io::Result<Strips> {
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
    pub(super) fn rows(&self, s: usize, height: usize) -> Range<usize> {
        let start = s * self.rows_per_strip;
        start..(start + self.rows_per_strip).min(height)
    }
}

/// A page's sample type (its bands share it; checked by `validate`).
pub(super) fn page_sample(page: &Page<'_>) -> SampleType {
    page.bands
        .first()
        .map_or(SampleType::Float32, |b| b.data.sample_type())
}

pub(super) fn len_u64(n: usize) -> io::Result<u64> {
    u64::try_from(n).map_err(|_| too_large())
}
