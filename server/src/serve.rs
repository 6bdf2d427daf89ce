//! `terraplan serve`: start-up, logging, graceful shutdown.

use std::io::IsTerminal;
use std::sync::Arc;

use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tracing_subscriber::EnvFilter;

use crate::app::{AppState, router};
use crate::config::{LogFormat, ServeConfig};
use crate::costmap_jobs::CostmapJobs;
use crate::db::Db;

pub fn init_tracing(format: LogFormat) {
    let filter = EnvFilter::try_from_env("TERRAPLAN_LOG")
        .unwrap_or_else(|_| EnvFilter::new("info,sqlx=warn"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    let _ = match format {
        LogFormat::Json => builder.json().try_init(),
        LogFormat::Text => builder.try_init(),
    };
}

pub async fn serve(config: ServeConfig) -> Result<(), String> {
    init_tracing(config.log_format);
    if config.planner_threads == 0 {
        return Err("--planner-threads must be at least 1".into());
    }
    std::fs::create_dir_all(&config.data_dir).map_err(|e| {
        format!(
            "cannot create data directory {}: {e}",
            config.data_dir.display()
        )
    })?;
    let db = Db::connect(config.database_url.as_deref(), &config.data_dir)
        .await
        .map_err(|e| format!("cannot open the database: {e}"))?;
    tracing::info!(backend = db.backend(), data_dir = %config.data_dir.display(), "database ready, migrations applied");

    let jobs = Arc::new(CostmapJobs::new(
        usize::try_from(config.costmap_jobs).unwrap_or(usize::MAX),
    ));
    let state = AppState {
        db: db.clone(),
        limits: config.limits(),
        planner: Arc::new(Semaphore::new(config.planner_threads)),
        dems: Arc::new(crate::app::DemStore::from_config(&config)),
        costmaps: jobs.clone(),
        routes: Arc::new(crate::app::RouteStore::from_config(&config)),
        web: Arc::new(crate::web_ui::WebUi::new(&config.web_dir)),
    };
    if state.web.is_built() {
        tracing::info!(dir = %config.web_dir.display(), "serving the web page at /");
    } else {
        tracing::warn!(dir = %config.web_dir.display(), "the web page is not built: / explains how to build it");
    }
    // Jobs a previous server left queued or running are queued again.
    let recovered = jobs.recover(&state).await;
    if recovered > 0 {
        tracing::info!(jobs = recovered, "unfinished costmap jobs queued again");
    }
    jobs.start_maintenance(&state);
    let app = router(state, &config.cors_origins, config.max_body_bytes);
    let listener = TcpListener::bind((config.host.as_str(), config.port))
        .await
        .map_err(|e| format!("cannot listen on {}:{}: {e}", config.host, config.port))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    // The first line on stdout is the address, for scripts and tests that
    // start the service on port 0.
    println!("listening on http://{addr}");
    tracing::info!(%addr, "terraplan serving");
    let stopping = jobs.clone();
    // Connections close with a linger, so a client still sending a body
    // the server refused reads the answer instead of a reset.
    let served = axum::serve(crate::linger::LingeringListener(listener), app)
        .with_graceful_shutdown(async move {
            shutdown_signal().await;
            // Cancel the costmap runs and end the event streams, so that
            // no request keeps the server from stopping.
            stopping.begin_shutdown();
        })
        .await
        .map_err(|e| format!("server error: {e}"));
    jobs.begin_shutdown();
    jobs.finish(&db).await;
    served?;
    db.close().await;
    tracing::info!("shut down cleanly");
    Ok(())
}

/// Ctrl-C or SIGTERM: stop accepting, let in-flight requests finish.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
    tracing::info!("shutdown requested: finishing in-flight requests");
}
