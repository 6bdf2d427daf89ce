//! `terraplan experiment flock` end to end: the thesis' §5.6 experiment
//! (12 cells, flocks of 3–8 UAVs, 10 starting formations, 60 trials) with
//! the `competition` and `balanced` policies, checked from the CSV files it
//! writes against the targets.

use std::collections::HashMap;

use terraplan_e2e::{terraplan, text};

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
    let out = terraplan(&["experiment", "flock", "--out", dir.path().to_str().unwrap()]);
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
}
