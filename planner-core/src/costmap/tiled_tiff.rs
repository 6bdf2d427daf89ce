//! A tiled run's tiles written as they come ([`TileSink`]): the costmap
//! GeoTIFF (cost and class pages, as [`super::Costmap::write_geotiff`]
//! writes them) and each kept layer's GeoTIFF, all tiled GeoTIFFs whose
//! tiles are the run's tiles, so nothing of the map is held.

use std::io::{self, Write};

use super::Layer;
use super::pipeline::{CLASS_NODATA, class_names};
use super::tiled::{CostmapTile, MapHeader, TileSink};
use crate::terrain::geotiff::{Band, BandData, Page, TiledGeoTiffWriter};

/// The costmap's GeoTIFF and its layers' being written tile by tile.
pub struct TiledTiffFiles<W: Write> {
    state: State<W>,
}

enum State<W: Write> {
    /// Before [`TileSink::begin`]: where the files go.
    Pending {
        costmap: W,
        layers: Vec<(Layer, W)>,
    },
    Writing {
        costmap: TiledGeoTiffWriter<W>,
        layers: Vec<(Layer, TiledGeoTiffWriter<W>)>,
    },
    Failed,
}

impl<W: Write> TiledTiffFiles<W> {
    /// The costmap's file goes to `costmap`, each layer's to its writer in
    /// `layers` (the run's layers, which it checks). The tile side must be
    /// a multiple of 16.
    pub fn new(costmap: W, layers: Vec<(Layer, W)>) -> TiledTiffFiles<W> {
        TiledTiffFiles {
            state: State::Pending { costmap, layers },
        }
    }

    /// Flushes every file once every tile is written.
    pub fn finish(self) -> io::Result<(W, Vec<(Layer, W)>)> {
        let State::Writing { costmap, layers } = self.state else {
            return Err(io::Error::other("the costmap's files were never begun"));
        };
        let costmap = costmap.finish()?;
        let layers = layers
            .into_iter()
            .map(|(l, w)| w.finish().map(|w| (l, w)))
            .collect::<io::Result<Vec<_>>>()?;
        Ok((costmap, layers))
    }
}

fn start<W: Write>(costmap: W, layers: Vec<(Layer, W)>, map: &MapHeader) -> io::Result<State<W>> {
    let wanted: Vec<Layer> = layers.iter().map(|(l, _)| *l).collect();
    if wanted != map.layers {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "files for the layers {wanted:?}, but the run keeps {:?}",
                map.layers
            ),
        ));
    }
    let (size, tile, t, crs) = ((map.width, map.height), map.tile, &map.transform, &map.crs);
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
    let costmap = TiledGeoTiffWriter::new(costmap, size.0, size.1, tile, t, crs, &pages)?;
    let layers = layers
        .into_iter()
        .map(|(layer, out)| {
            let band = [Band::new(layer.name(), layer.unit(), BandData::F32(&[]))];
            let page = [Page {
                bands: &band,
                nodata: Some(f64::NAN),
            }];
            TiledGeoTiffWriter::new(out, size.0, size.1, tile, t, crs, &page).map(|w| (layer, w))
        })
        .collect::<io::Result<Vec<_>>>()?;
    Ok(State::Writing { costmap, layers })
}

impl<W: Write> TileSink for TiledTiffFiles<W> {
    fn begin(&mut self, map: &MapHeader) -> io::Result<()> {
        match std::mem::replace(&mut self.state, State::Failed) {
            State::Pending { costmap, layers } => {
                self.state = start(costmap, layers, map)?;
                Ok(())
            }
            _ => Err(io::Error::other("the costmap's files were begun already")),
        }
    }

    fn tile(&mut self, t: &CostmapTile<'_>) -> io::Result<()> {
        let State::Writing { costmap, layers } = &mut self.state else {
            return Err(io::Error::other(
                "a tile before the costmap's files were begun",
            ));
        };
        costmap.write_tile(&[BandData::F32(t.cost), BandData::U8(t.class)])?;
        for (layer, w) in layers {
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
        );
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
