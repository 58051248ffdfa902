//! `bake --store`: a shot's bindings shared through a binding store (a
//! directory or `s3://`, the service's store), so that the chunks of a shot
//! on a farm bind each mesh once: the first to need a binding builds and
//! writes it, the others read it (in a fraction of the build time).
//!
//! A bake binding is named by blake3 of everything its deformer is built
//! from (`curvenet_core::DeformerInput::write_content`), not by the
//! service's binding id: the bake builds from USD, the service from its
//! wire request. Its blob is the service's stored envelope
//! (`curvenet_server::stored`) without a binding description. A blob that
//! fails any check is warned about, deleted and built again; a store that
//! cannot be read or written is warned about and the bake binds as without
//! one. The output does not depend on where a binding came from: a loaded
//! deformer's frames are bit for bit the built one's.

use std::sync::Arc;

use curvenet_core::{Deformer, DeformerInput};
use curvenet_server::Metrics;
use curvenet_server::store::BindingStore;
use curvenet_server::stored::{Meta, decode_blob, encode_blob};

use super::{CliError, CliResult};

/// Where a bake's deformer came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Built here, and written to the store when there is one.
    Built,
    /// Built here; the store could not take it (warned about).
    BuiltNotStored,
    Loaded,
}

/// An open binding store and the runtime its I/O runs on.
pub struct BakeStore {
    runtime: tokio::runtime::Runtime,
    store: BindingStore,
}

impl BakeStore {
    /// Opens the store at `location` (see `serve --store`), at most
    /// `max_bytes`. A location or `AWS_*` configuration that cannot work
    /// fails the bake (exit 2: every chunk would fail alike); a store that
    /// cannot be reached or written now is warned about through `warn`, and
    /// the bake goes on without it (None): a farm chunk binds rather than
    /// waits for the store.
    pub fn open(location: &str, max_bytes: Option<u64>, warn: &mut dyn FnMut(String)) -> CliResult<Option<Self>> {
        if max_bytes == Some(0) {
            return Err(CliError::Input("--store-bytes must be positive: 0 would delete every binding written".into()));
        }
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .thread_name("curvenet-store")
            .build()
            .map_err(|e| CliError::Io { context: "starting the store's runtime".into(), source: e })?;
        match runtime.block_on(BindingStore::open(location, max_bytes, Arc::new(Metrics::new()))) {
            Ok(store) => {
                if store.read_only() {
                    warn(format!(
                        "--store {}: read-only for this process: bindings are read from it, none written",
                        store.location()
                    ));
                }
                // No stored file larger than half the machine's memory is read (a
                // sparse or garbage file under an entry's name must not exhaust it).
                let store = match super::memory_fraction(2) {
                    Some(max) => store.with_max_blob_bytes(max),
                    None => store,
                };
                Ok(Some(Self { runtime, store }))
            }
            Err(e) if e.is_config() => Err(CliError::Input(format!("--store: {e}"))),
            Err(e) => {
                warn(format!("--store: {e}; binding without the store"));
                Ok(None)
            }
        }
    }

    /// The deformer of `input`: read from the store, else made by `build`
    /// and written to it. `what` names the mesh in warnings.
    pub fn deformer(
        &self,
        input: &DeformerInput<'_>,
        what: &str,
        build: impl FnOnce() -> CliResult<Deformer>,
    ) -> CliResult<(Deformer, Source)> {
        let mut hasher = blake3::Hasher::new();
        hasher.update(b"curvenet bake binding v1");
        input.write_content(|piece| {
            hasher.update(piece);
        });
        let key: [u8; 32] = *hasher.finalize().as_bytes();
        let location = self.store.location();
        // A StoreError names the store itself; the other messages name it here.
        let warn = |m: String| eprintln!("curvenet: warning: {what}: {m}");
        match self.runtime.block_on(self.store.get(&key)) {
            Ok(Some(bytes)) => match decode_blob(&bytes, &key) {
                Ok((_, deformer)) => return Ok((deformer, Source::Loaded)),
                Err(reason) => {
                    warn(format!("binding store {location}: the stored binding is refused ({reason}); binding again"));
                    // Another release's blob is left for it (stored.rs).
                    if !reason.is_other_version()
                        && let Err(e) = self.runtime.block_on(self.store.remove(&key))
                    {
                        warn(format!("could not delete the refused binding: {e}"));
                    }
                }
            },
            Ok(None) => {}
            Err(e) => warn(format!("{e}; binding without the stored copy")),
        }
        let deformer = build()?;
        let bytes = encode_blob(&key, &Meta::new(None, None), &deformer);
        if let Some(max) = self.store.max_bytes()
            && bytes.len() as u64 > max
        {
            warn(format!(
                "binding store {location}: the binding ({} bytes) alone is larger than --store-bytes ({max}): it is \
                 kept only until the next write",
                bytes.len()
            ));
        }
        if let Err(e) = self.runtime.block_on(self.store.put(&key, bytes)) {
            warn(format!("{e}; the bake goes on without writing it"));
            return Ok((deformer, Source::BuiltNotStored));
        }
        Ok((deformer, Source::Built))
    }
}
