//! The streaming writer's tiled layout: a GeoTIFF whose image is cut into
//! square tiles (`TileWidth` = `TileLength`, a multiple of 16 as TIFF
//! requires) that are written as they arrive, in row-major tile order,
//! so a raster larger than memory can be written by a computation that
//! makes it a tile at a time (the tiled costmap).
//!
//! The pages, bands and tags are as [`super::write_geotiff`] writes them
//! (uncompressed, `PlanarConfiguration = 2`); only the image data is laid
//! out differently. Uncompressed tiles all have the same size, so every
//! tile's offset is known before the first byte: the header and the IFDs
//! (with their complete `TileOffsets`) are written first, then for each
//! tile in turn every page's every band's tile — strictly sequentially,
//! without seeking. Tiles on the right and bottom edges are padded with
//! zeros to full tiles (readers clip them). A file over 4 GiB is a
//! BigTIFF.

use std::io::{self, Write};

use super::super::raster::{
    BandData, Page, Raster, SampleType, invalid_input, len_u64, page_sample, too_large,
};
use super::super::tags::{TILE_BYTE_COUNTS, TILE_LENGTH, TILE_OFFSETS, TILE_WIDTH};
use super::super::write_ifd::{Entry, image_entries, serialize_ifd};
use super::{align8, validate};
use crate::terrain::{Crs, GeoTransform};

/// A tiled GeoTIFF being written tile by tile.
pub struct TiledGeoTiffWriter<W: Write> {
    out: W,
    width: usize,
    height: usize,
    tile: usize,
    tiles_across: usize,
    tiles: usize,
    /// Every page's bands' sample types, in file order.
    samples: Vec<SampleType>,
    /// The next tile to write.
    next: usize,
    buf: Vec<u8>,
}

impl<W: Write> TiledGeoTiffWriter<W> {
    /// Starts a `width`×`height` GeoTIFF of `tile`×`tile` tiles with
    /// `pages` (as [`super::write_geotiff`]'s; the bands' data are not
    /// read, only their sample type: give empty slices), writing its
    /// header and IFDs to `out` (at the start of the file).
    ///
    /// # Errors
    ///
    /// `InvalidInput` for what [`super::write_geotiff`] refuses (but the
    /// bands' lengths) and a tile side that is 0 or not a multiple of 16;
    /// any error of `out`.
    pub fn new(
        mut out: W,
        width: usize,
        height: usize,
        tile: usize,
        transform: &GeoTransform,
        crs: &Crs,
        pages: &[Page<'_>],
    ) -> io::Result<TiledGeoTiffWriter<W>> {
        let raster = Raster {
            width,
            height,
            transform,
            crs,
            pages,
        };
        validate(&raster, false)?;
        if tile == 0 || !tile.is_multiple_of(16) || u32::try_from(tile).is_err() {
            return Err(invalid_input(format!(
                "tiles of {tile} cells: a TIFF's tiles are a positive multiple of 16 cells"
            )));
        }
        let (tiles_across, tiles_down) = (width.div_ceil(tile), height.div_ceil(tile));
        let tiles = tiles_across.checked_mul(tiles_down).ok_or_else(too_large)?;
        let head = match head(&raster, tile, tiles, false)? {
            Some(h) => h,
            None => head(&raster, tile, tiles, true)?.ok_or_else(too_large)?,
        };
        out.write_all(&head)?;
        let samples = pages
            .iter()
            .flat_map(|p| p.bands.iter().map(move |_| page_sample(p)))
            .collect();
        Ok(TiledGeoTiffWriter {
            out,
            width,
            height,
            tile,
            tiles_across,
            tiles,
            samples,
            next: 0,
            buf: Vec::new(),
        })
    }

    /// The tiles across and down.
    pub fn tiles(&self) -> [usize; 2] {
        [self.tiles_across, self.tiles / self.tiles_across.max(1)]
    }

    /// Writes the next tile (row-major order): `bands` holds every page's
    /// every band, in order, each the tile's cells inside the raster
    /// (row-major, `min(tile, width − col0)` wide).
    pub fn write_tile(&mut self, bands: &[BandData<'_>]) -> io::Result<()> {
        if self.next >= self.tiles {
            return Err(invalid_input(format!(
                "all {} tiles were written already",
                self.tiles
            )));
        }
        let (tx, ty) = (self.next % self.tiles_across, self.next / self.tiles_across);
        let tw = self.tile.min(self.width - tx * self.tile);
        let th = self.tile.min(self.height - ty * self.tile);
        if bands.len() != self.samples.len() {
            return Err(invalid_input(format!(
                "tile {} has {} bands, the file {}",
                self.next,
                bands.len(),
                self.samples.len()
            )));
        }
        for (b, (band, &sample)) in bands.iter().zip(&self.samples).enumerate() {
            if band.sample_type() != sample || band.len() != tw * th {
                return Err(invalid_input(format!(
                    "band {} of tile {} is {} values of {}, expected {tw}×{th} of {}",
                    b + 1,
                    self.next,
                    band.len(),
                    band.sample_type().name(),
                    sample.name()
                )));
            }
        }
        for (band, sample) in bands.iter().zip(&self.samples) {
            let bytes = sample.bytes();
            let pad = (self.tile - tw) * bytes;
            for r in 0..self.tile {
                if r < th {
                    band.encode(r * tw..(r + 1) * tw, &mut self.buf)?;
                    self.buf.resize(self.buf.len() + pad, 0);
                } else {
                    self.buf.clear();
                    self.buf.resize(self.tile * bytes, 0);
                }
                self.out.write_all(&self.buf)?;
            }
        }
        self.next += 1;
        Ok(())
    }

    /// Flushes the file once every tile is written, and gives `out` back.
    pub fn finish(mut self) -> io::Result<W> {
        if self.next != self.tiles {
            return Err(invalid_input(format!(
                "only {} of the {} tiles were written",
                self.next, self.tiles
            )));
        }
        self.out.flush()?;
        Ok(self.out)
    }
}

/// The header and the pages' IFDs, padded to where the tiles start;
/// `None` when a classic TIFF cannot hold the file.
fn head(r: &Raster<'_>, tile: usize, tiles: usize, big: bool) -> io::Result<Option<Vec<u8>>> {
    let header_len: u64 = if big { 16 } else { 8 };
    let cells = len_u64(tile)?
        .checked_mul(len_u64(tile)?)
        .ok_or_else(too_large)?;
    // Bytes of one band's tile, per page; of one tile of every band.
    let band_tile: Vec<u64> = r
        .pages
        .iter()
        .map(|p| cells * len_u64(page_sample(p).bytes()).unwrap_or(4))
        .collect();
    let block = r
        .pages
        .iter()
        .zip(&band_tile)
        .try_fold(0u64, |a, (p, &t)| {
            a.checked_add(t.checked_mul(len_u64(p.bands.len()).ok()?)?)
        })
        .ok_or_else(too_large)?;
    // Where each page's first band's tile sits in a tile's block.
    let mut page_base = Vec::with_capacity(r.pages.len());
    let mut at = 0u64;
    for (p, &t) in r.pages.iter().zip(&band_tile) {
        page_base.push(at);
        at += t * len_u64(p.bands.len())?;
    }
    let entries = |data_start: u64| -> io::Result<Vec<Vec<Entry>>> {
        r.pages
            .iter()
            .enumerate()
            .map(|(i, page)| {
                let mut offsets = Vec::with_capacity(tiles * page.bands.len());
                for b in 0..page.bands.len() {
                    for k in 0..tiles {
                        offsets.push(
                            data_start
                                + len_u64(k)? * block
                                + page_base[i]
                                + len_u64(b)? * band_tile[i],
                        );
                    }
                }
                let counts = vec![band_tile[i]; offsets.len()];
                let side = u32::try_from(tile).map_err(|_| too_large())?;
                let mut e = image_entries(r, page)?;
                e.push(Entry::long(TILE_WIDTH, side));
                e.push(Entry::long(TILE_LENGTH, side));
                e.push(Entry::offsets(TILE_OFFSETS, &offsets, big)?);
                e.push(Entry::offsets(TILE_BYTE_COUNTS, &counts, big)?);
                e.sort_by_key(|e| e.tag);
                Ok(e)
            })
            .collect()
    };
    let total = len_u64(tiles)?.checked_mul(block).ok_or_else(too_large)?;
    if !big && total > u64::from(u32::MAX) {
        return Ok(None);
    }
    // An IFD's size does not depend on the offsets' values: measure with
    // the data at 0, then lay out for real.
    let mut ifd_starts = Vec::with_capacity(r.pages.len());
    let mut at = header_len;
    for page_entries in entries(0)? {
        ifd_starts.push(at);
        let probe = serialize_ifd(&page_entries, big, at, 0)?;
        at = align8(at.checked_add(len_u64(probe.len())?))?;
    }
    let data_start = at;
    if !big
        && data_start
            .checked_add(total)
            .is_none_or(|end| end > u64::from(u32::MAX))
    {
        return Ok(None);
    }
    let mut head = Vec::with_capacity(usize::try_from(data_start).map_err(|_| too_large())?);
    head.extend_from_slice(b"II");
    if big {
        head.extend_from_slice(&43u16.to_le_bytes());
        head.extend_from_slice(&8u16.to_le_bytes());
        head.extend_from_slice(&0u16.to_le_bytes());
        head.extend_from_slice(&header_len.to_le_bytes());
    } else {
        head.extend_from_slice(&42u16.to_le_bytes());
        head.extend_from_slice(&8u32.to_le_bytes());
    }
    for (i, page_entries) in entries(data_start)?.iter().enumerate() {
        let next = ifd_starts.get(i + 1).copied().unwrap_or(0);
        head.extend_from_slice(&serialize_ifd(page_entries, big, ifd_starts[i], next)?);
        head.resize(head.len().next_multiple_of(8), 0);
    }
    head.resize(usize::try_from(data_start).map_err(|_| too_large())?, 0);
    Ok(Some(head))
}

#[cfg(test)]
mod tests {
    use super::super::super::raster::Band;
    use super::*;
    use crate::terrain::geotiff::write_geotiff;
    use crate::terrain::{DemLimits, read_geotiff_page_band};

    fn utm() -> Crs {
        Crs::from_epsg(32633).unwrap()
    }

    fn north_up() -> GeoTransform {
        GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 0.5,
            row_rotation: 0.0,
            origin_y: 4_000_000.0,
            col_rotation: 0.0,
            pixel_height: -0.5,
        }
    }

    /// A tiled file of a cost (with NaN) and a class page, written tile by
    /// tile, read back equal to the strip writer's file by our reader and
    /// the tiff crate.
    #[test]
    fn tiles_read_back_like_the_stripped_file() {
        let names = [("CLASS_1", "traversable")];
        for (w, h, tile) in [(50, 37, 16), (16, 16, 16), (5, 3, 32), (64, 33, 32)] {
            let cost: Vec<f32> = (0..w * h)
                .map(|i| {
                    if i % 7 == 0 {
                        f32::NAN
                    } else {
                        i as f32 * 0.25
                    }
                })
                .collect();
            let class: Vec<u8> = (0..w * h).map(|i| (i % 6) as u8).collect();
            let cost_band = [Band::new("cost", "cost", BandData::F32(&cost))];
            let class_band = [Band {
                description: "class",
                unit: "",
                metadata: &names,
                data: BandData::U8(&class),
            }];
            let pages = [
                Page {
                    bands: &cost_band,
                    nodata: Some(f64::NAN),
                },
                Page {
                    bands: &class_band,
                    nodata: Some(0.0),
                },
            ];
            let mut stripped = io::Cursor::new(Vec::new());
            write_geotiff(&mut stripped, w, h, &north_up(), &utm(), &pages).unwrap();
            let empty_cost = [Band::new("cost", "cost", BandData::F32(&[]))];
            let empty_class = [Band {
                data: BandData::U8(&[]),
                ..class_band[0]
            }];
            let spec = [
                Page {
                    bands: &empty_cost,
                    nodata: Some(f64::NAN),
                },
                Page {
                    bands: &empty_class,
                    nodata: Some(0.0),
                },
            ];
            let mut wr =
                TiledGeoTiffWriter::new(Vec::new(), w, h, tile, &north_up(), &utm(), &spec)
                    .unwrap();
            let [nx, ny] = wr.tiles();
            for ty in 0..ny {
                for tx in 0..nx {
                    let (c0, r0) = (tx * tile, ty * tile);
                    let (tw, th) = (tile.min(w - c0), tile.min(h - r0));
                    let mut tc = Vec::new();
                    let mut tk = Vec::new();
                    for r in r0..r0 + th {
                        tc.extend_from_slice(&cost[r * w + c0..r * w + c0 + tw]);
                        tk.extend_from_slice(&class[r * w + c0..r * w + c0 + tw]);
                    }
                    wr.write_tile(&[BandData::F32(&tc), BandData::U8(&tk)])
                        .unwrap();
                }
            }
            let tiled = wr.finish().unwrap();
            let stripped = stripped.into_inner();
            let limits = DemLimits::default();
            for page in [1, 2] {
                let a = read_geotiff_page_band(&tiled, page, 1, None, &limits).unwrap();
                let b = read_geotiff_page_band(&stripped, page, 1, None, &limits).unwrap();
                assert_eq!((a.width, a.height), (w, h));
                assert_eq!(a.transform, b.transform);
                assert_eq!(a.crs.epsg, 32633);
                assert_eq!(a.nodata.map(f64::to_bits), b.nodata.map(f64::to_bits));
                for (x, y) in a.values.iter().zip(&b.values) {
                    assert_eq!(x.to_bits(), y.to_bits(), "{w}×{h} tile {tile} page {page}");
                }
            }
            // The tiff crate sees tiles of the size asked.
            let mut d = tiff::decoder::Decoder::new(io::Cursor::new(&tiled)).unwrap();
            assert_eq!(d.chunk_dimensions(), (tile as u32, tile as u32));
            assert!(matches!(
                d.read_image().unwrap(),
                tiff::decoder::DecodingResult::F32(_)
            ));
        }
    }

    #[test]
    fn bad_tiles_and_missing_tiles_are_errors_not_files() {
        let cost = [Band::new("cost", "cost", BandData::F32(&[]))];
        let pages = [Page {
            bands: &cost,
            nodata: None,
        }];
        for tile in [0, 20] {
            let e = TiledGeoTiffWriter::new(Vec::new(), 40, 40, tile, &north_up(), &utm(), &pages)
                .err()
                .unwrap();
            assert!(e.to_string().contains("multiple of 16"), "{e}");
        }
        let mut wr =
            TiledGeoTiffWriter::new(Vec::new(), 40, 20, 32, &north_up(), &utm(), &pages).unwrap();
        assert_eq!(wr.tiles(), [2, 1]);
        // The first tile is 32 × 20 cells, not 40 × 20.
        let e = wr.write_tile(&[BandData::F32(&[0.0; 800])]).unwrap_err();
        assert!(e.to_string().contains("expected 32×20"), "{e}");
        let e = wr.write_tile(&[BandData::U8(&[0; 640])]).unwrap_err();
        assert!(e.to_string().contains("Float32"), "{e}");
        wr.write_tile(&[BandData::F32(&[1.0; 640])]).unwrap();
        let e = wr.finish().unwrap_err();
        assert!(e.to_string().contains("only 1 of the 2 tiles"), "{e}");
    }
}
