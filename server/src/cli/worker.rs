//! `terraplan worker`: a replica that serves no HTTP and only runs the
//! costmap jobs of a PostgreSQL database it shares with `terraplan serve`
//! replicas. It takes over jobs whose holder died or gave them back, as
//! every replica does, and runs the tile jobs of costmaps built as tiles
//! (over `--costmap-tile-cells`), a few at a time (`--costmap-jobs`); on
//! SIGTERM (or Ctrl-C) it stops taking jobs, gives back the ones it runs,
//! queued for another replica, and exits 0.

use super::common::Failure;
use crate::config::ServeConfig;
use crate::db::Db;
use crate::state::AppState;

pub(super) fn worker(config: ServeConfig) -> Result<(), Failure> {
    let shared = config
        .database_url
        .as_deref()
        .is_some_and(|u| u.starts_with("postgres://") || u.starts_with("postgresql://"));
    if !shared {
        return Err(Failure::input(
            "terraplan worker runs the jobs of a PostgreSQL database shared with `terraplan \
             serve` replicas: give --database-url (or DATABASE_URL) postgres://…; on the \
             embedded SQLite, `terraplan serve` runs its own jobs",
        ));
    }
    crate::memory::tune_allocator();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::other(format!("cannot start the async runtime: {e}")))?;
    let result = runtime.block_on(run(config));
    // A run the shutdown cancelled may still be finishing a stage on a
    // blocking thread: do not wait for it.
    runtime.shutdown_timeout(std::time::Duration::from_secs(1));
    result.map_err(Failure::other)
}

async fn run(config: ServeConfig) -> Result<(), String> {
    crate::serve::init_tracing(config.log_format);
    let db = Db::connect(config.database_url.as_deref(), &config.data_dir)
        .await
        .map_err(|e| format!("cannot open the database: {e}"))?;
    // The same job runner, DEM cache and memory budget as a server's.
    let state = AppState::from_config(&config, db.clone());
    let jobs = state.costmaps.clone();
    // Listening before announcing: a SIGTERM from then on is a graceful stop.
    let signalled = crate::serve::shutdown_signal();
    let recovered = jobs.recover().await;
    jobs.start_maintenance();
    // The first line on stdout, for scripts and tests.
    println!("worker {} ready", jobs.instance());
    tracing::info!(
        instance = jobs.instance(),
        costmap_jobs = config.costmap_jobs,
        costmap_tile_cells = config.costmap_tile_cells,
        costmap_tile_side = config.costmap_tile_side,
        lease_s = config.job_lease_s,
        taken_over = recovered,
        "terraplan worker running costmap jobs"
    );
    signalled.await;
    jobs.begin_shutdown();
    jobs.finish().await;
    db.close().await;
    tracing::info!("shut down cleanly");
    Ok(())
}
