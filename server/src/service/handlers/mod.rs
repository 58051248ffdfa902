//! The handlers, one file per resource: bindings (create, get, delete),
//! frames (one frame or a batch in one request), batches (`frames:batch`),
//! deform (bind and deform in one request), bake, operations (health,
//! readiness, metrics). Each parses its request with the extractors
//! (extract.rs), works through the frame module (frame.rs, binary.rs), the
//! solve pool (pool.rs) and the binding cache (cache.rs, builder.rs), and
//! answers in the request's form. The viewer's handlers live in viewer/.

pub(crate) mod bake;
pub(crate) mod batches;
pub(crate) mod bindings;
pub(crate) mod deform;
pub(crate) mod frames;
pub(crate) mod operations;
