//! `curvenet inspect STAGE`: what a stage holds for curvenet deformation, for
//! a rigging TD debugging a curvenet before binding it.
//!
//! Besides the raw data (meshes, curvenets, blend shapes, frames), every
//! curvenet is analysed as the binding will analyse it (paper §3): its neutral
//! pool against the projection pose of the first mesh that targets it. The
//! report lists the intersections, anchors and curves with their sampling, and
//! warns about what is likely a mistake (curves shorter than a mesh edge,
//! curves with a single segment, unused control points, samples far from the
//! surface, non-finite posed pools). Each curvenet's Curvenet Adjustments
//! (`CurvenetAdjustment` children) are listed with their knot, tangents,
//! animated attributes and values at `--time`. A curvenet whose analysis fails is
//! reported with its error (naming the prim) and the others are still
//! reported; the command then exits with status 2.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use curvenet_core::CurveEnd;
use curvenet_core::Surface;
use curvenet_core::{Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingStats, BindingTimings};
use curvenet_schema::{CurvenetData, MeshData};
use serde::Serialize;

use super::{CliError, CliResult};

/// A sample farther than this fraction of the mesh's bounding-box diagonal
/// from the surface is reported.
pub const FAR_FROM_SURFACE: f64 = 0.05;

/// At most this many control points are named in one warning.
const MAX_LISTED: usize = 20;

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
    /// Also bind every reported mesh to its curvenets as the bake does, and
    /// report the binding: cut-vertices, cut-faces, cracks, islands removed,
    /// the unknowns and the factor, the time of each stage, and every warning.
    #[arg(long)]
    pub bind: bool,
    /// After the report, open the stage in the browser viewer: serve on ADDR
    /// (default 127.0.0.1:8720) as `curvenet serve --open-stage STAGE` does
    /// and print the viewer's address; Ctrl-C stops.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8720")]
    pub serve: Option<String>,
}

#[derive(Serialize)]
struct Report {
    stage: String,
    time_code_range: Option<(f64, f64)>,
    meshes: Vec<MeshReport>,
    curvenets: Vec<CurvenetReport>,
    /// Every warning of the report, each naming its prim (the curvenets'
    /// warnings are also listed per curvenet).
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
    /// The UsdSkel rig that skins the mesh in process, and the spline
    /// skinning of its curvenets.
    #[serde(skip_serializing_if = "Option::is_none")]
    rig: Option<RigReport>,
    /// The cage coupled with the skeleton (`rel curvenet:cage`, Corda et al. 2020).
    #[serde(skip_serializing_if = "Option::is_none")]
    cage: Option<CageReport>,
    /// With `--bind`: the binding of the mesh to its curvenets.
    #[serde(skip_serializing_if = "Option::is_none")]
    binding: Option<BindingReport>,
}

/// A mesh's cage (`rel curvenet:cage`) as the bake couples it with the
/// mesh's skeleton: `Φ`, the MaxVol rows and their square system.
#[derive(Serialize)]
struct CageReport {
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

/// The rig found for a mesh (`super::rig::MeshRig`).
#[derive(Serialize)]
struct RigReport {
    skel_root: String,
    skeleton: String,
    joints: Vec<String>,
    animation: Option<String>,
    /// Time codes of the animation's joint-transform samples.
    animation_frames: usize,
    method: &'static str,
    influences_per_point: usize,
    /// The influences were authored `constant` (one set for the whole mesh).
    rigid: bool,
    geom_bind_transform: [f64; 16],
    /// Points whose skin weights do not sum to 1 (skinned as authored).
    unnormalized_points: usize,
    /// Blend shapes before skinning (UsdSkel's order) or after the solve.
    blend_shape_order: &'static str,
    curvenets: Vec<NetRigReport>,
    /// Wall time of the spline skinning precomputation.
    spline_precompute_ms: f64,
}

#[derive(Serialize)]
struct NetRigReport {
    path: String,
    /// `weights` (per control point), `mesh` (from the mesh's skin weights)
    /// or `none` (its own samples, else knot tracking).
    skinning: &'static str,
    /// The joints that weigh on the curvenet.
    joints: Vec<String>,
    /// `mesh`: the largest difference between the per-control-point weights
    /// derived from the mesh's and the mesh's own, at samples of the curves.
    #[serde(skip_serializing_if = "Option::is_none")]
    derived_weight_deviation: Option<f64>,
    c1_junctions: usize,
    g1_junctions: usize,
    angle_junctions: usize,
    /// With `--time`: the integrated distance (mean over arc length, and the
    /// largest) of the spline-skinned and of the naively skinned control
    /// points' curves to the densely skinned curves, over the mesh's diagonal.
    #[serde(skip_serializing_if = "Option::is_none")]
    distance_at_time: Option<SkinDistanceReport>,
}

#[derive(Serialize)]
struct SkinDistanceReport {
    spline_mean: f64,
    spline_max: f64,
    naive_mean: f64,
    naive_max: f64,
}

/// `inspect --bind`: what `Binding::new` built, and how long each stage took.
#[derive(Serialize)]
struct BindingReport {
    /// `None` when the binding failed (then `error` says why).
    /// The same counts and times, by the same names, as the service's
    /// binding response (`schema::wire`).
    stats: Option<BindingStats>,
    timings: Option<BindingTimings>,
    warnings: Vec<String>,
    error: Option<String>,
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
    /// The neutral-pose analysis; `None` when no mesh targets the curvenet
    /// or the analysis failed (then `error` says why).
    analysis: Option<Analysis>,
    /// Why the analysis failed (a `curvenet_core::Error`).
    error: Option<AnalysisError>,
    /// The warnings about this curvenet (also in the report's `warnings`).
    warnings: Vec<String>,
    /// Its `CurvenetAdjustment` prims, in the stage's child order.
    adjustments: Vec<AdjustmentReport>,
}

/// A `CurvenetAdjustment` prim (schema/README.md).
#[derive(Serialize)]
struct AdjustmentReport {
    path: String,
    /// The knot's pool index.
    knot: u32,
    /// `intersection`, `anchor` or `pass-through` (a valence-2 knot).
    knot_kind: &'static str,
    valence: usize,
    attach_tangents: bool,
    /// The knot's tangent control points (the order of `curvenet:tangentTranslates`).
    tangents: Vec<u32>,
    /// The authored attributes and how many time samples each has (0: static).
    attributes: BTreeMap<String, usize>,
    /// The values at `--time` (the default values without it): translate,
    /// rotate (`euler_xyz_degrees` or `quaternion_wxyz`), scale, tangent translates.
    values: AdjustmentValues,
}

#[derive(Serialize)]
struct AdjustmentValues {
    time: Option<f64>,
    translate: [f64; 3],
    euler_xyz_degrees: Option<[f64; 3]>,
    quaternion_wxyz: Option<[f64; 4]>,
    scale: [f64; 3],
    tangent_translates: Vec<[f64; 3]>,
}

#[derive(Serialize)]
struct AnalysisError {
    /// The `curvenet_core::Error` variant, e.g. `CoincidentTangents`.
    kind: String,
    /// The message, starting with the curvenet's prim path.
    message: String,
}

#[derive(Serialize)]
struct Analysis {
    /// The mesh analysed against (its projection pose).
    mesh: String,
    mean_edge_length: f64,
    bounding_box_diagonal: f64,
    control_points: usize,
    /// Pool indices used by no spline.
    unused_control_points: Vec<u32>,
    splines: usize,
    intersections: Vec<IntersectionReport>,
    /// Number of intersections by valence (JSON keys are the valences).
    intersections_by_valence: BTreeMap<u32, usize>,
    /// Pool indices of the anchors (valence-1 endpoints).
    anchors: Vec<u32>,
    curves: Vec<CurveReport>,
    /// Indices into `curves` of the isolated closed curves.
    isolated_closed_curves: Vec<usize>,
    samples: usize,
    segments: usize,
    /// The largest distance of a neutral sample from the surface.
    max_distance_to_surface: f64,
    /// The spline of that sample.
    max_distance_spline: u32,
}

#[derive(Serialize)]
struct IntersectionReport {
    /// The pool index of the intersection's control point.
    point: u32,
    valence: u32,
    /// Its (knot) sample.
    sample: u32,
    /// The curve ends there, counter-clockwise around the surface normal.
    curves_ccw: Vec<u32>,
}

#[derive(Serialize)]
struct CurveReport {
    splines: Vec<CurveSplineReport>,
    start: EndReport,
    end: EndReport,
    /// Samples along the curve (an open curve counts both ends, an isolated
    /// closed curve its start once).
    samples: usize,
    segments: usize,
    /// Arc length of the neutral samples' polyline.
    length: f64,
}

#[derive(Serialize)]
struct CurveSplineReport {
    spline: u32,
    reversed: bool,
}

#[derive(Serialize)]
struct EndReport {
    /// `intersection`, `anchor` or `closed` (an isolated closed curve).
    kind: &'static str,
    point: u32,
}

impl From<CurveEnd> for EndReport {
    fn from(e: CurveEnd) -> Self {
        match e {
            CurveEnd::Intersection(point) => Self { kind: "intersection", point },
            CurveEnd::Anchor(point) => Self { kind: "anchor", point },
            CurveEnd::Closed(point) => Self { kind: "closed", point },
        }
    }
}

impl std::fmt::Display for EndReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.kind {
            "closed" => write!(f, "closed at {}", self.point),
            kind => write!(f, "{kind} {}", self.point),
        }
    }
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
    let failed: Vec<&str> = report
        .curvenets
        .iter()
        .filter_map(|c| c.error.as_ref())
        .map(|e| e.message.as_str())
        .chain(report.meshes.iter().filter_map(|m| m.binding.as_ref()?.error.as_deref()))
        .collect();
    if let Some(addr) = &args.serve {
        for f in &failed {
            eprintln!("curvenet: warning: {f}");
        }
        return serve_viewer(&args.stage, addr);
    }
    if !failed.is_empty() {
        return Err(CliError::Input(format!(
            "the analysis or binding of {} prim{} failed:\n  {}",
            failed.len(),
            if failed.len() == 1 { "" } else { "s" },
            failed.join("\n  ")
        )));
    }
    Ok(())
}

/// `inspect STAGE --serve [ADDR]`: `curvenet serve --addr ADDR --open-stage STAGE`
/// (the other serve options from their environment variables).
fn serve_viewer(stage: &std::path::Path, addr: &str) -> CliResult {
    use clap::Parser as _;
    #[derive(clap::Parser)]
    struct Serve {
        #[command(flatten)]
        args: super::serve::Args,
    }
    let argv = ["serve".into(), "--addr".into(), addr.into(), "--open-stage".into(), stage.as_os_str().to_owned()];
    let serve = Serve::try_parse_from::<_, std::ffi::OsString>(argv).map_err(|e| CliError::Input(e.to_string()))?;
    super::serve::run(&serve.args)
}

fn build(stage: &Stage, args: &Args) -> CliResult<Report> {
    // All deformed meshes stay available to find the mesh of a curvenet,
    // even when `--prim` selects the curvenet alone.
    let all_meshes = stage.deformed_meshes()?;
    let mut meshes: Vec<&MeshData> = all_meshes.iter().collect();
    let mut curvenets = stage.curvenets()?;
    if let Some(prim) = &args.prim {
        meshes.retain(|m| &m.path == prim);
        curvenets.retain(|c| &c.path == prim);
        if meshes.is_empty() && curvenets.is_empty() {
            return Err(CliError::Input(format!(
                "{prim}: no deformed mesh or curvenet at this path in {}",
                stage.path()
            )));
        }
    }
    let mut warnings = Vec::new();
    let mut mesh_reports =
        meshes.iter().map(|m| mesh_report(stage, m, args.time, &mut warnings)).collect::<CliResult<Vec<_>>>()?;
    if args.bind {
        for (report, m) in mesh_reports.iter_mut().zip(&meshes) {
            let b = binding_report(stage, m)?;
            warnings.extend(b.warnings.iter().map(|w| format!("{}: {w}", m.path)));
            report.binding = Some(b);
        }
    }
    let mut surfaces: Vec<Option<Result<Surface, curvenet_core::Error>>> =
        (0..all_meshes.len()).map(|_| None).collect();
    let mut curvenet_reports = Vec::with_capacity(curvenets.len());
    for c in &curvenets {
        let r = curvenet_report(stage, c, args.time, &all_meshes, &mut surfaces)?;
        warnings.extend(r.warnings.iter().cloned());
        curvenet_reports.push(r);
    }
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
    let mesh_rig = super::rig::MeshRig::new(stage, m, &nets, 0)?;
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

/// The cage of `m`, coupled as the bake couples it (`Deformer::new` does
/// the same precomputation); `None` when the mesh has no `rel curvenet:cage`.
fn cage_report(stage: &Stage, m: &MeshData, rig: Option<&super::rig::MeshRig>) -> CliResult<Option<CageReport>> {
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

fn cage_text(s: &mut String, c: &CageReport) {
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

fn rig_report(
    stage: &Stage,
    m: &MeshData,
    nets: &[CurvenetData],
    rig: super::rig::MeshRig,
    time: Option<f64>,
) -> CliResult<RigReport> {
    use curvenet_core::JunctionKind;
    let transforms = match time {
        Some(_) => Some(rig.joints.read_transforms(stage, time)?),
        None => None,
    };
    let diagonal = curvenet_core::bounding_box_diagonal(&m.projection_points);
    let mut curvenets = Vec::new();
    for ((net, nr), spline) in nets.iter().zip(&rig.nets).zip(&rig.skinning.curvenets) {
        let (Some(nr), Some(spline)) = (nr, spline) else {
            curvenets.push(NetRigReport {
                path: net.path.clone(),
                skinning: "none",
                joints: Vec::new(),
                derived_weight_deviation: None,
                c1_junctions: 0,
                g1_junctions: 0,
                angle_junctions: 0,
                distance_at_time: None,
            });
            continue;
        };
        let count = |f: fn(&JunctionKind) -> bool| spline.junctions().iter().filter(|j| f(&j.kind)).count();
        let distance_at_time = match &transforms {
            None => None,
            Some(xf) => {
                let core = |source| CliError::Core { context: net.path.clone(), source };
                let mut fit = vec![[0.0; 3]; spline.n_points()];
                let mut naive = fit.clone();
                spline.pose(xf, &mut fit).map_err(core)?;
                spline.pose_naive(xf, &mut naive).map_err(core)?;
                let (a, b) = (
                    spline.distance_to_skinned(&fit, xf).map_err(core)?,
                    spline.distance_to_skinned(&naive, xf).map_err(core)?,
                );
                Some(SkinDistanceReport {
                    spline_mean: a.mean / diagonal,
                    spline_max: a.max / diagonal,
                    naive_mean: b.mean / diagonal,
                    naive_max: b.max / diagonal,
                })
            }
        };
        curvenets.push(NetRigReport {
            path: net.path.clone(),
            skinning: nr.mode,
            joints: spline.joints().iter().map(|&j| rig.joints.rig.joints[j as usize].clone()).collect(),
            derived_weight_deviation: nr.weight_deviation,
            c1_junctions: count(|k| *k == JunctionKind::C1),
            g1_junctions: count(|k| *k == JunctionKind::G1),
            angle_junctions: count(|k| matches!(k, JunctionKind::Angle(_))),
            distance_at_time,
        });
    }
    let order = stage.blend_shape_order(m)?.unwrap_or(curvenet_schema::usd::BlendShapeOrder::BeforeSkinning);
    Ok(RigReport {
        skel_root: rig.joints.rig.skel_root.clone(),
        skeleton: rig.joints.rig.skeleton.clone(),
        joints: rig.joints.rig.joints.clone(),
        animation: rig.joints.rig.animation.clone(),
        animation_frames: rig.joints.rig.time_samples.len(),
        method: rig.skinning.skin.method().token(),
        influences_per_point: rig.joints.rig.element_size,
        rigid: rig.joints.rig.constant_influences,
        geom_bind_transform: rig.joints.rig.geom_bind_transform,
        unnormalized_points: rig.unnormalized.len(),
        blend_shape_order: match order {
            curvenet_schema::usd::BlendShapeOrder::BeforeSkinning => "beforeSkinning",
            curvenet_schema::usd::BlendShapeOrder::AfterSolve => "afterSolve",
        },
        curvenets,
        spline_precompute_ms: rig.spline_ms,
    })
}

fn rig_text(s: &mut String, r: &RigReport) {
    let short: Vec<&str> = r.joints.iter().map(|j| j.rsplit('/').next().unwrap_or(j)).collect();
    let _ = writeln!(
        s,
        "  rig: skeleton {} ({} joints: {}) under {}, animation {} ({} frames), {}, {} influences per point{}, \
         geomBindTransform {}, blend shapes {}",
        r.skeleton,
        r.joints.len(),
        short.join(", "),
        r.skel_root,
        r.animation.as_deref().unwrap_or("none (rest pose)"),
        r.animation_frames,
        r.method,
        r.influences_per_point,
        if r.rigid { " (rigid: constant)" } else { "" },
        if r.geom_bind_transform == curvenet_core::MAT4_IDENTITY {
            "identity".to_string()
        } else {
            format!("{:?}", r.geom_bind_transform)
        },
        r.blend_shape_order
    );
    if r.unnormalized_points > 0 {
        let _ = writeln!(s, "    {} points' weights do not sum to 1 (skinned as authored)", r.unnormalized_points);
    }
    for c in &r.curvenets {
        if c.skinning == "none" {
            let _ = writeln!(s, "  curvenet {}: not spline-skinned (own samples, else knot tracking)", c.path);
            continue;
        }
        let how = match c.derived_weight_deviation {
            None => "weights per control point".to_string(),
            Some(d) => format!("weights from the mesh, per control point, within {d:.3} of the mesh's"),
        };
        let _ = writeln!(
            s,
            "  curvenet {}: spline-skinned ({how}) by {}; constraints: {} C1, {} G1, {} angle",
            c.path,
            c.joints.iter().map(|j| j.rsplit('/').next().unwrap_or(j)).collect::<Vec<_>>().join(", "),
            c.c1_junctions,
            c.g1_junctions,
            c.angle_junctions
        );
        if let Some(d) = &c.distance_at_time {
            let _ = writeln!(
                s,
                "    distance to the skinned curves (x diagonal): spline skinning mean {:.3e}, max {:.3e}; naive control points mean {:.3e}, max {:.3e}",
                d.spline_mean, d.spline_max, d.naive_mean, d.naive_max
            );
        }
    }
}

/// Binds `m` as the bake does (`super::deformer`). A core error is part of
/// the report (the command then exits 2); a stage that breaks the contract is
/// an error of the command.
fn binding_report(stage: &Stage, m: &MeshData) -> CliResult<BindingReport> {
    let nets = m.curvenets.iter().map(|p| stage.curvenet(p)).collect::<Result<Vec<_>, _>>()?;
    let start = std::time::Instant::now();
    // The binding is of the projection pose: the rig and the cage under it
    // change frames, not the binding (they are reported on their own).
    let bound = super::deformer(m, &nets, None, None);
    let total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(match bound {
        Ok(d) => BindingReport {
            stats: Some(BindingStats::from(&d.binding().stats())),
            timings: Some(BindingTimings::new(d.timings().analysis_ms, &d.binding().timings(), total_ms)),
            warnings: d.binding().warnings().iter().map(|w| w.to_string()).collect(),
            error: None,
        },
        Err(e) => BindingReport { stats: None, timings: None, warnings: Vec::new(), error: Some(e.to_string()) },
    })
}

/// A mesh's surface in its projection pose (core's, as the bake samples
/// against it), built once for all the curvenets that target it.
fn surface(m: &MeshData) -> Result<Surface, curvenet_core::Error> {
    let mesh = PolyMesh::new(&m.face_vertex_counts, &m.face_vertex_indices, m.projection_points.len())?;
    Surface::new(&mesh, &m.projection_points)
}

fn curvenet_report(
    stage: &Stage,
    c: &CurvenetData,
    time: Option<f64>,
    meshes: &[MeshData],
    surfaces: &mut [Option<Result<Surface, curvenet_core::Error>>],
) -> CliResult<CurvenetReport> {
    let mut warnings = Vec::new();
    let control_points_at_time = match time {
        Some(t) => {
            let pool = stage.posed_pool(c, time)?;
            if let Some(pool) = &pool {
                let bad: Vec<u32> =
                    (0..pool.len() as u32).filter(|&i| !pool[i as usize].iter().all(|x| x.is_finite())).collect();
                if !bad.is_empty() {
                    warnings.push(format!(
                        "{}: at time {t} the posed pool (primvars:curvenet:cv) has {} non-finite control point{}: {} \
                         (control point {} is {:?})",
                        c.path,
                        bad.len(),
                        plural(bad.len()),
                        list(&bad),
                        bad[0],
                        pool[bad[0] as usize]
                    ));
                }
            }
            Some(pool.unwrap_or_else(|| c.pool.clone()))
        }
        None => None,
    };
    let unused = unused_control_points(c);
    if !unused.is_empty() {
        warnings.push(format!(
            "{}: {} control point{} of the pool {} used by no spline: {}",
            c.path,
            unused.len(),
            plural(unused.len()),
            if unused.len() == 1 { "is" } else { "are" },
            list(&unused)
        ));
    }
    let targeting: Vec<usize> = (0..meshes.len()).filter(|&m| meshes[m].curvenets.contains(&c.path)).collect();
    let (analysis, error) = match targeting.first() {
        None => {
            warnings.push(format!(
                "{}: no deformed mesh targets this curvenet (rel curvenet:curvenets), so it cannot be analysed \
                 against a surface",
                c.path
            ));
            (None, None)
        }
        Some(&m) => {
            if targeting.len() > 1 {
                let paths: Vec<&str> = targeting.iter().map(|&k| meshes[k].path.as_str()).collect();
                warnings.push(format!(
                    "{}: {} meshes target this curvenet ({}); it is analysed against the first, {}",
                    c.path,
                    targeting.len(),
                    paths.join(", "),
                    meshes[m].path
                ));
            }
            let surface = surfaces[m].get_or_insert_with(|| surface(&meshes[m]));
            let result = match surface {
                Ok(surface) => analyse(c, &meshes[m].path, surface, unused, &mut warnings),
                Err(e) => Err(e.clone()),
            };
            match result {
                Ok(a) => (Some(a), None),
                Err(e) => {
                    let message = match surface {
                        Ok(_) => format!("{}: {e}", c.path),
                        Err(_) => format!("{}: cannot analyse against mesh {}: {e}", c.path, meshes[m].path),
                    };
                    (None, Some(AnalysisError { kind: error_kind(&e), message }))
                }
            }
        }
    };
    Ok(CurvenetReport {
        path: c.path.clone(),
        control_points: c.pool.len(),
        splines: c.splines.len(),
        sample_density: c.sample_density,
        posed_frames: c.sample_times.len(),
        control_points_at_time,
        spline_indices: c.splines.clone(),
        analysis,
        error,
        warnings,
        adjustments: adjustment_reports(stage, c, time)?,
    })
}

/// The curvenet's adjustments with their values at `time`.
fn adjustment_reports(stage: &Stage, c: &CurvenetData, time: Option<f64>) -> CliResult<Vec<AdjustmentReport>> {
    let list = stage.curvenet_adjustments(c)?;
    let values = stage.adjustments_at(std::slice::from_ref(&list), time)?;
    Ok(list
        .into_iter()
        .zip(values)
        .map(|(a, v)| {
            let valence = c.splines.iter().map(|s| (s[0] == a.knot) as usize + (s[3] == a.knot) as usize).sum();
            let (euler_xyz_degrees, quaternion_wxyz) = match v.rotate {
                curvenet_core::Rotate::EulerXyz(e) => (Some(e), None),
                curvenet_core::Rotate::Quaternion(q) => (None, Some(q)),
            };
            AdjustmentReport {
                knot_kind: match valence {
                    1 => "anchor",
                    2 => "pass-through",
                    _ => "intersection",
                },
                path: a.path,
                knot: a.knot,
                valence,
                attach_tangents: a.attach_tangents,
                tangents: a.tangents,
                attributes: a.attributes.into_iter().map(|(name, times)| (name, times.len())).collect(),
                values: AdjustmentValues {
                    time,
                    translate: v.translate,
                    euler_xyz_degrees,
                    quaternion_wxyz,
                    scale: v.scale,
                    tangent_translates: v.tangent_translates,
                },
            }
        })
        .collect())
}

fn unused_control_points(c: &CurvenetData) -> Vec<u32> {
    let mut used = vec![false; c.pool.len()];
    for s in &c.splines {
        for &p in s {
            if let Some(u) = used.get_mut(p as usize) {
                *u = true;
            }
        }
    }
    (0..c.pool.len() as u32).filter(|&p| !used[p as usize]).collect()
}

/// The analysis of one curvenet (neutral pool) against `surface`.
fn analyse(
    c: &CurvenetData,
    mesh_path: &str,
    surface: &Surface,
    unused_control_points: Vec<u32>,
    warnings: &mut Vec<String>,
) -> Result<Analysis, curvenet_core::Error> {
    let net = Curvenet::new(&c.splines, &c.pool)?;
    let options = SamplingOptions::default().with_density(c.sample_density);
    let layout =
        CurvenetLayout::with_closest_point(&net, surface.closest_points(), surface.mean_edge_length(), &options)?;
    let topology = layout.topology();
    let sampling = layout.sampling();
    let samples = layout.neutral_samples();

    let intersections: Vec<IntersectionReport> = layout
        .intersections()
        .iter()
        .map(|fan| IntersectionReport {
            point: fan.point(),
            valence: topology.valence(fan.point() as usize),
            sample: fan.sample(),
            curves_ccw: fan.emanations().iter().map(|e| e.curve).collect(),
        })
        .collect();
    let mut intersections_by_valence = BTreeMap::new();
    for i in &intersections {
        *intersections_by_valence.entry(i.valence).or_insert(0) += 1;
    }

    let dist =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let mut curves = Vec::with_capacity(topology.curves().len());
    for (k, curve) in topology.curves().iter().enumerate() {
        let segs = sampling.curve_segments(k);
        let n_segments = segs.len();
        let length: f64 = sampling.segments()[segs]
            .iter()
            .map(|s| dist(samples[s.samples[0] as usize], samples[s.samples[1] as usize]))
            .sum();
        let splines: Vec<CurveSplineReport> =
            curve.splines.iter().map(|s| CurveSplineReport { spline: s.spline, reversed: s.reversed }).collect();
        let names = spline_list(&splines);
        if length < surface.mean_edge_length() {
            warnings.push(format!(
                "{}: curve {k} (spline{} {names}) is {length:.4} long, shorter than one mean mesh edge ({:.4})",
                c.path,
                plural(splines.len()),
                surface.mean_edge_length()
            ));
        }
        if n_segments < 2 {
            warnings.push(format!(
                "{}: curve {k} (spline{} {names}) has {n_segments} segment; fewer than 2 leaves it no interior sample",
                c.path,
                plural(splines.len())
            ));
        }
        curves.push(CurveReport {
            splines,
            start: curve.start.into(),
            end: curve.end.into(),
            samples: sampling.curve_samples(k).len(),
            segments: n_segments,
            length,
        });
    }

    // Distance of every neutral sample from the surface, worst per spline.
    let distances = samples
        .iter()
        .map(|&p| surface.closest_points().closest_point(p).map(|h| h.distance))
        .collect::<Result<Vec<f64>, _>>()?;
    let limit = FAR_FROM_SURFACE * surface.diagonal();
    let (mut max_distance, mut max_spline) = (0.0f64, 0u32);
    for s in 0..c.splines.len() {
        let (sample, d) = sampling
            .spline_samples(s)
            .map(|q| (q, distances[q as usize]))
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        if d > max_distance {
            (max_distance, max_spline) = (d, s as u32);
        }
        if d > limit {
            warnings.push(format!(
                "{}: spline {s} is {d:.4} from the surface of {} at sample {sample} ({:.1}% of its bounding-box \
                 diagonal {:.4}; the limit is {:.0}%)",
                c.path,
                mesh_path,
                100.0 * d / surface.diagonal(),
                surface.diagonal(),
                100.0 * FAR_FROM_SURFACE
            ));
        }
    }

    Ok(Analysis {
        mesh: mesh_path.to_string(),
        mean_edge_length: surface.mean_edge_length(),
        bounding_box_diagonal: surface.diagonal(),
        control_points: c.pool.len(),
        unused_control_points,
        splines: c.splines.len(),
        intersections,
        intersections_by_valence,
        anchors: topology.anchors().to_vec(),
        curves,
        isolated_closed_curves: topology.isolated_closed_curves().collect(),
        samples: layout.n_samples(),
        segments: layout.n_segments(),
        max_distance_to_surface: max_distance,
        max_distance_spline: max_spline,
    })
}

/// The variant name of a core error (`CoincidentTangents`, ...).
fn error_kind(e: &curvenet_core::Error) -> String {
    format!("{e:?}").chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect()
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// `a, b, c` (at most [`MAX_LISTED`], then how many more).
fn list(items: &[u32]) -> String {
    let mut s: Vec<String> = items.iter().take(MAX_LISTED).map(|i| i.to_string()).collect();
    if items.len() > MAX_LISTED {
        s.push(format!("and {} more", items.len() - MAX_LISTED));
    }
    s.join(", ")
}

fn spline_list(splines: &[CurveSplineReport]) -> String {
    let s: Vec<String> = splines
        .iter()
        .map(|s| if s.reversed { format!("{} (reversed)", s.spline) } else { s.spline.to_string() })
        .collect();
    s.join(", ")
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
            rig_text(&mut s, r);
        }
        if let Some(c) = &m.cage {
            cage_text(&mut s, c);
        }
        if let Some(b) = &m.binding {
            binding_text(&mut s, b);
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
    for c in &r.curvenets {
        let _ = writeln!(
            s,
            "curvenet {}: {} control points, {} splines, sample density {}, {} posed frames",
            c.path, c.control_points, c.splines, c.sample_density, c.posed_frames
        );
        if let Some(e) = &c.error {
            let _ = writeln!(s, "  error ({}): {}", e.kind, e.message);
        }
        if let Some(a) = &c.analysis {
            analysis_text(&mut s, a);
        }
        for a in &c.adjustments {
            adjustment_text(&mut s, a);
        }
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

fn adjustment_text(s: &mut String, a: &AdjustmentReport) {
    let attributes: Vec<String> = a
        .attributes
        .iter()
        .map(|(name, n)| match n {
            0 => format!("{name} (static)"),
            n => format!("{name} ({n} time sample{})", plural(*n)),
        })
        .collect();
    let _ = writeln!(
        s,
        "  adjustment {}: knot {} ({}, valence {}), tangents {} ({}): {}",
        a.path,
        a.knot,
        a.knot_kind,
        a.valence,
        if a.attach_tangents { "attached" } else { "free" },
        list(&a.tangents),
        if attributes.is_empty() { "nothing authored".to_string() } else { attributes.join(", ") }
    );
    let v = &a.values;
    let rotate = match (v.euler_xyz_degrees, v.quaternion_wxyz) {
        (_, Some(q)) => format!("orient (w, x, y, z) {q:?}"),
        (Some(e), None) => format!("rotateXYZ {e:?} degrees"),
        (None, None) => "no rotate".to_string(),
    };
    let _ = writeln!(
        s,
        "    {}: translate {:?}, {rotate}, scale {:?}, tangent translates {:?}",
        match v.time {
            Some(t) => format!("at time {t}"),
            None => "default values".to_string(),
        },
        v.translate,
        v.scale,
        v.tangent_translates
    );
}

fn binding_text(s: &mut String, b: &BindingReport) {
    if let Some(e) = &b.error {
        let _ = writeln!(s, "  binding failed: {e}");
    }
    if let (Some(st), Some(t)) = (&b.stats, &b.timings) {
        let _ = writeln!(
            s,
            "  binding: {} samples, {} segments -> {} cut-vertices, {} cut-faces, {} cut-halfedges, {} crack{}, {} island{} removed",
            st.samples,
            st.segments,
            st.cut_vertices,
            st.cut_faces,
            st.cut_halfedges,
            st.cracks,
            plural(st.cracks),
            st.islands_removed,
            plural(st.islands_removed)
        );
        let _ = writeln!(
            s,
            "  segments embedded: {} inside one face, {} by straightest path, {} by fallback path, {} left out; {} detour{}",
            st.chord_paths,
            st.straightest_paths,
            st.fallback_paths,
            st.segments_left_out,
            st.detours,
            plural(st.detours)
        );
        let _ = writeln!(
            s,
            "  binding: {} unknowns, {} constraint rows, {} factor nonzeros",
            st.unknowns, st.constraints, st.factor_nonzeros
        );
        let _ = writeln!(
            s,
            "  binding time: {:.1} ms (analysis {:.1}, surface {:.1}, cutting {:.1}, assembly {:.1}, factor {:.1})",
            t.total_ms, t.analysis_ms, t.surface_ms, t.cutting_ms, t.assembly_ms, t.factor_ms
        );
    }
}

fn analysis_text(s: &mut String, a: &Analysis) {
    let by_valence: Vec<String> =
        a.intersections_by_valence.iter().rev().map(|(v, n)| format!("{n} of valence {v}")).collect();
    let _ = writeln!(
        s,
        "  analysis against {} (neutral pool, projection pose): {} intersections ({}), {} anchors, {} curves, \
         {} isolated closed curve{}, {} samples, {} segments",
        a.mesh,
        a.intersections.len(),
        if by_valence.is_empty() { "none".to_string() } else { by_valence.join(", ") },
        a.anchors.len(),
        a.curves.len(),
        a.isolated_closed_curves.len(),
        plural(a.isolated_closed_curves.len()),
        a.samples,
        a.segments
    );
    let _ = writeln!(
        s,
        "  farthest sample from the surface: {:.4} ({:.2}% of the diagonal {:.4}), on spline {}; unused control points: {}",
        a.max_distance_to_surface,
        100.0 * a.max_distance_to_surface / a.bounding_box_diagonal,
        a.bounding_box_diagonal,
        a.max_distance_spline,
        if a.unused_control_points.is_empty() { "none".to_string() } else { list(&a.unused_control_points) }
    );
    for i in &a.intersections {
        let curves: Vec<String> = i.curves_ccw.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(
            s,
            "  intersection at control point {}: valence {}, sample {}, curves counter-clockwise {}",
            i.point,
            i.valence,
            i.sample,
            curves.join(", ")
        );
    }
    if !a.anchors.is_empty() {
        let anchors: Vec<String> = a.anchors.iter().map(|p| p.to_string()).collect();
        let _ = writeln!(s, "  anchors at control points {}", anchors.join(", "));
    }
    for (k, c) in a.curves.iter().enumerate() {
        let ends = if c.start.kind == "closed" { c.start.to_string() } else { format!("{} to {}", c.start, c.end) };
        let _ = writeln!(
            s,
            "  curve {k}: {ends}, spline{} {}, {} samples, {} segments, length {:.4}",
            plural(c.splines.len()),
            spline_list(&c.splines),
            c.samples,
            c.segments,
            c.length
        );
    }
    if !a.isolated_closed_curves.is_empty() {
        let closed: Vec<String> = a.isolated_closed_curves.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(s, "  isolated closed curves: {}", closed.join(", "));
    }
}
