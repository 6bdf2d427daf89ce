//! What the accept loop, a connection's tasks and its lingering close
//! share about one connection: its requests in hand, the body being read,
//! and whether it timed out or was closed to make room.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::time::Instant;

pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // The state guarded holds no invariant a panic could break half-way.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// What the accept loop and a connection's tasks share about it.
pub struct ConnState {
    inner: Mutex<Activity>,
    evict: Notify,
    /// Ended by a read timeout: there is little point lingering.
    timed_out: AtomicBool,
}

pub struct Activity {
    /// Requests whose answers are not yet sent.
    pub in_flight: usize,
    /// When it last had no request in hand.
    pub idle_since: Instant,
    /// The request body being read: when its reading began, and the
    /// bytes received so far.
    body: Option<(Instant, u64)>,
    pub evicted: bool,
}

impl Activity {
    /// Its request body has been read for `grace` at least, and has come
    /// slower than `min_rate` bytes/s.
    pub fn crawling(&self, min_rate: u64, grace: Duration) -> bool {
        self.body.is_some_and(|(started, received)| {
            let t = started.elapsed();
            min_rate > 0
                && t >= grace
                && u128::from(received) * 1000 < u128::from(min_rate) * t.as_millis()
        })
    }
}

impl ConnState {
    pub fn new() -> ConnState {
        ConnState {
            inner: Mutex::new(Activity {
                in_flight: 0,
                idle_since: Instant::now(),
                body: None,
                evicted: false,
            }),
            evict: Notify::new(),
            timed_out: AtomicBool::new(false),
        }
    }

    pub fn begin_request(self: &Arc<Self>) -> Busy {
        lock(&self.inner).in_flight += 1;
        Busy(self.clone())
    }

    /// What it is doing, locked.
    pub fn activity(&self) -> MutexGuard<'_, Activity> {
        lock(&self.inner)
    }

    /// Close it to make room for another connection.
    pub fn evict(&self) {
        lock(&self.inner).evicted = true;
        self.evict.notify_waiters();
    }

    /// Closed to make room for another connection.
    pub fn is_evicted(&self) -> bool {
        lock(&self.inner).evicted
    }

    /// Resolves once the connection is closed to make room.
    pub async fn evicted(&self) {
        loop {
            let notified = self.evict.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            if self.is_evicted() {
                return;
            }
            notified.await;
        }
    }

    /// A header or body read timed out on it.
    pub fn timed_out(&self) -> bool {
        self.timed_out.load(Ordering::Acquire)
    }

    pub fn set_timed_out(&self) {
        self.timed_out.store(true, Ordering::Release);
    }

    pub fn set_body(&self, body: Option<(Instant, u64)>) {
        lock(&self.inner).body = body;
    }
}

/// A request in hand, until its answer is sent (or dropped).
pub struct Busy(Arc<ConnState>);

impl Drop for Busy {
    fn drop(&mut self) {
        let mut a = lock(&self.0.inner);
        a.in_flight -= 1;
        if a.in_flight == 0 {
            a.idle_since = Instant::now();
        }
    }
}
