//! The survey pipeline: area → free space → cells → lanes → tour → mission,
//! stage by stage (SPEC §3). The CLI and the service both call
//! [`plan_survey`] and write [`SurveyPlan::files`].

use geo::{Area, ConvexHull, Euclidean, Length, MultiPoint};
use geo_types::{Coord, MultiPolygon, Point, Polygon};
use rayon::prelude::*;
use serde::{Deserialize, Deserializer, Serialize};
use serde_json::{Map, Value, json};

use crate::coverage::{self, Camera, CellPlan, SurveyGeometry};
use crate::decompose;
use crate::export::{
    self, AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem, geojson as gj,
};
use crate::flock::{FlockUav, ObstacleMap, Piece, Policy, count_turns};
use crate::geo::{
    GeoError, Issue, Limits, MAX_ISSUES, ParsedPolygon, SurveyArea, cap_issues, parse_polygons,
    prepare_area,
};
use crate::num::readable;
use crate::terrain::{Dem, TerrainModel};

mod flock_plan;
mod homes;
mod rally;
mod terrain_flight;

pub use rally::{MAX_RALLY_DISTANCE_M, MAX_RALLY_POINTS, RallyPoint};
pub use terrain_flight::{FlightLeg, LegKind, ProfilePoint, UavTerrain};
use terrain_flight::{FlightRules, cell_length_3d, fly_tour, lanes_known_fraction};

/// Most UAVs in one survey.
pub const MAX_UAVS: usize = 64;

/// Default `nfz_clearance_m`: see [`SurveyParams::nfz_clearance_m`].
pub const DEFAULT_NFZ_CLEARANCE_M: f64 = 5.0;

/// Free space smaller than this (m²) is treated as nothing left to survey.
const MIN_FREE_AREA_M2: f64 = 1.0;
/// How many slice angles `auto` tries at most: every 15° plus the bearings
/// of the longest boundary edges, where the fewest turns usually are.
const AUTO_EDGE_CANDIDATES: usize = 12;
const AUTO_STEP_DEG: f64 = 15.0;

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
/// request body. Ranges are checked by [`SurveyParams::validate`].
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
    /// A stored DEM (`POST /api/v1/dems`) to follow the terrain over;
    /// without one the survey is flown flat at `altitude_m` above home.
    pub dem_id: Option<String>,
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
    /// Rally points, [lon, lat] each (at most 64): where a UAV may return
    /// instead of home; exported in each `.plan` and as a rally file.
    #[cfg_attr(feature = "openapi", schema(max_items = 64))]
    pub rally_points: Vec<[f64; 2]>,
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
            dem_id: None,
            agl_tolerance_m: 5.0,
            transit_clearance_m: None,
            max_climb_rate_m_s: None,
            max_descent_rate_m_s: None,
            allow_partial_dem: false,
            assignment: Policy::Balanced,
            rally_points: Vec::new(),
        }
    }
}

pub const DEFAULT_ALTITUDE_M: f64 = 60.0;

fn check_range(issues: &mut Vec<Issue>, pointer: &str, v: f64, lo: f64, hi: f64, lo_open: bool) {
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

impl SurveyParams {
    /// Parse a params JSON value; unknown fields and wrong types are
    /// reported with the pointer of the member at fault.
    pub fn from_json(value: &Value, pointer: &str) -> Result<Self, Vec<Issue>> {
        let params: SurveyParams = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let ptr = if path == "." {
                pointer.to_string()
            } else {
                format!(
                    "{pointer}/{}",
                    path.replace(['.', '['], "/").replace(']', "")
                )
            };
            vec![Issue::new(&ptr, &e.into_inner().to_string())]
        })?;
        params.validate(pointer)?;
        Ok(params)
    }

    /// Range checks; every out-of-range value is reported, none is clamped.
    pub fn validate(&self, pointer: &str) -> Result<(), Vec<Issue>> {
        let mut issues = Vec::new();
        let p = |f: &str| format!("{pointer}/{f}");
        if let Some(a) = self.altitude_m {
            check_range(&mut issues, &p("altitude_m"), a, 1.0, 1000.0, false);
        }
        if let Some(g) = self.gsd_cm_px {
            check_range(&mut issues, &p("gsd_cm_px"), g, 0.05, 100.0, false);
            if self.altitude_m.is_some() {
                issues.push(Issue::new(
                    &p("gsd_cm_px"),
                    "give altitude_m or gsd_cm_px, not both",
                ));
            }
        }
        check_range(
            &mut issues,
            &p("side_overlap"),
            self.side_overlap,
            0.0,
            0.95,
            false,
        );
        check_range(
            &mut issues,
            &p("front_overlap"),
            self.front_overlap,
            0.0,
            0.95,
            false,
        );
        if let Some(s) = self.line_spacing_m {
            check_range(&mut issues, &p("line_spacing_m"), s, 0.5, 2000.0, false);
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
        check_range(
            &mut issues,
            &p("speed_m_s"),
            self.speed_m_s,
            0.0,
            50.0,
            true,
        );
        check_range(
            &mut issues,
            &p("turn_penalty_s"),
            self.turn_penalty_s,
            0.0,
            120.0,
            false,
        );
        check_range(
            &mut issues,
            &p("nfz_clearance_m"),
            self.nfz_clearance_m,
            0.0,
            100.0,
            false,
        );
        check_range(
            &mut issues,
            &p("fence_margin_m"),
            self.fence_margin_m,
            0.0,
            1000.0,
            false,
        );
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
                    &mut issues,
                    &p(&format!("uavs/{i}/speed_m_s")),
                    v,
                    0.0,
                    50.0,
                    true,
                );
            }
            if let Some(t) = u.max_flight_time_s {
                check_range(
                    &mut issues,
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
            let [lon, lat] = u.start;
            if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
                issues.push(Issue::new(
                    &p(&format!("uavs/{i}/start/0")),
                    &format!("longitude {} is outside [-180, 180]", readable(lon)),
                ));
            }
            if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
                issues.push(Issue::new(
                    &p(&format!("uavs/{i}/start/1")),
                    &format!("latitude {} is outside [-90, 90]", readable(lat)),
                ));
            }
        }
        if let Some(id) = &self.dem_id
            && (id.is_empty() || id.len() > 64)
        {
            issues.push(Issue::new(&p("dem_id"), "a DEM id has 1 to 64 characters"));
        }
        check_range(
            &mut issues,
            &p("agl_tolerance_m"),
            self.agl_tolerance_m,
            0.5,
            100.0,
            false,
        );
        if let Some(c) = self.transit_clearance_m {
            check_range(
                &mut issues,
                &p("transit_clearance_m"),
                c,
                1.0,
                2000.0,
                false,
            );
        }
        if let Some(r) = self.max_climb_rate_m_s {
            check_range(&mut issues, &p("max_climb_rate_m_s"), r, 0.0, 50.0, true);
        }
        if let Some(r) = self.max_descent_rate_m_s {
            check_range(&mut issues, &p("max_descent_rate_m_s"), r, 0.0, 50.0, true);
        }
        if self.rally_points.len() > MAX_RALLY_POINTS {
            issues.push(Issue::new(
                &p("rally_points"),
                &format!(
                    "{} rally points given; a survey takes at most {MAX_RALLY_POINTS}",
                    self.rally_points.len()
                ),
            ));
        }
        for (i, &[lon, lat]) in self.rally_points.iter().enumerate() {
            if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
                issues.push(Issue::new(
                    &p(&format!("rally_points/{i}/0")),
                    &format!("longitude {} is outside [-180, 180]", readable(lon)),
                ));
            }
            if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
                issues.push(Issue::new(
                    &p(&format!("rally_points/{i}/1")),
                    &format!("latitude {} is outside [-90, 90]", readable(lat)),
                ));
            }
        }
        if issues.is_empty() {
            Ok(())
        } else {
            Err(issues)
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
        let roi = match obj.get("roi") {
            Some(v) => parse_polygons(v, ROI_POINTER).unwrap_or_else(|e| {
                issues.extend(e);
                Vec::new()
            }),
            None => {
                issues.push(Issue::new(
                    ROI_POINTER,
                    "missing: the region of interest (GeoJSON) is required",
                ));
                Vec::new()
            }
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
        rest.remove("no_fly_zones");
        let params = SurveyParams::from_json(&Value::Object(rest), "").unwrap_or_else(|e| {
            issues.extend(e);
            SurveyParams::default()
        });
        if issues.is_empty() {
            Ok(SurveyRequest {
                roi,
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

/// Statistics of the whole survey.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurveyStats {
    pub area_m2: f64,
    pub free_area_m2: f64,
    /// The free area less the band within `nfz_clearance_m` of the NFZs
    /// (and pockets no way into keeps that clearance): what the cells tile
    /// and the lanes are flown over. Coverage is still of the free area.
    #[serde(default)]
    pub flyable_area_m2: f64,
    /// The distance kept from every NFZ and the inclusion fence, m.
    #[serde(default)]
    pub nfz_clearance_m: f64,
    pub altitude_m: f64,
    pub gsd_cm_px: f64,
    pub footprint_side_m: f64,
    pub footprint_front_m: f64,
    pub line_spacing_m: f64,
    pub trigger_distance_m: f64,
    pub slice_angle_deg: f64,
    pub cell_count: usize,
    pub lane_count: usize,
    /// Photos, lengths, turns and flight time are summed over the flock
    /// (see `makespan_s` for the survey's duration).
    pub photos: usize,
    pub length_m: f64,
    pub length_3d_m: f64,
    pub turns: usize,
    pub flight_time_s: f64,
    pub coverage_ratio: f64,
    /// UAVs in the flock.
    #[serde(default)]
    pub uav_count: usize,
    /// The assignment policy used.
    #[serde(default)]
    pub assignment: Policy,
    /// The longest UAV mission (all its sorties), s.
    #[serde(default)]
    pub makespan_s: f64,
    /// No way of sharing the cells can have a shorter makespan than this, s.
    #[serde(default)]
    pub makespan_lower_bound_s: f64,
    /// `makespan_s / makespan_lower_bound_s - 1`: how far the plan can at
    /// most be from the best possible.
    #[serde(default)]
    pub makespan_gap: f64,
    /// Longest minus shortest UAV mission time, s.
    #[serde(default)]
    pub imbalance_s: f64,
    /// Longest minus shortest UAV 3D length, m.
    #[serde(default)]
    pub imbalance_3d_m: f64,
    /// Sorties flown by the whole flock (more than one per UAV when a
    /// battery is too small for its share).
    #[serde(default)]
    pub sorties: usize,
    /// Terrain following, when the survey is flown over a DEM.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terrain: Option<SurveyTerrainStats>,
}

/// How a survey follows the terrain.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurveyTerrainStats {
    /// Share of the survey lanes with DEM heights under them, [0, 1].
    pub dem_known_fraction: f64,
    /// Radius of the grey-scale dilation flown over, m (at least half the
    /// footprint).
    pub dilation_radius_m: f64,
    pub agl_tolerance_m: f64,
    pub transit_clearance_m: f64,
}

/// Statistics of one UAV's mission.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UavStats {
    pub length_m: f64,
    pub length_3d_m: f64,
    pub survey_length_m: f64,
    pub transit_length_m: f64,
    pub turns: usize,
    pub flight_time_s: f64,
    pub photos: usize,
    /// Cells flown, wholly or in part.
    pub cells: usize,
    /// Flights from take-off to landing (battery sorties).
    #[serde(default = "one")]
    pub sorties: usize,
}

fn one() -> usize {
    1
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellOut {
    pub id: usize,
    pub area_m2: f64,
    pub lane_bearing_deg: f64,
    pub lanes: usize,
    /// Summed length of the cell's survey lanes, m.
    #[serde(default)]
    pub lane_length_m: f64,
    /// GeoJSON Polygon, WGS84.
    pub polygon: Value,
}

/// One flight of a UAV, from take-off at its start to landing there.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SortiePlan {
    /// Stem of the sortie's file names: the UAV id, or `<id>.sortie<k>`
    /// (k from 1) when the UAV flies several sorties.
    pub file_stem: String,
    /// Cell ids in the order flown.
    pub cells: Vec<usize>,
    /// The parts of cells flown, in order.
    pub pieces: Vec<Piece>,
    pub stats: UavStats,
    pub mission: Mission,
    /// The flight over the DEM, when there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terrain: Option<UavTerrain>,
}

impl SortiePlan {
    /// The flown route as a GeoJSON Feature (positions at heights above the
    /// WGS 84 ellipsoid over a DEM, 2D without one; the mission's altitudes
    /// as properties): see [`gj::route_feature`].
    pub fn route_feature(&self, properties: Map<String, Value>) -> Value {
        let flown: Vec<[f64; 3]> = self
            .terrain
            .iter()
            .flat_map(|t| t.legs.iter().flat_map(|l| l.points.iter().copied()))
            .collect();
        gj::route_feature(&self.mission, &flown, properties)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "StoredUavPlan")]
pub struct UavPlan {
    pub id: String,
    pub start: [f64; 2],
    pub speed_m_s: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_flight_time_s: Option<f64>,
    /// Cell ids in the order flown (a cell flown in parts appears once per
    /// run of its parts).
    pub cells: Vec<usize>,
    /// The parts of cells flown, in order: a whole cell, or part of it when
    /// cells were halved for more UAVs than cells or for the battery.
    pub pieces: Vec<Piece>,
    /// Totals over the sorties.
    pub stats: UavStats,
    /// At least one; several when the battery needs them.
    pub sorties: Vec<SortiePlan>,
}

/// A [`UavPlan`] as stored: the current layout, or the one-mission layout
/// of plans stored before flocks (`mission`, `terrain` and `stats` at the
/// top), read as one sortie, so that older surveys still open.
#[derive(Deserialize)]
struct StoredUavPlan {
    id: String,
    start: [f64; 2],
    #[serde(default)]
    speed_m_s: Option<f64>,
    #[serde(default)]
    max_flight_time_s: Option<f64>,
    cells: Vec<usize>,
    #[serde(default)]
    pieces: Vec<Piece>,
    stats: UavStats,
    #[serde(default)]
    sorties: Vec<SortiePlan>,
    #[serde(default)]
    mission: Option<Mission>,
    #[serde(default)]
    terrain: Option<UavTerrain>,
}

impl From<StoredUavPlan> for UavPlan {
    fn from(s: StoredUavPlan) -> UavPlan {
        let mut sorties = s.sorties;
        if sorties.is_empty()
            && let Some(mission) = s.mission
        {
            sorties.push(SortiePlan {
                file_stem: s.id.clone(),
                cells: s.cells.clone(),
                // Old plans did not say which lanes: their cells were whole.
                pieces: s.pieces.clone(),
                stats: s.stats.clone(),
                mission,
                terrain: s.terrain,
            });
        }
        let speed_m_s = s
            .speed_m_s
            .or_else(|| sorties.first().map(|f| f.mission.cruise_speed_m_s))
            .unwrap_or(10.0);
        UavPlan {
            id: s.id,
            start: s.start,
            speed_m_s,
            max_flight_time_s: s.max_flight_time_s,
            cells: s.cells,
            pieces: s.pieces,
            stats: s.stats,
            sorties,
        }
    }
}

/// A planned survey: what `plan.json` holds and the files are made from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurveyPlan {
    pub utm_epsg: u32,
    pub altitude_frame: AltitudeFrame,
    pub stats: SurveyStats,
    pub cells: Vec<CellOut>,
    pub uavs: Vec<UavPlan>,
    /// Fence polygons (lon/lat): the inclusion area, then every no-fly zone.
    pub fences: Vec<FencePolygon>,
    /// Rally points, in the inclusion fence and clear of the no-fly zones.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rally_points: Vec<RallyPoint>,
    pub warnings: Vec<String>,
}

/// A file produced from a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanFile {
    pub name: String,
    pub content_type: &'static str,
    pub content: String,
}

/// Plan a survey end to end, flat (no DEM).
pub fn plan_survey(req: &SurveyRequest, limits: &Limits) -> Result<SurveyPlan, PlanError> {
    plan_survey_over(req, limits, None)
}

/// JSON pointer of the DEM reference in a request document.
pub const DEM_POINTER: &str = "/dem_id";

/// Plan a survey end to end, following the terrain of `dem` when given
/// (the DEM `params.dem_id` names, resolved by the caller).
pub fn plan_survey_over(
    req: &SurveyRequest,
    limits: &Limits,
    dem: Option<&Dem>,
) -> Result<SurveyPlan, PlanError> {
    let params = &req.params;
    params.validate("").map_err(PlanError::Invalid)?;
    if dem.is_none() && params.dem_id.is_some() {
        return Err(PlanError::Invalid(vec![Issue::new(
            DEM_POINTER,
            "this DEM id names a DEM stored in the service; outside it give the DEM file itself",
        )]));
    }
    if dem.is_none() && params.altitude_frame == AltitudeFrame::Amsl {
        return Err(PlanError::Invalid(vec![Issue::new(
            "/altitude_frame",
            "altitude_frame \"amsl\" needs terrain heights from a DEM, which this request has \
             not got: give dem_id, or use \"relative\" or \"terrain\"",
        )]));
    }
    let area = prepare_area(&req.roi, &req.no_fly, ROI_POINTER, NO_FLY_POINTER, limits)?;
    let proj = &area.projection;

    let free = roi_minus(&area, &area.no_fly);
    crate::cancel::check()?;
    let free_area = free.unsigned_area();
    if free_area < MIN_FREE_AREA_M2 {
        return Err(PlanError::Invalid(vec![Issue::new(
            NO_FLY_POINTER,
            "the no-fly zones cover the whole region of interest: nothing is left to survey",
        )]));
    }

    let camera = params.camera();
    let altitude = params.altitude(&camera);
    if !(1.0..=1000.0).contains(&altitude) {
        return Err(PlanError::Invalid(vec![Issue::new(
            "/gsd_cm_px",
            &format!("this GSD needs an altitude of {altitude:.1} m, outside [1, 1000] m"),
        )]));
    }
    let geometry = coverage::survey_geometry(
        &camera,
        altitude,
        params.side_overlap,
        params.front_overlap,
        params.line_spacing_m,
    );

    let lane_km = free_area / geometry.line_spacing_m / 1000.0;
    if lane_km > limits.max_lane_km {
        let ptr = if params.line_spacing_m.is_some() {
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
    let fastest = params
        .uavs
        .iter()
        .filter_map(|u| u.speed_m_s)
        .fold(params.speed_m_s, f64::max);
    let rules = FlightRules {
        agl_m: altitude,
        tolerance_m: params.agl_tolerance_m,
        transit_clearance_m: params.transit_clearance_m.unwrap_or(altitude),
        // Slopes from rates at the fastest UAV's speed: safe for all.
        max_climb_per_m: params.max_climb_rate_m_s.map(|r| r / fastest),
        max_descent_per_m: params.max_descent_rate_m_s.map(|r| r / fastest),
    };
    if dem.is_some() && rules.tolerance_m >= altitude {
        return Err(PlanError::Invalid(vec![Issue::new(
            "/agl_tolerance_m",
            &format!(
                "{} m is not smaller than the flight height above ground ({altitude:.1} m): the \
                 UAV could touch the terrain",
                rules.tolerance_m
            ),
        )]));
    }
    // Everything flown keeps the clearance from the NFZs (they are exported
    // as exclusion fences): lanes, links and transits are planned outside
    // this keep-out area, coverage is still measured over the free space.
    let clearance = params.nfz_clearance_m;
    let nfz_union = nfz_union(&area.no_fly);
    let keep_out = crate::geo::keep_out_area(&nfz_union, clearance);
    let flyable = if clearance > 0.0 {
        roi_minus(&area, &keep_out.0)
    } else {
        free.clone()
    };
    crate::cancel::check()?;
    if flyable.unsigned_area() < MIN_FREE_AREA_M2 {
        return Err(homes::nothing_flyable(clearance));
    }
    let mut warnings = Vec::new();

    // The flock: every UAV's start in planning coordinates.
    let default_uav;
    let uav_specs: &[UavSpec] = if params.uavs.is_empty() {
        let (start, note) = homes::default_start(&req.roi[0].polygon, &area, &keep_out, clearance)?;
        warnings.extend(note);
        default_uav = [UavSpec {
            id: "uav1".to_string(),
            start,
            speed_m_s: None,
            max_flight_time_s: None,
        }];
        &default_uav
    } else {
        &params.uavs
    };
    let pointer = |i: usize, field: &str| -> String {
        if params.uavs.is_empty() {
            "/uavs".to_string()
        } else {
            format!("/uavs/{i}/{field}")
        }
    };
    let homes: Vec<Coord<f64>> = uav_specs
        .iter()
        .map(|u| {
            proj.to_utm(Coord {
                x: u.start[0],
                y: u.start[1],
            })
        })
        .collect::<Result<_, _>>()?;
    // Pockets the keep-out area encloses cannot be reached (gaps between
    // NFZs narrower than twice the clearance): not flown, unless a UAV
    // takes off inside.
    let (keep_out, enclosed_m2) = crate::geo::fill_enclosed(&keep_out, &homes);
    let flyable = if enclosed_m2 > 0.0 {
        roi_minus(&area, &keep_out.0)
    } else {
        flyable
    };
    crate::cancel::check()?;
    if flyable.unsigned_area() < MIN_FREE_AREA_M2 {
        return Err(homes::nothing_flyable(clearance));
    }
    let mut obstacles = ObstacleMap::new(&keep_out, 0.0);
    let ids: Vec<String> = uav_specs.iter().map(|u| u.id.clone()).collect();
    warnings.extend(
        homes::check_homes(
            &homes,
            &ids,
            &pointer,
            &area.no_fly,
            clearance,
            &mut obstacles,
            proj,
        )
        .map_err(cancelled_or)?,
    );
    crate::cancel::check()?;
    let Decomposition {
        slice_angle_deg: slice_angle,
        cells,
        mut plans,
        ..
    } = decompose_and_cover(&flyable, params.slice_angle_deg, geometry.line_spacing_m)?;
    let terrain = match dem {
        None => None,
        Some(dem) => {
            // Cheap checks first: every start needs a height (relative
            // altitudes are measured from it), unless the DEM misses the
            // whole area (reported as such below).
            let no_home = |i: usize| {
                let u = &uav_specs[i];
                Issue::new(
                    &pointer(i, "start"),
                    &format!(
                        "the DEM has no height under UAV {}'s start ({:.6}, {:.6}): relative \
                         altitudes are measured from there; start inside the DEM",
                        u.id, u.start[0], u.start[1]
                    ),
                )
            };
            let sampler = crate::terrain::TerrainSampler::new(dem, proj.epsg())
                .map_err(|e| PlanError::Invalid(vec![Issue::new(DEM_POINTER, &e.to_string())]))?;
            let roi_vertex = area.roi.0[0].exterior().0[0];
            if sampler.height(roi_vertex).is_some() {
                let missing: Vec<Issue> = (0..homes.len())
                    .filter(|&i| sampler.height(homes[i]).is_none())
                    .map(no_home)
                    .collect();
                if !missing.is_empty() {
                    return Err(PlanError::Invalid(missing));
                }
            }
            let spaces = Spaces {
                free: &free,
                flyable: &flyable,
            };
            let t = prepare_terrain(dem, &area, &homes, &geometry, &plans, params, spaces)
                .map_err(cancelled_or)?;
            if t.known_fraction < 1.0 {
                warnings.push(format!(
                    "the DEM has no heights under {:.1} % of the survey area: flown there at the \
                     highest height nearby",
                    (1.0 - t.known_fraction) * 100.0
                ));
            }
            // Among the lane directions with the fewest turns, fly the one
            // with the shortest 3D length over the terrain.
            plans = plans
                .into_iter()
                .map(|p| {
                    if crate::cancel::check().is_err() {
                        return p; // checked again below
                    }
                    let candidates = coverage::plan_cell_candidates_in(
                        p.cell_index,
                        &cells[p.cell_index],
                        &t.free_space,
                        geometry.line_spacing_m,
                        slice_angle,
                    )
                    .unwrap_or_default();
                    if candidates.len() < 2 {
                        return p;
                    }
                    candidates
                        .into_iter()
                        .map(|c| (cell_length_3d(&t.model, &c, &rules), c))
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                        .map_or(p, |(_, c)| c)
                })
                .collect();
            crate::cancel::check()?;
            let homes_amsl: Vec<f64> = (0..homes.len())
                .map(|i| t.model.terrain(homes[i]).ok_or_else(|| no_home(i)))
                .collect::<Result<_, Issue>>()
                .map_err(|i| PlanError::Invalid(vec![i]))?;
            Some((t, homes_amsl))
        }
    };

    let (rally_points, rally_utm) =
        rally::check_rally_points(&params.rally_points, &area, clearance, dem)?;

    let speeds: Vec<f64> = uav_specs
        .iter()
        .map(|u| u.speed_m_s.unwrap_or(params.speed_m_s))
        .collect();
    let input = flock_plan::FlockInput {
        plans: &plans,
        cells: &cells,
        free: &flyable,
        obstacles: &obstacles,
        uavs: homes
            .iter()
            .zip(&speeds)
            .map(|(&home, &speed_m_s)| FlockUav { home, speed_m_s })
            .collect(),
        batteries: uav_specs.iter().map(|u| u.max_flight_time_s).collect(),
        ids: uav_specs.iter().map(|u| u.id.clone()).collect(),
        pointer: &pointer,
        policy: params.assignment,
        turn_penalty_s: params.turn_penalty_s,
        altitude_m: altitude,
        terrain: terrain.as_ref().map(|(t, _)| (&t.model, rules)),
    };
    let outcome = flock_plan::share(&input).map_err(cancelled_or)?;
    crate::cancel::check()?;

    let mut uav_plans = Vec::with_capacity(uav_specs.len());
    let mut all_paths: Vec<Coord<f64>> = Vec::new();
    for (i, (spec, flights)) in uav_specs.iter().zip(outcome.sorties).enumerate() {
        let speed = speeds[i];
        let several = flights.len() > 1;
        let mut sorties = Vec::with_capacity(flights.len());
        for (k, flight) in flights.into_iter().enumerate() {
            crate::cancel::check()?;
            let tour = &flight.tour;
            let (mission, length_3d, uav_terrain) = match &terrain {
                None => {
                    let home = GeoPoint {
                        lon: spec.start[0],
                        lat: spec.start[1],
                        alt: 0.0,
                    };
                    let mission =
                        build_mission(tour, home, altitude, speed, &geometry, params, proj)?;
                    // Flat survey: 3D adds the climb after take-off and the
                    // descent home.
                    (mission, tour.length_m() + 2.0 * altitude, None)
                }
                Some((t, homes_amsl)) => {
                    let flight = fly_tour(
                        tour,
                        &t.model,
                        &rules,
                        spec.start,
                        homes_amsl[i],
                        params.altitude_frame,
                        speed,
                        &geometry,
                        proj,
                    )?;
                    (flight.mission, flight.length_3d_m, Some(flight.terrain))
                }
            };
            let path = tour.path();
            let stats = tour_stats(tour, &path, length_3d, speed, params, &geometry);
            all_paths.extend(path);
            sorties.push(SortiePlan {
                file_stem: if several {
                    format!("{}.sortie{}", spec.id, k + 1)
                } else {
                    spec.id.clone()
                },
                cells: visited_cells(&flight.pieces),
                pieces: flight.pieces,
                stats,
                mission,
                terrain: uav_terrain,
            });
        }
        let pieces: Vec<Piece> = sorties.iter().flat_map(|s| s.pieces.clone()).collect();
        let cells_flown = visited_cells(&pieces);
        let sum = |f: fn(&UavStats) -> f64| sorties.iter().map(|s| f(&s.stats)).sum::<f64>();
        let stats = UavStats {
            length_m: sum(|s| s.length_m),
            length_3d_m: sum(|s| s.length_3d_m),
            survey_length_m: sum(|s| s.survey_length_m),
            transit_length_m: sum(|s| s.transit_length_m),
            turns: sorties.iter().map(|s| s.stats.turns).sum(),
            flight_time_s: sum(|s| s.flight_time_s),
            photos: sorties.iter().map(|s| s.stats.photos).sum(),
            cells: {
                let mut c = cells_flown.clone();
                c.sort_unstable();
                c.dedup();
                c.len()
            },
            sorties: sorties.len(),
        };
        uav_plans.push(UavPlan {
            id: spec.id.clone(),
            start: spec.start,
            speed_m_s: speed,
            max_flight_time_s: spec.max_flight_time_s,
            cells: cells_flown,
            pieces,
            stats,
            sorties,
        });
    }

    let lanes: Vec<coverage::Lane> = plans.iter().flat_map(|p| p.lanes.iter().copied()).collect();
    let coverage_ratio = coverage::coverage_ratio(&lanes, geometry.footprint_side_m, &free);
    crate::cancel::check()?;
    if enclosed_m2 > 0.0 {
        warnings.push(format!(
            "{:.0} m² of the free area are enclosed by no-fly zones with gaps narrower than twice \
             nfz_clearance_m ({clearance} m): no way in keeps the clearance, so they are not flown",
            enclosed_m2
        ));
    }
    if coverage_ratio < 0.995 {
        warnings.push(format!(
            "footprints cover {:.2} % of the free area: {:.0} m² are left out (narrow corners \
             between no-fly zones, or strips the lanes cannot reach while keeping \
             nfz_clearance_m = {clearance} m from them)",
            coverage_ratio * 100.0,
            (1.0 - coverage_ratio) * free_area
        ));
    }

    let cells_out = cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let plan = plans.iter().find(|p| p.cell_index == i);
            Ok(CellOut {
                id: i,
                area_m2: c.unsigned_area(),
                lane_bearing_deg: plan.map_or(slice_angle, |p| p.direction_deg),
                lanes: plan.map_or(0, |p| p.lanes.len()),
                lane_length_m: plan
                    .map_or(0.0, |p| p.lanes.iter().map(|l| dist(l.start, l.end)).sum()),
                polygon: gj::polygon_geometry(&proj.polygon_to_wgs84(c)?),
            })
        })
        .collect::<Result<Vec<_>, GeoError>>()?;

    // The inclusion fence holds the rally points (a UAV flies there on
    // RTL) and keeps the NFZs' clearance too: a vehicle flying on its edge
    // would breach it with ordinary GPS error.
    all_paths.extend(rally_utm);
    let fences = fences(
        &area,
        &all_paths,
        params.fence_margin_m.max(params.nfz_clearance_m),
    )?;
    let times: Vec<f64> = uav_plans.iter().map(|u| u.stats.flight_time_s).collect();
    let lengths: Vec<f64> = uav_plans.iter().map(|u| u.stats.length_3d_m).collect();
    let spread = |v: &[f64]| {
        v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - v.iter().copied().fold(f64::INFINITY, f64::min)
    };
    let makespan = times.iter().copied().fold(0.0, f64::max);
    let total = |f: fn(&UavStats) -> f64| uav_plans.iter().map(|u| f(&u.stats)).sum::<f64>();
    let stats = SurveyStats {
        area_m2: area.roi.unsigned_area(),
        free_area_m2: free_area,
        flyable_area_m2: flyable.unsigned_area(),
        nfz_clearance_m: clearance,
        altitude_m: altitude,
        gsd_cm_px: geometry.gsd_cm_px,
        footprint_side_m: geometry.footprint_side_m,
        footprint_front_m: geometry.footprint_front_m,
        line_spacing_m: geometry.line_spacing_m,
        trigger_distance_m: geometry.trigger_distance_m,
        slice_angle_deg: slice_angle,
        cell_count: cells.len(),
        lane_count: lanes.len(),
        photos: uav_plans.iter().map(|u| u.stats.photos).sum(),
        length_m: total(|s| s.length_m),
        length_3d_m: total(|s| s.length_3d_m),
        turns: uav_plans.iter().map(|u| u.stats.turns).sum(),
        flight_time_s: total(|s| s.flight_time_s),
        coverage_ratio,
        uav_count: uav_plans.len(),
        assignment: params.assignment,
        makespan_s: makespan,
        makespan_lower_bound_s: outcome.lower_bound_s,
        makespan_gap: if outcome.lower_bound_s > 0.0 {
            makespan / outcome.lower_bound_s - 1.0
        } else {
            0.0
        },
        imbalance_s: spread(&times),
        imbalance_3d_m: spread(&lengths),
        sorties: uav_plans.iter().map(|u| u.stats.sorties).sum(),
        terrain: terrain.as_ref().map(|(t, _)| SurveyTerrainStats {
            dem_known_fraction: t.known_fraction,
            dilation_radius_m: t.model.dilation_radius_m(),
            agl_tolerance_m: rules.tolerance_m,
            transit_clearance_m: rules.transit_clearance_m,
        }),
    };
    Ok(SurveyPlan {
        utm_epsg: proj.epsg(),
        altitude_frame: params.altitude_frame,
        stats,
        cells: cells_out,
        uavs: uav_plans,
        fences,
        rally_points,
        warnings,
    })
}

/// Statistics of one flown tour.
fn tour_stats(
    tour: &crate::flock::Tour,
    path: &[Coord<f64>],
    length_3d: f64,
    speed: f64,
    params: &SurveyParams,
    geometry: &SurveyGeometry,
) -> UavStats {
    let lane_lengths: Vec<f64> = tour
        .visits
        .iter()
        .flat_map(|v| &v.lanes)
        .map(|l| dist(l.start, l.end))
        .collect();
    let turns = count_turns(path);
    let mut cells: Vec<usize> = tour.visits.iter().map(|v| v.cell_index).collect();
    cells.sort_unstable();
    cells.dedup();
    UavStats {
        length_m: tour.length_m(),
        length_3d_m: length_3d,
        survey_length_m: lane_lengths.iter().sum(),
        transit_length_m: tour.transit_length_m(),
        turns,
        flight_time_s: length_3d / speed + turns as f64 * params.turn_penalty_s,
        photos: lane_lengths
            .iter()
            .map(|&len| coverage::photo_count(len, geometry.trigger_distance_m))
            .sum(),
        cells: cells.len(),
        sorties: 1,
    }
}

/// Cell ids in the order the pieces are flown, a cell once per run of its
/// pieces.
fn visited_cells(pieces: &[Piece]) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    for p in pieces {
        if out.last() != Some(&p.cell) {
            out.push(p.cell);
        }
    }
    out
}

/// The DEM prepared for one survey.
struct SurveyTerrain {
    model: TerrainModel,
    free_space: coverage::FreeSpace,
    /// Share of the lanes with DEM heights under them.
    known_fraction: f64,
}

/// The free space (ROI − NFZs: what is to be covered) and the flyable
/// space (less the NFZs' keep-out area: where lanes and links run).
struct Spaces<'a> {
    free: &'a MultiPolygon<f64>,
    flyable: &'a MultiPolygon<f64>,
}

/// Crop and dilate the DEM around the survey (ROI, no-fly zones — transits
/// go round them — and the start), and check that it has heights under the
/// lanes of `plans`.
fn prepare_terrain(
    dem: &Dem,
    area: &SurveyArea,
    homes: &[Coord<f64>],
    geometry: &SurveyGeometry,
    plans: &[CellPlan],
    params: &SurveyParams,
    spaces: Spaces,
) -> Result<SurveyTerrain, PlanError> {
    let Spaces { free, flyable } = spaces;
    use geo::BoundingRect;
    let mut pts: Vec<Coord<f64>> = area
        .roi
        .0
        .iter()
        .flat_map(|p| p.exterior().0.iter().copied())
        .collect();
    pts.extend(
        area.no_fly
            .iter()
            .flat_map(|p| p.exterior().0.iter().copied()),
    );
    pts.extend_from_slice(homes);
    let bbox = geo_types::LineString(pts)
        .bounding_rect()
        .ok_or_else(|| PlanError::Internal("empty survey extent".into()))?;
    // Transits round no-fly zones pass their corners pushed out by the
    // clearance: keep them inside the model.
    let grow = params.nfz_clearance_m + 10.0;
    let extent = geo_types::Rect::new(
        Coord {
            x: bbox.min().x - grow,
            y: bbox.min().y - grow,
        },
        Coord {
            x: bbox.max().x + grow,
            y: bbox.max().y + grow,
        },
    );
    // Everything under the footprint must be cleared: dilate by half of it.
    let radius = geometry.footprint_side_m.max(geometry.footprint_front_m) / 2.0;
    // About what will be flown: the cells' paths and a transit per cell.
    let diagonal = (extent.width()).hypot(extent.height());
    let path_length: f64 =
        plans.iter().map(CellPlan::length_m).sum::<f64>() + (plans.len() + 1) as f64 * diagonal;
    let model = TerrainModel::new(dem, area.projection.epsg(), extent, radius, path_length)
        .map_err(|e| PlanError::Invalid(vec![Issue::new(DEM_POINTER, &e.to_string())]))?;
    let lanes: Vec<coverage::Lane> = plans.iter().flat_map(|p| p.lanes.iter().copied()).collect();
    let known_fraction = lanes_known_fraction(&model, &lanes);
    if model.is_empty() || (known_fraction < 1.0 && !params.allow_partial_dem) {
        let missing = 1.0 - known_fraction;
        let msg = if model.is_empty() || known_fraction == 0.0 {
            "the DEM has no heights anywhere under the region of interest: it covers another area"
                .to_string()
        } else {
            format!(
                "the DEM has no heights under {:.1} % of the survey area (about {:.2} ha of {:.2} \
                 ha): give a DEM that covers the whole region of interest, or set \
                 allow_partial_dem: true to fly those parts at the highest height nearby",
                missing * 100.0,
                missing * free.unsigned_area() / 1e4,
                free.unsigned_area() / 1e4
            )
        };
        return Err(PlanError::Invalid(vec![Issue::new(DEM_POINTER, &msg)]));
    }
    Ok(SurveyTerrain {
        model,
        free_space: coverage::FreeSpace::new(flyable),
        known_fraction,
    })
}

/// ROI minus `zones`, over every part of the ROI: the free space (minus
/// the NFZs), or the flyable space (minus their keep-out area, where lanes,
/// links and transits may run).
fn roi_minus(area: &SurveyArea, zones: &[Polygon<f64>]) -> MultiPolygon<f64> {
    let mut parts = Vec::new();
    for roi in &area.roi.0 {
        parts.extend(decompose::free_space(roi, zones).0);
    }
    if area.roi.0.len() > 1 {
        // Overlapping ROI parts must not be surveyed twice.
        crate::geo::overlay::unary_union(parts.iter())
    } else {
        MultiPolygon(parts)
    }
}

/// `e`, or the cancellation that made a stage fail in its own words (see
/// [`crate::cancel`]).
fn cancelled_or(e: PlanError) -> PlanError {
    match crate::cancel::check() {
        Err(c) => PlanError::Cancelled(c),
        Ok(()) => e,
    }
}

/// One pass over all zones: folding pairwise unions is quadratic.
fn nfz_union(no_fly: &[Polygon<f64>]) -> MultiPolygon<f64> {
    crate::geo::overlay::unary_union(no_fly.iter())
}

/// Cells at one slice angle and the lawnmower plan of each.
struct Decomposition {
    slice_angle_deg: f64,
    cells: Vec<Polygon<f64>>,
    plans: Vec<CellPlan>,
    turns: usize,
    length_m: f64,
}

/// The cells of one slice angle, their lane layouts and the turns these
/// need in all.
struct Laid {
    angle: f64,
    cells: Vec<Polygon<f64>>,
    layouts: Vec<Option<coverage::CellLayouts>>,
    turns: usize,
}

/// Decompose at the requested angle, or at every candidate angle for
/// `auto`, and plan the lanes of every cell. `auto` keeps the angle with
/// the fewest turns in total, then the shortest lanes-and-links length.
/// The turns of an angle are known from its cells' lane layouts alone, so
/// the lanes are only extended and linked for the angles that tie on the
/// fewest (most of the work among thousands of NFZs).
fn decompose_and_cover(
    free: &MultiPolygon<f64>,
    angle: SliceAngle,
    spacing: f64,
) -> Result<Decomposition, PlanError> {
    let candidates = match angle {
        SliceAngle::Degrees(d) => vec![d],
        SliceAngle::Auto => auto_candidates(free),
    };
    let token = crate::cancel::current();
    // One decomposition per core at a time (each can hold tens of
    // thousands of cells), the token taken along to the worker threads.
    let decomposed = |a: f64| -> Result<Laid, PlanError> {
        token.scope(|| {
            crate::cancel::check()?;
            let cells = decompose::decompose(free, a).map_err(|e| match e {
                decompose::DecomposeError::EmptyFreeSpace => PlanError::Invalid(vec![Issue::new(
                    NO_FLY_POINTER,
                    "the no-fly zones cover the whole region of interest: nothing is left to \
                     survey",
                )]),
                decompose::DecomposeError::Cancelled(c) => PlanError::Cancelled(c),
                other => PlanError::Internal(other.to_string()),
            })?;
            let layouts: Vec<Option<coverage::CellLayouts>> = cells
                .iter()
                .enumerate()
                .map(|(i, c)| coverage::CellLayouts::new(i, c, spacing, a))
                .collect();
            // The cells stop early when cancelled, with layouts to throw away.
            crate::cancel::check()?;
            let turns = layouts.iter().flatten().map(|l| l.turns()).sum();
            Ok(Laid {
                angle: a,
                cells,
                layouts,
                turns,
            })
        })
    };
    let mut fewest = usize::MAX;
    let mut contenders: Vec<Laid> = Vec::new();
    for batch in candidates.chunks(rayon::current_num_threads().max(1)) {
        let results: Vec<_> = batch.par_iter().map(|&a| decomposed(a)).collect();
        for result in results {
            let laid = result?;
            if laid.turns < fewest {
                fewest = laid.turns;
                contenders.clear();
            }
            if laid.turns == fewest {
                contenders.push(laid);
            }
        }
    }
    let mut best: Option<Decomposition> = None;
    // Index the free space once for every cell of every contending angle.
    let free_space = coverage::FreeSpace::new(free);
    for Laid {
        angle: a,
        cells,
        layouts,
        ..
    } in contenders
    {
        let plans: Vec<CellPlan> = layouts
            .par_iter()
            .zip(&cells)
            .filter_map(|(l, c)| token.scope(|| l.as_ref()?.best_plan(c, &free_space)))
            .collect();
        crate::cancel::check()?;
        let turns: usize = plans.iter().map(CellPlan::turns).sum();
        let length_m: f64 = plans.iter().map(CellPlan::length_m).sum();
        let better = best
            .as_ref()
            .is_none_or(|b| turns < b.turns || (turns == b.turns && length_m < b.length_m - 1e-6));
        if better {
            best = Some(Decomposition {
                slice_angle_deg: a,
                cells,
                plans,
                turns,
                length_m,
            });
        }
    }
    let best = best.ok_or_else(|| PlanError::Internal("no slice angle tried".into()))?;
    if best.plans.is_empty() {
        return Err(PlanError::Invalid(vec![Issue::new(
            ROI_POINTER,
            "the free area is too small or too thin for a single survey lane",
        )]));
    }
    Ok(best)
}

/// Candidate slice angles for `auto`: every 15°, and the bearings of the
/// longest boundary edges (a lane or slice along a long edge saves turns).
fn auto_candidates(free: &MultiPolygon<f64>) -> Vec<f64> {
    let mut edges: Vec<(f64, f64)> = free
        .0
        .iter()
        .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
        .flat_map(|r| r.lines())
        .map(|l| (Euclidean.length(&l), bearing_mod_180(l.start, l.end)))
        .collect();
    edges.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<f64> = (0..(180.0 / AUTO_STEP_DEG) as usize)
        .map(|i| i as f64 * AUTO_STEP_DEG)
        .collect();
    for (_, b) in edges.into_iter().take(AUTO_EDGE_CANDIDATES) {
        for c in [b, (b + 90.0) % 180.0] {
            if out.iter().all(|o| angle_gap(*o, c) > 0.5) {
                out.push(c);
            }
        }
    }
    out
}

fn bearing_mod_180(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let deg = (b.x - a.x).atan2(b.y - a.y).to_degrees();
    let m = deg.rem_euclid(180.0);
    if m >= 180.0 - 1e-9 { 0.0 } else { m }
}

fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(180.0);
    d.min(180.0 - d)
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// The mission: take-off, speed, then every transit and lane in order, with
/// the camera triggering by distance along each lane, back above home, RTL.
fn build_mission(
    tour: &crate::flock::Tour,
    home: GeoPoint,
    altitude: f64,
    speed_m_s: f64,
    geometry: &SurveyGeometry,
    params: &SurveyParams,
    proj: &crate::geo::UtmProjection,
) -> Result<Mission, GeoError> {
    let wp = |c: Coord<f64>| -> Result<MissionItem, GeoError> {
        let ll = proj.to_wgs84(c)?;
        Ok(MissionItem::Waypoint(GeoPoint {
            lon: ll.x,
            lat: ll.y,
            alt: altitude,
        }))
    };
    let mut items = vec![
        MissionItem::Takeoff { alt: altitude },
        MissionItem::ChangeSpeed { speed_m_s },
    ];
    let transit =
        |items: &mut Vec<MissionItem>, t: &[Coord<f64>], keep_last: bool| -> Result<(), GeoError> {
            // The first point is where we already are; the last is the next lane
            // start, written by the lane itself, except on the way home.
            let end = if keep_last {
                t.len()
            } else {
                t.len().saturating_sub(1)
            };
            for &c in t.iter().take(end).skip(1) {
                items.push(wp(c)?);
            }
            Ok(())
        };
    for (i, visit) in tour.visits.iter().enumerate() {
        transit(&mut items, &tour.transits[i], false)?;
        for (k, lane) in visit.lanes.iter().enumerate() {
            items.push(wp(lane.start)?);
            items.push(MissionItem::CameraTriggerDistance {
                distance_m: geometry.trigger_distance_m,
            });
            items.push(wp(lane.end)?);
            items.push(MissionItem::CameraTriggerDistance { distance_m: 0.0 });
            if let Some(link) = visit.links.get(k) {
                for &c in link {
                    items.push(wp(c)?);
                }
            }
        }
    }
    if let Some(last) = tour.transits.last() {
        transit(&mut items, last, true)?;
    }
    items.push(MissionItem::ReturnToLaunch);
    Ok(Mission {
        home,
        frame: params.altitude_frame,
        cruise_speed_m_s: speed_m_s,
        items,
        over_terrain: false,
    })
}

/// The inclusion fence (convex hull of the ROI and the flown path, grown by
/// at least `margin`) followed by every no-fly zone as an exclusion fence.
fn fences(
    area: &SurveyArea,
    path: &[Coord<f64>],
    margin: f64,
) -> Result<Vec<FencePolygon>, GeoError> {
    let proj = &area.projection;
    let mut pts: Vec<Point<f64>> = area
        .roi
        .0
        .iter()
        .flat_map(|p| p.exterior().0.iter().map(|&c| Point(c)))
        .collect();
    pts.extend(path.iter().map(|&c| Point(c)));
    // Grow the hull by `margin`: a 16-gon circumscribed about a circle of
    // that radius round every hull vertex, hulled again. Its edges touch
    // the circles, so every flown point is at least `margin` inside.
    let hull = MultiPoint(pts).convex_hull();
    let radius = margin / (std::f64::consts::PI / 16.0).cos();
    let mut grown = Vec::new();
    for c in &hull.exterior().0 {
        for k in 0..16 {
            let t = f64::from(k) * std::f64::consts::TAU / 16.0;
            grown.push(Point::new(c.x + radius * t.cos(), c.y + radius * t.sin()));
        }
    }
    let hull = MultiPoint(grown).convex_hull();
    let mut out = vec![FencePolygon {
        inclusion: true,
        vertices: ring_lonlat(&proj.polygon_to_wgs84(&hull)?),
    }];
    for nfz in &area.no_fly_wgs84 {
        out.push(FencePolygon {
            inclusion: false,
            vertices: ring_lonlat(nfz),
        });
    }
    Ok(out)
}

fn ring_lonlat(p: &Polygon<f64>) -> Vec<[f64; 2]> {
    let ring = &p.exterior().0;
    let n = if ring.len() > 1 && ring.first() == ring.last() {
        ring.len() - 1
    } else {
        ring.len()
    };
    ring[..n].iter().map(|c| [c.x, c.y]).collect()
}

impl SurveyPlan {
    /// Names of the plan's files: per sortie `<stem>.waypoints`,
    /// `<stem>.plan`, `<stem>.route.geojson` and `<stem>.kml` (the stem is
    /// the UAV id, or `<id>.sortie<k>` for a UAV flying several sorties);
    /// per UAV `<id>.fence.waypoints`; then `cells.geojson`.
    pub fn file_names(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for u in &self.uavs {
            for s in &u.sorties {
                out.extend(
                    SORTIE_FILE_SUFFIXES
                        .iter()
                        .map(|suffix| format!("{}.{suffix}", s.file_stem)),
                );
            }
            out.push(format!("{}.{FENCE_FILE_SUFFIX}", u.id));
        }
        out.extend(self.rally_file_names());
        out.push(CELLS_FILE.to_string());
        out
    }

    /// Every file of the plan, rendered.
    pub fn files(&self) -> Vec<PlanFile> {
        self.file_names()
            .iter()
            .filter_map(|n| self.file(n))
            .collect()
    }

    /// One file of the plan by name (see [`SurveyPlan::file_names`]),
    /// rendered alone; `None` for an unknown name.
    pub fn file(&self, name: &str) -> Option<PlanFile> {
        let text = "text/plain; charset=utf-8";
        let done = |content_type: &'static str, content: String| {
            Some(PlanFile {
                name: name.to_string(),
                content_type,
                content,
            })
        };
        if name == CELLS_FILE {
            return done("application/geo+json", pretty(&self.cells_geojson()));
        }
        if let Some(rally) = self.rally_file(name) {
            return Some(rally);
        }
        // The fence is the UAV's; it is also served under each sortie's stem.
        let fence = format!(".{FENCE_FILE_SUFFIX}");
        if self.uavs.iter().any(|u| {
            std::iter::once(u.id.as_str())
                .chain(u.sorties.iter().map(|s| s.file_stem.as_str()))
                .any(|stem| name.strip_prefix(stem) == Some(fence.as_str()))
        }) {
            return done(text, export::write_fence(&self.fences));
        }
        let (u, s, suffix) = self.uavs.iter().find_map(|u| {
            u.sorties.iter().find_map(|s| {
                let rest = name.strip_prefix(s.file_stem.as_str())?.strip_prefix('.')?;
                SORTIE_FILE_SUFFIXES.contains(&rest).then_some((u, s, rest))
            })
        })?;
        match suffix {
            "waypoints" => done(text, export::write_waypoints(&s.mission)),
            "plan" => done(
                "application/json",
                pretty(&export::write_plan(
                    &s.mission,
                    &self.fences,
                    &self.rally_for(u),
                )),
            ),
            "route.geojson" => {
                let mut props = Map::new();
                props.insert("uav".into(), json!(u.id));
                props.insert("sortie".into(), json!(s.file_stem));
                props.insert("altitude_frame".into(), json!(self.altitude_frame));
                props.insert("length_m".into(), json!(s.stats.length_m));
                props.insert("flight_time_s".into(), json!(s.stats.flight_time_s));
                let route =
                    json!({"type": "FeatureCollection", "features": [s.route_feature(props)]});
                done("application/geo+json", pretty(&route))
            }
            "kml" => {
                let cell_rings: Vec<(String, Vec<[f64; 2]>)> = self
                    .cells
                    .iter()
                    .filter(|c| s.cells.contains(&c.id))
                    .map(|c| (format!("cell {}", c.id), geojson_exterior(&c.polygon)))
                    .collect();
                let title = if u.sorties.len() > 1 {
                    format!("terraplan survey, UAV {}, {}", u.id, s.file_stem)
                } else {
                    format!("terraplan survey, UAV {}", u.id)
                };
                done(
                    "application/vnd.google-earth.kml+xml",
                    export::write_kml(&title, &s.mission, &cell_rings),
                )
            }
            _ => None,
        }
    }

    /// The cells as a GeoJSON FeatureCollection (WGS84).
    pub fn cells_geojson(&self) -> Value {
        gj::feature_collection(self.cells.iter().map(|c| {
            let mut props = Map::new();
            props.insert("id".into(), json!(c.id));
            props.insert("area_m2".into(), json!(c.area_m2));
            props.insert("lane_bearing_deg".into(), json!(c.lane_bearing_deg));
            props.insert("lanes".into(), json!(c.lanes));
            props.insert("lane_length_m".into(), json!(c.lane_length_m));
            (c.polygon.clone(), props)
        }))
    }
}

/// Suffixes of each sortie's files, after `<stem>.`.
const SORTIE_FILE_SUFFIXES: [&str; 4] = ["waypoints", "plan", "route.geojson", "kml"];
/// Suffix of each UAV's fence file, after `<uav id>.`.
const FENCE_FILE_SUFFIX: &str = "fence.waypoints";
/// Name of the cells file.
const CELLS_FILE: &str = "cells.geojson";

/// The exterior ring of a GeoJSON Polygon geometry as [lon, lat] pairs.
fn geojson_exterior(polygon: &Value) -> Vec<[f64; 2]> {
    polygon["coordinates"][0]
        .as_array()
        .map(|ring| {
            ring.iter()
                .filter_map(|p| Some([p[0].as_f64()?, p[1].as_f64()?]))
                .collect()
        })
        .unwrap_or_default()
}

fn pretty(v: &Value) -> String {
    let mut s = serde_json::to_string_pretty(v).unwrap_or_default();
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::polygon;

    #[test]
    fn plans_stored_before_flocks_still_open() {
        // A UAV as stored by the one-UAV planner (commit 7c9a861).
        let old = json!({
            "id": "uav1", "start": [5.0, 52.0], "cells": [0, 1],
            "stats": {"length_m": 100.0, "length_3d_m": 220.0, "survey_length_m": 80.0,
                      "transit_length_m": 20.0, "turns": 4, "flight_time_s": 30.0,
                      "photos": 7, "cells": 2},
            "mission": {"home": {"lon": 5.0, "lat": 52.0, "alt": 0.0}, "frame": "relative",
                        "cruise_speed_m_s": 8.0, "items": [], "over_terrain": false}
        });
        let uav: UavPlan = serde_json::from_value(old).unwrap();
        assert_eq!(uav.sorties.len(), 1);
        assert_eq!(uav.sorties[0].file_stem, "uav1");
        assert_eq!(uav.sorties[0].cells, vec![0, 1]);
        assert_eq!(uav.speed_m_s, 8.0);
        assert_eq!(uav.stats.sorties, 1);
        // And the current layout reads back as written.
        let again: UavPlan = serde_json::from_value(serde_json::to_value(&uav).unwrap()).unwrap();
        assert_eq!(again, uav);
    }

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

    #[test]
    fn plans_a_square_and_renders_each_file_alone() {
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "no_fly_zones": [{"type": "Polygon", "coordinates": [[[5.001, 52.001], [5.002, 52.001], [5.002, 52.002], [5.001, 52.002]]]}],
            "slice_angle_deg": 0,
            "uavs": [{"id": "a-1", "start": [4.999, 51.999]}],
        });
        let plan = plan_survey(
            &SurveyRequest::from_document(&doc).unwrap(),
            &Limits::default(),
        )
        .unwrap();
        // An NFZ inside a square sliced north-south: left, below, above, right.
        assert_eq!(plan.stats.cell_count, 4);
        assert!(
            plan.stats.coverage_ratio >= 0.995,
            "{}",
            plan.stats.coverage_ratio
        );
        let names = plan.file_names();
        assert_eq!(
            names,
            [
                "a-1.waypoints",
                "a-1.plan",
                "a-1.route.geojson",
                "a-1.kml",
                "a-1.fence.waypoints",
                "cells.geojson"
            ]
        );
        let all = plan.files();
        assert_eq!(all.len(), names.len());
        for f in &all {
            assert_eq!(plan.file(&f.name).as_ref(), Some(f));
        }
        assert!(plan.file("a-1.exe").is_none());
        assert!(plan.file("b.waypoints").is_none());
        assert!(
            plan.file("a-1.waypoints")
                .unwrap()
                .content
                .starts_with("QGC WPL 110\n")
        );
    }

    /// A geographic DEM (EPSG:4326, 0.0001° cells) rising 0.02 m per metre
    /// eastwards, over the square of `plans_a_square…`.
    fn slope_dem() -> crate::terrain::Dem {
        use crate::terrain::{Crs, Dem, DemFormat, GeoTransform};
        let (w, h) = (80usize, 70usize);
        let t = GeoTransform {
            origin_x: 4.997,
            pixel_width: 1e-4,
            row_rotation: 0.0,
            origin_y: 52.005,
            col_rotation: 0.0,
            pixel_height: -1e-4,
        };
        let m_per_deg_lon = 111_320.0 * 52.0f64.to_radians().cos();
        let mut values = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let (lon, _) = t.apply(c as f64 + 0.5, r as f64 + 0.5);
                values.push(100.0 + (lon - 4.997) * m_per_deg_lon * 0.02);
            }
        }
        Dem {
            width: w,
            height: h,
            values,
            nodata: None,
            transform: t,
            crs: Crs {
                epsg: 4326,
                name: "WGS 84".into(),
                geographic: true,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    #[test]
    fn follows_terrain_in_every_altitude_frame() {
        let dem = slope_dem();
        let start = [4.999, 51.999];
        let home_amsl = dem.sample(start[0], start[1]).unwrap();
        let mut route_heights = Vec::new();
        for frame in ["relative", "amsl", "terrain"] {
            let doc = json!({
                "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
                "slice_angle_deg": 0,
                "altitude_m": 50,
                "agl_tolerance_m": 2,
                "transit_clearance_m": 60,
                "altitude_frame": frame,
                "dem_id": "x",
                "uavs": [{"id": "a", "start": start}],
            });
            let req = SurveyRequest::from_document(&doc).unwrap();
            let plan = plan_survey_over(&req, &Limits::default(), Some(&dem)).unwrap();
            let uav = &plan.uavs[0].sorties[0];
            let t = uav.terrain.as_ref().unwrap();
            assert!((uav.mission.home.alt - home_amsl).abs() < 1e-9);
            assert!((t.home_amsl_m - home_amsl).abs() < 1e-9);
            assert!(
                t.min_lane_agl_m.unwrap() >= 48.0 - 1e-6,
                "{:?}",
                t.min_lane_agl_m
            );
            assert!(t.min_transit_clearance_m.unwrap() >= 60.0 - 1e-6);
            let stats = plan.stats.terrain.as_ref().unwrap();
            assert_eq!(stats.dem_known_fraction, 1.0);
            // Every mission waypoint, back in the DEM's datum, is a leg point.
            let leg_z: Vec<f64> = t
                .legs
                .iter()
                .flat_map(|l| l.points.iter().map(|p| p[2]))
                .collect();
            let mut amsl = vec![home_amsl];
            for p in uav.mission.waypoints() {
                let ground = dem.sample(p.lon, p.lat).unwrap();
                let z = match frame {
                    "relative" => p.alt + home_amsl,
                    "amsl" => p.alt,
                    _ => p.alt + ground,
                };
                assert!(leg_z.iter().any(|lz| (lz - z).abs() < 1e-6), "{frame}: {z}");
                amsl.push(z);
                assert!(
                    z - ground >= 48.0 - 1e-6,
                    "{frame}: {} above ground",
                    z - ground
                );
            }
            // The slope makes the 3D length longer than the 2D one.
            assert!(uav.stats.length_3d_m > uav.stats.length_m);
            let wpl = plan.file("a.waypoints").unwrap().content;
            let want = match frame {
                "relative" => "\t3\t16\t",
                "amsl" => "\t0\t16\t",
                _ => "\t10\t16\t",
            };
            assert!(wpl.lines().skip(2).any(|l| l.contains(want)), "{frame}");
            // route.geojson: those heights above mean sea level, home at
            // both ends, plus the EGM96 undulation above the ellipsoid.
            amsl.push(home_amsl);
            let route: Value =
                serde_json::from_str(&plan.file("a.route.geojson").unwrap().content).unwrap();
            let f = &route["features"][0];
            let got: Vec<f64> =
                serde_json::from_value(f["properties"]["heights_amsl_m"].clone()).unwrap();
            assert_eq!(got.len(), amsl.len(), "{frame}");
            assert!(
                got.iter().zip(&amsl).all(|(a, b)| (a - b).abs() < 1e-3),
                "{frame}"
            );
            let h: Vec<f64> = f["geometry"]["coordinates"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c[2].as_f64().unwrap())
                .collect();
            route_heights.push(h);
        }
        // The same flight in every frame: the same GeoJSON heights.
        for h in &route_heights[1..] {
            assert_eq!(h.len(), route_heights[0].len());
            assert!(
                h.iter()
                    .zip(&route_heights[0])
                    .all(|(a, b)| (a - b).abs() < 1e-3)
            );
        }
        // Without the DEM, a dem_id cannot be planned.
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "dem_id": "x",
        });
        let req = SurveyRequest::from_document(&doc).unwrap();
        assert!(
            matches!(plan_survey(&req, &Limits::default()), Err(PlanError::Invalid(i)) if i[0].pointer == DEM_POINTER)
        );
    }

    #[test]
    fn turns_are_heading_changes() {
        let c = |x: f64, y: f64| Coord { x, y };
        // A lawnmower with two lane changes: four 90° turns.
        let path = [
            c(0., 0.),
            c(10., 0.),
            c(10., 1.),
            c(0., 1.),
            c(0., 2.),
            c(10., 2.),
        ];
        assert_eq!(count_turns(&path), 4);
        assert_eq!(count_turns(&[c(0., 0.), c(1., 0.), c(2., 0.01)]), 0);
    }

    #[test]
    fn auto_candidates_include_edge_bearings() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 100.0, y: 100.0), (x: 90.0, y: 110.0), (x: -10.0, y: 10.0)];
        let c = auto_candidates(&MultiPolygon(vec![p]));
        assert!(c.iter().any(|a| angle_gap(*a, 45.0) < 1e-9));
        assert!(c.iter().any(|a| angle_gap(*a, 135.0) < 1e-9));
    }
}
