//! Flock stage timing: 64 UAVs sharing about 200 cells of a 4 km × 4 km
//! ROI with octagonal NFZs (as in `benches/survey.rs`).
//!
//! 1. End to end, decomposition to files: `plan_survey` and every file of
//!    the plan rendered, for each assignment policy, with the plan's
//!    makespan, its lower bound and the gap between them.
//! 2. The assignment alone on the same instance (the survey's cells, jobs,
//!    homes and obstacles rebuilt through the public API): `assign` with a
//!    fresh `Flock` (it memoises legs) per run, and where its time goes.
//! 3. The Hungarian solver on random 64×200 and 500×500 matrices, next to
//!    SciPy's `linear_sum_assignment` on the same matrices in the same run
//!    (the validators' venv, `TERRAPLAN_VENV` or `.venv`; skipped with the
//!    reason when it or SciPy is missing), both checked for the same optimal
//!    sum.
//!
//! `min_reach` takes seconds per run, too slow for criterion's ten samples:
//! it is timed by three plain runs instead (one under `cargo test`).
//!
//! `CARGO_TARGET_DIR=/tmp/bench-target cargo bench -p planner-core --bench flock`
//! (about 90 s on 2 cores after the build). The tables at the end give the
//! median of every timed run, criterion's warm-up included.

use std::hint::black_box;
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use criterion::{Bencher, Criterion, SamplingMode};
use geo_types::{Coord, MultiPolygon, Polygon, polygon};
use planner_core::coverage::{self, CellPlan};
use planner_core::decompose;
use planner_core::flock::{
    Flock, FlockJob, FlockUav, ObstacleMap, Part, Policy, assign, balanced, competition,
    halve_until, hungarian, makespan_lower_bound,
};
use planner_core::geo::{Limits, ParsedPolygon, UtmProjection, prepare_area};
use planner_core::survey::{SurveyParams, SurveyPlan, SurveyRequest, UavSpec, plan_survey};

mod area;

use area::{Lcg, SIDE_M, nfzs};
/// NFZs in the ROI: tuned for about 200 cells.
const NFZ_COUNT: usize = 64;
const UAV_COUNT: usize = 64;
/// Where the ROI's south-west corner is (lon, lat).
const ORIGIN: Coord<f64> = Coord { x: 8.55, y: 47.35 };
const POLICIES: [Policy; 3] = [Policy::Balanced, Policy::Competition, Policy::MinReach];

/// The survey request: ROI and NFZs in lon/lat, 64 UAVs spread along the
/// ROI's south edge, 30 m outside it.
fn request(policy: Policy, nfz_count: usize) -> SurveyRequest {
    let proj = UtmProjection::for_lonlat(ORIGIN).expect("UTM zone");
    let origin = proj.to_utm(ORIGIN).expect("origin to UTM");
    let lonlat = |c: Coord<f64>| {
        proj.to_wgs84(Coord {
            x: origin.x + c.x,
            y: origin.y + c.y,
        })
        .expect("to WGS84")
    };
    let to_lonlat = |p: &Polygon<f64>, pointer: String| ParsedPolygon {
        polygon: Polygon::new(p.exterior().0.iter().map(|&c| lonlat(c)).collect(), vec![]),
        pointer,
    };
    let roi = polygon![(x: 0.0, y: 0.0), (x: SIDE_M, y: 0.0), (x: SIDE_M, y: SIDE_M), (x: 0.0, y: SIDE_M)];
    let uavs = (0..UAV_COUNT)
        .map(|i| {
            let home = lonlat(Coord {
                x: (i as f64 + 0.5) * SIDE_M / UAV_COUNT as f64,
                y: -30.0,
            });
            UavSpec {
                id: format!("uav{i}"),
                start: [home.x, home.y],
                speed_m_s: None,
                max_flight_time_s: None,
            }
        })
        .collect();
    SurveyRequest {
        roi: vec![to_lonlat(&roi, "/roi/coordinates".into())],
        corridor: None,
        no_fly: nfzs(nfz_count)
            .iter()
            .enumerate()
            .map(|(i, p)| to_lonlat(p, format!("/no_fly_zones/{i}/coordinates")))
            .collect(),
        params: SurveyParams {
            uavs,
            assignment: policy,
            ..SurveyParams::default()
        },
    }
}

/// Plans the survey and renders every file; the plan, files and bytes.
fn survey_to_files(req: &SurveyRequest) -> (SurveyPlan, usize, usize) {
    let plan = plan_survey(req, &Limits::default()).expect("plan_survey");
    let files = plan.files();
    let bytes = files.iter().map(|f| f.content.len()).sum();
    (plan, files.len(), bytes)
}

/// The flock instance `plan_survey` shares for `req`, rebuilt through the
/// public API at the slice angle and spacing the survey chose.
struct Instance {
    uavs: Vec<FlockUav>,
    jobs: Vec<FlockJob>,
    obstacles: ObstacleMap,
    turn_penalty_s: f64,
    altitude_m: f64,
}

impl Instance {
    fn of(req: &SurveyRequest, plan: &SurveyPlan) -> Instance {
        let area = prepare_area(
            &req.roi,
            &req.no_fly,
            "/roi",
            "/no_fly_zones",
            &Limits::default(),
        )
        .expect("prepare_area");
        let free = MultiPolygon(
            area.roi
                .0
                .iter()
                .flat_map(|roi| decompose::free_space(roi, &area.no_fly).0)
                .collect(),
        );
        let angle = plan.stats.slice_angle_deg;
        let cells = decompose::decompose(&free, angle).expect("decompose");
        let index = coverage::FreeSpace::new(&free);
        let plans: Vec<CellPlan> = cells
            .iter()
            .enumerate()
            .filter_map(|(i, c)| {
                coverage::plan_cell_in(i, c, &index, plan.stats.line_spacing_m, angle)
            })
            .collect();
        let whole: Vec<Part> = plans
            .into_iter()
            .filter(|p| !p.lanes.is_empty())
            .map(Part::whole)
            .collect();
        let parts = halve_until(whole, UAV_COUNT, CellPlan::length_m);
        let jobs = parts
            .iter()
            .filter_map(|p| FlockJob::from_plan(&p.plan, p.plan.length_m()))
            .collect();
        let nfz_union = geo::unary_union(area.no_fly.iter());
        let params = &req.params;
        let uavs = params
            .uavs
            .iter()
            .map(|u| FlockUav {
                home: area
                    .projection
                    .to_utm(Coord {
                        x: u.start[0],
                        y: u.start[1],
                    })
                    .expect("home to UTM"),
                speed_m_s: u.speed_m_s.unwrap_or(params.speed_m_s),
            })
            .collect();
        Instance {
            uavs,
            jobs,
            // As the survey pipeline does: transits stay outside the NFZs
            // grown by the clearance.
            obstacles: ObstacleMap::new(
                &planner_core::geo::keep_out_area(&nfz_union, params.nfz_clearance_m),
                0.0,
            ),
            turn_penalty_s: params.turn_penalty_s,
            altitude_m: plan.stats.altitude_m,
        }
    }

    fn flock(&self) -> Flock<'_> {
        Flock::flat(
            self.uavs.clone(),
            self.jobs.clone(),
            self.turn_penalty_s,
            &self.obstacles,
            self.altitude_m,
        )
    }
}

/// Times `run` on a fresh `setup()` per iteration (setup and drop outside
/// the clock) for criterion, and keeps every run's seconds for the table.
fn timed<S, R>(
    b: &mut Bencher,
    log: &mut Vec<f64>,
    mut setup: impl FnMut() -> S,
    mut run: impl FnMut(&mut S) -> R,
) {
    b.iter_custom(|iters| {
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            let mut input = setup();
            let t = Instant::now();
            let out = black_box(run(black_box(&mut input)));
            let e = t.elapsed();
            drop(out);
            total += e;
            log.push(e.as_secs_f64());
        }
        total
    });
}

fn median(xs: &[f64]) -> Option<f64> {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

fn ms(xs: &[f64]) -> String {
    median(xs).map_or("-".into(), |s| format!("{:.3}", s * 1e3))
}

/// A random `rows × cols` cost matrix, uniform in [0, 1000) m.
fn random_matrix(rows: usize, cols: usize, seed: u64) -> Vec<f64> {
    let mut rng = Lcg(seed);
    (0..rows * cols).map(|_| rng.next() * 1000.0).collect()
}

/// The validators' Python (`TERRAPLAN_VENV`, else the repository's `.venv`).
fn venv_python() -> PathBuf {
    let venv = std::env::var_os("TERRAPLAN_VENV").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv"),
        PathBuf::from,
    );
    venv.join("bin/python")
}

/// SciPy's `linear_sum_assignment` on `cost`: median seconds over `reps`
/// runs (after one warm-up) and the optimal sum; `Err` says why it was
/// skipped.
fn scipy_lsa(cost: &[f64], rows: usize, cols: usize, reps: usize) -> Result<(f64, f64), String> {
    let python = venv_python();
    if !python.exists() {
        return Err(format!(
            "no venv Python at {} (bash scripts/setup.sh --with-validators)",
            python.display()
        ));
    }
    let file = std::env::temp_dir().join(format!(
        "terraplan-bench-lsa-{}-{rows}x{cols}.f64",
        std::process::id()
    ));
    let bytes: Vec<u8> = cost.iter().flat_map(|c| c.to_le_bytes()).collect();
    std::fs::write(&file, bytes).map_err(|e| format!("writing {}: {e}", file.display()))?;
    let script = r#"
import sys, time
import numpy as np
from scipy.optimize import linear_sum_assignment
path, rows, cols, reps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
a = np.fromfile(path, dtype='<f8').reshape(rows, cols)
r, c = linear_sum_assignment(a)
ts = []
for _ in range(reps):
    t = time.perf_counter()
    r, c = linear_sum_assignment(a)
    ts.append(time.perf_counter() - t)
ts.sort()
print(repr(ts[len(ts) // 2]), repr(float(a[r, c].sum())))
"#;
    let out = Command::new(&python)
        .arg("-c")
        .arg(script)
        .arg(&file)
        .args([rows, cols, reps].map(|n| n.to_string()))
        .output();
    let _ = std::fs::remove_file(&file);
    let out = out.map_err(|e| format!("running {}: {e}", python.display()))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "SciPy reference failed: {}",
            err.lines().last().unwrap_or("no message")
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut it = text.split_whitespace().map(str::parse::<f64>);
    match (it.next(), it.next()) {
        (Some(Ok(t)), Some(Ok(sum))) => Ok((t, sum)),
        _ => Err(format!("unexpected SciPy output {text:?}")),
    }
}

/// Seconds of each of `runs` plain runs of `f` (for what is too slow for
/// criterion's ten samples).
fn plain<R>(runs: usize, mut f: impl FnMut() -> R) -> Vec<f64> {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            let out = black_box(f());
            let e = t.elapsed().as_secs_f64();
            drop(out);
            e
        })
        .collect()
}

/// Seconds of one run of `f`, and its result.
fn once<R>(f: impl FnOnce() -> R) -> (f64, R) {
    let t = Instant::now();
    let out = f();
    (t.elapsed().as_secs_f64(), out)
}

/// End-to-end row of the table.
struct SurveyRow {
    policy: Policy,
    cells: usize,
    files: usize,
    bytes: usize,
    makespan_s: f64,
    lower_bound_s: f64,
    gap: f64,
    times: Vec<f64>,
}

/// Assignment-alone row of the table.
struct AssignRow {
    policy: Policy,
    makespan_s: f64,
    lower_bound_s: f64,
    times: Vec<f64>,
}

/// Hungarian row of the table.
struct LsaRow {
    rows: usize,
    cols: usize,
    times: Vec<f64>,
    sum: f64,
    scipy: Result<(f64, f64), String>,
}

/// `min_reach` is timed by plain runs: one of its runs takes seconds.
fn criterion_times(policy: Policy) -> bool {
    policy != Policy::MinReach
}

fn main() {
    // `cargo bench` passes --bench; `cargo test --benches` runs each once.
    let quick = !std::env::args().any(|a| a == "--bench");
    let slow_runs = if quick { 0 } else { 2 };
    let mut c = Criterion::default().configure_from_args();

    // 1. Decomposition to files, per policy.
    let mut survey_rows = Vec::new();
    let mut instance = None;
    let mut profile = Vec::new();
    {
        let mut group = c.benchmark_group("flock_survey");
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(1))
            .measurement_time(Duration::from_secs(8));
        for policy in POLICIES {
            let req = request(policy, NFZ_COUNT);
            // The first run gives the stats (and is a timed run too).
            let (t_plan, plan) = once(|| plan_survey(&req, &Limits::default()).expect("plan"));
            let (t_files, files) = once(|| plan.files());
            let bytes = files.iter().map(|f| f.content.len()).sum();
            profile.push((format!("{}: plan_survey", policy.name()), t_plan));
            profile.push((format!("{}: files()", policy.name()), t_files));
            let s = &plan.stats;
            eprintln!(
                "{}: {} cells, {} UAVs, {} files ({bytes} bytes), makespan {:.1} s, lower bound \
                 {:.1} s, gap {:.3}",
                policy.name(),
                s.cell_count,
                s.uav_count,
                files.len(),
                s.makespan_s,
                s.makespan_lower_bound_s,
                s.makespan_gap
            );
            let mut times = vec![t_plan + t_files];
            if criterion_times(policy) {
                group.bench_function(policy.name(), |b| {
                    timed(b, &mut times, || (), |_| survey_to_files(&req))
                });
            } else {
                times.extend(plain(slow_runs, || survey_to_files(&req)));
            }
            if instance.is_none() {
                instance = Some(Instance::of(&req, &plan));
            }
            survey_rows.push(SurveyRow {
                policy,
                cells: s.cell_count,
                files: files.len(),
                bytes,
                makespan_s: s.makespan_s,
                lower_bound_s: s.makespan_lower_bound_s,
                gap: s.makespan_gap,
                times,
            });
        }
        group.finish();
    }

    // 2. The assignment alone, on the same instance.
    let instance = instance.expect("instance");
    let mut assign_rows = Vec::new();
    {
        let mut group = c.benchmark_group("flock_assign");
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(1))
            .measurement_time(Duration::from_secs(4));
        for policy in POLICIES {
            let mut flock = instance.flock();
            let (t, routes) = once(|| assign(&mut flock, policy).expect("assign"));
            let makespan_s = flock.makespan(&routes).expect("makespan");
            let (t_bound, lower_bound_s) =
                once(|| makespan_lower_bound(&mut flock, false).expect("bound"));
            profile.push((
                format!("{}: makespan_lower_bound after it", policy.name()),
                t_bound,
            ));
            let mut times = vec![t];
            if criterion_times(policy) {
                group.bench_function(policy.name(), |b| {
                    timed(
                        b,
                        &mut times,
                        || instance.flock(),
                        |f| assign(f, policy).expect("assign"),
                    )
                });
            } else {
                times.extend(plain(slow_runs, || {
                    assign(&mut instance.flock(), policy).expect("assign")
                }));
            }
            assign_rows.push(AssignRow {
                policy,
                makespan_s,
                lower_bound_s,
                times,
            });
        }
        group.finish();
    }

    // Where the assignment's time goes (one run each).
    {
        let mut flock = instance.flock();
        let (t_comp, (start, _)) =
            once(|| competition::competition(&mut flock).expect("competition"));
        let (t_search, _) = once(|| balanced::balanced(&mut flock, start).expect("balanced"));
        profile.push(("balanced: competition start".into(), t_comp));
        profile.push(("balanced: local search after it".into(), t_search));
    }

    // 3. The Hungarian solver next to SciPy.
    let mut lsa_rows = Vec::new();
    {
        let mut group = c.benchmark_group("hungarian");
        group
            .sample_size(20)
            .measurement_time(Duration::from_secs(3));
        for (rows, cols) in [(64usize, 200usize), (500, 500)] {
            let cost = random_matrix(rows, cols, 7 + rows as u64);
            let cols_of = hungarian::min_cost_assignment(&cost, rows, cols).expect("solve");
            let sum: f64 = cols_of
                .iter()
                .enumerate()
                .map(|(r, &c)| cost[r * cols + c])
                .sum();
            let mut times = Vec::new();
            group.bench_function(format!("{rows}x{cols}"), |b| {
                timed(
                    b,
                    &mut times,
                    || (),
                    |_| hungarian::min_cost_assignment(&cost, rows, cols).expect("solve"),
                )
            });
            let scipy = scipy_lsa(&cost, rows, cols, if quick { 1 } else { 20 });
            if let Ok((_, theirs)) = &scipy {
                assert!(
                    (sum - theirs).abs() <= 1e-9 * theirs.abs().max(1.0),
                    "{rows}×{cols}: our optimum {sum} differs from SciPy's {theirs}"
                );
            }
            lsa_rows.push(LsaRow {
                rows,
                cols,
                times,
                sum,
                scipy,
            });
        }
        group.finish();
    }
    c.final_summary();

    // The instance: the largest job against an even share of all the work.
    let flock = instance.flock();
    let job_times: Vec<f64> = (0..flock.jobs.len())
        .map(|j| flock.job_time(0, j))
        .collect();
    let work: f64 = job_times.iter().sum();
    let largest = job_times.iter().copied().fold(0.0, f64::max);
    drop(flock);

    println!();
    println!(
        "end to end, decomposition to files ({UAV_COUNT} UAVs, {NFZ_COUNT} NFZs; median of all \
         runs, min_reach {} plain runs)",
        slow_runs + 1
    );
    println!(
        "{:<12} {:>6} {:>6} {:>8} {:>6} {:>10} {:>12} {:>12} {:>8}",
        "policy", "cells", "files", "MB", "runs", "ms", "makespan s", "bound s", "gap"
    );
    for r in &survey_rows {
        println!(
            "{:<12} {:>6} {:>6} {:>8.2} {:>6} {:>10} {:>12.1} {:>12.1} {:>8.3}",
            r.policy.name(),
            r.cells,
            r.files,
            r.bytes as f64 / 1e6,
            r.times.len(),
            ms(&r.times),
            r.makespan_s,
            r.lower_bound_s,
            r.gap
        );
    }
    println!();
    println!(
        "assignment alone ({UAV_COUNT} UAVs × {} jobs, fresh Flock per run; jobs {:.0} s of work \
         in all, {:.0} s per UAV if shared evenly, largest job {:.0} s)",
        instance.jobs.len(),
        work,
        work / UAV_COUNT as f64,
        largest
    );
    println!(
        "{:<12} {:>6} {:>10} {:>12} {:>12}",
        "policy", "runs", "ms", "makespan s", "bound s"
    );
    for r in &assign_rows {
        println!(
            "{:<12} {:>6} {:>10} {:>12.1} {:>12.1}",
            r.policy.name(),
            r.times.len(),
            ms(&r.times),
            r.makespan_s,
            r.lower_bound_s
        );
    }
    println!();
    println!("where the time goes (single runs)");
    for (what, t) in &profile {
        println!("  {what:<58} {:>10.3} ms", t * 1e3);
    }
    println!();
    println!("Hungarian min_cost_assignment vs scipy.optimize.linear_sum_assignment");
    println!(
        "{:<10} {:>10} {:>10} {:>8} {:>18}",
        "matrix", "ours ms", "scipy ms", "ratio", "optimal sum"
    );
    for r in &lsa_rows {
        let ours = median(&r.times);
        let (theirs, ratio) = match (&r.scipy, ours) {
            (Ok((t, _)), Some(o)) => (format!("{:.3}", t * 1e3), format!("{:.2}", o / t)),
            _ => ("-".into(), "-".into()),
        };
        println!(
            "{:<10} {:>10} {:>10} {:>8} {:>18.6}",
            format!("{}x{}", r.rows, r.cols),
            ms(&r.times),
            theirs,
            ratio,
            r.sum
        );
        if let Err(why) = &r.scipy {
            println!("  SciPy reference skipped: {why}");
        }
    }
}
