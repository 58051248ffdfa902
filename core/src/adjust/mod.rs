//! The Curvenet Adjuster (Nguyen et al., *Shaping the Elements*, Elemental
//! 2023, §3): surface-relative orientations for every curvenet knot, and
//! animators' adjustments of knots expressed in them.
//!
//! It runs inside every frame ([`crate::Binding::deform`] with
//! [`crate::Frame::adjustments`]) after everything that poses the
//! curvenet — its posed pool, else knot tracking to the frame's rest pose,
//! else the neutral pool — and before the curvenet is sampled for the solve:
//!
//! ```text
//! pool posed so far ──► knot orientations O_k (OrientationPlan)      orientations.rs
//!                  └──► adjusted pool (each adjustment in its knot's O) apply.rs
//!                        └──► samples, scaled frames, Poisson solve   (as without adjustments)
//! ```
//!
//! # Knot orientations
//!
//! A knot's orientation `O` is a rotation that maps the neutral curvenet to
//! the curvenet as posed so far, near that knot. It is the identity in the
//! neutral pose, so an adjustment's axes are the stage's axes on the neutral
//! character and turn with the surface as the character deforms ("up"
//! follows the surface); a rigid rotation `R` of the whole character turns
//! every `O` into `R O`.
//!
//! - **Intersections** (knots shared by three or more curves, paper §3):
//!   the weighted Kabsch/Procrustes fit ([`fit_rotation`]) of the incident
//!   tangents of the neutral curvenet onto those of the posed one. A curve's
//!   tangent at the intersection is its Bézier end tangent: from the knot to
//!   the spline's first control point that does not coincide with it
//!   (normally the handle). Directions are fitted as unit vectors, each
//!   **weighted by its neutral tangent length**: a long handle shapes its
//!   curve more than a short one, the weights are fixed per binding, and a
//!   posed stretch of one handle does not tilt the fit (a posed tangent of
//!   zero length drops out). All tangents parallel in a pose is
//!   [`crate::Error::UndeterminedKnotOrientation`].
//! - **Knots on curves reaching an intersection** get its orientation
//!   parallel-transported along the sampled curve. With `D` the
//!   intersection's orientation, `Ω` the transport (product of the smallest
//!   rotations between consecutive segment directions) from the curve's
//!   first segment to the knot's tangent in the pose, and `Ω̌` the same in
//!   the neutral pose, the knot gets `Ω G Ω̌ᵀ` where `G = R(D ť → t) D`
//!   first turns `D` so that it maps the first segment's neutral direction
//!   `ť` exactly onto the posed `t`. Then the knot's orientation maps its
//!   neutral tangent exactly onto its posed tangent, and the result is
//!   equivariant under rigid motions. A knot's tangent is the normalised sum
//!   of the directions of the two segments meeting there.
//! - **Between two intersections** (or both ends of a loop through one),
//!   the two transported rotations are **blended by inverse distance along
//!   the curve**, measured as the neutral arc length (fixed per binding, so
//!   a stretch does not slide the blend): weights `1/d_A`, `1/d_B`
//!   normalised, i.e. the end's weight is `d_A / (d_A + d_B)`. Two rotations
//!   are blended by spherical linear interpolation of their quaternions in
//!   one hemisphere ([`blend_rotations`]) — the log-space mean for two
//!   rotations: continuous, symmetric in its arguments, and exactly the
//!   halfway rotation at equal distances.
//! - **Known behaviour under shear.** Where the deformation is far from
//!   rigid, an intersection's fit can be turned about a curve's tangent
//!   relative to the curve itself (e.g. a finger ring's dorsal intersection
//!   follows the finger line's tangent, which a curl turns more than the
//!   ring). Parallel transport keeps that turn about the tangent, so around
//!   a ring the knots opposite the intersection turn less than the surface
//!   under them. On the skinned hand (tests/adjust.rs) neighbouring knots
//!   differ by at most 23° more than the surface's local rotations; an
//!   extreme analytic curl (100° over 0.4 of the hand's length) reached 75°.
//!   Correcting the intersection's rotation directly to each knot's tangent
//!   halves that but has a singularity where a curve turns half a turn
//!   relative to its intersection, so the transport stays as the talk
//!   describes it.
//! - **Knots on curves that reach no intersection** (isolated closed
//!   curves, curves between two anchors, the "floating" lip and eye curves
//!   of the talk) use their own curve frame, anchored to the surface: at
//!   each knot, `F = [τ, ν × τ, ν]` from the curve's tangent `τ` there and
//!   the surface normal `ν` (made orthogonal to `τ`) of the triangle the
//!   knot is bound to (its closest point in the projection pose), in the
//!   frame's rest pose; the orientation is `F F̌ᵀ` with `F̌` the same frame
//!   in the neutral pose. Anchoring every knot to the surface under it,
//!   rather than transporting one anchored frame around the curve, leaves no
//!   holonomy seam on closed curves and follows a surface that twists under
//!   the curve. Where the normal is nearly along the tangent
//!   ([`NORMAL_ALONG_TANGENT`]) the knot gets the smallest rotation of its
//!   tangent.
//!
//! # Adjustments
//!
//! An [`Adjustment`] exposes one knot (by its pool index) with a translate,
//! a rotate (XYZ Euler angles in degrees, as USD's `xformOp:rotateXYZ`:
//! about X, then Y, then Z; or a quaternion) and a scale, all in the knot's
//! orientation frame `O`, composed like USD's `translate · rotate · scale`:
//! with the knot at `k`, `M = O R S Oᵀ`,
//!
//! - the knot moves to `k + O t`;
//! - with `attach_tangents` (the default) each of its tangent control points
//!   (see [`OrientationPlan::knot_tangents`]) moves to `k + O t + M (h − k)`:
//!   it rotates and scales about the knot and moves with it; without, the
//!   tangents stay where they are (so rotate and scale change nothing);
//! - then each tangent moves by its own translate, `O t_h`, in the knot's
//!   orientation frame (not turned by the adjustment's own rotate, so a
//!   tangent translate means the same direction whatever the knot's rotate).
//!
//! Adjustments compose on top of the posed curvenet, in list order; all
//! orientations are those of the pool before any adjustment. An identity
//! adjustment (zero translate, identity rotate, unit scale, zero tangent
//! translates) writes nothing, so a frame with zero adjustments is bit for
//! bit the frame without them. [`crate::Binding::deform`] refuses (naming
//! the adjustment and knot) a curvenet index or knot out of range, a
//! control point that is not a knot, non-finite values, a zero quaternion,
//! a tangent-translate list that is neither empty nor one per tangent, and
//! two adjustments of the same knot.

mod apply;
mod fit;
mod frame;
mod orientations;

pub use apply::{Adjustment, Rotate, apply_adjustment, check_adjustment, knot_tangents};
pub use fit::{DEGENERATE_FIT, blend_rotations, fit_rotation};
pub use orientations::{NORMAL_ALONG_TANGENT, OrientationPlan};

pub(crate) use frame::UNCLAIMED;
