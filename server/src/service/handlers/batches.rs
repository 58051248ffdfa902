//! Batches: `POST /v1/bindings/{id}/frames:batch`, many frames of one
//! binding in one request, solved in parallel (as many at once as the
//! request could take solve permits) and answered in request order. Parsed,
//! validated, solved and encoded as frames.rs does, through the one solve
//! helper (pool.rs), which also bounds the answer (`--max-batch-bytes`).

use axum::extract::State;
use axum::response::Response;
use curvenet_schema::wire::{ErrorBody, FrameBatchRequest, FrameBatchResponse};

use crate::binary::BinaryFrames;
use crate::error::ServiceError;
use crate::extract::{Admission, CachedBinding, ContentType, JsonOrBinary, SizedBody};
use crate::state::AppState;

/// Deforms many frames of one binding in parallel; answers in frame order.
#[utoipa::path(post, path = "/v1/bindings/{id}/frames:batch", tag = "frames", security(("bearer" = [])),
    params(("id" = String, Path, description = "binding id")),
    request_body(content(
        (FrameBatchRequest = "application/json"),
        (BinaryFrames = "application/octet-stream"),
    )),
    responses(
        (status = 200, description = "The frames, in request order", content(
            (FrameBatchResponse = "application/json"),
            (BinaryFrames = "application/octet-stream"),
        )),
        (status = 400, description = "malformed_json, malformed_binary", body = ErrorBody),
        (status = 404, description = "unknown_binding", body = ErrorBody),
        (status = 408, description = "request_timeout: the body stalled or arrived too slowly", body = ErrorBody),
        (status = 409, description = "topology_changed", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "A frame is invalid (the message starts with frames[i], details.frame is i), or limit_exceeded: the answer would be larger than --max-batch-bytes", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn post_frames_batch(
    State(state): State<AppState>,
    ContentType(form, _): ContentType<JsonOrBinary>,
    CachedBinding(entry): CachedBinding,
    SizedBody(bytes): SizedBody,
) -> Result<Response, ServiceError> {
    // Once its body is read, each in line up to --queue-timeout: a batch
    // slot (batches hold at most half the solve permits, so single frames
    // find theirs); the batch gate (one batch at a time holds part of its
    // memory share, so two cannot each hold a part and wait for each
    // other); its first share of --max-batch-memory, for its body and its
    // frames before they are parsed (at most the whole budget: the real
    // size is known once parsed); then a solve permit, and what permits
    // are free besides, each with a slot. The full share, once parsed,
    // opens the gate (pool.rs).
    let _slot = state.batch_slot().await?;
    let first = bytes.len() as u64 + super::frames::input_bound(form, bytes.len());
    let memory = state.batch_first_share(first).await?;
    let admission = Admission::one(&state).await?.widen(&state);
    super::frames::answer(&state, entry, form, bytes, admission, true, Some(memory)).await
}
