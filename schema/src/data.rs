//! Plain data read from a stage: what the core needs, nothing USD-specific.
//! Positions are widened from USD's 32-bit floats to `f64`.

use serde::Serialize;

/// A mesh deformed by curvenets (a `UsdGeomMesh` with `rel curvenet:curvenets`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshData {
    /// Composed prim path, e.g. `/Hand/Mesh`.
    pub path: String,
    /// Corners per face.
    pub face_vertex_counts: Vec<u32>,
    /// Vertex indices, face after face, counter-clockwise (a `leftHanded`
    /// mesh has been reversed face by face).
    pub face_vertex_indices: Vec<u32>,
    /// The projection pose (`primvars:curvenet:projectionPoints`, else the
    /// default value of `points`).
    pub projection_points: Vec<[f64; 3]>,
    /// Time codes at which `points` (the rest pose) has samples; empty when
    /// the rest pose is the default value at every frame.
    pub rest_sample_times: Vec<f64>,
    /// Paths of the curvenet prims that deform this mesh, in order.
    pub curvenets: Vec<String>,
    /// Blend shapes bound to the mesh, in `skel:blendShapes` order.
    pub blend_shapes: Vec<BlendShapeData>,
    /// The `SkelAnimation` that carries the blend-shape weights, if any.
    pub blend_shape_animation: Option<String>,
}

/// A curvenet prim: a control-point pool and the cubic Bézier splines indexing it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurvenetData {
    /// Composed prim path.
    pub path: String,
    /// The neutral pose of the pool (the default value of `primvars:curvenet:cv`).
    pub pool: Vec<[f64; 3]>,
    /// Four pool indices per spline: endpoint, handle, handle, endpoint.
    pub splines: Vec<[u32; 4]>,
    /// `curvenet:sampleDensity` (5 when not authored).
    pub sample_density: f64,
    /// Time codes at which the pool has posed samples (empty: not articulated).
    pub sample_times: Vec<f64>,
}

/// One UsdSkel blend shape bound to a mesh.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlendShapeData {
    /// The name the mesh's `skel:blendShapes` gives it (the name weights refer to).
    pub name: String,
    /// Path of the `BlendShape` prim.
    pub prim: String,
    /// Offsets of the full shape (weight 1).
    pub offsets: Vec<[f64; 3]>,
    /// The vertex each offset applies to; `None` for a dense shape (one offset per vertex).
    pub point_indices: Option<Vec<u32>>,
    /// Inbetween shapes, sorted by weight.
    pub inbetweens: Vec<InbetweenData>,
}

/// An inbetween shape of a blend shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InbetweenData {
    /// The name after `inbetweens:`.
    pub name: String,
    /// The weight at which this shape is reached exactly.
    pub weight: f64,
    /// Offsets, laid out like the parent's `offsets`.
    pub offsets: Vec<[f64; 3]>,
}

/// A `CurvenetAdjustment` prim (schema/README.md): one exposed knot of a
/// curvenet. Its animated values are read per frame with
/// `Stage::adjustments_at`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AdjustmentData {
    /// Composed prim path (a child of the curvenet prim).
    pub path: String,
    /// The curvenet prim it adjusts (its parent).
    pub curvenet: String,
    /// `curvenet:knot`: the knot's index in the curvenet's pool.
    pub knot: u32,
    /// `curvenet:attachTangents` (true when not authored).
    pub attach_tangents: bool,
    /// The knot's tangent control points (pool indices, increasing): the
    /// order of `curvenet:tangentTranslates`.
    pub tangents: Vec<u32>,
    /// Which rotate attribute is authored: `xformOp:rotateXYZ`,
    /// `xformOp:orient`, or neither.
    pub rotate: Option<String>,
    /// The authored attributes among `xformOp:translate`, the rotate,
    /// `xformOp:scale`, `curvenet:tangentTranslates`, with their time-sample
    /// times (empty: a static value).
    pub attributes: Vec<(String, Vec<f64>)>,
}

/// The one conversion from stage data to core's deformer input: the mesh in
/// its projection pose and its curvenets, with no blend shapes, no rig and
/// default options (add those with struct update syntax:
/// `DeformerInput { blend_shapes, ..deformer_input(&mesh, &curvenets) }`).
/// `curvenets` are [`CurvenetData::input`]s, in the mesh's order.
pub fn deformer_input<'a>(
    mesh: &'a MeshData,
    curvenets: &'a [curvenet_core::CurvenetInput<'a>],
) -> curvenet_core::DeformerInput<'a> {
    curvenet_core::DeformerInput {
        mesh: mesh.input(),
        curvenets,
        blend_shapes: Vec::new(),
        skinning: None,
        cage: None,
        options: Default::default(),
    }
}

impl MeshData {
    /// The mesh as core takes it: its faces and its projection pose.
    pub fn input(&self) -> curvenet_core::MeshInput<'_> {
        curvenet_core::MeshInput {
            face_vertex_counts: &self.face_vertex_counts,
            face_vertex_indices: &self.face_vertex_indices,
            projection_points: &self.projection_points,
        }
    }
}

impl CurvenetData {
    /// The curvenet as core takes it: splines, neutral pool, sampling density.
    pub fn input(&self) -> curvenet_core::CurvenetInput<'_> {
        curvenet_core::CurvenetInput { splines: &self.splines, pool: &self.pool, sample_density: self.sample_density }
    }
}
