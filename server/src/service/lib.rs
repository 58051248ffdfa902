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
//! `run(listener, state, shutdown)` (serve.rs) serves it over TCP with the
//! connection limits and timeouts and graceful shutdown with a deadline;
//! limits.rs predicts and bounds a binding's work, jobs.rs cancels it.

mod bake;
mod binary;
mod binding;
mod bounded;
mod cache;
mod error;
mod frames;
#[cfg(test)]
mod fuzz_tests;
mod jobs;
mod limits;
mod metrics;
mod openapi;
mod routes;
mod serve;
mod state;
mod viewer;

pub use bake::{BakeFailure, BakeJob, Baker};
pub use error::{Code, ServiceError};
pub use limits::{
    DEFAULT_MAX_BINDING_TIME, DEFAULT_MAX_SAMPLE_DENSITY, DEFAULT_MAX_SEGMENTS_PER_VERTEX, MIN_SEGMENT_ALLOWANCE,
    WorkLimits,
};
pub use openapi::openapi;
pub use routes::app;
pub use serve::{
    ConnectionLimits, DEFAULT_BODY_MIN_RATE, DEFAULT_BODY_TIMEOUT, DEFAULT_HEADER_TIMEOUT, DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS, Drained, run,
};
pub use state::{
    AppState, Config, DEFAULT_BODY_LIMIT, DEFAULT_CACHE_BYTES, DEFAULT_DRAIN_TIMEOUT, DEFAULT_MAX_BATCH_BYTES,
    DEFAULT_MAX_SOLVES, DEFAULT_QUEUE_TIMEOUT,
};
pub use viewer::{FrameSource, ViewerStage};
