//! `BindingRequest` → validated core inputs → `curvenet_core::Binding`.
//! Everything cheap is checked before the expensive steps (the curvenet
//! analysis, the cut and the factorisation); every message names the array
//! and index it refers to.

use std::sync::Mutex;
use std::time::Instant;

use curvenet_core::binding::CutOptions;
use curvenet_core::binding::surface::Surface;
use curvenet_core::blend_shapes::{BlendShape, BlendShapes};
use curvenet_core::{BindOptions, BindWarning, Binding, Cancel, Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};
use curvenet_schema::wire::{BindingRequest, BindingResponse, BindingStats, BindingTimings, SegmentAt, Warning};

use crate::cache::{Entry, Key, hex};
use crate::error::{Code, Phase, ServiceError};
use crate::limits::{Prediction, WorkLimits};

/// Binding options with the defaults filled in (what the id hashes).
#[derive(Debug, Clone, Copy)]
pub struct EffectiveOptions {
    pub strict: bool,
    pub snap_tolerance: f64,
    pub max_projection_distance: f64,
}

impl EffectiveOptions {
    /// The options of `req`, checked: tolerances finite, snapping in
    /// `[0, 0.1]`, the projection distance in `(0, 10]`.
    pub fn of(req: &BindingRequest) -> Result<Self, ServiceError> {
        let d = CutOptions::default();
        let o = &req.options;
        let snap = o.snap_tolerance.unwrap_or(d.snap_tolerance);
        let far = o.max_projection_distance.unwrap_or(d.max_projection_distance);
        if !(snap.is_finite() && (0.0..=0.1).contains(&snap)) {
            return Err(ServiceError::new(
                Code::InvalidParameter,
                format!("options.snap_tolerance must be in [0, 0.1], got {snap}"),
            ));
        }
        if !(far.is_finite() && far > 0.0 && far <= 10.0) {
            return Err(ServiceError::new(
                Code::InvalidParameter,
                format!("options.max_projection_distance must be in (0, 10], got {far}"),
            ));
        }
        Ok(Self { strict: o.strict, snap_tolerance: snap, max_projection_distance: far })
    }

    fn bind_options(&self, cancel: Cancel) -> BindOptions {
        let mut cut = CutOptions::default();
        cut.snap_tolerance = self.snap_tolerance;
        cut.max_projection_distance = self.max_projection_distance;
        let mut o = BindOptions::default().with_strict(self.strict).with_cancel(cancel);
        o.cut = cut;
        o
    }
}

/// Largest coordinate magnitude accepted anywhere (points, pools, offsets):
/// an f32 (the wire and output type) spaces its values 1e8 apart at 1e15,
/// so larger values are no longer geometry, and their squares stay far from
/// overflowing the f64 arithmetic of the core.
pub const MAX_COORDINATE: f64 = 1e15;

/// Largest blend-shape weight magnitude accepted (weights are about 0..1;
/// UsdSkel extrapolates linearly beyond, and beyond a million nothing useful
/// remains).
pub const MAX_WEIGHT: f64 = 1e6;

/// Checks what can be checked without building anything: counts,
/// indices, finiteness and magnitudes, sample densities, blend-shape point
/// indices. Names the offending element. Allocates at most one bit per
/// mesh vertex (the duplicate check of point indices).
pub fn validate(req: &BindingRequest) -> Result<(), ServiceError> {
    let n = req.projection_points.len();
    if n == 0 {
        return Err(ServiceError::new(Code::EmptyInput, "projection_points is empty"));
    }
    check_points(&req.projection_points, "projection_points")?;
    if req.curvenets.is_empty() {
        return Err(ServiceError::new(Code::EmptyInput, "curvenets is empty: a binding needs at least one curvenet"));
    }
    for (k, c) in req.curvenets.iter().enumerate() {
        if !(c.sample_density.is_finite() && c.sample_density > 0.0) {
            return Err(ServiceError::new(
                Code::InvalidParameter,
                format!("curvenets[{k}].sample_density must be finite and positive, got {}", c.sample_density),
            ));
        }
        if c.pool.is_empty() {
            return Err(ServiceError::new(Code::EmptyInput, format!("curvenets[{k}].pool is empty")));
        }
        if c.splines.is_empty() {
            return Err(ServiceError::new(Code::EmptyInput, format!("curvenets[{k}].splines is empty")));
        }
        check_points(&c.pool, &format!("curvenets[{k}].pool"))?;
        for (s, spline) in c.splines.iter().enumerate() {
            if let Some(&v) = spline.iter().find(|&&v| v as usize >= c.pool.len()) {
                return Err(ServiceError::new(
                    Code::IndexOutOfRange,
                    format!(
                        "curvenets[{k}].splines[{s}] refers to control point {v}, but the pool has {}",
                        c.pool.len()
                    ),
                ));
            }
        }
    }
    let mut seen = Vec::new();
    for (k, s) in req.blend_shapes.iter().enumerate() {
        check_points(&s.offsets, &format!("blend_shapes[{k}].offsets"))?;
        for (i, ib) in s.inbetweens.iter().enumerate() {
            if !(ib.weight.is_finite() && ib.weight.abs() <= MAX_WEIGHT) {
                return Err(ServiceError::new(
                    Code::InvalidParameter,
                    format!(
                        "blend_shapes[{k}].inbetweens[{i}].weight must be finite and at most {MAX_WEIGHT:e} in magnitude, got {}",
                        ib.weight
                    ),
                ));
            }
            check_points(&ib.offsets, &format!("blend_shapes[{k}].inbetweens[{i}].offsets"))?;
        }
        if let Some(ix) = &s.point_indices {
            if let Some((i, &v)) = ix.iter().enumerate().find(|(_, v)| **v as usize >= n) {
                return Err(ServiceError::new(
                    Code::IndexOutOfRange,
                    format!("blend_shapes[{k}].point_indices[{i}] is vertex {v}, but the mesh has {n} vertices"),
                ));
            }
            // Each vertex at most once: UsdSkel's point indices name distinct points.
            seen.clear();
            seen.resize(n.div_ceil(64), 0u64);
            for (i, &v) in ix.iter().enumerate() {
                let (word, bit) = (v as usize / 64, 1u64 << (v % 64));
                if seen[word] & bit != 0 {
                    let first = ix.iter().position(|&x| x == v).unwrap_or(0);
                    return Err(ServiceError::new(
                        Code::InvalidParameter,
                        format!(
                            "blend_shapes[{k}].point_indices[{i}] repeats vertex {v} (first at point_indices[{first}]); each vertex may appear once"
                        ),
                    ));
                }
                seen[word] |= bit;
            }
        }
    }
    Ok(())
}

/// Checks points: every coordinate finite (`non_finite`) and at most
/// [`MAX_COORDINATE`] in magnitude (`invalid_parameter`), naming `what` and the index.
pub fn check_points(points: &[[f64; 3]], what: &str) -> Result<(), ServiceError> {
    match points.iter().position(|p| !p.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORDINATE)) {
        None => Ok(()),
        Some(i) if points[i].iter().all(|x| x.is_finite()) => Err(ServiceError::new(
            Code::InvalidParameter,
            format!("{what}[{i}] = {:?} is larger than {MAX_COORDINATE:e} in magnitude", points[i]),
        )),
        Some(i) => {
            Err(ServiceError::new(Code::NonFinite, format!("{what}[{i}] has a non-finite coordinate {:?}", points[i])))
        }
    }
}

/// Predicts what binding `req` (validated) will cost and checks it against
/// `limits` (see limits.rs). Builds the mesh's topology to measure its mean
/// edge length: allocations proportional to the request, nothing more.
pub fn predict(req: &BindingRequest, limits: &WorkLimits) -> Result<Prediction, ServiceError> {
    let mesh = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, req.projection_points.len())
        .map_err(|e| ServiceError::core(e, Phase::Bind).context("mesh"))?;
    let mean_edge_length = mesh.mean_edge_length(&req.projection_points);
    if !(mean_edge_length.is_finite() && mean_edge_length > 0.0) {
        return Err(ServiceError::new(
            Code::InvalidMesh,
            format!("mesh: its mean edge length is {mean_edge_length}: every point coincides"),
        ));
    }
    crate::limits::check(req, mean_edge_length, limits)
}

/// Builds the entry for `req` (already validated): the curvenet analysis,
/// the binding, the blend shapes. CPU-heavy: run it off the async runtime.
/// `cancel` stops it (`Error::Cancelled`, flagged on the returned error);
/// `keep` workspaces are budgeted in the entry's size (one per solve thread).
pub fn build(
    req: &BindingRequest,
    key: Key,
    topology: Key,
    options: EffectiveOptions,
    cancel: Cancel,
    keep: usize,
) -> Result<Entry, ServiceError> {
    let t0 = Instant::now();
    let n = req.projection_points.len();
    let mesh = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, n)
        .map_err(|e| ServiceError::core(e, Phase::Bind).context("mesh"))?;
    // Blend shapes first: cheap, and a bad shape should not cost a factorisation.
    let shapes = req
        .blend_shapes
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
            BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib)
                .map_err(|e| ServiceError::core(e, Phase::Bind).context(&format!("blend_shapes[{k}]")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n_shapes = shapes.len();
    let shapes = (!shapes.is_empty()).then(|| BlendShapes::new(n, shapes));

    // One surface (validation, face planes, closest-point BVH) serves the
    // curvenets' sampling and the binding.
    let t_surface = Instant::now();
    let surface =
        Surface::new(&mesh, &req.projection_points).map_err(|e| ServiceError::core(e, Phase::Bind).context("mesh"))?;
    let surface_ms = t_surface.elapsed().as_secs_f64() * 1e3;
    let stopped = |e| ServiceError::core(e, Phase::Bind);
    cancel.check("the curvenet analysis").map_err(stopped)?;
    let layouts = req
        .curvenets
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let ctx = format!("curvenets[{k}]");
            let net =
                Curvenet::new(&c.splines, &c.pool).map_err(|e| ServiceError::core(e, Phase::Bind).context(&ctx))?;
            let sampling = SamplingOptions::default().with_density(c.sample_density);
            CurvenetLayout::with_closest_point(&net, surface.closest_points(), surface.mean_edge_length(), &sampling)
                .map_err(|e| ServiceError::core(e, Phase::Bind).context(&ctx))
        })
        .collect::<Result<Vec<_>, _>>()?;
    // The surface is timed on its own (`surface_ms`), not as analysis.
    let analysis_ms = t0.elapsed().as_secs_f64() * 1e3 - surface_ms;
    let refs: Vec<&CurvenetLayout> = layouts.iter().collect();
    let binding = Binding::with_surface(surface, &refs, &options.bind_options(cancel), surface_ms)
        .map_err(|e| ServiceError::core(e, Phase::Bind))?;
    drop(layouts);
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;

    // What the entry holds, measured (see `curvenet_core::heap`): the
    // binding, the shapes, the projection pose, and the workspaces frames
    // reuse (one per solve thread; the first is made now and measured).
    let workspace = binding.workspace();
    let keep = keep.max(1);
    let size_bytes = (binding.heap_bytes()
        + std::mem::size_of::<Binding>()
        + shapes.as_ref().map_or(0, BlendShapes::heap_bytes)
        + req.projection_points.len() * std::mem::size_of::<[f64; 3]>()
        + keep * workspace.heap_bytes()
        + ENTRY_OVERHEAD) as u64;
    let s = binding.stats();
    let t = binding.timings();
    let response = BindingResponse {
        binding_id: hex(&key),
        topology_hash: hex(&topology),
        cached: false,
        vertices: n,
        control_points: req.curvenets.iter().map(|c| c.pool.len()).collect(),
        blend_shapes: n_shapes,
        size_bytes,
        stats: BindingStats::from(&s),
        timings: BindingTimings::new(analysis_ms, &t, total_ms),
        warnings: binding.warnings().iter().map(warning).collect(),
    };
    Ok(Entry {
        id: response.binding_id.clone(),
        topology_hash: response.topology_hash.clone(),
        binding,
        shapes,
        n_shapes,
        projection_points: req.projection_points.clone(),
        response,
        size_bytes,
        keep_workspaces: keep,
        workspaces: Mutex::new(vec![workspace]),
    })
}

/// Bytes of an entry besides its measured arrays: the entry, its strings
/// and its response (warnings), rounded up.
const ENTRY_OVERHEAD: usize = 4096;

fn warning(w: &BindWarning) -> Warning {
    let (code, segment) = match w {
        BindWarning::UntouchedComponent { .. } => ("untouched_component", None),
        BindWarning::IslandsRemoved { .. } => ("islands_removed", None),
        BindWarning::DegenerateCutFaces { .. } => ("degenerate_cut_faces", None),
        BindWarning::FacesSplit { .. } => ("faces_split", None),
        BindWarning::CurvesTouch { .. } => ("curves_touch", None),
        BindWarning::SegmentDetour { segment, t, position, path_length, segment_length } => (
            "segment_detour",
            Some(SegmentAt {
                curvenet: segment.curvenet,
                spline: segment.spline,
                segment: segment.segment,
                t: *t,
                position: *position,
                path_length: path_length.is_finite().then_some(*path_length),
                segment_length: *segment_length,
            }),
        ),
        _ => ("other", None),
    };
    Warning { code: code.into(), message: w.to_string(), segment }
}
