//! The one solve helper: every route that solves frames (frames, batches,
//! deform) goes through [`solve_frames`], which runs on the solve pool
//! holding the request's [`Admission`]: read the frames → validate each
//! against the binding → (batches) check the answer's size and reserve the
//! batch's memory → solve them with `curvenet_core::Deformer::frames`, in
//! groups of up to [`BATCH_FRAMES`] frames sharing one sweep of each
//! triangular solve (a batch's groups as many at once as it holds permits,
//! each group its own job on the pool) → record the metrics → build the answer.

use std::convert::Infallible;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::body::Bytes;

use crate::config::BATCH_FRAMES;
use crate::entry::Entry;
use crate::error::{Code, ServiceError};
use crate::extract::Admission;
use curvenet_schema::wire::FrameRequest;

use crate::frame::{self, Solved};
use crate::metrics::Metrics;
use crate::state::{AppState, BatchMemory, blocking};

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

/// Solves the frames `read` returns from `entry` and answers what `answer`
/// makes of them. `admission` is held until the answer is built.
///
/// One frame (`/frames`, `/deform`, the viewer; the interactive path) is
/// one job on the solve pool: read, check, `Deformer::frame`, answer.
///
/// A batch (`Numbering::Batch`) is read, checked and answered on tokio's
/// blocking threads (parsing and encoding a large batch take seconds that
/// are not solving), and solved on the pool a wave of groups at a time
/// (one group per permit the request holds), each group its own job. The
/// pool takes jobs first come, first served, so a frame posted while long
/// batches run waits for about one group of each, not for them; a batch
/// whose client goes away (this future is dropped) stops after its wave.
/// A batch holds `memory` (reserved for its parsed frames before it was
/// read, [`crate::frames::input_bound`]), made its full size once its frames are
/// read ([`batch_held_bytes`]: its frames, results and answer; waiting in
/// line for the rest), and returned beside the answer for the answer's body
/// to hold until it is sent ([`HeldBody`]).
pub(crate) async fn solve_frames<T: Send + 'static>(
    state: &AppState,
    admission: Admission,
    entry: Arc<Entry>,
    numbering: Numbering,
    memory: Option<BatchMemory>,
    read: impl FnOnce(&Entry) -> Result<Vec<FrameRequest>, ServiceError> + Send + 'static,
    answer: impl FnOnce(&Entry, Vec<Solved>) -> Result<T, ServiceError> + Send + 'static,
) -> Result<(T, Option<BatchMemory>), ServiceError> {
    let metrics = state.inner.metrics.clone();
    let parallel = admission.parallel();
    let _admission = admission;
    let Numbering::Batch { max_bytes, json } = numbering else {
        let (out, solved) = state
            .on_pool(move || {
                let frames = read(&entry)?;
                let [frame] = &frames[..] else {
                    return Err(ServiceError::internal(format!("one frame expected, {} read", frames.len())));
                };
                frame::validate(&entry, frame).map_err(|e| numbering.name(0, e))?;
                let solved = vec![frame::solve(&entry, frame).map_err(|e| numbering.name(0, e))?];
                record(&metrics, &solved);
                let solve_ms = solved[0].solve_ms;
                Ok((answer(&entry, solved)?, solve_ms))
            })
            .await?;
        let span = tracing::Span::current();
        span.record("solve_ms", solved);
        span.record("frames", 1);
        return Ok((out, memory));
    };
    let (frames, held) = {
        let entry = entry.clone();
        blocking(move || {
            let frames = read(&entry)?;
            for (i, f) in frames.iter().enumerate() {
                frame::validate(&entry, f).map_err(|e| numbering.name(i, e))?;
            }
            let answer = check_batch_size(&entry, &frames, max_bytes, json)?;
            let held = batch_held_bytes(&entry, &frames, answer);
            Ok((frames, held))
        })
        .await?
    };
    let memory = match memory {
        Some(mut m) => {
            m.resize(held).await?;
            m
        }
        None => state.batch_memory(held).await?,
    };
    let solved = solve_in_waves(state, &entry, frames, numbering, parallel).await?;
    let solve_ms: f64 = solved.iter().map(|s| s.solve_ms).sum();
    let n = solved.len();
    let out = blocking(move || answer(&entry, solved)).await?;
    let span = tracing::Span::current();
    span.record("solve_ms", solve_ms);
    span.record("frames", n);
    Ok((out, Some(memory)))
}

/// Counts solved frames in the metrics (a batch's as each group is done).
fn record(metrics: &Metrics, solved: &[Solved]) {
    for s in solved {
        metrics.solve_seconds.record(s.solve_ms / 1e3);
    }
    metrics.frames_solved.increment(solved.len() as u64);
}

/// A batch's frames in groups of up to [`BATCH_FRAMES`] (one multi-frame
/// solve each), no larger than an even share of the frames over the
/// `parallel` permits the request holds (so a small batch still spreads).
/// Each group is a job on the pool, queued `parallel` at a time (a wave),
/// the next wave once this one is done. Errors name the first failing frame
/// in order.
async fn solve_in_waves(
    state: &AppState,
    entry: &Arc<Entry>,
    frames: Vec<FrameRequest>,
    numbering: Numbering,
    parallel: usize,
) -> Result<Vec<Solved>, ServiceError> {
    let parallel = parallel.max(1);
    let n = frames.len();
    let size = if parallel > 1 { n.div_ceil(parallel) } else { BATCH_FRAMES }.clamp(1, BATCH_FRAMES);
    let frames = Arc::new(frames);
    let starts: Vec<usize> = (0..n).step_by(size).collect();
    let mut solved = Vec::with_capacity(n);
    for wave in starts.chunks(parallel) {
        let jobs: Vec<_> = wave
            .iter()
            .map(|&start| {
                let (frames, entry) = (frames.clone(), entry.clone());
                state.spawn_on_pool(move || {
                    let group = &frames[start..(start + size).min(frames.len())];
                    frame::solve_group(&entry, group).map_err(|(j, e)| numbering.name(start + j, e))
                })
            })
            .collect();
        for job in jobs {
            let group = job.await?;
            record(&state.inner.metrics, &group);
            solved.extend(group);
        }
    }
    Ok(solved)
}

/// What a batch holds until its answer is built, counted against
/// `--max-batch-memory`: its parsed frames (f64), its solved frames (f32:
/// 12 bytes a vertex, 48 with gradients) and its encoded answer (`answer`
/// bytes, [`check_batch_size`]). The request body is bounded apart
/// (`--body-limit`). At the other limits' defaults the largest batch (a
/// 256 MiB binary answer of frames that each carry a rest pose) holds
/// 24 + 12 + 12 bytes a vertex-frame for 22.4M vertex-frames: 1.07 GB.
fn batch_held_bytes(entry: &Entry, frames: &[FrameRequest], answer: u64) -> u64 {
    let v = entry.binding().n_vertices() as u64;
    let results: u64 = frames.iter().map(|f| v * if f.gradients { 48 } else { 12 }).sum();
    let inputs: u64 = frames.iter().map(|f| frame::held_bytes(f) as u64).sum();
    answer + results + inputs
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
/// Returns the answer's bytes.
fn check_batch_size(entry: &Entry, frames: &[FrameRequest], max: u64, json: bool) -> Result<u64, ServiceError> {
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
    Ok(bytes)
}

/// An answer's body that holds its batch's reservation of
/// `--max-batch-memory` until it is sent: written in chunks of
/// [`HeldBody::CHUNK`] bytes (slices of one buffer, freed when the last is
/// written), the reservation dropped with the last chunk or when the
/// connection goes away. A client that stops reading holds it until the
/// idle timeout closes its connection.
pub(crate) struct HeldBody {
    bytes: Bytes,
    memory: Option<BatchMemory>,
}

impl HeldBody {
    const CHUNK: usize = 1 << 20;

    pub(crate) fn new(bytes: Vec<u8>, memory: Option<BatchMemory>) -> Self {
        Self { bytes: Bytes::from(bytes), memory }
    }
}

impl http_body::Body for HeldBody {
    type Data = Bytes;
    type Error = Infallible;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, Infallible>>> {
        if self.bytes.is_empty() {
            self.memory = None;
            return Poll::Ready(None);
        }
        let n = self.bytes.len().min(Self::CHUNK);
        let chunk = self.bytes.split_to(n);
        if self.bytes.is_empty() {
            self.memory = None;
        }
        Poll::Ready(Some(Ok(http_body::Frame::data(chunk))))
    }

    fn is_end_stream(&self) -> bool {
        self.bytes.is_empty()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        http_body::SizeHint::with_exact(self.bytes.len() as u64)
    }
}
