//! 4×4 transforms in USD's convention (row-major, row vectors; see the
//! skinning module docs) and their checks: a leaf the skinning methods and
//! the cage's centres of rotation import.

use crate::error::{Result, SkinningError};

/// A 4×4 transform, row-major, acting on row vectors (see the module docs).
pub type Mat4 = [f64; 16];

/// The 4×4 identity.
pub const IDENTITY: Mat4 = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

pub(crate) fn check_finite(m: &Mat4, what: &'static str, index: usize) -> Result<()> {
    if m.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(SkinningError::NonFiniteTransform { what, index }.into()) }
}

/// Refuses a non-finite matrix or one whose last column is not (0, 0, 0, 1).
pub fn check_affine(m: &Mat4, what: &'static str, index: usize) -> Result<()> {
    check_finite(m, what, index)?;
    let column = [m[3], m[7], m[11], m[15]];
    let tol = 1e-9 * m.iter().fold(1.0f64, |a, x| a.max(x.abs()));
    if column[0].abs() > tol || column[1].abs() > tol || column[2].abs() > tol || (column[3] - 1.0).abs() > tol {
        return Err(SkinningError::NotAffine { what, index, column }.into());
    }
    Ok(())
}

/// `a · b` (row vectors: `a` applies first).
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [0.0; 16];
    for r in 0..4 {
        for c in 0..4 {
            m[4 * r + c] = (0..4).map(|k| a[4 * r + k] * b[4 * k + c]).sum();
        }
    }
    m
}

/// `[p 1] · m`, dropping the last column (an affine transform of a point,
/// UsdSkel's `TransformAffine`).
#[inline]
pub fn transform_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    [
        p[0] * m[0] + p[1] * m[4] + p[2] * m[8] + m[12],
        p[0] * m[1] + p[1] * m[5] + p[2] * m[9] + m[13],
        p[0] * m[2] + p[1] * m[6] + p[2] * m[10] + m[14],
    ]
}

/// `[v 0] · m`: a direction, without the translation.
#[inline]
pub fn transform_vector(m: &Mat4, v: [f64; 3]) -> [f64; 3] {
    [
        v[0] * m[0] + v[1] * m[4] + v[2] * m[8],
        v[0] * m[1] + v[1] * m[5] + v[2] * m[9],
        v[0] * m[2] + v[1] * m[6] + v[2] * m[10],
    ]
}

/// The inverse of an affine transform, `None` when its linear part is
/// singular (determinant below 1e-12 of its scale cubed).
pub fn inverse(m: &Mat4) -> Option<Mat4> {
    let a = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let scale = a.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if !(det.abs() > 1e-12 * scale.powi(3)) {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            // inverse = adjugate / det; adj[r][c] = cofactor[c][r]
            let (r1, r2) = ((c + 1) % 3, (c + 2) % 3);
            let (c1, c2) = ((r + 1) % 3, (r + 2) % 3);
            inv[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
        }
    }
    let t = [m[12], m[13], m[14]];
    let mut out = IDENTITY;
    for r in 0..3 {
        for c in 0..3 {
            out[4 * r + c] = inv[r][c];
        }
    }
    for c in 0..3 {
        out[12 + c] = -(t[0] * inv[0][c] + t[1] * inv[1][c] + t[2] * inv[2][c]);
    }
    Some(out)
}
