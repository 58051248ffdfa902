//! The service's frame: every frame a request carries (a JSON frame or a
//! batch's, a binary frame read by binary.rs, a viewer frame) is the one
//! wire type `FrameRequest`, checked here against the binding (counts,
//! finiteness, topology, adjustments: [`validate`]), made core's frame by
//! [`CoreFrame`] (the one conversion) and solved by
//! `curvenet_core::Deformer::frame` (or, for a group of a batch's frames,
//! `Deformer::frames`: [`solve_group`]); the answer is [`Solved`].

use std::time::Instant;

use std::collections::BTreeMap;

use curvenet_core::Adjustment;
use curvenet_schema::wire::{AdjustmentSpec, BlendShapeMode, FrameRequest, FrameResponse};

use crate::entry::Entry;
use crate::error::{Code, Phase, ServiceError};
use crate::request::{MAX_COORDINATE, MAX_WEIGHT, check_points};

/// Bytes of a frame's arrays (what a batch holds of it,
/// `--max-batch-memory`); its adjustments counted as the core
/// `Adjustment`s they become at the solve.
pub fn held_bytes(frame: &FrameRequest) -> usize {
    let points = |p: &Option<Vec<[f64; 3]>>| p.as_ref().map_or(0, |p| p.len() * 24);
    frame.posed.iter().flatten().map(points).sum::<usize>()
        + points(&frame.rest)
        + points(&frame.rest_cage)
        + points(&frame.posed_cage_offsets)
        + frame.blend_shape_weights.as_ref().map_or(0, |w| w.len() * 8)
        + frame.joint_transforms.as_ref().map_or(0, |j| j.len() * 128)
        + frame.adjustments.len() * std::mem::size_of::<Adjustment>()
        + frame.topology_hash.as_ref().map_or(0, String::len)
}

/// The one place a frame becomes core's: what `curvenet_core::Frame`
/// borrows from a [`FrameRequest`] besides its arrays (the posed pools as
/// slices, the adjustments as core's, `Adjustment::from` in
/// `curvenet_schema::frame`).
#[derive(Debug, Clone, Default)]
pub(crate) struct CoreFrame<'a> {
    posed: Vec<Option<&'a [[f64; 3]]>>,
    adjustments: Vec<Adjustment>,
}

impl<'a> CoreFrame<'a> {
    pub(crate) fn new(request: &'a FrameRequest) -> Self {
        Self {
            posed: request.posed.iter().flatten().map(|p| p.as_deref()).collect(),
            adjustments: request.adjustments.iter().map(Adjustment::from).collect(),
        }
    }

    /// The request's adjustments, as core's.
    pub(crate) fn adjustments(&self) -> &[Adjustment] {
        &self.adjustments
    }

    /// Core's frame of `request` (the request these parts were made of).
    pub(crate) fn frame<'b>(&'b self, request: &'b FrameRequest) -> curvenet_core::Frame<'b> {
        curvenet_core::Frame {
            posed: &self.posed,
            rest: request.rest.as_deref(),
            blend_shape_weights: request.blend_shape_weights.as_deref(),
            blend_shape_mode: request.blend_shape_mode.into(),
            adjustments: &self.adjustments,
            joint_transforms: request.joint_transforms.as_deref(),
            rest_cage: request.rest_cage.as_deref(),
            posed_cage_offsets: request.posed_cage_offsets.as_deref(),
        }
    }
}

/// A solved frame, in the wire's f32 (converted as soon as a frame is
/// solved, so a batch holds its frames at the answer's size, not twice it).
pub struct Solved {
    pub points: Vec<[f32; 3]>,
    pub gradients: Option<Vec<[f32; 9]>>,
    pub solve_ms: f64,
    /// Per curvenet, knot pool index → row-major orientation (when asked).
    pub knot_orientations: Option<Vec<BTreeMap<String, [f64; 9]>>>,
}

impl Solved {
    pub fn into_response(self) -> FrameResponse {
        FrameResponse {
            points: self.points,
            gradients: self.gradients,
            solve_ms: self.solve_ms,
            knot_orientations: self.knot_orientations,
        }
    }
}

/// Checks `frame` against the binding: topology hash, counts, finiteness.
/// Messages name the array and index (`posed[1][17]`), details the same.
pub fn validate(entry: &Entry, frame: &FrameRequest) -> Result<(), ServiceError> {
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
    let b = entry.binding();
    let count = |what: &str, expected: usize, got: usize| {
        let what = what.to_string();
        move |d: &mut curvenet_schema::wire::ErrorDetails| {
            d.what = Some(what);
            d.expected = Some(expected);
            d.got = Some(got);
        }
    };
    if let Some(posed) = frame.posed.as_ref().filter(|p| !p.is_empty()) {
        if posed.len() != b.n_curvenets() {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!(
                    "posed has {} entries, but the binding has {} curvenets (one pool or null each)",
                    posed.len(),
                    b.n_curvenets()
                ),
            )
            .detail(count("posed", b.n_curvenets(), posed.len())));
        }
        for (k, pool) in posed.iter().enumerate() {
            if let Some(pool) = pool {
                if pool.len() != b.n_control_points(k) {
                    return Err(ServiceError::new(
                        Code::CountMismatch,
                        format!(
                            "posed[{k}] has {} control points, but curvenet {k}'s pool has {}",
                            pool.len(),
                            b.n_control_points(k)
                        ),
                    )
                    .detail(count("posed", b.n_control_points(k), pool.len()))
                    .detail(|d| d.curvenet = Some(k as u32)));
                }
                check_points(pool, &format!("posed[{k}]")).map_err(|e| e.detail(|d| d.curvenet = Some(k as u32)))?;
            }
        }
    }
    if let Some(rest) = &frame.rest {
        if rest.len() != b.n_vertices() {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("rest has {} points, but the mesh has {} vertices", rest.len(), b.n_vertices()),
            )
            .detail(count("rest", b.n_vertices(), rest.len())));
        }
        check_points(rest, "rest")?;
    }
    if let Some(t) = &frame.joint_transforms {
        let joints = entry.deformer.rig().map(|r| r.skin.influences().n_joints());
        let Some(joints) = joints else {
            return Err(ServiceError::new(
                Code::Unsupported,
                "joint_transforms: the binding has no skin (post the binding with `skin` to skin frames)",
            )
            .detail(|d| d.what = Some("joint_transforms".into())));
        };
        if t.len() != joints {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("joint_transforms has {} transforms, but the binding's skin has {joints} joints", t.len()),
            )
            .detail(count("joint_transforms", joints, t.len())));
        }
        if let Some(i) = t.iter().position(|m| !m.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORDINATE)) {
            return Err(ServiceError::new(
                Code::NonFinite,
                format!("joint_transforms[{i}] has a value that is not finite or beyond {MAX_COORDINATE:e}"),
            )
            .detail(|d| {
                d.what = Some("joint_transforms".into());
                d.index = Some(i);
            }));
        }
        if frame.orientations {
            return Err(ServiceError::new(
                Code::Unsupported,
                "orientations with joint_transforms: knot orientations of a skinned frame are not answered yet",
            )
            .detail(|d| d.what = Some("orientations".into())));
        }
    }
    if frame.orientations && entry.deformer.cage().is_some() {
        return Err(ServiceError::new(
            Code::Unsupported,
            "orientations with a cage: knot orientations of a caged binding's frames are not answered yet",
        )
        .detail(|d| d.what = Some("orientations".into())));
    }
    for (what, cage) in [("rest_cage", &frame.rest_cage), ("posed_cage_offsets", &frame.posed_cage_offsets)] {
        let Some(cage) = cage else { continue };
        let Some(vertices) = entry.deformer.cage().map(|c| c.n_cage_vertices()) else {
            return Err(ServiceError::new(
                Code::Unsupported,
                format!("{what}: the binding has no cage (post the binding with `cage` to edit it per frame)"),
            )
            .detail(|d| d.what = Some(what.into())));
        };
        if cage.len() != vertices {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("{what} has {} points, but the binding's cage has {vertices} vertices", cage.len()),
            )
            .detail(count(what, vertices, cage.len())));
        }
        check_points(cage, what)?;
    }
    check_adjustment_values(&frame.adjustments)?;
    if let Some(w) = &frame.blend_shape_weights {
        let n_shapes = entry.n_shapes();
        if w.len() != n_shapes {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!("blend_shape_weights has {} weights, but the binding has {} blend shapes", w.len(), n_shapes),
            )
            .detail(count("blend_shape_weights", n_shapes, w.len())));
        }
        let at = |i: usize| {
            move |d: &mut curvenet_schema::wire::ErrorDetails| {
                d.what = Some("blend_shape_weights".into());
                d.index = Some(i);
            }
        };
        if let Some(i) = w.iter().position(|x| !x.is_finite()) {
            return Err(
                ServiceError::new(Code::NonFinite, format!("blend_shape_weights[{i}] is {}", w[i])).detail(at(i))
            );
        }
        if let Some(i) = w.iter().position(|x| x.abs() > MAX_WEIGHT) {
            return Err(ServiceError::new(
                Code::InvalidParameter,
                format!("blend_shape_weights[{i}] is {}, larger than {MAX_WEIGHT:e} in magnitude", w[i]),
            )
            .detail(at(i)));
        }
    }
    Ok(())
}

/// Solves a validated frame through `curvenet_core::Deformer::frame`.
/// CPU-heavy: run it on the solve pool (see pool.rs).
pub fn solve(entry: &Entry, frame: &FrameRequest) -> Result<Solved, ServiceError> {
    let t0 = Instant::now();
    let n = entry.binding().n_vertices();
    let parts = CoreFrame::new(frame);
    let input = parts.frame(frame);
    let mut points = vec![[0.0; 3]; n];
    let mut gradients = frame.gradients.then(|| vec![[0.0; 9]; n]);
    entry
        .deformer
        .frame(&input, &mut points, gradients.as_deref_mut())
        .map_err(|e| name_adjustment(ServiceError::core(e, Phase::Frame), &frame.adjustments))?;
    let points = in_f32(&points, "points")?;
    let gradients = gradients.map(|g| in_f32(&g, "gradients")).transpose()?;
    let knot_orientations = if frame.orientations { Some(orientations(entry, frame)?) } else { None };
    Ok(Solved { points, gradients, solve_ms: t0.elapsed().as_secs_f64() * 1e3, knot_orientations })
}

/// Solves validated frames together through
/// `curvenet_core::Deformer::frames` (one sweep of each triangular solve
/// for the group; the same results as [`solve`] frame by frame). Each
/// frame's `solve_ms` is the group's time over its frames. An error names
/// the frame by its index in `frames`. CPU-heavy: run it on the solve pool.
pub fn solve_group(entry: &Entry, frames: &[FrameRequest]) -> Result<Vec<Solved>, (usize, ServiceError)> {
    let t0 = Instant::now();
    let n = entry.binding().n_vertices();
    let parts: Vec<CoreFrame<'_>> = frames.iter().map(CoreFrame::new).collect();
    let inputs: Vec<curvenet_core::Frame<'_>> =
        frames.iter().zip(&parts).map(|(frame, parts)| parts.frame(frame)).collect();
    let mut points = vec![vec![[0.0; 3]; n]; frames.len()];
    let mut gradients: Vec<Option<Vec<[f64; 9]>>> =
        frames.iter().map(|f| f.gradients.then(|| vec![[0.0; 9]; n])).collect();
    let mut outs: Vec<curvenet_core::FrameOut<'_>> = points
        .iter_mut()
        .zip(gradients.iter_mut())
        .map(|(p, g)| curvenet_core::FrameOut { points: p, gradients: g.as_deref_mut() })
        .collect();
    entry.deformer.frames(&inputs, &mut outs).map_err(|e| {
        (e.frame, name_adjustment(ServiceError::core(e.error, Phase::Frame), &frames[e.frame].adjustments))
    })?;
    let solve_ms = t0.elapsed().as_secs_f64() * 1e3 / frames.len().max(1) as f64;
    frames
        .iter()
        .zip(points.into_iter().zip(gradients))
        .enumerate()
        .map(|(i, (frame, (points, gradients)))| {
            let checked = (|| {
                let points = in_f32(&points, "points")?;
                let gradients = gradients.map(|g| in_f32(&g, "gradients")).transpose()?;
                let knot_orientations = if frame.orientations { Some(orientations(entry, frame)?) } else { None };
                Ok(Solved { points, gradients, solve_ms, knot_orientations })
            })();
            checked.map_err(|e| (i, e))
        })
        .collect()
}

/// Refuses an adjustment the wire allows but the service does not: both
/// `rotate` and `orient` given, or a value beyond the service's coordinate
/// bound (core refuses only non-finite ones: translates, scales, rotate
/// angles, quaternions and tangent translates past 1e15). Both are
/// `invalid_parameter`, naming `adjustments[i].field` and the adjustment,
/// curvenet and knot in details.
pub(crate) fn check_adjustment_values(adjustments: &[AdjustmentSpec]) -> Result<(), ServiceError> {
    for (i, a) in adjustments.iter().enumerate() {
        let refuse = |field: &str, message: String| {
            ServiceError::new(
                Code::InvalidParameter,
                format!("adjustments[{i}] (curvenet {}, knot {}): {message}", a.curvenet, a.knot),
            )
            .detail(|d| {
                d.adjustment = Some(i);
                d.curvenet = Some(a.curvenet);
                d.control_point = Some(a.knot);
                d.what = Some(format!("adjustments[{i}].{field}"));
            })
        };
        if a.rotate.is_some() && a.orient.is_some() {
            return Err(refuse(
                "orient",
                "both rotate (Euler angles) and orient (a quaternion) are given; give one".into(),
            ));
        }
        let fields: [(&str, &[f64]); 5] = [
            ("translate", a.translate.as_ref().map_or(&[], |v| v)),
            ("rotate", a.rotate.as_ref().map_or(&[], |v| v)),
            ("orient", a.orient.as_ref().map_or(&[], |v| v)),
            ("scale", a.scale.as_ref().map_or(&[], |v| v)),
            ("tangent_translates", a.tangent_translates.as_flattened()),
        ];
        for (field, values) in fields {
            // A non-finite value is core's to refuse (InvalidAdjustment).
            if let Some(x) = values.iter().find(|x| x.is_finite() && x.abs() > MAX_COORDINATE) {
                return Err(refuse(field, format!("its {field} has {x:e}, beyond {MAX_COORDINATE:e}")));
            }
        }
    }
    Ok(())
}

/// An error about adjustment `i` also names its curvenet (core's
/// out-of-range knot names only the adjustment and the control point) and,
/// when core's message does not, the adjustment's place in the request.
pub(crate) fn name_adjustment(e: ServiceError, adjustments: &[AdjustmentSpec]) -> ServiceError {
    let Some(i) = e.details.as_ref().and_then(|d| d.adjustment) else { return e };
    let Some(a) = adjustments.get(i) else { return e };
    let curvenet = a.curvenet;
    let e = e.detail(|d| {
        d.curvenet.get_or_insert(curvenet);
    });
    if e.code == Code::IndexOutOfRange && e.message.starts_with("adjustment ") {
        let message = format!("adjustments[{i}] (curvenet {curvenet}, knot {}): {}", a.knot, e.message);
        ServiceError { message, ..e }
    } else {
        e
    }
}

/// Every knot's orientation of every curvenet in `frame` (core's
/// `Binding::knot_orientations`), in the pose the frame's adjustments act
/// on: the posed pool, else the pool tracked to the frame's rest pose (with
/// `before`-mode blend shapes added to it, as `Deformer::frame` does).
fn orientations(entry: &Entry, frame: &FrameRequest) -> Result<Vec<BTreeMap<String, [f64; 9]>>, ServiceError> {
    let deformer = &entry.deformer;
    let sculpted = match (&frame.blend_shape_weights, frame.blend_shape_mode) {
        (Some(w), BlendShapeMode::Before) if entry.n_shapes() > 0 && w.iter().any(|&x| x != 0.0) => {
            let mut rest = frame.rest.clone().unwrap_or_else(|| deformer.projection_points().to_vec());
            deformer.blend_shapes().add_to(w, &mut rest).map_err(|e| ServiceError::core(e, Phase::Frame))?;
            Some(rest)
        }
        _ => None,
    };
    let rest = sculpted.as_deref().or(frame.rest.as_deref());
    let b = deformer.binding();
    (0..b.n_curvenets())
        .map(|k| {
            let posed = frame.posed.as_ref().and_then(|p| p.get(k)).and_then(|p| p.as_deref());
            let knots = b.knot_orientations(k, posed, rest).map_err(|e| ServiceError::core(e, Phase::Frame))?;
            Ok(knots
                .into_iter()
                .map(|(point, m)| {
                    (
                        point.to_string(),
                        [m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2]],
                    )
                })
                .collect())
        })
        .collect()
}

/// A result in the wire's f32; refuses one that is not finite once sent
/// as f32 (a pose or weights extreme enough to overflow): `non_finite`,
/// naming the first bad vertex.
fn in_f32<const N: usize>(values: &[[f64; N]], what: &str) -> Result<Vec<[f32; N]>, ServiceError> {
    let bad = |x: &f64| !(x.is_finite() && x.abs() <= f32::MAX as f64);
    match values.iter().position(|v| v.iter().any(bad)) {
        None => Ok(values.iter().map(|v| v.map(|x| x as f32)).collect()),
        Some(i) => Err(ServiceError::new(
            Code::NonFinite,
            format!(
                "the frame's result is not finite: {what}[{i}] = {:?} overflows f32 (the pose, rest pose or blend-shape weights are too extreme)",
                values[i]
            ),
        )
        .detail(|d| {
            d.what = Some(what.to_string());
            d.vertex = Some(i as u32);
        })),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A request's arrays reach core's frame as the same slices.
    #[test]
    fn the_core_frame_borrows_the_requests_arrays() {
        let request = FrameRequest {
            posed: Some(vec![None, Some(vec![[1.0, 2.0, 3.0]])]),
            rest: Some(vec![[0.0; 3]; 4]),
            blend_shape_weights: Some(vec![0.5]),
            blend_shape_mode: BlendShapeMode::Before,
            joint_transforms: Some(vec![curvenet_core::MAT4_IDENTITY]),
            ..FrameRequest::default()
        };
        let parts = CoreFrame::new(&request);
        let frame = parts.frame(&request);
        assert_eq!(frame.posed.len(), 2);
        assert!(frame.posed[0].is_none());
        assert_eq!(frame.posed[1], Some(&[[1.0, 2.0, 3.0]][..]));
        assert_eq!(frame.rest.map(<[_]>::len), Some(4));
        assert_eq!(frame.blend_shape_weights, Some(&[0.5][..]));
        assert!(matches!(frame.blend_shape_mode, curvenet_core::BlendShapeMode::Before));
        assert_eq!(frame.joint_transforms.map(<[_]>::len), Some(1));
        assert!(frame.rest_cage.is_none() && frame.posed_cage_offsets.is_none() && frame.adjustments.is_empty());
        let unposed = FrameRequest::default();
        assert!(CoreFrame::new(&unposed).frame(&unposed).posed.is_empty());
    }
}
