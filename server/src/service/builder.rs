//! `BindingRequest` (checked by request.rs) → plain data (`curvenet_core::DeformerInput`)
//! → `curvenet_core::Deformer::new`, the one way a binding is made.
//! Everything cheap is checked before the expensive steps (the curvenet
//! analysis, the cut and the factorisation); every message names the array
//! and index it refers to, and the details name them by field.

use curvenet_core::BlendShape;
use curvenet_core::{Binding, Cancel, CurvenetInput, Deformer, DeformerInput, DeformerOptions, PolyMesh};
use curvenet_core::{CageInput, Rig};
use curvenet_core::{ClosestPointBvh, MAT4_IDENTITY};
use curvenet_core::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, Influences, Skeleton, Skin, SkinningMethod, SplineSkinning,
    SplineSkinningOptions, SurfaceWeights,
};
use curvenet_schema::wire::{
    BindingRequest, BindingResponse, BindingStats, BindingTimings, CageStats, CurvenetSkinSpec, SkinMethod, SkinSpec,
    Warning,
};

use crate::cache::{Entry, Key, hex};
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
    // Measured on the shapes as built here: the deformer keeps copies of
    // them, no larger (a copy's arrays have no spare capacity).
    let shapes_bytes = if n_shapes == 0 {
        0
    } else {
        blend_shapes.capacity() * std::mem::size_of::<BlendShape>()
            + blend_shapes.iter().map(BlendShape::heap_bytes).sum::<usize>()
    };
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

    // What the entry holds, measured (see `curvenet_core::heap`): the
    // binding, the shapes, the projection pose, the workspaces frames
    // reuse (one per solve thread; the first is made now and measured),
    // the group workspaces batches keep (one per solve thread; see
    // `cache::Entry::size_bytes`) and the factor's row copy the first batch
    // makes.
    let b = deformer.binding();
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
        + n * std::mem::size_of::<[f64; 3]>()
        + keep * workspace_bytes
        + keep * deformer.group_bytes(crate::config::BATCH_FRAMES, workspace_bytes)
        + b.factor_row_copy_bytes()
        + ENTRY_OVERHEAD) as u64
        + cage.as_ref().map_or(0, |c| c.phi_bytes);
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

/// Skin weights of a point that sum to 1 within this are rescaled to sum to
/// 1 exactly (float rounding), as `curvenet bake` does (cli/rig.rs).
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-4;

/// The rig of `req` (its `skin`): the mesh's influences and skin, and the
/// spline skinning of the curvenets that ask for it, as `curvenet bake`
/// builds them from UsdSkel (cli/rig.rs). Errors name the field.
fn build_rig(req: &BindingRequest, skin: &SkinSpec) -> Result<Rig, ServiceError> {
    let bind = |what: String| move |e: curvenet_core::Error| ServiceError::core(e, Phase::Bind).context(&what);
    let n = req.projection_points.len();
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
    let mut influences =
        Influences::new(n, skin.element_size as usize, &skin.joint_indices, &skin.joint_weights, n_joints)
            .map_err(bind("skin".into()))?;
    influences.renormalize(WEIGHT_SUM_TOLERANCE);
    let geom_bind = skin.geom_bind_transform.unwrap_or(MAT4_IDENTITY);
    let options = SplineSkinningOptions::default();
    let mut surface: Option<ClosestPointBvh> = None;
    let mut splines = Vec::with_capacity(req.curvenets.len());
    for (k, net) in req.curvenets.iter().enumerate() {
        let context = format!("skin.curvenets[{k}]");
        let field = match skin.curvenets.get(k) {
            None | Some(CurvenetSkinSpec::None) => {
                splines.push(None);
                continue;
            }
            Some(CurvenetSkinSpec::Weights { element_size, joint_indices, joint_weights }) => {
                let cp =
                    Influences::new(net.pool.len(), *element_size as usize, joint_indices, joint_weights, n_joints)
                        .map_err(bind(context.clone()))?;
                ControlPointWeights::new(cp)
            }
            Some(CurvenetSkinSpec::Mesh) => {
                if surface.is_none() {
                    let topo = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, n)
                        .map_err(bind("mesh".into()))?;
                    surface = Some(ClosestPointBvh::new(&topo, &req.projection_points).map_err(bind("mesh".into()))?);
                }
                let Some(bvh) = surface.as_ref() else {
                    return Err(ServiceError::internal("the surface of the mesh was not built"));
                };
                let weights = SurfaceWeights::new(bvh, &influences).map_err(bind(context.clone()))?;
                ControlPointWeights::from_surface(&net.pool, &net.splines, &weights, DERIVED_WEIGHT_SAMPLES)
                    .map_err(bind(context.clone()))?
                    .0
            }
        };
        let spline = SplineSkinning::new(&net.pool, &net.splines, &field, &geom_bind, &options)
            .map_err(bind(context.clone()))?;
        splines.push(Some(spline));
    }
    let method = match skin.method {
        SkinMethod::ClassicLinear => SkinningMethod::ClassicLinear,
        SkinMethod::DualQuaternion => SkinningMethod::DualQuaternion,
        SkinMethod::CentersOfRotation => SkinningMethod::CentersOfRotation,
    };
    let skeleton = match &skin.skeleton {
        None => None,
        Some(s) => {
            let parents: Vec<Option<u32>> = s.parents.iter().map(|&p| u32::try_from(p).ok()).collect();
            Some(Skeleton::new(&parents, &s.bind_transforms).map_err(bind("skin.skeleton".into()))?)
        }
    };
    let skin_core = Skin::new(influences, geom_bind, method).map_err(bind("skin".into()))?;
    Ok(Rig { skin: skin_core, curvenets: splines, flexible_iterations: skin.flexible_iterations as usize, skeleton })
}

/// Bytes of an entry besides its measured arrays: the entry, its strings
/// and its response (warnings), rounded up.
const ENTRY_OVERHEAD: usize = 4096;
