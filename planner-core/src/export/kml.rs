//! KML 2.2 for Google Earth: the flown route in 3D and the cells.

use std::fmt::Write;

use super::mission::{AltitudeFrame, Mission};
use crate::xml::xml_escape;

/// A KML document with the route of `mission` as a 3D LineString and each
/// cell ring (lon/lat, closed) as a Polygon. Terrain-frame altitudes are
/// written `relativeToGround`; AMSL altitudes, and relative ones planned
/// over a DEM (home's height added), `absolute`; relative altitudes of a
/// flat survey `relativeToGround` (exact over flat ground).
pub fn write_kml(name: &str, mission: &Mission, cells: &[(String, Vec<[f64; 2]>)]) -> String {
    let (mode, add) = match mission.frame {
        AltitudeFrame::Amsl => ("absolute", 0.0),
        AltitudeFrame::Relative if mission.over_terrain => ("absolute", mission.home.alt),
        AltitudeFrame::Relative | AltitudeFrame::Terrain => ("relativeToGround", 0.0),
    };
    let mut out = String::new();
    let _ = writeln!(out, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(out, r#"<kml xmlns="http://www.opengis.net/kml/2.2">"#);
    let _ = writeln!(out, "<Document>\n<name>{}</name>", xml_escape(name));
    let _ = writeln!(
        out,
        "<Style id=\"route\"><LineStyle><color>ff0000ff</color><width>2</width></LineStyle></Style>"
    );
    let _ = writeln!(
        out,
        "<Style id=\"cell\"><LineStyle><color>ffffaa00</color></LineStyle><PolyStyle><color>3fffaa00</color></PolyStyle></Style>"
    );
    let _ = writeln!(
        out,
        "<Placemark>\n<name>route</name>\n<styleUrl>#route</styleUrl>"
    );
    let _ = writeln!(
        out,
        "<LineString>\n<altitudeMode>{mode}</altitudeMode>\n<coordinates>"
    );
    let home = mission.home;
    let home_z = if mode == "absolute" { home.alt } else { 0.0 };
    let _ = writeln!(out, "{:.8},{:.8},{:.3}", home.lon, home.lat, home_z);
    for w in mission.waypoints() {
        let _ = writeln!(out, "{:.8},{:.8},{:.3}", w.lon, w.lat, w.alt + add);
    }
    let _ = writeln!(out, "{:.8},{:.8},{:.3}", home.lon, home.lat, home_z);
    let _ = writeln!(out, "</coordinates>\n</LineString>\n</Placemark>");
    for (cell_name, ring) in cells {
        let _ = writeln!(
            out,
            "<Placemark>\n<name>{}</name>\n<styleUrl>#cell</styleUrl>",
            xml_escape(cell_name)
        );
        let _ = writeln!(
            out,
            "<Polygon>\n<altitudeMode>clampToGround</altitudeMode>\n<outerBoundaryIs><LinearRing><coordinates>"
        );
        for p in ring {
            let _ = writeln!(out, "{:.8},{:.8},0", p[0], p[1]);
        }
        let _ = writeln!(
            out,
            "</coordinates></LinearRing></outerBoundaryIs>\n</Polygon>\n</Placemark>"
        );
    }
    let _ = writeln!(out, "</Document>\n</kml>");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::mission::{GeoPoint, sample_mission};

    #[test]
    fn route_and_cells_in_order() {
        let m = sample_mission(GeoPoint {
            lon: 1.5,
            lat: 2.5,
            alt: 30.0,
        });
        let cells = vec![(
            "cell <0>".to_string(),
            vec![[1.0, 2.0], [1.1, 2.0], [1.1, 2.1], [1.0, 2.0]],
        )];
        let k = write_kml("a & b", &m, &cells);
        assert!(k.contains("<name>a &amp; b</name>"));
        assert!(k.contains("<name>cell &lt;0&gt;</name>"));
        assert!(k.contains("<altitudeMode>relativeToGround</altitudeMode>"));
        let route = k
            .split("<coordinates>")
            .nth(1)
            .unwrap()
            .split("</coordinates>")
            .next()
            .unwrap();
        let lines: Vec<&str> = route.trim().lines().collect();
        assert_eq!(
            lines,
            [
                "1.00000000,2.00000000,0.000",
                "1.50000000,2.50000000,30.000",
                "1.00000000,2.00000000,0.000"
            ]
        );
    }

    #[test]
    fn relative_altitudes_over_a_dem_are_written_absolute() {
        let mut m = sample_mission(GeoPoint {
            lon: 1.5,
            lat: 2.5,
            alt: 30.0,
        });
        m.home.alt = 412.5;
        m.over_terrain = true;
        let k = write_kml("t", &m, &[]);
        assert!(k.contains("<altitudeMode>absolute</altitudeMode>"));
        assert!(k.contains("1.00000000,2.00000000,412.500\n1.50000000,2.50000000,442.500\n"));
    }
}
