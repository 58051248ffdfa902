//! What `curvenet serve` is configured with: [`Config`], its defaults, the
//! connection limits and timeouts, and the [`Baker`] the command line
//! supplies for `POST /v1/bake`. The bottom of the service's layers:
//! it imports nothing from the service but the work limits.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use curvenet_core::Cancel;

use crate::limits::WorkLimits;

/// Frames of one request solved together (`Deformer::frames`): the bake's
/// default group size (core's measured default).
pub(crate) const BATCH_FRAMES: usize = curvenet_core::DEFAULT_BATCH_FRAMES;

/// Default cache size: 2 GiB of bindings (measured: the 22k-vertex hand holds 77 MB, the 94k one about 300 MB).
pub const DEFAULT_CACHE_BYTES: u64 = 2 << 30;
/// Default body limit: 256 MiB (a JSON batch of 100k-vertex frames is large).
pub const DEFAULT_BODY_LIMIT: usize = 256 << 20;
/// Default solve permits: frames running or queued for a core at once.
pub const DEFAULT_MAX_SOLVES: usize = 64;
/// Default drain timeout at shutdown.
pub const DEFAULT_DRAIN_TIMEOUT: Duration = Duration::from_secs(30);
/// Default longest wait for a solve permit when all are taken.
pub const DEFAULT_QUEUE_TIMEOUT: Duration = Duration::from_secs(2);
/// Default largest answer of a batch, in bytes of f32 data.
pub const DEFAULT_MAX_BATCH_BYTES: u64 = 256 << 20;
/// Default `Config::max_batch_memory`: 1.5 GiB held by batches in flight
/// together. The largest batch the other defaults let in (a 256 MiB binary
/// answer, with a rest pose per frame) holds about 1.07 GB (see
/// `pool::batch_held_bytes`); so one always fits, and with smaller ones a
/// few run at once.
pub const DEFAULT_MAX_BATCH_MEMORY: u64 = 1536 << 20;
/// Default `Config::max_bake_bytes`: 1 GiB of points (about 950 frames of
/// the 94k hand); a bake's peak memory is a few times that (the layer is
/// built from them at the end).
pub const DEFAULT_MAX_BAKE_BYTES: u64 = 1 << 30;

/// Everything `curvenet serve` can be configured with.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bytes of bindings the cache keeps (estimated; least recently used evicted first).
    pub cache_bytes: u64,
    /// Largest request body, bytes (413 beyond).
    pub body_limit: usize,
    /// Solves (frames, bindings, bakes) admitted at once, running or
    /// waiting for a solve thread; beyond it requests get 503 + Retry-After.
    pub max_solves: usize,
    /// Threads of the frame-solve pool (0: one per core).
    pub solve_threads: usize,
    /// How long requests in flight may finish after a shutdown signal.
    pub drain_timeout: Duration,
    /// Bearer token required on every route but /healthz and /readyz.
    pub token: Option<String>,
    /// Directories `POST /v1/bake` may read from and write to.
    pub bake_roots: Vec<PathBuf>,
    /// Limits on the work of one binding (density, segments, time).
    pub work: WorkLimits,
    /// Longest a request waits, in line, for a solve permit before 503.
    pub queue_timeout: Duration,
    /// Largest answer of one batch: frames × vertices × 12 bytes (48 with gradients).
    pub max_batch_bytes: u64,
    /// Bytes all batches in flight may hold together (their frames, results
    /// and answers): a batch waits in line for its share up to the queue
    /// timeout (then 503); one larger than all of it is refused (422).
    pub max_batch_memory: u64,
    /// Largest bake: the points it holds until it writes, frames × vertices × 12 bytes.
    pub max_bake_bytes: u64,
    /// Connection limits and timeouts (headers, bodies, idle keep-alive).
    pub connections: ConnectionLimits,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            cache_bytes: DEFAULT_CACHE_BYTES,
            body_limit: DEFAULT_BODY_LIMIT,
            max_solves: DEFAULT_MAX_SOLVES,
            solve_threads: 0,
            drain_timeout: DEFAULT_DRAIN_TIMEOUT,
            token: None,
            bake_roots: Vec::new(),
            work: WorkLimits::default(),
            queue_timeout: DEFAULT_QUEUE_TIMEOUT,
            max_batch_bytes: DEFAULT_MAX_BATCH_BYTES,
            max_batch_memory: DEFAULT_MAX_BATCH_MEMORY,
            max_bake_bytes: DEFAULT_MAX_BAKE_BYTES,
            connections: Default::default(),
        }
    }
}

/// Default time a client has to send a request head once it started.
pub const DEFAULT_HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// Default time an idle connection is kept open.
pub const DEFAULT_IDLE_TIMEOUT: Duration = Duration::from_secs(60);
/// Default time a body may stall, and the grace before its rate is checked.
pub const DEFAULT_BODY_TIMEOUT: Duration = Duration::from_secs(30);
/// Default slowest average body rate accepted after the grace, bytes/s.
pub const DEFAULT_BODY_MIN_RATE: u64 = 16 << 10;
/// Default cap on connections open at once.
pub const DEFAULT_MAX_CONNECTIONS: usize = 512;

/// Connection limits and timeouts (see the module docs and `extract::read_body`).
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// A request head must arrive within this time of its first byte.
    pub header_timeout: Duration,
    /// A connection with no request being handled and no byte moving is closed after this.
    pub idle_timeout: Duration,
    /// A request body may not stall longer than this; after it, its average
    /// rate must be at least `body_min_rate`.
    pub body_timeout: Duration,
    /// Slowest average rate of a body (bytes/s) once `body_timeout` has passed.
    pub body_min_rate: u64,
    /// Connections open at once; beyond, 503 and close.
    pub max_connections: usize,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            header_timeout: DEFAULT_HEADER_TIMEOUT,
            idle_timeout: DEFAULT_IDLE_TIMEOUT,
            body_timeout: DEFAULT_BODY_TIMEOUT,
            body_min_rate: DEFAULT_BODY_MIN_RATE,
            max_connections: DEFAULT_MAX_CONNECTIONS,
        }
    }
}

/// One bake, with checked, canonical paths.
#[derive(Debug, Clone)]
pub struct BakeJob {
    pub stage: PathBuf,
    pub output: PathBuf,
    /// `A-B` or `A`, as the bake command takes it.
    pub frames: Option<String>,
    /// The canonical bake roots: every layer and asset the stage opens
    /// (sublayers, references, payloads) must resolve inside one.
    pub roots: Vec<PathBuf>,
    /// Largest `frames × vertices × 12` bytes of points the bake may hold
    /// (`--max-bake-bytes`): over it, [`BakeFailure::Limit`] before any work.
    pub max_points_bytes: u64,
    /// Raised when the request goes away (its client disconnected) or at the
    /// drain deadline: the baker stops at its next chunk of frames, writing
    /// nothing.
    pub cancel: Cancel,
}

/// Why a bake failed.
#[derive(Debug, Clone)]
pub enum BakeFailure {
    /// Bad input (the stage breaks the contract, a bad frame range, ...): 422.
    Input(String),
    /// Worth retrying (an I/O failure): 503.
    Retry(String),
    /// The stage opens a layer or asset outside the roots: 403 `path_forbidden`.
    Forbidden(String),
    /// Over `BakeJob::max_points_bytes`: 422 `limit_exceeded`.
    Limit(String),
    /// Stopped through `BakeJob::cancel`.
    Cancelled,
}

/// Runs a bake to completion (blocking).
/// Bakes a checked job; returns the bake's warnings (each naming the stage
/// or prim it is about), which the answer carries.
pub type Baker = Arc<dyn Fn(&BakeJob) -> Result<Vec<String>, BakeFailure> + Send + Sync>;
