//! Frames: `POST /v1/bindings/{id}/frames` (and the parsing and encoding
//! `frames:batch` shares, batches.rs): the body is parsed (JSON or binary.rs)
//! into frames (frame.rs), solved on the solve pool (pool.rs) and encoded
//! back in the request's form.

use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

use curvenet_schema::wire::{ErrorBody, FrameBatchResponse, FrameRequest, FrameResponse};

use crate::binary;
use crate::binary::BinaryFrames;
use crate::entry::Entry;
use crate::error::{Code, ServiceError};
use crate::extract::{Admission, Admitted, CachedBinding, ContentType, Form, JsonOrBinary, SizedBody, parse_json};
use crate::pool::{HeldBody, Numbering, solve_frames};
use crate::state::{AppState, BatchMemory};

use crate::frame::Solved;
/// Deforms one frame of a cached binding (JSON, or the binary form).
#[utoipa::path(post, path = "/v1/bindings/{id}/frames", tag = "frames", security(("bearer" = [])),
    params(("id" = String, Path, description = "binding id")),
    request_body(content(
        (FrameRequest = "application/json"),
        (BinaryFrames = "application/octet-stream"),
    )),
    responses(
        (status = 200, description = "The deformed frame, in the request's form", content(
            (FrameResponse = "application/json"),
            (BinaryFrames = "application/octet-stream"),
        )),
        (status = 400, description = "malformed_json, malformed_binary", body = ErrorBody),
        (status = 404, description = "unknown_binding: post the binding again", body = ErrorBody),
        (status = 408, description = "request_timeout: the body stalled or arrived too slowly", body = ErrorBody),
        (status = 409, description = "topology_changed", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "count_mismatch, non_finite, index_out_of_range, invalid_parameter, degenerate_pose; a bad adjustment names it (details: adjustment, curvenet, control_point); rest_cage or posed_cage_offsets on a binding without a cage is unsupported, a wrong count count_mismatch (details.what names the array); details: curvenet, spline, segment, control_point, what, index", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn post_frames(
    State(state): State<AppState>,
    ContentType(form, _): ContentType<JsonOrBinary>,
    CachedBinding(entry): CachedBinding,
    Admitted(SizedBody(bytes), admission): Admitted<SizedBody>,
) -> Result<Response, ServiceError> {
    answer(&state, entry, form, bytes, admission, false, None).await
}

/// Parses, solves and encodes the frames of one request (`batch`: the
/// `frames:batch` form, holding `memory`), through the one solve helper.
pub(crate) async fn answer(
    state: &AppState,
    entry: Arc<Entry>,
    form: Form,
    bytes: Bytes,
    admission: Admission,
    batch: bool,
    memory: Option<BatchMemory>,
) -> Result<Response, ServiceError> {
    let max_batch_bytes = state.config().max_batch_bytes;
    let numbering = if batch {
        Numbering::Batch { max_bytes: max_batch_bytes, json: matches!(form, Form::Json) }
    } else {
        Numbering::One
    };
    let (out, memory) = solve_frames(
        state,
        admission,
        entry,
        numbering,
        memory,
        move |entry| parse(entry, form, &bytes, batch, max_batch_bytes),
        move |_, solved| encode(form, batch, solved),
    )
    .await?;
    let content_type = match form {
        Form::Json => HeaderValue::from_static("application/json"),
        Form::Binary => HeaderValue::from_static(binary::CONTENT_TYPE),
    };
    Ok(([(header::CONTENT_TYPE, content_type)], axum::body::Body::new(HeldBody::new(out, memory))).into_response())
}

/// About the most memory the frames parsed from a body of `len` bytes hold
/// (reserved before parsing a batch, `--max-batch-memory`): binary f32
/// become f64, twice their bytes; a JSON number takes at least two
/// characters with its separator, and its f64 eight bytes.
pub(crate) fn input_bound(form: Form, len: usize) -> u64 {
    len as u64 * if matches!(form, Form::Json) { 4 } else { 2 }
}

/// Parses the frames of a request (on the solve pool; checked afterwards by [`validate`]).
fn parse(
    entry: &Entry,
    form: Form,
    bytes: &[u8],
    batch: bool,
    max_batch_bytes: u64,
) -> Result<Vec<FrameRequest>, ServiceError> {
    let vertices = entry.binding().n_vertices();
    let max_frames = crate::bounded::max_frames(max_batch_bytes, vertices);
    Ok(match form {
        Form::Json if batch => match crate::bounded::frames::<FrameRequest>(bytes, max_frames) {
            Ok(f) => f,
            Err(crate::bounded::BatchError::TooMany(max)) => return Err(crate::bounded::too_many(max, vertices)),
            Err(crate::bounded::BatchError::Malformed(e)) => {
                return Err(ServiceError::new(Code::MalformedJson, format!("the JSON body is invalid: {e}")));
            }
            Err(crate::bounded::BatchError::NotBatch) => {
                return Err(ServiceError::new(
                    Code::MalformedJson,
                    "the JSON body is invalid: frames:batch takes {\"frames\": [...]} and nothing else",
                ));
            }
        },
        Form::Json => vec![parse_json::<FrameRequest>(bytes)?],
        Form::Binary => {
            let b = entry.binding();
            let pools: Vec<usize> = (0..b.n_curvenets()).map(|k| b.n_control_points(k)).collect();
            let joints = entry.deformer.rig().map(|r| r.skin.influences().n_joints());
            let cage = entry.deformer.cage().map(|c| c.n_cage_vertices());
            let expected =
                binary::Expected { pools: &pools, vertices, blend_shapes: entry.n_shapes(), joints, cage, max_frames };
            let (frames, is_batch) = binary::parse(bytes, &expected)?;
            if is_batch != batch {
                return Err(ServiceError::new(
                    Code::MalformedBinary,
                    if batch {
                        "frames:batch takes a header {\"frames\": [...]} listing each frame's arrays"
                    } else {
                        "this endpoint takes one frame's header; send {\"frames\": [...]} to frames:batch"
                    },
                ));
            }
            frames
        }
    })
}

/// Encodes solved frames in the request's form.
fn encode(form: Form, batch: bool, solved: Vec<Solved>) -> Result<Vec<u8>, ServiceError> {
    match (form, batch) {
        (Form::Binary, _) => Ok(binary::encode(&solved, batch)),
        (Form::Json, false) => serde_json::to_vec(&solved.into_iter().next().map(Solved::into_response))
            .map_err(ServiceError::internal_from),
        (Form::Json, true) => {
            serde_json::to_vec(&FrameBatchResponse { frames: solved.into_iter().map(Solved::into_response).collect() })
                .map_err(ServiceError::internal_from)
        }
    }
}
