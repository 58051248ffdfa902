//! The curvenet HTTP service (`curvenet serve`): bindings cached by content
//! hash, frames solved off the async runtime, versioned under `/v1` and
//! described by OpenAPI 3.1 at `/openapi.json`.
//!
//! One frame, from the body to the solver and back:
//!
//! ```text
//! routes.rs    the router and its layers (request id, token, declared length)
//! frames.rs    the handler: its extractors (extract.rs: content type, the cached binding,
//!              the sized body, a solve permit), parsing (JSON or binary.rs), validation, encoding
//! solve.rs     the one solve helper: on the solve pool, validate → Deformer::frame → metrics
//! core/src/deformer.rs   Deformer::frame: workspace pool, rest pose, blend shapes, Binding::deform
//! ```
//!
//! One file per resource: bindings.rs (binding.rs builds the request's
//! `curvenet_core::Deformer`, cache.rs caches it by content hash), frames.rs,
//! batches.rs, deform.rs, bake.rs, operations.rs (health, readiness,
//! metrics, OpenAPI), viewer.rs; error.rs holds the error type, its code →
//! status table and the core error → code table.
//!
//! `app(state)` is the whole router, so tests drive it with `oneshot`;
//! `run(listener, state, shutdown)` (serve.rs) serves it over TCP with the
//! connection limits and timeouts and graceful shutdown with a deadline;
//! limits.rs predicts and bounds a binding's work, jobs.rs cancels it.

mod bake;
mod batches;
mod binary;
mod binding;
mod bindings;
mod bounded;
mod cache;
mod deform;
mod error;
mod extract;
mod frames;
#[cfg(test)]
mod fuzz_tests;
mod jobs;
mod limits;
mod metrics;
mod openapi;
mod operations;
mod routes;
mod serve;
mod solve;
mod state;
mod viewer;

pub use bake::{BakeFailure, BakeJob, Baker, names_a_directory};
pub use binding::{MAX_COORDINATE, MAX_WEIGHT};
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
    AppState, Config, DEFAULT_BODY_LIMIT, DEFAULT_CACHE_BYTES, DEFAULT_DRAIN_TIMEOUT, DEFAULT_MAX_BAKE_BYTES,
    DEFAULT_MAX_BATCH_BYTES, DEFAULT_MAX_BATCH_MEMORY, DEFAULT_MAX_SOLVES, DEFAULT_QUEUE_TIMEOUT,
};
pub use viewer::{FrameSource, StageAdjustment, StageFrame, ViewerStage};
