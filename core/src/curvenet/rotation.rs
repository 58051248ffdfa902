//! Small rotation helpers on unit vectors (private to the curvenet module).

use glam::{DMat3, DVec3};

/// Below this, `1 + a·b` counts as zero: `a` and `b` are antiparallel and the
/// smallest rotation between them is not unique.
pub(crate) const ANTIPARALLEL: f64 = 1e-12;

/// Applies the smallest rotation taking unit `from` to unit `to` to every
/// vector `n` of `normals`: `c n + v × n + v (v·n)/(1 + c)` with
/// `v = from × to`, `c = from·to` (the terms shared by all of them). For
/// antiparallel `from`, `to` it uses the half turn about `n`'s component
/// orthogonal to `from` (which keeps a normal unchanged).
#[inline]
pub(crate) fn transport<const N: usize>(normals: &mut [DVec3; N], from: DVec3, to: DVec3) {
    let c = from.dot(to);
    if 1.0 + c > ANTIPARALLEL {
        let v = from.cross(to);
        let k = 1.0 / (1.0 + c);
        for n in normals {
            *n = c * *n + v.cross(*n) + v * (v.dot(*n) * k);
        }
    }
}

/// The smallest rotation taking unit `from` to unit `to`. For antiparallel
/// vectors: the half turn about `normalize(from × e)`, `e` the coordinate
/// axis least aligned with `from`.
pub(crate) fn smallest_rotation(from: DVec3, to: DVec3) -> DMat3 {
    let c = from.dot(to);
    if 1.0 + c > ANTIPARALLEL {
        let v = from.cross(to);
        let k = skew(v);
        DMat3::IDENTITY + k + k * k * (1.0 / (1.0 + c))
    } else {
        let a = from.abs();
        let e = if a.x <= a.y && a.x <= a.z {
            DVec3::X
        } else if a.y <= a.z {
            DVec3::Y
        } else {
            DVec3::Z
        };
        let axis = from.cross(e).normalize();
        2.0 * outer(axis, axis) - DMat3::IDENTITY
    }
}

/// Rotates `n` by `angle` (radians, right-handed) about the unit `axis`.
pub(crate) fn rotate_about(n: DVec3, axis: DVec3, angle: f64) -> DVec3 {
    let (s, c) = angle.sin_cos();
    c * n + s * axis.cross(n) + (1.0 - c) * axis.dot(n) * axis
}

/// The part of `m` orthogonal to unit `t`, normalised (`None` if `m` is
/// (numerically) along `t`).
pub(crate) fn orthonormalize(m: DVec3, t: DVec3) -> Option<DVec3> {
    let p = m - m.dot(t) * t;
    let len = p.length();
    if len > 1e-9 * m.length() && len > 0.0 { Some(p / len) } else { None }
}

/// The outer product `a bᵀ`.
pub(crate) fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(DVec3::new(0.0, v.z, -v.y), DVec3::new(-v.z, 0.0, v.x), DVec3::new(v.y, -v.x, 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smallest_rotation_maps_and_transports() {
        let a = DVec3::new(1.0, 2.0, -0.5).normalize();
        for b in [DVec3::new(-0.3, 0.1, 0.9).normalize(), a, -a, DVec3::new(1.0, 2.0, -0.4999).normalize()] {
            let r = smallest_rotation(a, b);
            assert!((r * a - b).length() < 1e-12, "{b}");
            assert!((r.transpose() * r - DMat3::IDENTITY).to_cols_array().iter().all(|x| x.abs() < 1e-12));
            assert!((r.determinant() - 1.0).abs() < 1e-12);
            // The axis a × b is fixed, so the rotation is the smallest one.
            let axis = a.cross(b);
            assert!((r * axis - axis).length() < 1e-12);
            if 1.0 + a.dot(b) > 1e-9 {
                let n = [a.any_orthonormal_vector(), a.cross(a.any_orthonormal_vector()), DVec3::new(0.3, -1.0, 2.0)];
                let mut moved = n;
                transport(&mut moved, a, b);
                for (m, n) in moved.iter().zip(n) {
                    assert!((*m - r * n).length() < 1e-12);
                }
            }
        }
        let n = DVec3::X;
        assert!((rotate_about(n, DVec3::Z, std::f64::consts::FRAC_PI_2) - DVec3::Y).length() < 1e-15);
        assert_eq!(
            skew(DVec3::new(1.0, 2.0, 3.0)) * DVec3::new(-1.0, 0.5, 2.0),
            DVec3::new(1.0, 2.0, 3.0).cross(DVec3::new(-1.0, 0.5, 2.0))
        );
    }
}
