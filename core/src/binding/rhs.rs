//! Binding stage 6: the maps a frame uses to build its right-hand sides and
//! its output — which sample each slot reads, every sample's projection and
//! rest offset, every crossing row's rest offset from its chord, every
//! corner's Poisson right-hand side of a unit gradient, and the constraint
//! rows of the mesh vertices on the curvenet (whose output is their mean) —
//! and, per curvenet, where its knots sit over the surface (knot tracking).

use glam::DVec3;

use crate::cancel::Cancel;
use crate::curvenet::CurvenetLayout;
use crate::error::Result;
use crate::ids::MeshVertex;

use super::classify::Classified;
use super::cut::CutMesh;
use super::join::Joined;
use super::parts::{Corner, KnotBinding, triangle_frame};
use super::surface::Surface;

/// The right-hand-side maps.
#[derive(Debug)]
pub(crate) struct RhsMaps {
    pub slot_sample: Vec<u32>,
    pub sample_projection: Vec<DVec3>,
    pub sample_offset: Vec<DVec3>,
    pub crossing_offset: Vec<DVec3>,
    pub corner_r: Vec<DVec3>,
    pub curve_vertices: Vec<MeshVertex>,
    pub curve_vertex_start: Vec<u32>,
    pub curve_vertex_rows: Vec<u32>,
}

pub(crate) fn rhs_maps(
    cut: &CutMesh,
    joined: &Joined,
    curvenets: &[&CurvenetLayout],
    classified: &Classified,
    face_laplacian: (&[f64], &[u32]),
    cancel: &Cancel,
) -> Result<RhsMaps> {
    let samples = &joined.samples;
    let mut slot_sample = Vec::with_capacity(joined.n_slots as usize);
    for (layout, range) in curvenets.iter().zip(&joined.nets) {
        slot_sample.extend(layout.constraints().slots().iter().map(|s| s.sample + range.sample));
    }
    let sample_projection: Vec<DVec3> = (0..samples.len() as u32)
        .map(|i| match cut.sample_vertex(i) {
            Some(v) => cut.vertex(v).pos,
            None => DVec3::from_array(samples[i as usize]),
        })
        .collect();
    let sample_offset: Vec<DVec3> =
        samples.iter().zip(&sample_projection).map(|(q, p)| DVec3::from_array(*q) - *p).collect();
    let crossing_offset = classified
        .crossings
        .iter()
        .map(|c| {
            let (pl, ph) = (
                sample_projection[slot_sample[c.lo as usize] as usize],
                sample_projection[slot_sample[c.hi as usize] as usize],
            );
            cut.vertex(c.vertex).pos - pl.lerp(ph, c.t)
        })
        .collect();
    let (laplacian, start) = face_laplacian;
    let mut corner_r = vec![DVec3::ZERO; cut.n_halfedges()];
    for f in 0..cut.n_faces() as u32 {
        cancel.check("assembly")?; // per face: a cut-face's Laplacian costs up to its corners cubed
        let hs = cut.face_halfedges(f);
        let n = hs.len();
        let lf = &laplacian[start[f as usize] as usize..start[f as usize + 1] as usize];
        for j in 0..n {
            corner_r[hs.start as usize + j] =
                (0..n).map(|k| lf[j * n + k] * cut.vertex(cut.tail(hs.start + k as u32)).pos).sum();
        }
    }
    let n_vertices = classified.vertex_is_curve.len();
    let mut rows_of: Vec<Vec<u32>> = vec![Vec::new(); n_vertices];
    for h in 0..cut.n_halfedges() as u32 {
        let v = cut.tail(h) as usize;
        if v < n_vertices
            && classified.vertex_is_curve[v]
            && let Corner::Constraint(r) = classified.corner[h as usize]
        {
            rows_of[v].push(r.0);
        }
    }
    let mut curve_vertices = Vec::new();
    let mut curve_vertex_start = vec![0u32];
    let mut curve_vertex_rows = Vec::new();
    for (v, rows) in rows_of.iter().enumerate() {
        if !rows.is_empty() {
            curve_vertices.push(MeshVertex(v as u32));
            curve_vertex_rows.extend_from_slice(rows);
            curve_vertex_start.push(curve_vertex_rows.len() as u32);
        }
    }
    Ok(RhsMaps {
        slot_sample,
        sample_projection,
        sample_offset,
        crossing_offset,
        corner_r,
        curve_vertices,
        curve_vertex_start,
        curve_vertex_rows,
    })
}

/// Per curvenet, per pool point: its closest surface point (triangle and
/// barycentric coordinates) and its offset from it in the triangle's frame
/// (Elemental's knot tracking carries the knots to a frame's rest pose).
pub(crate) fn bind_knots(surface: &Surface, curvenets: &[&CurvenetLayout]) -> Result<Vec<Vec<KnotBinding>>> {
    let mut knots = Vec::with_capacity(curvenets.len());
    for layout in curvenets {
        let pool = layout.neutral_pool();
        let mut bound = Vec::with_capacity(pool.len());
        for p in pool {
            let hit = surface.bvh.closest_point(*p)?;
            let tri = hit.triangle;
            let [a, b, c] = surface.triangle_points(tri, &surface.points);
            let offset = DVec3::from_array(*p) - DVec3::from_array(hit.point);
            let (local, size) = match triangle_frame(a, b, c) {
                Some((fr, size)) => {
                    ([offset.dot(fr[0]) / size, offset.dot(fr[1]) / size, offset.dot(fr[2]) / size], size)
                }
                None => (offset.to_array(), 0.0),
            };
            bound.push(KnotBinding { tri, bary: hit.barycentric, local, size });
        }
        knots.push(bound);
    }
    Ok(knots)
}

/// The gradient part of the Poisson right-hand side (Algorithm 1, lines
/// 7–8; Eq. 5) as one gather per unknown, for frames in the projection pose.
///
/// Per cut face `f`, `F_f` is the mean of the gradients of its corners that
/// are not fixed (an unknown's `f_v` from the harmonic solve, a constraint
/// row's `f_c`), and every unknown corner `h` of `f` receives `F_f r_h`
/// (`r_h` = `corner_r`). By linearity that is, per unknown `u`,
/// `Σ_s F_s w_us` with `w_us = Σ_{f ∋ u, s} r_{h(f,u)} / n_f` over the faces
/// holding both: a fixed sparse operator, built once per binding. A frame
/// applies it source by source: it streams the sources' gradients in order
/// (each read once, about 7 unknowns fed per source on a triangle mesh)
/// and adds into the unknowns' rows, which are a fraction of the size and
/// local in the factor's numbering. Measured on the 22k hand against the
/// same operator applied unknown by unknown (each reading its sources,
/// whose 72-byte rows missed the cache): 35% fewer `perf` samples in the
/// Poisson right-hand side; against the face loop before it, the loop
/// stalled on scattered loads (a third of its samples on one load on the
/// 94k hand). A frame with its own rest pose has per-frame `r_h` and keeps
/// the face loop ([`Binding::deform_poisson_rhs`](super::Binding)).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(crate) struct GradientRhs {
    /// Entries of source `s` (a row of the workspace's `grad9`: below the
    /// unknowns' count an unknown's `f_v`, then the constraint rows' `f_c`):
    /// `start[s]..start[s + 1]`.
    #[serde(with = "crate::persist::pod")]
    start: Vec<u32>,
    /// Per entry, the unknown it adds to (increasing within a source).
    #[serde(with = "crate::persist::pod")]
    dst: Vec<u32>,
    /// Per entry, `w_us`.
    #[serde(with = "crate::persist::pod")]
    weight: Vec<[f64; 3]>,
}

impl GradientRhs {
    pub(crate) fn new(
        cut: &CutMesh,
        corner: &[Corner],
        corner_r: &[DVec3],
        n_unknowns: usize,
        cancel: &Cancel,
    ) -> Result<Self> {
        let source = |c: Corner| match c {
            Corner::Unknown(u) => Some(u.0),
            Corner::Constraint(r) => Some(n_unknowns as u32 + r.0),
            Corner::Fixed => None,
        };
        // Row lengths before merging: per unknown corner, its face's sources.
        let mut start = vec![0u32; n_unknowns + 1];
        for f in 0..cut.n_faces() as u32 {
            cancel.check_every(f as usize, "assembly")?;
            let hs = cut.face_halfedges(f);
            let n = hs.clone().filter(|&h| source(corner[h as usize]).is_some()).count() as u32;
            for h in hs {
                if let Corner::Unknown(u) = corner[h as usize] {
                    start[u.0 as usize + 1] += n;
                }
            }
        }
        for u in 0..n_unknowns {
            start[u + 1] += start[u];
        }
        let total = start[n_unknowns] as usize;
        let mut src = vec![0u32; total];
        let mut weight = vec![[0.0; 3]; total];
        let mut next = start.clone();
        for f in 0..cut.n_faces() as u32 {
            let hs = cut.face_halfedges(f);
            let n = hs.clone().filter(|&h| source(corner[h as usize]).is_some()).count();
            for h in hs.clone() {
                let Corner::Unknown(u) = corner[h as usize] else { continue };
                let w = corner_r[h as usize] / n as f64;
                for g in hs.clone() {
                    if let Some(s) = source(corner[g as usize]) {
                        let e = next[u.0 as usize] as usize;
                        src[e] = s;
                        weight[e] = w.to_array();
                        next[u.0 as usize] += 1;
                    }
                }
            }
        }
        // Merge each row's repeated sources (a source shares about two faces
        // with its unknown), in place: `slot[s]` is where source `s` went in
        // the row being merged (positions before the row are stale).
        let n_src = src.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
        let mut slot = vec![u32::MAX; n_src];
        let mut out_start = vec![0u32; n_unknowns + 1];
        let mut m = 0usize;
        for u in 0..n_unknowns {
            cancel.check_every(u, "assembly")?;
            let row_begin = m;
            for e in start[u] as usize..start[u + 1] as usize {
                let (s, w) = (src[e], weight[e]);
                let p = slot[s as usize];
                if p != u32::MAX && p as usize >= row_begin {
                    let acc = &mut weight[p as usize];
                    for i in 0..3 {
                        acc[i] += w[i];
                    }
                } else {
                    // m <= e: the entry was read before its place is reused.
                    slot[s as usize] = m as u32;
                    src[m] = s;
                    weight[m] = w;
                    m += 1;
                }
            }
            out_start[u + 1] = m as u32;
        }
        // Transposed: per source, the unknowns it feeds (in unknown order,
        // as the entries are).
        let mut unknown_of = vec![0u32; m];
        for u in 0..n_unknowns {
            unknown_of[out_start[u] as usize..out_start[u + 1] as usize].fill(u as u32);
        }
        let (by_src, order) = crate::sparse::group_by_key(n_src, &src[..m]);
        let dst = order.iter().map(|&e| unknown_of[e as usize]).collect();
        let weight = order.iter().map(|&e| weight[e as usize]).collect();
        Ok(Self { start: by_src, dst, weight })
    }

    /// `rhs3[u] += Σ_s F_s w_us` (`F_s` row-major 3×3, `grad9[s]`: the
    /// unknowns' f_v, then the constraint rows' f_c), source by source.
    #[inline]
    pub(crate) fn add_to(&self, grad9: &[[f64; 9]], rhs3: &mut [[f64; 3]]) {
        use crate::simd::Simd;
        match Simd::detect() {
            // SAFETY: `Simd::detect` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.add_to_avx512(grad9, rhs3) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.add_to_avx2(grad9, rhs3) },
            Simd::Baseline => self.add_to_body(grad9, rhs3),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn add_to_avx512(&self, grad9: &[[f64; 9]], rhs3: &mut [[f64; 3]]) {
        self.add_to_body(grad9, rhs3);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn add_to_avx2(&self, grad9: &[[f64; 9]], rhs3: &mut [[f64; 3]]) {
        self.add_to_body(grad9, rhs3);
    }

    #[inline(always)]
    fn add_to_body(&self, grad9: &[[f64; 9]], rhs3: &mut [[f64; 3]]) {
        for (s, f) in grad9.iter().enumerate().take(self.start.len().saturating_sub(1)) {
            for e in self.start[s] as usize..self.start[s + 1] as usize {
                let w = &self.weight[e];
                let out = &mut rhs3[self.dst[e] as usize];
                for i in 0..3 {
                    out[i] += f[3 * i] * w[0] + f[3 * i + 1] * w[1] + f[3 * i + 2] * w[2];
                }
            }
        }
    }

    /// [`Self::add_to`] for `lanes` frames at once, on lane-interleaved
    /// rows (component `c` of frame `i` at `c · lanes + i`; `grad` 9 ·
    /// `lanes` values per source, `rhs` 3 · `lanes` per unknown): every
    /// entry's weight is read once for all frames and applied with one
    /// vector operation per component. Per frame the same operations in the
    /// same order as [`Self::add_to`], so the same bits.
    pub(crate) fn add_to_lanes(&self, grad: &[f64], rhs: &mut [f64], lanes: usize) {
        use crate::simd::Simd;
        let n_src = self.start.len().saturating_sub(1);
        assert!(lanes > 0 && grad.len() >= n_src * 9 * lanes, "9 · lanes gradients per source");
        match Simd::detect() {
            // SAFETY: `Simd::detect` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.add_to_lanes_avx512(grad, rhs, lanes) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.add_to_lanes_avx2(grad, rhs, lanes) },
            Simd::Baseline => self.add_to_lanes_any(grad, rhs, lanes),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn add_to_lanes_avx512(&self, grad: &[f64], rhs: &mut [f64], lanes: usize) {
        self.add_to_lanes_any(grad, rhs, lanes);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn add_to_lanes_avx2(&self, grad: &[f64], rhs: &mut [f64], lanes: usize) {
        self.add_to_lanes_any(grad, rhs, lanes);
    }

    /// [`Self::add_to_lanes`], compiled for the common group sizes so that
    /// a source's gradients stay in registers over its entries.
    #[inline(always)]
    fn add_to_lanes_any(&self, grad: &[f64], rhs: &mut [f64], lanes: usize) {
        match lanes {
            2 => self.add_to_lanes_fixed::<2>(grad, rhs),
            4 => self.add_to_lanes_fixed::<4>(grad, rhs),
            8 => self.add_to_lanes_fixed::<8>(grad, rhs),
            16 => self.add_to_lanes_fixed::<16>(grad, rhs),
            _ => self.add_to_lanes_dyn(grad, rhs, lanes),
        }
    }

    #[inline(always)]
    fn add_to_lanes_fixed<const L: usize>(&self, grad: &[f64], rhs: &mut [f64]) {
        let (grad, _) = grad.as_chunks::<L>();
        let (rhs, _) = rhs.as_chunks_mut::<L>();
        let n_src = self.start.len().saturating_sub(1);
        for (s, f) in grad.chunks_exact(9).enumerate().take(n_src) {
            let f: [[f64; L]; 9] = std::array::from_fn(|j| f[j]);
            for e in self.start[s] as usize..self.start[s + 1] as usize {
                let w = self.weight[e];
                let d = self.dst[e] as usize;
                for (c, o) in rhs[3 * d..3 * d + 3].iter_mut().enumerate() {
                    let (f0, f1, f2) = (&f[3 * c], &f[3 * c + 1], &f[3 * c + 2]);
                    for i in 0..L {
                        o[i] += f0[i] * w[0] + f1[i] * w[1] + f2[i] * w[2];
                    }
                }
            }
        }
    }

    #[inline(always)]
    fn add_to_lanes_dyn(&self, grad: &[f64], rhs: &mut [f64], lanes: usize) {
        let l = lanes;
        for (s, f) in grad.chunks_exact(9 * l).enumerate().take(self.start.len().saturating_sub(1)) {
            for e in self.start[s] as usize..self.start[s + 1] as usize {
                let w = self.weight[e];
                let d = self.dst[e] as usize;
                let out = &mut rhs[d * 3 * l..(d + 1) * 3 * l];
                for (c, o) in out.chunks_exact_mut(l).enumerate() {
                    let f0 = &f[3 * c * l..(3 * c + 1) * l];
                    let f1 = &f[(3 * c + 1) * l..(3 * c + 2) * l];
                    let f2 = &f[(3 * c + 2) * l..(3 * c + 3) * l];
                    for i in 0..l {
                        o[i] += f0[i] * w[0] + f1[i] * w[1] + f2[i] * w[2];
                    }
                }
            }
        }
    }

    pub(crate) fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.start) + bytes(&self.dst) + bytes(&self.weight)
    }
}

/// The cut faces a frame with its own rest pose visits to make its
/// Poisson right-hand side (paper Eq. 5 with per-frame `r_h`,
/// [`Binding::deform_poisson_rhs`](super::Binding)), with their corners'
/// value sources resolved.
///
/// Faces are visited in the order of their smallest unknown, so that the
/// rows of `f` they read and the rows of the right-hand side they add to
/// come nearly in the order the unknowns are numbered (the factor's):
/// visited in cut-face order, both were scattered over the whole array,
/// and this loop was the largest part of a group of rest-pose frames
/// (docs/performance.md, "Rest-pose frames in the unknowns' order"). Faces without an
/// unknown corner add nothing and are left out. Every frame visits them in
/// this one order, so a frame's bits do not depend on how it is solved
/// (alone or in a group of any size, on any thread).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(crate) struct RestFaces {
    /// The visited faces.
    #[serde(with = "crate::persist::pod")]
    pub face: Vec<u32>,
    /// Corners of visited face `i`: `start[i]..start[i + 1]` into `src` and
    /// `tail`, in the face's halfedge order (also the positions of their
    /// `r_h` in the workspace's per-frame array).
    #[serde(with = "crate::persist::pod")]
    pub start: Vec<u32>,
    /// Per corner, the `grad9` row it reads, or [`RestFaces::NONE`] for a
    /// fixed corner: below the unknowns' count an unknown (the row the
    /// corner also adds to), from there `n_unknowns + r` for constraint
    /// row `r` (which adds to none).
    #[serde(with = "crate::persist::pod")]
    pub src: Vec<u32>,
    /// Per corner, its cut-vertex (the halfedge's tail), whose rest
    /// position the corner's `r_h` reads.
    #[serde(with = "crate::persist::pod")]
    pub tail: Vec<u32>,
}

impl RestFaces {
    pub const NONE: u32 = u32::MAX;

    pub(crate) fn new(cut: &CutMesh, corner: &[Corner], n_unknowns: usize) -> Self {
        let mut faces: Vec<u32> = Vec::new();
        let mut keys: Vec<u32> = Vec::new();
        for f in 0..cut.n_faces() as u32 {
            let first = cut
                .face_halfedges(f)
                .filter_map(|h| match corner[h as usize] {
                    Corner::Unknown(u) => Some(u.0),
                    _ => None,
                })
                .min();
            if let Some(u) = first {
                faces.push(f);
                keys.push(u);
            }
        }
        // Stable by key: faces with the same smallest unknown keep cut-face order.
        let (_, order) = crate::sparse::group_by_key(n_unknowns, &keys);
        let face: Vec<u32> = order.iter().map(|&i| faces[i as usize]).collect();
        let mut start = Vec::with_capacity(face.len() + 1);
        start.push(0u32);
        let (mut src, mut tail) = (Vec::new(), Vec::new());
        for &f in &face {
            for h in cut.face_halfedges(f) {
                tail.push(cut.tail(h));
                src.push(match corner[h as usize] {
                    Corner::Unknown(u) => u.0,
                    Corner::Constraint(r) => n_unknowns as u32 + r.0,
                    Corner::Fixed => Self::NONE,
                });
            }
            start.push(src.len() as u32);
        }
        Self { face, start, src, tail }
    }

    /// The per-face Laplacians `(values, start)` of [`super::assemble`]
    /// (row-major `n_f × n_f` squares, concatenated in cut-face order)
    /// stored again with the visited faces first, in visiting order, then
    /// the others in cut-face order: `start[f]` is where face `f`'s square
    /// begins (no end: its size is the face's), so that a frame with its
    /// own rest pose reads them front to back.
    pub(crate) fn laplacians_in_visiting_order(
        &self,
        cut: &CutMesh,
        values: &[f64],
        start: &[u32],
    ) -> (Vec<f64>, Vec<u32>) {
        let n_faces = cut.n_faces();
        let mut visited = vec![false; n_faces];
        let mut out = Vec::with_capacity(values.len());
        let mut out_start = vec![0u32; n_faces];
        let mut push = |f: usize, out: &mut Vec<f64>| {
            out_start[f] = out.len() as u32;
            out.extend_from_slice(&values[start[f] as usize..start[f + 1] as usize]);
        };
        for &f in &self.face {
            visited[f as usize] = true;
            push(f as usize, &mut out);
        }
        for f in 0..n_faces {
            if !visited[f] {
                push(f, &mut out);
            }
        }
        (out, out_start)
    }

    /// Number of corners of the visited faces.
    pub(crate) fn n_corners(&self) -> usize {
        self.src.len()
    }

    pub(crate) fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.face) + bytes(&self.start) + bytes(&self.src) + bytes(&self.tail)
    }
}

#[cfg(test)]
mod tests {
    use super::GradientRhs;
    use crate::polygon_laplacian::tests::Rng;

    /// Every lane of [`GradientRhs::add_to_lanes`] is bit for bit
    /// [`GradientRhs::add_to`] of its own frame, for every group size and
    /// every vector variant this CPU has (a random operator: sources with
    /// no entries, several entries into one unknown).
    #[test]
    fn lanes_equal_the_one_frame_operator_bit_for_bit() {
        let mut rng = Rng(0xD1B5_4A32_D192_ED03);
        let (n_src, n_dst) = (41, 23);
        let (mut start, mut dst, mut weight) = (vec![0u32], Vec::new(), Vec::new());
        for s in 0..n_src {
            for _ in 0..((rng.next() + 1.0) * 5.0) as usize * (s % 7 != 2) as usize {
                dst.push(((rng.next() + 1.0) * 0.5 * n_dst as f64) as u32);
                weight.push([rng.next(), rng.next() * 1e-3, rng.next() * 1e3]);
            }
            start.push(dst.len() as u32);
        }
        let op = GradientRhs { start, dst, weight };
        for lanes in 1..=crate::sparse::MAX_LANES {
            let grad: Vec<f64> = (0..n_src * 9 * lanes).map(|_| rng.next()).collect();
            let rhs0: Vec<f64> = (0..n_dst * 3 * lanes).map(|_| rng.next()).collect();
            let mut variants: Vec<(&str, Vec<f64>)> = Vec::new();
            let mut rhs = rhs0.clone();
            op.add_to_lanes(&grad, &mut rhs, lanes);
            variants.push(("dispatched", rhs));
            let mut rhs = rhs0.clone();
            op.add_to_lanes_any(&grad, &mut rhs, lanes);
            variants.push(("portable", rhs));
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx2") {
                    let mut rhs = rhs0.clone();
                    // SAFETY: the feature was detected.
                    unsafe { op.add_to_lanes_avx2(&grad, &mut rhs, lanes) };
                    variants.push(("avx2", rhs));
                }
                if std::arch::is_x86_feature_detected!("avx512f") {
                    let mut rhs = rhs0.clone();
                    // SAFETY: the feature was detected.
                    unsafe { op.add_to_lanes_avx512(&grad, &mut rhs, lanes) };
                    variants.push(("avx512", rhs));
                }
            }
            for i in 0..lanes {
                let g: Vec<[f64; 9]> =
                    (0..n_src).map(|s| std::array::from_fn(|c| grad[s * 9 * lanes + c * lanes + i])).collect();
                let mut want: Vec<[f64; 3]> =
                    (0..n_dst).map(|d| std::array::from_fn(|c| rhs0[d * 3 * lanes + c * lanes + i])).collect();
                op.add_to(&g, &mut want);
                for (name, rhs) in &variants {
                    for (d, w) in want.iter().enumerate() {
                        for c in 0..3 {
                            let got = rhs[d * 3 * lanes + c * lanes + i];
                            assert_eq!(
                                got.to_bits(),
                                w[c].to_bits(),
                                "{lanes} lanes, {name}: lane {i}, unknown {d}, component {c}"
                            );
                        }
                    }
                }
            }
        }
    }
}
