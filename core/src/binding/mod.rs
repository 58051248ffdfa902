//! Binding curvenets to a surface (paper §4.1–4.2, Algorithm 1 lines 1–3):
//! the cut-mesh, the cut-aware Laplacian, the matrices `V` and `C`, and the
//! factorisation of `VᵀL_hV`. Built once per (mesh, curvenets, projection
//! pose); immutable and `Send + Sync`, shared by every frame.
//!
//! # Unknowns and constraints
//!
//! Every cut-face corner (= cut halfedge) takes its value either from an
//! unknown (a mesh vertex that is not on the curvenet: a column of `V`) or
//! from a constraint row (a column of `C`), never both, so `V 1 + C 1 = 1`
//! and `VᵀC = 0`. A mesh vertex on the curvenet is constrained (the paper's
//! precedence); its output position is the mean of its corners' constrained
//! positions.
//!
//! Constraint rows are the curvenet's slots (sample × side, one copy per
//! incident segment at curve ends; `curvenet::ConstraintTable`) followed by
//! one row per (crossing cut-vertex, side). The paper maps a segment–edge
//! crossing to its segment's two samples by linear interpolation; we give it
//! a row of its own whose value is that interpolation plus the crossing's
//! own rest offset carried by the interpolated gradient (see `solve`). The
//! paper's form would pull a crossing onto the chord between the samples,
//! so the neutral pose would not reproduce the input mesh (off by the
//! surface's curvature over a segment); with the offset it does, exactly,
//! and so does any rigid motion.
//!
//! Which side of the curvenet a corner is on is read from the cut-mesh by
//! circulating around its cut-vertex to the nearest curve halfedge
//! clockwise: the corner lies to its left. At an intersection this picks the
//! copy of the curve end bounding the corner's sector clockwise.

mod assemble;
mod classify;
pub mod cut;
mod drawing;
mod export;
mod join;
pub(crate) mod knots;
pub mod locate;
mod parts;
pub mod path;
pub(crate) mod rhs;
pub mod strip;
pub mod surface;
pub mod trace;

use std::time::Instant;

use glam::DVec3;

use crate::cancel::Cancel;
use crate::cholesky::Cholesky;
use crate::curvenet::{CurvenetLayout, ScaledFrame, scaled_frames};
use crate::error::{Error, Result};
use crate::ids::{ConstraintRow, CutFace, CutHalfedge, MeshVertex, Unknown};
use crate::mesh::PolyMesh;
use crate::polygon_laplacian::DEFAULT_LAMBDA;
use crate::sparse::Csr;
pub use cut::{
    CROSSING, CutInput, CutMesh, CutOptions, DETOUR_EDGES, DETOUR_RATIO, Detour, EmbeddingCounts, MESH_VERTEX, SAMPLE,
};
pub use export::FrameSystem;
pub use parts::BindWarning;
pub(crate) use parts::{Corner, CrossingRow, KnotBinding, NetRange};
pub use surface::Surface;

/// Options of [`Binding::new`].
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct BindOptions {
    pub cut: CutOptions,
    /// Weight of the `QᵀQ` term of the polygon Laplacian (paper: 1).
    pub lambda: f64,
    /// Refuse what is otherwise bound with a warning: a mesh component no
    /// curvenet touches (its vertices pass through), and segments whose
    /// surface path is a detour ([`BindWarning::SegmentDetour`]).
    pub strict: bool,
    /// Checked between the binding's stages and inside its long loops
    /// (cutting per segment and per face, assembly per face); raised, the
    /// binding returns [`Error::Cancelled`]. The factorisation itself is one
    /// uninterruptible call, checked before and after.
    pub cancel: Cancel,
}

impl Default for BindOptions {
    fn default() -> Self {
        Self { cut: CutOptions::default(), lambda: DEFAULT_LAMBDA, strict: false, cancel: Cancel::default() }
    }
}

impl BindOptions {
    pub fn with_strict(mut self, strict: bool) -> Self {
        self.strict = strict;
        self
    }

    /// Sets the cancellation flag the binding checks.
    pub fn with_cancel(mut self, cancel: Cancel) -> Self {
        self.cancel = cancel;
        self
    }
}

/// Timings of the binding stages, in milliseconds.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct BindTimings {
    pub surface_ms: f64,
    pub cutting_ms: f64,
    pub assembly_ms: f64,
    pub factor_ms: f64,
}

/// Counts describing a binding (for `curvenet inspect --bind` and logs).
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct BindStats {
    pub mesh_vertices: usize,
    pub mesh_faces: usize,
    pub samples: usize,
    pub segments: usize,
    pub cut_vertices: usize,
    pub cut_faces: usize,
    pub cut_halfedges: usize,
    pub cracks: usize,
    pub islands_removed: usize,
    /// How the segments' surface paths were found.
    pub embedding: EmbeddingCounts,
    /// Segments bound along a detour or left out ([`BindWarning::SegmentDetour`]).
    pub detours: usize,
    pub unknowns: usize,
    pub constraints: usize,
    pub factor_nonzeros: usize,
}

/// A curvenet binding: everything a frame solve needs that does not change
/// per frame.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Binding {
    pub(crate) surface: Surface,
    pub(crate) cut: CutMesh,
    pub(crate) nets: Vec<NetRange>,
    /// Total slots over all curvenets (crossing rows follow).
    pub(crate) n_slots: usize,
    pub(crate) crossings: Vec<CrossingRow>,
    /// Per cut halfedge (= corner).
    pub(crate) corner: Vec<Corner>,
    /// Mesh vertex of each unknown.
    pub(crate) unknown_vertex: Vec<MeshVertex>,
    /// Per mesh vertex: its unknown, if any (none: on the curvenet, in an
    /// untouched component or in no face).
    pub(crate) vertex_unknown: Vec<Option<Unknown>>,
    /// Per-cut-face Laplacians, row-major `n_f × n_f` squares, concatenated
    /// with the faces a rest-pose frame visits first, in its visiting order
    /// ([`rhs::RestFaces::laplacians_in_visiting_order`]).
    #[serde(with = "crate::persist::pod")]
    pub(crate) face_laplacian: Vec<f64>,
    /// Per cut-face, where its square starts in `face_laplacian` (its end
    /// is the face's size squared further).
    #[serde(with = "crate::persist::pod")]
    pub(crate) face_laplacian_start: Vec<u32>,
    /// `VᵀL_hC`: unknowns × constraint rows.
    pub(crate) b: Csr,
    pub(crate) factor: Cholesky,
    /// The curvenets, as analysed (owned: a frame evaluates their samples and frames).
    pub(crate) layouts: Vec<CurvenetLayout>,
    /// Global sample of every slot.
    #[serde(with = "crate::persist::pod")]
    pub(crate) slot_sample: Vec<u32>,
    /// Per global sample: its projected position p̌ (its cut-vertex; the
    /// sample itself when removed with an island) and offset q̌ − p̌.
    #[serde(with = "crate::persist::pod")]
    pub(crate) sample_projection: Vec<DVec3>,
    #[serde(with = "crate::persist::pod")]
    pub(crate) sample_offset: Vec<DVec3>,
    /// Per crossing row: X̌ − lerp(p̌_lo, p̌_hi, t), the crossing's rest offset from the chord.
    #[serde(with = "crate::persist::pod")]
    pub(crate) crossing_offset: Vec<DVec3>,
    /// The gradient part of the Poisson right-hand side as a fixed sparse
    /// operator from the gradients to the unknowns (frames in the projection pose; [`rhs::GradientRhs`], built
    /// from every corner's (L_f X̌_f)_j, which the binding does not keep: a
    /// frame with its own rest pose computes its own).
    pub(crate) gradient_rhs: rhs::GradientRhs,
    /// The faces and corners a frame with its own rest pose visits for its
    /// Poisson right-hand side.
    pub(crate) rest_faces: rhs::RestFaces,
    /// Mesh vertices on the curvenet and the constraint rows of their corners
    /// (their output is the mean), CSR by `curve_vertex_start`.
    pub(crate) curve_vertices: Vec<MeshVertex>,
    #[serde(with = "crate::persist::pod")]
    pub(crate) curve_vertex_start: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    pub(crate) curve_vertex_rows: Vec<u32>,
    /// Per curvenet, per pool point: where it sits over the projection-pose
    /// surface (for tracking the knots to a rest pose).
    pub(crate) knots: Vec<Vec<KnotBinding>>,
    /// Per curvenet: the neutral part of its knot orientations (Curvenet Adjuster).
    pub(crate) orientation_plans: Vec<crate::adjust::OrientationPlan>,
    pub(crate) warnings: Vec<BindWarning>,
    pub(crate) stats: BindStats,
    pub(crate) timings: BindTimings,
}

impl Binding {
    /// Binds `curvenets` (analysed against this mesh in the projection pose)
    /// to `mesh` posed at `projection_points`.
    pub fn new(
        mesh: &PolyMesh,
        projection_points: &[[f64; 3]],
        curvenets: &[&CurvenetLayout],
        options: &BindOptions,
    ) -> Result<Self> {
        let t0 = Instant::now();
        options.cancel.check("the surface")?;
        let surface = Surface::new(mesh, projection_points)?;
        let t1 = Instant::now();
        Self::with_surface(surface, curvenets, options, ms(t0, t1))
    }

    /// Like [`Self::new`] with a prepared surface. The stages, one
    /// function each (private modules of `core/src/binding/`): join the
    /// curvenets (`join`) → cut the mesh along them ([`CutMesh::new`]) and
    /// check how they were drawn (`drawing`) → classify the corners and
    /// number the unknowns (`classify`) → assemble the Laplacian and factor
    /// it (`assemble`) → the right-hand-side maps and the knots' bindings
    /// (`rhs`).
    pub fn with_surface(
        surface: Surface,
        curvenets: &[&CurvenetLayout],
        options: &BindOptions,
        surface_ms: f64,
    ) -> Result<Self> {
        if curvenets.is_empty() {
            return Err(Error::Empty { what: "the list of curvenets to bind" });
        }
        let cancel = &options.cancel;
        cancel.check("cutting")?;
        let t1 = Instant::now();
        let joined = join::join(curvenets)?;
        let input = CutInput {
            samples: &joined.samples,
            segments: &joined.segments,
            sample_ref: &joined.sample_ref,
            segment_ref: &joined.segment_ref,
            segment_curve: &joined.segment_curve,
            cancel,
        };
        let cut = CutMesh::new(&surface, input, &options.cut)?;
        let mut warnings = drawing::check_drawing(&surface, &cut, &joined, curvenets, options.strict)?;
        let t2 = Instant::now();

        let mut classified = classify::classify(&surface, &cut, &joined, options.strict, cancel, &mut warnings)?;
        let (islands, island_samples) = cut.islands_removed();
        if islands > 0 {
            warnings.push(BindWarning::IslandsRemoved { islands, samples: island_samples });
        }
        let (n_u, n_c) = (classified.unknown_vertex.len(), classified.n_rows(&joined));
        let mut assembled =
            assemble::assemble(&cut, &classified.corner, (n_u, n_c), options.lambda, cancel, &mut warnings)?;
        cancel.check("the factorisation")?;
        let t3 = Instant::now();
        let factor = assemble::factor(
            std::mem::take(&mut assembled.system),
            &surface,
            &classified.unknown_vertex,
            &classified.vertex_component,
        )?;
        // From here on the unknowns are numbered in the factor's order: the
        // solves need no permutation, and the per-unknown arrays a frame
        // reads are in the order the sweeps visit them (AMD on the
        // spatially numbered system keeps neighbours near each other).
        let (factor, perm) = factor.into_factor_order();
        classified.renumber_unknowns(&perm);
        assembled.b = assembled.b.permute_rows(&perm);
        let t4 = Instant::now();
        cancel.check("the factorisation")?;

        let stats = BindStats {
            mesh_vertices: surface.mesh.n_vertices(),
            mesh_faces: surface.mesh.n_faces(),
            samples: joined.samples.len(),
            segments: joined.segments.len(),
            cut_vertices: cut.n_vertices(),
            cut_faces: cut.n_faces(),
            cut_halfedges: cut.n_halfedges(),
            cracks: cut.n_cracks(),
            islands_removed: islands,
            embedding: cut.embedding(),
            detours: cut.detours().len(),
            unknowns: n_u,
            constraints: n_c,
            factor_nonzeros: factor.nnz(),
        };
        let timings =
            BindTimings { surface_ms, cutting_ms: ms(t1, t2), assembly_ms: ms(t2, t3), factor_ms: ms(t3, t4) };
        let face_laplacian = (&assembled.face_laplacian[..], &assembled.face_laplacian_start[..]);
        let maps = rhs::rhs_maps(&cut, &joined, curvenets, &classified, face_laplacian, cancel)?;
        let gradient_rhs =
            rhs::GradientRhs::new(&cut, &classified.corner, &maps.corner_r, classified.unknown_vertex.len(), cancel)?;
        let rest_faces = rhs::RestFaces::new(&cut, &classified.corner, classified.unknown_vertex.len());
        let (face_laplacian, face_laplacian_start) =
            rest_faces.laplacians_in_visiting_order(&cut, &assembled.face_laplacian, &assembled.face_laplacian_start);
        let knots = rhs::bind_knots(&surface, curvenets)?;
        let orientation_plans = knots::orientation_plans(&surface, curvenets, &knots)?;
        Ok(Self {
            knots,
            orientation_plans,
            layouts: curvenets.iter().map(|l| (*l).clone()).collect(),
            slot_sample: maps.slot_sample,
            sample_projection: maps.sample_projection,
            sample_offset: maps.sample_offset,
            crossing_offset: maps.crossing_offset,
            gradient_rhs,
            rest_faces,
            curve_vertices: maps.curve_vertices,
            curve_vertex_start: maps.curve_vertex_start,
            curve_vertex_rows: maps.curve_vertex_rows,
            surface,
            cut,
            nets: joined.nets,
            n_slots: joined.n_slots as usize,
            crossings: classified.crossings,
            corner: classified.corner,
            unknown_vertex: classified.unknown_vertex,
            vertex_unknown: classified.vertex_unknown,
            face_laplacian,
            face_laplacian_start,
            b: assembled.b,
            factor,
            warnings,
            stats,
            timings,
        })
    }

    pub fn surface(&self) -> &Surface {
        &self.surface
    }
    pub fn cut_mesh(&self) -> &CutMesh {
        &self.cut
    }
    pub fn warnings(&self) -> &[BindWarning] {
        &self.warnings
    }
    pub fn stats(&self) -> BindStats {
        self.stats
    }
    pub fn timings(&self) -> BindTimings {
        self.timings
    }
    /// Number of unknowns (mesh vertices off the curvenet in touched components).
    pub fn n_unknowns(&self) -> usize {
        self.unknown_vertex.len()
    }
    /// Number of constraint rows `n_c` (slots, then crossing rows).
    pub fn n_constraints(&self) -> usize {
        self.n_slots + self.crossings.len()
    }
    /// The Laplacian of cut-face `f` (row-major, `n_f × n_f`).
    pub fn face_laplacian(&self, f: CutFace) -> &[f64] {
        let n = self.cut.face_halfedges(f.0).len();
        let at = self.face_laplacian_start[f.index()] as usize;
        &self.face_laplacian[at..at + n * n]
    }
    /// The value source of corner (cut halfedge) `h`: `Some(Ok(u))` unknown
    /// `u`, `Some(Err(r))` constraint row `r`, `None` fixed.
    pub fn corner_source(&self, h: CutHalfedge) -> Option<std::result::Result<Unknown, ConstraintRow>> {
        match self.corner[h.index()] {
            Corner::Unknown(u) => Some(Ok(u)),
            Corner::Constraint(r) => Some(Err(r)),
            Corner::Fixed => None,
        }
    }
    /// The mesh vertex of unknown `u`.
    pub fn unknown_vertex(&self, u: Unknown) -> MeshVertex {
        self.unknown_vertex[u.index()]
    }
    /// Solves `VᵀL_hV x = rhs` for K columns stored per row (see
    /// [`Cholesky::solve_in_place`]). The factor is in its own order (the
    /// unknowns are numbered so), so `work` is not used and may be empty.
    pub fn solve_in_place<const K: usize>(&self, rhs: &mut [[f64; K]], work: &mut [[f64; K]]) {
        if rhs.is_empty() {
            return;
        }
        // One borrow check of a thread-local per solve when nothing records
        // (no allocation): see [`Binding::frame_system`].
        let recording = SOLVES.with(|r| r.borrow().is_some());
        if recording {
            let before = rhs.as_flattened().to_vec();
            self.factor.solve_in_place(rhs, work);
            let after = rhs.as_flattened().to_vec();
            SOLVES.with(|r| {
                if let Some(list) = r.borrow_mut().as_mut() {
                    list.push(RecordedSolve { columns: K, rhs: before, solution: after });
                }
            });
        } else {
            self.factor.solve_in_place(rhs, work);
        }
    }
    /// The unknown of mesh vertex `v`, or `None` when it is on the
    /// curvenet, in an untouched component or in no face.
    pub fn vertex_unknown(&self, v: MeshVertex) -> Option<Unknown> {
        self.vertex_unknown[v.index()]
    }
    /// The projected (closest surface) position p̌ of global sample `i`.
    pub fn sample_projection(&self, i: u32) -> [f64; 3] {
        self.sample_projection[i as usize].to_array()
    }

    /// The bound curvenets as analysed (neutral samples, frames, topology), in binding order.
    pub fn layouts(&self) -> &[CurvenetLayout] {
        &self.layouts
    }

    /// The first global sample of curvenet `k` (global samples number the
    /// curvenets' samples one curvenet after another, as
    /// [`Binding::sample_projection`] and `CutMesh::sample_vertex` do).
    pub fn sample_offset(&self, k: usize) -> usize {
        self.nets[k].sample as usize
    }

    /// Curvenet `k` as a frame sees it: its samples and the scaled frames
    /// of both sides of every segment (`[segment][Side as usize]`), for the
    /// posed pool `posed`, else the pool tracked to the frame's `rest` pose,
    /// else the neutral pose — the samples and frames [`Binding::deform`]
    /// uses. Fails naming the curvenet when the pool has the wrong length or
    /// the pose is degenerate. For inspection tools (the service's viewer).
    pub fn curvenet_pose(
        &self,
        k: usize,
        posed: Option<&[[f64; 3]]>,
        rest: Option<&[[f64; 3]]>,
    ) -> Result<CurvenetPose> {
        let layout = self.layouts.get(k).ok_or(Error::IndexOutOfRange {
            what: "curvenet pose request",
            index: 0,
            target: "curvenet",
            value: k as u32,
            len: self.layouts.len(),
        })?;
        let samples = match (posed, rest) {
            (Some(pool), _) => layout.sampling().samples(pool)?,
            (None, Some(rest)) => {
                let mut tracked = vec![[0.0; 3]; layout.sampling().n_points()];
                self.tracked_pool_into(k, rest, &mut tracked)?;
                layout.sampling().samples(&tracked)?
            }
            (None, None) => layout.neutral_samples().to_vec(),
        };
        let frames = scaled_frames(layout, &samples)?;
        Ok((samples, frames))
    }
}

/// A curvenet's samples and per-side scaled frames in one pose.
pub type CurvenetPose = (Vec<[f64; 3]>, Vec<[ScaledFrame; 2]>);

/// One triangular solve of a frame, recorded: right-hand side and solution,
/// `columns` values per unknown (interleaved per row, unknown order).
#[derive(Debug, Clone)]
pub(crate) struct RecordedSolve {
    pub columns: usize,
    pub rhs: Vec<f64>,
    pub solution: Vec<f64>,
}

thread_local! {
    /// `Some` while [`Binding::frame_system`] records the solves of one
    /// frame on this thread; `None` (no recording) otherwise.
    pub(crate) static SOLVES: std::cell::RefCell<Option<Vec<RecordedSolve>>> = const { std::cell::RefCell::new(None) };
}

fn ms(a: Instant, b: Instant) -> f64 {
    (b - a).as_secs_f64() * 1e3
}

impl Binding {
    /// Heap bytes of the factor's row copy that the first group of frames
    /// makes (see [`crate::cholesky::Cholesky::row_copy_bytes`]), not in
    /// [`Self::heap_bytes`] until then: callers that budget a binding's
    /// memory before its first group add it.
    pub fn factor_row_copy_bytes(&self) -> usize {
        if self.factor.rows_made() { 0 } else { self.factor.row_copy_bytes() }
    }

    /// Heap bytes held by the binding: the surface, the cut-mesh, the
    /// factor (with its symbolic analysis), the curvenet layouts and every
    /// per-corner, per-sample and per-vertex array. Add `std::mem::size_of::<Binding>()`
    /// for the struct itself when it is boxed or shared.
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::{bytes, nested_bytes};
        self.surface.heap_bytes()
            + self.cut.heap_bytes()
            + bytes(&self.nets)
            + bytes(&self.crossings)
            + bytes(&self.corner)
            + bytes(&self.unknown_vertex)
            + bytes(&self.vertex_unknown)
            + bytes(&self.face_laplacian)
            + bytes(&self.face_laplacian_start)
            + self.b.heap_bytes()
            + self.factor.heap_bytes()
            + bytes(&self.layouts)
            + self.layouts.iter().map(|l| l.heap_bytes()).sum::<usize>()
            + bytes(&self.slot_sample)
            + bytes(&self.sample_projection)
            + bytes(&self.sample_offset)
            + bytes(&self.crossing_offset)
            + self.gradient_rhs.heap_bytes()
            + self.rest_faces.heap_bytes()
            + bytes(&self.curve_vertices)
            + bytes(&self.curve_vertex_start)
            + bytes(&self.curve_vertex_rows)
            + nested_bytes(&self.knots)
            + bytes(&self.warnings)
    }
}
