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

use crate::binding::{Binding, Corner};
use crate::curvenet::{Mat3, ScaledFrame, constraint_gradients_into, deformation_gradients_into, scaled_frames_into};
use crate::error::{Error, Result};

/// One frame's input.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameInput<'a> {
    /// The posed control-point pool of each bound curvenet, in binding
    /// order (absolute positions); `None` for a curvenet that is not
    /// articulated this frame, whose knots then track the rest pose.
    pub posed: &'a [Option<&'a [[f64; 3]]>],
    /// The mesh's rest pose this frame (skinning or cloth output, one point
    /// per vertex); `None` for the projection pose.
    pub rest: Option<&'a [[f64; 3]]>,
}

/// Reusable buffers of a frame solve, sized for one binding.
#[derive(Debug, Clone)]
pub struct Workspace {
    samples: Vec<Vec<[f64; 3]>>,
    frames: Vec<Vec<[ScaledFrame; 2]>>,
    gradients: Vec<Vec<[Mat3; 2]>>,
    slot_f: Vec<Mat3>,
    fc: Vec<[f64; 9]>,
    xc: Vec<[f64; 3]>,
    rhs9: Vec<[f64; 9]>,
    work9: Vec<[f64; 9]>,
    rhs3: Vec<[f64; 3]>,
    work3: Vec<[f64; 3]>,
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
            fc: vec![[0.0; 9]; self.n_constraints()],
            xc: vec![[0.0; 3]; self.n_constraints()],
            rhs9: vec![[0.0; 9]; self.n_unknowns()],
            work9: vec![[0.0; 9]; self.n_unknowns()],
            rhs3: vec![[0.0; 3]; self.n_unknowns()],
            work3: vec![[0.0; 3]; self.n_unknowns()],
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
        input: &FrameInput<'_>,
        ws: &mut Workspace,
        out: &mut [[f64; 3]],
        gradients: Option<&mut [[f64; 9]]>,
    ) -> Result<()> {
        let posed = input.posed;
        if input.rest.is_some() {
            return Err(Error::Unsupported { what: "a rest pose other than the projection pose" });
        }
        if posed.len() != self.layouts.len() {
            return Err(Error::CountMismatch { what: "posed curvenets", expected: self.layouts.len(), got: posed.len() });
        }
        if out.len() != self.n_vertices() {
            return Err(Error::CountMismatch { what: "output points", expected: self.n_vertices(), got: out.len() });
        }
        // Curvenet deformation (Algorithm 1, line 4) and f_c (line 5).
        for (k, layout) in self.layouts.iter().enumerate() {
            match posed[k] {
                Some(pool) => layout.sampling().samples_into(pool, &mut ws.samples[k])?,
                None => ws.samples[k].copy_from_slice(layout.neutral_samples()),
            }
            scaled_frames_into(layout, &ws.samples[k], &mut ws.frames[k])?;
            deformation_gradients_into(layout, layout.neutral_frames(), &ws.frames[k], &mut ws.gradients[k])?;
            let range = self.nets[k];
            let slots = range.slot as usize..range.slot as usize + layout.constraints().len();
            constraint_gradients_into(layout.constraints(), &ws.gradients[k], &mut ws.slot_f[slots])?;
        }
        // Slot rows: F and p = q − F (q̌ − p̌) (line 8).
        for (r, f) in ws.slot_f.iter().enumerate() {
            let m = mat(f);
            let sample = self.slot_sample[r] as usize;
            let q = self.posed_sample(ws, sample);
            let p = q - m * self.sample_offset[sample];
            ws.fc[r] = flat(f);
            ws.xc[r] = p.to_array();
        }
        // Crossing rows: interpolated along the segment, plus the crossing's own offset.
        for (c, row) in self.crossings.iter().enumerate() {
            let r = self.n_slots + c;
            let (lo, hi) = (ws.fc[row.lo as usize], ws.fc[row.hi as usize]);
            let mut f = [0.0; 9];
            for i in 0..9 {
                f[i] = lo[i] + row.t * (hi[i] - lo[i]);
            }
            let p = DVec3::from_array(ws.xc[row.lo as usize]).lerp(DVec3::from_array(ws.xc[row.hi as usize]), row.t)
                + unflat(&f) * self.crossing_offset[c];
            ws.fc[r] = f;
            ws.xc[r] = p.to_array();
        }
        if let Some((r, _)) = ws.xc.iter().enumerate().find(|(_, p)| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFinite { what: "constraint position", index: r, value: ws.xc[r] });
        }
        // Harmonic solve for f_v (line 6, Eq. 4).
        ws.rhs9.iter_mut().for_each(|x| *x = [0.0; 9]);
        self.b.mul_add(&ws.fc, &mut ws.rhs9, -1.0);
        self.solve_in_place(&mut ws.rhs9, &mut ws.work9);
        // y_h via per-cut-face gradients (line 7) and the Poisson right-hand side.
        ws.rhs3.iter_mut().for_each(|x| *x = [0.0; 3]);
        self.b.mul_add(&ws.xc, &mut ws.rhs3, -1.0);
        for f in 0..self.cut.n_faces() as u32 {
            let hs = self.cut.face_halfedges(f);
            let mut sum = [0.0; 9];
            let mut n = 0.0;
            for h in hs.clone() {
                let v = match self.corner[h as usize] {
                    Corner::Unknown(u) => &ws.rhs9[u as usize],
                    Corner::Constraint(r) => &ws.fc[r as usize],
                    Corner::Fixed => continue,
                };
                for i in 0..9 {
                    sum[i] += v[i];
                }
                n += 1.0;
            }
            if n == 0.0 {
                continue;
            }
            let ff = unflat(&sum) * (1.0 / n);
            for h in hs {
                if let Corner::Unknown(u) = self.corner[h as usize] {
                    let y = ff * self.corner_r[h as usize];
                    let row = &mut ws.rhs3[u as usize];
                    row[0] += y.x;
                    row[1] += y.y;
                    row[2] += y.z;
                }
            }
        }
        // Poisson solve for x_v (line 9, Eq. 5).
        self.solve_in_place(&mut ws.rhs3, &mut ws.work3);
        // Output: unknowns solved, curvenet vertices the mean of their
        // constrained corners, untouched vertices at the rest pose.
        for (v, o) in out.iter_mut().enumerate() {
            *o = self.surface.points[v].to_array();
        }
        for (u, &v) in self.unknown_vertex.iter().enumerate() {
            out[v as usize] = ws.rhs3[u];
        }
        for (k, &v) in self.curve_vertices.iter().enumerate() {
            let rows = &self.curve_vertex_rows[self.curve_vertex_start[k] as usize..self.curve_vertex_start[k + 1] as usize];
            let mean: DVec3 = rows.iter().map(|&r| DVec3::from_array(ws.xc[r as usize])).sum::<DVec3>() / rows.len() as f64;
            out[v as usize] = mean.to_array();
        }
        if let Some(g) = gradients {
            if g.len() != out.len() {
                return Err(Error::CountMismatch { what: "output gradients", expected: out.len(), got: g.len() });
            }
            g.iter_mut().for_each(|x| *x = flat(&crate::curvenet::IDENTITY));
            for (u, &v) in self.unknown_vertex.iter().enumerate() {
                g[v as usize] = ws.rhs9[u];
            }
            for (k, &v) in self.curve_vertices.iter().enumerate() {
                let rows = &self.curve_vertex_rows[self.curve_vertex_start[k] as usize..self.curve_vertex_start[k + 1] as usize];
                let mut m = [0.0; 9];
                for &r in rows {
                    for i in 0..9 {
                        m[i] += ws.fc[r as usize][i] / rows.len() as f64;
                    }
                }
                g[v as usize] = m;
            }
        }
        if let Some((v, p)) = out.iter().enumerate().find(|(_, p)| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFinite { what: "deformed point", index: v, value: *p });
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
