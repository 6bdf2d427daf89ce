//! The accept loop and its connections: slow clients cannot hold the
//! server.
//!
//! - HTTP/1.1, served by hyper. A request head must arrive within the
//!   header read timeout, which is also the longest a kept-alive
//!   connection waits for its next request.
//! - A request body must arrive within the body read timeout plus one
//!   second for every `body_min_bytes_per_s` bytes received (Apache's
//!   `mod_reqtimeout` rule: a big upload at a decent rate is never cut, a
//!   trickle is); a late body is answered 408 and its connection closed.
//! - At most `max_connections` sockets are open at once, kept below the
//!   process' file limit. When all are taken, the oldest connection
//!   without a request in hand (waiting for a request head, or lingering
//!   after its answer) is closed to make room, else the oldest whose
//!   request body arrives slower than the minimum rate, so a crowd of slow
//!   or idle clients cannot lock healthy ones out.
//! - An accept that fails for want of file descriptors (EMFILE, ENFILE)
//!   is retried after a pause instead of ending the loop.
//! - hyper's own answers to requests it cannot parse (400, 414 URI too
//!   long, 431 header too large) are rewritten as problem+json.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, ready};
use std::time::Duration;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::http::{HeaderValue, Request, Response, StatusCode, header};
use axum::response::IntoResponse;
use http_body::{Frame, SizeHint};
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc, watch};
use tokio::time::{Instant, Sleep};
use tower::ServiceExt;

use crate::conn_state::{Activity, Busy, ConnState, lock};
use crate::error::ApiError;
use crate::linger::LingeringStream;

/// How long clients may take, and how many may be connected.
#[derive(Clone, Debug)]
pub struct ConnLimits {
    /// Longest wait for a request head (and between kept-alive requests).
    pub header_read_timeout: Duration,
    /// Time a request body may take, before the allowance for its size.
    pub body_read_timeout: Duration,
    /// Each this many bytes of body received give one more second; 0
    /// gives none (a body must arrive whole within the timeout).
    pub body_min_bytes_per_s: u64,
    /// Sockets open at once, lingering ones included.
    pub max_connections: usize,
}

/// Descriptors kept free for everything but client sockets: the
/// database (SQLite's file, WAL and shared memory per pooled connection,
/// or PostgreSQL's sockets), stored and temporary files, the runtime.
pub fn reserved_descriptors(file_limit: u64) -> u64 {
    (file_limit / 8).clamp(64, 1024).min(file_limit / 2)
}

/// More client sockets than this are never open by default, whatever
/// the file limit: each holds buffers.
pub const MAX_DEFAULT_CONNECTIONS: u64 = 16_384;

/// The default connection limit under a file limit of `file_limit`.
pub fn default_max_connections(file_limit: u64) -> usize {
    let room = file_limit
        .saturating_sub(reserved_descriptors(file_limit))
        .clamp(1, MAX_DEFAULT_CONNECTIONS);
    usize::try_from(room).unwrap_or(usize::MAX)
}

/// The process' soft limit on open files (`RLIMIT_NOFILE`); `None` when
/// it cannot be read or is unlimited.
pub fn file_limit() -> Option<u64> {
    #[cfg(unix)]
    {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit writes into the struct it is given and
        // touches nothing else.
        let ok = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &raw mut lim) } == 0;
        (ok && lim.rlim_cur != libc::RLIM_INFINITY).then_some(lim.rlim_cur)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// The open connections, oldest first, and the slots they take.
struct Registry {
    slots: Arc<Semaphore>,
    open: Mutex<BTreeMap<u64, Arc<ConnState>>>,
    next_id: AtomicU64,
    /// An idle connection younger than this is not closed to make room:
    /// its client may be sending its request right now.
    grace: Duration,
    /// `--body-min-bytes-per-s`: a body behind it may be closed to make
    /// room (it would time out anyway).
    min_rate: u64,
}

/// A connection's place under the limit, held until its socket closes.
pub struct Slot {
    id: u64,
    state: Arc<ConnState>,
    registry: Arc<Registry>,
    _permit: OwnedSemaphorePermit,
}

impl Slot {
    pub fn state(&self) -> &Arc<ConnState> {
        &self.state
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        lock(&self.registry.open).remove(&self.id);
    }
}

impl Registry {
    fn new(max_connections: usize, grace: Duration, min_rate: u64) -> Arc<Registry> {
        Arc::new(Registry {
            slots: Arc::new(Semaphore::new(max_connections.max(1))),
            open: Mutex::new(BTreeMap::new()),
            next_id: AtomicU64::new(0),
            grace,
            min_rate,
        })
    }

    fn open(self: &Arc<Self>, permit: OwnedSemaphorePermit) -> Slot {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let state = Arc::new(ConnState::new());
        lock(&self.open).insert(id, state.clone());
        Slot {
            id,
            state,
            registry: self.clone(),
            _permit: permit,
        }
    }

    /// Close a connection to make room: the oldest that has had no
    /// request in hand for the grace period, else the oldest whose request
    /// body arrives slower than the minimum rate (it would time out
    /// anyway); false when there is none.
    fn evict_one(&self) -> bool {
        let open = lock(&self.open);
        let idle = |a: &Activity| a.in_flight == 0 && a.idle_since.elapsed() >= self.grace;
        let crawling = |a: &Activity| a.crawling(self.min_rate, self.grace);
        let pick = |rule: &dyn Fn(&Activity) -> bool| {
            open.values().find(|state| {
                let a = state.activity();
                !a.evicted && rule(&a)
            })
        };
        let Some(state) = pick(&idle).or_else(|| pick(&crawling)) else {
            return false;
        };
        state.evict();
        true
    }

    /// A free slot, closing idle connections to make one when all are
    /// taken.
    async fn slot(self: &Arc<Self>) -> Slot {
        if let Ok(permit) = self.slots.clone().try_acquire_owned() {
            return self.open(permit);
        }
        loop {
            // Connections turn idle (an answer sent) while this waits:
            // look again now and then.
            self.evict_one();
            tokio::select! {
                permit = self.slots.clone().acquire_owned() => {
                    // The semaphore is never closed.
                    if let Ok(permit) = permit {
                        return self.open(permit);
                    }
                }
                () = tokio::time::sleep(EVICT_RETRY) => {}
            }
        }
    }
}

/// An idle connection younger than this is not closed to make room. A
/// client sends its request as soon as it is connected, so it has
/// normally arrived by then; a server that is full closes the slowest.
const EVICT_GRACE: Duration = Duration::from_millis(100);
/// At shutdown, a request body is judged against the minimum rate after
/// this long (a full server judges it after the eviction grace): a body
/// that lags a little behind its head (a loaded client, the network) is
/// not crawling, and its request is finished.
const CRAWL_GRACE: Duration = Duration::from_secs(1);
/// How often a full server looks again for an idle connection to close.
const EVICT_RETRY: Duration = Duration::from_millis(25);
/// Pause after an accept failed for want of descriptors or memory.
const ACCEPT_RETRY: Duration = Duration::from_millis(50);

/// Serve `app` on `listener` until `shutdown` resolves, then stop
/// accepting and wait for the open connections' requests to finish.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()> + Send,
) {
    let limits = Arc::new(limits);
    let grace = (limits.header_read_timeout / 2).min(EVICT_GRACE);
    let registry = Registry::new(limits.max_connections, grace, limits.body_min_bytes_per_s);
    let (stop_tx, stop_rx) = watch::channel(false);
    // Every connection task holds a sender: when all are dropped, every
    // connection has ended.
    let (done_tx, mut done_rx) = mpsc::channel::<()>(1);
    let mut short_of_descriptors = false;
    tokio::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            biased;
            () = &mut shutdown => break,
            r = listener.accept() => r,
        };
        let (stream, peer) = match accepted {
            Ok((stream, peer)) => {
                short_of_descriptors = false;
                (stream, peer)
            }
            Err(e) if is_connection_error(&e) => continue,
            Err(e) => {
                // EMFILE, ENFILE, ENOBUFS, ENOMEM: the waiting client stays
                // in the backlog; make room and try again shortly.
                if !short_of_descriptors {
                    tracing::warn!(error = %e, "cannot accept a connection: retrying");
                    short_of_descriptors = true;
                }
                // A connection closed frees its descriptor at once.
                let pause = if registry.evict_one() {
                    Duration::from_millis(1)
                } else {
                    ACCEPT_RETRY
                };
                tokio::select! {
                    () = &mut shutdown => break,
                    () = tokio::time::sleep(pause) => continue,
                }
            }
        };
        let _ = stream.set_nodelay(true);
        let slot = tokio::select! {
            biased;
            () = &mut shutdown => break,
            slot = registry.slot() => slot,
        };
        let conn = serve_connection(
            stream,
            peer,
            slot,
            app.clone(),
            limits.clone(),
            stop_rx.clone(),
        );
        let done = done_tx.clone();
        tokio::spawn(async move {
            conn.await;
            drop(done);
        });
    }
    drop(listener);
    let _ = stop_tx.send(true);
    drop(done_tx);
    let _ = done_rx.recv().await;
}

/// Errors of one connection, not of the listener (as hyper and axum
/// tell them apart).
fn is_connection_error(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionRefused
            | io::ErrorKind::ConnectionAborted
            | io::ErrorKind::ConnectionReset
    )
}

/// Serve one connection until it ends, is closed to make room, or the
/// server stops (then gracefully: the request in hand is answered).
async fn serve_connection(
    stream: TcpStream,
    peer: std::net::SocketAddr,
    slot: Slot,
    app: Router,
    limits: Arc<ConnLimits>,
    mut stop: watch::Receiver<bool>,
) {
    let state = slot.state().clone();
    let io = TokioIo::new(ParseErrorAnswers::new(LingeringStream::new(
        stream,
        state.clone(),
        slot,
    )));
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout);
    let min_rate = limits.body_min_bytes_per_s;
    let service_state = state.clone();
    let service = hyper::service::service_fn(move |mut req: Request<Incoming>| {
        // The client's address, for the rate limits by address.
        req.extensions_mut()
            .insert(axum::extract::ConnectInfo(peer));
        let app = app.clone();
        let limits = limits.clone();
        let state = service_state.clone();
        async move { Ok::<_, Infallible>(answer(app, &limits, &state, req).await) }
    });
    let conn = builder.serve_connection(io, service);
    tokio::pin!(conn);
    let mut stopping = false;
    loop {
        tokio::select! {
            r = conn.as_mut() => {
                if let Err(e) = r {
                    if e.is_timeout() {
                        state.set_timed_out();
                    }
                    tracing::debug!(error = %e, "connection ended");
                }
                break;
            }
            () = state.evicted() => {
                tracing::debug!("idle connection closed to make room for another");
                break;
            }
            _ = stop.wait_for(|s| *s), if !stopping => {
                // No request in hand (idle, or its head still coming), or
                // one whose body crawls in: nothing to finish (hyper would
                // wait for a head begun, a handler for its body).
                let a = state.activity();
                if a.in_flight == 0 || a.crawling(min_rate, CRAWL_GRACE) {
                    break;
                }
                drop(a);
                stopping = true;
                conn.as_mut().graceful_shutdown();
            }
        }
    }
}

/// One request: its body timed, its answer holding the connection busy
/// until sent.
async fn answer(
    app: Router,
    limits: &ConnLimits,
    conn: &Arc<ConnState>,
    req: Request<Incoming>,
) -> Response<Body> {
    let busy = conn.begin_request();
    let clock = Arc::new(BodyClock::default());
    let req = req.map(|body| {
        Body::new(TimedBody::new(
            body,
            limits.body_read_timeout,
            limits.body_min_bytes_per_s,
            clock.clone(),
            conn.clone(),
        ))
    });
    let mut res = app.oneshot(req).await.unwrap_or_else(|e| match e {});
    if let Some((received, waited)) = clock.expired() {
        // Whatever the handler made of the failed read, the answer is
        // that the client was too slow.
        conn.set_timed_out();
        let allowance = if limits.body_min_bytes_per_s > 0 {
            format!(
                " plus 1 s per {} bytes received",
                limits.body_min_bytes_per_s
            )
        } else {
            String::new()
        };
        res = ApiError::RequestTimeout(format!(
            "the request body arrived too slowly: {received} bytes in {:.1} s; a body may take \
             {:.1} s{allowance}",
            waited.as_secs_f64(),
            limits.body_read_timeout.as_secs_f64()
        ))
        .into_response();
        res.headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
    }
    res.map(|body| {
        Body::new(Tracked {
            inner: body,
            _busy: busy,
        })
    })
}

/// An answer's body; the connection has a request in hand until it is
/// sent or dropped.
struct Tracked {
    inner: Body,
    _busy: Busy,
}

impl http_body::Body for Tracked {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        Pin::new(&mut self.inner).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

/// What a [`TimedBody`] tells its request's handler about a timeout.
#[derive(Default)]
struct BodyClock {
    expired: AtomicBool,
    received: AtomicU64,
    waited_ms: AtomicU64,
}

impl BodyClock {
    /// Bytes received and time waited, when the body timed out.
    fn expired(&self) -> Option<(u64, Duration)> {
        self.expired.load(Ordering::Acquire).then(|| {
            (
                self.received.load(Ordering::Relaxed),
                Duration::from_millis(self.waited_ms.load(Ordering::Relaxed)),
            )
        })
    }
}

/// A request body that must arrive by a deadline: `timeout` after it is
/// first read, plus one second per `min_rate` bytes received. Only a
/// read that has to wait for the client can time out: a body the server
/// is slow to read is not the client's fault.
struct TimedBody {
    inner: Incoming,
    timeout: Duration,
    min_rate: u64,
    started: Option<Instant>,
    received: u64,
    deadline: Pin<Box<Sleep>>,
    clock: Arc<BodyClock>,
    /// Told the body's progress, so that a full server can close the
    /// connection of a crawling body first.
    conn: Arc<ConnState>,
}

impl TimedBody {
    fn new(
        inner: Incoming,
        timeout: Duration,
        min_rate: u64,
        clock: Arc<BodyClock>,
        conn: Arc<ConnState>,
    ) -> Self {
        TimedBody {
            inner,
            timeout,
            min_rate,
            started: None,
            received: 0,
            deadline: Box::pin(tokio::time::sleep(timeout)),
            clock,
            conn,
        }
    }

    fn deadline_after(&self, started: Instant) -> Instant {
        // No allowance at a minimum rate of 0.
        let allowance = Duration::from_millis(
            self.received
                .saturating_mul(1000)
                .checked_div(self.min_rate)
                .unwrap_or(0),
        );
        let far = Duration::from_secs(365 * 86_400);
        started + (self.timeout + allowance).min(far)
    }
}

impl http_body::Body for TimedBody {
    type Data = Bytes;
    type Error = Box<dyn std::error::Error + Send + Sync>;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
        let this = &mut *self;
        let started = match this.started {
            Some(t) => t,
            None => {
                let now = Instant::now();
                this.started = Some(now);
                let deadline = this.deadline_after(now);
                this.deadline.as_mut().reset(deadline);
                this.conn.set_body(Some((now, 0)));
                now
            }
        };
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => {
                if let Some(data) = frame.data_ref() {
                    this.received += data.len() as u64;
                    let deadline = this.deadline_after(started);
                    this.deadline.as_mut().reset(deadline);
                    this.conn.set_body(Some((started, this.received)));
                }
                Poll::Ready(Some(Ok(frame)))
            }
            Poll::Ready(Some(Err(e))) => {
                this.conn.set_body(None);
                Poll::Ready(Some(Err(e.into())))
            }
            Poll::Ready(None) => {
                this.conn.set_body(None);
                Poll::Ready(None)
            }
            Poll::Pending => {
                ready!(this.deadline.as_mut().poll(cx));
                let waited = started.elapsed();
                this.clock.received.store(this.received, Ordering::Relaxed);
                this.clock.waited_ms.store(
                    u64::try_from(waited.as_millis()).unwrap_or(u64::MAX),
                    Ordering::Relaxed,
                );
                this.clock.expired.store(true, Ordering::Release);
                this.conn.set_body(None);
                Poll::Ready(Some(Err(Box::new(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "the request body arrived too slowly",
                )))))
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

impl Drop for TimedBody {
    fn drop(&mut self) {
        if self.started.is_some() {
            self.conn.set_body(None);
        }
    }
}

/// A connection whose writes pass through, except hyper's own answers to
/// requests it could not parse (a bare head, `content-length: 0`, status
/// 400, 414 or 431), which become problem+json answers. The
/// application's answers always have a body, so they never match.
pub struct ParseErrorAnswers<S> {
    inner: S,
    /// A replacement answer, and how much of it is written.
    pending: Option<(Vec<u8>, usize)>,
}

impl<S> ParseErrorAnswers<S> {
    pub fn new(inner: S) -> Self {
        ParseErrorAnswers {
            inner,
            pending: None,
        }
    }
}

impl<S: AsyncWrite + Unpin> ParseErrorAnswers<S> {
    /// Write out the replacement answer, if there is one.
    fn poll_pending(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while let Some((bytes, written)) = &mut self.pending {
            if *written == bytes.len() {
                self.pending = None;
                break;
            }
            let n = ready!(Pin::new(&mut self.inner).poll_write(cx, &bytes[*written..]))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            *written += n;
        }
        Poll::Ready(Ok(()))
    }

    /// Take `head` (all of what hyper writes, `len` bytes) as written
    /// and send its replacement instead.
    fn replace(
        &mut self,
        cx: &mut Context<'_>,
        answer: Vec<u8>,
        len: usize,
    ) -> Poll<io::Result<usize>> {
        self.pending = Some((answer, 0));
        match self.poll_pending(cx) {
            // The rest goes out on hyper's flush, which always follows.
            Poll::Ready(Ok(())) | Poll::Pending => Poll::Ready(Ok(len)),
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
        }
    }
}

/// The problem+json answer replacing `head`, when `head` is hyper's own
/// answer to a request it could not parse.
pub fn parse_error_answer(head: &[u8]) -> Option<Vec<u8>> {
    let (status, detail) = if head.starts_with(b"HTTP/1.1 400 ") {
        (
            StatusCode::BAD_REQUEST,
            "the request is not valid HTTP/1.1: its request line or a header field is malformed",
        )
    } else if head.starts_with(b"HTTP/1.1 414 ") {
        (
            StatusCode::URI_TOO_LONG,
            "the request's URI is too long: at most 65534 bytes",
        )
    } else if head.starts_with(b"HTTP/1.1 431 ") {
        (
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "the request's header is too large: at most 100 header fields and about 400 KiB \
             in all",
        )
    } else {
        return None;
    };
    let text = std::str::from_utf8(head).ok()?;
    let fields = text.strip_suffix("\r\n\r\n")?;
    let mut lines = fields.split("\r\n");
    let status_line = lines.next()?;
    let mut declared_empty = false;
    let mut kept = Vec::new();
    for line in lines {
        let (name, value) = line.split_once(':')?;
        if name.eq_ignore_ascii_case("content-length") {
            declared_empty = value.trim() == "0";
        } else if !name.eq_ignore_ascii_case("content-type") {
            kept.push(line);
        }
    }
    if !declared_empty {
        return None;
    }
    let body = crate::error::problem_body(status, detail.to_string());
    let mut out = format!(
        "{status_line}\r\ncontent-type: {}\r\ncontent-length: {}\r\n",
        crate::error::PROBLEM_JSON,
        body.len()
    );
    for line in kept {
        out.push_str(line);
        out.push_str("\r\n");
    }
    out.push_str("\r\n");
    let mut out = out.into_bytes();
    out.extend_from_slice(&body);
    Some(out)
}

impl<S: AsyncRead + Unpin> AsyncRead for ParseErrorAnswers<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for ParseErrorAnswers<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = &mut *self;
        ready!(this.poll_pending(cx))?;
        if let Some(answer) = parse_error_answer(buf) {
            return this.replace(cx, answer, buf.len());
        }
        Pin::new(&mut this.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = &mut *self;
        ready!(this.poll_pending(cx))?;
        let mut parts = bufs.iter().filter(|b| !b.is_empty());
        if let (Some(first), None) = (parts.next(), parts.next())
            && let Some(answer) = parse_error_answer(first)
        {
            return this.replace(cx, answer, first.len());
        }
        Pin::new(&mut this.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_pending(cx))?;
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_pending(cx))?;
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_limit_leaves_room_for_files() {
        // The common soft limit: 128 descriptors kept, 896 for clients.
        assert_eq!(reserved_descriptors(1024), 128);
        assert_eq!(default_max_connections(1024), 896);
        // Small limits keep at least 64, or half.
        assert_eq!(default_max_connections(256), 192);
        assert_eq!(default_max_connections(100), 50);
        assert_eq!(default_max_connections(1), 1);
        // Large ones keep 1024, and clients are capped.
        assert_eq!(default_max_connections(65_536), 16_384);
        assert_eq!(default_max_connections(10_000), 10_000 - 1024);
    }

    #[test]
    fn the_file_limit_is_read() {
        let limit = file_limit().expect("a test process has a finite RLIMIT_NOFILE");
        assert!(limit >= 16, "{limit}");
    }

    /// hyper's answer to a request with too many header fields.
    const HYPER_431: &[u8] = b"HTTP/1.1 431 Request Header Fields Too Large\r\nconnection: \
        close\r\ncontent-length: 0\r\ndate: Thu, 26 Nov 2026 08:06:48 GMT\r\n\r\n";

    #[test]
    fn hyper_parse_errors_become_problems() {
        let answer = parse_error_answer(HYPER_431).expect("replaced");
        let text = String::from_utf8(answer).unwrap();
        let (head, body) = text.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 431 Request Header Fields Too Large\r\n"));
        assert!(head.contains("\r\ncontent-type: application/problem+json\r\n"));
        assert!(head.contains(&format!("\r\ncontent-length: {}\r\n", body.len())));
        // hyper's other fields are kept.
        assert!(head.contains("\r\nconnection: close\r\n") && head.contains("\r\ndate: Thu"));
        let problem: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(problem["status"], 431);
        assert_eq!(problem["title"], "Request Header Fields Too Large");
        assert!(
            problem["detail"]
                .as_str()
                .unwrap()
                .contains("100 header fields"),
            "{problem}"
        );
        for status in ["400 Bad Request", "414 URI Too Long"] {
            let head = format!("HTTP/1.1 {status}\r\ncontent-length: 0\r\n\r\n");
            let answer = parse_error_answer(head.as_bytes()).expect(status);
            assert!(String::from_utf8(answer).unwrap().contains("\"status\":"));
        }
    }

    #[test]
    fn the_applications_answers_pass_through() {
        // A problem the application made: it has a body.
        let own = b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/problem+json\r\n\
            content-length: 80\r\n\r\n";
        assert!(parse_error_answer(own).is_none());
        // Other statuses, a head with its body, body bytes.
        assert!(parse_error_answer(b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n").is_none());
        assert!(parse_error_answer(b"HTTP/1.1 431 X\r\ncontent-length: 0\r\n\r\n{}").is_none());
        assert!(parse_error_answer(b"HTTP/1.1 414 URI Too Long and more").is_none());
    }

    /// A replacement the socket takes in pieces is still written whole,
    /// and what follows it goes out after it.
    #[tokio::test]
    async fn a_replacement_is_written_whole_through_short_writes() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let (client, server) = tokio::io::duplex(7);
        let mut w = ParseErrorAnswers::new(server);
        let reader = tokio::spawn(async move {
            let mut client = client;
            let mut all = Vec::new();
            client.read_to_end(&mut all).await.unwrap();
            all
        });
        let n = w.write(HYPER_431).await.unwrap();
        assert_eq!(n, HYPER_431.len(), "hyper's head counts as written");
        w.write_all(b"after").await.unwrap();
        w.shutdown().await.unwrap();
        drop(w);
        let all = String::from_utf8(reader.await.unwrap()).unwrap();
        let expected = String::from_utf8(parse_error_answer(HYPER_431).unwrap()).unwrap();
        assert_eq!(all, format!("{expected}after"));
    }
}
