//! QGroundControl `.plan` files (fileType "Plan", version 1, mission
//! version 2) with the no-fly zones as exclusion fences and the survey area
//! as an inclusion fence.

use serde_json::{Value, json};

use super::mission::{AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem, cmd, frame};

/// QGC's `firmwareType` for ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
const FIRMWARE_ARDUPILOT: u8 = 3;
/// QGC's `vehicleType` for a multirotor (MAV_TYPE_QUADROTOR).
const VEHICLE_MULTIROTOR: u8 = 2;

/// The mission and fences as a QGroundControl plan document.
pub fn write_plan(mission: &Mission, fences: &[FencePolygon]) -> Value {
    let f = mission.frame.mav_frame();
    // QGC's AltMode: 1 relative, 2 absolute (AMSL), 4 terrain frame.
    let altitude_mode = match mission.frame {
        AltitudeFrame::Relative => 1,
        AltitudeFrame::Amsl => 2,
        AltitudeFrame::Terrain => 4,
    };
    let home = mission.home;
    let items: Vec<Value> = mission
        .items
        .iter()
        .enumerate()
        .map(|(i, item)| {
            let (command, fr, params): (u16, u8, [Value; 7]) = match *item {
                MissionItem::Takeoff { alt } => (
                    cmd::NAV_TAKEOFF,
                    f,
                    [
                        0.into(),
                        0.into(),
                        0.into(),
                        Value::Null,
                        home.lat.into(),
                        home.lon.into(),
                        alt.into(),
                    ],
                ),
                MissionItem::ChangeSpeed { speed_m_s } => (
                    cmd::DO_CHANGE_SPEED,
                    frame::MISSION,
                    [
                        1.into(),
                        speed_m_s.into(),
                        (-1).into(),
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                    ],
                ),
                MissionItem::Waypoint(p) => (
                    cmd::NAV_WAYPOINT,
                    f,
                    [
                        0.into(),
                        0.into(),
                        0.into(),
                        Value::Null,
                        p.lat.into(),
                        p.lon.into(),
                        p.alt.into(),
                    ],
                ),
                MissionItem::CameraTriggerDistance { distance_m } => (
                    cmd::DO_SET_CAM_TRIGG_DIST,
                    frame::MISSION,
                    [
                        distance_m.into(),
                        0.into(),
                        (if distance_m > 0.0 { 1 } else { 0 }).into(),
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                    ],
                ),
                MissionItem::ReturnToLaunch => (
                    cmd::NAV_RETURN_TO_LAUNCH,
                    f,
                    [
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                        0.into(),
                    ],
                ),
            };
            let mut out = json!({
                "autoContinue": true,
                "command": command,
                "doJumpId": i + 1,
                "frame": fr,
                "params": params,
                "type": "SimpleItem",
            });
            // QGC's own altitude fields on positional items, so its editor
            // shows the same altitude mode as the frame.
            if let MissionItem::Takeoff { alt } | MissionItem::Waypoint(GeoPoint { alt, .. }) =
                *item
            {
                out["Altitude"] = alt.into();
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
                "inclusion": p.inclusion,
                "polygon": p.vertices.iter().map(|v| [v[1], v[0]]).collect::<Vec<_>>(),
                "version": 1,
            })
        })
        .collect();
    json!({
        "fileType": "Plan",
        "version": 1,
        "groundStation": "terraplan",
        "geoFence": { "circles": [], "polygons": polygons, "version": 2 },
        "rallyPoints": { "points": [], "version": 2 },
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
    use crate::export::mission::{AltitudeFrame, GeoPoint};

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
        let plan = write_plan(&m, &fences);
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
    }
}
