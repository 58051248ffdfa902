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
//!
//! The report's parts live in `inspect/`: a mesh (`mesh.rs`) with its rig
//! (`rig.rs`), cage (`cage.rs`) and `--bind` binding (`binding.rs`); a
//! curvenet (`curvenet.rs`) with its analysis (`analysis.rs`) and its
//! adjustments (`adjustments.rs`); the wording they share (`wording.rs`).

use std::fmt::Write as _;

use curvenet_core::Surface;
use curvenet_schema::MeshData;
use curvenet_schema::usd::Stage;
use serde::Serialize;

use super::{CliError, CliResult};

mod adjustments;
mod analysis;
mod binding;
mod cage;
mod curvenet;
mod mesh;
mod rig;
mod wording;

use binding::binding_report;
use curvenet::{CurvenetReport, curvenet_report, curvenet_text};
use mesh::{MeshReport, mesh_report, mesh_text};

#[derive(clap::Args)]
pub struct Args {
    /// The USD stage (.usda, .usdc, .usdz).
    pub stage: std::path::PathBuf,
    /// Only this prim (a mesh or a curvenet).
    #[arg(long)]
    pub prim: Option<String>,
    /// Read posed data at this time code (default: the default value).
    #[arg(long, value_parser = finite_time, allow_hyphen_values = true)]
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

fn text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "stage {}", r.stage);
    if let Some((a, b)) = r.time_code_range {
        let _ = writeln!(s, "  frames {a} to {b}");
    }
    for m in &r.meshes {
        mesh_text(&mut s, m);
    }
    for c in &r.curvenets {
        curvenet_text(&mut s, c);
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

/// `--time`: a finite time code (USD has no NaN or infinite time code; a
/// stage read at one would show whichever sample the reader fell on).
fn finite_time(s: &str) -> Result<f64, String> {
    super::units::parse_numbers(s, "a time code").map(|[t]| t)
}
