//! The autopilot mission of one UAV, independent of file format.

use serde::{Deserialize, Serialize};

/// MAVLink command ids used in exported missions.
pub mod cmd {
    pub const NAV_WAYPOINT: u16 = 16;
    pub const NAV_RETURN_TO_LAUNCH: u16 = 20;
    pub const NAV_LAND: u16 = 21;
    pub const NAV_TAKEOFF: u16 = 22;
    pub const NAV_VTOL_TAKEOFF: u16 = 84;
    pub const NAV_VTOL_LAND: u16 = 85;
    pub const DO_LAND_START: u16 = 189;
    pub const DO_CHANGE_SPEED: u16 = 178;
    pub const DO_SET_CAM_TRIGG_DIST: u16 = 206;
    pub const DO_SET_CAM_TRIGG_INTERVAL: u16 = 214;
    pub const DO_GIMBAL_MANAGER_PITCHYAW: u16 = 1000;
    pub const IMAGE_START_CAPTURE: u16 = 2000;
    pub const DO_TRIGGER_CONTROL: u16 = 2003;
    pub const NAV_FENCE_POLYGON_VERTEX_INCLUSION: u16 = 5001;
    pub const NAV_FENCE_POLYGON_VERTEX_EXCLUSION: u16 = 5002;
    pub const NAV_RALLY_POINT: u16 = 5100;
}

/// Param 4 (yaw) of take-off and waypoint items: NaN, which MAVLink defines
/// as "keep the current yaw behaviour" for MAV_CMD_NAV_WAYPOINT and
/// MAV_CMD_NAV_TAKEOFF. PX4 then yaws by its yaw mode (towards the next
/// waypoint by default) where 0 would turn it north at every waypoint;
/// ArduPilot accepts NaN in exactly this parameter (AP_Mission's
/// sanity_check_params) and yaws by `WP_YAW_BEHAVIOR` either way.
/// `.waypoints` files carry it as `NaN` (how Mission Planner prints it; read
/// by pymavlink, MAVProxy, MAVSDK's strtod and Qt), `.plan` files as `null`
/// (how QGroundControl stores NaN).
pub const KEEP_HEADING: f64 = f64::NAN;

/// MAV_FRAME values.
pub mod frame {
    pub const GLOBAL: u8 = 0;
    pub const MISSION: u8 = 2;
    pub const GLOBAL_RELATIVE_ALT: u8 = 3;
    pub const GLOBAL_TERRAIN_ALT: u8 = 10;
}

/// How mission altitudes are expressed (SPEC §2).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AltitudeFrame {
    /// Above home (MAV_FRAME_GLOBAL_RELATIVE_ALT = 3).
    #[default]
    Relative,
    /// Above mean sea level (MAV_FRAME_GLOBAL = 0); assumes an orthometric DEM.
    Amsl,
    /// Above terrain, followed by the autopilot (MAV_FRAME_GLOBAL_TERRAIN_ALT = 10).
    Terrain,
}

impl AltitudeFrame {
    pub fn mav_frame(self) -> u8 {
        match self {
            AltitudeFrame::Relative => frame::GLOBAL_RELATIVE_ALT,
            AltitudeFrame::Amsl => frame::GLOBAL,
            AltitudeFrame::Terrain => frame::GLOBAL_TERRAIN_ALT,
        }
    }
}

/// A WGS84 position with an altitude in the mission's frame (metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeoPoint {
    pub lon: f64,
    pub lat: f64,
    pub alt: f64,
}

/// One step of a mission, in flight order.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum MissionItem {
    /// Climb to `alt` above the launch point.
    Takeoff { alt: f64 },
    /// Set the ground speed.
    ChangeSpeed { speed_m_s: f64 },
    /// Fly to a point.
    Waypoint(GeoPoint),
    /// Trigger the camera every `distance_m` metres (0 stops triggering).
    CameraTriggerDistance { distance_m: f64 },
    /// Fly home and land.
    ReturnToLaunch,
    /// A plane's take-off: climb to `alt` above the launch point, nose up
    /// at least `pitch_deg`.
    PlaneTakeoff { alt: f64, pitch_deg: f64 },
    /// A VTOL's vertical take-off to `alt`, then the transition to forward
    /// flight.
    VtolTakeoff { alt: f64 },
    /// Marks where the landing sequence starts (RTL jumps there).
    LandStart,
    /// A plane's landing at a point, on the slope from the waypoint before.
    Land(GeoPoint),
    /// A VTOL's landing: fly to the point, transition, descend vertically.
    VtolLand(GeoPoint),
    /// Point the gimbal `deg` below (negative) the horizon, facing forward.
    GimbalPitch { deg: f64 },
    /// Set the time between photos of time-based triggering.
    CameraTriggerInterval { interval_s: f64 },
    /// Start (`on`) or stop time-based triggering.
    CameraTriggerControl { on: bool },
    /// Fly to a point and hover there `hold_s` seconds.
    HoldWaypoint { point: GeoPoint, hold_s: f64 },
    /// Take one photo.
    ImageStartCapture,
}

/// A complete mission for one vehicle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mission {
    /// Launch point; `alt` is metres above mean sea level (0 without a DEM).
    pub home: GeoPoint,
    /// Frame of every altitude in `items` (not of `home`).
    pub frame: AltitudeFrame,
    pub cruise_speed_m_s: f64,
    pub items: Vec<MissionItem>,
    /// Planned over a DEM: `home.alt` is the DEM height at home and the
    /// altitudes follow the terrain (so a relative altitude is not a
    /// height above the ground under the waypoint).
    #[serde(default)]
    pub over_terrain: bool,
}

/// One MAVLink mission item as every mission format writes it: command,
/// frame, params 1–4 and position (params 5–7; 0 where the command has
/// none). Both the `.waypoints` and the `.plan` writer render these, so the
/// two files of a mission agree item by item.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MavItem {
    pub command: u16,
    pub frame: u8,
    pub params: [f64; 4],
    pub lat: f64,
    pub lon: f64,
    pub alt: f64,
}

impl MavItem {
    /// A command without a position (frame MAV_FRAME_MISSION).
    fn action(command: u16, params: [f64; 4]) -> MavItem {
        MavItem {
            command,
            frame: frame::MISSION,
            params,
            lat: 0.0,
            lon: 0.0,
            alt: 0.0,
        }
    }
}

impl Mission {
    /// The mission items in flight order, without home (which the
    /// `.waypoints` file writes as item 0 and the `.plan` file as
    /// `plannedHomePosition`).
    pub fn mav_items(&self) -> Vec<MavItem> {
        let home = self.home;
        let f = self.frame.mav_frame();
        // A command at a position, in the mission's frame.
        let nav = |command: u16, params: [f64; 4], p: GeoPoint| MavItem {
            command,
            frame: f,
            params,
            lat: p.lat,
            lon: p.lon,
            alt: p.alt,
        };
        self.items
            .iter()
            .map(|item| match *item {
                MissionItem::Takeoff { alt } => nav(
                    cmd::NAV_TAKEOFF,
                    [0.0, 0.0, 0.0, KEEP_HEADING],
                    GeoPoint { alt, ..home },
                ),
                // param1 1 = ground speed; param3 -1 = leave throttle unchanged.
                MissionItem::ChangeSpeed { speed_m_s } => {
                    MavItem::action(cmd::DO_CHANGE_SPEED, [1.0, speed_m_s, -1.0, 0.0])
                }
                MissionItem::Waypoint(p) => {
                    nav(cmd::NAV_WAYPOINT, [0.0, 0.0, 0.0, KEEP_HEADING], p)
                }
                // param3 1 = take a photo at once when a distance is set.
                MissionItem::CameraTriggerDistance { distance_m } => MavItem::action(
                    cmd::DO_SET_CAM_TRIGG_DIST,
                    [
                        distance_m,
                        0.0,
                        if distance_m > 0.0 { 1.0 } else { 0.0 },
                        0.0,
                    ],
                ),
                MissionItem::ReturnToLaunch => MavItem {
                    frame: f,
                    ..MavItem::action(cmd::NAV_RETURN_TO_LAUNCH, [0.0; 4])
                },
                // Param 1 is the (minimum) pitch of the climb for planes in
                // both ArduPlane and PX4.
                MissionItem::PlaneTakeoff { alt, pitch_deg } => nav(
                    cmd::NAV_TAKEOFF,
                    [pitch_deg, 0.0, 0.0, KEEP_HEADING],
                    GeoPoint { alt, ..home },
                ),
                // Param 2 0 = the autopilot's default transition heading.
                MissionItem::VtolTakeoff { alt } => nav(
                    cmd::NAV_VTOL_TAKEOFF,
                    [0.0, 0.0, 0.0, KEEP_HEADING],
                    GeoPoint { alt, ..home },
                ),
                MissionItem::LandStart => MavItem::action(cmd::DO_LAND_START, [0.0; 4]),
                // Abort altitude and precision landing 0 = the defaults.
                MissionItem::Land(p) => nav(cmd::NAV_LAND, [0.0, 0.0, 0.0, KEEP_HEADING], p),
                MissionItem::VtolLand(p) => {
                    nav(cmd::NAV_VTOL_LAND, [0.0, 0.0, 0.0, KEEP_HEADING], p)
                }
                MissionItem::HoldWaypoint { point, hold_s } => {
                    nav(cmd::NAV_WAYPOINT, [hold_s, 0.0, 0.0, KEEP_HEADING], point)
                }
                // Pointed with DO_GIMBAL_MANAGER_PITCHYAW, not the older
                // DO_MOUNT_CONTROL: both autopilots run it as a mission item
                // (ArduPilot from 4.3, whose gimbal page keeps
                // DO_MOUNT_CONTROL for the mount mode only; PX4 from 1.13
                // with MNT_MODE_IN "MAVLink gimbal v2", its DO_MOUNT_CONTROL
                // input being deprecated), and MAVLink deprecated
                // DO_MOUNT_CONTROL in 2020. Yaw 0 = ahead (flags 0 in param
                // 5: vehicle frame), rates NaN = unset so the angle rules,
                // gimbal device 0 = all (param 7).
                MissionItem::GimbalPitch { deg } => MavItem::action(
                    cmd::DO_GIMBAL_MANAGER_PITCHYAW,
                    [deg, 0.0, f64::NAN, f64::NAN],
                ),
                // Cycle time in ms; shutter time -1 = unchanged.
                MissionItem::CameraTriggerInterval { interval_s } => MavItem::action(
                    cmd::DO_SET_CAM_TRIGG_INTERVAL,
                    [interval_s * 1000.0, -1.0, 0.0, 0.0],
                ),
                // An interval of 0 means "ignore" in MAVLink, not "stop":
                // time triggering is started and stopped by this (reset
                // and pause -1 = unchanged).
                MissionItem::CameraTriggerControl { on } => MavItem::action(
                    cmd::DO_TRIGGER_CONTROL,
                    [if on { 1.0 } else { 0.0 }, -1.0, -1.0, 0.0],
                ),
                // One image (count 1) from every camera (id 0), sequence 0.
                MissionItem::ImageStartCapture => {
                    MavItem::action(cmd::IMAGE_START_CAPTURE, [0.0, 0.0, 1.0, 0.0])
                }
            })
            .collect()
    }

    /// The positions flown, home first, as (lon, lat, alt).
    pub fn waypoints(&self) -> impl Iterator<Item = &GeoPoint> {
        self.items.iter().filter_map(|i| match i {
            MissionItem::Waypoint(p) | MissionItem::HoldWaypoint { point: p, .. } => Some(p),
            _ => None,
        })
    }
}

/// A fence polygon: an inclusion area the vehicle must stay in, or an
/// exclusion area (a no-fly zone) it must stay out of. Rings are lon/lat,
/// not closed (the first vertex is not repeated).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FencePolygon {
    pub inclusion: bool,
    pub vertices: Vec<[f64; 2]>,
}

/// A one-waypoint mission from (1°, 2°) for the format writers' tests.
#[cfg(test)]
pub(crate) fn sample_mission(waypoint: GeoPoint) -> Mission {
    Mission {
        home: GeoPoint {
            lon: 1.0,
            lat: 2.0,
            alt: 0.0,
        },
        frame: AltitudeFrame::Relative,
        cruise_speed_m_s: 5.0,
        over_terrain: false,
        items: vec![
            MissionItem::Takeoff { alt: waypoint.alt },
            MissionItem::Waypoint(waypoint),
            MissionItem::ReturnToLaunch,
        ],
    }
}
