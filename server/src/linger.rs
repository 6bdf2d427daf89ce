//! Lingering close (RFC 9112 §9.6, as nginx and Apache do it): a
//! connection hyper ends is half-closed, and what the client still sends
//! is read and thrown away for a while before the socket is closed.
//!
//! hyper answers as soon as the handler does, and a refusal from the
//! headers alone (413 from the Content-Length, 415 from the Content-Type)
//! leaves the body unread. Closing a socket with unread data makes the
//! kernel send a reset, and a reset can reach the client while it is still
//! sending: it then reports "connection reset" or "broken pipe" instead of
//! the answer. With the lingering close the client sees the answer and
//! the end of the stream, stops sending and closes; the server's read then
//! ends, and so does the connection.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::TcpStream;

use crate::conn_state::ConnState;

/// Longest a closing connection is read from in all (nginx's
/// `lingering_time`).
const LINGER_TOTAL: Duration = Duration::from_secs(30);
/// Longest a closing connection may stay silent before it is closed
/// (nginx's `lingering_timeout`).
const LINGER_IDLE: Duration = Duration::from_secs(5);
/// The same for a connection whose client was too slow (a read timed
/// out): long enough to read a 408 already sent, no longer.
const TIMED_OUT_LINGER_TOTAL: Duration = Duration::from_secs(2);
const TIMED_OUT_LINGER_IDLE: Duration = Duration::from_secs(1);

/// A connection that, when dropped, lingers in a task of its own; its
/// place under the connection limit (`slot`, dropped to give it back) is
/// held until the socket closes.
pub struct LingeringStream {
    stream: Option<TcpStream>,
    slot: Option<(Arc<ConnState>, Box<dyn Send>)>,
}

impl LingeringStream {
    pub fn new(
        stream: TcpStream,
        state: Arc<ConnState>,
        slot: impl Send + 'static,
    ) -> LingeringStream {
        LingeringStream {
            stream: Some(stream),
            slot: Some((state, Box::new(slot))),
        }
    }

    fn stream(&mut self) -> &mut TcpStream {
        self.stream
            .as_mut()
            .expect("a stream is only taken when dropped")
    }
}

impl AsyncRead for LingeringStream {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(self.stream()).poll_read(cx, buf)
    }
}

impl AsyncWrite for LingeringStream {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(self.stream()).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(self.stream()).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(self.stream()).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(self.stream()).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.as_ref().is_some_and(|s| s.is_write_vectored())
    }
}

impl Drop for LingeringStream {
    fn drop(&mut self) {
        let (Some(stream), Some((state, slot))) = (self.stream.take(), self.slot.take()) else {
            return;
        };
        // Closed to make room: at once.
        if state.is_evicted() {
            return;
        }
        let (total, idle) = if state.timed_out() {
            (TIMED_OUT_LINGER_TOTAL, TIMED_OUT_LINGER_IDLE)
        } else {
            (LINGER_TOTAL, LINGER_IDLE)
        };
        // Outside a runtime (never, in the server) the socket just closes.
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(async move {
                tokio::select! {
                    () = linger(stream, total, idle) => {},
                    // A full server may close a lingering connection early.
                    () = state.evicted() => {},
                }
                drop(slot);
            });
        }
    }
}

/// Half-close `stream`, then read and discard until the client closes,
/// stays silent for `idle`, fails, or `total` has passed; then close.
pub async fn linger(mut stream: TcpStream, total: Duration, idle: Duration) {
    // The answer is already written; this sends the end of the stream
    // after it (hyper may have done so already).
    let _ = stream.shutdown().await;
    let mut sink = vec![0u8; 64 * 1024];
    let _ = tokio::time::timeout(total, async {
        while let Ok(Ok(n)) = tokio::time::timeout(idle, stream.read(&mut sink)).await {
            if n == 0 {
                break;
            }
        }
    })
    .await;
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};

    use tokio::net::TcpListener;

    use super::*;

    /// A client sending a body the server never reads gets the answer and
    /// the end of the stream, not a reset, and its whole body is taken
    /// (read and discarded) while it sends.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_client_reads_the_answer_and_finishes_sending() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        // 32 MiB: more than the socket buffers of both ends hold.
        const BODY: usize = 32 * 1024 * 1024;
        let client = tokio::task::spawn_blocking(move || {
            let mut s = std::net::TcpStream::connect(addr).unwrap();
            let mut r = s.try_clone().unwrap();
            let reader = std::thread::spawn(move || {
                let mut answer = Vec::new();
                r.read_to_end(&mut answer).map(|_| answer)
            });
            let head = format!("POST / HTTP/1.1\r\nContent-Length: {BODY}\r\n\r\n");
            let written = s
                .write_all(head.as_bytes())
                .and_then(|()| s.write_all(&vec![1u8; BODY]));
            drop(s.shutdown(std::net::Shutdown::Write));
            (written, reader.join().unwrap())
        });
        let (mut stream, _) = listener.accept().await.unwrap();
        let mut head = [0u8; 16];
        stream.read_exact(&mut head).await.unwrap();
        stream
            .write_all(
                b"HTTP/1.1 413 Payload Too Large\r\nconnection: close\r\ncontent-length: 0\r\n\r\n",
            )
            .await
            .unwrap();
        linger(stream, Duration::from_secs(60), Duration::from_secs(60)).await;
        let (written, answer) = client.await.unwrap();
        written.expect("the whole body was taken, with no reset");
        let answer = String::from_utf8(answer.expect("no reset")).unwrap();
        assert!(answer.starts_with("HTTP/1.1 413 "), "{answer}");
    }

    /// A client that stops sending without closing is given up on after
    /// the idle time.
    #[tokio::test]
    async fn a_silent_client_is_given_up_on() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let _client = TcpStream::connect(addr).await.unwrap();
        let (stream, _) = listener.accept().await.unwrap();
        let t = std::time::Instant::now();
        linger(stream, Duration::from_secs(60), Duration::from_millis(200)).await;
        let waited = t.elapsed();
        assert!(
            waited >= Duration::from_millis(200) && waited < Duration::from_secs(30),
            "{waited:?}"
        );
    }
}
