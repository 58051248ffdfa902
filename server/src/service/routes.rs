//! The router: every route and the layers around it (request ids, tracing,
//! panics, closing connections whose request body went unread, the
//! declared-length check, the token, the request metrics). The
//! handlers live in one file per resource (bindings.rs, frames.rs,
//! batches.rs, deform.rs, bake.rs, operations.rs, viewer/); the steps they
//! share are extractors (extract.rs) and the one solve helper (pool.rs).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{HeaderValue, header};
use axum::middleware::{Next, from_fn_with_state};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::request_id::{MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use tracing::field::Empty;

use crate::error::{Code, ServiceError};
use crate::extract::too_large;
use crate::handlers::{bake, batches, bindings, deform, frames, operations};
use crate::state::{AppState, panic_message};
use crate::viewer;

/// The whole service: `/v1` API, `/healthz`, `/readyz`, `/metrics`, `/openapi.json`.
pub fn app(state: AppState) -> Router {
    let open = Router::new()
        .route("/healthz", get(operations::healthz))
        .route("/readyz", get(operations::readyz))
        // The viewer page holds no data (it asks for the token itself).
        .route("/viewer", get(viewer::page))
        .route("/viewer/js/{module}", get(viewer::module))
        .route("/viewer/viewer.css", get(viewer::style));
    let api = Router::new()
        .route("/v1/bindings", post(bindings::create_binding))
        .route("/v1/bindings/{id}", get(bindings::get_binding).delete(bindings::delete_binding))
        .route("/v1/bindings/{id}/frames", post(frames::post_frames))
        .route("/v1/bindings/{id}/frames:batch", post(batches::post_frames_batch))
        .route("/v1/deform", post(deform::deform))
        .route("/v1/bake", post(bake::bake))
        .route("/v1/bindings/{id}/viewer-data", get(viewer::viewer_data))
        .route("/v1/bindings/{id}/viewer-frame", post(viewer::viewer_frame))
        .route("/v1/viewer/stages", get(viewer::stages))
        .route("/v1/viewer/stages/{index}", get(viewer::stage))
        .route("/v1/viewer/stages/{index}/frames/{k}", get(viewer::stage_frame).post(viewer::stage_frame_adjusted))
        .route("/v1/viewer/stages/{index}/export", post(viewer::stage_export))
        .route("/v1/viewer/stages/{index}/refusal", get(viewer::stage_refusal))
        .route("/metrics", get(operations::metrics))
        .route("/openapi.json", get(crate::openapi::openapi_json))
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
                .layer(axum::middleware::from_fn(close_if_unread))
                .layer(CatchPanicLayer::custom(|panic: Box<dyn std::any::Any + Send + 'static>| {
                    ServiceError::internal(format!("a handler panicked: {}", panic_message(&panic))).into_response()
                }))
                // Bodies are read by `SizedBody` with the configured limit, not axum's 2 MB default.
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

/// Answers that leave part of the request body unread (a refusal before
/// the body is read: an unknown binding, a wrong token, a declared length
/// over the limit) say `Connection: close`. The rest of the body is still
/// on the connection, so it cannot carry the client's next request; hyper
/// closes it after the answer, and without the header a keep-alive client
/// would send its next request into a connection about to close.
async fn close_if_unread(req: Request, next: Next) -> Response {
    let read = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let req = req.map(|body| {
        read.store(http_body::Body::is_end_stream(&body), Ordering::Relaxed);
        axum::body::Body::new(Watched { inner: body, read: read.clone() })
    });
    let mut response = next.run(req).await;
    if !read.load(Ordering::Relaxed) {
        response.headers_mut().insert(header::CONNECTION, HeaderValue::from_static("close"));
    }
    response
}

/// A request body that records when it has been read to its end.
struct Watched {
    inner: axum::body::Body,
    read: Arc<std::sync::atomic::AtomicBool>,
}

impl http_body::Body for Watched {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        let this = self.get_mut();
        let polled = std::pin::Pin::new(&mut this.inner).poll_frame(cx);
        if matches!(polled, std::task::Poll::Ready(None)) || this.inner.is_end_stream() {
            this.read.store(true, Ordering::Relaxed);
        }
        polled
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.inner.size_hint()
    }
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
