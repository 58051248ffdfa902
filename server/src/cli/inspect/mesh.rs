//! One deformed mesh's report: its topology, poses, curvenets, blend shapes,
//! rig and cage (and, with `--bind`, its binding, filled in by the face), and
//! its lines of the text report.

use std::fmt::Write as _;

use curvenet_core::PolyMesh;
use curvenet_schema::MeshData;
use curvenet_schema::usd::Stage;
use serde::Serialize;

use super::binding::{BindingReport, binding_text};
use super::cage::{CageReport, cage_report, cage_text};
use super::rig::{RigReport, rig_report, rig_text};
use crate::cli::{CliError, CliResult};

#[derive(Serialize)]
pub(super) struct MeshReport {
    path: String,
    vertices: usize,
    faces: usize,
    face_sizes: FaceSizes,
    mean_edge_length: f64,
    bounding_box_diagonal: f64,
    rest_pose_frames: usize,
    curvenets: Vec<String>,
    blend_shapes: Vec<BlendShapeReport>,
    blend_shape_weights: Option<Vec<f64>>,
    /// The UsdSkel rig that skins the mesh in process, and the spline
    /// skinning of its curvenets.
    #[serde(skip_serializing_if = "Option::is_none")]
    rig: Option<RigReport>,
    /// The cage coupled with the skeleton (`rel curvenet:cage`, Corda et al. 2020).
    #[serde(skip_serializing_if = "Option::is_none")]
    cage: Option<CageReport>,
    /// With `--bind`: the binding of the mesh to its curvenets.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) binding: Option<BindingReport>,
}

#[derive(Serialize, Default)]
struct FaceSizes {
    triangles: usize,
    quads: usize,
    polygons: usize,
}

#[derive(Serialize)]
struct BlendShapeReport {
    name: String,
    prim: String,
    offsets: usize,
    sparse: bool,
    inbetween_weights: Vec<f64>,
}

pub(super) fn mesh_report(
    stage: &Stage,
    m: &MeshData,
    time: Option<f64>,
    warnings: &mut Vec<String>,
) -> CliResult<MeshReport> {
    let n = m.projection_points.len();
    let topo = PolyMesh::new(&m.face_vertex_counts, &m.face_vertex_indices, n)
        .map_err(|e| CliError::Input(format!("{}: {e}", m.path)))?;
    let mut face_sizes = FaceSizes::default();
    for c in &m.face_vertex_counts {
        match c {
            3 => face_sizes.triangles += 1,
            4 => face_sizes.quads += 1,
            _ => face_sizes.polygons += 1,
        }
    }
    if m.curvenets.is_empty() {
        warnings.push(format!("{}: curvenet:curvenets has no targets; the mesh is not deformed", m.path));
    }
    let blend_shape_weights = match time {
        Some(_) if !m.blend_shapes.is_empty() => Some(stage.blend_shape_weights(m, time)?),
        _ => None,
    };
    let nets = m.curvenets.iter().map(|p| stage.curvenet(p)).collect::<Result<Vec<_>, _>>()?;
    let mesh_rig = crate::cli::rig::MeshRig::new(stage, m, &nets, 0)?;
    let cage = cage_report(stage, m, mesh_rig.as_ref())?;
    let rig = match mesh_rig {
        Some(r) => Some(rig_report(stage, m, &nets, r, time)?),
        None => None,
    };
    Ok(MeshReport {
        path: m.path.clone(),
        vertices: n,
        faces: topo.n_faces(),
        face_sizes,
        mean_edge_length: topo.mean_edge_length(&m.projection_points),
        bounding_box_diagonal: curvenet_core::bounding_box_diagonal(&m.projection_points),
        rest_pose_frames: m.rest_sample_times.len(),
        curvenets: m.curvenets.clone(),
        blend_shapes: m
            .blend_shapes
            .iter()
            .map(|b| BlendShapeReport {
                name: b.name.clone(),
                prim: b.prim.clone(),
                offsets: b.offsets.len(),
                sparse: b.point_indices.is_some(),
                inbetween_weights: b.inbetweens.iter().map(|i| i.weight).collect(),
            })
            .collect(),
        blend_shape_weights,
        rig,
        cage,
        binding: None,
    })
}

/// The mesh's lines of the text report.
pub(super) fn mesh_text(s: &mut String, m: &MeshReport) {
    let _ = writeln!(
        s,
        "mesh {}: {} vertices, {} faces ({} triangles, {} quads, {} polygons), mean edge {:.4}, diagonal {:.4}, {} rest-pose frames",
        m.path,
        m.vertices,
        m.faces,
        m.face_sizes.triangles,
        m.face_sizes.quads,
        m.face_sizes.polygons,
        m.mean_edge_length,
        m.bounding_box_diagonal,
        m.rest_pose_frames
    );
    let _ = writeln!(s, "  curvenets: {}", m.curvenets.join(", "));
    if let Some(r) = &m.rig {
        rig_text(s, r);
    }
    if let Some(c) = &m.cage {
        cage_text(s, c);
    }
    if let Some(b) = &m.binding {
        binding_text(s, b);
    }
    for (k, b) in m.blend_shapes.iter().enumerate() {
        let w = m.blend_shape_weights.as_ref().map(|w| format!(", weight {}", w[k])).unwrap_or_default();
        let _ = writeln!(
            s,
            "  blend shape {:?} ({}): {} offsets{}, inbetweens at {:?}{w}",
            b.name,
            b.prim,
            b.offsets,
            if b.sparse { " (sparse)" } else { "" },
            b.inbetween_weights
        );
    }
}
