//! Service configuration: command-line flags, each with an environment
//! variable of the same meaning.

use std::path::PathBuf;

use planner_core::geo::Limits;
use planner_core::terrain::DemLimits;

/// `--survey-timeout-s` by default.
pub const SURVEY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(60);

#[derive(clap::Args, Clone, Debug)]
pub struct ServeConfig {
    /// Address to listen on.
    #[arg(long, env = "TERRAPLAN_HOST", default_value = "127.0.0.1")]
    pub host: String,
    /// Port to listen on (0 picks a free one; the address is printed).
    #[arg(long, env = "TERRAPLAN_PORT", default_value_t = 8080)]
    pub port: u16,
    /// Directory for the embedded SQLite database and stored files.
    #[arg(long, env = "TERRAPLAN_DATA_DIR", default_value = "terraplan-data")]
    pub data_dir: PathBuf,
    /// The built web UI (`npm run build` in web-ui/), served at `/`.
    #[arg(long, env = "TERRAPLAN_WEB_DIR", default_value = "web-ui/dist")]
    pub web_dir: PathBuf,
    /// `postgres://…` to use PostgreSQL instead of the embedded SQLite
    /// (`sqlite:PATH` is accepted too).
    #[arg(long, env = "DATABASE_URL")]
    pub database_url: Option<String>,
    /// Largest request body accepted, bytes.
    #[arg(long, env = "TERRAPLAN_MAX_BODY_BYTES", default_value_t = 16 * 1024 * 1024)]
    pub max_body_bytes: usize,
    /// Largest DEM file accepted by `POST /api/v1/dems`, MiB (its own
    /// limit, apart from `--max-body-bytes`).
    #[arg(long, env = "TERRAPLAN_MAX_DEM_MB", default_value_t = 256, value_parser = clap::value_parser!(u64).range(1..=4096))]
    pub max_dem_mb: u64,
    /// Most pixels (width × height) a DEM may have.
    #[arg(long, env = "TERRAPLAN_MAX_DEM_PIXELS", default_value_t = DemLimits::default().max_pixels, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_dem_pixels: u64,
    /// Memory for parsed DEMs kept ready for sampling, MiB (at most
    /// four are kept; the least recently used goes first).
    #[arg(long, env = "TERRAPLAN_DEM_CACHE_MB", default_value_t = 1024)]
    pub dem_cache_mb: u64,
    /// Largest ROI accepted, km².
    #[arg(long, env = "TERRAPLAN_MAX_ROI_AREA_KM2", default_value_t = Limits::default().max_roi_area_km2)]
    pub max_roi_area_km2: f64,
    /// Most vertices accepted over the ROI and all no-fly zones.
    #[arg(long, env = "TERRAPLAN_MAX_VERTICES", default_value_t = Limits::default().max_vertices)]
    pub max_vertices: usize,
    /// Most no-fly zones accepted in one request.
    #[arg(long, env = "TERRAPLAN_MAX_NO_FLY_ZONES", default_value_t = Limits::default().max_no_fly_zones)]
    pub max_no_fly_zones: usize,
    /// Most survey-lane kilometres one plan may need (area / line spacing).
    #[arg(long, env = "TERRAPLAN_MAX_LANE_KM", default_value_t = Limits::default().max_lane_km)]
    pub max_lane_km: f64,
    /// Most Features one photos.geojson download holds; beyond it every
    /// k-th photo is written and the file's properties say so.
    #[arg(long, env = "TERRAPLAN_MAX_PHOTO_FEATURES", default_value_t = Limits::default().max_photo_features, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_photo_features: usize,
    /// Plans computed at once; further requests wait their turn.
    #[arg(long, env = "TERRAPLAN_PLANNER_THREADS", default_value_t = default_threads())]
    pub planner_threads: usize,
    /// Costmaps built at once; further jobs wait, queued.
    #[arg(long, env = "TERRAPLAN_COSTMAP_JOBS", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=256))]
    pub costmap_jobs: u64,
    /// How long a costmap job's claim lasts unless renewed, seconds
    /// (fractions allowed, at least 1): replicas sharing a PostgreSQL
    /// database take over the job of one that died this long after its last
    /// renewal. Renewed five times per lease.
    #[arg(long, env = "TERRAPLAN_JOB_LEASE_S", default_value_t = crate::jobs::DEFAULT_LEASE.as_secs_f64(), value_parser = parse_job_lease)]
    pub job_lease_s: f64,
    /// Costmaps of more working cells than this are built as tiles by every
    /// `terraplan serve` replica and `terraplan worker` on the database at
    /// once, each tile a job in the database's queue (run in the
    /// `--costmap-jobs` slots); smaller ones are built whole by one process.
    #[arg(long, env = "TERRAPLAN_COSTMAP_TILE_CELLS", default_value_t = 64_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub costmap_tile_cells: u64,
    /// The side of a tiled costmap's tiles, working cells: a multiple of 16
    /// from 16 to 8192 (the tiles of its GeoTIFFs too).
    #[arg(long, env = "TERRAPLAN_COSTMAP_TILE_SIDE", default_value_t = 512, value_parser = parse_tile_side)]
    pub costmap_tile_side: usize,
    /// Longest a route search may take, seconds (fractions allowed); a
    /// search still running then is stopped and answered with a 503.
    #[arg(long, env = "TERRAPLAN_ROUTE_TIMEOUT_S", default_value_t = 120.0, value_parser = parse_planning_timeout)]
    pub route_timeout_s: f64,
    /// Costmaps with more cells than this are routed coarse to fine (A* on
    /// 16 × 16 block minima, then A* in a corridor around that route,
    /// widened until proven optimal), the costmap read a window at a time;
    /// so are smaller ones whose plain A* would not fit the memory budget.
    /// Plain A* holds 16 bytes for every cell of the map.
    #[arg(long, env = "TERRAPLAN_ROUTE_COARSE_CELLS", default_value_t = crate::state::route_store::COARSE_CELLS)]
    pub route_coarse_cells: u64,
    /// Longest a survey may plan, seconds (fractions allowed); a survey
    /// still planning then is stopped and answered with a 503.
    #[arg(long, env = "TERRAPLAN_SURVEY_TIMEOUT_S", default_value_t = SURVEY_TIMEOUT.as_secs_f64(), value_parser = parse_planning_timeout)]
    pub survey_timeout_s: f64,
    /// Memory for the route searches kept for replanning (D* Lite states,
    /// about 17 bytes per costmap cell each), MiB; the least recently used
    /// goes first. 0 keeps none: every replan searches from scratch.
    #[arg(long, env = "TERRAPLAN_ROUTE_CACHE_MB", default_value_t = 512)]
    pub route_cache_mb: u64,
    /// Memory for heavy work at once, MiB: reading DEMs, hillshades,
    /// costmap builds and route searches each reserve their estimated peak
    /// (from the raster's declared size) before they start; work that does
    /// not fit beside the running work waits, work that alone needs more is
    /// refused (413 for an upload, 422 otherwise). Apart from it: the
    /// caches (`--dem-cache-mb`, `--route-cache-mb`). Default: half the
    /// machine's (or cgroup's) memory, at least 256.
    #[arg(long, env = "TERRAPLAN_MEMORY_BUDGET_MB", default_value_t = crate::memory::default_budget_mb(), value_parser = clap::value_parser!(u64).range(16..=4_194_303))]
    pub memory_budget_mb: u64,
    /// Longest wait for a request's head (request line and header
    /// fields), seconds; also how long a kept-alive connection waits for
    /// its next request. A slower client is disconnected.
    #[arg(long, env = "TERRAPLAN_HEADER_READ_TIMEOUT_S", default_value_t = 20.0, value_parser = parse_read_timeout)]
    pub header_read_timeout_s: f64,
    /// Time a request body may take to arrive, seconds, plus 1 s for
    /// every `--body-min-bytes-per-s` bytes received; a slower body is
    /// answered 408 and its connection closed.
    #[arg(long, env = "TERRAPLAN_BODY_READ_TIMEOUT_S", default_value_t = 30.0, value_parser = parse_read_timeout)]
    pub body_read_timeout_s: f64,
    /// The slowest steady rate a request body may keep, bytes/s (see
    /// `--body-read-timeout-s`); 0: a body must arrive whole within the
    /// timeout.
    #[arg(long, env = "TERRAPLAN_BODY_MIN_BYTES_PER_S", default_value_t = 1024)]
    pub body_min_bytes_per_s: u64,
    /// Client connections open at once, lingering ones included; when all
    /// are taken, one without a request in hand, else one whose body is
    /// slower than `--body-min-bytes-per-s`, is closed to make room (or new
    /// clients wait in the backlog). Default: the open-file limit
    /// (`ulimit -n`) less a reserve for the database and files (1/8 of
    /// it, 64 to 1024), at most 16384.
    #[arg(long, env = "TERRAPLAN_MAX_CONNECTIONS", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_connections: Option<u64>,
    /// Allowed CORS origin (repeatable; `*` allows any). None: no CORS headers.
    #[arg(
        long = "cors-origin",
        env = "TERRAPLAN_CORS_ORIGINS",
        value_delimiter = ','
    )]
    pub cors_origins: Vec<String>,
    /// Host name the service answers to besides the loopback names and the
    /// `--host` address (repeatable; `*` any). Other `Host` headers get 400,
    /// which keeps web pages elsewhere from reaching the service through
    /// DNS rebinding. Behind a proxy or on a LAN, name the public host.
    #[arg(
        long = "allowed-host",
        env = "TERRAPLAN_ALLOWED_HOSTS",
        value_delimiter = ','
    )]
    pub allowed_hosts: Vec<String>,
    /// Sign-in attempts a minute from one address, and for one user name
    /// (0: no limit); more get 429 with Retry-After.
    #[arg(long, env = "TERRAPLAN_SIGN_IN_PER_MINUTE", default_value_t = 10)]
    pub sign_in_per_minute: u32,
    /// Planning requests (surveys, costmaps, routes, replans, DEM uploads) a
    /// minute from one user, and from one address (0: no limit), up to half
    /// of them at once; more get 429 with Retry-After.
    #[arg(long, env = "TERRAPLAN_PLANNING_PER_MINUTE", default_value_t = 600)]
    pub planning_per_minute: u32,
    /// Bytes of DEM and costmap files one project may hold, MiB (0: no
    /// limit); an upload or costmap past it gets 413.
    #[arg(long, env = "TERRAPLAN_PROJECT_QUOTA_MB", default_value_t = 4096)]
    pub project_quota_mb: u64,
    /// Costmap jobs one project may have queued or running (0: no limit);
    /// more get 429 with Retry-After.
    #[arg(long, env = "TERRAPLAN_PROJECT_QUEUED_JOBS", default_value_t = 8)]
    pub project_queued_jobs: u64,
    /// Vehicles the service may send missions to
    /// (`POST /api/v1/surveys/{id}/uavs/{uav}/upload`), comma-separated or
    /// repeated: an exact address (`udpout:192.168.1.10:14550`,
    /// `tcpout:127.0.0.1:5760`, `serial:/dev/ttyACM0:57600`) or one whose
    /// port (baud rate) is a range (`udpout:10.0.0.5:14550-14560`) or any
    /// (`udpout:10.0.0.5:*`); hosts are always named exactly. None: the
    /// upload endpoint answers 404 (switched off).
    #[arg(
        long = "vehicle-links",
        env = "TERRAPLAN_VEHICLE_LINKS",
        value_delimiter = ',',
        value_name = "ADDR",
        value_parser = crate::vehicle_link::allow::parse_link_pattern
    )]
    pub vehicle_links: Vec<crate::vehicle_link::LinkPattern>,
    /// Mark the session cookie `Secure` on every answer (it is anyway when
    /// a proxy sends `X-Forwarded-Proto: https`): for a service behind TLS.
    #[arg(long, env = "TERRAPLAN_COOKIE_SECURE")]
    pub cookie_secure: bool,
    /// Log format.
    #[arg(long, env = "TERRAPLAN_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogFormat {
    Text,
    Json,
}

/// `--route-timeout-s`, `--survey-timeout-s` (and `terraplan survey
/// --timeout-s`): a number of seconds in (0, 86400].
pub(crate) fn parse_planning_timeout(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v > 0.0 && v <= 86_400.0 {
        Ok(v)
    } else {
        Err(format!("{s} is outside (0, 86400] seconds"))
    }
}

/// `--header-read-timeout-s`, `--body-read-timeout-s`: seconds in
/// (0, 3600].
fn parse_read_timeout(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v > 0.0 && v <= 3600.0 {
        Ok(v)
    } else {
        Err(format!("{s} is outside (0, 3600] seconds"))
    }
}

/// `--costmap-tile-side`: a multiple of 16 in [16, 8192].
fn parse_tile_side(s: &str) -> Result<usize, String> {
    let v: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of cells"))?;
    if (16..=8192).contains(&v) && v.is_multiple_of(16) {
        Ok(v)
    } else {
        Err(format!(
            "{s}: tiles are a multiple of 16 cells, from 16 to 8192"
        ))
    }
}

/// `--job-lease-s`: seconds in [1, 3600].
fn parse_job_lease(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if (crate::jobs::MIN_LEASE.as_secs_f64()..=3600.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{s} is outside [1, 3600] seconds"))
    }
}

fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

impl ServeConfig {
    pub fn limits(&self) -> Limits {
        Limits {
            max_roi_area_km2: self.max_roi_area_km2,
            max_vertices: self.max_vertices,
            max_no_fly_zones: self.max_no_fly_zones,
            max_lane_km: self.max_lane_km,
            max_photo_features: self.max_photo_features,
        }
    }

    pub fn dem_limits(&self) -> DemLimits {
        DemLimits {
            max_pixels: self.max_dem_pixels,
            ..DemLimits::default()
        }
    }

    /// `--job-lease-s`.
    pub fn job_lease(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.job_lease_s)
    }

    /// `--costmap-tile-cells` and `--costmap-tile-side`.
    pub fn tile_settings(&self) -> crate::jobs::TileSettings {
        crate::jobs::TileSettings {
            cells: self.costmap_tile_cells,
            side: self.costmap_tile_side,
        }
    }

    /// `--route-cache-mb` in bytes.
    pub fn route_cache_bytes(&self) -> usize {
        usize::try_from(self.route_cache_mb.saturating_mul(1024 * 1024)).unwrap_or(usize::MAX)
    }

    /// `--max-dem-mb` in bytes.
    pub fn max_dem_bytes(&self) -> usize {
        usize::try_from(self.max_dem_mb.saturating_mul(1024 * 1024)).unwrap_or(usize::MAX)
    }
}
