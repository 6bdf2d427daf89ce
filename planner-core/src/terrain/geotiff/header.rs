//! The header of a GeoTIFF page: everything needed to read it (size,
//! sample layout, chunks, georeferencing, CRS, nodata, vertical unit),
//! checked against the limits before any pixel is allocated.

use super::geokeys::GeoKeys;
use super::ifd::{Ifd, TiffBytes, tiff_bytes};
use super::tags::*;
use super::{invalid, unsupported};
use crate::terrain::common::{c_atof, check_limits};
use crate::terrain::{DemLimits, GeoTransform, TerrainError};

/// Sample types terraplan reads; each converts exactly to f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum SampleType {
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
    pub(super) fn from_tags(format: u64, bits: u64) -> Result<SampleType, TerrainError> {
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

    pub(super) fn bytes(self) -> u64 {
        use SampleType::*;
        match self {
            U8 | I8 => 1,
            U16 | I16 => 2,
            U32 | I32 | F32 => 4,
            F64 => 8,
        }
    }

    /// The range of an integer type.
    pub(super) fn int_range(self) -> Option<(f64, f64)> {
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
pub(super) enum NoDataMatch {
    None,
    Int(i64),
    F32(f32),
    F64(f64),
}

impl NoDataMatch {
    pub(super) fn new(nodata: Option<f64>, st: SampleType) -> NoDataMatch {
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
    pub(super) fn fill(self) -> f64 {
        match self {
            NoDataMatch::None => 0.0,
            _ => f64::NAN,
        }
    }
}

/// Strips or tiles, with their count along each axis.
#[derive(Clone, Copy, Debug)]
pub(super) struct ChunkGrid {
    /// Chunk width and height in pixels.
    pub(super) cw: u64,
    pub(super) ch: u64,
    pub(super) across: u64,
    pub(super) down: u64,
    pub(super) tiled: bool,
}

impl ChunkGrid {
    pub(super) fn count(&self) -> u64 {
        self.across * self.down
    }

    pub(super) fn kind(&self) -> &'static str {
        if self.tiled { "tile" } else { "strip" }
    }
}

/// Everything learnt from the header.
pub(super) struct Header {
    pub(super) width: u64,
    pub(super) height: u64,
    pub(super) sample: SampleType,
    pub(super) white_is_zero: bool,
    pub(super) grid: ChunkGrid,
    /// The band read, as the decoder sees it: samples per pixel in a
    /// decoded chunk (SamplesPerPixel for PlanarConfiguration 1, else 1),
    /// the band's index among them, and the index of its first chunk in
    /// the offsets (PlanarConfiguration 2: band b's chunks follow all of
    /// band b−1's). A single-band raster is (1, 0, 0).
    pub(super) chunk_samples: usize,
    pub(super) sample_index: usize,
    /// SamplesPerPixel.
    pub(super) bands: u64,
    pub(super) first_chunk: u64,
    /// Rows the decoder produces for a chunk, at most (see `parse_header`).
    pub(super) decoded_rows: u64,
    /// Deflate-compressed (Compression 8 or 32946): its chunks are checked
    /// whole before they are decoded (see `deflate_check`).
    pub(super) deflate: bool,
    pub(super) offsets: Vec<u64>,
    pub(super) byte_counts: Vec<u64>,
    pub(super) transform: GeoTransform,
    pub(super) crs_code: Result<u32, String>,
    pub(super) nodata: Option<f64>,
    /// Metres per unit of the heights (VerticalUnitsGeoKey; 1 when absent).
    pub(super) vertical_scale: f64,
    /// Where the ImageWidth entry is (to widen a tiled image, see `decode`).
    pub(super) width_entry: Option<u64>,
    pub(super) le: bool,
    pub(super) big: bool,
}

impl Header {
    /// Whether chunk `chunk` (its index in the offsets) is sparse: a byte
    /// count of 0, whatever its offset, reads as nodata (0 if none), as
    /// GDAL reads it.
    pub(super) fn is_sparse(&self, chunk: usize) -> bool {
        self.byte_counts.get(chunk) == Some(&0)
    }

    /// The bytes chunk row `cy`'s chunks hold decoded (a strip cut at the
    /// bottom holds fewer rows), and the bytes of a whole chunk.
    pub(super) fn chunk_bytes(&self, cy: u64) -> (u64, u64) {
        let rows = if self.grid.tiled {
            self.grid.ch
        } else {
            self.grid
                .ch
                .min(self.height.saturating_sub(cy.saturating_mul(self.grid.ch)))
        };
        let row = self
            .grid
            .cw
            .saturating_mul(self.chunk_samples as u64)
            .saturating_mul(self.sample.bytes());
        (row.saturating_mul(rows), row.saturating_mul(self.grid.ch))
    }
}

/// The header of page `page` (0-based) of a GeoTIFF, for reading band
/// `band` (1-based) of it, or with `None` for reading it as a DEM (which
/// must have a single band).
pub(super) fn parse_header(
    bytes: &[u8],
    limits: &DemLimits,
    page: usize,
    band: Option<usize>,
) -> Result<Header, TerrainError> {
    parse_header_of(tiff_bytes(bytes)?, limits, page, band)
}

/// [`parse_header`] of a file seen through `file` (the whole file, or
/// the pieces of a file on disk its header occupies).
pub(super) fn parse_header_of(
    file: TiffBytes<'_>,
    limits: &DemLimits,
    page: usize,
    band: Option<usize>,
) -> Result<Header, TerrainError> {
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
    let sample_index = sample_index(spp, band)?;
    let (sample, planar) = sample_layout(&ifd, spp)?;
    let deflate = check_compression(&ifd, sample)?;
    let white_is_zero = white_is_zero(&ifd, sample, spp)?;
    let (grid, chunk_samples, planes, decoded_rows) = chunk_layout(
        &ifd,
        [width, height],
        (sample, spp, planar, sample_index),
        limits,
    )?;
    let (offsets, byte_counts) = chunk_offsets(&ifd, [width, height], &grid, planes, file.len())?;
    let n = grid.count();
    let (transform, crs_code, nodata, vertical_scale) = georeferencing_and_units(&ifd)?;

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
        deflate,
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

/// The index (from 0) among the `spp` samples of a pixel of band `band`
/// (1-based), or 0 for reading a single-band page as a DEM (`None`).
fn sample_index(spp: u64, band: Option<usize>) -> Result<usize, TerrainError> {
    Ok(match band {
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
    })
}

/// The sample type of a page with `spp` samples per pixel (one for all of
/// them) and whether its bands are stored in separate planes.
fn sample_layout(ifd: &Ifd, spp: u64) -> Result<(SampleType, bool), TerrainError> {
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
    Ok((sample, planar))
}

/// Refuses compressions and predictors the decoder does not undo; whether
/// the page is Deflate-compressed.
fn check_compression(ifd: &Ifd, sample: SampleType) -> Result<bool, TerrainError> {
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
    Ok(matches!(compression, 8 | 32946))
}

/// Whether the page is WhiteIsZero (else MinIsBlack; nothing else is an
/// elevation raster).
fn white_is_zero(ifd: &Ifd, sample: SampleType, spp: u64) -> Result<bool, TerrainError> {
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
    Ok(white_is_zero)
}

/// The page's strips or tiles, the samples per pixel of a decoded chunk,
/// the number of planes and the rows the decoder produces for a chunk; a
/// decoded chunk checked to fit the limits.
fn chunk_layout(
    ifd: &Ifd,
    [width, height]: [u64; 2],
    (sample, spp, planar, sample_index): (SampleType, u64, bool, usize),
    limits: &DemLimits,
) -> Result<(ChunkGrid, u64, u64, u64), TerrainError> {
    let grid = chunk_grid(ifd, width, height)?;
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
    Ok((grid, chunk_samples, planes, decoded_rows))
}

/// The chunks' offsets and byte counts (`planes` sets of the grid's
/// chunks), each chunk checked to lie within the file of `len` bytes.
fn chunk_offsets(
    ifd: &Ifd,
    [width, height]: [u64; 2],
    grid: &ChunkGrid,
    planes: u64,
    len: u64,
) -> Result<(Vec<u64>, Vec<u64>), TerrainError> {
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
    for (i, (&o, &c)) in offsets.iter().zip(&byte_counts).enumerate() {
        if o.checked_add(c).is_none_or(|end| end > len) {
            return Err(invalid(format!(
                "{} {i} of {all} (offset {o}, {c} bytes) extends past the end of the file \
                 ({len} bytes): the file is truncated",
                grid.kind()
            )));
        }
    }
    Ok((offsets, byte_counts))
}

/// The page's transform (PixelIsPoint shifted as GDAL does), its EPSG
/// code or why there is none, its nodata value and the metres per unit of
/// its heights.
#[allow(clippy::type_complexity)]
fn georeferencing_and_units(
    ifd: &Ifd,
) -> Result<(GeoTransform, Result<u32, String>, Option<f64>, f64), TerrainError> {
    let mut transform = georeferencing(ifd)?;
    let keys = GeoKeys::parse(ifd)?;
    if keys.as_ref().and_then(|k| k.short(GT_RASTER_TYPE)) == Some(2) {
        shift_pixel_is_point(&mut transform);
    }
    let crs_code = match &keys {
        Some(k) => k.epsg(),
        None => Err("the TIFF has no GeoKeyDirectory tag, so no coordinate system".to_string()),
    };
    // libtiff reads GDAL_NODATA as ASCII, or as bytes taken for ASCII;
    // GDAL ignores it when it has any other type.
    let nodata = match ifd.entry(GDAL_NODATA) {
        Some(e) if matches!(e.typ, 1 | 2 | 6 | 7) => ifd
            .ascii(GDAL_NODATA)?
            .map(|t| c_atof(t.split('\0').next().unwrap_or("")).0),
        _ => None,
    };
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
    Ok((transform, crs_code, nodata, vertical_scale))
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
