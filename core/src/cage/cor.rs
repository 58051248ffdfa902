//! Skinning with optimised centres of rotation (Le and Hodgins 2016,
//! "Real-time skeletal skinning with optimized centers of rotation"), as
//! Corda et al. 2020 use it (their Eq. 5 and 6).
//!
//! # Centres (Eq. 5)
//!
//! The centre of rotation of vertex `i` is a similarity-weighted average
//! of the mesh's triangles:
//!
//! ```text
//! p_i = Σ_t s(w_i, w_t) a_t x_t / Σ_t s(w_i, w_t) a_t
//! s(w_i, w_t) = Σ_{j<k} w_ij w_ik w_tj w_tk exp(−(w_ij w_tk − w_ik w_tj)² / σ²)
//! ```
//!
//! with `a_t` the triangle's area, `x_t` its centroid, `w_t` the average of
//! its corners' weights, and the kernel width `σ = 0.1` ([`COR_SIGMA`],
//! Le and Hodgins' value). Only triangles sharing at least two joints with
//! the vertex contribute (`s` is 0 otherwise), so the sum runs over the
//! triangles listed under each pair of the vertex's joints. A vertex with
//! a single joint, or that no triangle resembles, keeps itself as its
//! centre: it moves rigidly with its joint whatever its centre is.
//!
//! The centres are linear in the mesh's points once the areas and
//! similarities are frozen at bind: `p = Φ_CoR · M`. When the rest mesh
//! follows a cage (`M = Φ C`), the centres follow it with `Λ = Φ_CoR · Φ`
//! (Corda et al. Eq. 14, computed by [`CentersOfRotation::cage_coordinates`]),
//! keeping the bind-time areas as the paper does.
//!
//! # Skinning (Eq. 6)
//!
//! ```text
//! R(i) = the rotation of the normalised quaternion blend Σ_j w_ij q_j
//! p̃_i  = Σ_j w_ij T_j(p_i)                      (the centre, skinned by LBS)
//! v′_i = R(i) (v_i − p_i) + p̃_i
//! ```
//!
//! Quaternions are flipped to the hemisphere of the point's largest
//! weight, as in [`crate::skinning::skin_points_dqs`]. Transforms
//! with scale or shear are split as UsdSkel's dual-quaternion skinning
//! splits them (rotation × scale); when any joint scales, the point and its
//! centre are first scaled by the linear blend of the scale parts, and the
//! rigid parts then act as above. Without scale this is exactly Eq. 6.

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::CageError;
use super::mvc::Mvc;
use crate::error::Result;
use crate::skinning::dqs::DualQuat;
use crate::skinning::influences::{Influences, check_skinning_input};
use crate::skinning::transform::{Mat4, transform_point};

/// The kernel width `σ` of the weight similarity (Le and Hodgins 2016).
pub const COR_SIGMA: f64 = 0.1;

/// Points per rayon task.
const CHUNK: usize = 512;

/// Per-vertex centres of rotation of a mesh, and what recomputing them
/// from the mesh's points needs.
#[derive(Debug, Clone, PartialEq)]
pub struct CentersOfRotation {
    centers: Vec<[f64; 3]>,
    /// Whether vertex `i` has a centre of its own (else it is itself).
    blended: Vec<bool>,
}

/// The bind-time data of Eq. 5: triangle weights, areas and the pair lists.
struct Similarity<'a> {
    triangles: &'a [[u32; 3]],
    /// Triangle `t`'s (joint, weight) pairs: `tri_weights[offsets[t]..offsets[t + 1]]`, joints sorted.
    offsets: Vec<usize>,
    tri_weights: Vec<(u32, f64)>,
    areas: Vec<f64>,
    pairs: FxHashMap<(u32, u32), Vec<u32>>,
}

impl<'a> Similarity<'a> {
    fn new(points: &[[f64; 3]], triangles: &'a [[u32; 3]], influences: &Influences) -> Self {
        let mut offsets = vec![0];
        let mut tri_weights = Vec::new();
        let mut areas = Vec::with_capacity(triangles.len());
        let mut pairs: FxHashMap<(u32, u32), Vec<u32>> = FxHashMap::default();
        let mut merged: Vec<(u32, f64)> = Vec::new();
        for (t, tri) in triangles.iter().enumerate() {
            merged.clear();
            for &v in tri {
                for (j, w) in influences.point(v as usize) {
                    if w == 0.0 {
                        continue;
                    }
                    match merged.iter_mut().find(|(k, _)| *k == j) {
                        Some(e) => e.1 += w / 3.0,
                        None => merged.push((j, w / 3.0)),
                    }
                }
            }
            merged.sort_unstable_by_key(|e| e.0);
            for a in 0..merged.len() {
                for b in a + 1..merged.len() {
                    pairs.entry((merged[a].0, merged[b].0)).or_default().push(t as u32);
                }
            }
            tri_weights.extend_from_slice(&merged);
            offsets.push(tri_weights.len());
            let p = tri.map(|v| DVec3::from_array(points[v as usize]));
            areas.push((p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0);
        }
        Self { triangles, offsets, tri_weights, areas, pairs }
    }

    fn tri(&self, t: usize) -> &[(u32, f64)] {
        &self.tri_weights[self.offsets[t]..self.offsets[t + 1]]
    }

    /// Calls `f(triangle, s · area)` for every triangle resembling a vertex
    /// whose nonzero weights are `w` (joints sorted), each triangle once.
    fn for_each(&self, w: &[(u32, f64)], mut f: impl FnMut(usize, f64)) {
        let weight_of = |t: usize, j: u32| self.tri(t).iter().find(|e| e.0 == j).map_or(0.0, |e| e.1);
        let mut pair_index = 0;
        for a in 0..w.len() {
            for b in a + 1..w.len() {
                let Some(list) = self.pairs.get(&(w[a].0, w[b].0)) else {
                    pair_index += 1;
                    continue;
                };
                'tri: for &t in list {
                    let t = t as usize;
                    // Counted under its first pair of the vertex's joints only.
                    let mut k = 0;
                    for a2 in 0..w.len() {
                        for b2 in a2 + 1..w.len() {
                            if k == pair_index {
                                break;
                            }
                            if weight_of(t, w[a2].0) > 0.0 && weight_of(t, w[b2].0) > 0.0 {
                                continue 'tri;
                            }
                            k += 1;
                        }
                    }
                    let mut s = 0.0;
                    for a2 in 0..w.len() {
                        for b2 in a2 + 1..w.len() {
                            let (tj, tk) = (weight_of(t, w[a2].0), weight_of(t, w[b2].0));
                            let (ij, ik) = (w[a2].1, w[b2].1);
                            let d = (ij * tk - ik * tj) / COR_SIGMA;
                            s += ij * ik * tj * tk * (-d * d).exp();
                        }
                    }
                    if s > 0.0 {
                        f(t, s * self.areas[t]);
                    }
                }
                pair_index += 1;
            }
        }
    }
}

/// The nonzero (joint, weight) pairs of point `p`, joints sorted and merged, into `out`.
fn nonzero(influences: &Influences, p: usize, out: &mut Vec<(u32, f64)>) {
    out.clear();
    for (j, w) in influences.point(p) {
        if w == 0.0 {
            continue;
        }
        match out.iter_mut().find(|(k, _)| *k == j) {
            Some(e) => e.1 += w,
            None => out.push((j, w)),
        }
    }
    out.sort_unstable_by_key(|e| e.0);
}

impl CentersOfRotation {
    /// The centres of every vertex of a triangle mesh (`points`, outward
    /// `triangles`; a polygon mesh is triangulated by the caller) with its
    /// skin `influences` (Eq. 5, parallel over vertices). Refused, naming
    /// the element: counts, a triangle index out of range, a non-finite point.
    pub fn new(points: &[[f64; 3]], triangles: &[[u32; 3]], influences: &Influences) -> Result<Self> {
        check(points, triangles, influences)?;
        let sim = Similarity::new(points, triangles, influences);
        let mut centers = points.to_vec();
        let mut blended = vec![false; points.len()];
        centers.par_chunks_mut(CHUNK).zip(blended.par_chunks_mut(CHUNK)).enumerate().for_each(|(chunk, (c, b))| {
            let mut w = Vec::new();
            for k in 0..c.len() {
                let i = chunk * CHUNK + k;
                nonzero(influences, i, &mut w);
                if w.len() < 2 {
                    continue;
                }
                let mut num = DVec3::ZERO;
                let mut den = 0.0;
                sim.for_each(&w, |t, coef| {
                    let x =
                        sim.triangles[t].iter().map(|&v| DVec3::from_array(points[v as usize])).sum::<DVec3>() / 3.0;
                    num += x * coef;
                    den += coef;
                });
                if den > 0.0 {
                    c[k] = (num / den).to_array();
                    b[k] = true;
                }
            }
        });
        Ok(Self { centers, blended })
    }

    /// Vertex `i`'s centre of rotation (mesh space).
    pub fn centers(&self) -> &[[f64; 3]] {
        &self.centers
    }

    /// Whether vertex `i` has a centre of its own (two or more joints and a
    /// resembling triangle); the others are their own centre.
    pub fn is_blended(&self, i: usize) -> bool {
        self.blended[i]
    }

    /// Number of vertices with a centre of their own.
    pub fn n_blended(&self) -> usize {
        self.blended.iter().filter(|b| **b).count()
    }

    /// `Λ = Φ_CoR · Φ` (Corda et al. Eq. 14): the cage coordinates of the
    /// centres, for the vertices with a centre of their own, in vertex
    /// order (`n_blended() × #C`, row-major). The other vertices' centres
    /// are the vertices themselves, whose coordinates are `Φ`'s rows. The
    /// mesh (`points`, `triangles`, `influences`) must be the one the
    /// centres were computed from, and `mvc` its coordinates.
    pub fn cage_coordinates(
        &self,
        points: &[[f64; 3]],
        triangles: &[[u32; 3]],
        influences: &Influences,
        mvc: &Mvc,
    ) -> Result<Vec<f64>> {
        check(points, triangles, influences)?;
        if mvc.n_points() != points.len() || self.centers.len() != points.len() {
            return Err(CageError::Count {
                what: "points of the cage coordinates",
                expected: self.centers.len(),
                got: mvc.n_points(),
            }
            .into());
        }
        let sim = Similarity::new(points, triangles, influences);
        let c = mvc.n_cage_vertices();
        let rows: Vec<usize> = (0..points.len()).filter(|&i| self.blended[i]).collect();
        let mut lambda = vec![0.0; rows.len() * c];
        lambda.par_chunks_mut(c).zip(rows.par_iter()).for_each_init(Vec::new, |w, (out, &i)| {
            nonzero(influences, i, w);
            let mut den = 0.0;
            sim.for_each(w, |t, coef| {
                for &v in &sim.triangles[t] {
                    for (o, phi) in out.iter_mut().zip(mvc.row(v as usize)) {
                        *o += coef / 3.0 * phi;
                    }
                }
                den += coef;
            });
            out.iter_mut().for_each(|o| *o /= den);
        });
        Ok(lambda)
    }
}

fn check(points: &[[f64; 3]], triangles: &[[u32; 3]], influences: &Influences) -> Result<()> {
    if influences.n_points() != points.len() {
        return Err(
            CageError::Count { what: "influenced points", expected: points.len(), got: influences.n_points() }.into()
        );
    }
    crate::mesh::check_finite(points, "point")?;
    for (face, t) in triangles.iter().enumerate() {
        for (corner, &v) in t.iter().enumerate() {
            if v as usize >= points.len() {
                return Err(CageError::IndexOutOfRange { face, corner, vertex: v, n_vertices: points.len() }.into());
            }
        }
    }
    Ok(())
}

/// A transform split into a rigid part (a unit dual quaternion) and a scale
/// (column-vector 3×3), as UsdSkel's dual-quaternion skinning splits it.
pub(crate) fn split(m: &Mat4) -> (DualQuat, DMat3) {
    let (dq, s) = DualQuat::from_transform(m);
    (dq.unwrap_or(DualQuat::ZERO), s)
}

/// Centre-of-rotation skinning (Eq. 6, see the module docs): `points` and
/// `centers` (one per point, both in the mesh's space, before
/// `geom_bind`), the point's influences and the skinning transforms; into
/// `out` (skeleton space). Parallel over points.
pub fn skin_points_cor(
    points: &[[f64; 3]],
    centers: &[[f64; 3]],
    influences: &Influences,
    geom_bind: &Mat4,
    transforms: &[Mat4],
    out: &mut [[f64; 3]],
) -> Result<()> {
    check_skinning_input(points, influences, transforms, out)?;
    if centers.len() != points.len() {
        return Err(CageError::Count { what: "centres of rotation", expected: points.len(), got: centers.len() }.into());
    }
    let parts: Vec<(DualQuat, DMat3)> = transforms.iter().map(split).collect();
    let has_scale = parts.iter().any(|(_, s)| {
        (*s - DMat3::IDENTITY).to_cols_array().iter().any(|d| d.abs() > crate::skinning::dqs::SCALE_TOLERANCE)
    });
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, block)| {
        for (k, o) in block.iter_mut().enumerate() {
            let i = chunk * CHUNK + k;
            let v = DVec3::from_array(transform_point(geom_bind, points[i]));
            let p = DVec3::from_array(transform_point(geom_bind, centers[i]));
            *o = cor_point(&parts, has_scale, influences, i, v, p).to_array();
        }
    });
    Ok(())
}

/// Eq. 6 for point `i` at `v` with centre `p` (both in skeleton space).
#[inline]
pub(crate) fn cor_point(
    parts: &[(DualQuat, DMat3)],
    has_scale: bool,
    influences: &Influences,
    i: usize,
    v: DVec3,
    p: DVec3,
) -> DVec3 {
    let mut pivot: Option<(u32, f64)> = None;
    for (j, w) in influences.point(i) {
        if pivot.is_none_or(|(_, m)| m < w) {
            pivot = Some((j, w));
        }
    }
    let pivot_q = pivot.map_or(DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), |(j, _)| parts[j as usize].0.real);
    let mut q = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    let (mut vs, mut ps) = (DVec3::ZERO, DVec3::ZERO);
    for (j, w) in influences.point(i) {
        if w == 0.0 {
            continue;
        }
        let (dq, s) = &parts[j as usize];
        if has_scale {
            vs += (*s * v) * w;
            ps += (*s * p) * w;
        }
        let sw = if dq.real.dot(pivot_q) < 0.0 { -w } else { w };
        q += dq.real * sw;
    }
    if !has_scale {
        vs = v;
        ps = p;
    }
    let len = q.length();
    let r = if len >= 1e-10 { q * (1.0 / len) } else { DQuat::IDENTITY };
    let mut centre = DVec3::ZERO;
    for (j, w) in influences.point(i) {
        if w == 0.0 {
            continue;
        }
        centre += parts[j as usize].0.transform_point(ps) * w;
    }
    r * (vs - ps) + centre
}
