use std::io::{Cursor, SeekFrom};

use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

use super::*;
use crate::terrain::geotiff::raster::{Band, BandData};
use crate::terrain::geotiff::tags::*;
use crate::terrain::geotiff::write_ifd::{format_nodata, gdal_metadata};
use crate::terrain::{DemLimits, geotiff_pages, read_dem, read_geotiff_page_band};
use crate::xml::xml_escape;

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
        strip_by_strip: false,
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
        strip_by_strip: false,
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
fn bands_written_whole_equal_bands_encoded_strip_by_strip() {
    // Two float bands on one page (their planes back to back) and a byte
    // page, in strips of a few rows and a last short strip, classic and
    // BigTIFF: the bytes whichever way the bands go out.
    let (w, h) = (19, 11);
    let cost = cost_band(w, h);
    let other: Vec<f32> = cost.iter().map(|v| -2.5 * v).collect();
    let class: Vec<u8> = (0..w * h).map(|i| (i * 5 % 7) as u8).collect();
    let t = north_up(500_000.0, 5_000_000.0, 1.0, 1.0);
    let floats = [
        Band::new("cost", "cost", BandData::F32(&cost)),
        Band::new("other", "m", BandData::F32(&other)),
    ];
    let bytes = [Band::new("class", "", BandData::U8(&class))];
    let pages = [page(&floats, Some(f64::NAN)), page(&bytes, Some(0.0))];
    for force_bigtiff in [false, true] {
        let opts = |strip_by_strip| Options {
            strip_target_bytes: 3 * w * 4,
            force_bigtiff,
            strip_by_strip,
        };
        let whole = write(w, h, &t, &utm33(), &pages, opts(false)).unwrap();
        let strips = write(w, h, &t, &utm33(), &pages, opts(true)).unwrap();
        assert!(whole == strips, "bigtiff {force_bigtiff}");
        let (got, _) = decode_page(&whole, 0);
        assert!(got[1].iter().zip(&other).all(|(&a, &b)| same(a, b)));
    }
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
        strip_by_strip: false,
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
