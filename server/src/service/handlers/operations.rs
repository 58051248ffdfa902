//! Operations: `/healthz`, `/readyz`, `/metrics` (Prometheus text);
//! `/openapi.json` is served by openapi.rs.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::HealthResponse;

use crate::state::AppState;

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
    inner.metrics.batch_memory_bytes.set(state.batch_memory_held() as f64);
    inner.metrics.bindings_running.set(inner.jobs.len() as f64);
    inner.metrics.bindings_cancelled.absolute(inner.jobs.cancelled());
    ([(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4"))], inner.metrics.render())
        .into_response()
}
