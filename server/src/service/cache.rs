//! The binding cache: content hash → `Arc<Entry>`, bounded by an estimate
//! of the bindings' memory, least recently used evicted first (moka, LRU
//! policy). Concurrent requests for one new key compute it once.
//!
//! With a binding store (`serve --store`, stored.rs), a key missing from
//! memory is looked up in the store before it is built or answered
//! unknown, and a binding built here is written to the store before the
//! post that built it is answered (so a replica that gets the id next finds
//! it). Concurrent requests for one key load it once, too.
//!
//! # The content hash
//!
//! A binding id is blake3 over a fixed binary encoding (not the JSON text,
//! so formatting and field order do not matter) of exactly what the result
//! of a frame depends on: the topology, the projection points as f64 bits,
//! each curvenet (pool as f64 bits, splines, sample density), the effective
//! options (defaults filled in, so an explicit default and an absent option
//! give one id) and, only when there are any, the blend shapes, the skin
//! (with its skeleton) and the cage (points as f64 bits, triangles). Every array
//! is preceded by its length, so no two requests encode alike.

use std::sync::Arc;

use curvenet_schema::wire::{BindingRequest, CurvenetSkinSpec};
use moka::future::Cache;
use moka::notification::RemovalCause;
use moka::policy::EvictionPolicy;

use crate::entry::{Entry, Key};
use crate::error::{Code, ServiceError};
use crate::metrics::Metrics;
use crate::request::EffectiveOptions;
use crate::stored::StoredBindings;

/// `cache_too_small`: a binding of `bytes` (measured, or predicted "at least")
/// does not fit in a cache of `capacity`.
pub fn too_small(bytes: u64, capacity: u64, how: &str) -> ServiceError {
    ServiceError::new(
        Code::CacheTooSmall,
        format!(
            "the binding needs {how} {bytes} bytes but the whole cache holds {capacity} (CURVENET_CACHE_BYTES / \
             --cache-bytes); a binding's size includes a frame workspace and a batch's group workspace per solve \
             thread (--solve-threads), most of it on small meshes with many threads"
        ),
    )
}

/// The cache: moka's future cache weighed in KiB (its weigher is u32).
pub struct BindingCache {
    cache: Cache<Key, Arc<Entry>>,
    capacity_bytes: u64,
    metrics: Arc<Metrics>,
    stored: Option<StoredBindings>,
}

impl BindingCache {
    pub fn new(capacity_bytes: u64, metrics: Arc<Metrics>, stored: Option<StoredBindings>) -> Self {
        let evictions = metrics.cache_evictions.clone();
        let cache = Cache::builder()
            .max_capacity(capacity_bytes / 1024)
            .weigher(|_k: &Key, e: &Arc<Entry>| u32::try_from(e.size_bytes.div_ceil(1024)).unwrap_or(u32::MAX))
            .eviction_policy(EvictionPolicy::lru())
            .eviction_listener(move |_k, _v, cause| {
                if matches!(cause, RemovalCause::Size | RemovalCause::Expired) {
                    evictions.increment(1);
                }
            })
            .build();
        metrics.cache_capacity_bytes.set(capacity_bytes as f64);
        Self { cache, capacity_bytes, metrics, stored }
    }

    /// `key` from the store, if it holds a good entry; `cache_too_small`
    /// when that entry cannot fit in this replica's cache (building it
    /// again would give the same size: the post would fail after the build).
    async fn load(&self, key: &Key) -> Result<Option<Entry>, ServiceError> {
        let Some(stored) = &self.stored else { return Ok(None) };
        let entry = match stored.load(key).await {
            Ok(Some(entry)) => entry,
            Ok(None) => return Ok(None),
            // Its file alone is larger than the cache: not read.
            Err(file_bytes) => return Err(too_small(file_bytes, self.capacity_bytes, "more than")),
        };
        if entry.size_bytes > self.capacity_bytes {
            tracing::warn!(binding_id = %entry.id, bytes = entry.size_bytes, capacity = self.capacity_bytes, "a stored binding does not fit in this replica's cache");
            return Err(too_small(entry.size_bytes, self.capacity_bytes, "about"));
        }
        Ok(Some(entry))
    }

    /// The cached binding `key`, if any (counts a hit or a miss), or else
    /// the stored one (then cached); `cache_too_small` when the stored one
    /// cannot fit in this cache.
    pub async fn get(&self, key: &Key) -> Result<Option<Arc<Entry>>, ServiceError> {
        if let Some(e) = self.cache.get(key).await {
            self.metrics.cache_hits.increment(1);
            return Ok(Some(e));
        }
        self.metrics.cache_misses.increment(1);
        if self.stored.is_none() {
            return Ok(None);
        }
        let entry = self
            .cache
            .entry(*key)
            .or_try_insert_with(async {
                match self.load(key).await {
                    Ok(Some(e)) => Ok(Arc::new(e)),
                    Ok(None) => Err(None),
                    Err(e) => Err(Some(e)),
                }
            })
            .await;
        match entry {
            Ok(e) => Ok(Some(e.into_value())),
            Err(e) => match &*e {
                None => Ok(None),
                Some(e) => Err(e.clone()),
            },
        }
    }

    /// The binding `key`, computed by `compute` unless cached or stored.
    /// Concurrent calls for one key run `compute` once; the others wait for
    /// it (and for its write to the store). Returns the entry and whether it
    /// was found (in memory or in the store) rather than computed.
    pub async fn get_or_compute<F>(&self, key: Key, compute: F) -> Result<(Arc<Entry>, bool), ServiceError>
    where
        F: Future<Output = Result<Entry, ServiceError>>,
    {
        let loaded = std::sync::atomic::AtomicBool::new(false);
        let entry = self
            .cache
            .entry(key)
            .or_try_insert_with(async {
                if let Some(e) = self.load(&key).await? {
                    loaded.store(true, std::sync::atomic::Ordering::Relaxed);
                    return Ok(Arc::new(e));
                }
                let e = Arc::new(compute.await?);
                self.metrics.bindings_computed.increment(1);
                if let Some(stored) = &self.stored {
                    stored.save(&key, e.clone()).await;
                }
                Ok::<_, ServiceError>(e)
            })
            .await
            .map_err(|e: Arc<ServiceError>| (*e).clone())?;
        let fresh = entry.is_fresh() && !loaded.load(std::sync::atomic::Ordering::Relaxed);
        if fresh {
            self.metrics.cache_misses.increment(1)
        } else {
            self.metrics.cache_hits.increment(1)
        }
        let value = entry.into_value();
        if value.size_bytes > self.capacity_bytes {
            self.cache.invalidate(&key).await;
            return Err(too_small(value.size_bytes, self.capacity_bytes, "about"));
        }
        if let Some(stored) = &self.stored
            && !fresh
            && !loaded.load(std::sync::atomic::Ordering::Relaxed)
        {
            // Found in memory: the store may have lost it meanwhile, and the
            // post carries the mesh, so one stat (or HEAD) is cheap beside it.
            stored.ensure(&key, value.clone()).await;
        }
        Ok((value, !fresh))
    }

    /// Drops binding `key` from memory and from the store; whether either
    /// held it. A store that cannot be asked (down, paused) is 503
    /// `unavailable` (the binding is gone from memory, but its stored copy
    /// may remain, and other replicas would load it again): the caller
    /// retries the DELETE.
    pub async fn remove(&self, key: &Key) -> Result<bool, ServiceError> {
        let in_memory = self.cache.remove(key).await.is_some();
        let stored = match &self.stored {
            Some(stored) => stored.remove(key).await.map_err(|e| {
                ServiceError::new(
                    Code::Unavailable,
                    format!("the binding store could not delete the stored copy ({e}); retry the DELETE"),
                )
            })?,
            None => false,
        };
        Ok(in_memory || stored)
    }

    /// Runs moka's pending maintenance (evictions) and updates the gauges.
    pub async fn refresh_gauges(&self) {
        self.cache.run_pending_tasks().await;
        self.metrics.cache_bytes.set((self.cache.weighted_size() * 1024) as f64);
        self.metrics.cache_entries.set(self.cache.entry_count() as f64);
    }
}

/// A blake3 hasher fed through a buffer (one `update` per 64 KiB, not per number).
struct Writer {
    hasher: blake3::Hasher,
    buf: Vec<u8>,
}

impl Writer {
    fn new(domain: &str) -> Self {
        let mut w = Self { hasher: blake3::Hasher::new(), buf: Vec::with_capacity(1 << 16) };
        w.bytes(domain.as_bytes());
        w
    }
    fn bytes(&mut self, b: &[u8]) {
        if self.buf.len() + b.len() > self.buf.capacity() {
            self.hasher.update(&self.buf);
            self.buf.clear();
        }
        if b.len() > self.buf.capacity() {
            self.hasher.update(b);
        } else {
            self.buf.extend_from_slice(b);
        }
    }
    fn u64(&mut self, x: u64) {
        self.bytes(&x.to_le_bytes());
    }
    fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
    fn u32s(&mut self, xs: &[u32]) {
        self.u64(xs.len() as u64);
        for x in xs {
            self.bytes(&x.to_le_bytes());
        }
    }
    fn points(&mut self, ps: &[[f64; 3]]) {
        self.u64(ps.len() as u64);
        for p in ps {
            for c in p {
                self.f64(*c);
            }
        }
    }
    fn finish(mut self) -> Key {
        self.hasher.update(&self.buf);
        *self.hasher.finalize().as_bytes()
    }
}

fn skin_influences(w: &mut Writer, joint_indices: &[i64], joint_weights: &[f64]) {
    w.u64(joint_indices.len() as u64);
    for i in joint_indices {
        w.bytes(&i.to_le_bytes());
    }
    w.u64(joint_weights.len() as u64);
    joint_weights.iter().for_each(|x| w.f64(*x));
}

/// blake3 of the topology alone.
pub fn topology_key(req: &BindingRequest) -> Key {
    let mut w = Writer::new("curvenet topology v1");
    w.u32s(&req.face_vertex_counts);
    w.u32s(&req.face_vertex_indices);
    w.finish()
}

/// The binding id of `req` with its effective options (see the module docs).
pub fn binding_key(req: &BindingRequest, options: &EffectiveOptions) -> Key {
    let mut w = Writer::new("curvenet binding v1");
    w.u32s(&req.face_vertex_counts);
    w.u32s(&req.face_vertex_indices);
    w.points(&req.projection_points);
    w.u64(req.curvenets.len() as u64);
    for c in &req.curvenets {
        w.points(&c.pool);
        w.u64(c.splines.len() as u64);
        for s in &c.splines {
            for i in s {
                w.bytes(&i.to_le_bytes());
            }
        }
        w.f64(c.sample_density);
    }
    w.u64(options.strict as u64);
    w.f64(options.snap_tolerance);
    w.f64(options.max_projection_distance);
    if !req.blend_shapes.is_empty() {
        w.bytes(b"blend shapes");
        w.u64(req.blend_shapes.len() as u64);
        for s in &req.blend_shapes {
            w.points(&s.offsets);
            match &s.point_indices {
                Some(ix) => {
                    w.u64(1);
                    w.u32s(ix);
                }
                None => w.u64(0),
            }
            w.u64(s.inbetweens.len() as u64);
            for ib in &s.inbetweens {
                w.f64(ib.weight);
                w.points(&ib.offsets);
            }
        }
    }
    if let Some(skin) = &req.skin {
        // Absent, nothing is written: the ids of bindings without a rig are unchanged.
        w.bytes(b"skin");
        w.u64(skin.joints as u64);
        w.u64(skin.element_size as u64);
        skin_influences(&mut w, &skin.joint_indices, &skin.joint_weights);
        match &skin.geom_bind_transform {
            Some(m) => {
                w.u64(1);
                m.iter().for_each(|x| w.f64(*x));
            }
            None => w.u64(0),
        }
        w.u64(skin.method as u64);
        w.u64(skin.flexible_iterations as u64);
        w.u64(skin.curvenets.len() as u64);
        for c in &skin.curvenets {
            match c {
                CurvenetSkinSpec::None => w.u64(0),
                CurvenetSkinSpec::Mesh => w.u64(1),
                CurvenetSkinSpec::Weights { element_size, joint_indices, joint_weights } => {
                    w.u64(2);
                    w.u64(*element_size as u64);
                    skin_influences(&mut w, joint_indices, joint_weights);
                }
            }
        }
        if let Some(skeleton) = &skin.skeleton {
            // Absent, nothing is written: the ids of skins without one are unchanged.
            w.bytes(b"skeleton");
            w.u64(skeleton.parents.len() as u64);
            skeleton.parents.iter().for_each(|p| w.bytes(&p.to_le_bytes()));
            w.u64(skeleton.bind_transforms.len() as u64);
            skeleton.bind_transforms.iter().flatten().for_each(|x| w.f64(*x));
        }
    }
    if let Some(cage) = &req.cage {
        w.bytes(b"cage");
        w.points(&cage.points);
        w.u64(cage.triangles.len() as u64);
        cage.triangles.iter().flatten().for_each(|i| w.bytes(&i.to_le_bytes()));
    }
    w.finish()
}
