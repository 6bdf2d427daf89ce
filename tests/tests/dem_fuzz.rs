//! Hostile GeoTIFF uploads through the real server (issue 22 item 1, "fuzz
//! the tile store and the streamed GeoTIFF reader"): a few hundred
//! seeded mutations of GeoTIFFs GDAL wrote in strips, tiles, compressions,
//! sample types, byte orders and BigTIFF — cut short at random offsets,
//! header and IFD bytes flipped, tag values (sizes, offsets, byte counts,
//! compression, predictor, sample format, bits) set to lies, tile data
//! overwritten with noise, IFDs pointing past the end or at themselves.
//!
//! Every answer is a 2xx (then the file is valid and the DEM's cells read
//! back from its tiles equal GDAL's read of the same bytes) or a 4xx
//! problem+json naming the fault; nothing of a refused upload is left in
//! the database (its DEM, tile set, tiles or upload record); the server
//! never panics (its log is checked) and its peak memory stays within the
//! memory budget given to it, without growth from case to case.

#[path = "support/dem_rows.rs"]
mod dem_rows;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use dem_rows::{DemRows, RowCounter};
use terraplan_e2e::{Server, get, post, run_tool, shared_data};

const MIB: u64 = 1024 * 1024;
/// The server's memory budget (MiB), which bounds its peak growth.
const BUDGET_MB: u64 = 256;
/// Mutations per seed file.
const CASES_PER_SEED: usize = 45;

/// xorshift64*: the same cases every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next() % n }
    }

    fn pick<T: Copy>(&mut self, of: &[T]) -> T {
        of[self.below(of.len() as u64) as usize]
    }
}

/// One IFD entry of a TIFF: where it is and what it holds.
#[derive(Clone, Debug)]
struct Entry {
    tag: u16,
    typ: u16,
    count: u64,
    /// Where the entry starts in the file.
    at: usize,
    /// Where its values are (inline in the entry, or at its offset).
    values_at: usize,
}

/// The first IFD of a classic or BigTIFF file, either byte order.
struct Layout {
    le: bool,
    big: bool,
    /// Where the first IFD's entry count is.
    ifd: usize,
    entries: Vec<Entry>,
}

fn type_size(typ: u16) -> u64 {
    match typ {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 | 16 | 17 | 18 => 8,
        _ => 1,
    }
}

impl Layout {
    fn read(bytes: &[u8]) -> Layout {
        let le = &bytes[..2] == b"II";
        let big = read_uint(bytes, 2, 2, le) == 43;
        let ifd = if big {
            read_uint(bytes, 8, 8, le)
        } else {
            read_uint(bytes, 4, 4, le)
        } as usize;
        let (count_len, entry_len, field) = if big { (8, 20, 8) } else { (2, 12, 4) };
        // (A mutated file's count may be anything: the entries in the file.)
        let n = read_uint(bytes, ifd, count_len, le).min(1000) as usize;
        let mut entries = Vec::new();
        for i in 0..n {
            let at = ifd + count_len + i * entry_len;
            if at + entry_len > bytes.len() {
                break;
            }
            let tag = read_uint(bytes, at, 2, le) as u16;
            let typ = read_uint(bytes, at + 2, 2, le) as u16;
            let count = read_uint(bytes, at + 4, field, le);
            let field_at = at + 4 + field;
            let values_at = if count * type_size(typ) <= field as u64 {
                field_at
            } else {
                read_uint(bytes, field_at, field, le) as usize
            };
            entries.push(Entry {
                tag,
                typ,
                count,
                at,
                values_at,
            });
        }
        Layout {
            le,
            big,
            ifd,
            entries,
        }
    }

    fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries.iter().find(|e| e.tag == tag)
    }

    /// Set value `i` of `e` to `v` (truncated to its type's width).
    fn set(&self, bytes: &mut [u8], e: &Entry, i: u64, v: u64) {
        let size = type_size(e.typ) as usize;
        let at = e.values_at + (i as usize) * size;
        write_uint(bytes, at, size, v, self.le);
    }

    fn value(&self, bytes: &[u8], e: &Entry, i: u64) -> u64 {
        let size = type_size(e.typ) as usize;
        read_uint(bytes, e.values_at + (i as usize) * size, size, self.le)
    }
}

fn read_uint(bytes: &[u8], at: usize, len: usize, le: bool) -> u64 {
    let Some(b) = bytes.get(at..at + len) else {
        return 0;
    };
    let mut v = 0u64;
    for k in 0..len {
        let byte = if le { b[len - 1 - k] } else { b[k] };
        v = (v << 8) | u64::from(byte);
    }
    v
}

fn write_uint(bytes: &mut [u8], at: usize, len: usize, v: u64, le: bool) {
    let Some(b) = bytes.get_mut(at..at + len) else {
        return;
    };
    for k in 0..len {
        let byte = (v >> (8 * k)) as u8;
        if le {
            b[k] = byte;
        } else {
            b[len - 1 - k] = byte;
        }
    }
}

const IMAGE_WIDTH: u16 = 256;
const IMAGE_LENGTH: u16 = 257;
const BITS_PER_SAMPLE: u16 = 258;
const COMPRESSION: u16 = 259;
const STRIP_OFFSETS: u16 = 273;
const SAMPLES_PER_PIXEL: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const STRIP_BYTE_COUNTS: u16 = 279;
const PREDICTOR: u16 = 317;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const TILE_OFFSETS: u16 = 324;
const TILE_BYTE_COUNTS: u16 = 325;
const SAMPLE_FORMAT: u16 = 339;

/// One hostile variant of `seed` and what was done to it.
fn mutate(seed: &[u8], rng: &mut Rng) -> (Vec<u8>, String) {
    let mut b = seed.to_vec();
    let layout = Layout::read(seed);
    let len = b.len() as u64;
    let hostile = |rng: &mut Rng, old: u64| {
        let any = rng.next();
        rng.pick(&[
            0,
            1,
            2,
            old.wrapping_sub(1),
            old + 1,
            old.wrapping_mul(2),
            0x7FFF,
            0xFFFF,
            0xFFFF_FFFF,
            len,
            len + 1,
            any,
        ])
    };
    let offsets = [STRIP_OFFSETS, TILE_OFFSETS];
    let counts = [STRIP_BYTE_COUNTS, TILE_BYTE_COUNTS];
    match rng.below(11) {
        0 => {
            let at = 1 + rng.below(len - 1);
            b.truncate(at as usize);
            (b, format!("cut at {at} of {len}"))
        }
        1 => {
            // Flip bytes in the header and the IFD.
            let end = (layout.ifd as u64 + 8 + layout.entries.len() as u64 * 20).min(len);
            let n = 1 + rng.below(4);
            let mut at = Vec::new();
            for _ in 0..n {
                let i = if rng.below(3) == 0 {
                    rng.below(16.min(len))
                } else {
                    layout.ifd as u64 + rng.below(end - layout.ifd as u64)
                } as usize;
                b[i] ^= 1 << rng.below(8);
                at.push(i);
            }
            (b, format!("bits flipped at {at:?}"))
        }
        2 => {
            // A size or layout tag set to a lie.
            let tags = [
                IMAGE_WIDTH,
                IMAGE_LENGTH,
                ROWS_PER_STRIP,
                TILE_WIDTH,
                TILE_LENGTH,
                SAMPLES_PER_PIXEL,
            ];
            let present: Vec<&Entry> = layout
                .entries
                .iter()
                .filter(|e| tags.contains(&e.tag))
                .collect();
            let e = present[rng.below(present.len() as u64) as usize].clone();
            let old = layout.value(&b, &e, 0);
            let v = hostile(rng, old);
            layout.set(&mut b, &e, 0, v);
            (b, format!("tag {} {old} -> {v}", e.tag))
        }
        3 | 4 => {
            // Offsets or byte counts that lie.
            let which = if rng.below(2) == 0 { offsets } else { counts };
            let Some(e) = which.iter().find_map(|&t| layout.entry(t)).cloned() else {
                return (b, "unchanged".into());
            };
            let n = 1 + rng.below(e.count.min(4));
            let mut done = Vec::new();
            for _ in 0..n {
                let i = rng.below(e.count);
                let old = layout.value(&b, &e, i);
                let v = hostile(rng, old);
                layout.set(&mut b, &e, i, v);
                done.push((i, old, v));
            }
            (b, format!("tag {} entries {done:?}", e.tag))
        }
        5 => {
            // Compression and predictor that do not match the data.
            let mut what = String::new();
            if let Some(e) = layout.entry(COMPRESSION).cloned() {
                let v = rng.pick(&[1, 2, 5, 7, 8, 32773, 32946, 34887, 50000, 9]);
                layout.set(&mut b, &e, 0, v);
                what += &format!("compression {v} ");
            }
            if let Some(e) = layout.entry(PREDICTOR).cloned() {
                let v = rng.pick(&[1, 2, 3, 4, 0xFFFF]);
                layout.set(&mut b, &e, 0, v);
                what += &format!("predictor {v}");
            }
            (b, what)
        }
        6 => {
            // Sample type and width that do not match the data.
            let mut what = String::new();
            if let Some(e) = layout.entry(BITS_PER_SAMPLE).cloned() {
                let v = rng.pick(&[0, 1, 8, 12, 16, 24, 32, 64, 128, 0xFFFF]);
                layout.set(&mut b, &e, 0, v);
                what += &format!("bits {v} ");
            }
            if let Some(e) = layout.entry(SAMPLE_FORMAT).cloned() {
                let v = rng.pick(&[0, 1, 2, 3, 4, 5, 6, 0xFFFF]);
                layout.set(&mut b, &e, 0, v);
                what += &format!("sample format {v}");
            }
            (b, what)
        }
        7 => {
            // Noise over part of the raster's data (after the IFD).
            let start = (layout.ifd + 8 + layout.entries.len() * 20).min(b.len() - 1) as u64;
            let from = start + rng.below(len - start);
            let to = (from + 1 + rng.below(4096)).min(len);
            for i in from..to {
                b[i as usize] = rng.next() as u8;
            }
            (b, format!("noise over {from}..{to}"))
        }
        8 => {
            // The IFD's entry count, or the next IFD, a lie.
            let (count_len, entry_len) = if layout.big { (8, 20) } else { (2, 12) };
            if rng.below(2) == 0 {
                let any = rng.next();
                let v = rng.pick(&[0, 1, 0xFFFF, 0xFFFF_FFFF, any]);
                write_uint(&mut b, layout.ifd, count_len, v, layout.le);
                (b, format!("entry count {v}"))
            } else {
                let next = layout.ifd + count_len + layout.entries.len() * entry_len;
                let any = rng.next();
                let v = rng.pick(&[layout.ifd as u64, len, len + 100, 8, any]);
                write_uint(&mut b, next, count_len.max(4), v, layout.le);
                (b, format!("next IFD at {v}"))
            }
        }
        9 => {
            // An entry's type or count a lie.
            let e = layout.entries[rng.below(layout.entries.len() as u64) as usize].clone();
            let field = if layout.big { 8 } else { 4 };
            if rng.below(2) == 0 {
                let v = rng.pick(&[0, 2, 3, 4, 5, 12, 16, 99, 0xFFFF]);
                write_uint(&mut b, e.at + 2, 2, v, layout.le);
                (b, format!("tag {} type {v}", e.tag))
            } else {
                let any = rng.next();
                let v = rng.pick(&[0, e.count + 1, 0xFFFF_FFFF, 1 << 40, any]);
                write_uint(&mut b, e.at + 4, field, v, layout.le);
                (b, format!("tag {} count {v}", e.tag))
            }
        }
        _ => {
            // Two of the above.
            let (once, a) = mutate(seed, rng);
            if once.len() < 16 {
                return (once, a);
            }
            let saved = once.clone();
            let (twice, c) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                let mut r2 = Rng(rng.next() | 1);
                mutate(&saved, &mut r2)
            }))
            .unwrap_or((once, String::new()));
            (twice, format!("{a}; {c}"))
        }
    }
}

/// GDAL's read of `path` (cells as f64, nodata as NaN), or what GDAL
/// said when it cannot read it.
fn gdal_cells(path: &Path, dir: &Path) -> Result<(usize, usize, Vec<f64>), String> {
    let out = Command::new("gdalinfo")
        .args(["-json", path.to_str().unwrap()])
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).map_err(|e| e.to_string())?;
    let dims = || -> Option<(usize, usize)> {
        Some((
            info["size"][0].as_u64()? as usize,
            info["size"][1].as_u64()? as usize,
        ))
    };
    let (w, h) = dims().ok_or("gdalinfo gave no size")?;
    let nodata = info["bands"][0]["noDataValue"].as_f64();
    let raw = dir.join("gdal.f64");
    let ok = Command::new("gdal_translate")
        .args(["-q", "-ot", "Float64", "-of", "ENVI"])
        .arg(path)
        .arg(&raw)
        .output()
        .map_err(|e| e.to_string())?;
    if !ok.status.success() {
        return Err(String::from_utf8_lossy(&ok.stderr).into_owned());
    }
    let bytes = std::fs::read(&raw).map_err(|e| e.to_string())?;
    if bytes.len() != w * h * 8 {
        return Err(format!("{} bytes read of {w} x {h}", bytes.len()));
    }
    let cells = bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .map(|v| {
            if Some(v) == nodata || !v.is_finite() {
                f64::NAN
            } else {
                v
            }
        })
        .collect();
    Ok((w, h, cells))
}

/// The seed GeoTIFFs: GDAL's layouts of real terrain.
fn seeds(dir: &Path) -> Vec<(&'static str, PathBuf)> {
    let dtm = shared_data("dems/opengeos_data__elevation_dtm.tif"); // Float32 283 × 259
    let dsm64 = shared_data("dems/codem__AOI-DigitalSurfaceModel.tif"); // Float64
    let make: Vec<(&str, &Path, Vec<&str>)> = vec![
        ("Float32 strips of 1 row", &dtm, vec!["-co", "BLOCKYSIZE=1"]),
        (
            "Deflate strips, predictor 2, big-endian",
            &dtm,
            vec![
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "PREDICTOR=2",
                "-co",
                "BLOCKYSIZE=16",
                "-co",
                "ENDIANNESS=BIG",
            ],
        ),
        (
            "LZW tiles of 128, predictor 3, 700 x 600",
            &dtm,
            vec![
                "-outsize",
                "700",
                "600",
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=128",
                "-co",
                "BLOCKYSIZE=128",
                "-co",
                "COMPRESS=LZW",
                "-co",
                "PREDICTOR=3",
            ],
        ),
        (
            "Int16 PackBits tiles",
            &dtm,
            vec![
                "-ot",
                "Int16",
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=64",
                "-co",
                "BLOCKYSIZE=64",
                "-co",
                "COMPRESS=PACKBITS",
            ],
        ),
        (
            "BigTIFF Deflate tiles",
            &dtm,
            vec![
                "-co",
                "BIGTIFF=YES",
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=128",
                "-co",
                "BLOCKYSIZE=128",
                "-co",
                "COMPRESS=DEFLATE",
            ],
        ),
        (
            "Float64 big-endian BigTIFF strips",
            &dsm64,
            vec![
                "-srcwin",
                "0",
                "0",
                "200",
                "150",
                "-co",
                "BIGTIFF=YES",
                "-co",
                "ENDIANNESS=BIG",
                "-co",
                "BLOCKYSIZE=7",
            ],
        ),
        (
            "UInt16 LZW strips",
            &dtm,
            vec![
                "-ot",
                "UInt16",
                "-co",
                "COMPRESS=LZW",
                "-co",
                "BLOCKYSIZE=32",
            ],
        ),
    ];
    make.into_iter()
        .enumerate()
        .map(|(i, (what, src, args))| {
            let dst = dir.join(format!("seed{i}.tif"));
            let mut all = vec!["-q"];
            all.extend_from_slice(&args);
            all.push(src.to_str().unwrap());
            all.push(dst.to_str().unwrap());
            run_tool("gdal_translate", &all, None);
            (what, dst)
        })
        .collect()
}

/// (VmRSS, VmHWM) of process `pid`, bytes.
fn rss(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .unwrap()
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse::<u64>()
            .unwrap()
            * 1024
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Every hostile upload is answered with a 201 or a 4xx problem naming
/// the fault, stores nothing when refused, never panics the server nor
/// grows its memory; a file stored reads back whole from its tiles. Its
/// cells are compared with GDAL's read of the same bytes, and the files
/// where they differ are printed (the test below requires there are none).
#[test]
fn hostile_geotiff_uploads_are_4xx_naming_the_fault_and_store_nothing() {
    let differ = fuzz_uploads();
    eprintln!(
        "{} stored files differ from GDAL's read (see the test below):",
        differ.len()
    );
    for d in &differ {
        eprintln!("  {d}");
    }
}

/// The hostile files the server stores read back as GDAL reads them:
/// the reader honours byte counts (a count of 0 is a sparse chunk, a
/// Deflate chunk must end within its count with a valid checksum and
/// inflate to the chunk's size), refuses an IFD of more than 4096 entries
/// and ignores a `GDAL_NODATA` tag that is not text, as GDAL does.
#[test]
fn hostile_geotiffs_the_server_stores_read_back_as_gdal_reads_them() {
    let differ = fuzz_uploads();
    assert!(
        differ.is_empty(),
        "{} stored DEMs differ from GDAL's read:\n{}",
        differ.len(),
        differ.join("\n")
    );
}

/// Run the hostile uploads (asserting everything but the equality with
/// GDAL's read); the stored files whose cells differ from GDAL's.
fn fuzz_uploads() -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let work = tempfile::tempdir().unwrap();
    let budget = BUDGET_MB.to_string();
    let server = Server::start_logging(
        dir.path(),
        &["--memory-budget-mb", &budget],
        "warn,terraplan=info",
    );
    let pid = server.pid();
    let seeds = seeds(work.path());
    let upload = |bytes: &[u8]| {
        post(
            &server.url("/api/v1/dems?crs=EPSG:32618"),
            "image/tiff",
            bytes,
        )
    };
    // Warm up with the intact seeds: each is stored and reads back as GDAL
    // reads it.
    for (what, path) in &seeds {
        let bytes = std::fs::read(path).unwrap();
        let r = upload(&bytes);
        assert_eq!(r.status, 201, "{what}: {}", r.text());
        let id = r.json()["id"].as_str().unwrap().to_string();
        check_cells(&server, &id, path, work.path(), what).unwrap();
        assert_eq!(
            terraplan_e2e::delete(&server.url(&format!("/api/v1/dems/{id}"))).status,
            204
        );
    }
    let mut rows = RowCounter::new(dir.path());
    assert_eq!(rows.count(), DemRows::NONE);
    let (rss_start, _) = rss(pid);
    std::fs::write(format!("/proc/{pid}/clear_refs"), "5").unwrap();

    let mut rng = Rng(0x7E44_A9F1_0DD5_2026);
    let mut statuses: BTreeMap<u16, usize> = BTreeMap::new();
    let mut faults: BTreeMap<String, usize> = BTreeMap::new();
    let mut stored = 0;
    let mut mismatches = Vec::new();
    let mut rss_midway = 0;
    let total = seeds.len() * CASES_PER_SEED;
    let mut case = 0;
    for (what, path) in &seeds {
        let seed = std::fs::read(path).unwrap();
        for _ in 0..CASES_PER_SEED {
            case += 1;
            if case == total / 2 {
                rss_midway = rss(pid).0;
            }
            let (bytes, how) = mutate(&seed, &mut rng);
            let label = format!("case {case} ({what}: {how})");
            let r = upload(&bytes);
            *statuses.entry(r.status).or_default() += 1;
            match r.status {
                201 => {
                    stored += 1;
                    let dem = r.json();
                    let id = dem["id"].as_str().unwrap().to_string();
                    // It reads back whole from its tiles.
                    let (w, h) = (
                        dem["width"].as_u64().unwrap(),
                        dem["height"].as_u64().unwrap(),
                    );
                    let back = get(&server.url(&format!(
                        "/api/v1/dems/{id}/window?col=0&row=0&width={w}&height={h}"
                    )));
                    assert_eq!(back.status, 200, "{label}: {}", back.text());
                    assert_eq!(back.body.len() as u64, w * h * 8, "{label}");
                    let file = work.path().join("case.tif");
                    std::fs::write(&file, &bytes).unwrap();
                    if let Err(e) = check_cells(&server, &id, &file, work.path(), &label) {
                        mismatches.push(e);
                    }
                    let gone = terraplan_e2e::delete(&server.url(&format!("/api/v1/dems/{id}")));
                    assert_eq!(gone.status, 204, "{label}");
                }
                400 | 413 | 415 | 422 => {
                    assert_eq!(
                        r.header("content-type"),
                        Some("application/problem+json"),
                        "{label}: {}",
                        r.text()
                    );
                    let p = r.json();
                    assert_eq!(p["status"], r.status, "{label}: {p}");
                    let detail = p["detail"].as_str().unwrap_or("");
                    assert!(detail.len() > 20, "{label}: a vague answer {p}");
                    assert!(
                        !detail.contains("database:") && !detail.contains("panic"),
                        "{label}: {p}"
                    );
                    *faults.entry(fault_kind(detail)).or_default() += 1;
                }
                other => panic!("{label}: answered {other}: {}", r.text()),
            }
            let left = rows.count();
            assert_eq!(left, DemRows::NONE, "{label}: left {left:?}");
        }
    }
    let (rss_end, peak) = rss(pid);
    eprintln!("{total} hostile uploads: statuses {statuses:?}, {stored} valid and stored");
    eprintln!("{} distinct faults named:", faults.len());
    for (kind, n) in &faults {
        eprintln!("  {n:4} × {kind}");
    }
    eprintln!(
        "server RSS {:.1} MiB before, {:.1} MiB half-way, {:.1} MiB after, peak {:.1} MiB",
        rss_start as f64 / MIB as f64,
        rss_midway as f64 / MIB as f64,
        rss_end as f64 / MIB as f64,
        peak as f64 / MIB as f64
    );
    // Each upload holds at most what the budget lets it reserve.
    assert!(
        peak < rss_start + BUDGET_MB * MIB,
        "peak {peak} over the budget from {rss_start}"
    );
    // No growth from case to case (freed memory may stay mapped: a margin).
    assert!(
        rss_end < rss_midway + 64 * MIB,
        "RSS grew from {rss_midway} half-way to {rss_end}"
    );
    assert!(statuses.values().sum::<usize>() == total);
    assert!(
        faults.len() >= 5,
        "the faults are named in too few ways: {faults:?}"
    );
    // The server never panicked: no such line in its log.
    let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        server.wait_for_log(&["panicked"], std::time::Duration::from_secs(1))
    }));
    assert!(
        panicked.is_err(),
        "the server panicked: {:?}",
        panicked.ok()
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);
    mismatches
}

/// A problem's detail without its numbers and ids, for a histogram of
/// the faults named.
fn fault_kind(detail: &str) -> String {
    let words: Vec<&str> = detail
        .split(|c: char| !c.is_alphabetic() && c != '\'')
        .filter(|w| w.len() > 1)
        .collect();
    words.join(" ")
}

/// The DEM `id`'s cells, read back from its tiles, equal GDAL's read of
/// `file`; `what` labels failures. A file the server took but GDAL cannot
/// read cleanly is a failure too.
fn check_cells(
    server: &Server,
    id: &str,
    file: &Path,
    dir: &Path,
    what: &str,
) -> Result<(), String> {
    let (w, h, want) = gdal_cells(file, dir)
        .map_err(|e| format!("{what}: stored as DEM {id}, but GDAL cannot read it: {e}"))?;
    let r = get(&server.url(&format!(
        "/api/v1/dems/{id}/window?col=0&row=0&width={w}&height={h}"
    )));
    if r.status != 200 || r.body.len() != w * h * 8 {
        return Err(format!(
            "{what}: {w} x {h} by GDAL; the window: {} {}",
            r.status,
            r.text()
        ));
    }
    for (k, b) in r.body.chunks_exact(8).enumerate() {
        let a = f64::from_le_bytes(b.try_into().unwrap());
        let g = want[k];
        if !(a.to_bits() == g.to_bits() || (a.is_nan() && g.is_nan())) {
            return Err(format!(
                "{what}: cell ({}, {}) is {a} from the tiles, {g} from GDAL",
                k % w,
                k / w
            ));
        }
    }
    Ok(())
}
