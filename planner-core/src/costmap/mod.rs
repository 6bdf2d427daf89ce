//! Traversability costmaps for a ground vehicle (SPEC §4.2, thesis
//! chapter 3), one stage per file:
//!
//! 1. [`grid`]: the working grid — the DEM, optionally resampled by block
//!    averaging, with each cell's size in metres (geographic DEMs use the
//!    local metres per degree, never degrees);
//! 2. [`smooth`]: light Gaussian smoothing for the normals;
//! 3. [`normals`]: PCA surface normals, Zcomp = |n_z| = cos(slope), and the
//!    plane-fit residual (roughness);
//! 4. [`steps`]: height discontinuities, by the thesis' neighbour test or
//!    (default) against the local surface's continuation;
//! 5. [`regions`]: traversable pockets enclosed by obstacles and smaller
//!    than a minimum area become obstacles;
//! 6. [`inflate`]: obstacle proximity, by a Gaussian of the exact
//!    Euclidean distance ([`distance`], default) or the thesis' blur;
//! 7. [`pipeline`]: the slope cost, the weighted sum and the classes;
//!
//! and [`preview`] (PNG + legend) and [`stats`] for the results.

mod bands;
pub mod class_store;
pub mod distance;
pub mod grid;
pub mod halo;
pub mod inflate;
pub mod landcover;
pub mod normals;
pub mod params;
pub mod pipeline;
pub mod preview;
pub mod preview_tiles;
pub mod progress;
pub mod region_join;
pub mod regions;
pub mod smooth;
pub mod stats;
pub mod steps;
pub mod tile_bytes;
pub mod tile_stages;
pub mod tiled;
pub mod tiled_tiff;
pub mod vehicle;

pub use distance::distance_transform;
pub use halo::{Halos, TileLayout, TileWindow};
pub use pipeline::build_costmap;
pub use preview::{legend_svg, legend_svg_of, preview_png};
pub use preview_tiles::PreviewPart;
pub use progress::{Progress, Stage};
pub use region_join::{JoinError, RegionFill, RegionJoin, TileEdges, TileFill};
pub use stats::TallyPart;
pub use stats::{CostHistogram, CostmapStats};
pub use tile_bytes::PieceError;
pub use tile_stages::{
    ClassTiles, ClassWindows, Classified, CostTile, DEFAULT_PREVIEW_MAX_SIDE, FinishMerge, TilePlan,
};
pub use tiled::{
    CostmapTile, MapHeader, TileSink, TiledCostmap, TiledError, TiledOptions, build_costmap_tiled,
};
pub use tiled_tiff::{CostmapTiffWriter, LayerTiffWriter, TiledTiffFiles};
pub use vehicle::{Vehicle, VehiclePreset, VehicleSpec};

use serde::{Deserialize, Serialize};

use crate::geo::Issue;
use crate::terrain::{Crs, GeoTransform};

/// How height discontinuities are found (SPEC §4.2 step 4).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StepMode {
    /// Each neighbour's height is compared with what the surface on either
    /// side predicts (its linear continuation along the same line), so an
    /// even slope never counts as a step, at any resolution.
    #[default]
    Residual,
    /// The thesis' literal test: any of the 8 neighbours differs by more
    /// than max_step. Every slope steeper than atan(max_step / (cell·√2))
    /// becomes a step obstacle.
    Neighbours,
}

/// How obstacle proximity is spread (SPEC §4.2 step 6).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InflationMode {
    /// exp(−d²/2σ²) of the exact distance d to the nearest obstacle: a
    /// one-cell wall is inflated like a thick one.
    #[default]
    Distance,
    /// The thesis' Gaussian blur of the binary obstacle grid (kernel
    /// (2·⌈2σ⌉+1) cells): thin obstacles come out diluted.
    Blur,
}

/// Per-layer rasters that can be kept with a costmap.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layer {
    /// Slope of the PCA normal, degrees.
    Slope,
    /// |n_z| of the PCA normal, [0, 1].
    Zcomp,
    /// Largest height discontinuity to a neighbour, metres (by `step_mode`).
    Step,
    /// Obstacle proximity before weighting, [0, 1].
    Inflation,
    /// RMS distance of the neighbourhood from its fitted plane, metres.
    Roughness,
    /// Depth below the local fitted plane (ditches), metres.
    NegativeStep,
    /// Land-cover cost of each cell (NaN where lethal or unknown).
    Landcover,
}

impl Layer {
    pub const ALL: [Layer; 7] = [
        Layer::Slope,
        Layer::Zcomp,
        Layer::Step,
        Layer::Inflation,
        Layer::Roughness,
        Layer::NegativeStep,
        Layer::Landcover,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Layer::Slope => "slope",
            Layer::Zcomp => "zcomp",
            Layer::Step => "step",
            Layer::Inflation => "inflation",
            Layer::Roughness => "roughness",
            Layer::NegativeStep => "negative_step",
            Layer::Landcover => "landcover",
        }
    }

    pub fn from_name(name: &str) -> Option<Layer> {
        Layer::ALL.into_iter().find(|l| l.name() == name)
    }

    /// The unit of the layer's values, as written in its GeoTIFF for
    /// GDAL's `GetUnitType()`: `deg`, `m`, `cost` (a cost on the cost
    /// band's scale), or `1` for the dimensionless fractions in [0, 1]
    /// (the CF conventions' unit for a pure number).
    pub fn unit(self) -> &'static str {
        match self {
            Layer::Slope => "deg",
            Layer::Zcomp | Layer::Inflation => "1",
            Layer::Step | Layer::Roughness | Layer::NegativeStep => "m",
            Layer::Landcover => "cost",
        }
    }
}

/// Cell classes of the costmap's class band (page 2 of its GeoTIFF).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Class {
    /// No height, or too near nodata or the border to be judged.
    Unknown = 0,
    Traversable = 1,
    /// Steeper than max_slope.
    Slope = 2,
    /// A step higher than max_step (or, with `negative_steps`, a ditch).
    Step = 3,
    /// A traversable pocket enclosed by obstacles, smaller than the
    /// minimum area.
    Enclosed = 4,
    /// Lethal land cover, or rougher than the roughness limit.
    Other = 5,
}

impl Class {
    pub const ALL: [Class; 6] = [
        Class::Unknown,
        Class::Traversable,
        Class::Slope,
        Class::Step,
        Class::Enclosed,
        Class::Other,
    ];

    pub fn from_code(code: u8) -> Option<Class> {
        Class::ALL.get(usize::from(code)).copied()
    }

    /// The name it has in statistics and in the class band's metadata.
    pub fn name(self) -> &'static str {
        match self {
            Class::Unknown => "unknown",
            Class::Traversable => "traversable",
            Class::Slope => "slope",
            Class::Step => "step",
            Class::Enclosed => "enclosed",
            Class::Other => "other",
        }
    }

    /// An obstacle the vehicle must not enter (not unknown).
    pub fn is_obstacle(self) -> bool {
        matches!(
            self,
            Class::Slope | Class::Step | Class::Enclosed | Class::Other
        )
    }
}

/// Optional roughness layer (seed 000/002: plane-fit residual).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoughnessOptions {
    /// Cells rougher than this (RMS residual, metres) are obstacles
    /// (class 5). (0, 10].
    pub max_m: f64,
    /// Cost added at max_m, growing linearly from 0 on a perfect plane.
    /// [0, 1000], default 5.
    #[serde(default = "default_layer_weight")]
    pub weight: f64,
}

/// Optional negative-obstacle layer (seed 003: ditches and holes).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NegativeStepOptions {
    /// Cells lying deeper than this below the plane fitted to their
    /// surroundings are obstacles (class 3). (0, 100] m; default the
    /// vehicle's max_step.
    pub max_depth_m: Option<f64>,
    /// Radius of the surroundings the plane is fitted to, metres; default
    /// 1.5 × the vehicle's longer side (a ditch narrower than that is
    /// seen). 1 to 25 cells.
    pub radius_m: Option<f64>,
}

/// One land-cover class code and what it costs.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandcoverClass {
    /// The raster value.
    pub code: i64,
    /// Cost added to the cell, [0, 1000]; default 0.
    #[serde(default)]
    pub cost: f64,
    /// The vehicle must not enter (class 5).
    #[serde(default)]
    pub lethal: bool,
    /// A label, for people.
    #[serde(default)]
    pub name: Option<String>,
}

/// Optional land-cover layer: a second raster of class codes (any CRS; it
/// is sampled at each costmap cell's centre, nearest value) and a table.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandcoverOptions {
    /// Where the class raster comes from: an uploaded DEM's id for the
    /// service, a file path for the CLI.
    pub source: String,
    /// 1–256 classes with distinct codes.
    pub classes: Vec<LandcoverClass>,
    /// Cost of codes not in the table; default 0.
    #[serde(default)]
    pub unlisted_cost: f64,
    /// Codes not in the table are lethal.
    #[serde(default)]
    pub unlisted_lethal: bool,
}

fn default_layer_weight() -> f64 {
    5.0
}

/// Every tunable of the pipeline; `None` takes the documented default.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CostmapOptions {
    /// Working resolution, metres: the DEM is resampled to it by averaging
    /// whole blocks of cells (thesis: 0.986 cm → 9.86 cm). Default: the
    /// DEM's own. Must not be finer than the DEM's cells.
    pub resolution_m: Option<f64>,
    /// σ of the Gaussian smoothing before the normals, metres; 0 = none.
    /// Default 0.5 × cell (light: a 5-cell kernel).
    pub smoothing_sigma_m: Option<f64>,
    /// Neighbourhood radius of the PCA normals, metres. Default 1.5 ×
    /// cell (the 3 × 3 neighbours). At most 50 cells.
    pub pca_radius_m: Option<f64>,
    #[serde(default)]
    pub step_mode: StepMode,
    #[serde(default)]
    pub inflation: InflationMode,
    /// σ of the inflation, metres. Default half the vehicle's longer side
    /// (where a vehicle centred that far from an obstacle would touch
    /// it), never less than one cell.
    pub inflation_sigma_m: Option<f64>,
    /// Traversable pockets enclosed by obstacles and smaller than this
    /// (m²) become obstacles. Default 10 × the vehicle's footprint.
    pub min_region_area_m2: Option<f64>,
    pub roughness: Option<RoughnessOptions>,
    pub negative_steps: Option<NegativeStepOptions>,
    pub landcover: Option<LandcoverOptions>,
    /// Per-layer rasters to keep with the result.
    #[serde(default)]
    pub layers: Vec<Layer>,
}

/// Most cells a PCA or negative-step neighbourhood radius may span.
pub const MAX_RADIUS_CELLS: f64 = 50.0;

impl CostmapOptions {
    /// Range checks that need no DEM; pointers under `prefix`.
    pub fn validate(&self, prefix: &str) -> Vec<Issue> {
        let mut issues = Vec::new();
        let range = |field: &str, x: Option<f64>, lo: f64, lo_open: bool, hi: f64| {
            range_issue(prefix, field, x, (lo, lo_open), hi)
        };
        issues.extend(range(
            "resolution_m",
            self.resolution_m,
            0.0,
            true,
            10_000.0,
        ));
        issues.extend(range(
            "smoothing_sigma_m",
            self.smoothing_sigma_m,
            0.0,
            false,
            10_000.0,
        ));
        issues.extend(range(
            "pca_radius_m",
            self.pca_radius_m,
            0.0,
            true,
            100_000.0,
        ));
        issues.extend(range(
            "inflation_sigma_m",
            self.inflation_sigma_m,
            0.0,
            true,
            10_000.0,
        ));
        issues.extend(range(
            "min_region_area_m2",
            self.min_region_area_m2,
            0.0,
            false,
            1e12,
        ));
        if let Some(r) = &self.roughness {
            issues.extend(range("roughness/max_m", Some(r.max_m), 0.0, true, 10.0));
            issues.extend(range(
                "roughness/weight",
                Some(r.weight),
                0.0,
                false,
                1000.0,
            ));
        }
        if let Some(n) = &self.negative_steps {
            issues.extend(range(
                "negative_steps/max_depth_m",
                n.max_depth_m,
                0.0,
                true,
                100.0,
            ));
            issues.extend(range(
                "negative_steps/radius_m",
                n.radius_m,
                0.0,
                true,
                100_000.0,
            ));
        }
        if let Some(l) = &self.landcover {
            landcover_issues(l, prefix, &mut issues);
        }
        self.layer_issues(prefix, &mut issues);
        issues
    }

    /// Layers listed twice, or asked for without the option that makes
    /// them.
    fn layer_issues(&self, prefix: &str, issues: &mut Vec<Issue>) {
        let mut seen = Vec::new();
        for (i, layer) in self.layers.iter().enumerate() {
            if seen.contains(layer) {
                issues.push(Issue::new(
                    &format!("{prefix}/layers/{i}"),
                    &format!("layer {} is listed twice", layer.name()),
                ));
            }
            seen.push(*layer);
            let needs = match layer {
                Layer::Roughness => self.roughness.is_none().then_some("roughness"),
                Layer::NegativeStep => self.negative_steps.is_none().then_some("negative_steps"),
                Layer::Landcover => self.landcover.is_none().then_some("landcover"),
                _ => None,
            };
            if let Some(option) = needs {
                issues.push(Issue::new(
                    &format!("{prefix}/layers/{i}"),
                    &format!("layer {} needs the {option} option", layer.name()),
                ));
            }
        }
    }
}

/// An issue at `{prefix}/{field}` unless `x` (when given) is finite and in
/// the range from `lo` (excluded when `lo_open`) to `hi`.
fn range_issue(
    prefix: &str,
    field: &str,
    x: Option<f64>,
    (lo, lo_open): (f64, bool),
    hi: f64,
) -> Option<Issue> {
    let x = x?;
    let low_ok = if lo_open { x > lo } else { x >= lo };
    (!(x.is_finite() && low_ok && x <= hi)).then(|| {
        let open = if lo_open { "(" } else { "[" };
        Issue::new(
            &format!("{prefix}/{field}"),
            &format!(
                "must be in {open}{lo}, {hi}], got {}",
                crate::num::readable(x)
            ),
        )
    })
}

/// The land-cover options' faults: the class count, each class's cost,
/// codes listed twice, the unlisted cost.
fn landcover_issues(l: &LandcoverOptions, prefix: &str, issues: &mut Vec<Issue>) {
    // Over the cap the classes are not looked at one by one: the
    // duplicate check is quadratic in their count.
    let classes = if l.classes.is_empty() || l.classes.len() > 256 {
        issues.push(Issue::new(
            &format!("{prefix}/landcover/classes"),
            &format!("give 1 to 256 classes, got {}", l.classes.len()),
        ));
        &[][..]
    } else {
        &l.classes[..]
    };
    for (i, c) in classes.iter().enumerate() {
        issues.extend(range_issue(
            prefix,
            &format!("landcover/classes/{i}/cost"),
            Some(c.cost),
            (0.0, false),
            1000.0,
        ));
        if classes[..i].iter().any(|d| d.code == c.code) {
            issues.push(Issue::new(
                &format!("{prefix}/landcover/classes/{i}/code"),
                &format!("code {} is listed twice", c.code),
            ));
        }
    }
    issues.extend(range_issue(
        prefix,
        "landcover/unlisted_cost",
        Some(l.unlisted_cost),
        (0.0, false),
        1000.0,
    ));
}

/// The parameters a costmap was actually built with (defaults filled in).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResolvedParams {
    /// Working cell size [x, y], metres (at the grid's centre for a
    /// geographic DEM).
    pub resolution_m: [f64; 2],
    /// DEM cells averaged into one working cell [x, y].
    pub resample_factor: [usize; 2],
    pub smoothing_sigma_m: f64,
    pub pca_radius_m: f64,
    pub step_mode: StepMode,
    pub inflation: InflationMode,
    pub inflation_sigma_m: f64,
    pub min_region_area_m2: f64,
}

/// A finished costmap, on the working grid.
#[derive(Clone, Debug)]
pub struct Costmap {
    pub width: usize,
    pub height: usize,
    /// Georeferencing in the DEM's CRS (the DEM's own, or the resampled
    /// grid's).
    pub transform: GeoTransform,
    pub crs: Crs,
    pub vehicle: Vehicle,
    pub params: ResolvedParams,
    /// Row-major traversing cost ≥ w_slope > 0 (range [1, 20] with the
    /// defaults); `NaN` on obstacles and unknown cells.
    pub cost: Vec<f32>,
    /// Row-major [`Class`] codes.
    pub class: Vec<u8>,
    /// The per-layer rasters asked for, in [`Layer::ALL`] order.
    pub layers: Vec<(Layer, Vec<f32>)>,
    pub stats: CostmapStats,
    /// What the caller should know (e.g. a DEM too coarse for the vehicle).
    pub warnings: Vec<String>,
}

/// Why a costmap could not be built.
#[derive(Debug, thiserror::Error)]
pub enum CostmapError {
    /// Parameters that do not fit this DEM (or are out of range).
    #[error("invalid costmap parameters")]
    Invalid(Vec<Issue>),
    /// The progress callback asked to stop.
    #[error("cancelled")]
    Cancelled,
}

impl CostmapError {
    pub(crate) fn invalid(pointer: &str, message: String) -> CostmapError {
        CostmapError::Invalid(vec![Issue::new(pointer, &message)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Over 256 land-cover classes is one fault, found without looking
    /// at the classes (their duplicate check is quadratic): 200 000 take
    /// no time.
    #[test]
    fn too_many_landcover_classes_are_one_fault_found_at_once() {
        let class = |code| LandcoverClass {
            code,
            cost: 1.0,
            lethal: false,
            name: None,
        };
        let options = CostmapOptions {
            landcover: Some(LandcoverOptions {
                source: "dem".into(),
                classes: (0..200_000).map(class).collect(),
                unlisted_cost: 0.0,
                unlisted_lethal: false,
            }),
            ..CostmapOptions::default()
        };
        let t = std::time::Instant::now();
        let issues = options.validate("/options");
        assert!(
            t.elapsed() < std::time::Duration::from_secs(1),
            "{:?}",
            t.elapsed()
        );
        assert_eq!(issues.len(), 1, "{issues:?}");
        assert_eq!(issues[0].pointer, "/options/landcover/classes");
        assert!(
            issues[0].message.contains("got 200000"),
            "{}",
            issues[0].message
        );
        // Within the cap each class is still checked.
        let mut options = options;
        let landcover = options.landcover.as_mut().unwrap();
        landcover.classes = vec![class(3), class(3)];
        let issues = options.validate("/options");
        assert_eq!(issues.len(), 1, "{issues:?}");
        assert_eq!(issues[0].pointer, "/options/landcover/classes/1/code");
    }
}
