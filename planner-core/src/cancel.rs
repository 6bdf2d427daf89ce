//! Cooperative cancellation of planning work.
//!
//! A [`CancelToken`] is cancelled by whoever waits for the work (the
//! service cancels it when the client goes away) and may carry a time
//! limit. Planning code checks it every so often and returns [`Cancelled`]
//! up the stack; a check is an atomic load (plus a clock read when the
//! token has a limit, a few tens of nanoseconds), cheap enough for every
//! iteration of a loop doing real work, and [`Pacer`] spaces checks out in
//! tight loops.
//!
//! Deep stages of the pipelines check the token of the current thread,
//! [`check`], set for the duration of a call by [`CancelToken::scope`], so
//! the token need not be passed through every signature on the way. Work
//! handed to other threads takes the token along ([`current`]).
//!
//! A function that cannot return the error (it returns a plain value or an
//! `Option`) may stop early with a partial result when a check fails; its
//! caller checks again right after and throws that result away. The owner
//! of the token can [`settle`](CancelToken::settle) the outcome, so that
//! a failure caused by such a partial result reads as the cancellation.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::{Duration, Instant};

/// Why work stopped before its end.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Cancelled {
    /// Cancelled by its owner ([`CancelToken::cancel`]).
    #[error("the work was cancelled")]
    Stopped,
    /// Its time limit ran out.
    #[error("the work took longer than its time limit of {} s", seconds(*.limit))]
    TimedOut { limit: Duration },
}

/// A duration in seconds as people write it: `60`, `0.5`, `2.25`.
fn seconds(d: Duration) -> String {
    let s = format!("{:.3}", d.as_secs_f64());
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

const RUNNING: u8 = 0;
const STOPPED: u8 = 1;
const TIMED_OUT: u8 = 2;

#[derive(Debug)]
struct Inner {
    state: AtomicU8,
    deadline: Option<Instant>,
    limit: Option<Duration>,
}

/// A cancellation flag shared by the work and its owner, with an optional
/// time limit. Clones share the flag.
#[derive(Clone, Debug)]
pub struct CancelToken {
    inner: Arc<Inner>,
}

impl Default for CancelToken {
    fn default() -> Self {
        CancelToken::new()
    }
}

impl CancelToken {
    /// A token without a time limit: work stops only once it is cancelled.
    pub fn new() -> CancelToken {
        CancelToken::build(None)
    }

    /// A token whose work stops `limit` from now (or once cancelled).
    pub fn with_limit(limit: Duration) -> CancelToken {
        CancelToken::build(Some(limit))
    }

    fn build(limit: Option<Duration>) -> CancelToken {
        CancelToken {
            inner: Arc::new(Inner {
                state: AtomicU8::new(RUNNING),
                // A limit beyond the clock's range is no limit.
                deadline: limit.and_then(|l| Instant::now().checked_add(l)),
                limit,
            }),
        }
    }

    /// The time limit, if any.
    pub fn limit(&self) -> Option<Duration> {
        self.inner.limit
    }

    /// Stop the work: its next check fails with [`Cancelled::Stopped`]
    /// (unless its time limit ran out first).
    pub fn cancel(&self) {
        let _ = self.inner.state.compare_exchange(
            RUNNING,
            STOPPED,
            Ordering::Relaxed,
            Ordering::Relaxed,
        );
    }

    /// `Err` once the token is cancelled or its time limit has run out.
    #[inline]
    pub fn check(&self) -> Result<(), Cancelled> {
        match self.inner.state.load(Ordering::Relaxed) {
            RUNNING => match self.inner.deadline {
                Some(d) if Instant::now() >= d => {
                    // Remembered, so that later checks skip the clock and a
                    // cancel after the deadline still reads as the timeout.
                    let _ = self.inner.state.compare_exchange(
                        RUNNING,
                        TIMED_OUT,
                        Ordering::Relaxed,
                        Ordering::Relaxed,
                    );
                    self.check()
                }
                _ => Ok(()),
            },
            STOPPED => Err(Cancelled::Stopped),
            _ => Err(Cancelled::TimedOut {
                limit: self.inner.limit.unwrap_or_default(),
            }),
        }
    }

    /// True once [`check`](Self::check) would fail.
    pub fn is_cancelled(&self) -> bool {
        self.check().is_err()
    }

    /// `result`, or the cancellation when it failed once this token was
    /// cancelled: a stage that cannot return [`Cancelled`] stops early with
    /// what it has, and a later one may then fail in its own words.
    pub fn settle<T, E: From<Cancelled>>(&self, result: Result<T, E>) -> Result<T, E> {
        match (result, self.check()) {
            (Err(_), Err(c)) => Err(c.into()),
            (result, _) => result,
        }
    }

    /// A guard that cancels this token when dropped: held by a request's
    /// future, it stops the work when the future is dropped (the client
    /// went away).
    pub fn cancel_on_drop(&self) -> CancelOnDrop {
        CancelOnDrop(self.clone())
    }

    /// Run `f` with this token as the current thread's ([`check`] checks
    /// it); the previous one is restored afterwards, also on a panic.
    pub fn scope<T>(&self, f: impl FnOnce() -> T) -> T {
        struct Restore(Option<CancelToken>);
        impl Drop for Restore {
            fn drop(&mut self) {
                let previous = self.0.take();
                CURRENT.with(|c| *c.borrow_mut() = previous);
            }
        }
        let previous = CURRENT.with(|c| c.replace(Some(self.clone())));
        let _restore = Restore(previous);
        f()
    }
}

/// Cancels its token when dropped (see [`CancelToken::cancel_on_drop`]).
#[derive(Debug)]
pub struct CancelOnDrop(CancelToken);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

thread_local! {
    static CURRENT: RefCell<Option<CancelToken>> = const { RefCell::new(None) };
}

/// Check the current thread's token (see [`CancelToken::scope`]); `Ok`
/// when there is none.
#[inline]
pub fn check() -> Result<(), Cancelled> {
    CURRENT.with(|c| c.borrow().as_ref().map_or(Ok(()), CancelToken::check))
}

/// The current thread's token, to take along to other threads (a fresh,
/// never cancelled one when there is none).
pub fn current() -> CancelToken {
    CURRENT.with(|c| c.borrow().clone()).unwrap_or_default()
}

/// Runs `a` on this thread and `b` on another, side by side, both under
/// the current thread's token. (`a` need not be `Send`: the survey's
/// projection, a PROJ handle, is not.)
pub fn join<A, B: Send>(a: impl FnOnce() -> A, b: impl FnOnce() -> B + Send) -> (A, B) {
    let token = current();
    std::thread::scope(|s| {
        let other = s.spawn(|| token.scope(b));
        let ra = a();
        match other.join() {
            Ok(rb) => (ra, rb),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

/// Checks the current thread's token once every `every` calls of
/// [`tick`](Pacer::tick): for loops whose iterations are too short to check
/// each time.
#[derive(Debug)]
pub struct Pacer {
    every: u32,
    count: u32,
}

impl Pacer {
    /// A check every `every` ticks (at least 1).
    pub fn new(every: u32) -> Pacer {
        Pacer {
            every: every.max(1),
            count: 0,
        }
    }

    /// One more iteration; checks the token every `every` of them.
    #[inline]
    pub fn tick(&mut self) -> Result<(), Cancelled> {
        self.count += 1;
        if self.count >= self.every {
            self.count = 0;
            check()
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cancel_is_seen_by_every_clone_and_stays() {
        let token = CancelToken::new();
        let clone = token.clone();
        assert_eq!(clone.check(), Ok(()));
        assert!(!token.is_cancelled());
        token.cancel();
        assert_eq!(clone.check(), Err(Cancelled::Stopped));
        assert_eq!(token.check(), Err(Cancelled::Stopped));
        token.cancel();
        assert_eq!(clone.check(), Err(Cancelled::Stopped));
        assert_eq!(token.limit(), None);
    }

    #[test]
    fn time_limit_runs_out_and_wins_over_a_later_cancel() {
        let limit = Duration::from_millis(30);
        let token = CancelToken::with_limit(limit);
        assert_eq!(token.limit(), Some(limit));
        assert_eq!(token.check(), Ok(()));
        std::thread::sleep(Duration::from_millis(40));
        assert_eq!(token.check(), Err(Cancelled::TimedOut { limit }));
        token.cancel();
        assert_eq!(token.check(), Err(Cancelled::TimedOut { limit }));
        assert_eq!(
            Cancelled::TimedOut { limit }.to_string(),
            "the work took longer than its time limit of 0.03 s"
        );
        let minute = Cancelled::TimedOut {
            limit: Duration::from_secs(60),
        };
        assert_eq!(
            minute.to_string(),
            "the work took longer than its time limit of 60 s"
        );
        // Cancelled before the deadline: stopped, not timed out.
        let token = CancelToken::with_limit(Duration::from_secs(3600));
        token.cancel();
        assert_eq!(token.check(), Err(Cancelled::Stopped));
        // A limit beyond the clock's range never runs out.
        let far = CancelToken::with_limit(Duration::MAX);
        assert_eq!(far.check(), Ok(()));
    }

    #[test]
    fn settle_reports_a_failure_after_cancelling_as_the_cancellation() {
        #[derive(Debug, PartialEq)]
        enum E {
            Other,
            Cancelled(Cancelled),
        }
        impl From<Cancelled> for E {
            fn from(c: Cancelled) -> E {
                E::Cancelled(c)
            }
        }
        let token = CancelToken::new();
        assert_eq!(token.settle(Err::<(), _>(E::Other)), Err(E::Other));
        token.cancel();
        assert_eq!(
            token.settle(Err::<(), _>(E::Other)),
            Err(E::Cancelled(Cancelled::Stopped))
        );
        // A result that made it is kept.
        assert_eq!(token.settle(Ok::<_, E>(7)), Ok(7));
    }

    #[test]
    fn dropping_the_guard_cancels() {
        let token = CancelToken::new();
        {
            let _guard = token.cancel_on_drop();
            assert_eq!(token.check(), Ok(()));
        }
        assert_eq!(token.check(), Err(Cancelled::Stopped));
    }

    #[test]
    fn scope_sets_the_thread_token_and_restores_the_previous() {
        assert_eq!(check(), Ok(()), "no token: never cancelled");
        let outer = CancelToken::new();
        let inner = CancelToken::new();
        inner.cancel();
        outer.scope(|| {
            assert_eq!(check(), Ok(()));
            inner.scope(|| assert_eq!(check(), Err(Cancelled::Stopped)));
            assert_eq!(check(), Ok(()), "outer token back");
            // Taken along to another thread, where no token is set.
            let taken = current();
            outer.cancel();
            std::thread::spawn(move || {
                assert_eq!(check(), Ok(()));
                assert_eq!(taken.check(), Err(Cancelled::Stopped));
            })
            .join()
            .unwrap();
            assert_eq!(check(), Err(Cancelled::Stopped));
        });
        assert_eq!(check(), Ok(()), "nothing set after the scope");
        // Restored on a panic too.
        let r = std::panic::catch_unwind(|| inner.scope(|| panic!("boom")));
        assert!(r.is_err());
        assert_eq!(check(), Ok(()));
        assert_eq!(current().check(), Ok(()));
    }

    #[test]
    fn pacer_checks_every_nth_tick() {
        let token = CancelToken::new();
        token.cancel();
        token.scope(|| {
            let mut pace = Pacer::new(3);
            assert_eq!(pace.tick(), Ok(()));
            assert_eq!(pace.tick(), Ok(()));
            assert_eq!(pace.tick(), Err(Cancelled::Stopped));
            assert_eq!(pace.tick(), Ok(()));
            let mut every = Pacer::new(0);
            assert_eq!(every.tick(), Err(Cancelled::Stopped));
        });
    }

    /// A survey request over a round field of `vertices` vertices, with a
    /// ring of `zones` round no-fly zones inside it and two UAVs.
    fn round_field(vertices: usize, zones: usize) -> crate::survey::SurveyRequest {
        let ring = |lon: f64, lat: f64, r_m: f64, n: usize| {
            let mut pts: Vec<[f64; 2]> = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    [
                        lon + r_m * a.cos() / (111_320.0 * 51.5f64.to_radians().cos()),
                        lat + r_m * a.sin() / 110_540.0,
                    ]
                })
                .collect();
            pts.push(pts[0]);
            serde_json::json!({"type": "Polygon", "coordinates": [pts]})
        };
        let (lon, lat) = (6.06, 51.5);
        let nfz: Vec<_> = (0..zones)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / zones as f64;
                let (dx, dy) = (300.0 * a.cos(), 300.0 * a.sin());
                ring(
                    lon + dx / (111_320.0 * 51.5f64.to_radians().cos()),
                    lat + dy / 110_540.0,
                    25.0,
                    12,
                )
            })
            .collect();
        let doc = serde_json::json!({
            "roi": ring(lon, lat, 600.0, vertices),
            "no_fly_zones": nfz,
            "altitude_m": 40,
            "uavs": [{"id": "a", "start": [lon, lat]}, {"id": "b", "start": [lon + 0.001, lat]}],
        });
        crate::survey::SurveyRequest::from_document(&doc).expect("a valid request")
    }

    #[test]
    fn planning_calls_answer_a_cancelled_token_with_cancelled() {
        use crate::survey::{PlanError, plan_survey};
        use crate::terrain::test_support::{dem, north_up};
        let req = round_field(64, 4);
        let limits = crate::geo::Limits::default();
        assert!(plan_survey(&req, &limits).is_ok());
        let stopped = CancelToken::new();
        stopped.cancel();
        assert!(matches!(
            stopped.scope(|| plan_survey(&req, &limits)),
            Err(PlanError::Cancelled(Cancelled::Stopped))
        ));
        let zero = CancelToken::with_limit(Duration::ZERO);
        assert!(matches!(
            zero.scope(|| plan_survey(&req, &limits)),
            Err(PlanError::Cancelled(Cancelled::TimedOut { limit })) if limit == Duration::ZERO
        ));
        let d = dem(
            300,
            200,
            (0..60_000).map(|i| f64::from(i % 97)).collect(),
            north_up(0.0, 0.0, 10.0, 10.0),
            false,
        );
        assert!(crate::terrain::hillshade_png(&d, 256).is_ok());
        assert!(crate::terrain::dilate(&d, 50.0).is_ok());
        stopped.scope(|| {
            assert_eq!(
                crate::terrain::hillshade_png(&d, 256),
                Err(Cancelled::Stopped)
            );
            assert_eq!(crate::terrain::dilate(&d, 50.0), Err(Cancelled::Stopped));
        });
    }

    /// Cancelled at any point of its run, a survey stops soon: every stage
    /// checks the token often. The bound is generous (the test may share
    /// the machine); the service promises a free planner within 1 s.
    #[test]
    fn a_survey_cancelled_midway_stops_soon() {
        use crate::survey::{PlanError, plan_survey};
        let req = round_field(3000, 12);
        let limits = crate::geo::Limits::default();
        let began = Instant::now();
        plan_survey(&req, &limits).expect("plans");
        let whole = began.elapsed();
        for tenth in [1u32, 3, 5, 7, 9] {
            let token = CancelToken::new();
            let (req, limits, t) = (req.clone(), limits.clone(), token.clone());
            let run = std::thread::spawn(move || {
                let r = t.scope(|| plan_survey(&req, &limits));
                (r, Instant::now())
            });
            std::thread::sleep(whole * tenth / 10);
            let cancelled_at = Instant::now();
            token.cancel();
            let (r, ended) = run.join().unwrap();
            match r {
                Err(PlanError::Cancelled(Cancelled::Stopped)) => {
                    let late = ended.saturating_duration_since(cancelled_at);
                    assert!(
                        late < Duration::from_secs(2),
                        "stopped {late:?} after the cancel at {tenth}/10 of {whole:?}"
                    );
                }
                // Finished first (the machine was slower the first time).
                Ok(_) => {}
                Err(e) => panic!("{e}"),
            }
        }
    }
}
