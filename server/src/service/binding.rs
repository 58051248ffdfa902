//! `BindingRequest` → validated core inputs → `curvenet_core::Binding`.
//! Everything cheap is checked before the expensive steps (the curvenet
//! analysis, the cut and the factorisation); every message names the array
//! and index it refers to.

use std::sync::Mutex;
use std::time::Instant;

use curvenet_core::binding::CutOptions;
use curvenet_core::binding::surface::Surface;
use curvenet_core::blend_shapes::{BlendShape, BlendShapes};
use curvenet_core::{BindOptions, BindWarning, Binding, Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};
use curvenet_schema::wire::{BindingRequest, BindingResponse, BindingStats, BindingTimings, SegmentAt, Warning};

use crate::cache::{Entry, Key, estimate_bytes, hex};
use crate::error::{Code, Phase, ServiceError};

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

    fn bind_options(&self) -> BindOptions {
        let mut cut = CutOptions::default();
        cut.snap_tolerance = self.snap_tolerance;
        cut.max_projection_distance = self.max_projection_distance;
        let mut o = BindOptions::default().with_strict(self.strict);
        o.cut = cut;
        o
    }
}

/// Checks what can be checked without building anything: counts,
/// indices, finiteness, sample densities. Names the offending element.
pub fn validate(req: &BindingRequest) -> Result<(), ServiceError> {
    let n = req.projection_points.len();
    if n == 0 {
        return Err(ServiceError::new(Code::EmptyInput, "projection_points is empty"));
    }
    non_finite(&req.projection_points, "projection_points")?;
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
        non_finite(&c.pool, &format!("curvenets[{k}].pool"))?;
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
    for (k, s) in req.blend_shapes.iter().enumerate() {
        non_finite(&s.offsets, &format!("blend_shapes[{k}].offsets"))?;
        for (i, ib) in s.inbetweens.iter().enumerate() {
            non_finite(&ib.offsets, &format!("blend_shapes[{k}].inbetweens[{i}].offsets"))?;
        }
        if let Some(ix) = &s.point_indices
            && let Some((i, &v)) = ix.iter().enumerate().find(|(_, v)| **v as usize >= n)
        {
            return Err(ServiceError::new(
                Code::IndexOutOfRange,
                format!("blend_shapes[{k}].point_indices[{i}] is vertex {v}, but the mesh has {n} vertices"),
            ));
        }
    }
    Ok(())
}

/// The first non-finite point of `points`, as a `non_finite` error naming `what` and the index.
pub fn non_finite(points: &[[f64; 3]], what: &str) -> Result<(), ServiceError> {
    match points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        None => Ok(()),
        Some(i) => {
            Err(ServiceError::new(Code::NonFinite, format!("{what}[{i}] has a non-finite coordinate {:?}", points[i])))
        }
    }
}

/// Builds the entry for `req` (already validated): the curvenet analysis,
/// the binding, the blend shapes. CPU-heavy: run it off the async runtime.
pub fn build(req: &BindingRequest, key: Key, topology: Key, options: EffectiveOptions) -> Result<Entry, ServiceError> {
    let t0 = Instant::now();
    let n = req.projection_points.len();
    let mesh = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, n)
        .map_err(|e| ServiceError::core(e, Phase::Bind).context("mesh"))?;
    // Blend shapes first: cheap, and a bad shape should not cost a factorisation.
    let mut shape_offsets = 0;
    let shapes = req
        .blend_shapes
        .iter()
        .enumerate()
        .map(|(k, s)| {
            shape_offsets += s.offsets.len() * (1 + s.inbetweens.len());
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
    let binding = Binding::with_surface(surface, &refs, &options.bind_options(), surface_ms)
        .map_err(|e| ServiceError::core(e, Phase::Bind))?;
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;

    let size_bytes = estimate_bytes(&binding, shape_offsets) + (n as u64) * 24;
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
        stats: BindingStats {
            mesh_vertices: s.mesh_vertices,
            mesh_faces: s.mesh_faces,
            samples: s.samples,
            segments: s.segments,
            cut_vertices: s.cut_vertices,
            cut_faces: s.cut_faces,
            cut_halfedges: s.cut_halfedges,
            cracks: s.cracks,
            islands_removed: s.islands_removed,
            chord_paths: s.embedding.chord,
            straightest_paths: s.embedding.straightest,
            fallback_paths: s.embedding.fallback,
            segments_left_out: s.embedding.disconnected,
            detours: s.detours,
            unknowns: s.unknowns,
            constraints: s.constraints,
            factor_nonzeros: s.factor_nonzeros,
        },
        timings: BindingTimings {
            analysis_ms,
            surface_ms: t.surface_ms,
            cutting_ms: t.cutting_ms,
            assembly_ms: t.assembly_ms,
            factor_ms: t.factor_ms,
            total_ms,
        },
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
        workspaces: Mutex::default(),
    })
}

fn warning(w: &BindWarning) -> Warning {
    let (code, segment) = match w {
        BindWarning::UntouchedComponent { .. } => ("untouched_component", None),
        BindWarning::IslandsRemoved { .. } => ("islands_removed", None),
        BindWarning::DegenerateCutFaces { .. } => ("degenerate_cut_faces", None),
        BindWarning::FacesSplit { .. } => ("faces_split", None),
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
