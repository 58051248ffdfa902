//! In-process requests to a service's router (`tower::ServiceExt::oneshot`,
//! no socket): the helpers the service tests share.

use axum::Router;
use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, Request, StatusCode, header};
use curvenet_schema::wire::{BindingRequest, BindingResponse};
use tower::ServiceExt as _;

/// Sends `req` to `app`: the status, headers and whole body.
pub async fn send(app: &Router, req: Request<Body>) -> (StatusCode, HeaderMap, Bytes) {
    let r = app.clone().oneshot(req).await.unwrap();
    let status = r.status();
    let headers = r.headers().clone();
    let body = axum::body::to_bytes(r.into_body(), usize::MAX).await.unwrap();
    (status, headers, body)
}

/// `POST uri` with `body` as JSON.
pub fn post_json(uri: &str, body: &impl serde::Serialize) -> Request<Body> {
    Request::post(uri)
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(serde_json::to_vec(body).unwrap()))
        .unwrap()
}

/// `GET uri`.
pub fn get(uri: &str) -> Request<Body> {
    Request::get(uri).body(Body::empty()).unwrap()
}

/// Posts `req` to `/v1/bindings`, which must answer 200.
pub async fn post_binding(app: &Router, req: &BindingRequest) -> BindingResponse {
    let (status, _, body) = send(app, post_json("/v1/bindings", req)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

/// The value of the unlabelled metric `name` in `/metrics`, if it is there
/// (a counter never incremented may not be).
pub async fn metric_opt(app: &Router, name: &str) -> Option<f64> {
    let (status, _, body) = send(app, get("/metrics")).await;
    assert_eq!(status, StatusCode::OK);
    let text = String::from_utf8(body.to_vec()).unwrap();
    text.lines().find_map(|l| l.strip_prefix(name).and_then(|r| r.strip_prefix(' '))).map(|v| v.trim().parse().unwrap())
}

/// The metric `name`, which must be in `/metrics`.
pub async fn metric(app: &Router, name: &str) -> f64 {
    metric_opt(app, name).await.unwrap_or_else(|| panic!("{name} not in /metrics"))
}
