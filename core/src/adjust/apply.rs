//! Adjustments as plain data, their validation, and applying one to a pool.

use glam::{DMat3, DQuat, DVec3};

use super::fit::from_mat3;
use super::orientations::OrientationPlan;
use crate::curvenet::{CurvenetLayout, Mat3};
use crate::error::{Error, Result};

/// A rotate of an [`Adjustment`], in the knot's orientation frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rotate {
    /// Euler angles in degrees, applied about X, then Y, then Z (USD's
    /// `xformOp:rotateXYZ`; the matrix is `Rz Ry Rx`).
    EulerXyz([f64; 3]),
    /// A quaternion `[w, x, y, z]` (real part first, as USD writes a `quatf`),
    /// normalised before use; it must not be zero.
    Quaternion([f64; 4]),
}

impl Default for Rotate {
    fn default() -> Self {
        Rotate::EulerXyz([0.0; 3])
    }
}

impl Rotate {
    /// Whether this is exactly the identity (no rotation at all).
    pub fn is_identity(&self) -> bool {
        match *self {
            Rotate::EulerXyz(e) => e == [0.0; 3],
            Rotate::Quaternion([w, x, y, z]) => x == 0.0 && y == 0.0 && z == 0.0 && w != 0.0,
        }
    }

    /// The rotation matrix (row-major).
    pub fn matrix(&self) -> Mat3 {
        super::fit::to_mat3(self.dmat3())
    }

    fn dmat3(&self) -> DMat3 {
        match *self {
            Rotate::EulerXyz([x, y, z]) => DMat3::from_quat(
                DQuat::from_rotation_z(z.to_radians())
                    * DQuat::from_rotation_y(y.to_radians())
                    * DQuat::from_rotation_x(x.to_radians()),
            ),
            Rotate::Quaternion([w, x, y, z]) => DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize()),
        }
    }
}

/// One exposed knot and its animation controls (plain data; see the
/// module docs of [`crate::adjust`] for what each field does).
#[derive(Debug, Clone, PartialEq)]
pub struct Adjustment {
    /// The curvenet, by its index in the binding.
    pub curvenet: usize,
    /// The knot, by its index in the curvenet's control-point pool; it must
    /// be a spline endpoint.
    pub knot: u32,
    /// Translate in the knot's orientation frame.
    pub translate: [f64; 3],
    /// Rotate in the knot's orientation frame, about the knot.
    pub rotate: Rotate,
    /// Scale along the axes of the knot's orientation frame, about the knot.
    pub scale: [f64; 3],
    /// Whether the knot's tangents move, rotate and scale with it.
    pub attach_tangents: bool,
    /// Translate of each tangent in the knot's orientation frame, in the
    /// order of [`OrientationPlan::knot_tangents`] (increasing pool index);
    /// empty for none.
    pub tangent_translates: Vec<[f64; 3]>,
}

impl Adjustment {
    /// The identity adjustment of `knot` of curvenet `curvenet` (tangents attached).
    pub fn new(curvenet: usize, knot: u32) -> Self {
        Self {
            curvenet,
            knot,
            translate: [0.0; 3],
            rotate: Rotate::default(),
            scale: [1.0; 3],
            attach_tangents: true,
            tangent_translates: Vec::new(),
        }
    }

    /// Sets the translate.
    pub fn with_translate(mut self, translate: [f64; 3]) -> Self {
        self.translate = translate;
        self
    }

    /// Sets the rotate.
    pub fn with_rotate(mut self, rotate: Rotate) -> Self {
        self.rotate = rotate;
        self
    }

    /// Sets the scale.
    pub fn with_scale(mut self, scale: [f64; 3]) -> Self {
        self.scale = scale;
        self
    }

    /// Sets whether the tangents are attached to the knot.
    pub fn with_attach_tangents(mut self, attach: bool) -> Self {
        self.attach_tangents = attach;
        self
    }

    /// Sets the tangent translates.
    pub fn with_tangent_translates(mut self, translates: Vec<[f64; 3]>) -> Self {
        self.tangent_translates = translates;
        self
    }

    /// Whether the adjustment changes nothing (it is then skipped entirely).
    pub fn is_identity(&self) -> bool {
        self.translate == [0.0; 3]
            && self.rotate.is_identity()
            && self.scale == [1.0; 3]
            && self.tangent_translates.iter().all(|t| *t == [0.0; 3])
    }
}

/// The tangent control points of `knot` in a curvenet with `splines`: the
/// handle next to it of every spline ending there (control point 1 at a
/// spline's control point 0, 2 at 3), leaving out the knot itself and
/// handles that are knots, in increasing pool order without repeats — the
/// rule of [`OrientationPlan::knot_tangents`], for callers that have only
/// the splines (e.g. a USD reader checking an adjustment's tangent count).
pub fn knot_tangents(splines: &[[u32; 4]], knot: u32) -> Vec<u32> {
    let is_knot = |p: u32| splines.iter().any(|s| s[0] == p || s[3] == p);
    let mut tangents: Vec<u32> = splines
        .iter()
        .flat_map(|s| [(s[0], s[1]), (s[3], s[2])])
        .filter(|&(end, handle)| end == knot && handle != end && !is_knot(handle))
        .map(|(_, handle)| handle)
        .collect();
    tangents.sort_unstable();
    tangents.dedup();
    tangents
}

/// Checks adjustment number `index` against the curvenet it names, given
/// the binding's `layouts` and `plans` (one per curvenet). Returns the knot
/// index (`layout.sampling().knot_sample(knot)`).
///
/// Fails naming the adjustment and its knot: [`Error::IndexOutOfRange`]
/// (curvenet or control point), [`Error::NotAKnot`],
/// [`Error::InvalidAdjustment`] (non-finite value, zero quaternion),
/// [`Error::TangentTranslateCount`].
pub fn check_adjustment(
    index: usize,
    a: &Adjustment,
    layouts: &[CurvenetLayout],
    plans: &[OrientationPlan],
) -> Result<usize> {
    let (Some(layout), Some(plan)) = (layouts.get(a.curvenet), plans.get(a.curvenet)) else {
        return Err(Error::IndexOutOfRange {
            what: "adjustment",
            index,
            target: "curvenet",
            value: u32::try_from(a.curvenet).unwrap_or(u32::MAX),
            len: layouts.len().min(plans.len()),
        });
    };
    let sampling = layout.sampling();
    if a.knot as usize >= sampling.n_points() {
        return Err(Error::IndexOutOfRange {
            what: "adjustment",
            index,
            target: "control point",
            value: a.knot,
            len: sampling.n_points(),
        });
    }
    let Some(knot) = sampling.knot_sample(a.knot as usize) else {
        return Err(Error::NotAKnot { adjustment: index, curvenet: a.curvenet, point: a.knot });
    };
    let invalid = |problem: &'static str| Error::InvalidAdjustment {
        adjustment: index,
        curvenet: a.curvenet,
        point: a.knot,
        problem,
    };
    if !a.translate.iter().all(|x| x.is_finite()) {
        return Err(invalid("its translate is not finite"));
    }
    if !a.scale.iter().all(|x| x.is_finite()) {
        return Err(invalid("its scale is not finite"));
    }
    match a.rotate {
        Rotate::EulerXyz(e) if !e.iter().all(|x| x.is_finite()) => return Err(invalid("its rotate is not finite")),
        Rotate::Quaternion(q) if !q.iter().all(|x| x.is_finite()) => {
            return Err(invalid("its quaternion is not finite"));
        }
        Rotate::Quaternion(q) if q.iter().map(|x| x * x).sum::<f64>() < 1e-24 => {
            return Err(invalid("its quaternion is zero"));
        }
        _ => {}
    }
    if !a.tangent_translates.iter().flatten().all(|x| x.is_finite()) {
        return Err(invalid("a tangent translate is not finite"));
    }
    let tangents = plan.knot_tangents(knot as usize).len();
    if !a.tangent_translates.is_empty() && a.tangent_translates.len() != tangents {
        return Err(Error::TangentTranslateCount {
            adjustment: index,
            curvenet: a.curvenet,
            point: a.knot,
            expected: tangents,
            got: a.tangent_translates.len(),
        });
    }
    Ok(knot as usize)
}

/// Applies adjustment `a` to `pool` (its curvenet's control points, as left
/// by the adjustments before it), with `orientation` its knot's orientation
/// (row-major) and `tangents` its knot's tangent control points
/// ([`OrientationPlan::knot_tangents`]). The adjustment must have passed
/// [`check_adjustment`] (indices are not checked again). Allocation-free;
/// an identity part writes nothing.
pub fn apply_adjustment(a: &Adjustment, orientation: &Mat3, tangents: &[u32], pool: &mut [[f64; 3]]) {
    if a.is_identity() {
        return;
    }
    let o = from_mat3(orientation);
    let v = |p: [f64; 3]| DVec3::from_array(p);
    let knot = v(pool[a.knot as usize]);
    if a.attach_tangents && !(a.rotate.is_identity() && a.scale == [1.0; 3]) {
        let m = o * a.rotate.dmat3() * DMat3::from_diagonal(DVec3::from_array(a.scale)) * o.transpose();
        for &h in tangents {
            pool[h as usize] = (knot + m * (v(pool[h as usize]) - knot)).to_array();
        }
    }
    if a.translate != [0.0; 3] {
        let d = o * v(a.translate);
        pool[a.knot as usize] = (knot + d).to_array();
        if a.attach_tangents {
            for &h in tangents {
                pool[h as usize] = (v(pool[h as usize]) + d).to_array();
            }
        }
    }
    for (&h, t) in tangents.iter().zip(&a.tangent_translates) {
        if *t != [0.0; 3] {
            pool[h as usize] = (v(pool[h as usize]) + o * v(*t)).to_array();
        }
    }
}
