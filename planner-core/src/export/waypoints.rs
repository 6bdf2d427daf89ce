//! `QGC WPL 110` waypoint files, as read by ArduPilot, Mission Planner,
//! MAVProxy and pymavlink: tab-separated, 12 columns, LF line endings.

use std::fmt::Write;

use super::mission::{FencePolygon, GeoPoint, MavItem, Mission, cmd, frame};

/// The mission as a `QGC WPL 110` file. Item 0 is home (frame 0, AMSL), as
/// ArduPilot expects; then the mission items in order.
pub fn write_waypoints(mission: &Mission) -> String {
    let home = mission.home;
    let mut rows = vec![MavItem {
        command: cmd::NAV_WAYPOINT,
        frame: frame::GLOBAL,
        params: [0.0; 4],
        lat: home.lat,
        lon: home.lon,
        alt: home.alt,
    }];
    rows.extend(mission.mav_items());
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
            rows.push(MavItem {
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

/// Rally points as a WPL rally mission (MAV_CMD_NAV_RALLY_POINT 5100,
/// altitude above home, frame 3): what MAVProxy's `rally load` sends to
/// ArduPilot with the MAVLink mission protocol (mission type RALLY), and the
/// items PX4 and QGroundControl use for rally (safe) points. The older
/// `RALLY lat lon alt …` text is not written: MAVProxy's current rally
/// module reads its altitude ×1000.
pub fn write_rally(points: &[GeoPoint]) -> String {
    let rows: Vec<MavItem> = points
        .iter()
        .map(|p| MavItem {
            command: cmd::NAV_RALLY_POINT,
            frame: frame::GLOBAL_RELATIVE_ALT,
            params: [0.0; 4],
            lat: p.lat,
            lon: p.lon,
            alt: p.alt,
        })
        .collect();
    render(&rows, false)
}

fn render(rows: &[MavItem], first_is_current: bool) -> String {
    let mut out = String::from("QGC WPL 110\n");
    for (seq, r) in rows.iter().enumerate() {
        let current = u8::from(first_is_current && seq == 0);
        let _ = write!(out, "{seq}\t{current}\t{}\t{}", r.frame, r.command);
        // A NaN param prints as `NaN` (see `KEEP_HEADING`).
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
    use crate::export::mission::{AltitudeFrame, MissionItem};

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
    fn takeoff_and_waypoints_keep_the_heading() {
        let text = write_waypoints(&mission());
        for line in text.lines().skip(2) {
            let cols: Vec<&str> = line.split('\t').collect();
            let yaw = cols[7];
            match cols[3] {
                // Take-off and waypoints: NaN, "keep the yaw behaviour".
                "22" | "16" => assert_eq!(yaw, "NaN", "{line}"),
                _ => assert_eq!(yaw, "0.000000", "{line}"),
            }
            // Every field parses as a number (Rust, like strtod and
            // Python's float, reads `NaN`).
            for c in &cols {
                assert!(c.parse::<f64>().is_ok(), "{c:?} in {line}");
            }
        }
        // Home (item 0) is no flown waypoint: its yaw stays 0.
        assert_eq!(
            text.lines().nth(1).unwrap().split('\t').nth(7),
            Some("0.000000")
        );
    }

    #[test]
    fn rally_rows_are_relative_rally_points() {
        let text = write_rally(&[
            GeoPoint {
                lon: 5.1,
                lat: 52.2,
                alt: 60.0,
            },
            GeoPoint {
                lon: 5.123456789,
                lat: 52.25,
                alt: 72.5,
            },
        ]);
        assert_eq!(
            text,
            "QGC WPL 110\n\
             0\t0\t3\t5100\t0.000000\t0.000000\t0.000000\t0.000000\t52.20000000\t5.10000000\t60.000000\t1\n\
             1\t0\t3\t5100\t0.000000\t0.000000\t0.000000\t0.000000\t52.25000000\t5.12345679\t72.500000\t1\n"
        );
        assert_eq!(write_rally(&[]), "QGC WPL 110\n");
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
