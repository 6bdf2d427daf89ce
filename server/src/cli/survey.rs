//! `terraplan survey`: a photo survey planned from files, written as the
//! service serves it.

use std::path::{Path, PathBuf};

use planner_core::cancel::{CancelToken, Cancelled};
use planner_core::geo::{Issue, Limits};
use planner_core::survey::{
    CORRIDOR_POINTER, DEM_POINTER, NO_FLY_POINTER, PlanError, ROI_POINTER, content_type_of,
    plan_survey_over,
};
use planner_core::terrain::DemLimits;
use serde_json::{Value, json};

use super::common::{Failure, list_issues, read_dem_file, read_json};
use crate::imports::Role;

#[derive(clap::Args)]
pub(super) struct SurveyArgs {
    /// Region of interest: a GeoJSON Polygon, MultiPolygon, Feature or FeatureCollection (WGS84,
    /// or the CRS its `crs` member names), a zipped Shapefile (.zip), .shp, .gpkg, .kml, .kmz or
    /// .gpx.
    #[arg(long, value_name = "FILE", required_unless_present = "corridor")]
    roi: Option<PathBuf>,
    /// A corridor instead of an area: its centre line, a GeoJSON LineString
    /// (WGS84), or one line in a .zip/.shp/.gpkg/.kml/.kmz/.gpx (a GPX track or
    /// route); the width is the params' `corridor_width_m`.
    #[arg(long, value_name = "LINE.geojson", conflicts_with = "roi")]
    corridor: Option<PathBuf>,
    /// No-fly zones (GeoJSON, .zip/.shp Shapefile, .gpkg, .kml, .kmz); may be
    /// given several times.
    #[arg(long = "no-fly", value_name = "FILE")]
    no_fly: Vec<PathBuf>,
    /// Survey parameters as JSON (same fields as the API request).
    #[arg(long, value_name = "FILE.json")]
    params: Option<PathBuf>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Largest ROI accepted, km².
    #[arg(long, default_value_t = Limits::default().max_roi_area_km2)]
    max_roi_area_km2: f64,
    /// Most Features one `<uav>.photos.geojson` holds; beyond it every
    /// k-th photo is written and the file's properties say so.
    #[arg(long, value_name = "N", default_value_t = Limits::default().max_photo_features, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    max_photo_features: usize,
    /// A DEM (GeoTIFF, ESRI ASCII grid, SRTM .hgt) to follow the terrain
    /// over (the params' `agl_tolerance_m`, `transit_clearance_m`, … apply).
    #[arg(long, value_name = "FILE")]
    dem: Option<PathBuf>,
    /// Horizontal CRS of the DEM (`EPSG:32633`), when the file does not say.
    #[arg(long, value_name = "EPSG:CODE", requires = "dem")]
    dem_crs: Option<String>,
    /// Stop planning after this many seconds (fractions allowed) and exit
    /// 1; no limit by default.
    #[arg(long, value_name = "SECONDS", value_parser = crate::config::parse_planning_timeout)]
    timeout_s: Option<f64>,
}

pub(super) fn survey(args: &SurveyArgs) -> Result<(), Failure> {
    // Assemble the same request document the API takes, so both share one
    // parser and one set of JSON pointers.
    let mut doc = match &args.params {
        Some(p) => read_json(p, "params")?,
        None => json!({}),
    };
    let Some(obj) = doc.as_object_mut() else {
        return Err(Failure::input("the params file must hold a JSON object"));
    };
    for key in ["roi", "no_fly_zones", "corridor"] {
        if obj.contains_key(key) {
            return Err(Failure::input(format!(
                "the params file may not contain {key:?}: give areas with --roi (or --corridor) \
                 and --no-fly"
            )));
        }
    }
    match (&args.roi, &args.corridor) {
        (Some(roi), _) => obj.insert("roi".into(), read_geometry(roi, "ROI", Role::Area)?),
        (None, Some(line)) => obj.insert(
            "corridor".into(),
            read_geometry(line, "corridor", Role::Line)?,
        ),
        (None, None) => return Err(Failure::input("give --roi FILE or --corridor LINE.geojson")),
    };
    let zones = args
        .no_fly
        .iter()
        .map(|p| read_geometry(p, "no-fly", Role::Area))
        .collect::<Result<Vec<_>, _>>()?;
    obj.insert("no_fly_zones".into(), Value::Array(zones));
    if obj.contains_key("dem_id") {
        return Err(Failure::input(
            "the params file may not contain \"dem_id\" (a DEM stored in the service): give the \
             DEM file with --dem",
        ));
    }
    let dem = match &args.dem {
        None => None,
        Some(path) => Some(
            read_dem_file(
                path,
                args.dem_crs.as_deref(),
                "--dem-crs",
                DemLimits::default(),
            )?
            .0,
        ),
    };

    let limits = Limits {
        max_roi_area_km2: args.max_roi_area_km2,
        max_photo_features: args.max_photo_features,
        ..Limits::default()
    };
    let describe = |issues: &[Issue]| describe_issues(issues, args);
    // The service's reader, so faults read as they do over HTTP; it finds
    // no dem_id (refused above).
    let (req, _) =
        crate::api::surveys::read_document(&mut doc).map_err(|e| plan_failure(e, &describe))?;
    let token = match args.timeout_s {
        Some(s) => CancelToken::with_limit(std::time::Duration::from_secs_f64(s)),
        None => CancelToken::new(),
    };
    let plan = token
        .settle(token.scope(|| plan_survey_over(&req, &limits, dem.as_ref())))
        .map_err(|e| plan_failure(e, &describe))?;

    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", args.out.display())))?;
    // plan.json is written straight from the plan (a `serde_json::Value`
    // copies tens of megabytes among thousands of NFZs), compact (indented,
    // its coordinates took 2.5 times the bytes and half the writing time),
    // on its own thread while the other files render: it lists them by name
    // alone.
    #[derive(serde::Serialize)]
    struct FileRef {
        name: String,
        content_type: &'static str,
    }
    #[derive(serde::Serialize)]
    struct PlanDocument<'a> {
        #[serde(flatten)]
        plan: &'a planner_core::survey::SurveyPlan,
        files: Vec<FileRef>,
    }
    let doc = PlanDocument {
        plan: &plan,
        files: plan
            .file_names()
            .into_iter()
            .map(|name| FileRef {
                content_type: content_type_of(&name),
                name,
            })
            .collect(),
    };
    let write = |name: &str, content: &[u8]| {
        let path = args.out.join(name);
        std::fs::write(&path, content)
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    let (files, plan_json) = std::thread::scope(|scope| {
        let plan_json = scope.spawn(|| -> Result<(), Failure> {
            let mut text =
                serde_json::to_string(&doc).map_err(|e| Failure::other(e.to_string()))?;
            text.push('\n');
            write("plan.json", text.as_bytes())
        });
        let written = plan.each_file(|f| write(&f.name, &f.content));
        let plan_json = plan_json
            .join()
            .unwrap_or_else(|_| Err(Failure::other("plan.json could not be written")));
        (written, plan_json)
    });
    files?;
    plan_json?;
    let s = &plan.stats;
    println!(
        "planned {} cells, {} lanes, {} UAV(s) ({} sorties, {}), {:.0} m, {} photos, makespan {:.0} \
         s, coverage {:.2} % -> {}",
        s.cell_count,
        s.lane_count,
        s.uav_count,
        s.sorties,
        s.assignment.name(),
        s.length_m,
        s.photos,
        s.makespan_s,
        s.coverage_ratio * 100.0,
        args.out.display()
    );
    for w in &plan.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// The GeoJSON in the file at `path`: a WGS84 GeoJSON file as it is; a
/// Shapefile, KML, KMZ, GPX or GeoJSON naming another CRS imported in WGS84
/// (with a warning for each feature skipped).
fn read_geometry(path: &Path, what: &str, role: Role) -> Result<Value, Failure> {
    if !crate::imports::is_gis_file(path) {
        let doc = read_json(path, what)?;
        if planner_core::import::named_crs(&doc).is_none() {
            return Ok(doc);
        }
    }
    let (doc, messages) = crate::imports::read_geometry_file(path, role)
        .map_err(|m| Failure::input(format!("{what} file {}: {m}", path.display())))?;
    for m in messages {
        eprintln!("warning: {}: {m}", path.display());
    }
    Ok(doc)
}

fn plan_failure(e: PlanError, describe: &dyn Fn(&[Issue]) -> String) -> Failure {
    match e {
        PlanError::Invalid(issues) => Failure::input(describe(&issues)),
        PlanError::Internal(m) => Failure::other(format!("planning failed: {m}")),
        PlanError::Cancelled(Cancelled::TimedOut { limit }) => Failure::other(format!(
            "the survey took longer than {} s (--timeout-s) and was stopped: survey a smaller \
             area, with fewer vertices or no-fly zones or a wider line spacing, or allow more time",
            limit.as_secs_f64()
        )),
        PlanError::Cancelled(c) => Failure::other(format!("planning stopped: {c}")),
    }
}

/// Issues with their pointers translated to the file they came from, e.g.
/// `field.geojson#/coordinates/0: ring self-intersects …`.
fn describe_issues(issues: &[Issue], args: &SurveyArgs) -> String {
    let locate = |ptr: &str| -> String {
        if let (Some(rest), Some(roi)) = (ptr.strip_prefix(ROI_POINTER), &args.roi) {
            return format!("{}#{rest}", roi.display());
        }
        let in_corridor = ptr
            .strip_prefix(CORRIDOR_POINTER)
            .filter(|r| r.is_empty() || r.starts_with('/'));
        if let (Some(rest), Some(line)) = (in_corridor, &args.corridor) {
            return format!("{}#{rest}", line.display());
        }
        if let Some(rest) = ptr.strip_prefix(NO_FLY_POINTER) {
            let rest = rest.trim_start_matches('/');
            let (idx, tail) = rest.split_once('/').unwrap_or((rest, ""));
            if let Some(p) = idx.parse::<usize>().ok().and_then(|i| args.no_fly.get(i)) {
                let tail = if tail.is_empty() {
                    String::new()
                } else {
                    format!("/{tail}")
                };
                return format!("{}#{tail}", p.display());
            }
            return "no-fly zones".to_string();
        }
        if ptr == DEM_POINTER
            && let Some(dem) = &args.dem
        {
            return format!("DEM {}", dem.display());
        }
        let file = args
            .params
            .as_ref()
            .map_or("params".to_string(), |p| p.display().to_string());
        format!("{file}#{ptr}")
    };
    list_issues(issues, locate)
}
