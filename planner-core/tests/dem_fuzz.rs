//! Fuzzing the DEM readers: real files with random bytes overwritten (in the
//! header and first-IFD regions, and anywhere), bits flipped and random truncation.
//! Every case must end in `Ok` or `Err` — never a panic or a hang — and
//! quickly, with small limits so mutated huge headers are rejected before
//! anything is allocated.
//!
//! The corpus is built at test time from the shared DEMs (see `dem_gdal.rs`
//! for where they are found) plus, when `gdal_translate` is installed, small
//! crops of them in the layouts the shared files lack (tiled LZW with
//! predictor 2, Deflate with predictor 3, BigTIFF PackBits, big-endian), and
//! a synthetic SRTM .hgt tile.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use planner_core::terrain::{DemLimits, read_dem};
use proptest::prelude::*;
use proptest::test_runner::Config;

mod support;
use support::data_dir;

/// Limits for fuzzing: the corpus fits, mutated headers claiming more are
/// `TooLarge` at once.
const LIMITS: DemLimits = DemLimits {
    max_pixels: 1_500_000,
    max_side: 4096,
};

/// The slowest a single case may be (a hang or a decompression bomb would
/// exceed it by far).
const MAX_CASE_TIME: Duration = Duration::from_secs(5);

/// Bytes at the start of a file where the header/IFD mutations land.
const HEADER_REGION: usize = 4096;

struct Sample {
    name: String,
    bytes: Vec<u8>,
    /// The CRS to give (ASCII grids and local CRSs have none).
    crs: Option<u32>,
}

fn corpus() -> &'static [Sample] {
    static CORPUS: OnceLock<Vec<Sample>> = OnceLock::new();
    CORPUS.get_or_init(build_corpus)
}

fn build_corpus() -> Vec<Sample> {
    let dir = data_dir();
    let mut shared: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list the shared DEMs in {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("tif" | "tiff" | "asc" | "hgt")
            )
        })
        .collect();
    shared.sort();
    let mut out: Vec<Sample> = shared
        .iter()
        .map(|p| Sample {
            name: p.file_name().unwrap().to_string_lossy().into_owned(),
            bytes: std::fs::read(p).unwrap(),
            crs: Some(32613),
        })
        .collect();

    // Small crops in other layouts, if GDAL is there.
    let tmp = std::env::temp_dir().join(format!("terraplan-dem-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let by_name = |part: &str| shared.iter().find(|p| p.to_string_lossy().contains(part));
    let variants: [(&str, &str, &[&str]); 5] = [
        (
            "srtm_ref",
            "tiled_lzw_pred2.tif",
            &[
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=32",
                "-co",
                "BLOCKYSIZE=16",
                "-co",
                "COMPRESS=LZW",
                "-co",
                "PREDICTOR=2",
            ],
        ),
        (
            "elevation_dsm",
            "deflate_pred3.tif",
            &[
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "PREDICTOR=3",
                "-co",
                "BLOCKYSIZE=7",
            ],
        ),
        (
            "codem",
            "bigtiff_packbits.tif",
            &[
                "-co",
                "BIGTIFF=YES",
                "-co",
                "COMPRESS=PACKBITS",
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=16",
                "-co",
                "BLOCKYSIZE=16",
            ],
        ),
        (
            "srtm_ref",
            "bigendian_int32.tif",
            &[
                "-co",
                "ENDIANNESS=BIG",
                "-ot",
                "Int32",
                "-co",
                "COMPRESS=DEFLATE",
            ],
        ),
        ("elevation_dsm", "grid.asc", &["-of", "AAIGrid"]),
    ];
    let mut made = 0;
    for (src, name, args) in variants {
        let (Some(src), out_path) = (by_name(src), tmp.join(name)) else {
            continue;
        };
        let ok = Command::new("gdal_translate")
            .arg("-q")
            .args(["-srcwin", "10", "20", "70", "50"])
            .args(args)
            .arg(src)
            .arg(&out_path)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if ok && let Ok(bytes) = std::fs::read(&out_path) {
            out.push(Sample {
                name: name.into(),
                bytes,
                crs: Some(32613),
            });
            made += 1;
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    if made == 0 {
        eprintln!("gdal_translate not available: fuzzing the shared DEMs only");
    }

    // A synthetic 3" SRTM tile.
    let n = 1201usize;
    let bytes: Vec<u8> = (0..n * n)
        .flat_map(|i| ((i % 3000) as i16 - 500).to_be_bytes())
        .collect();
    out.push(Sample {
        name: "N45E006.hgt".into(),
        bytes,
        crs: None,
    });

    for s in &out {
        // Unmutated, every sample reads.
        read_dem(&s.bytes, Some(&s.name), s.crs, &LIMITS)
            .unwrap_or_else(|e| panic!("corpus file {} does not read: {e}", s.name));
    }
    out
}

/// Where header mutations land: the first `HEADER_REGION` bytes and, for a
/// TIFF whose first IFD is elsewhere (e.g. at the end), the IFD and what
/// follows it. Positions are drawn from the concatenation of the ranges.
fn hot_positions(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut ranges = Vec::with_capacity(2);
    ranges.push(0..bytes.len().min(HEADER_REGION));
    let ifd = match bytes.get(..8) {
        Some([b'I', b'I', 42, 0, a, b, c, d]) => {
            Some(u32::from_le_bytes([*a, *b, *c, *d]) as usize)
        }
        Some([b'M', b'M', 0, 42, a, b, c, d]) => {
            Some(u32::from_be_bytes([*a, *b, *c, *d]) as usize)
        }
        _ => None,
    };
    if let Some(ifd) = ifd
        && ifd >= HEADER_REGION
        && ifd < bytes.len()
    {
        ranges.push(ifd..bytes.len().min(ifd + HEADER_REGION));
    }
    ranges
}

/// The `k`-th hot position (modulo their total).
fn hot(ranges: &[std::ops::Range<usize>], k: usize) -> usize {
    let total: usize = ranges.iter().map(|r| r.len()).sum();
    let mut k = k % total.max(1);
    for r in ranges {
        if k < r.len() {
            return r.start + k;
        }
        k -= r.len();
    }
    0
}

/// Read mutated bytes: must return (the result is irrelevant) and quickly.
fn check(sample: &Sample, bytes: &[u8], with_crs: bool) -> Result<(), TestCaseError> {
    let t = Instant::now();
    let crs = if with_crs { sample.crs } else { None };
    let _ = read_dem(bytes, Some(&sample.name), crs, &LIMITS);
    let dt = t.elapsed();
    prop_assert!(dt < MAX_CASE_TIME, "{}: a case took {dt:?}", sample.name);
    Ok(())
}

/// Cases per property; `TERRAPLAN_FUZZ_SCALE=k` runs k times as many.
fn config(cases: u32) -> Config {
    let scale: u32 = std::env::var("TERRAPLAN_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    Config {
        cases: cases.saturating_mul(scale.max(1)),
        max_shrink_iters: 200,
        ..Config::default()
    }
}

proptest! {
    #![proptest_config(config(40000))]

    /// Random bytes overwritten in the header / IFD region.
    #[test]
    fn header_bytes_overwritten(
        file in any::<usize>(),
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..24),
        with_crs in any::<bool>(),
    ) {
        let s = &corpus()[file % corpus().len()];
        let mut b = s.bytes.clone();
        let hot_ranges = hot_positions(&b);
        for (pos, v) in edits {
            let at = hot(&hot_ranges, pos);
            b[at] = v;
        }
        check(s, &b, with_crs)?;
    }
}

proptest! {
    #![proptest_config(config(16000))]

    /// Bits flipped anywhere (headers, offsets, compressed streams).
    #[test]
    fn bits_flipped_anywhere(
        file in any::<usize>(),
        flips in prop::collection::vec((any::<usize>(), 0u8..8), 1..16),
    ) {
        let s = &corpus()[file % corpus().len()];
        let mut b = s.bytes.clone();
        let len = b.len();
        for (pos, bit) in flips {
            b[pos % len] ^= 1 << bit;
        }
        check(s, &b, true)?;
    }

    /// Random truncation, optionally after header edits.
    #[test]
    fn truncated(
        file in any::<usize>(),
        keep in 0.0f64..1.0,
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 0..6),
    ) {
        let s = &corpus()[file % corpus().len()];
        let mut b = s.bytes.clone();
        let hot_ranges = hot_positions(&b);
        for (pos, v) in edits {
            let at = hot(&hot_ranges, pos);
            b[at] = v;
        }
        b.truncate((b.len() as f64 * keep) as usize);
        check(s, &b, true)?;
    }

    /// Whole 4- or 8-byte fields set to extreme values (offsets, counts,
    /// sizes) in the header region.
    #[test]
    fn extreme_fields(
        file in any::<usize>(),
        fields in prop::collection::vec(
            (any::<usize>(), prop_oneof![
                Just(0u64), Just(1), Just(u64::MAX), Just(u64::from(u32::MAX)),
                Just(1 << 31), Just(0x7FFF), any::<u64>(),
            ], any::<bool>()),
            1..6,
        ),
    ) {
        let s = &corpus()[file % corpus().len()];
        let mut b = s.bytes.clone();
        let hot_ranges = hot_positions(&b);
        for (pos, v, wide) in fields {
            let bytes = v.to_le_bytes();
            let n = if wide { 8 } else { 4 };
            let at = hot(&hot_ranges, pos);
            for (i, byte) in bytes.iter().take(n).enumerate() {
                if let Some(x) = b.get_mut(at + i) {
                    *x = *byte;
                }
            }
        }
        check(s, &b, true)?;
    }
}
