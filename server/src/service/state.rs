//! The service's configuration and its shared state: a cheap-to-clone handle.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::bake::Baker;
use crate::cache::BindingCache;
use crate::error::{Code, ServiceError};
use crate::metrics::Metrics;

/// Default cache size: 2 GiB of bindings (the 94k-vertex hand weighs ~60 MB).
pub const DEFAULT_CACHE_BYTES: u64 = 2 << 30;
/// Default body limit: 256 MiB (a JSON batch of 100k-vertex frames is large).
pub const DEFAULT_BODY_LIMIT: usize = 256 << 20;
/// Default solve permits: frames running or queued for a core at once.
pub const DEFAULT_MAX_SOLVES: usize = 64;
/// Default drain timeout at shutdown.
pub const DEFAULT_DRAIN_TIMEOUT: Duration = Duration::from_secs(30);

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
        }
    }
}

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
    pub pool: rayon::ThreadPool,
    pub metrics: Arc<Metrics>,
    pub token_hash: Option<blake3::Hash>,
    pub draining: AtomicBool,
    /// Stages opened in the viewer (`serve --open-stage`), by index.
    pub viewer_stages: std::sync::RwLock<Vec<Arc<crate::viewer::ViewerStage>>>,
}

impl AppState {
    /// Builds the state. Fails when a bake root does not exist or the solve
    /// pool cannot start.
    pub fn new(config: Config, baker: Option<Baker>) -> std::io::Result<Self> {
        let bake_roots = config
            .bake_roots
            .iter()
            .map(|r| {
                std::fs::canonicalize(r)
                    .map_err(|e| std::io::Error::new(e.kind(), format!("bake root {}: {e}", r.display())))
            })
            .collect::<std::io::Result<Vec<_>>>()?;
        let metrics = Arc::new(Metrics::new());
        let cache = BindingCache::new(config.cache_bytes, metrics.clone());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.solve_threads)
            .thread_name(|i| format!("curvenet-solve-{i}"))
            .build()
            .map_err(std::io::Error::other)?;
        Ok(Self {
            inner: Arc::new(Inner {
                permits: Arc::new(Semaphore::new(config.max_solves.min(Semaphore::MAX_PERMITS))),
                token_hash: config.token.as_deref().map(|t| blake3::hash(t.as_bytes())),
                config,
                bake_roots,
                baker,
                cache,
                pool,
                metrics,
                draining: AtomicBool::new(false),
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

    /// Takes `n` solve permits or answers `saturated`.
    pub(crate) fn permits(&self, n: u32) -> Result<OwnedSemaphorePermit, ServiceError> {
        match self.inner.permits.clone().try_acquire_many_owned(n) {
            Ok(p) => Ok(p),
            Err(_) => {
                self.inner.metrics.saturated.increment(1);
                Err(ServiceError::new(
                    Code::Saturated,
                    format!(
                        "the server is solving at its limit ({} solves at once); retry after the Retry-After delay",
                        self.inner.config.max_solves
                    ),
                ))
            }
        }
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
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.inner.pool.spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
            let _ = tx.send(r);
        });
        match rx.await {
            Ok(Ok(r)) => r,
            Ok(Err(panic)) => Err(ServiceError::internal(format!("a solve panicked: {}", panic_message(&panic)))),
            Err(_) => Err(ServiceError::internal("the solve pool dropped a job")),
        }
    }
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
