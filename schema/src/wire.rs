//! The HTTP wire types of `curvenet serve`, documented here once; the
//! service serves them as OpenAPI 3.1 at `/openapi.json`.
//!
//! # Conventions
//!
//! - JSON field names are `snake_case`. The two topology arrays also accept
//!   their USD spellings (`faceVertexCounts`, `faceVertexIndices`).
//! - Points are `[x, y, z]` triples in the stage's units. Requests carry
//!   them as JSON numbers (read as `f64`) or, in the binary form, as
//!   little-endian `f32`; responses carry `f32` (USD's `point3f`).
//! - Indices are 0-based `u32`. Every count and index in an error message
//!   refers to the arrays of the request (e.g. `posed[1] point 17`).
//! - A 3×3 matrix (a per-vertex deformation gradient) is 9 numbers, row
//!   major, acting on column vectors.
//!
//! # Binary frames
//!
//! `POST /v1/bindings/{id}/frames` (and `frames:batch`) also accept
//! `Content-Type: application/octet-stream`:
//!
//! ```text
//! u32 little-endian  header length H (bytes)
//! H bytes            UTF-8 JSON header: a BinaryFrameHeader, or {"frames": [BinaryFrameHeader, ...]}
//! raw data           the arrays the header lists, in its order, little-endian f32, no padding
//! ```
//!
//! The response uses the same framing: a [`BinaryResponseHeader`] (or
//! `{"frames": [...]}` for a batch) followed by `points` (`#V × 3` f32) and,
//! when asked for, `gradients` (`#V × 9` f32) per frame. The server pads its
//! header with spaces to a multiple of 4 bytes so the arrays are aligned.

use serde::{Deserialize, Serialize};

use crate::{CurvenetData, MeshData};
use utoipa::ToSchema;

/// The default samples per mean mesh edge length of a curvenet
/// (`curvenet:sampleDensity`).
pub const DEFAULT_SAMPLE_DENSITY: f64 = 5.0;

fn default_density() -> f64 {
    DEFAULT_SAMPLE_DENSITY
}

/// `POST /v1/bindings`: a mesh, its projection pose and the curvenets that
/// deform it (paper §4.1–4.2). Everything that changes a frame's result is
/// hashed into the binding id (blake3, hex): posting the same content again
/// returns the same id without recomputing.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BindingRequest {
    /// Corners per face (USD `faceVertexCounts`), each at least 3.
    #[serde(alias = "faceVertexCounts")]
    pub face_vertex_counts: Vec<u32>,
    /// Vertex indices, face after face, counter-clockwise seen from outside
    /// (USD `faceVertexIndices`).
    #[serde(alias = "faceVertexIndices")]
    pub face_vertex_indices: Vec<u32>,
    /// The projection pose, one point per vertex (`#V`): the pose the
    /// curvenets were drawn and are bound in.
    pub projection_points: Vec<[f64; 3]>,
    /// The curvenets deforming the mesh, in order (frames name their posed
    /// pools in this order). At least one.
    pub curvenets: Vec<CurvenetSpec>,
    /// UsdSkel blend shapes of the mesh; frames give one weight per shape.
    #[serde(default)]
    pub blend_shapes: Vec<BlendShapeSpec>,
    /// The rig underneath (UsdSkel skin of the mesh, spline skinning of the
    /// curvenets); frames then carry `joint_transforms`. Absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skin: Option<SkinSpec>,
    /// A closed triangle cage around the mesh (Corda et al. 2020): with a
    /// `skin` (which then needs its `skeleton`) the cage is coupled with the
    /// skeleton and a frame's rest pose is the coupled result; without one
    /// the cage alone deforms the mesh. Frames edit it with `rest_cage` and
    /// `posed_cage_offsets`. Absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageSpec>,
    #[serde(default)]
    pub options: BindingOptions,
}

/// A closed, consistently oriented triangle cage, its rest points at bind
/// (the cage the projection pose is bound to).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CageSpec {
    /// The rest cage at bind, one point per cage vertex (`#C`).
    pub points: Vec<[f64; 3]>,
    /// Three cage vertex indices per triangle, counter-clockwise seen from
    /// outside; the cage must be closed (every edge shared by two triangles).
    pub triangles: Vec<[u32; 3]>,
}

/// The skeleton of a skin (UsdSkel `joints` topology and `bindTransforms`):
/// needed when the skin is coupled with a cage (the cage relocates the joints).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SkeletonSpec {
    /// One parent per joint, an earlier joint's index, or -1 for a root.
    pub parents: Vec<i64>,
    /// One bind transform per joint in skeleton space (row-major 4×4, row
    /// vectors, translation in the last row: USD's layout).
    pub bind_transforms: Vec<[f64; 16]>,
}

/// How a skinned mesh blends its joints (UsdSkel `skel:skinningMethod`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SkinMethod {
    /// `classicLinear`: linear blend skinning (the default).
    #[default]
    ClassicLinear,
    /// `dualQuaternion`: dual-quaternion skinning.
    DualQuaternion,
    /// Centres of rotation (Le & Hodgins 2016; `curvenet:skinningMethod`
    /// `centersOfRotation`).
    CentersOfRotation,
}

/// The mesh's skin (UsdSkel form) and the curvenets' spline skinning. A
/// frame's `joint_transforms` (one skinning transform per joint, in the
/// mesh's space) skin the frame's rest pose (or the projection pose) and
/// pose the spline-skinned curvenets.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SkinSpec {
    /// The skeleton's joint count (every joint index is below it).
    pub joints: u32,
    /// Influences per mesh point (`primvars:skel:jointIndices` element size).
    pub element_size: u32,
    /// `element_size` joint indices per mesh point.
    pub joint_indices: Vec<i64>,
    /// `element_size` weights per mesh point; a point's weights summing to 1
    /// within 1e-4 are rescaled to sum to 1 exactly.
    pub joint_weights: Vec<f64>,
    /// `primvars:skel:geomBindTransform`, row-major with row vectors (USD's
    /// layout, translation in the last row); absent: the identity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geom_bind_transform: Option<[f64; 16]>,
    #[serde(default)]
    pub method: SkinMethod,
    /// One entry per curvenet (in `curvenets` order), or empty: none is
    /// spline-skinned.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub curvenets: Vec<CurvenetSkinSpec>,
    /// G¹-flexible spline-skinning iterations (0: the fixed-ratio fit, as
    /// `curvenet bake` by default).
    #[serde(default)]
    pub flexible_iterations: u32,
    /// The skeleton: required with a `cage` (the coupled rig relocates the
    /// joints); without a cage it changes no result (it is still part of
    /// the binding id).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skeleton: Option<SkeletonSpec>,
}

/// How one curvenet follows the skeleton.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum CurvenetSkinSpec {
    /// Not spline-skinned: its posed pool, else knot tracking.
    None,
    /// Spline skinning with weights per control point (`element_size` per pool point).
    Weights { element_size: u32, joint_indices: Vec<i64>, joint_weights: Vec<f64> },
    /// Spline skinning with weights taken from the mesh's skin at the curves.
    Mesh,
}

impl BindingRequest {
    /// The request for `mesh` of a stage bound to its curvenets `nets` (in
    /// `mesh.curvenets` order), with the mesh's blend shapes and default
    /// options: what `curvenet serve --open-stage` posts, and what a client
    /// reading the stage itself would send.
    pub fn from_stage(mesh: &MeshData, nets: &[CurvenetData]) -> Self {
        Self {
            face_vertex_counts: mesh.face_vertex_counts.clone(),
            face_vertex_indices: mesh.face_vertex_indices.clone(),
            projection_points: mesh.projection_points.clone(),
            curvenets: nets
                .iter()
                .map(|n| CurvenetSpec {
                    pool: n.pool.clone(),
                    splines: n.splines.clone(),
                    sample_density: n.sample_density,
                })
                .collect(),
            blend_shapes: mesh
                .blend_shapes
                .iter()
                .map(|s| BlendShapeSpec {
                    name: Some(s.name.clone()),
                    offsets: s.offsets.clone(),
                    point_indices: s.point_indices.clone(),
                    inbetweens: s
                        .inbetweens
                        .iter()
                        .map(|i| InbetweenSpec { weight: i.weight, offsets: i.offsets.clone() })
                        .collect(),
                })
                .collect(),
            skin: None,
            cage: None,
            options: BindingOptions::default(),
        }
    }
}

impl BindingRequest {
    /// The request with the stage's cage (`Stage::cage`): its rest points
    /// at bind and its triangles.
    pub fn with_cage(mut self, cage: &crate::CageData) -> Self {
        self.cage = Some(CageSpec { points: cage.rest_points.clone(), triangles: cage.triangles.clone() });
        self
    }

    /// The request with the mesh's UsdSkel skin (`Stage::skin_rig`), its
    /// skeleton, and how each curvenet follows it (`curvenets`, binding
    /// order, e.g. from `Stage::curvenet_skinning`), as `curvenet bake`
    /// rigs it: `curvenet:skinningMethod` overrides UsdSkel's token.
    pub fn with_skin(mut self, rig: &crate::usd::SkinRig, curvenets: Vec<CurvenetSkinSpec>) -> Self {
        use crate::usd::CurvenetSkinningMethod as M;
        use curvenet_core::SkinningMethod as S;
        let method = match (rig.curvenet_method, rig.method) {
            (Some(M::ClassicLinear), _) | (None, S::ClassicLinear) => SkinMethod::ClassicLinear,
            (Some(M::DualQuaternion), _) | (None, S::DualQuaternion) => SkinMethod::DualQuaternion,
            (Some(M::CentersOfRotation), _) | (None, S::CentersOfRotation) => SkinMethod::CentersOfRotation,
        };
        self.skin = Some(SkinSpec {
            joints: rig.joints.len() as u32,
            element_size: rig.element_size as u32,
            joint_indices: rig.joint_indices.clone(),
            joint_weights: rig.joint_weights.clone(),
            geom_bind_transform: Some(rig.geom_bind_transform),
            method,
            curvenets: if curvenets.iter().all(|c| *c == CurvenetSkinSpec::None) { Vec::new() } else { curvenets },
            flexible_iterations: 0,
            skeleton: Some(SkeletonSpec {
                parents: rig.parents.iter().map(|p| p.map_or(-1, i64::from)).collect(),
                bind_transforms: rig.bind_transforms.clone(),
            }),
        });
        self
    }
}

/// One curvenet: a pool of control points and cubic Bézier splines indexing it.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CurvenetSpec {
    /// The neutral pose of the control-point pool (`#P` points), drawn over
    /// the projection pose (`primvars:curvenet:cv`).
    pub pool: Vec<[f64; 3]>,
    /// Four pool indices per spline: endpoint, handle, handle, endpoint.
    /// Splines sharing an endpoint index are joined there.
    pub splines: Vec<[u32; 4]>,
    /// Samples per mean mesh edge length (`curvenet:sampleDensity`), default 5.
    #[serde(default = "default_density")]
    pub sample_density: f64,
}

/// A UsdSkel blend shape: offsets at weight 1, optional sparse point
/// indices, inbetweens at their weights.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BlendShapeSpec {
    /// Informational (e.g. the `skel:blendShapes` token); not hashed.
    #[serde(default)]
    pub name: Option<String>,
    /// Offsets of the full shape: one per vertex, or one per point index.
    pub offsets: Vec<[f64; 3]>,
    /// The vertex of each offset (sparse shape); absent for a dense shape.
    #[serde(default)]
    pub point_indices: Option<Vec<u32>>,
    /// Inbetween shapes, laid out like `offsets`.
    #[serde(default)]
    pub inbetweens: Vec<InbetweenSpec>,
}

/// An inbetween shape, reached exactly at `weight` (not 0 or 1).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct InbetweenSpec {
    pub weight: f64,
    pub offsets: Vec<[f64; 3]>,
}

/// Binding options. Both tolerances are relative to the mesh's
/// bounding-box diagonal.
#[derive(Debug, Clone, Default, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BindingOptions {
    /// Refuse a mesh with a connected component no curvenet touches
    /// (otherwise its vertices pass through at the rest pose, with a warning).
    #[serde(default)]
    pub strict: bool,
    /// Vertex/edge snapping tolerance of the cutter (default 1e-5, the paper's 0.001 %).
    #[serde(default)]
    pub snap_tolerance: Option<f64>,
    /// Largest distance of a curvenet sample from the surface (default 0.05).
    #[serde(default)]
    pub max_projection_distance: Option<f64>,
}

/// The answer to `POST /v1/bindings`.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct BindingResponse {
    /// The content hash (blake3, 64 hex digits) naming the binding in `/v1/bindings/{id}/...`.
    pub binding_id: String,
    /// blake3 of the topology alone; frames may send it back to assert
    /// that their mesh is still the bound one.
    pub topology_hash: String,
    /// Whether the binding was already cached (nothing was recomputed).
    pub cached: bool,
    /// Mesh vertices (`#V`): the length of every frame's points.
    pub vertices: usize,
    /// Control points of each curvenet's pool, in order (the length of its posed pool).
    pub control_points: Vec<usize>,
    /// Number of blend shapes (the length of a frame's weights).
    pub blend_shapes: usize,
    /// The binding's estimated memory, as weighed by the cache (bytes): the
    /// binding, one frame workspace per solve thread, and the group
    /// workspaces it keeps once batches are solved on it (per solve thread,
    /// 8 frame workspaces and their interleaved block), counted from the
    /// start so that the cache's bound holds whatever frames come.
    pub size_bytes: u64,
    pub stats: BindingStats,
    pub timings: BindingTimings,
    pub warnings: Vec<Warning>,
    /// The binding's cage, when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageStats>,
}

/// A binding's cage: counts, the MaxVol system and the memory of `Φ`.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct CageStats {
    /// Cage vertices (`#C`): the length of a frame's `rest_cage` and `posed_cage_offsets`.
    pub vertices: usize,
    pub triangles: usize,
    /// Mesh vertices chosen by MaxVol (the square system CageRev inverts).
    pub maxvol_rows: usize,
    /// Condition number of the MaxVol system.
    pub condition: f64,
    /// Bytes of the mean value coordinates `Φ` (`#V × #C`).
    pub phi_bytes: u64,
}

/// Counts describing a binding.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct BindingStats {
    pub mesh_vertices: usize,
    pub mesh_faces: usize,
    pub samples: usize,
    pub segments: usize,
    pub cut_vertices: usize,
    pub cut_faces: usize,
    pub cut_halfedges: usize,
    pub cracks: usize,
    pub islands_removed: usize,
    /// Segments embedded as a chord inside one face.
    pub chord_paths: usize,
    /// Segments embedded by the straightest path (the paper's choice).
    pub straightest_paths: usize,
    /// Segments embedded by the fallback (shortest path in a strip of
    /// faces) after the straightest path missed.
    pub fallback_paths: usize,
    /// Segments left out: their samples project onto two mesh components.
    pub segments_left_out: usize,
    /// Segments bound along a detour or left out (`segment_detour` warnings).
    pub detours: usize,
    pub unknowns: usize,
    pub constraints: usize,
    pub factor_nonzeros: usize,
}

/// Times of the binding's stages, milliseconds (of the computation that
/// made the cached binding, also when `cached` is true).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct BindingTimings {
    /// Curvenet analysis (paper §3): sampling, intersections.
    pub analysis_ms: f64,
    pub surface_ms: f64,
    pub cutting_ms: f64,
    pub assembly_ms: f64,
    pub factor_ms: f64,
    /// The whole binding, wall time.
    pub total_ms: f64,
}

impl BindingRequest {
    /// The request's mesh as core takes it (faces and projection pose).
    pub fn mesh_input(&self) -> curvenet_core::MeshInput<'_> {
        curvenet_core::MeshInput {
            face_vertex_counts: &self.face_vertex_counts,
            face_vertex_indices: &self.face_vertex_indices,
            projection_points: &self.projection_points,
        }
    }
}

impl CurvenetSpec {
    /// The curvenet as core takes it: splines, neutral pool, sampling density.
    pub fn input(&self) -> curvenet_core::CurvenetInput<'_> {
        curvenet_core::CurvenetInput { splines: &self.splines, pool: &self.pool, sample_density: self.sample_density }
    }
}

impl From<&curvenet_core::BindStats> for BindingStats {
    /// The one conversion from core's counts to their wire names (the
    /// service's binding response and `curvenet inspect --bind` both use it).
    fn from(s: &curvenet_core::BindStats) -> Self {
        BindingStats {
            mesh_vertices: s.mesh_vertices,
            mesh_faces: s.mesh_faces,
            samples: s.samples,
            segments: s.segments,
            cut_vertices: s.cut_vertices,
            cut_faces: s.cut_faces,
            cut_halfedges: s.cut_halfedges,
            cracks: s.cracks,
            islands_removed: s.islands_removed,
            chord_paths: s.embedding.chord,
            straightest_paths: s.embedding.straightest,
            fallback_paths: s.embedding.fallback,
            segments_left_out: s.embedding.disconnected,
            detours: s.detours,
            unknowns: s.unknowns,
            constraints: s.constraints,
            factor_nonzeros: s.factor_nonzeros,
        }
    }
}

impl BindingTimings {
    /// Core's stage times with the analysis and wall time measured around them.
    pub fn new(analysis_ms: f64, stages: &curvenet_core::BindTimings, total_ms: f64) -> Self {
        BindingTimings {
            analysis_ms,
            surface_ms: stages.surface_ms,
            cutting_ms: stages.cutting_ms,
            assembly_ms: stages.assembly_ms,
            factor_ms: stages.factor_ms,
            total_ms,
        }
    }
}

/// Something the binding did that the user should know about. Besides the
/// code and the message, the elements it is about, in fields that are
/// absent when they do not apply (clients that read only `code` and
/// `message` keep working).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct Warning {
    /// `untouched_component`, `islands_removed`, `degenerate_cut_faces`, `faces_split`,
    /// `curves_touch` or `segment_detour`.
    pub code: String,
    pub message: String,
    /// The segment a `segment_detour` warning is about.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment: Option<SegmentAt>,
    /// The points a `curves_touch` warning names (the first few of
    /// `count`): the two segments and where their surface paths meet.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub touches: Vec<TouchAt>,
    /// The input faces a `faces_split` warning names.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faces: Vec<u32>,
    /// The mesh component an `untouched_component` warning names (the
    /// numbering of the binding's connected components): the first of
    /// `count` (one warning stands for every untouched component; its
    /// message lists the first few).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component: Option<usize>,
    /// How many places the warning is about, when it lists only some
    /// (`curves_touch`: every meeting point, `touches` shows the first few;
    /// `untouched_component`: every untouched component, `component` is
    /// the first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<usize>,
}

/// A curvenet segment as users number it: the curvenet (in the binding
/// request's order), the spline within it, the segment within the spline
/// (from the spline's control point 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct SegmentId {
    pub curvenet: u32,
    pub spline: u32,
    pub segment: u32,
}

impl From<curvenet_core::SegmentRef> for SegmentId {
    fn from(s: curvenet_core::SegmentRef) -> Self {
        SegmentId { curvenet: s.curvenet, spline: s.spline, segment: s.segment }
    }
}

/// Two segments whose surface paths meet where they share no knot, and
/// that point in the projection pose (a `curves_touch` warning).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct TouchAt {
    pub segment: SegmentId,
    pub other: SegmentId,
    pub position: [f64; 3],
}

impl From<&curvenet_core::BindWarning> for Warning {
    /// The one conversion from core's warnings to the wire: the code, the
    /// message core writes, and the elements as fields.
    fn from(w: &curvenet_core::BindWarning) -> Self {
        use curvenet_core::BindWarning as W;
        let mut out = Warning {
            code: String::new(),
            message: w.to_string(),
            segment: None,
            touches: Vec::new(),
            faces: Vec::new(),
            component: None,
            count: None,
        };
        out.code = match w {
            W::UntouchedComponents { count, examples, .. } => {
                out.component = examples.first().map(|&(c, _)| c);
                out.count = Some(*count);
                "untouched_component"
            }
            W::IslandsRemoved { .. } => "islands_removed",
            W::DegenerateCutFaces { .. } => "degenerate_cut_faces",
            W::FacesSplit { faces } => {
                out.faces = faces.clone();
                "faces_split"
            }
            W::CurvesTouch { count, examples } => {
                out.count = Some(*count);
                out.touches = examples
                    .iter()
                    .map(|(s, o, p)| TouchAt { segment: (*s).into(), other: (*o).into(), position: *p })
                    .collect();
                "curves_touch"
            }
            W::SegmentDetour { segment, t, position, path_length, segment_length } => {
                out.segment = Some(SegmentAt {
                    curvenet: segment.curvenet,
                    spline: segment.spline,
                    segment: segment.segment,
                    t: *t,
                    position: *position,
                    path_length: path_length.is_finite().then_some(*path_length),
                    segment_length: *segment_length,
                });
                "segment_detour"
            }
            _ => "other",
        }
        .to_string();
        out
    }
}

/// A curvenet segment and where it is: the curvenet (in the binding
/// request's order), the spline within it, the segment within the spline
/// (from the spline's control point 0), the segment's midpoint as a
/// fraction of the spline's arc length, and that midpoint in the projection pose.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct SegmentAt {
    pub curvenet: u32,
    pub spline: u32,
    pub segment: u32,
    pub t: f64,
    pub position: [f64; 3],
    /// Length of the segment's surface path; absent when the segment was
    /// left out (its samples project onto two mesh components).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path_length: Option<f64>,
    pub segment_length: f64,
}

/// How blend shapes combine with the curvenet deformation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum BlendShapeMode {
    /// Offsets mapped by each vertex's deformation gradient after the
    /// deformation (paper §5; the default): sculpts move with the surface.
    #[default]
    After,
    /// Offsets added to the rest pose before the deformation.
    Before,
}

/// One frame (`POST /v1/bindings/{id}/frames`, JSON form).
#[derive(Debug, Clone, Default, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FrameRequest {
    /// The posed control-point pool of each curvenet, in binding order, or
    /// `null` for a curvenet that is not articulated this frame (its knots
    /// track the rest pose). Absent: no curvenet is articulated.
    #[serde(default)]
    pub posed: Option<Vec<Option<Vec<[f64; 3]>>>>,
    /// The mesh's rest pose this frame (skinning or cloth output, `#V`
    /// points); absent: the projection pose.
    #[serde(default)]
    pub rest: Option<Vec<[f64; 3]>>,
    /// One weight per blend shape of the binding; absent: all zero.
    #[serde(default)]
    pub blend_shape_weights: Option<Vec<f64>>,
    #[serde(default)]
    pub blend_shape_mode: BlendShapeMode,
    /// Also return the per-vertex deformation gradients.
    #[serde(default)]
    pub gradients: bool,
    /// The binding's `topology_hash` as the client knows it; a mismatch is
    /// refused (`topology_changed`) instead of deforming the wrong mesh.
    #[serde(default)]
    pub topology_hash: Option<String>,
    /// Curvenet Adjustments, applied in order on top of whatever poses the
    /// curvenets (the posed pools, or knot tracking to the rest pose when a
    /// curvenet is not articulated). Absent or empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub adjustments: Vec<AdjustmentSpec>,
    /// Also return every knot's orientation (`knot_orientations`): the
    /// frames the adjustments are expressed in.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub orientations: bool,
    /// The skinning transforms of this frame, one per joint of the
    /// binding's `skin` (row-major 4×4, row vectors, in the mesh's space:
    /// UsdSkel's skinning transforms); absent: no skinning this frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_transforms: Option<Vec<[f64; 16]>>,
    /// The rest cage this frame, one point per vertex of the binding's
    /// `cage` (the mesh's space); absent: the cage at bind.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rest_cage: Option<Vec<[f64; 3]>>,
    /// Posed-cage edits this frame, one offset per vertex of the binding's
    /// `cage` (the skinned points' space); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub posed_cage_offsets: Option<Vec<[f64; 3]>>,
}

/// One Curvenet Adjustment: a knot (a spline endpoint) moved in its
/// orientation frame, so "up" follows the surface. Every field but
/// `curvenet` and `knot` is optional and defaults to no change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AdjustmentSpec {
    /// The curvenet, by its index in the binding request's `curvenets`.
    pub curvenet: u32,
    /// The knot, by its index in the curvenet's pool; it must be a spline endpoint.
    pub knot: u32,
    /// Translate in the knot's frame; default `[0, 0, 0]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translate: Option<[f64; 3]>,
    /// Rotate about the knot in its frame, Euler angles in degrees, applied
    /// about X, then Y, then Z (USD's `rotateXYZ`); default `[0, 0, 0]`.
    /// Acts on the knot's attached tangents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<[f64; 3]>,
    /// Rotate about the knot in its frame by a quaternion `(w, x, y, z)`
    /// instead (USD's `xformOp:orient`; normalised); give `rotate` or
    /// `orient`, not both. Acts on the knot's attached tangents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orient: Option<[f64; 4]>,
    /// Scale about the knot in its frame; default `[1, 1, 1]`. Acts on the
    /// knot's attached tangents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f64; 3]>,
    /// Whether the knot's tangent control points move, rotate and scale
    /// with it; default `true`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attach_tangents: Option<bool>,
    /// One translate per tangent control point of the knot, in the knot's
    /// frame, in the order the tangents appear in the pool; absent or
    /// empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tangent_translates: Vec<[f64; 3]>,
}

/// One deformed frame.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct FrameResponse {
    /// Deformed points, `#V`.
    pub points: Vec<[f32; 3]>,
    /// Per-vertex deformation gradients (row-major 3×3), when asked for.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub gradients: Option<Vec<[f32; 9]>>,
    /// The solve's wall time, milliseconds.
    pub solve_ms: f64,
    /// When the frame asked for `orientations`: one object per curvenet,
    /// mapping each knot's pool index (a string key, e.g. `"12"`) to its
    /// orientation in this frame (row-major 3×3; its columns are the knot
    /// frame's axes), in the pose the frame's adjustments act on (before them).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub knot_orientations: Option<Vec<std::collections::BTreeMap<String, [f64; 9]>>>,
}

/// `POST /v1/bindings/{id}/frames:batch` (JSON form).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FrameBatchRequest {
    pub frames: Vec<FrameRequest>,
}

/// The frames of a batch, in request order.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct FrameBatchResponse {
    pub frames: Vec<FrameResponse>,
}

/// `POST /v1/deform`: a binding and one frame in one request. The binding
/// goes through the cache (same content → no recomputation).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeformRequest {
    pub binding: BindingRequest,
    pub frame: FrameRequest,
}

/// The answer to `POST /v1/deform`.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct DeformResponse {
    pub binding_id: String,
    /// Whether the binding came from the cache.
    pub cached: bool,
    pub frame: FrameResponse,
}

/// `POST /v1/bake`: bake a shot stage on the server's file system. Both
/// paths must lie inside one of the server's `--bake-root` directories
/// (after resolving `..` and symlinks); relative paths are relative to the
/// first root.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BakeRequest {
    /// The shot stage to read.
    pub stage: String,
    /// The override layer to write (`.usda` or `.usdc`).
    pub output: String,
    /// Frame range `A-B` (inclusive); absent: the stage's time-code range.
    #[serde(default)]
    pub frames: Option<String>,
}

/// The answer to `POST /v1/bake`.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct BakeResponse {
    /// The canonical stage path.
    pub stage: String,
    /// The canonical output path.
    pub output: String,
    pub elapsed_ms: f64,
    /// What `curvenet bake` would print as warnings on stderr (without its
    /// `curvenet: warning: ` prefix), each naming the stage or prim: the
    /// bindings' warnings, skin weights that do not sum to 1, a frame range
    /// reaching outside the stage's. Empty when there were none.
    #[serde(default)]
    pub warnings: Vec<String>,
}

/// Every error answer: a stable snake_case `code` (see the service's code
/// table), a message naming the offending element, and, when the error is
/// about elements of the request, `details` naming them by field.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    pub code: String,
    pub message: String,
    /// The elements the error is about; absent when it names none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub details: Option<ErrorDetails>,
}

/// The elements an error is about, each numbered as in the request (absent
/// fields are omitted). Curvenets are numbered in the binding request's
/// order, splines within their curvenet, segments within their spline (from
/// its control point 0), samples within their curvenet; faces and vertices
/// are the request mesh's.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ErrorDetails {
    /// The frame of a batch (its index in `frames`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<usize>,
    /// The curvenet (index in `curvenets`, or in a frame's `posed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curvenet: Option<u32>,
    /// The spline, within its curvenet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spline: Option<u32>,
    /// Two splines (both leave one intersection in the same direction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub splines: Option<[u32; 2]>,
    /// The segment, within its spline.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment: Option<u32>,
    /// The other segment of two that overlap or cross.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub other: Option<SegmentId>,
    /// The sample, within its curvenet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample: Option<u32>,
    /// A control point of the curvenet's pool (an intersection or a knot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_point: Option<u32>,
    /// A face of the mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face: Option<usize>,
    /// Faces of the mesh (those sharing an edge).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub faces: Option<Vec<u32>>,
    /// A vertex of the mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertex: Option<u32>,
    /// Vertices of the mesh (a face's corners, coincident corners).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices: Option<Vec<u32>>,
    /// A mesh edge, as its two vertices.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge: Option<[u32; 2]>,
    /// A connected component of the mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component: Option<usize>,
    /// The row of the failing pivot of a factorisation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row: Option<usize>,
    /// A Curvenet Adjustment (its index), or two of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adjustment: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adjustments: Option<[usize; 2]>,
    /// The array or quantity the error is about (`rest`, `blend_shape_weights`, `face vertex index`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub what: Option<String>,
    /// The index into `what`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<usize>,
    /// The count expected and the count given (`count_mismatch`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub got: Option<usize>,
    /// The spline parameter of the place (a segment's midpoint, as a fraction of arc length).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t: Option<f64>,
    /// The place, in the projection pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
}

/// `/healthz` and `/readyz`.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct HealthResponse {
    /// `ok`, `ready` or `draining`.
    pub status: String,
}

/// One array of a binary frame.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BinaryArray {
    /// `posed` (with `index`: the curvenet), `rest`, `blend_shape_weights`,
    /// `joint_transforms` (`[J, 16]`), `rest_cage` or `posed_cage_offsets`
    /// (`[C, 3]`, one row per cage vertex) in requests; `points` or
    /// `gradients` in responses.
    pub name: String,
    /// The curvenet of a `posed` array.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<u32>,
    /// Only `f32` (little-endian; `float32` and `<f4` are accepted too).
    #[serde(default = "default_dtype")]
    pub dtype: String,
    /// `[n, 3]` for points, `[n, 9]` for gradients, `[k]` for weights,
    /// `[J, 16]` for joint transforms.
    pub shape: Vec<u64>,
}

fn default_dtype() -> String {
    "f32".into()
}

/// The JSON header of one binary frame request. A curvenet without a
/// `posed` array is not articulated this frame.
#[derive(Debug, Clone, Default, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BinaryFrameHeader {
    #[serde(default)]
    pub arrays: Vec<BinaryArray>,
    #[serde(default)]
    pub blend_shape_mode: BlendShapeMode,
    #[serde(default)]
    pub gradients: bool,
    #[serde(default)]
    pub topology_hash: Option<String>,
    /// Curvenet Adjustments, as in [`FrameRequest::adjustments`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub adjustments: Vec<AdjustmentSpec>,
    /// Also return the knots' orientations, as in [`FrameRequest::orientations`].
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub orientations: bool,
}

/// The JSON header of one binary frame response.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct BinaryResponseHeader {
    pub arrays: Vec<BinaryArray>,
    pub solve_ms: f64,
    /// As in [`FrameResponse::knot_orientations`], when asked for.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub knot_orientations: Option<Vec<std::collections::BTreeMap<String, [f64; 9]>>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn untouched_components_go_out_as_one_warning_with_the_first_and_the_count() {
        let w =
            curvenet_core::BindWarning::UntouchedComponents { count: 9, vertices: 54, examples: vec![(2, 6), (4, 6)] };
        let out = Warning::from(&w);
        assert_eq!((out.code.as_str(), out.component, out.count), ("untouched_component", Some(2), Some(9)));
        let json = serde_json::to_value(&out).unwrap();
        assert_eq!((json["component"].as_u64(), json["count"].as_u64()), (Some(2), Some(9)));
        assert!(out.message.contains("9 mesh components"), "{}", out.message);
    }
}
