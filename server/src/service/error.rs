//! The service's one error type. Every error has a stable snake_case code;
//! [`Code::status`] is the one table mapping codes to HTTP statuses. Bad
//! input answers 4xx with a message naming the offending array and index;
//! internal failures are logged and answered with a generic message.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::ErrorBody;

/// Stable error codes (the `code` field of every error answer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Code {
    /// The body is not valid JSON for the endpoint (syntax, types, unknown fields).
    MalformedJson,
    /// A binary frame's framing or header is wrong.
    MalformedBinary,
    /// The Content-Type is neither JSON nor (where accepted) octet-stream.
    UnsupportedMediaType,
    /// Two lengths that must agree do not (names the arrays).
    CountMismatch,
    /// A NaN or infinite value (names the array and index).
    NonFinite,
    /// An index past the end of the array it indexes.
    IndexOutOfRange,
    /// A required array is empty.
    EmptyInput,
    /// The mesh is not a valid manifold polygon mesh (names the face, edge or vertex).
    InvalidMesh,
    /// A curvenet is invalid on its own (names the spline or control point).
    InvalidCurvenet,
    /// A numeric option or weight is out of range.
    InvalidParameter,
    /// The curvenets cannot be bound to this surface (far from it, crossing, ...).
    BindingFailed,
    /// The posed curvenet of a frame is degenerate (collapsed segments, ...).
    DegeneratePose,
    /// A feature the core does not support yet.
    Unsupported,
    /// The request is within the body limit but would cost more work or
    /// memory than a configured limit allows (names the element and the flag).
    LimitExceeded,
    /// The binding id is not (or no longer) cached: post the binding again.
    UnknownBinding,
    /// The frame's `topology_hash` is not the binding's topology.
    TopologyChanged,
    /// The body is larger than the server's limit.
    PayloadTooLarge,
    /// The body stalled or arrived slower than the minimum rate.
    RequestTimeout,
    /// A binding larger than the whole cache.
    CacheTooSmall,
    /// Missing or wrong bearer token.
    Unauthorized,
    /// A bake path outside the configured roots (or no roots configured).
    PathForbidden,
    /// A bake stage that does not exist.
    StageNotFound,
    /// The bake refused its input.
    BakeFailed,
    /// No such route.
    NotFound,
    /// The route exists with another method.
    MethodNotAllowed,
    /// Too many solves in flight: retry after the Retry-After delay.
    Saturated,
    /// A transient failure (e.g. bake I/O) worth retrying.
    Unavailable,
    /// A bug in the service or the core; the details are in the server log.
    Internal,
}

impl Code {
    /// Every code, in the order of the table in server/README.md.
    pub const ALL: [Code; 28] = [
        Code::MalformedJson,
        Code::MalformedBinary,
        Code::UnsupportedMediaType,
        Code::CountMismatch,
        Code::NonFinite,
        Code::IndexOutOfRange,
        Code::EmptyInput,
        Code::InvalidMesh,
        Code::InvalidCurvenet,
        Code::InvalidParameter,
        Code::BindingFailed,
        Code::DegeneratePose,
        Code::Unsupported,
        Code::LimitExceeded,
        Code::UnknownBinding,
        Code::TopologyChanged,
        Code::PayloadTooLarge,
        Code::RequestTimeout,
        Code::CacheTooSmall,
        Code::Unauthorized,
        Code::PathForbidden,
        Code::StageNotFound,
        Code::BakeFailed,
        Code::NotFound,
        Code::MethodNotAllowed,
        Code::Saturated,
        Code::Unavailable,
        Code::Internal,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Code::MalformedJson => "malformed_json",
            Code::MalformedBinary => "malformed_binary",
            Code::UnsupportedMediaType => "unsupported_media_type",
            Code::CountMismatch => "count_mismatch",
            Code::NonFinite => "non_finite",
            Code::IndexOutOfRange => "index_out_of_range",
            Code::EmptyInput => "empty_input",
            Code::InvalidMesh => "invalid_mesh",
            Code::InvalidCurvenet => "invalid_curvenet",
            Code::InvalidParameter => "invalid_parameter",
            Code::BindingFailed => "binding_failed",
            Code::DegeneratePose => "degenerate_pose",
            Code::Unsupported => "unsupported",
            Code::LimitExceeded => "limit_exceeded",
            Code::UnknownBinding => "unknown_binding",
            Code::TopologyChanged => "topology_changed",
            Code::PayloadTooLarge => "payload_too_large",
            Code::RequestTimeout => "request_timeout",
            Code::CacheTooSmall => "cache_too_small",
            Code::Unauthorized => "unauthorized",
            Code::PathForbidden => "path_forbidden",
            Code::StageNotFound => "stage_not_found",
            Code::BakeFailed => "bake_failed",
            Code::NotFound => "not_found",
            Code::MethodNotAllowed => "method_not_allowed",
            Code::Saturated => "saturated",
            Code::Unavailable => "unavailable",
            Code::Internal => "internal",
        }
    }

    /// The code → status table.
    pub fn status(self) -> StatusCode {
        match self {
            Code::MalformedJson | Code::MalformedBinary => StatusCode::BAD_REQUEST,
            Code::Unauthorized => StatusCode::UNAUTHORIZED,
            Code::PathForbidden => StatusCode::FORBIDDEN,
            Code::UnknownBinding | Code::NotFound | Code::StageNotFound => StatusCode::NOT_FOUND,
            Code::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            Code::TopologyChanged => StatusCode::CONFLICT,
            Code::PayloadTooLarge => StatusCode::PAYLOAD_TOO_LARGE,
            Code::RequestTimeout => StatusCode::REQUEST_TIMEOUT,
            Code::UnsupportedMediaType => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            Code::CountMismatch
            | Code::NonFinite
            | Code::IndexOutOfRange
            | Code::EmptyInput
            | Code::InvalidMesh
            | Code::InvalidCurvenet
            | Code::InvalidParameter
            | Code::BindingFailed
            | Code::DegeneratePose
            | Code::Unsupported
            | Code::LimitExceeded
            | Code::BakeFailed => StatusCode::UNPROCESSABLE_ENTITY,
            Code::CacheTooSmall => StatusCode::INSUFFICIENT_STORAGE,
            Code::Saturated | Code::Unavailable => StatusCode::SERVICE_UNAVAILABLE,
            Code::Internal => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }
}

/// Seconds a client should wait after `saturated` or `unavailable`.
pub const RETRY_AFTER_S: u64 = 1;

/// An error answer: a code and a message for the client. For `internal`
/// the message is logged and the client gets a generic one.
#[derive(Debug, Clone)]
pub struct ServiceError {
    pub code: Code,
    pub message: String,
    /// The core stopped because the service raised its cancel flag
    /// (`curvenet_core::Error::Cancelled`); the caller knows why.
    pub(crate) cancelled: bool,
}

impl ServiceError {
    pub fn new(code: Code, message: impl Into<String>) -> Self {
        Self { code, message: message.into(), cancelled: false }
    }

    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(Code::Internal, message)
    }

    pub fn internal_from(e: impl std::fmt::Display) -> Self {
        Self::internal(e.to_string())
    }

    pub fn unknown_binding(id: &str) -> Self {
        Self::new(
            Code::UnknownBinding,
            format!(
                "binding {id} is not cached (never posted, or evicted): POST /v1/bindings with its content again, then retry"
            ),
        )
    }

    /// Prefixes the message with `context: ` (e.g. `frames[3]`).
    pub fn context(mut self, context: &str) -> Self {
        if self.code != Code::Internal {
            self.message = format!("{context}: {}", self.message);
        }
        self
    }

    /// A core error raised while binding (`Phase::Bind`) or solving a frame.
    pub fn core(e: curvenet_core::Error, phase: Phase) -> Self {
        use curvenet_core::Error as E;
        let code = match &e {
            E::Empty { .. } => Code::EmptyInput,
            E::FaceCountMismatch { .. } | E::CountMismatch { .. } => Code::CountMismatch,
            E::IndexOutOfRange { .. } => Code::IndexOutOfRange,
            E::NonFinite { .. } if phase == Phase::Frame => Code::DegeneratePose,
            E::NonFinite { .. } => Code::NonFinite,
            E::DegenerateFaceCount { .. }
            | E::NonManifoldEdge { .. }
            | E::InconsistentOrientation { .. }
            | E::NonManifoldVertex { .. }
            | E::ZeroAreaFace { .. }
            | E::FoldedFace { .. }
            | E::RepeatedFaceVertex { .. } => Code::InvalidMesh,
            E::SampleFarFromSurface { .. }
            | E::SegmentNotTraced { .. }
            | E::SegmentDetour { .. }
            | E::CurvesOverlap { .. }
            | E::CurvesCross { .. }
            | E::SegmentCrossesFaceBoundary { .. }
            | E::UntouchedComponent { .. }
            | E::NotPositiveDefinite { .. }
            | E::DegenerateSurfaceFace { .. } => Code::BindingFailed,
            E::SegmentCollapsed { .. } | E::DegenerateIntersection { .. } if phase == Phase::Frame => {
                Code::DegeneratePose
            }
            E::ZeroLengthSpline { .. }
            | E::CoincidentTangents { .. }
            | E::TangentAlongNormal { .. }
            | E::SegmentCollapsed { .. }
            | E::DegenerateIntersection { .. }
            | E::TooManySegments { .. } => Code::InvalidCurvenet,
            E::InvalidParameter { .. } => Code::InvalidParameter,
            E::Unsupported { .. } => Code::Unsupported,
            E::Internal { .. } => Code::Internal,
            // The service raises the flag itself and maps the reason (routes.rs, jobs.rs).
            E::Cancelled { .. } => Code::Unavailable,
            _ => Code::InvalidParameter,
        };
        let cancelled = matches!(e, E::Cancelled { .. });
        Self { cancelled, ..Self::new(code, e.to_string()) }
    }
}

/// Where a core error was raised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Bind,
    Frame,
}

impl std::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.code.as_str(), self.message)
    }
}

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        let status = self.code.status();
        let message = if self.code == Code::Internal {
            tracing::error!(error = %self.message, "internal error");
            "internal error; the details are in the server log under this request's x-request-id".to_string()
        } else {
            if status.is_server_error() {
                tracing::warn!(code = self.code.as_str(), error = %self.message);
            } else {
                tracing::debug!(code = self.code.as_str(), error = %self.message);
            }
            self.message
        };
        let mut response = (status, axum::Json(ErrorBody { code: self.code.as_str().into(), message })).into_response();
        let headers = response.headers_mut();
        if matches!(self.code, Code::Saturated | Code::Unavailable) {
            headers.insert(header::RETRY_AFTER, HeaderValue::from(RETRY_AFTER_S));
        }
        if self.code == Code::Unauthorized {
            headers.insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if self.code == Code::RequestTimeout {
            // The rest of the body is not read: the connection cannot be reused.
            headers.insert(header::CONNECTION, HeaderValue::from_static("close"));
        }
        response
    }
}
