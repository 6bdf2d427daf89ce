//! Rate limits: sign-in attempts per client address and per user name
//! (against password guessing), planning requests per caller and per
//! address (against one client taking every planner). Token buckets in
//! memory, a bounded number of them; an empty bucket is a 429
//! problem+json with `Retry-After`.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::extract::{ConnectInfo, Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::auth::Caller;
use crate::error::ApiError;
use crate::state::AppState;

/// Most keys one limiter remembers; past it, full buckets (keys idle long
/// enough to have refilled) are forgotten first, then the stalest.
const MAX_KEYS: usize = 65_536;

/// One kind of limit: `per_minute` requests a minute for each key, up to
/// `burst` at once. `per_minute` 0: no limit.
pub struct Limiter {
    per_minute: u32,
    burst: u32,
    buckets: Mutex<HashMap<String, Bucket>>,
}

#[derive(Clone, Copy)]
struct Bucket {
    tokens: f64,
    updated: Instant,
}

impl Limiter {
    pub fn new(per_minute: u32, burst: u32) -> Limiter {
        Limiter {
            per_minute,
            burst: burst.max(1),
            buckets: Mutex::new(HashMap::new()),
        }
    }

    fn rate_per_s(&self) -> f64 {
        f64::from(self.per_minute) / 60.0
    }

    /// Take one request for `key`; when there is none left, how long until
    /// there is.
    pub fn take(&self, key: &str, now: Instant) -> Result<(), Duration> {
        if self.per_minute == 0 {
            return Ok(());
        }
        let mut buckets = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        if buckets.len() >= MAX_KEYS && !buckets.contains_key(key) {
            self.forget_some(&mut buckets, now);
        }
        let burst = f64::from(self.burst);
        let rate = self.rate_per_s();
        let bucket = buckets.entry(key.to_string()).or_insert(Bucket {
            tokens: burst,
            updated: now,
        });
        let elapsed = now.saturating_duration_since(bucket.updated).as_secs_f64();
        bucket.tokens = (bucket.tokens + elapsed * rate).min(burst);
        bucket.updated = now;
        if bucket.tokens >= 1.0 {
            bucket.tokens -= 1.0;
            Ok(())
        } else {
            Err(Duration::from_secs_f64((1.0 - bucket.tokens) / rate))
        }
    }

    /// Make room: drop the buckets that have refilled, or else the half
    /// touched longest ago.
    fn forget_some(&self, buckets: &mut HashMap<String, Bucket>, now: Instant) {
        let (burst, rate) = (f64::from(self.burst), self.rate_per_s());
        buckets.retain(|_, b| {
            b.tokens + now.saturating_duration_since(b.updated).as_secs_f64() * rate < burst
        });
        if buckets.len() >= MAX_KEYS {
            let mut times: Vec<Instant> = buckets.values().map(|b| b.updated).collect();
            times.sort_unstable();
            let cut = times[times.len() / 2];
            buckets.retain(|_, b| b.updated > cut);
        }
    }
}

/// The limits of a service.
pub struct RateLimits {
    pub sign_in: Limiter,
    pub planning: Limiter,
}

impl RateLimits {
    pub fn new(sign_in_per_minute: u32, planning_per_minute: u32) -> RateLimits {
        RateLimits {
            // A burst of a few attempts (a mistyped password), then the rate.
            sign_in: Limiter::new(sign_in_per_minute, sign_in_per_minute.min(10)),
            planning: Limiter::new(planning_per_minute, planning_per_minute.div_ceil(2)),
        }
    }

    /// Take one sign-in attempt for the user name `name` (the handler
    /// calls this once the body is read).
    pub fn sign_in_name(&self, name: &str) -> Result<(), ApiError> {
        self.sign_in
            .take(&format!("name:{name}"), Instant::now())
            .map_err(|wait| too_many("sign-in attempts for this user name", wait))
    }
}

fn too_many(what: &str, wait: Duration) -> ApiError {
    let retry_after_s = wait.as_secs_f64().ceil().max(1.0) as u64;
    ApiError::TooManyRequests {
        message: format!("too many {what}: try again in {retry_after_s} s"),
        retry_after_s,
    }
}

/// Whether requests `method path` (a path or its template) are rate
/// limited: sign-ins and planning.
pub fn is_rate_limited(method: &Method, path: &str) -> bool {
    is_sign_in(method, path) || is_planning(method, path)
}

fn is_sign_in(method: &Method, path: &str) -> bool {
    method == Method::POST && path == "/api/v1/session"
}

/// Requests that start planning work (or store a large upload).
fn is_planning(method: &Method, path: &str) -> bool {
    if method != Method::POST {
        return false;
    }
    matches!(
        path,
        "/api/v1/surveys" | "/api/v1/costmaps" | "/api/v1/dems"
    ) || (path.starts_with("/api/v1/costmaps/") && path.ends_with("/routes"))
        || (path.starts_with("/api/v1/routes/") && path.ends_with("/replan"))
}

/// Middleware (inside `authenticate`, so the caller is known): sign-ins
/// per client address, planning per caller and per address.
pub async fn limit_rates(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let now = Instant::now();
    let address = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map(|c| c.0.ip().to_string());
    let path = req.uri().path();
    let checked = if is_sign_in(req.method(), path) {
        match &address {
            Some(ip) => state
                .rates
                .sign_in
                .take(&format!("ip:{ip}"), now)
                .map_err(|w| too_many("sign-in attempts from this address", w)),
            None => Ok(()),
        }
    } else if is_planning(req.method(), path) {
        let by_caller = match req.extensions().get::<Caller>() {
            Some(c) => state
                .rates
                .planning
                .take(&format!("user:{}", c.user_id), now)
                .map_err(|w| too_many("planning requests from this user", w)),
            None => Ok(()),
        };
        by_caller.and_then(|()| match &address {
            Some(ip) => state
                .rates
                .planning
                .take(&format!("ip:{ip}"), now)
                .map_err(|w| too_many("planning requests from this address", w)),
            None => Ok(()),
        })
    } else {
        Ok(())
    };
    match checked {
        Ok(()) => next.run(req).await,
        Err(e) => e.into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_allows_its_burst_then_the_rate() {
        let l = Limiter::new(60, 3); // one a second, three at once
        let t0 = Instant::now();
        for _ in 0..3 {
            assert!(l.take("a", t0).is_ok());
        }
        let wait = l.take("a", t0).unwrap_err();
        assert!((wait.as_secs_f64() - 1.0).abs() < 1e-6, "{wait:?}");
        assert!(l.take("b", t0).is_ok(), "keys are separate");
        assert!(l.take("a", t0 + Duration::from_millis(999)).is_err());
        assert!(l.take("a", t0 + Duration::from_millis(1001)).is_ok());
        let unlimited = Limiter::new(0, 1);
        for _ in 0..1000 {
            assert!(unlimited.take("a", t0).is_ok());
        }
    }

    #[test]
    fn the_number_of_keys_is_bounded() {
        let l = Limiter::new(1, 1);
        let t0 = Instant::now();
        for i in 0..(MAX_KEYS + 10) {
            let _ = l.take(&i.to_string(), t0 + Duration::from_nanos(i as u64));
        }
        let n = l.buckets.lock().unwrap().len();
        assert!(n <= MAX_KEYS, "{n} keys kept");
        // The newest key is still limited.
        let last = (MAX_KEYS + 9).to_string();
        assert!(
            l.take(&last, t0 + Duration::from_nanos(MAX_KEYS as u64 + 9))
                .is_err()
        );
    }

    #[test]
    fn planning_requests_are_recognised() {
        assert!(is_planning(&Method::POST, "/api/v1/surveys"));
        assert!(is_planning(&Method::POST, "/api/v1/costmaps/x/routes"));
        assert!(is_planning(&Method::POST, "/api/v1/routes/x/replan"));
        assert!(!is_planning(&Method::GET, "/api/v1/surveys"));
        assert!(!is_planning(&Method::POST, "/api/v1/projects"));
    }
}
