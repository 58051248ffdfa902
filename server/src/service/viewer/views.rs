//! What the viewer's endpoints answer and take: the serialized views of a
//! binding (mesh, cut-mesh, curvenets, cage), of a solved frame, of a
//! refused stage, and the requests of the stage endpoints. Plain data;
//! geometry.rs and refusal.rs fill them.

use std::collections::BTreeMap;

use curvenet_schema::wire::{AdjustmentSpec, BindingResponse, Warning};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::highlight::Highlight;
use super::stage::ViewerStage;

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

impl ViewerStageInfo {
    /// Stage `index` as `GET /v1/viewer/stages` lists it.
    pub fn of(index: usize, s: &ViewerStage) -> Self {
        Self {
            index,
            stage: s.stage.clone(),
            mesh: s.mesh.clone(),
            curvenets: s.curvenets.clone(),
            times: s.times.clone(),
        }
    }
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
    /// Samples farther than `FAR_SAMPLE_WARNING` (geometry.rs) of the diagonal from the surface.
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
    /// The frame's rest pose as the solve sees it, when it is not the
    /// projection pose (`Deformer::pose`: the frame's own rest pose with
    /// `before`-mode blend shapes, skinned, through the cage): the mesh, the
    /// cut-vertices and the curvenets tracked to it.
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
    /// A caged binding's cage this frame, where it deforms the mesh
    /// (`Deformer::pose`): the posed cage after CageUp (with a skin), else
    /// the frame's rest cage with its edits; flat `f32` xyz, `#C` (the
    /// edges of [`ViewerData::cage`] connect them).
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

/// A frame's rest pose, as the solve sees it.
#[derive(Debug, Serialize, ToSchema)]
pub struct RestView {
    pub points: Vec<f32>,
    pub cut_points: Vec<f32>,
    pub curvenets: Vec<PoseView>,
    /// A caged binding's rest cage this frame (its rest-cage edits, and
    /// the posed-cage offsets taken back by CageRev), flat `f32` xyz, `#C`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cage: Option<Vec<f32>>,
}

/// A posed curvenet.
#[derive(Debug, Serialize, ToSchema)]
pub struct PoseView {
    pub samples: Vec<f32>,
    pub frames: Vec<f32>,
}
