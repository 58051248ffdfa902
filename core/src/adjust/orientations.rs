//! Knot orientations: one rotation per knot (spline endpoint) that maps the
//! neutral curvenet to the curvenet as posed so far (see the module docs of
//! [`crate::adjust`] for the definitions and the decisions behind them).
//!
//! [`OrientationPlan`] holds what depends only on the neutral pose (built
//! once per bound curvenet); [`OrientationPlan::orientations_into`]
//! evaluates a pose without allocating.

use std::ops::Range;

use glam::{DMat3, DQuat, DVec3};

use super::fit::{fit_quat, to_mat3};
use crate::curvenet::{CurveEnd, CurvenetLayout, Mat3, Sampling, ZERO_LENGTH_TOLERANCE};
use crate::error::{Error, Result};

/// A surface normal whose part orthogonal to a knot's tangent is shorter
/// than this fraction of it does not fix the knot's frame (the curve leaves
/// the surface along its normal); such a knot falls back to the smallest
/// rotation of its tangent.
pub const NORMAL_ALONG_TANGENT: f64 = 1e-6;

/// The neutral-pose part of the knot orientations of one curvenet.
/// Immutable and `Send + Sync`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct OrientationPlan {
    n_knots: usize,
    n_points: usize,
    fans: Vec<FanPlan>,
    fan_tangents: Vec<FanTangent>,
    curves: Vec<CurvePlan>,
    curve_knots: Vec<CurveKnot>,
    /// The tangent control points of every knot (CSR by knot), increasing.
    #[serde(with = "crate::persist::pod")]
    knot_tangent_start: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    knot_tangents: Vec<u32>,
}

/// An intersection: its knot and the range of its tangents in `fan_tangents`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct FanPlan {
    knot: u32,
    point: u32,
    tangents: Range<usize>,
}

/// One curve end at an intersection: the control point giving its Bézier
/// end tangent, the neutral unit direction and the fit weight (the neutral
/// tangent's length).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct FanTangent {
    point: u32,
    direction: DVec3,
    weight: f64,
}

/// A curve and the knots on it that are not intersections.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct CurvePlan {
    curve: u32,
    /// Fan indices of the intersections at the curve's start and end.
    start: Option<u32>,
    end: Option<u32>,
    knots: Range<usize>,
    /// Neutral unit tangents of the first and last segments.
    neutral_first: DVec3,
    neutral_last: DVec3,
}

impl CurvePlan {
    /// A curve that reaches no intersection (both ends anchors, or closed).
    fn floating(&self) -> bool {
        self.start.is_none() && self.end.is_none()
    }
}

#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct CurveKnot {
    knot: u32,
    point: u32,
    /// Position in the curve's samples (`Sampling::curve_samples`).
    position: u32,
    /// Neutral arc length from the start over the curve's length: the
    /// weight of the end's orientation in the blend.
    toward_end: f64,
    /// Inverse neutral transports from the start and from the end.
    from_start: DQuat,
    from_end: DQuat,
    /// Floating curves: the transposed neutral knot frame (`None`: the
    /// normal does not fix it) and the neutral knot tangent.
    neutral_frame: Option<DMat3>,
    neutral_tangent: DVec3,
}

impl OrientationPlan {
    /// Prepares the orientations of the knots of `layout`. `neutral_normal`
    /// gives the surface normal at control point `p`'s closest point in the
    /// pose the curvenet was drawn over (used for knots on curves that reach
    /// no intersection; the same rule must give the posed normals).
    pub fn new(layout: &CurvenetLayout, neutral_normal: impl Fn(u32) -> [f64; 3]) -> Result<Self> {
        let sampling = layout.sampling();
        let topology = layout.topology();
        let pool = layout.neutral_pool();
        let samples = layout.neutral_samples();
        let splines = sampling.splines();
        let n_knots = sampling.n_knots();
        let knot_of = |p: u32| {
            sampling.knot_sample(p as usize).ok_or_else(|| Error::Internal {
                what: format!("control point {p} is a curve end but has no knot sample"),
            })
        };
        let v = |p: u32| DVec3::from_array(pool[p as usize]);
        let tolerance = ZERO_LENGTH_TOLERANCE * crate::mesh::bounding_box_diagonal(pool);

        let mut fans = Vec::with_capacity(layout.intersections().len());
        let mut fan_tangents = Vec::new();
        for fan in layout.intersections() {
            let point = fan.point();
            let first = fan_tangents.len();
            for e in fan.emanations() {
                let curve = &topology.curves()[e.curve as usize];
                let cs = if e.at_start { curve.splines[0] } else { curve.splines[curve.splines.len() - 1] };
                let s = splines[cs.spline as usize];
                // Control points walked outwards from the intersection.
                let outward = if e.at_start != cs.reversed { s } else { [s[3], s[2], s[1], s[0]] };
                let knot = v(outward[0]);
                let Some(&p) = outward[1..].iter().find(|&&p| (v(p) - knot).length() > tolerance) else {
                    return Err(Error::ZeroLengthSpline { spline: cs.spline as usize });
                };
                let d = v(p) - knot;
                fan_tangents.push(FanTangent { point: p, direction: d / d.length(), weight: d.length() });
            }
            fans.push(FanPlan { knot: knot_of(point)?, point, tangents: first..fan_tangents.len() });
        }

        let mut curves = Vec::with_capacity(sampling.n_curves());
        let mut curve_knots = Vec::new();
        for (c, curve) in topology.curves().iter().enumerate() {
            let [start, end] = layout.curve_end_slots(c).map(|slot| slot.map(|(f, _)| f));
            let segs = sampling.curve_segments(c);
            let cs = sampling.curve_samples(c);
            let n = segs.len();
            let first = curve_knots.len();
            let mut arc = 0.0;
            let lengths: f64 = segs.clone().map(|s| segment_vector(sampling, samples, s).length()).sum();
            for (i, &q) in cs.iter().enumerate() {
                let at_intersection = (i == 0 && start.is_some()) || (i == n && end.is_some());
                if (q as usize) < n_knots && !at_intersection {
                    curve_knots.push(CurveKnot {
                        knot: q,
                        point: sampling.knot_point(q as usize),
                        position: i as u32,
                        toward_end: if lengths > 0.0 { arc / lengths } else { 0.0 },
                        from_start: DQuat::IDENTITY,
                        from_end: DQuat::IDENTITY,
                        neutral_frame: None,
                        neutral_tangent: knot_tangent(sampling, samples, c, i),
                    });
                }
                if i < n {
                    arc += segment_vector(sampling, samples, segs.start + i).length();
                }
            }
            let knots = first..curve_knots.len();
            let plan = CurvePlan {
                curve: c as u32,
                start,
                end,
                knots: knots.clone(),
                neutral_first: direction(sampling, samples, segs.start),
                neutral_last: direction(sampling, samples, segs.end - 1),
            };
            let here = &mut curve_knots[knots];
            if start.is_some() {
                walk_forward(sampling, samples, c, |i, omega| {
                    if let Some(k) = find(here, i) {
                        k.from_start = omega.inverse();
                    }
                });
            }
            if end.is_some() {
                walk_backward(sampling, samples, c, |i, omega| {
                    if let Some(k) = find(here, i) {
                        k.from_end = omega.inverse();
                    }
                });
            }
            if plan.floating() {
                for k in here.iter_mut() {
                    let normal = DVec3::from_array(neutral_normal(k.point));
                    k.neutral_frame = knot_frame(k.neutral_tangent, normal).map(|f| f.transpose());
                }
            }
            debug_assert!(matches!(curve.start, CurveEnd::Closed(_)) == (cs.len() == n));
            curves.push(plan);
        }

        // Tangents of every knot for adjustments: the handles next to it.
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(2 * splines.len());
        for s in splines {
            for (end, handle) in [(s[0], s[1]), (s[3], s[2])] {
                if handle != end && sampling.knot_sample(handle as usize).is_none() {
                    pairs.push((knot_of(end)?, handle));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut knot_tangent_start = vec![0u32; n_knots + 1];
        for &(k, _) in &pairs {
            knot_tangent_start[k as usize + 1] += 1;
        }
        for k in 0..n_knots {
            knot_tangent_start[k + 1] += knot_tangent_start[k];
        }
        let knot_tangents = pairs.iter().map(|&(_, h)| h).collect();

        let plan = Self {
            n_knots,
            n_points: pool.len(),
            fans,
            fan_tangents,
            curves,
            curve_knots,
            knot_tangent_start,
            knot_tangents,
        };
        let covered = plan.fans.len() + plan.curve_knots.len();
        if covered != n_knots {
            return Err(Error::Internal {
                what: format!("knot orientations cover {covered} of the curvenet's {n_knots} knots"),
            });
        }
        Ok(plan)
    }

    /// Number of knots (the length of an orientation buffer); knot `k` is
    /// control point `layout.sampling().knot_point(k)`.
    pub fn n_knots(&self) -> usize {
        self.n_knots
    }

    /// The tangent control points of knot `k`: the handles next to it (of
    /// every spline ending there) that are not themselves knots, in
    /// increasing pool order. An adjustment's tangent translates follow
    /// this order.
    pub fn knot_tangents(&self, k: usize) -> &[u32] {
        &self.knot_tangents[self.knot_tangent_start[k] as usize..self.knot_tangent_start[k + 1] as usize]
    }

    /// The orientation of every knot (`#knots` row-major rotations into
    /// `out`) of the curvenet of `layout` posed at `pool` (`#P` points) with
    /// samples `samples` (from `layout.sampling().samples_into(pool, ..)`).
    /// `normal` gives the surface normal at control point `p`'s closest
    /// point in this pose, by the same rule as the plan's neutral normals.
    /// Allocation-free.
    ///
    /// Fails with [`Error::CountMismatch`] for wrong lengths and
    /// [`Error::UndeterminedKnotOrientation`] naming an intersection whose
    /// tangents are all parallel in this pose.
    pub fn orientations_into(
        &self,
        layout: &CurvenetLayout,
        pool: &[[f64; 3]],
        samples: &[[f64; 3]],
        normal: impl Fn(u32) -> [f64; 3],
        out: &mut [Mat3],
    ) -> Result<()> {
        self.some_orientations_into(layout, pool, samples, normal, |_| true, out)
    }

    /// Like [`Self::orientations_into`], computing only the orientations of
    /// the intersections and of the knots `wanted(k)` asks for (the other
    /// entries of `out` are left as they were). A frame's adjuster asks for
    /// its adjusted knots only.
    pub fn some_orientations_into(
        &self,
        layout: &CurvenetLayout,
        pool: &[[f64; 3]],
        samples: &[[f64; 3]],
        normal: impl Fn(u32) -> [f64; 3],
        wanted: impl Fn(usize) -> bool,
        out: &mut [Mat3],
    ) -> Result<()> {
        let sampling = layout.sampling();
        for (what, expected, got) in [
            ("posed curvenet control points", self.n_points, pool.len()),
            ("curvenet samples", sampling.n_samples(), samples.len()),
            ("knot orientation buffer", self.n_knots, out.len()),
        ] {
            if expected != got {
                return Err(Error::CountMismatch { what, expected, got });
            }
        }
        let v = |p: u32| DVec3::from_array(pool[p as usize]);
        for fan in &self.fans {
            let knot = v(fan.point);
            let pairs = self.fan_tangents[fan.tangents.clone()].iter().filter_map(|t| {
                let d = v(t.point) - knot;
                let l = d.length();
                (l > 0.0 && l.is_finite()).then(|| (t.direction, d / l, t.weight))
            });
            let q = fit_quat(pairs).ok_or(Error::UndeterminedKnotOrientation { point: fan.point })?;
            out[fan.knot as usize] = to_mat3(DMat3::from_quat(q));
        }
        for plan in &self.curves {
            let knots = &self.curve_knots[plan.knots.clone()];
            if !knots.iter().any(|k| wanted(k.knot as usize)) {
                continue;
            }
            let c = plan.curve as usize;
            let segs = sampling.curve_segments(c);
            if plan.floating() {
                for k in knots {
                    let tangent = knot_tangent(sampling, samples, c, k.position as usize);
                    let n = DVec3::from_array(normal(k.point));
                    let d = match (knot_frame(tangent, n), k.neutral_frame) {
                        (Some(frame), Some(neutral)) => frame * neutral,
                        _ => DMat3::from_quat(arc(k.neutral_tangent, tangent)),
                    };
                    out[k.knot as usize] = to_mat3(d);
                }
                continue;
            }
            // The intersection's orientation, first turned to map the curve's
            // first (last) neutral segment direction exactly onto the posed one.
            let aligned = |d: DQuat, neutral: DVec3, posed: DVec3| (arc(d * neutral, posed) * d).normalize();
            if let Some(f) = plan.start {
                let g = aligned(self.fan_quat(f, out), plan.neutral_first, direction(sampling, samples, segs.start));
                walk_forward(sampling, samples, c, |i, omega| {
                    if let Ok(j) = knots.binary_search_by_key(&(i as u32), |k| k.position) {
                        let q = (omega * g * knots[j].from_start).normalize();
                        out[knots[j].knot as usize] = to_mat3(DMat3::from_quat(q));
                    }
                });
            }
            if let Some(f) = plan.end {
                let g = aligned(self.fan_quat(f, out), plan.neutral_last, direction(sampling, samples, segs.end - 1));
                let blended = plan.start.is_some();
                walk_backward(sampling, samples, c, |i, omega| {
                    if let Ok(j) = knots.binary_search_by_key(&(i as u32), |k| k.position) {
                        let k = &knots[j];
                        let from_end = (omega * g * k.from_end).normalize();
                        let q = match blended {
                            true => {
                                let from_start = DQuat::from_mat3(&super::fit::from_mat3(&out[k.knot as usize]));
                                from_start.normalize().slerp(from_end, k.toward_end).normalize()
                            }
                            false => from_end,
                        };
                        out[k.knot as usize] = to_mat3(DMat3::from_quat(q));
                    }
                });
            }
        }
        Ok(())
    }

    /// The fitted orientation of fan `f` (already in `out`), as a quaternion.
    fn fan_quat(&self, f: u32, out: &[Mat3]) -> DQuat {
        DQuat::from_mat3(&super::fit::from_mat3(&out[self.fans[f as usize].knot as usize])).normalize()
    }
}

fn find(knots: &mut [CurveKnot], position: usize) -> Option<&mut CurveKnot> {
    let j = knots.binary_search_by_key(&(position as u32), |k| k.position).ok()?;
    Some(&mut knots[j])
}

fn segment_vector(sampling: &Sampling, samples: &[[f64; 3]], s: usize) -> DVec3 {
    let [a, b] = sampling.segments()[s].samples;
    DVec3::from_array(samples[b as usize]) - DVec3::from_array(samples[a as usize])
}

/// Unit direction of segment `s` (zero for a collapsed segment, which the
/// scaled frames refuse later).
fn direction(sampling: &Sampling, samples: &[[f64; 3]], s: usize) -> DVec3 {
    segment_vector(sampling, samples, s).normalize_or_zero()
}

/// The unit tangent of curve `c` at its sample position `i`, in curve
/// direction: the normalised sum of the two segment directions meeting
/// there (the outgoing one when they are opposite), or the one segment's at
/// an open curve's end.
fn knot_tangent(sampling: &Sampling, samples: &[[f64; 3]], c: usize, i: usize) -> DVec3 {
    let segs = sampling.curve_segments(c);
    let n = segs.len();
    let closed = sampling.curve_samples(c).len() == n;
    let before = match i {
        0 if closed => Some(direction(sampling, samples, segs.end - 1)),
        0 => None,
        _ => Some(direction(sampling, samples, segs.start + i - 1)),
    };
    let after = (i < n).then(|| direction(sampling, samples, segs.start + i));
    match (before, after) {
        (Some(a), Some(b)) => {
            let s = a + b;
            if s.length() > 1e-9 { s.normalize() } else { b }
        }
        (Some(a), None) => a,
        (None, Some(b)) => b,
        (None, None) => DVec3::ZERO,
    }
}

/// Walks curve `c` from its start, calling `visit(i, Ω)` at every sample
/// position `i ≥ 1` holding a knot, with `Ω` the parallel transport (the
/// product of the smallest rotations between consecutive tangents) from the
/// first segment's direction to the knot's tangent. Open curves only.
fn walk_forward(sampling: &Sampling, samples: &[[f64; 3]], c: usize, mut visit: impl FnMut(usize, DQuat)) {
    let segs = sampling.curve_segments(c);
    let cs = sampling.curve_samples(c);
    let n = segs.len();
    let n_knots = sampling.n_knots() as u32;
    let mut omega = DQuat::IDENTITY;
    let mut previous = direction(sampling, samples, segs.start);
    for i in 1..=n {
        if cs[i] < n_knots {
            let tangent = knot_tangent(sampling, samples, c, i);
            visit(i, (arc(previous, tangent) * omega).normalize());
        }
        if i < n {
            let next = direction(sampling, samples, segs.start + i);
            omega = arc(previous, next) * omega;
            previous = next;
        }
    }
}

/// Like [`walk_forward`] from the curve's end towards its start (positions
/// `i ≤ n − 1`). Transport along reversed tangents is the same rotation, so
/// the tangents keep the curve's direction.
fn walk_backward(sampling: &Sampling, samples: &[[f64; 3]], c: usize, mut visit: impl FnMut(usize, DQuat)) {
    let segs = sampling.curve_segments(c);
    let cs = sampling.curve_samples(c);
    let n = segs.len();
    let n_knots = sampling.n_knots() as u32;
    let mut omega = DQuat::IDENTITY;
    let mut previous = direction(sampling, samples, segs.end - 1);
    for i in (0..n).rev() {
        if cs[i] < n_knots {
            let tangent = knot_tangent(sampling, samples, c, i);
            visit(i, (arc(previous, tangent) * omega).normalize());
        }
        if i > 0 {
            let next = direction(sampling, samples, segs.start + i - 1);
            omega = arc(previous, next) * omega;
            previous = next;
        }
    }
}

/// The smallest rotation taking unit `from` to unit `to`: the unit
/// quaternion `(from × to, 1 + from·to)` normalised, with `1 + from·to`
/// taken as `|from + to|²/2` (no cancellation near opposite vectors). No
/// threshold drops small rotations (glam's `from_rotation_arc` returns the
/// identity below about 2e-8 rad, which would break the equivariance of the
/// transport). The identity when either vector is zero; a half turn about a
/// perpendicular axis when they are exactly opposite.
fn arc(from: DVec3, to: DVec3) -> DQuat {
    if from == DVec3::ZERO || to == DVec3::ZERO {
        return DQuat::IDENTITY;
    }
    let w = 0.5 * (from + to).length_squared();
    let c = from.cross(to);
    if w == 0.0 && c == DVec3::ZERO {
        return DQuat::from_axis_angle(from.any_orthonormal_vector(), std::f64::consts::PI);
    }
    DQuat::from_xyzw(c.x, c.y, c.z, w).normalize()
}

/// The frame `[τ, ν × τ, ν]` of a knot with unit tangent `τ`, `ν` the
/// surface normal `n` made orthogonal to it (`None` when `n` is zero or
/// nearly along `τ`).
fn knot_frame(tangent: DVec3, n: DVec3) -> Option<DMat3> {
    let nu = n - n.dot(tangent) * tangent;
    let l = nu.length();
    if !(l > NORMAL_ALONG_TANGENT * n.length()) || tangent == DVec3::ZERO {
        return None;
    }
    let nu = nu / l;
    Some(DMat3::from_cols(tangent, nu.cross(tangent), nu))
}
