//! Rotation fitting and blending for knot orientations.
//!
//! - [`fit_rotation`]: the weighted Kabsch/Procrustes fit, by Horn's
//!   quaternion method (B. K. P. Horn, "Closed-form solution of absolute
//!   orientation using unit quaternions", JOSA A 4(4), 1987): the rotation
//!   maximising `Σ w_i b_i·(R a_i)` is the unit quaternion of the largest
//!   eigenvalue of a symmetric 4×4 matrix built from `S = Σ w_i a_i b_iᵀ`.
//!   This is the Kabsch optimum with its reflection correction built in (the
//!   answer is always a proper rotation). The 4×4 eigenproblem is solved by
//!   cyclic Jacobi rotations on the stack: no allocation, and faer's general
//!   dense eigensolver would need a scratch buffer for a fixed 4×4.
//! - [`blend_rotations`]: spherical linear interpolation of two rotations in
//!   one quaternion hemisphere (for two rotations this is the log-space mean).

use glam::{DMat3, DQuat, DVec3};

use crate::curvenet::Mat3;
use crate::error::{Error, Result};

/// The fit is undetermined (a rotation about a common axis is free) when the
/// two largest eigenvalues of Horn's matrix are closer than this fraction of
/// the total weight: all directions are (anti)parallel.
pub const DEGENERATE_FIT: f64 = 1e-9;

/// The rotation `R` maximising `Σ w_i to_i·(R from_i)`: the weighted
/// Kabsch/Procrustes fit of the vectors `from` onto `to` (as given; pass unit
/// vectors to fit directions only). Row-major.
///
/// Fails with [`Error::CountMismatch`] for slices of different lengths and
/// [`Error::InvalidParameter`] for a negative or non-finite weight or a
/// non-finite vector; returns `Ok(None)` when the rotation is not determined
/// (fewer than two non-parallel pairs with positive weight).
pub fn fit_rotation(from: &[[f64; 3]], to: &[[f64; 3]], weights: &[f64]) -> Result<Option<Mat3>> {
    if to.len() != from.len() {
        return Err(Error::CountMismatch { what: "fit target vectors", expected: from.len(), got: to.len() });
    }
    if weights.len() != from.len() {
        return Err(Error::CountMismatch { what: "fit weights", expected: from.len(), got: weights.len() });
    }
    if let Some(&w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(Error::InvalidParameter { what: "a fit weight (finite, not negative)", value: w });
    }
    if let Some(x) = from.iter().chain(to).flatten().find(|x| !x.is_finite()) {
        return Err(Error::InvalidParameter { what: "a fit vector coordinate (finite)", value: *x });
    }
    let pairs = from.iter().zip(to).zip(weights).map(|((a, b), &w)| (DVec3::from_array(*a), DVec3::from_array(*b), w));
    Ok(fit_quat(pairs).map(|q| to_mat3(DMat3::from_quat(q))))
}

/// [`fit_rotation`] over `(from, to, weight)` triples, as a unit quaternion
/// (`None` when undetermined). Allocation-free.
pub(crate) fn fit_quat(pairs: impl Iterator<Item = (DVec3, DVec3, f64)>) -> Option<DQuat> {
    let mut s = [[0.0f64; 3]; 3];
    let mut total = 0.0;
    for (a, b, w) in pairs {
        total += w * a.length() * b.length();
        let (a, b) = (a.to_array(), b.to_array());
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += w * a[i] * b[j];
            }
        }
    }
    if !(total > 0.0) {
        return None;
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = symmetric_eigen4(n);
    let mut order = [0usize, 1, 2, 3];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    if values[order[0]] - values[order[1]] <= DEGENERATE_FIT * total {
        return None;
    }
    let k = order[0];
    let q = DQuat::from_xyzw(vectors[1][k], vectors[2][k], vectors[3][k], vectors[0][k]);
    let len = q.length();
    (len > 0.0 && len.is_finite()).then(|| q / len)
}

/// Eigenvalues and eigenvectors (the columns of the second result) of a
/// symmetric 4×4 matrix, by cyclic Jacobi rotations.
fn symmetric_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..64 {
        let off: f64 = (0..4).flat_map(|p| (p + 1..4).map(move |q| (p, q))).map(|(p, q)| a[p][q] * a[p][q]).sum();
        if off <= f64::EPSILON * f64::EPSILON * scale * 1e-4 || off == 0.0 {
            break;
        }
        for p in 0..4 {
            for q in p + 1..4 {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                // A ← Jᵀ A J with J the rotation in the (p, q) plane.
                for k in 0..4 {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}

/// Rotates `a` towards `b` (both rotations, row-major) by the fraction `t`
/// of the way: spherical linear interpolation of their unit quaternions in
/// one hemisphere. Continuous in `a`, `b` and `t` (except between rotations
/// half a turn apart, where no blend is), and symmetric:
/// `blend_rotations(a, b, t) == blend_rotations(b, a, 1 − t)`.
pub fn blend_rotations(a: &Mat3, b: &Mat3, t: f64) -> Mat3 {
    to_mat3(blend(from_mat3(a), from_mat3(b), t))
}

pub(crate) fn blend(a: DMat3, b: DMat3, t: f64) -> DMat3 {
    let qa = DQuat::from_mat3(&a).normalize();
    let qb = DQuat::from_mat3(&b).normalize();
    DMat3::from_quat(qa.slerp(qb, t).normalize())
}

/// A row-major [`Mat3`] as a glam matrix (which is column-major).
pub(crate) fn from_mat3(m: &Mat3) -> DMat3 {
    DMat3::from_cols_array_2d(m).transpose()
}

/// A glam matrix as a row-major [`Mat3`].
pub(crate) fn to_mat3(m: DMat3) -> Mat3 {
    m.transpose().to_cols_array_2d()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalises() {
        let a = [[4.0, 1.0, -2.0, 0.5], [1.0, 3.0, 0.0, 1.5], [-2.0, 0.0, -1.0, 2.0], [0.5, 1.5, 2.0, 0.0]];
        let (w, v) = symmetric_eigen4(a);
        for k in 0..4 {
            for i in 0..4 {
                let av: f64 = (0..4).map(|j| a[i][j] * v[j][k]).sum();
                assert!((av - w[k] * v[i][k]).abs() < 1e-13, "A v = λ v fails for eigenpair {k}");
            }
        }
    }

    #[test]
    fn horn_recovers_a_rotation_and_refuses_collinear_vectors() {
        let r = DMat3::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.3);
        let from = [DVec3::X, DVec3::new(0.3, 1.0, 0.2), DVec3::new(-1.0, 0.1, 0.7)];
        let q = fit_quat(from.iter().map(|&a| (a, r * a, 1.0))).unwrap();
        assert!((DMat3::from_quat(q) - r).to_cols_array().iter().all(|x| x.abs() < 1e-14));
        // Two antiparallel directions leave the rotation about them free.
        assert!(fit_quat([(DVec3::X, DVec3::Y, 1.0), (-DVec3::X, -DVec3::Y, 2.0)].into_iter()).is_none());
        assert!(fit_quat(std::iter::empty()).is_none());
    }

    #[test]
    fn blending_is_symmetric_and_halfway_is_the_midpoint() {
        let a = from_mat3(&to_mat3(DMat3::from_axis_angle(DVec3::Z, 0.2)));
        let b = DMat3::from_axis_angle(DVec3::Z, 1.4);
        let mid = blend(a, b, 0.5);
        assert!((mid - DMat3::from_axis_angle(DVec3::Z, 0.8)).to_cols_array().iter().all(|x| x.abs() < 1e-14));
        let (x, y) = (blend(a, b, 0.3), blend(b, a, 0.7));
        assert!((x - y).to_cols_array().iter().all(|v| v.abs() < 1e-14));
    }
}
