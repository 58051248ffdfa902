//! The binding store's error type, below both backends so that each names
//! the same operations in the same words.

use std::fmt;
use std::path::Path;

/// What the store was doing when it failed: each error names one, so a log
/// line says whether a read, a write or the eviction sweep broke.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// Opening the store: creating and checking the directory, or building the S3 client and listing once.
    Open,
    /// Reading a blob.
    Get,
    /// Refreshing an entry's recency after a hit (the file's mtime, or the S3 `.used` marker).
    Touch,
    /// Writing a blob (temporary file, sync, rename; or one PUT).
    Put,
    /// Deleting an entry on request.
    Remove,
    /// Listing the entries (usage, eviction).
    List,
    /// Deleting an entry, a stale temporary file or an orphan marker to stay within the size limit.
    Evict,
}

impl fmt::Display for Op {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Op::Open => "open",
            Op::Get => "get",
            Op::Touch => "touch",
            Op::Put => "put",
            Op::Remove => "remove",
            Op::List => "list",
            Op::Evict => "evict",
        })
    }
}

/// Why a binding store operation failed. Every variant names the store's
/// location, and those about one blob the file or object and its key, so a
/// log line alone points at the thing to look at.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// The location string is not a directory path, a `file://` path or an
    /// `s3://bucket/prefix` URL (no bucket, a bad prefix, another scheme).
    #[error("binding store location {location:?}: {problem}")]
    Location { location: String, problem: String },
    /// The S3 configuration in the `AWS_*` variables cannot work (a
    /// malformed endpoint, plain http without `AWS_ALLOW_HTTP`, half a key
    /// pair): names the variable. Like [`StoreError::Location`], retrying
    /// cannot mend it.
    #[error("binding store {location}: {problem}")]
    Config { location: String, problem: String },
    /// Opening the store failed in a way that may pass (the endpoint did
    /// not answer in time, the first listing was refused): what happened
    /// and, when the environment suggests why, a hint.
    #[error("binding store {location}: {problem}")]
    Unreachable { location: String, problem: String },
    /// The directory cannot be created, is not a directory, or cannot be written.
    #[error("binding store {location}: cannot {what}: {source}")]
    Open { location: String, what: &'static str, source: std::io::Error },
    /// A file system call on one file (or the directory) failed.
    #[error("binding store {location}: {op}{key}: {path}: {source}", key = key_part(key))]
    Io { location: String, op: Op, key: Option<String>, path: String, source: std::io::Error },
    /// An object store call failed (S3, or any `ObjectStore`).
    #[error("binding store {location}: {op}{key}: {object}: {source}", key = key_part(key))]
    Object { location: String, op: Op, key: Option<String>, object: String, source: Box<object_store::Error> },
    /// The directory was opened for reading only (this process cannot
    /// write in it): nothing is written.
    #[error("binding store {location}: put of {key}: the store is read-only for this process (opened so at start)")]
    ReadOnly { location: String, key: String },
    /// The blob is larger than the largest this store reads
    /// ([`super::BindingStore::with_max_blob_bytes`]); it was not read.
    #[error(
        "binding store {location}: get of {key}: the blob is {bytes} bytes, more than the {max} this process reads"
    )]
    TooLarge { location: String, key: String, bytes: u64, max: u64 },
    /// A call did not finish within its time (a store that accepts
    /// connections and never answers, a hung NFS mount).
    #[error("binding store {location}: {op}{key}: no answer within {seconds} s", key = key_part(key))]
    TimedOut { location: String, op: Op, key: Option<String>, seconds: u64 },
    /// The store is not asked for a while after a call timed out or the
    /// object store failed (see `BindingStore`'s docs, "A store that fails").
    #[error("binding store {location}: {op}{key}: not asked for {seconds} s more (it failed or did not answer a moment ago)", key = key_part(key))]
    Paused { location: String, op: Op, key: Option<String>, seconds: u64 },
    /// The blocking task that ran a directory operation did not finish (it
    /// panicked, or the runtime is shutting down).
    #[error("binding store {location}: {op}{key}: the blocking task failed: {source}", key = key_part(key))]
    Task { location: String, op: Op, key: Option<String>, source: tokio::task::JoinError },
}

/// ` of KEY` when the error is about one key, else nothing.
fn key_part(key: &Option<String>) -> String {
    key.as_ref().map(|k| format!(" of {k}")).unwrap_or_default()
}

impl StoreError {
    /// The I/O error of `op` on `path` (about `key`, when there is one).
    pub(super) fn io(location: &str, op: Op, key: Option<&[u8; 32]>, path: &Path, source: std::io::Error) -> Self {
        StoreError::Io {
            location: location.to_string(),
            op,
            key: key.map(super::names::hex),
            path: path.display().to_string(),
            source,
        }
    }

    /// The object store error of `op` on `object` (about `key`, when there is one).
    pub(super) fn object(
        location: &str,
        op: Op,
        key: Option<&[u8; 32]>,
        object: &object_store::path::Path,
        source: object_store::Error,
    ) -> Self {
        StoreError::Object {
            location: location.to_string(),
            op,
            key: key.map(super::names::hex),
            object: object.to_string(),
            source: Box::new(source),
        }
    }

    /// The operation that failed (`Op::Open` for a bad location).
    pub fn op(&self) -> Op {
        match self {
            StoreError::Location { .. }
            | StoreError::Config { .. }
            | StoreError::Unreachable { .. }
            | StoreError::Open { .. } => Op::Open,
            StoreError::Io { op, .. }
            | StoreError::Object { op, .. }
            | StoreError::Task { op, .. }
            | StoreError::TimedOut { op, .. }
            | StoreError::Paused { op, .. } => *op,
            StoreError::ReadOnly { .. } => Op::Put,
            StoreError::TooLarge { .. } => Op::Get,
        }
    }

    /// The hex key the error is about, if it is about one blob.
    pub fn key(&self) -> Option<&str> {
        match self {
            StoreError::Io { key, .. }
            | StoreError::Object { key, .. }
            | StoreError::Task { key, .. }
            | StoreError::TimedOut { key, .. }
            | StoreError::Paused { key, .. } => key.as_deref(),
            StoreError::ReadOnly { key, .. } | StoreError::TooLarge { key, .. } => Some(key),
            StoreError::Location { .. }
            | StoreError::Config { .. }
            | StoreError::Unreachable { .. }
            | StoreError::Open { .. } => None,
        }
    }

    /// Whether the error is in what the user wrote (the location, the
    /// `AWS_*` configuration), so that trying again as is cannot help: the
    /// command line exits 2 for these and 75 (try again later) for the rest.
    pub fn is_config(&self) -> bool {
        match self {
            StoreError::Location { .. } | StoreError::Config { .. } => true,
            // A file where the directory must be stays one; so does a symlink loop.
            StoreError::Open { source, .. } => {
                matches!(source.kind(), std::io::ErrorKind::NotADirectory | std::io::ErrorKind::AlreadyExists)
                    || source.raw_os_error() == Some(libc::ELOOP)
            }
            // A bucket that does not exist will not appear by retrying.
            StoreError::Unreachable { problem, .. } => problem.contains("NoSuchBucket"),
            _ => false,
        }
    }
}

/// A result with the failures that did not stop it: a hit whose recency
/// could not be refreshed, an eviction that could not delete one entry. The
/// store logs and counts each, and still answers with `value`.
#[derive(Debug)]
pub(super) struct Outcome<T> {
    pub value: T,
    pub problems: Vec<StoreError>,
}

impl<T> Outcome<T> {
    /// `value` with nothing gone wrong.
    pub fn clean(value: T) -> Self {
        Outcome { value, problems: Vec::new() }
    }
}
