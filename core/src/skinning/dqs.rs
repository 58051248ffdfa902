//! Dual-quaternion skinning with UsdSkel's semantics (`dualQuaternion`).
//!
//! Each skinning transform `M` (row vectors, `p' = p·A + t`) is split as
//! UsdSkel does (`GfMatrix4d::Factor`): `A = S · U` with `U` the rotation of
//! the polar decomposition of `A` (of `−A` when `det A < 0`, so that `U` is
//! a proper rotation) and `S = A · Uᵀ` the remaining scale and shear. The
//! rotation and translation become a unit dual quaternion; the scale stays
//! a 3×3 matrix. Per point `q = p · geomBind`:
//!
//! 1. scale: if any joint's `S` differs from the identity by more than 1e-6
//!    in some entry, `q_s = Σ_k w_k (q · S_k)` (linear blending of the scale
//!    parts); otherwise `q_s = q`;
//! 2. rotation and translation: the dual quaternions are summed with the
//!    point's weights, each flipped to the hemisphere of the pivot joint's
//!    (the joint with the largest weight, the first one on a tie), the sum
//!    normalised (a zero sum becomes the identity), and `q_s` transformed.
//!
//! A joint whose transform is singular (`|det A| < 1e-10`) contributes a
//! zero dual quaternion and an identity scale, as in UsdSkel. With all
//! weights 0 or 1 this is exactly linear blend skinning (for transforms
//! without shear); for a single joint it is rigid.

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;

use super::influences::{Influences, PAR_CHUNK, check_skinning_input};
use super::transform::{Mat4, transform_point};
use crate::error::Result;

/// A scale entry further than this from the identity's turns on the
/// linear blending of scales (UsdSkel's `GfIsClose(scale, 1, 1e-6)`).
pub const SCALE_TOLERANCE: f64 = 1e-6;

/// Below this `|det A|` a transform is not decomposed (GfMatrix4d::Factor's `eps`).
pub const SINGULAR_DETERMINANT: f64 = 1e-10;

/// A dual quaternion `real + ε dual`; unit ones are rigid motions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualQuat {
    pub real: DQuat,
    pub dual: DQuat,
}

impl DualQuat {
    pub const ZERO: DualQuat =
        DualQuat { real: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), dual: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0) };
    pub const IDENTITY: DualQuat = DualQuat { real: DQuat::IDENTITY, dual: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0) };

    /// The rigid motion "rotate by `rotation` (unit), then translate by `t`".
    pub fn from_rotation_translation(rotation: DQuat, t: DVec3) -> Self {
        let tq = DQuat::from_xyzw(t.x, t.y, t.z, 0.0);
        DualQuat { real: rotation, dual: (tq * rotation) * 0.5 }
    }

    /// Splits an affine skinning transform into its rigid part (a unit dual
    /// quaternion) and its scale and shear `S` (row-vector 3×3 as a
    /// column-vector matrix: `S q` scales a point), as described in the
    /// module docs. `None` for the rigid part when `|det A| < 1e-10`.
    pub fn from_transform(m: &Mat4) -> (Option<DualQuat>, DMat3) {
        // The column-vector linear map: columns = the rows of the row-vector A.
        let a = DMat3::from_cols_array(&[m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]]);
        let det = a.determinant();
        if !(det.abs() >= SINGULAR_DETERMINANT) {
            return (None, DMat3::IDENTITY);
        }
        let r = polar_rotation(if det < 0.0 { -a } else { a });
        let rotation = DQuat::from_mat3(&r).normalize();
        let t = DVec3::new(m[12], m[13], m[14]);
        // A = R S (column vectors), so S = Rᵀ A.
        (Some(Self::from_rotation_translation(rotation, t)), r.transpose() * a)
    }

    /// The translation of a unit dual quaternion: `2 dual · conj(real)`.
    pub fn translation(&self) -> DVec3 {
        let t = (self.dual * self.real.conjugate()) * 2.0;
        DVec3::new(t.x, t.y, t.z)
    }

    /// Normalises to a unit dual quaternion: both parts divided by the real
    /// part's length, then the dual part made orthogonal to the real part.
    /// A real part shorter than 1e-10 gives the identity.
    pub fn normalized(&self) -> DualQuat {
        let len = self.real.length();
        if !(len >= 1e-10) {
            return DualQuat::IDENTITY;
        }
        let real = self.real * (1.0 / len);
        let dual = self.dual * (1.0 / len);
        DualQuat { real, dual: dual - real * real.dot(dual) }
    }

    /// Rotates then translates `p` (a unit dual quaternion).
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.real * p + self.translation()
    }
}

/// The rotation of the polar decomposition `a = R·H` (`det a > 0`), by the
/// scaled Newton iteration `X ← ½(γX + X⁻ᵀ/γ)`, which converges
/// quadratically for any non-singular matrix.
fn polar_rotation(a: DMat3) -> DMat3 {
    let mut x = a;
    for _ in 0..100 {
        let inv_t = x.inverse().transpose();
        // Frobenius-norm scaling (Higham) speeds up the first steps.
        let g = ((inv_t.x_axis.length_squared() + inv_t.y_axis.length_squared() + inv_t.z_axis.length_squared())
            / (x.x_axis.length_squared() + x.y_axis.length_squared() + x.z_axis.length_squared()))
        .sqrt()
        .sqrt();
        let next = (x * g + inv_t * (1.0 / g)) * 0.5;
        let change = (next - x).to_cols_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        x = next;
        if change <= 1e-15 {
            break;
        }
    }
    // One unscaled step cleans the last rounding of the scaling.
    (x + x.inverse().transpose()) * 0.5
}

/// Dual-quaternion skinning with UsdSkel's semantics (see the module docs);
/// arguments as [`super::skin_points_lbs`]. Parallel over points.
pub fn skin_points_dqs(
    points: &[[f64; 3]],
    influences: &Influences,
    geom_bind: &Mat4,
    transforms: &[Mat4],
    out: &mut [[f64; 3]],
) -> Result<()> {
    check_skinning_input(points, influences, transforms, out)?;
    let parts: Vec<(DualQuat, DMat3)> = transforms
        .iter()
        .map(|m| {
            let (dq, s) = DualQuat::from_transform(m);
            (dq.unwrap_or(DualQuat::ZERO), s)
        })
        .collect();
    let has_scale =
        parts.iter().any(|(_, s)| (*s - DMat3::IDENTITY).to_cols_array().iter().any(|d| d.abs() > SCALE_TOLERANCE));
    out.par_chunks_mut(PAR_CHUNK).enumerate().for_each(|(chunk, block)| {
        for (i, o) in block.iter_mut().enumerate() {
            let p = chunk * PAR_CHUNK + i;
            let q = DVec3::from_array(transform_point(geom_bind, points[p]));
            // The pivot: the largest weight, the first on a tie.
            let mut pivot: Option<(u32, f64)> = None;
            for (j, w) in influences.point(p) {
                if pivot.is_none_or(|(_, m)| m < w) {
                    pivot = Some((j, w));
                }
            }
            let pivot_q = pivot.map_or(DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), |(j, _)| parts[j as usize].0.real);
            let mut sum = DualQuat::ZERO;
            let mut scaled = DVec3::ZERO;
            for (j, w) in influences.point(p) {
                if w == 0.0 {
                    continue;
                }
                let (dq, s) = &parts[j as usize];
                if has_scale {
                    scaled += (*s * q) * w;
                }
                let w = if dq.real.dot(pivot_q) < 0.0 { -w } else { w };
                sum.real += dq.real * w;
                sum.dual += dq.dual * w;
            }
            if !has_scale {
                scaled = q;
            }
            *o = sum.normalized().transform_point(scaled).to_array();
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trs(axis: DVec3, deg: f64, scale: DVec3, t: DVec3) -> Mat4 {
        // Column-vector A = R · diag(scale); row-vector matrix = Aᵀ.
        let a = DMat3::from_axis_angle(axis.normalize(), deg.to_radians()) * DMat3::from_diagonal(scale);
        let c = a.to_cols_array();
        [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, t.x, t.y, t.z, 1.0]
    }

    #[test]
    fn decomposition_recovers_rotation_translation_and_scale() {
        let m = trs(DVec3::new(1.0, 2.0, 3.0), 70.0, DVec3::new(1.0, 1.0, 1.0), DVec3::new(0.3, -2.0, 1.0));
        let (dq, s) = DualQuat::from_transform(&m);
        let dq = dq.unwrap();
        assert!((s - DMat3::IDENTITY).to_cols_array().iter().all(|d| d.abs() < 1e-14));
        let p = DVec3::new(0.4, 0.1, -0.7);
        let want = DVec3::from_array(transform_point(&m, p.to_array()));
        assert!((dq.transform_point(p) - want).length() < 1e-14);
        // A mirror: the rotation stays proper, the scale takes the sign.
        let mirror = trs(DVec3::Z, 30.0, DVec3::new(-1.0, 2.0, 1.0), DVec3::ZERO);
        let (dq, s) = DualQuat::from_transform(&mirror);
        let r = DMat3::from_quat(dq.unwrap().real);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        let a = DMat3::from_cols_array(&[
            mirror[0], mirror[1], mirror[2], mirror[4], mirror[5], mirror[6], mirror[8], mirror[9], mirror[10],
        ]);
        assert!((r * s - a).to_cols_array().iter().all(|d| d.abs() < 1e-14));
        let mut singular = super::super::IDENTITY;
        singular[0] = 0.0;
        assert!(DualQuat::from_transform(&singular).0.is_none());
    }
}
