//! The router and its handlers: thin — read the body, look the binding up,
//! take a solve permit, hand the work to a pool, answer.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use axum::Json;
use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, FromRequestParts, MatchedPath, Path, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{Next, from_fn_with_state};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use curvenet_schema::wire::{
    BakeRequest, BakeResponse, BindingRequest, BindingResponse, DeformRequest, DeformResponse, ErrorBody,
    FrameBatchRequest, FrameBatchResponse, FrameRequest, FrameResponse, HealthResponse,
};
use http_body_util::BodyExt;
use rayon::prelude::*;
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::request_id::{MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use tracing::field::Empty;

use crate::bake::{BakeFailure, BakeJob, check_output, check_stage};
use crate::binary;
use crate::binding::{EffectiveOptions, build, validate};
use crate::cache::{Entry, binding_key, hex, parse_key, topology_key};
use crate::error::{Code, ServiceError};
use crate::frames::{self, Frame, Solved};
use crate::openapi::BinaryFrames;
use crate::state::{AppState, blocking, panic_message};
use crate::viewer;

/// The whole service: `/v1` API, `/healthz`, `/readyz`, `/metrics`, `/openapi.json`.
pub fn app(state: AppState) -> Router {
    let open = Router::new()
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        // The viewer page holds no data (it asks for the token itself).
        .route("/viewer", get(viewer::page))
        .route("/viewer/viewer.js", get(viewer::script))
        .route("/viewer/viewer.css", get(viewer::style));
    let api = Router::new()
        .route("/v1/bindings", post(create_binding))
        .route("/v1/bindings/{id}", get(get_binding).delete(delete_binding))
        .route("/v1/bindings/{id}/frames", post(post_frames))
        .route("/v1/bindings/{id}/frames:batch", post(post_frames_batch))
        .route("/v1/deform", post(deform))
        .route("/v1/bake", post(bake))
        .route("/v1/bindings/{id}/viewer-data", get(viewer::viewer_data))
        .route("/v1/bindings/{id}/viewer-frame", post(viewer::viewer_frame))
        .route("/v1/viewer/stages", get(viewer::stages))
        .route("/v1/viewer/stages/{index}", get(viewer::stage))
        .route("/v1/viewer/stages/{index}/frames/{k}", get(viewer::stage_frame))
        .route("/metrics", get(metrics))
        .route("/openapi.json", get(openapi_json))
        .route_layer(from_fn_with_state(state.clone(), auth));
    Router::new()
        .merge(open)
        .merge(api)
        .route_layer(from_fn_with_state(state.clone(), count_requests))
        .fallback(|| async {
            ServiceError::new(Code::NotFound, "no such route; the API is described at /openapi.json")
        })
        .method_not_allowed_fallback(|| async {
            ServiceError::new(Code::MethodNotAllowed, "this route does not take this method")
        })
        .layer(
            ServiceBuilder::new()
                .layer(SetRequestIdLayer::x_request_id(MakeId::default()))
                .layer(PropagateRequestIdLayer::x_request_id())
                .layer(
                    TraceLayer::new_for_http()
                        .make_span_with(make_span)
                        .on_response(DefaultOnResponse::new().level(tracing::Level::INFO)),
                )
                .layer(CatchPanicLayer::custom(|panic: Box<dyn std::any::Any + Send + 'static>| {
                    ServiceError::internal(format!("a handler panicked: {}", panic_message(&panic))).into_response()
                }))
                // Bodies are read by `read_body` with the configured limit, not axum's 2 MB default.
                .layer(DefaultBodyLimit::disable())
                .layer(from_fn_with_state(state.clone(), content_length_limit)),
        )
        .with_state(state)
}

fn make_span(req: &Request) -> tracing::Span {
    let id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
    tracing::info_span!(
        "request",
        request_id = %id,
        method = %req.method(),
        path = %req.uri().path(),
        binding_id = Empty,
        cached = Empty,
        cut_ms = Empty,
        factor_ms = Empty,
        solve_ms = Empty,
        frames = Empty,
    )
}

/// Request ids: a per-process random prefix and a counter.
#[derive(Clone)]
struct MakeId {
    prefix: u32,
    counter: Arc<AtomicU64>,
}

impl Default for MakeId {
    fn default() -> Self {
        let seed = format!("{:?}{}", std::time::SystemTime::now(), std::process::id());
        let h = blake3::hash(seed.as_bytes());
        let b = h.as_bytes();
        Self { prefix: u32::from_le_bytes([b[0], b[1], b[2], b[3]]), counter: Arc::new(AtomicU64::new(0)) }
    }
}

impl MakeRequestId for MakeId {
    fn make_request_id<B>(&mut self, _: &axum::http::Request<B>) -> Option<RequestId> {
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        HeaderValue::from_str(&format!("{:08x}-{n:012x}", self.prefix)).ok().map(RequestId::new)
    }
}

async fn auth(State(state): State<AppState>, req: Request, next: Next) -> Response {
    if let Some(expected) = state.inner.token_hash {
        let given = req.headers().get(header::AUTHORIZATION).and_then(|v| v.to_str().ok());
        // The scheme is case-insensitive (RFC 9110 §11.1): `Bearer`, `bearer`, `BEARER`.
        let token = given.and_then(|v| {
            let (scheme, token) = v.trim_start().split_once(' ')?;
            scheme.eq_ignore_ascii_case("bearer").then_some(token)
        });
        // Hashes compare in constant time.
        if token.is_none_or(|t| blake3::hash(t.trim().as_bytes()) != expected) {
            let message = if given.is_none() {
                "this server requires a bearer token: send Authorization: Bearer <token>"
            } else {
                "the bearer token is wrong"
            };
            return ServiceError::new(Code::Unauthorized, message).into_response();
        }
    }
    next.run(req).await
}

async fn count_requests(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let route = req.extensions().get::<MatchedPath>().map_or("unmatched", |m| m.as_str()).to_string();
    let method = req.method().to_string();
    let t = Instant::now();
    let response = next.run(req).await;
    state.inner.metrics.request(&route, &method, response.status().as_u16(), t.elapsed());
    response
}

fn too_large(limit: usize) -> ServiceError {
    ServiceError::new(
        Code::PayloadTooLarge,
        format!("the body is larger than the server's limit of {limit} bytes (--body-limit)"),
    )
}

/// Refuses a declared Content-Length over the limit before reading anything.
async fn content_length_limit(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let limit = state.config().body_limit;
    let declared =
        req.headers().get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()).and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return too_large(limit).into_response();
    }
    next.run(req).await
}

/// Reads the whole body: at most the configured limit (413 beyond), and
/// never stalling longer than the body timeout nor, once that much time has
/// passed, arriving slower on average than the minimum rate (408 and the
/// connection closed). The deadline for the next bytes is
/// `min(last bytes + timeout, start + max(timeout, received / min_rate))`.
pub(crate) async fn read_body(state: &AppState, body: Body) -> Result<Bytes, ServiceError> {
    let limit = state.config().body_limit;
    let c = state.config().connections;
    let start = tokio::time::Instant::now();
    let mut last = start;
    let mut body = http_body_util::Limited::new(body, limit);
    let mut buf: Vec<u8> = Vec::new();
    loop {
        let rate = c.body_min_rate.max(1) as f64;
        let allowance = c.body_timeout.max(Duration::from_secs_f64((buf.len() as f64 / rate).min(1e9)));
        let deadline = (last + c.body_timeout).min(start + allowance);
        match tokio::time::timeout_at(deadline, body.frame()).await {
            Err(_) => {
                return Err(ServiceError::new(
                    Code::RequestTimeout,
                    format!(
                        "the request body stalled or arrived too slowly: {} bytes in {:.1} s (a body may not stall for \
                         {} s, nor arrive slower than {} bytes/s after that: --body-timeout, --body-min-rate)",
                        buf.len(),
                        start.elapsed().as_secs_f64(),
                        c.body_timeout.as_secs_f64(),
                        c.body_min_rate
                    ),
                ));
            }
            Ok(None) => return Ok(Bytes::from(buf)),
            Ok(Some(Ok(frame))) => {
                if let Ok(data) = frame.into_data() {
                    if !data.is_empty() {
                        last = tokio::time::Instant::now();
                    }
                    buf.extend_from_slice(&data);
                }
            }
            Ok(Some(Err(e))) if e.downcast_ref::<http_body_util::LengthLimitError>().is_some() => {
                return Err(too_large(limit));
            }
            Ok(Some(Err(e))) => {
                return Err(ServiceError::new(Code::MalformedJson, format!("the body could not be read: {e}")));
            }
        }
    }
}

/// Path parameters whose parse failure (`/v1/viewer/stages/-1`) is a JSON
/// `not_found` like every other error, not axum's plain-text rejection.
pub(crate) struct Params<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> FromRequestParts<S> for Params<T> {
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut axum::http::request::Parts, state: &S) -> Result<Self, ServiceError> {
        match Path::<T>::from_request_parts(parts, state).await {
            Ok(Path(t)) => Ok(Params(t)),
            Err(e) => Err(ServiceError::new(
                Code::NotFound,
                format!("{} does not exist: {}", parts.uri.path(), e.body_text()),
            )),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Form {
    Json,
    Binary,
}

pub(crate) fn form(headers: &HeaderMap, binary_ok: bool) -> Result<Form, ServiceError> {
    let Some(ct) = headers.get(header::CONTENT_TYPE) else { return Ok(Form::Json) };
    let ct = ct.to_str().unwrap_or("").split(';').next().unwrap_or("").trim().to_ascii_lowercase();
    if ct == "application/json" || ct.ends_with("+json") {
        Ok(Form::Json)
    } else if binary_ok && ct == binary::CONTENT_TYPE {
        Ok(Form::Binary)
    } else {
        let accepted = if binary_ok { "application/json or application/octet-stream" } else { "application/json" };
        Err(ServiceError::new(
            Code::UnsupportedMediaType,
            format!("Content-Type {ct} is not accepted here; send {accepted}"),
        ))
    }
}

pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ServiceError> {
    serde_json::from_slice(bytes)
        .map_err(|e| ServiceError::new(Code::MalformedJson, format!("the JSON body is invalid: {e}")))
}

fn json_bytes(bytes: Vec<u8>) -> Response {
    ([(header::CONTENT_TYPE, HeaderValue::from_static("application/json"))], bytes).into_response()
}

/// Finds a cached binding or answers `unknown_binding`.
pub(crate) async fn lookup(state: &AppState, id: &str) -> Result<Arc<Entry>, ServiceError> {
    tracing::Span::current().record("binding_id", id);
    let key = parse_key(id).ok_or_else(|| ServiceError::unknown_binding(id))?;
    state.inner.cache.get(&key).await.ok_or_else(|| ServiceError::unknown_binding(id))
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
            let prediction = crate::binding::predict(&req, &limits)?;
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

fn binding_response(entry: &Entry, cached: bool) -> BindingResponse {
    BindingResponse { cached, ..entry.response.clone() }
}

#[utoipa::path(get, path = "/healthz", tag = "operations",
    responses((status = 200, description = "The process is up", body = HealthResponse)))]
pub(crate) async fn healthz() -> Json<HealthResponse> {
    Json(HealthResponse { status: "ok".into() })
}

#[utoipa::path(get, path = "/readyz", tag = "operations",
    responses(
        (status = 200, description = "Accepting work", body = HealthResponse),
        (status = 503, description = "Draining before shutdown", body = HealthResponse),
    ))]
pub(crate) async fn readyz(State(state): State<AppState>) -> Response {
    if state.is_draining() {
        (StatusCode::SERVICE_UNAVAILABLE, Json(HealthResponse { status: "draining".into() })).into_response()
    } else {
        Json(HealthResponse { status: "ready".into() }).into_response()
    }
}

#[utoipa::path(get, path = "/metrics", tag = "operations", security(("bearer" = [])),
    responses((status = 200, description = "Prometheus text exposition", body = String, content_type = "text/plain")))]
pub(crate) async fn metrics(State(state): State<AppState>) -> Response {
    let inner = &state.inner;
    inner.cache.refresh_gauges().await;
    inner.metrics.solves_in_flight.set(state.solves_in_flight() as f64);
    inner.metrics.bindings_running.set(inner.jobs.len() as f64);
    inner.metrics.bindings_cancelled.absolute(inner.jobs.cancelled());
    ([(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4"))], inner.metrics.render())
        .into_response()
}

#[utoipa::path(get, path = "/openapi.json", tag = "operations", security(("bearer" = [])),
    responses((status = 200, description = "This API, OpenAPI 3.1")))]
pub(crate) async fn openapi_json() -> Json<utoipa::openapi::OpenApi> {
    Json(crate::openapi())
}

/// Binds a mesh to its curvenets, or finds the binding already cached.
#[utoipa::path(post, path = "/v1/bindings", tag = "bindings", security(("bearer" = [])),
    request_body = BindingRequest,
    responses(
        (status = 200, description = "Bound (or found in the cache: `cached`)", body = BindingResponse),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 422, description = "The mesh, a curvenet or the binding is invalid (count_mismatch, non_finite, index_out_of_range, empty_input, invalid_mesh, invalid_curvenet, invalid_parameter, binding_failed)", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
        (status = 507, description = "cache_too_small", body = ErrorBody),
    ))]
pub(crate) async fn create_binding(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ServiceError> {
    form(&headers, false)?;
    let bytes = read_body(&state, body).await?;
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
pub(crate) async fn get_binding(
    State(state): State<AppState>,
    Params(id): Params<String>,
) -> Result<Json<BindingResponse>, ServiceError> {
    let entry = lookup(&state, &id).await?;
    Ok(Json(binding_response(&entry, true)))
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
    if state.inner.cache.remove(&key).await {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ServiceError::unknown_binding(&id))
    }
}

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
        (status = 409, description = "topology_changed", body = ErrorBody),
        (status = 413, description = "payload_too_large", body = ErrorBody),
        (status = 415, description = "unsupported_media_type", body = ErrorBody),
        (status = 422, description = "count_mismatch, non_finite, index_out_of_range, degenerate_pose", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn post_frames(
    State(state): State<AppState>,
    Params(id): Params<String>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ServiceError> {
    solve_frames(state, id, headers, body, false).await
}

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
        (status = 422, description = "A frame is invalid; the message starts with frames[i]", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn post_frames_batch(
    State(state): State<AppState>,
    Params(id): Params<String>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ServiceError> {
    solve_frames(state, id, headers, body, true).await
}

async fn solve_frames(
    state: AppState,
    id: String,
    headers: HeaderMap,
    body: Body,
    batch: bool,
) -> Result<Response, ServiceError> {
    let form = form(&headers, true)?;
    let entry = lookup(&state, &id).await?;
    let bytes = read_body(&state, body).await?;
    // Every request takes one permit, waiting in line for it (fairly) when
    // all are taken; a batch then also takes whatever permits are free right
    // now, up to one per solve thread, and solves its frames that many at once.
    let permit = state.permit().await?;
    let spare = if batch { state.spare_permits(state.solve_threads().saturating_sub(1) as u32) } else { None };
    let parallel = 1 + spare.as_ref().map_or(0, |p| p.num_permits());
    let metrics = state.inner.metrics.clone();
    let max_batch_bytes = state.config().max_batch_bytes;
    let (out, n, solve_ms) = state
        .on_pool(move || {
            let _permits = (permit, spare);
            let frames = parse_frames(&entry, form, &bytes, batch, max_batch_bytes)?;
            let solved: Vec<Solved> = if batch {
                check_batch_size(&entry, &frames, max_batch_bytes)?;
                let chunk = frames.len().div_ceil(parallel).max(1);
                let results: Vec<Result<Solved, ServiceError>> = frames
                    .par_chunks(chunk)
                    .enumerate()
                    .flat_map_iter(|(c, part)| {
                        let entry = &entry;
                        part.iter().enumerate().map(move |(j, f)| {
                            frames::solve(entry, f).map_err(|e| e.context(&format!("frames[{}]", c * chunk + j)))
                        })
                    })
                    .collect();
                results.into_iter().collect::<Result<_, _>>()?
            } else {
                vec![frames::solve(&entry, &frames[0])?]
            };
            for s in &solved {
                metrics.solve_seconds.record(s.solve_ms / 1e3);
            }
            metrics.frames_solved.increment(solved.len() as u64);
            let solve_ms: f64 = solved.iter().map(|s| s.solve_ms).sum();
            let n = solved.len();
            let out = match (form, batch) {
                (Form::Binary, _) => binary::encode(&solved, batch),
                (Form::Json, false) => serde_json::to_vec(&solved.into_iter().next().map(Solved::into_response))
                    .map_err(ServiceError::internal_from)?,
                (Form::Json, true) => serde_json::to_vec(&FrameBatchResponse {
                    frames: solved.into_iter().map(Solved::into_response).collect(),
                })
                .map_err(ServiceError::internal_from)?,
            };
            Ok((out, n, solve_ms))
        })
        .await?;
    let span = tracing::Span::current();
    span.record("solve_ms", solve_ms);
    span.record("frames", n);
    Ok(match form {
        Form::Json => json_bytes(out),
        Form::Binary => ([(header::CONTENT_TYPE, HeaderValue::from_static(binary::CONTENT_TYPE))], out).into_response(),
    })
}

/// Refuses a batch whose answer would hold more than `max` bytes of f32
/// data (frames × vertices × 12, 48 with gradients) before solving it: the
/// answer, unlike the request, is not bounded by the body limit.
fn check_batch_size(entry: &Entry, frames: &[Frame], max: u64) -> Result<(), ServiceError> {
    let v = entry.binding.n_vertices() as u64;
    let bytes: u64 = frames.iter().map(|f| v * if f.gradients { 48 } else { 12 }).sum();
    if bytes > max {
        return Err(ServiceError::new(
            Code::LimitExceeded,
            format!(
                "the batch's answer would hold {bytes} bytes ({} frames of {v} vertices), more than this server's \
                 limit of {max} (--max-batch-bytes, CURVENET_MAX_BATCH_BYTES); split it",
                frames.len()
            ),
        ));
    }
    Ok(())
}

/// Parses and validates the frames of a request (on the solve pool).
fn parse_frames(
    entry: &Entry,
    form: Form,
    bytes: &[u8],
    batch: bool,
    max_batch_bytes: u64,
) -> Result<Vec<Frame>, ServiceError> {
    let vertices = entry.binding.n_vertices();
    let max_frames = crate::bounded::max_frames(max_batch_bytes, vertices);
    let frames: Vec<Frame> = match form {
        Form::Json if batch => match crate::bounded::frames::<FrameRequest>(bytes, max_frames) {
            Ok(f) => f.into_iter().map(Frame::from).collect(),
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
        Form::Json => vec![parse_json::<FrameRequest>(bytes)?.into()],
        Form::Binary => {
            let pools: Vec<usize> =
                (0..entry.binding.n_curvenets()).map(|k| entry.binding.n_control_points(k)).collect();
            let expected = binary::Expected { pools: &pools, vertices, blend_shapes: entry.n_shapes, max_frames };
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
    };
    for (i, f) in frames.iter().enumerate() {
        frames::validate(entry, f).map_err(|e| if batch { e.context(&format!("frames[{i}]")) } else { e })?;
    }
    Ok(frames)
}

/// Binds (through the cache) and deforms one frame in one request.
#[utoipa::path(post, path = "/v1/deform", tag = "frames", security(("bearer" = [])),
    request_body = DeformRequest,
    responses(
        (status = 200, description = "The deformed frame", body = DeformResponse),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 422, description = "The binding or the frame is invalid", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn deform(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ServiceError> {
    form(&headers, false)?;
    let bytes = read_body(&state, body).await?;
    let req: DeformRequest = blocking(move || parse_json(&bytes)).await?;
    let (entry, cached) = match bind(&state, req.binding).await {
        Ok(r) => r,
        Err(e) => return Err(e.context("binding")),
    };
    let permit = state.permit().await?;
    let frame = Frame::from(req.frame);
    let metrics = state.inner.metrics.clone();
    let solved = state
        .on_pool(move || {
            let _permit = permit;
            frames::validate(&entry, &frame).map_err(|e| e.context("frame"))?;
            let s = frames::solve(&entry, &frame).map_err(|e| e.context("frame"))?;
            metrics.solve_seconds.record(s.solve_ms / 1e3);
            metrics.frames_solved.increment(1);
            Ok(DeformResponse { binding_id: entry.id.clone(), cached, frame: s.into_response() })
        })
        .await?;
    tracing::Span::current().record("solve_ms", solved.frame.solve_ms);
    Ok(Json(solved).into_response())
}

/// Bakes a shot stage on the server's file system (inside the bake roots).
#[utoipa::path(post, path = "/v1/bake", tag = "bake", security(("bearer" = [])),
    request_body = BakeRequest,
    responses(
        (status = 200, description = "Baked", body = BakeResponse),
        (status = 403, description = "path_forbidden: a path outside the bake roots", body = ErrorBody),
        (status = 404, description = "stage_not_found", body = ErrorBody),
        (status = 422, description = "bake_failed", body = ErrorBody),
        (status = 503, description = "saturated or unavailable (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn bake(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ServiceError> {
    form(&headers, false)?;
    let bytes = read_body(&state, body).await?;
    let req: BakeRequest = parse_json(&bytes)?;
    let roots = state.inner.bake_roots.clone();
    let job = blocking(move || {
        Ok(BakeJob {
            stage: check_stage(&req.stage, &roots)?,
            output: check_output(&req.output, &roots)?,
            frames: req.frames,
            roots,
        })
    })
    .await?;
    let baker =
        state.inner.baker.clone().ok_or_else(|| ServiceError::internal("this server was started without a baker"))?;
    let permit = state.permit().await?;
    let t = Instant::now();
    let job2 = job.clone();
    blocking(move || {
        let _permit = permit;
        baker(&job2).map_err(|f| match f {
            BakeFailure::Input(m) => ServiceError::new(Code::BakeFailed, m),
            BakeFailure::Retry(m) => ServiceError::new(Code::Unavailable, m),
            BakeFailure::Forbidden(m) => ServiceError::new(Code::PathForbidden, m),
        })
    })
    .await?;
    Ok(Json(BakeResponse {
        stage: job.stage.display().to_string(),
        output: job.output.display().to_string(),
        elapsed_ms: t.elapsed().as_secs_f64() * 1e3,
    })
    .into_response())
}
