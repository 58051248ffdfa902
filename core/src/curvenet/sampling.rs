//! The fixed sampling plan of a curvenet and its per-pose evaluation.
//!
//! Every spline gets `n = max(1, round(density × control-polygon length ÷
//! mean mesh edge length))` segments, both lengths in the neutral pose
//! (§3 "Sampling"). The counts are then **fixed**: every pose has the same
//! samples, so segments correspond one to one between poses. Two exceptions
//! keep the polyline non-degenerate: a spline whose endpoints coincide gets
//! at least 3 segments, and a closed curve (isolated, or a loop through an
//! intersection) with fewer than 3 segments in all gets the missing ones on
//! its first spline.
//!
//! In a pose, each spline is refined uniformly in parameter
//! (`max(min_refinement, refinement_per_segment × n)` pieces), then its
//! `n − 1` interior samples are placed at equal arc length along that
//! polyline and evaluated exactly on the Bézier curve.
//!
//! # Sample numbering
//!
//! Samples are unique points: first one **knot sample** per control point
//! that is a spline endpoint (in increasing control-point order; its position
//! is the control point itself), then the `n − 1` interior samples of every
//! spline in spline order, each run ordered from the spline's control point
//! 0 to 3. Consecutive splines of a curve share their knot sample, and an
//! intersection's sample is shared by all its curves.
//!
//! # Segment numbering
//!
//! Segments are numbered curve after curve, in curve direction. A segment
//! also records its spline and its index within the spline counted from the
//! spline's control point 0 (so errors can name it).

use std::ops::Range;

use glam::DVec3;

use super::topology::Topology;
use super::{Curvenet, ZERO_LENGTH_TOLERANCE, v3};
use crate::error::{Error, Result};
use crate::mesh::check_finite;
use crate::simd::Simd;

/// Default samples per mean mesh edge length of control polygon (the paper's 5).
pub const DEFAULT_DENSITY: f64 = 5.0;
/// Default fewest uniform parametric pieces per spline before arc-length resampling.
pub const DEFAULT_MIN_REFINEMENT: u32 = 128;
/// Default uniform parametric pieces per output segment (when more than the minimum).
pub const DEFAULT_REFINEMENT_PER_SEGMENT: u32 = 8;
/// Default largest number of segments one spline may get.
pub const DEFAULT_MAX_SEGMENTS_PER_SPLINE: u32 = 100_000;

/// Sampling options, with named defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SamplingOptions {
    /// Segments per mean mesh edge length of control polygon ([`DEFAULT_DENSITY`]).
    pub density: f64,
    /// Fewest uniform parametric pieces per spline ([`DEFAULT_MIN_REFINEMENT`]).
    pub min_refinement: u32,
    /// Parametric pieces per segment ([`DEFAULT_REFINEMENT_PER_SEGMENT`]).
    pub refinement_per_segment: u32,
    /// Largest segment count of one spline ([`DEFAULT_MAX_SEGMENTS_PER_SPLINE`]);
    /// more gives [`Error::TooManySegments`].
    pub max_segments_per_spline: u32,
}

impl Default for SamplingOptions {
    fn default() -> Self {
        Self {
            density: DEFAULT_DENSITY,
            min_refinement: DEFAULT_MIN_REFINEMENT,
            refinement_per_segment: DEFAULT_REFINEMENT_PER_SEGMENT,
            max_segments_per_spline: DEFAULT_MAX_SEGMENTS_PER_SPLINE,
        }
    }
}

impl SamplingOptions {
    /// Sets the sampling density.
    pub fn with_density(mut self, density: f64) -> Self {
        self.density = density;
        self
    }

    /// Sets the largest segment count of one spline.
    pub fn with_max_segments_per_spline(mut self, max: u32) -> Self {
        self.max_segments_per_spline = max;
        self
    }
}

/// A segment: two consecutive samples of a curve, in curve direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Segment {
    /// `[from, to]` sample indices, in curve direction.
    pub samples: [u32; 2],
    /// The curve containing the segment.
    pub curve: u32,
    /// The spline containing the segment.
    pub spline: u32,
    /// Index of the segment within its spline, counted from control point 0.
    pub spline_segment: u32,
}

/// The immutable sampling plan of a curvenet (see the module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sampling {
    #[serde(with = "crate::persist::pod")]
    splines: Vec<[u32; 4]>,
    n_points: usize,
    #[serde(with = "crate::persist::pod")]
    spline_segments: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    spline_refinement: Vec<u32>,
    /// First interior sample of every spline.
    #[serde(with = "crate::persist::pod")]
    spline_interior: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    knot_points: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    point_knot: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    curve_sample_offsets: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    curve_samples: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    curve_segment_offsets: Vec<u32>,
    segments: Vec<Segment>,
    n_samples: usize,
}

const NO_KNOT: u32 = u32::MAX;

impl Sampling {
    /// Plans the sampling of `curvenet` (with its `topology`), with
    /// `mean_edge_length` the mean edge length of the surface mesh in the
    /// neutral pose.
    ///
    /// Fails with [`Error::InvalidParameter`] for a non-positive density or
    /// edge length, [`Error::TooManySegments`], or [`Error::ZeroLengthSpline`]
    /// when a spline's neutral arc length is zero.
    pub fn new(
        curvenet: &Curvenet,
        topology: &Topology,
        mean_edge_length: f64,
        options: &SamplingOptions,
    ) -> Result<Self> {
        if !(mean_edge_length.is_finite() && mean_edge_length > 0.0) {
            return Err(Error::InvalidParameter {
                what: "the mean edge length of the surface mesh",
                value: mean_edge_length,
            });
        }
        if !(options.density.is_finite() && options.density > 0.0) {
            return Err(Error::InvalidParameter { what: "the sampling density", value: options.density });
        }
        let splines = curvenet.splines();
        let points = curvenet.points();
        let tol = ZERO_LENGTH_TOLERANCE * crate::mesh::bounding_box_diagonal(points);

        let mut spline_segments = Vec::with_capacity(splines.len());
        for (i, s) in splines.iter().enumerate() {
            let p = s.map(|v| v3(points[v as usize]));
            let polygon = (p[1] - p[0]).length() + (p[2] - p[1]).length() + (p[3] - p[2]).length();
            let raw = options.density * polygon / mean_edge_length;
            if raw.is_nan() || raw.round() > options.max_segments_per_spline as f64 {
                return Err(Error::TooManySegments { spline: i, segments: raw, max: options.max_segments_per_spline });
            }
            let mut n = (raw.round() as u32).max(1);
            if (p[3] - p[0]).length() <= tol {
                n = n.max(3);
            }
            spline_segments.push(n);
        }
        for curve in topology.curves() {
            let total: u32 = curve.splines.iter().map(|cs| spline_segments[cs.spline as usize]).sum();
            if curve.is_closed() && total < 3 {
                spline_segments[curve.splines[0].spline as usize] += 3 - total;
            }
        }
        let spline_refinement: Vec<u32> = spline_segments
            .iter()
            .map(|&n| options.min_refinement.max(1).max(options.refinement_per_segment.saturating_mul(n)))
            .collect();
        for (i, s) in splines.iter().enumerate() {
            let ctrl = s.map(|v| v3(points[v as usize]));
            if polyline_length(&ctrl, spline_refinement[i]) <= tol {
                return Err(Error::ZeroLengthSpline { spline: i });
            }
        }

        // Knot samples, then interior samples.
        let mut point_knot = vec![NO_KNOT; points.len()];
        for s in splines {
            point_knot[s[0] as usize] = 0;
            point_knot[s[3] as usize] = 0;
        }
        let mut knot_points = Vec::new();
        for (p, k) in point_knot.iter_mut().enumerate() {
            if *k == 0 {
                *k = knot_points.len() as u32;
                knot_points.push(p as u32);
            }
        }
        let mut spline_interior = Vec::with_capacity(splines.len());
        let mut next = knot_points.len() as u64;
        for &n in &spline_segments {
            spline_interior.push(next as u32);
            next += n as u64 - 1;
        }
        if next >= u32::MAX as u64 {
            return Err(Error::CountMismatch {
                what: "curvenet samples (at most 2^32 - 1)",
                expected: u32::MAX as usize - 1,
                got: next as usize,
            });
        }
        let n_samples = next as usize;

        let spline_sample = |s: usize, k: u32| -> u32 {
            let n = spline_segments[s];
            if k == 0 {
                point_knot[splines[s][0] as usize]
            } else if k == n {
                point_knot[splines[s][3] as usize]
            } else {
                spline_interior[s] + k - 1
            }
        };
        let mut curve_sample_offsets = vec![0u32];
        let mut curve_samples = Vec::new();
        let mut curve_segment_offsets = vec![0u32];
        let mut segments = Vec::new();
        for (c, curve) in topology.curves().iter().enumerate() {
            let first_sample = curve_samples.len();
            for (j, cs) in curve.splines.iter().enumerate() {
                let s = cs.spline as usize;
                let n = spline_segments[s];
                for step in 0..=n {
                    let k = if cs.reversed { n - step } else { step };
                    if step == 0 && j > 0 {
                        continue; // shared with the previous spline
                    }
                    if step > 0 {
                        let seg = if cs.reversed { n - step } else { step - 1 };
                        let from = *curve_samples.last().expect("a curve's first sample precedes its segments");
                        segments.push(Segment {
                            samples: [from, spline_sample(s, k)],
                            curve: c as u32,
                            spline: cs.spline,
                            spline_segment: seg,
                        });
                    }
                    curve_samples.push(spline_sample(s, k));
                }
            }
            if matches!(curve.start, super::CurveEnd::Closed(_)) {
                // An isolated closed curve lists its start sample once.
                curve_samples.pop();
            }
            debug_assert!(curve_samples.len() > first_sample);
            curve_sample_offsets.push(curve_samples.len() as u32);
            curve_segment_offsets.push(segments.len() as u32);
        }

        Ok(Self {
            splines: splines.to_vec(),
            n_points: points.len(),
            spline_segments,
            spline_refinement,
            spline_interior,
            knot_points,
            point_knot,
            curve_sample_offsets,
            curve_samples,
            curve_segment_offsets,
            segments,
            n_samples,
        })
    }

    /// The splines, `#S` quadruples of control-point indices.
    pub fn splines(&self) -> &[[u32; 4]] {
        &self.splines
    }

    /// Number of control points `#P` of the pool this plan samples.
    pub fn n_points(&self) -> usize {
        self.n_points
    }

    /// Number of samples `#Q` (the length of a sample buffer).
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// Number of knot samples (they come first; knot `k` is control point
    /// [`Self::knot_point`]`(k)`).
    pub fn n_knots(&self) -> usize {
        self.knot_points.len()
    }

    /// The control point of knot sample `k < n_knots()`.
    pub fn knot_point(&self, k: usize) -> u32 {
        self.knot_points[k]
    }

    /// The knot sample of control point `p`, if `p` is a spline endpoint.
    pub fn knot_sample(&self, p: usize) -> Option<u32> {
        self.point_knot.get(p).copied().filter(|&k| k != NO_KNOT)
    }

    /// Number of segments `#G` (the length of a frame or gradient buffer).
    pub fn n_segments(&self) -> usize {
        self.segments.len()
    }

    /// All segments, curve after curve, in curve direction.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// The number of segments of spline `s` (fixed for all poses).
    pub fn spline_segments(&self, s: usize) -> u32 {
        self.spline_segments[s]
    }

    /// The `n + 1` samples of spline `s`, from its control point 0 to 3.
    pub fn spline_samples(&self, s: usize) -> impl ExactSizeIterator<Item = u32> + '_ {
        let n = self.spline_segments[s];
        (0..n + 1).map(move |k| {
            if k == 0 {
                self.point_knot[self.splines[s][0] as usize]
            } else if k == n {
                self.point_knot[self.splines[s][3] as usize]
            } else {
                self.spline_interior[s] + k - 1
            }
        })
    }

    /// The samples along curve `c`, in curve direction. Open curves and loops
    /// through an intersection list both ends (a loop lists its intersection
    /// first and last); an isolated closed curve lists its start once.
    pub fn curve_samples(&self, c: usize) -> &[u32] {
        &self.curve_samples[self.curve_sample_offsets[c] as usize..self.curve_sample_offsets[c + 1] as usize]
    }

    /// The segment indices of curve `c`, in curve direction.
    pub fn curve_segments(&self, c: usize) -> Range<usize> {
        self.curve_segment_offsets[c] as usize..self.curve_segment_offsets[c + 1] as usize
    }

    /// Number of curves.
    pub fn n_curves(&self) -> usize {
        self.curve_segment_offsets.len() - 1
    }

    /// Evaluates the samples of the curvenet posed at `points` (`#P` control
    /// points) into `out` (`#Q` samples). Allocation-free.
    ///
    /// Fails with [`Error::CountMismatch`] for a wrong pool or buffer length
    /// and [`Error::NonFinite`] naming a non-finite control point.
    pub fn samples_into(&self, points: &[[f64; 3]], out: &mut [[f64; 3]]) -> Result<()> {
        if points.len() != self.n_points {
            return Err(Error::CountMismatch {
                what: "posed curvenet control points",
                expected: self.n_points,
                got: points.len(),
            });
        }
        if out.len() != self.n_samples {
            return Err(Error::CountMismatch {
                what: "curvenet sample buffer",
                expected: self.n_samples,
                got: out.len(),
            });
        }
        check_finite(points, "posed curvenet control point")?;
        for (k, &p) in self.knot_points.iter().enumerate() {
            out[k] = points[p as usize];
        }
        let mut len = [0.0; STACK_PIECES];
        for (s, spline) in self.splines.iter().enumerate() {
            let ctrl = spline.map(|v| v3(points[v as usize]));
            let first = self.spline_interior[s] as usize;
            interior_parameters(&ctrl, self.spline_segments[s], self.spline_refinement[s], &mut len, |k, t| {
                out[first + k] = bezier(&ctrl, t).to_array();
            });
        }
        Ok(())
    }

    /// Allocating form of [`Self::samples_into`].
    pub fn samples(&self, points: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
        let mut out = vec![[0.0; 3]; self.n_samples];
        self.samples_into(points, &mut out)?;
        Ok(out)
    }
}

/// The cubic Bézier curve with control points `p` at parameter `t`.
pub(crate) fn bezier(p: &[DVec3; 4], t: f64) -> DVec3 {
    let s = 1.0 - t;
    (s * s * s) * p[0] + (3.0 * s * s * t) * p[1] + (3.0 * s * t * t) * p[2] + (t * t * t) * p[3]
}

fn polyline_length(p: &[DVec3; 4], pieces: u32) -> f64 {
    let mut prev = p[0];
    let mut total = 0.0;
    for u in 1..=pieces {
        let x = bezier(p, u as f64 / pieces as f64);
        total += (x - prev).length();
        prev = x;
    }
    total
}

/// Refinements up to this many pieces keep their piece lengths in a
/// buffer on the stack (one pass of evaluations; 32 KiB, zeroed once per
/// curvenet evaluation, not per spline); longer ones (a spline of more than
/// 512 segments at the default refinement) evaluate their polyline twice.
const STACK_PIECES: usize = 4096;

/// Pieces evaluated together: positions, then lengths, each a loop the
/// compiler vectorises.
const CHUNK: usize = 16;

/// `len[u − 1]` = the length of piece `u = 1..=pieces` of the spline `p`'s
/// `pieces`-piece uniform parametric refinement (`len.len() ≥ pieces`);
/// returns their sum, added in order. Compiled for the widest vector unit
/// the CPU has ([`Simd`]); every variant gives the same bits, and the same
/// bits as `(bezier(u) − bezier(u − 1)).length()` piece by piece.
fn piece_lengths(p: &[DVec3; 4], pieces: usize, len: &mut [f64]) -> f64 {
    match Simd::detect() {
        // SAFETY: `Simd::detect` found the feature on this CPU.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { piece_lengths_avx512(p, pieces, len) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { piece_lengths_avx2(p, pieces, len) },
        Simd::Baseline => piece_lengths_body(p, pieces, len),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn piece_lengths_avx512(p: &[DVec3; 4], pieces: usize, len: &mut [f64]) -> f64 {
    piece_lengths_body(p, pieces, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn piece_lengths_avx2(p: &[DVec3; 4], pieces: usize, len: &mut [f64]) -> f64 {
    piece_lengths_body(p, pieces, len)
}

/// The operations of [`bezier`] and of `DVec3::length`, in their order,
/// component by component over a chunk of parameters (structure of arrays),
/// so that each loop vectorises; the running sum stays sequential.
#[inline(always)]
fn piece_lengths_body(p: &[DVec3; 4], pieces: usize, len: &mut [f64]) -> f64 {
    let nf = pieces as f64;
    let mut total = 0.0;
    let (mut x0, mut y0, mut z0) = (p[0].x, p[0].y, p[0].z);
    let mut u0 = 1;
    while u0 <= pieces {
        let m = CHUNK.min(pieces + 1 - u0);
        let base = u0 as f64;
        let (mut x, mut y, mut z) = ([0.0; CHUNK + 1], [0.0; CHUNK + 1], [0.0; CHUNK + 1]);
        (x[0], y[0], z[0]) = (x0, y0, z0);
        // A whole chunk every time (past `pieces` the values go unused), so
        // the loop has a fixed trip count.
        for i in 0..CHUNK {
            let t = (base + i as f64) / nf;
            let s = 1.0 - t;
            let (w0, w1, w2, w3) = (s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
            x[i + 1] = w0 * p[0].x + w1 * p[1].x + w2 * p[2].x + w3 * p[3].x;
            y[i + 1] = w0 * p[0].y + w1 * p[1].y + w2 * p[2].y + w3 * p[3].y;
            z[i + 1] = w0 * p[0].z + w1 * p[1].z + w2 * p[2].z + w3 * p[3].z;
        }
        let mut d = [0.0; CHUNK];
        for i in 0..CHUNK {
            let (dx, dy, dz) = (x[i + 1] - x[i], y[i + 1] - y[i], z[i + 1] - z[i]);
            d[i] = (dx * dx + dy * dy + dz * dz).sqrt();
        }
        for i in 0..m {
            total += d[i];
        }
        len[u0 - 1..u0 - 1 + m].copy_from_slice(&d[..m]);
        (x0, y0, z0) = (x[m], y[m], z[m]);
        u0 += m;
    }
    total
}

/// Calls `emit(k, t)` for the `n − 1` interior samples `k = 0..n-1` of the
/// spline `p`, with `t` the parameter at arc length `(k + 1)/n` of the
/// spline's `pieces`-piece uniform parametric refinement (linear in `t`
/// within a piece). `len`: scratch for `STACK_PIECES` piece lengths. No
/// allocation.
fn interior_parameters(
    p: &[DVec3; 4],
    n: u32,
    pieces: u32,
    len: &mut [f64; STACK_PIECES],
    mut emit: impl FnMut(usize, f64),
) {
    if n < 2 {
        return;
    }
    let mut k = 1u32;
    let mut cum = 0.0;
    if pieces as usize <= STACK_PIECES {
        let step = piece_lengths(p, pieces as usize, len) / n as f64;
        for (u, &d) in (1..=pieces).zip(&len[..pieces as usize]) {
            walk_piece(u, d, cum, step, n, pieces, &mut k, &mut emit);
            cum += d;
        }
    } else {
        // Two passes over the polyline: its length, then the walk.
        let step = polyline_length(p, pieces) / n as f64;
        let mut prev = p[0];
        for u in 1..=pieces {
            let x = bezier(p, u as f64 / pieces as f64);
            let d = (x - prev).length();
            walk_piece(u, d, cum, step, n, pieces, &mut k, &mut emit);
            cum += d;
            prev = x;
        }
    }
    // Round-off may leave the last targets a hair past the end.
    while k < n {
        emit(k as usize - 1, 1.0);
        k += 1;
    }
}

/// Emits the samples `k..` whose arc length `k × step` falls in piece `u`
/// (length `d`, starting at arc length `cum`), advancing `k`. The same sums
/// whether the piece lengths were kept or are evaluated again.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn walk_piece(
    u: u32,
    d: f64,
    cum: f64,
    step: f64,
    n: u32,
    pieces: u32,
    k: &mut u32,
    emit: &mut impl FnMut(usize, f64),
) {
    while *k < n && cum + d >= *k as f64 * step {
        let frac = if d > 0.0 { ((*k as f64 * step - cum) / d).clamp(0.0, 1.0) } else { 0.0 };
        emit(*k as usize - 1, (u as f64 - 1.0 + frac) / pieces as f64);
        *k += 1;
    }
}

impl Sampling {
    /// Heap bytes held by the plan (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.splines)
            + bytes(&self.spline_segments)
            + bytes(&self.spline_refinement)
            + bytes(&self.spline_interior)
            + bytes(&self.knot_points)
            + bytes(&self.point_knot)
            + bytes(&self.curve_sample_offsets)
            + bytes(&self.curve_samples)
            + bytes(&self.curve_segment_offsets)
            + bytes(&self.segments)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Arc length of the Bézier curve between parameters `a < b`, by
    /// composite 8-point Gauss–Legendre quadrature of |B'(t)| (independent of
    /// the polyline used by the sampler).
    #[allow(clippy::excessive_precision)]
    fn arc_length(p: &[DVec3; 4], a: f64, b: f64) -> f64 {
        const X: [f64; 4] = [0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363];
        const W: [f64; 4] = [0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763];
        let d = |t: f64| {
            let s = 1.0 - t;
            (3.0 * s * s * (p[1] - p[0]) + 6.0 * s * t * (p[2] - p[1]) + 3.0 * t * t * (p[3] - p[2])).length()
        };
        let pieces = 200;
        let h = (b - a) / pieces as f64;
        let mut sum = 0.0;
        for i in 0..pieces {
            let m = a + (i as f64 + 0.5) * h;
            for k in 0..4 {
                sum += W[k] * (d(m - 0.5 * h * X[k]) + d(m + 0.5 * h * X[k]));
            }
        }
        sum * 0.5 * h
    }

    #[test]
    fn interior_samples_are_evenly_spaced_in_arc_length() {
        let cases: [[[f64; 3]; 4]; 4] = [
            // straight, uneven handles (parametric speed varies 10×)
            [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.1, 0.0, 0.0], [3.0, 0.0, 0.0]],
            // strongly bent: a hairpin
            [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            // a near-cusp (handles crossed)
            [[0.0, 0.0, 0.0], [3.0, 2.0, 0.0], [-2.0, 2.0, 0.5], [1.0, 0.0, 0.0]],
            // a teardrop loop (endpoints coincide)
            [[0.0, 0.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0], [0.0, 0.0, 0.0]],
        ];
        for case in cases {
            let p = case.map(DVec3::from_array);
            for n in [2, 3, 7, 40, 100] {
                let pieces = DEFAULT_MIN_REFINEMENT.max(DEFAULT_REFINEMENT_PER_SEGMENT * n);
                let mut ts = vec![0.0];
                let mut len = [0.0; STACK_PIECES];
                interior_parameters(&p, n, pieces, &mut len, |k, t| {
                    assert_eq!(k, ts.len() - 1);
                    ts.push(t);
                });
                ts.push(1.0);
                assert_eq!(ts.len(), n as usize + 1);
                let total = arc_length(&p, 0.0, 1.0);
                for w in ts.windows(2) {
                    let rel = (arc_length(&p, w[0], w[1]) / (total / n as f64) - 1.0).abs();
                    assert!(rel < 1e-3, "case {case:?} n {n}: spacing off by {rel}");
                }
            }
        }
    }

    /// The sampler as it was written first, one piece at a time: the
    /// chunked, vectorised walk must give its parameters bit for bit.
    fn reference_parameters(p: &[DVec3; 4], n: u32, pieces: u32) -> Vec<f64> {
        let step = polyline_length(p, pieces) / n as f64;
        let (mut out, mut k, mut prev, mut cum) = (Vec::new(), 1u32, p[0], 0.0);
        for u in 1..=pieces {
            let x = bezier(p, u as f64 / pieces as f64);
            let d = (x - prev).length();
            while k < n && cum + d >= k as f64 * step {
                let frac = if d > 0.0 { ((k as f64 * step - cum) / d).clamp(0.0, 1.0) } else { 0.0 };
                out.push((u as f64 - 1.0 + frac) / pieces as f64);
                k += 1;
            }
            cum += d;
            prev = x;
        }
        while k < n {
            out.push(1.0);
            k += 1;
        }
        out
    }

    /// Random splines (a fixed seed; every message names the case and the
    /// spline), piece counts around the chunk and stack sizes: the
    /// parameters equal the one-piece-at-a-time reference bit for bit, and
    /// every vector variant of the piece lengths equals the portable one
    /// bit for bit.
    #[test]
    fn chunked_walk_equals_the_reference_bit_for_bit() {
        let mut rng = crate::polygon_laplacian::tests::Rng(0x9E37_79B9_7F4A_7C15);
        let mut next = || 2.0 * rng.next();
        let mut len = [0.0; STACK_PIECES];
        let mut portable = vec![0.0; STACK_PIECES + 2];
        for case in 0..60 {
            let p: [DVec3; 4] = std::array::from_fn(|_| DVec3::new(next(), next(), next()));
            let pieces = [1, 2, 15, 16, 17, 33, 128, 488, 1040, 4096, 4097, 5000][case % 12];
            let n = 1 + (case as u32 * 7) % 130;
            let mut got = Vec::new();
            interior_parameters(&p, n, pieces, &mut len, |k, t| {
                assert_eq!(k, got.len());
                got.push(t);
            });
            let want = reference_parameters(&p, n, pieces);
            let (g, w): (Vec<u64>, Vec<u64>) =
                (got.iter().map(|t| t.to_bits()).collect(), want.iter().map(|t| t.to_bits()).collect());
            assert_eq!(g, w, "case {case}: {pieces} pieces, {n} segments, spline {p:?}");
            if pieces as usize <= STACK_PIECES {
                let m = pieces as usize;
                let total = piece_lengths_body(&p, pieces as usize, &mut portable[..m]);
                #[cfg(target_arch = "x86_64")]
                for (name, feature) in [
                    ("avx2", std::arch::is_x86_feature_detected!("avx2")),
                    ("avx512f", std::arch::is_x86_feature_detected!("avx512f")),
                ] {
                    if !feature {
                        continue;
                    }
                    let mut v = vec![0.0; m];
                    // SAFETY: the CPU reports the feature.
                    let t = unsafe {
                        if name == "avx2" {
                            piece_lengths_avx2(&p, pieces as usize, &mut v)
                        } else {
                            piece_lengths_avx512(&p, pieces as usize, &mut v)
                        }
                    };
                    assert!(
                        t.to_bits() == total.to_bits()
                            && v.iter().zip(&portable[..m]).all(|(a, b)| a.to_bits() == b.to_bits()),
                        "case {case}: {name} lengths differ from the portable ones ({pieces} pieces)"
                    );
                }
            }
        }
    }
}
