//! `terraplan experiment flock`: the thesis' §5.6 flock experiment on real
//! data, for the `competition` and `balanced` policies side by side.
//!
//! The area (embedded, see `server/experiments/flock/README.md`): a 7.9 ha
//! rectangle over the opengeos bare-earth DTM (Alexandria, VA) with four real
//! building footprints as no-fly zones, decomposed at slice 0° into 12
//! cells, flown terrain-following. Flocks of 3 to 8 UAVs start from 10
//! formations each: 60 trials, each planned with both policies.
//!
//! Printed like thesis Tables 5.1–5.7: per trial the shortest, longest,
//! spread and mean UAV length (3D, metres, home to home), and per flock the
//! standard deviations over the formations; plus the makespan (seconds),
//! the balanced policy's reduction of it and the gap to the lower bound.
//! With `--instances` each trial's flock problem is also written as a
//! routing instance (see [`instances`]).

mod instances;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clap::Subcommand;

use geo::Contains;
use geo_types::{Coord, Point, Polygon};
use planner_core::flock::Policy;
use planner_core::flock::instance::{Instance, recording};
use planner_core::geo::{Limits, UtmProjection, parse_polygons};
use planner_core::survey::{SurveyRequest, plan_survey_over};
use planner_core::terrain::{Dem, DemLimits, read_dem};
use serde_json::{Value, json};

use super::common::Failure;

const ROI: &str = include_str!("../../experiments/flock/roi.geojson");
const NO_FLY: &str = include_str!("../../experiments/flock/no_fly.geojson");
const DTM: &[u8] = include_bytes!("../../experiments/flock/opengeos_dtm.tif");

#[derive(Subcommand)]
pub(super) enum ExperimentCommand {
    /// The thesis' flock experiment (§5.6): 12 cells, 3–8 UAVs, 10 starting
    /// formations, 60 trials, `competition` and `balanced` side by side;
    /// prints tables like thesis Tables 5.1–5.7.
    Flock {
        /// Also write trials.csv, uavs.csv and flocks.csv here.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Also write each trial's flock problem as a routing instance
        /// (JSON: nodes, travel times, job durations and the balanced
        /// policy's routes) here, one file per trial.
        #[arg(long, value_name = "DIR")]
        instances: Option<PathBuf>,
    },
}

pub(super) fn experiment(command: &ExperimentCommand) -> Result<(), Failure> {
    match command {
        ExperimentCommand::Flock { out, instances } => flock(out.as_deref(), instances.as_deref()),
    }
}

fn flock(out: Option<&Path>, instances: Option<&Path>) -> Result<(), Failure> {
    let trials = run_trials(instances.is_some()).map_err(Failure::other)?;
    print!("{}", report(&trials));
    let mut written = Vec::new();
    if let Some(dir) = out {
        written.extend(write_csv(&trials, dir).map_err(Failure::other)?);
    }
    if let Some(dir) = instances {
        written.extend(instances::write_instances(&trials, dir).map_err(Failure::other)?);
    }
    for path in written {
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// UTM zone of the area (18 N) and the ROI's extent in it, metres.
const ZONE: u8 = 18;
const WEST: f64 = 321_550.0;
const EAST: f64 = 321_790.0;
const SOUTH: f64 = 4_297_550.0;
const NORTH: f64 = 4_297_880.0;

/// The starting formations (thesis Figures 5.9–5.10 use ten).
pub const FORMATIONS: [&str; 10] = [
    "grid",
    "linear",
    "wide linear",
    "chessboard",
    "clustered",
    "corners",
    "diagonal",
    "ring",
    "west column",
    "two clusters",
];

/// One planned trial.
#[derive(Clone, Debug)]
pub struct Trial {
    pub uavs: usize,
    pub experiment: usize,
    pub policy: Policy,
    pub cells: usize,
    /// Per UAV: 3D length (m) and flight time (s).
    pub lengths_m: Vec<f64>,
    pub times_s: Vec<f64>,
    pub makespan_s: f64,
    pub lower_bound_s: f64,
    pub coverage_ratio: f64,
    /// The flock problem as solved, when recorded.
    pub instance: Option<Instance>,
}

impl Trial {
    fn min(&self) -> f64 {
        self.lengths_m.iter().copied().fold(f64::INFINITY, f64::min)
    }
    fn max(&self) -> f64 {
        self.lengths_m.iter().copied().fold(0.0, f64::max)
    }
    fn mean(&self) -> f64 {
        self.lengths_m.iter().sum::<f64>() / self.lengths_m.len().max(1) as f64
    }
    fn gap(&self) -> f64 {
        self.makespan_s / self.lower_bound_s - 1.0
    }
}

/// Start positions (UTM) of `n` UAVs in formation `f` (0-based), moved out
/// of any no-fly zone.
fn formation(f: usize, n: usize, nfz: &[Polygon<f64>]) -> Vec<Coord<f64>> {
    let (w, h) = (EAST - WEST, NORTH - SOUTH);
    let at = |fx: f64, fy: f64| Coord {
        x: WEST + fx * w,
        y: SOUTH + fy * h,
    };
    let t = |i: usize| {
        if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.5
        }
    };
    let pts: Vec<Coord<f64>> = (0..n)
        .map(|i| match f {
            // Rows × columns over the area.
            0 => {
                let cols = (n as f64).sqrt().ceil() as usize;
                let rows = n.div_ceil(cols);
                let (r, c) = (i / cols, i % cols);
                at(
                    (c as f64 + 0.5) / cols as f64,
                    (r as f64 + 0.5) / rows as f64,
                )
            }
            // 10 m apart on the south edge, centred.
            1 => Coord {
                x: (WEST + EAST) / 2.0 + (i as f64 - (n - 1) as f64 / 2.0) * 10.0,
                y: SOUTH + 5.0,
            },
            // Spanning the south edge.
            2 => at(0.05 + 0.9 * t(i), 0.015),
            // Dark squares of a 4 × 4 board, filled row by row.
            3 => {
                let squares: Vec<(usize, usize)> = (0..4)
                    .flat_map(|r| (0..4).map(move |c| (r, c)))
                    .filter(|(r, c)| (r + c) % 2 == 0)
                    .collect();
                let (r, c) = squares[(i * 3) % squares.len()];
                at((c as f64 + 0.5) / 4.0, (r as f64 + 0.5) / 4.0)
            }
            // A tight group near the south-west corner.
            4 => Coord {
                x: WEST + 10.0 + 6.0 * (i % 3) as f64,
                y: SOUTH + 10.0 + 6.0 * (i / 3) as f64,
            },
            // Round the four corners in turn.
            5 => {
                let corner: (f64, f64) =
                    [(0.03, 0.03), (0.97, 0.03), (0.97, 0.97), (0.03, 0.97)][i % 4];
                let k = (i / 4) as f64;
                at(corner.0 + 0.04 * k * (0.5 - corner.0).signum(), corner.1)
            }
            // South-west to north-east.
            6 => at(0.05 + 0.9 * t(i), 0.05 + 0.9 * t(i)),
            // A ring round the centre.
            7 => {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                let r = 0.35 * w.min(h);
                Coord {
                    x: (WEST + EAST) / 2.0 + r * a.cos(),
                    y: (SOUTH + NORTH) / 2.0 + r * a.sin(),
                }
            }
            // Along the west edge.
            8 => at(0.015, 0.05 + 0.9 * t(i)),
            // Half near the north-west corner, half near the south-east.
            _ => {
                let k = (i / 2) as f64 * 6.0;
                if i % 2 == 0 {
                    Coord {
                        x: WEST + 10.0 + k,
                        y: NORTH - 10.0,
                    }
                } else {
                    Coord {
                        x: EAST - 10.0 - k,
                        y: SOUTH + 10.0,
                    }
                }
            }
        })
        .collect();
    pts.into_iter()
        .map(|mut p| {
            // Step east out of a building (a few metres at most here).
            for _ in 0..100 {
                if !nfz.iter().any(|z| z.contains(&Point(p))) {
                    break;
                }
                p.x += 2.0;
            }
            p
        })
        .collect()
}

/// Runs all trials: `(uavs, formation, policy)` for 3–8 UAVs, every
/// formation, competition and balanced; on two threads. With `record`,
/// each trial keeps its flock problem as an [`Instance`].
pub fn run_trials(record: bool) -> Result<Vec<Trial>, String> {
    let dem = read_dem(DTM, Some("opengeos_dtm.tif"), None, &DemLimits::default())
        .map_err(|e| format!("embedded DTM: {e}"))?;
    let proj = UtmProjection::new(ZONE, true).map_err(|e| e.to_string())?;
    let no_fly: Value = serde_json::from_str(NO_FLY).map_err(|e| e.to_string())?;
    let nfz_utm: Vec<Polygon<f64>> = parse_polygons(&no_fly, "/no_fly_zones")
        .map_err(|e| format!("embedded no-fly zones: {e:?}"))?
        .iter()
        .map(|p| proj.polygon_to_utm(&p.polygon))
        .collect::<Result<_, _>>()
        .map_err(|e| e.to_string())?;
    let mut jobs = Vec::new();
    for n in 3..=8 {
        for f in 0..FORMATIONS.len() {
            for policy in [Policy::Competition, Policy::Balanced] {
                jobs.push((n, f, policy));
            }
        }
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                // PROJ handles are per thread.
                let proj = match UtmProjection::new(ZONE, true) {
                    Ok(p) => p,
                    Err(e) => {
                        if let Ok(mut v) = results.lock() {
                            v.push((usize::MAX, Err(e.to_string())));
                        }
                        return;
                    }
                };
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(&(n, f, policy)) = jobs.get(k) else {
                        break;
                    };
                    let r = trial(&dem, &proj, &nfz_utm, (n, f, policy), record);
                    if let Ok(mut v) = results.lock() {
                        v.push((k, r));
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().map_err(|e| e.to_string())?;
    results.sort_by_key(|(k, _)| *k);
    results.into_iter().map(|(_, r)| r).collect()
}

fn trial(
    dem: &Dem,
    proj: &UtmProjection,
    nfz: &[Polygon<f64>],
    (n, f, policy): (usize, usize, Policy),
    record: bool,
) -> Result<Trial, String> {
    let uavs: Vec<Value> = formation(f, n, nfz)
        .into_iter()
        .enumerate()
        .map(|(i, p)| {
            let ll = proj.to_wgs84(p).map_err(|e| e.to_string())?;
            Ok(json!({"id": format!("uav{}", i + 1), "start": [ll.x, ll.y]}))
        })
        .collect::<Result<_, String>>()?;
    let roi: Value = serde_json::from_str(ROI).map_err(|e| e.to_string())?;
    let no_fly: Value = serde_json::from_str(NO_FLY).map_err(|e| e.to_string())?;
    let doc = json!({
        "roi": roi,
        "no_fly_zones": [no_fly],
        "altitude_m": 30,
        "slice_angle_deg": 0,
        "speed_m_s": 5,
        "turn_penalty_s": 2,
        "uavs": uavs,
        "assignment": policy,
    });
    let req = SurveyRequest::from_document(&doc).map_err(|e| e.to_string())?;
    let plan_it = || plan_survey_over(&req, &Limits::default(), Some(dem));
    let (plan, instance) = if record {
        let (plan, instance) = recording(plan_it);
        (plan, Some(instance))
    } else {
        (plan_it(), None)
    };
    let what = || format!("{n} UAVs, {}", FORMATIONS[f]);
    let plan = plan.map_err(|e| format!("{}: {e}", what()))?;
    let instance = instance
        .transpose()
        .map_err(|e| format!("{}: flock instance: {e}", what()))?;
    Ok(Trial {
        uavs: n,
        experiment: f + 1,
        policy,
        cells: plan.stats.cell_count,
        lengths_m: plan.uavs.iter().map(|u| u.stats.length_3d_m).collect(),
        times_s: plan.uavs.iter().map(|u| u.stats.flight_time_s).collect(),
        makespan_s: plan.stats.makespan_s,
        lower_bound_s: plan.stats.makespan_lower_bound_s,
        coverage_ratio: plan.stats.coverage_ratio,
        instance,
    })
}

/// Sample standard deviation (n − 1), as MATLAB's `std`.
fn std_dev(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// The printed report (tables and the summary).
pub fn report(trials: &[Trial]) -> String {
    let mut out = String::new();
    let find = |n: usize, e: usize, p: Policy| {
        trials
            .iter()
            .find(|t| t.uavs == n && t.experiment == e && t.policy == p)
    };
    let _ = writeln!(
        out,
        "Flock experiment (thesis §5.6): 12 cells, terrain-following at 30 m over the opengeos \
         DTM, 5 m/s, 2 s per turn.\nLengths are 3D, home to home, in metres; makespan is the \
         longest mission in seconds.\n"
    );
    let mut reductions = Vec::new();
    let mut gaps = Vec::new();
    let mut worse = 0;
    for n in 3..=8 {
        let _ = writeln!(out, "{n}-UAV flock (like thesis Table 5.{})", n - 2);
        let _ = writeln!(
            out,
            "{:>4} {:<13}| {:>8} {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} | {:>7} {:>7} {:>6} {:>6}",
            "exp",
            "formation",
            "min",
            "max",
            "max-min",
            "mean",
            "min",
            "max",
            "max-min",
            "mean",
            "T comp",
            "T bal",
            "red.%",
            "gap%"
        );
        let _ = writeln!(
            out,
            "{:>18} {:^35} | {:^35} | {:>7} {:>7}",
            "", "competition (m)", "balanced (m)", "(s)", "(s)"
        );
        for e in 1..=FORMATIONS.len() {
            let (Some(c), Some(b)) = (
                find(n, e, Policy::Competition),
                find(n, e, Policy::Balanced),
            ) else {
                continue;
            };
            let reduction = 1.0 - b.makespan_s / c.makespan_s;
            reductions.push(reduction);
            gaps.push(b.gap());
            if b.makespan_s > c.makespan_s * (1.0 + 1e-9) {
                worse += 1;
            }
            let _ = writeln!(
                out,
                "{e:>4} {:<13}| {:>8.1} {:>8.1} {:>8.1} {:>8.1} | {:>8.1} {:>8.1} {:>8.1} {:>8.1} | {:>7.1} {:>7.1} {:>6.1} {:>6.1}",
                FORMATIONS[e - 1],
                c.min(),
                c.max(),
                c.max() - c.min(),
                c.mean(),
                b.min(),
                b.max(),
                b.max() - b.min(),
                b.mean(),
                c.makespan_s,
                b.makespan_s,
                100.0 * reduction,
                100.0 * b.gap()
            );
        }
        out.push('\n');
    }
    let _ = writeln!(
        out,
        "Standard deviations over the 10 formations (like thesis Table 5.7), metres"
    );
    let _ = writeln!(
        out,
        "{:>5} | {:>12} {:>12} | {:>12} {:>12}",
        "UAVs", "comp. mean", "comp. max-min", "bal. mean", "bal. max-min"
    );
    for row in flock_stats(trials) {
        let _ = writeln!(
            out,
            "{:>5} | {:>12.2} {:>12.2} | {:>12.2} {:>12.2}",
            row.0, row.1[0], row.1[1], row.2[0], row.2[1]
        );
    }
    let mean_reduction = reductions.iter().sum::<f64>() / reductions.len().max(1) as f64;
    let _ = writeln!(
        out,
        "\n{} trials. balanced makespan > competition in {worse} of them. Mean makespan \
         reduction {:.1} % (min {:.1} %, max {:.1} %). Median gap to the lower bound {:.1} % \
         (max {:.1} %).",
        reductions.len(),
        100.0 * mean_reduction,
        100.0 * reductions.iter().copied().fold(f64::INFINITY, f64::min),
        100.0 * reductions.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        100.0 * median(gaps.clone()),
        100.0 * gaps.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    out
}

/// Per flock size: (size, [std of means, std of spreads] for competition,
/// the same for balanced).
fn flock_stats(trials: &[Trial]) -> Vec<(usize, [f64; 2], [f64; 2])> {
    (3..=8)
        .map(|n| {
            let of = |p: Policy| {
                let ts: Vec<&Trial> = trials
                    .iter()
                    .filter(|t| t.uavs == n && t.policy == p)
                    .collect();
                let means: Vec<f64> = ts.iter().map(|t| t.mean()).collect();
                let spreads: Vec<f64> = ts.iter().map(|t| t.max() - t.min()).collect();
                [std_dev(&means), std_dev(&spreads)]
            };
            (n, of(Policy::Competition), of(Policy::Balanced))
        })
        .collect()
}

/// Writes `trials.csv`, `uavs.csv` and `flocks.csv` into `dir`.
pub fn write_csv(trials: &[Trial], dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut t = String::from(
        "uavs,experiment,formation,policy,cells,min_length_m,max_length_m,max_min_m,\
         mean_length_m,makespan_s,makespan_lower_bound_s,gap,coverage_ratio\n",
    );
    let mut u = String::from("uavs,experiment,policy,uav,length_3d_m,flight_time_s\n");
    for tr in trials {
        let _ = writeln!(
            t,
            "{},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.5},{:.6}",
            tr.uavs,
            tr.experiment,
            FORMATIONS[tr.experiment - 1],
            tr.policy.name(),
            tr.cells,
            tr.min(),
            tr.max(),
            tr.max() - tr.min(),
            tr.mean(),
            tr.makespan_s,
            tr.lower_bound_s,
            tr.gap(),
            tr.coverage_ratio
        );
        for (k, (l, s)) in tr.lengths_m.iter().zip(&tr.times_s).enumerate() {
            let _ = writeln!(
                u,
                "{},{},{},uav{},{l:.3},{s:.3}",
                tr.uavs,
                tr.experiment,
                tr.policy.name(),
                k + 1
            );
        }
    }
    let mut f = String::from("uavs,policy,mean_length_std_m,max_min_std_m\n");
    for (n, c, b) in flock_stats(trials) {
        let _ = writeln!(f, "{n},competition,{:.3},{:.3}", c[0], c[1]);
        let _ = writeln!(f, "{n},balanced,{:.3},{:.3}", b[0], b[1]);
    }
    let mut written = Vec::new();
    for (name, text) in [("trials.csv", t), ("uavs.csv", u), ("flocks.csv", f)] {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}
