//! One hand mesh benched (`MeshBench`, a row of every table): its
//! bindings, its frames and the parts of each frame timed apart, the copy
//! reference, throughput across frames, frames in groups, and, with the
//! flags, its orderings and its export.

use std::path::{Path, PathBuf};

use curvenet_core::Frame;
use serde::Serialize;

use super::export;
use super::frame_parts::{CopyReference, CurvenetEval};
use super::inputs::{MAX_ANGLE_DEG, TriSolve, build, load, pose, solve};
use super::measure::{Series, Stopwatch, max_distance, median, ratio};
use super::ordering;
use super::stored;
use super::targets::{self, Targets};
use super::throughput::{THROUGHPUT_REPEATS, throughput};
use crate::cli::bench_batch;
use crate::cli::{CliError, CliResult};

/// What `bench_mesh` does besides the bench proper.
pub(super) struct Extra<'a> {
    pub(super) orderings: bool,
    pub(super) export: Option<&'a Path>,
    pub(super) exported: Vec<export::Exported>,
    /// Every file the export wrote (or began), removed if the export fails.
    pub(super) export_written: Vec<PathBuf>,
}

/// The pose `--export` writes: the finger curl at frame 1 of 4 (30°).
pub(super) const EXPORT_FRAME: (usize, usize) = (1, 4);

#[derive(Serialize)]
pub(super) struct MeshBench {
    pub(super) mesh: String,
    pub(super) file: String,
    // Table 1.
    pub(super) faces: usize,
    pub(super) vertices: usize,
    /// Curvenet control points that are spline endpoints (knot samples).
    pub(super) knots: usize,
    pub(super) samples: usize,
    pub(super) cutting_ms: f64,
    pub(super) factor_ms: f64,
    /// Median wall time of one `Binding::deform` (both solves and everything around them).
    pub(super) solve_ms: f64,
    /// Whether the `*_cpu_ms` fields were measured (thread CPU time, Linux).
    pub(super) cpu_clock: bool,
    // Sizes.
    pub(super) control_points: usize,
    pub(super) splines: usize,
    pub(super) segments: usize,
    pub(super) cut_vertices: usize,
    pub(super) cut_faces: usize,
    pub(super) unknowns: usize,
    pub(super) constraints: usize,
    pub(super) factor_nonzeros: usize,
    /// The factor's fill-reducing ordering (`amd` or `metis`).
    pub(super) ordering: &'static str,
    /// `Binding::heap_bytes` of the binding, and per mesh vertex.
    pub(super) binding_bytes: usize,
    pub(super) binding_bytes_per_vertex: f64,
    // Binding.
    pub(super) repeats: usize,
    pub(super) load_ms: f64,
    pub(super) analysis_ms: f64,
    pub(super) surface_ms: f64,
    pub(super) assembly_ms: f64,
    pub(super) binding_other_ms: f64,
    /// The deformer written in the store's format and read back (`bench/stored.rs`).
    pub(super) stored: stored::StoredBench,
    /// `deformer_ms` less `analysis_ms`.
    pub(super) binding_ms: f64,
    /// Wall time of the whole `Deformer::new`.
    pub(super) deformer_ms: f64,
    /// Thread CPU time of `Deformer::new` (excludes time preempted; faer's factorisation runs on this thread).
    pub(super) deformer_cpu_ms: Option<f64>,
    // Frames.
    pub(super) frames: usize,
    pub(super) max_angle_deg: f64,
    pub(super) solve_min_ms: f64,
    pub(super) solve_max_ms: f64,
    pub(super) tri9_ms: f64,
    pub(super) tri3_ms: f64,
    /// (tri9 + tri3) / solve.
    pub(super) tri_share: f64,
    /// The curvenet part of a frame alone (samples, scaled frames, per-side
    /// and per-slot gradients), timed through the public curvenet functions.
    pub(super) curvenet_eval_ms: f64,
    /// deform − tri9 − tri3 − curvenet_eval.
    pub(super) rest_of_frame_ms: f64,
    /// The same posed frames with their own rest pose (the projection pose
    /// moved rigidly by 1% of the diagonal): the path of a bake over
    /// skinning or cloth, which warps the binding to the rest pose and
    /// builds the Poisson right-hand side face by face.
    pub(super) rest_pose_frame_ms: f64,
    pub(super) reference_bytes: usize,
    pub(super) reference_ms: f64,
    pub(super) solve_over_reference: f64,
    pub(super) tri_over_reference: f64,
    // The same in thread CPU time (medians; null without a thread CPU clock).
    pub(super) solve_cpu_ms: Option<f64>,
    pub(super) tri9_cpu_ms: Option<f64>,
    pub(super) tri3_cpu_ms: Option<f64>,
    pub(super) tri_share_cpu: Option<f64>,
    pub(super) curvenet_eval_cpu_ms: Option<f64>,
    pub(super) rest_of_frame_cpu_ms: Option<f64>,
    pub(super) reference_cpu_ms: Option<f64>,
    pub(super) solve_over_reference_cpu: Option<f64>,
    pub(super) threads: usize,
    pub(super) serial_frames_per_s: f64,
    pub(super) parallel_frames_per_s: f64,
    pub(super) parallel_speedup: f64,
    // Sanity of the frames (relative to the mesh's bounding-box diagonal).
    pub(super) neutral_max_error: f64,
    pub(super) max_displacement: f64,
    pub(super) warnings: Vec<String>,
    pub(super) targets: Option<Targets>,
    /// Frames in groups of K (`batch`, `batch_k`, `batch_frames_per_s`, `batch_over_reference`; bench_batch.rs).
    #[serde(flatten)]
    pub(super) batch: bench_batch::BatchFigures,
    /// AMD against METIS on this binding's matrix (with `--orderings`).
    pub(super) orderings: Option<ordering::OrderingComparison>,
}

pub(super) fn bench_mesh(
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
    let batch = bench_batch::bench_batches(&deformer, &inputs, &rest_pose, frames, threads, reference_ms)?;
    let solve_cpu = deform_t.cpu();
    let tri_cpu = tri9_t.cpu().zip(tri3_t.cpu()).map(|(a, b)| a + b);
    let rest_cpu = solve_cpu.zip(tri_cpu).zip(eval_t.cpu()).map(|((s, t), e)| s - t - e);
    let targets = targets::judge(name, solve_ms, binding_ms, &batch);
    let stored = {
        let pools = pose(&nets, EXPORT_FRAME.0, EXPORT_FRAME.1);
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| Some(p.as_slice())).collect();
        stored::measure(&deformer, total.wall(), repeats, &posed)?
    };
    Ok(MeshBench {
        stored,
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
