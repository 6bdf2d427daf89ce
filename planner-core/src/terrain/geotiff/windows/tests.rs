use super::*;
use crate::terrain::geotiff::read::tests::{Builder, V, encode_f32_chunk, encoded, geokeys};
use crate::terrain::geotiff::tags::*;
use crate::terrain::{Dem, read_dem, read_geotiff_page_band};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use tiff::encoder::{Compression, DeflateLevel};
use tiff::tags::Predictor;

/// The shared real-world DEMs (`../shared/data/dems` beside the
/// repository; `TERRAPLAN_SHARED_DATA` overrides the data folder).
fn shared_dems() -> PathBuf {
    std::env::var("TERRAPLAN_SHARED_DATA").map_or_else(
        |_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/dems"),
        |d| PathBuf::from(d).join("dems"),
    )
}

/// `bytes` written to a file of their own, opened as windows (the name is
/// removed at once: the open file stays readable).
fn open_bytes(bytes: &[u8]) -> Result<GeoTiffWindows, TerrainError> {
    open_bytes_band(bytes, None, None)
}

fn open_bytes_band(
    bytes: &[u8],
    page_band: Option<(usize, usize)>,
    crs: Option<u32>,
) -> Result<GeoTiffWindows, TerrainError> {
    static N: AtomicUsize = AtomicUsize::new(0);
    let path = std::env::temp_dir().join(format!(
        "terraplan-geotiff-windows-{}-{}.tif",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::write(&path, bytes).unwrap();
    let file = File::open(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    match page_band {
        None => GeoTiffWindows::open(file, crs, &DemLimits::default()),
        Some((p, b)) => GeoTiffWindows::open_band(file, p, b, crs, &DemLimits::default()),
    }
}

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 33) as usize % n.max(1)
    }
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Random windows (and the whole raster, and single cells at the
/// corners) of `w` equal the cells of `dem`.
fn assert_windows_equal<R: ReadAt>(w: &GeoTiffWindows<R>, dem: &Dem, windows: usize, what: &str) {
    let g = w.grid();
    assert_eq!((g.width, g.height), (dem.width, dem.height), "{what}");
    assert_eq!(g.transform, dem.transform, "{what}");
    assert_eq!(g.crs, dem.crs, "{what}");
    assert_eq!(
        g.nodata.map(f64::to_bits),
        dem.nodata.map(f64::to_bits),
        "{what}"
    );
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ dem.width as u64);
    let check = |c0: usize, r0: usize, ww: usize, hh: usize| {
        let mut out = vec![-1.0; ww * hh];
        w.read_window(c0, r0, ww, hh, &mut out)
            .unwrap_or_else(|e| panic!("{what}: window {c0},{r0} {ww}x{hh}: {e}"));
        for r in 0..hh {
            for c in 0..ww {
                let want = dem.values[(r0 + r) * dem.width + c0 + c];
                let got = out[r * ww + c];
                assert!(
                    same(got, want),
                    "{what}: cell ({}, {}) is {got}, read_dem says {want}",
                    c0 + c,
                    r0 + r
                );
            }
        }
    };
    check(0, 0, dem.width, dem.height);
    check(dem.width - 1, dem.height - 1, 1, 1);
    check(0, dem.height - 1, 1, 1);
    check(dem.width - 1, 0, 1, 1);
    for _ in 0..windows {
        let c0 = rng.below(dem.width);
        let r0 = rng.below(dem.height);
        let ww = 1 + rng.below((dem.width - c0).min(600));
        let hh = 1 + rng.below((dem.height - r0).min(600));
        check(c0, r0, ww, hh);
    }
}

/// Bytes in memory read at most `most` at a time.
struct ShortReads {
    bytes: Vec<u8>,
    most: usize,
}

impl ReadAt for ShortReads {
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize> {
        let n = buf.len().min(self.most);
        self.bytes.read_at(offset, &mut buf[..n])
    }

    fn size(&self) -> io::Result<u64> {
        self.bytes.size()
    }
}

#[test]
fn every_shared_dem_reads_as_read_dem_reads_it() {
    let dir = shared_dems();
    let mut tested = 0;
    for entry in std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("shared DEMs {} are missing: {e}", dir.display()))
    {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("tif") {
            continue;
        }
        let bytes = std::fs::read(&path).unwrap();
        // A DEM without a CRS is read with one given, by both readers.
        let crs = match read_dem(&bytes, None, None, &DemLimits::default()) {
            Err(TerrainError::UnknownCrs(_)) => Some(32633),
            _ => None,
        };
        let dem = read_dem(&bytes, None, crs, &DemLimits::default()).unwrap();
        let file = File::open(&path).unwrap();
        let w = GeoTiffWindows::open(file, crs, &DemLimits::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_windows_equal(&w, &dem, 40, &path.display().to_string());
        // The same bytes from another source of positioned reads, one
        // that answers a few bytes at a time (as a reader over stored
        // chunks stops at a chunk's end).
        let short = ShortReads { bytes, most: 4093 };
        let w = GeoTiffWindows::open(short, crs, &DemLimits::default())
            .unwrap_or_else(|e| panic!("{} by short reads: {e}", path.display()));
        assert_windows_equal(&w, &dem, 10, &format!("{} by short reads", path.display()));
        tested += 1;
    }
    assert!(
        tested >= 5,
        "only {tested} shared GeoTIFFs in {}",
        dir.display()
    );
}

/// The first shared DEM's cells, as f32, cropped to `w`×`h`: real terrain
/// (with its nodata) for the layout variants.
fn shared_cells(w: usize, h: usize) -> Vec<f32> {
    let path = shared_dems().join("whitebox-tools__DEM.tif");
    let dem = read_dem(
        &std::fs::read(&path).unwrap(),
        None,
        Some(32633),
        &DemLimits::default(),
    )
    .unwrap();
    assert!(dem.width >= w && dem.height >= h);
    let mut v = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            v.push(dem.values[y * dem.width + x] as f32);
        }
    }
    // Holes of nodata, a few in every chunk.
    for i in (0..v.len()).step_by(97) {
        v[i] = f32::NAN;
    }
    v
}

#[derive(Clone, Copy, Debug)]
enum Layout {
    Strips(usize),
    Tiles(usize, usize),
}

/// A Float32 GeoTIFF of `cells` (`w`×`h`, NaN for nodata written as
/// -9999) in `layout`, with a predictor (1, 2, 3) and a compression
/// (1, 5, 8, 32773).
fn f32_variant(
    cells: &[f32],
    (w, h): (usize, usize),
    layout: Layout,
    predictor: u16,
    compression: u16,
) -> Vec<u8> {
    use tiff::encoder::compression::{CompressionAlgorithm, Packbits};
    let (cw, ch, across, down) = match layout {
        Layout::Strips(rps) => (w, rps, 1, h.div_ceil(rps)),
        Layout::Tiles(tw, th) => (tw, th, w.div_ceil(tw), h.div_ceil(th)),
    };
    let tiled = matches!(layout, Layout::Tiles(..));
    let mut chunks = Vec::new();
    for i in 0..across * down {
        let (x0, y0) = ((i % across) * cw, (i / across) * ch);
        let rows = if tiled { ch } else { ch.min(h - y0) };
        let value = |x: usize, y: usize, _s: usize| {
            let (gx, gy) = (x0 + x, y0 + y);
            if gx < w && gy < h {
                let v = cells[gy * w + gx];
                if v.is_nan() { -9999.0 } else { v }
            } else {
                0.0
            }
        };
        let chunk = if compression == 32773 {
            let raw = encode_f32_chunk(rows, cw, 1, value, predictor, 1);
            let mut out = Vec::new();
            Packbits.write_to(&mut out, &raw).unwrap();
            out
        } else {
            encode_f32_chunk(rows, cw, 1, value, predictor, compression)
        };
        chunks.push(chunk);
    }
    let b = Builder::image(w as u32, h as u32, 3, 32)
        .tag(COMPRESSION, V::Short(vec![compression]))
        .tag(PREDICTOR, V::Short(vec![predictor]))
        .tag(GDAL_NODATA, V::Ascii("-9999"));
    match layout {
        Layout::Strips(rps) => b.strips(rps as u32, chunks),
        Layout::Tiles(tw, th) => b.tiles(tw as u32, th as u32, chunks),
    }
    .build()
}

#[test]
fn strips_tiles_compressions_and_predictors_read_as_read_dem_reads_them() {
    let (w, h) = (157, 131);
    let cells = shared_cells(w, h);
    let layouts = [
        Layout::Strips(1),
        Layout::Strips(7),
        Layout::Strips(h),
        Layout::Tiles(16, 16),
        Layout::Tiles(32, 48),
        Layout::Tiles(256, 256),
    ];
    for layout in layouts {
        for predictor in [1u16, 2, 3] {
            for compression in [1u16, 5, 8, 32773] {
                let bytes = f32_variant(&cells, (w, h), layout, predictor, compression);
                let what = format!("{layout:?} predictor {predictor} compression {compression}");
                let dem = read_dem(&bytes, None, None, &DemLimits::default())
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                assert!(dem.values.iter().any(|v| v.is_nan()), "{what}: no nodata");
                let windows = open_bytes(&bytes).unwrap_or_else(|e| panic!("{what}: {e}"));
                assert_eq!(windows.sample_type_name(), "Float32");
                assert!(windows.exact_in_f32());
                assert_windows_equal(&windows, &dem, 12, &what);
            }
        }
    }
}

#[test]
fn int16_strips_of_every_compression_and_bigtiff() {
    for (name, compression) in [
        ("none", Compression::Uncompressed),
        ("LZW", Compression::Lzw),
        ("Deflate", Compression::Deflate(DeflateLevel::default())),
        ("PackBits", Compression::Packbits),
    ] {
        for predictor in [Predictor::None, Predictor::Horizontal] {
            for big in [false, true] {
                let bytes = encoded(compression, predictor, big);
                let what = format!("{name} {predictor:?} big {big}");
                // Its corners are not degrees: read as UTM.
                let dem = read_dem(&bytes, None, Some(32633), &DemLimits::default()).unwrap();
                let windows = open_bytes_band(&bytes, None, Some(32633))
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                assert_eq!(windows.sample_type_name(), "Int16");
                assert!(windows.exact_in_f32());
                assert_windows_equal(&windows, &dem, 30, &what);
            }
        }
    }
}

#[test]
fn other_sample_types_and_big_endian() {
    let (w, h) = (21usize, 13usize);
    let value = |x: usize, y: usize| (y * 31 + x * 7) as i64 - 100;
    // (SampleFormat, bits, bytes of a value in the file's order)
    type Encode = fn(i64, bool) -> Vec<u8>;
    let types: [(u16, u16, Encode, &str, bool); 5] = [
        (1, 8, |v, _| vec![(v + 100) as u8], "Byte", true),
        (
            1,
            16,
            |v, le| to_order(&((v + 100) as u16).to_le_bytes(), le),
            "UInt16",
            true,
        ),
        (
            2,
            32,
            |v, le| to_order(&(v as i32).to_le_bytes(), le),
            "Int32",
            false,
        ),
        (
            1,
            32,
            |v, le| to_order(&((v + 100) as u32).to_le_bytes(), le),
            "UInt32",
            false,
        ),
        (
            3,
            64,
            |v, le| to_order(&(v as f64 * 0.25).to_le_bytes(), le),
            "Float64",
            false,
        ),
    ];
    for (format, bits, enc, name, exact) in types {
        for le in [true, false] {
            let mut chunk = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    chunk.extend(enc(value(x, y), le));
                }
            }
            let mut b = Builder::image(w as u32, h as u32, format, bits)
                .tag(GDAL_NODATA, V::Ascii("3"))
                .strips(h as u32, vec![chunk]);
            b.le = le;
            let bytes = b.build();
            let dem = read_dem(&bytes, None, None, &DemLimits::default()).unwrap();
            let windows = open_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(windows.sample_type_name(), name);
            assert_eq!(windows.exact_in_f32(), exact, "{name}");
            assert_windows_equal(&windows, &dem, 20, name);
        }
    }
}

fn to_order(le_bytes: &[u8], le: bool) -> Vec<u8> {
    let mut v = le_bytes.to_vec();
    if !le {
        v.reverse();
    }
    v
}

#[test]
fn bands_of_a_multiband_file_read_as_read_geotiff_page_band_reads_them() {
    use crate::terrain::geotiff::read::tests::multiband_f32;
    for planar in [false, true] {
        for tiled in [false, true] {
            let chunks = if tiled {
                crate::terrain::geotiff::read::tests::Chunks::Tiles(16, 16)
            } else {
                crate::terrain::geotiff::read::tests::Chunks::Strips(3)
            };
            let bytes = multiband_f32((19, 21, 3), planar, chunks, 2, 8);
            for band in 1..=3 {
                let what = format!("planar {planar} tiled {tiled} band {band}");
                let dem = read_geotiff_page_band(&bytes, 1, band, None, &DemLimits::default())
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                let windows = open_bytes_band(&bytes, Some((1, band)), None)
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                assert_windows_equal(&windows, &dem, 20, &what);
            }
            // A DEM has one band.
            let e = open_bytes(&bytes).err().expect("three bands read as a DEM");
            assert!(e.to_string().contains("single band"), "{e}");
            let e = open_bytes_band(&bytes, Some((1, 4)), None)
                .err()
                .expect("band 4");
            assert!(e.to_string().contains("band 4 does not exist"), "{e}");
            let e = open_bytes_band(&bytes, Some((2, 1)), None)
                .err()
                .expect("page 2");
            assert!(e.to_string().contains("page 2 does not exist"), "{e}");
        }
    }
}

#[test]
fn windows_are_read_from_several_threads_at_once() {
    let (w, h) = (157, 131);
    let cells = shared_cells(w, h);
    let bytes = f32_variant(&cells, (w, h), Layout::Tiles(16, 16), 3, 5);
    let dem = read_dem(&bytes, None, None, &DemLimits::default()).unwrap();
    let windows = open_bytes(&bytes).unwrap();
    std::thread::scope(|s| {
        for t in 0..4 {
            let (windows, dem) = (&windows, &dem);
            s.spawn(move || {
                for k in 0..20 {
                    let (c0, r0) = ((t * 13 + k * 7) % (w - 20), (t * 11 + k * 5) % (h - 20));
                    let mut out = vec![0.0; 20 * 20];
                    windows.read_window(c0, r0, 20, 20, &mut out).unwrap();
                    for r in 0..20 {
                        for c in 0..20 {
                            let want = dem.values[(r0 + r) * w + c0 + c];
                            assert!(same(out[r * 20 + c], want));
                        }
                    }
                }
            });
        }
    });
}

#[test]
fn windows_outside_the_raster_are_errors() {
    let bytes = encoded(Compression::Lzw, Predictor::Horizontal, false);
    let windows = open_bytes_band(&bytes, None, Some(32633)).unwrap();
    let mut out = vec![0.0; 4];
    assert!(windows.read_window(36, 0, 2, 2, &mut out).is_err());
    assert!(windows.read_window(0, usize::MAX, 2, 2, &mut out).is_err());
    assert!(windows.read_window(0, 0, 2, 3, &mut out).is_err());
    windows.read_window(37, 23, 0, 0, &mut []).unwrap();
}

/// Opens `bytes` and reads every cell: an error (never a panic) is
/// `Err`.
fn open_and_read_all(bytes: &[u8]) -> Result<(), TerrainError> {
    let w = open_bytes_band(bytes, None, Some(32633))?;
    let (gw, gh) = (w.grid().width, w.grid().height);
    let mut out = vec![0.0; gw * gh];
    w.read_window(0, 0, gw, gh, &mut out)
}

#[test]
fn every_truncation_is_an_error_not_a_panic() {
    let (w, h) = (40, 30);
    let cells = shared_cells(w, h);
    for bytes in [
        encoded(Compression::Lzw, Predictor::Horizontal, false),
        encoded(
            Compression::Deflate(DeflateLevel::default()),
            Predictor::None,
            true,
        ),
        f32_variant(&cells, (w, h), Layout::Tiles(16, 16), 3, 8),
        f32_variant(&cells, (w, h), Layout::Strips(4), 2, 5),
    ] {
        assert!(open_and_read_all(&bytes).is_ok());
        for len in 0..bytes.len() {
            assert!(
                open_and_read_all(&bytes[..len]).is_err(),
                "a prefix of {len} of {} bytes read",
                bytes.len()
            );
        }
    }
}

#[test]
fn hostile_headers_are_errors_without_large_allocations() {
    let strip = |v: &[i16]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let base = || Builder::image(3, 3, 2, 16).strips(3, vec![strip(&[1, 2, 3, 4, 5, 6, 7, 8, 9])]);
    assert!(open_and_read_all(&base().build()).is_ok());
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "offset past the end",
            base().tag(STRIP_OFFSETS, V::Long(vec![1 << 30])).build(),
            "past the end of the file",
        ),
        (
            "huge byte count",
            base()
                .tag(STRIP_BYTE_COUNTS, V::Long(vec![u32::MAX]))
                .build(),
            "past the end of the file",
        ),
        (
            "zero-sized tiles",
            Builder::image(3, 3, 2, 16)
                .tiles(0, 0, vec![strip(&[1; 9])])
                .build(),
            "tiles are 0×0",
        ),
        (
            "a huge image",
            Builder::image(1_000_000, 1_000_000, 2, 16)
                .strips(1, vec![])
                .tag(STRIP_OFFSETS, V::Long(vec![8]))
                .tag(STRIP_BYTE_COUNTS, V::Long(vec![2]))
                .build(),
            "over the limit",
        ),
        (
            "one strip of 60000×1000 Float64 (480 MB decoded)",
            Builder::image(60_000, 1000, 3, 64)
                .strips(1000, vec![vec![0; 64]])
                .build(),
            "rewrite it tiled",
        ),
        (
            "the IFD offset past the end",
            {
                let mut b = base().build();
                b[4..8].copy_from_slice(&(1u32 << 31).to_le_bytes());
                b
            },
            "outside the file",
        ),
        (
            "an IFD that claims every entry",
            {
                let mut b = base().build();
                let at = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
                b[at..at + 2].copy_from_slice(&u16::MAX.to_le_bytes());
                b
            },
            "claims 65535 entries, more than the 4096",
        ),
        (
            "an IFD whose entries run past the end",
            {
                let mut b = base().build();
                let at = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
                b[at..at + 2].copy_from_slice(&4000u16.to_le_bytes());
                b
            },
            "truncated",
        ),
        ("not a TIFF", b"GIF89a and more".to_vec(), "not a TIFF file"),
        ("empty", Vec::new(), "it is empty"),
    ];
    for (what, bytes, says) in cases {
        let e = open_and_read_all(&bytes)
            .err()
            .unwrap_or_else(|| panic!("{what} read"));
        assert!(e.to_string().contains(says), "{what}: {e}");
    }

    // A byte count that lies inside the file but is far more than the
    // chunk can take compressed: refused at open.
    let mut pad = strip(&[1, 2, 3, 4, 5, 6, 7, 8, 9]);
    pad.resize(100_000, 0);
    let e = open_and_read_all(
        &Builder::image(3, 3, 2, 16)
            .tag(COMPRESSION, V::Short(vec![8]))
            .strips(3, vec![pad])
            .build(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("header is corrupt"), "{e}");

    // Garbage in place of a Deflate stream: an error when read.
    let windows = open_bytes(
        &Builder::image(3, 3, 2, 16)
            .tag(COMPRESSION, V::Short(vec![8]))
            .strips(3, vec![vec![0xff; 12]])
            .build(),
    )
    .unwrap();
    let mut out = vec![0.0; 9];
    let e = windows.read_window(0, 0, 3, 3, &mut out).unwrap_err();
    assert!(e.to_string().contains("strip 0 of 1"), "{e}");
}

#[test]
fn geographic_crs_needs_degrees_and_pages_loop() {
    // UTM-like coordinates declared geographic (EPSG:4326).
    let bytes = Builder::image(3, 3, 2, 16)
        .tag(
            GEO_KEY_DIRECTORY,
            V::Short(geokeys(&[(1024, 2), (2048, 4326)])),
        )
        .strips(3, vec![vec![0; 18]])
        .build();
    let e = open_bytes(&bytes).err().expect("read");
    assert!(matches!(e, TerrainError::Crs(_)), "{e}");
    // The IFD's next pointer points at itself: page 2 is a loop.
    let mut b = Builder::image(3, 3, 2, 16)
        .strips(3, vec![vec![0; 18]])
        .build();
    let at = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes(b[at..at + 2].try_into().unwrap()) as usize;
    let next = at + 2 + n * 12;
    b[next..next + 4].copy_from_slice(&(at as u32).to_le_bytes());
    let e = open_bytes_band(&b, Some((5, 1)), None)
        .err()
        .expect("page 5");
    assert!(e.to_string().contains("loop"), "{e}");
}

#[test]
fn the_cache_keeps_at_most_its_budget_and_the_newest_chunk() {
    let mut c = CellCache::new(CACHE_BYTES);
    let chunk = CACHE_BYTES / 8 / 4;
    for i in 0..10 {
        c.put(i, Arc::new(vec![i as f64; chunk]));
    }
    assert_eq!(c.bytes(), 4 * chunk * 8);
    assert!(c.get(9).is_some() && c.get(6).is_some() && c.get(5).is_none());
    // A chunk larger than the budget is still kept, alone.
    c.put(100, Arc::new(vec![0.0; CACHE_BYTES / 8 + 1]));
    assert_eq!(c.bytes(), (CACHE_BYTES / 8 + 1) * 8);
    assert!(c.get(9).is_none());
    assert!(c.get(100).is_some());
}

#[test]
fn hostile_files_read_as_gdal_reads_them_or_are_refused() {
    use crate::terrain::geotiff::read::tests::{assert_read_as_gdal, gdal_gap_cases};
    for (what, bytes, want) in gdal_gap_cases() {
        let got = open_bytes_band(&bytes, None, Some(32633)).and_then(|w| {
            let (gw, gh) = (w.grid().width, w.grid().height);
            let mut out = vec![0.0; gw * gh];
            w.read_window(0, 0, gw, gh, &mut out).map(|()| out)
        });
        assert_read_as_gdal(what, got, &want);
    }
}
