//! The binding store: opaque blobs keyed by a 32-byte binding key, kept in
//! a directory or under an S3 prefix so that bindings outlive the process
//! and are shared by the service and the farm's bake workers. This module
//! moves bytes only; what a blob holds, and whether it is valid, is the
//! caller's (which counts a blob it rejects in `store_rejected` and
//! [`BindingStore::remove`]s it).
//!
//! # Layout
//!
//! One file or object per entry, named `<64 lowercase hex of the key>.cnb`,
//! directly in the directory or under the prefix. Nothing else there is the
//! store's: other names, deeper folders, uppercase hex are ignored by the
//! listing, so the store can share a directory with other files.
//!
//! # Writes are atomic, readers never see a partial blob
//!
//! - Directory: the blob is written to `.<hex>.<pid>.<unique>.tmp` in the
//!   same directory (created exclusively; `unique` holds 64 random bits, so
//!   hosts sharing an NFS directory do not clash), synced, and renamed over
//!   the entry. A reader opens the old file or the new one. Only `rename` is
//!   relied upon, which NFS keeps atomic; no hard links, no locks.
//! - S3: one PUT, which S3 applies whole or not at all.
//!
//! Two writers of one key both write valid blobs; the last rename (or PUT)
//! wins. Another process may delete or replace any entry at any time: a
//! file that is gone when read is a miss, gone when evicted, already evicted.
//!
//! # Recency and eviction
//!
//! With a size limit, every [`BindingStore::put`] ends with a sweep: the
//! entries are listed and the least recently used deleted until the rest
//! hold at most the limit (never the key just written, which may alone be
//! over it). Without one, the put still lists, to report the size.
//!
//! - Directory: recency is the file's mtime. A write sets it; a hit sets it
//!   to now (`File::set_modified` on the handle just read). The sweep also
//!   deletes the store's temporary files untouched for an hour (their
//!   writer died). Several processes may sweep at once; at worst they
//!   evict a little more than needed.
//! - S3: objects have no access time, and their `last_modified` changes
//!   only when they are written. Rewriting a blob on each hit (a copy onto
//!   itself) would cost a copy of a large object per hit; instead a hit
//!   PUTs an empty marker object `<hex>.used` beside it, and the entry's
//!   recency is the later of the blob's and the marker's `last_modified`,
//!   both read from the one listing the sweep makes anyway. The cost is one
//!   small PUT per hit (the service's in-memory cache in front of the store
//!   keeps hits rare) and one marker per entry in the listing. A marker
//!   whose blob is gone (evicted by another process, or written just after
//!   it was evicted) is deleted by a sweep once an hour old; its bytes are
//!   not counted in the store's size.
//!
//! A failure to refresh recency or to delete one entry does not fail the
//! get or the put: it is logged and counted as an error, and the answer
//! stands.
//!
//! # A store that fails
//!
//! A stat or HEAD must answer within 2 s, a delete or a listing with its
//! sweep within 10 s, a blob's read or write within 120 s; an S3 read or
//! write must not stall for 5 s without a byte (`AWS_READ_TIMEOUT`),
//! retried for at most 10 s. When an object store
//! call fails or any call times out, the store is left alone for 30 s:
//! every call answers [`StoreError::Paused`] at once (not counted as an
//! error), which the service takes as a miss, so a store that accepts
//! connections and never answers costs one slow request per replica per 30
//! s, not every request (a blocking thread stuck in a hung NFS call stays
//! stuck, but no request waits for it). A directory's I/O errors (a full
//! disk, a read-only mount) do not pause it: they are quick and may concern
//! one file.
//!
//! # Metrics and logs
//!
//! Hits, misses, errors (every backend failure, also those that did not
//! fail the call), evictions, blobs and bytes written and read; the size
//! after the last put or usage; the seconds of a hit's load and of a write
//! (the write alone, without its sweep). Each failure is logged at warn,
//! naming the store, the operation, the file or object and the key.

mod dir;
mod error;
mod names;
mod s3;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::time::{Duration, Instant};

use dir::Dir;
use error::Outcome;
pub use error::{Op, StoreError};

pub use names::BLOB_MAGIC;

/// The metrics the store counts into: re-exported so that the command line,
/// which opens a store without a service, can make them.
pub use crate::metrics::Metrics;

/// The store: a directory or an object store prefix, with an optional size
/// limit. Send + Sync; share it as `Arc<BindingStore>`.
pub struct BindingStore {
    backend: Backend,
    max_bytes: Option<u64>,
    metrics: Arc<Metrics>,
    /// Until when the store is not asked (see "A store that fails").
    paused_until: std::sync::Mutex<Option<Instant>>,
    /// The largest blob read (None: any).
    max_blob_bytes: Option<u64>,
}

/// How long the store is left alone after an object store call failed or
/// any call timed out: a store that hangs costs one slow request per
/// replica per pause, not every request.
const PAUSE: Duration = Duration::from_secs(30);
/// How long a stat or HEAD may take (`contains`: the check a post found in
/// memory makes before it is answered).
const CHECK_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a delete, or a listing with its sweep, may take.
const SMALL_CALL_TIMEOUT: Duration = Duration::from_secs(10);
/// How long reading or writing one blob may take (a hung NFS mount, an S3
/// endpoint that trickles bytes): S3's own per-request limit, and a
/// 376k-vertex character's 732 MB over a 100 Mbit/s link in half of it.
const BLOB_CALL_TIMEOUT: Duration = Duration::from_secs(120);

/// Where the entries live.
enum Backend {
    Dir(dir::Dir),
    Objects(s3::Objects),
}

impl std::fmt::Debug for BindingStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BindingStore").field("location", &self.location()).field("max_bytes", &self.max_bytes).finish()
    }
}

/// What a location string names.
#[derive(Debug, PartialEq, Eq)]
enum Location {
    Dir(std::path::PathBuf),
    S3(s3::S3Url),
}

/// Parses a location: `s3://bucket/optional/prefix`, `file://PATH`, or a
/// path. Any other `scheme://` is refused rather than taken for a
/// directory named `scheme:`.
fn parse_location(location: &str) -> Result<Location, StoreError> {
    let bad = |problem: &str| StoreError::Location { location: location.to_string(), problem: problem.to_string() };
    if location.is_empty() {
        return Err(bad("empty (a directory path, file://PATH or s3://bucket/optional/prefix)"));
    }
    if location.starts_with("s3://") {
        return Ok(Location::S3(s3::S3Url::parse(location)?));
    }
    if let Some(path) = location.strip_prefix("file://") {
        if path.is_empty() {
            return Err(bad("file:// names no directory"));
        }
        return Ok(Location::Dir(path.into()));
    }
    if let Some((scheme, _)) = location.split_once("://")
        && !scheme.is_empty()
        && scheme.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'+' | b'-' | b'.'))
    {
        return Err(bad("unsupported scheme (a directory path, file://PATH or s3://bucket/optional/prefix)"));
    }
    Ok(Location::Dir(location.into()))
}

impl BindingStore {
    /// Opens the store at `location`: a directory path (absolute or
    /// relative to the working directory, `file://` allowed; created if
    /// missing and checked writable) or `s3://bucket/optional/prefix`
    /// (credentials, region and endpoint from the standard `AWS_*`
    /// environment variables: `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
    /// `AWS_SESSION_TOKEN`, `AWS_REGION`/`AWS_DEFAULT_REGION`,
    /// `AWS_ENDPOINT_URL(_S3)`, `AWS_ALLOW_HTTP`; the prefix is listed once,
    /// so bad credentials fail here). `max_bytes`: None keeps everything;
    /// else each put evicts the least recently used entries until the
    /// store holds at most `max_bytes`.
    pub async fn open(location: &str, max_bytes: Option<u64>, metrics: Arc<Metrics>) -> Result<Self, StoreError> {
        let opened = match parse_location(location)? {
            Location::Dir(path) => Dir::open(path).await.map(Backend::Dir),
            Location::S3(url) => open_s3(&url, aws_vars(), PROBE_TIMEOUT).await,
        };
        if let Ok(Backend::Dir(d)) = &opened
            && d.read_only()
        {
            tracing::warn!(
                location = d.location(),
                "binding store opened read-only: bindings are read from it, none written"
            );
        }
        match opened {
            Ok(backend) => {
                Ok(Self { backend, max_bytes, metrics, paused_until: Default::default(), max_blob_bytes: None })
            }
            Err(e) => {
                metrics.store_errors.increment(1);
                tracing::warn!(location, "{e}");
                Err(e)
            }
        }
    }

    /// A store over any object store (`prefix` may be empty), named
    /// `location` in logs: how the S3 backend is tested over
    /// `object_store::memory::InMemory`, and how another object store could
    /// be used. A bad prefix is [`StoreError::Location`].
    pub fn with_object_store(
        store: Arc<dyn object_store::ObjectStore>,
        prefix: &str,
        location: &str,
        max_bytes: Option<u64>,
        metrics: Arc<Metrics>,
    ) -> Result<Self, StoreError> {
        let prefix = s3::parse_prefix(location, prefix)?;
        let objects = s3::Objects::new(store, prefix, location.to_string());
        Ok(Self {
            backend: Backend::Objects(objects),
            max_bytes,
            metrics,
            paused_until: Default::default(),
            max_blob_bytes: None,
        })
    }

    /// Reads no blob larger than `max` bytes: a larger one answers
    /// [`StoreError::TooLarge`] before a byte of it is read. The service
    /// passes its cache's capacity (a stored binding is smaller than its
    /// cached size, so a larger file could not be cached anyway), the bake
    /// half the machine's memory: a file under an entry's name (a sparse
    /// one, or garbage that starts like a blob) cannot make the process
    /// allocate more than that.
    pub fn with_max_blob_bytes(mut self, max: u64) -> Self {
        self.max_blob_bytes = Some(max);
        self
    }

    /// Where the store is (the absolute directory, or `s3://bucket/prefix`), for logs.
    pub fn location(&self) -> &str {
        match &self.backend {
            Backend::Dir(d) => d.location(),
            Backend::Objects(o) => o.location(),
        }
    }

    /// Whether the store was opened for reading only (a directory this
    /// process cannot write in): writes answer [`StoreError::ReadOnly`].
    pub fn read_only(&self) -> bool {
        matches!(&self.backend, Backend::Dir(d) if d.read_only())
    }

    /// The size limit the store was opened with.
    pub fn max_bytes(&self) -> Option<u64> {
        self.max_bytes
    }

    /// The blob of `key`, or None if absent. A hit refreshes the entry's
    /// recency. Counts the hit or the miss, the bytes read and the load's
    /// seconds (hits only).
    pub async fn get(&self, key: &[u8; 32]) -> Result<Option<Vec<u8>>, StoreError> {
        let started = Instant::now();
        let max = self.max_blob_bytes;
        let got = self
            .guarded(Op::Get, Some(key), BLOB_CALL_TIMEOUT, async {
                match &self.backend {
                    Backend::Dir(d) => d.get(*key, max).await,
                    Backend::Objects(o) => o.get(key, max).await,
                }
            })
            .await?;
        match &got {
            Some(bytes) => {
                self.metrics.store_hits.increment(1);
                self.metrics.store_read_bytes.increment(bytes.len() as u64);
                self.metrics.store_load_seconds.record(started.elapsed().as_secs_f64());
            }
            None => self.metrics.store_misses.increment(1),
        }
        Ok(got)
    }

    /// Writes `bytes` as the blob of `key`, atomically (see the module
    /// docs), then sweeps to the size limit (never evicting `key`). Counts
    /// the write's seconds. The write's failure is the error; the sweep's
    /// failures are logged and counted, and the put still succeeds.
    pub async fn put(&self, key: &[u8; 32], bytes: Vec<u8>) -> Result<(), StoreError> {
        let started = Instant::now();
        let len = bytes.len() as u64;
        self.guarded(Op::Put, Some(key), BLOB_CALL_TIMEOUT, async {
            match &self.backend {
                Backend::Dir(d) => d.put(*key, bytes).await,
                Backend::Objects(o) => o.put(key, bytes).await,
            }
            .map(Outcome::clean)
        })
        .await?;
        self.metrics.store_write_seconds.record(started.elapsed().as_secs_f64());
        self.metrics.store_written.increment(1);
        self.metrics.store_written_bytes.increment(len);
        if let Some(max) = self.max_bytes
            && len > max
        {
            tracing::warn!(
                store = self.location(),
                key = %names::hex(key),
                bytes = len,
                max_bytes = max,
                "this binding alone is larger than the store's size limit: it is kept only until the next write \
                 (raise --store-bytes)"
            );
        }
        let swept = self
            .guarded(Op::Evict, None, SMALL_CALL_TIMEOUT, async {
                match &self.backend {
                    Backend::Dir(d) => d.sweep(self.max_bytes, *key).await,
                    Backend::Objects(o) => o.sweep(self.max_bytes, key).await,
                }
            })
            .await;
        if let Ok(swept) = swept {
            self.metrics.store_evictions.increment(swept.evicted as u64);
            self.metrics.store_bytes.set(swept.bytes as f64);
            if swept.evicted > 0 {
                tracing::debug!(
                    store = self.location(),
                    evicted = swept.evicted,
                    bytes = swept.bytes,
                    entries = swept.entries,
                    "binding store swept"
                );
            }
        }
        Ok(())
    }

    /// Whether the store holds an entry for `key` now (a stat, or one
    /// HEAD; neither a hit nor a miss, and the entry's recency is kept).
    pub async fn contains(&self, key: &[u8; 32]) -> Result<bool, StoreError> {
        self.guarded(Op::Get, Some(key), CHECK_TIMEOUT, async {
            match &self.backend {
                Backend::Dir(d) => d.contains(*key).await,
                Backend::Objects(o) => o.contains(key).await,
            }
            .map(Outcome::clean)
        })
        .await
    }

    /// Deletes the entry of `key` (a blob the caller found corrupt, or a
    /// `DELETE`); an absent entry is not an error. Whether it was there.
    pub async fn remove(&self, key: &[u8; 32]) -> Result<bool, StoreError> {
        self.guarded(Op::Remove, Some(key), SMALL_CALL_TIMEOUT, async {
            match &self.backend {
                Backend::Dir(d) => d.remove(*key).await,
                Backend::Objects(o) => o.remove(key).await,
            }
            .map(Outcome::clean)
        })
        .await
    }

    /// The store's total bytes and entry count now, from a listing (which
    /// also sets the size gauge).
    pub async fn usage(&self) -> Result<(u64, usize), StoreError> {
        let entries = self
            .guarded(Op::List, None, SMALL_CALL_TIMEOUT, async {
                match &self.backend {
                    Backend::Dir(d) => d.list().await.map(|l| l.entries),
                    Backend::Objects(o) => o.list().await.map(|l| l.entries),
                }
                .map(Outcome::clean)
            })
            .await?;
        let bytes = entries.iter().map(|e| e.bytes).sum();
        self.metrics.store_bytes.set(bytes as f64);
        Ok((bytes, entries.len()))
    }

    /// Logs and counts the failures in `result` (the error, or the problems
    /// of a success) and returns its value.
    fn settle<T>(&self, result: Result<Outcome<T>, StoreError>) -> Result<T, StoreError> {
        match result {
            Ok(Outcome { value, problems }) => {
                for p in problems {
                    self.failed(&p);
                }
                Ok(value)
            }
            Err(e) => {
                self.failed(&e);
                if matches!(e, StoreError::Object { .. } | StoreError::TimedOut { .. }) {
                    self.pause(&e);
                }
                Err(e)
            }
        }
    }

    /// Every backend call goes through here: [`StoreError::Paused`] at once
    /// while the store is paused (not counted); else `call`, or
    /// [`StoreError::TimedOut`] when it takes longer than `limit`, settled
    /// (its failures logged and counted, the store paused after an object
    /// store failure or a timeout).
    async fn guarded<T>(
        &self,
        op: Op,
        key: Option<&[u8; 32]>,
        limit: Duration,
        call: impl Future<Output = Result<Outcome<T>, StoreError>>,
    ) -> Result<T, StoreError> {
        self.check_paused(op, key)?;
        let done = tokio::time::timeout(limit, call).await.unwrap_or_else(|_| {
            Err(StoreError::TimedOut {
                location: self.location().to_string(),
                op,
                key: key.map(names::hex),
                seconds: limit.as_secs(),
            })
        });
        self.settle(done)
    }

    /// Leaves the store alone for [`PAUSE`] after `e`.
    fn pause(&self, e: &StoreError) {
        let mut until = self.paused_until.lock().unwrap_or_else(|p| p.into_inner());
        *until = Some(Instant::now() + PAUSE);
        tracing::warn!(store = self.location(), seconds = PAUSE.as_secs(), "binding store paused after: {e}");
    }

    /// [`StoreError::Paused`] while the store is paused (not counted as an
    /// error: the failure that paused it was).
    fn check_paused(&self, op: Op, key: Option<&[u8; 32]>) -> Result<(), StoreError> {
        let until = *self.paused_until.lock().unwrap_or_else(|p| p.into_inner());
        match until {
            Some(until) if until > Instant::now() => Err(StoreError::Paused {
                location: self.location().to_string(),
                op,
                key: key.map(names::hex),
                seconds: (until - Instant::now()).as_secs().max(1),
            }),
            _ => Ok(()),
        }
    }

    /// Counts one backend failure and logs it at warn.
    fn failed(&self, e: &StoreError) {
        self.metrics.store_errors.increment(1);
        tracing::warn!(store = self.location(), op = %e.op(), key = e.key().unwrap_or("-"), "{e}");
    }
}

/// How long opening an S3 store may wait for its first listing: an
/// endpoint that accepts connections and never answers must fail the start
/// (which a supervisor retries), not hang it.
const PROBE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(20);

/// Builds the S3 client of `url` from `vars` and lists its prefix once,
/// within `timeout`.
async fn open_s3(
    url: &s3::S3Url,
    vars: impl IntoIterator<Item = (String, String)>,
    timeout: std::time::Duration,
) -> Result<Backend, StoreError> {
    let client = s3::s3_client(url, vars)?;
    let objects = s3::Objects::new(client.store, url.prefix.clone(), url.display());
    let unreachable = |problem: String| StoreError::Unreachable { location: url.display(), problem };
    match tokio::time::timeout(timeout, objects.probe()).await {
        Ok(Ok(())) => Ok(Backend::Objects(objects)),
        Ok(Err(e)) => {
            let hint = client.credentials_hint.map(|h| format!(" ({h})")).unwrap_or_default();
            Err(unreachable(format!("cannot list the bucket: {e}{hint}")))
        }
        Err(_) => Err(unreachable(format!(
            "the endpoint did not answer a listing within {} s (AWS_ENDPOINT_URL, the network)",
            timeout.as_secs()
        ))),
    }
}

/// The process's `AWS_*` environment variables (those that are Unicode),
/// collected (the environment's iterator is not `Send`: `open`'s future is).
fn aws_vars() -> Vec<(String, String)> {
    std::env::vars_os()
        .filter_map(|(k, v)| Some((k.into_string().ok()?, v.into_string().ok()?)))
        .filter(|(k, _)| k.to_ascii_uppercase().starts_with("AWS_"))
        .collect()
}
