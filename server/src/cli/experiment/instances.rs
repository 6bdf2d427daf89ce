//! `terraplan experiment flock --instances DIR`: each trial's flock problem
//! as a routing instance in JSON (issue 21), for general solvers to be run
//! on (`scripts/bench-flock.sh`), with the balanced policy's answer.

use std::path::{Path, PathBuf};

use planner_core::flock::Policy;
use serde_json::{Value, json};

use super::{FORMATIONS, Trial};

/// The file name (and instance name) of a trial: `n3-e01-grid`.
fn name_of(t: &Trial) -> String {
    format!(
        "n{}-e{:02}-{}",
        t.uavs,
        t.experiment,
        FORMATIONS[t.experiment - 1].replace(' ', "-")
    )
}

/// The instance document of a trial that recorded its flock problem.
fn document(t: &Trial) -> Option<Value> {
    let inst = t.instance.as_ref()?;
    let uavs: Vec<Value> = inst
        .starts
        .iter()
        .enumerate()
        .map(|(u, &start)| json!({"id": format!("uav{}", u + 1), "start": start}))
        .collect();
    let jobs: Vec<Value> = inst
        .jobs
        .iter()
        .enumerate()
        .map(|(j, job)| json!({"id": format!("job{j}"), "ends": job.ends, "duration_s": job.duration_s}))
        .collect();
    Some(json!({
        "name": name_of(t),
        "uavs": uavs,
        "jobs": jobs,
        "travel_s": inst.travel_s,
        "terraplan": {
            "policy": t.policy.name(),
            "makespan_s": inst.makespan_s,
            "lower_bound_s": inst.lower_bound_s,
            "solve_s": inst.solve_s,
            // [job index, flown from ends[1] to ends[0]] per UAV.
            "routes": inst.routes,
            // The mission files' makespan (waypoints as flown) beside the
            // model's, for reference.
            "flown_makespan_s": t.makespan_s,
        },
    }))
}

/// Writes `<name>.json` for each trial planned with the balanced policy
/// (the competition's trials share their instance).
pub fn write_instances(trials: &[Trial], dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut written = Vec::new();
    for t in trials.iter().filter(|t| t.policy == Policy::Balanced) {
        let Some(doc) = document(t) else {
            return Err(format!("trial {} recorded no flock instance", name_of(t)));
        };
        let path = dir.join(format!("{}.json", name_of(t)));
        std::fs::write(&path, doc.to_string())
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}
