//! The bench's multi-frame figures (issue 19): frames of one mesh solved in
//! groups of K through `Deformer::frames` (one sweep of each triangular
//! solve per group), for K = 1, 2, 4, 8, 16, 32.
//!
//! Per K:
//! - **per frame** (`per_frame_ms`): one thread, the median over groups of
//!   the group's wall time over K; at least [`MIN_GROUPS`] groups and at
//!   least `--frames` frames, after one untimed group (the workspaces). Over
//!   `reference_ms`, the bench's memory-copy reference of the same run
//!   (`per_frame_over_reference`).
//! - **frames/s** (`frames_per_s`): all threads (`--threads`), groups of K
//!   spread over a rayon pool, one `Deformer::frames` per task; the median
//!   of 3 runs of `max(frames, 4 × K × threads)` frames (rounded up to whole
//!   groups), after an untimed run that gives every thread its workspaces.
//!
//! `batch_k` is the K with the most frames/s, `batch_frames_per_s` its
//! frames/s and `batch_over_reference` its per-frame time over `reference_ms`.
//!
//! `rest_batch`: the same figures for groups of [`REST_K`] frames that each
//! carry their own rest pose (a bake over skinning or cloth: knot tracking,
//! and rows and the Poisson right-hand side made frame by frame), beside
//! the projection-pose groups above.

use std::sync::Mutex;
use std::time::Instant;

use curvenet_core::{Deformer, Frame, FrameOut};
use rayon::prelude::*;
use serde::Serialize;

use super::{CliError, CliResult};

/// The group sizes measured.
pub(super) const BATCH_KS: [usize; 6] = [1, 2, 4, 8, 16, 32];
/// Fewest timed groups per K on one thread.
const MIN_GROUPS: usize = 5;
/// Repetitions of each all-threads run.
const REPEATS: usize = 3;
/// The group size of the rest-pose row (the bake's default group).
pub(super) const REST_K: usize = curvenet_core::DEFAULT_BATCH_FRAMES;

/// One group size's figures.
#[derive(Serialize, Clone, Copy)]
pub(super) struct BatchRow {
    pub k: usize,
    /// Median wall time of a group on one thread, over its frames.
    pub per_frame_ms: f64,
    pub per_frame_over_reference: f64,
    /// Frames per second, groups on all threads.
    pub frames_per_s: f64,
}

/// The figures of every K, and the best.
#[derive(Serialize)]
pub(super) struct BatchFigures {
    pub batch: Vec<BatchRow>,
    /// The K with the most frames per second (all threads).
    pub batch_k: usize,
    pub batch_frames_per_s: f64,
    /// `per_frame_ms` of `batch_k` over `reference_ms`.
    pub batch_over_reference: f64,
    /// Groups of [`REST_K`] frames with their own rest pose.
    pub rest_batch: BatchRow,
}

impl BatchFigures {
    /// `per_frame_over_reference` of groups of `k`, if `k` was timed.
    pub fn over_reference_at(&self, k: usize) -> Option<f64> {
        self.batch.iter().find(|r| r.k == k).map(|r| r.per_frame_over_reference)
    }
}

/// Measures every K of [`BATCH_KS`] on the bench's poses (`inputs`, cycled).
/// `rest`: the rest pose of the rest-pose row.
pub(super) fn bench_batches(
    deformer: &Deformer,
    inputs: &[Vec<Option<&[[f64; 3]]>>],
    rest: &[[f64; 3]],
    frames: usize,
    threads: usize,
    reference_ms: f64,
) -> CliResult<BatchFigures> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| CliError::Input(format!("cannot start {threads} bench threads: {e}")))?;
    let mut rows = Vec::with_capacity(BATCH_KS.len());
    for k in BATCH_KS {
        rows.push(measure(deformer, &pool, inputs, None, k, frames, threads, reference_ms)?);
    }
    let rest_batch = measure(deformer, &pool, inputs, Some(rest), REST_K, frames, threads, reference_ms)?;
    let best = rows.iter().copied().max_by(|a, b| a.frames_per_s.total_cmp(&b.frames_per_s)).expect("K values");
    Ok(BatchFigures {
        batch_k: best.k,
        batch_frames_per_s: best.frames_per_s,
        batch_over_reference: best.per_frame_over_reference,
        batch: rows,
        rest_batch,
    })
}

/// One group size's figures: groups of `k` of the poses, each frame with
/// the rest pose `rest` when given.
#[allow(clippy::too_many_arguments)]
fn measure(
    deformer: &Deformer,
    pool: &rayon::ThreadPool,
    inputs: &[Vec<Option<&[[f64; 3]]>>],
    rest: Option<&[[f64; 3]]>,
    k: usize,
    frames: usize,
    threads: usize,
    reference_ms: f64,
) -> CliResult<BatchRow> {
    let err = |source| CliError::Core { context: "bench frames in groups".into(), source };
    let n = deformer.n_vertices();
    let frame = |i: usize| Frame { posed: &inputs[i % inputs.len()], rest, ..Frame::default() };
    // One thread: groups of k consecutive poses (cycling).
    let groups = MIN_GROUPS.max(frames.div_ceil(k));
    let all: Vec<Frame<'_>> = (0..(groups + 1) * k).map(frame).collect();
    let mut buffers = vec![vec![[0.0; 3]; n]; k];
    let mut times = Vec::with_capacity(groups);
    for (g, group) in all.chunks(k).enumerate() {
        let mut outs: Vec<FrameOut<'_>> = buffers.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
        let t = Instant::now();
        deformer.frames(group, &mut outs).map_err(|e| err(e.error))?;
        if g > 0 {
            times.push(t.elapsed().as_secs_f64() * 1e3 / k as f64);
        }
    }
    let per_frame_ms = median(times);
    // All threads.
    let jobs = frames.max(4 * k * threads).div_ceil(k) * k;
    let all: Vec<Frame<'_>> = (0..jobs).map(frame).collect();
    let buffers: Vec<Mutex<Vec<Vec<[f64; 3]>>>> =
        (0..threads).map(|_| Mutex::new(vec![vec![[0.0; 3]; n]; k])).collect();
    let run = |frames: &[Frame<'_>]| {
        pool.install(|| {
            frames.par_chunks(k).with_max_len(1).try_for_each(|group| {
                let slot = rayon::current_thread_index().unwrap_or(0);
                let mut buffers = buffers[slot].lock().unwrap_or_else(|e| e.into_inner());
                let mut outs: Vec<FrameOut<'_>> =
                    buffers.iter_mut().map(|p| FrameOut { points: p, gradients: None }).collect();
                deformer.frames(group, &mut outs).map_err(|e| e.error)
            })
        })
    };
    run(&all[..(2 * k * threads).min(jobs)]).map_err(err)?;
    let mut rates = Vec::with_capacity(REPEATS);
    for _ in 0..REPEATS {
        let t = Instant::now();
        run(&all).map_err(err)?;
        rates.push(jobs as f64 / t.elapsed().as_secs_f64());
    }
    Ok(BatchRow {
        k,
        per_frame_ms,
        per_frame_over_reference: per_frame_ms / reference_ms.max(f64::MIN_POSITIVE),
        frames_per_s: median(rates),
    })
}

/// The text report's table: per mesh, per K, the per-frame time, its ratio
/// to the reference and the all-threads throughput (K = 1 is
/// `Deformer::frames` with one frame; the single-frame `Deformer::frame`
/// figures are the table above).
pub(super) fn text_table<'a>(
    meshes: impl Iterator<Item = (&'a str, f64, f64, &'a BatchFigures)>,
    threads: usize,
) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Frames in groups of K (Deformer::frames: one sweep of each triangular solve per group; per frame = median group \
         wall time / K on one thread; frames/s on {threads} thread(s); single = Deformer::frame)"
    );
    let _ = writeln!(s, "{:<10} {:>6} {:>14} {:>10} {:>12}", "mesh", "K", "ms per frame", "frame/ref", "frames/s");
    for (mesh, solve_ms, single_fps, b) in meshes {
        let _ = writeln!(s, "{:<10} {:>6} {:>14.3} {:>10} {:>12.1}", mesh, "single", solve_ms, "", single_fps);
        for r in &b.batch {
            let _ = writeln!(
                s,
                "{:<10} {:>6} {:>14.3} {:>10.2} {:>12.1}{}",
                mesh,
                r.k,
                r.per_frame_ms,
                r.per_frame_over_reference,
                r.frames_per_s,
                if r.k == b.batch_k { "  best" } else { "" }
            );
        }
        let r = &b.rest_batch;
        let _ = writeln!(
            s,
            "{:<10} {:>6} {:>14.3} {:>10.2} {:>12.1}  each frame with its own rest pose",
            mesh,
            format!("{}+rest", r.k),
            r.per_frame_ms,
            r.per_frame_over_reference,
            r.frames_per_s,
        );
    }
    s
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}
