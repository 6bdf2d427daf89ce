//! QGroundControl `.plan` files (fileType "Plan", version 1, mission
//! version 2) with the no-fly zones as exclusion fences, the survey area as
//! an inclusion fence, rally points, and the first rally point as the
//! fence's breach return point.

use serde::ser::{Serialize, SerializeMap, Serializer};

use super::mission::{AltitudeFrame, FencePolygon, GeoPoint, MavItem, Mission, cmd};

/// QGC's `firmwareType` for ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
const FIRMWARE_ARDUPILOT: u8 = 3;
/// QGC's `vehicleType` for a multirotor (MAV_TYPE_QUADROTOR).
const VEHICLE_MULTIROTOR: u8 = 2;
/// `fenceAction` of each fence polygon. QGroundControl builds that know the
/// key require it (QGCFencePolygon::loadFromJson) and send it as param3 of
/// the polygon's vertices; 0 keeps param3 as MAVLink reserves it and as the
/// `.fence.waypoints` file writes it, so the breach action is the vehicle's
/// own (ArduPilot's `FENCE_ACTION`, PX4's `GF_ACTION`). Other builds ignore
/// the key.
const FENCE_ACTION: u8 = 0;

/// The mission, fences and rally points (altitude above home) as a
/// QGroundControl plan document, indented, with a final newline. The first
/// rally point is also the fence's `breachReturn` (QGroundControl sends it
/// to ArduPilot as MAV_CMD_NAV_FENCE_RETURN_POINT): a point inside the
/// inclusion fence and clear of the no-fly zones; without rally points the
/// key is left out and the autopilot returns home.
///
/// Serialised straight from the mission (no `serde_json::Value` in
/// between): a plan among thousands of no-fly zones is tens of MB. Keys are
/// written in byte order, as a JSON object map would sort them.
pub fn write_plan(mission: &Mission, fences: &[FencePolygon], rally: &[GeoPoint]) -> String {
    // QGC's AltMode: 1 relative, 2 absolute (AMSL), 4 terrain frame.
    let altitude_mode = match mission.frame {
        AltitudeFrame::Relative => 1,
        AltitudeFrame::Amsl => 2,
        AltitudeFrame::Terrain => 4,
    };
    let home = mission.home;
    let items = mission.mav_items();
    let document = PlanDocument {
        file_type: "Plan",
        geo_fence: GeoFence {
            breach_return: rally.first().map(|p| [p.lat, p.lon, p.alt]),
            circles: [],
            polygons: FencePolygons(fences),
            version: 2,
        },
        ground_station: "terraplan",
        mission: PlanMission {
            cruise_speed: mission.cruise_speed_m_s,
            firmware_type: FIRMWARE_ARDUPILOT,
            global_plan_altitude_mode: altitude_mode,
            hover_speed: mission.cruise_speed_m_s,
            items: PlanItems {
                items: &items,
                altitude_mode,
            },
            planned_home_position: [home.lat, home.lon, home.alt],
            vehicle_type: VEHICLE_MULTIROTOR,
            version: 2,
        },
        rally_points: RallyPoints {
            points: rally.iter().map(|p| [p.lat, p.lon, p.alt]).collect(),
            version: 2,
        },
        version: 1,
    };
    let mut text = serde_json::to_string_pretty(&document).unwrap_or_default();
    text.push('\n');
    text
}

// Fields in byte order of their JSON keys (see `write_plan`).
#[derive(serde::Serialize)]
struct PlanDocument<'a> {
    #[serde(rename = "fileType")]
    file_type: &'static str,
    #[serde(rename = "geoFence")]
    geo_fence: GeoFence<'a>,
    #[serde(rename = "groundStation")]
    ground_station: &'static str,
    mission: PlanMission<'a>,
    #[serde(rename = "rallyPoints")]
    rally_points: RallyPoints,
    version: u8,
}

#[derive(serde::Serialize)]
struct GeoFence<'a> {
    #[serde(rename = "breachReturn", skip_serializing_if = "Option::is_none")]
    breach_return: Option<[f64; 3]>,
    circles: [u8; 0],
    polygons: FencePolygons<'a>,
    version: u8,
}

#[derive(serde::Serialize)]
struct RallyPoints {
    points: Vec<[f64; 3]>,
    version: u8,
}

#[derive(serde::Serialize)]
struct PlanMission<'a> {
    #[serde(rename = "cruiseSpeed")]
    cruise_speed: f64,
    #[serde(rename = "firmwareType")]
    firmware_type: u8,
    #[serde(rename = "globalPlanAltitudeMode")]
    global_plan_altitude_mode: u8,
    #[serde(rename = "hoverSpeed")]
    hover_speed: f64,
    items: PlanItems<'a>,
    #[serde(rename = "plannedHomePosition")]
    planned_home_position: [f64; 3],
    #[serde(rename = "vehicleType")]
    vehicle_type: u8,
    version: u8,
}

/// The fence polygons, vertices as QGC writes them: [lat, lon].
struct FencePolygons<'a>(&'a [FencePolygon]);

impl Serialize for FencePolygons<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(FenceEntry))
    }
}

struct FenceEntry<'a>(&'a FencePolygon);

impl Serialize for FenceEntry<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(4))?;
        map.serialize_entry("fenceAction", &FENCE_ACTION)?;
        map.serialize_entry("inclusion", &self.0.inclusion)?;
        map.serialize_entry("polygon", &LatLonRing(&self.0.vertices))?;
        map.serialize_entry("version", &1)?;
        map.end()
    }
}

struct LatLonRing<'a>(&'a [[f64; 2]]);

impl Serialize for LatLonRing<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(|v| [v[1], v[0]]))
    }
}

/// The mission items as QGC's `SimpleItem`s.
struct PlanItems<'a> {
    items: &'a [MavItem],
    altitude_mode: u8,
}

impl Serialize for PlanItems<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.items.iter().enumerate().map(|(i, item)| PlanItem {
            jump_id: i + 1,
            item,
            altitude_mode: self.altitude_mode,
        }))
    }
}

struct PlanItem<'a> {
    jump_id: usize,
    item: &'a MavItem,
    altitude_mode: u8,
}

impl Serialize for PlanItem<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let m = self.item;
        // QGC's own altitude fields on positional items, so its editor
        // shows the same altitude mode as the frame.
        let positional = m.command == cmd::NAV_TAKEOFF || m.command == cmd::NAV_WAYPOINT;
        let mut map = s.serialize_map(Some(if positional { 9 } else { 6 }))?;
        if positional {
            map.serialize_entry("AMSLAltAboveTerrain", &())?;
            map.serialize_entry("Altitude", &m.alt)?;
            map.serialize_entry("AltitudeMode", &self.altitude_mode)?;
        }
        map.serialize_entry("autoContinue", &true)?;
        map.serialize_entry("command", &m.command)?;
        map.serialize_entry("doJumpId", &self.jump_id)?;
        map.serialize_entry("frame", &m.frame)?;
        // A parameter QGC stores as null when NaN (e.g. `KEEP_HEADING`):
        // serde_json writes a non-finite number as null.
        let [p1, p2, p3, p4] = m.params;
        map.serialize_entry("params", &[p1, p2, p3, p4, m.lat, m.lon, m.alt])?;
        map.serialize_entry("type", "SimpleItem")?;
        map.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    fn plan_value(mission: &Mission, fences: &[FencePolygon], rally: &[GeoPoint]) -> Value {
        serde_json::from_str(&write_plan(mission, fences, rally)).expect("the plan is JSON")
    }
    use crate::export::mission::MissionItem;
    use crate::export::write_waypoints;

    #[test]
    fn plan_structure_matches_qgc() {
        let m = Mission {
            home: GeoPoint {
                lon: 8.5,
                lat: 47.4,
                alt: 400.0,
            },
            frame: AltitudeFrame::Terrain,
            cruise_speed_m_s: 12.0,
            over_terrain: false,
            items: vec![
                MissionItem::Takeoff { alt: 50.0 },
                MissionItem::Waypoint(GeoPoint {
                    lon: 8.51,
                    lat: 47.41,
                    alt: 50.0,
                }),
                MissionItem::ReturnToLaunch,
            ],
        };
        let fences = [FencePolygon {
            inclusion: false,
            vertices: vec![[8.5, 47.4], [8.6, 47.4], [8.6, 47.5]],
        }];
        let plan = plan_value(&m, &fences, &[]);
        assert_eq!(plan["fileType"], "Plan");
        assert_eq!(plan["version"], 1);
        assert_eq!(plan["mission"]["version"], 2);
        assert_eq!(plan["mission"]["plannedHomePosition"][0], 47.4);
        let items = plan["mission"]["items"].as_array().unwrap();
        assert_eq!(items.len(), 3);
        assert_eq!(items[1]["command"], 16);
        assert_eq!(items[1]["frame"], 10);
        assert_eq!(items[1]["AltitudeMode"], 4);
        assert_eq!(items[1]["Altitude"], items[1]["params"][6]);
        assert_eq!(plan["mission"]["globalPlanAltitudeMode"], 4);
        assert_eq!(items[1]["params"][4], 47.41);
        assert_eq!(items[1]["params"][5], 8.51);
        assert_eq!(items[2]["doJumpId"], 3);
        let poly = &plan["geoFence"]["polygons"][0];
        assert_eq!(poly["inclusion"], false);
        assert_eq!(poly["polygon"][1], json!([47.4, 8.6]));
        // The keys QGroundControl's fence loader requires.
        assert_eq!(poly["version"], 1);
        assert_eq!(poly["fenceAction"], 0);
        assert_eq!(plan["rallyPoints"], json!({"points": [], "version": 2}));
        // No rally point, no breach return point: QGroundControl reads the
        // key as optional.
        assert!(plan["geoFence"].get("breachReturn").is_none());
        // Take-off and waypoint yaw: null (NaN, keep the heading); RTL: 0.
        assert_eq!(items[0]["params"][3], Value::Null);
        assert_eq!(items[1]["params"][3], Value::Null);
        assert_eq!(items[2]["params"][3], 0.0);
    }

    #[test]
    fn plan_items_agree_with_waypoints_rows() {
        let mut m = crate::export::mission::sample_mission(GeoPoint {
            lon: 1.001,
            lat: 2.002,
            alt: 40.0,
        });
        m.items
            .insert(1, MissionItem::ChangeSpeed { speed_m_s: 7.0 });
        m.items
            .insert(2, MissionItem::CameraTriggerDistance { distance_m: 12.5 });
        let plan = plan_value(&m, &[], &[]);
        let text = write_waypoints(&m);
        let rows: Vec<Vec<f64>> = text
            .lines()
            .skip(2)
            .map(|l| l.split('\t').map(|c| c.parse().unwrap()).collect())
            .collect();
        let items = plan["mission"]["items"].as_array().unwrap();
        assert_eq!(rows.len(), items.len());
        for (row, item) in rows.iter().zip(items) {
            assert_eq!(row[3], item["command"].as_f64().unwrap());
            assert_eq!(row[2], item["frame"].as_f64().unwrap());
            for k in 0..7 {
                let p = item["params"][k].as_f64().unwrap_or(f64::NAN);
                let w = row[4 + k];
                // .waypoints rounds to 6 (params, alt) or 8 (lat/lon) decimals.
                assert!(
                    (p.is_nan() && w.is_nan()) || (p - w).abs() <= 5e-7,
                    "param {}: plan {p} vs waypoints {w}",
                    k + 1
                );
            }
        }
    }

    #[test]
    fn rally_points_are_lat_lon_alt() {
        let m = crate::export::mission::sample_mission(GeoPoint {
            lon: 1.001,
            lat: 2.002,
            alt: 40.0,
        });
        let plan = plan_value(
            &m,
            &[],
            &[GeoPoint {
                lon: 1.01,
                lat: 2.02,
                alt: 45.5,
            }],
        );
        assert_eq!(
            plan["rallyPoints"],
            json!({"points": [[2.02, 1.01, 45.5]], "version": 2})
        );
        // The fence's breach return point: [lat, lon, alt], as QGC saves it.
        assert_eq!(plan["geoFence"]["breachReturn"], json!([2.02, 1.01, 45.5]));
    }
}
