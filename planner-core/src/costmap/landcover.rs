//! Optional land-cover layer (SPEC §4.2 optional layers): a raster of
//! class codes in any CRS, read like a DEM, sampled at each costmap cell's
//! centre (nearest cell: codes are labels, not quantities), and a table
//! of what each code costs or whether it is lethal.

use geo_types::Coord;
use rayon::prelude::*;

use super::{CostmapError, LandcoverOptions};
use crate::terrain::{Dem, GeoTransform, TerrainSampler};

/// Land-cover cost of every cell of a `width`×`height` grid with
/// `transform` in `EPSG:grid_epsg`: the table's cost, `+∞` where lethal,
/// `NaN` where the raster has no value (outside it or nodata).
pub fn landcover_costs(
    raster: &Dem,
    table: &LandcoverOptions,
    width: usize,
    height: usize,
    transform: &GeoTransform,
    grid_epsg: u32,
) -> Result<Vec<f32>, CostmapError> {
    landcover_costs_window(raster, table, [0, 0], width, height, transform, grid_epsg)
}

/// [`landcover_costs`] of the `width`×`height` window whose top-left cell
/// is `[col0, row0]` of the grid georeferenced by `transform`: cell
/// centres are computed from the grid's own transform, so a window gives
/// the same bits as the whole grid there.
pub fn landcover_costs_window(
    raster: &Dem,
    table: &LandcoverOptions,
    [col0, row0]: [usize; 2],
    width: usize,
    height: usize,
    transform: &GeoTransform,
    grid_epsg: u32,
) -> Result<Vec<f32>, CostmapError> {
    // Fail early, with the reason, if the CRSs cannot be related.
    TerrainSampler::new(raster, grid_epsg).map_err(|e| {
        CostmapError::invalid(
            "/options/landcover/source",
            format!("land-cover raster: {e}"),
        )
    })?;
    let cost_of = |code: f64| -> f32 {
        let listed = table
            .classes
            .iter()
            .find(|c| code.fract() == 0.0 && c.code as f64 == code);
        match listed {
            Some(c) if c.lethal => f32::INFINITY,
            Some(c) => c.cost as f32,
            None if table.unlisted_lethal => f32::INFINITY,
            None => table.unlisted_cost as f32,
        }
    };
    let mut out = vec![f32::NAN; width * height];
    out.par_chunks_mut(width.max(1)).enumerate().for_each_init(
        // PROJ objects are per thread; the CRS pair was checked above.
        || TerrainSampler::new(raster, grid_epsg).ok(),
        |sampler, (r, row)| {
            let Some(sampler) = sampler.as_ref() else {
                return;
            };
            for (c, o) in row.iter_mut().enumerate() {
                let (x, y) = transform.apply((col0 + c) as f64 + 0.5, (row0 + r) as f64 + 0.5);
                let Some((lx, ly)) = sampler.to_dem(Coord { x, y }) else {
                    continue;
                };
                let Some((col, line)) = raster.transform.invert(lx, ly) else {
                    continue;
                };
                if col < 0.0 || line < 0.0 {
                    continue;
                }
                if let Some(code) = raster.value(col as usize, line as usize) {
                    *o = cost_of(code);
                }
            }
        },
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::LandcoverClass;
    use crate::terrain::test_support::{dem, north_up};

    #[test]
    fn codes_are_looked_up_at_cell_centres() {
        // A 2×2 class raster of 10 m cells under a 4×4 grid of 5 m cells.
        let raster = dem(
            2,
            2,
            vec![1.0, 2.0, 3.0, f64::NAN],
            north_up(1000.0, 2000.0, 10.0, 10.0),
            false,
        );
        let table = LandcoverOptions {
            source: "x".into(),
            classes: vec![
                LandcoverClass {
                    code: 1,
                    cost: 0.0,
                    lethal: false,
                    name: None,
                },
                LandcoverClass {
                    code: 2,
                    cost: 3.5,
                    lethal: false,
                    name: None,
                },
                LandcoverClass {
                    code: 3,
                    cost: 0.0,
                    lethal: true,
                    name: None,
                },
            ],
            unlisted_cost: 0.0,
            unlisted_lethal: false,
        };
        let t = north_up(1000.0, 2000.0, 5.0, 5.0);
        let v = landcover_costs(&raster, &table, 4, 4, &t, 32633).unwrap();
        assert_eq!(&v[0..4], &[0.0, 0.0, 3.5, 3.5]);
        assert_eq!(v[8], f32::INFINITY);
        assert!(v[15].is_nan());
    }
}
