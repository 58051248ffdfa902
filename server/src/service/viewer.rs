//! The browser viewer: a page at `/viewer` (HTML, a hand-written WebGL2
//! renderer and CSS, built into the binary; nothing is loaded from anywhere
//! else) and the read-only JSON it draws.
//!
//! ```text
//! GET  /viewer, /viewer/js/{module}.js, /viewer/viewer.css the page and its ES modules (no token: they hold no data)
//! GET  /v1/viewer/stages                                  stages opened with `serve --open-stage` / `inspect --serve`
//! GET  /v1/viewer/stages/{index}                          binds the stage's mesh (through the cache): its BindingResponse
//! GET  /v1/viewer/stages/{index}/frames/{k}               frame k of the stage (with its Curvenet Adjustments), solved: a ViewerFrame
//! POST /v1/viewer/stages/{index}/frames/{k}               the same with the user's adjustments composed on top (ViewerAdjustRequest)
//! POST /v1/viewer/stages/{index}/export                   the user's adjustments as a USD layer over the stage (ViewerExportRequest → .usda)
//! GET  /v1/viewer/stages/{index}/refusal                  a stage whose binding is refused: mesh, curvenets, the element named (a ViewerRefusal)
//! GET  /v1/bindings/{id}/viewer-data                      the binding's geometry: a ViewerData
//! POST /v1/bindings/{id}/viewer-frame                     a FrameRequest, solved: a ViewerFrame
//! ```
//!
//! Frames solve through the service's one solve helper
//! (`pool::solve_frames`: a solve permit, the solve pool, validation,
//! `Deformer::frame`, the frame metrics); the posed curvenet's
//! samples and scaled frames come from `Binding::curvenet_pose`, the
//! samples and frames the solve itself uses. Positions are sent as flat
//! `f32` arrays (`[x0, y0, z0, x1, ...]`) to keep the JSON small.
//!
//! The mesh is drawn in core's own triangulation (`Surface::triangles`: the
//! triangles the closest-point queries and the cut-faces use). Warnings and
//! refusals carry [`Highlight`]s: the element a core warning or error names
//! (segments, a spline, a sample, faces, vertices), with its geometry and a
//! box to frame (see `highlight.rs`).
//!
//! A stage's frames carry its `CurvenetAdjustment` prims, read as `curvenet
//! bake` reads them; the user's adjustments replace the stage's of the same
//! knots, and export as a layer that bakes to what the viewer showed (see
//! `adjust.rs` for the decisions).

use std::sync::{Arc, Mutex};

use axum::Json;

use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use curvenet_core::Adjustment;
use curvenet_core::INVALID_INDEX;
use curvenet_core::ScaledFrame;
use curvenet_core::Surface;
use curvenet_core::{
    BindOptions, Binding, Curvenet, CurvenetInput, CurvenetLayout, Deformer, DeformerInput, DeformerOptions, Error,
    MeshInput, PolyMesh, SamplingOptions,
};
use curvenet_core::{CUT_CROSSING, CUT_MESH_VERTEX, CUT_SAMPLE};
use curvenet_schema::usd::{LayerFormat, encode_adjustment_layer};
use curvenet_schema::wire::{
    AdjustmentSpec, BindingRequest, BindingResponse, BlendShapeMode, ErrorBody, FrameRequest, Warning,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use utoipa::ToSchema;

mod adjust;
mod highlight;

pub use adjust::StageAdjustment;

pub use highlight::Highlight;
use highlight::{NetGeometry, Scene};

use crate::cache::{Entry, parse_key};
use crate::error::{Code, Phase, ServiceError};
use crate::extract::{Admission, Admitted, CachedBinding, ContentType, JsonOnly, Params, SizedBody, parse_json};
use crate::frame::{Frame, Solved};
use crate::pool::{Numbering, solve_frames};
use crate::state::{AppState, blocking};

/// The page and its assets, built into the binary.
const INDEX_HTML: &str = include_str!("viewer/index.html");
const VIEWER_CSS: &str = include_str!("viewer/viewer.css");

/// The script's ES modules (`/viewer/js/{name}`), the entry point first;
/// they import one another by relative paths (`./math.js`).
pub const MODULES: [(&str, &str); 7] = [
    ("main.js", include_str!("viewer/js/main.js")),
    ("api.js", include_str!("viewer/js/api.js")),
    ("math.js", include_str!("viewer/js/math.js")),
    ("camera.js", include_str!("viewer/js/camera.js")),
    ("gl.js", include_str!("viewer/js/gl.js")),
    ("highlight.js", include_str!("viewer/js/highlight.js")),
    ("adjust.js", include_str!("viewer/js/adjust.js")),
];

/// Everything the page may load: itself. No remote scripts, styles, fonts or images.
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'";

/// Samples farther than this fraction of the mesh's bounding-box diagonal
/// from the surface are listed as a viewer warning (`far_samples`): half the
/// distance at which the binding refuses them (`CutOptions::max_projection_distance`).
pub const FAR_SAMPLE_WARNING: f64 = 0.5 * curvenet_core::DEFAULT_MAX_PROJECTION_DISTANCE;

/// Reads frame `k` of a stage opened in the viewer (the stage's k-th time
/// code): posed pools, the rest pose, blend-shape weights and the stage's
/// Curvenet Adjustments at that time. A reader that fails names the frame
/// and the prim.
pub type FrameSource = Arc<dyn Fn(usize) -> Result<StageFrame, String> + Send + Sync>;

/// A frame of a stage opened in the viewer, as read from the stage.
#[derive(Debug, Clone, Default)]
pub struct StageFrame {
    pub request: FrameRequest,
    /// The stage's Curvenet Adjustments at this frame (core's: a rotate
    /// may be a quaternion), applied after the request's own.
    pub adjustments: Vec<Adjustment>,
}

impl From<FrameRequest> for StageFrame {
    fn from(request: FrameRequest) -> Self {
        Self { request, adjustments: Vec::new() }
    }
}

/// A deformed mesh of a stage opened in the viewer (`curvenet serve
/// --open-stage STAGE`): what to bind, and how to read each frame.
pub struct ViewerStage {
    /// The stage's path, as given.
    pub stage: String,
    /// The mesh prim.
    pub mesh: String,
    /// The curvenet prims deforming it, in binding order.
    pub curvenets: Vec<String>,
    /// The frames' time codes, in order.
    pub times: Vec<f64>,
    /// The binding of the mesh to its curvenets.
    pub binding: BindingRequest,
    /// Frame `k` (an index into `times`).
    pub frame: FrameSource,
    /// The stage's `CurvenetAdjustment` prims (what an export keys among).
    pub adjustments: Vec<StageAdjustment>,
    /// The binding id once bound (to skip re-hashing the request per frame).
    bound: Mutex<Option<String>>,
}

impl ViewerStage {
    pub fn new(
        stage: String,
        mesh: String,
        curvenets: Vec<String>,
        times: Vec<f64>,
        binding: BindingRequest,
        frame: FrameSource,
    ) -> Self {
        Self { stage, mesh, curvenets, times, binding, frame, adjustments: Vec::new(), bound: Mutex::new(None) }
    }

    /// The stage's `CurvenetAdjustment` prims (their values per frame come
    /// with the frames).
    pub fn with_adjustments(mut self, adjustments: Vec<StageAdjustment>) -> Self {
        self.adjustments = adjustments;
        self
    }
}

impl AppState {
    /// Opens a stage's mesh in the viewer; returns its index in `/v1/viewer/stages`.
    pub fn open_in_viewer(&self, stage: ViewerStage) -> usize {
        let mut stages = self.inner.viewer_stages.write().unwrap_or_else(|e| e.into_inner());
        stages.push(Arc::new(stage));
        stages.len() - 1
    }

    fn viewer_stage(&self, index: usize) -> Result<Arc<ViewerStage>, ServiceError> {
        let stages = self.inner.viewer_stages.read().unwrap_or_else(|e| e.into_inner());
        stages.get(index).cloned().ok_or_else(|| {
            ServiceError::new(
                Code::NotFound,
                format!(
                    "no stage {index} is open in the viewer ({} open; start the server with --open-stage STAGE)",
                    stages.len()
                ),
            )
        })
    }
}

// ---------------------------------------------------------------- wire types

/// `GET /v1/viewer/stages`.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerStages {
    pub stages: Vec<ViewerStageInfo>,
}

/// A stage opened in the viewer.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerStageInfo {
    pub index: usize,
    pub stage: String,
    pub mesh: String,
    pub curvenets: Vec<String>,
    /// The frames' time codes; frame `k` is `times[k]`.
    pub times: Vec<f64>,
}

/// `GET /v1/viewer/stages/{index}`: the stage and its binding.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerStageBinding {
    #[serde(flatten)]
    pub info: ViewerStageInfo,
    pub binding: BindingResponse,
}

/// `GET /v1/bindings/{id}/viewer-data`: what the viewer draws of a binding.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerData {
    /// The binding's counts, timings and warnings (as `POST /v1/bindings` answered).
    pub binding: BindingResponse,
    /// Bounding-box diagonal of the projection pose.
    pub diagonal: f64,
    pub mesh: MeshView,
    pub cut: CutView,
    pub curvenets: Vec<CurvenetView>,
    /// The binding's warnings followed by the viewer's own (`far_samples`).
    pub warnings: Vec<Warning>,
    /// What each warning is about (same order and length as `warnings`).
    pub highlights: Vec<Highlight>,
    /// The binding's cage, when it has one: drawn as a wireframe layer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageView>,
}

/// A binding's cage at bind.
#[derive(Debug, Serialize, ToSchema)]
pub struct CageView {
    /// The rest cage at bind, flat `f32` xyz, `#C`.
    pub points: Vec<f32>,
    /// Its triangles, flat vertex triples.
    pub triangles: Vec<u32>,
    /// Its edges (each once), flat vertex pairs: the wireframe.
    pub edges: Vec<u32>,
}

/// The input mesh in the projection pose.
#[derive(Debug, Serialize, ToSchema)]
pub struct MeshView {
    /// Flat `f32` xyz, `#V`.
    pub points: Vec<f32>,
    /// Triangles, flat vertex triples: core's own triangulation of the
    /// faces (`Surface::triangles`), or a fan per face when the mesh could
    /// not be made a surface (see `triangulation`).
    pub triangles: Vec<u32>,
    /// `surface` (core's triangulation) or `fan` (a refused mesh core could not triangulate).
    pub triangulation: String,
    /// The input face of each triangle.
    pub triangle_face: Vec<u32>,
    /// Edges, flat vertex pairs.
    pub edges: Vec<u32>,
}

/// Kinds of [`CutView::edge_kind`].
pub const EDGE_PLAIN: u8 = 0;
pub const EDGE_CURVE: u8 = 1;
pub const EDGE_CRACK: u8 = 2;
pub const EDGE_BOUNDARY: u8 = 3;

/// The cut-mesh (paper §4.1) in the projection pose.
#[derive(Debug, Serialize, ToSchema)]
pub struct CutView {
    /// Flat `f32` xyz per cut-vertex.
    pub points: Vec<f32>,
    /// Per cut-vertex: 1 mesh vertex | 2 sample | 4 crossing.
    pub mask: Vec<u8>,
    /// Edges (one per halfedge pair), flat cut-vertex pairs.
    pub edges: Vec<u32>,
    /// Per edge: 0 plain, 1 along the curvenet, 2 crack (both sides bound one cut-face), 3 mesh boundary.
    pub edge_kind: Vec<u8>,
    /// Cut-face `f` has the corners `face_vertices[face_start[f]..face_start[f + 1]]`, in loop order.
    pub face_start: Vec<u32>,
    pub face_vertices: Vec<u32>,
    /// The input face of each cut-face.
    pub face_parent: Vec<u32>,
}

/// One bound curvenet in its neutral pose.
#[derive(Debug, Serialize, ToSchema)]
pub struct CurvenetView {
    /// Flat `f32` xyz per sample.
    pub samples: Vec<f32>,
    /// Flat sample pairs, in curve direction.
    pub segments: Vec<u32>,
    /// Samples at intersections (knots shared by three or more spline ends).
    pub intersections: Vec<u32>,
    /// Samples at anchors (curve ends at no intersection).
    pub anchors: Vec<u32>,
    /// Samples removed with an island (a curvenet cluster inside one face).
    pub removed_samples: Vec<u32>,
    /// Samples farther than [`FAR_SAMPLE_WARNING`] of the diagonal from the surface.
    pub far_samples: Vec<u32>,
    /// Flat `f32` xyz per sample: its projection p̌ onto the surface.
    pub projections: Vec<f32>,
    /// Scaled frames, 18 floats per segment: for the plus then the minus
    /// side, `t·l`, `b·w`, `n·h` (paper Fig. 5).
    pub frames: Vec<f32>,
    /// The knots (spline endpoints) by pool index; knot `i` is sample `i`
    /// (in every pose's `samples`).
    pub knots: Vec<u32>,
}

/// `GET /v1/viewer/stages/{index}/refusal`: a stage whose binding is
/// refused, drawn anyway: the mesh, the curvenets and the element the
/// error names.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerRefusal {
    /// The stage (its `mesh` is the prim's path; the field `mesh` below is the geometry).
    pub stage: ViewerStageInfo,
    /// The error code the service answers for this refusal (`binding_failed`,
    /// `invalid_mesh`, `invalid_curvenet`, ...).
    pub code: String,
    /// Core's message, naming the element.
    pub message: String,
    /// Bounding-box diagonal of the projection pose.
    pub diagonal: f64,
    /// The mesh in its projection pose (core's triangulation when the mesh
    /// is a valid surface, else a fan per face).
    pub mesh: MeshView,
    pub curvenets: Vec<SketchView>,
    /// What the error names, with its geometry and the box to frame.
    pub highlight: Highlight,
}

/// A curvenet of a refused binding.
#[derive(Debug, Serialize, ToSchema)]
pub struct SketchView {
    /// Its splines as Bézier polylines, flat `f32` xyz: spline `s` is points
    /// `spline_start[s]..spline_start[s + 1]`.
    pub points: Vec<f32>,
    pub spline_start: Vec<u32>,
    /// Its samples (flat `f32` xyz) and segments (sample pairs), when it
    /// could be sampled on the surface; empty otherwise.
    pub samples: Vec<f32>,
    pub segments: Vec<u32>,
}

/// A solved frame as the viewer draws it.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerFrame {
    /// The time code (stage frames only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    /// Deformed points, flat `f32` xyz.
    pub points: Vec<f32>,
    /// The cut-vertices carried by the deformed surface (each at its
    /// location on an input face, interpolated linearly), flat `f32` xyz.
    pub cut_points: Vec<f32>,
    pub solve_ms: f64,
    /// The posed curvenets: samples and scaled frames, as in [`CurvenetView`].
    pub curvenets: Vec<PoseView>,
    /// The frame's rest pose, when it has one (else the projection pose
    /// is the rest pose): the mesh, the cut-vertices and the curvenets
    /// tracked to it, as the solve sees them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rest: Option<RestView>,
    /// The Curvenet Adjustments the solve applied (a stage frame: the
    /// stage's, with the user's in place of the stage's of the same knot),
    /// as values in the layer's types; a quaternion rotate is given as Euler
    /// angles.
    pub adjustments: Vec<ViewerAdjustment>,
    /// Per curvenet, each knot's orientation (pool index → row-major 3×3,
    /// its columns the knot frame's axes), before the adjustments; when the
    /// frame asked for `orientations` (stage frames always do).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub knot_orientations: Option<Vec<BTreeMap<String, [f64; 9]>>>,
    /// A caged binding's cage this frame, where it deforms the mesh: the
    /// posed cage after CageUp (with a skin), else the frame's rest cage
    /// with its edits; flat `f32` xyz, `#C` (the edges of
    /// [`ViewerData::cage`] connect them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cage: Option<Vec<f32>>,
}

/// An adjustment a viewer frame applied.
#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerAdjustment {
    #[serde(flatten)]
    pub adjustment: AdjustmentSpec,
    /// The stage's `CurvenetAdjustment` prim of this knot, when it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prim: Option<String>,
    /// `stage` (the stage's own values) or `user` (the request's).
    pub source: String,
}

/// `POST /v1/viewer/stages/{index}/frames/{k}`: the user's adjustments.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ViewerAdjustRequest {
    /// Each replaces the stage's adjustment of its knot at this frame.
    #[serde(default)]
    pub adjustments: Vec<AdjustmentSpec>,
}

/// `POST /v1/viewer/stages/{index}/export`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ViewerExportRequest {
    /// The frame the adjustments were made at (an index into the stage's times).
    pub frame: usize,
    /// The user's adjustments, as posted for the frame.
    pub adjustments: Vec<AdjustmentSpec>,
}

/// A frame's own rest pose.
#[derive(Debug, Serialize, ToSchema)]
pub struct RestView {
    pub points: Vec<f32>,
    pub cut_points: Vec<f32>,
    pub curvenets: Vec<PoseView>,
}

/// A posed curvenet.
#[derive(Debug, Serialize, ToSchema)]
pub struct PoseView {
    pub samples: Vec<f32>,
    pub frames: Vec<f32>,
}

// ---------------------------------------------------------------- the page

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
            (header::CONTENT_SECURITY_POLICY, HeaderValue::from_static(CSP)),
            (header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff")),
        ],
        body,
    )
        .into_response()
}

pub(crate) async fn page() -> Response {
    asset("text/html; charset=utf-8", INDEX_HTML)
}

/// One of the [`MODULES`], as JavaScript (the MIME type module scripts need).
pub(crate) async fn module(Params(name): Params<String>) -> Result<Response, ServiceError> {
    match MODULES.iter().find(|(n, _)| *n == name) {
        Some((_, source)) => Ok(asset("text/javascript; charset=utf-8", source)),
        None => Err(ServiceError::new(
            Code::NotFound,
            format!(
                "the viewer has no module {name} (it has {})",
                MODULES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            ),
        )),
    }
}

pub(crate) async fn style() -> Response {
    asset("text/css; charset=utf-8", VIEWER_CSS)
}

// ---------------------------------------------------------------- handlers

fn info(index: usize, s: &ViewerStage) -> ViewerStageInfo {
    ViewerStageInfo {
        index,
        stage: s.stage.clone(),
        mesh: s.mesh.clone(),
        curvenets: s.curvenets.clone(),
        times: s.times.clone(),
    }
}

/// The stages opened in the viewer.
#[utoipa::path(get, path = "/v1/viewer/stages", tag = "viewer", security(("bearer" = [])),
    responses((status = 200, description = "The stages opened with --open-stage", body = ViewerStages)))]
pub(crate) async fn stages(State(state): State<AppState>) -> Json<ViewerStages> {
    let stages = state.inner.viewer_stages.read().unwrap_or_else(|e| e.into_inner());
    Json(ViewerStages { stages: stages.iter().enumerate().map(|(i, s)| info(i, s)).collect() })
}

/// The entry of a stage's binding: cached, else bound now (through the cache).
async fn stage_entry(state: &AppState, stage: &ViewerStage) -> Result<(Arc<Entry>, bool), ServiceError> {
    let known = stage.bound.lock().unwrap_or_else(|e| e.into_inner()).clone();
    if let Some(id) = known
        && let Some(entry) = parse_key(&id)
        && let Some(e) = state.inner.cache.get(&entry).await
    {
        return Ok((e, true));
    }
    let (entry, cached) =
        crate::handlers::bindings::bind(state, stage.binding.clone()).await.map_err(|e| e.context(&stage.mesh))?;
    *stage.bound.lock().unwrap_or_else(|e| e.into_inner()) = Some(entry.id.clone());
    Ok((entry, cached))
}

/// Binds a stage opened in the viewer (through the cache) and describes it.
#[utoipa::path(get, path = "/v1/viewer/stages/{index}", tag = "viewer", security(("bearer" = [])),
    params(("index" = usize, Path, description = "The stage's index in /v1/viewer/stages")),
    responses(
        (status = 200, description = "The stage and its binding", body = ViewerStageBinding),
        (status = 404, description = "not_found: no such stage", body = ErrorBody),
        (status = 422, description = "The stage's mesh cannot be bound", body = ErrorBody),
    ))]
pub(crate) async fn stage(
    State(state): State<AppState>,
    Params(index): Params<usize>,
) -> Result<Json<ViewerStageBinding>, ServiceError> {
    let stage = state.viewer_stage(index)?;
    let (entry, cached) = stage_entry(&state, &stage).await?;
    Ok(Json(ViewerStageBinding {
        info: info(index, &stage),
        binding: BindingResponse { cached, ..entry.response.clone() },
    }))
}

/// Draws a stage whose binding is refused: the mesh, the curvenets and the
/// element the error names, found by building the stage's input through
/// core again (the surface, each curvenet's analysis, `Deformer::new`) and
/// reading the typed error. Answers `not_found` when the stage binds.
#[utoipa::path(get, path = "/v1/viewer/stages/{index}/refusal", tag = "viewer", security(("bearer" = [])),
    params(("index" = usize, Path, description = "The stage's index in /v1/viewer/stages")),
    responses(
        (status = 200, description = "The refused stage, with the element its error names", body = ViewerRefusal),
        (status = 404, description = "not_found: no such stage, or it binds", body = ErrorBody),
    ))]
pub(crate) async fn stage_refusal(
    State(state): State<AppState>,
    Params(index): Params<usize>,
) -> Result<Response, ServiceError> {
    let stage = state.viewer_stage(index)?;
    let bytes = blocking(move || {
        let Some(refused) = refusal(index, &stage) else {
            return Err(ServiceError::new(
                Code::NotFound,
                format!("stage {index} ({}) binds: nothing is refused (GET /v1/viewer/stages/{index})", stage.mesh),
            ));
        };
        serde_json::to_vec(&refused).map_err(ServiceError::internal_from)
    })
    .await?;
    Ok(([(header::CONTENT_TYPE, HeaderValue::from_static("application/json"))], bytes).into_response())
}

/// Solves frame `k` of a stage opened in the viewer, with the stage's
/// Curvenet Adjustments and the knots' orientations.
#[utoipa::path(get, path = "/v1/viewer/stages/{index}/frames/{k}", tag = "viewer", security(("bearer" = [])),
    params(
        ("index" = usize, Path, description = "The stage's index in /v1/viewer/stages"),
        ("k" = usize, Path, description = "The frame: an index into the stage's times"),
    ),
    responses(
        (status = 200, description = "The solved frame", body = ViewerFrame),
        (status = 404, description = "not_found: no such stage or frame", body = ErrorBody),
        (status = 422, description = "The frame is invalid", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn stage_frame(
    State(state): State<AppState>,
    Params((index, k)): Params<(usize, usize)>,
) -> Result<Json<ViewerFrame>, ServiceError> {
    Ok(Json(solve_stage_frame(&state, index, k, &[]).await?))
}

/// Solves frame `k` of a stage with the user's Curvenet Adjustments: each
/// replaces the stage's adjustment of its knot (the values rounded to the
/// types the export layer stores, so that the export bakes to these points).
#[utoipa::path(post, path = "/v1/viewer/stages/{index}/frames/{k}", tag = "viewer", security(("bearer" = [])),
    params(
        ("index" = usize, Path, description = "The stage's index in /v1/viewer/stages"),
        ("k" = usize, Path, description = "The frame: an index into the stage's times"),
    ),
    request_body = ViewerAdjustRequest,
    responses(
        (status = 200, description = "The solved frame", body = ViewerFrame),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 404, description = "not_found: no such stage or frame", body = ErrorBody),
        (status = 422, description = "The frame is invalid, or an adjustment (named: adjustments[i], its curvenet and knot)", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn stage_frame_adjusted(
    State(state): State<AppState>,
    Params((index, k)): Params<(usize, usize)>,
    _json: ContentType<JsonOnly>,
    SizedBody(bytes): SizedBody,
) -> Result<Json<ViewerFrame>, ServiceError> {
    let request = parse_json::<ViewerAdjustRequest>(&bytes)?;
    Ok(Json(solve_stage_frame(&state, index, k, &request.adjustments).await?))
}

/// The user's adjustments as a USD layer (`.usda` text) over the stage: see
/// `adjust.rs`. `curvenet bake` of the layer reproduces the viewer's frame.
#[utoipa::path(post, path = "/v1/viewer/stages/{index}/export", tag = "viewer", security(("bearer" = [])),
    params(("index" = usize, Path, description = "The stage's index in /v1/viewer/stages")),
    request_body = ViewerExportRequest,
    responses(
        (status = 200, description = "The layer, USD text (sublayers the stage)", content_type = "text/plain"),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 404, description = "not_found: no such stage or frame", body = ErrorBody),
        (status = 422, description = "An adjustment is invalid (named: adjustments[i], its curvenet and knot)", body = ErrorBody),
    ))]
pub(crate) async fn stage_export(
    State(state): State<AppState>,
    Params(index): Params<usize>,
    _json: ContentType<JsonOnly>,
    SizedBody(bytes): SizedBody,
) -> Result<Response, ServiceError> {
    let request = parse_json::<ViewerExportRequest>(&bytes)?;
    let stage = state.viewer_stage(index)?;
    let time = frame_time(&stage, request.frame)?;
    let (entry, _) = stage_entry(&state, &stage).await?;
    user_adjustments(&entry, &stage, &request.adjustments)?;
    let b = entry.binding();
    let range = match (stage.times.first(), stage.times.last()) {
        (Some(&a), Some(&z)) => Some((a, z)),
        _ => None,
    };
    // The layer names the stage by its absolute path, so it can be saved anywhere.
    let sublayer = std::fs::canonicalize(&stage.stage).map_or(stage.stage.clone(), |p| p.display().to_string());
    let layer = adjust::export_layer(
        &sublayer,
        &stage.curvenets,
        range,
        &stage.adjustments,
        time,
        &request.adjustments,
        |k, knot| {
            let sampling = b.layouts()[k].sampling();
            sampling.knot_sample(knot as usize).map_or(0, |i| b.orientation_plan(k).knot_tangents(i as usize).len())
        },
    );
    let text = encode_adjustment_layer(&layer, LayerFormat::Usda).map_err(|e| {
        ServiceError::new(Code::InvalidParameter, format!("{}: cannot write the adjustment layer: {e}", stage.mesh))
    })?;
    let name = std::path::Path::new(&stage.stage).file_stem().and_then(|s| s.to_str()).unwrap_or("stage");
    let disposition = format!("attachment; filename=\"{}_adjusted.usda\"", name.replace(['"', '\\'], "_"));
    Ok((
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("text/plain; charset=utf-8")),
            (
                header::CONTENT_DISPOSITION,
                HeaderValue::from_str(&disposition)
                    .unwrap_or(HeaderValue::from_static("attachment; filename=\"adjusted.usda\"")),
            ),
        ],
        text,
    )
        .into_response())
}

fn frame_time(stage: &ViewerStage, k: usize) -> Result<f64, ServiceError> {
    stage.times.get(k).copied().ok_or_else(|| {
        ServiceError::new(
            Code::NotFound,
            format!("{} has {} frames; frame {k} does not exist", stage.stage, stage.times.len()),
        )
    })
}

/// The user's adjustments as solved (see `adjust::layer_adjustment`),
/// checked against the binding: a bad one is refused naming
/// `adjustments[i]`, its curvenet and knot.
fn user_adjustments(
    entry: &Entry,
    stage: &ViewerStage,
    specs: &[AdjustmentSpec],
) -> Result<Vec<Adjustment>, ServiceError> {
    let user: Vec<Adjustment> = specs
        .iter()
        .map(|s| adjust::layer_adjustment(s, adjust::find(&stage.adjustments, s.curvenet, s.knot)))
        .collect();
    entry
        .binding()
        .check_adjustments(&user)
        .map_err(|e| crate::frame::name_adjustment(ServiceError::core(e, Phase::Frame), &user))?;
    Ok(user)
}

async fn solve_stage_frame(
    state: &AppState,
    index: usize,
    k: usize,
    specs: &[AdjustmentSpec],
) -> Result<ViewerFrame, ServiceError> {
    let stage = state.viewer_stage(index)?;
    let time = frame_time(&stage, k)?;
    let (entry, _) = stage_entry(state, &stage).await?;
    let user = user_adjustments(&entry, &stage, specs)?;
    let read = stage.clone();
    let read = blocking(move || {
        (read.frame)(k)
            .map_err(|m| ServiceError::new(Code::InvalidParameter, format!("{}, frame {time}: {m}", read.stage)))
    })
    .await?;
    let context = format!("{} frame {time}", stage.mesh);
    let mut frame = Frame::from(read.request);
    frame.adjustments.extend(read.adjustments);
    frame.adjustments = adjust::compose(std::mem::take(&mut frame.adjustments), &user);
    // Knot orientations are answered for frames the curvenets are tracked
    // on in the frame's own rest pose: not yet for skinned or caged frames.
    frame.orientations = frame.joint_transforms.is_none() && entry.deformer.cage().is_none();
    let admission = Admission::one(state).await?;
    let mut view = solve_frame(state, admission, entry, frame).await.map_err(|e| e.context(&context))?;
    view.time = Some(time);
    for a in &mut view.adjustments {
        let (c, n) = (a.adjustment.curvenet, a.adjustment.knot);
        a.prim = adjust::find(&stage.adjustments, c, n).map(|s| s.data.path.clone());
        if user.iter().any(|u| u.curvenet == c as usize && u.knot == n) {
            a.source = "user".into();
        }
    }
    Ok(view)
}

/// The geometry of a cached binding, for the viewer.
#[utoipa::path(get, path = "/v1/bindings/{id}/viewer-data", tag = "viewer", security(("bearer" = [])),
    params(("id" = String, Path, description = "The binding id")),
    responses(
        (status = 200, description = "The mesh, cut-mesh and curvenets of the binding", body = ViewerData),
        (status = 404, description = "unknown_binding", body = ErrorBody),
    ))]
pub(crate) async fn viewer_data(
    State(state): State<AppState>,
    Params(id): Params<String>,
) -> Result<Response, ServiceError> {
    let entry = crate::extract::lookup(&state, &id).await?;
    let bytes = blocking(move || serde_json::to_vec(&data(&entry)).map_err(ServiceError::internal_from)).await?;
    Ok(([(header::CONTENT_TYPE, HeaderValue::from_static("application/json"))], bytes).into_response())
}

/// Solves one frame of a cached binding and answers what the viewer draws.
#[utoipa::path(post, path = "/v1/bindings/{id}/viewer-frame", tag = "viewer", security(("bearer" = [])),
    params(("id" = String, Path, description = "The binding id")),
    request_body = FrameRequest,
    responses(
        (status = 200, description = "The solved frame with its posed curvenets", body = ViewerFrame),
        (status = 400, description = "malformed_json", body = ErrorBody),
        (status = 404, description = "unknown_binding", body = ErrorBody),
        (status = 422, description = "The frame is invalid", body = ErrorBody),
        (status = 503, description = "saturated (Retry-After)", body = ErrorBody),
    ))]
pub(crate) async fn viewer_frame(
    State(state): State<AppState>,
    _json: ContentType<JsonOnly>,
    CachedBinding(entry): CachedBinding,
    Admitted(SizedBody(bytes), admission): Admitted<SizedBody>,
) -> Result<Json<ViewerFrame>, ServiceError> {
    let frame = Frame::from(parse_json::<FrameRequest>(&bytes)?);
    Ok(Json(solve_frame(&state, admission, entry, frame).await?))
}

/// Solves `frame` through the service's one solve helper (as `POST
/// /v1/bindings/{id}/frames` does: validation, the solve pool, the frame
/// metrics), then evaluates the posed curvenets.
async fn solve_frame(
    state: &AppState,
    admission: Admission,
    entry: Arc<Entry>,
    frame: Frame,
) -> Result<ViewerFrame, ServiceError> {
    let poses = frame.clone();
    solve_frames(
        state,
        admission,
        entry,
        Numbering::One,
        None,
        move |_| Ok(vec![frame]),
        move |entry, solved| {
            let solved =
                solved.into_iter().next().ok_or_else(|| ServiceError::internal("a frame solved to nothing"))?;
            viewer_frame_view(entry, &poses, &solved)
        },
    )
    .await
    .map(|(view, _)| view)
}

/// What the viewer draws of a solved frame: its points and cut-vertices,
/// and the posed curvenets (posed, and in the frame's rest pose).
fn viewer_frame_view(entry: &Entry, frame: &Frame, solved: &Solved) -> Result<ViewerFrame, ServiceError> {
    let b = entry.binding();
    let poses = |posed: &[Option<&[[f64; 3]]>]| {
        (0..b.n_curvenets())
            .map(|k| {
                let (samples, frames) = b
                    .curvenet_pose(k, posed.get(k).copied().flatten(), frame.rest.as_deref())
                    .map_err(|e| ServiceError::core(e, Phase::Frame).context(&format!("curvenet {k}")))?;
                Ok(PoseView { samples: flat(&samples), frames: flat_frames(&frames) })
            })
            .collect::<Result<Vec<_>, ServiceError>>()
    };
    // With adjustments, the curvenets drawn are the adjusted pools the solve used.
    let adjusted: Vec<Vec<[f64; 3]>> = if frame.adjustments.is_empty() {
        Vec::new()
    } else {
        (0..b.n_curvenets())
            .map(|k| {
                let posed = frame.posed.get(k).and_then(|p| p.as_deref());
                b.adjusted_pool(k, posed, frame.rest.as_deref(), &frame.adjustments)
                    .map_err(|e| ServiceError::core(e, Phase::Frame).context(&format!("curvenet {k}")))
            })
            .collect::<Result<_, _>>()?
    };
    let posed: Vec<Option<&[[f64; 3]]>> = if adjusted.is_empty() {
        frame.posed.iter().map(|p| p.as_deref()).collect()
    } else {
        adjusted.iter().map(|p| Some(&p[..])).collect()
    };
    let curvenets = poses(&posed)?;
    let rest = match frame.rest.as_deref() {
        Some(r) => Some(RestView { points: flat(r), cut_points: cut_points(b, r), curvenets: poses(&[])? }),
        None => None,
    };
    // The solved points are already the wire's f32; the cut-vertices are
    // placed on the surface posed at those (the viewer draws in f32).
    let points: Vec<[f64; 3]> = solved.points.iter().map(|p| p.map(f64::from)).collect();
    Ok(ViewerFrame {
        time: None,
        cut_points: cut_points(b, &points),
        points: solved.points.as_flattened().to_vec(),
        solve_ms: solved.solve_ms,
        curvenets,
        rest,
        adjustments: frame
            .adjustments
            .iter()
            .map(|a| ViewerAdjustment { adjustment: adjust::spec_of(a), prim: None, source: "stage".into() })
            .collect(),
        knot_orientations: solved.knot_orientations.clone(),
        cage: frame_cage(entry, frame)?.map(|c| flat(&c)),
    })
}

/// The cage of a caged binding this frame, as `Deformer::frame` poses it:
/// the coupled rig (core's `CoupledRig::evaluate`) on the frame's rest pose
/// (with `before`-mode blend shapes), its rest-cage edits, joint transforms
/// and posed-cage offsets; its posed cage (CageUp; the edited rest cage
/// without a skeleton). `None` without a cage.
fn frame_cage(entry: &Entry, frame: &Frame) -> Result<Option<Vec<[f64; 3]>>, ServiceError> {
    let deformer = &entry.deformer;
    let Some(rig) = deformer.cage() else { return Ok(None) };
    let mut base = frame.rest.clone().unwrap_or_else(|| deformer.projection_points().to_vec());
    if let (Some(w), BlendShapeMode::Before) = (&frame.weights, frame.mode)
        && entry.n_shapes() > 0
    {
        deformer.blend_shapes().add_to(w, &mut base).map_err(|e| ServiceError::core(e, Phase::Frame))?;
    }
    let input = curvenet_core::CageFrame {
        base: Some(&base),
        rest_cage: frame.rest_cage.as_deref(),
        joint_transforms: frame.joint_transforms.as_deref(),
        posed_cage_offsets: frame.posed_cage_offsets.as_deref(),
    };
    let mut ws = curvenet_core::CoupledWorkspace::default();
    let mut out = vec![[0.0; 3]; base.len()];
    rig.evaluate(&input, &mut ws, &mut out).map_err(|e| ServiceError::core(e, Phase::Frame).context("cage"))?;
    Ok(Some(ws.posed_cage().to_vec()))
}

/// The cage of a caged binding at bind, with its edges, for the viewer.
fn cage_view(entry: &Entry) -> Option<CageView> {
    let cage = entry.deformer.cage()?.mvc().cage();
    let mut edges: Vec<[u32; 2]> = cage
        .triangles()
        .iter()
        .flat_map(|t| {
            [0, 1, 2].map(|i| {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                [a.min(b), a.max(b)]
            })
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    Some(CageView {
        points: flat(cage.points()),
        triangles: cage.triangles().iter().flatten().copied().collect(),
        edges: edges.into_iter().flatten().collect(),
    })
}

// ---------------------------------------------------------------- geometry

fn flat(points: &[[f64; 3]]) -> Vec<f32> {
    points.iter().flat_map(|p| p.map(|x| x as f32)).collect()
}

/// The cut-vertices at their locations on the surface posed at `points`.
fn cut_points(b: &Binding, points: &[[f64; 3]]) -> Vec<f32> {
    let cut = b.cut_mesh();
    (0..cut.n_vertices() as u32)
        .flat_map(|v| b.surface().position_in(cut.vertex(v).loc, points).to_array().map(|x| x as f32))
        .collect()
}

fn flat_frames(frames: &[[ScaledFrame; 2]]) -> Vec<f32> {
    let mut out = Vec::with_capacity(frames.len() * 18);
    for pair in frames {
        for f in pair {
            for (axis, s) in [f.tangent, f.binormal, f.normal].iter().zip(f.scale) {
                out.extend(axis.iter().map(|x| (x * s) as f32));
            }
        }
    }
    out
}

/// The viewer's picture of a binding: the mesh, the cut-mesh with its edge
/// kinds, the curvenets with their marked samples and neutral frames.
pub fn data(entry: &Entry) -> ViewerData {
    let b: &Binding = entry.binding();
    let mesh_view = surface_mesh_view(b.surface(), entry.projection_points());

    let cut = b.cut_mesh();
    let mut edges = Vec::new();
    let mut edge_kind = Vec::new();
    for h in 0..cut.n_halfedges() as u32 {
        let t = cut.twin(h);
        if t != INVALID_INDEX && t < h {
            continue; // one edge per halfedge pair
        }
        let kind = if t == INVALID_INDEX {
            EDGE_BOUNDARY
        } else if cut.face(t) == cut.face(h) {
            EDGE_CRACK
        } else if cut.segment(h).is_some() {
            EDGE_CURVE
        } else {
            EDGE_PLAIN
        };
        edges.extend([cut.tail(h), cut.head(h)]);
        edge_kind.push(kind);
    }
    let mut face_start = vec![0u32];
    let mut face_vertices = Vec::with_capacity(cut.n_halfedges());
    for f in 0..cut.n_faces() as u32 {
        face_vertices.extend(cut.face_halfedges(f).map(|h| cut.tail(h)));
        face_start.push(face_vertices.len() as u32);
    }
    let cut_view = CutView {
        points: (0..cut.n_vertices() as u32).flat_map(|v| cut.vertex(v).pos.to_array().map(|x| x as f32)).collect(),
        mask: (0..cut.n_vertices() as u32)
            .map(|v| cut.vertex(v).mask & (CUT_MESH_VERTEX | CUT_SAMPLE | CUT_CROSSING))
            .collect(),
        edges,
        edge_kind,
        face_start,
        face_vertices,
        face_parent: (0..cut.n_faces() as u32).map(|f| cut.parent(f)).collect(),
    };

    let diagonal = b.surface().diagonal();
    let mut warnings = entry.response.warnings.clone();
    // (warning, curvenet) of the far_samples warnings added below.
    let mut far_warnings: Vec<(usize, usize)> = Vec::new();
    let curvenets: Vec<CurvenetView> = b
        .layouts()
        .iter()
        .enumerate()
        .map(|(k, layout)| {
            let base = b.sample_offset(k);
            let samples = layout.neutral_samples();
            let knot = |p: &u32| layout.sampling().knot_sample(*p as usize);
            let projections: Vec<[f64; 3]> = (0..samples.len()).map(|i| b.sample_projection((base + i) as u32)).collect();
            let distance = |i: usize| {
                let (q, p) = (samples[i], projections[i]);
                ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt()
            };
            let far_samples: Vec<u32> = (0..samples.len()).filter(|&i| distance(i) > FAR_SAMPLE_WARNING * diagonal).map(|i| i as u32).collect();
            if let Some(worst) = far_samples.iter().copied().max_by(|&i, &j| distance(i as usize).total_cmp(&distance(j as usize))) {
                warnings.push(Warning {
                    code: "far_samples".into(),
                    message: format!(
                        "curvenet {k}: {} samples are farther than {}% of the diagonal from the surface (sample {worst}: {:.3}%; the binding refuses {}%)",
                        far_samples.len(),
                        FAR_SAMPLE_WARNING * 100.0,
                        distance(worst as usize) / diagonal * 100.0,
                        curvenet_core::DEFAULT_MAX_PROJECTION_DISTANCE * 100.0
                    ),
                    segment: None,
                    touches: Vec::new(),
                    faces: Vec::new(),
                    component: None,
                    count: Some(far_samples.len()),
                });
                far_warnings.push((warnings.len() - 1, k));
            }
            CurvenetView {
                samples: flat(samples),
                segments: layout.sampling().segments().iter().flat_map(|s| s.samples).collect(),
                intersections: layout.topology().intersections().iter().filter_map(knot).collect(),
                anchors: layout.topology().anchors().iter().filter_map(knot).collect(),
                removed_samples: (0..samples.len() as u32).filter(|&i| cut.sample_vertex(base as u32 + i).is_none()).collect(),
                far_samples,
                projections: flat(&projections),
                frames: flat_frames(layout.neutral_frames()),
                knots: (0..layout.sampling().n_knots()).map(|i| layout.sampling().knot_point(i)).collect(),
            }
        })
        .collect();
    let highlights = {
        let scene = Scene {
            points: entry.projection_points(),
            faces: Vec::new(),
            surface: Some(b.surface()),
            nets: b
                .layouts()
                .iter()
                .map(|l| NetGeometry { pool: l.neutral_pool(), splines: l.sampling().splines(), layout: Some(l) })
                .collect(),
        };
        let mut highlights: Vec<Highlight> = warnings.iter().map(|w| scene.warning(w)).collect();
        // The viewer's own far_samples warnings: the far samples of their curvenet.
        for &(w, k) in &far_warnings {
            let c: &CurvenetView = &curvenets[k];
            let mut g = Highlight {
                code: warnings[w].code.clone(),
                message: warnings[w].message.clone(),
                ..Highlight::default()
            };
            g.curvenet = Some(k as u32);
            g.sample = c.far_samples.first().copied();
            for &i in &c.far_samples {
                g.points.extend_from_slice(&c.samples[3 * i as usize..3 * i as usize + 3]);
            }
            highlights[w] = scene.finish(g);
        }
        highlights
    };
    ViewerData {
        binding: BindingResponse { cached: true, ..entry.response.clone() },
        diagonal,
        mesh: mesh_view,
        cut: cut_view,
        curvenets,
        warnings,
        highlights,
        cage: cage_view(entry),
    }
}

/// The mesh as core's surface triangulates it.
fn surface_mesh_view(surface: &Surface, points: &[[f64; 3]]) -> MeshView {
    let (mut triangles, mut triangle_face) = (Vec::new(), Vec::new());
    for (t, f) in surface.triangles() {
        triangles.extend(t);
        triangle_face.push(f);
    }
    MeshView {
        points: flat(points),
        triangles,
        triangle_face,
        edges: surface.mesh().edges().into_iter().flat_map(|(a, c)| [a, c]).collect(),
        triangulation: "surface".into(),
    }
}

/// The refusal of a stage's binding, or `None` when it binds. The stages
/// run in the order `Deformer::new` runs them (mesh, surface, each
/// curvenet's analysis, the binding), keeping what succeeded for drawing.
fn refusal(index: usize, stage: &ViewerStage) -> Option<ViewerRefusal> {
    let req = &stage.binding;
    let points = &req.projection_points;
    let mut error: Option<Error> = None;
    let mesh = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, points.len())
        .map_err(|e| error = Some(e))
        .ok();
    let surface = mesh.as_ref().and_then(|m| Surface::new(m, points).map_err(|e| error = Some(e)).ok());
    let layouts: Vec<Option<CurvenetLayout>> = req
        .curvenets
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let s = surface.as_ref()?;
            let sampling = SamplingOptions::default().with_density(c.sample_density);
            Curvenet::new(&c.splines, &c.pool)
                .and_then(|net| {
                    CurvenetLayout::with_closest_point(&net, s.closest_points(), s.mean_edge_length(), &sampling)
                })
                .map_err(|e| {
                    error.get_or_insert(Error::Curvenet { curvenet: k as u32, source: Box::new(e) });
                })
                .ok()
        })
        .collect();
    if error.is_none() {
        // Everything before the binding went through: the binding itself,
        // through the one constructor, names the rest.
        let nets: Vec<CurvenetInput> = req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
        let o = &req.options;
        let mut bind = BindOptions::default().with_strict(o.strict);
        bind.cut.snap_tolerance = o.snap_tolerance.unwrap_or(bind.cut.snap_tolerance);
        bind.cut.max_projection_distance = o.max_projection_distance.unwrap_or(bind.cut.max_projection_distance);
        let input = DeformerInput {
            mesh: MeshInput {
                face_vertex_counts: &req.face_vertex_counts,
                face_vertex_indices: &req.face_vertex_indices,
                projection_points: points,
            },
            curvenets: &nets,
            blend_shapes: Vec::new(),
            skinning: None,
            cage: None,
            options: DeformerOptions::default().with_bind(bind),
        };
        error = Some(Deformer::new(&input).err()?);
    }
    let error = error?;
    let answered = ServiceError::core(error.clone(), Phase::Bind).context(&stage.mesh);

    let raw = Scene::raw_faces(&req.face_vertex_counts, &req.face_vertex_indices, points.len());
    let scene = Scene {
        points,
        faces: raw.clone(),
        surface: surface.as_ref(),
        nets: req
            .curvenets
            .iter()
            .zip(&layouts)
            .map(|(c, l)| NetGeometry { pool: &c.pool, splines: &c.splines, layout: l.as_ref() })
            .collect(),
    };
    let highlight = scene.error(&error, answered.code.as_str(), &answered.message);
    let mesh_view = match &surface {
        Some(s) => surface_mesh_view(s, points),
        None => fan_mesh_view(&raw, points),
    };
    let curvenets = layouts
        .iter()
        .enumerate()
        .map(|(k, layout)| {
            let mut view =
                SketchView { points: Vec::new(), spline_start: vec![0], samples: Vec::new(), segments: Vec::new() };
            for s in 0..req.curvenets[k].splines.len() {
                let line = scene.spline_polyline(k, s);
                view.points.extend(flat(&line));
                view.spline_start.push((view.points.len() / 3) as u32);
            }
            if let Some(l) = layout {
                view.samples = flat(l.neutral_samples());
                view.segments = l.sampling().segments().iter().flat_map(|s| s.samples).collect();
            }
            view
        })
        .collect();
    Some(ViewerRefusal {
        stage: info(index, stage),
        code: answered.code.as_str().to_string(),
        message: answered.message,
        diagonal: curvenet_core::bounding_box_diagonal(points),
        mesh: mesh_view,
        curvenets,
        highlight,
    })
}

/// A mesh core could not make a surface of: a fan per face (faces with a
/// corner out of range left out), edges from the faces' sides.
fn fan_mesh_view(faces: &[Option<&[u32]>], points: &[[f64; 3]]) -> MeshView {
    let (mut triangles, mut triangle_face, mut edges) = (Vec::new(), Vec::new(), Vec::new());
    for (f, face) in faces.iter().enumerate() {
        let Some(face) = face else { continue };
        for k in 1..face.len().saturating_sub(1) {
            triangles.extend([face[0], face[k], face[k + 1]]);
            triangle_face.push(f as u32);
        }
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            edges.push((a.min(b), a.max(b)));
        }
    }
    edges.sort_unstable();
    edges.dedup();
    MeshView {
        points: flat(points),
        triangles,
        triangle_face,
        edges: edges.into_iter().flat_map(|(a, b)| [a, b]).collect(),
        triangulation: "fan".into(),
    }
}
