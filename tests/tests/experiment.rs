//! `terraplan experiment flock` end to end: the thesis' §5.6 experiment
//! (12 cells, flocks of 3–8 UAVs, 10 starting formations, 60 trials) with
//! the `competition` and `balanced` policies, checked from the CSV files it
//! writes against the targets, and its routing instances
//! (`--instances`) against the plans they came from.

use std::collections::HashMap;

use terraplan_e2e::{terraplan, text, validator};

/// One row of trials.csv.
struct Row {
    uavs: usize,
    experiment: usize,
    policy: String,
    cells: usize,
    min: f64,
    max: f64,
    mean: f64,
    makespan_s: f64,
    lower_bound_s: f64,
    coverage: f64,
}

fn read_trials(csv: &str) -> Vec<Row> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (u, e, p, c) = (col("uavs"), col("experiment"), col("policy"), col("cells"));
    let (mn, mx, me) = (
        col("min_length_m"),
        col("max_length_m"),
        col("mean_length_m"),
    );
    let (ms, lb, cov) = (
        col("makespan_s"),
        col("makespan_lower_bound_s"),
        col("coverage_ratio"),
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let n = |i: usize| f[i].parse::<f64>().unwrap();
            Row {
                uavs: f[u].parse().unwrap(),
                experiment: f[e].parse().unwrap(),
                policy: f[p].to_string(),
                cells: f[c].parse().unwrap(),
                min: n(mn),
                max: n(mx),
                mean: n(me),
                makespan_s: n(ms),
                lower_bound_s: n(lb),
                coverage: n(cov),
            }
        })
        .collect()
}

#[test]
fn flock_experiment_meets_the_balancing_targets() {
    let dir = tempfile::tempdir().unwrap();
    let instances = dir.path().join("instances");
    let out = terraplan(&[
        "experiment",
        "flock",
        "--out",
        dir.path().to_str().unwrap(),
        "--instances",
        instances.to_str().unwrap(),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    // The printed tables: one per flock size and the standard deviations.
    for n in 3..=8 {
        assert!(stdout.contains(&format!("{n}-UAV flock")), "{stdout}");
    }
    assert!(stdout.contains("Table 5.7"), "{stdout}");

    let rows = read_trials(&std::fs::read_to_string(dir.path().join("trials.csv")).unwrap());
    assert_eq!(rows.len(), 120, "60 trials × 2 policies");
    let mut by_trial: HashMap<(usize, usize), HashMap<String, &Row>> = HashMap::new();
    for r in &rows {
        assert_eq!(r.cells, 12, "the area decomposes into 12 cells");
        assert!(r.coverage >= 0.995, "coverage {}", r.coverage);
        assert!(r.min <= r.mean && r.mean <= r.max);
        // The bound holds up to the model's rounding against the flown
        // lengths (1e-6 relative).
        assert!(
            r.lower_bound_s <= r.makespan_s * (1.0 + 1e-6),
            "bound {} above makespan {}",
            r.lower_bound_s,
            r.makespan_s
        );
        by_trial
            .entry((r.uavs, r.experiment))
            .or_default()
            .insert(r.policy.clone(), r);
    }
    assert_eq!(by_trial.len(), 60);
    let mut reductions = Vec::new();
    let mut gaps = Vec::new();
    for ((n, e), p) in &by_trial {
        let (c, b) = (p["competition"], p["balanced"]);
        // balanced starts from competition and only takes improving moves.
        assert!(
            b.makespan_s <= c.makespan_s * (1.0 + 1e-9),
            "{n} UAVs, formation {e}: balanced {} > competition {}",
            b.makespan_s,
            c.makespan_s
        );
        reductions.push(1.0 - b.makespan_s / c.makespan_s);
        gaps.push(b.makespan_s / b.lower_bound_s - 1.0);
    }
    let mean_reduction = reductions.iter().sum::<f64>() / reductions.len() as f64;
    gaps.sort_by(f64::total_cmp);
    let median_gap = (gaps[29] + gaps[30]) / 2.0;
    assert!(
        mean_reduction >= 0.15,
        "mean makespan reduction {mean_reduction}"
    );
    assert!(
        median_gap <= 0.10,
        "median gap to the lower bound {median_gap}"
    );

    for name in ["uavs.csv", "flocks.csv"] {
        let csv = std::fs::read_to_string(dir.path().join(name)).unwrap();
        assert!(csv.lines().count() > 1, "{name} is empty");
    }
    let flocks = std::fs::read_to_string(dir.path().join("flocks.csv")).unwrap();
    assert_eq!(flocks.lines().count(), 1 + 6 * 2);

    check_instances(&instances, &by_trial);
}

/// The instances, one per trial: the validator recomputes each plan's
/// makespan from the travel matrix and the job durations alone (within
/// 1e-6 s of the plan's), and a tampered instance fails it.
fn check_instances(
    dir: &std::path::Path,
    by_trial: &HashMap<(usize, usize), HashMap<String, &Row>>,
) {
    let out = validator("check_flock_instance.py", &[dir]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 60, "one instance per trial");
    for l in &lines {
        let name = l["name"].as_str().unwrap();
        // n3-e01-grid: 3 UAVs, formation 1.
        let n: usize = name[1..2].parse().unwrap();
        let e: usize = name[4..6].parse().unwrap();
        assert_eq!(l["uavs"].as_u64(), Some(n as u64), "{name}");
        assert_eq!(l["jobs"].as_u64(), Some(12), "{name}: the 12 cells");
        // The balanced plan's makespan as trials.csv prints it (3 decimals).
        let csv = by_trial[&(n, e)]["balanced"].makespan_s;
        let recomputed = l["makespan_s"].as_f64().unwrap();
        assert!(
            (recomputed - csv).abs() <= 5e-4,
            "{name}: {recomputed} vs {csv}"
        );
    }

    let path = dir.join("n5-e03-wide-linear.json");
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    // A second more on every transit: each UAV's time grows by at least 2 s
    // (out and home), so the recomputed makespan no longer matches.
    for row in doc["travel_s"].as_array_mut().unwrap() {
        for t in row.as_array_mut().unwrap() {
            *t = serde_json::json!(t.as_f64().unwrap() + 1.0);
        }
    }
    let tampered = tempfile::tempdir().unwrap();
    std::fs::write(tampered.path().join("t.json"), doc.to_string()).unwrap();
    let out = validator("check_flock_instance.py", &[tampered.path()]);
    assert!(!out.status.success(), "a reordered route passed");
    assert!(
        text(&out.stderr).contains("recomputed makespan"),
        "{}",
        text(&out.stderr)
    );
}
