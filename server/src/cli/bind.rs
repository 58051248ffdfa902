//! A mesh's deformer from what a stage read gives (`curvenet bake`,
//! `inspect --bind`): its blend shapes, rig and cage as core's
//! `DeformerInput`, built by `Deformer::new`, or read from a binding store
//! (`bake --store`, cli/store.rs).

use super::store;
use super::{CliError, CliResult, net_list};

/// The deformer of `mesh` (its projection pose, its blend shapes) and its
/// curvenets, as the bake and `inspect --bind` build it: through
/// [`curvenet_core::Deformer::new`], each curvenet sampled at its own density
/// against the mesh's surface, then one binding over all of them; `skinning`
/// is the rig underneath when the mesh is skinned in process
/// ([`rig::MeshRig`]). Errors name the blend shape, the curvenet or the mesh.
pub fn deformer(
    mesh: &curvenet_schema::MeshData,
    nets: &[curvenet_schema::CurvenetData],
    skinning: Option<curvenet_core::Rig>,
    cage: Option<&curvenet_schema::CageData>,
) -> CliResult<curvenet_core::Deformer> {
    deformer_in(None, mesh, nets, skinning, cage).map(|(d, _)| d)
}

/// [`deformer`], read from `store` when it holds it (and written to it
/// when built): `bake --store`.
pub fn deformer_in(
    store: Option<&store::BakeStore>,
    mesh: &curvenet_schema::MeshData,
    nets: &[curvenet_schema::CurvenetData],
    skinning: Option<curvenet_core::Rig>,
    cage: Option<&curvenet_schema::CageData>,
) -> CliResult<(curvenet_core::Deformer, store::Source)> {
    use curvenet_core::BlendShape;
    use curvenet_core::{CurvenetInput, Deformer, DeformerInput};
    use curvenet_schema::CurvenetData;
    let n = mesh.projection_points.len();
    let blend_shapes = mesh
        .blend_shapes
        .iter()
        .map(|s| {
            let inbetweens = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
            BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), inbetweens)
                .map_err(|source| CliError::Core { context: s.prim.clone(), source })
        })
        .collect::<CliResult<Vec<_>>>()?;
    let curvenets: Vec<CurvenetInput> = nets.iter().map(CurvenetData::input).collect();
    let cage = cage.map(|c| curvenet_core::CageInput { points: &c.rest_points, triangles: &c.triangles });
    let input = DeformerInput { blend_shapes, skinning, cage, ..curvenet_schema::deformer_input(mesh, &curvenets) };
    let build = || {
        Deformer::new(&input).map_err(|e| match e {
            curvenet_core::Error::Curvenet { curvenet, source } => CliError::Core {
                context: format!("{} (bound to {})", nets[curvenet as usize].path, mesh.path),
                source: *source,
            },
            source => CliError::Core { context: format!("{} (binding {})", mesh.path, net_list(nets)), source },
        })
    };
    match store {
        None => build().map(|d| (d, store::Source::Built)),
        Some(s) => s.deformer(&input, &mesh.path, build),
    }
}
