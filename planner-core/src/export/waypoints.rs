//! `QGC WPL 110` waypoint files, as read by ArduPilot, Mission Planner,
//! MAVProxy and pymavlink: tab-separated, 12 columns, LF line endings.

use std::fmt::Write;

use super::mission::{FencePolygon, Mission, MissionItem, cmd, frame};

/// One row of a WPL file.
struct Row {
    command: u16,
    frame: u8,
    params: [f64; 4],
    lat: f64,
    lon: f64,
    alt: f64,
}

/// The mission as a `QGC WPL 110` file. Item 0 is home (frame 0, AMSL), as
/// ArduPilot expects; then the mission items in order.
pub fn write_waypoints(mission: &Mission) -> String {
    let home = mission.home;
    let f = mission.frame.mav_frame();
    let mut rows = vec![Row {
        command: cmd::NAV_WAYPOINT,
        frame: frame::GLOBAL,
        params: [0.0; 4],
        lat: home.lat,
        lon: home.lon,
        alt: home.alt,
    }];
    for item in &mission.items {
        rows.push(match *item {
            MissionItem::Takeoff { alt } => Row {
                command: cmd::NAV_TAKEOFF,
                frame: f,
                params: [0.0; 4],
                lat: home.lat,
                lon: home.lon,
                alt,
            },
            MissionItem::ChangeSpeed { speed_m_s } => Row {
                command: cmd::DO_CHANGE_SPEED,
                frame: frame::MISSION,
                // param1 1 = ground speed; param3 -1 = leave throttle unchanged.
                params: [1.0, speed_m_s, -1.0, 0.0],
                lat: 0.0,
                lon: 0.0,
                alt: 0.0,
            },
            MissionItem::Waypoint(p) => Row {
                command: cmd::NAV_WAYPOINT,
                frame: f,
                params: [0.0; 4],
                lat: p.lat,
                lon: p.lon,
                alt: p.alt,
            },
            MissionItem::CameraTriggerDistance { distance_m } => Row {
                command: cmd::DO_SET_CAM_TRIGG_DIST,
                frame: frame::MISSION,
                // param3 1 = take a photo at once when a distance is set.
                params: [
                    distance_m,
                    0.0,
                    if distance_m > 0.0 { 1.0 } else { 0.0 },
                    0.0,
                ],
                lat: 0.0,
                lon: 0.0,
                alt: 0.0,
            },
            MissionItem::ReturnToLaunch => Row {
                command: cmd::NAV_RETURN_TO_LAUNCH,
                frame: f,
                params: [0.0; 4],
                lat: 0.0,
                lon: 0.0,
                alt: 0.0,
            },
        });
    }
    render(&rows, true)
}

/// Fence polygons as a WPL fence mission (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_
/// INCLUSION 5001 / EXCLUSION 5002, param1 = vertex count), the format of
/// ArduPilot's fence files, for autopilots loaded without QGroundControl.
pub fn write_fence(polygons: &[FencePolygon]) -> String {
    let mut rows = Vec::new();
    for p in polygons {
        let command = if p.inclusion {
            cmd::NAV_FENCE_POLYGON_VERTEX_INCLUSION
        } else {
            cmd::NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        };
        for v in &p.vertices {
            rows.push(Row {
                command,
                frame: frame::GLOBAL,
                params: [p.vertices.len() as f64, 0.0, 0.0, 0.0],
                lat: v[1],
                lon: v[0],
                alt: 0.0,
            });
        }
    }
    render(&rows, false)
}

fn render(rows: &[Row], first_is_current: bool) -> String {
    let mut out = String::from("QGC WPL 110\n");
    for (seq, r) in rows.iter().enumerate() {
        let current = u8::from(first_is_current && seq == 0);
        let _ = write!(out, "{seq}\t{current}\t{}\t{}", r.frame, r.command);
        for p in r.params {
            let _ = write!(out, "\t{p:.6}");
        }
        let _ = writeln!(out, "\t{:.8}\t{:.8}\t{:.6}\t1", r.lat, r.lon, r.alt);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::mission::{AltitudeFrame, GeoPoint};

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
            over_terrain: false,
            items: vec![
                MissionItem::Takeoff { alt: 60.0 },
                MissionItem::ChangeSpeed { speed_m_s: 8.0 },
                MissionItem::Waypoint(GeoPoint {
                    lon: 5.123456789,
                    lat: 52.2,
                    alt: 60.0,
                }),
                MissionItem::CameraTriggerDistance { distance_m: 12.5 },
                MissionItem::Waypoint(GeoPoint {
                    lon: 5.13,
                    lat: 52.21,
                    alt: 60.0,
                }),
                MissionItem::CameraTriggerDistance { distance_m: 0.0 },
                MissionItem::ReturnToLaunch,
            ],
        }
    }

    #[test]
    fn twelve_tab_separated_columns_and_lf() {
        let text = write_waypoints(&mission());
        assert!(!text.contains('\r'));
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "QGC WPL 110");
        assert_eq!(lines.len(), 1 + 8);
        for l in &lines[1..] {
            assert_eq!(l.split('\t').count(), 12, "{l}");
        }
        assert_eq!(
            lines[1],
            "0\t1\t0\t16\t0.000000\t0.000000\t0.000000\t0.000000\t52.20000000\t5.10000000\t3.000000\t1"
        );
        let cols: Vec<&str> = lines[4].split('\t').collect();
        assert_eq!((cols[2], cols[3], cols[9]), ("3", "16", "5.12345679"));
        let cols: Vec<&str> = lines[5].split('\t').collect();
        assert_eq!((cols[3], cols[4]), ("206", "12.500000"));
        assert!(lines[8].split('\t').nth(3) == Some("20"));
    }

    #[test]
    fn fence_rows_carry_vertex_count() {
        let text = write_fence(&[
            FencePolygon {
                inclusion: true,
                vertices: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            },
            FencePolygon {
                inclusion: false,
                vertices: vec![[0.2, 0.2], [0.4, 0.2], [0.3, 0.4]],
            },
        ]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 8);
        assert!(lines[1].starts_with("0\t0\t0\t5001\t4.000000"));
        assert!(lines[5].starts_with("4\t0\t0\t5002\t3.000000"));
    }
}
