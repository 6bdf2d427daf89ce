//! One tile job's work: its stage run on a blocking thread through
//! `planner_core::costmap::TilePlan`, its inputs read from and its
//! outputs made for `costmap_tiles` (what each stage stores: see the
//! migration `costmap_tile_jobs`).

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use planner_core::costmap::{ClassTiles, CostmapError, TileEdges, TileFill, TilePlan, TiledError};

use super::codec::{decode_classes, encode_classes, encode_values};
use super::context::CostmapContext;
use crate::db::{Db, TileJob, TileOutput, TileStage};
use crate::memory;

/// Pieces read from the database at once (edges, tallies, previews).
pub const PAGE: i64 = 64;

/// How a stage's run ended, but for its outputs.
#[derive(Debug)]
pub enum StageError {
    /// Stopped: its costmap was deleted or the job taken over, or shutdown.
    Cancelled,
    /// It can never succeed (an invalid request, a bug): the costmap fails
    /// with this.
    Fatal(String),
    /// A fault that may pass (storage, damaged pieces): tried again, and
    /// the costmap fails with it once the job has failed too often.
    Fault(String),
}

impl From<TiledError> for StageError {
    fn from(e: TiledError) -> StageError {
        match e {
            TiledError::Costmap(CostmapError::Cancelled) => StageError::Cancelled,
            TiledError::Costmap(CostmapError::Invalid(issues)) => {
                StageError::Fatal(super::super::build::invalid_request(&issues))
            }
            TiledError::NoSuchTile { .. } => StageError::Fatal(e.to_string()),
            other => StageError::Fault(other.to_string()),
        }
    }
}

fn storage(e: sqlx::Error) -> StageError {
    StageError::Fault(format!("the database: {e}"))
}

/// Run `work` on a blocking thread; a panic is a bug, and fatal.
pub async fn blocking<T: Send + 'static>(
    work: impl FnOnce() -> Result<T, StageError> + Send + 'static,
) -> Result<T, StageError> {
    match tokio::task::spawn_blocking(work).await {
        Ok(r) => r,
        Err(e) if e.is_panic() => {
            let payload = e.into_panic();
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".to_string());
            Err(StageError::Fatal(format!(
                "internal error: the costmap builder panicked ({what}); this is a bug, please \
                 report it"
            )))
        }
        Err(_) => Err(StageError::Cancelled),
    }
}

fn output(kind: &str, k: usize, data: Vec<u8>) -> TileOutput {
    TileOutput {
        kind: kind.to_string(),
        tile: k as i64,
        data,
    }
}

fn encoded(r: std::io::Result<Vec<u8>>) -> Result<Vec<u8>, StageError> {
    r.map_err(|e| StageError::Fault(format!("a tile could not be compressed: {e}")))
}

/// The stored name of a layer's tiles.
pub fn layer_kind(layer: planner_core::costmap::Layer) -> String {
    format!("layer:{}", layer.name())
}

/// The class tiles `reads` of kind `kind` of costmap `id`, read from the
/// database before the stage runs (so its blocking thread never waits on
/// the database for them), as the windows a stage reads.
async fn stored_classes(
    db: &Db,
    id: &str,
    kind: &'static str,
    plan: &TilePlan,
    reads: Vec<usize>,
) -> Result<ClassTiles<impl Fn(usize) -> Result<Arc<[u8]>, TiledError> + Sync + use<>>, StageError>
{
    let layout = plan.layout();
    let mut tiles: HashMap<usize, Arc<[u8]>> = HashMap::with_capacity(reads.len());
    for t in reads {
        let data = db
            .costmap_tile(id, kind, t as i64)
            .await
            .map_err(storage)?
            .ok_or_else(|| {
                StageError::Fault(format!("the {kind} classes of tile {t} are missing"))
            })?;
        let w = layout.tile(t);
        let cells = decode_classes(&data, w.width * w.height)
            .map_err(|m| StageError::Fault(format!("the {kind} classes of tile {t}: {m}")))?;
        tiles.insert(t, cells.into());
    }
    Ok(ClassTiles::new(layout, move |t: usize| {
        tiles.get(&t).cloned().ok_or_else(|| {
            TiledError::Mismatch(format!("the {kind} classes of tile {t} were not read"))
        })
    }))
}

/// The memory a job of `stage` on tile `k` takes at most, bytes: the
/// per-cell build of the whole pipeline over the tile's widest window
/// (its core and halos, at the DEM's resolution), and its heights.
pub fn job_bytes(plan: &TilePlan, stage: TileStage, k: usize) -> u64 {
    if !matches!(stage, TileStage::Classify | TileStage::Cost) {
        // Class tiles, edges and parts: about a tile's cells a few times.
        let side = plan.layout().tile as u64;
        return memory::costmap_build_bytes(side * side, 0);
    }
    let Ok(t) = plan.tile(k) else {
        return 0;
    };
    let h = plan.halos();
    let reach = |a: usize| h.surface[a].max(h.inflation[a]) as u64 + 1;
    let [fx, fy] = plan.params().resample_factor;
    let cells = (t.width as u64 + 2 * reach(0))
        .saturating_mul(t.height as u64 + 2 * reach(1))
        .saturating_mul((fx * fy) as u64);
    memory::costmap_build_bytes(cells, plan.layers().len() as u64)
        .saturating_add(cells.saturating_mul(8))
}

/// Run job `job`'s stage (but the finish) and return what it stores.
pub async fn run_stage(
    db: &Db,
    ctx: &Arc<CostmapContext>,
    job: &TileJob,
    cancel: &Arc<AtomicBool>,
) -> Result<Vec<TileOutput>, StageError> {
    let id = job.key.costmap_id.clone();
    let n = ctx.plan.tile_count();
    let k = usize::try_from(job.key.tile)
        .ok()
        .filter(|&k| k < n || !job.key.stage.per_tile())
        .ok_or_else(|| {
            StageError::Fatal(format!("tile {} is not one of its {n} tiles", job.key.tile))
        })?;
    match job.key.stage {
        TileStage::Classify => {
            let (ctx, cancel) = (ctx.clone(), cancel.clone());
            blocking(move || {
                let c = ctx
                    .plan
                    .classify(&*ctx.dem, ctx.landcover.as_deref(), k, &cancel)?;
                Ok(vec![
                    output("prefill", k, encoded(encode_classes(&c.core))?),
                    output("edges", k, c.edges.to_bytes()),
                ])
            })
            .await
        }
        TileStage::Join => {
            let mut pieces = Vec::with_capacity(n);
            while pieces.len() < n {
                let page = db
                    .costmap_tiles_of_kind(&id, "edges", pieces.len() as i64, PAGE)
                    .await
                    .map_err(storage)?;
                if page.is_empty() {
                    break;
                }
                pieces.extend(page);
            }
            if pieces.len() != n {
                return Err(StageError::Fault(format!(
                    "the edges of {} of its {n} tiles are stored",
                    pieces.len()
                )));
            }
            let ctx = ctx.clone();
            blocking(move || {
                let mut edges = Vec::with_capacity(n);
                for (t, bytes) in pieces {
                    let e = TileEdges::from_bytes(&bytes).map_err(TiledError::from)?;
                    edges.push((t as usize, e));
                }
                let fill = ctx.plan.join(edges)?;
                if fill.len() != n {
                    return Err(StageError::Fatal(format!(
                        "the join decided for {} tiles of {n}",
                        fill.len()
                    )));
                }
                Ok(fill
                    .into_tiles()
                    .iter()
                    .enumerate()
                    .map(|(t, f)| output("fill", t, f.to_bytes()))
                    .collect())
            })
            .await
        }
        TileStage::Fill => {
            let fill = db
                .costmap_tile(&id, "fill", k as i64)
                .await
                .map_err(storage)?
                .ok_or_else(|| StageError::Fault(format!("the fill of tile {k} is missing")))?;
            let reads = ctx.plan.fill_reads(k)?;
            let prefill = stored_classes(db, &id, "prefill", &ctx.plan, reads).await?;
            let ctx = ctx.clone();
            blocking(move || {
                let fill = TileFill::from_bytes(&fill).map_err(TiledError::from)?;
                let core = ctx.plan.fill(k, &prefill, &fill)?;
                Ok(vec![output("final", k, encoded(encode_classes(&core))?)])
            })
            .await
        }
        TileStage::Cost => {
            let reads = ctx.plan.cost_reads(k)?;
            let classes = stored_classes(db, &id, "final", &ctx.plan, reads).await?;
            let (ctx, cancel) = (ctx.clone(), cancel.clone());
            blocking(move || {
                let c = ctx
                    .plan
                    .cost(&*ctx.dem, ctx.landcover.as_deref(), &classes, k, &cancel)?;
                let mut out = vec![
                    output("cost", k, encoded(encode_values(&c.cost))?),
                    output("class", k, encoded(encode_classes(&c.class))?),
                    output("tally", k, c.tally.to_bytes()),
                    output("preview", k, c.preview.to_bytes()),
                ];
                for (layer, values) in &c.layers {
                    out.push(output(
                        &layer_kind(*layer),
                        k,
                        encoded(encode_values(values))?,
                    ));
                }
                Ok(out)
            })
            .await
        }
        TileStage::Finish => Err(StageError::Fatal(
            "the finish stage is run by the finish, not as a tile".into(),
        )),
    }
}
