//! A tiled run's tiles written as they come ([`TileSink`]): the costmap
//! GeoTIFF (cost and class pages, as [`super::Costmap::write_geotiff`]
//! writes them) and each kept layer's GeoTIFF, all tiled GeoTIFFs whose
//! tiles are the run's tiles, so nothing of the map is held.
//!
//! The writers need only [`Write`], never `Seek`: a tiled GeoTIFF's
//! header and directories (with every tile's offset) are written first,
//! then the tiles strictly in row-major tile order. [`TiledTiffFiles`]
//! writes every file at once from a run's tiles; [`CostmapTiffWriter`]
//! and [`LayerTiffWriter`] write one file each (e.g. from stored tiles,
//! one file after another).

use std::io::{self, Write};

use super::Layer;
use super::pipeline::{CLASS_NODATA, class_names};
use super::tiled::{CostmapTile, MapHeader, TileSink};
use crate::terrain::geotiff::{Band, BandData, Page, TiledGeoTiffWriter};

/// costmap.tif (page 1 the cost, page 2 the class) written tile by tile.
pub struct CostmapTiffWriter<W: Write> {
    out: TiledGeoTiffWriter<W>,
}

impl<W: Write> CostmapTiffWriter<W> {
    /// Writes the header of the map's costmap GeoTIFF to `out` (at the
    /// start of the file). The tile side must be a multiple of 16.
    pub fn new(out: W, map: &MapHeader) -> io::Result<CostmapTiffWriter<W>> {
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
        let out = TiledGeoTiffWriter::new(
            out,
            map.width,
            map.height,
            map.tile,
            &map.transform,
            &map.crs,
            &pages,
        )?;
        Ok(CostmapTiffWriter { out })
    }

    /// Writes the next tile (row-major tile order): its costs and classes,
    /// row-major, the tile's own width.
    pub fn write_tile(&mut self, cost: &[f32], class: &[u8]) -> io::Result<()> {
        self.out
            .write_tile(&[BandData::F32(cost), BandData::U8(class)])
    }

    /// The writer, once every tile is written (flush it).
    pub fn finish(self) -> io::Result<W> {
        self.out.finish()
    }
}

/// One layer's GeoTIFF written tile by tile.
pub struct LayerTiffWriter<W: Write> {
    layer: Layer,
    out: TiledGeoTiffWriter<W>,
}

impl<W: Write> LayerTiffWriter<W> {
    /// Writes the header of the map's `layer` GeoTIFF to `out`.
    pub fn new(out: W, map: &MapHeader, layer: Layer) -> io::Result<LayerTiffWriter<W>> {
        let band = [Band::new(layer.name(), layer.unit(), BandData::F32(&[]))];
        let page = [Page {
            bands: &band,
            nodata: Some(f64::NAN),
        }];
        let out = TiledGeoTiffWriter::new(
            out,
            map.width,
            map.height,
            map.tile,
            &map.transform,
            &map.crs,
            &page,
        )?;
        Ok(LayerTiffWriter { layer, out })
    }

    pub fn layer(&self) -> Layer {
        self.layer
    }

    /// Writes the next tile's values (row-major tile order).
    pub fn write_tile(&mut self, values: &[f32]) -> io::Result<()> {
        self.out.write_tile(&[BandData::F32(values)])
    }

    pub fn finish(self) -> io::Result<W> {
        self.out.finish()
    }
}

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
        costmap: CostmapTiffWriter<W>,
        layers: Vec<LayerTiffWriter<W>>,
    },
    Failed,
}

impl<W: Write> TiledTiffFiles<W> {
    /// The costmap's file goes to `costmap`, each layer's to its writer in
    /// `layers` (the run's layers, in [`Layer::ALL`] order, which it
    /// checks). The tile side must be a multiple of 16.
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
            .map(|w| {
                let layer = w.layer();
                w.finish().map(|w| (layer, w))
            })
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
    let costmap = CostmapTiffWriter::new(costmap, map)?;
    let layers = layers
        .into_iter()
        .map(|(layer, out)| LayerTiffWriter::new(out, map, layer))
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
        costmap.write_tile(t.cost, t.class)?;
        for w in layers {
            let layer = w.layer();
            let data = t
                .layers
                .iter()
                .find(|(l, _)| *l == layer)
                .map(|(_, d)| d.as_slice())
                .ok_or_else(|| {
                    io::Error::new(
                        io::ErrorKind::InvalidInput,
                        format!("the tile has no {} layer", layer.name()),
                    )
                })?;
            w.write_tile(data)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::tile_stages::{ClassTiles, TilePlan};
    use crate::costmap::{
        CostmapOptions, Progress, Stage, TiledOptions, VehiclePreset, build_costmap,
        build_costmap_tiled,
    };
    use crate::terrain::test_support::{dem, north_up};
    use crate::terrain::{DemLimits, DemWindows, RasterWindows, read_geotiff_page_band};
    use std::sync::atomic::AtomicBool;

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

        // The same files one at a time from the stages' tiles, into a
        // writer that cannot seek: the same bytes.
        struct Forward(Vec<u8>);
        impl Write for Forward {
            fn write(&mut self, b: &[u8]) -> io::Result<usize> {
                self.0.extend_from_slice(b);
                Ok(b.len())
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let src = DemWindows::new(&d);
        let plan = TilePlan::new(src.grid(), &v, &o, None, 16).unwrap();
        let cancel = AtomicBool::new(false);
        let n = plan.tile_count();
        let classified: Vec<_> = (0..n)
            .map(|k| plan.classify(&src, None, k, &cancel).unwrap())
            .collect();
        let fill = plan
            .join(
                classified
                    .iter()
                    .enumerate()
                    .map(|(k, c)| (k, c.edges.clone())),
            )
            .unwrap();
        let prefill = ClassTiles::new(plan.layout(), |k| Ok(classified[k].core.as_slice()));
        let finals: Vec<Vec<u8>> = (0..n)
            .map(|k| plan.fill(k, &prefill, fill.tile(k).unwrap()).unwrap())
            .collect();
        let classes = ClassTiles::new(plan.layout(), |k| Ok(finals[k].as_slice()));
        let tiles: Vec<_> = (0..n)
            .map(|k| plan.cost(&src, None, &classes, k, &cancel).unwrap())
            .collect();
        let header = plan.header();
        let mut c = CostmapTiffWriter::new(Forward(Vec::new()), &header).unwrap();
        for t in &tiles {
            c.write_tile(&t.cost, &t.class).unwrap();
        }
        assert!(c.finish().unwrap().0 == tif);
        for (i, (layer, bytes)) in layers.iter().enumerate() {
            let mut l = LayerTiffWriter::new(Forward(Vec::new()), &header, *layer).unwrap();
            for t in &tiles {
                assert_eq!(t.layers[i].0, *layer);
                l.write_tile(&t.layers[i].1).unwrap();
            }
            assert_eq!(&l.finish().unwrap().0, bytes, "{layer:?}");
        }
        // A tile too many is refused.
        let mut c = CostmapTiffWriter::new(Forward(Vec::new()), &header).unwrap();
        for t in tiles.iter().chain(&tiles[..1]).take(n) {
            c.write_tile(&t.cost, &t.class).unwrap();
        }
        assert!(c.write_tile(&tiles[0].cost, &tiles[0].class).is_err());
    }
}
