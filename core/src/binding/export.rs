//! The binding's linear systems as data, for comparing other sparse solvers
//! on exactly the systems a frame solves (`curvenet bench --export`):
//! `VᵀL_hV` as lower-triangle triplets in the unknowns' own order, and one
//! frame's two right-hand sides (Eq. 4: n×9, Eq. 5: n×3) with the solutions
//! the factor gave them.
//!
//! The matrix is re-split from the stored per-cut-face Laplacians through
//! the same function the assembly uses, so it is the matrix that was
//! factored. The right-hand sides and solutions are recorded from the
//! frame's own solve ([`Binding::deform`] runs unchanged; its two calls of
//! [`Binding::solve_in_place`] copy their input and output while a
//! thread-local recorder is set), not recomputed.

use crate::cholesky::{Cholesky, SymmetricTriplets};
use crate::error::{Error, Result};
use crate::frame::Frame;

use super::assemble::split_face;
use super::{Binding, RecordedSolve, SOLVES};

/// One frame's two solves, column-major (`rhs9[c * n + u]` is column c of
/// unknown u), in the unknowns' order.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameSystem {
    /// Unknowns (rows of every array).
    pub n: usize,
    /// Eq. 4's right-hand side `−VᵀL_hC f_c` (n×9: a row-major 3×3 gradient per unknown).
    pub rhs9: Vec<f64>,
    /// Its solution f_v (n×9).
    pub x9: Vec<f64>,
    /// Eq. 5's right-hand side (n×3).
    pub rhs3: Vec<f64>,
    /// Its solution x_v (n×3), the deformed positions of the unknowns.
    pub x3: Vec<f64>,
}

/// Clears the recorder when the frame returns or unwinds.
struct Recording;

impl Recording {
    fn start() -> Self {
        SOLVES.with(|r| *r.borrow_mut() = Some(Vec::new()));
        Recording
    }
    fn take(self) -> Vec<RecordedSolve> {
        SOLVES.with(|r| r.borrow_mut().take()).unwrap_or_default()
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        SOLVES.with(|r| *r.borrow_mut() = None);
    }
}

impl Binding {
    /// The factored matrix `VᵀL_hV`: its lower triangle (`row >= col`) in the
    /// unknowns' order ([`Binding::unknown_vertex`]), duplicates summed,
    /// sorted by column then row.
    pub fn system_matrix(&self) -> SymmetricTriplets {
        let mut entries = Vec::new();
        for f in 0..self.cut.n_faces() as u32 {
            let hs = self.cut.face_halfedges(f);
            let lf = self.face_laplacian(crate::ids::CutFace(f));
            split_face(lf, &self.corner[hs.start as usize..hs.end as usize], &mut entries, None);
        }
        entries.sort_unstable_by_key(|&(r, c, _)| (c, r));
        let mut summed: Vec<(u32, u32, f64)> = Vec::with_capacity(entries.len());
        for (r, c, v) in entries {
            match summed.last_mut() {
                Some(last) if last.0 == r && last.1 == c => last.2 += v,
                _ => summed.push((r, c, v)),
            }
        }
        SymmetricTriplets { n: self.n_unknowns(), entries: summed }
    }

    /// The Cholesky factor of [`Self::system_matrix`] (its size, fill and
    /// ordering; solves go through [`Binding::solve_in_place`]).
    pub fn factor(&self) -> &Cholesky {
        &self.factor
    }

    /// Solves one frame with the curvenets posed as `posed` (as
    /// [`Binding::deform`] takes them, the projection pose as rest pose, no
    /// adjustments) and returns its two linear systems' right-hand sides and
    /// solutions as that solve saw them. Allocates: for export and tests,
    /// not for the frame loop.
    pub fn frame_system(&self, posed: &[Option<&[[f64; 3]]>]) -> Result<FrameSystem> {
        let n = self.n_unknowns();
        let mut ws = self.workspace();
        let mut out = vec![[0.0; 3]; self.n_vertices()];
        let recording = Recording::start();
        self.deform(&Frame { posed, ..Frame::default() }, &mut ws, &mut out, None)?;
        let solves = recording.take();
        if n == 0 {
            return Ok(FrameSystem { n, rhs9: Vec::new(), x9: Vec::new(), rhs3: Vec::new(), x3: Vec::new() });
        }
        let [first, second] = &solves[..] else {
            return Err(Error::Internal { what: format!("a frame made {} triangular solves, not 2", solves.len()) });
        };
        if (first.columns, second.columns) != (9, 3) {
            return Err(Error::Internal {
                what: format!("a frame solved {} then {} columns, not 9 then 3", first.columns, second.columns),
            });
        }
        Ok(FrameSystem {
            n,
            rhs9: column_major(&first.rhs, n, 9),
            x9: column_major(&first.solution, n, 9),
            rhs3: column_major(&second.rhs, n, 3),
            x3: column_major(&second.solution, n, 3),
        })
    }
}

/// Row-interleaved (`k` values per row) to column-major.
fn column_major(rows: &[f64], n: usize, k: usize) -> Vec<f64> {
    let mut out = vec![0.0; n * k];
    for (u, row) in rows.chunks_exact(k).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            out[c * n + u] = v;
        }
    }
    out
}
