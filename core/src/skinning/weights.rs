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
//!   closest to each curve point (barycentric interpolation of the closest
//!   triangle's vertex weights, on the pose the curvenet was drawn on).
//!   Naive control-point skinning then uses the weights at the surface
//!   point closest to each control point, handles included.
//!
//! Weights are sparse `(joint, weight)` lists; a joint appears at most once.

use super::{Influences, SkinningError};
use crate::closest_point::ClosestPointBvh;
use crate::error::Result;

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

    fn at(&self, point: [f64; 3], out: &mut Vec<(u32, f64)>) -> Result<()> {
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
