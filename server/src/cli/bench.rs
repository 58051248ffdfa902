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
//! Per hand mesh (`fixtures/hand/<name>.usda` or `.usdc`; `bench/hand.rs`, its
//! text tables in `bench/tables.rs`, the issues' targets in `bench/targets.rs`):
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
//! - **Corpus** (unless `--no-corpus`; `bench/corpus.rs`): every stage in `<fixtures>/corpus`,
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

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{CliError, CliResult};

mod cage;
mod corpus;
mod export;
mod frame_parts;
mod growth;
mod hand;
mod inputs;
mod measure;
mod ordering;
mod stored;
mod tables;
mod targets;
mod throughput;

use corpus::{CorpusBench, bench_corpus_mesh, corpus_files};
use hand::{Extra, MeshBench, bench_mesh};

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

/// The growth row's mesh unless `--growth-mesh` names another.
const DEFAULT_GROWTH_MESH: &str = "hand_94k";

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

/// The text report: the hand rows' tables, then the corpus table.
fn text_report(r: &Report) -> String {
    let mut s = tables::text(&r.meshes, r.repeats, r.frames, r.threads, r.simd);
    s += &corpus::text(&r.corpus, r.repeats);
    s
}
