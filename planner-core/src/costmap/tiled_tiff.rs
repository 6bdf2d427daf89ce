//! A tiled run's tiles written as they come ([`TileSink`]): the costmap
//! GeoTIFF (cost and class pages, as [`super::Costmap::write_geotiff`]
//! writes them) and each kept layer's GeoTIFF, all tiled GeoTIFFs whose
//! tiles are the run's tiles, so nothing of the map is held.

use std::io::{self, Write};

use super::Layer;
use super::pipeline::{CLASS_NODATA, class_names};
use super::tiled::{CostmapTile, TileSink};
use crate::terrain::geotiff::{Band, BandData, Page, TiledGeoTiffWriter};
use crate::terrain::{Crs, GeoTransform};

/// The costmap's GeoTIFF and its layers' being written tile by tile.
pub struct TiledTiffFiles<W: Write> {
    costmap: TiledGeoTiffWriter<W>,
    layers: Vec<(Layer, TiledGeoTiffWriter<W>)>,
}

impl<W: Write> TiledTiffFiles<W> {
    /// Starts the costmap's file in `costmap` and one per layer in
    /// `layers` (the layers the run keeps, in [`Layer::ALL`] order), for a
    /// `width`×`height` map in tiles of `tile` cells (a multiple of 16).
    pub fn new(
        costmap: W,
        layers: Vec<(Layer, W)>,
        [width, height]: [usize; 2],
        tile: usize,
        transform: &GeoTransform,
        crs: &Crs,
    ) -> io::Result<TiledTiffFiles<W>> {
        let names = class_names();
        let names: Vec<(&str, &str)> = names.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        let cost = [Band::new("cost", "cost", BandData::F32(&[]))];
        let class = [Band {
            description: "class",
            unit: "",
            metadata: &names,
            data: BandData::U8(&[]),
        }];
        let pages = [
            Page {
                bands: &cost,
                nodata: Some(f64::NAN),
            },
            Page {
                bands: &class,
                nodata: Some(f64::from(CLASS_NODATA)),
            },
        ];
        let costmap =
            TiledGeoTiffWriter::new(costmap, width, height, tile, transform, crs, &pages)?;
        let layers = layers
            .into_iter()
            .map(|(layer, out)| {
                let band = [Band::new(layer.name(), layer.unit(), BandData::F32(&[]))];
                let page = [Page {
                    bands: &band,
                    nodata: Some(f64::NAN),
                }];
                TiledGeoTiffWriter::new(out, width, height, tile, transform, crs, &page)
                    .map(|w| (layer, w))
            })
            .collect::<io::Result<Vec<_>>>()?;
        Ok(TiledTiffFiles { costmap, layers })
    }

    /// Flushes every file once every tile is written.
    pub fn finish(self) -> io::Result<(W, Vec<(Layer, W)>)> {
        let costmap = self.costmap.finish()?;
        let layers = self
            .layers
            .into_iter()
            .map(|(l, w)| w.finish().map(|w| (l, w)))
            .collect::<io::Result<Vec<_>>>()?;
        Ok((costmap, layers))
    }
}

impl<W: Write> TileSink for TiledTiffFiles<W> {
    fn tile(&mut self, t: &CostmapTile<'_>) -> io::Result<()> {
        self.costmap
            .write_tile(&[BandData::F32(t.cost), BandData::U8(t.class)])?;
        for (layer, w) in &mut self.layers {
            let data = t
                .layers
                .iter()
                .find(|(l, _)| l == layer)
                .map(|(_, d)| d.as_slice())
                .ok_or_else(|| {
                    io::Error::new(
                        io::ErrorKind::InvalidInput,
                        format!("the tile has no {} layer", layer.name()),
                    )
                })?;
            w.write_tile(&[BandData::F32(data)])?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{
        CostmapOptions, Progress, Stage, TiledOptions, VehiclePreset, build_costmap,
        build_costmap_tiled,
    };
    use crate::terrain::test_support::{dem, north_up};
    use crate::terrain::{DemLimits, DemWindows, read_geotiff_page_band};

    #[test]
    fn the_tiled_files_read_back_as_the_whole_maps_files() {
        let (w, h) = (53, 41);
        let values = (0..w * h)
            .map(|i| {
                let (c, r) = ((i % w) as f64, (i / w) as f64);
                if (c - 20.0).abs() < 3.0 && (r - 17.0).abs() < 3.0 {
                    f64::NAN
                } else {
                    10.0 + 0.02 * c + if c > 30.0 { 0.4 } else { 0.0 } + 0.01 * (r * 0.7).sin()
                }
            })
            .collect();
        let d = dem(
            w,
            h,
            values,
            north_up(400_000.0, 4_500_000.0, 0.1, 0.1),
            false,
        );
        let v = VehiclePreset::UGo.vehicle();
        let o = CostmapOptions {
            layers: vec![Layer::Slope, Layer::Inflation],
            inflation_sigma_m: Some(0.2),
            ..Default::default()
        };
        let quiet = |_: Stage, _: f64| true;
        let whole = build_costmap(&d, &v, &o, None, &quiet as &dyn Progress).unwrap();
        let mut files = TiledTiffFiles::new(
            Vec::new(),
            vec![(Layer::Slope, Vec::new()), (Layer::Inflation, Vec::new())],
            [whole.width, whole.height],
            16,
            &whole.transform,
            &whole.crs,
        )
        .unwrap();
        let opts = TiledOptions {
            tile: 16,
            scratch_dir: std::env::temp_dir(),
            preview_max_side: 32,
        };
        build_costmap_tiled(
            &DemWindows::new(&d),
            &v,
            &o,
            None,
            &opts,
            &quiet,
            &mut files,
        )
        .unwrap();
        let (tif, layers) = files.finish().unwrap();
        let mut want = std::io::Cursor::new(Vec::new());
        whole.write_geotiff(&mut want).unwrap();
        let want = want.into_inner();
        let limits = DemLimits::default();
        let same = |a: &[u8], b: &[u8], page: usize| {
            let a = read_geotiff_page_band(a, page, 1, None, &limits).unwrap();
            let b = read_geotiff_page_band(b, page, 1, None, &limits).unwrap();
            assert_eq!(
                (a.width, a.height, a.transform),
                (b.width, b.height, b.transform)
            );
            assert_eq!(a.nodata.map(f64::to_bits), b.nodata.map(f64::to_bits));
            assert!(
                a.values
                    .iter()
                    .zip(&b.values)
                    .all(|(x, y)| x.to_bits() == y.to_bits())
            );
        };
        same(&tif, &want, 1);
        same(&tif, &want, 2);
        for (layer, bytes) in &layers {
            let mut one = std::io::Cursor::new(Vec::new());
            assert!(whole.write_layer_geotiff(*layer, &mut one).unwrap());
            same(bytes, &one.into_inner(), 1);
        }
    }
}
