//! The finish stage of a tiled costmap: the tiles' statistics and
//! previews merged in tile order, the legend and the result document (the
//! same [`CostmapResult`] as a whole build's), and `costmap.tif` and
//! `layers/<name>.tif` written as tiled GeoTIFFs from the stored tiles,
//! one tile at a time, straight into the chunked file tables: never the
//! whole raster in memory. The files are written under names of this run
//! ([`partial_file_name`]) and take their own names in the transaction
//! that sets the costmap done.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use planner_core::costmap::{
    CostmapTile, Layer, PreviewPart, TallyPart, TileSink, TiledError, TiledTiffFiles,
};

use super::codec::{decode_classes, decode_values};
use super::context::CostmapContext;
use super::stages::{PAGE, StageError, blocking, layer_kind};
use crate::clock::now_millis;
use crate::db::{CHUNK_BYTES, CostmapFileRow, Db, TileJob, WrittenFile, partial_file_name};
use crate::jobs::record::{COSTMAP_TIF, CostmapResult, LEGEND_SVG, PREVIEW_PNG, layer_file};

/// A stored file being written a chunk at a time, from a blocking thread.
struct ChunkWriter {
    db: Db,
    runtime: tokio::runtime::Handle,
    costmap_id: String,
    partial: String,
    name: String,
    seq: i64,
    size: i64,
    buf: Vec<u8>,
}

impl ChunkWriter {
    fn new(
        db: &Db,
        runtime: &tokio::runtime::Handle,
        job: &TileJob,
        owner: &str,
        name: String,
    ) -> std::io::Result<ChunkWriter> {
        let id = &job.key.costmap_id;
        let partial = partial_file_name(owner, job.attempts, &name);
        runtime
            .block_on(db.start_costmap_file(id, &partial, "image/tiff"))
            .map_err(std::io::Error::other)?;
        Ok(ChunkWriter {
            db: db.clone(),
            runtime: runtime.clone(),
            costmap_id: id.clone(),
            partial,
            name,
            seq: 0,
            size: 0,
            buf: Vec::with_capacity(CHUNK_BYTES),
        })
    }

    fn store(&mut self) -> std::io::Result<()> {
        if self.buf.is_empty() {
            return Ok(());
        }
        self.runtime
            .block_on(self.db.add_costmap_file_chunk(
                &self.costmap_id,
                &self.partial,
                self.seq,
                &self.buf,
            ))
            .map_err(std::io::Error::other)?;
        self.seq += 1;
        self.size += self.buf.len() as i64;
        self.buf.clear();
        Ok(())
    }

    /// The last chunk stored: the file as written.
    fn close(mut self) -> std::io::Result<WrittenFile> {
        self.store()?;
        Ok(WrittenFile {
            partial: self.partial,
            name: self.name,
            size_bytes: self.size,
        })
    }
}

impl Write for ChunkWriter {
    fn write(&mut self, data: &[u8]) -> std::io::Result<usize> {
        let n = data.len().min(CHUNK_BYTES - self.buf.len());
        self.buf.extend_from_slice(&data[..n]);
        if self.buf.len() == CHUNK_BYTES {
            self.store()?;
        }
        Ok(n)
    }

    /// Chunks are stored whole (all but the last of [`CHUNK_BYTES`]):
    /// the last is stored by [`ChunkWriter::close`].
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Everything the finish stores.
pub struct Finished {
    pub result: String,
    pub written: Vec<WrittenFile>,
    pub small: Vec<CostmapFileRow>,
}

fn fault(what: &str) -> impl Fn(sqlx::Error) -> StageError + '_ {
    move |e| StageError::Fault(format!("{what}: {e}"))
}

/// Run the finish of job `job` (held by `owner`): its files written, the
/// rest returned to be stored with the costmap's status done.
pub async fn finish(
    db: &Db,
    ctx: &Arc<CostmapContext>,
    job: &TileJob,
    owner: &str,
    cancel: &Arc<AtomicBool>,
) -> Result<Finished, StageError> {
    let (db, ctx, job, owner, cancel) = (
        db.clone(),
        ctx.clone(),
        job.clone(),
        owner.to_string(),
        cancel.clone(),
    );
    let runtime = tokio::runtime::Handle::current();
    blocking(move || {
        let plan = &ctx.plan;
        let id = job.key.costmap_id.as_str();
        let n = plan.tile_count();
        // The statistics and preview, a page of parts at a time.
        let mut merge = plan.merge();
        let mut k = 0;
        while k < n {
            let read = |kind: &str| {
                runtime
                    .block_on(db.costmap_tiles_of_kind(id, kind, k as i64, PAGE))
                    .map_err(fault("the tiles' statistics cannot be read"))
            };
            let (tallies, previews) = (read("tally")?, read("preview")?);
            if tallies.is_empty() || previews.is_empty() {
                return Err(StageError::Fault(format!(
                    "the statistics or preview of tile {k} are missing"
                )));
            }
            for ((t, tally), (p, preview)) in tallies.iter().zip(&previews) {
                if *t != k as i64 || *p != k as i64 {
                    return Err(StageError::Fault(format!(
                        "the statistics or preview of tile {k} are missing"
                    )));
                }
                let tally = TallyPart::from_bytes(tally).map_err(TiledError::from)?;
                let preview = PreviewPart::from_bytes(preview).map_err(TiledError::from)?;
                merge.add(k, &tally, &preview)?;
                k += 1;
            }
        }
        let map = merge.finish()?;
        if cancel.load(Ordering::Relaxed) {
            return Err(StageError::Cancelled);
        }

        // The GeoTIFFs, tile by tile.
        let io = |e: std::io::Error| StageError::Fault(format!("writing the costmap's files: {e}"));
        let layers: Vec<Layer> = plan.layers();
        let costmap =
            ChunkWriter::new(&db, &runtime, &job, &owner, COSTMAP_TIF.into()).map_err(io)?;
        let layer_writers = layers
            .iter()
            .map(|l| ChunkWriter::new(&db, &runtime, &job, &owner, layer_file(*l)).map(|w| (*l, w)))
            .collect::<std::io::Result<Vec<_>>>()
            .map_err(io)?;
        let mut files = TiledTiffFiles::new(costmap, layer_writers);
        files.begin(&plan.header()).map_err(io)?;
        for k in 0..n {
            if cancel.load(Ordering::Relaxed) {
                return Err(StageError::Cancelled);
            }
            let t = plan.tile(k)?;
            let cells = t.width * t.height;
            let tile = |kind: &str| -> Result<Vec<u8>, StageError> {
                runtime
                    .block_on(db.costmap_tile(id, kind, k as i64))
                    .map_err(fault("the costmap's tiles cannot be read"))?
                    .ok_or_else(|| StageError::Fault(format!("the {kind} of tile {k} is missing")))
            };
            let damaged = |m: String| StageError::Fault(format!("tile {k}: {m}"));
            let cost = decode_values(&tile("cost")?, cells).map_err(damaged)?;
            let class = decode_classes(&tile("class")?, cells).map_err(damaged)?;
            let mut layer_values = Vec::with_capacity(layers.len());
            for l in &layers {
                let v = decode_values(&tile(&layer_kind(*l))?, cells).map_err(damaged)?;
                layer_values.push((*l, v));
            }
            files
                .tile(&CostmapTile {
                    tx: t.tx,
                    ty: t.ty,
                    col0: t.col0,
                    row0: t.row0,
                    width: t.width,
                    height: t.height,
                    cost: &cost,
                    class: &class,
                    layers: &layer_values,
                })
                .map_err(io)?;
        }
        let (costmap, layer_writers) = files.finish().map_err(io)?;
        let mut written = vec![costmap.close().map_err(io)?];
        for (_, w) in layer_writers {
            written.push(w.close().map_err(io)?);
        }

        let (bounds, bounds_wgs84) =
            planner_core::terrain::raster_bounds(&map.transform, map.width, map.height, &map.crs)
                .map_err(|e| StageError::Fatal(format!("the costmap's bounds: {e}")))?;
        let legend = map.legend_svg();
        let result = CostmapResult {
            bounds: Some(bounds),
            bounds_wgs84: Some(bounds_wgs84),
            vehicle: map.vehicle,
            params: map.params,
            stats: map.stats,
            warnings: map.warnings,
            width: map.width,
            height: map.height,
            crs: map.crs,
            layers,
        };
        let result = serde_json::to_string(&result)
            .map_err(|e| StageError::Fatal(format!("the result document: {e}")))?;
        let small = vec![
            CostmapFileRow {
                name: PREVIEW_PNG.to_string(),
                content_type: "image/png".to_string(),
                data: map.preview_png,
            },
            CostmapFileRow {
                name: LEGEND_SVG.to_string(),
                content_type: "image/svg+xml".to_string(),
                data: legend.into_bytes(),
            },
        ];
        Ok(Finished {
            result,
            written,
            small,
        })
    })
    .await
}

/// Store what the finish made: false when the job or costmap is no
/// longer this owner's to finish (deleted, taken over).
pub async fn store(
    db: &Db,
    job: &TileJob,
    owner: &str,
    finished: &Finished,
) -> Result<bool, StageError> {
    db.finish_tiled_costmap(
        &job.key,
        owner,
        &finished.result,
        &finished.written,
        &finished.small,
        now_millis(),
    )
    .await
    .map_err(fault("the costmap cannot be stored"))
}
