use super::*;
use crate::terrain::GeoTransform;
use crate::terrain::geotiff::is_tiff;
use crate::terrain::geotiff::tags::*;
use crate::terrain::read_dem;
use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
use tiff::tags::{Predictor, Tag};

/// A tag value for the hand-made TIFFs.
#[derive(Clone, Debug)]
pub(in crate::terrain::geotiff) enum V {
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
pub(in crate::terrain::geotiff) struct Builder {
    pub(in crate::terrain::geotiff) le: bool,
    big: bool,
    tags: Vec<(u16, V)>,
    chunks: Vec<Vec<u8>>,
    tiled: bool,
}

impl Builder {
    pub(in crate::terrain::geotiff) fn new() -> Builder {
        Builder {
            le: true,
            big: false,
            tags: Vec::new(),
            chunks: Vec::new(),
            tiled: false,
        }
    }

    pub(in crate::terrain::geotiff) fn tag(mut self, tag: u16, v: V) -> Builder {
        self.tags.retain(|(t, _)| *t != tag);
        self.tags.push((tag, v));
        self
    }

    /// A north-up single-band image with the usual tags.
    pub(in crate::terrain::geotiff) fn image(
        width: u32,
        height: u32,
        format: u16,
        bits: u16,
    ) -> Builder {
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

    pub(in crate::terrain::geotiff) fn strips(
        mut self,
        rows_per_strip: u32,
        chunks: Vec<Vec<u8>>,
    ) -> Builder {
        self.chunks = chunks;
        self.tiled = false;
        self.tag(ROWS_PER_STRIP, V::Long(vec![rows_per_strip]))
    }

    pub(in crate::terrain::geotiff) fn tiles(
        mut self,
        tw: u32,
        th: u32,
        chunks: Vec<Vec<u8>>,
    ) -> Builder {
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

    pub(in crate::terrain::geotiff) fn build(&self) -> Vec<u8> {
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

pub(in crate::terrain::geotiff) fn geokeys(keys: &[(u16, u16)]) -> Vec<u16> {
    let mut v = vec![1, 1, 0, keys.len() as u16];
    for (k, val) in keys {
        v.extend([*k, 0, 1, *val]);
    }
    v
}

pub(in crate::terrain::geotiff) fn i16_le(v: &[i16]) -> Vec<u8> {
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
                3.0, 4.0, 0.0, 1000.0, 4.0, -3.0, 0.0, 2000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                1.0,
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
pub(in crate::terrain::geotiff) fn encoded(
    compression: Compression,
    predictor: Predictor,
    big: bool,
) -> Vec<u8> {
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
    b[ifd..ifd + 2].copy_from_slice(&4000u16.to_le_bytes());
    assert!(read(&b).unwrap_err().to_string().contains("past the end"));
    // More entries than libtiff reads (4096).
    let mut b = good.clone();
    b[ifd..ifd + 2].copy_from_slice(&u16::MAX.to_le_bytes());
    let e = read(&b).unwrap_err().to_string();
    assert!(
        e.contains("claims 65535 entries, more than the 4096"),
        "{e}"
    );
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
pub(in crate::terrain::geotiff) enum Chunks {
    Strips(usize),
    Tiles(usize, usize),
}

/// Encode one chunk: `rows` rows of `row_px` pixels of `spp`
/// interleaved samples each (`value(x, y, s)`), with a predictor
/// (as libtiff's horDiff32 / fpDiff on a little-endian host) and a
/// compression.
pub(in crate::terrain::geotiff) fn encode_f32_chunk(
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
pub(in crate::terrain::geotiff) fn multiband_f32(
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
    use crate::terrain::geotiff::{Band, BandData, Page, write_geotiff};
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

// ---- Hostile files GDAL reads in its own way (the gaps found by the
// e2e dem_fuzz test): both readers must read them as GDAL does, or refuse. ----

/// What GDAL does with a hand-made file: the cells it reads (nodata
/// `NaN`), or the refusal the reader must give (a part of its message).
pub(in crate::terrain::geotiff) enum GdalReads {
    Cells(Vec<f64>),
    Refused(&'static str),
}

fn zlib(data: &[u8], level: flate2::Compression) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), level);
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

/// One hand-made Int16 file per gap, with what GDAL reads of it.
pub(in crate::terrain::geotiff) fn gdal_gap_cases() -> Vec<(&'static str, Vec<u8>, GdalReads)> {
    let nan = f64::NAN;
    let deflate = |rows: &[i16]| zlib(&i16_le(rows), flate2::Compression::default());
    let deflated = || {
        Builder::image(2, 2, 2, 16)
            .tag(COMPRESSION, V::Short(vec![8]))
            .tag(GDAL_NODATA, V::Ascii("-1"))
    };
    // Noise over a stored (uncompressed) Deflate block's bytes: the stream
    // still inflates to the strip's size, only its checksum tells.
    let mut noisy = zlib(&i16_le(&[6, 7]), flate2::Compression::none());
    noisy[8] ^= 0x5A;
    vec![
        (
            "a byte count of 0 with a real offset is a sparse strip",
            Builder::image(2, 2, 2, 16)
                .tag(GDAL_NODATA, V::Ascii("-1"))
                .strips(1, vec![i16_le(&[4, 5]), i16_le(&[6, 7])])
                .tag(STRIP_BYTE_COUNTS, V::Long(vec![4, 0]))
                .build(),
            GdalReads::Cells(vec![4.0, 5.0, nan, nan]),
        ),
        (
            "a byte count of 0 with a real offset is a sparse tile, 0 without nodata",
            Builder::image(2, 2, 2, 16)
                .tiles(16, 16, vec![i16_le(&[9; 256]); 1])
                .tag(TILE_BYTE_COUNTS, V::Long(vec![0]))
                .build(),
            GdalReads::Cells(vec![0.0; 4]),
        ),
        (
            "a Deflate strip's byte count of 1 cuts its stream",
            {
                let chunks = vec![deflate(&[4, 5]), deflate(&[6, 7])];
                let first = chunks[0].len() as u32;
                deflated()
                    .strips(1, chunks)
                    .tag(STRIP_BYTE_COUNTS, V::Long(vec![first, 1]))
                    .build()
            },
            GdalReads::Refused("strip 1 of 2: its Deflate data"),
        ),
        (
            "a Deflate tile's byte count of 2 cuts its stream",
            Builder::image(2, 2, 2, 16)
                .tag(COMPRESSION, V::Short(vec![8]))
                .tiles(16, 16, vec![deflate(&[3; 256])])
                .tag(TILE_BYTE_COUNTS, V::Long(vec![2]))
                .build(),
            GdalReads::Refused("tile 0 of 1: its Deflate data ends early"),
        ),
        (
            "a width lowered by one on predictor-2 Deflate strips",
            // Strips written 3 cells wide, the header says 2.
            deflated()
                .tag(PREDICTOR, V::Short(vec![2]))
                .strips(1, vec![deflate(&[4, 1, 1]), deflate(&[6, 1, 1])])
                .build(),
            GdalReads::Refused("inflates to more than the 4 bytes it holds"),
        ),
        (
            "noise in Deflate data that still inflates",
            deflated().strips(1, vec![deflate(&[4, 5]), noisy]).build(),
            GdalReads::Refused("strip 1 of 2: its Deflate data is corrupt"),
        ),
        (
            "a Deflate strip that inflates short",
            deflated()
                .strips(1, vec![deflate(&[4, 5]), deflate(&[6])])
                .build(),
            GdalReads::Refused("inflates to 2 bytes, fewer than the 4"),
        ),
        (
            "a GDAL_NODATA tag of type SHORT is ignored",
            Builder::image(2, 1, 2, 16)
                .tag(GDAL_NODATA, V::Raw(3, 1, (-9999i16).to_le_bytes().to_vec()))
                .strips(1, vec![i16_le(&[-9999, 5])])
                .build(),
            GdalReads::Cells(vec![-9999.0, 5.0]),
        ),
        (
            "a GDAL_NODATA tag of type BYTE is read as text",
            Builder::image(2, 1, 2, 16)
                .tag(GDAL_NODATA, V::Raw(1, 4, b"-99\0".to_vec()))
                .strips(1, vec![i16_le(&[-99, 5])])
                .build(),
            GdalReads::Cells(vec![nan, 5.0]),
        ),
        (
            "valid Deflate strips, the last one cut at the bottom",
            Builder::image(2, 3, 2, 16)
                .tag(COMPRESSION, V::Short(vec![8]))
                .tag(PREDICTOR, V::Short(vec![2]))
                .strips(2, vec![deflate(&[4, 1, 6, 1]), deflate(&[8, 1])])
                .build(),
            GdalReads::Cells(vec![4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
        ),
    ]
}

/// `got` (a reader's answer) is what GDAL reads, `want`.
pub(in crate::terrain::geotiff) fn assert_read_as_gdal(
    what: &str,
    got: Result<Vec<f64>, TerrainError>,
    want: &GdalReads,
) {
    match (got, want) {
        (Ok(cells), GdalReads::Cells(want)) => {
            assert_eq!(cells.len(), want.len(), "{what}");
            for (a, b) in cells.iter().zip(want) {
                assert!(a == b || (a.is_nan() && b.is_nan()), "{what}: {cells:?}");
            }
        }
        (Err(e), GdalReads::Refused(says)) => {
            assert!(matches!(e, TerrainError::Invalid(_)), "{what}: {e}");
            assert!(e.to_string().contains(says), "{what}: {e}");
        }
        (Ok(cells), GdalReads::Refused(says)) => panic!("{what}: read {cells:?}, not {says}"),
        (Err(e), GdalReads::Cells(_)) => panic!("{what}: {e}"),
    }
}

#[test]
fn hostile_files_read_as_gdal_reads_them_or_are_refused() {
    for (what, bytes, want) in gdal_gap_cases() {
        assert_read_as_gdal(what, read(&bytes).map(|d| d.values), &want);
    }
}
