//! A mesh's cage (`rel curvenet:cage`) coupled with its skeleton as the bake
//! couples it: `Φ`, the MaxVol rows, their conditioning, and its line of the
//! text report.

use std::fmt::Write as _;

use curvenet_core::PolyMesh;
use curvenet_schema::MeshData;
use curvenet_schema::usd::Stage;
use serde::Serialize;

use crate::cli::rig::MeshRig;
use crate::cli::{CliError, CliResult};

/// A mesh's cage (`rel curvenet:cage`) as the bake couples it with the
/// mesh's skeleton: `Φ`, the MaxVol rows and their square system.
#[derive(Serialize)]
pub(super) struct CageReport {
    path: String,
    vertices: usize,
    triangles: usize,
    /// Coupled with the mesh's UsdSkel skeleton (else the cage alone deforms the mesh).
    coupled: bool,
    /// The mesh vertices whose rows of `Φ` form the square system CageUp solves.
    maxvol_rows: Vec<usize>,
    /// The 2-norm condition number of that square system.
    condition: f64,
    /// Memory of the mean value coordinates `Φ`.
    phi_bytes: usize,
    /// `max |M₀ − Φ C₀|` over the mesh's bind points (linear precision: rounding).
    bind_residual: f64,
    /// Time samples of the cage's `points` (rest-cage edits).
    rest_cage_frames: usize,
    /// Time samples of `primvars:curvenet:posedCageOffsets` (posed-cage edits).
    posed_offset_frames: usize,
    /// Wall time of `Φ`, MaxVol and the coupling's precomputation.
    precompute_ms: f64,
}

/// The cage of `m`, coupled as the bake couples it (`Deformer::new` does
/// the same precomputation); `None` when the mesh has no `rel curvenet:cage`.
pub(super) fn cage_report(stage: &Stage, m: &MeshData, rig: Option<&MeshRig>) -> CliResult<Option<CageReport>> {
    use curvenet_core::{CageRevApproximation, CoupledRig};
    let Some(cage) = stage.cage(m)? else { return Ok(None) };
    let start = std::time::Instant::now();
    let topo = PolyMesh::new(&m.face_vertex_counts, &m.face_vertex_indices, m.projection_points.len())
        .map_err(|source| CliError::Core { context: m.path.clone(), source })?;
    let triangles = curvenet_core::fan_triangles(&topo);
    let skinning = rig.map(|r| (&r.joints.skeleton, &r.skinning.skin));
    let coupled = CoupledRig::new(
        &cage.rest_points,
        &cage.triangles,
        &m.projection_points,
        &triangles,
        skinning,
        CageRevApproximation::default(),
    )
    .map_err(|source| CliError::Core { context: format!("{} (the cage of {})", cage.path, m.path), source })?;
    Ok(Some(CageReport {
        path: cage.path.clone(),
        vertices: coupled.n_cage_vertices(),
        triangles: coupled.n_cage_triangles(),
        coupled: rig.is_some(),
        maxvol_rows: coupled.maxvol_rows().to_vec(),
        condition: coupled.condition(),
        phi_bytes: coupled.phi_bytes(),
        bind_residual: coupled.max_bind_residual(),
        rest_cage_frames: cage.rest_samples.len(),
        posed_offset_frames: cage.posed_offset_samples.len(),
        precompute_ms: start.elapsed().as_secs_f64() * 1e3,
    }))
}

pub(super) fn cage_text(s: &mut String, c: &CageReport) {
    let _ = writeln!(
        s,
        "  cage: {} ({} vertices, {} triangles), {}; MaxVol rows: {} (condition {:.3e}); Φ {:.1} MB; bind \
         residual {:.2e}; rest-cage edits at {} frames, posed-cage edits at {} frames; precompute {:.0} ms",
        c.path,
        c.vertices,
        c.triangles,
        if c.coupled { "coupled with the skeleton (SkelUp, CageUp, CageRev)" } else { "alone (M = ΦC)" },
        c.maxvol_rows.len(),
        c.condition,
        c.phi_bytes as f64 / 1e6,
        c.bind_residual,
        c.rest_cage_frames,
        c.posed_offset_frames,
        c.precompute_ms
    );
}
