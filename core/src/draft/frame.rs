//! The drafting frame (axis, across direction, centroid, extents) and the
//! nominal plane positions planned in it, with the jitter applied.

use glam::{DQuat, DVec3};

use super::error::DraftError;
use super::options::DraftOptions;
use super::rng::SplitMix64;
use super::section::Plane;
use super::surface::{self, TriSurface};

/// The drafting frame: unit axis and across directions, centroid, extents.
pub(super) struct Frame {
    pub(super) centroid: DVec3,
    pub(super) axis: DVec3,
    pub(super) across: DVec3,
    pub(super) axis_range: [f64; 2],
    pub(super) across_range: [f64; 2],
}

impl Frame {
    pub(super) fn new(surface: &TriSurface, o: &DraftOptions) -> Result<Self, DraftError> {
        let (centroid, cov) = surface.weighted_covariance();
        let axis = match o.axis {
            Some(a) => DVec3::from_array(a).normalize(),
            None => surface::symmetric_eigenvectors(cov)[0],
        };
        let across = match o.across {
            Some(b) => DVec3::from_array(b).reject_from(axis),
            None => {
                // The principal axis of the distribution projected across the
                // axis: the top eigenvector of P C P, P = I - a aᵀ.
                let p = |r: usize, c: usize| f64::from(r == c) - axis[r] * axis[c];
                let mut pc = [[0.0; 3]; 3];
                for r in 0..3 {
                    for c in 0..3 {
                        pc[r][c] = (0..3).map(|m| p(r, m) * cov[m][c]).sum();
                    }
                }
                let mut pcp = [[0.0; 3]; 3];
                for r in 0..3 {
                    for c in 0..3 {
                        pcp[r][c] = (0..3).map(|m| pc[r][m] * p(m, c)).sum();
                    }
                }
                surface::symmetric_eigenvectors(pcp)[0].reject_from(axis)
            }
        };
        if !(across.length() > 1e-6) {
            return Err(DraftError::Option { what: "across", problem: "must not be parallel to the axis".into() });
        }
        let across = across.normalize();
        Ok(Self {
            centroid,
            axis,
            across,
            axis_range: extent_along(surface, centroid, axis),
            across_range: extent_along(surface, centroid, across),
        })
    }

    /// The point at position `s` along the axis line through the centroid.
    pub(super) fn at(&self, s: f64) -> DVec3 {
        self.centroid + self.axis * s
    }
}

/// Nominal plane positions (with the jitter applied).
pub(super) struct Plan {
    /// Per ring: unit normal and position along the axis (relative to the centroid).
    pub(super) rings: Vec<(DVec3, f64)>,
    pub(super) ring_spacing: f64,
    pub(super) axis_range: [f64; 2],
    /// Per line: position across (relative to the centroid).
    pub(super) lines: Vec<f64>,
    pub(super) line_spacing: f64,
    pub(super) across: DVec3,
    pub(super) centroid: DVec3,
}

impl Plan {
    pub(super) fn new(surface: &TriSurface, frame: &Frame, o: &DraftOptions, mut rng: Option<&mut SplitMix64>) -> Self {
        let [a0, a1] = frame.axis_range;
        let extent = a1 - a0;
        let [lo, hi] = o.span;
        let ring_spacing = if o.rings > 1 { (hi - lo) * extent / (o.rings - 1) as f64 } else { (hi - lo) * extent };
        let mut rings = Vec::with_capacity(o.rings);
        for k in 0..o.rings {
            let f = if o.rings > 1 { lo + (hi - lo) * k as f64 / (o.rings - 1) as f64 } else { 0.5 * (lo + hi) };
            let mut s = a0 + f * extent;
            let mut normal = frame.axis;
            if let (Some(j), Some(r)) = (o.jitter, rng.as_deref_mut()) {
                s += r.signed() * j.plane_shift * ring_spacing;
                let turn = r.range(0.0, std::f64::consts::TAU);
                let tilt_axis = DQuat::from_axis_angle(frame.axis, turn) * frame.across;
                normal = DQuat::from_axis_angle(tilt_axis, r.signed() * j.ring_tilt_degrees.to_radians()) * frame.axis;
            }
            rings.push((normal, s));
        }
        let mut across = frame.across;
        if let (Some(j), Some(r)) = (o.jitter, rng.as_deref_mut()) {
            across = (DQuat::from_axis_angle(frame.axis, r.signed() * j.line_turn_degrees.to_radians()) * across)
                .normalize();
        }
        let [b0, b1] =
            if across == frame.across { frame.across_range } else { extent_along(surface, frame.centroid, across) };
        let line_spacing = (b1 - b0) / (o.lines + 1) as f64;
        let mut lines = Vec::with_capacity(o.lines);
        for j in 0..o.lines {
            let mut b = b0 + (j + 1) as f64 * line_spacing;
            if let (Some(jit), Some(r)) = (o.jitter, rng.as_deref_mut()) {
                b += r.signed() * jit.plane_shift * line_spacing;
            }
            lines.push(b);
        }
        Self {
            rings,
            ring_spacing,
            axis_range: frame.axis_range,
            lines,
            line_spacing,
            across,
            centroid: frame.centroid,
        }
    }

    pub(super) fn line_planes(&self, shift: f64, surface: &TriSurface) -> Vec<Plane> {
        self.lines
            .iter()
            .map(|&b| {
                let point = self.centroid + self.across * (b + shift * self.line_spacing);
                Plane::through(self.across, point).clear_of_vertices(surface)
            })
            .collect()
    }
}

/// The smallest and largest `(p - origin) · d` over the vertices.
fn extent_along(surface: &TriSurface, origin: DVec3, d: DVec3) -> [f64; 2] {
    surface.points.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |r, p| {
        let x = (*p - origin).dot(d);
        [r[0].min(x), r[1].max(x)]
    })
}
