//! Joint weights along a curvenet's splines, for spline skinning.
//!
//! Spline skinning (Liu et al. 2015) integrates the skinning weight
//! functions `w_i` along each neutral curve. A [`WeightField`] gives them:
//!
//! - [`ControlPointWeights`]: weights authored per control point of the
//!   pool (the curvenet's `primvars:curvenet:skel:jointIndices` /
//!   `jointWeights`), interpolated along each spline with its cubic
//!   Bernstein basis, `w(t) = Σ_k B_k(t) w(c_k)`: the weights move with the
//!   curve as its points do, and naive control-point skinning uses exactly
//!   the authored weights.
//! - [`SurfaceWeights`]: the mesh's skin weights at the surface point
//!   closest to a point (barycentric interpolation of the closest
//!   triangle's vertex weights, on the pose the curvenet was drawn on).
//!   Piecewise linear over the mesh's triangles, so along a curve it has a
//!   kink at every mesh edge the curve crosses, which no Bézier spline
//!   follows: on the rigged hand's middle finger (hand_1k4), fitting the
//!   curves skinned by it directly (and keeping G¹) came out 7–20 % worse
//!   than naive control-point skinning. So [`ControlPointWeights::from_surface`]
//!   derives **per-control-point weights** from it instead: the least-squares
//!   fit of the Bernstein-interpolated weights to the surface weights at
//!   samples of the neutral curves; the curvenet is then skinned with those,
//!   as if they were authored.
//!
//! Weights are sparse `(joint, weight)` lists; a joint appears at most once.

use super::influences::Influences;
use crate::closest_point::ClosestPointBvh;
use crate::error::Result;
use crate::error::SkinningError;

/// Joint weights of the points of a curvenet (see the module docs).
pub trait WeightField: Sync {
    /// The number of joints the weights refer to.
    fn n_joints(&self) -> usize;

    /// The weights at parameter `t ∈ [0, 1]` of spline `spline` (control
    /// points `indices`), whose neutral position is `point`; written into
    /// `out` (cleared first).
    fn along(&self, indices: [u32; 4], t: f64, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()>;

    /// The weights naive control-point skinning gives pool point `k` at its
    /// neutral position `point`.
    fn at_control_point(&self, k: usize, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()>;
}

/// Samples per spline (plus both ends) of [`ControlPointWeights::from_surface`].
pub const DERIVED_WEIGHT_SAMPLES: usize = 16;

/// Weights authored per control point, Bernstein-interpolated along splines.
#[derive(Debug, Clone)]
pub struct ControlPointWeights {
    influences: Influences,
}

impl ControlPointWeights {
    /// `influences`: one point per pool control point.
    pub fn new(influences: Influences) -> Self {
        Self { influences }
    }

    pub fn influences(&self) -> &Influences {
        &self.influences
    }

    /// Per-control-point weights derived from `surface` (see the module
    /// docs): for every joint, the pool weights `w` minimising
    /// `Σ_s (Σ_k B_k(t_s) w(c_k) − w_surface(p_s))²` over `samples` points
    /// `p_s` per spline (parameters `(j + ½)/samples`, plus both ends), all
    /// joints at once (one normal matrix). Negative weights (overshoot at a
    /// steep transition) are set to 0 and each point's weights rescaled to
    /// sum to 1; pool points no spline uses take the surface weights at
    /// themselves. Returns the weights and the largest difference, over the
    /// samples and joints, between the derived and the surface weights.
    pub fn from_surface(
        pool: &[[f64; 3]],
        splines: &[[u32; 4]],
        surface: &SurfaceWeights<'_>,
        samples: usize,
    ) -> Result<(Self, f64)> {
        use faer::Mat;
        use faer::linalg::solvers::Solve;
        let n_joints = surface.n_joints();
        let mut unknown = vec![u32::MAX; pool.len()];
        let mut used = Vec::new();
        for s in splines {
            for &k in s {
                if unknown[k as usize] == u32::MAX {
                    unknown[k as usize] = used.len() as u32;
                    used.push(k);
                }
            }
        }
        let n = used.len();
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, n_joints);
        let mut scratch = Vec::new();
        let mut sampled = Vec::new();
        let ts: Vec<f64> =
            std::iter::once(0.0).chain((0..samples).map(|j| (j as f64 + 0.5) / samples as f64)).chain([1.0]).collect();
        for s in splines {
            for &t in &ts {
                let u = 1.0 - t;
                let basis = [u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t];
                let mut p = [0.0; 3];
                for (k, bk) in s.iter().zip(basis) {
                    for c in 0..3 {
                        p[c] += bk * pool[*k as usize][c];
                    }
                }
                surface.at(p, &mut scratch)?;
                for (ka, ba) in s.iter().zip(basis) {
                    let ua = unknown[*ka as usize] as usize;
                    for (kb, bb) in s.iter().zip(basis) {
                        a[(ua, unknown[*kb as usize] as usize)] += ba * bb;
                    }
                    for &(j, w) in &scratch {
                        b[(ua, j as usize)] += ba * w;
                    }
                }
                sampled.push((*s, basis, scratch.clone()));
            }
        }
        let x = a.partial_piv_lu().solve(&b);
        // Clamp, renormalise, and keep the nonzero weights of every point.
        let mut rows: Vec<Vec<(u32, f64)>> = vec![Vec::new(); pool.len()];
        for (p, row) in rows.iter_mut().enumerate() {
            match unknown[p] {
                u32::MAX => surface.at(pool[p], row)?,
                u => {
                    for j in 0..n_joints {
                        let w = x[(u as usize, j)];
                        if !w.is_finite() {
                            return Err(crate::Error::Internal {
                                what: format!("derived weight of control point {p} is not finite"),
                            });
                        }
                        if w > 0.0 {
                            row.push((j as u32, w));
                        }
                    }
                }
            }
            normalize(row, "control point", p)?;
        }
        let element_size = rows.iter().map(Vec::len).max().unwrap_or(1).max(1);
        let mut indices = Vec::with_capacity(element_size * pool.len());
        let mut weights = Vec::with_capacity(element_size * pool.len());
        for row in &rows {
            for k in 0..element_size {
                let (j, w) = row.get(k).copied().unwrap_or((0, 0.0));
                indices.push(j as i64);
                weights.push(w);
            }
        }
        let derived = Self::new(Influences::new(pool.len(), element_size, &indices, &weights, n_joints)?);
        let mut worst = 0.0f64;
        let mut mine = Vec::new();
        for (s, basis, want) in &sampled {
            mine.clear();
            for (k, bk) in s.iter().zip(basis) {
                for (j, w) in derived.influences.point(*k as usize) {
                    add(&mut mine, j, bk * w);
                }
            }
            for j in 0..n_joints as u32 {
                let get = |v: &[(u32, f64)]| v.iter().find(|x| x.0 == j).map_or(0.0, |x| x.1);
                worst = worst.max((get(&mine) - get(want)).abs());
            }
        }
        Ok((derived, worst))
    }
}

impl WeightField for ControlPointWeights {
    fn n_joints(&self) -> usize {
        self.influences.n_joints()
    }

    fn along(&self, indices: [u32; 4], t: f64, _point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
        out.clear();
        let s = 1.0 - t;
        let basis = [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t];
        for (k, &b) in indices.iter().zip(&basis) {
            for (j, w) in self.influences.point(*k as usize) {
                add(out, j, b * w);
            }
        }
        Ok(())
    }

    fn at_control_point(&self, k: usize, _point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
        out.clear();
        for (j, w) in self.influences.point(k) {
            add(out, j, w);
        }
        Ok(())
    }
}

/// The mesh's skin weights at the closest surface point.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceWeights<'a> {
    surface: &'a ClosestPointBvh,
    influences: &'a Influences,
}

impl<'a> SurfaceWeights<'a> {
    /// `surface`: the mesh in the pose the curvenet was drawn on;
    /// `influences`: one point per mesh vertex.
    pub fn new(surface: &'a ClosestPointBvh, influences: &'a Influences) -> Result<Self> {
        let n = (0..surface.n_triangles()).flat_map(|t| surface.triangle(t).0).max().map_or(0, |v| v as usize + 1);
        if n > influences.n_points() {
            return Err(crate::Error::CountMismatch {
                what: "mesh skin influences (one per vertex)",
                expected: n,
                got: influences.n_points(),
            });
        }
        Ok(Self { surface, influences })
    }

    /// The weights at the surface point closest to `point`, into `out`.
    pub fn at(&self, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
        out.clear();
        let hit = self.surface.closest_point(point)?;
        for (&v, &b) in hit.corners.iter().zip(&hit.barycentric) {
            for (j, w) in self.influences.point(v as usize) {
                add(out, j, b * w);
            }
        }
        Ok(())
    }
}

impl WeightField for SurfaceWeights<'_> {
    fn n_joints(&self) -> usize {
        self.influences.n_joints()
    }

    fn along(&self, _indices: [u32; 4], _t: f64, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
        self.at(point, out)
    }

    fn at_control_point(&self, _k: usize, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
        self.at(point, out)
    }
}

fn add(out: &mut Vec<(u32, f64)>, joint: u32, w: f64) {
    if w == 0.0 {
        return;
    }
    match out.iter_mut().find(|(j, _)| *j == joint) {
        Some((_, x)) => *x += w,
        None => out.push((joint, w)),
    }
}

/// Rescales `weights` to sum to 1; fails when they sum to (almost) nothing.
pub(crate) fn normalize(weights: &mut [(u32, f64)], what: &'static str, index: usize) -> Result<()> {
    let sum: f64 = weights.iter().map(|(_, w)| w).sum();
    if !(sum.abs() > 1e-12) {
        return Err(SkinningError::Unweighted { what, index }.into());
    }
    weights.iter_mut().for_each(|(_, w)| *w /= sum);
    Ok(())
}
