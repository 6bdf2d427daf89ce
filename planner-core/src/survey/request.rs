//! The survey request: its schema (the parameters, the slice angle, the
//! UAVs), reading a request document and checking every member, and the
//! faults a survey is refused with.

use serde::{Deserialize, Deserializer, Serialize};
use serde_json::Value;

use super::terrain_flight::FlightRules;
use crate::coverage::{self, Camera, SurveyGeometry};
use crate::export::AltitudeFrame;
use crate::flock::Policy;
use crate::geo::{GeoError, Issue, Limits, MAX_ISSUES, ParsedPolygon, cap_issues, parse_polygons};
use crate::num::readable;
use crate::terrain::Dem;

/// Most UAVs in one survey.
pub const MAX_UAVS: usize = 64;

/// Most rally points in one survey (ArduPilot keeps as many as its rally
/// storage holds, at least 10 on every board; PX4 as many as its dataman).
pub const MAX_RALLY_POINTS: usize = 64;

/// Default `nfz_clearance_m`: see [`SurveyParams::nfz_clearance_m`].
pub const DEFAULT_NFZ_CLEARANCE_M: f64 = 5.0;

/// Slice-line bearing: a fixed angle or `"auto"` (fewest turns in total).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum SliceAngle {
    #[default]
    Auto,
    Degrees(f64),
}

#[cfg(feature = "openapi")]
impl utoipa::PartialSchema for SliceAngle {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{ObjectBuilder, OneOfBuilder, Type};
        OneOfBuilder::new()
            .item(
                ObjectBuilder::new()
                    .schema_type(Type::Number)
                    .minimum(Some(0.0))
                    .exclusive_maximum(Some(180.0))
                    .description(Some(
                        "bearing of the slice lines, degrees clockwise from grid north",
                    )),
            )
            .item(
                ObjectBuilder::new()
                    .schema_type(Type::String)
                    .enum_values(Some(["auto"]))
                    .description(Some("the angle with the fewest turns in total")),
            )
            .default(Some(serde_json::json!("auto")))
            .into()
    }
}

#[cfg(feature = "openapi")]
impl utoipa::ToSchema for SliceAngle {}

impl Serialize for SliceAngle {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            SliceAngle::Auto => s.serialize_str("auto"),
            SliceAngle::Degrees(d) => s.serialize_f64(*d),
        }
    }
}

impl<'de> Deserialize<'de> for SliceAngle {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Num(f64),
            Str(String),
        }
        match Raw::deserialize(d).map_err(|_| {
            serde::de::Error::custom("slice_angle_deg must be a number of degrees or \"auto\"")
        })? {
            Raw::Num(v) => Ok(SliceAngle::Degrees(v)),
            Raw::Str(s) if s == "auto" => Ok(SliceAngle::Auto),
            Raw::Str(s) => Err(serde::de::Error::custom(format!(
                "slice_angle_deg must be a number of degrees or \"auto\", found {s:?}"
            ))),
        }
    }
}

/// One UAV of the flock.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UavSpec {
    pub id: String,
    /// Take-off and landing point, [lon, lat].
    pub start: [f64; 2],
    /// Cruise speed of this UAV, m/s, (0, 50]; the survey's `speed_m_s`
    /// when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 50))]
    pub speed_m_s: Option<f64>,
    /// Battery endurance, s, [30, 86400]: a longer mission is flown in
    /// sorties that each return home (one mission file per sortie).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(minimum = 30, maximum = 86400))]
    pub max_flight_time_s: Option<f64>,
}

/// Survey request parameters: the fields of the params file and of the API
/// request body (which adds `dem_id`, a DEM stored in the service, that
/// the service resolves into the DEM it plans over). Ranges are checked by
/// [`SurveyParams::validate`].
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema), schema(default))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurveyParams {
    /// Flight height above ground, m, in [1, 1000]; default 60 unless
    /// `gsd_cm_px` is given.
    #[cfg_attr(feature = "openapi", schema(minimum = 1, maximum = 1000, example = 60))]
    pub altitude_m: Option<f64>,
    /// Target ground sample distance, cm/px, in [0.05, 100]; sets the altitude.
    #[cfg_attr(feature = "openapi", schema(minimum = 0.05, maximum = 100))]
    pub gsd_cm_px: Option<f64>,
    /// Camera; default [`Camera::default`].
    pub camera: Option<Camera>,
    /// Name of a camera preset (see [`coverage::PRESETS`]); exclusive with `camera`.
    pub camera_preset: Option<String>,
    /// Side overlap of neighbouring lanes' footprints, [0, 0.95]; default 0.7.
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 0.95))]
    pub side_overlap: f64,
    /// Front overlap of consecutive photos, [0, 0.95]; default 0.8.
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 0.95))]
    pub front_overlap: f64,
    /// Direct line spacing, m, in [0.5, 2000]; overrides the side overlap.
    #[cfg_attr(feature = "openapi", schema(minimum = 0.5, maximum = 2000))]
    pub line_spacing_m: Option<f64>,
    /// Bearing of the slice lines, degrees in [0, 180), or "auto"; default auto.
    pub slice_angle_deg: SliceAngle,
    /// Ground speed, m/s, in (0, 50]; default 10.
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 50))]
    pub speed_m_s: f64,
    /// Time charged per turn in the flight-time estimate, s, in [0, 120]; default 2.
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 120))]
    pub turn_penalty_s: f64,
    /// UAVs (at most 64, ids unique); default one UAV starting at the ROI's
    /// first vertex.
    #[cfg_attr(feature = "openapi", schema(max_items = 64))]
    pub uavs: Vec<UavSpec>,
    /// Altitude frame of the mission; default relative.
    pub altitude_frame: AltitudeFrame,
    /// Distance every flown point (lanes, links, transits; not the vertical
    /// take-off and landing at home) keeps from every no-fly zone and from
    /// the inclusion fence, m, in [0, 100]; default 5. The NFZs are exported
    /// as exclusion fences: with the fence enabled, a vehicle flying on an
    /// NFZ's edge breaches it with ordinary GNSS error and triggers its
    /// fence action. 5 m covers ArduPilot's default FENCE_MARGIN (2 m) plus
    /// a multirotor's usual position error (GNSS and tracking, 2–3 m).
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 100))]
    pub nfz_clearance_m: f64,
    /// Margin of the inclusion geofence around the flown area, m, in [0, 1000]; default 30
    /// (never less than `nfz_clearance_m`).
    #[cfg_attr(feature = "openapi", schema(minimum = 0, maximum = 1000))]
    pub fence_margin_m: f64,
    /// Allowed deviation from `altitude_m` above the (dilated) terrain along
    /// lanes, m, in [0.5, 100], smaller than the altitude; default 5.
    #[cfg_attr(feature = "openapi", schema(minimum = 0.5, maximum = 100))]
    pub agl_tolerance_m: f64,
    /// Least height above the dilated terrain on transits, m, in [1, 2000];
    /// default `altitude_m`.
    #[cfg_attr(feature = "openapi", schema(minimum = 1, maximum = 2000))]
    pub transit_clearance_m: Option<f64>,
    /// Steepest climb allowed, m/s, in (0, 50]; default unlimited.
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 50))]
    pub max_climb_rate_m_s: Option<f64>,
    /// Steepest descent allowed, m/s, in (0, 50]; default unlimited.
    #[cfg_attr(feature = "openapi", schema(exclusive_minimum = 0, maximum = 50))]
    pub max_descent_rate_m_s: Option<f64>,
    /// Plan even if the DEM has no heights under part of the area (flown at
    /// the highest height nearby there); default false: a 422 says how much
    /// is missing.
    pub allow_partial_dem: bool,
    /// How the cells are shared among the UAVs: `balanced` (default,
    /// shortest makespan), `competition` (thesis Algorithm 3) or
    /// `min_reach` (thesis policy 1, least summed reach distance).
    pub assignment: Policy,
    /// The airframe (`multirotor` by default): planes enter lanes straight
    /// and turn on arcs (see [`super::Aircraft`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aircraft: Option<super::aircraft::Aircraft>,
    /// Rally points, [lon, lat] each (at most 64): where a UAV may return
    /// instead of home; exported in each `.plan` and as a rally file.
    #[cfg_attr(feature = "openapi", schema(max_items = 64))]
    pub rally_points: Vec<[f64; 2]>,
    /// Width of a `corridor` (given instead of `roi`), m, in [1, 2000]: lanes run along its line.
    #[cfg_attr(feature = "openapi", schema(minimum = 1, maximum = 2000))]
    pub corridor_width_m: Option<f64>,
    /// `grid` (default) or `crosshatch`: each cell flown a second time with lanes at 90°.
    pub pattern: crate::coverage::Pattern,
    /// Camera pitch, degrees in [-90, -30], forward along the lanes; default -90 (nadir, no gimbal command).
    #[cfg_attr(feature = "openapi", schema(minimum = -90, maximum = -30))]
    pub camera_pitch_deg: Option<f64>,
    /// How the camera is triggered along the lanes; default by distance.
    pub trigger: super::capture::Trigger,
    /// The DJI aircraft and camera of the WPML missions (`.kmz`): `m3e`
    /// (default), `m3t`, `m3ta`, `m30`, `m30t`, `m3d`, `m3td`, `m4e`, `m4t`,
    /// `m4d`, `m4td`, or `m300_`/`m350_` with `h20`, `h20t`, `h20n`, `h30`,
    /// `h30t`. Terrain following (`altitude_frame` `terrain`) needs a Mavic 3
    /// enterprise (`m3e`, `m3t`, `m3ta`).
    pub dji_aircraft: crate::export::wpml::DjiAircraft,
}

impl Default for SurveyParams {
    fn default() -> Self {
        SurveyParams {
            altitude_m: None,
            gsd_cm_px: None,
            camera: None,
            camera_preset: None,
            side_overlap: 0.7,
            front_overlap: 0.8,
            line_spacing_m: None,
            slice_angle_deg: SliceAngle::Auto,
            speed_m_s: 10.0,
            turn_penalty_s: 2.0,
            uavs: Vec::new(),
            altitude_frame: AltitudeFrame::Relative,
            nfz_clearance_m: DEFAULT_NFZ_CLEARANCE_M,
            fence_margin_m: 30.0,
            agl_tolerance_m: 5.0,
            transit_clearance_m: None,
            max_climb_rate_m_s: None,
            max_descent_rate_m_s: None,
            allow_partial_dem: false,
            assignment: Policy::Balanced,
            aircraft: None,
            rally_points: Vec::new(),
            corridor_width_m: None,
            pattern: crate::coverage::Pattern::Grid,
            camera_pitch_deg: None,
            trigger: super::capture::Trigger::default(),
            dji_aircraft: crate::export::wpml::DjiAircraft::default(),
        }
    }
}

pub const DEFAULT_ALTITUDE_M: f64 = 60.0;

pub(super) fn check_range(
    issues: &mut Vec<Issue>,
    pointer: &str,
    v: f64,
    lo: f64,
    hi: f64,
    lo_open: bool,
) {
    let ok = v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi;
    if !ok {
        let (v, lo, hi) = (readable(v), readable(lo), readable(hi));
        let range = if lo_open {
            format!("({lo}, {hi}]")
        } else {
            format!("[{lo}, {hi}]")
        };
        issues.push(Issue::new(
            pointer,
            &format!("{v} is outside the allowed range {range}"),
        ));
    }
}

/// A [lon, lat] position at `pointer`: each out-of-range coordinate is
/// reported at `pointer/0` or `pointer/1`.
fn check_lon_lat(issues: &mut Vec<Issue>, pointer: &str, [lon, lat]: [f64; 2]) {
    if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
        issues.push(Issue::new(
            &format!("{pointer}/0"),
            &format!("longitude {} is outside [-180, 180]", readable(lon)),
        ));
    }
    if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
        issues.push(Issue::new(
            &format!("{pointer}/1"),
            &format!("latitude {} is outside [-90, 90]", readable(lat)),
        ));
    }
}

impl SurveyParams {
    /// Parse a params JSON value; unknown fields and wrong types are
    /// reported with the pointer of the member at fault.
    pub fn from_json(value: &Value, pointer: &str) -> Result<Self, Vec<Issue>> {
        let params: SurveyParams =
            crate::geo::deserialize_at(value, pointer).map_err(|issue| vec![issue])?;
        params.validate(pointer)?;
        Ok(params)
    }

    /// Range checks; every out-of-range value is reported, none is clamped.
    pub fn validate(&self, pointer: &str) -> Result<(), Vec<Issue>> {
        let mut issues = Vec::new();
        let p = |f: &str| format!("{pointer}/{f}");
        self.check_flight(&mut issues, &p);
        self.check_camera(&mut issues, &p);
        self.check_uavs(&mut issues, &p);
        self.check_terrain(&mut issues, &p);
        self.check_rally_points(&mut issues, &p);
        if let Some(a) = &self.aircraft {
            a.check(&mut issues, &p("aircraft"));
        }
        self.check_corridor(&mut issues, &p);
        self.check_patterns(&mut issues, &p);
        self.check_dji(&mut issues, &p);
        if issues.is_empty() {
            Ok(())
        } else {
            Err(issues)
        }
    }

    /// Height, overlaps, spacing, angle, speed and clearances.
    fn check_flight(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        if let Some(a) = self.altitude_m {
            check_range(issues, &p("altitude_m"), a, 1.0, 1000.0, false);
        }
        if let Some(g) = self.gsd_cm_px {
            check_range(issues, &p("gsd_cm_px"), g, 0.05, 100.0, false);
            if self.altitude_m.is_some() {
                issues.push(Issue::new(
                    &p("gsd_cm_px"),
                    "give altitude_m or gsd_cm_px, not both",
                ));
            }
        }
        check_range(
            issues,
            &p("side_overlap"),
            self.side_overlap,
            0.0,
            0.95,
            false,
        );
        check_range(
            issues,
            &p("front_overlap"),
            self.front_overlap,
            0.0,
            0.95,
            false,
        );
        if let Some(s) = self.line_spacing_m {
            check_range(issues, &p("line_spacing_m"), s, 0.5, 2000.0, false);
        }
        if let SliceAngle::Degrees(d) = self.slice_angle_deg
            && !(d.is_finite() && (0.0..180.0).contains(&d))
        {
            issues.push(Issue::new(
                &p("slice_angle_deg"),
                &format!(
                    "{} is outside the allowed range [0, 180) (or use \"auto\")",
                    readable(d)
                ),
            ));
        }
        check_range(issues, &p("speed_m_s"), self.speed_m_s, 0.0, 50.0, true);
        check_range(
            issues,
            &p("turn_penalty_s"),
            self.turn_penalty_s,
            0.0,
            120.0,
            false,
        );
        check_range(
            issues,
            &p("nfz_clearance_m"),
            self.nfz_clearance_m,
            0.0,
            100.0,
            false,
        );
        check_range(
            issues,
            &p("fence_margin_m"),
            self.fence_margin_m,
            0.0,
            1000.0,
            false,
        );
    }

    /// The camera or camera preset.
    fn check_camera(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        match (&self.camera, &self.camera_preset) {
            (Some(_), Some(_)) => issues.push(Issue::new(
                &p("camera_preset"),
                "give camera or camera_preset, not both",
            )),
            (Some(c), None) => {
                if let Err(errs) = c.validate() {
                    issues.extend(
                        errs.into_iter()
                            .map(|(f, m)| Issue::new(&p(&format!("camera/{f}")), &m)),
                    );
                }
            }
            (None, Some(name)) if Camera::preset(name).is_none() => issues.push(Issue::new(
                &p("camera_preset"),
                &format!(
                    "unknown camera preset {name:?}; known presets: {}",
                    coverage::PRESETS.join(", ")
                ),
            )),
            _ => {}
        }
    }

    /// The UAVs: their count, ids, speeds, batteries and starts.
    fn check_uavs(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        // Over the cap, the UAVs are not looked at one by one: that work
        // (and the list of their faults) would grow with the request.
        let uavs = if self.uavs.len() > MAX_UAVS {
            issues.push(Issue::new(
                &p("uavs"),
                &format!(
                    "{} UAVs given; a survey takes at most {MAX_UAVS}",
                    self.uavs.len()
                ),
            ));
            &[][..]
        } else {
            &self.uavs[..]
        };
        let mut ids = std::collections::HashSet::with_capacity(uavs.len());
        for (i, u) in uavs.iter().enumerate() {
            if !ids.insert(u.id.as_str()) {
                issues.push(Issue::new(
                    &p(&format!("uavs/{i}/id")),
                    &format!(
                        "UAV id {:?} is given twice (ids name the mission files)",
                        u.id
                    ),
                ));
            }
            if let Some(v) = u.speed_m_s {
                check_range(
                    issues,
                    &p(&format!("uavs/{i}/speed_m_s")),
                    v,
                    0.0,
                    50.0,
                    true,
                );
            }
            if let Some(t) = u.max_flight_time_s {
                check_range(
                    issues,
                    &p(&format!("uavs/{i}/max_flight_time_s")),
                    t,
                    30.0,
                    86_400.0,
                    false,
                );
            }
            if u.id.trim().is_empty() || u.id.len() > 64 {
                issues.push(Issue::new(
                    &p(&format!("uavs/{i}/id")),
                    "a UAV id must have 1 to 64 characters",
                ));
            } else if !u
                .id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            {
                issues.push(Issue::new(
                    &p(&format!("uavs/{i}/id")),
                    "a UAV id may only contain letters, digits, '-' and '_' (it names files)",
                ));
            }
            check_lon_lat(issues, &p(&format!("uavs/{i}/start")), u.start);
        }
    }

    /// Terrain following: tolerance, clearance and climb and descent rates.
    fn check_terrain(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        check_range(
            issues,
            &p("agl_tolerance_m"),
            self.agl_tolerance_m,
            0.5,
            100.0,
            false,
        );
        if let Some(c) = self.transit_clearance_m {
            check_range(issues, &p("transit_clearance_m"), c, 1.0, 2000.0, false);
        }
        if let Some(r) = self.max_climb_rate_m_s {
            check_range(issues, &p("max_climb_rate_m_s"), r, 0.0, 50.0, true);
        }
        if let Some(r) = self.max_descent_rate_m_s {
            check_range(issues, &p("max_descent_rate_m_s"), r, 0.0, 50.0, true);
        }
    }

    /// The rally points: their count and positions.
    fn check_rally_points(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        if self.rally_points.len() > MAX_RALLY_POINTS {
            issues.push(Issue::new(
                &p("rally_points"),
                &format!(
                    "{} rally points given; a survey takes at most {MAX_RALLY_POINTS}",
                    self.rally_points.len()
                ),
            ));
        }
        for (i, &point) in self.rally_points.iter().enumerate() {
            check_lon_lat(issues, &p(&format!("rally_points/{i}")), point);
        }
    }

    pub fn camera(&self) -> Camera {
        match (&self.camera, &self.camera_preset) {
            (Some(c), _) => c.clone(),
            (None, Some(name)) => Camera::preset(name).unwrap_or_default(),
            (None, None) => Camera::default(),
        }
    }

    pub fn altitude(&self, camera: &Camera) -> f64 {
        match (self.altitude_m, self.gsd_cm_px) {
            (Some(a), _) => a,
            (None, Some(g)) => coverage::altitude_for_gsd(camera, g),
            (None, None) => DEFAULT_ALTITUDE_M,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The request is invalid; each issue names the member at fault.
    #[error("{}", crate::geo::join_issues(.0))]
    Invalid(Vec<Issue>),
    /// A stage failed on valid input (a bug, or geometry beyond its reach).
    #[error("planning failed: {0}")]
    Internal(String),
    /// Stopped by its cancellation token (see [`crate::cancel`]).
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
}

impl From<GeoError> for PlanError {
    fn from(e: GeoError) -> Self {
        match e {
            GeoError::Invalid(issues) => PlanError::Invalid(issues),
            GeoError::OutsideUtm { .. } => {
                PlanError::Invalid(vec![Issue::new(ROI_POINTER, &e.to_string())])
            }
            GeoError::Projection(m) => PlanError::Internal(m),
            GeoError::Cancelled(c) => PlanError::Cancelled(c),
        }
    }
}

/// JSON pointer of the ROI in a request document.
pub const ROI_POINTER: &str = "/roi";
/// JSON pointer of the no-fly zones array in a request document.
pub const NO_FLY_POINTER: &str = "/no_fly_zones";

/// A survey request: area, no-fly zones and parameters.
#[derive(Clone, Debug)]
pub struct SurveyRequest {
    pub roi: Vec<ParsedPolygon>,
    /// A corridor's centre line, given instead of `roi` (then empty).
    pub corridor: Option<crate::geo::ParsedLine>,
    pub no_fly: Vec<ParsedPolygon>,
    pub params: SurveyParams,
}

impl SurveyRequest {
    /// Read a request document: `{"roi": GeoJSON, "no_fly_zones": [GeoJSON,
    /// …], …SurveyParams fields}` — the body of `POST /api/v1/surveys`, and
    /// what the CLI assembles from its files. Every fault is collected, each
    /// with the JSON pointer of the member at fault.
    pub fn from_document(doc: &Value) -> Result<Self, PlanError> {
        let Some(obj) = doc.as_object() else {
            return Err(PlanError::Invalid(vec![Issue::new(
                "",
                "the request must be a JSON object",
            )]));
        };
        let mut issues = Vec::new();
        let corridor = super::corridor::read_corridor(obj, &mut issues);
        let roi = match obj.get("roi") {
            Some(v) => parse_polygons(v, ROI_POINTER).unwrap_or_else(|e| {
                issues.extend(e);
                Vec::new()
            }),
            None => Vec::new(),
        };
        let mut no_fly = Vec::new();
        match obj.get("no_fly_zones") {
            None | Some(Value::Null) => {}
            Some(Value::Array(zones)) => {
                // An empty collection (a GIS layer with no zones drawn)
                // means no NFZs, not a fault. Reading stops once the faults
                // fill the list a reply can carry.
                for (i, v) in zones
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| !is_empty_collection(v))
                {
                    if issues.len() > MAX_ISSUES {
                        break;
                    }
                    match parse_polygons(v, &format!("{NO_FLY_POINTER}/{i}")) {
                        Ok(p) => no_fly.extend(p),
                        Err(e) => issues.extend(e),
                    }
                }
            }
            Some(_) => issues.push(Issue::new(
                NO_FLY_POINTER,
                "must be an array of GeoJSON areas",
            )),
        }
        let mut rest = obj.clone();
        rest.remove("roi");
        rest.remove("corridor");
        rest.remove("no_fly_zones");
        let params = SurveyParams::from_json(&Value::Object(rest), "").unwrap_or_else(|e| {
            issues.extend(e);
            SurveyParams::default()
        });
        if issues.is_empty() {
            Ok(SurveyRequest {
                roi,
                corridor,
                no_fly,
                params,
            })
        } else {
            Err(PlanError::Invalid(cap_issues(issues)))
        }
    }
}

/// A GeoJSON FeatureCollection or GeometryCollection with no members.
fn is_empty_collection(v: &Value) -> bool {
    let members = match v.get("type").and_then(Value::as_str) {
        Some("FeatureCollection") => "features",
        Some("GeometryCollection") => "geometries",
        _ => return false,
    };
    v.get(members)
        .and_then(Value::as_array)
        .is_some_and(Vec::is_empty)
}

/// JSON pointer the faults of the DEM a survey is planned over are
/// reported at: the member naming the DEM in the service's request.
pub const DEM_POINTER: &str = "/dem_id";

/// `e`, or the cancellation that made a stage fail in its own words (see
/// [`crate::cancel`]).
pub(super) fn cancelled_or(e: PlanError) -> PlanError {
    match crate::cancel::check() {
        Err(c) => PlanError::Cancelled(c),
        Ok(()) => e,
    }
}

impl SurveyParams {
    /// The check that needs to know whether a DEM is given: the `amsl`
    /// frame needs terrain heights.
    pub(super) fn check_dem(&self, dem: Option<&Dem>) -> Result<(), PlanError> {
        if dem.is_none() && self.altitude_frame == AltitudeFrame::Amsl {
            return Err(PlanError::Invalid(vec![Issue::new(
                "/altitude_frame",
                "altitude_frame \"amsl\" needs terrain heights from a DEM, which this request has \
                 not got: give dem_id, or use \"relative\" or \"terrain\"",
            )]));
        }
        Ok(())
    }

    /// How the survey is flown (see [`Flight`]), over a DEM or not; the
    /// lanes over `free_area_m2` must stay within `limits`.
    pub(super) fn flight(
        &self,
        free_area_m2: f64,
        limits: &Limits,
        over_dem: bool,
    ) -> Result<Flight, PlanError> {
        let (altitude, geometry) = self.geometry(free_area_m2, limits)?;
        let rules = self.flight_rules(altitude, over_dem)?;
        Ok(Flight {
            altitude,
            geometry,
            rules,
        })
    }

    /// The flight height, and the footprint, spacing and trigger distance
    /// it gives, refused when the height is out of range or the lanes over
    /// `free_area_m2` would be longer than `limits` allow.
    fn geometry(
        &self,
        free_area_m2: f64,
        limits: &Limits,
    ) -> Result<(f64, SurveyGeometry), PlanError> {
        let camera = self.camera();
        let altitude = self.altitude(&camera);
        if !(1.0..=1000.0).contains(&altitude) {
            return Err(PlanError::Invalid(vec![Issue::new(
                "/gsd_cm_px",
                &format!("this GSD needs an altitude of {altitude:.1} m, outside [1, 1000] m"),
            )]));
        }
        let geometry = self.camera_geometry(&camera, altitude)?;
        let lane_km = free_area_m2 / geometry.line_spacing_m / 1000.0;
        if lane_km > limits.max_lane_km {
            let ptr = if self.line_spacing_m.is_some() {
                "/line_spacing_m"
            } else {
                "/altitude_m"
            };
            return Err(PlanError::Invalid(vec![Issue::new(
                ptr,
                &format!(
                    "this survey would need about {lane_km:.0} km of lanes at {:.2} m spacing, over the \
                     limit of {} km: fly higher, lower the side overlap or survey a smaller area",
                    geometry.line_spacing_m, limits.max_lane_km
                ),
            )]));
        }
        Ok((altitude, geometry))
    }

    /// The heights and slopes flown at `altitude` above the terrain; over a
    /// DEM the tolerance must stay below the altitude.
    fn flight_rules(&self, altitude: f64, over_dem: bool) -> Result<FlightRules, PlanError> {
        let fastest = self
            .uavs
            .iter()
            .filter_map(|u| u.speed_m_s)
            .fold(self.speed_m_s, f64::max);
        let rules = FlightRules {
            agl_m: altitude,
            tolerance_m: self.agl_tolerance_m,
            transit_clearance_m: self.transit_clearance_m.unwrap_or(altitude),
            // Slopes from rates at the fastest UAV's speed: safe for all.
            max_climb_per_m: self.max_climb_rate_m_s.map(|r| r / fastest),
            max_descent_per_m: self.max_descent_rate_m_s.map(|r| r / fastest),
        };
        if over_dem && rules.tolerance_m >= altitude {
            return Err(PlanError::Invalid(vec![Issue::new(
                "/agl_tolerance_m",
                &format!(
                    "{} m is not smaller than the flight height above ground ({altitude:.1} m): the \
                     UAV could touch the terrain",
                    rules.tolerance_m
                ),
            )]));
        }
        Ok(rules)
    }
}

/// How a survey is flown: the height above ground, the camera geometry
/// that height gives and the rules over the terrain.
pub(super) struct Flight {
    pub altitude: f64,
    pub geometry: SurveyGeometry,
    pub rules: FlightRules,
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn huge_lists_are_refused_by_their_count_with_a_capped_fault_list() {
        // 100 000 UAVs (the same id each): one fault, the count, and no
        // pairwise id check.
        let uavs: Vec<Value> = (0..100_000)
            .map(|_| json!({"id": "a", "start": [5.0, 52.0]}))
            .collect();
        let e = SurveyParams::from_json(&json!({"uavs": uavs}), "").unwrap_err();
        assert_eq!(e.len(), 1, "{:?}", &e[..e.len().min(3)]);
        assert_eq!(e[0].pointer, "/uavs");
        assert!(
            e[0].message.starts_with("100000 UAVs given"),
            "{}",
            e[0].message
        );

        // 400 000 empty NFZs: at most MAX_ISSUES faults, the last a count.
        let empty = json!({"type": "Polygon", "coordinates": []});
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.01, 52.0], [5.01, 52.01]]]},
            "no_fly_zones": vec![empty; 400_000],
        });
        let Err(PlanError::Invalid(issues)) = SurveyRequest::from_document(&doc) else {
            panic!("empty NFZs must be refused");
        };
        assert_eq!(issues.len(), MAX_ISSUES);
        assert_eq!(issues[0].pointer, "/no_fly_zones/0/coordinates");
        assert!(
            issues[MAX_ISSUES - 1]
                .message
                .contains("more problems (only the first 99"),
            "{:?}",
            issues.last()
        );
        // A few faults are listed whole.
        assert_eq!(crate::geo::cap_issues(issues[..3].to_vec()).len(), 3);
    }

    #[test]
    fn params_defaults_and_ranges() {
        let p = SurveyParams::from_json(&json!({}), "").unwrap();
        assert_eq!(p.side_overlap, 0.7);
        assert_eq!(p.front_overlap, 0.8);
        assert_eq!(p.speed_m_s, 10.0);
        assert_eq!(p.slice_angle_deg, SliceAngle::Auto);
        assert_eq!(p.altitude(&p.camera()), DEFAULT_ALTITUDE_M);

        let e = SurveyParams::from_json(&json!({"side_overlap": 1.0, "altitude_m": -5}), "")
            .unwrap_err();
        let ptrs: Vec<&str> = e.iter().map(|i| i.pointer.as_str()).collect();
        assert!(
            ptrs.contains(&"/side_overlap") && ptrs.contains(&"/altitude_m"),
            "{e:?}"
        );

        let e = SurveyParams::from_json(&json!({"slice_angle_deg": "sideways"}), "").unwrap_err();
        assert_eq!(e[0].pointer, "/slice_angle_deg");
        let e = SurveyParams::from_json(&json!({"altitude": 50}), "").unwrap_err();
        assert!(e[0].message.contains("unknown field"), "{e:?}");
        let e =
            SurveyParams::from_json(&json!({"camera": {"sensor_width_mm": "x"}}), "").unwrap_err();
        assert!(e[0].pointer.starts_with("/camera"), "{e:?}");
        let p = SurveyParams::from_json(&json!({"slice_angle_deg": 30}), "").unwrap();
        assert_eq!(p.slice_angle_deg, SliceAngle::Degrees(30.0));
    }
}
