//! Throughput across frames: the poses deformed in parallel on a rayon
//! pool, one `Deformer::frame` per task, in frames per second.

use std::sync::Mutex;
use std::time::Instant;

use curvenet_core::Deformer;
use rayon::prelude::*;

use super::inputs::solve;
use crate::cli::{CliError, CliResult};

/// Repetitions of each throughput measurement.
pub(super) const THROUGHPUT_REPEATS: usize = 3;

/// Frames per second deforming `jobs` frames (cycling over `inputs`) on a
/// rayon pool of `threads` threads, one `Deformer::frame` per task (each
/// takes a workspace from the deformer's pool; one untimed frame per
/// thread first, so that the pool holds one per thread), one output buffer
/// per thread.
pub(super) fn throughput(
    deformer: &Deformer,
    inputs: &[Vec<Option<&[[f64; 3]]>>],
    jobs: usize,
    threads: usize,
) -> CliResult<f64> {
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
