//! The rig under the curvenets of one mesh, as the bake and `inspect` read
//! it: the mesh's UsdSkel skin and the spline skinning of the curvenets that
//! ask for it, built into a [`curvenet_core::Rig`] that
//! [`curvenet_core::Deformer`] runs per frame (the skinned rest pose, the
//! spline-skinned posed pools).
//!
//! Per frame the stage gives joint-local transforms
//! ([`JointReader::read_transforms`], on the stage's thread); everything else
//! is core math inside `Deformer::frame`, safe to run on any thread.

use curvenet_core::Rig;
use curvenet_core::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, Influences, MAT4_IDENTITY, Mat4, Skeleton, Skin, SkinningMethod,
    SplineSkinning, SplineSkinningOptions, SurfaceWeights, mat4_mul,
};

use curvenet_core::{ClosestPointBvh, PolyMesh};
use curvenet_schema::usd::{CurvenetSkinning, CurvenetSkinningMethod, SkinRig, Stage};
use curvenet_schema::{CurvenetData, MeshData};

use super::{CliError, CliResult};

/// Skin weights of a point that sum to 1 within this are rescaled to sum
/// to 1 exactly (float rounding); others are skinned as authored, with a warning.
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-4;

/// How one curvenet of the mesh follows the skeleton (its spline skinning
/// is the matching entry of [`Rig::curvenets`]).
pub struct NetRig {
    /// `"weights"` (authored per control point) or `"mesh"` (from the mesh's skin weights).
    pub mode: &'static str,
    /// `mesh`: the largest difference between the per-control-point weights
    /// derived from the mesh's and the mesh's own, at samples of the curves.
    pub weight_deviation: Option<f64>,
}

/// What reads a frame's skinning transforms from the stage: the UsdSkel
/// binding and the Skeleton's topology and bind transforms.
pub struct JointReader {
    pub rig: SkinRig,
    pub skeleton: Skeleton,
}

/// A mesh's UsdSkel rig, ready for a [`curvenet_core::Deformer`].
pub struct MeshRig {
    pub joints: JointReader,
    /// The skin and the curvenets' spline skinning, for `DeformerInput::skinning`.
    pub skinning: Rig,
    /// Mesh points whose weights do not sum to 1 (skinned as authored).
    pub unnormalized: Vec<usize>,
    /// One entry per curvenet of the mesh, in binding order.
    pub nets: Vec<Option<NetRig>>,
    /// Wall time of the spline skinning precomputation (all curvenets).
    pub spline_ms: f64,
}

fn core(context: String) -> impl FnOnce(curvenet_core::Error) -> CliError {
    move |source| CliError::Core { context, source }
}

impl MeshRig {
    /// The rig of `mesh` and its curvenets `nets`, or `None` when the mesh
    /// has no UsdSkel joint influences; spline-skinned poses take up to
    /// `flexible` G¹-flexible iterations (0: the fixed-ratio fit). A
    /// curvenet that asks for spline skinning on a mesh without a rig is
    /// bad input.
    pub fn new(stage: &Stage, mesh: &MeshData, nets: &[CurvenetData], flexible: usize) -> CliResult<Option<Self>> {
        let modes = nets.iter().map(|n| stage.curvenet_skinning(n)).collect::<Result<Vec<_>, _>>()?;
        let Some(rig) = stage.skin_rig(mesh)? else {
            if let Some((net, _)) = nets.iter().zip(&modes).find(|(_, m)| **m != CurvenetSkinning::None) {
                return Err(CliError::Input(format!(
                    "{}: asks for spline skinning, but the mesh it deforms, {}, has no UsdSkel skin \
                     (primvars:skel:jointIndices)",
                    net.path, mesh.path
                )));
            }
            return Ok(None);
        };
        let n_joints = rig.joints.len();
        let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).map_err(core(rig.skeleton.clone()))?;
        let n = mesh.projection_points.len();
        let mut influences = Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, n_joints)
            .map_err(core(format!("{} (primvars:skel:jointIndices, jointWeights)", mesh.path)))?;
        let unnormalized = influences.renormalize(WEIGHT_SUM_TOLERANCE);
        let t0 = std::time::Instant::now();
        let mut surface: Option<ClosestPointBvh> = None;
        let mut net_rigs = Vec::with_capacity(nets.len());
        let mut splines = Vec::with_capacity(nets.len());
        for (net, mode) in nets.iter().zip(modes) {
            let context = || format!("{} (spline skinning over {})", net.path, mesh.path);
            let options = SplineSkinningOptions::default();
            let (spline, net_rig) = match mode {
                CurvenetSkinning::None => (None, None),
                CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                    let cp = Influences::new(net.pool.len(), element_size, &joint_indices, &joint_weights, n_joints)
                        .map_err(core(format!("{} (primvars:curvenet:skel:jointIndices, jointWeights)", net.path)))?;
                    let field = ControlPointWeights::new(cp);
                    let spline =
                        SplineSkinning::new(&net.pool, &net.splines, &field, &rig.geom_bind_transform, &options)
                            .map_err(core(context()))?;
                    (Some(spline), Some(NetRig { mode: "weights", weight_deviation: None }))
                }
                CurvenetSkinning::FromMesh => {
                    if surface.is_none() {
                        let topo = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n)
                            .map_err(core(mesh.path.clone()))?;
                        surface = Some(
                            ClosestPointBvh::new(&topo, &mesh.projection_points).map_err(core(mesh.path.clone()))?,
                        );
                    }
                    let mesh_weights =
                        SurfaceWeights::new(surface.as_ref().expect("built"), &influences).map_err(core(context()))?;
                    let (field, deviation) = ControlPointWeights::from_surface(
                        &net.pool,
                        &net.splines,
                        &mesh_weights,
                        DERIVED_WEIGHT_SAMPLES,
                    )
                    .map_err(core(context()))?;
                    let spline =
                        SplineSkinning::new(&net.pool, &net.splines, &field, &rig.geom_bind_transform, &options)
                            .map_err(core(context()))?;
                    (Some(spline), Some(NetRig { mode: "mesh", weight_deviation: Some(deviation) }))
                }
            };
            splines.push(spline);
            net_rigs.push(net_rig);
        }
        let spline_ms = t0.elapsed().as_secs_f64() * 1e3;
        // `curvenet:skinningMethod` (schema/README.md) overrides UsdSkel's token:
        // it can name centres of rotation, which UsdSkel's tokens cannot.
        let method = match rig.curvenet_method {
            None => rig.method,
            Some(CurvenetSkinningMethod::ClassicLinear) => SkinningMethod::ClassicLinear,
            Some(CurvenetSkinningMethod::DualQuaternion) => SkinningMethod::DualQuaternion,
            Some(CurvenetSkinningMethod::CentersOfRotation) => SkinningMethod::CentersOfRotation,
        };
        let skin = Skin::new(influences, rig.geom_bind_transform, method).map_err(core(mesh.path.clone()))?;
        Ok(Some(Self {
            // The skeleton goes with the rig: a cage coupled with it relocates the joints (SkelUp).
            skinning: Rig { skin, curvenets: splines, flexible_iterations: flexible, skeleton: Some(skeleton.clone()) },
            joints: JointReader { rig, skeleton },
            unnormalized,
            nets: net_rigs,
            spline_ms,
        }))
    }
}

impl JointReader {
    /// The skinning transforms at `time` (one per Skeleton joint), with the
    /// Skeleton-to-mesh transform folded in so that skinned points come out
    /// in the mesh's space: [`curvenet_core::Frame::joint_transforms`].
    /// Reads the stage.
    pub fn read_transforms(&self, stage: &Stage, time: Option<f64>) -> CliResult<Vec<Mat4>> {
        let local = stage.joint_local_transforms(&self.rig, time)?;
        let mut out = vec![MAT4_IDENTITY; local.len()];
        self.skeleton.skinning_transforms(&local, &mut out).map_err(core(self.rig.skeleton.clone()))?;
        let to_mesh = stage.skel_to_mesh_transform(&self.rig, time)?;
        if to_mesh != MAT4_IDENTITY {
            for m in &mut out {
                *m = mat4_mul(m, &to_mesh);
            }
        }
        Ok(out)
    }
}
