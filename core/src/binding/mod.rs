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

pub mod cut;
pub mod locate;
pub mod strip;
pub mod surface;
pub mod trace;
mod view;

use rustc_hash::FxHashMap as HashMap;
use std::time::Instant;

use glam::DVec3;

use crate::cancel::Cancel;
use crate::cholesky::{Cholesky, SymmetricTriplets};
use crate::curvenet::{CurvenetLayout, Side};
use crate::error::{Error, Result, SampleRef, SegmentRef};
use crate::halfedge::INVALID;
use crate::mesh::PolyMesh;
use crate::polygon_laplacian::{DEFAULT_LAMBDA, PolygonScratch, polygon_laplacian};
use crate::sparse::Csr;
pub use cut::{
    CROSSING, CutInput, CutMesh, CutOptions, DETOUR_EDGES, DETOUR_RATIO, Detour, EmbeddingCounts, MESH_VERTEX, SAMPLE,
};
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

/// Something a binding did that the user should know about.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum BindWarning {
    /// A connected component of the mesh touched by no curvenet: its
    /// vertices pass through at the rest pose.
    UntouchedComponent { component: usize, vertices: usize },
    /// Curvenet clusters held inside single faces were removed (too fine for the mesh).
    IslandsRemoved { islands: usize, samples: usize },
    /// Cut-faces of (numerically) zero area were left out of the Laplacian.
    DegenerateCutFaces { count: usize },
    /// Segments whose surface paths meet where there is no shared knot
    /// (`cut::Touch`): a path through another segment's sample or crossing,
    /// two paths crossing inside a face, or two paths over one stretch.
    /// Bound as if the curves met there. `examples` names the first few:
    /// (segment, other, position).
    CurvesTouch { count: usize, examples: Vec<(SegmentRef, SegmentRef, [f64; 3])> },
    /// Input faces folded over themselves in their own plane (strongly
    /// warped polygons) and were split into triangles ([`Surface::split_faces`]).
    FacesSplit { faces: Vec<u32> },
    /// A segment whose surface path is much longer than the segment
    /// (longer than [`DETOUR_RATIO`] × its length + [`DETOUR_EDGES`] mean
    /// edges: its samples project across a concavity or onto the far side
    /// of a thin part), bound along that path; or, with an infinite
    /// `path_length`, one whose samples project onto different mesh
    /// components, left out. `t` is the segment's midpoint as a fraction of
    /// its spline's arc length, `position` that midpoint in the projection
    /// pose.
    SegmentDetour { segment: SegmentRef, t: f64, position: [f64; 3], path_length: f64, segment_length: f64 },
}

impl BindWarning {
    /// How many elements a warning lists at most.
    pub const EXAMPLES: usize = 5;
}

impl std::fmt::Display for BindWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BindWarning::UntouchedComponent { component, vertices } => write!(
                f,
                "mesh component {component} ({vertices} vertices) is touched by no curvenet; its vertices pass through at the rest pose"
            ),
            BindWarning::IslandsRemoved { islands, samples } => {
                write!(f, "{islands} curvenet islands inside single faces were removed ({samples} samples)")
            }
            BindWarning::DegenerateCutFaces { count } => {
                write!(f, "{count} zero-area cut-faces were left out of the Laplacian")
            }
            BindWarning::CurvesTouch { count, examples } => {
                let shown: Vec<String> = examples
                    .iter()
                    .map(|(a, b, [x, y, z])| format!("{a} and {b} at ({x:.4}, {y:.4}, {z:.4})"))
                    .collect();
                write!(
                    f,
                    "{count} point{} where two curves' projections onto the surface meet without a shared knot (a curve drawn across a concavity or a thin part, or two curves drawn close together), bound as if the curves met there: {}{}",
                    if *count == 1 { "" } else { "s" },
                    shown.join("; "),
                    if *count > examples.len() { "; ..." } else { "" }
                )
            }
            BindWarning::FacesSplit { faces } => {
                let shown: Vec<String> = faces.iter().take(10).map(|f| f.to_string()).collect();
                let more = if faces.len() > 10 { format!(" and {} more", faces.len() - 10) } else { String::new() };
                write!(
                    f,
                    "{} faces fold over themselves in their own plane and were split into triangles: {}{more}",
                    faces.len(),
                    shown.join(", ")
                )
            }
            BindWarning::SegmentDetour { segment, t, position, path_length, segment_length } => {
                let [x, y, z] = position;
                if path_length.is_finite() {
                    write!(
                        f,
                        "{segment} at ({x:.4}, {y:.4}, {z:.4}) (spline parameter {t:.3}): its samples project {path_length:.4} apart over the surface for a segment {segment_length:.4} long (the curve bridges a concavity or a thin part there); bound along that path"
                    )
                } else {
                    write!(
                        f,
                        "{segment} at ({x:.4}, {y:.4}, {z:.4}) (spline parameter {t:.3}): its samples project onto two different mesh components; the segment is left out"
                    )
                }
            }
        }
    }
}

/// What a corner takes its value from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Corner {
    /// Unknown `u` (row of `V`'s column space).
    Unknown(u32),
    /// Constraint row `k`.
    Constraint(u32),
    /// A vertex passed through (an untouched component): contributes nothing.
    Fixed,
}

/// A constraint row at a segment–edge crossing: interpolates the slots
/// `lo` (segment tail) and `hi` (segment head) at `t`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CrossingRow {
    pub lo: u32,
    pub hi: u32,
    pub t: f64,
    /// The crossing's cut-vertex.
    pub vertex: u32,
}

/// A curvenet control point bound to the surface: a triangle (index into
/// the surface's triangles), barycentric coordinates of its closest point,
/// and its offset from that point in the triangle's orthonormal frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct KnotBinding {
    pub tri: u32,
    pub bary: [f64; 3],
    pub local: [f64; 3],
}

/// An orthonormal frame of a triangle: (edge direction, in-plane normal to
/// it, triangle normal), or `None` for a degenerate triangle.
pub(crate) fn triangle_frame(a: DVec3, b: DVec3, c: DVec3) -> Option<[DVec3; 3]> {
    let e1 = (b - a).normalize_or_zero();
    let n = (b - a).cross(c - a).normalize_or_zero();
    if e1 == DVec3::ZERO || n == DVec3::ZERO {
        return None;
    }
    Some([e1, n.cross(e1), n])
}

/// Per-curvenet offsets into the concatenated samples, segments and slots.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NetRange {
    pub sample: u32,
    pub segment: u32,
    pub slot: u32,
}

/// Timings of the binding stages, in milliseconds.
#[derive(Debug, Clone, Copy, Default)]
pub struct BindTimings {
    pub surface_ms: f64,
    pub cutting_ms: f64,
    pub assembly_ms: f64,
    pub factor_ms: f64,
}

/// Counts describing a binding (for `curvenet inspect --bind` and logs).
#[derive(Debug, Clone, Copy, Default)]
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
#[derive(Debug, Clone)]
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
    pub(crate) unknown_vertex: Vec<u32>,
    /// Per mesh vertex: its unknown, or INVALID (constrained, fixed or unused).
    pub(crate) vertex_unknown: Vec<u32>,
    /// Per-cut-face Laplacians, row-major, concatenated (`face_start`-aligned squares).
    pub(crate) face_laplacian: Vec<f64>,
    pub(crate) face_laplacian_start: Vec<u32>,
    /// `VᵀL_hC`: unknowns × constraint rows.
    pub(crate) b: Csr,
    pub(crate) factor: Cholesky,
    /// The curvenets, as analysed (owned: a frame evaluates their samples and frames).
    pub(crate) layouts: Vec<CurvenetLayout>,
    /// Global sample of every slot.
    pub(crate) slot_sample: Vec<u32>,
    /// Per global sample: its projected position p̌ (its cut-vertex; the
    /// sample itself when removed with an island) and offset q̌ − p̌.
    pub(crate) sample_projection: Vec<DVec3>,
    pub(crate) sample_offset: Vec<DVec3>,
    /// Per crossing row: X̌ − lerp(p̌_lo, p̌_hi, t), the crossing's rest offset from the chord.
    pub(crate) crossing_offset: Vec<DVec3>,
    /// Per corner: (L_f X̌_f)_j, the Poisson right-hand side of a unit gradient.
    pub(crate) corner_r: Vec<DVec3>,
    /// Mesh vertices on the curvenet and the constraint rows of their corners
    /// (their output is the mean), CSR by `curve_vertex_start`.
    pub(crate) curve_vertices: Vec<u32>,
    pub(crate) curve_vertex_start: Vec<u32>,
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

const TAIL: u8 = 0;
const HEAD: u8 = 1;

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

    /// Like [`Self::new`] with a prepared surface.
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
        // Concatenate the curvenets.
        let mut samples = Vec::new();
        let mut segments = Vec::new();
        let mut sample_ref = Vec::new();
        let mut segment_ref = Vec::new();
        let mut segment_curve = Vec::new();
        let mut n_curves = 0u32;
        let mut nets = Vec::new();
        let mut slot_of: HashMap<(u32, u8, Side), u32> = HashMap::default();
        let mut n_slots = 0u32;
        for (k, layout) in curvenets.iter().enumerate() {
            let curvenet = k as u32;
            let range = NetRange { sample: samples.len() as u32, segment: segments.len() as u32, slot: n_slots };
            nets.push(range);
            samples.extend_from_slice(layout.neutral_samples());
            let first = sample_ref.len();
            sample_ref.extend((0..layout.n_samples() as u32).map(|sample| SampleRef {
                curvenet,
                spline: u32::MAX,
                sample,
            }));
            for seg in layout.sampling().segments() {
                segments.push(seg.samples.map(|i| i + range.sample));
                segment_ref.push(SegmentRef { curvenet, spline: seg.spline, segment: seg.spline_segment });
                segment_curve.push(n_curves + seg.curve);
                for &i in &seg.samples {
                    sample_ref[first + i as usize].spline = seg.spline;
                }
            }
            for (k, slot) in layout.constraints().slots().iter().enumerate() {
                let id = range.slot + k as u32;
                if let Some(s) = slot.outgoing {
                    slot_of.insert((s + range.segment, TAIL, slot.side), id);
                }
                if let Some(s) = slot.incoming {
                    slot_of.insert((s + range.segment, HEAD, slot.side), id);
                }
            }
            n_slots += layout.constraints().len() as u32;
            n_curves += layout.sampling().n_curves() as u32;
        }
        let cut = CutMesh::new(
            &surface,
            CutInput {
                samples: &samples,
                segments: &segments,
                sample_ref: &sample_ref,
                segment_ref: &segment_ref,
                segment_curve: &segment_curve,
                cancel,
            },
            &options.cut,
        )?;
        let mut warnings = Vec::new();
        if !surface.split_faces().is_empty() {
            warnings.push(BindWarning::FacesSplit { faces: surface.split_faces().to_vec() });
        }
        // Strict mode names a stretch first (the graver), else the first point.
        let worst = cut.touches().iter().find(|t| t.stretch).or(cut.touches().first());
        if let Some(first) = worst {
            let at = |t: &cut::Touch| {
                (segment_ref[t.segment as usize], segment_ref[t.other as usize], cut.vertex(t.vertex).pos.to_array())
            };
            if options.strict {
                let (segment, other, _) = at(first);
                let face = match cut.vertex(first.vertex).loc {
                    locate::Location::Face { face, .. } => face,
                    loc => {
                        let mut faces = Vec::new();
                        surface.faces_of(loc, &mut faces);
                        faces.first().copied().unwrap_or(0)
                    }
                };
                return Err(if first.stretch {
                    Error::CurvesOverlap { segment, other }
                } else {
                    Error::CurvesCross { segment, other, face: surface.input_face(face) }
                });
            }
            let touches = cut.touches();
            warnings.push(BindWarning::CurvesTouch {
                count: touches.len(),
                examples: touches.iter().take(BindWarning::EXAMPLES).map(at).collect(),
            });
        }
        for d in cut.detours() {
            let seg = segment_ref[d.segment as usize];
            let layout = curvenets[seg.curvenet as usize];
            let n = layout.sampling().spline_segments(seg.spline as usize).max(1) as f64;
            let [i, j] = segments[d.segment as usize];
            let mid = (DVec3::from_array(samples[i as usize]) + DVec3::from_array(samples[j as usize])) * 0.5;
            let (t, position) = ((seg.segment as f64 + 0.5) / n, mid.to_array());
            let (path_length, segment_length) = (d.path_length, d.segment_length);
            if options.strict {
                return Err(Error::SegmentDetour { segment: seg, t, position, path_length, segment_length });
            }
            warnings.push(BindWarning::SegmentDetour { segment: seg, t, position, path_length, segment_length });
        }
        let t2 = Instant::now();

        // Corners: unknown, slot or crossing row.
        let n_vertices = surface.mesh.n_vertices();
        let mut corner = vec![Corner::Fixed; cut.n_halfedges()];
        let mut crossings: Vec<CrossingRow> = Vec::new();
        let mut crossing_row: HashMap<(u32, u32, Side), u32> = HashMap::default();
        let mut vertex_is_curve = vec![false; n_vertices];
        for h in 0..cut.n_halfedges() as u32 {
            cancel.check_every(h as usize, "assembly")?;
            let v = cut.tail(h);
            let cv = cut.vertex(v);
            if cv.mask & (SAMPLE | CROSSING) == 0 {
                continue; // a plain mesh vertex: decided below
            }
            if cv.mask & MESH_VERTEX != 0 {
                vertex_is_curve[v as usize] = true;
            }
            let (seg, side, end) = curve_side(&cut, h).ok_or_else(|| Error::Internal {
                what: format!("cut-vertex {v} is on the curvenet but no curve halfedge reaches it"),
            })?;
            // A vertex the segment's path passes through takes a crossing row
            // of that segment; one of its samples, the sample's slot.
            let row = match cut.crossing_t(v, seg) {
                Some(t) => {
                    let key = (v, seg, side);
                    match crossing_row.get(&key) {
                        Some(&r) => r,
                        None => {
                            let lo = slot(&slot_of, seg, TAIL, side)?;
                            let hi = slot(&slot_of, seg, HEAD, side)?;
                            let r = n_slots + crossings.len() as u32;
                            crossings.push(CrossingRow { lo, hi, t, vertex: v });
                            crossing_row.insert(key, r);
                            r
                        }
                    }
                }
                None => slot(&slot_of, seg, end, side)?,
            };
            corner[h as usize] = Corner::Constraint(row);
        }

        // Components touched by the curvenet.
        let he = &surface.halfedges;
        let mut touched = vec![false; he.n_components()];
        for h in 0..cut.n_halfedges() as u32 {
            if matches!(corner[h as usize], Corner::Constraint(_)) {
                touched[he.face_component(surface_face(&cut, h)) as usize] = true;
            }
        }
        let mut component_vertices = vec![0usize; he.n_components()];
        let mut vertex_component = vec![INVALID; n_vertices];
        for f in 0..surface.mesh.n_faces() {
            for &v in surface.mesh.face(f) {
                vertex_component[v as usize] = he.face_component(f as u32);
            }
        }
        for v in 0..n_vertices {
            if vertex_component[v] != INVALID {
                component_vertices[vertex_component[v] as usize] += 1;
            }
        }
        for (c, &t) in touched.iter().enumerate() {
            if !t {
                if options.strict {
                    return Err(Error::UntouchedComponent { component: c, vertices: component_vertices[c] });
                }
                warnings.push(BindWarning::UntouchedComponent { component: c, vertices: component_vertices[c] });
            }
        }
        let mut vertex_unknown = vec![INVALID; n_vertices];
        let mut unknown_vertex = Vec::new();
        for v in 0..n_vertices {
            let c = vertex_component[v];
            if c != INVALID && touched[c as usize] && !vertex_is_curve[v] {
                vertex_unknown[v] = unknown_vertex.len() as u32;
                unknown_vertex.push(v as u32);
            }
        }
        for h in 0..cut.n_halfedges() as u32 {
            if corner[h as usize] == Corner::Fixed {
                let v = cut.tail(h);
                let u = vertex_unknown[v as usize];
                if u != INVALID {
                    corner[h as usize] = Corner::Unknown(u);
                }
            }
        }
        let (islands, island_samples) = cut.islands_removed();
        if islands > 0 {
            warnings.push(BindWarning::IslandsRemoved { islands, samples: island_samples });
        }

        // Assembly.
        let n_u = unknown_vertex.len();
        let n_c = n_slots as usize + crossings.len();
        let mut k_entries = Vec::new();
        let mut b_entries: Vec<(u32, u32, f64)> = Vec::new();
        let mut face_laplacian = Vec::new();
        let mut face_laplacian_start = vec![0u32];
        let mut scratch = PolygonScratch::default();
        let mut lf = Vec::new();
        let mut corners = Vec::new();
        let mut degenerate = 0usize;
        for f in 0..cut.n_faces() as u32 {
            cancel.check("assembly")?; // per face: a cut-face's Laplacian costs up to its corners cubed
            let hs = cut.face_halfedges(f);
            corners.clear();
            corners.extend(hs.clone().map(|h| cut.vertex(cut.tail(h)).pos));
            let n = corners.len();
            if polygon_laplacian(&corners, options.lambda, &mut scratch, &mut lf).is_none() {
                degenerate += 1;
                lf.clear();
                lf.resize(n * n, 0.0);
            }
            face_laplacian.extend_from_slice(&lf);
            face_laplacian_start.push(face_laplacian.len() as u32);
            let base = hs.start;
            for j in 0..n {
                let Corner::Unknown(uj) = corner[base as usize + j] else { continue };
                for k in 0..n {
                    let l = lf[j * n + k];
                    if l == 0.0 {
                        continue;
                    }
                    match corner[base as usize + k] {
                        Corner::Unknown(uk) if uk <= uj => k_entries.push((uj, uk, l)),
                        Corner::Constraint(r) => b_entries.push((uj, r, l)),
                        _ => {}
                    }
                }
            }
        }
        if degenerate > 0 {
            warnings.push(BindWarning::DegenerateCutFaces { count: degenerate });
        }
        let b = Csr::from_triplets(n_u, n_c, b_entries);
        cancel.check("the factorisation")?;
        let t3 = Instant::now();
        let factor = if n_u == 0 {
            Cholesky::new(&SymmetricTriplets { n: 0, entries: Vec::new() })?
        } else {
            Cholesky::new(&SymmetricTriplets { n: n_u, entries: k_entries }).map_err(|e| match e {
                Error::NotPositiveDefinite { pivot } => {
                    let at = pivot.and_then(|u| unknown_vertex.get(u)).map_or(String::new(), |&v| {
                        format!(" (first failing pivot at mesh vertex {v}, component {})", vertex_component[v as usize])
                    });
                    Error::Internal {
                        what: format!(
                            "VᵀLV is not positive definite although every unknown's component is constrained{at}"
                        ),
                    }
                }
                other => other,
            })?
        };
        let t4 = Instant::now();
        cancel.check("the factorisation")?;
        let stats = BindStats {
            mesh_vertices: n_vertices,
            mesh_faces: surface.mesh.n_faces(),
            samples: samples.len(),
            segments: segments.len(),
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

        let mut slot_sample = Vec::with_capacity(n_slots as usize);
        for (layout, range) in curvenets.iter().zip(&nets) {
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
        let crossing_offset = crossings
            .iter()
            .map(|c| {
                let (pl, ph) = (
                    sample_projection[slot_sample[c.lo as usize] as usize],
                    sample_projection[slot_sample[c.hi as usize] as usize],
                );
                cut.vertex(c.vertex).pos - pl.lerp(ph, c.t)
            })
            .collect();
        let mut corner_r = vec![DVec3::ZERO; cut.n_halfedges()];
        for f in 0..cut.n_faces() as u32 {
            cancel.check("assembly")?; // per face: a cut-face's Laplacian costs up to its corners cubed
            let hs = cut.face_halfedges(f);
            let n = hs.len();
            let lf = &face_laplacian
                [face_laplacian_start[f as usize] as usize..face_laplacian_start[f as usize + 1] as usize];
            for j in 0..n {
                corner_r[hs.start as usize + j] =
                    (0..n).map(|k| lf[j * n + k] * cut.vertex(cut.tail(hs.start + k as u32)).pos).sum();
            }
        }
        let mut rows_of: Vec<Vec<u32>> = vec![Vec::new(); n_vertices];
        for h in 0..cut.n_halfedges() as u32 {
            let v = cut.tail(h);
            if (v as usize) < n_vertices
                && vertex_is_curve[v as usize]
                && let Corner::Constraint(r) = corner[h as usize]
            {
                rows_of[v as usize].push(r);
            }
        }
        let mut curve_vertices = Vec::new();
        let mut curve_vertex_start = vec![0u32];
        let mut curve_vertex_rows = Vec::new();
        for (v, rows) in rows_of.iter().enumerate() {
            if !rows.is_empty() {
                curve_vertices.push(v as u32);
                curve_vertex_rows.extend_from_slice(rows);
                curve_vertex_start.push(curve_vertex_rows.len() as u32);
            }
        }
        let mut knots = Vec::with_capacity(curvenets.len());
        for layout in curvenets {
            let pool = layout.neutral_pool();
            let mut bound = Vec::with_capacity(pool.len());
            for p in pool {
                let hit = surface.bvh.closest_point(*p)?;
                let tri = hit.triangle;
                let [a, b, c] = surface.triangle_points(tri, &surface.points);
                let offset = DVec3::from_array(*p) - DVec3::from_array(hit.point);
                let local = match triangle_frame(a, b, c) {
                    Some(fr) => [offset.dot(fr[0]), offset.dot(fr[1]), offset.dot(fr[2])],
                    None => offset.to_array(),
                };
                bound.push(KnotBinding { tri, bary: hit.barycentric, local });
            }
            knots.push(bound);
        }
        let orientation_plans = crate::adjust::orientation_plans(&surface, curvenets, &knots)?;
        Ok(Self {
            knots,
            orientation_plans,
            layouts: curvenets.iter().map(|l| (*l).clone()).collect(),
            slot_sample,
            sample_projection,
            sample_offset,
            crossing_offset,
            corner_r,
            curve_vertices,
            curve_vertex_start,
            curve_vertex_rows,
            surface,
            cut,
            nets,
            n_slots: n_slots as usize,
            crossings,
            corner,
            unknown_vertex,
            vertex_unknown,
            face_laplacian,
            face_laplacian_start,
            b,
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
    pub fn face_laplacian(&self, f: u32) -> &[f64] {
        &self.face_laplacian
            [self.face_laplacian_start[f as usize] as usize..self.face_laplacian_start[f as usize + 1] as usize]
    }
    /// The value source of corner (cut halfedge) `h`: `Some(Ok(u))` unknown
    /// `u`, `Some(Err(r))` constraint row `r`, `None` fixed.
    pub fn corner_source(&self, h: u32) -> Option<std::result::Result<u32, u32>> {
        match self.corner[h as usize] {
            Corner::Unknown(u) => Some(Ok(u)),
            Corner::Constraint(r) => Some(Err(r)),
            Corner::Fixed => None,
        }
    }
    /// The mesh vertex of unknown `u`.
    pub fn unknown_vertex(&self, u: u32) -> u32 {
        self.unknown_vertex[u as usize]
    }
    /// Solves `VᵀL_hV x = rhs` for K columns stored per row (see [`Cholesky::solve_in_place`]).
    pub fn solve_in_place<const K: usize>(&self, rhs: &mut [[f64; K]], work: &mut [[f64; K]]) {
        if !rhs.is_empty() {
            self.factor.solve_in_place(rhs, work);
        }
    }
    /// The unknown of mesh vertex `v`, or `None` when it is on the
    /// curvenet, in an untouched component or in no face.
    pub fn vertex_unknown(&self, v: u32) -> Option<u32> {
        let u = self.vertex_unknown[v as usize];
        (u != INVALID).then_some(u)
    }
    /// The projected (closest surface) position p̌ of global sample `i`.
    pub fn sample_projection(&self, i: u32) -> [f64; 3] {
        self.sample_projection[i as usize].to_array()
    }
}

fn ms(a: Instant, b: Instant) -> f64 {
    (b - a).as_secs_f64() * 1e3
}

fn slot(map: &HashMap<(u32, u8, Side), u32>, segment: u32, end: u8, side: Side) -> Result<u32> {
    map.get(&(segment, end, side)).copied().ok_or_else(|| Error::Internal {
        what: format!("no constraint slot for segment {segment} end {end} side {side:?}"),
    })
}

/// The input face of the cut-face of halfedge `h`.
fn surface_face(cut: &CutMesh, h: u32) -> u32 {
    cut.parent(cut.face(h))
}

/// For the corner at `tail(h)`: the curve halfedge bounding its sector (the
/// nearest clockwise, else the nearest counter-clockwise when the mesh
/// boundary intervenes), as (segment, side of the corner, which end of the
/// segment the cut-vertex is: TAIL or HEAD).
fn curve_side(cut: &CutMesh, h: u32) -> Option<(u32, Side, u8)> {
    // Clockwise: g = outgoing, the corner lies to the left of g.
    let mut g = h;
    for _ in 0..cut.n_halfedges() {
        if let Some((s, fwd)) = cut.segment(g) {
            // g leaves the vertex: forward means the vertex is the segment's tail side.
            return Some((s, if fwd { Side::Plus } else { Side::Minus }, if fwd { TAIL } else { HEAD }));
        }
        let t = cut.twin(g);
        if t == INVALID {
            break;
        }
        g = cut.next(t);
        if g == h {
            return None;
        }
    }
    // Counter-clockwise: p = incoming, the corner lies to the left of p.
    let mut g = h;
    for _ in 0..cut.n_halfedges() {
        let p = cut.prev(g);
        if let Some((s, fwd)) = cut.segment(p) {
            // p arrives at the vertex: forward means the vertex is the segment's head side.
            return Some((s, if fwd { Side::Plus } else { Side::Minus }, if fwd { HEAD } else { TAIL }));
        }
        let t = cut.twin(p);
        if t == INVALID || t == h {
            return None;
        }
        g = t;
    }
    None
}

impl Binding {
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
            + bytes(&self.corner_r)
            + bytes(&self.curve_vertices)
            + bytes(&self.curve_vertex_start)
            + bytes(&self.curve_vertex_rows)
            + nested_bytes(&self.knots)
            + bytes(&self.warnings)
    }
}
