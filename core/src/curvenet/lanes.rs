//! The curvenet deformation of a group of `K` frames at once, one frame per
//! vector lane (issue #19): scaled frames, per-side deformation gradients
//! and the constraint slots' rows (f_c and x_c) of every frame of a group,
//! written straight into the group's interleaved block (`crate::solve`'s
//! `Lanes`).
//!
//! A frame alone takes [`frames_into`](super::frames::frames_into),
//! [`deformation_gradients_into`](super::gradient::deformation_gradients_into)
//! and [`constraint_gradients_into`](super::constraints::constraint_gradients_into)
//! and then the binding's slot rows; this module does the same IEEE
//! operations in the same order for each lane (glam's association of every
//! dot, cross and matrix product spelled out; no fused multiply-add; `sin`,
//! `cos` and `atan2` called per lane), so a group gives every frame the bits
//! its single solve gives (`tests/multi_frame.rs` compares them). The
//! branches of the scalar code become per-lane selects of values computed
//! in every lane; the rare branches that would need more (a curve end's
//! normals and widths at an intersection, the torsion angle) run the
//! scalar code once per lane.
//!
//! Anything the scalar code would report as an error (a collapsed segment,
//! a non-finite sample, a degenerate intersection) makes [`slot_rows`]
//! return `Err(())`: the group then makes its rows frame by frame, which
//! names the error and the frame. A curve that meets no intersection
//! (`CurvenetLayout::curve_is_isolated`: its frames come from its own
//! vector area) runs the scalar code lane by lane.

use glam::DVec3;

use super::frames::{EndFrame, ScaledFrame, end_frame, isolated_curve_area};
use super::gradient::segment_gradients;
use super::layout::CurvenetLayout;
use super::rotation::ANTIPARALLEL;
use super::rotation::orthonormalize;

/// `K` values, one per frame of the group.
type L<const K: usize> = [f64; K];
/// A 3-vector of `K` lanes (`[x, y, z]`).
type V<const K: usize> = [L<K>; 3];

/// Reusable per-group buffers (grown, never shrunk).
#[derive(Debug, Default)]
pub(crate) struct LaneScratch {
    /// Per segment: tangent x, y, z and length, `K` lanes each.
    tl: Vec<f64>,
    /// Per segment of the curve in progress, per side: the transported normal.
    u: Vec<f64>,
    /// Per segment of the curve in progress, per side: `F`, row-major.
    g: Vec<f64>,
}

impl LaneScratch {
    /// Heap bytes held.
    pub(crate) fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.tl) + crate::heap::bytes(&self.u) + crate::heap::bytes(&self.g)
    }

    /// Sizes the buffers for `k` lanes of the curvenets `layouts`.
    pub(crate) fn size(&mut self, layouts: &[CurvenetLayout], k: usize) {
        let segs = layouts.iter().map(|l| l.sampling().n_segments()).max().unwrap_or(0);
        let curve = layouts
            .iter()
            .flat_map(|l| (0..l.sampling().n_curves()).map(|c| l.sampling().curve_segments(c).len()))
            .max()
            .unwrap_or(0);
        self.tl.resize(segs * 4 * k, 0.0);
        self.u.resize(curve * 2 * 3 * k, 0.0);
        self.g.resize(curve * 2 * 9 * k, 0.0);
    }
}

/// Where one curvenet's slot rows go.
pub(crate) struct SlotRows<'a, const K: usize> {
    /// The curvenet's first global slot and first global sample.
    pub first_slot: usize,
    pub first_sample: usize,
    /// The binding's global sample of every global slot, and every global
    /// sample's rest offset q̌ − p̌.
    pub slot_sample: &'a [u32],
    pub sample_offset: &'a [DVec3],
    /// The block's constraint rows: 9 lane vectors per row (f_c, row-major
    /// `F`), and 3 per row (x_c).
    pub grad: &'a mut [L<K>],
    pub xc: &'a mut [L<K>],
}

#[inline(always)]
fn lanes<const K: usize>(mut f: impl FnMut(usize) -> f64) -> L<K> {
    let mut x = [0.0; K];
    for (i, x) in x.iter_mut().enumerate() {
        *x = f(i);
    }
    x
}
/// `[f(0), f(1), f(2)]`.
#[inline(always)]
fn vec3<const K: usize>(mut f: impl FnMut(usize) -> L<K>) -> V<K> {
    [f(0), f(1), f(2)]
}
#[inline(always)]
fn add<const K: usize>(a: L<K>, b: L<K>) -> L<K> {
    lanes(|i| a[i] + b[i])
}
#[inline(always)]
fn sub<const K: usize>(a: L<K>, b: L<K>) -> L<K> {
    lanes(|i| a[i] - b[i])
}
#[inline(always)]
fn mul<const K: usize>(a: L<K>, b: L<K>) -> L<K> {
    lanes(|i| a[i] * b[i])
}
#[inline(always)]
fn div<const K: usize>(a: L<K>, b: L<K>) -> L<K> {
    lanes(|i| a[i] / b[i])
}
#[inline(always)]
fn sqrt<const K: usize>(a: L<K>) -> L<K> {
    lanes(|i| a[i].sqrt())
}
#[inline(always)]
fn splat<const K: usize>(x: f64) -> L<K> {
    [x; K]
}
/// `a · b` as glam: `(x·x + y·y) + z·z`.
#[inline(always)]
fn dot<const K: usize>(a: &V<K>, b: &V<K>) -> L<K> {
    add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]))
}
/// `a × b` as glam: `x = a.y b.z − b.y a.z`, and so on.
#[inline(always)]
fn cross<const K: usize>(a: &V<K>, b: &V<K>) -> V<K> {
    [
        sub(mul(a[1], b[2]), mul(b[1], a[2])),
        sub(mul(a[2], b[0]), mul(b[2], a[0])),
        sub(mul(a[0], b[1]), mul(b[0], a[1])),
    ]
}
/// `s v`.
#[inline(always)]
fn scale<const K: usize>(s: L<K>, v: &V<K>) -> V<K> {
    [mul(s, v[0]), mul(s, v[1]), mul(s, v[2])]
}
#[inline(always)]
fn vadd<const K: usize>(a: &V<K>, b: &V<K>) -> V<K> {
    [add(a[0], b[0]), add(a[1], b[1]), add(a[2], b[2])]
}
/// Per lane, `a` where `keep` else `b`.
#[inline(always)]
fn select<const K: usize>(keep: [bool; K], a: &V<K>, b: &V<K>) -> V<K> {
    vec3(|c| lanes(|i| if keep[i] { a[c][i] } else { b[c][i] }))
}
/// Lane `i` of `v`.
#[inline(always)]
fn lane<const K: usize>(v: &V<K>, i: usize) -> DVec3 {
    DVec3::new(v[0][i], v[1][i], v[2][i])
}

/// [`super::rotation::transport`] of both normals, lane by lane.
#[inline(always)]
fn transport<const K: usize>(u: &mut [V<K>; 2], from: &V<K>, to: &V<K>) {
    let c = dot(from, to);
    let one_c = add(splat(1.0), c);
    let moves: [bool; K] = std::array::from_fn(|i| one_c[i] > ANTIPARALLEL);
    if !moves.iter().any(|&m| m) {
        return;
    }
    let v = cross(from, to);
    let k = div(splat(1.0), one_c);
    for n in u.iter_mut() {
        let moved = vadd(&vadd(&scale(c, n), &cross(&v, n)), &scale(mul(dot(&v, n), k), &v));
        *n = select(moves, &moved, n);
    }
}

/// Tangent (3 lane vectors) and length of segment `s` in `tl`.
#[inline(always)]
fn tangent<const K: usize>(tl: &[L<K>], s: usize) -> (V<K>, L<K>) {
    ([tl[4 * s], tl[4 * s + 1], tl[4 * s + 2]], tl[4 * s + 3])
}

/// One curvenet's slot rows (f_c and x_c) for the `K` frames sampled at
/// `samples` (each frame's samples of this curvenet, as
/// `Sampling::samples_into` makes them), as the scalar path makes them:
/// [`frames_into`](super::frames::frames_into), then the gradients against
/// the neutral frames, then per slot the mean of its segments' `F` and
/// `q − F (q̌ − p̌)`. `Err(())` where the scalar path would fail (module
/// docs): nothing the block holds is then meaningful.
#[inline(always)]
pub(crate) fn slot_rows<const K: usize>(
    layout: &CurvenetLayout,
    samples: &[&[[f64; 3]]; K],
    scratch: &mut LaneScratch,
    rows: SlotRows<'_, K>,
) -> Result<(), ()> {
    let plan = layout.frame_plan();
    let sampling = plan.sampling;
    let neutral = layout.neutral_frames();
    if samples.iter().any(|s| s.len() != sampling.n_samples()) || neutral.len() != sampling.n_segments() {
        return Err(());
    }
    let (tl, _) = scratch.tl.as_chunks_mut::<K>();
    let (ub, _) = scratch.u.as_chunks_mut::<K>();
    let (gb, _) = scratch.g.as_chunks_mut::<K>();
    // Tangents and lengths of every segment (curve ends read other curves').
    let min_length = plan.collapse_length;
    for (s, seg) in sampling.segments().iter().enumerate() {
        let [a, b] = seg.samples.map(|x| x as usize);
        let d: V<K> = vec3(|c| lanes(|i| samples[i][b][c] - samples[i][a][c]));
        let l = sqrt(dot(&d, &d));
        if l.iter().any(|&l| !(l.is_finite() && l > min_length)) {
            return Err(());
        }
        for c in 0..3 {
            tl[4 * s + c] = div(d[c], l);
        }
        tl[4 * s + 3] = l;
    }
    let tl: &[L<K>] = tl;
    let mut slot = rows.first_slot;
    for c in 0..sampling.n_curves() {
        let segs = sampling.curve_segments(c);
        let local = |s: usize| s - segs.start;
        // The scalar code's own tests: `frames_into` takes a curve with no
        // end at an intersection apart; the gradients, an isolated curve.
        if plan.curve_ends[c] == [None, None] {
            // A curve that meets no intersection, lane by lane through the
            // scalar code (such curves are few, and rarely long).
            for (i, lane_samples) in samples.iter().enumerate() {
                let length: f64 = segs.clone().map(|s| tangent(tl, s).1[i]).sum();
                let area = isolated_curve_area(lane_samples, sampling.curve_samples(c), length);
                for s in segs.clone() {
                    let (t, l) = tangent(tl, s);
                    let t = lane(&t, i);
                    let normal = area.and_then(|a| orthonormalize(a, t));
                    let frame = ScaledFrame {
                        tangent: t.to_array(),
                        binormal: normal.map_or([0.0; 3], |n| n.cross(t).to_array()),
                        normal: normal.map_or([0.0; 3], |n| n.to_array()),
                        scale: [l[i]; 3],
                    };
                    let r = &neutral[s];
                    if r.iter().flat_map(|f| f.scale.iter()).any(|x| !(x.is_finite() && *x > 0.0)) {
                        return Err(());
                    }
                    for (side, f) in segment_gradients(layout.curve_is_isolated(c), r, &[frame; 2]).iter().enumerate() {
                        let g = &mut gb[(local(s) * 2 + side) * 9..][..9];
                        for (e, x) in f.as_flattened().iter().enumerate() {
                            g[e][i] = *x;
                        }
                    }
                }
            }
        } else {
            intersection_curve(layout, tl, ub, gb, c)?;
        }
        // The curve's slots: the mean of the segments' F on each side, and
        // q − F (q̌ − p̌).
        for cs in layout.constraints().curve_slots(c) {
            let side = cs.side as usize;
            let gather = |seg: u32| (local(seg as usize) * 2 + side) * 9;
            let (a, b) = match (cs.incoming, cs.outgoing) {
                (Some(a), Some(b)) => (gather(a), Some(gather(b))),
                (Some(a), None) | (None, Some(a)) => (gather(a), None),
                (None, None) => return Err(()),
            };
            let f = &mut rows.grad[slot * 9..][..9];
            match b {
                Some(b) => {
                    for e in 0..9 {
                        f[e] = mul(splat(0.5), add(gb[a + e], gb[b + e]));
                    }
                }
                None => f.copy_from_slice(&gb[a..a + 9]),
            }
            let sample = rows.slot_sample[slot] as usize;
            let o = rows.sample_offset[sample];
            let q = sample - rows.first_sample;
            for row in 0..3 {
                let q = lanes(|i| samples[i][q][row]);
                let fo = add(
                    add(mul(f[row * 3], splat(o.x)), mul(f[row * 3 + 1], splat(o.y))),
                    mul(f[row * 3 + 2], splat(o.z)),
                );
                rows.xc[slot * 3 + row] = sub(q, fo);
            }
            slot += 1;
        }
    }
    Ok(())
}

/// The `F` of both sides of every segment of curve `c`, a curve that meets
/// an intersection, into `gb` (9 lane vectors per segment and side, from
/// the curve's first segment), from the tangents and lengths `tl`, as
/// [`frames_into`](super::frames::frames_into) and the gradients make them
/// (`ub`: room for the transported normals).
#[inline(always)]
fn intersection_curve<const K: usize>(
    layout: &CurvenetLayout,
    tl: &[L<K>],
    ub: &mut [L<K>],
    gb: &mut [L<K>],
    c: usize,
) -> Result<(), ()> {
    let plan = layout.frame_plan();
    let neutral = layout.neutral_frames();
    let segs = plan.sampling.curve_segments(c);
    let [start, end] = plan.curve_ends[c];
    let local = |s: usize| s - segs.start;
    // Each frame's curve ends, by the scalar code on its lane.
    let mut ends: [[Option<EndFrame>; 2]; K] = [[None; 2]; K];
    for (i, e) in ends.iter_mut().enumerate() {
        let segment = |s: usize| {
            let (t, l) = tangent(tl, s);
            (lane(&t, i), l[i])
        };
        for (slot, end, at_start) in [(0, start, true), (1, end, false)] {
            if let Some((f, k)) = end {
                e[slot] = Some(end_frame(plan.fans, f, k, at_start, segment).map_err(|_| ())?);
            }
        }
    }
    let normals = |which: usize, side: usize| -> V<K> {
        vec3(|comp| lanes(|i| ends[i][which].map_or(0.0, |e| e.normal[side][comp])))
    };
    let widths = |which: usize, side: usize| -> L<K> { lanes(|i| ends[i][which].map_or(0.0, |e| e.width[side])) };
    // Transport the normals from the intersection end (into `ub`).
    let from = if start.is_some() {
        0
    } else if end.is_some() {
        1
    } else {
        return Err(());
    };
    let mut u = [normals(from, 0), normals(from, 1)];
    let mut keep = |s: usize, u: &[V<K>; 2]| {
        for (side, n) in u.iter().enumerate() {
            for comp in 0..3 {
                ub[(local(s) * 2 + side) * 3 + comp] = n[comp];
            }
        }
    };
    if from == 0 {
        for s in segs.clone() {
            if s > segs.start {
                transport(&mut u, &tangent(tl, s - 1).0, &tangent(tl, s).0);
            }
            keep(s, &u);
        }
    } else {
        for s in segs.clone().rev() {
            if s + 1 < segs.end {
                transport(&mut u, &tangent(tl, s + 1).0, &tangent(tl, s).0);
            }
            keep(s, &u);
        }
    }
    // The torsion between two intersections, per lane and side.
    let blend = start.is_some() && end.is_some();
    let mut theta = [[0.0; K]; 2];
    if blend {
        let t_k = tangent(tl, segs.end - 1).0;
        for (side, th) in theta.iter_mut().enumerate() {
            for (i, x) in th.iter_mut().enumerate() {
                let (u, n) = (lane(&u[side], i), ends[i][1].map_or(DVec3::ZERO, |e| e.normal[side]));
                *x = u.dot(n.cross(lane(&t_k, i))).atan2(u.dot(n));
            }
        }
    }
    let (w_first, w_last) = ([widths(from, 0), widths(from, 1)], [widths(1, 0), widths(1, 1)]);
    let mut total = splat::<K>(-0.0);
    if blend {
        for s in segs.clone() {
            total = add(total, tangent(tl, s).1);
        }
    }
    // Blend, complete the frames, and their gradients (into `gb`).
    let mut arc = splat::<K>(0.0);
    for s in segs.clone() {
        let (t, l) = tangent(tl, s);
        for side in 0..2 {
            let at = (local(s) * 2 + side) * 3;
            let mut n: V<K> = [ub[at], ub[at + 1], ub[at + 2]];
            let mut w = w_first[side];
            if blend {
                let alpha = div(arc, total);
                let angle = mul(alpha, theta[side]);
                let mut sn = [0.0; K];
                let mut cs = [0.0; K];
                for i in 0..K {
                    (sn[i], cs[i]) = angle[i].sin_cos();
                }
                // c n + s (t × n) + ((1 − c)(t · n)) t
                let along = mul(sub(splat(1.0), cs), dot(&t, &n));
                n = vadd(&vadd(&scale(cs, &n), &scale(sn, &cross(&t, &n))), &scale(along, &t));
                w = add(mul(sub(splat(1.0), alpha), w_first[side]), mul(alpha, w_last[side]));
            }
            // orthonormalize(n, t).unwrap_or(n)
            let d = dot(&n, &t);
            let p = [sub(n[0], mul(d, t[0])), sub(n[1], mul(d, t[1])), sub(n[2], mul(d, t[2]))];
            let len = sqrt(dot(&p, &p));
            let m_len = sqrt(dot(&n, &n));
            let ok: [bool; K] = std::array::from_fn(|i| len[i] > 1e-9 * m_len[i] && len[i] > 0.0);
            let unit = [div(p[0], len), div(p[1], len), div(p[2], len)];
            let n = select(ok, &unit, &n);
            let b = cross(&n, &t);
            let h = sqrt(mul(l, w));
            // F = (l/ľ) t ⊗ ť + (w/w̌) b ⊗ b̌ + (h/ȟ) n ⊗ ň, summed as glam sums the three matrices.
            let r = &neutral[s][side];
            if r.scale.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
                return Err(());
            }
            let s0 = div(l, splat(r.scale[0]));
            let s1 = div(w, splat(r.scale[1]));
            let s2 = div(h, splat(r.scale[2]));
            let g = &mut gb[(local(s) * 2 + side) * 9..][..9];
            for row in 0..3 {
                for col in 0..3 {
                    let a = mul(mul(t[row], splat(r.tangent[col])), s0);
                    let bb = mul(mul(b[row], splat(r.binormal[col])), s1);
                    let nn = mul(mul(n[row], splat(r.normal[col])), s2);
                    g[row * 3 + col] = add(add(a, bb), nn);
                }
            }
        }
        arc = add(arc, l);
    }
    Ok(())
}
