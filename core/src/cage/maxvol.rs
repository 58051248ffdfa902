//! The MaxVol row subset of `Φ` (Goreinov, Oseledets, Savostyanov,
//! Tyrtyshnikov, Zamarashkin 2010, "How to find a good submatrix"), as
//! Corda et al. §4.1 use it (after Thiery et al. 2012): `#C` rows of `Φ`
//! whose square submatrix `Φ̃` has a (locally) maximal volume, factored
//! once; the cage updater then fits the posed cage by back-substitution,
//! `Φ̃ C′ = M̃′`, at a cost independent of the mesh.
//!
//! 1. Start rows: Gaussian elimination of `Φ` with row pivoting (each
//!    column's largest remaining entry), which picks a well-conditioned
//!    square submatrix.
//! 2. `B = Φ Φ̃⁻¹` (`#P × #C`); while some `|B_ij| > 1 + 10⁻²` (at most
//!    `100·#C` times), row `i` replaces the `j`-th chosen row, which
//!    multiplies `|det Φ̃|` by `|B_ij|`, and `B` is updated by a rank-one
//!    correction. On exit every row of `Φ` is a combination of the chosen
//!    rows with coefficients of magnitude at most 1.01.
//! 3. `Φ̃⁻¹` is computed once (dense LU with partial pivoting, faer) and
//!    kept; its 2-norm condition number is reported ([`MaxVol::condition`]).

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, MatRef};
use rayon::prelude::*;

use super::CageError;
use super::mvc::Mvc;
use crate::error::Result;

/// Swaps stop when no `|B_ij|` exceeds this.
pub const MAXVOL_TOLERANCE: f64 = 1.01;

/// The chosen rows, `Φ̃⁻¹` and its conditioning.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MaxVol {
    #[serde(with = "crate::persist::pod")]
    rows: Vec<usize>,
    /// `Φ̃⁻¹`, `#C × #C` row-major.
    #[serde(with = "crate::persist::pod")]
    inverse: Vec<f64>,
    condition: f64,
    swaps: usize,
}

impl MaxVol {
    /// Chooses the rows of `mvc`'s `Φ` (see the module docs). Refused with
    /// [`CageError::SingularMaxVol`] naming a cage vertex when `Φ` has rank
    /// below `#C` (fewer points than cage vertices, or a cage vertex that
    /// influences no point).
    pub fn new(mvc: &Mvc) -> Result<Self> {
        let (n, c) = (mvc.n_points(), mvc.n_cage_vertices());
        let phi = mvc.matrix();
        if n < c {
            return Err(CageError::SingularMaxVol { vertex: n, condition: f64::INFINITY }.into());
        }
        // 1. Row-pivoted elimination on a copy.
        let mut a = phi.to_vec();
        let mut rows = Vec::with_capacity(c);
        let mut taken = vec![false; n];
        let scale = phi.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for j in 0..c {
            let (best, value) = a
                .par_chunks(c)
                .enumerate()
                .filter(|(i, _)| !taken[*i])
                .map(|(i, r)| (i, r[j].abs()))
                .reduce(|| (usize::MAX, -1.0), |x, y| if y.1 > x.1 || (y.1 == x.1 && y.0 < x.0) { y } else { x });
            if !(value > 1e-13 * scale) {
                return Err(CageError::SingularMaxVol { vertex: j, condition: f64::INFINITY }.into());
            }
            taken[best] = true;
            rows.push(best);
            let pivot: Vec<f64> = a[best * c..(best + 1) * c].to_vec();
            a.par_chunks_mut(c).enumerate().for_each(|(i, r)| {
                if i == best || r[j] == 0.0 {
                    return;
                }
                let f = r[j] / pivot[j];
                for k in j..c {
                    r[k] -= f * pivot[k];
                }
            });
        }
        drop(a);
        // 2. Swaps.
        let phi_ref = MatRef::from_row_major_slice(phi, n, c);
        let inv = inverse_of_rows(phi, c, &rows)?;
        let b_mat: Mat<f64> = phi_ref * inv.as_ref();
        let mut b = vec![0.0; n * c];
        b.par_chunks_mut(c).enumerate().for_each(|(i, r)| {
            for (k, x) in r.iter_mut().enumerate() {
                *x = b_mat[(i, k)];
            }
        });
        drop(b_mat);
        let mut swaps = 0;
        for _ in 0..100 * c {
            let (i, j, v) = b
                .par_chunks(c)
                .enumerate()
                .map(|(i, r)| {
                    let (j, v) = r
                        .iter()
                        .enumerate()
                        .fold((0, 0.0f64), |m, (j, x)| if x.abs() > m.1 { (j, x.abs()) } else { m });
                    (i, j, v)
                })
                .reduce(|| (0, 0, -1.0), |x, y| if y.2 > x.2 { y } else { x });
            if v <= MAXVOL_TOLERANCE {
                break;
            }
            // B ← B − B[:, j] (B[i, :] − e_j) / B[i, j]
            let mut bi: Vec<f64> = b[i * c..(i + 1) * c].to_vec();
            let bij = bi[j];
            bi[j] -= 1.0;
            b.par_chunks_mut(c).for_each(|r| {
                let f = r[j] / bij;
                if f != 0.0 {
                    for (x, y) in r.iter_mut().zip(&bi) {
                        *x -= f * y;
                    }
                }
            });
            rows[j] = i;
            swaps += 1;
        }
        // 3. The kept inverse and the conditioning.
        let inv = inverse_of_rows(phi, c, &rows)?;
        let sub = Mat::<f64>::from_fn(c, c, |r, k| phi[rows[r] * c + k]);
        let sv = sub.singular_values().map_err(|_| CageError::SingularMaxVol { vertex: 0, condition: f64::NAN })?;
        let (hi, lo) = sv.iter().fold((0.0f64, f64::MAX), |(h, l), s| (h.max(*s), l.min(*s)));
        let condition = hi / lo;
        let mut inverse = vec![0.0; c * c];
        for r in 0..c {
            for k in 0..c {
                inverse[r * c + k] = inv[(r, k)];
            }
        }
        if !inverse.iter().all(|x| x.is_finite()) || !(condition < 1e14) {
            return Err(CageError::SingularMaxVol { vertex: 0, condition }.into());
        }
        Ok(Self { rows, inverse, condition, swaps })
    }

    /// The chosen rows (mesh points), the `j`-th paired with cage vertex `j`'s column order.
    pub fn rows(&self) -> &[usize] {
        &self.rows
    }
    /// The 2-norm condition number of `Φ̃`.
    pub fn condition(&self) -> f64 {
        self.condition
    }
    /// Row swaps done after the elimination's start.
    pub fn swaps(&self) -> usize {
        self.swaps
    }
    /// `Φ̃⁻¹`, row-major.
    pub fn inverse(&self) -> &[f64] {
        &self.inverse
    }

    /// `out = Φ̃⁻¹ rhs` (one point per chosen row in, one per cage vertex
    /// out); sizes are the caller's (`#C` each).
    pub fn solve(&self, rhs: &[[f64; 3]], out: &mut [[f64; 3]]) {
        let c = self.rows.len();
        for (r, o) in out.iter_mut().enumerate() {
            let row = &self.inverse[r * c..(r + 1) * c];
            let mut acc = [0.0; 3];
            for (w, q) in row.iter().zip(rhs) {
                acc[0] += w * q[0];
                acc[1] += w * q[1];
                acc[2] += w * q[2];
            }
            *o = acc;
        }
    }
}

fn inverse_of_rows(phi: &[f64], c: usize, rows: &[usize]) -> Result<Mat<f64>> {
    let sub = Mat::<f64>::from_fn(c, c, |r, k| phi[rows[r] * c + k]);
    let inv = sub.partial_piv_lu().inverse();
    if let Some(k) = (0..c).find(|&k| (0..c).any(|r| !inv[(r, k)].is_finite())) {
        return Err(CageError::SingularMaxVol { vertex: k, condition: f64::INFINITY }.into());
    }
    Ok(inv)
}
