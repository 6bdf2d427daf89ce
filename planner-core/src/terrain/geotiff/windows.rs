//! A GeoTIFF read a window at a time ([`GeoTiffWindows`]), from a file on
//! disk or any other source of positioned reads ([`ReadAt`]): the
//! header, IFDs and tag values read with bounded positioned reads, then
//! only the strips or tiles a window touches decoded (by the `tiff` crate,
//! as the in-memory reader decodes them), with a small LRU of decoded
//! chunks so that reading a strip-organised file tile by tile decodes
//! each strip once. Neither the file nor the raster is held in memory.

use std::fs::File;
use std::io::{self, BufReader, Read, Seek, SeekFrom};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Mutex};

use tiff::decoder::{Decoder, Limits};

use super::deflate_check::check_deflate_chunk;
use super::header::{Header, NoDataMatch, SampleType, parse_header_of};
use super::ifd::too_many_entries;
use super::ifd::{MAX_IFD_ENTRIES, tiff_pieces};
use super::read::{put_chunk, tiff_error, width_entry};
use super::tags::type_size;
use super::{invalid, is_tiff, unsupported};
use crate::terrain::common::resolve_crs;
use crate::terrain::read::{check_corners_in_degrees, describe_start};
use crate::terrain::{CellCache, check_window};
use crate::terrain::{DemLimits, RasterGrid, RasterWindows, TerrainError};

mod read_at;
pub use read_at::ReadAt;

/// The largest decoded chunk (a strip or tile, all its samples) read:
/// a file in bigger chunks (e.g. one strip for a whole large image) has
/// to be rewritten tiled to be read a window at a time.
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// Bytes of decoded chunks (as f64 cells) the cache keeps, at least one.
const CACHE_BYTES: usize = 16 << 20;

/// The largest tag value read from the header (e.g. the offsets of
/// 8 M chunks); larger ones are refused.
const MAX_TAG_BYTES: u64 = 64 << 20;

/// A compressed chunk may hold at most this many times its decoded size
/// (plus [`CHUNK_SLACK`]): LZW's worst case is 1.5×, Deflate's and
/// PackBits' less; a larger byte count is a lie of the header.
const EXPANSION: u64 = 2;
const CHUNK_SLACK: u64 = 4096;

/// Reads of the header's pieces (IFDs, tag values) are this large at least,
/// so a small header is one read.
const FIRST_READ: u64 = 64 * 1024;

/// One band of one page of a GeoTIFF file (by default on disk; any
/// [`ReadAt`] source), read a window at a time. Reads from several threads
/// at once (positioned reads on one source; each thread decodes with a
/// decoder of its own, kept for the next read).
pub struct GeoTiffWindows<R: ReadAt = File> {
    file: Arc<R>,
    len: u64,
    page: usize,
    header: Header,
    grid: RasterGrid,
    nodata_match: NoDataMatch,
    /// The ImageWidth entry to lay over the file (its position and bytes),
    /// for tiled images whose width is not a multiple of the tile width
    /// (see `read::decode`).
    width_patch: Option<Arc<(u64, Vec<u8>)>>,
    decoders: Mutex<Vec<Decoder<BufReader<FileReader<R>>>>>,
    cache: Mutex<CellCache<u64>>,
}

impl<R: ReadAt> GeoTiffWindows<R> {
    /// Bytes of decoded chunks (as f64 cells) the windows keep at most.
    pub const CACHE_BYTES: usize = CACHE_BYTES;

    /// Open a single-band GeoTIFF as a DEM (its first page), as
    /// [`crate::terrain::read_dem`] reads it: `crs` overrides or supplies
    /// the CRS, `limits` are checked from the header.
    ///
    /// # Errors
    ///
    /// Everything [`crate::terrain::read_dem`] refuses of a GeoTIFF's
    /// header, a header too large to read, a chunk decoding to more than
    /// [`MAX_CHUNK_BYTES`], and a chunk byte count larger than its decoded
    /// size allows.
    pub fn open(file: R, crs: Option<u32>, limits: &DemLimits) -> Result<Self, TerrainError> {
        Self::open_page_band(file, 0, None, crs, limits)
    }

    /// Open band `band` of page `page` (both numbered from 1), as
    /// [`crate::terrain::read_geotiff_page_band`] reads it.
    ///
    /// # Errors
    ///
    /// As [`GeoTiffWindows::open`], and for a page or band that does not
    /// exist.
    pub fn open_band(
        file: R,
        page: usize,
        band: usize,
        crs: Option<u32>,
        limits: &DemLimits,
    ) -> Result<Self, TerrainError> {
        if page == 0 {
            return Err(invalid("page 0 does not exist: pages are numbered from 1"));
        }
        Self::open_page_band(file, page - 1, Some(band), crs, limits)
    }

    fn open_page_band(
        file: R,
        page: usize,
        band: Option<usize>,
        crs: Option<u32>,
        limits: &DemLimits,
    ) -> Result<Self, TerrainError> {
        let len = file
            .size()
            .map_err(|e| invalid(format!("the TIFF file cannot be read: {e}")))?;
        let pieces = read_header_pieces(&file, len, page)?;
        let header = parse_header_of(tiff_pieces(&pieces, len)?, limits, page, band)?;
        drop(pieces);
        check_chunks(&header)?;
        let crs = resolve_crs(header.crs_code.clone(), crs)?;
        let width = usize::try_from(header.width).map_err(|_| invalid("the TIFF is too wide"))?;
        let height = usize::try_from(header.height).map_err(|_| invalid("the TIFF is too high"))?;
        check_corners_in_degrees(&header.transform, &crs, width, height)?;
        let padded_width = if header.grid.tiled {
            header.grid.across * header.grid.cw
        } else {
            header.width
        };
        let width_patch = match header.width_entry {
            Some(pos) if padded_width != header.width => {
                Some(Arc::new((pos, width_entry(&header, padded_width)?)))
            }
            _ => None,
        };
        let grid = RasterGrid {
            width,
            height,
            transform: header.transform,
            crs,
            nodata: header.nodata,
        };
        let windows = GeoTiffWindows {
            file: Arc::new(file),
            len,
            page,
            nodata_match: NoDataMatch::new(header.nodata, header.sample),
            header,
            grid,
            width_patch,
            decoders: Mutex::new(Vec::new()),
            cache: Mutex::new(CellCache::new(CACHE_BYTES)),
        };
        // The decoder reads the IFD itself: it must agree with ours.
        let dec = windows.new_decoder()?;
        windows.put_decoder(dec);
        Ok(windows)
    }

    /// Every value converts exactly to f32 (samples of at most 16-bit
    /// integers, or Float32, in metres): a copy stored as f32 loses
    /// nothing.
    pub fn exact_in_f32(&self) -> bool {
        matches!(
            self.header.sample,
            SampleType::U8 | SampleType::I8 | SampleType::U16 | SampleType::I16 | SampleType::F32
        ) && self.header.vertical_scale == 1.0
    }

    /// GDAL's name of the file's sample type (`Int16`, `Float32`, …).
    pub fn sample_type_name(&self) -> &'static str {
        match self.header.sample {
            SampleType::U8 => "Byte",
            SampleType::I8 => "Int8",
            SampleType::U16 => "UInt16",
            SampleType::I16 => "Int16",
            SampleType::U32 => "UInt32",
            SampleType::I32 => "Int32",
            SampleType::F32 => "Float32",
            SampleType::F64 => "Float64",
        }
    }

    /// The size of the file's strips or tiles (width, height) in cells:
    /// windows aligned to them decode nothing twice.
    pub fn block_size(&self) -> (usize, usize) {
        let g = &self.header.grid;
        (
            usize::try_from(g.cw.min(self.header.width)).unwrap_or(usize::MAX),
            usize::try_from(g.ch.min(self.header.height)).unwrap_or(usize::MAX),
        )
    }

    fn new_decoder(&self) -> Result<Decoder<BufReader<FileReader<R>>>, TerrainError> {
        let h = &self.header;
        let reader = FileReader {
            file: Arc::clone(&self.file),
            len: self.len,
            pos: 0,
            patch: self.width_patch.clone(),
            chunk: None,
        };
        let inconsistent = || {
            invalid(format!(
                "the TIFF's image directory {} is inconsistent",
                self.page + 1
            ))
        };
        let opened = catch_unwind(AssertUnwindSafe(|| -> Result<_, TerrainError> {
            let mut dec =
                Decoder::new(BufReader::with_capacity(16 * 1024, reader)).map_err(tiff_error)?;
            if self.page > 0 {
                dec.seek_to_image(self.page).map_err(tiff_error)?;
            }
            let mut limits = Limits::default();
            limits.decoding_buffer_size = usize::try_from(decoded_chunk_bytes(h))
                .unwrap_or(usize::MAX)
                .max(1);
            let largest = h.byte_counts.iter().copied().max().unwrap_or(0);
            limits.intermediate_buffer_size = usize::try_from(largest).unwrap_or(usize::MAX).max(1);
            let mut dec = dec.with_limits(limits);
            let (dw, dh) = dec.dimensions().map_err(tiff_error)?;
            let padded = if h.grid.tiled {
                h.grid.across * h.grid.cw
            } else {
                h.width
            };
            if (u64::from(dw), u64::from(dh)) != (padded, h.height) {
                return Err(inconsistent());
            }
            if h.bands > 1 {
                let samples = match dec.colortype().map_err(tiff_error)? {
                    tiff::ColorType::Multiband { num_samples, .. } => u64::from(num_samples),
                    _ => 0,
                };
                if samples != h.bands {
                    return Err(inconsistent());
                }
            }
            Ok(dec)
        }));
        opened.unwrap_or_else(|_| {
            Err(invalid(
                "the TIFF's image directory is corrupt (the decoder failed)",
            ))
        })
    }

    fn take_decoder(&self) -> Result<Decoder<BufReader<FileReader<R>>>, TerrainError> {
        let kept = self.decoders.lock().ok().and_then(|mut d| d.pop());
        match kept {
            Some(d) => Ok(d),
            None => self.new_decoder(),
        }
    }

    fn put_decoder(&self, dec: Decoder<BufReader<FileReader<R>>>) {
        if let Ok(mut d) = self.decoders.lock() {
            // One per thread that reads at once is enough.
            if d.len() < 64 {
                d.push(dec);
            }
        }
    }

    /// The cells of chunk (`cx`, `cy`) of the band read, `cw × ch` of them
    /// (cut at the image's right and bottom), nodata `NaN`, in metres.
    fn chunk(&self, cx: u64, cy: u64) -> Result<Arc<Vec<f64>>, TerrainError> {
        let h = &self.header;
        let i = cy * h.grid.across + cx;
        if let Some(c) = self.cache.lock().ok().and_then(|mut c| c.get(i)) {
            return Ok(c);
        }
        let x0 = cx * h.grid.cw;
        let y0 = cy * h.grid.ch;
        let cw = h.grid.cw.min(h.width - x0) as usize;
        let ch = h.grid.ch.min(h.height - y0) as usize;
        let n = h.grid.count();
        let chunk = h.first_chunk + i;
        let idx = usize::try_from(chunk).map_err(|_| invalid("the TIFF has too many chunks"))?;
        let mut cells = vec![0.0f64; cw * ch];
        if h.is_sparse(idx) {
            // Sparse chunk: GDAL reads nodata (or 0).
            cells.fill(self.nodata_match.fill());
        } else {
            let chunk_index =
                u32::try_from(chunk).map_err(|_| invalid("the TIFF has too many chunks"))?;
            // A Deflate chunk is checked whole, then decoded from the bytes
            // read for the check (not read twice).
            let held = if h.deflate {
                let (Some(&at), Some(&count)) = (h.offsets.get(idx), h.byte_counts.get(idx)) else {
                    return Err(invalid("the TIFF has too many chunks"));
                };
                let compressed = read_piece(&*self.file, at, count, self.len)?;
                let (wanted, most) = h.chunk_bytes(cy);
                check_deflate_chunk(&compressed, wanted, most)
                    .map_err(|e| invalid(format!("{} {i} of {n}: {e}", h.grid.kind())))?;
                Some((at, compressed))
            } else {
                None
            };
            let mut dec = self.take_decoder()?;
            dec.inner().get_mut().chunk = held;
            let decoded = catch_unwind(AssertUnwindSafe(|| {
                dec.read_chunk(chunk_index).map_err(|e| {
                    let e = tiff_error(e);
                    invalid(format!("{} {i} of {n}: {e}", h.grid.kind()))
                })
            }));
            dec.inner().get_mut().chunk = None;
            let res = match decoded {
                Ok(r) => r?,
                Err(_) => {
                    return Err(invalid(format!(
                        "{} {i} of {n}: the TIFF's image data is corrupt (the decoder failed)",
                        h.grid.kind()
                    )));
                }
            };
            self.put_decoder(dec);
            let src_width = if h.grid.tiled { h.grid.cw as usize } else { cw };
            put_chunk(
                res,
                h.white_is_zero,
                self.nodata_match,
                &mut cells,
                cw,
                (src_width, h.chunk_samples, h.sample_index),
                0,
                0,
                cw,
                ch,
            )
            .map_err(|e| invalid(format!("{} {i} of {n}: {e}", h.grid.kind())))?;
            if h.vertical_scale != 1.0 {
                for v in &mut cells {
                    *v *= h.vertical_scale;
                }
            }
        }
        let cells = Arc::new(cells);
        if let Ok(mut c) = self.cache.lock() {
            c.put(i, Arc::clone(&cells));
        }
        Ok(cells)
    }
}

impl<R: ReadAt> RasterWindows for GeoTiffWindows<R> {
    fn grid(&self) -> &RasterGrid {
        &self.grid
    }

    fn read_window(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut [f64],
    ) -> Result<(), TerrainError> {
        check_window(&self.grid, col0, row0, width, height, out.len())?;
        if width == 0 || height == 0 {
            return Ok(());
        }
        let g = self.header.grid;
        let (cw, ch) = (g.cw as usize, g.ch as usize);
        for cy in row0 / ch..=(row0 + height - 1) / ch {
            for cx in col0 / cw..=(col0 + width - 1) / cw {
                let cells = self.chunk(cx as u64, cy as u64)?;
                let (x0, y0) = (cx * cw, cy * ch);
                let chunk_w = cw.min(self.grid.width - x0);
                let chunk_h = ch.min(self.grid.height - y0);
                // The window's part of this chunk, in image coordinates.
                let (xa, xb) = (col0.max(x0), (col0 + width).min(x0 + chunk_w));
                let (ya, yb) = (row0.max(y0), (row0 + height).min(y0 + chunk_h));
                for y in ya..yb {
                    let src = (y - y0) * chunk_w + (xa - x0);
                    let dst = (y - row0) * width + (xa - col0);
                    let (Some(s), Some(d)) = (
                        cells.get(src..src + (xb - xa)),
                        out.get_mut(dst..dst + (xb - xa)),
                    ) else {
                        return Err(invalid("a decoded chunk is smaller than its place"));
                    };
                    d.copy_from_slice(s);
                }
            }
        }
        Ok(())
    }
}

/// Bytes of the largest decoded chunk (all its samples).
fn decoded_chunk_bytes(h: &Header) -> u64 {
    h.grid
        .cw
        .saturating_mul(h.decoded_rows)
        .saturating_mul(h.chunk_samples as u64)
        .saturating_mul(h.sample.bytes())
}

/// Chunks small enough to decode one at a time, and byte counts no
/// larger than their decoded size allows (the offsets and counts already
/// lie inside the file, checked by the header).
fn check_chunks(h: &Header) -> Result<(), TerrainError> {
    let decoded = decoded_chunk_bytes(h);
    if decoded > MAX_CHUNK_BYTES {
        return Err(unsupported(format!(
            "the TIFF's {}×{} {}s take {decoded} bytes each decoded, more than the {} MiB a \
             window reader decodes at once; rewrite it tiled (e.g. gdal_translate -co TILED=YES)",
            h.grid.cw,
            h.grid.ch,
            h.grid.kind(),
            MAX_CHUNK_BYTES >> 20
        )));
    }
    let most = decoded
        .saturating_mul(EXPANSION)
        .saturating_add(CHUNK_SLACK);
    if let Some((i, &c)) = h.byte_counts.iter().enumerate().find(|(_, c)| **c > most) {
        return Err(invalid(format!(
            "{} {i} of the TIFF is {c} bytes long, more than a {}×{} {} of {} can take \
             ({most} bytes): the header is corrupt",
            h.grid.kind(),
            h.grid.cw,
            h.grid.ch,
            h.grid.kind(),
            match h.sample.bytes() {
                1 => "bytes",
                _ => "samples",
            }
        )));
    }
    Ok(())
}

/// Reads `len` bytes at `at` (fewer at the end of the file).
fn read_piece(
    file: &impl ReadAt,
    at: u64,
    len: u64,
    file_len: u64,
) -> Result<Vec<u8>, TerrainError> {
    let len = len.min(file_len.saturating_sub(at));
    let len = usize::try_from(len).map_err(|_| invalid("the TIFF's header is too large"))?;
    let mut buf = vec![0u8; len];
    let mut done = 0;
    while done < len {
        match file.read_at(at + done as u64, &mut buf[done..]) {
            Ok(0) => break,
            Ok(n) => done += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(invalid(format!("the TIFF file cannot be read: {e}"))),
        }
    }
    buf.truncate(done);
    Ok(buf)
}

/// The pieces of the file a page's header occupies: the TIFF header, the
/// IFDs of pages 0..=`page` and the values of page `page`'s entries
/// that do not fit inside them (each at most [`MAX_TAG_BYTES`]; larger
/// ones are left out, and refused if the header needs them).
fn read_header_pieces(
    file: &impl ReadAt,
    len: u64,
    page: usize,
) -> Result<Vec<(u64, Vec<u8>)>, TerrainError> {
    let start = read_piece(file, 0, FIRST_READ, len)?;
    if !is_tiff(&start) {
        return Err(invalid(format!(
            "not a TIFF file: the file starts with {}",
            if start.is_empty() {
                "nothing (it is empty)".to_string()
            } else {
                describe_start(&start)
            }
        )));
    }
    let mut pieces = vec![(0u64, start)];
    let mut ifd = tiff_pieces(&pieces, len)?.first_ifd_offset()?;
    let mut target = ifd;
    let mut seen = std::collections::HashSet::new();
    for k in 0..=page {
        target = ifd;
        if !seen.insert(ifd) {
            break; // a loop: the header names it
        }
        let view = tiff_pieces(&pieces, len)?;
        let big = view.big;
        let (count_len, entry_len, ptr_len) = if big { (8, 20, 8) } else { (2, 12, 4) };
        if view.slice(ifd, count_len).is_none() {
            let piece = read_piece(file, ifd, FIRST_READ, len)?;
            pieces.push((ifd, piece));
        }
        let view = tiff_pieces(&pieces, len)?;
        let n = if big {
            view.u64(ifd)
        } else {
            view.u16(ifd).map(u64::from)
        }
        .ok_or_else(|| view.ifd_outside(ifd))?;
        if n > MAX_IFD_ENTRIES {
            return Err(too_many_entries(ifd, n));
        }
        let table = count_len + n * entry_len + ptr_len;
        if view.slice(ifd, table).is_none() {
            let piece = read_piece(file, ifd, table.max(FIRST_READ), len)?;
            pieces.push((ifd, piece));
        }
        if k == page {
            break;
        }
        let view = tiff_pieces(&pieces, len)?;
        let (n, first, entry_len, _) = view.ifd_table(ifd)?;
        match view.offset(first + n * entry_len) {
            Some(0) | None => break, // the header names the missing page
            Some(next) => ifd = next,
        }
    }
    // The values of the page's entries.
    let view = tiff_pieces(&pieces, len)?;
    let mut wanted = Vec::new();
    for e in view.ifd_entries(target)? {
        let Some(bytes) = type_size(e.typ).and_then(|s| s.checked_mul(e.count)) else {
            continue;
        };
        let inside = e.data.checked_add(bytes).is_some_and(|end| end <= len);
        if bytes == 0 || !inside || bytes > MAX_TAG_BYTES || view.slice(e.data, bytes).is_some() {
            continue;
        }
        wanted.push((e.data, bytes));
    }
    let mut total = 0u64;
    for (at, bytes) in wanted {
        total += bytes;
        if total > MAX_TAG_BYTES {
            return Err(invalid(format!(
                "the TIFF's tag values take more than {} MiB",
                MAX_TAG_BYTES >> 20
            )));
        }
        pieces.push((at, read_piece(file, at, bytes, len)?));
    }
    Ok(pieces)
}

/// The file as the decoder reads it: positioned reads at its own
/// position (so readers on several threads share one file), with the
/// widened ImageWidth entry laid over the original.
struct FileReader<R> {
    file: Arc<R>,
    len: u64,
    pos: u64,
    patch: Option<Arc<(u64, Vec<u8>)>>,
    /// The chunk being decoded, already read (its offset and bytes):
    /// reads inside it are served from it.
    chunk: Option<(u64, Vec<u8>)>,
}

impl<R: ReadAt> Read for FileReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let left = self.len.saturating_sub(self.pos);
        let want = buf.len().min(usize::try_from(left).unwrap_or(usize::MAX));
        if want == 0 {
            return Ok(0);
        }
        let held = self.chunk.as_ref().and_then(|(at, bytes)| {
            let start = usize::try_from(self.pos.checked_sub(*at)?).ok()?;
            bytes.get(start..).filter(|rest| !rest.is_empty())
        });
        let n = match held {
            Some(rest) => {
                let n = want.min(rest.len());
                buf[..n].copy_from_slice(&rest[..n]);
                n
            }
            None => self.file.read_at(self.pos, &mut buf[..want])?,
        };
        if let Some(patch) = &self.patch {
            let (at, bytes) = (patch.0, &patch.1);
            let (a, b) = (self.pos, self.pos + n as u64);
            let (pa, pb) = (at, at + bytes.len() as u64);
            let (lo, hi) = (a.max(pa), b.min(pb));
            for p in lo..hi {
                buf[(p - a) as usize] = bytes[(p - pa) as usize];
            }
        }
        self.pos += n as u64;
        Ok(n)
    }
}

impl<R> Seek for FileReader<R> {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let next = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = next
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "seek before the start"))?;
        Ok(self.pos)
    }
}

#[cfg(test)]
mod tests;
