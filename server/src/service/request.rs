//! A binding request checked before anything is built: its options with
//! the defaults filled in (what the id hashes), the bounds on every number,
//! counts and indices (each message names the array and index it refers
//! to), and the predicted work against the limits.

use curvenet_core::{BindOptions, Cancel, CutOptions, PolyMesh};
use curvenet_schema::wire::BindingRequest;

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

    pub(crate) fn bind_options(&self, cancel: Cancel) -> BindOptions {
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
            )
            .detail(|d| {
                d.curvenet = Some(k as u32);
                d.what = Some("sample_density".into());
            }));
        }
        if c.pool.is_empty() {
            return Err(ServiceError::new(Code::EmptyInput, format!("curvenets[{k}].pool is empty"))
                .detail(|d| (d.curvenet, d.what) = (Some(k as u32), Some("pool".into()))));
        }
        if c.splines.is_empty() {
            return Err(ServiceError::new(Code::EmptyInput, format!("curvenets[{k}].splines is empty"))
                .detail(|d| (d.curvenet, d.what) = (Some(k as u32), Some("splines".into()))));
        }
        check_points(&c.pool, &format!("curvenets[{k}].pool"))
            .map_err(|e| e.detail(|d| d.curvenet = Some(k as u32)))?;
        for (s, spline) in c.splines.iter().enumerate() {
            if let Some(&v) = spline.iter().find(|&&v| v as usize >= c.pool.len()) {
                return Err(ServiceError::new(
                    Code::IndexOutOfRange,
                    format!(
                        "curvenets[{k}].splines[{s}] refers to control point {v}, but the pool has {}",
                        c.pool.len()
                    ),
                )
                .detail(|d| {
                    d.curvenet = Some(k as u32);
                    d.spline = Some(s as u32);
                    d.control_point = Some(v);
                }));
            }
        }
    }
    validate_cage(req)?;
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

/// Checks the cage and the skeleton cheaply: the cage's points, its
/// triangles' indices, and a skeleton with a cage and a skin (the coupled
/// rig needs it) whose parents and bind transforms agree. The cage's
/// closedness and orientation are core's (`Cage::new`), named there.
fn validate_cage(req: &BindingRequest) -> Result<(), ServiceError> {
    if let Some(skeleton) = req.skin.as_ref().and_then(|s| s.skeleton.as_ref()) {
        let n = skeleton.parents.len();
        if skeleton.bind_transforms.len() != n {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!(
                    "skin.skeleton.bind_transforms has {} transforms, but skin.skeleton.parents has {n} joints",
                    skeleton.bind_transforms.len()
                ),
            )
            .detail(|d| {
                d.what = Some("skin.skeleton.bind_transforms".into());
                d.expected = Some(n);
                d.got = Some(skeleton.bind_transforms.len());
            }));
        }
        if let Some(skin) = &req.skin
            && skin.joints as usize != n
        {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("skin.skeleton.parents has {n} joints, but skin.joints is {}", skin.joints),
            )
            .detail(|d| {
                d.what = Some("skin.skeleton.parents".into());
                d.expected = Some(skin.joints as usize);
                d.got = Some(n);
            }));
        }
        for (j, &p) in skeleton.parents.iter().enumerate() {
            if p != -1 && !(0..j as i64).contains(&p) {
                return Err(ServiceError::new(
                    Code::IndexOutOfRange,
                    format!("skin.skeleton.parents[{j}] is {p}: a parent is an earlier joint, or -1 for a root"),
                )
                .detail(|d| (d.what, d.index) = (Some("skin.skeleton.parents".into()), Some(j))));
            }
        }
        if let Some(j) =
            skeleton.bind_transforms.iter().position(|m| !m.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORDINATE))
        {
            return Err(ServiceError::new(
                Code::NonFinite,
                format!(
                    "skin.skeleton.bind_transforms[{j}] has a value that is not finite or beyond {MAX_COORDINATE:e}"
                ),
            )
            .detail(|d| (d.what, d.index) = (Some("skin.skeleton.bind_transforms".into()), Some(j))));
        }
    }
    let Some(cage) = &req.cage else { return Ok(()) };
    if let Some(skin) = &req.skin
        && skin.skeleton.is_none()
    {
        return Err(ServiceError::new(
            Code::InvalidParameter,
            format!(
                "skin.skeleton is required with a cage: the cage is coupled with the skin's {} joints and relocates them \
                 (give parents and bind_transforms)",
                skin.joints
            ),
        )
        .detail(|d| d.what = Some("skin.skeleton".into())));
    }
    check_points(&cage.points, "cage.points")?;
    let c = cage.points.len();
    for (t, tri) in cage.triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v as usize >= c) {
            return Err(ServiceError::new(
                Code::IndexOutOfRange,
                format!("cage.triangles[{t}] refers to cage vertex {v}, but the cage has {c} points"),
            )
            .detail(|d| {
                d.what = Some("cage.triangles".into());
                d.index = Some(t);
                d.face = Some(t);
                d.vertex = Some(v);
            }));
        }
    }
    Ok(())
}

/// Checks points: every coordinate finite (`non_finite`) and at most
/// [`MAX_COORDINATE`] in magnitude (`invalid_parameter`), naming `what` and the index.
pub fn check_points(points: &[[f64; 3]], what: &str) -> Result<(), ServiceError> {
    let at = |i: usize| {
        // `posed[0]` is the array `posed` (the curvenet is the caller's detail).
        let array = what.split('[').next().unwrap_or(what).to_string();
        move |d: &mut curvenet_schema::wire::ErrorDetails| (d.what, d.index) = (Some(array), Some(i))
    };
    match points.iter().position(|p| !p.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORDINATE)) {
        None => Ok(()),
        Some(i) if points[i].iter().all(|x| x.is_finite()) => Err(ServiceError::new(
            Code::InvalidParameter,
            format!("{what}[{i}] = {:?} is larger than {MAX_COORDINATE:e} in magnitude", points[i]),
        )
        .detail(at(i))),
        Some(i) => {
            Err(ServiceError::new(Code::NonFinite, format!("{what}[{i}] has a non-finite coordinate {:?}", points[i]))
                .detail(at(i)))
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
