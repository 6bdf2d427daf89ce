//! QGroundControl `.plan` files (fileType "Plan", version 1, mission
//! version 2) with the no-fly zones as exclusion fences, the survey area as
//! an inclusion fence, and rally points.

use serde_json::{Value, json};

use super::mission::{AltitudeFrame, FencePolygon, GeoPoint, Mission, cmd};

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

/// A mission parameter as QGC stores it: NaN (e.g. `KEEP_HEADING`) as null.
fn param(v: f64) -> Value {
    if v.is_nan() { Value::Null } else { v.into() }
}

/// The mission, fences and rally points (altitude above home) as a
/// QGroundControl plan document.
pub fn write_plan(mission: &Mission, fences: &[FencePolygon], rally: &[GeoPoint]) -> Value {
    // QGC's AltMode: 1 relative, 2 absolute (AMSL), 4 terrain frame.
    let altitude_mode = match mission.frame {
        AltitudeFrame::Relative => 1,
        AltitudeFrame::Amsl => 2,
        AltitudeFrame::Terrain => 4,
    };
    let home = mission.home;
    let items: Vec<Value> = mission
        .mav_items()
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let [p1, p2, p3, p4] = m.params;
            let params = [p1, p2, p3, p4, m.lat, m.lon, m.alt].map(param);
            let mut out = json!({
                "autoContinue": true,
                "command": m.command,
                "doJumpId": i + 1,
                "frame": m.frame,
                "params": params,
                "type": "SimpleItem",
            });
            // QGC's own altitude fields on positional items, so its editor
            // shows the same altitude mode as the frame.
            if m.command == cmd::NAV_TAKEOFF || m.command == cmd::NAV_WAYPOINT {
                out["Altitude"] = m.alt.into();
                out["AltitudeMode"] = altitude_mode.into();
                out["AMSLAltAboveTerrain"] = Value::Null;
            }
            out
        })
        .collect();
    let polygons: Vec<Value> = fences
        .iter()
        .map(|p| {
            json!({
                "fenceAction": FENCE_ACTION,
                "inclusion": p.inclusion,
                "polygon": p.vertices.iter().map(|v| [v[1], v[0]]).collect::<Vec<_>>(),
                "version": 1,
            })
        })
        .collect();
    let rally_points: Vec<[f64; 3]> = rally.iter().map(|p| [p.lat, p.lon, p.alt]).collect();
    json!({
        "fileType": "Plan",
        "version": 1,
        "groundStation": "terraplan",
        "geoFence": { "circles": [], "polygons": polygons, "version": 2 },
        "rallyPoints": { "points": rally_points, "version": 2 },
        "mission": {
            "cruiseSpeed": mission.cruise_speed_m_s,
            "hoverSpeed": mission.cruise_speed_m_s,
            "firmwareType": FIRMWARE_ARDUPILOT,
            "vehicleType": VEHICLE_MULTIROTOR,
            "globalPlanAltitudeMode": altitude_mode,
            "items": items,
            "plannedHomePosition": [home.lat, home.lon, home.alt],
            "version": 2,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
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
        let plan = write_plan(&m, &fences, &[]);
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
        let plan = write_plan(&m, &[], &[]);
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
        let plan = write_plan(
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
    }
}
