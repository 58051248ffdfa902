//! The curvenet HTTP service (`curvenet serve`): bindings cached by content
//! hash, frames solved off the async runtime, versioned under `/v1` and
//! described by OpenAPI 3.1 at `/openapi.json`.
//!
//! One frame, from the body to the solver and back:
//!
//! ```text
//! routes.rs    read the body (limit), look the binding up in the cache, take a solve permit
//! frames.rs    parse (JSON or binary.rs), validate against the binding, solve on the pool, encode
//! cache.rs     content hash → Arc<Entry> (moka, weighed in bytes, LRU)
//! binding.rs   BindingRequest → validated core inputs → curvenet_core::Binding
//! error.rs     the error type and its code → status table
//! viewer.rs    the browser viewer at /viewer (assets in viewer/) and its read-only JSON
//! ```
//!
//! `app(state)` is the whole router, so tests drive it with `oneshot`;
//! `run(listener, state, shutdown)` serves it with graceful shutdown.

mod bake;
mod binary;
mod binding;
mod cache;
mod error;
mod frames;
mod metrics;
mod openapi;
mod routes;
mod state;
mod viewer;

pub use bake::{BakeFailure, BakeJob, Baker};
pub use error::{Code, ServiceError};
pub use openapi::openapi;
pub use routes::app;
pub use state::{AppState, Config, DEFAULT_BODY_LIMIT, DEFAULT_CACHE_BYTES, DEFAULT_DRAIN_TIMEOUT, DEFAULT_MAX_SOLVES};
pub use viewer::{FrameSource, ViewerStage};

use std::future::Future;
use std::sync::Arc;

use tokio::net::TcpListener;

/// Serves `app(state)` on `listener` until `shutdown` resolves, then stops
/// accepting connections and lets requests in flight finish for at most the
/// configured drain timeout.
pub async fn run(
    listener: TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let drain = state.config().drain_timeout;
    let started = Arc::new(tokio::sync::Notify::new());
    let signal = {
        let state = state.clone();
        let started = started.clone();
        async move {
            shutdown.await;
            tracing::info!(drain_timeout_s = drain.as_secs_f64(), "shutting down: draining requests in flight");
            state.set_draining();
            started.notify_one();
        }
    };
    let upkeep = {
        let metrics = state.inner.metrics.clone();
        tokio::spawn(async move {
            let mut every = tokio::time::interval(std::time::Duration::from_secs(5));
            loop {
                every.tick().await;
                metrics.upkeep();
            }
        })
    };
    let server = axum::serve(listener, app(state)).with_graceful_shutdown(signal);
    let server = std::future::IntoFuture::into_future(server);
    tokio::pin!(server);
    let result = tokio::select! {
        r = &mut server => r,
        _ = async { started.notified().await; tokio::time::sleep(drain).await } => {
            tracing::warn!("drain timeout reached; closing the connections still open");
            Ok(())
        }
    };
    upkeep.abort();
    result
}
