//! One-shot deforms: `POST /v1/deform` binds (through the cache, as
//! `POST /v1/bindings` does) and solves one frame in one request. The
//! binding takes a solve permit of its own, so the frame's admission is
//! taken only once it is bound.

use axum::Json;
use axum::extract::State;
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::{DeformRequest, DeformResponse, ErrorBody};

use super::bindings::bind;
use crate::error::ServiceError;
use crate::extract::{Admission, ContentType, JsonOnly, SizedBody, parse_json};
use crate::pool::{Numbering, solve_frames};
use crate::state::{AppState, blocking};

/// Binds (through the cache) and deforms one frame in one request.
#[utoipa::path(post, path = "/v1/deform", tag = "frames", security(("bearer" = [])),
    request_body = DeformRequest,
    responses(
        (status = 200, description = "The deformed frame", body = DeformResponse),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 408, description = "request_timeout: the body stalled or arrived too slowly", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "The binding (message starting `binding: `) or the frame (`frame: `) is invalid, or limit_exceeded; codes and details as for the bindings and frames routes", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
        (status = 507, description = "cache_too_small", body = ErrorBody),
    ))]
pub(crate) async fn deform(
    State(state): State<AppState>,
    _: ContentType<JsonOnly>,
    SizedBody(bytes): SizedBody,
) -> Result<Response, ServiceError> {
    let req: DeformRequest = blocking(move || parse_json(&bytes)).await?;
    let (entry, cached) = bind(&state, req.binding).await.map_err(|e| e.context("binding"))?;
    let admission = Admission::one(&state).await?;
    let frame = req.frame;
    let answer = solve_frames(
        &state,
        admission,
        entry,
        Numbering::Named("frame"),
        None,
        move |_| Ok(vec![frame]),
        move |entry, solved| {
            let frame = solved.into_iter().next().ok_or_else(|| ServiceError::internal("a deform solved no frame"))?;
            Ok(DeformResponse { binding_id: entry.id.clone(), cached, frame: frame.into_response() })
        },
    )
    .await?
    .0;
    Ok(Json(answer).into_response())
}
