//! The rig under the curvenets of one mesh, as the bake and `inspect` read
//! it: the mesh's UsdSkel skin and the spline skinning of the curvenets that
//! ask for it, read from the stage and built by [`curvenet_core::Rig::build`]
//! (the one place a rig is built; the service calls it too) into a rig that
//! [`curvenet_core::Deformer`] runs per frame (the skinned rest pose, the
//! spline-skinned posed pools).
//!
//! Per frame the stage gives joint-local transforms
//! ([`JointReader::read_transforms`], on the stage's thread); everything else
//! is core math inside `Deformer::frame`, safe to run on any thread.

use curvenet_core::{InfluenceArrays, NetSkinning, Rig, RigCurvenet, RigError, RigInput, RigPart};
use curvenet_core::{MAT4_IDENTITY, Mat4, Skeleton, SkinningMethod, mat4_mul};
use curvenet_schema::usd::{CurvenetSkinning, CurvenetSkinningMethod, SkinRig, Stage};
use curvenet_schema::{CurvenetData, MeshData};

use super::{CliError, CliResult};

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
        let skinnings: Vec<NetSkinning<'_>> = modes
            .iter()
            .map(|mode| match mode {
                CurvenetSkinning::None => NetSkinning::None,
                CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                    NetSkinning::Weights(InfluenceArrays { element_size: *element_size, joint_indices, joint_weights })
                }
                CurvenetSkinning::FromMesh => NetSkinning::FromMesh,
            })
            .collect();
        // `curvenet:skinningMethod` (schema/README.md) overrides UsdSkel's token:
        // it can name centres of rotation, which UsdSkel's tokens cannot.
        let method = match rig.curvenet_method {
            None => rig.method,
            Some(CurvenetSkinningMethod::ClassicLinear) => SkinningMethod::ClassicLinear,
            Some(CurvenetSkinningMethod::DualQuaternion) => SkinningMethod::DualQuaternion,
            Some(CurvenetSkinningMethod::CentersOfRotation) => SkinningMethod::CentersOfRotation,
        };
        let input = RigInput {
            face_vertex_counts: &mesh.face_vertex_counts,
            face_vertex_indices: &mesh.face_vertex_indices,
            projection_points: &mesh.projection_points,
            influences: InfluenceArrays {
                element_size: rig.element_size,
                joint_indices: &rig.joint_indices,
                joint_weights: &rig.joint_weights,
            },
            n_joints: rig.joints.len(),
            geom_bind_transform: rig.geom_bind_transform,
            method,
            // The skeleton goes with the rig: a cage coupled with it relocates the joints (SkelUp).
            skeleton: Some((&rig.parents, &rig.bind_transforms)),
            curvenets: nets
                .iter()
                .zip(&skinnings)
                .map(|(net, &skinning)| RigCurvenet { pool: &net.pool, splines: &net.splines, skinning })
                .collect(),
            flexible_iterations: flexible,
        };
        let (skinning, report) = Rig::build(&input).map_err(|RigError { part, source }| {
            let context = match part {
                RigPart::Skeleton => rig.skeleton.clone(),
                RigPart::Influences => format!("{} (primvars:skel:jointIndices, jointWeights)", mesh.path),
                RigPart::Mesh | RigPart::Skin => mesh.path.clone(),
                RigPart::CurvenetWeights(k) => {
                    format!("{} (primvars:curvenet:skel:jointIndices, jointWeights)", nets[k].path)
                }
                RigPart::CurvenetSkinning(k) => format!("{} (spline skinning over {})", nets[k].path, mesh.path),
            };
            CliError::Core { context, source }
        })?;
        let skeleton =
            skinning.skeleton.clone().ok_or_else(|| CliError::Input(format!("{}: no skeleton", rig.skeleton)))?;
        let net_rigs = skinnings
            .iter()
            .zip(&report.weight_deviation)
            .map(|(s, &weight_deviation)| match s {
                NetSkinning::None => None,
                NetSkinning::Weights(_) => Some(NetRig { mode: "weights", weight_deviation: None }),
                NetSkinning::FromMesh => Some(NetRig { mode: "mesh", weight_deviation }),
            })
            .collect();
        Ok(Some(Self {
            skinning,
            joints: JointReader { rig, skeleton },
            unnormalized: report.unnormalized,
            nets: net_rigs,
            spline_ms: report.spline_ms,
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
