//! DJI WPML missions: a KMZ (`wpmz/template.kml` and `wpmz/waylines.wpml`)
//! that DJI Pilot 2, FlightHub 2 and the Cloud API fly on DJI's enterprise
//! aircraft, written to DJI's public WPML reference (namespace
//! `http://www.dji.com/wpmz/1.0.2`).

use std::io::Write as _;

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesText, Event};
use serde::{Deserialize, Serialize};

use super::geoid::egm96_undulation_m;
use super::mission::{AltitudeFrame, GeoPoint, Mission};
use super::wpml_route::{DjiRoute, DjiRouteError, Interval};

/// The KML namespace of both files.
pub const KML_NAMESPACE: &str = "http://www.opengis.net/kml/2.2";
/// The WPML namespace, as DJI's reference and its sample files declare it.
pub const WPML_NAMESPACE: &str = "http://www.dji.com/wpmz/1.0.2";
/// Most waypoints of one wayline: `wpml:index` runs over [0, 65535].
pub const MAX_WAYPOINTS: usize = 65_536;
/// Most action groups of one KMZ: `wpml:actionGroupId` runs over [0, 65535].
pub const MAX_ACTION_GROUPS: usize = 65_536;
/// Range of `wpml:globalRTHHeight`, m above the take-off point.
const RTH_HEIGHT_M: (f64, f64) = (2.0, 1500.0);
/// Range of `wpml:takeOffSecurityHeight`, m (remote-controller missions).
const TAKEOFF_HEIGHT_M: (f64, f64) = (1.2, 1500.0);

/// A DJI enterprise aircraft and camera that fly WPML missions, named as
/// DJI's Cloud API "product support" page lists them: the drone's
/// `type`/`sub_type` and the payload's `type` (gimbal index 0, the main
/// gimbal). M300 RTK and M350 RTK carry a Zenmuse H20/H20T/H20N/H30/H30T.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DjiAircraft {
    /// Mavic 3 Enterprise, wide camera (the default).
    #[default]
    M3e,
    /// Mavic 3 Thermal.
    M3t,
    /// Mavic 3 Thermal Advanced.
    M3ta,
    /// Matrice 30.
    M30,
    /// Matrice 30T.
    M30t,
    /// Matrice 3D (Dock 2).
    M3d,
    /// Matrice 3TD (Dock 2).
    M3td,
    /// Matrice 4E.
    M4e,
    /// Matrice 4T.
    M4t,
    /// Matrice 4D (Dock 3).
    M4d,
    /// Matrice 4TD (Dock 3).
    M4td,
    M300H20,
    M300H20t,
    M300H20n,
    M300H30,
    M300H30t,
    M350H20,
    M350H20t,
    M350H20n,
    M350H30,
    M350H30t,
}

/// The enum values of an aircraft in `wpml:droneInfo` and `wpml:payloadInfo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DjiEnums {
    pub drone: u32,
    pub drone_sub: u32,
    pub payload: u32,
    pub payload_position: u32,
}

impl DjiAircraft {
    /// Its drone and payload enum values (DJI Cloud API, product support).
    pub fn enums(self) -> DjiEnums {
        use DjiAircraft::*;
        let (drone, drone_sub, payload) = match self {
            M3e => (77, 0, 66),
            M3t => (77, 1, 67),
            M3ta => (77, 3, 129),
            M30 => (67, 0, 52),
            M30t => (67, 1, 53),
            M3d => (91, 0, 80),
            M3td => (91, 1, 81),
            M4e => (99, 0, 88),
            M4t => (99, 1, 89),
            M4d => (100, 0, 98),
            M4td => (100, 1, 99),
            M300H20 => (60, 0, 42),
            M300H20t => (60, 0, 43),
            M300H20n => (60, 0, 61),
            M300H30 => (60, 0, 82),
            M300H30t => (60, 0, 83),
            M350H20 => (89, 0, 42),
            M350H20t => (89, 0, 43),
            M350H20n => (89, 0, 61),
            M350H30 => (89, 0, 82),
            M350H30t => (89, 0, 83),
        };
        DjiEnums {
            drone,
            drone_sub,
            payload,
            payload_position: 0,
        }
    }

    /// Whether it follows the terrain in real time: WPML's
    /// `realTimeFollowSurface` height mode is for the Mavic 3 enterprise
    /// series only.
    pub fn follows_terrain(self) -> bool {
        matches!(
            self,
            DjiAircraft::M3e | DjiAircraft::M3t | DjiAircraft::M3ta
        )
    }

    /// The name requests use (`m3e`, `m350_h20t`, …).
    pub fn name(self) -> String {
        serde_json::to_value(self)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default()
    }
}

/// What the mission itself does not say.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WpmlOptions {
    pub aircraft: DjiAircraft,
    /// Height of the return home, m above the take-off point (clear of
    /// everything the mission flies over).
    pub rth_height_m: f64,
}

/// Why a mission cannot be a DJI WPML mission.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WpmlError {
    #[error(transparent)]
    Route(#[from] DjiRouteError),
    #[error(
        "it has {0} waypoints, more than the {MAX_WAYPOINTS} one DJI wayline holds (wpml:index \
         runs over 0-65535): plan smaller sorties (max_flight_time_s)"
    )]
    TooManyWaypoints(usize),
    #[error(
        "it takes {0} action groups, more than the {MAX_ACTION_GROUPS} one KMZ holds \
         (wpml:actionGroupId runs over 0-65535): plan smaller sorties (max_flight_time_s)"
    )]
    TooManyActionGroups(usize),
    #[error(
        "DJI's {} cannot follow the terrain in real time (WPML's realTimeFollowSurface is for \
         the Mavic 3 enterprise series: m3e, m3t, m3ta): plan it with altitude_frame relative \
         or amsl, or choose one of those",
        .0.name()
    )]
    NoTerrainFollow(DjiAircraft),
    #[error("its return height of {0:.1} m is outside the 2-1500 m DJI allows")]
    RthHeight(f64),
    #[error("the KMZ could not be written: {0}")]
    Write(String),
}

/// Checks that `mission` makes a DJI WPML mission, without writing it.
pub fn check_wpml(mission: &Mission, options: &WpmlOptions) -> Result<DjiRoute, WpmlError> {
    let route = DjiRoute::of(mission)?;
    if mission.frame == AltitudeFrame::Terrain && !options.aircraft.follows_terrain() {
        return Err(WpmlError::NoTerrainFollow(options.aircraft));
    }
    if route.waypoints.len() > MAX_WAYPOINTS {
        return Err(WpmlError::TooManyWaypoints(route.waypoints.len()));
    }
    let groups = action_groups(&route).len();
    if groups > MAX_ACTION_GROUPS {
        return Err(WpmlError::TooManyActionGroups(groups));
    }
    let rth = options.rth_height_m;
    if !(RTH_HEIGHT_M.0..=RTH_HEIGHT_M.1).contains(&rth) {
        return Err(WpmlError::RthHeight(rth));
    }
    Ok(route)
}

/// The mission as a DJI WPML KMZ (a zip of `wpmz/template.kml` and
/// `wpmz/waylines.wpml`, deflated, dated 1980-01-01 so that the same
/// mission always gives the same bytes).
pub fn write_kmz(mission: &Mission, options: &WpmlOptions) -> Result<Vec<u8>, WpmlError> {
    let route = check_wpml(mission, options)?;
    let doc = Doc {
        mission,
        route: &route,
        options,
        groups: action_groups(&route),
    };
    let template = doc
        .render(false)
        .map_err(|e| WpmlError::Write(e.to_string()))?;
    let waylines = doc
        .render(true)
        .map_err(|e| WpmlError::Write(e.to_string()))?;
    let zip_err = |e: zip::result::ZipError| WpmlError::Write(e.to_string());
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .last_modified_time(zip::DateTime::default());
    for (name, text) in [
        ("wpmz/template.kml", template),
        ("wpmz/waylines.wpml", waylines),
    ] {
        zip.start_file(name, opts).map_err(zip_err)?;
        zip.write_all(&text)
            .map_err(|e| WpmlError::Write(e.to_string()))?;
    }
    Ok(zip.finish().map_err(zip_err)?.into_inner())
}

/// One action group: at a waypoint (`reachPoint`), or photos every so
/// often from `start` to `end`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Group {
    start: usize,
    end: usize,
    trigger: Option<Interval>,
    gimbal_pitch_deg: Option<f64>,
    hover_s: Option<f64>,
    photo: bool,
}

/// The action groups of a route in waypoint order: at each waypoint where
/// the gimbal pitch is set (the first) or changes, or that hovers or takes
/// a photo, one `reachPoint` group; one per run of photos.
fn action_groups(route: &DjiRoute) -> Vec<Group> {
    let mut out = Vec::new();
    let mut runs = route.runs.iter().peekable();
    let mut pitch = None;
    for (i, w) in route.waypoints.iter().enumerate() {
        let turn = (pitch != Some(w.gimbal_pitch_deg)).then_some(w.gimbal_pitch_deg);
        pitch = Some(w.gimbal_pitch_deg);
        if turn.is_some() || w.hold_s.is_some() || w.photo {
            out.push(Group {
                start: i,
                end: i,
                trigger: None,
                gimbal_pitch_deg: turn,
                hover_s: w.hold_s,
                photo: w.photo,
            });
        }
        while let Some(r) = runs.next_if(|r| r.start == i) {
            out.push(Group {
                start: r.start,
                end: r.end,
                trigger: Some(r.every),
                gimbal_pitch_deg: None,
                hover_s: None,
                photo: true,
            });
        }
    }
    out
}

type Xml = Writer<Vec<u8>>;
type XmlResult = std::io::Result<()>;

/// `<name>text</name>`.
fn el(w: &mut Xml, name: &str, text: &str) -> XmlResult {
    w.create_element(name)
        .write_text_content(BytesText::new(text))?;
    Ok(())
}

/// A number as WPML writes it: shortest exact form for whole numbers,
/// else up to `decimals` places without trailing zeros.
fn num(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// Everything the two files are written from.
struct Doc<'a> {
    mission: &'a Mission,
    route: &'a DjiRoute,
    options: &'a WpmlOptions,
    groups: Vec<Group>,
}

impl Doc<'_> {
    /// `waylines.wpml` (the flight) when `waylines`, else `template.kml`
    /// (the same waypoints for DJI's editors).
    fn render(&self, waylines: bool) -> std::io::Result<Vec<u8>> {
        let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
        w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
        w.create_element("kml")
            .with_attribute(("xmlns", KML_NAMESPACE))
            .with_attribute(("xmlns:wpml", WPML_NAMESPACE))
            .write_inner_content(|w| {
                w.create_element("Document").write_inner_content(|w| {
                    if !waylines {
                        el(w, "wpml:author", "terraplan")?;
                    }
                    self.mission_config(w, waylines)?;
                    w.create_element("Folder").write_inner_content(|w| {
                        if waylines {
                            self.waylines_folder(w)
                        } else {
                            self.template_folder(w)
                        }
                    })?;
                    Ok(())
                })?;
                Ok(())
            })?;
        let mut out = w.into_inner();
        out.push(b'\n');
        Ok(out)
    }

    /// `wpml:missionConfig`: take off to the mission's take-off height and
    /// fly to the first waypoint safely; home at the end when the mission
    /// returns (else hover there); home when the remote-controller link is
    /// lost, at the return height.
    fn mission_config(&self, w: &mut Xml, waylines: bool) -> XmlResult {
        let r = self.route;
        let e = self.options.aircraft.enums();
        let takeoff = r
            .takeoff_alt_m
            .clamp(TAKEOFF_HEIGHT_M.0, TAKEOFF_HEIGHT_M.1);
        w.create_element("wpml:missionConfig")
            .write_inner_content(|w| {
                el(w, "wpml:flyToWaylineMode", "safely")?;
                let finish = if r.return_home { "goHome" } else { "noAction" };
                el(w, "wpml:finishAction", finish)?;
                el(w, "wpml:exitOnRCLost", "executeLostAction")?;
                el(w, "wpml:executeRCLostAction", "goBack")?;
                el(w, "wpml:takeOffSecurityHeight", &num(takeoff, 2))?;
                if !waylines && let Some((ellipsoidal, amsl)) = self.home_heights() {
                    let h = self.mission.home;
                    let p = format!(
                        "{},{},{}",
                        num(h.lat, 8),
                        num(h.lon, 8),
                        num(ellipsoidal, 3)
                    );
                    el(w, "wpml:takeOffRefPoint", &p)?;
                    el(w, "wpml:takeOffRefPointAGLHeight", &num(amsl, 3))?;
                }
                el(
                    w,
                    "wpml:globalTransitionalSpeed",
                    &num(r.cruise_speed_m_s, 2),
                )?;
                el(
                    w,
                    "wpml:globalRTHHeight",
                    &num(self.options.rth_height_m, 2),
                )?;
                w.create_element("wpml:droneInfo")
                    .write_inner_content(|w| {
                        el(w, "wpml:droneEnumValue", &e.drone.to_string())?;
                        el(w, "wpml:droneSubEnumValue", &e.drone_sub.to_string())
                    })?;
                w.create_element("wpml:payloadInfo")
                    .write_inner_content(|w| {
                        el(w, "wpml:payloadEnumValue", &e.payload.to_string())?;
                        el(
                            w,
                            "wpml:payloadPositionIndex",
                            &e.payload_position.to_string(),
                        )
                    })?;
                Ok(())
            })?;
        Ok(())
    }

    /// Home's height above the ellipsoid and above mean sea level, when
    /// the mission knows it (planned over a DEM, or in AMSL).
    fn home_heights(&self) -> Option<(f64, f64)> {
        let m = self.mission;
        (m.over_terrain || m.frame == AltitudeFrame::Amsl).then(|| {
            (
                m.home.alt + egm96_undulation_m(m.home.lon, m.home.lat),
                m.home.alt,
            )
        })
    }

    /// The waylines' `executeHeightMode` and each waypoint's height in it:
    /// above the take-off point, above the WGS 84 ellipsoid (AMSL plus the
    /// EGM96 undulation), or above the terrain followed in real time.
    fn execute_height(&self, p: &GeoPoint) -> (&'static str, f64) {
        match self.mission.frame {
            AltitudeFrame::Relative => ("relativeToStartPoint", p.alt),
            AltitudeFrame::Amsl => ("WGS84", p.alt + egm96_undulation_m(p.lon, p.lat)),
            AltitudeFrame::Terrain => ("realTimeFollowSurface", p.alt),
        }
    }

    fn waylines_folder(&self, w: &mut Xml) -> XmlResult {
        let r = self.route;
        let (length, duration) = r.length_and_duration();
        let mode = self.execute_height(&r.waypoints[0].point).0;
        el(w, "wpml:templateId", "0")?;
        el(w, "wpml:executeHeightMode", mode)?;
        el(w, "wpml:waylineId", "0")?;
        el(w, "wpml:distance", &num(length, 1))?;
        el(w, "wpml:duration", &num(duration, 1))?;
        el(w, "wpml:autoFlightSpeed", &num(r.cruise_speed_m_s, 2))?;
        for (i, wp) in r.waypoints.iter().enumerate() {
            w.create_element("Placemark").write_inner_content(|w| {
                point(w, &wp.point)?;
                el(w, "wpml:index", &i.to_string())?;
                el(
                    w,
                    "wpml:executeHeight",
                    &num(self.execute_height(&wp.point).1, 3),
                )?;
                el(w, "wpml:waypointSpeed", &num(wp.speed_m_s, 2))?;
                heading_param(w, "wpml:waypointHeadingParam")?;
                turn_param(w)?;
                self.groups_at(w, i)
            })?;
        }
        Ok(())
    }

    /// The template's heights: its `heightMode` and, per waypoint, the
    /// height in it and above the ellipsoid. Terrain following is edited
    /// above ground level in DJI's editors; its ellipsoidal height is left
    /// to them (they hold the terrain), so it repeats the height.
    fn template_height(&self, p: &GeoPoint) -> (&'static str, f64, f64) {
        match self.mission.frame {
            AltitudeFrame::Relative => ("relativeToStartPoint", p.alt, p.alt),
            AltitudeFrame::Amsl => ("EGM96", p.alt, self.execute_height(p).1),
            AltitudeFrame::Terrain => ("aboveGroundLevel", p.alt, p.alt),
        }
    }

    fn template_folder(&self, w: &mut Xml) -> XmlResult {
        let r = self.route;
        let first = &r.waypoints[0].point;
        el(w, "wpml:templateType", "waypoint")?;
        el(w, "wpml:templateId", "0")?;
        w.create_element("wpml:waylineCoordinateSysParam")
            .write_inner_content(|w| {
                el(w, "wpml:coordinateMode", "WGS84")?;
                el(w, "wpml:heightMode", self.template_height(first).0)?;
                el(w, "wpml:positioningType", "GPS")
            })?;
        el(w, "wpml:autoFlightSpeed", &num(r.cruise_speed_m_s, 2))?;
        el(
            w,
            "wpml:globalHeight",
            &num(self.template_height(first).1, 3),
        )?;
        el(w, "wpml:gimbalPitchMode", "usePointSetting")?;
        heading_param(w, "wpml:globalWaypointHeadingParam")?;
        el(
            w,
            "wpml:globalWaypointTurnMode",
            "toPointAndStopWithDiscontinuityCurvature",
        )?;
        el(w, "wpml:globalUseStraightLine", "1")?;
        for (i, wp) in r.waypoints.iter().enumerate() {
            let (_, height, ellipsoidal) = self.template_height(&wp.point);
            w.create_element("Placemark").write_inner_content(|w| {
                point(w, &wp.point)?;
                el(w, "wpml:index", &i.to_string())?;
                el(w, "wpml:useGlobalHeight", "0")?;
                el(w, "wpml:ellipsoidHeight", &num(ellipsoidal, 3))?;
                el(w, "wpml:height", &num(height, 3))?;
                el(w, "wpml:useGlobalSpeed", "0")?;
                el(w, "wpml:waypointSpeed", &num(wp.speed_m_s, 2))?;
                el(w, "wpml:useGlobalHeadingParam", "1")?;
                el(w, "wpml:useGlobalTurnParam", "1")?;
                el(w, "wpml:gimbalPitchAngle", &num(wp.gimbal_pitch_deg, 2))?;
                self.groups_at(w, i)
            })?;
        }
        Ok(())
    }

    /// The action groups that start at waypoint `i`.
    fn groups_at(&self, w: &mut Xml, i: usize) -> XmlResult {
        let payload = self.options.aircraft.enums().payload_position.to_string();
        let first = self.groups.partition_point(|g| g.start < i);
        for (id, g) in self.groups.iter().enumerate().skip(first) {
            if g.start != i {
                break;
            }
            w.create_element("wpml:actionGroup")
                .write_inner_content(|w| {
                    el(w, "wpml:actionGroupId", &id.to_string())?;
                    el(w, "wpml:actionGroupStartIndex", &g.start.to_string())?;
                    el(w, "wpml:actionGroupEndIndex", &g.end.to_string())?;
                    el(w, "wpml:actionGroupMode", "sequence")?;
                    trigger(w, g.trigger)?;
                    actions(w, g, id, &payload)
                })?;
        }
        Ok(())
    }
}

/// `<Point><coordinates>lon,lat</coordinates></Point>` (1e-9° ≈ 0.1 mm).
fn point(w: &mut Xml, p: &GeoPoint) -> XmlResult {
    w.create_element("Point").write_inner_content(|w| {
        el(
            w,
            "coordinates",
            &format!("{},{}", num(p.lon, 9), num(p.lat, 9)),
        )
    })?;
    Ok(())
}

/// Heading along the wayline (as the MAVLink missions leave the yaw to the
/// autopilot, which points the nose at the next waypoint).
fn heading_param(w: &mut Xml, name: &str) -> XmlResult {
    w.create_element(name).write_inner_content(|w| {
        el(w, "wpml:waypointHeadingMode", "followWayline")?;
        el(w, "wpml:waypointHeadingPathMode", "followBadArc")
    })?;
    Ok(())
}

/// Straight legs, stopping at each waypoint: the aircraft passes every
/// waypoint of the plan (survey lanes end where they turn).
fn turn_param(w: &mut Xml) -> XmlResult {
    w.create_element("wpml:waypointTurnParam")
        .write_inner_content(|w| {
            el(
                w,
                "wpml:waypointTurnMode",
                "toPointAndStopWithDiscontinuityCurvature",
            )?;
            el(w, "wpml:waypointTurnDampingDist", "0")
        })?;
    Ok(())
}

fn trigger(w: &mut Xml, every: Option<Interval>) -> XmlResult {
    w.create_element("wpml:actionTrigger")
        .write_inner_content(|w| match every {
            None => el(w, "wpml:actionTriggerType", "reachPoint"),
            Some(Interval::Distance(d)) => {
                el(w, "wpml:actionTriggerType", "multipleDistance")?;
                el(w, "wpml:actionTriggerParam", &num(d, 3))
            }
            Some(Interval::Time(s)) => {
                el(w, "wpml:actionTriggerType", "multipleTiming")?;
                el(w, "wpml:actionTriggerParam", &num(s, 3))
            }
        })?;
    Ok(())
}

/// The group's actions in order: point the gimbal, hover, take the photo.
fn actions(w: &mut Xml, g: &Group, group_id: usize, payload: &str) -> XmlResult {
    let mut id = 0;
    let mut action = |w: &mut Xml, func: &str, params: &dyn Fn(&mut Xml) -> XmlResult| {
        let r = w.create_element("wpml:action").write_inner_content(|w| {
            el(w, "wpml:actionId", &id.to_string())?;
            el(w, "wpml:actionActuatorFunc", func)?;
            w.create_element("wpml:actionActuatorFuncParam")
                .write_inner_content(|w| params(w))?;
            Ok(())
        });
        id += 1;
        r.map(|_| ())
    };
    if let Some(pitch) = g.gimbal_pitch_deg {
        action(w, "gimbalRotate", &|w| {
            el(w, "wpml:gimbalHeadingYawBase", "north")?;
            el(w, "wpml:gimbalRotateMode", "absoluteAngle")?;
            el(w, "wpml:gimbalPitchRotateEnable", "1")?;
            el(w, "wpml:gimbalPitchRotateAngle", &num(pitch, 2))?;
            el(w, "wpml:gimbalRollRotateEnable", "0")?;
            el(w, "wpml:gimbalRollRotateAngle", "0")?;
            el(w, "wpml:gimbalYawRotateEnable", "0")?;
            el(w, "wpml:gimbalYawRotateAngle", "0")?;
            el(w, "wpml:gimbalRotateTimeEnable", "0")?;
            el(w, "wpml:gimbalRotateTime", "0")?;
            el(w, "wpml:payloadPositionIndex", payload)
        })?;
    }
    if let Some(s) = g.hover_s.filter(|s| *s > 0.0) {
        action(w, "hover", &|w| el(w, "wpml:hoverTime", &num(s, 2)))?;
    }
    if g.photo {
        action(w, "takePhoto", &|w| {
            el(w, "wpml:payloadPositionIndex", payload)?;
            el(w, "wpml:fileSuffix", &format!("terraplan{group_id}"))?;
            el(w, "wpml:payloadLensIndex", "wide")?;
            el(w, "wpml:useGlobalPayloadLensIndex", "0")
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::wpml_route::sample_dji_mission;
    use std::io::Read;

    fn options() -> WpmlOptions {
        WpmlOptions {
            aircraft: DjiAircraft::default(),
            rth_height_m: 60.0,
        }
    }

    /// The two files of a KMZ.
    fn unzip(kmz: &[u8]) -> (String, String) {
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(kmz)).unwrap();
        let mut names: Vec<String> = zip.file_names().map(|n| n.unwrap().to_string()).collect();
        names.sort();
        assert_eq!(names, ["wpmz/template.kml", "wpmz/waylines.wpml"]);
        let mut read = |name: &str| {
            let mut s = String::new();
            zip.by_name(name).unwrap().read_to_string(&mut s).unwrap();
            s
        };
        (read("wpmz/template.kml"), read("wpmz/waylines.wpml"))
    }

    /// The texts of every `<tag>` in `xml`, in order.
    fn texts(xml: &str, tag: &str) -> Vec<String> {
        let open = format!("<{tag}>");
        xml.split(&open)
            .skip(1)
            .map(|s| s.split(&format!("</{tag}>")).next().unwrap().to_string())
            .collect()
    }

    #[test]
    fn kmz_holds_both_files_with_dji_namespaces_and_enums() {
        let m = sample_dji_mission();
        let kmz = write_kmz(&m, &options()).unwrap();
        // Rendered twice, the same bytes (no clock in the zip).
        assert_eq!(kmz, write_kmz(&m, &options()).unwrap());
        let (template, waylines) = unzip(&kmz);
        for doc in [&template, &waylines] {
            assert!(doc.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>"));
            assert!(doc.contains(
                r#"<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:wpml="http://www.dji.com/wpmz/1.0.2">"#
            ));
            assert_eq!(texts(doc, "wpml:droneEnumValue"), ["77"]);
            assert_eq!(texts(doc, "wpml:payloadEnumValue"), ["66"]);
            assert_eq!(texts(doc, "wpml:finishAction"), ["goHome"]);
            assert_eq!(texts(doc, "wpml:globalRTHHeight"), ["60"]);
            assert_eq!(texts(doc, "wpml:takeOffSecurityHeight"), ["50"]);
        }
        assert_eq!(texts(&template, "wpml:templateType"), ["waypoint"]);
        assert_eq!(
            texts(&waylines, "wpml:executeHeightMode"),
            ["relativeToStartPoint"]
        );
        assert_eq!(texts(&waylines, "wpml:index"), ["0", "1", "2", "3", "4"]);
        assert_eq!(texts(&waylines, "coordinates")[1], "5.001,52.002");
        assert_eq!(texts(&waylines, "wpml:executeHeight"), ["50"; 5]);
        assert_eq!(texts(&waylines, "wpml:waypointSpeed"), ["8"; 5]);
    }

    #[test]
    fn photo_actions_follow_the_mission() {
        let (_, waylines) = unzip(&write_kmz(&sample_dji_mission(), &options()).unwrap());
        // Gimbal at the first waypoint, the distance run from it, the
        // hover photo, the time run.
        assert_eq!(
            texts(&waylines, "wpml:actionTriggerType"),
            [
                "reachPoint",
                "multipleDistance",
                "reachPoint",
                "multipleTiming"
            ]
        );
        assert_eq!(texts(&waylines, "wpml:actionTriggerParam"), ["12", "1.5"]);
        assert_eq!(
            texts(&waylines, "wpml:actionGroupStartIndex"),
            ["0", "0", "3", "3"]
        );
        assert_eq!(
            texts(&waylines, "wpml:actionGroupEndIndex"),
            ["0", "2", "3", "4"]
        );
        assert_eq!(
            texts(&waylines, "wpml:actionActuatorFunc"),
            [
                "gimbalRotate",
                "takePhoto",
                "hover",
                "takePhoto",
                "takePhoto"
            ]
        );
        assert_eq!(texts(&waylines, "wpml:gimbalPitchRotateAngle"), ["-80"]);
        assert_eq!(texts(&waylines, "wpml:hoverTime"), ["2"]);
        assert_eq!(texts(&waylines, "wpml:actionGroupId"), ["0", "1", "2", "3"]);
    }

    #[test]
    fn amsl_heights_are_ellipsoidal_in_the_waylines() {
        let mut m = sample_dji_mission();
        m.frame = AltitudeFrame::Amsl;
        for i in &mut m.items {
            if let crate::export::MissionItem::Waypoint(p) = i {
                p.alt = 120.0;
            }
        }
        let (template, waylines) = unzip(&write_kmz(&m, &options()).unwrap());
        assert_eq!(texts(&waylines, "wpml:executeHeightMode"), ["WGS84"]);
        let h: f64 = texts(&waylines, "wpml:executeHeight")[0].parse().unwrap();
        // EGM96 in the middle of the Netherlands: 43.4 m above the ellipsoid.
        let n = egm96_undulation_m(5.001, 52.001);
        assert!((n - 43.4).abs() < 0.5, "{n}");
        assert!((h - (120.0 + n)).abs() < 1e-3, "{h}");
        assert_eq!(texts(&template, "wpml:heightMode"), ["EGM96"]);
        assert_eq!(texts(&template, "wpml:height")[0], "120");
        let e: f64 = texts(&template, "wpml:ellipsoidHeight")[0].parse().unwrap();
        assert!((e - h).abs() < 1e-9);
        // Home's height is known in AMSL: the reference take-off point.
        assert_eq!(texts(&template, "wpml:takeOffRefPointAGLHeight"), ["10"]);
    }

    #[test]
    fn terrain_following_needs_a_mavic_3_enterprise() {
        let mut m = sample_dji_mission();
        m.frame = AltitudeFrame::Terrain;
        let (_, waylines) = unzip(&write_kmz(&m, &options()).unwrap());
        assert_eq!(
            texts(&waylines, "wpml:executeHeightMode"),
            ["realTimeFollowSurface"]
        );
        let m30 = WpmlOptions {
            aircraft: DjiAircraft::M30t,
            ..options()
        };
        let e = write_kmz(&m, &m30).unwrap_err();
        assert_eq!(e, WpmlError::NoTerrainFollow(DjiAircraft::M30t));
        assert!(
            e.to_string().contains("m30t cannot follow the terrain"),
            "{e}"
        );
    }

    #[test]
    fn aircraft_names_and_limits() {
        let a: DjiAircraft = serde_json::from_str("\"m350_h20t\"").unwrap();
        assert_eq!(a, DjiAircraft::M350H20t);
        assert_eq!(a.name(), "m350_h20t");
        assert_eq!(
            a.enums(),
            DjiEnums {
                drone: 89,
                drone_sub: 0,
                payload: 43,
                payload_position: 0
            }
        );
        assert_eq!(DjiAircraft::M30t.enums().drone_sub, 1);
        let high = WpmlOptions {
            rth_height_m: 1600.0,
            ..options()
        };
        assert_eq!(
            check_wpml(&sample_dji_mission(), &high).unwrap_err(),
            WpmlError::RthHeight(1600.0)
        );
        assert_eq!(num(-0.0001, 2), "0");
        assert_eq!(num(12.5, 3), "12.5");
        assert_eq!(num(5.123456789, 9), "5.123456789");
    }
}
