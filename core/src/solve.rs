//! The per-frame deformation (paper §4.3, Algorithm 1 lines 4–9), over a
//! [`Binding`]: posed control points → samples → per-side deformation
//! gradients → `f_c` → harmonic solve for `f_v` (Eq. 4) → per-cut-face
//! `F_f` → `y_h` → `x_c` → Poisson solve for `x_v` (Eq. 5). Both solves use
//! the binding's factor of `VᵀL_hV`.
//!
//! A [`Workspace`] holds every buffer a frame needs; [`Binding::deform`]
//! allocates nothing, so one workspace per thread solves frame after frame.
//! Frames are independent: solve many in parallel with one workspace each.

use glam::{DMat3, DVec3};

use crate::adjust::UNCLAIMED;
use crate::binding::Binding;
use crate::binding::rhs::RestFaces;
use crate::curvenet::lanes::{LaneScratch, SlotRows, slot_rows};
use crate::curvenet::{Mat3, ScaledFrame, constraint_gradients_into, deformation_gradients_into, scaled_frames_into};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::mesh::check_finite;

/// Reusable buffers of a frame solve, sized for one binding.
#[derive(Debug, Clone)]
pub struct Workspace {
    samples: Vec<Vec<[f64; 3]>>,
    frames: Vec<Vec<[ScaledFrame; 2]>>,
    gradients: Vec<Vec<[Mat3; 2]>>,
    slot_f: Vec<Mat3>,
    /// The 9-column gradients, one array so that a gather reads either
    /// kind without a branch: rows `..n_unknowns` are the harmonic system's
    /// right-hand side, then its solution f_v (in a group, f_v only when
    /// the frame needs it, see [`Binding::lanes_solve_harmonic`]); rows
    /// `n_unknowns..` are the constraint rows' f_c.
    grad9: Vec<[f64; 9]>,
    n_unknowns: usize,
    xc: Vec<[f64; 3]>,
    rhs3: Vec<[f64; 3]>,
    // Rest-pose state (used when a frame brings its own rest pose).
    tracked: Vec<Vec<[f64; 3]>>,
    rest_samples: Vec<Vec<[f64; 3]>>,
    rest_frames: Vec<Vec<[ScaledFrame; 2]>>,
    rest_cut: Vec<DVec3>,
    rest_corner_r: Vec<DVec3>,
    /// Whether the frame in progress brought its own rest pose.
    rest_mode: bool,
    rest_sample_offset: Vec<DVec3>,
    rest_crossing_offset: Vec<DVec3>,
    // Adjustment state (used when a frame brings adjustments): per curvenet
    // the adjusted pool, the knot orientations, and which adjustment claims
    // each knot (UNCLAIMED between frames).
    adjusted: Vec<Vec<[f64; 3]>>,
    orientations: Vec<Vec<Mat3>>,
    claimed: Vec<Vec<u32>>,
}

impl Binding {
    /// Buffers for [`Self::deform`].
    pub fn workspace(&self) -> Workspace {
        let zero_frame = ScaledFrame::default();
        Workspace {
            samples: self.layouts.iter().map(|l| vec![[0.0; 3]; l.n_samples()]).collect(),
            frames: self.layouts.iter().map(|l| vec![[zero_frame; 2]; l.n_segments()]).collect(),
            gradients: self.layouts.iter().map(|l| vec![[[[0.0; 3]; 3]; 2]; l.n_segments()]).collect(),
            slot_f: vec![[[0.0; 3]; 3]; self.n_slots],
            grad9: vec![[0.0; 9]; self.n_unknowns() + self.n_constraints()],
            n_unknowns: self.n_unknowns(),
            xc: vec![[0.0; 3]; self.n_constraints()],
            rhs3: vec![[0.0; 3]; self.n_unknowns()],
            tracked: self.layouts.iter().map(|l| vec![[0.0; 3]; l.sampling().n_points()]).collect(),
            rest_samples: self.layouts.iter().map(|l| vec![[0.0; 3]; l.n_samples()]).collect(),
            rest_frames: self.layouts.iter().map(|l| vec![[zero_frame; 2]; l.n_segments()]).collect(),
            rest_cut: vec![DVec3::ZERO; self.cut.n_vertices()],
            rest_corner_r: vec![DVec3::ZERO; self.rest_faces.n_corners()],
            rest_mode: false,
            rest_sample_offset: vec![DVec3::ZERO; self.sample_offset.len()],
            rest_crossing_offset: vec![DVec3::ZERO; self.crossings.len()],
            adjusted: self.layouts.iter().map(|l| vec![[0.0; 3]; l.sampling().n_points()]).collect(),
            orientations: self.layouts.iter().map(|l| vec![[[0.0; 3]; 3]; l.sampling().n_knots()]).collect(),
            claimed: self.layouts.iter().map(|l| vec![UNCLAIMED; l.sampling().n_knots()]).collect(),
        }
    }

    /// Number of mesh vertices (the length of a frame's output).
    pub fn n_vertices(&self) -> usize {
        self.surface.mesh.n_vertices()
    }

    /// Number of bound curvenets.
    pub fn n_curvenets(&self) -> usize {
        self.layouts.len()
    }

    /// The control-point count of curvenet `k`'s pool.
    pub fn n_control_points(&self, k: usize) -> usize {
        self.layouts[k].sampling().n_points()
    }

    /// Deforms the mesh for one frame. Writes the deformed points into `out`
    /// (one per mesh vertex) and, if given, the per-vertex deformation
    /// gradients (row-major 3×3) into `gradients`.
    pub fn deform(
        &self,
        input: &Frame<'_>,
        ws: &mut Workspace,
        out: &mut [[f64; 3]],
        gradients: Option<&mut [[f64; 9]]>,
    ) -> Result<()> {
        input.check_binding_only()?;
        self.deform_harmonic_rhs(input, ws, out.len())?;
        // Harmonic solve for f_v (line 6, Eq. 4).
        self.solve_harmonic(ws);
        self.deform_poisson_rhs(ws);
        // Poisson solve for x_v (line 9, Eq. 5).
        self.solve_poisson(ws);
        self.deform_output(input.rest, ws, out, gradients)
    }

    /// A frame up to its first solve: [`Self::deform_constraints`], then the
    /// harmonic right-hand side (in `ws.grad9[..n_unknowns]`).
    pub(crate) fn deform_harmonic_rhs(&self, input: &Frame<'_>, ws: &mut Workspace, n_out: usize) -> Result<()> {
        self.deform_constraints(input, ws, n_out)?;
        self.harmonic_rhs(ws);
        Ok(())
    }

    /// The harmonic right-hand side for f_v (line 6, Eq. 4) from the
    /// constraint rows' f_c, into `ws.grad9[..n_unknowns]`.
    pub(crate) fn harmonic_rhs(&self, ws: &mut Workspace) {
        let (rhs9, fc) = ws.grad9.split_at_mut(ws.n_unknowns);
        rhs9.fill([0.0; 9]);
        self.b.mul_add(fc, rhs9, -1.0);
    }

    /// A frame's constraint rows: checks, the rest pose, the curvenet
    /// deformation, then f_c (in `ws.grad9[n_unknowns..]`) and x_c (in
    /// `ws.xc`). `n_out`: the length of the caller's output.
    pub(crate) fn deform_constraints(&self, input: &Frame<'_>, ws: &mut Workspace, n_out: usize) -> Result<()> {
        self.deform_samples(input, ws, n_out)?;
        self.deform_rows(ws)
    }

    /// The first part of [`Self::deform_constraints`]: checks, the rest
    /// pose, Curvenet Adjustments, and every curvenet's samples (in
    /// `ws.samples`). [`Self::deform_rows`] (one frame) or
    /// [`Self::lanes_rows`] (a group) makes the rows from them.
    pub(crate) fn deform_samples(&self, input: &Frame<'_>, ws: &mut Workspace, n_out: usize) -> Result<()> {
        let posed = input.posed;
        if posed.len() != self.layouts.len() {
            return Err(Error::CountMismatch {
                what: "posed curvenets",
                expected: self.layouts.len(),
                got: posed.len(),
            });
        }
        if n_out != self.n_vertices() {
            return Err(Error::CountMismatch { what: "output points", expected: self.n_vertices(), got: n_out });
        }
        if let Some(rest) = input.rest {
            if rest.len() != self.n_vertices() {
                return Err(Error::CountMismatch {
                    what: "rest-pose points",
                    expected: self.n_vertices(),
                    got: rest.len(),
                });
            }
            check_finite(rest, "rest-pose point")?;
            self.warp_to_rest(rest, ws)?;
        }
        let rest_mode = input.rest.is_some();
        if !input.adjustments.is_empty() {
            self.check_adjustments_with(input.adjustments, &mut ws.claimed)?;
        }
        // Curvenet deformation (Algorithm 1, line 4) and f_c (line 5).
        for (k, layout) in self.layouts.iter().enumerate() {
            if input.adjustments.iter().any(|a| a.curvenet == k) {
                // The Curvenet Adjuster: orientations of the pool posed so
                // far, then the adjusted pool is the one sampled.
                let Workspace { samples, tracked, rest_samples, adjusted, orientations, .. } = &mut *ws;
                let (pool, pool_samples): (&[[f64; 3]], &[[f64; 3]]) = match (posed[k], rest_mode) {
                    (Some(pool), _) => {
                        layout.sampling().samples_into(pool, &mut samples[k])?;
                        (pool, samples[k].as_slice())
                    }
                    (None, false) => (layout.neutral_pool(), layout.neutral_samples()),
                    (None, true) => (tracked[k].as_slice(), rest_samples[k].as_slice()),
                };
                self.adjust_pool_into(
                    k,
                    pool,
                    pool_samples,
                    input.rest,
                    input.adjustments,
                    &mut orientations[k],
                    &mut adjusted[k],
                )?;
                layout.sampling().samples_into(&adjusted[k], &mut samples[k])?;
            } else {
                match (posed[k], rest_mode) {
                    (Some(pool), _) => layout.sampling().samples_into(pool, &mut ws.samples[k])?,
                    (None, false) => ws.samples[k].copy_from_slice(layout.neutral_samples()),
                    (None, true) => ws.samples[k].copy_from_slice(&ws.rest_samples[k]),
                }
            }
        }
        ws.rest_mode = rest_mode;
        Ok(())
    }

    /// The second part of [`Self::deform_constraints`], from the samples:
    /// scaled frames, deformation gradients, then f_c (in
    /// `ws.grad9[n_unknowns..]`) and x_c (in `ws.xc`).
    pub(crate) fn deform_rows(&self, ws: &mut Workspace) -> Result<()> {
        let rest_mode = ws.rest_mode;
        for (k, layout) in self.layouts.iter().enumerate() {
            // A degenerate pose (a collapsed segment, a degenerate
            // intersection) names the curvenet it is in.
            let net = |e| Error::Curvenet { curvenet: k as u32, source: Box::new(e) };
            scaled_frames_into(layout, &ws.samples[k], &mut ws.frames[k]).map_err(net)?;
            let rest_frames = if rest_mode { &ws.rest_frames[k][..] } else { layout.neutral_frames() };
            deformation_gradients_into(layout, rest_frames, &ws.frames[k], &mut ws.gradients[k]).map_err(net)?;
            let range = self.nets[k];
            let slots = range.slot as usize..range.slot as usize + layout.constraints().len();
            constraint_gradients_into(layout.constraints(), &ws.gradients[k], &mut ws.slot_f[slots]).map_err(net)?;
        }
        let (sample_offset, crossing_offset) = if rest_mode {
            (&ws.rest_sample_offset[..], &ws.rest_crossing_offset[..])
        } else {
            (&self.sample_offset[..], &self.crossing_offset[..])
        };
        // Slot rows: F and p = q − F (q̌ − p̌) (line 8).
        let n_u = ws.n_unknowns;
        for (r, f) in ws.slot_f.iter().enumerate() {
            let m = mat(f);
            let sample = self.slot_sample[r] as usize;
            let q = self.posed_sample(ws, sample);
            let p = q - m * sample_offset[sample];
            ws.grad9[n_u + r] = flat(f);
            ws.xc[r] = p.to_array();
        }
        // Crossing rows: interpolated along the segment, plus the crossing's own offset.
        for (c, row) in self.crossings.iter().enumerate() {
            let r = self.n_slots + c;
            let (lo, hi) = (ws.grad9[n_u + row.lo as usize], ws.grad9[n_u + row.hi as usize]);
            let mut f = [0.0; 9];
            for i in 0..9 {
                f[i] = lo[i] + row.t * (hi[i] - lo[i]);
            }
            let p = DVec3::from_array(ws.xc[row.lo as usize]).lerp(DVec3::from_array(ws.xc[row.hi as usize]), row.t)
                + unflat(&f) * crossing_offset[c];
            ws.grad9[n_u + r] = f;
            ws.xc[r] = p.to_array();
        }
        if let Some((r, _)) = ws.xc.iter().enumerate().find(|(_, p)| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFinite { what: "constraint position", index: r, value: ws.xc[r] });
        }
        Ok(())
    }

    /// After the harmonic solve (f_v in `ws.grad9[..n_unknowns]`): y_h via per-cut-face
    /// gradients (line 7) and the Poisson right-hand side (in `ws.rhs3`).
    pub(crate) fn deform_poisson_rhs(&self, ws: &mut Workspace) {
        ws.rhs3.iter_mut().for_each(|x| *x = [0.0; 3]);
        self.b.mul_add(&ws.xc, &mut ws.rhs3, -1.0);
        if !ws.rest_mode {
            // The binding's corner_r: the per-face sums are precomputed
            // into one sparse operator, applied source by source (the same
            // sum regrouped, so equal up to rounding to the face loop below).
            self.gradient_rhs.add_to(&ws.grad9, &mut ws.rhs3);
            return;
        }
        // A frame with its own rest pose: corner_r of that pose, face by
        // face, in the faces' visiting order (`RestFaces`).
        let rf = &self.rest_faces;
        let corner_r = &ws.rest_corner_r[..];
        for i in 0..rf.face.len() {
            let cs = rf.start[i] as usize..rf.start[i + 1] as usize;
            let mut sum = [0.0; 9];
            let mut n = 0.0;
            for &s in &rf.src[cs.clone()] {
                if s == RestFaces::NONE {
                    continue;
                }
                let v = &ws.grad9[s as usize];
                for i in 0..9 {
                    sum[i] += v[i];
                }
                n += 1.0;
            }
            if n == 0.0 {
                continue;
            }
            let ff = unflat(&sum) * (1.0 / n);
            for c in cs {
                // Unknowns add to their own rows; constraint rows and fixed corners to none.
                let d = rf.src[c] as usize;
                if d >= ws.n_unknowns {
                    continue;
                }
                let y = ff * corner_r[c];
                let row = &mut ws.rhs3[d];
                row[0] += y.x;
                row[1] += y.y;
                row[2] += y.z;
            }
        }
    }

    /// After the Poisson solve (x_v in `ws.rhs3`): the output. `rest` is
    /// the frame's rest pose (the one [`Self::deform_harmonic_rhs`] took).
    pub(crate) fn deform_output(
        &self,
        rest: Option<&[[f64; 3]]>,
        ws: &Workspace,
        out: &mut [[f64; 3]],
        gradients: Option<&mut [[f64; 9]]>,
    ) -> Result<()> {
        // Output: unknowns solved, curvenet vertices the mean of their
        // constrained corners, untouched vertices at the rest pose.
        match rest {
            Some(rest) => out.copy_from_slice(rest),
            None => {
                for (v, o) in out.iter_mut().enumerate() {
                    *o = self.surface.points[v].to_array();
                }
            }
        }
        for (u, &v) in self.unknown_vertex.iter().enumerate() {
            out[v.index()] = ws.rhs3[u];
        }
        for (k, &v) in self.curve_vertices.iter().enumerate() {
            let rows =
                &self.curve_vertex_rows[self.curve_vertex_start[k] as usize..self.curve_vertex_start[k + 1] as usize];
            let mean: DVec3 =
                rows.iter().map(|&r| DVec3::from_array(ws.xc[r as usize])).sum::<DVec3>() / rows.len() as f64;
            out[v.index()] = mean.to_array();
        }
        if let Some(g) = gradients {
            if g.len() != out.len() {
                return Err(Error::CountMismatch { what: "output gradients", expected: out.len(), got: g.len() });
            }
            g.iter_mut().for_each(|x| *x = flat(&crate::curvenet::IDENTITY));
            for (u, &v) in self.unknown_vertex.iter().enumerate() {
                g[v.index()] = ws.grad9[u];
            }
            for (k, &v) in self.curve_vertices.iter().enumerate() {
                let rows = &self.curve_vertex_rows
                    [self.curve_vertex_start[k] as usize..self.curve_vertex_start[k + 1] as usize];
                let mut m = [0.0; 9];
                for &r in rows {
                    for i in 0..9 {
                        m[i] += ws.grad9[ws.n_unknowns + r as usize][i] / rows.len() as f64;
                    }
                }
                g[v.index()] = m;
            }
        }
        if let Some((v, p)) = out.iter().enumerate().find(|(_, p)| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFinite { what: "deformed point", index: v, value: *p });
        }
        Ok(())
    }

    /// The curvenet control points of curvenet `k` tracked from the
    /// projection pose to the rest pose `rest` (Elemental's knot tracking):
    /// each point keeps its closest surface point (barycentric) and its
    /// offset from it in the local triangle frame.
    pub fn tracked_pool_into(&self, k: usize, rest: &[[f64; 3]], out: &mut [[f64; 3]]) -> Result<()> {
        let knots = &self.knots[k];
        if out.len() != knots.len() {
            return Err(Error::CountMismatch { what: "tracked control points", expected: knots.len(), got: out.len() });
        }
        for (o, kb) in out.iter_mut().zip(knots) {
            let [a, b, c] = self.surface.triangle_points(kb.tri, rest);
            let base = a * kb.bary[0] + b * kb.bary[1] + c * kb.bary[2];
            *o = (base + kb.offset_on(a, b, c)).to_array();
        }
        Ok(())
    }

    /// Moves the binding's rest-pose state to `rest` (paper §5, "Projection
    /// versus Rest"): cut-vertices by their location on the input mesh, the
    /// curvenet by knot tracking, then the rest scaled frames, the samples'
    /// and crossings' offsets and the Poisson right-hand side of each corner.
    /// The rest samples are those of the tracked knots, so a curvenet that is
    /// not articulated gives F = I and reproduces the rest pose exactly.
    fn warp_to_rest(&self, rest: &[[f64; 3]], ws: &mut Workspace) -> Result<()> {
        for (v, x) in ws.rest_cut.iter_mut().enumerate() {
            *x = self.surface.position_in(self.cut.vertex(v as u32).loc, rest);
        }
        for (k, layout) in self.layouts.iter().enumerate() {
            // A tracked curvenet that degenerates names the rest pose.
            let tracked =
                |e| Error::Curvenet { curvenet: k as u32, source: Box::new(Error::RestPose { source: Box::new(e) }) };
            self.tracked_pool_into(k, rest, &mut ws.tracked[k])?;
            layout.sampling().samples_into(&ws.tracked[k], &mut ws.rest_samples[k]).map_err(tracked)?;
            scaled_frames_into(layout, &ws.rest_samples[k], &mut ws.rest_frames[k]).map_err(tracked)?;
            let base = self.nets[k].sample as usize;
            for (i, q) in ws.rest_samples[k].iter().enumerate() {
                let g = base + i;
                let p = match self.cut.sample_vertex(g as u32) {
                    Some(v) => ws.rest_cut[v as usize],
                    None => DVec3::from_array(*q),
                };
                ws.rest_sample_offset[g] = DVec3::from_array(*q) - p;
            }
        }
        for (c, row) in self.crossings.iter().enumerate() {
            let (lo, hi) = (self.slot_sample[row.lo as usize] as usize, self.slot_sample[row.hi as usize] as usize);
            let p = |g: usize| match self.cut.sample_vertex(g as u32) {
                Some(v) => ws.rest_cut[v as usize],
                None => DVec3::ZERO,
            };
            ws.rest_crossing_offset[c] = ws.rest_cut[row.vertex as usize] - p(lo).lerp(p(hi), row.t);
        }
        // r_h = (L_f X̌_f)_j of every visited corner, in the order the
        // Poisson right-hand side reads them (`RestFaces`).
        let rf = &self.rest_faces;
        // The binding stores the visited faces' Laplacians first, in this
        // order (`RestFaces::laplacians_in_visiting_order`).
        let mut lap = 0;
        for i in 0..rf.face.len() {
            let at = rf.start[i] as usize;
            let n = rf.start[i + 1] as usize - at;
            debug_assert_eq!(self.face_laplacian_start[rf.face[i] as usize] as usize, lap);
            let lf = &self.face_laplacian[lap..lap + n * n];
            lap += n * n;
            let tails = &rf.tail[at..at + n];
            for j in 0..n {
                let mut r = DVec3::ZERO;
                for (k, &t) in tails.iter().enumerate() {
                    r += lf[j * n + k] * ws.rest_cut[t as usize];
                }
                ws.rest_corner_r[at + j] = r;
            }
        }
        Ok(())
    }

    fn posed_sample(&self, ws: &Workspace, global: usize) -> DVec3 {
        // Nets are few: find the one holding this global sample.
        let k = self.nets.iter().rposition(|r| r.sample as usize <= global).unwrap_or(0);
        DVec3::from_array(ws.samples[k][global - self.nets[k].sample as usize])
    }
}

fn mat(m: &Mat3) -> DMat3 {
    DMat3::from_cols_array_2d(m).transpose()
}

fn flat(m: &Mat3) -> [f64; 9] {
    [m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2]]
}

fn unflat(f: &[f64; 9]) -> DMat3 {
    DMat3::from_cols_array(f).transpose()
}

impl Workspace {
    /// Heap bytes held by the workspace's buffers (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::{bytes, nested_bytes};
        nested_bytes(&self.samples)
            + nested_bytes(&self.frames)
            + nested_bytes(&self.gradients)
            + bytes(&self.slot_f)
            + bytes(&self.grad9)
            + bytes(&self.xc)
            + bytes(&self.rhs3)
            + nested_bytes(&self.tracked)
            + nested_bytes(&self.rest_samples)
            + nested_bytes(&self.rest_frames)
            + bytes(&self.rest_cut)
            + bytes(&self.rest_corner_r)
            + bytes(&self.rest_sample_offset)
            + bytes(&self.rest_crossing_offset)
    }
}

/// The right-hand sides and solutions of a group of frames solved together
/// ([`crate::Deformer::frames`]), so that one sweep of each triangular
/// solve, one pass over `B` and one over the gradient operator serve every
/// frame of the group. Rows are in the factor's order (the binding numbers
/// its unknowns so), and each row holds its components lane-interleaved:
/// component `c` of frame `i` at `c · lanes + i`, so that the operators add
/// one weight into every frame's lane with one vector operation. The
/// triangular solves treat every column alike, so the order of the columns
/// within a row is theirs to choose. Frames come in and go out through
/// their workspaces, all frames in one pass over the rows.
#[derive(Debug, Default)]
pub(crate) struct Lanes {
    lanes: usize,
    /// 9 per frame: the unknowns' rows (the harmonic right-hand side, then
    /// f_v), then the constraint rows' f_c, as a workspace's `grad9`.
    grad: Vec<f64>,
    /// 3 per frame: the constraint rows' x_c.
    xc: Vec<f64>,
    /// 3 per frame: the unknowns' Poisson right-hand side, then x_v.
    pos: Vec<f64>,
    /// The curvenet's per-segment values while [`Binding::lanes_rows`]
    /// makes the constraint rows.
    scratch: LaneScratch,
}

/// A frame of a group ([`Lanes`]) holds its workspace.
pub(crate) trait HasWorkspace {
    fn workspace(&mut self) -> &mut Workspace;
}

impl Lanes {
    /// Copies, row by row, every masked frame's `C` values of a row into
    /// (`into_lanes`) or out of its lane of `rows` (`C · lanes` per row);
    /// `field` picks the workspace's rows. Row by row, every frame's value
    /// in turn: a row's cache lines are written (or read) by all frames
    /// while in the cache, each frame's rows stream in order.
    fn copy<const C: usize, S: HasWorkspace>(
        items: &mut [S],
        rows: &mut [f64],
        mask: u32,
        into_lanes: bool,
        field: impl Fn(&mut Workspace) -> &mut [[f64; C]],
    ) {
        let k = items.len();
        let n = rows.len() / (C * k).max(1);
        let mut mine: [&mut [[f64; C]]; crate::sparse::MAX_LANES] = std::array::from_fn(|_| Default::default());
        let mut active = [0usize; crate::sparse::MAX_LANES];
        let mut m = 0;
        for (i, item) in items.iter_mut().enumerate() {
            if mask & (1 << i) != 0 {
                let rows = field(item.workspace());
                assert!(rows.len() >= n, "a workspace's rows");
                mine[m] = &mut rows[..n];
                active[m] = i;
                m += 1;
            }
        }
        let (mine, active) = (&mut mine[..m], &active[..m]);
        if m == k {
            // Every lane: rows of a fixed size for the common group sizes.
            match k {
                2 => return Self::copy_all::<C, 2>(rows, mine, into_lanes),
                4 => return Self::copy_all::<C, 4>(rows, mine, into_lanes),
                8 => return Self::copy_all::<C, 8>(rows, mine, into_lanes),
                16 => return Self::copy_all::<C, 16>(rows, mine, into_lanes),
                _ => {}
            }
        }
        for (r, row) in rows.chunks_exact_mut(C * k).enumerate() {
            for (f, &i) in mine.iter_mut().zip(active) {
                let v = &mut f[r];
                for c in 0..C {
                    if into_lanes {
                        row[c * k + i] = v[c];
                    } else {
                        v[c] = row[c * k + i];
                    }
                }
            }
        }
    }

    /// [`Self::copy`] of all `L` lanes.
    fn copy_all<const C: usize, const L: usize>(rows: &mut [f64], mine: &mut [&mut [[f64; C]]], into_lanes: bool) {
        let mine: &mut [&mut [[f64; C]]; L] = mine.try_into().expect("one workspace per lane");
        let (rows, _) = rows.as_chunks_mut::<L>();
        for (r, row) in rows.chunks_exact_mut(C).enumerate() {
            if into_lanes {
                for (c, lanes) in row.iter_mut().enumerate() {
                    *lanes = std::array::from_fn(|i| mine[i][r][c]);
                }
            } else {
                for (i, f) in mine.iter_mut().enumerate() {
                    f[r] = std::array::from_fn(|c| row[c][i]);
                }
            }
        }
    }
}

/// Whether groups of `k` frames have fixed-width kernels ([`Binding::lanes_rows`]).
fn lanes_fixed(k: usize) -> bool {
    matches!(k, 2 | 4 | 8 | 16)
}

/// The mask of lanes `0..k`.
fn all_lanes(k: usize) -> u32 {
    if k >= 32 { u32::MAX } else { (1 << k) - 1 }
}

/// The mask of the frames that brought their own rest pose.
fn own_rest_lanes<S: HasWorkspace>(items: &mut [S]) -> u32 {
    let mut mask = 0;
    for (i, item) in items.iter_mut().enumerate() {
        if item.workspace().rest_mode {
            mask |= 1 << i;
        }
    }
    mask
}

impl Binding {
    /// Sizes `lanes` for a group of `k` frames (allocating only when it
    /// grows past every group before).
    pub(crate) fn lanes_start(&self, lanes: &mut Lanes, k: usize) {
        assert!((1..=crate::sparse::MAX_LANES).contains(&k), "1 to {} frames in a group", crate::sparse::MAX_LANES);
        debug_assert!(self.factor.in_factor_order(), "rows of the lanes are the factor's");
        let [grad, xc, pos] = self.lanes_lens(k);
        lanes.lanes = k;
        lanes.grad.resize(grad, 0.0);
        lanes.xc.resize(xc, 0.0);
        lanes.pos.resize(pos, 0.0);
        if lanes_fixed(k) {
            lanes.scratch.size(&self.layouts, k);
        }
    }

    /// The lengths of a group's `grad`, `xc` and `pos` for `k` frames: 9
    /// values per frame for every unknown and constraint row, 3 for every
    /// constraint row, 3 for every unknown.
    fn lanes_lens(&self, k: usize) -> [usize; 3] {
        let (u, c) = (self.n_unknowns(), self.n_constraints());
        [(u + c) * 9 * k, c * 3 * k, u * 3 * k]
    }

    /// Heap bytes of a group's block ([`Lanes`], as [`Self::lanes_start`]
    /// sizes it) for `k` frames: 12 values per frame for every unknown and
    /// every constraint row, and the curvenet's per-segment scratch of
    /// [`Self::lanes_rows`] when it runs for `k`.
    pub(crate) fn lanes_bytes(&self, k: usize) -> usize {
        let mut scratch = LaneScratch::default();
        if lanes_fixed(k) {
            scratch.size(&self.layouts, k);
        }
        self.lanes_lens(k).iter().sum::<usize>() * std::mem::size_of::<f64>() + scratch.heap_bytes()
    }

    /// Every frame's constraint rows (f_c and x_c) made in its lane of the
    /// block, as [`Self::deform_rows`] makes them in a workspace (the same
    /// operations in the same order, so the same bits), from the samples
    /// [`Self::deform_samples`] left in each workspace; x_c then goes out to
    /// every workspace (the output reads it) and f_c to those of the frames
    /// in `mask` (their gradients read it). Runs for groups of 2, 4, 8 or 16
    /// frames in the projection pose (no frame with its own rest pose);
    /// returns false,
    /// having changed no workspace, for any other group, and for a group
    /// some frame of which [`Self::deform_rows`] would refuse: the caller
    /// then makes the rows frame by frame and loads them
    /// ([`Self::lanes_load`]), which names the frame and the error.
    pub(crate) fn lanes_rows<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S], mask: u32) -> bool {
        use crate::simd::Simd;
        let k = lanes.lanes;
        if !lanes_fixed(k) || items.len() != k || own_rest_lanes(items) != 0 {
            return false;
        }
        let made = match Simd::detect() {
            // SAFETY: `Simd::detect` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.lanes_rows_avx512(lanes, items) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.lanes_rows_avx2(lanes, items) },
            Simd::Baseline => self.lanes_rows_any(lanes, items),
        };
        if !made {
            return false;
        }
        #[cfg(feature = "counters")]
        crate::counters::lane_rows_made();
        let (k, u) = (lanes.lanes, self.n_unknowns());
        Lanes::copy::<3, S>(items, &mut lanes.xc, all_lanes(k), false, |ws| &mut ws.xc);
        if mask != 0 {
            Lanes::copy::<9, S>(items, &mut lanes.grad[u * 9 * k..], mask, false, |ws| &mut ws.grad9[u..]);
        }
        true
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn lanes_rows_avx512<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) -> bool {
        self.lanes_rows_any(lanes, items)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn lanes_rows_avx2<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) -> bool {
        self.lanes_rows_any(lanes, items)
    }

    #[inline(always)]
    fn lanes_rows_any<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) -> bool {
        match lanes.lanes {
            2 => self.lanes_rows_fixed::<2, S>(lanes, items),
            4 => self.lanes_rows_fixed::<4, S>(lanes, items),
            8 => self.lanes_rows_fixed::<8, S>(lanes, items),
            16 => self.lanes_rows_fixed::<16, S>(lanes, items),
            _ => false,
        }
    }

    /// [`Self::lanes_rows`] for `K` frames: the slot rows curvenet by
    /// curvenet ([`crate::curvenet::lanes`]), then the crossing rows as
    /// [`Self::deform_rows`] interpolates them, then the finiteness check.
    #[inline(always)]
    fn lanes_rows_fixed<const K: usize, S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) -> bool {
        let u = self.n_unknowns();
        let mut wss: [Option<&Workspace>; K] = [None; K];
        for (w, item) in wss.iter_mut().zip(items.iter_mut()) {
            *w = Some(item.workspace());
        }
        let Lanes { grad, xc, scratch, .. } = lanes;
        let (grad, _) = grad[u * 9 * K..].as_chunks_mut::<K>();
        let (xc, _) = xc.as_chunks_mut::<K>();
        for (k, layout) in self.layouts.iter().enumerate() {
            let samples: [&[[f64; 3]]; K] = std::array::from_fn(|i| wss[i].map_or(&[][..], |w| &w.samples[k][..]));
            let rows = SlotRows {
                first_slot: self.nets[k].slot as usize,
                first_sample: self.nets[k].sample as usize,
                slot_sample: &self.slot_sample,
                sample_offset: &self.sample_offset,
                grad: &mut *grad,
                xc: &mut *xc,
            };
            if slot_rows(layout, &samples, scratch, rows).is_err() {
                return false;
            }
        }
        for (c, row) in self.crossings.iter().enumerate() {
            let r = self.n_slots + c;
            let (lo, hi, t) = (row.lo as usize, row.hi as usize, row.t);
            let o = self.crossing_offset[c];
            let mut f = [[0.0; K]; 9];
            for (e, f) in f.iter_mut().enumerate() {
                let (a, b) = (grad[lo * 9 + e], grad[hi * 9 + e]);
                *f = std::array::from_fn(|i| a[i] + t * (b[i] - a[i]));
                grad[r * 9 + e] = *f;
            }
            for comp in 0..3 {
                let (a, b) = (xc[lo * 3 + comp], xc[hi * 3 + comp]);
                xc[r * 3 + comp] = std::array::from_fn(|i| {
                    let lerp = a[i] * (1.0 - t) + b[i] * t;
                    lerp + ((f[comp * 3][i] * o.x + f[comp * 3 + 1][i] * o.y) + f[comp * 3 + 2][i] * o.z)
                });
            }
        }
        let n_rows = self.n_constraints();
        xc[..n_rows * 3].iter().all(|x| x.iter().all(|v| v.is_finite()))
    }

    /// Every frame's constraint rows (f_c and x_c, from
    /// [`Self::deform_constraints`] in its workspace) into its lane.
    pub(crate) fn lanes_load<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) {
        let (k, u) = (lanes.lanes, self.n_unknowns());
        let all = all_lanes(k);
        Lanes::copy::<9, S>(items, &mut lanes.grad[u * 9 * k..], all, true, |ws| &mut ws.grad9[u..]);
        Lanes::copy::<3, S>(items, &mut lanes.xc, all, true, |ws| &mut ws.xc);
    }

    /// Every lane's harmonic right-hand side ([`Self::harmonic_rhs`]) and
    /// solve: f_v. Then f_v out to the workspaces of the frames in `mask`
    /// (those whose output needs it) and of every frame with its own rest
    /// pose ([`Self::lanes_solve_poisson`] makes its Poisson right-hand
    /// side from it); the other workspaces' rows `..n_unknowns` of `grad9`
    /// are left as they were.
    pub(crate) fn lanes_solve_harmonic<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S], mask: u32) {
        let (k, u) = (lanes.lanes, self.n_unknowns());
        let (rhs, fc) = lanes.grad.split_at_mut(u * 9 * k);
        self.b.mul_add_lanes::<9>(fc, rhs, k, -1.0, true);
        self.solve_permuted(9 * k, rhs);
        let mask = mask | own_rest_lanes(items);
        if mask != 0 {
            Lanes::copy::<9, S>(items, rhs, mask, false, |ws| &mut ws.grad9[..u]);
        }
    }

    /// Every lane's Poisson right-hand side as [`Self::deform_poisson_rhs`]
    /// makes it in the projection pose, except that a frame with its own
    /// rest pose (its `r_h` are its own; f_v already in its workspace, see
    /// [`Self::lanes_solve_harmonic`]) makes its own in its workspace;
    /// then the solve, and every frame's x_v out to its workspace.
    pub(crate) fn lanes_solve_poisson<S: HasWorkspace>(&self, lanes: &mut Lanes, items: &mut [S]) {
        let k = lanes.lanes;
        let own = own_rest_lanes(items);
        for (i, item) in items.iter_mut().enumerate() {
            if own & (1 << i) != 0 {
                self.deform_poisson_rhs(item.workspace());
            }
        }
        if own != all_lanes(k) {
            self.b.mul_add_lanes::<3>(&lanes.xc, &mut lanes.pos, k, -1.0, true);
            self.gradient_rhs.add_to_lanes(&lanes.grad, &mut lanes.pos, k);
        }
        if own != 0 {
            Lanes::copy::<3, S>(items, &mut lanes.pos, own, true, |ws| &mut ws.rhs3);
        }
        self.solve_permuted(3 * k, &mut lanes.pos);
        Lanes::copy::<3, S>(items, &mut lanes.pos, all_lanes(k), false, |ws| &mut ws.rhs3);
    }

    /// Solves `VᵀL_hV X = B` for `width` interleaved columns in the
    /// factor's row order ([`crate::cholesky::Cholesky::solve_permuted`]).
    pub(crate) fn solve_permuted(&self, width: usize, rows: &mut [f64]) {
        if self.n_unknowns() > 0 {
            self.factor.solve_permuted(width, rows);
        }
    }
}

impl Binding {
    /// The harmonic solve of one frame ([`Self::deform`]'s first solve).
    /// The factor is in its own order (the binding renumbers its unknowns
    /// so), so the solves need no scratch rows.
    pub(crate) fn solve_harmonic(&self, ws: &mut Workspace) {
        self.solve_in_place(&mut ws.grad9[..ws.n_unknowns], &mut []);
    }
    /// The Poisson solve of one frame ([`Self::deform`]'s second solve).
    pub(crate) fn solve_poisson(&self, ws: &mut Workspace) {
        self.solve_in_place(&mut ws.rhs3, &mut []);
    }
}
