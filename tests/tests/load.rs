//! Bounded load test on loopback: 32 concurrent clients post surveys for
//! `TERRAPLAN_LOAD_SECONDS` (default 20) seconds; every request must
//! succeed. Prints requests/s and latency percentiles next to the planner's
//! own time per request (from the `Server-Timing` header). Figures are
//! reported, never asserted.

use std::time::{Duration, Instant};

use terraplan_e2e::{Server, example_survey_request, post_json};

#[test]
fn thirty_two_clients_posting_surveys() {
    let seconds: u64 = std::env::var("TERRAPLAN_LOAD_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let dir = tempfile::tempdir().unwrap();
    // A load test measures the service, not its per-user rate limit.
    let server = Server::start(dir.path(), &["--planning-per-minute", "0"]);
    let body = example_survey_request();
    let url = server.url("/api/v1/surveys");
    let deadline = Instant::now() + Duration::from_secs(seconds);
    let started = Instant::now();
    let handles: Vec<_> = (0..32)
        .map(|_| {
            let (url, body) = (url.clone(), body.clone());
            std::thread::spawn(move || {
                let mut out = Vec::new();
                while Instant::now() < deadline {
                    let t = Instant::now();
                    let r = post_json(&url, &body);
                    let plan_ms = r
                        .header("server-timing")
                        .and_then(|h| h.split(',').next())
                        .and_then(|p| p.trim().strip_prefix("plan;dur="))
                        .and_then(|v| v.parse::<f64>().ok());
                    out.push((r.status, t.elapsed(), plan_ms));
                }
                out
            })
        })
        .collect();
    let results: Vec<(u16, Duration, Option<f64>)> = handles
        .into_iter()
        .flat_map(|h| h.join().unwrap())
        .collect();
    let elapsed = started.elapsed().as_secs_f64();
    let failures: Vec<u16> = results.iter().filter(|r| r.0 != 201).map(|r| r.0).collect();
    let mut lat: Vec<f64> = results.iter().map(|r| r.1.as_secs_f64() * 1e3).collect();
    lat.sort_by(f64::total_cmp);
    let mut plan: Vec<f64> = results.iter().filter_map(|r| r.2).collect();
    plan.sort_by(f64::total_cmp);
    let pct = |v: &[f64], p: f64| v[((v.len() as f64 - 1.0) * p).round() as usize];
    let backend = if std::env::var("TERRAPLAN_TEST_DATABASE_URL").is_ok() {
        "postgres"
    } else {
        "sqlite"
    };
    eprintln!(
        "load[{backend}]: {} requests in {elapsed:.1} s = {:.1} req/s; latency p50 {:.1} ms, p99 {:.1} ms; \
         planner alone p50 {:.1} ms, p99 {:.1} ms; failures {}",
        results.len(),
        results.len() as f64 / elapsed,
        pct(&lat, 0.5),
        pct(&lat, 0.99),
        pct(&plan, 0.5),
        pct(&plan, 0.99),
        failures.len()
    );
    assert!(!results.is_empty());
    assert!(
        failures.is_empty(),
        "{} of {} requests failed: {:?}",
        failures.len(),
        results.len(),
        &failures[..failures.len().min(10)]
    );
    assert_eq!(
        plan.len(),
        results.len(),
        "every response carries the planner's time"
    );
}
