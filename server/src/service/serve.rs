//! Serving the router over TCP (HTTP/1.1, hyper): the connection cap, the
//! header and idle keep-alive timeouts, and graceful shutdown with an
//! enforced deadline. (The body timeouts are in `extract::read_body`, where
//! bodies are read.)
//!
//! Every connection has a watchdog that sees three things: whether a
//! request is being handled (its handler called and not yet answered), when
//! bytes last moved either way, and when the first byte of the next request
//! head arrived. With no request being handled, a connection is closed when
//!
//! - a request head has been arriving for longer than `header_timeout`
//!   (a client trickling its headers), or
//! - no byte has moved for `idle_timeout` (an idle keep-alive connection, a
//!   client that connects and sends nothing, or one that stops reading its
//!   answer).
//!
//! A client over the cap (`max_connections` open at once) gets a 503
//! `saturated` answer on a connection that is then closed.

use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::Body;
use axum::http::{Request, Response};
use hyper::body::Incoming;
use hyper_util::rt::TokioIo;
use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, watch};
use tower::ServiceExt as _;

use crate::config::ConnectionLimits;
use crate::jobs::Reason;
use crate::routes::app;
use crate::state::AppState;

/// How a shutdown ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drained {
    /// Every request in flight finished within the drain timeout.
    Clean,
    /// The drain timeout passed: these connections were still open (their
    /// requests cut short) and these bindings were cancelled.
    CutShort { connections: usize, bindings: usize },
}

/// Serves `app(state)` on `listener` until `shutdown` resolves, then stops
/// accepting connections, closes idle ones, lets requests in flight finish
/// for at most the drain timeout, and at that deadline cancels the bindings
/// still computing and returns [`Drained::CutShort`] (the caller should
/// exit without waiting for them).
pub async fn run(
    listener: TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> io::Result<Drained> {
    let config = state.config().clone();
    let limits = config.connections;
    let max = limits.max_connections.clamp(1, Semaphore::MAX_PERMITS);
    let open = Arc::new(Semaphore::new(max));
    let (stop_tx, stop_rx) = watch::channel(false);
    let router = app(state.clone());
    let upkeep = {
        let metrics = state.inner.metrics.clone();
        tokio::spawn(async move {
            let mut every = tokio::time::interval(Duration::from_secs(5));
            loop {
                every.tick().await;
                metrics.upkeep();
            }
        })
    };
    tokio::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            () = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok(x) => x,
                Err(e) => {
                    // Out of file descriptors and the like: wait, do not exit.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        let _ = stream.set_nodelay(true);
        match open.clone().try_acquire_owned() {
            Ok(permit) => {
                let router = router.clone();
                let stop = stop_rx.clone();
                tokio::spawn(async move {
                    serve_connection(stream, router, limits, stop).await;
                    drop(permit);
                });
            }
            Err(_) => {
                state.inner.metrics.connections_refused.increment(1);
                tracing::warn!(%peer, max, "connection refused: too many connections open");
                tokio::spawn(refuse(stream, max));
            }
        }
    }
    drop(listener);
    let drain = config.drain_timeout;
    tracing::info!(drain_timeout_s = drain.as_secs_f64(), "shutting down: draining requests in flight");
    state.set_draining();
    let _ = stop_tx.send(true);
    let all = u32::try_from(max).unwrap_or(u32::MAX);
    let outcome = match tokio::time::timeout(drain, open.acquire_many(all)).await {
        Ok(_) => Drained::Clean,
        Err(_) => {
            let connections = max - open.available_permits();
            let bindings = state.inner.jobs.cancel_all(Reason::Shutdown);
            state.inner.bakes.cancel_all(Reason::Shutdown);
            tracing::warn!(connections, bindings, "drain timeout reached: cutting short what is still running");
            Drained::CutShort { connections, bindings }
        }
    };
    upkeep.abort();
    Ok(outcome)
}

/// Serves one connection until it ends, its watchdog closes it, or (after
/// `stop`) it finishes its request in flight.
async fn serve_connection(
    stream: TcpStream,
    router: Router,
    limits: ConnectionLimits,
    mut stop: watch::Receiver<bool>,
) {
    let activity = Arc::new(Activity::new());
    let io = TokioIo::new(Tracked { inner: stream, activity: activity.clone() });
    let service = Handler { router, activity: activity.clone() };
    let conn = hyper::server::conn::http1::Builder::new().keep_alive(true).serve_connection(io, service);
    tokio::pin!(conn);
    let tick =
        (limits.header_timeout.min(limits.idle_timeout) / 4).clamp(Duration::from_millis(20), Duration::from_secs(1));
    let mut stopping = *stop.borrow();
    if stopping {
        conn.as_mut().graceful_shutdown();
    }
    loop {
        tokio::select! {
            r = conn.as_mut() => {
                if let Err(e) = r {
                    tracing::debug!(error = %e, "connection ended with an error");
                }
                return;
            }
            changed = stop.changed(), if !stopping => {
                stopping = true;
                if changed.is_ok() {
                    conn.as_mut().graceful_shutdown();
                }
            }
            () = tokio::time::sleep(tick) => {
                if let Some(why) = activity.expired(&limits) {
                    tracing::info!(reason = why, "closing a connection");
                    return; // dropping the connection closes the socket
                }
            }
        }
    }
}

/// Answers a connection over the cap: reads what the client sends first
/// (briefly), answers 503 and closes.
async fn refuse(mut stream: TcpStream, max: usize) {
    let mut buf = [0u8; 4096];
    let _ = tokio::time::timeout(Duration::from_millis(200), stream.read(&mut buf)).await;
    let body = format!(
        "{{\"code\":\"saturated\",\"message\":\"the server has {max} connections open, its limit (--max-connections); retry after the Retry-After delay\"}}"
    );
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: {}\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        crate::error::RETRY_AFTER_S,
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        let _ = stream.write_all(answer.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
}

/// What a connection's watchdog sees (milliseconds since the connection opened).
struct Activity {
    opened: Instant,
    last_io: AtomicU64,
    /// When the first byte of the next request head arrived (`NONE`: not yet).
    head_started: AtomicU64,
    /// Requests whose handler runs now.
    in_flight: AtomicUsize,
}

const NONE: u64 = u64::MAX;

impl Activity {
    fn new() -> Self {
        Self {
            opened: Instant::now(),
            last_io: AtomicU64::new(0),
            head_started: AtomicU64::new(NONE),
            in_flight: AtomicUsize::new(0),
        }
    }

    fn now(&self) -> u64 {
        self.opened.elapsed().as_millis() as u64
    }

    fn read(&self, n: usize) {
        if n == 0 {
            return;
        }
        let now = self.now();
        self.last_io.store(now, Ordering::Relaxed);
        if self.in_flight.load(Ordering::SeqCst) == 0 {
            let _ = self.head_started.compare_exchange(NONE, now, Ordering::SeqCst, Ordering::SeqCst);
        }
    }

    fn wrote(&self, n: usize) {
        if n > 0 {
            self.last_io.store(self.now(), Ordering::Relaxed);
        }
    }

    fn request_started(self: &Arc<Self>) -> InFlight {
        self.in_flight.fetch_add(1, Ordering::SeqCst);
        self.head_started.store(NONE, Ordering::SeqCst);
        InFlight(self.clone())
    }

    /// Why the connection should be closed now, if it should.
    fn expired(&self, limits: &ConnectionLimits) -> Option<&'static str> {
        if self.in_flight.load(Ordering::SeqCst) > 0 {
            return None;
        }
        let now = self.now();
        let head = self.head_started.load(Ordering::SeqCst);
        if head != NONE && now.saturating_sub(head) > limits.header_timeout.as_millis() as u64 {
            return Some("the request head did not arrive within the header timeout (--header-timeout)");
        }
        if now.saturating_sub(self.last_io.load(Ordering::Relaxed)) > limits.idle_timeout.as_millis() as u64 {
            return Some("idle for the idle timeout (--idle-timeout)");
        }
        None
    }
}

/// A request being handled; dropping it (answered, or the connection gone) ends it.
struct InFlight(Arc<Activity>);

impl Drop for InFlight {
    fn drop(&mut self) {
        let a = &self.0;
        a.last_io.store(a.now(), Ordering::Relaxed);
        a.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The router as a hyper service, marking each request in flight.
#[derive(Clone)]
struct Handler {
    router: Router,
    activity: Arc<Activity>,
}

impl hyper::service::Service<Request<Incoming>> for Handler {
    type Response = Response<Body>;
    type Error = Infallible;
    type Future = Pin<Box<dyn Future<Output = Result<Response<Body>, Infallible>> + Send>>;

    fn call(&self, req: Request<Incoming>) -> Self::Future {
        let in_flight = self.activity.request_started();
        let router = self.router.clone();
        Box::pin(async move {
            let response = router.oneshot(req.map(Body::new)).await;
            drop(in_flight);
            response
        })
    }
}

/// A TCP stream that reports its reads and writes to the watchdog.
struct Tracked {
    inner: TcpStream,
    activity: Arc<Activity>,
}

impl AsyncRead for Tracked {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = r {
            self.activity.read(buf.filled().len() - before);
        }
        r
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, data);
        if let Poll::Ready(Ok(n)) = r {
            self.activity.wrote(n);
        }
        r
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        if let Poll::Ready(Ok(n)) = r {
            self.activity.wrote(n);
        }
        r
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
