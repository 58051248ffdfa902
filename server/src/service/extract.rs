//! The steps every route shares, as axum extractors, in the order a
//! handler lists them (request parts first, the body last):
//!
//! ```text
//! ContentType<A>   the Content-Type: JSON, or (A = JsonOrBinary) the binary frame form; else 415
//! Params<T>        path parameters; one that does not parse is a JSON 404
//! CachedBinding    the binding named by the path's {id}, from the cache; else 404 unknown_binding
//! SizedBody        the body, read within --body-limit (413) and the body timeout and rate (408)
//! Admitted<T>      T (the body), then a solve permit: waits in line up to --queue-timeout, else 503
//! ```
//!
//! A route that must admit its solve later (`/v1/deform` binds first, and
//! the binding takes a permit of its own) takes an [`Admission`] itself.

use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::request::Parts;
use axum::http::{HeaderMap, header};
use http_body_util::BodyExt;
use tokio::sync::OwnedSemaphorePermit;

use crate::binary;
use crate::entry::{Entry, parse_key};
use crate::error::{Code, ServiceError};
use crate::state::AppState;

// ---------------------------------------------------------------- content type

/// The form of a body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Form {
    Json,
    Binary,
}

/// What a route accepts: [`JsonOnly`] or [`JsonOrBinary`].
pub(crate) trait Accepts {
    const BINARY: bool;
}

/// JSON only (`application/json`, `*+json`, or no Content-Type).
pub(crate) struct JsonOnly;
impl Accepts for JsonOnly {
    const BINARY: bool = false;
}

/// JSON or the binary frame form (`application/octet-stream`).
pub(crate) struct JsonOrBinary;
impl Accepts for JsonOrBinary {
    const BINARY: bool = true;
}

/// The body's form, checked against what the route accepts (415 otherwise).
pub(crate) struct ContentType<A>(pub Form, pub PhantomData<A>);

impl<A: Accepts, S: Send + Sync> FromRequestParts<S> for ContentType<A> {
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ServiceError> {
        form(&parts.headers, A::BINARY).map(|f| ContentType(f, PhantomData))
    }
}

/// The form of a body with these headers (JSON when no Content-Type is given).
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

/// Parses a JSON body (`malformed_json` naming the line and column).
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ServiceError> {
    serde_json::from_slice(bytes)
        .map_err(|e| ServiceError::new(Code::MalformedJson, format!("the JSON body is invalid: {e}")))
}

// ---------------------------------------------------------------- the body

/// The whole body, read within the server's limits (see [`read_body`]).
pub(crate) struct SizedBody(pub Bytes);

impl FromRequest<AppState> for SizedBody {
    type Rejection = ServiceError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ServiceError> {
        read_body(state, req.into_body()).await.map(SizedBody)
    }
}

/// `payload_too_large` for a body over `limit` bytes.
pub(crate) fn too_large(limit: usize) -> ServiceError {
    ServiceError::new(
        Code::PayloadTooLarge,
        format!("the body is larger than the server's limit of {limit} bytes (--body-limit)"),
    )
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

// ---------------------------------------------------------------- path and binding

/// Path parameters whose parse failure (`/v1/viewer/stages/-1`) is a JSON
/// `not_found` like every other error, not axum's plain-text rejection.
pub(crate) struct Params<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> FromRequestParts<S> for Params<T> {
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ServiceError> {
        match Path::<T>::from_request_parts(parts, state).await {
            Ok(Path(t)) => Ok(Params(t)),
            Err(e) => Err(ServiceError::new(
                Code::NotFound,
                format!("{} does not exist: {}", parts.uri.path(), e.body_text()),
            )),
        }
    }
}

/// The cached binding the path's `{id}` names (404 `unknown_binding` when
/// it is not cached: the client posts it again).
pub(crate) struct CachedBinding(pub Arc<Entry>);

impl FromRequestParts<AppState> for CachedBinding {
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ServiceError> {
        let Params(id) = Params::<String>::from_request_parts(parts, state).await?;
        lookup(state, &id).await.map(CachedBinding)
    }
}

/// Finds a cached binding or answers `unknown_binding`.
pub(crate) async fn lookup(state: &AppState, id: &str) -> Result<Arc<Entry>, ServiceError> {
    tracing::Span::current().record("binding_id", id);
    let key = parse_key(id).ok_or_else(|| ServiceError::unknown_binding(id))?;
    state.inner.cache.get(&key).await?.ok_or_else(|| ServiceError::unknown_binding(id))
}

// ---------------------------------------------------------------- admission

/// The right to solve: one solve permit, and for a batch the permits that
/// were free besides it (one per extra frame solved at once). Dropped when
/// the solve is done.
pub(crate) struct Admission {
    _permit: OwnedSemaphorePermit,
    /// A batch's spare batch slots and the permits they go with.
    spare: Option<(OwnedSemaphorePermit, OwnedSemaphorePermit)>,
}

impl Admission {
    /// Takes one solve permit, waiting in line for it (fairly) when all are
    /// taken, at most `--queue-timeout` (see [`AppState::permit`]).
    pub(crate) async fn one(state: &AppState) -> Result<Self, ServiceError> {
        Ok(Self { _permit: state.permit().await?, spare: None })
    }

    /// Also takes whatever permits (each with a batch slot) are free right
    /// now, up to one per solve thread in all: a batch solves that many
    /// groups at once.
    pub(crate) fn widen(mut self, state: &AppState) -> Self {
        self.spare = state.spare_permits(state.solve_threads().saturating_sub(1) as u32);
        self
    }

    /// Frames this admission may solve at once.
    pub(crate) fn parallel(&self) -> usize {
        1 + self.spare.as_ref().map_or(0, |(_, p)| p.num_permits())
    }
}

/// `T` (the body), then an [`Admission`]: the body is read before the
/// request waits for a permit, so a slow client holds none.
pub(crate) struct Admitted<T>(pub T, pub Admission);

impl<T: FromRequest<AppState, Rejection = ServiceError> + Send> FromRequest<AppState> for Admitted<T> {
    type Rejection = ServiceError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ServiceError> {
        let t = T::from_request(req, state).await?;
        Ok(Admitted(t, Admission::one(state).await?))
    }
}
