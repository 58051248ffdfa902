//! The cage rows of `curvenet bench` (issue #18): the per-frame cost of the
//! coupled cage's stages (CageRev, SkelUp, CageUp), which should not grow
//! with the mesh, beside the two that touch every vertex (`Φ·C` and
//! skinning), on every benched hand with the SAME cage, skeleton and
//! animation: those of `fixtures/shots/hand_caged` (a 170-vertex cage around
//! the hand, the rigged hand's 8 joints, frames 1–10 editing the rest cage,
//! posing the skeleton and editing the posed cage). The shot's skin weights
//! are authored on the 1.4k hand; each benched hand takes them from its
//! closest point on that surface. The skin is linear blend here (the shot
//! asks for centres of rotation, whose precomputation is not a per-frame
//! cost and grows with the mesh).

use std::path::Path;
use std::time::{Duration, Instant};

use curvenet_core::{CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
use curvenet_core::{ClosestPointBvh, PolyMesh};
use curvenet_core::{Influences, MAT4_IDENTITY, Skeleton, Skin, SkinningMethod, SurfaceWeights};
use curvenet_schema::usd::Stage;
use serde::Serialize;

use crate::cli::{CliError, CliResult};

/// The shot whose cage, skeleton and frames every row uses.
const SHOT: &str = "shots/hand_caged/shot.usda";

/// One benched hand with the shot's cage.
#[derive(Serialize)]
pub struct CageBench {
    pub mesh: String,
    pub vertices: usize,
    pub cage_vertices: usize,
    pub joints: usize,
    /// `Φ`, MaxVol and the coupling (`CoupledRig::new`).
    pub build_ms: f64,
    pub phi_bytes: usize,
    /// Condition number of the MaxVol square system.
    pub condition: f64,
    /// Medians over the shot's frames, ms.
    pub cage_rev_ms: f64,
    pub skel_up_ms: f64,
    pub cage_up_ms: f64,
    /// `M = base + Φ(C − C₀)`: grows with the mesh.
    pub phi_c_ms: f64,
    pub skinning_ms: f64,
}

fn core(context: &str) -> impl FnOnce(curvenet_core::Error) -> CliError + '_ {
    move |source| CliError::Core { context: context.to_string(), source }
}

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v.get(v.len() / 2).map_or(0.0, |d| d.as_secs_f64() * 1e3)
}

/// The cage rows of the hands `meshes` (name, fixture file), `repeats`
/// passes over the shot's frames each.
pub fn bench_cage(fixtures: &Path, meshes: &[(&str, &Path)], repeats: usize) -> CliResult<Vec<CageBench>> {
    let shot = Stage::open(fixtures.join(SHOT))?;
    let hand = shot.deformed_meshes()?.into_iter().next().ok_or_else(|| CliError::Input(format!("{SHOT}: no mesh")))?;
    let cage = shot.cage(&hand)?.ok_or_else(|| CliError::Input(format!("{SHOT}: {} has no cage", hand.path)))?;
    let rig = shot.skin_rig(&hand)?.ok_or_else(|| CliError::Input(format!("{SHOT}: {} has no skin", hand.path)))?;
    let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).map_err(core(&rig.skeleton))?;
    let n0 = hand.projection_points.len();
    let mut weights0 = Influences::new(n0, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len())
        .map_err(core(&hand.path))?;
    weights0.renormalize(1e-4);
    let topo0 = PolyMesh::new(&hand.face_vertex_counts, &hand.face_vertex_indices, n0).map_err(core(&hand.path))?;
    let bvh0 = ClosestPointBvh::new(&topo0, &hand.projection_points).map_err(core(&hand.path))?;
    let surface0 = SurfaceWeights::new(&bvh0, &weights0).map_err(core(&hand.path))?;
    // The shot's frames: rest-cage edits, joint transforms, posed-cage offsets.
    let times = cage.sample_times();
    let transforms = times
        .iter()
        .map(|&t| {
            let local = shot.joint_local_transforms(&rig, Some(t))?;
            let mut out = vec![MAT4_IDENTITY; local.len()];
            skeleton.skinning_transforms(&local, &mut out).map_err(core(&rig.skeleton))?;
            Ok(out)
        })
        .collect::<CliResult<Vec<_>>>()?;
    let mut rows = Vec::new();
    for (name, file) in meshes {
        let stage = Stage::open(file)?;
        let mesh =
            stage.deformed_meshes()?.into_iter().next().ok_or_else(|| CliError::Input(format!("{name}: no mesh")))?;
        let n = mesh.projection_points.len();
        // The shot's weights at each vertex's closest point on the 1.4k hand.
        let mut per_point = Vec::with_capacity(n);
        let mut w = Vec::new();
        for p in &mesh.projection_points {
            surface0.at(*p, &mut w).map_err(core(name))?;
            per_point.push(w.clone());
        }
        let size = per_point.iter().map(Vec::len).max().unwrap_or(1).max(1);
        let (mut indices, mut values) = (Vec::with_capacity(n * size), Vec::with_capacity(n * size));
        for influences in &per_point {
            for k in 0..size {
                let (j, x) = influences.get(k).copied().unwrap_or((0, 0.0));
                indices.push(j as i64);
                values.push(x);
            }
        }
        let influences = Influences::new(n, size, &indices, &values, rig.joints.len()).map_err(core(name))?;
        let skin = Skin::new(influences, rig.geom_bind_transform, SkinningMethod::ClassicLinear).map_err(core(name))?;
        let topo = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n).map_err(core(name))?;
        let t0 = Instant::now();
        let coupled = CoupledRig::new(
            &cage.rest_points,
            &cage.triangles,
            &mesh.projection_points,
            &fan_triangles(&topo),
            Some((&skeleton, &skin)),
            CageRevApproximation::default(),
        )
        .map_err(core(name))?;
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        let mut ws = CoupledWorkspace::default();
        let mut out = vec![[0.0; 3]; n];
        let (mut rev, mut up, mut cu, mut phi, mut sk) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..repeats.max(1) {
            for (&t, xf) in times.iter().zip(&transforms) {
                let edits = cage.frame(Some(t));
                let frame = CageFrame {
                    base: None,
                    rest_cage: edits.rest_cage(),
                    joint_transforms: Some(xf),
                    posed_cage_offsets: edits.posed_cage_offsets(),
                };
                coupled.evaluate(&frame, &mut ws, &mut out).map_err(core(name))?;
                let s = ws.timings();
                rev.push(s.cage_rev);
                up.push(s.skel_up);
                cu.push(s.cage_up);
                phi.push(s.cage_to_mesh);
                sk.push(s.skinning);
            }
        }
        rows.push(CageBench {
            mesh: name.to_string(),
            vertices: n,
            cage_vertices: coupled.n_cage_vertices(),
            joints: coupled.n_joints(),
            build_ms,
            phi_bytes: coupled.phi_bytes(),
            condition: coupled.condition(),
            cage_rev_ms: median(rev),
            skel_up_ms: median(up),
            cage_up_ms: median(cu),
            phi_c_ms: median(phi),
            skinning_ms: median(sk),
        });
    }
    Ok(rows)
}

/// The rows as the text report prints them.
pub fn text(rows: &[CageBench]) -> String {
    let mut s = String::from(
        "\nCoupled cage (fixtures/shots/hand_caged's cage, skeleton and frames on every hand; ms, medians per frame)\n\
         mesh        vertices  cage  joints   build  Φ MB  condition   CageRev    SkelUp    CageUp  |     Φ·C  skinning\n",
    );
    for r in rows {
        s += &format!(
            "{:<10} {:>9} {:>5} {:>7} {:>7.0} {:>5.0} {:>10.3e} {:>9.3} {:>9.4} {:>9.3}  | {:>7.2} {:>9.2}\n",
            r.mesh,
            r.vertices,
            r.cage_vertices,
            r.joints,
            r.build_ms,
            r.phi_bytes as f64 / 1e6,
            r.condition,
            r.cage_rev_ms,
            r.skel_up_ms,
            r.cage_up_ms,
            r.phi_c_ms,
            r.skinning_ms
        );
    }
    s
}
