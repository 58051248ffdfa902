//! `curvenet bench [--json] [--meshes hand_1k4,hand_22k,hand_94k] [--repeats N]
//! [--frames N] [--fixtures DIR] [--threads N] [--no-corpus] [--corpus-frames N]
//! [--orderings] [--export DIR] [--no-growth] [--growth-mesh M] [--growth-repeats N]
//! [--growth-frames N]`:
//! the paper's Table 1 (faces, vertices, knots, samples, cutting, factor and
//! per-frame solve times) on the hand fixtures, plus what is needed to read
//! those numbers, and a row per robustness-corpus mesh (`fixtures/corpus`).
//!
//! A benchmark, not a test: it never fails because a target is missed.
//!
//! Every binding is built as every caller builds one, by
//! `curvenet_core::Deformer::new` (one surface: validation, face planes and
//! the closest-point tree shared by the curvenet analysis and the binding),
//! and every timed frame is solved by `Deformer::frame`.
//!
//! Per hand mesh (`fixtures/hand/<name>.usda` or `.usdc`):
//!
//! - **Binding**, `--repeats` times (default 5): `Deformer::new`, whose own
//!   timings give the curvenet analysis (§3: sampling, intersections;
//!   `analysis_ms`) and the binding's stages (surface, cutting, assembly,
//!   factor). `binding_ms` is the wall time of the whole call less the
//!   analysis (what the targets are set on; the analysis is reported
//!   apart as it always was), `deformer_ms` the whole call;
//!   `binding_other_ms` is the part after the factorisation (per-corner
//!   right-hand sides, curvenet-vertex tables, blend shapes). Medians.
//! - **Frames**, `--frames` poses (default 50): frame 0 is the neutral pose;
//!   frame i rotates the control points distal to a plane across the fingers
//!   (55 % of the pool's extent along +y, the finger direction) about the
//!   x axis towards the palm (+z) by `60°·½(1 − cos 2πi/N)`, blended in over
//!   a band of 10 % of the extent with a smoothstep (a smooth, deterministic
//!   curl of every finger). Every frame runs through `Deformer::frame` (its
//!   workspace pool: allocation-free once warm) after one untimed warm-up
//!   frame; the median, min and max per frame are reported.
//! - **Where a frame goes**: `deform` cannot be split from outside, so
//!   its parts are timed on their own, right after each timed frame (so
//!   they see the same machine load), medians over the frames:
//!   `Binding::solve_in_place::<9>` and `::<3>` on fixed random right-hand
//!   sides of `n_unknowns` rows (`tri9_ms`, `tri3_ms`, `tri_share` of the
//!   frame), and the curvenet part of the frame through the public
//!   curvenet functions `deform` calls (`curvenet_eval_ms`: posed samples,
//!   scaled frames, per-side and per-slot gradients).
//!   `rest_of_frame_ms` = deform − the three: constraint rows, the two
//!   `B` products, per-face gradients and the Poisson right-hand side,
//!   output and finiteness checks.
//! - **Reference**: copying a `Vec<f64>` of `factor_nonzeros × 8` bytes
//!   twice (there and back), timed after each frame like the parts: a pure
//!   memory-bandwidth pass of the factor's size in the same run, so that
//!   runs on a noisy machine compare through `solve_over_reference` and
//!   `tri_over_reference` (a solve streams the factor's values twice,
//!   forward and backward, plus its u32 row indices).
//! - **Clocks**: every timing is wall clock; the frame parts and the whole
//!   binding are also measured in thread CPU time (`*_cpu_ms`, Linux), which
//!   leaves out time the thread spent preempted on a shared machine. Targets
//!   are judged on the wall-clock medians.
//! - **Throughput**: the poses deformed in parallel across frames on a rayon
//!   pool (`--threads`, default all cores), one `Deformer::frame` per task
//!   (each takes a workspace from the deformer's pool), against the same
//!   pool with one thread; medians of 3 runs of `max(frames, 8 × threads)` frames.
//! - **Frames in groups** (bench_batch.rs): the same poses through
//!   `Deformer::frames` in groups of K = 1, 2, 4, 8, 16, 32 (one sweep of
//!   each triangular solve per group): per-frame time on one thread over
//!   `reference_ms`, and frames/s on all threads; the best K by frames/s.
//! - **Corpus** (unless `--no-corpus`): every stage in `<fixtures>/corpus`,
//!   its first curvenet-deformed mesh bound `--repeats` times and
//!   `--corpus-frames` frames (default 10) of the same kind of pose solved:
//!   median binding and solve times, how the segments were embedded
//!   (straightest path, fallback path, inside one face, left out) and the
//!   binding's warnings.
//!
//! - **Orderings** (with `--orderings`): every hand's and corpus mesh's
//!   matrix factored with AMD and with METIS, alternating (`bench/ordering.rs`).
//! - **Export** (with `--export DIR`): every hand's system matrix, one
//!   frame's right-hand sides and solutions and a manifest (`bench/export.rs`).
//! - **Growth** (unless `--no-growth`; only when `--growth-mesh`, default
//!   hand_94k, is among `--meshes`): that hand subdivided 1-to-4 at run time
//!   and bound to the same curvenets (`bench/growth.rs`).
//! - **Memory**: `binding_bytes_per_vertex`, the binding's `heap_bytes` over
//!   the mesh's vertices.
//!
//! `--json` prints one object: `{"threads", "simd", "repeats", "frames", "meshes":
//! [...], "corpus": [...]}`, one entry per hand mesh with (at least) `mesh`,
//! `vertices`, `faces`, `knots`, `samples`, `cutting_ms`, `factor_ms`,
//! `solve_ms`, `binding_ms`, all the other measurements under their field
//! names (see `MeshBench`), `targets` (hand_22k and hand_94k: issue #5's
//! `solve_ms`, `solve_stretch_ms`, `binding_ms` and issue #19's `frame_ms`,
//! `batch_frames_per_s`, `group16_over_reference`, each with its `*_met`;
//! null for other meshes), `batch` (per K: `k`, `per_frame_ms`, `per_frame_over_reference`,
//! `frames_per_s`), `batch_k`, `batch_frames_per_s`, `batch_over_reference` and
//! `rest_batch` (the same figures for groups of 8 frames with their own rest
//! pose); one entry per corpus mesh (see `CorpusBench`). Times are milliseconds.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use curvenet_core::{CurvenetLayout, Deformer, Frame, Mat3};
use curvenet_core::{ScaledFrame, constraint_gradients_into, deformation_gradients_into, scaled_frames_into};
use rayon::prelude::*;
use serde::Serialize;

use super::{CliError, CliResult};

mod cage;
mod export;
mod growth;
mod inputs;
mod measure;
mod ordering;

use inputs::{MAX_ANGLE_DEG, TriSolve, build, load, pose};
use measure::{Lap, Series, Stopwatch, max_distance, median, ms_since, ratio};

/// Repetitions of each throughput measurement.
const THROUGHPUT_REPEATS: usize = 3;

#[derive(clap::Args)]
pub struct Args {
    /// Print one JSON object (`{"threads", "repeats", "frames", "meshes": [...]}`) instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Hand fixtures to measure (names in `<fixtures>/hand/`, comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "hand_1k4,hand_22k,hand_94k")]
    pub meshes: Vec<String>,
    /// Bindings per mesh (times are medians).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeats: u32,
    /// Timed frames per mesh (frame 0 is the neutral pose).
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
    /// The fixtures directory (relative to the current directory).
    #[arg(long, default_value = "fixtures")]
    pub fixtures: PathBuf,
    /// Threads of the parallel throughput run (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub threads: Option<u32>,
    /// Leave out the robustness corpus (`<fixtures>/corpus`).
    #[arg(long)]
    pub no_corpus: bool,
    /// Timed frames per corpus mesh.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub corpus_frames: u32,
    /// Also factor every mesh's matrix with AMD and with METIS and compare
    /// them (fill, ordering, factorisation and solve times; `bench/ordering.rs`).
    #[arg(long)]
    pub orderings: bool,
    /// Write every hand mesh's system matrix, one frame's right-hand sides
    /// and solutions and a manifest into DIR (`bench/export.rs`).
    #[arg(long, value_name = "DIR")]
    pub export: Option<PathBuf>,
    /// Leave out the growth row (the `--growth-mesh` subdivided 1-to-4; slow;
    /// only made when that mesh is among `--meshes`, as it is by default).
    #[arg(long)]
    pub no_growth: bool,
    /// The hand fixture the growth row subdivides (default hand_94k, left
    /// out when not among `--meshes`; named here, it must be).
    #[arg(long)]
    pub growth_mesh: Option<String>,
    /// Bindings of the growth mesh (times are medians).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub growth_repeats: u32,
    /// Timed frames of the growth mesh.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub growth_frames: u32,
    /// Leave out the coupled-cage rows (fixtures/shots/hand_caged's cage on every benched hand).
    #[arg(long)]
    pub no_cage: bool,
}

/// What `bench_mesh` does besides the bench proper.
struct Extra<'a> {
    orderings: bool,
    export: Option<&'a Path>,
    exported: Vec<export::Exported>,
    /// Every file the export wrote (or began), removed if the export fails.
    export_written: Vec<PathBuf>,
}

/// The pose `--export` writes: the finger curl at frame 1 of 4 (30°).
const EXPORT_FRAME: (usize, usize) = (1, 4);

#[derive(Serialize)]
struct Report {
    threads: usize,
    /// The vector unit the triangular sweeps ran on (`baseline`, `avx2`,
    /// `avx512`; `CURVENET_SIMD=baseline|avx2` caps it).
    simd: &'static str,
    repeats: usize,
    frames: usize,
    meshes: Vec<MeshBench>,
    corpus: Vec<CorpusBench>,
    /// The growth row (null with `--no-growth`).
    growth: Option<growth::GrowthBench>,
    /// The coupled cage's per-frame stages on every benched hand (empty with `--no-cage`).
    cage: Vec<cage::CageBench>,
}

/// One corpus mesh: binding and solve medians, how its segments were
/// embedded, its warnings.
#[derive(Serialize)]
struct CorpusBench {
    mesh: String,
    file: String,
    faces: usize,
    vertices: usize,
    samples: usize,
    segments: usize,
    repeats: usize,
    /// Median wall time of `Deformer::new` less its curvenet analysis.
    binding_ms: f64,
    analysis_ms: f64,
    /// Segments embedded by the straightest path, by the fallback (shortest
    /// path in a strip of faces), inside one face, and left out.
    straightest_paths: usize,
    fallback_paths: usize,
    chord_paths: usize,
    segments_left_out: usize,
    frames: usize,
    /// Median wall time of one `Deformer::frame`.
    solve_ms: f64,
    neutral_max_error: f64,
    /// The binding's warnings (`code: message`).
    warnings: Vec<String>,
    /// AMD against METIS on this binding's matrix (with `--orderings`).
    orderings: Option<ordering::OrderingComparison>,
}

#[derive(Serialize)]
struct MeshBench {
    mesh: String,
    file: String,
    // Table 1.
    faces: usize,
    vertices: usize,
    /// Curvenet control points that are spline endpoints (knot samples).
    knots: usize,
    samples: usize,
    cutting_ms: f64,
    factor_ms: f64,
    /// Median wall time of one `Binding::deform` (both solves and everything around them).
    solve_ms: f64,
    /// Whether the `*_cpu_ms` fields were measured (thread CPU time, Linux).
    cpu_clock: bool,
    // Sizes.
    control_points: usize,
    splines: usize,
    segments: usize,
    cut_vertices: usize,
    cut_faces: usize,
    unknowns: usize,
    constraints: usize,
    factor_nonzeros: usize,
    /// The factor's fill-reducing ordering (`amd` or `metis`).
    ordering: &'static str,
    /// `Binding::heap_bytes` of the binding, and per mesh vertex.
    binding_bytes: usize,
    binding_bytes_per_vertex: f64,
    // Binding.
    repeats: usize,
    load_ms: f64,
    analysis_ms: f64,
    surface_ms: f64,
    assembly_ms: f64,
    binding_other_ms: f64,
    /// `deformer_ms` less `analysis_ms`.
    binding_ms: f64,
    /// Wall time of the whole `Deformer::new`.
    deformer_ms: f64,
    /// Thread CPU time of `Deformer::new` (excludes time preempted; faer's factorisation runs on this thread).
    deformer_cpu_ms: Option<f64>,
    // Frames.
    frames: usize,
    max_angle_deg: f64,
    solve_min_ms: f64,
    solve_max_ms: f64,
    tri9_ms: f64,
    tri3_ms: f64,
    /// (tri9 + tri3) / solve.
    tri_share: f64,
    /// The curvenet part of a frame alone (samples, scaled frames, per-side
    /// and per-slot gradients), timed through the public curvenet functions.
    curvenet_eval_ms: f64,
    /// deform − tri9 − tri3 − curvenet_eval.
    rest_of_frame_ms: f64,
    /// The same posed frames with their own rest pose (the projection pose
    /// moved rigidly by 1% of the diagonal): the path of a bake over
    /// skinning or cloth, which warps the binding to the rest pose and
    /// builds the Poisson right-hand side face by face.
    rest_pose_frame_ms: f64,
    reference_bytes: usize,
    reference_ms: f64,
    solve_over_reference: f64,
    tri_over_reference: f64,
    // The same in thread CPU time (medians; null without a thread CPU clock).
    solve_cpu_ms: Option<f64>,
    tri9_cpu_ms: Option<f64>,
    tri3_cpu_ms: Option<f64>,
    tri_share_cpu: Option<f64>,
    curvenet_eval_cpu_ms: Option<f64>,
    rest_of_frame_cpu_ms: Option<f64>,
    reference_cpu_ms: Option<f64>,
    solve_over_reference_cpu: Option<f64>,
    threads: usize,
    serial_frames_per_s: f64,
    parallel_frames_per_s: f64,
    parallel_speedup: f64,
    // Sanity of the frames (relative to the mesh's bounding-box diagonal).
    neutral_max_error: f64,
    max_displacement: f64,
    warnings: Vec<String>,
    targets: Option<Targets>,
    /// Frames in groups of K (`batch`, `batch_k`, `batch_frames_per_s`, `batch_over_reference`; bench_batch.rs).
    #[serde(flatten)]
    batch: super::bench_batch::BatchFigures,
    /// AMD against METIS on this binding's matrix (with `--orderings`).
    orderings: Option<ordering::OrderingComparison>,
}

#[derive(Serialize, Clone, Copy)]
struct Targets {
    solve_ms: f64,
    solve_stretch_ms: f64,
    binding_ms: f64,
    solve_met: bool,
    solve_stretch_met: bool,
    binding_met: bool,
    /// Issue #19's: the single frame, the best group's frames per second
    /// on all threads, and a frame in a group of 16 over the copy reference.
    frame_ms: f64,
    frame_met: bool,
    batch_frames_per_s: f64,
    batch_met: bool,
    group16_over_reference: f64,
    group16_met: Option<bool>,
}

/// The growth row's mesh unless `--growth-mesh` names another.
const DEFAULT_GROWTH_MESH: &str = "hand_94k";

/// Issue #5's targets: (solve, stretch solve, binding) in ms.
fn targets_for(mesh: &str) -> Option<(f64, f64, f64)> {
    match mesh {
        "hand_22k" => Some((9.7, 5.0, 150.0)),
        "hand_94k" => Some((35.0, 20.0, 560.0)),
        _ => None,
    }
}

/// Issue #19's targets: (single frame ms, best group's frames/s on all
/// threads); a frame in a group of 16 is at most [`GROUP16_OVER_REFERENCE`]
/// × the copy reference on both meshes.
fn throughput_targets_for(mesh: &str) -> Option<(f64, f64)> {
    match mesh {
        "hand_22k" => Some((3.0, 1200.0)),
        "hand_94k" => Some((15.0, 250.0)),
        _ => None,
    }
}

const GROUP16_OVER_REFERENCE: f64 = 3.0;

pub fn run(args: &Args) -> CliResult {
    let dir = &args.fixtures;
    if !dir.is_dir() {
        let what = if dir.exists() { "is not a directory" } else { "not found" };
        return Err(CliError::Input(format!(
            "fixtures directory `{}` {what} (run from the repository root or pass --fixtures DIR)",
            dir.display()
        )));
    }
    if let Some((k, m)) = args.meshes.iter().enumerate().find(|(k, m)| args.meshes[..*k].contains(m)) {
        return Err(CliError::Input(format!("--meshes names {m} twice (the second time as mesh {})", k + 1)));
    }
    let growth_mesh = args.growth_mesh.clone().unwrap_or_else(|| DEFAULT_GROWTH_MESH.to_string());
    if let Some(g) = &args.growth_mesh
        && !args.meshes.contains(g)
    {
        return Err(CliError::Input(format!(
            "--growth-mesh {g} is not among --meshes ({}): the growth row's frame is judged against that mesh's",
            args.meshes.join(",")
        )));
    }
    if let Some(export) = &args.export {
        export::prepare(export)?;
    }
    let files = args.meshes.iter().map(|m| fixture_file(dir, m)).collect::<CliResult<Vec<_>>>()?;
    let threads = super::check_threads("--threads", args.threads.map_or(0, |t| t as usize))?;
    let (repeats, frames) = (args.repeats as usize, args.frames as usize);
    let corpus = if args.no_corpus { Vec::new() } else { corpus_files(dir)? };
    // The growth row grows a mesh benched in this run (its frame is the
    // reference of the row's frame target): none when that mesh is not.
    let grow = !args.no_growth && args.meshes.contains(&growth_mesh);
    let growth_file = if grow { Some(fixture_file(dir, &growth_mesh)?) } else { None };
    let mut report = Report {
        threads,
        simd: curvenet_core::Simd::detect().name(),
        repeats,
        frames,
        meshes: Vec::new(),
        corpus: Vec::new(),
        growth: None,
        cage: Vec::new(),
    };
    let mut extra = Extra {
        orderings: args.orderings,
        export: args.export.as_deref(),
        exported: Vec::new(),
        export_written: Vec::new(),
    };
    let mut hands = || -> CliResult {
        for (name, file) in args.meshes.iter().zip(&files) {
            if !args.json {
                eprintln!("curvenet bench: {name}: {repeats} bindings, {frames} frames…");
            }
            report.meshes.push(bench_mesh(name, file, repeats, frames, threads, &mut extra)?);
        }
        if let Some(dir) = &args.export {
            export::write_manifest(dir, &extra.exported, &mut extra.export_written)?;
        }
        Ok(())
    };
    if let Err(e) = hands() {
        // No export without its manifest: what this run wrote goes.
        for path in &extra.export_written {
            let _ = std::fs::remove_file(path);
        }
        return Err(e);
    }
    if !args.no_cage {
        if !args.json {
            eprintln!("curvenet bench: the coupled cage on every hand…");
        }
        let hands: Vec<(&str, &Path)> =
            args.meshes.iter().map(String::as_str).zip(files.iter().map(|f| f.as_path())).collect();
        report.cage = cage::bench_cage(dir, &hands, repeats)?;
    }
    let corpus_frames = args.corpus_frames as usize;
    for (name, file) in &corpus {
        if !args.json {
            eprintln!("curvenet bench: corpus {name}: {repeats} bindings, {corpus_frames} frames…");
        }
        report.corpus.push(bench_corpus_mesh(name, file, repeats, corpus_frames, args.orderings)?);
    }
    if let Some(file) = &growth_file {
        let name = &growth_mesh;
        let (g_repeats, g_frames) = (args.growth_repeats as usize, args.growth_frames as usize);
        if !args.json {
            eprintln!("curvenet bench: growth: {name} subdivided 1-to-4, {g_repeats} bindings, {g_frames} frames…");
        }
        let base_solve = report.meshes.iter().find(|m| &m.mesh == name).map(|m| m.solve_ms);
        report.growth = Some(growth::bench_growth(name, file, g_repeats, g_frames, base_solve, args.orderings)?);
    }
    if args.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| CliError::Input(e.to_string()))?;
        println!("{text}");
    } else {
        print!("{}", text_report(&report));
        let rows: Vec<(&str, &ordering::OrderingComparison)> = report
            .meshes
            .iter()
            .filter_map(|m| m.orderings.as_ref().map(|o| (m.mesh.as_str(), o)))
            .chain(report.corpus.iter().filter_map(|m| m.orderings.as_ref().map(|o| (m.mesh.as_str(), o))))
            .chain(report.growth.iter().filter_map(|g| g.orderings.as_ref().map(|o| ("growth", o))))
            .collect();
        print!("{}", ordering::text(&rows, repeats, frames));
        if let Some(g) = &report.growth {
            print!("{}", growth::text(g));
        }
        if !report.cage.is_empty() {
            print!("{}", cage::text(&report.cage));
        }
    }
    Ok(())
}

fn fixture_file(dir: &Path, mesh: &str) -> CliResult<PathBuf> {
    if mesh.is_empty() || mesh.contains(['/', '\\']) {
        return Err(CliError::Input(format!("--meshes: `{mesh}` is not a hand fixture name (e.g. hand_22k)")));
    }
    for ext in ["usda", "usdc", "usd"] {
        let p = dir.join("hand").join(format!("{mesh}.{ext}"));
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(CliError::Input(format!(
        "--meshes: no fixture `{mesh}` in {} (.usda, .usdc or .usd)",
        dir.join("hand").display()
    )))
}

/// The corpus stages (`<fixtures>/corpus/*.usd[ac]`), by name, sorted.
fn corpus_files(dir: &Path) -> CliResult<Vec<(String, PathBuf)>> {
    let corpus = dir.join("corpus");
    let entries = std::fs::read_dir(&corpus).map_err(|e| {
        CliError::Input(format!("{}: {e} (pass --no-corpus to leave the corpus out)", corpus.display()))
    })?;
    let mut out = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| CliError::Input(format!("{}: {e}", corpus.display())))?.path();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if matches!(ext, "usda" | "usdc" | "usd")
            && let Some(stem) = path.file_stem().and_then(|s| s.to_str())
        {
            out.push((stem.to_string(), path.clone()));
        }
    }
    out.sort();
    Ok(out)
}

/// Solves one frame through `Deformer::frame` into `out`.
fn solve(deformer: &Deformer, posed: &[Option<&[[f64; 3]]>], out: &mut [[f64; 3]]) -> curvenet_core::Result<()> {
    deformer.frame(&Frame { posed, ..Frame::default() }, out, None)
}

fn bench_corpus_mesh(
    name: &str,
    file: &Path,
    repeats: usize,
    frames: usize,
    orderings: bool,
) -> CliResult<CorpusBench> {
    let (mesh, nets, _) = load(file)?;
    let context = format!("{} {}", file.display(), mesh.path);
    let (mut binding_ms, mut analysis_ms) = (Vec::new(), Vec::new());
    let mut bound = None;
    for _ in 0..repeats {
        drop(bound.take());
        let (deformer, lap) = build(&mesh, &nets, &context)?;
        let analysis = deformer.timings().analysis_ms;
        analysis_ms.push(analysis);
        binding_ms.push(lap.wall_ms - analysis);
        bound = Some(deformer);
    }
    let deformer = bound.ok_or_else(|| CliError::Input("--repeats must be at least 1".into()))?;
    let points = &mesh.projection_points;
    let diagonal = curvenet_core::bounding_box_diagonal(points).max(f64::MIN_POSITIVE);
    let pools: Vec<Vec<Vec<[f64; 3]>>> = (0..frames).map(|i| pose(&nets, i, frames)).collect();
    let mut out = vec![[0.0; 3]; deformer.n_vertices()];
    let frame_err = |i: usize| {
        let context = context.clone();
        move |source| CliError::Core { context: format!("{context}, bench frame {i}"), source }
    };
    let inputs: Vec<Vec<Option<&[[f64; 3]]>>> =
        pools.iter().map(|f| f.iter().map(|p| Some(p.as_slice())).collect()).collect();
    solve(&deformer, &inputs[0], &mut out).map_err(frame_err(0))?; // warm-up: the workspace
    let neutral_max_error = max_distance(&out, points) / diagonal;
    let mut solve_ms = Vec::with_capacity(frames);
    for (i, input) in inputs.iter().enumerate() {
        let t = Instant::now();
        solve(&deformer, input, &mut out).map_err(frame_err(i))?;
        solve_ms.push(ms_since(t));
    }
    let b = deformer.binding();
    let stats = b.stats();
    let orderings = if orderings { Some(ordering::compare(b, repeats, frames)?) } else { None };
    Ok(CorpusBench {
        mesh: name.to_string(),
        file: file.display().to_string(),
        faces: stats.mesh_faces,
        vertices: stats.mesh_vertices,
        samples: stats.samples,
        segments: stats.segments,
        repeats,
        binding_ms: median(binding_ms),
        analysis_ms: median(analysis_ms),
        straightest_paths: stats.embedding.straightest,
        fallback_paths: stats.embedding.fallback,
        chord_paths: stats.embedding.chord,
        segments_left_out: stats.embedding.disconnected,
        frames,
        solve_ms: median(solve_ms),
        neutral_max_error,
        warnings: b
            .warnings()
            .iter()
            .map(|w| {
                let wire = curvenet_schema::wire::Warning::from(w);
                format!("{}: {}", wire.code, wire.message)
            })
            .collect(),
        orderings,
    })
}

fn bench_mesh(
    name: &str,
    file: &Path,
    repeats: usize,
    frames: usize,
    threads: usize,
    extra: &mut Extra,
) -> CliResult<MeshBench> {
    // Load (once; timed for context).
    let (mesh, nets, load_ms) = load(file)?;
    let context = format!("{} {}", file.display(), mesh.path);
    let points = &mesh.projection_points;

    // Bindings, through the one constructor.
    let (mut analysis, mut surface, mut cutting, mut assembly, mut factor, mut other, mut binding_wall) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut total = Series::default();
    let mut bound = None;
    for _ in 0..repeats {
        drop(bound.take());
        let (deformer, lap) = build(&mesh, &nets, &context)?;
        let t = deformer.timings();
        let tm = t.binding;
        analysis.push(t.analysis_ms);
        surface.push(tm.surface_ms);
        cutting.push(tm.cutting_ms);
        assembly.push(tm.assembly_ms);
        factor.push(tm.factor_ms);
        let binding_lap = lap.wall_ms - t.analysis_ms;
        binding_wall.push(binding_lap);
        other.push(binding_lap - (tm.surface_ms + tm.cutting_ms + tm.assembly_ms + tm.factor_ms));
        total.push(lap);
        bound = Some(deformer);
    }
    let deformer = bound.ok_or_else(|| CliError::Input("--repeats must be at least 1".into()))?;
    let binding = deformer.binding();
    let layouts = binding.layouts();
    let stats = binding.stats();
    let knots: usize = layouts.iter().map(|l| l.sampling().n_knots()).sum();

    // Poses.
    let pools: Vec<Vec<Vec<[f64; 3]>>> = (0..frames).map(|i| pose(&nets, i, frames)).collect();
    let inputs: Vec<Vec<Option<&[[f64; 3]]>>> =
        pools.iter().map(|frame| frame.iter().map(|p| Some(p.as_slice())).collect()).collect();
    let diagonal = curvenet_core::bounding_box_diagonal(points).max(f64::MIN_POSITIVE);

    // Frames, one after another through `Deformer::frame` (the first, untimed,
    // makes the workspace it then reuses). Right after each timed frame (so
    // that all see the same machine load) the curvenet part of its pose, the
    // two triangular solves on random right-hand sides and the copy
    // reference are timed too.
    let ctx: &str = &context;
    let frame_err = |i: usize| move |source| CliError::Core { context: format!("{ctx}, bench frame {i}"), source };
    let mut out = vec![[0.0; 3]; deformer.n_vertices()];
    solve(&deformer, &inputs[0], &mut out).map_err(frame_err(0))?;
    let neutral_max_error = max_distance(&out, points) / diagonal;
    let mut eval = CurvenetEval::new(layouts);
    let mut tri9 = TriSolve::<9>::new(binding.n_unknowns(), 9);
    let mut tri3 = TriSolve::<3>::new(binding.n_unknowns(), 3);
    let mut reference = CopyReference::new(stats.factor_nonzeros);
    eval.time(layouts, &pools[0]).map_err(frame_err(0))?; // warm-ups
    tri9.time(binding);
    tri3.time(binding);
    reference.time();
    let (mut deform_t, mut eval_t, mut tri9_t, mut tri3_t, mut reference_t) =
        (Series::default(), Series::default(), Series::default(), Series::default(), Series::default());
    let mut max_displacement = 0.0f64;
    let shift = 0.01 * diagonal;
    let rest_pose: Vec<[f64; 3]> = points.iter().map(|p| [p[0] + shift, p[1], p[2]]).collect();
    let mut rest_t = Series::default();
    for (i, (input, pose)) in inputs.iter().zip(&pools).enumerate() {
        let clock = Stopwatch::start();
        solve(&deformer, input, &mut out).map_err(frame_err(i))?;
        deform_t.push(clock.stop());
        max_displacement = max_displacement.max(max_distance(&out, points) / diagonal);
        let clock = Stopwatch::start();
        deformer
            .frame(&Frame { posed: input, rest: Some(&rest_pose), ..Frame::default() }, &mut out, None)
            .map_err(frame_err(i))?;
        rest_t.push(clock.stop());
        eval_t.push(eval.time(layouts, pose).map_err(frame_err(i))?);
        tri9_t.push(tri9.time(binding));
        tri3_t.push(tri3.time(binding));
        reference_t.push(reference.time());
    }

    // AMD against METIS, and the export, on this binding.
    let orderings = if extra.orderings { Some(ordering::compare(binding, repeats, frames)?) } else { None };
    if let Some(dir) = extra.export {
        let (index, of) = EXPORT_FRAME;
        let pools = pose(&nets, index, of);
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| Some(p.as_slice())).collect();
        let angle_deg = MAX_ANGLE_DEG * 0.5 * (1.0 - (std::f64::consts::TAU * index as f64 / of as f64).cos());
        let frame = export::ExportedFrame { index, frames: of, angle_deg };
        extra.exported.push(export::export_mesh(dir, name, binding, &posed, frame, &mut extra.export_written)?);
    }

    // Throughput across frames.
    let jobs = frames.max(8 * threads);
    let serial =
        median((0..THROUGHPUT_REPEATS).map(|_| throughput(&deformer, &inputs, jobs, 1)).collect::<CliResult<_>>()?);
    let parallel = median(
        (0..THROUGHPUT_REPEATS).map(|_| throughput(&deformer, &inputs, jobs, threads)).collect::<CliResult<_>>()?,
    );

    let solve_ms = deform_t.wall();
    let binding_ms = median(binding_wall);
    let (tri9_ms, tri3_ms, eval_ms, reference_ms) = (tri9_t.wall(), tri3_t.wall(), eval_t.wall(), reference_t.wall());
    let batch = super::bench_batch::bench_batches(&deformer, &inputs, &rest_pose, frames, threads, reference_ms)?;
    let solve_cpu = deform_t.cpu();
    let tri_cpu = tri9_t.cpu().zip(tri3_t.cpu()).map(|(a, b)| a + b);
    let rest_cpu = solve_cpu.zip(tri_cpu).zip(eval_t.cpu()).map(|((s, t), e)| s - t - e);
    let group16 = batch.over_reference_at(16);
    let targets = targets_for(name).zip(throughput_targets_for(name)).map(|((s, st, b), (f, fps))| Targets {
        solve_ms: s,
        solve_stretch_ms: st,
        binding_ms: b,
        solve_met: solve_ms <= s,
        solve_stretch_met: solve_ms <= st,
        binding_met: binding_ms <= b,
        frame_ms: f,
        frame_met: solve_ms <= f,
        batch_frames_per_s: fps,
        batch_met: batch.batch_frames_per_s >= fps,
        group16_over_reference: GROUP16_OVER_REFERENCE,
        group16_met: group16.map(|g| g <= GROUP16_OVER_REFERENCE),
    });
    Ok(MeshBench {
        mesh: name.to_string(),
        file: file.display().to_string(),
        faces: stats.mesh_faces,
        vertices: stats.mesh_vertices,
        knots,
        samples: stats.samples,
        cutting_ms: median(cutting),
        factor_ms: median(factor),
        solve_ms,
        cpu_clock: solve_cpu.is_some(),
        control_points: nets.iter().map(|n| n.pool.len()).sum(),
        splines: nets.iter().map(|n| n.splines.len()).sum(),
        segments: stats.segments,
        cut_vertices: stats.cut_vertices,
        cut_faces: stats.cut_faces,
        unknowns: stats.unknowns,
        constraints: stats.constraints,
        factor_nonzeros: stats.factor_nonzeros,
        ordering: binding.factor().ordering().name(),
        binding_bytes: binding.heap_bytes(),
        binding_bytes_per_vertex: binding.heap_bytes() as f64 / stats.mesh_vertices.max(1) as f64,
        repeats,
        load_ms,
        analysis_ms: median(analysis),
        surface_ms: median(surface),
        assembly_ms: median(assembly),
        binding_other_ms: median(other),
        binding_ms,
        deformer_ms: total.wall(),
        deformer_cpu_ms: total.cpu(),
        frames,
        max_angle_deg: MAX_ANGLE_DEG,
        solve_min_ms: deform_t.wall_min(),
        solve_max_ms: deform_t.wall_max(),
        tri9_ms,
        tri3_ms,
        rest_pose_frame_ms: rest_t.wall(),
        tri_share: ratio(tri9_ms + tri3_ms, solve_ms),
        curvenet_eval_ms: eval_ms,
        rest_of_frame_ms: solve_ms - tri9_ms - tri3_ms - eval_ms,
        reference_bytes: stats.factor_nonzeros * 8,
        reference_ms,
        solve_over_reference: ratio(solve_ms, reference_ms),
        tri_over_reference: ratio(tri9_ms + tri3_ms, reference_ms),
        solve_cpu_ms: solve_cpu,
        tri9_cpu_ms: tri9_t.cpu(),
        tri3_cpu_ms: tri3_t.cpu(),
        tri_share_cpu: tri_cpu.zip(solve_cpu).map(|(t, s)| ratio(t, s)),
        curvenet_eval_cpu_ms: eval_t.cpu(),
        rest_of_frame_cpu_ms: rest_cpu,
        reference_cpu_ms: reference_t.cpu(),
        solve_over_reference_cpu: solve_cpu.zip(reference_t.cpu()).map(|(s, r)| ratio(s, r)),
        threads,
        serial_frames_per_s: serial,
        parallel_frames_per_s: parallel,
        parallel_speedup: ratio(parallel, serial),
        neutral_max_error,
        max_displacement,
        warnings: binding.warnings().iter().map(|w| w.to_string()).collect(),
        targets,
        batch,
        orderings,
    })
}

/// Copying `len` f64 there and back (two passes): the memory-bandwidth reference.
struct CopyReference {
    a: Vec<f64>,
    b: Vec<f64>,
}

impl CopyReference {
    fn new(len: usize) -> Self {
        let len = len.max(1);
        let a: Vec<f64> = (0..len).map(|i| i as f64 * 0.5 + 1.0).collect();
        let b = a.clone(); // both touched
        Self { a, b }
    }

    fn time(&mut self) -> Lap {
        let clock = Stopwatch::start();
        black_box(&mut self.b).copy_from_slice(black_box(&self.a));
        black_box(&mut self.a).copy_from_slice(black_box(&self.b));
        black_box((&self.a, &self.b));
        clock.stop()
    }
}

/// The curvenet part of a frame, as `Binding::deform` runs it: posed
/// samples, scaled frames, per-side deformation gradients, per-slot gradients.
struct CurvenetEval {
    samples: Vec<Vec<[f64; 3]>>,
    frames: Vec<Vec<[ScaledFrame; 2]>>,
    gradients: Vec<Vec<[Mat3; 2]>>,
    slots: Vec<Vec<Mat3>>,
}

impl CurvenetEval {
    fn new(layouts: &[CurvenetLayout]) -> Self {
        Self {
            samples: layouts.iter().map(|l| vec![[0.0; 3]; l.n_samples()]).collect(),
            frames: layouts.iter().map(|l| vec![[ScaledFrame::default(); 2]; l.n_segments()]).collect(),
            gradients: layouts.iter().map(|l| vec![[[[0.0; 3]; 3]; 2]; l.n_segments()]).collect(),
            slots: layouts.iter().map(|l| vec![[[0.0; 3]; 3]; l.constraints().len()]).collect(),
        }
    }

    fn time(&mut self, layouts: &[CurvenetLayout], pools: &[Vec<[f64; 3]>]) -> curvenet_core::Result<Lap> {
        let clock = Stopwatch::start();
        for (k, layout) in layouts.iter().enumerate() {
            layout.sampling().samples_into(&pools[k], &mut self.samples[k])?;
            scaled_frames_into(layout, &self.samples[k], &mut self.frames[k])?;
            deformation_gradients_into(layout, layout.neutral_frames(), &self.frames[k], &mut self.gradients[k])?;
            constraint_gradients_into(layout.constraints(), &self.gradients[k], &mut self.slots[k])?;
        }
        black_box(&self.slots);
        Ok(clock.stop())
    }
}

/// Frames per second deforming `jobs` frames (cycling over `inputs`) on a
/// rayon pool of `threads` threads, one `Deformer::frame` per task (each
/// takes a workspace from the deformer's pool; one untimed frame per
/// thread first, so that the pool holds one per thread), one output buffer
/// per thread.
fn throughput(deformer: &Deformer, inputs: &[Vec<Option<&[[f64; 3]]>>], jobs: usize, threads: usize) -> CliResult<f64> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| CliError::Input(format!("cannot start {threads} bench threads: {e}")))?;
    let buffers: Vec<Mutex<Vec<[f64; 3]>>> =
        (0..threads).map(|_| Mutex::new(vec![[0.0; 3]; deformer.n_vertices()])).collect();
    let run = |jobs: usize| {
        pool.install(|| {
            (0..jobs).into_par_iter().with_max_len(1).try_for_each(|k| {
                let slot = rayon::current_thread_index().unwrap_or(0);
                let mut out = buffers[slot].lock().unwrap_or_else(|e| e.into_inner());
                solve(deformer, &inputs[k % inputs.len()], &mut out)
            })
        })
    };
    // Untimed: the deformer's pool gets a workspace for (about) every thread.
    run(4 * threads).map_err(|source| CliError::Core { context: "parallel bench frames".into(), source })?;
    let t = Instant::now();
    run(jobs).map_err(|source| CliError::Core { context: "parallel bench frames".into(), source })?;
    Ok(jobs as f64 / t.elapsed().as_secs_f64())
}

fn text_report(r: &Report) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let w = r.meshes.iter().map(|m| m.mesh.len()).max().unwrap_or(4).max(10);
    let _ = writeln!(
        s,
        "curvenet bench: medians of {} bindings and {} frames per mesh (frame 0 neutral, then a finger curl up to {}°); {} thread(s) for throughput; triangular sweeps on {}",
        r.repeats, r.frames, MAX_ANGLE_DEG, r.threads, r.simd
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "Table 1 (paper columns)");
    let _ = writeln!(
        s,
        "{:<w$} {:>7} {:>8} {:>6} {:>8} {:>11} {:>10} {:>15}",
        "mesh", "faces", "vertices", "knots", "samples", "cutting ms", "factor ms", "solve ms/frame"
    );
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>7} {:>8} {:>6} {:>8} {:>11.2} {:>10.2} {:>15.3}",
            m.mesh, m.faces, m.vertices, m.knots, m.samples, m.cutting_ms, m.factor_ms, m.solve_ms
        );
    }
    let _ = writeln!(
        s,
        "  paper (Xeon E5-2699, CHOLMOD; its Factor = assembly + factorisation; 448 knots): Hand Tri 2896/1459 verts: 33.4 / 11.8 / 1.4 ms; Hand Subd 10447 verts: 51.1 / 46.2 / 6.3 ms; Hand Dense 93991 verts: 153.7 / 408.2 / 35.4 ms"
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Binding (ms, medians of Deformer::new; stages as its timings report them; total = its wall time less the analysis; deformer = its wall time, cpu = its thread CPU time; other = after the factorisation)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:>8} {:>8} {:>9} {:>8} {:>7} {:>8} {:>9} {:>9} {:>14} {:>9}",
        "mesh",
        "surface",
        "cutting",
        "assembly",
        "factor",
        "other",
        "total",
        "deformer",
        "cpu",
        "| analysis §3",
        "load USD"
    );
    for m in &r.meshes {
        let cpu = m.deformer_cpu_ms.map_or_else(|| "-".to_string(), |c| format!("{c:.2}"));
        let _ = writeln!(
            s,
            "{:<w$} {:>8.2} {:>8.2} {:>9.2} {:>8.2} {:>7.2} {:>8.2} {:>9.2} {:>9} {:>14.2} {:>9.1}",
            m.mesh,
            m.surface_ms,
            m.cutting_ms,
            m.assembly_ms,
            m.factor_ms,
            m.binding_other_ms,
            m.binding_ms,
            m.deformer_ms,
            cpu,
            m.analysis_ms,
            m.load_ms
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "Sizes");
    let _ = writeln!(
        s,
        "{:<w$} {:>8} {:>9} {:>9} {:>11} {:>10} {:>12} {:>9} {:>9} {:>14}",
        "mesh",
        "splines",
        "segments",
        "cut faces",
        "cut verts",
        "unknowns",
        "constraints",
        "L nnz",
        "ordering",
        "binding B/vert"
    );
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>8} {:>9} {:>9} {:>11} {:>10} {:>12} {:>9} {:>9} {:>14.0}",
            m.mesh,
            m.splines,
            m.segments,
            m.cut_faces,
            m.cut_vertices,
            m.unknowns,
            m.constraints,
            m.factor_nonzeros,
            m.ordering,
            m.binding_bytes_per_vertex
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Per frame (ms, medians; deform = Deformer::frame (its pooled workspace reused); timed right after each frame: tri9/tri3 = solve_in_place::<9>/<3>"
    );
    let _ = writeln!(
        s,
        "           on random right-hand sides, curve = the curvenet part (samples, frames, gradients), ref = copying factor-nnz × 8 bytes there and back;"
    );
    let _ = writeln!(
        s,
        "           rest = deform − tri9 − tri3 − curve: constraint rows, B products, per-face gradients, output; cpu = thread CPU time, without preemption)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:<5} {:>8} {:>8} {:>8} {:>7} {:>7} {:>9} {:>7} {:>7} {:>7} {:>10} {:>8}",
        "mesh",
        "clock",
        "deform",
        "min",
        "max",
        "tri9",
        "tri3",
        "tri share",
        "curve",
        "rest",
        "ref",
        "deform/ref",
        "tri/ref"
    );
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:<5} {:>8.3} {:>8.3} {:>8.3} {:>7.3} {:>7.3} {:>8.0}% {:>7.3} {:>7.3} {:>7.3} {:>10.1} {:>8.1}",
            m.mesh,
            "wall",
            m.solve_ms,
            m.solve_min_ms,
            m.solve_max_ms,
            m.tri9_ms,
            m.tri3_ms,
            100.0 * m.tri_share,
            m.curvenet_eval_ms,
            m.rest_of_frame_ms,
            m.reference_ms,
            m.solve_over_reference,
            m.tri_over_reference
        );
        if let (Some(d), Some(t9), Some(t3), Some(share), Some(curve), Some(rest), Some(reference)) = (
            m.solve_cpu_ms,
            m.tri9_cpu_ms,
            m.tri3_cpu_ms,
            m.tri_share_cpu,
            m.curvenet_eval_cpu_ms,
            m.rest_of_frame_cpu_ms,
            m.reference_cpu_ms,
        ) {
            let _ = writeln!(
                s,
                "{:<w$} {:<5} {:>8.3} {:>8} {:>8} {:>7.3} {:>7.3} {:>8.0}% {:>7.3} {:>7.3} {:>7.3} {:>10.1} {:>8.1}",
                "",
                "cpu",
                d,
                "",
                "",
                t9,
                t3,
                100.0 * share,
                curve,
                rest,
                reference,
                ratio(d, reference),
                ratio(t9 + t3, reference)
            );
        }
    }
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} a frame with its own rest pose (bakes over skinning): {:.3} ms ({:.2}× the frame above)",
            m.mesh,
            m.rest_pose_frame_ms,
            m.rest_pose_frame_ms / m.solve_ms
        );
    }
    let _ = writeln!(s);
    let _ =
        writeln!(s, "Throughput across frames (frames/s; Deformer::frame on every thread, workspaces from its pool)");
    let _ = writeln!(s, "{:<w$} {:>10} {:>14} {:>8}", "mesh", "1 thread", format!("{} threads", r.threads), "speedup");
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} {:>10.1} {:>14.1} {:>7.2}×",
            m.mesh, m.serial_frames_per_s, m.parallel_frames_per_s, m.parallel_speedup
        );
    }
    let _ = writeln!(s);
    s += &super::bench_batch::text_table(
        r.meshes.iter().map(|m| (m.mesh.as_str(), m.solve_ms, m.parallel_frames_per_s, &m.batch)),
        r.threads,
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "Frames (relative to the bounding-box diagonal)");
    for m in &r.meshes {
        let _ = writeln!(
            s,
            "{:<w$} neutral pose reproduces the mesh to {:.1e}; largest displacement {:.3}",
            m.mesh, m.neutral_max_error, m.max_displacement
        );
        for warning in &m.warnings {
            let _ = writeln!(s, "{:<w$} warning: {warning}", "");
        }
    }
    let with_targets: Vec<&MeshBench> = r.meshes.iter().filter(|m| m.targets.is_some()).collect();
    if !with_targets.is_empty() {
        let _ = writeln!(s);
        let _ = writeln!(s, "Targets of the issues (informative; the bench never fails on them)");
        let met = |b: bool| if b { "met" } else { "NOT met" };
        for m in with_targets {
            let t = m.targets.expect("filtered");
            let _ = writeln!(
                s,
                "{:<w$} solve {:.2} ms ≤ {} ms: {} (stretch ≤ {} ms: {}); binding {:.1} ms ≤ {} ms: {}",
                m.mesh,
                m.solve_ms,
                t.solve_ms,
                met(t.solve_met),
                t.solve_stretch_ms,
                met(t.solve_stretch_met),
                m.binding_ms,
                t.binding_ms,
                met(t.binding_met)
            );
            let group16 = m.batch.over_reference_at(16);
            let _ = writeln!(
                s,
                "{:<w$} issue #19: frame {:.2} ms ≤ {} ms: {}; best group {:.0} frames/s ≥ {}: {}; group of 16 {} ≤ {}× the copy reference: {}",
                "",
                m.solve_ms,
                t.frame_ms,
                met(t.frame_met),
                m.batch.batch_frames_per_s,
                t.batch_frames_per_s,
                met(t.batch_met),
                group16.map_or("not run".to_string(), |g| format!("{g:.1}×")),
                t.group16_over_reference,
                t.group16_met.map_or("not run", met),
            );
            if let (Some(sc), Some(dc)) = (m.solve_cpu_ms, m.deformer_cpu_ms) {
                let _ = writeln!(
                    s,
                    "{:<w$} (judged on wall-clock medians; in thread CPU time: solve {sc:.2} ms, Deformer::new {dc:.1} ms of which analysis {:.1} ms wall)",
                    "", m.analysis_ms
                );
            }
        }
    }
    if !r.corpus.is_empty() {
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "Robustness corpus (fixtures/corpus; ms, medians of {} bindings and of the frames; paths: how segments were embedded)",
            r.repeats
        );
        let w = r.corpus.iter().map(|m| m.mesh.len()).max().unwrap_or(4).max(10);
        let _ = writeln!(
            s,
            "{:<w$} {:>8} {:>8} {:>9} {:>10} {:>9} {:>12} {:>9} {:>9} {:>9} {:>9}",
            "mesh",
            "vertices",
            "segments",
            "binding",
            "analysis",
            "solve",
            "straightest",
            "fallback",
            "in face",
            "left out",
            "warnings"
        );
        for m in &r.corpus {
            let _ = writeln!(
                s,
                "{:<w$} {:>8} {:>8} {:>9.1} {:>10.1} {:>9.2} {:>12} {:>9} {:>9} {:>9} {:>9}",
                m.mesh,
                m.vertices,
                m.segments,
                m.binding_ms,
                m.analysis_ms,
                m.solve_ms,
                m.straightest_paths,
                m.fallback_paths,
                m.chord_paths,
                m.segments_left_out,
                m.warnings.len()
            );
        }
        for m in &r.corpus {
            for warning in &m.warnings {
                let _ = writeln!(s, "{:<w$} warning {warning}", m.mesh);
            }
        }
    }
    s
}
