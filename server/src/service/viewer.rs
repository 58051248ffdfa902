//! The browser viewer: a page at `/viewer` (HTML, a hand-written WebGL2
//! renderer and CSS, built into the binary; nothing is loaded from anywhere
//! else) and the read-only JSON it draws.
//!
//! ```text
//! GET  /viewer, /viewer/viewer.js, /viewer/viewer.css     the page (no token: it holds no data)
//! GET  /v1/viewer/stages                                  stages opened with `serve --open-stage` / `inspect --serve`
//! GET  /v1/viewer/stages/{index}                          binds the stage's mesh (through the cache): its BindingResponse
//! GET  /v1/viewer/stages/{index}/frames/{k}               frame k of the stage, solved: a ViewerFrame
//! GET  /v1/bindings/{id}/viewer-data                      the binding's geometry: a ViewerData
//! POST /v1/bindings/{id}/viewer-frame                     a FrameRequest, solved: a ViewerFrame
//! ```
//!
//! Frames solve through the service's own path (`frames::validate`,
//! `frames::solve`, a solve permit, the solve pool); the posed curvenet's
//! samples and scaled frames come from `Binding::curvenet_pose`, the
//! samples and frames the solve itself uses. Positions are sent as flat
//! `f32` arrays (`[x0, y0, z0, x1, ...]`) to keep the JSON small.

use std::sync::{Arc, Mutex};

use axum::Json;
use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use curvenet_core::Binding;
use curvenet_core::binding::{CROSSING, MESH_VERTEX, SAMPLE};
use curvenet_core::curvenet::ScaledFrame;
use curvenet_core::halfedge::INVALID;
use curvenet_schema::wire::{BindingRequest, BindingResponse, ErrorBody, FrameRequest, Warning};
use serde::Serialize;
use utoipa::ToSchema;

use crate::cache::{Entry, parse_key};
use crate::error::{Code, Phase, ServiceError};
use crate::frames::{self, Frame};
use crate::routes::Params;
use crate::state::{AppState, blocking};

/// The page and its assets, built into the binary.
const INDEX_HTML: &str = include_str!("viewer/index.html");
const VIEWER_JS: &str = include_str!("viewer/viewer.js");
const VIEWER_CSS: &str = include_str!("viewer/viewer.css");

/// Everything the page may load: itself. No remote scripts, styles, fonts or images.
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'";

/// Samples farther than this fraction of the mesh's bounding-box diagonal
/// from the surface are listed as a viewer warning (`far_samples`): half the
/// distance at which the binding refuses them (`CutOptions::max_projection_distance`).
pub const FAR_SAMPLE_WARNING: f64 = 0.5 * curvenet_core::binding::cut::DEFAULT_MAX_PROJECTION_DISTANCE;

/// Reads frame `k` of a stage opened in the viewer (the stage's k-th time
/// code) as a [`FrameRequest`]: posed pools, the rest pose, blend-shape
/// weights. A reader that fails names the frame and the prim.
pub type FrameSource = Arc<dyn Fn(usize) -> Result<FrameRequest, String> + Send + Sync>;

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
        Self { stage, mesh, curvenets, times, binding, frame, bound: Mutex::new(None) }
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
}

/// The input mesh in the projection pose.
#[derive(Debug, Serialize, ToSchema)]
pub struct MeshView {
    /// Flat `f32` xyz, `#V`.
    pub points: Vec<f32>,
    /// Triangles (a fan per face), flat vertex triples.
    pub triangles: Vec<u32>,
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

pub(crate) async fn script() -> Response {
    asset("text/javascript; charset=utf-8", VIEWER_JS)
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
        crate::routes::bind(state, stage.binding.clone()).await.map_err(|e| e.context(&stage.mesh))?;
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

/// Solves frame `k` of a stage opened in the viewer.
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
    let stage = state.viewer_stage(index)?;
    let Some(&time) = stage.times.get(k) else {
        return Err(ServiceError::new(
            Code::NotFound,
            format!("{} has {} frames; frame {k} does not exist", stage.stage, stage.times.len()),
        ));
    };
    let (entry, _) = stage_entry(&state, &stage).await?;
    let read = stage.clone();
    let request = blocking(move || {
        (read.frame)(k)
            .map_err(|m| ServiceError::new(Code::InvalidParameter, format!("{}, frame {time}: {m}", read.stage)))
    })
    .await?;
    let context = format!("{} frame {time}", stage.mesh);
    let mut frame = solve_frame(&state, entry, Frame::from(request)).await.map_err(|e| e.context(&context))?;
    frame.time = Some(time);
    Ok(Json(frame))
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
    let entry = crate::routes::lookup(&state, &id).await?;
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
    Params(id): Params<String>,
    headers: HeaderMap,
    body: Body,
) -> Result<Json<ViewerFrame>, ServiceError> {
    crate::routes::form(&headers, false)?;
    let entry = crate::routes::lookup(&state, &id).await?;
    let bytes = crate::routes::read_body(&state, body).await?;
    let request: FrameRequest = crate::routes::parse_json(&bytes)?;
    Ok(Json(solve_frame(&state, entry, Frame::from(request)).await?))
}

/// Validates and solves `frame` as `POST /v1/bindings/{id}/frames` does (a
/// solve permit, the solve pool, the frame metrics), then evaluates the
/// posed curvenets.
async fn solve_frame(state: &AppState, entry: Arc<Entry>, frame: Frame) -> Result<ViewerFrame, ServiceError> {
    let permit = state.permit().await?;
    let metrics = state.inner.metrics.clone();
    state
        .on_pool(move || {
            let _permit = permit;
            frames::validate(&entry, &frame)?;
            let solved = frames::solve(&entry, &frame)?;
            metrics.solve_seconds.record(solved.solve_ms / 1e3);
            metrics.frames_solved.increment(1);
            let b = &entry.binding;
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
            let posed: Vec<Option<&[[f64; 3]]>> = frame.posed.iter().map(|p| p.as_deref()).collect();
            let curvenets = poses(&posed)?;
            let rest = match frame.rest.as_deref() {
                Some(r) => Some(RestView { points: flat(r), cut_points: cut_points(b, r), curvenets: poses(&[])? }),
                None => None,
            };
            Ok(ViewerFrame {
                time: None,
                cut_points: cut_points(b, &solved.points),
                points: flat(&solved.points),
                solve_ms: solved.solve_ms,
                curvenets,
                rest,
            })
        })
        .await
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
    let b: &Binding = &entry.binding;
    let mesh = b.surface().mesh();
    let mut triangles = Vec::new();
    let mut triangle_face = Vec::new();
    for (f, face) in mesh.faces().enumerate() {
        for k in 1..face.len() - 1 {
            triangles.extend([face[0], face[k], face[k + 1]]);
            triangle_face.push(f as u32);
        }
    }
    let mesh_view = MeshView {
        points: flat(&entry.projection_points),
        triangles,
        triangle_face,
        edges: mesh.edges().into_iter().flat_map(|(a, c)| [a, c]).collect(),
    };

    let cut = b.cut_mesh();
    let mut edges = Vec::new();
    let mut edge_kind = Vec::new();
    for h in 0..cut.n_halfedges() as u32 {
        let t = cut.twin(h);
        if t != INVALID && t < h {
            continue; // one edge per halfedge pair
        }
        let kind = if t == INVALID {
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
        mask: (0..cut.n_vertices() as u32).map(|v| cut.vertex(v).mask & (MESH_VERTEX | SAMPLE | CROSSING)).collect(),
        edges,
        edge_kind,
        face_start,
        face_vertices,
        face_parent: (0..cut.n_faces() as u32).map(|f| cut.parent(f)).collect(),
    };

    let diagonal = b.surface().diagonal();
    let mut warnings = entry.response.warnings.clone();
    let curvenets = b
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
                        curvenet_core::binding::cut::DEFAULT_MAX_PROJECTION_DISTANCE * 100.0
                    ),
                    segment: None,
                });
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
            }
        })
        .collect();
    ViewerData {
        binding: BindingResponse { cached: true, ..entry.response.clone() },
        diagonal,
        mesh: mesh_view,
        cut: cut_view,
        curvenets,
        warnings,
    }
}
