//! The rig under the curvenets, built in one place: the mesh's UsdSkel skin
//! (influences, `geomBindTransform`, method), the skeleton a coupled cage
//! relocates, and the spline skinning (Liu et al. 2015) of each curvenet that
//! follows the skeleton, with its weights authored per control point or
//! derived from the mesh's. The bake and `inspect` (from USD, `cli/rig.rs`)
//! and the service (from a binding request's `skin`, `builder.rs`) fill a
//! [`RigInput`] with their arrays and get the same [`Rig`] for the same
//! numbers; a [`RigError`] says which part refused, so each caller names it
//! in its own terms (a prim path and attribute, or a request field).

use std::time::Instant;

use crate::closest_point::ClosestPointBvh;
use crate::error::Error;
use crate::mesh::PolyMesh;
use crate::skinning::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, Influences, Mat4, Skeleton, Skin, SkinningMethod, SplineSkinning,
    SplineSkinningOptions, SurfaceWeights,
};

/// Skin weights of a point that sum to 1 within this are rescaled to sum to
/// 1 exactly (float rounding); others are skinned as authored (and listed in
/// [`RigReport::unnormalized`]).
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-4;

/// The rig under the curvenets ([`crate::skinning`], UsdSkel's semantics):
/// the mesh's skin, whose skinning of the mesh's points is a frame's rest
/// pose, and the spline skinning (Liu et al. 2015) of the curvenets that
/// follow the skeleton.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Rig {
    /// The mesh's influences, `geomBindTransform` and skinning method.
    pub skin: Skin,
    /// One entry per curvenet (the order of [`crate::DeformerInput::curvenets`]):
    /// its spline skinning, `None` for a curvenet that does not follow the
    /// skeleton (it takes the frame's posed pool, else tracks the rest pose).
    pub curvenets: Vec<Option<SplineSkinning>>,
    /// Up to this many G¹-flexible iterations per spline-skinned pose
    /// ([`SplineSkinning::pose_flexible`]); 0: the fixed-ratio fit
    /// ([`SplineSkinning::pose`]).
    pub flexible_iterations: usize,
    /// The skeleton (hierarchy and bind transforms), which a cage coupled
    /// with the rig needs to relocate the joints (SkelUp); `None` for a rig
    /// without a cage.
    pub skeleton: Option<Skeleton>,
}

/// UsdSkel joint influences as authored: `element_size` (joint, weight)
/// pairs per point, point after point.
#[derive(Debug, Clone, Copy)]
pub struct InfluenceArrays<'a> {
    pub element_size: usize,
    pub joint_indices: &'a [i64],
    pub joint_weights: &'a [f64],
}

/// How one curvenet follows the skeleton.
#[derive(Debug, Clone, Copy)]
pub enum NetSkinning<'a> {
    /// It does not: it takes a frame's posed pool, else tracks the rest pose.
    None,
    /// Spline skinning with weights authored per control point.
    Weights(InfluenceArrays<'a>),
    /// Spline skinning with per-control-point weights fitted to the mesh's
    /// skin weights at samples of the curves ([`ControlPointWeights::from_surface`]).
    FromMesh,
}

/// One curvenet of a [`RigInput`]: its control points, splines and skinning.
#[derive(Debug, Clone, Copy)]
pub struct RigCurvenet<'a> {
    pub pool: &'a [[f64; 3]],
    pub splines: &'a [[u32; 4]],
    pub skinning: NetSkinning<'a>,
}

/// Everything a [`Rig`] is built from, as plain arrays.
#[derive(Debug, Clone)]
pub struct RigInput<'a> {
    /// The mesh (its projection pose), for the count of influenced points and
    /// for weights derived from the mesh ([`NetSkinning::FromMesh`]).
    pub face_vertex_counts: &'a [u32],
    pub face_vertex_indices: &'a [u32],
    pub projection_points: &'a [[f64; 3]],
    /// The mesh's influences, over `n_joints` joints.
    pub influences: InfluenceArrays<'a>,
    pub n_joints: usize,
    pub geom_bind_transform: Mat4,
    pub method: SkinningMethod,
    /// The skeleton's parents (`None` for a root) and bind transforms, for a
    /// cage coupled with the rig; `None` when there is none.
    pub skeleton: Option<(&'a [Option<u32>], &'a [Mat4])>,
    /// One entry per curvenet, in binding order.
    pub curvenets: Vec<RigCurvenet<'a>>,
    /// [`Rig::flexible_iterations`].
    pub flexible_iterations: usize,
}

/// What building a rig found besides the rig.
#[derive(Debug, Clone, Default)]
pub struct RigReport {
    /// Mesh points whose weights do not sum to 1 within
    /// [`WEIGHT_SUM_TOLERANCE`] (skinned as authored).
    pub unnormalized: Vec<usize>,
    /// Per curvenet: for weights derived from the mesh, the largest
    /// difference between the fitted per-control-point weights and the
    /// mesh's own at samples of the curves.
    pub weight_deviation: Vec<Option<f64>>,
    /// Wall time of the spline skinning precomputation (all curvenets).
    pub spline_ms: f64,
}

/// The part of a [`RigInput`] that was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigPart {
    /// The skeleton's parents or bind transforms.
    Skeleton,
    /// The mesh's influences.
    Influences,
    /// The mesh's topology or projection points (for derived weights).
    Mesh,
    /// Curvenet `k`'s authored per-control-point influences.
    CurvenetWeights(usize),
    /// Curvenet `k`'s spline skinning (its curves, or weights derived from the mesh).
    CurvenetSkinning(usize),
    /// The skin (its `geomBindTransform` or method).
    Skin,
}

/// Why a rig could not be built: the part, and core's error naming the element.
#[derive(Debug, Clone, PartialEq)]
pub struct RigError {
    pub part: RigPart,
    pub source: Error,
}

impl Rig {
    /// Builds the rig of `input`: the skeleton, the mesh's influences
    /// (renormalised within [`WEIGHT_SUM_TOLERANCE`]), each curvenet's spline
    /// skinning, then the skin.
    pub fn build(input: &RigInput<'_>) -> Result<(Rig, RigReport), RigError> {
        let at = |part: RigPart| move |source: Error| RigError { part, source };
        let skeleton = match input.skeleton {
            None => None,
            Some((parents, binds)) => Some(Skeleton::new(parents, binds).map_err(at(RigPart::Skeleton))?),
        };
        let n = input.projection_points.len();
        let inf = input.influences;
        let mut influences = Influences::new(n, inf.element_size, inf.joint_indices, inf.joint_weights, input.n_joints)
            .map_err(at(RigPart::Influences))?;
        let unnormalized = influences.renormalize(WEIGHT_SUM_TOLERANCE);
        let t0 = Instant::now();
        let options = SplineSkinningOptions::default();
        let geom_bind = &input.geom_bind_transform;
        let mut surface: Option<ClosestPointBvh> = None;
        let mut splines = Vec::with_capacity(input.curvenets.len());
        let mut weight_deviation = Vec::with_capacity(input.curvenets.len());
        for (k, net) in input.curvenets.iter().enumerate() {
            let (field, deviation) = match net.skinning {
                NetSkinning::None => {
                    splines.push(None);
                    weight_deviation.push(None);
                    continue;
                }
                NetSkinning::Weights(w) => {
                    let cp = Influences::new(
                        net.pool.len(),
                        w.element_size,
                        w.joint_indices,
                        w.joint_weights,
                        input.n_joints,
                    )
                    .map_err(at(RigPart::CurvenetWeights(k)))?;
                    (ControlPointWeights::new(cp), None)
                }
                NetSkinning::FromMesh => {
                    let bvh = match &mut surface {
                        Some(bvh) => bvh,
                        slot @ None => {
                            let topo = PolyMesh::new(input.face_vertex_counts, input.face_vertex_indices, n)
                                .map_err(at(RigPart::Mesh))?;
                            slot.insert(
                                ClosestPointBvh::new(&topo, input.projection_points).map_err(at(RigPart::Mesh))?,
                            )
                        }
                    };
                    let mesh_weights =
                        SurfaceWeights::new(bvh, &influences).map_err(at(RigPart::CurvenetSkinning(k)))?;
                    let (field, deviation) =
                        ControlPointWeights::from_surface(net.pool, net.splines, &mesh_weights, DERIVED_WEIGHT_SAMPLES)
                            .map_err(at(RigPart::CurvenetSkinning(k)))?;
                    (field, Some(deviation))
                }
            };
            let spline = SplineSkinning::new(net.pool, net.splines, &field, geom_bind, &options)
                .map_err(at(RigPart::CurvenetSkinning(k)))?;
            splines.push(Some(spline));
            weight_deviation.push(deviation);
        }
        let spline_ms = t0.elapsed().as_secs_f64() * 1e3;
        let skin = Skin::new(influences, input.geom_bind_transform, input.method).map_err(at(RigPart::Skin))?;
        let rig = Rig { skin, curvenets: splines, flexible_iterations: input.flexible_iterations, skeleton };
        Ok((rig, RigReport { unnormalized, weight_deviation, spline_ms }))
    }
}
