//! One frame: parsed (JSON or binary) into a [`Frame`], checked against the
//! binding (counts, finiteness, topology), solved with a reused workspace,
//! blend shapes applied, and encoded back.

use std::time::Instant;

use curvenet_core::FrameInput;
use curvenet_schema::wire::{BlendShapeMode, FrameRequest, FrameResponse};

use crate::binding::{MAX_WEIGHT, check_points};
use crate::cache::Entry;
use crate::error::{Code, Phase, ServiceError};

/// A frame's input, in f64, whatever its wire form.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// One entry per curvenet (`None`: not articulated); empty: none articulated.
    pub posed: Vec<Option<Vec<[f64; 3]>>>,
    pub rest: Option<Vec<[f64; 3]>>,
    pub weights: Option<Vec<f64>>,
    pub mode: BlendShapeMode,
    pub gradients: bool,
    pub topology_hash: Option<String>,
}

impl From<FrameRequest> for Frame {
    fn from(r: FrameRequest) -> Self {
        Self {
            posed: r.posed.unwrap_or_default(),
            rest: r.rest,
            weights: r.blend_shape_weights,
            mode: r.blend_shape_mode,
            gradients: r.gradients,
            topology_hash: r.topology_hash,
        }
    }
}

/// A solved frame, in f64.
pub struct Solved {
    pub points: Vec<[f64; 3]>,
    pub gradients: Option<Vec<[f64; 9]>>,
    pub solve_ms: f64,
}

impl Solved {
    pub fn into_response(self) -> FrameResponse {
        FrameResponse {
            points: self.points.iter().map(|p| p.map(|x| x as f32)).collect(),
            gradients: self.gradients.map(|g| g.iter().map(|m| m.map(|x| x as f32)).collect()),
            solve_ms: self.solve_ms,
        }
    }
}

/// Checks `frame` against the binding: topology hash, counts, finiteness.
/// Messages name the array and index (`posed[1][17]`).
pub fn validate(entry: &Entry, frame: &Frame) -> Result<(), ServiceError> {
    if let Some(h) = &frame.topology_hash
        && !h.eq_ignore_ascii_case(&entry.topology_hash)
    {
        return Err(ServiceError::new(
            Code::TopologyChanged,
            format!(
                "the frame is for topology {h}, but binding {} has topology {}: the mesh changed, so post the new binding and use its id",
                entry.id, entry.topology_hash
            ),
        ));
    }
    let b = &entry.binding;
    if !frame.posed.is_empty() {
        if frame.posed.len() != b.n_curvenets() {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!(
                    "posed has {} entries, but the binding has {} curvenets (one pool or null each)",
                    frame.posed.len(),
                    b.n_curvenets()
                ),
            ));
        }
        for (k, pool) in frame.posed.iter().enumerate() {
            if let Some(pool) = pool {
                if pool.len() != b.n_control_points(k) {
                    return Err(ServiceError::new(
                        Code::CountMismatch,
                        format!(
                            "posed[{k}] has {} control points, but curvenet {k}'s pool has {}",
                            pool.len(),
                            b.n_control_points(k)
                        ),
                    ));
                }
                check_points(pool, &format!("posed[{k}]"))?;
            }
        }
    }
    if let Some(rest) = &frame.rest {
        if rest.len() != b.n_vertices() {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("rest has {} points, but the mesh has {} vertices", rest.len(), b.n_vertices()),
            ));
        }
        check_points(rest, "rest")?;
    }
    if let Some(w) = &frame.weights {
        if w.len() != entry.n_shapes {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!(
                    "blend_shape_weights has {} weights, but the binding has {} blend shapes",
                    w.len(),
                    entry.n_shapes
                ),
            ));
        }
        if let Some(i) = w.iter().position(|x| !x.is_finite()) {
            return Err(ServiceError::new(Code::NonFinite, format!("blend_shape_weights[{i}] is {}", w[i])));
        }
        if let Some(i) = w.iter().position(|x| x.abs() > MAX_WEIGHT) {
            return Err(ServiceError::new(
                Code::InvalidParameter,
                format!("blend_shape_weights[{i}] is {}, larger than {MAX_WEIGHT:e} in magnitude", w[i]),
            ));
        }
    }
    Ok(())
}

/// Solves a validated frame. CPU-heavy: run it on the solve pool.
pub fn solve(entry: &Entry, frame: &Frame) -> Result<Solved, ServiceError> {
    let t0 = Instant::now();
    let b = &entry.binding;
    let n = b.n_vertices();
    let weights = frame.weights.as_deref().filter(|w| w.iter().any(|&x| x != 0.0));
    let shapes = entry.shapes.as_ref().zip(weights);
    let posed: Vec<Option<&[[f64; 3]]>> = if frame.posed.is_empty() {
        vec![None; b.n_curvenets()]
    } else {
        frame.posed.iter().map(|p| p.as_deref()).collect()
    };
    // The `before` mode sculpts the rest pose (the projection pose when the frame has none).
    let sculpted_rest = match (shapes, frame.mode) {
        (Some((s, w)), BlendShapeMode::Before) => {
            let mut rest = frame.rest.clone().unwrap_or_else(|| entry.projection_points.clone());
            s.add_to(w, &mut rest).map_err(|e| ServiceError::core(e, Phase::Frame))?;
            Some(rest)
        }
        _ => None,
    };
    let rest = sculpted_rest.as_deref().or(frame.rest.as_deref());
    let after = shapes.filter(|_| frame.mode == BlendShapeMode::After);
    let mut points = vec![[0.0; 3]; n];
    let mut gradients = (frame.gradients || after.is_some()).then(|| vec![[0.0; 9]; n]);
    let mut ws = entry.take_workspace();
    let r = b.deform(
        &FrameInput { posed: &posed, rest, ..Default::default() },
        &mut ws,
        &mut points,
        gradients.as_deref_mut(),
    );
    entry.give_workspace(ws);
    r.map_err(|e| ServiceError::core(e, Phase::Frame))?;
    if let (Some((s, w)), Some(g)) = (after, gradients.as_deref()) {
        s.add_deformed(w, g, &mut points).map_err(|e| ServiceError::core(e, Phase::Frame))?;
    }
    let gradients = gradients.filter(|_| frame.gradients);
    finite_in_f32(&points, "points")?;
    if let Some(g) = &gradients {
        finite_in_f32(g, "gradients")?;
    }
    Ok(Solved { points, gradients, solve_ms: t0.elapsed().as_secs_f64() * 1e3 })
}

/// Refuses a result that is not finite once sent as f32 (a pose or weights
/// extreme enough to overflow): `non_finite`, naming the first bad vertex.
fn finite_in_f32<const N: usize>(values: &[[f64; N]], what: &str) -> Result<(), ServiceError> {
    let bad = |x: &f64| !(x.is_finite() && x.abs() <= f32::MAX as f64);
    match values.iter().position(|v| v.iter().any(bad)) {
        None => Ok(()),
        Some(i) => Err(ServiceError::new(
            Code::NonFinite,
            format!(
                "the frame's result is not finite: {what}[{i}] = {:?} overflows f32 (the pose, rest pose or blend-shape weights are too extreme)",
                values[i]
            ),
        )),
    }
}
