//! A cached binding: its id (the content key, see cache.rs), its deformer
//! and the answer that described it. Below the cache, the builder and the
//! store's encoding, which all hold entries.

use curvenet_core::{Binding, Deformer};
use curvenet_schema::wire::BindingResponse;

/// A binding id: blake3 of the binding's content.
pub type Key = [u8; 32];

/// One cached binding: its deformer (`curvenet_core::Deformer`: the
/// binding, the blend shapes, the projection pose and the frame workspaces)
/// and the answer that described it.
pub struct Entry {
    pub id: String,
    pub topology_hash: String,
    pub deformer: Deformer,
    /// The answer to the post that computed it (`cached` false).
    pub response: BindingResponse,
    /// Bytes the entry holds, measured when it was built (counted against the
    /// cache): the deformer with one frame workspace per solve thread, and
    /// the group workspaces it keeps once frames are solved in groups on it
    /// (`Deformer::group_bytes`: per solve thread, the service's group size
    /// of frame workspaces and their interleaved block) and the factor's row
    /// copy the first group makes (`Binding::factor_row_copy_bytes`).
    /// Counted from the start: weighing an entry again when its first batch
    /// allocates them raced with removals (the cache lost count) and let one
    /// batch evict every other binding.
    pub size_bytes: u64,
}

impl Entry {
    /// The binding (cut-mesh, factor, analysed curvenets).
    pub fn binding(&self) -> &Binding {
        self.deformer.binding()
    }

    /// The mesh in its projection pose.
    pub fn projection_points(&self) -> &[[f64; 3]] {
        self.deformer.projection_points()
    }

    /// Blend shapes of the binding (the length of a frame's weights).
    pub fn n_shapes(&self) -> usize {
        self.deformer.blend_shapes().len()
    }
}

/// Lowercase hex of a hash.
pub fn hex(bytes: &[u8; 32]) -> String {
    blake3::Hash::from_bytes(*bytes).to_hex().to_string()
}

/// Parses a 64-digit hex binding id.
pub fn parse_key(id: &str) -> Option<Key> {
    blake3::Hash::from_hex(id).ok().map(|h| *h.as_bytes())
}
