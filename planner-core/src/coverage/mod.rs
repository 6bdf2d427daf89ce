//! Coverage stage: camera model (GSD, footprint, spacing) and the
//! back-and-forth (lawnmower) path inside each cell (SPEC §3.1, §3.3).

pub mod airframe;
pub mod arcs;
mod camera;
mod corridor;
mod coverage_ratio;
pub mod dubins;
mod grid;
mod lanes;
mod links;
mod oblique;
mod pattern;
mod region;

pub use camera::{
    Camera, Orientation, PRESETS, SurveyGeometry, altitude_for_gsd, photo_count, survey_geometry,
};
pub use corridor::{
    CorridorCells, CorridorError, MAX_CORRIDOR_LANES, corridor_cells, corridor_lane_lines,
    corridor_polygon, lane_offsets, offset_curve,
};
pub use coverage_ratio::coverage_ratio;
pub use grid::LaneGrid;
pub use lanes::{CellLayouts, is_one_lane, plan_cell, plan_cell_candidates_in, plan_cell_in};
pub use oblique::{
    FAR_EDGE_BELOW_HORIZON_DEG, MIN_PITCH_DEG, NADIR_PITCH_DEG, PitchTooShallow, footprint_corners,
    least_steep_pitch_deg, pitched_geometry,
};
pub use pattern::{Pattern, crosshatch, crosshatch_all};
pub use region::FreeSpace;

use geo_types::Coord;

/// One survey lane, flown from `start` to `end` with the camera triggering.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lane {
    pub start: Coord<f64>,
    pub end: Coord<f64>,
}

/// The lawnmower path of one cell, in flight order (UTM metres).
#[derive(Clone, Debug, PartialEq)]
pub struct CellPlan {
    /// Index of the cell in the decomposition this plan covers.
    pub cell_index: usize,
    /// Bearing of the lanes, degrees clockwise from grid north, in [0, 180).
    pub direction_deg: f64,
    /// Lanes in the order they are flown, each oriented in flight direction.
    pub lanes: Vec<Lane>,
    /// `links[i]` holds the intermediate points flown between `lanes[i].end`
    /// and `lanes[i + 1].start`; empty when the straight link stays in free
    /// space. Always `lanes.len() - 1` entries (0 for an empty plan).
    pub links: Vec<Vec<Coord<f64>>>,
}

impl CellPlan {
    /// First point flown in the cell.
    pub fn entry(&self) -> Option<Coord<f64>> {
        self.lanes.first().map(|l| l.start)
    }

    /// Last point flown in the cell.
    pub fn exit(&self) -> Option<Coord<f64>> {
        self.lanes.last().map(|l| l.end)
    }

    /// The whole flown polyline: lanes joined by their links.
    pub fn path(&self) -> Vec<Coord<f64>> {
        let mut out = Vec::with_capacity(self.lanes.len() * 2);
        for (i, lane) in self.lanes.iter().enumerate() {
            out.push(lane.start);
            out.push(lane.end);
            if let Some(link) = self.links.get(i) {
                out.extend_from_slice(link);
            }
        }
        out
    }

    /// Horizontal length of [`CellPlan::path`] in metres.
    pub fn length_m(&self) -> f64 {
        self.path()
            .windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum()
    }

    /// The same path flown exactly backwards.
    pub fn reversed(&self) -> CellPlan {
        let mut out = self.clone();
        out.lanes.reverse();
        for lane in &mut out.lanes {
            std::mem::swap(&mut lane.start, &mut lane.end);
        }
        out.links.reverse();
        for link in &mut out.links {
            link.reverse();
        }
        out
    }

    /// The lanes flown as one, as index ranges: consecutive lanes that
    /// join end to start with no link points between (a corridor's lane
    /// following its bends). In an area's plan every lane is a run.
    pub fn runs(&self) -> Vec<std::ops::Range<usize>> {
        let mut out = Vec::new();
        let mut start = 0;
        for i in 0..self.lanes.len() {
            let joined = self.lanes.get(i + 1).is_some_and(|next| {
                self.lanes[i].end == next.start && self.links.get(i).is_none_or(Vec::is_empty)
            });
            if !joined {
                out.push(start..i + 1);
                start = i + 1;
            }
        }
        out
    }

    /// Turns flown inside the cell: every change from one lane to the next is
    /// two 90° turns (the usual count for a lawnmower pattern).
    pub fn turns(&self) -> usize {
        2 * self.lanes.len().saturating_sub(1)
    }
}
