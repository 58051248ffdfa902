//! The service's configuration and its shared state: a cheap-to-clone handle.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::cache::BindingCache;
use crate::config::{Baker, Config};
use crate::error::{Code, ServiceError};
use crate::jobs::Jobs;
use crate::metrics::Metrics;

/// Threads a solve pool of `configured` threads has (0: one per core, as
/// rayon counts them).
fn resolved_solve_threads(configured: usize) -> usize {
    match configured {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
}

/// Requests that may wait in line for a solve permit, per permit.
pub const MAX_LINE_PER_SOLVE: usize = 4;

/// The shared state: a handle, cheap to clone.
#[derive(Clone)]
pub struct AppState {
    pub(crate) inner: Arc<Inner>,
}

pub(crate) struct Inner {
    pub config: Config,
    /// Canonical bake roots.
    pub bake_roots: Vec<PathBuf>,
    pub baker: Option<Baker>,
    pub cache: BindingCache,
    pub permits: Arc<Semaphore>,
    /// `max_batch_memory` in KiB, one permit each ([`AppState::batch_memory`]).
    pub batch_memory: Arc<Semaphore>,
    /// KiB of `batch_memory` granted now (the metric).
    pub batch_kib_held: std::sync::atomic::AtomicUsize,
    /// Batches admitted at once, and the permits they hold: half of
    /// `max_solves` ([`AppState::batch_slot`], [`AppState::spare_permits`]).
    pub batch_slots: Arc<Semaphore>,
    /// One batch at a time between its first share of `batch_memory` and its
    /// full share ([`AppState::batch_gate`]).
    pub batch_gate: Arc<Semaphore>,
    pub pool: rayon::ThreadPool,
    pub metrics: Arc<Metrics>,
    pub token_hash: Option<blake3::Hash>,
    pub draining: AtomicBool,
    /// Bindings being computed, cancellable.
    pub jobs: Arc<Jobs>,
    /// Bakes running (`POST /v1/bake`), apart from the bindings so that the
    /// binding metrics count bindings only; cancelled alike at the drain
    /// deadline.
    pub bakes: Arc<Jobs>,
    /// Requests waiting in line for a solve permit.
    pub waiting: std::sync::atomic::AtomicUsize,
    /// Stages opened in the viewer (`serve --open-stage`), by index.
    pub viewer_stages: std::sync::RwLock<Vec<Arc<crate::viewer::stage::ViewerStage>>>,
}

impl AppState {
    /// Builds the state. Fails when a bake root does not exist or the solve
    /// pool cannot start.
    pub fn new(config: Config, baker: Option<Baker>) -> std::io::Result<Self> {
        Self::with_store(config, baker, Arc::new(Metrics::new()), None)
    }

    /// Builds the state over the binding store at `location` (a directory
    /// or an `s3://` URL, at most `max_bytes`; see stored.rs): bindings
    /// missing from memory are read from it, and bindings built here are
    /// written to it. Fails when the store cannot be opened (named).
    pub async fn open(
        config: Config,
        baker: Option<Baker>,
        location: &str,
        max_bytes: Option<u64>,
    ) -> std::io::Result<Self> {
        let metrics = Arc::new(Metrics::new());
        let store = crate::store::BindingStore::open(location, max_bytes, metrics.clone())
            .await
            // The store's error names the store; kept whole (`get_ref`) so a caller can tell
            // a configuration mistake (`StoreError::is_config`) from an outage.
            .map_err(std::io::Error::other)?
            // A stored file larger than the cache holds a binding that cannot be cached.
            .with_max_blob_bytes(config.cache_bytes);
        let keep = resolved_solve_threads(config.solve_threads);
        let stored = crate::stored::StoredBindings::new(Arc::new(store), metrics.clone(), keep);
        Self::with_store(config, baker, metrics, Some(stored))
    }

    fn with_store(
        config: Config,
        baker: Option<Baker>,
        metrics: Arc<Metrics>,
        stored: Option<crate::stored::StoredBindings>,
    ) -> std::io::Result<Self> {
        let bake_roots = config
            .bake_roots
            .iter()
            .map(|r| {
                std::fs::canonicalize(r)
                    .map_err(|e| std::io::Error::new(e.kind(), format!("bake root {}: {e}", r.display())))
            })
            .collect::<std::io::Result<Vec<_>>>()?;
        let cache = BindingCache::new(config.cache_bytes, metrics.clone(), stored);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.solve_threads)
            .thread_name(|i| format!("curvenet-solve-{i}"))
            .build()
            .map_err(std::io::Error::other)?;
        Ok(Self {
            inner: Arc::new(Inner {
                permits: Arc::new(Semaphore::new(config.max_solves.min(Semaphore::MAX_PERMITS))),
                batch_memory: Arc::new(Semaphore::new(budget_kib(config.max_batch_memory) as usize)),
                batch_kib_held: Default::default(),
                batch_slots: Arc::new(Semaphore::new(batch_slots(config.max_solves))),
                batch_gate: Arc::new(Semaphore::new(1)),
                token_hash: config.token.as_deref().map(|t| blake3::hash(t.as_bytes())),
                config,
                bake_roots,
                baker,
                cache,
                pool,
                metrics,
                draining: AtomicBool::new(false),
                jobs: Arc::default(),
                bakes: Arc::default(),
                waiting: Default::default(),
                viewer_stages: Default::default(),
            }),
        })
    }

    pub fn config(&self) -> &Config {
        &self.inner.config
    }

    /// Marks the service as shutting down (`/readyz` answers 503).
    pub fn set_draining(&self) {
        self.inner.draining.store(true, Ordering::SeqCst);
    }

    pub fn is_draining(&self) -> bool {
        self.inner.draining.load(Ordering::SeqCst)
    }

    /// Solve permits held right now (work running or queued).
    pub fn solves_in_flight(&self) -> usize {
        self.inner.config.max_solves.min(Semaphore::MAX_PERMITS).saturating_sub(self.inner.permits.available_permits())
    }

    /// Takes one solve permit. When every permit is taken the request waits
    /// in line (first come, first served: tokio's semaphore is fair) for at
    /// most the queue timeout, with at most [`MAX_LINE_PER_SOLVE`] ×
    /// `max_solves` requests in line; beyond either it answers `saturated`.
    pub(crate) async fn permit(&self) -> Result<OwnedSemaphorePermit, ServiceError> {
        let inner = &self.inner;
        if let Ok(p) = inner.permits.clone().try_acquire_owned() {
            return Ok(p);
        }
        // Counted in line until this future ends, or is dropped with a
        // request whose client went away while it waited.
        let line = InLine::join(&inner.waiting);
        if line.ahead >= MAX_LINE_PER_SOLVE * inner.config.max_solves {
            return Err(self.saturated());
        }
        self.wait_in_line(&inner.permits, 1, |_| self.saturated_message()).await
    }

    /// Reserves `bytes` of `--max-batch-memory` for a batch until the guard
    /// is dropped (see [`BatchMemory::resize`] to change it). When the others
    /// in flight hold too much of it, the batch waits in line (first come,
    /// first served) at most the queue timeout, then `saturated`; a batch
    /// larger than all of it is `limit_exceeded`.
    pub(crate) async fn batch_memory(&self, bytes: u64) -> Result<BatchMemory, ServiceError> {
        let permit = self.reserve_batch_memory(bytes).await?;
        Ok(BatchMemory::new(self, permit))
    }

    async fn reserve_batch_memory(&self, bytes: u64) -> Result<OwnedSemaphorePermit, ServiceError> {
        let max = self.inner.config.max_batch_memory;
        let need = kib(bytes);
        if need > budget_kib(max) {
            return Err(too_large_for_batch_memory(bytes, max));
        }
        self.wait_in_line(&self.inner.batch_memory, need, |waited| {
            format!(
                "the batches in flight hold this server's memory for batches ({max} bytes, --max-batch-memory, \
                 CURVENET_MAX_BATCH_MEMORY) and this one, about {bytes} bytes, waited {waited:.1} s for its share; \
                 retry after the Retry-After delay, or send smaller batches"
            )
        })
        .await
    }

    /// A batch's first share, before its frames are parsed: `bytes` (its
    /// body and a bound on its parsed frames), at most the whole budget (the
    /// real size is known once parsed), taken through the batch gate
    /// ([`Self::batch_gate`]), which the share holds until
    /// [`BatchMemory::resize`] makes it the full one.
    pub(crate) async fn batch_first_share(&self, bytes: u64) -> Result<BatchMemory, ServiceError> {
        let gate = self.batch_gate().await?;
        let budget = budget_kib(self.inner.config.max_batch_memory) as u64 * 1024;
        let mut memory = self.batch_memory(bytes.min(budget)).await?;
        memory.gate = Some(gate);
        Ok(memory)
    }

    /// Bytes batches in flight hold now (granted reservations only; one
    /// waiting in line is not counted until it has all of its share).
    pub fn batch_memory_held(&self) -> u64 {
        self.inner.batch_kib_held.load(Ordering::SeqCst) as u64 * 1024
    }

    /// A batch's place among the batches admitted at once (at most half of
    /// `--max-solves`, so single frames and bindings always find permits):
    /// waits in line at most the queue timeout, then `saturated`.
    pub(crate) async fn batch_slot(&self) -> Result<OwnedSemaphorePermit, ServiceError> {
        self.wait_in_line(&self.inner.batch_slots, 1, |waited| {
            format!(
                "this server is solving as many batches as it admits at once ({}, half of --max-solves) and this \
                 one waited {waited:.1} s; retry after the Retry-After delay",
                batch_slots(self.inner.config.max_solves)
            )
        })
        .await
    }

    /// Up to `n` more permits for a batch, only those free right now, each
    /// with a batch slot (so batches hold at most half of the permits in
    /// all, and a batch's extra parallelism never takes the permits single
    /// frames wait for): (slots, permits).
    pub(crate) fn spare_permits(&self, n: u32) -> Option<(OwnedSemaphorePermit, OwnedSemaphorePermit)> {
        (1..=n).rev().find_map(|k| {
            let slots = self.inner.batch_slots.clone().try_acquire_many_owned(k).ok()?;
            let permits = self.inner.permits.clone().try_acquire_many_owned(k).ok()?;
            Some((slots, permits))
        })
    }

    /// The batch gate: one batch at a time holds part of its memory share
    /// while it is parsed and waits for the rest (two batches each holding
    /// a part could wait for each other), the others wait here holding none.
    /// Waits in line at most the queue timeout, then `saturated`.
    async fn batch_gate(&self) -> Result<OwnedSemaphorePermit, ServiceError> {
        self.wait_in_line(&self.inner.batch_gate, 1, |waited| {
            format!(
                "batches are read one at a time while they take their memory (--max-batch-memory), and this one \
                 waited {waited:.1} s for its turn; retry after the Retry-After delay"
            )
        })
        .await
    }

    /// `n` permits of `semaphore`, waiting in line (first come, first
    /// served) at most the queue timeout; else `saturated` with the message
    /// `message` makes of the seconds waited.
    async fn wait_in_line(
        &self,
        semaphore: &Arc<Semaphore>,
        n: u32,
        message: impl FnOnce(f64) -> String,
    ) -> Result<OwnedSemaphorePermit, ServiceError> {
        if let Ok(p) = semaphore.clone().try_acquire_many_owned(n) {
            return Ok(p);
        }
        let queue = self.inner.config.queue_timeout;
        let waited = if queue.is_zero() {
            None
        } else {
            tokio::time::timeout(queue, semaphore.clone().acquire_many_owned(n)).await.ok().and_then(Result::ok)
        };
        waited.ok_or_else(|| {
            self.inner.metrics.saturated.increment(1);
            ServiceError::new(Code::Saturated, message(queue.as_secs_f64()))
        })
    }

    fn saturated(&self) -> ServiceError {
        self.inner.metrics.saturated.increment(1);
        ServiceError::new(Code::Saturated, self.saturated_message())
    }

    fn saturated_message(&self) -> String {
        format!(
            "the server is solving at its limit ({} solves at once, and a full line waiting up to {:.1} s); retry after the Retry-After delay",
            self.inner.config.max_solves,
            self.inner.config.queue_timeout.as_secs_f64()
        )
    }

    /// Threads of the solve pool.
    pub(crate) fn solve_threads(&self) -> usize {
        self.inner.pool.current_num_threads()
    }

    /// Runs `f` on the solve pool; a panic becomes an `internal` error.
    pub(crate) async fn on_pool<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> Result<T, ServiceError> + Send + 'static,
    ) -> Result<T, ServiceError> {
        self.spawn_on_pool(f).await
    }

    /// Queues `f` on the solve pool now (behind the jobs queued before it:
    /// the pool takes jobs from outside it first come, first served) and
    /// returns its result to await. Dropping the future does not stop `f`.
    pub(crate) fn spawn_on_pool<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> Result<T, ServiceError> + Send + 'static,
    ) -> impl std::future::Future<Output = Result<T, ServiceError>> + Send + 'static {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.inner.pool.spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
            let _ = tx.send(r);
        });
        async move {
            match rx.await {
                Ok(Ok(r)) => r,
                Ok(Err(panic)) => Err(ServiceError::internal(format!("a solve panicked: {}", panic_message(&panic)))),
                Err(_) => Err(ServiceError::internal("the solve pool dropped a job")),
            }
        }
    }
}

/// A request in line for a solve permit, counted in `Inner::waiting` while
/// it lives; `ahead`: how many were in line before it.
struct InLine<'a> {
    waiting: &'a std::sync::atomic::AtomicUsize,
    ahead: usize,
}

impl<'a> InLine<'a> {
    fn join(waiting: &'a std::sync::atomic::AtomicUsize) -> Self {
        Self { ahead: waiting.fetch_add(1, Ordering::SeqCst), waiting }
    }
}

impl Drop for InLine<'_> {
    fn drop(&mut self) {
        self.waiting.fetch_sub(1, Ordering::SeqCst);
    }
}

/// A batch that would hold more than all of `--max-batch-memory`.
fn too_large_for_batch_memory(bytes: u64, max: u64) -> ServiceError {
    ServiceError::new(
        Code::LimitExceeded,
        format!(
            "the batch would hold about {bytes} bytes (its frames, results and answer), more than this server lets \
             all batches in flight hold together, {max} (--max-batch-memory, CURVENET_MAX_BATCH_MEMORY); send fewer \
             frames per batch{}",
            if max < 1 << 20 { ", or raise the limit: it is below 1 MiB" } else { "" }
        ),
    )
}

/// Batches admitted at once: half the solve permits, at least one.
fn batch_slots(max_solves: usize) -> usize {
    (max_solves.min(Semaphore::MAX_PERMITS) / 2).max(1)
}

/// A batch's reservation of `--max-batch-memory` ([`AppState::batch_memory`]),
/// released when dropped; counted in `curvenet_batch_memory_bytes` while held.
pub(crate) struct BatchMemory {
    state: AppState,
    permit: OwnedSemaphorePermit,
    /// The batch gate ([`AppState::batch_gate`]) while this is a first share,
    /// given back once [`Self::resize`] has made it the full one.
    gate: Option<OwnedSemaphorePermit>,
}

impl BatchMemory {
    fn new(state: &AppState, permit: OwnedSemaphorePermit) -> Self {
        state.inner.batch_kib_held.fetch_add(permit.num_permits(), Ordering::SeqCst);
        Self { state: state.clone(), permit, gate: None }
    }

    /// Makes the reservation `bytes`: gives back what it holds beyond, or
    /// waits in line for the rest as [`AppState::batch_memory`] does.
    pub(crate) async fn resize(&mut self, bytes: u64) -> Result<(), ServiceError> {
        let (want, held) = (kib(bytes) as usize, self.permit.num_permits());
        if want < held {
            if let Some(excess) = self.permit.split(held - want) {
                self.state.inner.batch_kib_held.fetch_sub(excess.num_permits(), Ordering::SeqCst);
            }
        } else if want > held {
            let max = self.state.inner.config.max_batch_memory;
            if want > budget_kib(max) as usize {
                return Err(too_large_for_batch_memory(bytes, max));
            }
            let more = self.state.reserve_batch_memory((want - held) as u64 * 1024).await?;
            self.state.inner.batch_kib_held.fetch_add(more.num_permits(), Ordering::SeqCst);
            self.permit.merge(more);
        }
        self.gate = None;
        Ok(())
    }
}

impl Drop for BatchMemory {
    fn drop(&mut self) {
        self.state.inner.batch_kib_held.fetch_sub(self.permit.num_permits(), Ordering::SeqCst);
    }
}

/// Bytes in KiB, rounded up, as semaphore permits: at most `u32::MAX` (what
/// one acquisition can take), so a budget over 4 TiB counts as 4 TiB.
fn kib(bytes: u64) -> u32 {
    bytes.div_ceil(1024).min(u32::MAX as u64) as u32
}

/// The budget in whole KiB, rounded down (so that a share, rounded up,
/// never admits more than the budget's bytes).
fn budget_kib(bytes: u64) -> u32 {
    (bytes / 1024).min(u32::MAX as u64) as u32
}

/// Runs `f` on tokio's blocking pool; a panic becomes an `internal` error.
pub(crate) async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ServiceError> + Send + 'static,
) -> Result<T, ServiceError> {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => r,
        Err(e) if e.is_panic() => {
            Err(ServiceError::internal(format!("a blocking task panicked: {}", panic_message(&e.into_panic()))))
        }
        Err(e) => Err(ServiceError::internal(format!("a blocking task failed: {e}"))),
    }
}

pub(crate) fn panic_message(panic: &Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = panic.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}
