//! The mission, fence and rally lists read from the files terraplan (and
//! QGroundControl, Mission Planner, MAVProxy) write: `QGC WPL 110`
//! `.waypoints` files (mission, `.fence.waypoints`, `.rally.waypoints`)
//! and QGroundControl `.plan` documents (mission, geoFence, rallyPoints).

use planner_core::export::mission::{MavItem, cmd, frame};
use serde_json::Value;

use super::items::{ItemError, MissionKind, WireItem};

/// QGroundControl's `firmwareType` for ArduPilot: its mission keeps home
/// at seq 0, so QGroundControl (and MAVSDK's importer) put the plan's
/// `plannedHomePosition` first when sending to ArduPilot.
const FIRMWARE_ARDUPILOT: u64 = 3;
/// MAV_CMD_NAV_FENCE_RETURN_POINT, MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION and
/// _EXCLUSION (the polygon vertices and rally point are in `cmd`).
const NAV_FENCE_RETURN_POINT: u16 = 5000;
const NAV_FENCE_CIRCLE_INCLUSION: u16 = 5003;
const NAV_FENCE_CIRCLE_EXCLUSION: u16 = 5004;
/// A list longer than MISSION_COUNT's u16 cannot be sent.
const MAX_ITEMS: usize = u16::MAX as usize;

/// One list to send, in order.
#[derive(Clone, Debug, PartialEq)]
pub struct ItemList {
    pub kind: MissionKind,
    pub items: Vec<WireItem>,
    /// Item 0 is the home position (ArduPilot's convention, which
    /// `.waypoints` files follow): ArduPilot overwrites it with its own
    /// home, so the read-back compares its command only.
    pub home_first: bool,
}

/// What a `.plan` file holds.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanLists {
    pub mission: ItemList,
    pub fence: ItemList,
    pub rally: ItemList,
}

/// Why a file cannot be sent.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("not a QGC WPL 110 file (first line {0:?})")]
    NotWpl(String),
    #[error("line {line}: {why}")]
    Row { line: usize, why: String },
    #[error("not a QGroundControl plan: {0}")]
    NotPlan(String),
    #[error("{path}: {why}")]
    PlanField { path: String, why: String },
    #[error("{0} items: a MAVLink mission holds at most 65535")]
    TooMany(usize),
    #[error("{kind} file has command {command} at item {seq}, which is not a {kind} item")]
    WrongKind {
        kind: &'static str,
        command: u16,
        seq: usize,
    },
}

/// Rows of a `QGC WPL 110` file as the list `kind`. Columns (tab or
/// space separated): seq, current, frame, command, param1-4, lat, lon,
/// alt, autocontinue; `NaN` params allowed (a yaw left to the autopilot).
pub fn read_wpl(text: &str, kind: MissionKind) -> Result<ItemList, FileError> {
    let mut lines = text.lines().enumerate();
    let first = lines.next().map_or("", |(_, l)| l.trim());
    if first != "QGC WPL 110" {
        return Err(FileError::NotWpl(first.chars().take(40).collect()));
    }
    let mut items = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let row = |why: String| FileError::Row { line: line_no, why };
        let cols: Vec<&str> = line.split_whitespace().collect();
        if cols.len() != 12 {
            return Err(row(format!("{} columns, expected 12", cols.len())));
        }
        let int = |k: usize, name: &str, max: u64| -> Result<u64, FileError> {
            match cols[k].parse::<u64>() {
                Ok(v) if v <= max => Ok(v),
                _ => Err(row(format!(
                    "{name} {:?} is not a whole number up to {max}",
                    cols[k]
                ))),
            }
        };
        let num = |k: usize, name: &str| -> Result<f64, FileError> {
            cols[k]
                .parse::<f64>()
                .map_err(|_| row(format!("{name} {:?} is not a number", cols[k])))
        };
        let seq = int(0, "seq", u64::from(u16::MAX))?;
        if seq != items.len() as u64 {
            return Err(row(format!("seq {seq}, expected {}", items.len())));
        }
        let item = MavItem {
            frame: int(2, "frame", 255)? as u8,
            command: int(3, "command", u64::from(u16::MAX))? as u16,
            params: [
                num(4, "param1")?,
                num(5, "param2")?,
                num(6, "param3")?,
                num(7, "param4")?,
            ],
            lat: num(8, "latitude")?,
            lon: num(9, "longitude")?,
            alt: num(10, "altitude")?,
        };
        let autocontinue = int(11, "autocontinue", 1)? == 1;
        let wire = WireItem::from_mav_item(&item, autocontinue)
            .map_err(|e: ItemError| row(e.to_string()))?;
        items.push(wire);
        if items.len() > MAX_ITEMS {
            return Err(FileError::TooMany(items.len()));
        }
    }
    check_kind(kind, &items)?;
    Ok(ItemList {
        kind,
        items,
        home_first: kind == MissionKind::Mission,
    })
}

/// Fence lists hold fence items only, rally lists rally points only (a
/// mission file given as `--fence` would replace the fence with nonsense).
fn check_kind(kind: MissionKind, items: &[WireItem]) -> Result<(), FileError> {
    let allowed = |c: u16| match kind {
        MissionKind::Mission => true,
        MissionKind::Fence => (NAV_FENCE_RETURN_POINT..=NAV_FENCE_CIRCLE_EXCLUSION).contains(&c),
        MissionKind::Rally => c == cmd::NAV_RALLY_POINT,
    };
    match items.iter().position(|i| !allowed(i.command)) {
        Some(seq) => Err(FileError::WrongKind {
            kind: kind.name(),
            command: items[seq].command,
            seq,
        }),
        None => Ok(()),
    }
}

/// The mission, fence and rally lists of a QGroundControl `.plan`.
pub fn read_plan(text: &str) -> Result<PlanLists, FileError> {
    let doc: Value =
        serde_json::from_str(text).map_err(|e| FileError::NotPlan(format!("not JSON: {e}")))?;
    if doc.get("fileType").and_then(Value::as_str) != Some("Plan") {
        return Err(FileError::NotPlan("fileType is not \"Plan\"".into()));
    }
    let field = |path: &str, why: &str| FileError::PlanField {
        path: path.to_string(),
        why: why.to_string(),
    };
    let mission = doc
        .get("mission")
        .ok_or_else(|| field("mission", "missing"))?;
    let mut items = Vec::new();
    let ardupilot = mission.get("firmwareType").and_then(Value::as_u64) == Some(FIRMWARE_ARDUPILOT);
    if ardupilot {
        let home = lat_lon_alt(
            mission.get("plannedHomePosition"),
            "mission.plannedHomePosition",
        )?;
        // As the `.waypoints` writer puts home: NAV_WAYPOINT, frame GLOBAL.
        items.push(wire(
            &MavItem {
                command: cmd::NAV_WAYPOINT,
                frame: frame::GLOBAL,
                params: [0.0; 4],
                lat: home[0],
                lon: home[1],
                alt: home[2],
            },
            true,
            "mission.plannedHomePosition",
        )?);
    }
    let plan_items = mission
        .get("items")
        .and_then(Value::as_array)
        .ok_or_else(|| field("mission.items", "missing or not an array"))?;
    for (k, it) in plan_items.iter().enumerate() {
        let path = format!("mission.items[{k}]");
        if it.get("type").and_then(Value::as_str) != Some("SimpleItem") {
            return Err(field(
                &path,
                "not a SimpleItem (QGroundControl expands survey and corridor patterns \
                 itself; export the mission from terraplan or as .waypoints)",
            ));
        }
        let command = it
            .get("command")
            .and_then(Value::as_u64)
            .filter(|&c| c <= u64::from(u16::MAX))
            .ok_or_else(|| {
                field(
                    &format!("{path}.command"),
                    "missing or not a command number",
                )
            })?;
        let frame = it
            .get("frame")
            .and_then(Value::as_u64)
            .filter(|&f| f <= 255)
            .ok_or_else(|| field(&format!("{path}.frame"), "missing or not a frame number"))?;
        let params = it
            .get("params")
            .and_then(Value::as_array)
            .filter(|p| p.len() == 7)
            .ok_or_else(|| field(&format!("{path}.params"), "missing or not 7 values"))?;
        let mut p = [0.0; 7];
        for (j, v) in params.iter().enumerate() {
            // QGroundControl stores NaN as null.
            p[j] = match v {
                Value::Null => f64::NAN,
                v => v
                    .as_f64()
                    .ok_or_else(|| field(&format!("{path}.params[{j}]"), "not a number or null"))?,
            };
        }
        let autocontinue = it
            .get("autoContinue")
            .and_then(Value::as_bool)
            .unwrap_or(true);
        items.push(wire(
            &MavItem {
                command: command as u16,
                frame: frame as u8,
                params: [p[0], p[1], p[2], p[3]],
                lat: p[4],
                lon: p[5],
                alt: p[6],
            },
            autocontinue,
            &path,
        )?);
    }
    let fence = read_plan_fence(doc.get("geoFence"))?;
    let rally = read_plan_rally(doc.get("rallyPoints"))?;
    for list in [&items, &fence, &rally] {
        if list.len() > MAX_ITEMS {
            return Err(FileError::TooMany(list.len()));
        }
    }
    Ok(PlanLists {
        mission: ItemList {
            kind: MissionKind::Mission,
            items,
            home_first: ardupilot,
        },
        fence: ItemList {
            kind: MissionKind::Fence,
            items: fence,
            home_first: false,
        },
        rally: ItemList {
            kind: MissionKind::Rally,
            items: rally,
            home_first: false,
        },
    })
}

/// geoFence polygons (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_*, param1 = vertex
/// count, frame GLOBAL, as the `.fence.waypoints` writer and QGroundControl
/// send them), circles (param1 = radius) and the breach return point
/// (frame GLOBAL_RELATIVE_ALT: its altitude is above home).
fn read_plan_fence(fence: Option<&Value>) -> Result<Vec<WireItem>, FileError> {
    let mut out = Vec::new();
    let Some(fence) = fence else { return Ok(out) };
    let field = |path: String, why: &str| FileError::PlanField {
        path,
        why: why.to_string(),
    };
    let polygons = fence.get("polygons").and_then(Value::as_array);
    for (k, poly) in polygons.into_iter().flatten().enumerate() {
        let path = format!("geoFence.polygons[{k}]");
        let inclusion = poly
            .get("inclusion")
            .and_then(Value::as_bool)
            .ok_or_else(|| field(format!("{path}.inclusion"), "missing or not a boolean"))?;
        let vertices = poly
            .get("polygon")
            .and_then(Value::as_array)
            .filter(|v| v.len() >= 3)
            .ok_or_else(|| {
                field(
                    format!("{path}.polygon"),
                    "missing or fewer than 3 vertices",
                )
            })?;
        let command = if inclusion {
            cmd::NAV_FENCE_POLYGON_VERTEX_INCLUSION
        } else {
            cmd::NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        };
        for (j, v) in vertices.iter().enumerate() {
            let vpath = format!("{path}.polygon[{j}]");
            let [lat, lon] = lat_lon(v, &vpath)?;
            out.push(wire(
                &MavItem {
                    command,
                    frame: frame::GLOBAL,
                    params: [vertices.len() as f64, 0.0, 0.0, 0.0],
                    lat,
                    lon,
                    alt: 0.0,
                },
                true,
                &vpath,
            )?);
        }
    }
    let circles = fence.get("circles").and_then(Value::as_array);
    for (k, c) in circles.into_iter().flatten().enumerate() {
        let path = format!("geoFence.circles[{k}]");
        let inclusion = c
            .get("inclusion")
            .and_then(Value::as_bool)
            .ok_or_else(|| field(format!("{path}.inclusion"), "missing or not a boolean"))?;
        let circle = c
            .get("circle")
            .ok_or_else(|| field(format!("{path}.circle"), "missing"))?;
        let [lat, lon] = lat_lon(
            circle.get("center").unwrap_or(&Value::Null),
            &format!("{path}.circle.center"),
        )?;
        let radius = circle
            .get("radius")
            .and_then(Value::as_f64)
            .filter(|r| *r > 0.0)
            .ok_or_else(|| field(format!("{path}.circle.radius"), "missing or not positive"))?;
        out.push(wire(
            &MavItem {
                command: if inclusion {
                    NAV_FENCE_CIRCLE_INCLUSION
                } else {
                    NAV_FENCE_CIRCLE_EXCLUSION
                },
                frame: frame::GLOBAL,
                params: [radius, 0.0, 0.0, 0.0],
                lat,
                lon,
                alt: 0.0,
            },
            true,
            &path,
        )?);
    }
    if let Some(ret) = fence.get("breachReturn") {
        let p = lat_lon_alt(Some(ret), "geoFence.breachReturn")?;
        out.push(wire(
            &MavItem {
                command: NAV_FENCE_RETURN_POINT,
                frame: frame::GLOBAL_RELATIVE_ALT,
                params: [0.0; 4],
                lat: p[0],
                lon: p[1],
                alt: p[2],
            },
            true,
            "geoFence.breachReturn",
        )?);
    }
    Ok(out)
}

/// rallyPoints.points as MAV_CMD_NAV_RALLY_POINT, altitude above home
/// (frame GLOBAL_RELATIVE_ALT), as the `.rally.waypoints` writer puts them.
fn read_plan_rally(rally: Option<&Value>) -> Result<Vec<WireItem>, FileError> {
    let points = rally
        .and_then(|r| r.get("points"))
        .and_then(Value::as_array);
    let mut out = Vec::new();
    for (k, p) in points.into_iter().flatten().enumerate() {
        let path = format!("rallyPoints.points[{k}]");
        let [lat, lon, alt] = lat_lon_alt(Some(p), &path)?;
        out.push(wire(
            &MavItem {
                command: cmd::NAV_RALLY_POINT,
                frame: frame::GLOBAL_RELATIVE_ALT,
                params: [0.0; 4],
                lat,
                lon,
                alt,
            },
            true,
            &path,
        )?);
    }
    Ok(out)
}

fn wire(item: &MavItem, autocontinue: bool, path: &str) -> Result<WireItem, FileError> {
    WireItem::from_mav_item(item, autocontinue).map_err(|e| FileError::PlanField {
        path: path.to_string(),
        why: e.to_string(),
    })
}

fn numbers<const N: usize>(
    v: Option<&Value>,
    path: &str,
    what: &str,
) -> Result<[f64; N], FileError> {
    let fail = || FileError::PlanField {
        path: path.to_string(),
        why: format!("not {what}"),
    };
    let arr = v
        .and_then(Value::as_array)
        .filter(|a| a.len() == N)
        .ok_or_else(fail)?;
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(arr) {
        *o = x.as_f64().ok_or_else(fail)?;
    }
    Ok(out)
}

fn lat_lon(v: &Value, path: &str) -> Result<[f64; 2], FileError> {
    numbers(Some(v), path, "[latitude, longitude]")
}

fn lat_lon_alt(v: Option<&Value>, path: &str) -> Result<[f64; 3], FileError> {
    numbers(v, path, "[latitude, longitude, altitude]")
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner_core::export::mission::{
        AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem,
    };
    use planner_core::export::waypoints::write_rally;
    use planner_core::export::{write_fence, write_plan, write_waypoints};

    fn mission() -> Mission {
        let home = GeoPoint {
            lon: 5.1,
            lat: 52.2,
            alt: 3.0,
        };
        Mission {
            home,
            frame: AltitudeFrame::Relative,
            cruise_speed_m_s: 8.0,
            items: vec![
                MissionItem::Takeoff { alt: 40.0 },
                MissionItem::ChangeSpeed { speed_m_s: 8.0 },
                MissionItem::CameraTriggerDistance { distance_m: 12.5 },
                MissionItem::Waypoint(GeoPoint {
                    lon: 5.123_456_789,
                    lat: 52.21,
                    alt: 40.0,
                }),
                MissionItem::ReturnToLaunch,
            ],
            over_terrain: false,
        }
    }

    fn fences() -> Vec<FencePolygon> {
        vec![FencePolygon {
            inclusion: true,
            vertices: vec![[5.0, 52.0], [5.2, 52.0], [5.2, 52.3], [5.0, 52.3]],
        }]
    }

    #[test]
    fn waypoints_and_plan_give_the_same_lists() {
        let m = mission();
        let rally = [GeoPoint {
            lon: 5.11,
            lat: 52.25,
            alt: 30.0,
        }];
        let wpl = read_wpl(&write_waypoints(&m), MissionKind::Mission).unwrap();
        let plan = read_plan(&write_plan(&m, &fences(), &rally)).unwrap();
        assert_eq!(wpl.items.len(), 6);
        assert_eq!(wpl.items.len(), plan.mission.items.len());
        for (k, (a, b)) in wpl.items.iter().zip(&plan.mission.items).enumerate() {
            // NaN yaw: compare bit patterns of the params.
            let bits = |w: &WireItem| w.params.map(f32::to_bits);
            assert_eq!(
                (a.command, a.frame, a.x, a.y, a.z),
                (b.command, b.frame, b.x, b.y, b.z),
                "item {k}"
            );
            assert_eq!(
                bits(a).map(|b| b != f32::NAN.to_bits()),
                bits(b).map(|b| b != f32::NAN.to_bits())
            );
        }
        assert!(wpl.home_first && plan.mission.home_first);
        let fence = read_wpl(&write_fence(&fences()), MissionKind::Fence).unwrap();
        // The plan's fence adds the breach return point.
        assert_eq!(plan.fence.items[..4], fence.items[..]);
        let ret = plan.fence.items[4];
        assert_eq!(
            (ret.command, ret.x, ret.y, ret.z),
            (5000, 522_500_000, 51_100_000, 30.0)
        );
        let rally_wpl = read_wpl(&write_rally(&rally), MissionKind::Rally).unwrap();
        assert_eq!(plan.rally.items, rally_wpl.items);
    }

    #[test]
    fn bad_files_name_the_fault() {
        let e = read_wpl("hello\n", MissionKind::Mission).unwrap_err();
        assert!(e.to_string().contains("not a QGC WPL 110"), "{e}");
        let e = read_wpl(
            "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t52\t5\n",
            MissionKind::Mission,
        )
        .unwrap_err();
        assert_eq!(e.to_string(), "line 2: 10 columns, expected 12");
        let e = read_wpl(
            "QGC WPL 110\n1\t1\t0\t16\t0\t0\t0\t0\t52\t5\t3\t1\n",
            MissionKind::Mission,
        )
        .unwrap_err();
        assert_eq!(e.to_string(), "line 2: seq 1, expected 0");
        let e = read_wpl(
            "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t95\t5\t3\t1\n",
            MissionKind::Mission,
        )
        .unwrap_err();
        assert!(e.to_string().contains("latitude 95"), "{e}");
        let e = read_wpl(&write_waypoints(&mission()), MissionKind::Fence).unwrap_err();
        assert!(
            e.to_string()
                .contains("fence file has command 16 at item 0"),
            "{e}"
        );
        let e = read_plan(
            "{\"fileType\": \"Plan\", \"mission\": {\"items\": [{\"type\": \"ComplexItem\"}]}}",
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("mission.items[0]: not a SimpleItem"),
            "{e}"
        );
        let e = read_plan("[1]").unwrap_err();
        assert!(e.to_string().contains("fileType"), "{e}");
    }

    #[test]
    fn plan_without_ardupilot_firmware_has_no_home_item() {
        let text =
            write_plan(&mission(), &[], &[]).replace("\"firmwareType\": 3", "\"firmwareType\": 12");
        let plan = read_plan(&text).unwrap();
        assert!(!plan.mission.home_first);
        assert_eq!(plan.mission.items.len(), 5);
        assert_eq!(plan.mission.items[0].command, cmd::NAV_TAKEOFF);
        assert!(plan.fence.items.is_empty() && plan.rally.items.is_empty());
    }
}
