//! The robustness corpus rows (unless `--no-corpus`): every stage in
//! `<fixtures>/corpus`, its first curvenet-deformed mesh bound and posed,
//! with how its segments were embedded and its warnings; and their text table.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::inputs::{build, load, pose, solve};
use super::measure::{max_distance, median, ms_since};
use super::ordering;
use crate::cli::{CliError, CliResult};

/// One corpus mesh: binding and solve medians, how its segments were
/// embedded, its warnings.
#[derive(Serialize)]
pub(super) struct CorpusBench {
    pub(super) mesh: String,
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
    pub(super) orderings: Option<ordering::OrderingComparison>,
}

/// The corpus stages (`<fixtures>/corpus/*.usd[ac]`), by name, sorted.
pub(super) fn corpus_files(dir: &Path) -> CliResult<Vec<(String, PathBuf)>> {
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

pub(super) fn bench_corpus_mesh(
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

/// The corpus table of the text report (nothing without corpus rows).
pub(super) fn text(corpus: &[CorpusBench], repeats: usize) -> String {
    let mut s = String::new();
    if !corpus.is_empty() {
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "Robustness corpus (fixtures/corpus; ms, medians of {} bindings and of the frames; paths: how segments were embedded)",
            repeats
        );
        let w = corpus.iter().map(|m| m.mesh.len()).max().unwrap_or(4).max(10);
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
        for m in corpus {
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
        for m in corpus {
            for warning in &m.warnings {
                let _ = writeln!(s, "{:<w$} warning {warning}", m.mesh);
            }
        }
    }
    s
}
