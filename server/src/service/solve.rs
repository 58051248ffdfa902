//! The one solve helper: every route that solves frames (frames, batches,
//! deform) goes through [`solve_frames`], which runs on the solve pool
//! holding the request's [`Admission`]: read the frames → validate each
//! against the binding → (batches) check the answer's size → solve them
//! with `curvenet_core::Deformer::frames`, in groups of up to
//! [`BATCH_FRAMES`] frames sharing one sweep of each triangular solve (a
//! batch's groups as many at once as it holds permits) → record the metrics → build the answer.

use std::sync::Arc;

use rayon::prelude::*;

use crate::cache::Entry;
use crate::error::{Code, ServiceError};
use crate::extract::Admission;
use crate::frames::{self, Frame, Solved};
use crate::state::AppState;

/// Frames of one request solved together (`Deformer::frames`): the bake's
/// default group size (core's measured default).
pub(crate) const BATCH_FRAMES: usize = curvenet_core::DEFAULT_BATCH_FRAMES;

/// How the frames of a request are named in its errors.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Numbering {
    /// One frame, named by nothing (`/frames`).
    One,
    /// One frame, named `name: ` (`/deform`: `frame`).
    Named(&'static str),
    /// A batch: `frames[i]: ` and `details.frame`; its answer (JSON or
    /// binary) may hold at most `max_bytes` (`--max-batch-bytes`).
    Batch { max_bytes: u64, json: bool },
}

impl Numbering {
    fn name(self, i: usize, e: ServiceError) -> ServiceError {
        match self {
            Numbering::One => e,
            Numbering::Named(name) => e.context(name),
            Numbering::Batch { .. } => e.in_frame(i),
        }
    }
}

/// Solves the frames `read` returns from `entry`, on the solve pool, and
/// answers what `answer` makes of them (also on the pool: encoding a large
/// batch is work too). `admission` is held until the answer is built.
pub(crate) async fn solve_frames<T: Send + 'static>(
    state: &AppState,
    admission: Admission,
    entry: Arc<Entry>,
    numbering: Numbering,
    read: impl FnOnce(&Entry) -> Result<Vec<Frame>, ServiceError> + Send + 'static,
    answer: impl FnOnce(&Entry, Vec<Solved>) -> Result<T, ServiceError> + Send + 'static,
) -> Result<T, ServiceError> {
    let metrics = state.inner.metrics.clone();
    let (out, n, solve_ms) = state
        .on_pool(move || {
            let parallel = admission.parallel();
            let _admission = admission;
            let frames = read(&entry)?;
            for (i, f) in frames.iter().enumerate() {
                frames::validate(&entry, f).map_err(|e| numbering.name(i, e))?;
            }
            if let Numbering::Batch { max_bytes, json } = numbering {
                check_batch_size(&entry, &frames, max_bytes, json)?;
            }
            let solved: Vec<Solved> = if frames.len() == 1 {
                // One frame (the interactive path): Deformer::frame.
                vec![frames::solve(&entry, &frames[0]).map_err(|e| numbering.name(0, e))?]
            } else {
                // Groups of up to BATCH_FRAMES frames (one multi-frame solve
                // each), spread over the permits the request holds: no larger
                // than an even share of the frames, so a small batch still
                // spreads. Errors name the first failing frame in order.
                let size = if parallel > 1 { frames.len().div_ceil(parallel) } else { BATCH_FRAMES };
                let size = size.clamp(1, BATCH_FRAMES);
                let solve = |(g, group): (usize, &[Frame])| {
                    frames::solve_group(&entry, group).map_err(|(j, e)| numbering.name(g * size + j, e))
                };
                let groups: Vec<Vec<Solved>> = if parallel > 1 {
                    let results: Vec<Result<Vec<Solved>, ServiceError>> =
                        frames.par_chunks(size).enumerate().map(solve).collect();
                    results.into_iter().collect::<Result<_, _>>()?
                } else {
                    frames.chunks(size).enumerate().map(solve).collect::<Result<_, _>>()?
                };
                groups.into_iter().flatten().collect()
            };
            for s in &solved {
                metrics.solve_seconds.record(s.solve_ms / 1e3);
            }
            metrics.frames_solved.increment(solved.len() as u64);
            let solve_ms: f64 = solved.iter().map(|s| s.solve_ms).sum();
            let n = solved.len();
            Ok((answer(&entry, solved)?, n, solve_ms))
        })
        .await?;
    let span = tracing::Span::current();
    span.record("solve_ms", solve_ms);
    span.record("frames", n);
    Ok(out)
}

/// Bytes per vertex a batch answer is counted at: binary f32 (a point 12,
/// its gradient 36), and JSON, where serde_json writes an f32 in at most 15
/// characters (`-1.2345678e-38`) plus a separator: a point `[x,y,z],` at
/// most 50, a gradient's nine numbers and brackets at most 150.
const BINARY_BYTES: (u64, u64) = (12, 36);
const JSON_BYTES: (u64, u64) = (50, 150);

/// Refuses a batch whose answer would hold more than `max` bytes (frames ×
/// vertices × the bytes per vertex of the answer's form, gradients
/// included) before solving it: the answer, unlike the request, is not
/// bounded by the body limit, and a JSON answer is about four times a
/// binary one.
fn check_batch_size(entry: &Entry, frames: &[Frame], max: u64, json: bool) -> Result<(), ServiceError> {
    let v = entry.binding().n_vertices() as u64;
    let (point, gradient) = if json { JSON_BYTES } else { BINARY_BYTES };
    let bytes: u64 = frames.iter().map(|f| v * if f.gradients { point + gradient } else { point }).sum();
    if bytes > max {
        return Err(ServiceError::new(
            Code::LimitExceeded,
            format!(
                "the batch's answer would hold {bytes} bytes ({} frames of {v} vertices), more than this server's \
                 limit of {max} (--max-batch-bytes, CURVENET_MAX_BATCH_BYTES); split it",
                frames.len()
            ),
        ));
    }
    Ok(())
}
