//! An entry as stored bytes and back, through the binding store
//! (`store.rs`): what a replica writes after building a binding and what
//! another replica, or this one after a restart, reads instead of building.
//!
//! # The stored entry
//!
//! ```text
//! offset  size  field
//!      0     8  magic, b"CNENTRY\0" (`store::BLOB_MAGIC`, which the store checks first)
//!      8     4  envelope version, u32 LE (ENVELOPE_VERSION)
//!     12     4  core's stored-binding format version (curvenet_core::STORED_FORMAT_VERSION)
//!     16    32  the binding key (the id's 32 bytes)
//!     48     4  meta length, u32 LE
//!     52     4  zero
//!     56     8  the first 8 bytes of blake3(meta)
//!     64     -  meta: JSON {"service_version", "topology_hash", "response"}
//!      -     -  the deformer in core's format (its own header, length and CRC-32)
//! ```
//!
//! A blob is used only when every check passes: magic, both versions and
//! the service version that wrote it (a replica of another release neither
//! reads nor is read: layouts and results may differ), the key it was asked
//! for (a file renamed to another key), the meta checksum and JSON, and
//! core's own length and checksum of the deformer, and for the service's
//! entries the binding id in the meta (a forged header). Anything else is a
//! [`Rejected`] blob: warned about with its reason, counted
//! (`curvenet_store_rejected_total`), deleted from the store so the next
//! build replaces it (except a blob of another release or format, which is
//! left for the replicas of that release and overwritten when this one
//! writes the key), and treated as absent (a post that carries the mesh
//! builds it again; a frame for the id answers `unknown_binding`, which the
//! client answers by posting the binding again).

use std::sync::Arc;
use std::time::Instant;

use curvenet_core::Deformer;
use curvenet_core::StoredFormatError as FormatError;
use curvenet_schema::wire::BindingResponse;
use serde::{Deserialize, Serialize};

use crate::builder::measure;
use crate::entry::{Entry, Key, hex};
use crate::metrics::Metrics;
use crate::store::{BLOB_MAGIC, BindingStore, StoreError};

/// The envelope's version (this file's layout).
pub const ENVELOPE_VERSION: u32 = 1;
/// Bytes before the meta.
const HEADER_BYTES: usize = 64;
/// Longest meta accepted (the response, with its warnings: far below).
const MAX_META_BYTES: usize = 16 << 20;
/// The release that wrote a blob; only the same release reads it.
const SERVICE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// Why a stored blob was not used.
#[derive(Debug, thiserror::Error)]
pub enum Rejected {
    #[error("truncated: {got} bytes, at least {expected} expected")]
    Truncated { expected: usize, got: usize },
    #[error("not a stored curvenet entry (magic {found:02x?})")]
    Magic { found: Vec<u8> },
    #[error("written by another version ({what} {found}, this build {supported})")]
    Version { what: &'static str, found: String, supported: String },
    #[error("stored under key {found} but read as {expected}")]
    WrongKey { found: String, expected: String },
    #[error("its description fails its checksum: corrupted")]
    MetaChecksum,
    #[error("its description does not parse: {0}")]
    Meta(String),
    #[error("its deformer: {0}")]
    Deformer(#[from] FormatError),
}

impl Rejected {
    /// Written by another release or format: not damaged, only not this
    /// build's to read. Such a blob is left in place (a replica of that
    /// release may be reading it) and replaced when this build writes the
    /// key; the other rejections delete it.
    pub fn is_other_version(&self) -> bool {
        matches!(self, Rejected::Version { .. })
    }
}

/// The envelope's description of what it holds: the release that wrote it
/// and, for the service's entries, the id's topology hash and the answer
/// that described the binding (a bake's bindings have neither).
#[derive(Serialize, Deserialize)]
pub struct Meta {
    pub service_version: String,
    pub topology_hash: Option<String>,
    pub response: Option<BindingResponse>,
}

impl Meta {
    /// A meta of this release.
    pub fn new(topology_hash: Option<String>, response: Option<BindingResponse>) -> Self {
        Self { service_version: SERVICE_VERSION.to_string(), topology_hash, response }
    }
}

fn meta_sum(meta: &[u8]) -> [u8; 8] {
    blake3::hash(meta).as_bytes()[..8].try_into().expect("8 bytes")
}

/// `entry`, stored under `key`. CPU work (a copy of the binding): run it
/// off the async runtime.
pub fn encode(entry: &Entry, key: &Key) -> Vec<u8> {
    let meta = Meta::new(Some(entry.topology_hash.clone()), Some(entry.response.clone()));
    encode_blob(key, &meta, &entry.deformer)
}

/// `deformer` with `meta`, stored under `key` (the layout in the module docs).
pub fn encode_blob(key: &Key, meta: &Meta, deformer: &Deformer) -> Vec<u8> {
    let meta = serde_json::to_vec(meta).expect("a binding response serialises to JSON");
    let mut out = Vec::with_capacity(HEADER_BYTES + meta.len() + deformer.stored_bytes_hint());
    out.extend_from_slice(&BLOB_MAGIC);
    out.extend_from_slice(&ENVELOPE_VERSION.to_le_bytes());
    out.extend_from_slice(&curvenet_core::STORED_FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(key);
    out.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&meta_sum(&meta));
    debug_assert_eq!(out.len(), HEADER_BYTES);
    out.extend_from_slice(&meta);
    deformer.append_bytes(&mut out);
    out
}

/// The entry stored in `bytes` under `key`, checked (see the module docs),
/// with its size measured for this replica's `keep` solve threads.
pub fn decode(bytes: &[u8], key: &Key, keep: usize) -> Result<Entry, Rejected> {
    let (meta, deformer) = decode_blob(bytes, key)?;
    let (Some(topology_hash), Some(response)) = (meta.topology_hash, meta.response) else {
        return Err(Rejected::Meta("no binding description (not written by the service)".into()));
    };
    if response.binding_id != hex(key) {
        return Err(Rejected::WrongKey { found: response.binding_id, expected: hex(key) });
    }
    let (size_bytes, cage) = measure(&deformer, keep);
    let response = BindingResponse { size_bytes, cage, ..response };
    Ok(Entry { id: hex(key), topology_hash, deformer, response, size_bytes })
}

/// The meta and deformer stored in `bytes` under `key`, every check passed
/// (see the module docs). CPU work: run it off the async runtime.
pub fn decode_blob(bytes: &[u8], key: &Key) -> Result<(Meta, Deformer), Rejected> {
    if bytes.len() < 8 || bytes[..8] != BLOB_MAGIC {
        return Err(Rejected::Magic { found: bytes[..bytes.len().min(8)].to_vec() });
    }
    if bytes.len() < HEADER_BYTES {
        return Err(Rejected::Truncated { expected: HEADER_BYTES, got: bytes.len() });
    }
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let version = |what, found: u32, supported: u32| Rejected::Version {
        what,
        found: found.to_string(),
        supported: supported.to_string(),
    };
    if u32_at(8) != ENVELOPE_VERSION {
        return Err(version("envelope version", u32_at(8), ENVELOPE_VERSION));
    }
    if u32_at(12) != curvenet_core::STORED_FORMAT_VERSION {
        return Err(version("binding format version", u32_at(12), curvenet_core::STORED_FORMAT_VERSION));
    }
    let found: Key = bytes[16..48].try_into().expect("32 bytes");
    if &found != key {
        return Err(Rejected::WrongKey { found: hex(&found), expected: hex(key) });
    }
    let meta_len = u32_at(48) as usize;
    let meta_end = HEADER_BYTES + meta_len.min(MAX_META_BYTES);
    if meta_len > MAX_META_BYTES || bytes.len() < meta_end {
        return Err(Rejected::Truncated { expected: HEADER_BYTES + meta_len, got: bytes.len() });
    }
    let meta = &bytes[HEADER_BYTES..meta_end];
    if meta_sum(meta) != bytes[56..64] {
        return Err(Rejected::MetaChecksum);
    }
    let meta: Meta = serde_json::from_slice(meta).map_err(|e| Rejected::Meta(e.to_string()))?;
    if meta.service_version != SERVICE_VERSION {
        return Err(Rejected::Version {
            what: "curvenet release",
            found: meta.service_version,
            supported: SERVICE_VERSION.into(),
        });
    }
    let deformer = Deformer::from_bytes(&bytes[meta_end..])?;
    Ok((meta, deformer))
}

/// The store as the cache uses it: entries in, entries out, every bad blob
/// refused (module docs).
pub struct StoredBindings {
    store: Arc<BindingStore>,
    metrics: Arc<Metrics>,
    /// Solve threads whose workspaces a loaded entry's size counts.
    keep: usize,
}

impl StoredBindings {
    pub fn new(store: Arc<BindingStore>, metrics: Arc<Metrics>, keep: usize) -> Self {
        Self { store, metrics, keep }
    }

    /// Where the store is (for logs and `/v1/status`-like answers).
    pub fn location(&self) -> &str {
        self.store.location()
    }

    /// The entry stored under `key`, if there is a good one. A store that
    /// cannot be read is warned about and treated as a miss: the binding is
    /// then built (or the id answered unknown), never failed on the store.
    /// `Err(bytes)`: the stored file is larger than this replica reads
    /// (its cache's capacity, `BindingStore::with_max_blob_bytes`), so its
    /// binding could not be cached; it was not read.
    pub async fn load(&self, key: &Key) -> Result<Option<Entry>, u64> {
        let t = Instant::now();
        let bytes = match self.store.get(key).await {
            Ok(Some(bytes)) => bytes,
            Ok(None) => return Ok(None),
            Err(StoreError::TooLarge { bytes, .. }) => return Err(bytes),
            Err(e @ StoreError::Paused { .. }) => {
                tracing::debug!(binding_id = %hex(key), error = %e, "binding store paused: a miss");
                return Ok(None);
            }
            Err(e) => {
                tracing::warn!(binding_id = %hex(key), store = %self.store.location(), error = %e, "binding store read failed");
                return Ok(None);
            }
        };
        let (n, k, keep) = (bytes.len(), *key, self.keep);
        let decoded = tokio::task::spawn_blocking(move || decode(&bytes, &k, keep)).await;
        match decoded {
            Ok(Ok(entry)) => {
                tracing::info!(binding_id = %entry.id, bytes = n, ms = t.elapsed().as_secs_f64() * 1e3, "loaded from the binding store");
                Ok(Some(entry))
            }
            Ok(Err(reason)) => {
                self.metrics.store_rejected.increment(1);
                if reason.is_other_version() {
                    tracing::warn!(binding_id = %hex(key), store = %self.store.location(), bytes = n, %reason, "stored binding of another release left in place; it will be built again (give each release its own store during a rolling upgrade)");
                    return Ok(None);
                }
                tracing::warn!(binding_id = %hex(key), store = %self.store.location(), bytes = n, %reason, "stored binding refused; it will be built again");
                if let Err(e) = self.store.remove(key).await {
                    tracing::warn!(binding_id = %hex(key), error = %e, "could not delete the refused stored binding");
                }
                Ok(None)
            }
            Err(join) => {
                tracing::error!(binding_id = %hex(key), error = %join, "decoding a stored binding failed");
                Ok(None)
            }
        }
    }

    /// Writes `entry` under `key`. A failed write is warned about and
    /// counted by the store; the binding itself is still answered.
    pub async fn save(&self, key: &Key, entry: Arc<Entry>) {
        let k = *key;
        let bytes = match tokio::task::spawn_blocking(move || encode(&entry, &k)).await {
            Ok(bytes) => bytes,
            Err(join) => {
                tracing::error!(binding_id = %hex(key), error = %join, "encoding a binding for the store failed");
                return;
            }
        };
        let n = bytes.len();
        match self.store.put(key, bytes).await {
            Ok(()) => tracing::info!(binding_id = %hex(key), bytes = n, "written to the binding store"),
            Err(e) => {
                tracing::warn!(binding_id = %hex(key), store = %self.store.location(), error = %e, "binding store write failed")
            }
        }
    }

    /// Makes sure the store holds `entry` under `key`: writes it when the
    /// store lost it (another replica's size limit evicted it, an operator
    /// deleted it) while this replica kept it in memory. A store that
    /// cannot be asked is warned about, and nothing is written.
    pub async fn ensure(&self, key: &Key, entry: Arc<Entry>) {
        match self.store.contains(key).await {
            Ok(true) => {}
            Ok(false) => {
                tracing::info!(binding_id = %hex(key), store = %self.store.location(), "the binding store lost this binding; writing it again");
                self.save(key, entry).await;
            }
            Err(e @ StoreError::Paused { .. }) => {
                tracing::debug!(binding_id = %hex(key), error = %e, "binding store paused: not checked")
            }
            Err(e) => {
                tracing::warn!(binding_id = %hex(key), store = %self.store.location(), error = %e, "binding store check failed")
            }
        }
    }

    /// Deletes the stored entry `key` (`DELETE /v1/bindings/{id}`), if any:
    /// whether the store held it, or the store's error (warned about; the
    /// stored copy may remain).
    pub async fn remove(&self, key: &Key) -> Result<bool, StoreError> {
        self.store.remove(key).await.inspect_err(|e| {
            tracing::warn!(binding_id = %hex(key), error = %e, "binding store delete failed");
        })
    }
}
