//! `terraplan serve`: start-up, logging, graceful shutdown.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

use sqlx::sqlite::SqliteConnectOptions;
use tokio::net::{TcpListener, TcpSocket};
use tracing_subscriber::EnvFilter;

use crate::app::router;
use crate::config::{LogFormat, ServeConfig};
use crate::db::Db;
use crate::state::AppState;

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
    // Held until the process ends.
    let _lock = lock_sqlite(&config)?;
    let db = Db::connect(config.database_url.as_deref(), &config.data_dir)
        .await
        .map_err(|e| format!("cannot open the database: {e}"))?;
    tracing::info!(backend = db.backend(), data_dir = %config.data_dir.display(), "database ready, migrations applied");

    // A service with no users gets its admin now; the secrets are shown
    // once, on stdout after the address, and never logged.
    let first = crate::auth::accounts::first_start(&db)
        .await
        .map_err(|e| format!("cannot make the first user: {e}"))?;
    if let Some(first) = &first {
        tracing::info!(
            user = crate::auth::accounts::FIRST_ADMIN,
            adopted_resources = first.adopted,
            "first start: made the admin user"
        );
    }

    let state = AppState::from_config(&config, db.clone());
    let jobs = state.costmaps.clone();
    if state.web.is_built() {
        tracing::info!(dir = %config.web_dir.display(), "serving the web page at /");
    } else {
        tracing::warn!(dir = %config.web_dir.display(), "the web page is not built: / explains how to build it");
    }
    // Jobs a previous server left queued or running are queued again.
    let recovered = jobs.recover().await;
    if recovered > 0 {
        tracing::info!(jobs = recovered, "unfinished costmap jobs queued again");
    }
    jobs.start_maintenance();
    // Tiles of uploads a killed server left (see dem_store::uploads).
    match crate::state::dem_store::uploads::sweep_at_start(&db).await {
        Ok(0) => {}
        Ok(n) => tracing::info!(uploads = n, "swept the tiles of unfinished DEM uploads"),
        Err(e) => return Err(format!("cannot sweep unfinished DEM uploads: {e}")),
    }
    crate::state::dem_store::uploads::start_sweeping(db.clone(), config.job_lease());
    let allowed_hosts = crate::guard::AllowedHosts::new(&config.host, &config.allowed_hosts);
    let app = router(
        state,
        &config.cors_origins,
        allowed_hosts,
        config.max_body_bytes,
    );
    let listener = listen(&config.host, config.port)
        .await
        .map_err(|e| format!("cannot listen on {}:{}: {e}", config.host, config.port))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    // Listening for the signals before the address is announced: a
    // SIGTERM from then on is a graceful stop, never the default kill.
    let signalled = shutdown_signal();
    // The first line on stdout is the address, for scripts and tests that
    // start the service on port 0.
    println!("listening on http://{addr}");
    if let Some(first) = first {
        println!(
            "first start: sign in at http://{addr} as \"{}\" with the one-time password {}, or \
             call the API with \"Authorization: Bearer {}\"",
            crate::auth::accounts::FIRST_ADMIN,
            first.password,
            first.token
        );
    }
    tracing::info!(%addr, "terraplan serving");
    let limits = conn_limits(&config);
    tracing::info!(
        max_connections = limits.max_connections,
        header_read_timeout_s = config.header_read_timeout_s,
        body_read_timeout_s = config.body_read_timeout_s,
        "accepting connections"
    );
    let stopping = jobs.clone();
    // Connections close with a linger, so a client still sending a body
    // the server refused reads the answer instead of a reset.
    crate::conn::serve(listener, app, limits, async move {
        signalled.await;
        // Cancel the costmap runs and end the event streams, so that
        // no request keeps the server from stopping.
        stopping.begin_shutdown();
    })
    .await;
    jobs.begin_shutdown();
    jobs.finish().await;
    db.close().await;
    tracing::info!("shut down cleanly");
    Ok(())
}

/// Connections the kernel queues until they are accepted. Rust's
/// default, 128, makes a burst of clients beyond the connection limit
/// wait for SYN retransmissions (1 s, 3 s, …) instead of their turn.
const LISTEN_BACKLOG: u32 = 1024;

/// A listener on the first of `host`'s addresses that can be bound.
async fn listen(host: &str, port: u16) -> std::io::Result<TcpListener> {
    let mut last = None;
    for addr in tokio::net::lookup_host((host, port)).await? {
        let socket = if addr.is_ipv4() {
            TcpSocket::new_v4()
        } else {
            TcpSocket::new_v6()
        }?;
        #[cfg(unix)]
        socket.set_reuseaddr(true)?;
        match socket
            .bind(addr)
            .and_then(|()| socket.listen(LISTEN_BACKLOG))
        {
            Ok(listener) => return Ok(listener),
            Err(e) => last = Some(e),
        }
    }
    Err(last.unwrap_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::NotFound, "the host has no address")
    }))
}

/// The connection limits of `config`: `--max-connections`, or room
/// under the open-file limit.
fn conn_limits(config: &ServeConfig) -> crate::conn::ConnLimits {
    let file_limit = crate::conn::file_limit();
    let room = file_limit.map_or(
        usize::try_from(crate::conn::MAX_DEFAULT_CONNECTIONS).unwrap_or(usize::MAX),
        crate::conn::default_max_connections,
    );
    let max_connections = match config.max_connections {
        Some(n) => {
            let n = usize::try_from(n).unwrap_or(usize::MAX);
            if n > room {
                tracing::warn!(
                    max_connections = n,
                    file_limit,
                    "--max-connections leaves little room under the open-file limit: \
                     raise `ulimit -n`, or files may fail to open under load"
                );
            }
            n
        }
        None => room,
    };
    crate::conn::ConnLimits {
        header_read_timeout: Duration::from_secs_f64(config.header_read_timeout_s),
        body_read_timeout: Duration::from_secs_f64(config.body_read_timeout_s),
        body_min_bytes_per_s: config.body_min_bytes_per_s,
        max_connections,
    }
}

/// The file whose lock makes an embedded SQLite database this server's
/// alone: `<database file>.lock`; `None` on PostgreSQL (shared by design:
/// costmap jobs are leased there) and for an in-memory database.
fn sqlite_lock_path(config: &ServeConfig) -> Option<PathBuf> {
    match config.database_url.as_deref() {
        None => Some(config.data_dir.join("terraplan.sqlite3.lock")),
        Some(url) if url.starts_with("sqlite:") => {
            if url.contains(":memory:") || url.contains("mode=memory") {
                return None;
            }
            let opts = SqliteConnectOptions::from_str(url).ok()?;
            let mut name = opts.get_filename().as_os_str().to_owned();
            name.push(".lock");
            Some(PathBuf::from(name))
        }
        Some(_) => None,
    }
}

/// Lock the SQLite database for this process: a second server on it
/// would take over the first one's running costmap jobs as if they had
/// been left by a crash. The lock (`flock`) lasts as long as the returned
/// file is open, and the kernel drops it when the process ends, crashes
/// included.
fn lock_sqlite(config: &ServeConfig) -> Result<Option<std::fs::File>, String> {
    let Some(path) = sqlite_lock_path(config) else {
        return Ok(None);
    };
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| format!("cannot open the lock file {}: {e}", path.display()))?;
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(std::fs::TryLockError::WouldBlock) => Err(format!(
            "another terraplan server is using this database ({} is locked): stop it first, or \
             give this one its own --data-dir",
            path.display()
        )),
        Err(std::fs::TryLockError::Error(e)) => Err(format!("cannot lock {}: {e}", path.display())),
    }
}

/// Ctrl-C or SIGTERM: stop accepting, let in-flight requests finish.
/// The handlers are installed when this is called, not when the future
/// is first polled.
pub(crate) fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    let (interrupt, terminate) = {
        use tokio::signal::unix::{SignalKind, signal};
        (
            signal(SignalKind::interrupt()).ok(),
            signal(SignalKind::terminate()).ok(),
        )
    };
    async move {
        #[cfg(unix)]
        {
            let wait = |s: Option<tokio::signal::unix::Signal>| async move {
                match s {
                    Some(mut s) => {
                        s.recv().await;
                    }
                    None => std::future::pending::<()>().await,
                }
            };
            tokio::select! {
                () = wait(interrupt) => {},
                () = wait(terminate) => {},
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
        tracing::info!("shutdown requested: finishing in-flight requests");
    }
}
