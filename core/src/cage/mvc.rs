//! Mean value coordinates of points with respect to a closed triangle cage
//! (Ju, Schaefer, Warren 2005, "Mean value coordinates for closed
//! triangular meshes"), and the validated cage they are computed against.
//!
//! # The formulation
//!
//! For a point `x` and cage vertices `p_j`, with `d_j = |p_j − x|` and the
//! unit directions `u_j = (p_j − x)/d_j`, every triangle `(p_1, p_2, p_3)`
//! contributes (indices mod 3):
//!
//! ```text
//! θ_i = ∠(u_{i+1}, u_{i−1}),  h = (θ_1 + θ_2 + θ_3)/2
//! c_i = 2 sin h · sin(h − θ_i) / (sin θ_{i+1} sin θ_{i−1}) − 1
//! s_i = sign(det[u_1 u_2 u_3]) · sqrt(1 − c_i²)
//! w_i += (θ_i − c_{i+1} θ_{i−1} − c_{i−1} θ_{i+1}) / (d_i sin θ_{i+1} s_{i−1})
//! ```
//!
//! and the coordinates are the `w_j` normalised to sum to 1. This is the
//! paper's robust pseudo-code (its Fig. 5): angles from `asin` of chord
//! lengths (`2 asin(|a − b|/2)`, accurate for small angles unlike `acos` of
//! dot products; `π − 2 asin(|a + b|/2)` above 90°, so that a point on an
//! edge, where one angle is π, is recognised to full precision), and
//! three special cases, decided with the tolerance [`MVC_EPSILON`] (relative
//! to the cage's bounding-box diagonal for distances):
//!
//! - `x` on a cage **vertex** (`d_j < ε·diag`): the coordinates are `δ_j`;
//! - `x` on a cage **face** (`π − h < ε`, the three directions span a
//!   half-sphere): the coordinates are the face's barycentric coordinates
//!   `w_i ∝ sin θ_i · d_{i−1} d_{i+1}`, all other vertices 0 — this also
//!   covers points on an **edge** (one barycentric is 0) — and the rest of
//!   the cage is ignored;
//! - `x` in the **plane** of a face but outside it (some `|s_i| < ε`): the
//!   face contributes nothing (its solid angle is 0).
//!
//! The coordinates are defined everywhere off the cage surface, inside and
//! outside, and have partition of unity and linear precision there
//! (`Σ_j φ_j p_j = x`) — so any point set, not only a mesh made from the
//! cage, is reproduced by `Φ·C₀` up to rounding. They are not positive
//! everywhere for non-convex cages (mean value coordinates never are).
//!
//! # Storage
//!
//! `Φ` is dense, `#P × #C`, row-major `f64`: 8 bytes per entry, so 100k
//! points and a 200-vertex cage take 160 MB ([`Mvc::heap_bytes`]). `f32`
//! storage would halve that but rounds every coordinate to 6e-8 relative,
//! which the 1e-10 linear-precision requirement does not allow.

use glam::DVec3;
use rayon::prelude::*;

use super::CageError;
use super::limits::{MAX_CAGE_VERTICES, MAX_PHI_BYTES};
use crate::error::Result;

/// Below this, a point is on a cage vertex (distances, relative to the
/// cage's bounding-box diagonal) or a face (`π − h`, the sines `s_i`).
pub const MVC_EPSILON: f64 = 1e-10;

/// Rows per rayon task in the products with `Φ`.
const ROW_CHUNK: usize = 1024;

/// A validated closed cage: a triangle mesh that is closed, edge-manifold
/// and consistently oriented with outward normals, every vertex used, all
/// points finite.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Cage {
    #[serde(with = "crate::persist::pod")]
    points: Vec<[f64; 3]>,
    #[serde(with = "crate::persist::pod")]
    triangles: Vec<[u32; 3]>,
    diagonal: f64,
}

impl Cage {
    /// The generalised winding number of `q` (van Oosterom and Strackee's
    /// solid angles of the triangles over 4π): 1 inside the cage, 0 outside.
    pub fn winding_number(&self, q: [f64; 3]) -> f64 {
        let q = DVec3::from_array(q);
        let mut omega = 0.0;
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| DVec3::from_array(self.points[i as usize]) - q);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
            omega += 2.0 * num.atan2(den);
        }
        omega / (4.0 * std::f64::consts::PI)
    }

    /// The distance from `q` to the cage's surface.
    pub fn distance(&self, q: [f64; 3]) -> f64 {
        let q = DVec3::from_array(q);
        let corner = |i: u32| DVec3::from_array(self.points[i as usize]);
        self.triangles
            .iter()
            .map(|t| {
                crate::closest_point::closest_on_triangle(q, corner(t[0]), corner(t[1]), corner(t[2])).1.distance(q)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Checks and stores a cage. Refused, naming the element: no triangles
    /// or fewer than 4 points; a corner index out of range; a triangle
    /// repeating a vertex or with zero area; a non-finite point; a vertex
    /// no triangle uses; an edge with one triangle (an open cage), with more
    /// than two, or whose two triangles run it the same way (a flipped
    /// face); a cage whose signed volume is not positive (inside out).
    /// Vertices where two sheets touch (non-manifold vertices) are allowed:
    /// the coordinates do not need manifold vertex neighbourhoods.
    pub fn new(points: &[[f64; 3]], triangles: &[[u32; 3]]) -> Result<Self> {
        if triangles.is_empty() || points.len() < 4 {
            return Err(CageError::TooSmall { vertices: points.len(), triangles: triangles.len() }.into());
        }
        for (vertex, p) in points.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(CageError::NonFinite { what: "cage point", index: vertex, value: *p }.into());
            }
        }
        let n = points.len();
        let mut used = vec![false; n];
        for (face, t) in triangles.iter().enumerate() {
            for (corner, &v) in t.iter().enumerate() {
                if v as usize >= n {
                    return Err(CageError::IndexOutOfRange { face, corner, vertex: v, n_vertices: n }.into());
                }
                used[v as usize] = true;
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(CageError::DegenerateFace { face, vertices: *t }.into());
            }
        }
        if let Some(vertex) = used.iter().position(|u| !u) {
            return Err(CageError::UnusedVertex { vertex }.into());
        }
        let (lo, hi) = points.iter().fold(([f64::MAX; 3], [f64::MIN; 3]), |(mut lo, mut hi), p| {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
            (lo, hi)
        });
        let diagonal = DVec3::from_array(hi).distance(DVec3::from_array(lo));
        let v = |i: u32| DVec3::from_array(points[i as usize]);
        let mut volume = 0.0;
        for (face, t) in triangles.iter().enumerate() {
            let n = (v(t[1]) - v(t[0])).cross(v(t[2]) - v(t[0]));
            if !(n.length() > 1e-14 * diagonal * diagonal) {
                return Err(CageError::DegenerateFace { face, vertices: *t }.into());
            }
            volume += v(t[0]).dot(v(t[1]).cross(v(t[2]))) / 6.0;
        }
        // Edges: each undirected edge must be run once each way.
        let mut edges: Vec<(u32, u32, u32)> = triangles
            .iter()
            .enumerate()
            .flat_map(|(f, t)| (0..3).map(move |k| (t[k], t[(k + 1) % 3], f as u32)))
            .collect();
        edges.sort_unstable_by_key(|&(a, b, f)| (a.min(b), a.max(b), f));
        let mut i = 0;
        while i < edges.len() {
            let (a, b, f) = edges[i];
            let key = (a.min(b), a.max(b));
            let mut j = i + 1;
            while j < edges.len() && (edges[j].0.min(edges[j].1), edges[j].0.max(edges[j].1)) == key {
                j += 1;
            }
            match j - i {
                1 => return Err(CageError::OpenEdge { a, b, face: f as usize }.into()),
                2 => {
                    let (a2, _, f2) = edges[i + 1];
                    if a2 == a {
                        return Err(CageError::FlippedFace { face: f2 as usize, neighbour: f as usize, a, b }.into());
                    }
                }
                _ => {
                    let faces = edges[i..j].iter().map(|e| e.2).collect();
                    return Err(CageError::NonManifoldEdge { a: key.0, b: key.1, faces }.into());
                }
            }
            i = j;
        }
        if !(volume > 0.0) {
            return Err(CageError::InsideOut { volume }.into());
        }
        Ok(Self { points: points.to_vec(), triangles: triangles.to_vec(), diagonal })
    }

    /// The cage's rest points (as given).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    pub fn n_vertices(&self) -> usize {
        self.points.len()
    }
    /// The diagonal of the cage's bounding box.
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// The mean value coordinates of `x` into `out` (one per cage vertex).
    pub fn coordinates(&self, x: [f64; 3], out: &mut [f64]) {
        raw_coordinates(&self.points, &self.triangles, self.diagonal, DVec3::from_array(x), out);
    }
}

/// The mean value coordinates of one point (see the module docs) with
/// respect to any triangle set (unvalidated; used raw to localise joints).
pub(crate) fn raw_coordinates(points: &[[f64; 3]], triangles: &[[u32; 3]], diagonal: f64, x: DVec3, w: &mut [f64]) {
    w.iter_mut().for_each(|v| *v = 0.0);
    // Directions and distances are recomputed per triangle corner: three
    // normalisations per triangle, no per-point scratch.
    let near = MVC_EPSILON * diagonal;
    for (j, p) in points.iter().enumerate() {
        if DVec3::from_array(*p).distance(x) < near {
            w[j] = 1.0;
            return;
        }
    }
    for t in triangles {
        let mut d = [0.0; 3];
        let mut u = [DVec3::ZERO; 3];
        for k in 0..3 {
            let e = DVec3::from_array(points[t[k] as usize]) - x;
            d[k] = e.length();
            u[k] = e / d[k];
        }
        let mut theta = [0.0; 3];
        for i in 0..3 {
            theta[i] = angle(u[(i + 1) % 3], u[(i + 2) % 3]);
        }
        let h = (theta[0] + theta[1] + theta[2]) / 2.0;
        if std::f64::consts::PI - h < MVC_EPSILON {
            // On the face: barycentric coordinates, nothing else.
            w.iter_mut().for_each(|v| *v = 0.0);
            let mut sum = 0.0;
            for i in 0..3 {
                let b = theta[i].sin() * d[(i + 2) % 3] * d[(i + 1) % 3];
                w[t[i] as usize] = b;
                sum += b;
            }
            for i in 0..3 {
                w[t[i] as usize] /= sum;
            }
            return;
        }
        let sign = u[0].dot(u[1].cross(u[2])).signum();
        let mut c = [0.0; 3];
        let mut s = [0.0; 3];
        let mut planar = false;
        for i in 0..3 {
            let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
            c[i] = 2.0 * h.sin() * (h - theta[i]).sin() / (theta[i1].sin() * theta[i2].sin()) - 1.0;
            s[i] = sign * (1.0 - c[i] * c[i]).max(0.0).sqrt();
            if s[i].abs() <= MVC_EPSILON {
                planar = true;
            }
        }
        if planar {
            continue;
        }
        for i in 0..3 {
            let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
            w[t[i] as usize] += (theta[i] - c[i1] * theta[i2] - c[i2] * theta[i1]) / (d[i] * theta[i1].sin() * s[i2]);
        }
    }
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= sum);
}

/// The angle between unit vectors, from chord lengths: `2 asin(|a − b|/2)`
/// below 90° and `π − 2 asin(|a + b|/2)` above, accurate at both ends
/// (an `asin` near 1 would lose half the digits of an angle near π).
fn angle(a: DVec3, b: DVec3) -> f64 {
    let l = (a - b).length();
    if l <= std::f64::consts::SQRT_2 {
        2.0 * (l / 2.0).min(1.0).asin()
    } else {
        std::f64::consts::PI - 2.0 * ((a + b).length() / 2.0).min(1.0).asin()
    }
}

/// The mean value coordinates `Φ` (dense `#P × #C`, row-major `f64`) of a
/// set of points with respect to a [`Cage`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mvc {
    cage: Cage,
    n_points: usize,
    #[serde(with = "crate::persist::pod")]
    phi: Vec<f64>,
}

impl Mvc {
    /// Validates the cage ([`Cage::new`]) and computes the coordinates of
    /// every point (parallel over points). A non-finite point is refused,
    /// naming it.
    pub fn new(cage_points: &[[f64; 3]], cage_triangles: &[[u32; 3]], points: &[[f64; 3]]) -> Result<Self> {
        Self::with_cage(Cage::new(cage_points, cage_triangles)?, points)
    }

    /// As [`Self::new`] with a validated cage.
    pub fn with_cage(cage: Cage, points: &[[f64; 3]]) -> Result<Self> {
        for (index, p) in points.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(CageError::NonFinite { what: "point", index, value: *p }.into());
            }
        }
        let c = cage.n_vertices();
        // Φ is dense: refuse before allocating what no coarse cage needs.
        let bytes = points.len().saturating_mul(c).saturating_mul(std::mem::size_of::<f64>());
        if c > MAX_CAGE_VERTICES || bytes > MAX_PHI_BYTES {
            return Err(CageError::TooLarge { points: points.len(), cage_vertices: c, bytes }.into());
        }
        // Mean value coordinates interpolate inside the cage; outside they
        // extrapolate, and a cage edit would move such points arbitrarily far.
        // Points on the cage (within 1e-9 of its diagonal) count as inside.
        let outside: Vec<usize> = points
            .par_iter()
            .enumerate()
            .filter(|(_, p)| cage.winding_number(**p) < 0.5 && cage.distance(**p) > 1e-9 * cage.diagonal)
            .map(|(i, _)| i)
            .collect();
        if let Some(&point) = outside.first() {
            return Err(CageError::NotEnclosing { point, position: points[point], outside: outside.len() }.into());
        }
        let mut phi = vec![0.0; points.len() * c];
        if c > 0 {
            phi.par_chunks_mut(c).zip(points.par_iter()).for_each(|(row, p)| {
                raw_coordinates(&cage.points, &cage.triangles, cage.diagonal, DVec3::from_array(*p), row);
            });
        }
        Ok(Self { cage, n_points: points.len(), phi })
    }

    pub fn cage(&self) -> &Cage {
        &self.cage
    }
    /// Number of points (rows of `Φ`).
    pub fn n_points(&self) -> usize {
        self.n_points
    }
    /// Number of cage vertices (columns of `Φ`).
    pub fn n_cage_vertices(&self) -> usize {
        self.cage.n_vertices()
    }
    /// Row `i` of `Φ`: the coordinates of point `i`.
    pub fn row(&self, i: usize) -> &[f64] {
        let c = self.n_cage_vertices();
        &self.phi[i * c..(i + 1) * c]
    }
    /// `Φ`, row-major.
    pub fn matrix(&self) -> &[f64] {
        &self.phi
    }
    /// Heap bytes of `Φ` (8 per entry) and the cage.
    pub fn heap_bytes(&self) -> usize {
        self.phi.len() * 8 + self.cage.points.len() * 24 + self.cage.triangles.len() * 12
    }

    /// `out = Φ · cage` (one point per row), parallel over row blocks.
    /// Fails on counts, naming the array.
    pub fn apply(&self, cage: &[[f64; 3]], out: &mut [[f64; 3]]) -> Result<()> {
        self.check_apply(cage, out)?;
        self.apply_add(cage, None, out);
        Ok(())
    }

    /// `out = base + Φ · cage` (`base` `None`: zero), sizes already checked.
    pub(crate) fn apply_add(&self, cage: &[[f64; 3]], base: Option<&[[f64; 3]]>, out: &mut [[f64; 3]]) {
        let c = self.n_cage_vertices();
        out.par_chunks_mut(ROW_CHUNK).enumerate().for_each(|(chunk, block)| {
            for (k, o) in block.iter_mut().enumerate() {
                let i = chunk * ROW_CHUNK + k;
                let row = &self.phi[i * c..(i + 1) * c];
                let mut acc = base.map_or([0.0; 3], |b| b[i]);
                for (w, q) in row.iter().zip(cage) {
                    acc[0] += w * q[0];
                    acc[1] += w * q[1];
                    acc[2] += w * q[2];
                }
                *o = acc;
            }
        });
    }

    fn check_apply(&self, cage: &[[f64; 3]], out: &[[f64; 3]]) -> Result<()> {
        if cage.len() != self.n_cage_vertices() {
            return Err(
                CageError::Count { what: "cage points", expected: self.n_cage_vertices(), got: cage.len() }.into()
            );
        }
        if out.len() != self.n_points {
            return Err(CageError::Count { what: "output points", expected: self.n_points, got: out.len() }.into());
        }
        Ok(())
    }
}
