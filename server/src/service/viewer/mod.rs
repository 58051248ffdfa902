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
//! (`solve::solve_frames`: a solve permit, the solve pool, validation,
//! `Deformer::frame`, the frame metrics). Every pose drawn is the
//! deformer's: the frame's rest pose, posed pools and cage come from
//! `Deformer::pose` (the code `Deformer::frame` solves from: blend shapes
//! before, skinning, the coupled cage, spline skinning), the posed
//! curvenet's samples and scaled frames from `Binding::curvenet_pose` (the
//! samples and frames the solve itself uses). The viewer evaluates no
//! blend shape, skinning or cage itself. Positions are sent as flat `f32`
//! arrays (`[x0, y0, z0, x1, ...]`) to keep the JSON small.
//!
//! This file holds the routes' handlers; each other file one concern, and
//! none of them names anything of this file (the stage types are a leaf
//! the application state holds):
//!
//! ```text
//! stage.rs      ViewerStage, FrameSource: the stages opened
//! views.rs      the serialized views and requests
//! geometry.rs   binding and frame geometry, read from core (ViewerData, ViewerFrame)
//! refusal.rs    a refused stage, rebuilt through core for drawing (ViewerRefusal)
//! highlight.rs  what warnings and errors name, with its geometry
//! adjust.rs     Curvenet Adjustments: composition and the export layer
//! assets.rs     the page, its ES modules and CSS, built in
//! ```
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

use std::sync::Arc;

use crate::frame::CoreFrame;
use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use curvenet_core::Adjustment;
use curvenet_schema::usd::{LayerFormat, encode_adjustment_layer};
use curvenet_schema::wire::{AdjustmentSpec, BindingResponse, ErrorBody, FrameRequest};

mod adjust;
mod assets;
mod geometry;
mod highlight;
mod refusal;
pub(crate) mod stage;
mod views;

pub use adjust::StageAdjustment;
pub use highlight::Highlight;
pub use stage::{FrameSource, ViewerStage};
pub use views::{
    CageView, CurvenetView, CutView, MeshView, PoseView, RestView, SketchView, ViewerAdjustRequest, ViewerAdjustment,
    ViewerData, ViewerExportRequest, ViewerFrame, ViewerRefusal, ViewerStageBinding, ViewerStageInfo, ViewerStages,
};

use crate::entry::{Entry, parse_key};
use crate::error::{Code, Phase, ServiceError};
use crate::extract::{Admission, Admitted, CachedBinding, ContentType, JsonOnly, Params, SizedBody, parse_json};
use crate::pool::{Numbering, solve_frames};
use crate::state::{AppState, blocking};

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

// ---------------------------------------------------------------- the page

pub(crate) async fn page() -> Response {
    assets::asset("text/html; charset=utf-8", assets::INDEX_HTML)
}

/// One of the viewer's ES modules (`assets::MODULES`), as JavaScript (the
/// MIME type module scripts need).
pub(crate) async fn module(Params(name): Params<String>) -> Result<Response, ServiceError> {
    match assets::module_source(&name) {
        Some(source) => Ok(assets::asset("text/javascript; charset=utf-8", source)),
        None => Err(ServiceError::new(
            Code::NotFound,
            format!("the viewer has no module {name} (it has {})", assets::module_names()),
        )),
    }
}

pub(crate) async fn style() -> Response {
    assets::asset("text/css; charset=utf-8", assets::VIEWER_CSS)
}

// ---------------------------------------------------------------- handlers

/// The stages opened in the viewer.
#[utoipa::path(get, path = "/v1/viewer/stages", tag = "viewer", security(("bearer" = [])),
    responses((status = 200, description = "The stages opened with --open-stage", body = ViewerStages)))]
pub(crate) async fn stages(State(state): State<AppState>) -> Json<ViewerStages> {
    let stages = state.inner.viewer_stages.read().unwrap_or_else(|e| e.into_inner());
    Json(ViewerStages { stages: stages.iter().enumerate().map(|(i, s)| ViewerStageInfo::of(i, s)).collect() })
}

/// The entry of a stage's binding: cached, else bound now (through the cache).
async fn stage_entry(state: &AppState, stage: &ViewerStage) -> Result<(Arc<Entry>, bool), ServiceError> {
    let known = stage.bound();
    if let Some(id) = known
        && let Some(entry) = parse_key(&id)
        && let Ok(Some(e)) = state.inner.cache.get(&entry).await
    {
        return Ok((e, true));
    }
    let (entry, cached) =
        crate::handlers::bindings::bind(state, stage.binding.clone()).await.map_err(|e| e.context(&stage.mesh))?;
    stage.set_bound(entry.id.clone());
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
        info: ViewerStageInfo::of(index, &stage),
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
        let Some(refused) = refusal::refusal(index, &stage) else {
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

/// The user's adjustments as solved (see `adjust::layer_adjustment`: as
/// the exported layer stores them), checked against the binding: a bad one
/// is refused naming `adjustments[i]`, its curvenet and knot.
fn user_adjustments(
    entry: &Entry,
    stage: &ViewerStage,
    specs: &[AdjustmentSpec],
) -> Result<Vec<AdjustmentSpec>, ServiceError> {
    // Refused as a frame's adjustments are (both rotations, magnitudes; a
    // zero quaternion, a bad knot) before they are rounded to the layer's types.
    crate::frame::check_adjustment_values(specs)?;
    let given: Vec<Adjustment> = specs.iter().map(Adjustment::from).collect();
    entry
        .binding()
        .check_adjustments(&given)
        .map_err(|e| crate::frame::name_adjustment(ServiceError::core(e, Phase::Frame), specs))?;
    let user: Vec<Adjustment> = specs
        .iter()
        .map(|s| adjust::layer_adjustment(s, adjust::find(&stage.adjustments, s.curvenet, s.knot)))
        .collect();
    let user_specs: Vec<AdjustmentSpec> = user.iter().map(AdjustmentSpec::from).collect();
    entry
        .binding()
        .check_adjustments(&user)
        .map_err(|e| crate::frame::name_adjustment(ServiceError::core(e, Phase::Frame), &user_specs))?;
    Ok(user_specs)
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
    let mut frame = read;
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
        if user.iter().any(|u| u.curvenet == c && u.knot == n) {
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
    let bytes = blocking(move || {
        let data = geometry::data(entry.binding(), entry.projection_points(), entry.deformer.cage(), &entry.response);
        serde_json::to_vec(&data).map_err(ServiceError::internal_from)
    })
    .await?;
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
    let frame = parse_json::<FrameRequest>(&bytes)?;
    Ok(Json(solve_frame(&state, admission, entry, frame).await?))
}

/// Solves `frame` through the service's one solve helper (as `POST
/// /v1/bindings/{id}/frames` does: validation, the solve pool, the frame
/// metrics), then asks the deformer for the frame's pose (`Deformer::pose`:
/// the rest pose, posed pools and cage the solve started from) and draws it.
async fn solve_frame(
    state: &AppState,
    admission: Admission,
    entry: Arc<Entry>,
    frame: FrameRequest,
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
            let parts = CoreFrame::new(&poses);
            let pose = entry.deformer.pose(&parts.frame(&poses)).map_err(|e| ServiceError::core(e, Phase::Frame))?;
            geometry::frame_view(
                &entry.deformer,
                &pose,
                parts.adjustments(),
                &solved.points,
                solved.solve_ms,
                solved.knot_orientations,
            )
        },
    )
    .await
    .map(|(view, _)| view)
}
