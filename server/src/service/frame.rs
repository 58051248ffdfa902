//! The service's frame: a request's frame (JSON `FrameRequest` or binary,
//! binary.rs) in f64 as one [`Frame`], checked against the binding
//! (counts, finiteness, topology, adjustments), solved by
//! `curvenet_core::Deformer::frame` (or, for a group of a batch's frames,
//! `Deformer::frames`: [`solve_group`]), and the answer as [`Solved`].

use std::time::Instant;

use std::collections::BTreeMap;

use curvenet_core::{Adjustment, Rotate};
use curvenet_schema::wire::{AdjustmentSpec, BlendShapeMode, FrameRequest, FrameResponse};

use crate::cache::Entry;
use crate::error::{Code, Phase, ServiceError};
use crate::request::{MAX_COORDINATE, MAX_WEIGHT, check_points};

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
    /// Curvenet Adjustments, in request order (checked by core: knots named).
    pub adjustments: Vec<Adjustment>,
    /// Whether to answer every knot's orientation.
    pub orientations: bool,
    /// The frame's skinning transforms, one per joint of the binding's skin.
    pub joint_transforms: Option<Vec<[f64; 16]>>,
    /// The rest cage this frame, one point per cage vertex of the binding.
    pub rest_cage: Option<Vec<[f64; 3]>>,
    /// Posed-cage edits this frame, one offset per cage vertex of the binding.
    pub posed_cage_offsets: Option<Vec<[f64; 3]>>,
}

impl Frame {
    /// Bytes of its arrays (what a batch holds of it, `--max-batch-memory`).
    pub fn heap_bytes(&self) -> usize {
        let points = |p: &Option<Vec<[f64; 3]>>| p.as_ref().map_or(0, |p| p.len() * 24);
        self.posed.iter().map(points).sum::<usize>()
            + points(&self.rest)
            + points(&self.rest_cage)
            + points(&self.posed_cage_offsets)
            + self.weights.as_ref().map_or(0, |w| w.len() * 8)
            + self.joint_transforms.as_ref().map_or(0, |j| j.len() * 128)
            + self.adjustments.len() * std::mem::size_of::<Adjustment>()
            + self.topology_hash.as_ref().map_or(0, String::len)
    }
}

/// A wire adjustment as core's: absent fields are no change.
pub fn adjustment(a: &AdjustmentSpec) -> Adjustment {
    let mut out = Adjustment::new(a.curvenet as usize, a.knot)
        .with_translate(a.translate.unwrap_or([0.0; 3]))
        .with_rotate(Rotate::EulerXyz(a.rotate.unwrap_or([0.0; 3])))
        .with_scale(a.scale.unwrap_or([1.0; 3]))
        .with_tangent_translates(a.tangent_translates.clone());
    if let Some(attach) = a.attach_tangents {
        out = out.with_attach_tangents(attach);
    }
    out
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
            adjustments: r.adjustments.iter().map(adjustment).collect(),
            orientations: r.orientations,
            joint_transforms: r.joint_transforms,
            rest_cage: r.rest_cage,
            posed_cage_offsets: r.posed_cage_offsets,
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
    let b = entry.binding();
    let count = |what: &str, expected: usize, got: usize| {
        let what = what.to_string();
        move |d: &mut curvenet_schema::wire::ErrorDetails| {
            d.what = Some(what);
            d.expected = Some(expected);
            d.got = Some(got);
        }
    };
    if !frame.posed.is_empty() {
        if frame.posed.len() != b.n_curvenets() {
            return Err(ServiceError::new(
                Code::CountMismatch,
                format!(
                    "posed has {} entries, but the binding has {} curvenets (one pool or null each)",
                    frame.posed.len(),
                    b.n_curvenets()
                ),
            )
            .detail(count("posed", b.n_curvenets(), frame.posed.len())));
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
    if let Some(w) = &frame.weights {
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

impl Frame {
    /// The core's frame input over this frame's arrays (`posed`: its posed
    /// pools as slices), as [`solve`] and [`solve_group`] pass it.
    pub(crate) fn core<'a>(&'a self, posed: &'a [Option<&'a [[f64; 3]]>]) -> curvenet_core::Frame<'a> {
        curvenet_core::Frame {
            posed,
            rest: self.rest.as_deref(),
            blend_shape_weights: self.weights.as_deref(),
            blend_shape_mode: match self.mode {
                BlendShapeMode::After => curvenet_core::BlendShapeMode::After,
                BlendShapeMode::Before => curvenet_core::BlendShapeMode::Before,
            },
            adjustments: &self.adjustments,
            joint_transforms: self.joint_transforms.as_deref(),
            rest_cage: self.rest_cage.as_deref(),
            posed_cage_offsets: self.posed_cage_offsets.as_deref(),
        }
    }
}

/// Solves a validated frame through `curvenet_core::Deformer::frame`.
/// CPU-heavy: run it on the solve pool (see pool.rs).
pub fn solve(entry: &Entry, frame: &Frame) -> Result<Solved, ServiceError> {
    let t0 = Instant::now();
    let n = entry.binding().n_vertices();
    let posed: Vec<Option<&[[f64; 3]]>> = frame.posed.iter().map(|p| p.as_deref()).collect();
    let input = frame.core(&posed);
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
pub fn solve_group(entry: &Entry, frames: &[Frame]) -> Result<Vec<Solved>, (usize, ServiceError)> {
    let t0 = Instant::now();
    let n = entry.binding().n_vertices();
    let posed: Vec<Vec<Option<&[[f64; 3]]>>> =
        frames.iter().map(|f| f.posed.iter().map(|p| p.as_deref()).collect()).collect();
    let inputs: Vec<curvenet_core::Frame<'_>> =
        frames.iter().zip(&posed).map(|(frame, posed)| frame.core(posed)).collect();
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

/// Refuses an adjustment value beyond the service's coordinate bound (core
/// refuses only non-finite ones): translates, scales, rotate angles and
/// tangent translates past 1e15 are `invalid_parameter`, naming
/// `adjustments[i].field` and the adjustment, curvenet and knot in details.
fn check_adjustment_values(adjustments: &[Adjustment]) -> Result<(), ServiceError> {
    for (i, a) in adjustments.iter().enumerate() {
        let rotate: &[f64] = match &a.rotate {
            Rotate::EulerXyz(e) => e,
            Rotate::Quaternion(q) => q,
        };
        let fields: [(&str, &[f64]); 4] = [
            ("translate", &a.translate),
            ("rotate", rotate),
            ("scale", &a.scale),
            ("tangent_translates", a.tangent_translates.as_flattened()),
        ];
        for (field, values) in fields {
            // A non-finite value is core's to refuse (InvalidAdjustment).
            if let Some(x) = values.iter().find(|x| x.is_finite() && x.abs() > MAX_COORDINATE) {
                return Err(ServiceError::new(
                    Code::InvalidParameter,
                    format!(
                        "adjustments[{i}] (curvenet {}, knot {}): its {field} has {x:e}, beyond {MAX_COORDINATE:e}",
                        a.curvenet, a.knot
                    ),
                )
                .detail(|d| {
                    d.adjustment = Some(i);
                    d.curvenet = Some(a.curvenet as u32);
                    d.control_point = Some(a.knot);
                    d.what = Some(format!("adjustments[{i}].{field}"));
                }));
            }
        }
    }
    Ok(())
}

/// An error about adjustment `i` also names its curvenet (core's
/// out-of-range knot names only the adjustment and the control point) and,
/// when core's message does not, the adjustment's place in the request.
pub(crate) fn name_adjustment(e: ServiceError, adjustments: &[Adjustment]) -> ServiceError {
    let Some(i) = e.details.as_ref().and_then(|d| d.adjustment) else { return e };
    let Some(a) = adjustments.get(i) else { return e };
    let curvenet = a.curvenet as u32;
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
fn orientations(entry: &Entry, frame: &Frame) -> Result<Vec<BTreeMap<String, [f64; 9]>>, ServiceError> {
    let deformer = &entry.deformer;
    let sculpted = match (&frame.weights, frame.mode) {
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
            let posed = frame.posed.get(k).and_then(|p| p.as_deref());
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
