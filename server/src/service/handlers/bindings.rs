//! Bindings: `POST /v1/bindings`, `GET` and `DELETE /v1/bindings/{id}`.
//! A posted binding is validated, checked against the work limits, hashed
//! and built (builder.rs: `curvenet_core::Deformer::new`) through the cache,
//! as a cancellable job (jobs.rs).

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::{BindingRequest, BindingResponse, ErrorBody};

use crate::builder::build;
use crate::cache::{binding_key, topology_key};
use crate::entry::{Entry, hex, parse_key};
use crate::error::{Code, ServiceError};
use crate::extract::{CachedBinding, ContentType, JsonOnly, Params, SizedBody, parse_json};
use crate::request::{EffectiveOptions, validate};
use crate::state::{AppState, blocking};

/// Binds a mesh to its curvenets, or finds the binding already cached.
#[utoipa::path(post, path = "/v1/bindings", tag = "bindings", security(("bearer" = [])),
    request_body = BindingRequest,
    responses(
        (status = 200, description = "Bound (or found in the cache: `cached`)", body = BindingResponse),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 408, description = "request_timeout: the body stalled or arrived too slowly", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "The mesh, a curvenet or the binding is invalid (count_mismatch, non_finite, index_out_of_range, empty_input, invalid_mesh, invalid_curvenet, invalid_parameter, binding_failed; details name the curvenet, spline, segment, sample, face, vertex, ...; a bad cage names its face, edge or vertex with what = cage; a cage with a skin but no skin.skeleton is invalid_parameter naming skin.skeleton), or limit_exceeded (density, segments, binding time)", body = ErrorBody),
        (status = 503, description = "saturated, or unavailable: the server stopped the binding to shut down (Retry-After)", body = ErrorBody),
        (status = 507, description = "cache_too_small", body = ErrorBody),
    ))]
pub(crate) async fn create_binding(
    State(state): State<AppState>,
    _: ContentType<JsonOnly>,
    SizedBody(bytes): SizedBody,
) -> Result<Response, ServiceError> {
    let req: BindingRequest = blocking(move || parse_json(&bytes)).await?;
    let (entry, cached) = bind(&state, req).await?;
    Ok(Json(binding_response(&entry, cached)).into_response())
}

/// The binding's description, if it is cached.
#[utoipa::path(get, path = "/v1/bindings/{id}", tag = "bindings", security(("bearer" = [])),
    params(("id" = String, Path, description = "binding id")),
    responses(
        (status = 200, description = "Cached", body = BindingResponse),
        (status = 404, description = "unknown_binding", body = ErrorBody),
    ))]
pub(crate) async fn get_binding(CachedBinding(entry): CachedBinding) -> Json<BindingResponse> {
    Json(binding_response(&entry, true))
}

/// Drops a binding from the cache.
#[utoipa::path(delete, path = "/v1/bindings/{id}", tag = "bindings", security(("bearer" = [])),
    params(("id" = String, Path, description = "binding id")),
    responses(
        (status = 204, description = "Dropped"),
        (status = 404, description = "unknown_binding", body = ErrorBody),
    ))]
pub(crate) async fn delete_binding(
    State(state): State<AppState>,
    Params(id): Params<String>,
) -> Result<StatusCode, ServiceError> {
    let key = parse_key(&id).ok_or_else(|| ServiceError::unknown_binding(&id))?;
    if state.inner.cache.remove(&key).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ServiceError::unknown_binding(&id))
    }
}

fn binding_response(entry: &Entry, cached: bool) -> BindingResponse {
    BindingResponse { cached, ..entry.response.clone() }
}

/// Validates, checks the work limits, hashes and binds (through the
/// cache). Returns the entry and whether it was cached.
///
/// The computation is a cancellable [`crate::jobs::Job`]: dropped with this
/// future (the client went away), stopped at the binding time limit or at
/// the drain deadline.
pub(crate) async fn bind(state: &AppState, req: BindingRequest) -> Result<(Arc<Entry>, bool), ServiceError> {
    let req = Arc::new(req);
    let limits = state.config().work;
    let capacity = state.config().cache_bytes;
    let (key, topology, options) = blocking({
        let req = req.clone();
        move || {
            validate(&req)?;
            let options = EffectiveOptions::of(&req)?;
            let prediction = crate::request::predict(&req, &limits)?;
            if prediction.bytes_at_least > capacity {
                return Err(crate::cache::too_small(prediction.bytes_at_least, capacity, "at least"));
            }
            Ok((binding_key(&req, &options), topology_key(&req), options))
        }
    })
    .await?;
    let span = tracing::Span::current();
    span.record("binding_id", hex(&key));
    let st = state.clone();
    let (entry, cached) = state
        .inner
        .cache
        .get_or_compute(key, async move {
            let permit = st.permit().await?;
            let t = Instant::now();
            let job = st.inner.jobs.start();
            let cancel = job.cancel_flag();
            let keep = st.solve_threads();
            let work = blocking(move || {
                let _permit = permit;
                build(&req, key, topology, options, cancel, keep)
            });
            tokio::pin!(work);
            let result = tokio::select! {
                r = &mut work => r,
                () = tokio::time::sleep(limits.max_binding_time) => {
                    // Raise the flag, then wait for the core to notice it.
                    job.handle().cancel(crate::jobs::Reason::TimeLimit);
                    work.await
                }
            };
            let reason = job.finish();
            let entry = match result {
                Err(e) if e.cancelled => return Err(cancelled(reason, &limits, t.elapsed())),
                other => other?,
            };
            st.inner.metrics.bind_seconds.record(t.elapsed().as_secs_f64());
            tracing::info!(binding_id = %entry.id, bytes = entry.size_bytes, ms = t.elapsed().as_secs_f64() * 1e3, "bound");
            Ok(entry)
        })
        .await?;
    span.record("cached", cached);
    if !cached {
        span.record("cut_ms", entry.response.timings.cutting_ms);
        span.record("factor_ms", entry.response.timings.factor_ms);
    }
    Ok((entry, cached))
}

/// The answer to a binding the service stopped.
fn cancelled(reason: crate::jobs::Reason, limits: &crate::limits::WorkLimits, after: Duration) -> ServiceError {
    use crate::jobs::Reason;
    match reason {
        Reason::TimeLimit => ServiceError::new(
            Code::LimitExceeded,
            format!(
                "the binding was still computing after {:.1} s, this server's limit (--max-binding-seconds, \
                 CURVENET_MAX_BINDING_SECONDS); lower the curvenets' sample_density",
                limits.max_binding_time.as_secs_f64()
            ),
        ),
        Reason::Shutdown => ServiceError::new(
            Code::Unavailable,
            format!("the server is shutting down and stopped the binding after {:.1} s; retry", after.as_secs_f64()),
        ),
        // Nobody reads this answer (the client is gone); logged at debug.
        Reason::Abandoned | Reason::None => {
            ServiceError::new(Code::Unavailable, "the binding was cancelled: its client disconnected")
        }
    }
}
