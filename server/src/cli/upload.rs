//! `terraplan upload`: a mission file (and fence and rally points) sent to
//! a vehicle over MAVLink, read back and compared item by item.
//! Exit status: 2 for bad input (unreadable file, bad address), 3 when
//! the link or the vehicle fails (time-out, refusal, read-back mismatch).

use std::path::{Path, PathBuf};
use std::time::Duration;

use super::common::Failure;
use crate::vehicle_link::exchange::item_message;
use crate::vehicle_link::mission_file::{read_plan, read_wpl};
use crate::vehicle_link::{
    ItemList, MavlinkLink, MissionKind, Options, Progress, Stage, VehicleAddress, send_and_verify,
};

/// Exit status of a failed transfer (the input was good).
const LINK_FAILURE: u8 = 3;

#[derive(clap::Args)]
pub(super) struct UploadArgs {
    /// The mission: a `.waypoints` file (QGC WPL 110) or a QGroundControl
    /// `.plan`, whose fence and rally points are sent too (when it has
    /// any).
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// The vehicle: udpout:HOST:PORT (it listens), udpin:HOST:PORT (we
    /// listen; it must send first), tcpout:HOST:PORT or
    /// serial:DEVICE:BAUD.
    #[arg(long, value_name = "ADDRESS")]
    to: String,
    /// A fence to send: a `.fence.waypoints` file or a `.plan` (its
    /// geoFence). Replaces the fence of a `.plan` FILE.
    #[arg(long, value_name = "FILE")]
    fence: Option<PathBuf>,
    /// Rally points to send: a `.rally.waypoints` file or a `.plan` (its
    /// rallyPoints). Replaces the rally points of a `.plan` FILE.
    #[arg(long, value_name = "FILE")]
    rally: Option<PathBuf>,
    /// Send only the mission of a `.plan` FILE, not its fence and rally
    /// points (--fence and --rally still apply).
    #[arg(long)]
    mission_only: bool,
    /// Wait this long for each answer before asking again (e.g. 1.5s,
    /// 800ms; slow telemetry radios need more).
    #[arg(long, default_value = "1.5s", value_parser = parse_timeout)]
    timeout: Duration,
    /// Ask again this many times before giving up. A dead link fails
    /// after (retries + 1) × timeout at the step where it died.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(0..=100))]
    retries: u32,
    /// The vehicle's MAVLink system id.
    #[arg(long, default_value_t = 1)]
    target_system: u8,
    /// The vehicle's MAVLink component id (1 = the autopilot).
    #[arg(long, default_value_t = 1)]
    target_component: u8,
}

fn parse_timeout(text: &str) -> Result<Duration, String> {
    let d = humantime::parse_duration(text).map_err(|e| e.to_string())?;
    if d < Duration::from_millis(10) || d > Duration::from_secs(60) {
        return Err("the time-out must be from 10ms to 60s".into());
    }
    Ok(d)
}

pub(super) fn upload(args: &UploadArgs) -> Result<(), Failure> {
    let address =
        VehicleAddress::parse(&args.to).map_err(|e| Failure::input(format!("--to: {e}")))?;
    let lists = read_lists(args)?;
    let opts = Options {
        timeout: args.timeout,
        retries: args.retries,
        target_system: args.target_system,
        target_component: args.target_component,
    };
    // A command or frame the wire cannot carry is bad input, found
    // before the vehicle's lists are touched.
    for list in &lists {
        for (seq, item) in list.items.iter().enumerate() {
            item_message(&opts, list.kind, seq as u16, item)
                .map_err(|why| Failure::input(format!("{} list: {why}", list.kind.name())))?;
        }
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::other(format!("cannot start the runtime: {e}")))?;
    let sent = runtime.block_on(async {
        let mut link = MavlinkLink::open(&address, opts.timeout * (opts.retries + 1))
            .await
            .map_err(|e| link_failure(&address, e))?;
        send_and_verify(&mut link, &opts, &lists, &mut report_progress)
            .await
            .map_err(|e| link_failure(&address, e))
    })?;
    let summary = serde_json::json!({
        "to": address.to_string(),
        "sent": sent,
        "verified": true,
    });
    println!("{summary}");
    Ok(())
}

fn link_failure(address: &VehicleAddress, e: impl std::fmt::Display) -> Failure {
    Failure {
        status: LINK_FAILURE,
        message: format!("{address}: {e}"),
    }
}

/// One line on stderr as each list finishes a stage.
fn report_progress(p: Progress) {
    if p.done == p.total {
        let what = match p.stage {
            Stage::Upload => "uploaded",
            Stage::ReadBack => "read back",
        };
        eprintln!("{}: {what} {} items", p.kind.name(), p.total);
    }
}

/// The lists to send, in order: mission, fence, rally.
fn read_lists(args: &UploadArgs) -> Result<Vec<ItemList>, Failure> {
    let (mission, mut fence, mut rally) = match extension(&args.file) {
        Ext::Plan => {
            let plan = read_plan(&read_text(&args.file)?).map_err(|e| bad_file(&args.file, e))?;
            let keep = |l: ItemList| (!args.mission_only && !l.items.is_empty()).then_some(l);
            (plan.mission, keep(plan.fence), keep(plan.rally))
        }
        Ext::Waypoints => (
            read_wpl(&read_text(&args.file)?, MissionKind::Mission)
                .map_err(|e| bad_file(&args.file, e))?,
            None,
            None,
        ),
    };
    if let Some(path) = &args.fence {
        fence = Some(read_side_list(path, MissionKind::Fence)?);
    }
    if let Some(path) = &args.rally {
        rally = Some(read_side_list(path, MissionKind::Rally)?);
    }
    Ok([Some(mission), fence, rally]
        .into_iter()
        .flatten()
        .collect())
}

fn read_side_list(path: &Path, kind: MissionKind) -> Result<ItemList, Failure> {
    let text = read_text(path)?;
    match extension(path) {
        Ext::Plan => {
            let plan = read_plan(&text).map_err(|e| bad_file(path, e))?;
            Ok(match kind {
                MissionKind::Fence => plan.fence,
                _ => plan.rally,
            })
        }
        Ext::Waypoints => read_wpl(&text, kind).map_err(|e| bad_file(path, e)),
    }
}

enum Ext {
    Plan,
    Waypoints,
}

/// `.plan` files are JSON; anything else is read as QGC WPL (Mission
/// Planner writes `.waypoints`, `.txt` and `.mission`).
fn extension(path: &Path) -> Ext {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("plan") => Ext::Plan,
        _ => Ext::Waypoints,
    }
}

fn read_text(path: &Path) -> Result<String, Failure> {
    std::fs::read_to_string(path)
        .map_err(|e| Failure::input(format!("cannot read {}: {e}", path.display())))
}

fn bad_file(path: &Path, e: impl std::fmt::Display) -> Failure {
    Failure::input(format!("{}: {e}", path.display()))
}
