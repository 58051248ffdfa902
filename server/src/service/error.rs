//! The service's one error type. Every error has a stable snake_case code;
//! [`Code::status`] is the one table mapping codes to HTTP statuses and
//! [`classify`] the one table mapping core errors to codes. Bad input
//! answers 4xx with a message naming the offending array and index and
//! `details` naming the same elements by field; internal failures are
//! logged and answered with a generic message.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use curvenet_schema::wire::{ErrorBody, ErrorDetails, SegmentId};

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

/// An error answer: a code, a message for the client and the elements it
/// names. For `internal` the message is logged and the client gets a
/// generic one (and no details).
#[derive(Debug, Clone)]
pub struct ServiceError {
    pub code: Code,
    pub message: String,
    /// The elements the error is about (`details` of the answer).
    pub details: Option<Box<ErrorDetails>>,
    /// The core stopped because the service raised its cancel flag
    /// (`curvenet_core::Error::Cancelled`); the caller knows why.
    pub(crate) cancelled: bool,
}

impl ServiceError {
    pub fn new(code: Code, message: impl Into<String>) -> Self {
        Self { code, message: message.into(), details: None, cancelled: false }
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

    /// Prefixes the message with `context: ` (e.g. `binding`).
    pub fn context(mut self, context: &str) -> Self {
        if self.code != Code::Internal {
            self.message = format!("{context}: {}", self.message);
        }
        self
    }

    /// Adds to the details (`f` fills in the fields it knows).
    pub fn detail(mut self, f: impl FnOnce(&mut ErrorDetails)) -> Self {
        f(self.details.get_or_insert_with(Default::default));
        self
    }

    /// The error of frame `i` of a batch: `frames[i]: ` before the message, `frame: i` in the details.
    pub fn in_frame(self, i: usize) -> Self {
        self.context(&format!("frames[{i}]")).detail(|d| d.frame = Some(i))
    }

    /// The error of curvenet `k` of a binding request: `curvenets[k]: ` before the message, `curvenet: k` in the details.
    pub fn in_curvenet(self, k: usize) -> Self {
        self.context(&format!("curvenets[{k}]")).detail(|d| d.curvenet = Some(k as u32))
    }

    /// A core error raised while binding (`Phase::Bind`) or solving a frame:
    /// its code (see [`classify`]), its message and the elements it names.
    pub fn core(e: curvenet_core::Error, phase: Phase) -> Self {
        if let curvenet_core::Error::Curvenet { curvenet, source } = e {
            // The message starts `curvenets[k]: `, as documented.
            return Self::core(*source, phase).in_curvenet(curvenet as usize);
        }
        let mut details = ErrorDetails::default();
        let code = classify(&e, phase, &mut details);
        let details = (details != ErrorDetails::default()).then(|| Box::new(details));
        let cancelled = matches!(e, curvenet_core::Error::Cancelled { .. });
        Self { code, message: e.to_string(), details, cancelled }
    }

    /// An error of `curvenet_core::Deformer::new`, numbered as the binding
    /// request numbers its arrays: an error about one curvenet's own shape
    /// starts `curvenets[k]: `, an error about the mesh `mesh: `.
    pub fn binding(e: curvenet_core::Error) -> Self {
        use curvenet_core::Error as E;
        match e {
            E::Curvenet { curvenet, source } => Self::core(*source, Phase::Bind).in_curvenet(curvenet as usize),
            e if is_mesh_error(&e) => Self::core(e, Phase::Bind).context("mesh"),
            e => Self::core(e, Phase::Bind),
        }
    }
}

/// Where a core error was raised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Bind,
    Frame,
}

/// The service code of every core error, and the elements it names into
/// `details`. Every variant is listed (no catch-all): a new core error does
/// not compile until it has a code here, in server/README.md and the OpenAPI.
pub fn classify(e: &curvenet_core::Error, phase: Phase, d: &mut ErrorDetails) -> Code {
    use curvenet_core::Error as E;
    use curvenet_core::SegmentRef;
    let frame = phase == Phase::Frame;
    let segment = |d: &mut ErrorDetails, s: &SegmentRef| {
        d.curvenet = Some(s.curvenet);
        d.spline = Some(s.spline);
        d.segment = Some(s.segment);
    };
    let other = |s: &SegmentRef| Some(SegmentId { curvenet: s.curvenet, spline: s.spline, segment: s.segment });
    let what = |w: &str| Some(w.to_string());
    match e {
        // The rig underneath (skinning) is read from USD by the command line;
        // the service takes no rig yet, so this names the input it refused.
        E::Skinning(_) => {
            d.what = what("skinning");
            Code::InvalidParameter
        }
        // The cage of a coupled cage-and-skeleton rig (or a frame's cage
        // arrays): the message names the face, edge, vertex or field.
        E::Cage(c) => {
            use curvenet_core::CageError as C;
            d.what = what("cage");
            match c {
                C::IndexOutOfRange { face, vertex, .. } => {
                    (d.face, d.vertex) = (Some(*face), Some(*vertex));
                    return Code::IndexOutOfRange;
                }
                C::DegenerateFace { face, vertices } => (d.face, d.vertices) = (Some(*face), Some(vertices.to_vec())),
                C::NonFinite { index, .. } => {
                    d.index = Some(*index);
                    return Code::NonFinite;
                }
                C::UnusedVertex { vertex } => d.vertex = Some(*vertex as u32),
                C::OpenEdge { a, b, face } => (d.edge, d.face) = (Some([*a, *b]), Some(*face)),
                C::NonManifoldEdge { a, b, faces } => (d.edge, d.faces) = (Some([*a, *b]), Some(faces.clone())),
                C::FlippedFace { face, neighbour, a, b } => {
                    (d.edge, d.face, d.faces) =
                        (Some([*a, *b]), Some(*face), Some(vec![*face as u32, *neighbour as u32]));
                }
                C::SingularMaxVol { vertex, .. } => d.vertex = Some(*vertex as u32),
                C::Count { what: w, expected, got } => {
                    (d.what, d.expected, d.got) = (what(w), Some(*expected), Some(*got));
                    return Code::CountMismatch;
                }
                C::SingularCageRev { .. } | C::JointCoordinates { .. } => return Code::DegeneratePose,
                C::UnlocalizedJoint { .. } | C::Missing { .. } => return Code::InvalidParameter,
                C::TooSmall { .. } | C::InsideOut { .. } => {}
                // `CageError` is non-exhaustive: a new variant is a bad cage until named here.
                _ => {}
            }
            Code::InvalidMesh
        }
        E::Empty { what: w } => {
            d.what = what(w);
            Code::EmptyInput
        }
        E::FaceCountMismatch { counts_sum, indices_len } => {
            d.what = what("face_vertex_indices");
            d.expected = Some(*counts_sum);
            d.got = Some(*indices_len);
            Code::CountMismatch
        }
        E::CountMismatch { what: w, expected, got } => {
            d.what = what(w);
            d.expected = Some(*expected);
            d.got = Some(*got);
            Code::CountMismatch
        }
        // An adjustment naming a curvenet or control point past the end: the
        // adjustment and what it names (the service adds the curvenet of a knot).
        E::IndexOutOfRange { what: "adjustment", index, target, value, .. } => {
            d.adjustment = Some(*index);
            if *target == "curvenet" {
                d.curvenet = Some(*value);
            } else {
                d.control_point = Some(*value);
            }
            Code::IndexOutOfRange
        }
        E::IndexOutOfRange { what: w, index, .. } => {
            d.what = what(w);
            d.index = Some(*index);
            Code::IndexOutOfRange
        }
        E::NonFinite { what: w, index, .. } => {
            d.what = what(w);
            d.index = Some(*index);
            // In a frame, a non-finite value the request did not carry (it is checked) comes from a degenerate pose.
            if frame { Code::DegeneratePose } else { Code::NonFinite }
        }
        E::NonFiniteScalar { what: w, index, .. } => {
            d.what = what(w);
            d.index = Some(*index);
            Code::NonFinite
        }
        E::Curvenet { curvenet, source } => {
            let code = classify(source, phase, d);
            d.curvenet = Some(*curvenet);
            code
        }
        // The curvenet tracked onto the frame's rest pose degenerated: the
        // source's code and elements, and `what: "rest"` (the frame field).
        E::RestPose { source } => {
            let code = classify(source, phase, d);
            d.what = what("rest");
            code
        }
        E::DegenerateFaceCount { face, .. } | E::FoldedFace { face } => {
            d.face = Some(*face);
            Code::InvalidMesh
        }
        E::NonManifoldEdge { a, b, faces, .. } => {
            d.edge = Some([*a, *b]);
            d.faces = Some(faces.clone());
            Code::InvalidMesh
        }
        E::InconsistentOrientation { a, b, faces } => {
            d.edge = Some([*a, *b]);
            d.faces = Some(faces.to_vec());
            Code::InvalidMesh
        }
        E::NonManifoldVertex { vertex, .. } => {
            d.vertex = Some(*vertex);
            Code::InvalidMesh
        }
        E::CoincidentFaceVertices { face, a, b } => {
            d.face = Some(*face);
            d.vertices = Some(vec![*a, *b]);
            Code::InvalidMesh
        }
        E::ZeroAreaFace { face, vertices, .. } => {
            d.face = Some(*face);
            d.vertices = Some(vertices.clone());
            Code::InvalidMesh
        }
        E::IllConditionedFace { vertex, face, vertices, .. } => {
            d.vertex = Some(*vertex);
            d.face = Some(*face);
            d.vertices = Some(vertices.clone());
            Code::InvalidMesh
        }
        E::RepeatedFaceVertex { face, vertex } => {
            d.face = Some(*face);
            d.vertex = Some(*vertex);
            Code::InvalidMesh
        }
        E::SampleFarFromSurface { at, position, .. } => {
            d.curvenet = Some(at.curvenet);
            d.spline = Some(at.spline);
            d.sample = Some(at.sample);
            d.position = Some(*position);
            Code::BindingFailed
        }
        E::SegmentNotTraced { segment: s } => {
            segment(d, s);
            Code::BindingFailed
        }
        E::SegmentDetour { segment: s, t, position, .. } => {
            segment(d, s);
            d.t = Some(*t);
            d.position = Some(*position);
            Code::BindingFailed
        }
        E::CurvesOverlap { segment: s, other: o } => {
            segment(d, s);
            d.other = other(o);
            Code::BindingFailed
        }
        E::CurvesCross { segment: s, other: o, face } => {
            segment(d, s);
            d.other = other(o);
            d.face = Some(*face as usize);
            Code::BindingFailed
        }
        E::SegmentCrossesFaceBoundary { segment: s, face } => {
            segment(d, s);
            d.face = Some(*face as usize);
            Code::BindingFailed
        }
        E::CurveCollapsedOnSurface { segment: s, position } => {
            segment(d, s);
            d.position = Some(*position);
            Code::BindingFailed
        }
        E::UntouchedComponent { component, .. } => {
            d.component = Some(*component);
            Code::BindingFailed
        }
        E::NotPositiveDefinite { pivot } => {
            d.row = *pivot;
            Code::BindingFailed
        }
        E::DegenerateSurfaceFace { point, face } => {
            d.control_point = Some(*point);
            d.face = Some(*face);
            Code::BindingFailed
        }
        E::ZeroLengthSpline { spline } => {
            d.spline = Some(*spline as u32);
            Code::InvalidCurvenet
        }
        E::TooManySegments { spline, .. } => {
            d.spline = Some(*spline as u32);
            Code::InvalidCurvenet
        }
        E::CoincidentTangents { point, splines } => {
            d.control_point = Some(*point);
            d.splines = Some(splines.map(|s| s as u32));
            Code::InvalidCurvenet
        }
        E::TangentAlongNormal { point, spline } => {
            d.control_point = Some(*point);
            d.spline = Some(*spline as u32);
            Code::InvalidCurvenet
        }
        E::SegmentCollapsed { spline, segment, .. } => {
            d.spline = Some(*spline as u32);
            d.segment = Some(*segment as u32);
            if frame { Code::DegeneratePose } else { Code::InvalidCurvenet }
        }
        E::DegenerateIntersection { point } | E::UndeterminedKnotOrientation { point } => {
            d.control_point = Some(*point);
            if frame { Code::DegeneratePose } else { Code::InvalidCurvenet }
        }
        E::NotAKnot { adjustment, curvenet, point } | E::InvalidAdjustment { adjustment, curvenet, point, .. } => {
            d.adjustment = Some(*adjustment);
            d.curvenet = Some(*curvenet as u32);
            d.control_point = Some(*point);
            Code::InvalidParameter
        }
        E::TangentTranslateCount { adjustment, curvenet, point, expected, got } => {
            d.adjustment = Some(*adjustment);
            d.curvenet = Some(*curvenet as u32);
            d.control_point = Some(*point);
            d.expected = Some(*expected);
            d.got = Some(*got);
            Code::CountMismatch
        }
        E::DuplicateAdjustment { curvenet, point, adjustments } => {
            d.curvenet = Some(*curvenet as u32);
            d.control_point = Some(*point);
            d.adjustments = Some(*adjustments);
            Code::InvalidParameter
        }
        E::InvalidParameter { what: w, .. } => {
            d.what = what(w);
            Code::InvalidParameter
        }
        E::Unsupported { what: w } => {
            d.what = what(w);
            Code::Unsupported
        }
        // A bug: the message goes to the log, nothing to the client.
        E::Internal { .. } => Code::Internal,
        // The service raises the flag itself and answers with the reason (bindings.rs, jobs.rs).
        E::Cancelled { .. } => Code::Unavailable,
    }
}

/// Whether `e` is about the mesh itself (its connectivity or its
/// projection pose), as `Deformer::new` raises them before any curvenet is
/// looked at. Listed variant by variant, like [`classify`].
fn is_mesh_error(e: &curvenet_core::Error) -> bool {
    use curvenet_core::Error as E;
    match e {
        E::FaceCountMismatch { .. }
        | E::DegenerateFaceCount { .. }
        | E::NonManifoldEdge { .. }
        | E::InconsistentOrientation { .. }
        | E::NonManifoldVertex { .. }
        | E::CoincidentFaceVertices { .. }
        | E::ZeroAreaFace { .. }
        | E::IllConditionedFace { .. }
        | E::FoldedFace { .. }
        | E::RepeatedFaceVertex { .. } => true,
        E::Empty { .. }
        | E::Skinning(_)
        | E::Cage(_)
        | E::IndexOutOfRange { .. }
        | E::NonFinite { .. }
        | E::NonFiniteScalar { .. }
        | E::Curvenet { .. }
        | E::RestPose { .. }
        | E::CountMismatch { .. }
        | E::SampleFarFromSurface { .. }
        | E::SegmentNotTraced { .. }
        | E::SegmentDetour { .. }
        | E::CurvesOverlap { .. }
        | E::CurvesCross { .. }
        | E::SegmentCrossesFaceBoundary { .. }
        | E::CurveCollapsedOnSurface { .. }
        | E::UntouchedComponent { .. }
        | E::NotPositiveDefinite { .. }
        | E::Unsupported { .. }
        | E::Internal { .. }
        | E::ZeroLengthSpline { .. }
        | E::CoincidentTangents { .. }
        | E::TangentAlongNormal { .. }
        | E::DegenerateSurfaceFace { .. }
        | E::SegmentCollapsed { .. }
        | E::DegenerateIntersection { .. }
        | E::TooManySegments { .. }
        | E::UndeterminedKnotOrientation { .. }
        | E::NotAKnot { .. }
        | E::InvalidAdjustment { .. }
        | E::TangentTranslateCount { .. }
        | E::DuplicateAdjustment { .. }
        | E::InvalidParameter { .. }
        | E::Cancelled { .. } => false,
    }
}

impl std::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.code.as_str(), self.message)
    }
}

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        let status = self.code.status();
        let (message, details) = if self.code == Code::Internal {
            tracing::error!(error = %self.message, "internal error");
            ("internal error; the details are in the server log under this request's x-request-id".to_string(), None)
        } else {
            if status.is_server_error() {
                tracing::warn!(code = self.code.as_str(), error = %self.message);
            } else {
                tracing::debug!(code = self.code.as_str(), error = %self.message);
            }
            (self.message, self.details.map(|d| *d))
        };
        let body = ErrorBody { code: self.code.as_str().into(), message, details };
        let mut response = (status, axum::Json(body)).into_response();
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

#[cfg(test)]
mod tests {
    use curvenet_core::Error as E;
    use curvenet_core::{SampleRef, SegmentRef};

    use super::*;

    fn seg(curvenet: u32, spline: u32, segment: u32) -> SegmentRef {
        SegmentRef { curvenet, spline, segment }
    }

    #[test]
    fn core_errors_get_their_code_and_name_their_elements() {
        let e =
            ServiceError::core(E::CurvesCross { segment: seg(0, 3, 7), other: seg(1, 5, 2), face: 118 }, Phase::Bind);
        assert_eq!(e.code, Code::BindingFailed);
        let d = e.details.as_deref().unwrap();
        assert_eq!((d.curvenet, d.spline, d.segment, d.face), (Some(0), Some(3), Some(7), Some(118)));
        assert_eq!(d.other, Some(SegmentId { curvenet: 1, spline: 5, segment: 2 }));

        let e = ServiceError::core(
            E::SampleFarFromSurface {
                at: SampleRef { curvenet: 2, spline: 4, sample: 9 },
                position: [1.0, 2.0, 3.0],
                distance: 1.0,
                limit: 0.1,
            },
            Phase::Bind,
        );
        let d = e.details.as_deref().unwrap();
        assert_eq!((d.curvenet, d.spline, d.sample, d.position), (Some(2), Some(4), Some(9), Some([1.0, 2.0, 3.0])));

        let e = ServiceError::core(E::NotPositiveDefinite { pivot: Some(12) }, Phase::Bind);
        assert_eq!((e.code, e.details.as_deref().and_then(|d| d.row)), (Code::BindingFailed, Some(12)));
        let e = ServiceError::core(E::CoincidentFaceVertices { face: 4, a: 1, b: 2 }, Phase::Bind);
        assert_eq!(e.code, Code::InvalidMesh);
        assert_eq!(e.details.as_deref().and_then(|d| d.vertices.clone()), Some(vec![1, 2]));
        let e = ServiceError::core(
            E::NonFiniteScalar { what: "blend-shape weight", index: 3, value: f64::NAN },
            Phase::Frame,
        );
        assert_eq!((e.code, e.details.as_deref().and_then(|d| d.index)), (Code::NonFinite, Some(3)));
        let e = ServiceError::core(
            E::SegmentDetour {
                segment: seg(0, 1, 2),
                t: 0.5,
                position: [0.0; 3],
                path_length: 3.0,
                segment_length: 1.0,
            },
            Phase::Bind,
        );
        assert_eq!((e.code, e.details.as_deref().and_then(|d| d.t)), (Code::BindingFailed, Some(0.5)));
    }

    #[test]
    fn the_phase_decides_between_a_bad_curvenet_and_a_degenerate_pose() {
        let collapsed = || E::SegmentCollapsed { spline: 1, segment: 2, length: 0.0 };
        assert_eq!(ServiceError::core(collapsed(), Phase::Bind).code, Code::InvalidCurvenet);
        assert_eq!(ServiceError::core(collapsed(), Phase::Frame).code, Code::DegeneratePose);
        let nan = || E::NonFinite { what: "deformed point", index: 5, value: [f64::NAN; 3] };
        assert_eq!(ServiceError::core(nan(), Phase::Bind).code, Code::NonFinite);
        assert_eq!(ServiceError::core(nan(), Phase::Frame).code, Code::DegeneratePose);
    }

    #[test]
    fn deformer_errors_are_numbered_as_the_request() {
        // A curvenet's own error: `curvenets[k]: `, its code and details, and the curvenet.
        let e = ServiceError::binding(E::Curvenet {
            curvenet: 1,
            source: Box::new(E::CoincidentTangents { point: 7, splines: [0, 3] }),
        });
        assert_eq!(e.code, Code::InvalidCurvenet);
        assert!(e.message.starts_with("curvenets[1]: splines [0, 3] leave"), "{}", e.message);
        let d = e.details.as_deref().unwrap();
        assert_eq!((d.curvenet, d.control_point, d.splines), (Some(1), Some(7), Some([0, 3])));
        // A mesh error: `mesh: `.
        let e = ServiceError::binding(E::FoldedFace { face: 9 });
        assert_eq!(
            (e.code, e.message.as_str()),
            (
                Code::InvalidMesh,
                "mesh: face 9 folds over itself (its projection onto its own plane is not a simple counter-clockwise polygon)"
            )
        );
        // Cancellation is flagged for the caller, which answers with the reason.
        let e = ServiceError::binding(E::Cancelled { stage: "cutting" });
        assert!(e.cancelled && e.details.is_none());
    }

    async fn body(e: ServiceError) -> (StatusCode, serde_json::Value) {
        let r = e.into_response();
        let status = r.status();
        let b = axum::body::to_bytes(r.into_body(), usize::MAX).await.unwrap();
        (status, serde_json::from_slice(&b).unwrap())
    }

    #[tokio::test]
    async fn details_are_answered_except_for_internal_errors() {
        let (status, v) = body(ServiceError::new(Code::InvalidMesh, "m").detail(|d| d.face = Some(1))).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
        assert_eq!(v, serde_json::json!({"code": "invalid_mesh", "message": "m", "details": {"face": 1}}));
        let (status, v) = body(ServiceError::new(Code::NotFound, "m")).await;
        assert_eq!((status, v.get("details")), (StatusCode::NOT_FOUND, None));
        let (status, v) = body(ServiceError::internal("a bug at face 1").detail(|d| d.face = Some(1))).await;
        assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR);
        assert!(v.get("details").is_none() && !v["message"].as_str().unwrap().contains("a bug"), "{v}");
    }
}
