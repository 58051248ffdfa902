//! `curvenet inspect STAGE`: what a stage holds for curvenet deformation, for
//! a rigging TD debugging a curvenet before binding it.

use std::fmt::Write as _;

use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};
use serde::Serialize;

use super::{CliError, CliResult};

#[derive(clap::Args)]
pub struct Args {
    /// The USD stage (.usda, .usdc, .usdz).
    pub stage: std::path::PathBuf,
    /// Only this prim (a mesh or a curvenet).
    #[arg(long)]
    pub prim: Option<String>,
    /// Read posed data at this time code (default: the default value).
    #[arg(long)]
    pub time: Option<f64>,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    stage: String,
    time_code_range: Option<(f64, f64)>,
    meshes: Vec<MeshReport>,
    curvenets: Vec<CurvenetReport>,
    warnings: Vec<String>,
}

#[derive(Serialize)]
struct MeshReport {
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

#[derive(Serialize)]
struct CurvenetReport {
    path: String,
    control_points: usize,
    splines: usize,
    sample_density: f64,
    posed_frames: usize,
    control_points_at_time: Option<Vec<[f64; 3]>>,
    spline_indices: Vec<[u32; 4]>,
}

pub fn run(args: &Args) -> CliResult {
    let stage = Stage::open(&args.stage)?;
    let report = build(&stage, args)?;
    if args.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| CliError::Input(e.to_string()))?;
        println!("{text}");
    } else {
        print!("{}", text(&report));
    }
    Ok(())
}

fn build(stage: &Stage, args: &Args) -> CliResult<Report> {
    let mut meshes = stage.deformed_meshes()?;
    let mut curvenets = stage.curvenets()?;
    if let Some(prim) = &args.prim {
        meshes.retain(|m| &m.path == prim);
        curvenets.retain(|c| &c.path == prim);
        if meshes.is_empty() && curvenets.is_empty() {
            return Err(CliError::Input(format!("{prim}: no deformed mesh or curvenet at this path in {}", stage.path())));
        }
    }
    let mut warnings = Vec::new();
    let mesh_reports = meshes
        .iter()
        .map(|m| mesh_report(stage, m, args.time, &mut warnings))
        .collect::<CliResult<Vec<_>>>()?;
    let curvenet_reports = curvenets
        .iter()
        .map(|c| curvenet_report(stage, c, args.time))
        .collect::<CliResult<Vec<_>>>()?;
    let known: std::collections::HashSet<&str> = curvenets.iter().map(|c| c.path.as_str()).collect();
    if args.prim.is_none() {
        for m in &meshes {
            for c in &m.curvenets {
                if !known.contains(c.as_str()) {
                    warnings.push(format!("{}: curvenet:curvenets targets {c}, which is not a curvenet", m.path));
                }
            }
        }
    }
    Ok(Report {
        stage: stage.path().to_string(),
        time_code_range: stage.time_code_range(),
        meshes: mesh_reports,
        curvenets: curvenet_reports,
        warnings,
    })
}

fn mesh_report(stage: &Stage, m: &MeshData, time: Option<f64>, warnings: &mut Vec<String>) -> CliResult<MeshReport> {
    let n = m.projection_points.len();
    let topo = curvenet_core::PolyMesh::new(&m.face_vertex_counts, &m.face_vertex_indices, n)
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
    Ok(MeshReport {
        path: m.path.clone(),
        vertices: n,
        faces: topo.n_faces(),
        face_sizes,
        mean_edge_length: topo.mean_edge_length(&m.projection_points),
        bounding_box_diagonal: curvenet_core::mesh::bounding_box_diagonal(&m.projection_points),
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
    })
}

fn curvenet_report(stage: &Stage, c: &CurvenetData, time: Option<f64>) -> CliResult<CurvenetReport> {
    let control_points_at_time = match time {
        Some(_) => Some(stage.posed_pool(c, time)?.unwrap_or_else(|| c.pool.clone())),
        None => None,
    };
    Ok(CurvenetReport {
        path: c.path.clone(),
        control_points: c.pool.len(),
        splines: c.splines.len(),
        sample_density: c.sample_density,
        posed_frames: c.sample_times.len(),
        control_points_at_time,
        spline_indices: c.splines.clone(),
    })
}

fn text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "stage {}", r.stage);
    if let Some((a, b)) = r.time_code_range {
        let _ = writeln!(s, "  frames {a} to {b}");
    }
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "mesh {}: {} vertices, {} faces ({} triangles, {} quads, {} polygons), mean edge {:.4}, diagonal {:.4}, {} rest-pose frames",
            m.path, m.vertices, m.faces, m.face_sizes.triangles, m.face_sizes.quads, m.face_sizes.polygons,
            m.mean_edge_length, m.bounding_box_diagonal, m.rest_pose_frames
        );
        let _ = writeln!(s, "  curvenets: {}", m.curvenets.join(", "));
        for (k, b) in m.blend_shapes.iter().enumerate() {
            let w = m.blend_shape_weights.as_ref().map(|w| format!(", weight {}", w[k])).unwrap_or_default();
            let _ = writeln!(
                s,
                "  blend shape {:?} ({}): {} offsets{}, inbetweens at {:?}{w}",
                b.name, b.prim, b.offsets, if b.sparse { " (sparse)" } else { "" }, b.inbetween_weights
            );
        }
    }
    for c in &r.curvenets {
        let _ = writeln!(
            s,
            "curvenet {}: {} control points, {} splines, sample density {}, {} posed frames",
            c.path, c.control_points, c.splines, c.sample_density, c.posed_frames
        );
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}
