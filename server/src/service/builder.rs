//! `BindingRequest` (checked by request.rs) → plain data (`curvenet_core::DeformerInput`)
//! → `curvenet_core::Deformer::new`, the one way a binding is made.
//! Everything cheap is checked before the expensive steps (the curvenet
//! analysis, the cut and the factorisation); every message names the array
//! and index it refers to, and the details name them by field.

use curvenet_core::BlendShape;
use curvenet_core::{Binding, Cancel, CurvenetInput, Deformer, DeformerInput, DeformerOptions};
use curvenet_core::{CageInput, MAT4_IDENTITY, SkinningMethod};
use curvenet_core::{InfluenceArrays, NetSkinning, Rig, RigCurvenet, RigError, RigInput, RigPart};
use curvenet_schema::wire::{
    BindingRequest, BindingResponse, BindingStats, BindingTimings, CageStats, CurvenetSkinSpec, SkinMethod, SkinSpec,
    Warning,
};

use crate::entry::{Entry, Key, hex};
use crate::error::{Code, Phase, ServiceError};
use crate::request::EffectiveOptions;

/// Builds the entry for `req` (already validated): its blend shapes, then
/// the deformer (`curvenet_core::Deformer::new`: the curvenet analysis and
/// the binding). CPU-heavy: run it off the async runtime. `cancel` stops it
/// (`Error::Cancelled`, flagged on the returned error); `keep` workspaces
/// are budgeted in the entry's size (one per solve thread).
pub fn build(
    req: &BindingRequest,
    key: Key,
    topology: Key,
    options: EffectiveOptions,
    cancel: Cancel,
    keep: usize,
) -> Result<Entry, ServiceError> {
    let n = req.projection_points.len();
    // Blend shapes first: cheap, and a bad shape should not cost a factorisation.
    let blend_shapes = req
        .blend_shapes
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
            BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib)
                .map_err(|e| ServiceError::core(e, Phase::Bind).context(&format!("blend_shapes[{k}]")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n_shapes = blend_shapes.len();
    let rig = match &req.skin {
        Some(skin) => Some(build_rig(req, skin)?),
        None => None,
    };
    let curvenets: Vec<CurvenetInput<'_>> =
        req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
    let input = DeformerInput {
        mesh: req.mesh_input(),
        curvenets: &curvenets,
        blend_shapes,
        skinning: rig,
        cage: req.cage.as_ref().map(|c| CageInput { points: &c.points, triangles: &c.triangles }),
        options: DeformerOptions::default().with_bind(options.bind_options(cancel)),
    };
    let deformer = Deformer::new(&input).map_err(ServiceError::binding)?;
    drop(input);

    let (size_bytes, cage) = measure(&deformer, keep);
    let b = deformer.binding();
    let t = deformer.timings();
    let response = BindingResponse {
        binding_id: hex(&key),
        topology_hash: hex(&topology),
        cached: false,
        vertices: n,
        control_points: req.curvenets.iter().map(|c| c.pool.len()).collect(),
        blend_shapes: n_shapes,
        size_bytes,
        stats: BindingStats::from(&b.stats()),
        timings: BindingTimings::new(t.analysis_ms, &t.binding, t.total_ms),
        warnings: b.warnings().iter().map(Warning::from).collect(),
        cage,
    };
    Ok(Entry {
        id: response.binding_id.clone(),
        topology_hash: response.topology_hash.clone(),
        deformer,
        response,
        size_bytes,
    })
}

/// The bytes an entry of `deformer` holds (counted against the cache) and
/// its cage's description: the binding, the shapes, the projection pose,
/// the workspaces frames reuse (one per solve thread, `keep`; the first is
/// made now and measured), the group workspaces batches keep (one per
/// solve thread; see `entry::Entry::size_bytes`) and the factor's row copy
/// the first batch makes (see `curvenet_core::heap`). For a deformer just
/// built and for one read back from the store alike.
pub fn measure(deformer: &Deformer, keep: usize) -> (u64, Option<CageStats>) {
    let b = deformer.binding();
    let shapes = deformer.blend_shapes();
    let shapes_bytes = if shapes.is_empty() { 0 } else { shapes.heap_bytes() };
    let workspace_bytes = deformer.prepare_workspace();
    let keep = keep.max(1);
    // The cage's `Φ` (`#V × #C`) dominates a caged binding's memory.
    let cage = deformer.cage().map(|c| CageStats {
        vertices: c.n_cage_vertices(),
        triangles: c.n_cage_triangles(),
        maxvol_rows: c.maxvol_rows().len(),
        condition: c.condition(),
        phi_bytes: c.phi_bytes() as u64,
    });
    let size_bytes = (b.heap_bytes()
        + std::mem::size_of::<Binding>()
        + shapes_bytes
        + std::mem::size_of_val(deformer.projection_points())
        + keep * workspace_bytes
        + keep * deformer.group_bytes(crate::config::BATCH_FRAMES, workspace_bytes)
        + b.factor_row_copy_bytes()
        + ENTRY_OVERHEAD) as u64
        + cage.as_ref().map_or(0, |c| c.phi_bytes);
    (size_bytes, cage)
}

/// The rig of `req` (its `skin`): the mesh's influences and skin, and the
/// spline skinning of the curvenets that ask for it, built by
/// [`Rig::build`] as `curvenet bake` builds it from UsdSkel (cli/rig.rs).
/// Errors name the field.
fn build_rig(req: &BindingRequest, skin: &SkinSpec) -> Result<Rig, ServiceError> {
    let n_joints = skin.joints as usize;
    if !skin.curvenets.is_empty() && skin.curvenets.len() != req.curvenets.len() {
        return Err(ServiceError::new(
            Code::CountMismatch,
            format!(
                "skin.curvenets has {} entries, but there are {} curvenets (one each, or none)",
                skin.curvenets.len(),
                req.curvenets.len()
            ),
        )
        .detail(|d| {
            d.what = Some("skin.curvenets".into());
            d.expected = Some(req.curvenets.len());
            d.got = Some(skin.curvenets.len());
        }));
    }
    let method = match skin.method {
        SkinMethod::ClassicLinear => SkinningMethod::ClassicLinear,
        SkinMethod::DualQuaternion => SkinningMethod::DualQuaternion,
        SkinMethod::CentersOfRotation => SkinningMethod::CentersOfRotation,
    };
    let parents: Option<Vec<Option<u32>>> =
        skin.skeleton.as_ref().map(|s| s.parents.iter().map(|&p| u32::try_from(p).ok()).collect());
    let input = RigInput {
        face_vertex_counts: &req.face_vertex_counts,
        face_vertex_indices: &req.face_vertex_indices,
        projection_points: &req.projection_points,
        influences: InfluenceArrays {
            element_size: skin.element_size as usize,
            joint_indices: &skin.joint_indices,
            joint_weights: &skin.joint_weights,
        },
        n_joints,
        geom_bind_transform: skin.geom_bind_transform.unwrap_or(MAT4_IDENTITY),
        method,
        skeleton: skin.skeleton.as_ref().zip(parents.as_deref()).map(|(s, p)| (p, &s.bind_transforms[..])),
        curvenets: req
            .curvenets
            .iter()
            .enumerate()
            .map(|(k, net)| RigCurvenet {
                pool: &net.pool,
                splines: &net.splines,
                skinning: match skin.curvenets.get(k) {
                    None | Some(CurvenetSkinSpec::None) => NetSkinning::None,
                    Some(CurvenetSkinSpec::Weights { element_size, joint_indices, joint_weights }) => {
                        NetSkinning::Weights(InfluenceArrays {
                            element_size: *element_size as usize,
                            joint_indices,
                            joint_weights,
                        })
                    }
                    Some(CurvenetSkinSpec::Mesh) => NetSkinning::FromMesh,
                },
            })
            .collect(),
        flexible_iterations: skin.flexible_iterations as usize,
    };
    let (rig, _report) = Rig::build(&input).map_err(|RigError { part, source }| {
        let what = match part {
            RigPart::Skeleton => "skin.skeleton".to_string(),
            RigPart::Influences | RigPart::Skin => "skin".to_string(),
            RigPart::Mesh => "mesh".to_string(),
            RigPart::CurvenetWeights(k) | RigPart::CurvenetSkinning(k) => format!("skin.curvenets[{k}]"),
        };
        ServiceError::core(source, Phase::Bind).context(&what)
    })?;
    Ok(rig)
}

/// Bytes of an entry besides its measured arrays: the entry, its strings
/// and its response (warnings), rounded up.
const ENTRY_OVERHEAD: usize = 4096;
