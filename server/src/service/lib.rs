//! The curvenet HTTP service (`curvenet serve`): bindings cached by content
//! hash, frames solved off the async runtime, versioned under `/v1` and
//! described by OpenAPI 3.1 at `/openapi.json`.
//!
//! The files form layers; each imports only from layers below it
//! (`scripts/check-imports` fails on any cycle):
//!
//! ```text
//! serve.rs      TCP: connection limits and timeouts, graceful shutdown (`run`)
//! routes.rs     the router and its layers (request id, token, declared length)
//! openapi.rs    the OpenAPI description, from the handlers' annotations
//! viewer/       the browser viewer: its routes, views and geometry
//! handlers/     one file per resource: bindings, frames, batches, deform, bake, operations
//! pool.rs       the solve pool: a permit, batch memory, validate → Deformer::frame(s) → metrics
//! extract.rs    extractors: content type, the cached binding, the sized body, admission
//! binary.rs     the binary frame form: parse into frames, encode answers
//! frame.rs      the frame: checked against the binding, solved by core, answered
//! state.rs      the shared state: config, cache, permits, the solve threads, jobs
//! builder.rs    a binding request → curvenet_core::Deformer (the one way a binding is made)
//! cache.rs      bindings by content hash (keys, LRU by bytes; memory, then the store)
//! stored.rs     an entry as stored bytes and back, through the store (store.rs)
//! entry.rs      a cached binding: id, deformer, description, size
//! request.rs    a binding request checked: options, bounds, counts, predicted work
//! config.rs     Config and its defaults, connection limits, the Baker hook
//! error.rs, limits.rs, jobs.rs, bounded.rs, metrics.rs   leaves
//! ```
//!
//! One frame, from the socket to the solver and back, passes routes.rs →
//! handlers/frames.rs → extract.rs → frame.rs (binary.rs for the binary
//! form) → pool.rs → core's deformer.rs, and back through frame.rs and
//! handlers/frames.rs (docs/architecture.md).
//!
//! `app(state)` is the whole router, so tests drive it with `oneshot`;
//! `run(listener, state, shutdown)` serves it over TCP.

mod binary;
mod bounded;
mod builder;
mod cache;
mod config;
mod entry;
mod error;
mod extract;
mod frame;
#[cfg(test)]
mod fuzz_tests;
mod handlers;
mod jobs;
mod limits;
mod metrics;
mod openapi;
mod pool;
mod request;
mod routes;
mod serve;
mod state;
pub mod store;
pub mod stored;
mod viewer;

pub use config::{
    BakeFailure, BakeJob, Baker, Config, ConnectionLimits, DEFAULT_BODY_LIMIT, DEFAULT_BODY_MIN_RATE,
    DEFAULT_BODY_TIMEOUT, DEFAULT_CACHE_BYTES, DEFAULT_DRAIN_TIMEOUT, DEFAULT_HEADER_TIMEOUT, DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_BAKE_BYTES, DEFAULT_MAX_BATCH_BYTES, DEFAULT_MAX_BATCH_MEMORY, DEFAULT_MAX_CONNECTIONS,
    DEFAULT_MAX_SOLVES, DEFAULT_QUEUE_TIMEOUT,
};
pub use error::{Code, ServiceError};
pub use handlers::bake::names_a_directory;
pub use limits::{
    DEFAULT_MAX_BINDING_TIME, DEFAULT_MAX_SAMPLE_DENSITY, DEFAULT_MAX_SEGMENTS_PER_VERTEX, MIN_SEGMENT_ALLOWANCE,
    WorkLimits,
};
pub use metrics::Metrics;
pub use openapi::openapi;
pub use request::{MAX_COORDINATE, MAX_WEIGHT};
pub use routes::app;
pub use serve::{Drained, run};
pub use state::AppState;
pub use viewer::{FrameSource, StageAdjustment, ViewerStage};
