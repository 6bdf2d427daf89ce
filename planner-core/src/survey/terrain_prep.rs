//! The DEM under one survey: cropped and dilated around it, checked to
//! have heights under the lanes and the starts, and the lane direction of
//! each cell chosen for the shortest 3D flight over it.

use geo::{Area, BoundingRect};
use geo_types::{Coord, MultiPolygon};

use super::cells::Decomposition;
use super::homes::FlockSetup;
use super::request::{DEM_POINTER, Flight, PlanError, SurveyParams, cancelled_or};
use super::terrain_flight::{cell_length_3d, lanes_known_fraction};
use crate::coverage::{self, CellPlan, SurveyGeometry};
use crate::geo::{Issue, SurveyArea};
use crate::terrain::{Dem, TerrainModel, TerrainSampler};

/// The survey over its DEM: the terrain and every start's height.
pub(super) struct OverDem {
    pub terrain: SurveyTerrain,
    /// DEM height under each UAV's start.
    pub homes_amsl: Vec<f64>,
}

/// Prepare the DEM for the survey (see [`prepare_terrain`]) and fly each
/// cell in the direction, among those with the fewest turns, with the
/// shortest 3D length over the terrain. Every start needs a height.
pub(super) fn follow_terrain(
    dem: &Dem,
    area: &SurveyArea,
    free: &MultiPolygon<f64>,
    flock: &FlockSetup,
    params: &SurveyParams,
    flight: &Flight,
    d: &mut Decomposition,
) -> Result<OverDem, PlanError> {
    let homes = &flock.homes;
    // Cheap checks first: every start needs a height (relative
    // altitudes are measured from it), unless the DEM misses the
    // whole area (reported as such below).
    let no_home = |i: usize| {
        let u = &flock.specs[i];
        Issue::new(
            &flock.pointer(i, "start"),
            &format!(
                "the DEM has no height under UAV {}'s start ({:.6}, {:.6}): relative \
                 altitudes are measured from there; start inside the DEM",
                u.id, u.start[0], u.start[1]
            ),
        )
    };
    let sampler = TerrainSampler::new(dem, area.projection.epsg())
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
    let geometry = &flight.geometry;
    let t = prepare_terrain(dem, area, flock, free, geometry, &d.plans, params)
        .map_err(cancelled_or)?;
    // Among the lane directions with the fewest turns, fly the one
    // with the shortest 3D length over the terrain.
    let plans = std::mem::take(&mut d.plans);
    d.plans = plans
        .into_iter()
        .map(|p| {
            let joined = d.joined.get(p.cell_index).copied().unwrap_or(false);
            if d.along_line || d.on_grid || joined || crate::cancel::check().is_err() {
                // A corridor's lanes, a joined cell's (only they cover it
                // whole) or lanes on one grid (cells share their lines);
                // or cancelled, checked again below.
                return p;
            }
            let candidates = coverage::plan_cell_candidates_in(
                p.cell_index,
                &d.cells[p.cell_index],
                &t.free_space,
                geometry.line_spacing_m,
                d.slice_angle_deg,
            )
            .unwrap_or_default();
            if candidates.len() < 2 {
                return p;
            }
            candidates
                .into_iter()
                .map(|c| (cell_length_3d(&t.model, &c, &flight.rules), c))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map_or(p, |(_, c)| c)
        })
        .collect();
    crate::cancel::check()?;
    let homes_amsl: Vec<f64> = (0..homes.len())
        .map(|i| t.model.terrain(homes[i]).ok_or_else(|| no_home(i)))
        .collect::<Result<_, Issue>>()
        .map_err(|i| PlanError::Invalid(vec![i]))?;
    Ok(OverDem {
        terrain: t,
        homes_amsl,
    })
}

impl SurveyTerrain {
    /// The warning of a plan over a DEM that misses part of the area.
    pub(super) fn warning(&self) -> Option<String> {
        (self.known_fraction < 1.0).then(|| {
            format!(
                "the DEM has no heights under {:.1} % of the survey area: flown there at the \
                 highest height nearby",
                (1.0 - self.known_fraction) * 100.0
            )
        })
    }
}

/// The DEM prepared for one survey.
pub(super) struct SurveyTerrain {
    pub model: TerrainModel,
    free_space: coverage::FreeSpace,
    /// Share of the lanes with DEM heights under them.
    pub known_fraction: f64,
}

/// Crop and dilate the DEM around the survey (ROI, no-fly zones — transits
/// go round them — and the start), and check that it has heights under the
/// lanes of `plans`.
fn prepare_terrain(
    dem: &Dem,
    area: &SurveyArea,
    flock: &FlockSetup,
    free: &MultiPolygon<f64>,
    geometry: &SurveyGeometry,
    plans: &[CellPlan],
    params: &SurveyParams,
) -> Result<SurveyTerrain, PlanError> {
    let (homes, flyable) = (&flock.homes, &flock.flyable);
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
