//! Curvenets (§3 of the paper): a pool of control points plus cubic Bézier
//! splines, analysed once in the neutral pose and then sampled, framed and
//! compared pose after pose.
//!
//! # Pipeline
//!
//! ```text
//! Curvenet::new(splines, neutral points)             validated input
//!   └─ CurvenetLayout::new(&curvenet, &mesh, mesh points, &options)
//!        ├─ Topology        intersections, anchors, curves            (topology.rs)
//!        ├─ Sampling        fixed sample / segment plan               (sampling.rs)
//!        ├─ IntersectionFan ccw order of curves at each intersection  (intersections.rs)
//!        └─ ConstraintTable sample slots for the binding (§4.3)       (constraints.rs)
//! per frame, allocation-free:
//!   layout.sampling().samples_into(pose, &mut samples)               (sampling.rs)
//!   scaled_frames_into(&layout, &samples, &mut frames)               (frames.rs)
//!   deformation_gradients_into(&layout, &rest, &frames, &mut f)      (gradient.rs)
//!   constraint_gradients_into(layout.constraints(), &f, &mut f_c)    (constraints.rs)
//! ```
//!
//! # Conventions
//!
//! - Points are `[f64; 3]`; a pose of the curvenet is a slice with one point
//!   per control point of the pool (`#P`).
//! - A 3×3 matrix ([`Mat3`]) is row-major, `m[row][col]`, acting on column
//!   vectors: `y[r] = Σ_c m[r][c] x[c]`. Flattening a `Mat3` row by row gives
//!   the paper's 9-vector rows of `f_c`.
//! - **Sides.** Looking down the surface normal (from outside the surface)
//!   and walking along a curve in its direction (from its start to its end),
//!   the **plus (+) side is the left** and the minus (−) side the right.
//!   Seen from an intersection, each emanating curve is walked outwards: at a
//!   curve's start this is the curve's own direction, at its end it is
//!   reversed, so there the intersection's left is the curve's right. Frames
//!   and gradients are always reported per curve side, in curve direction.
//! - In every frame `B = [t b n]`, `t` is the segment tangent (curve
//!   direction), `n` the side's normal (close to the surface normal) and
//!   `b = n × t`, which points to the plus (left) side for both sides' frames.

mod constraints;
mod frames;
mod gradient;
mod intersections;
pub(crate) mod lanes;
mod layout;
mod rotation;
mod sampling;
mod topology;

pub use constraints::{ConstraintSlot, ConstraintTable, constraint_gradients, constraint_gradients_into};
pub use frames::{FramePlan, ScaledFrame, frames, frames_into};
pub use gradient::{deformation_gradients, deformation_gradients_into};
pub use intersections::{COINCIDENT_ANGLE, CORNER_NORMAL_COS, Emanation, IntersectionFan, T_JUNCTION_SIN};
pub use layout::{COLLAPSE_TOLERANCE, CurvenetLayout, scaled_frames, scaled_frames_into};
pub use sampling::{
    DEFAULT_DENSITY, DEFAULT_MAX_SEGMENTS_PER_SPLINE, DEFAULT_MIN_REFINEMENT, DEFAULT_REFINEMENT_PER_SEGMENT, Sampling,
    SamplingOptions, Segment,
};
pub use topology::{Curve, CurveEnd, CurveSpline, EndpointKind, Topology};

use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::check_finite;

/// A row-major 3×3 matrix, `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

/// The 3×3 identity.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// A side of a curve segment, in curve direction (see the module docs).
/// Per-segment pairs such as `[ScaledFrame; 2]` are indexed by `side as usize`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Side {
    /// The left side, walking along the curve and looking down the surface normal.
    Plus = 0,
    /// The right side.
    Minus = 1,
}

impl Side {
    /// Both sides, in index order.
    pub const BOTH: [Side; 2] = [Side::Plus, Side::Minus];

    /// The other side.
    pub fn opposite(self) -> Side {
        match self {
            Side::Plus => Side::Minus,
            Side::Minus => Side::Plus,
        }
    }
}

/// Control points coinciding within this fraction of the curvenet's
/// bounding-box diagonal count as one point for [`Error::ZeroLengthSpline`].
pub const ZERO_LENGTH_TOLERANCE: f64 = 1e-12;

/// A validated curvenet: a pool of `#P` control points in the neutral pose and
/// `#S` cubic Bézier splines, each `[endpoint, handle, handle, endpoint]` as
/// indices into the pool.
///
/// Endpoints may be shared by any number of splines; handles may be any
/// points. No topological restriction applies (open ends, any valence,
/// several components, closed loops). Pool points used by no spline are
/// allowed and ignored.
#[derive(Debug, Clone, PartialEq)]
pub struct Curvenet {
    splines: Vec<[u32; 4]>,
    points: Vec<[f64; 3]>,
}

impl Curvenet {
    /// Validates and stores the curvenet.
    ///
    /// - `splines`: `#S` control-point index quadruples (at least one).
    /// - `points`: `#P` neutral-pose control points, all finite.
    ///
    /// Fails naming the element: [`Error::Empty`], [`Error::IndexOutOfRange`]
    /// (`index` is the spline), [`Error::NonFinite`] (`index` is the control
    /// point), [`Error::ZeroLengthSpline`] when a spline's four control points
    /// coincide within [`ZERO_LENGTH_TOLERANCE`] × the bounding-box diagonal.
    pub fn new(splines: &[[u32; 4]], points: &[[f64; 3]]) -> Result<Self> {
        if splines.is_empty() {
            return Err(Error::Empty { what: "the curvenet (it has no splines)" });
        }
        if points.len() >= u32::MAX as usize {
            return Err(Error::CountMismatch {
                what: "curvenet control points (at most 2^32 - 1)",
                expected: u32::MAX as usize - 1,
                got: points.len(),
            });
        }
        for (spline, s) in splines.iter().enumerate() {
            if let Some(&value) = s.iter().find(|&&v| v as usize >= points.len()) {
                return Err(Error::IndexOutOfRange {
                    what: "spline",
                    index: spline,
                    target: "control point",
                    value,
                    len: points.len(),
                });
            }
        }
        check_finite(points, "curvenet control point")?;
        let tol = ZERO_LENGTH_TOLERANCE * crate::mesh::bounding_box_diagonal(points);
        for (spline, s) in splines.iter().enumerate() {
            let p0 = DVec3::from_array(points[s[0] as usize]);
            if s[1..].iter().all(|&v| (DVec3::from_array(points[v as usize]) - p0).length() <= tol) {
                return Err(Error::ZeroLengthSpline { spline });
            }
        }
        Ok(Self { splines: splines.to_vec(), points: points.to_vec() })
    }

    /// The splines, `#S` quadruples of control-point indices.
    pub fn splines(&self) -> &[[u32; 4]] {
        &self.splines
    }

    /// The neutral-pose control points, `#P`.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// Number of control points `#P` (the length every pose must have).
    pub fn n_points(&self) -> usize {
        self.points.len()
    }
}

pub(crate) fn v3(p: [f64; 3]) -> DVec3 {
    DVec3::from_array(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_element() {
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]];
        assert!(Curvenet::new(&[[0, 1, 2, 3]], &pts).is_ok());
        assert!(matches!(Curvenet::new(&[], &pts), Err(Error::Empty { .. })));
        assert_eq!(
            Curvenet::new(&[[0, 1, 2, 3], [3, 2, 9, 0]], &pts),
            Err(Error::IndexOutOfRange { what: "spline", index: 1, target: "control point", value: 9, len: 4 })
        );
        let mut bad = pts;
        bad[2][1] = f64::INFINITY;
        assert!(matches!(Curvenet::new(&[[0, 1, 2, 3]], &bad), Err(Error::NonFinite { index: 2, .. })));
        // Spline 1 has all four control points at one place (two of them the
        // same index, the others within round-off).
        let pts2 = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1e-15, 0.0], [1.0, 0.0, 1e-14], [3.0, 0.0, 0.0]];
        assert_eq!(Curvenet::new(&[[0, 1, 2, 4], [1, 2, 3, 1]], &pts2), Err(Error::ZeroLengthSpline { spline: 1 }));
    }
}
