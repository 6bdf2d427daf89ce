//! What a survey plan is: the plan, its UAVs, sorties, cells and
//! statistics, as stored (`plan.json`) and read back, older layouts too.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::terrain_flight::UavTerrain;
use crate::coverage::SurveyGeometry;
use crate::export::{AltitudeFrame, FencePolygon, Mission, geojson as gj};
use crate::flock::{Piece, Policy};

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
    /// The overlaps and GSD its photos achieve on the ground.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photos: Option<super::photo_overlap::CellPhotos>,
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
    /// The photos taken (plans stored before photos were planned have none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photos: Option<super::photos::SortiePhotos>,
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
                photos: None,
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
    /// The DJI aircraft its WPML missions (`.kmz`) are for.
    #[serde(default, skip_serializing_if = "super::dji_files::is_default_dji")]
    pub dji_aircraft: crate::export::wpml::DjiAircraft,
    /// Most Features a `photos.geojson` of the plan holds (every k-th
    /// photo beyond): the planner's [`crate::geo::Limits`], set again by
    /// whoever renders a stored plan; not part of `plan.json`.
    #[serde(skip, default = "super::photos_file::default_max_photo_features")]
    pub max_photo_features: usize,
}

/// A rally point of a planned survey.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RallyPoint {
    pub lon: f64,
    pub lat: f64,
    /// DEM height under the point (above mean sea level), when the survey
    /// was planned over a DEM that covers it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_amsl_m: Option<f64>,
}

/// The survey-wide figures its statistics are made of, besides the sums
/// over the UAVs.
pub(super) struct Figures<'a> {
    pub area_m2: f64,
    pub free_area_m2: f64,
    pub flyable_area_m2: f64,
    pub nfz_clearance_m: f64,
    pub altitude_m: f64,
    pub geometry: &'a SurveyGeometry,
    pub slice_angle_deg: f64,
    pub cell_count: usize,
    pub lane_count: usize,
    pub coverage_ratio: f64,
    pub assignment: Policy,
    pub makespan_lower_bound_s: f64,
    pub terrain: Option<SurveyTerrainStats>,
}

impl SurveyStats {
    /// The statistics of a survey flown by `uavs`.
    pub(super) fn new(f: Figures, uavs: &[UavPlan]) -> SurveyStats {
        let times: Vec<f64> = uavs.iter().map(|u| u.stats.flight_time_s).collect();
        let lengths: Vec<f64> = uavs.iter().map(|u| u.stats.length_3d_m).collect();
        let spread = |v: &[f64]| {
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - v.iter().copied().fold(f64::INFINITY, f64::min)
        };
        let makespan = times.iter().copied().fold(0.0, f64::max);
        let total = |f: fn(&UavStats) -> f64| uavs.iter().map(|u| f(&u.stats)).sum::<f64>();
        SurveyStats {
            area_m2: f.area_m2,
            free_area_m2: f.free_area_m2,
            flyable_area_m2: f.flyable_area_m2,
            nfz_clearance_m: f.nfz_clearance_m,
            altitude_m: f.altitude_m,
            gsd_cm_px: f.geometry.gsd_cm_px,
            footprint_side_m: f.geometry.footprint_side_m,
            footprint_front_m: f.geometry.footprint_front_m,
            line_spacing_m: f.geometry.line_spacing_m,
            trigger_distance_m: f.geometry.trigger_distance_m,
            slice_angle_deg: f.slice_angle_deg,
            cell_count: f.cell_count,
            lane_count: f.lane_count,
            photos: uavs.iter().map(|u| u.stats.photos).sum(),
            length_m: total(|s| s.length_m),
            length_3d_m: total(|s| s.length_3d_m),
            turns: uavs.iter().map(|u| u.stats.turns).sum(),
            flight_time_s: total(|s| s.flight_time_s),
            coverage_ratio: f.coverage_ratio,
            uav_count: uavs.len(),
            assignment: f.assignment,
            makespan_s: makespan,
            makespan_lower_bound_s: f.makespan_lower_bound_s,
            makespan_gap: if f.makespan_lower_bound_s > 0.0 {
                makespan / f.makespan_lower_bound_s - 1.0
            } else {
                0.0
            },
            imbalance_s: spread(&times),
            imbalance_3d_m: spread(&lengths),
            sorties: uavs.iter().map(|u| u.stats.sorties).sum(),
            terrain: f.terrain,
        }
    }
}

impl UavStats {
    /// A UAV's totals over its `sorties`, which fly `cells` (ids, repeats
    /// allowed).
    pub(super) fn total(sorties: &[SortiePlan], cells: &[usize]) -> UavStats {
        let sum = |f: fn(&UavStats) -> f64| sorties.iter().map(|s| f(&s.stats)).sum::<f64>();
        UavStats {
            length_m: sum(|s| s.length_m),
            length_3d_m: sum(|s| s.length_3d_m),
            survey_length_m: sum(|s| s.survey_length_m),
            transit_length_m: sum(|s| s.transit_length_m),
            turns: sorties.iter().map(|s| s.stats.turns).sum(),
            flight_time_s: sum(|s| s.flight_time_s),
            photos: sorties.iter().map(|s| s.stats.photos).sum(),
            cells: {
                let mut c = cells.to_vec();
                c.sort_unstable();
                c.dedup();
                c.len()
            },
            sorties: sorties.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

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
}
