//! Reading a GeoTIFF page's pixels: strips and tiles decompressed and
//! un-predicted by the `tiff` crate, a row of chunks per task in parallel, into `f64`s,
//! nodata and infinite samples becoming `NaN`.

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};

use rayon::prelude::*;
use tiff::TiffError;
use tiff::decoder::{Decoder, DecodingResult, Limits};

use super::deflate_check::check_deflate_chunk;
use super::header::{Header, NoDataMatch, parse_header};
use super::{invalid, unsupported};
use crate::terrain::common::resolve_crs;
use crate::terrain::{Dem, DemFormat, DemLimits, TerrainError};

pub(super) fn tiff_error(e: TiffError) -> TerrainError {
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
pub(in crate::terrain) fn read(
    bytes: &[u8],
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    read_raster(bytes, 0, None, crs, limits)
}

/// Read band `band` (1-based) of page `page` (1-based) of a GeoTIFF with
/// any number of pages and bands.
pub(in crate::terrain) fn read_band(
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
    // PROJ's answer about the CRS takes milliseconds of one thread: asked
    // while the pixels are decoded; its error still comes first.
    let (crs, pixels) = rayon::join(
        || resolve_crs(h.crs_code.clone(), crs),
        || read_pixels(bytes, &h, page),
    );
    let crs = crs?;
    let (width, height, values) = pixels?;
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

/// The page's cells (width, height, row-major values), nodata `NaN`,
/// scaled to metres.
fn read_pixels(
    bytes: &[u8],
    h: &Header,
    page: usize,
) -> Result<(usize, usize, Vec<f64>), TerrainError> {
    let width = usize::try_from(h.width).map_err(|_| invalid("the TIFF is too wide"))?;
    let height = usize::try_from(h.height).map_err(|_| invalid("the TIFF is too high"))?;
    let n = width
        .checked_mul(height)
        .ok_or_else(|| invalid("the TIFF's pixel count overflows"))?;
    let matcher = NoDataMatch::new(h.nodata, h.sample);
    let mut values = crate::buffer::filled(n, 0.0f64);

    let decoded = catch_unwind(AssertUnwindSafe(|| {
        decode(bytes, h, page, matcher, width, &mut values)
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
    Ok((width, height, values))
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
    let mut dec = open_decoder(bytes, h, page)?;
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

    // Each row of chunks (a strip, or a row of tiles) fills its own rows
    // of the output, so the rows of chunks are decoded in parallel, each
    // thread with a decoder of its own; the first fault in file order is
    // reported, whatever order they were met in.
    let rows_per_chunk = usize::try_from(h.grid.ch).map_err(|_| invalid("the TIFF is too high"))?;
    let band_rows = rows_per_chunk
        .checked_mul(width)
        .ok_or_else(|| invalid("the TIFF's chunks are too large"))?;
    let first_decoder = std::sync::Mutex::new(Some(dec));
    let faults: Vec<Result<(), TerrainError>> = out
        .par_chunks_mut(band_rows.max(1))
        .enumerate()
        .with_min_len(CHUNK_ROWS_PER_TASK)
        .map_init(
            || {
                let reused = first_decoder.lock().ok().and_then(|mut d| d.take());
                reused.or_else(|| open_decoder(bytes, h, page).ok())
            },
            |dec, (cy, rows)| match dec {
                Some(dec) => decode_chunk_row(dec, h, nd, width, cy as u64, rows),
                None => Err(inconsistent()),
            },
        )
        .collect();
    faults.into_iter().collect()
}

/// Chunk rows a parallel task decodes at least (a strip of one row is
/// only a few kilobytes).
const CHUNK_ROWS_PER_TASK: usize = 16;

/// A decoder of `bytes` at page `page`, limited to the sizes `h` declares.
fn open_decoder<'a>(
    bytes: &'a [u8],
    h: &Header,
    page: usize,
) -> Result<Decoder<Cursor<&'a [u8]>>, TerrainError> {
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
    Ok(dec.with_limits(limits))
}

/// Decode the chunks of chunk row `cy` (one strip, or a row of tiles) into
/// `rows`, the output rows they cover (`width` wide).
fn decode_chunk_row(
    dec: &mut Decoder<Cursor<&[u8]>>,
    h: &Header,
    nd: NoDataMatch,
    width: usize,
    cy: u64,
    rows: &mut [f64],
) -> Result<(), TerrainError> {
    let n = h.grid.count();
    let ch = rows.len() / width.max(1);
    for cx in 0..h.grid.across {
        let i = cy * h.grid.across + cx;
        let x0 = cx * h.grid.cw;
        let cw = h.grid.cw.min(h.width - x0);
        let (x0, cw) = (x0 as usize, cw as usize);
        let chunk = h.first_chunk + i;
        let idx = usize::try_from(chunk).map_err(|_| invalid("the TIFF has too many chunks"))?;
        if h.is_sparse(idx) {
            // Sparse chunk: GDAL reads nodata (or 0).
            for r in 0..ch {
                let start = r * width + x0;
                if let Some(row) = rows.get_mut(start..start + cw) {
                    row.fill(nd.fill());
                }
            }
            continue;
        }
        if h.deflate {
            let file: &[u8] = dec.inner().get_ref();
            let compressed = chunk_data(file, h, idx)?;
            let (wanted, most) = h.chunk_bytes(cy);
            check_deflate_chunk(compressed, wanted, most)
                .map_err(|e| invalid(format!("{} {i} of {n}: {e}", h.grid.kind())))?;
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
            rows,
            width,
            (src_width, h.chunk_samples, h.sample_index),
            x0,
            0,
            cw,
            ch,
        )
        .map_err(|e| invalid(format!("{} {i} of {n}: {e}", h.grid.kind())))?;
    }
    Ok(())
}

/// The bytes of chunk `idx` (its index in the offsets), exactly its byte
/// count (inside the file: checked by the header).
fn chunk_data<'a>(bytes: &'a [u8], h: &Header, idx: usize) -> Result<&'a [u8], TerrainError> {
    let (Some(&at), Some(&len)) = (h.offsets.get(idx), h.byte_counts.get(idx)) else {
        return Err(invalid("the TIFF has too many chunks"));
    };
    usize::try_from(at)
        .ok()
        .zip(usize::try_from(len).ok())
        .and_then(|(at, len)| bytes.get(at..at.checked_add(len)?))
        .ok_or_else(|| invalid("a chunk of the TIFF lies outside the file"))
}

/// A copy of the file whose ImageWidth entry says `new_width` (as a LONG).
fn widen(bytes: &[u8], h: &Header, pos: u64, new_width: u64) -> Result<Vec<u8>, TerrainError> {
    let entry = width_entry(h, new_width)?;
    let mut b = bytes.to_vec();
    usize::try_from(pos)
        .ok()
        .and_then(|at| b.get_mut(at..at.checked_add(entry.len())?))
        .ok_or_else(|| invalid("the TIFF's ImageWidth entry is outside the file"))?
        .copy_from_slice(&entry);
    Ok(b)
}

/// The bytes of an ImageWidth IFD entry saying `new_width` (as a LONG),
/// in the file's byte order and entry size: what `widen` writes over the
/// original entry (the windowed reader lays it over the file as it reads).
pub(super) fn width_entry(h: &Header, new_width: u64) -> Result<Vec<u8>, TerrainError> {
    let value = u32::try_from(new_width).map_err(|_| invalid("the TIFF's tiles are too wide"))?;
    let mut e = Vec::with_capacity(20);
    let (tag, typ) = (super::tags::IMAGE_WIDTH, 4u16);
    if h.le {
        e.extend_from_slice(&tag.to_le_bytes());
        e.extend_from_slice(&typ.to_le_bytes());
    } else {
        e.extend_from_slice(&tag.to_be_bytes());
        e.extend_from_slice(&typ.to_be_bytes());
    }
    match (h.big, h.le) {
        (true, true) => {
            e.extend_from_slice(&1u64.to_le_bytes());
            e.extend_from_slice(&value.to_le_bytes());
            e.extend_from_slice(&[0; 4]);
        }
        (true, false) => {
            e.extend_from_slice(&1u64.to_be_bytes());
            e.extend_from_slice(&value.to_be_bytes());
            e.extend_from_slice(&[0; 4]);
        }
        (false, true) => {
            e.extend_from_slice(&1u32.to_le_bytes());
            e.extend_from_slice(&value.to_le_bytes());
        }
        (false, false) => {
            e.extend_from_slice(&1u32.to_be_bytes());
            e.extend_from_slice(&value.to_be_bytes());
        }
    }
    Ok(e)
}

/// Copy sample `sample` of every pixel of one decoded chunk (`cw`×`ch`
/// pixels of `spp` interleaved samples, rows `src_width` pixels apart)
/// into the output.
#[allow(clippy::too_many_arguments)]
pub(super) fn put_chunk(
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
pub(super) mod tests;
