//! How far each costmap cell looks (its *halo*), and the tiles a tiled
//! run cuts the working grid into.
//!
//! A cell's class and costs depend only on cells within a bounded
//! distance, except for the enclosed-pocket fill (global, joined across
//! tiles in [`super::region_join`]). Reading each tile with a halo at
//! least that wide, the stages see around every core cell exactly what
//! they see on the whole grid, so the core comes out the same.
//!
//! Per axis, in working cells (the widest over all rows for a geographic
//! grid, whose cells narrow northwards):
//! - the *surface* (steps, smoothing, normals, ditches):
//!   `max(pca + s, 2·s + 1, 2, ditch)` where `s` = ⌈3σ⌉ is the smoothing
//!   kernel's radius, `pca` the PCA neighbourhood's and `ditch` the
//!   negative-step plane's; `2·s + 1` keeps a clipped window wider than
//!   the kernel (the smoother treats rows narrower than the kernel apart),
//!   2 is the residual step test's reach;
//! - the *inflation*: the reach at which the fall-off is cut to 0
//!   (distance mode: d² / 2σ² > 40, so ⌊√80·σ / cell⌋, plus one), or the
//!   blur kernel's `2·⌈2σ⌉ + 1`. The inflation reads final classes from
//!   the first pass, so it does not add the surface's halo.

use super::params::negative_radius;
use super::{CostmapOptions, InflationMode, MAX_RADIUS_CELLS, ResolvedParams, Vehicle};

/// Halo widths, working cells, per axis [x, y].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Halos {
    /// Around a tile whose surface (steps, normals, classes before the
    /// pocket fill) is computed.
    pub surface: [usize; 2],
    /// Around a tile whose inflation is computed from final classes.
    pub inflation: [usize; 2],
}

/// The halos of a run with these parameters on a grid whose rows have
/// cells `row_size_m` metres and whose centre cell is `centre_m` (what
/// the kernels in cells are derived from, as in the whole-grid run).
pub fn halos(
    params: &ResolvedParams,
    options: &CostmapOptions,
    vehicle: &Vehicle,
    row_size_m: &[[f64; 2]],
    centre_m: [f64; 2],
) -> Halos {
    let [cx, cy] = centre_m;
    let smooth = [
        kernel_radius(params.smoothing_sigma_m / cx, 3.0),
        kernel_radius(params.smoothing_sigma_m / cy, 3.0),
    ];
    let pca = widest_reach(params.pca_radius_m, row_size_m);
    let ditch = options.negative_steps.as_ref().map_or([0, 0], |n| {
        widest_reach(negative_radius(vehicle, n.radius_m), row_size_m)
    });
    let surface = [0, 1].map(|a| {
        (pca[a] + smooth[a])
            .max(2 * smooth[a] + 1)
            .max(2)
            .max(ditch[a])
    });
    let inflation = [cx, cy].map(|cell| match params.inflation {
        InflationMode::Distance => {
            ((80f64.sqrt() * params.inflation_sigma_m / cell).floor() as usize).saturating_add(1)
        }
        InflationMode::Blur => 2 * kernel_radius(params.inflation_sigma_m / cell, 2.0) + 1,
    });
    Halos { surface, inflation }
}

/// The radius in cells of [`super::smooth`]'s kernel for σ in cells cut
/// at `reach`·σ (0 when there is no smoothing).
fn kernel_radius(sigma_cells: f64, reach: f64) -> usize {
    if sigma_cells > 0.0 {
        (reach * sigma_cells).ceil().max(1.0) as usize
    } else {
        0
    }
}

/// The widest reach [columns, rows] of a neighbourhood of `radius_m`
/// over all rows (as [`neighbourhood`] bounds it).
fn widest_reach(radius_m: f64, row_size_m: &[[f64; 2]]) -> [usize; 2] {
    let most = 4.0 * MAX_RADIUS_CELLS;
    let mut reach = [0, 0];
    for &[sx, sy] in row_size_m {
        reach[0] = reach[0].max((radius_m / sx).floor().min(most) as usize);
        reach[1] = reach[1].max((radius_m / sy).floor().min(most) as usize);
    }
    reach
}

/// A grid cut into tiles of `tile` × `tile` cells (the last column and
/// row of tiles narrower), in row-major tile order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileLayout {
    pub width: usize,
    pub height: usize,
    pub tile: usize,
}

/// One tile's core and the window around it, grid cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileWindow {
    /// Tile column and row.
    pub tx: usize,
    pub ty: usize,
    /// The core: top-left cell and size.
    pub col0: usize,
    pub row0: usize,
    pub width: usize,
    pub height: usize,
}

/// A window clipped to the grid: its top-left cell and size, and where
/// the core starts inside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Padded {
    pub col0: usize,
    pub row0: usize,
    pub width: usize,
    pub height: usize,
    /// The core's offset inside the window.
    pub dx: usize,
    pub dy: usize,
}

impl TileLayout {
    pub fn new(width: usize, height: usize, tile: usize) -> TileLayout {
        TileLayout {
            width,
            height,
            tile: tile.max(1),
        }
    }

    /// Tiles across and down.
    pub fn tiles(&self) -> [usize; 2] {
        [
            self.width.div_ceil(self.tile),
            self.height.div_ceil(self.tile),
        ]
    }

    pub fn count(&self) -> usize {
        let [nx, ny] = self.tiles();
        nx * ny
    }

    /// Tile `k` in row-major tile order.
    pub fn tile(&self, k: usize) -> TileWindow {
        let nx = self.tiles()[0];
        let (tx, ty) = (k % nx, k / nx);
        let (col0, row0) = (tx * self.tile, ty * self.tile);
        TileWindow {
            tx,
            ty,
            col0,
            row0,
            width: self.tile.min(self.width - col0),
            height: self.tile.min(self.height - row0),
        }
    }
}

impl TileWindow {
    /// The core grown by `halo` [x, y] cells on every side, clipped to a
    /// `width` × `height` grid.
    pub fn padded(&self, [hx, hy]: [usize; 2], width: usize, height: usize) -> Padded {
        let col0 = self.col0.saturating_sub(hx);
        let row0 = self.row0.saturating_sub(hy);
        let col1 = (self.col0 + self.width).saturating_add(hx).min(width);
        let row1 = (self.row0 + self.height).saturating_add(hy).min(height);
        Padded {
            col0,
            row0,
            width: col1 - col0,
            height: row1 - row0,
            dx: self.col0 - col0,
            dy: self.row0 - row0,
        }
    }
}

/// Copies the `core_w` × `core_h` block at (`dx`, `dy`) of a row-major
/// grid `width` cells wide into `out`.
pub fn crop<T: Copy>(
    grid: &[T],
    width: usize,
    [dx, dy]: [usize; 2],
    [core_w, core_h]: [usize; 2],
    out: &mut Vec<T>,
) {
    out.clear();
    for r in dy..dy + core_h {
        out.extend_from_slice(&grid[r * width + dx..r * width + dx + core_w]);
    }
}

/// The [`super::normals::neighbourhood`] reach, checked against [`widest_reach`] in the
/// tests.
#[cfg(test)]
fn hood_reach(radius_m: f64, sx: f64, sy: f64) -> [usize; 2] {
    let hood = super::normals::neighbourhood(radius_m, sx, sy);
    [
        hood.iter().map(|h| h.0.unsigned_abs()).max().unwrap_or(0),
        hood.iter().map(|h| h.1.unsigned_abs()).max().unwrap_or(0),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{StepMode, VehiclePreset};

    #[test]
    fn the_reach_is_the_neighbourhoods_widest_offset() {
        for (r, sx, sy) in [
            (1.5, 1.0, 1.0),
            (2.3, 0.7, 1.1),
            (0.9, 1.0, 1.0),
            (7.0, 0.5, 2.0),
        ] {
            assert_eq!(
                widest_reach(r, &[[sx, sy]]),
                hood_reach(r, sx, sy),
                "{r} {sx} {sy}"
            );
        }
        // Rows of different sizes: the widest.
        assert_eq!(widest_reach(2.0, &[[1.0, 1.0], [0.5, 1.0]]), [4, 2]);
    }

    #[test]
    fn halos_cover_every_kernel() {
        let v = VehiclePreset::UGo.vehicle();
        let params = ResolvedParams {
            resolution_m: [0.1, 0.1],
            resample_factor: [1, 1],
            smoothing_sigma_m: 0.05,
            pca_radius_m: 0.15,
            step_mode: StepMode::Residual,
            inflation: InflationMode::Distance,
            inflation_sigma_m: 0.5,
            min_region_area_m2: 1.0,
        };
        let rows = vec![[0.1, 0.1]; 10];
        let h = halos(&params, &CostmapOptions::default(), &v, &rows, [0.1, 0.1]);
        // σ 0.5 cells: kernel radius 2; PCA reach 1; 2·2 + 1 = 5.
        assert_eq!(h.surface, [5, 5]);
        // √80 · 5 cells = 44.7.
        assert_eq!(h.inflation, [45, 45]);
        let blur = ResolvedParams {
            inflation: InflationMode::Blur,
            ..params
        };
        let h = halos(&blur, &CostmapOptions::default(), &v, &rows, [0.1, 0.1]);
        assert_eq!(h.inflation, [21, 21]);
    }

    #[test]
    fn tiles_cover_the_grid_once_and_windows_clip() {
        let l = TileLayout::new(10, 7, 4);
        assert_eq!(l.tiles(), [3, 2]);
        let mut seen = vec![0; 70];
        for k in 0..l.count() {
            let t = l.tile(k);
            for r in t.row0..t.row0 + t.height {
                for c in t.col0..t.col0 + t.width {
                    seen[r * 10 + c] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        let t = l.tile(5);
        assert_eq!((t.tx, t.ty, t.width, t.height), (2, 1, 2, 3));
        let p = t.padded([3, 3], 10, 7);
        assert_eq!(
            (p.col0, p.row0, p.width, p.height, p.dx, p.dy),
            (5, 1, 5, 6, 3, 3)
        );
    }
}
