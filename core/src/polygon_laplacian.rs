//! The polygon Laplacian of one (cut-)face: Appendix A of the profile-curves
//! paper, after de Goes, Butts, Desbrun 2020.
//!
//! For a polygon with corners `X` (`n × 3`, the loop of halfedges outlining
//! the face, so a crack contributes its two halfedges and repeats corners):
//!
//! - `D` (`n × n`): `(D φ)_i = φ_{i+1} − φ_i`; edge vectors `E = D X`.
//! - `A` (`n × n`): averages consecutive corners, `(A φ)_i = (φ_i + φ_{i+1}) / 2`.
//! - vector area `a_f = ½ Σ x_i × x_{i+1}` (`[a_f] = Eᵀ A X`), area `a = |a_f|`,
//!   normal `n_f = a_f / a`.
//! - gradient `G = −(1/a) [n_f] Eᵀ A` (`3 × n`): column `j` is
//!   `n_f × (x_{j−1} − x_{j+1}) / (2a)`.
//! - projection `Q = D − E G` (`n × n`): zero on functions linear over the polygon.
//! - `L_f = a GᵀG + λ QᵀQ`, λ = 1 by default.
//!
//! Sign convention, fixed for the whole crate: **L is positive
//! semi-definite** (`φᵀ L φ` is the Dirichlet energy ≥ 0). It is symmetric,
//! has constants in its kernel, is invariant to scaling the polygon, equals
//! the cotangent stiffness (off-diagonal `−½ cot` of the opposite angle) on a
//! triangle, and is linearly precise on planar polygons, convex or not.

use glam::DVec3;

/// The paper's (and de Goes et al. 2020's) weight of the `QᵀQ` stabilisation term.
pub const DEFAULT_LAMBDA: f64 = 1.0;

/// Vector area `½ Σ x_i × x_{i+1}` of a closed polygon loop.
pub fn vector_area(corners: &[DVec3]) -> DVec3 {
    let n = corners.len();
    (0..n).map(|i| corners[i].cross(corners[(i + 1) % n])).sum::<DVec3>() * 0.5
}

/// Gradient columns `g_j` of `G_f` (one 3-vector per corner) and the area,
/// or `None` when the polygon has (numerically) zero area.
///
/// `G φ = Σ_j g_j φ_j` is the constant tangent gradient of a function given
/// at the corners; it is exact for functions linear over a planar polygon.
pub fn polygon_gradient(corners: &[DVec3], out: &mut Vec<DVec3>) -> Option<f64> {
    let n = corners.len();
    let va = vector_area(corners);
    let area = va.length();
    let scale = corners.iter().map(|c| (*c - corners[0]).length_squared()).fold(0.0, f64::max);
    // Relative test: the area of a sliver is tiny against the squared extent.
    if n < 3 || !(area > 1e-14 * scale) {
        return None;
    }
    let normal = va / area;
    out.clear();
    out.extend((0..n).map(|j| normal.cross(corners[(j + n - 1) % n] - corners[(j + 1) % n]) / (2.0 * area)));
    Some(area)
}

/// Scratch space for [`polygon_laplacian`], reused across faces so assembly
/// does not allocate per face.
#[derive(Default)]
pub struct PolygonScratch {
    gradient: Vec<DVec3>,
    /// Per corner, `e_{j−1} − e_j` (column j of `EᵀD`).
    a: Vec<DVec3>,
    /// Per corner, `EᵀE g_j`.
    mg: Vec<DVec3>,
}

/// Writes `L_f` (row-major `n × n`, `n = corners.len()`) into `out` and
/// returns the polygon's area, or `None` when the area is (numerically) zero.
pub fn polygon_laplacian(
    corners: &[DVec3],
    lambda: f64,
    scratch: &mut PolygonScratch,
    out: &mut Vec<f64>,
) -> Option<f64> {
    let n = corners.len();
    let area = polygon_gradient(corners, &mut scratch.gradient)?;
    let g = &scratch.gradient;
    // Q = D − E G (D the cyclic difference, row i: −1 at i, +1 at i + 1;
    // E the edges e_i = x_{i+1} − x_i as rows). QᵀQ expands into terms that
    // need no n × n × n product (the direct product cost seconds on cut
    // faces of thousands of corners, from curves sampled far finer than
    // the mesh):
    //   QᵀQ = DᵀD − DᵀE G − Gᵀ EᵀD + Gᵀ (EᵀE) G,
    // with DᵀD the cyclic path Laplacian (2 on the diagonal, −1 between
    // neighbours), (EᵀD) column j = a_j = e_{j−1} − e_j, and M = EᵀE.
    let e = |i: usize| corners[(i + 1) % n] - corners[i];
    let a = &mut scratch.a;
    a.clear();
    a.extend((0..n).map(|j| e((j + n - 1) % n) - e(j)));
    let m = (0..n).fold(glam::DMat3::ZERO, |m, i| {
        let ei = e(i);
        m + glam::DMat3::from_cols(ei * ei.x, ei * ei.y, ei * ei.z)
    });
    let mg = &mut scratch.mg;
    mg.clear();
    mg.extend(g.iter().map(|gj| m * *gj));
    out.clear();
    out.resize(n * n, 0.0);
    for j in 0..n {
        for k in j..n {
            let ddt = if j == k {
                2.0
            } else if k == j + 1 || (j == 0 && k == n - 1) {
                -1.0
            } else {
                0.0
            };
            let qq = ddt - a[j].dot(g[k]) - g[j].dot(a[k]) + g[j].dot(mg[k]);
            let v = area * g[j].dot(g[k]) + lambda * qq;
            out[j * n + k] = v;
            out[k * n + j] = v;
        }
    }
    Some(area)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn lap(corners: &[DVec3]) -> Vec<f64> {
        let mut out = Vec::new();
        polygon_laplacian(corners, DEFAULT_LAMBDA, &mut PolygonScratch::default(), &mut out).expect("non-degenerate");
        out
    }

    /// A deterministic pseudo-random sequence in [-1, 1) (xorshift), so tests need no RNG crate.
    pub(crate) struct Rng(pub(crate) u64);
    impl Rng {
        pub fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
        pub fn vec3(&mut self) -> DVec3 {
            DVec3::new(self.next(), self.next(), self.next())
        }
    }

    fn star(n: usize, inner: f64) -> Vec<DVec3> {
        // A non-convex star polygon in the plane z = 0, counter-clockwise.
        (0..2 * n)
            .map(|k| {
                let t = std::f64::consts::PI * k as f64 / n as f64;
                let r = if k % 2 == 0 { 1.0 } else { inner };
                DVec3::new(r * t.cos(), r * t.sin(), 0.0)
            })
            .collect()
    }

    fn check_invariants(corners: &[DVec3], rng: &mut Rng) {
        let n = corners.len();
        let l = lap(corners);
        let scale = l.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for j in 0..n {
            let row_sum: f64 = l[j * n..(j + 1) * n].iter().sum();
            assert!(row_sum.abs() <= 1e-12 * scale, "row {j} sums to {row_sum}");
            for k in 0..n {
                assert!((l[j * n + k] - l[k * n + j]).abs() <= 1e-13 * scale, "not symmetric at {j},{k}");
            }
        }
        for _ in 0..50 {
            let x: Vec<f64> = (0..n).map(|_| rng.next()).collect();
            let e: f64 = (0..n).map(|j| (0..n).map(|k| x[j] * l[j * n + k] * x[k]).sum::<f64>()).sum();
            assert!(e >= -1e-12 * scale, "negative energy {e}");
        }
    }

    #[test]
    fn triangle_gives_half_cotangent_weights() {
        let mut rng = Rng(7);
        for _ in 0..100 {
            let t = [rng.vec3(), rng.vec3(), rng.vec3()];
            let l = lap(&t);
            for (i, j, k) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
                // Angle at k, opposite edge (i, j).
                let (u, v) = (t[i] - t[k], t[j] - t[k]);
                let cot = u.dot(v) / u.cross(v).length();
                let want = -0.5 * cot;
                assert!((l[i * 3 + j] - want).abs() <= 1e-9 * (1.0 + want.abs()), "{} vs {want}", l[i * 3 + j]);
            }
        }
    }

    #[test]
    fn invariants_on_convex_nonconvex_nonplanar_and_cracked_polygons() {
        let mut rng = Rng(11);
        check_invariants(&star(5, 0.4), &mut rng);
        let mut bumpy = star(6, 0.5);
        for c in &mut bumpy {
            c.z = 0.3 * rng.next();
        }
        check_invariants(&bumpy, &mut rng);
        let quad = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.2), DVec3::Y];
        check_invariants(&quad, &mut rng);
        check_invariants(&cracked_square(), &mut rng);
    }

    /// The unit square with a crack from corner 0 to an interior point p:
    /// the loop 0 → p → 0 → 1 → 2 → 3.
    fn cracked_square() -> Vec<DVec3> {
        let p = DVec3::new(0.4, 0.3, 0.0);
        vec![DVec3::ZERO, p, DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y]
    }

    #[test]
    fn gradient_is_exact_and_q_vanishes_on_linear_functions() {
        let mut rng = Rng(3);
        for corners in [star(5, 0.4), cracked_square(), star(3, 0.9)] {
            let n = corners.len();
            let mut g = Vec::new();
            polygon_gradient(&corners, &mut g).unwrap();
            for _ in 0..10 {
                let grad = DVec3::new(rng.next(), rng.next(), 0.0);
                let phi: Vec<f64> = corners.iter().map(|c| grad.dot(*c) + 0.7).collect();
                let got: DVec3 = (0..n).map(|j| g[j] * phi[j]).sum();
                assert!((got - grad).length() < 1e-12, "{got} vs {grad}");
                // L φ = a Gᵀ g for linear φ (the Q term vanishes).
                let l = lap(&corners);
                let area = vector_area(&corners).length();
                for j in 0..n {
                    let lphi: f64 = (0..n).map(|k| l[j * n + k] * phi[k]).sum();
                    assert!((lphi - area * g[j].dot(grad)).abs() < 1e-11);
                }
            }
        }
    }

    #[test]
    fn a_crack_leaves_the_vector_area_unchanged() {
        let square = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        assert!((vector_area(&cracked_square()) - vector_area(&square)).length() < 1e-15);
    }

    #[test]
    fn scale_invariant_from_1e_minus_6_to_1e6() {
        let base = star(4, 0.3);
        let l0 = lap(&base);
        for s in [1e-6, 1e6] {
            let scaled: Vec<DVec3> = base.iter().map(|c| *c * s + DVec3::new(3.0, -2.0, 1.0) * s).collect();
            let l = lap(&scaled);
            for (a, b) in l.iter().zip(&l0) {
                assert!((a - b).abs() < 1e-8 * (1.0 + b.abs()), "scale {s}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn zero_area_polygons_are_refused() {
        let flat = [DVec3::ZERO, DVec3::X, DVec3::X * 2.0];
        assert!(polygon_laplacian(&flat, 1.0, &mut PolygonScratch::default(), &mut Vec::new()).is_none());
    }

    /// The expanded `QᵀQ` equals the direct product `Σ_i Q_ij Q_ik` with
    /// `Q = D − E G` formed explicitly, on random non-planar polygons of 3
    /// to 400 corners and stars (fixed seed; the message names the case).
    #[test]
    fn expanded_stabilisation_equals_the_direct_product() {
        let mut rng = Rng(2026);
        let mut cases: Vec<Vec<DVec3>> = vec![star(5, 0.4), star(200, 0.7), cracked_square()];
        for n in [3, 4, 5, 9, 40, 400] {
            cases.push(
                (0..n)
                    .map(|k| {
                        let t = std::f64::consts::TAU * k as f64 / n as f64;
                        DVec3::new(t.cos(), t.sin(), 0.0) + 0.2 * rng.vec3()
                    })
                    .collect(),
            );
        }
        for (c, corners) in cases.iter().enumerate() {
            let n = corners.len();
            let mut g = Vec::new();
            let area = polygon_gradient(corners, &mut g).expect("non-degenerate");
            let q: Vec<f64> = (0..n * n)
                .map(|ij| {
                    let (i, j) = (ij / n, ij % n);
                    let e = corners[(i + 1) % n] - corners[i];
                    let d = if j == i {
                        -1.0
                    } else if j == (i + 1) % n {
                        1.0
                    } else {
                        0.0
                    };
                    d - e.dot(g[j])
                })
                .collect();
            let l = lap(corners);
            let scale = l.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for j in 0..n {
                for k in 0..n {
                    let direct = area * g[j].dot(g[k]) + (0..n).map(|i| q[i * n + j] * q[i * n + k]).sum::<f64>();
                    let got = l[j * n + k];
                    assert!(
                        (got - direct).abs() <= 1e-12 * scale,
                        "case {c} ({n} corners) at {j},{k}: {got} vs {direct}"
                    );
                }
            }
        }
    }
}
