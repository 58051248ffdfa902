//! Scaled frames `B S` on both sides of every segment (§3, "Normal & width
//! at intersections" and "Normal & width interpolation").
//!
//! For the segments `s_i` emanating from an intersection in counter-clockwise
//! order, with outward unit tangents `t_i` and lengths `l_i`:
//!
//! - corner vectors `c_i = t_i × t_{i+1}`, corner normals `m_i = c_i/‖c_i‖`;
//! - left (+) normal `n⁺_i = m_i`, right (−) normal `n⁻_i = m_{i−1}`;
//! - widths `w⁺_i = l_i + ‖c_i‖(l_{i+1} − l_i)`, `w⁻_i = l_i + ‖c_{i−1}‖(l_{i−1} − l_i)`.
//!
//! Along a curve the normals are parallel-transported from an intersection
//! by the smallest rotation between consecutive tangents. Between two
//! intersections the mismatch at the far end, the torsion
//! `θ = atan2((Ω_k n_1)·(n_k × t_k), (Ω_k n_1)·n_k)`, is blended in by
//! normalised arc length `α_i = Σ_{j<i} l_j / Σ_j l_j` (rotation by `α_i θ`
//! about `t_i`), and widths are interpolated `w_i = (1 − α_i) w_1 + α_i w_k`.
//! Towards an anchor the width is copied. Finally `b = n × t`,
//! `h = sqrt(l w)`, `B = [t b n]`, `S = diag(l, w, h)`.
//!
//! # Decisions where the paper is silent
//!
//! - **Reflex corners.** A corner whose vector points against the surface
//!   normal in the neutral pose (the curves span less than a half plane) is
//!   negated, in every pose, so that corner normals follow the surface
//!   normal. This changes no deformation gradient while the corner stays
//!   reflex, but keeps the torsion angle away from ±π, where `atan2` would
//!   jump between poses.
//! - **T-junctions.** The paper replaces `m_i` by `(c_{i+1} + c_{i−1})/‖·‖`
//!   when `t_i ∥ t_{i+1}`. A corner that is a T-junction in the neutral
//!   pose (`IntersectionFan::corner_sign` 0: its tangents nearly parallel,
//!   or nearly opposite in the tangent plane so that `c_i` lies more than
//!   60° off the surface normal, as on the cap side of a curved ring met by
//!   one line) takes that fallback in every pose. Taking `c_i/‖c_i‖` there
//!   gave the cap side of a ring a normal along the ring's axis whose sign
//!   round-off decided, so a ring's two ends could disagree by a half turn
//!   and its torsion blend twisted the cap by an angle that jumped between
//!   ±π with the pose: a rigid rotation of a capped tube's curvenet moved
//!   its caps by 8% of the diagonal. Other corners blend smoothly from
//!   `c_i/‖c_i‖` (at `‖c_i‖ = T_JUNCTION_SIN`) to the fallback (at
//!   `‖c_i‖ = 0`), so a corner straightening in a pose does not flip its
//!   normal. The fallback sums only the neighbours that are not T-junction
//!   corners themselves (all such corners of the fan when both neighbours
//!   are). It is not orthogonal to `t_i` in general: every normal is
//!   projected orthogonally to its tangent and renormalised.
//! - **Antiparallel consecutive tangents** (a hairpin segment pair) transport
//!   the normal unchanged (a half turn about the normal).
//! - **Curves with no intersection** (both ends anchors, or isolated closed
//!   curves) have `scale = (l, l, l)` and a normal from the curve's own
//!   vector area when it has one (see `isolated_curve_frames`); a straight
//!   one keeps the paper's tangent-only frame (`normal = binormal = 0`).

use glam::DVec3;

use super::intersections::{IntersectionFan, T_JUNCTION_SIN};
use super::rotation::{orthonormalize, rotate_about, transport};
use super::sampling::Sampling;
use super::{Mat3, Side, v3};
use crate::error::{Error, Result};

/// Vectors shorter than this (relative to unit vectors) are treated as zero.
const TINY: f64 = 1e-12;

/// An orthonormal frame with a scale per axis: `B S` with `B = [t b n]`,
/// `S = diag(l, w, h)`.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct ScaledFrame {
    /// Unit tangent `t` of the segment, in curve direction.
    pub tangent: [f64; 3],
    /// Unit binormal `b = n × t` (points to the curve's plus/left side);
    /// zero for tangent-only frames.
    pub binormal: [f64; 3],
    /// Unit normal `n` of this side; zero for tangent-only frames.
    pub normal: [f64; 3],
    /// `(l, w, h)`: segment length, side width, and `sqrt(l w)`.
    pub scale: [f64; 3],
}

impl ScaledFrame {
    /// The matrix `B S` (row-major): column `j` is axis `j` times scale `j`.
    pub fn matrix(&self) -> Mat3 {
        let axes = [self.tangent, self.binormal, self.normal];
        let mut m = [[0.0; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = axes[j][r] * self.scale[j];
            }
        }
        m
    }

    /// Whether the frame has a normal (false for curves with no intersection).
    pub fn has_normal(&self) -> bool {
        self.normal != [0.0; 3]
    }
}

/// Normals and widths of one curve end, per curve side (index `Side as usize`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct EndFrame {
    pub(crate) normal: [DVec3; 2],
    pub(crate) width: [f64; 2],
}

/// What the frames need of a curvenet's analysis: its sampling plan, its
/// intersections and which fan slot each curve end occupies, and the length
/// below which a segment has collapsed (`CurvenetLayout::frame_plan`).
#[derive(Debug, Clone, Copy)]
pub struct FramePlan<'a> {
    pub sampling: &'a Sampling,
    pub fans: &'a [IntersectionFan],
    /// Per curve, `[start, end]`: `(fan, position in the fan)` at an intersection.
    pub curve_ends: &'a [[Option<(u32, u32)>; 2]],
    pub collapse_length: f64,
}

/// Computes the scaled frames of both sides of every segment of the curvenet
/// sampled at `samples` (`#Q`, e.g. from `Sampling::samples_into`) into `out`
/// (`#G` pairs indexed `[segment][side as usize]`). Allocation-free.
///
/// Fails with [`Error::CountMismatch`] for wrong buffer lengths,
/// [`Error::SegmentCollapsed`] naming the spline and segment when a segment
/// is (numerically) zero length, and [`Error::DegenerateIntersection`] when
/// all curves at an intersection are collinear. Never returns NaN.
pub fn frames_into(plan: FramePlan<'_>, samples: &[[f64; 3]], out: &mut [[ScaledFrame; 2]]) -> Result<()> {
    let sampling = plan.sampling;
    if samples.len() != sampling.n_samples() {
        return Err(Error::CountMismatch {
            what: "curvenet samples",
            expected: sampling.n_samples(),
            got: samples.len(),
        });
    }
    if out.len() != sampling.n_segments() {
        return Err(Error::CountMismatch {
            what: "scaled frame buffer",
            expected: sampling.n_segments(),
            got: out.len(),
        });
    }
    // Tangents and lengths.
    let min_length = plan.collapse_length;
    for (s, seg) in sampling.segments().iter().enumerate() {
        let [a, b] = seg.samples;
        let d = v3(samples[b as usize]) - v3(samples[a as usize]);
        let l = d.length();
        if !l.is_finite() {
            return Err(Error::NonFinite { what: "curvenet sample", index: b as usize, value: samples[b as usize] });
        }
        if l <= min_length {
            return Err(Error::SegmentCollapsed {
                spline: seg.spline as usize,
                segment: seg.spline_segment as usize,
                length: l,
            });
        }
        let f = ScaledFrame { tangent: (d / l).to_array(), binormal: [0.0; 3], normal: [0.0; 3], scale: [l, l, l] };
        out[s] = [f, f];
    }
    // Normals and widths, curve by curve.
    for c in 0..sampling.n_curves() {
        let [start, end] = plan.curve_ends[c];
        if start.is_none() && end.is_none() {
            isolated_curve_frames(samples, sampling.curve_samples(c), sampling.curve_segments(c), out);
            continue;
        }
        let segs = sampling.curve_segments(c);
        let segment = |s: usize| (tangent(out, s), out[s][0].scale[0]);
        let start = start.map(|(f, k)| end_frame(plan.fans, f, k, true, segment)).transpose()?;
        let end = end.map(|(f, k)| end_frame(plan.fans, f, k, false, segment)).transpose()?;
        // Transport the normals along the curve from the intersection end,
        // keeping the transported (not yet renormalised) normals in `out`.
        let theta = match (start, end) {
            (Some(first), last) => {
                let mut u = first.normal;
                for s in segs.clone() {
                    if s > segs.start {
                        transport(&mut u, tangent(out, s - 1), tangent(out, s));
                    }
                    for side in 0..2 {
                        out[s][side].normal = u[side].to_array();
                        out[s][side].scale[1] = first.width[side];
                    }
                }
                last.map(|last| {
                    let t_k = tangent(out, segs.end - 1);
                    let theta = [0, 1]
                        .map(|side| u[side].dot(last.normal[side].cross(t_k)).atan2(u[side].dot(last.normal[side])));
                    (theta, first.width, last.width)
                })
            }
            (None, Some(last)) => {
                // Transport backwards from the end towards the anchor.
                let mut u = last.normal;
                for s in segs.clone().rev() {
                    if s + 1 < segs.end {
                        transport(&mut u, tangent(out, s + 1), tangent(out, s));
                    }
                    for side in 0..2 {
                        out[s][side].normal = u[side].to_array();
                        out[s][side].scale[1] = last.width[side];
                    }
                }
                None
            }
            (None, None) => unreachable!("curves with no intersection are skipped"),
        };
        // Between two intersections, blend in the torsion and the widths by
        // arc length; then every normal is made a unit vector orthogonal to
        // its tangent (once, here: the transport is a rotation, so the chain
        // above needs no renormalising step) and the frame completed.
        let total: f64 = if theta.is_some() { segs.clone().map(|s| out[s][0].scale[0]).sum() } else { 0.0 };
        let mut arc = 0.0;
        for s in segs {
            let t = tangent(out, s);
            let l = out[s][0].scale[0];
            for side in 0..2 {
                let f = &mut out[s][side];
                let mut n = v3(f.normal);
                if let Some((theta, w_first, w_last)) = theta {
                    let alpha = arc / total;
                    n = rotate_about(n, t, alpha * theta[side]);
                    f.scale[1] = (1.0 - alpha) * w_first[side] + alpha * w_last[side];
                }
                let n = orthonormalize(n, t).unwrap_or(n);
                f.normal = n.to_array();
                f.binormal = n.cross(t).to_array();
                f.scale[2] = (f.scale[0] * f.scale[1]).sqrt();
            }
            arc += l;
        }
    }
    Ok(())
}

/// Frames of a curve that meets no intersection: the paper gives it only a
/// tangent. We complete the frame from the curve's own shape when it has
/// one: `N`, the vector area of its sample polygon (closed by its chord when
/// the curve is open), gives each segment the normal `N` made orthogonal to
/// its tangent. A rigid motion moves `N` with the curve, so such a curve's
/// `F` is the motion's rotation, as for curves meeting intersections; the
/// paper's smallest rotation of the tangent alone is not (it loses any
/// rotation about the tangent, e.g. tilting a ring). A straight curve has no
/// vector area and keeps tangent-only frames (the paper's rule).
fn isolated_curve_frames(
    samples: &[[f64; 3]],
    curve_samples: &[u32],
    segs: std::ops::Range<usize>,
    out: &mut [[ScaledFrame; 2]],
) {
    let length: f64 = segs.clone().map(|s| out[s][0].scale[0]).sum();
    let Some(area) = isolated_curve_area(samples, curve_samples, length) else { return };
    for s in segs {
        let t = v3(out[s][0].tangent);
        let Some(n) = orthonormalize(area, t) else { continue };
        for f in &mut out[s] {
            f.normal = n.to_array();
            f.binormal = n.cross(t).to_array();
        }
    }
}

/// The vector area `N` of an isolated curve's sample polygon (closed by its
/// chord), `None` when the curve is (numerically) straight: shorter than
/// `1e-6 length²` for the curve's `length` (the sum of its segments').
pub(crate) fn isolated_curve_area(samples: &[[f64; 3]], curve_samples: &[u32], length: f64) -> Option<DVec3> {
    let pts = || curve_samples.iter().map(|&i| v3(samples[i as usize]));
    let o = pts().next()?;
    let mut area = DVec3::ZERO;
    let mut prev = DVec3::ZERO;
    for p in pts() {
        area += prev.cross(p - o);
        prev = p - o;
    }
    (area.length() > 1e-6 * length * length).then_some(area)
}

/// Allocating form of [`frames_into`].
pub fn frames(plan: FramePlan<'_>, samples: &[[f64; 3]]) -> Result<Vec<[ScaledFrame; 2]>> {
    let mut out = vec![[ScaledFrame::default(); 2]; plan.sampling.n_segments()];
    frames_into(plan, samples, &mut out)?;
    Ok(out)
}

/// Normals and widths, per curve side, at the curve end occupying position
/// `k` of fan `f`. `at_start` tells whether it is the curve's start;
/// `segment(s)` gives segment `s`'s unit tangent and length (from the
/// frames in progress, or from one frame of a group).
pub(crate) fn end_frame(
    fans: &[IntersectionFan],
    f: u32,
    k: u32,
    at_start: bool,
    segment: impl Fn(usize) -> (DVec3, f64),
) -> Result<EndFrame> {
    let fan = &fans[f as usize];
    let v = fan.valence();
    let k = k as usize;
    // Outward tangent and length of emanation j.
    let out_tangent = |j: usize| {
        let e = fan.emanations()[j % v];
        let (t, l) = segment(e.segment as usize);
        (if e.at_start { t } else { -t }, l)
    };
    let raw = |j: usize| out_tangent(j).0.cross(out_tangent(j + 1).0);
    // The corner vector oriented along the surface normal; zero for a T-junction corner.
    let oriented = |j: usize| match fan.corner_sign(j % v) {
        0 => DVec3::ZERO,
        s if s < 0 => -raw(j % v),
        _ => raw(j % v),
    };
    let fallback = |j: usize| {
        let near = oriented(j + 1) + oriented(j + v - 1);
        if near.length() > TINY { near } else { (0..v).filter(|&i| i != j % v).map(oriented).sum() }
    };
    let corner_normal = |j: usize| -> Result<DVec3> {
        let j = j % v;
        let fb = fallback(j);
        let nf = fb.length();
        if fan.corner_sign(j) == 0 {
            return if nf > TINY { Ok(fb / nf) } else { Err(Error::DegenerateIntersection { point: fan.point() }) };
        }
        let c_hat = oriented(j);
        let nc = c_hat.length();
        if nc >= T_JUNCTION_SIN {
            return Ok(c_hat / nc);
        }
        let lambda = 1.0 - nc / T_JUNCTION_SIN;
        let blend = match (nc > TINY, nf > TINY) {
            (true, true) => (1.0 - lambda) * (c_hat / nc) + lambda * (fb / nf),
            (false, true) => fb,
            (true, false) => c_hat,
            (false, false) => DVec3::ZERO,
        };
        if blend.length() > 1e-6 {
            return Ok(blend.normalize());
        }
        if nf > TINY {
            return Ok(fb / nf);
        }
        let sum: DVec3 = (0..v).map(oriented).sum();
        if sum.length() > TINY {
            Ok(sum.normalize())
        } else {
            Err(Error::DegenerateIntersection { point: fan.point() })
        }
    };
    let (t, l) = out_tangent(k);
    let degenerate = || Error::DegenerateIntersection { point: fan.point() };
    let n_left = orthonormalize(corner_normal(k)?, t).ok_or_else(degenerate)?;
    let n_right = orthonormalize(corner_normal(k + v - 1)?, t).ok_or_else(degenerate)?;
    let w_left = l + raw(k).length() * (out_tangent(k + 1).1 - l);
    let w_right = l + raw(k + v - 1).length() * (out_tangent(k + v - 1).1 - l);
    // Seen from the intersection, a curve end is walked backwards: its left
    // is the curve's right.
    let (plus, minus) =
        if at_start { ((n_left, w_left), (n_right, w_right)) } else { ((n_right, w_right), (n_left, w_left)) };
    let mut frame = EndFrame { normal: [DVec3::ZERO; 2], width: [0.0; 2] };
    for (side, (n, w)) in [(Side::Plus, plus), (Side::Minus, minus)] {
        frame.normal[side as usize] = n;
        frame.width[side as usize] = w;
    }
    Ok(frame)
}

fn tangent(frames: &[[ScaledFrame; 2]], s: usize) -> DVec3 {
    v3(frames[s][0].tangent)
}
