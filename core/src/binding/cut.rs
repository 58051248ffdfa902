//! The cut-mesh (paper §4.1): the input mesh with every curvenet segment
//! inserted, its faces split into cut-faces along the segments, possibly
//! with cracks, and islands removed.
//!
//! Construction, face by face: every cut-face lies inside one input face, so
//! each input face is split on its own, in its own plane (the paper's tangent
//! plane of a cut-vertex inside a face). The face's boundary (its corners and
//! the cut-vertices on its edges, counter-clockwise) and the segment pieces
//! inside it (chords) form a planar straight-line graph; sorting each node's
//! neighbours by angle and following "next = the neighbour just clockwise of
//! where we came from" enumerates its faces. A dangling chord is walked out
//! and back by the same loop: a crack, two halfedges of one cut-face. Chord
//! clusters that touch no boundary node are islands and are removed. The
//! per-face loops are then stitched across input edges into one halfedge
//! mesh, so circulating around a cut-vertex crosses from face to face.
//!
//! The connectivity is the crate's one halfedge structure,
//! [`Halfedges`], built from the cut-face loops: halfedges of one cut-face
//! are contiguous, in loop order, so halfedge `h` is also face corner `h`
//! (the corner at `tail(h)`).

use rustc_hash::FxHashMap as HashMap;

use glam::{DVec2, DVec3};

use super::locate::Location;
use super::path::{Path, PathMethod, TraceFailure};
use super::surface::{Surface, segments_cross};
use crate::error::{Error, Result, SampleRef, SegmentRef};
use crate::halfedge::{Halfedges, INVALID};
use crate::sparse::disjoint_root;

/// Cut-vertex bitmask: the cut-vertex is an input mesh vertex.
pub const MESH_VERTEX: u8 = 1;
/// Cut-vertex bitmask: a curvenet sample projects here.
pub const SAMPLE: u8 = 2;
/// Cut-vertex bitmask: a segment crosses a mesh edge (or passes a mesh vertex) here.
pub const CROSSING: u8 = 4;

/// What a cut-vertex carries of the curvenet.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum CurvePoint {
    /// Not on the curvenet.
    None,
    /// The projection of sample `sample` (the first, if several merged).
    Sample(u32),
    /// A point of segment `segment` at arc-length fraction `t` in (0, 1).
    Crossing { segment: u32, t: f64 },
}

/// The curvenet as the cutter needs it: projection-pose sample positions
/// and segments as sample pairs (from sample `[0]` to sample `[1]`), in one
/// numbering over all bound curvenets.
#[derive(Debug, Clone, Copy)]
pub struct CutInput<'a> {
    pub samples: &'a [[f64; 3]],
    pub segments: &'a [[u32; 2]],
    /// Each sample as users number it (curvenet, spline, sample), to name it in errors.
    pub sample_ref: &'a [SampleRef],
    /// Each segment as users number it (curvenet, spline, segment within the spline).
    pub segment_ref: &'a [SegmentRef],
    /// The curve of each segment, numbered across all curvenets (samples of
    /// one curve merging into one cut-vertex is no touch; of two, it is).
    pub segment_curve: &'a [u32],
    /// Checked per sample, segment and face ([`Error::Cancelled`]).
    pub cancel: &'a crate::Cancel,
}

impl CutInput<'_> {
    fn segment(&self, s: u32) -> SegmentRef {
        self.segment_ref.get(s as usize).copied().unwrap_or(SegmentRef { curvenet: 0, spline: u32::MAX, segment: s })
    }
}

/// A segment whose surface path is much longer than the segment itself
/// (its samples project across a concavity or onto the far side of a thin
/// part), or whose samples project onto different connected components (no
/// path exists; the segment is left out of the cut).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Detour {
    /// The segment (global numbering of [`CutInput::segments`]).
    pub segment: u32,
    /// Length of the surface path, or infinity when there is none.
    pub path_length: f64,
    /// Distance between the segment's two samples.
    pub segment_length: f64,
}

/// A surface path is a detour when it is longer than this many times its
/// segment's length, plus [`DETOUR_EDGES`] mean edge lengths.
pub const DETOUR_RATIO: f64 = 3.0;
/// See [`DETOUR_RATIO`].
pub const DETOUR_EDGES: f64 = 2.0;

/// How the segments' surface paths were found (see [`PathMethod`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct EmbeddingCounts {
    /// Samples projecting to one cut-vertex: nothing to insert.
    pub collapsed: usize,
    /// Chords inside one face.
    pub chord: usize,
    /// Straightest paths.
    pub straightest: usize,
    /// Shortest paths in a face strip, after the straightest path missed.
    pub fallback: usize,
    /// Segments left out: their samples project onto different components.
    pub disconnected: usize,
}

/// Options of the cutter.
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub struct CutOptions {
    /// Vertex/edge snapping tolerance relative to the bounding-box diagonal
    /// (paper: 0.001 %).
    pub snap_tolerance: f64,
    /// Largest allowed distance from a sample to the surface, relative to
    /// the bounding-box diagonal.
    pub max_projection_distance: f64,
}

/// The paper's snapping tolerance: 0.001 % of the bounding-box diagonal.
pub const DEFAULT_SNAP_TOLERANCE: f64 = 1e-5;
/// Samples farther than 5 % of the diagonal from the surface are refused.
pub const DEFAULT_MAX_PROJECTION_DISTANCE: f64 = 0.05;

impl Default for CutOptions {
    fn default() -> Self {
        Self { snap_tolerance: DEFAULT_SNAP_TOLERANCE, max_projection_distance: DEFAULT_MAX_PROJECTION_DISTANCE }
    }
}

/// A cut-vertex.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct CutVertex {
    pub loc: Location,
    /// Position in the projection pose.
    pub pos: DVec3,
    /// [`MESH_VERTEX`] | [`SAMPLE`] | [`CROSSING`].
    pub mask: u8,
    pub curve: CurvePoint,
}

/// The cut-mesh. Immutable once built.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CutMesh {
    pub(crate) vertices: Vec<CutVertex>,
    /// The cut-faces as halfedge loops over cut-vertices; a halfedge's twin
    /// is in the same cut-face for a crack, INVALID on the mesh boundary.
    pub(crate) halfedges: Halfedges,
    /// Per halfedge: the curvenet segment it runs along, or INVALID.
    #[serde(with = "crate::persist::pod")]
    pub(crate) segment: Vec<u32>,
    /// Per halfedge: whether it runs in the segment's direction.
    pub(crate) forward: Vec<bool>,
    /// Parent (input) face of every cut-face.
    #[serde(with = "crate::persist::pod")]
    pub(crate) parent: Vec<u32>,
    /// The cut-vertex of every sample, or INVALID when it was removed with an island.
    #[serde(with = "crate::persist::pod")]
    pub(crate) sample_vertex: Vec<u32>,
    pub(crate) n_cracks: usize,
    pub(crate) n_islands_removed: usize,
    pub(crate) n_islands_samples: usize,
    pub(crate) embedding: EmbeddingCounts,
    pub(crate) detours: Vec<Detour>,
    /// Curve points of cut-vertices on more than one segment, beyond their
    /// primary `CutVertex::curve` (see [`Touch`]).
    pub(crate) extra_curve: HashMap<u32, Vec<CurvePoint>>,
    pub(crate) touches: Vec<Touch>,
}

/// Two segments whose surface paths meet at a cut-vertex that is not a
/// shared knot: a path passing through another segment's sample or
/// crossing, or two paths crossing inside a face. Their curves need not
/// touch in space: near a concavity drawn beyond its centre of curvature,
/// or a thin part, closest-point projection folds or swaps curves. The
/// cut-mesh meets them at the cut-vertex as at an intersection, each corner
/// taking the side of the segment nearest it clockwise.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Touch {
    /// The segment whose path reached the vertex, and the one already there
    /// (global numbering of [`CutInput::segments`]).
    pub segment: u32,
    pub other: u32,
    pub vertex: u32,
    /// The two paths run over a stretch from `vertex` (one curve folding
    /// back over itself, or two curves projecting onto one line, as either
    /// side of a thin part does), rather than meeting at a point.
    pub stretch: bool,
}

#[derive(Debug, Clone, Copy)]
struct Piece {
    a: u32,
    b: u32,
    face: u32,
    segment: u32,
    /// Arc-length fractions of `a` and `b` along the segment.
    ta: f64,
    tb: f64,
}

impl CutMesh {
    /// Cuts `surface` by the segments of `input`.
    pub fn new(surface: &Surface, input: CutInput<'_>, options: &CutOptions) -> Result<Self> {
        #[cfg(feature = "counters")]
        crate::counters::cut_mesh_built();
        let tol = options.snap_tolerance * surface.diagonal;
        let mut reg = Registry::new(surface);
        // 1. Where the samples project.
        let limit = options.max_projection_distance * surface.diagonal;
        let mut sample_loc = Vec::with_capacity(input.samples.len());
        for (i, q) in input.samples.iter().enumerate() {
            input.cancel.check_every(i, "cutting")?;
            let hit = surface.bvh.closest_point(*q)?;
            if hit.distance > limit {
                let at = input.sample_ref.get(i).copied().unwrap_or(SampleRef {
                    curvenet: 0,
                    spline: u32::MAX,
                    sample: i as u32,
                });
                return Err(Error::SampleFarFromSurface { at, position: *q, distance: hit.distance, limit });
            }
            let tri = surface.triangles[hit.triangle as usize];
            let p2: DVec2 = (0..3).map(|k| surface.corners_2d[tri[k] as usize] * hit.barycentric[k]).sum();
            sample_loc.push(surface.locate_in_face(hit.face, p2, tol));
        }
        // Segments whose samples land on different components cannot be
        // embedded; a sample none of whose segments can is left out too.
        let component = |loc: Location| {
            let mut faces = Vec::new();
            surface.faces_of(loc, &mut faces);
            surface.components.of_face(faces[0])
        };
        let sample_component: Vec<u32> = sample_loc.iter().map(|&l| component(l)).collect();
        let mut detours = Vec::new();
        let mut embedding = EmbeddingCounts::default();
        let mut sample_used = vec![false; input.samples.len()];
        let mut segment_embedded = vec![true; input.segments.len()];
        for (s, &[i, j]) in input.segments.iter().enumerate() {
            if sample_component[i as usize] == sample_component[j as usize] {
                sample_used[i as usize] = true;
                sample_used[j as usize] = true;
            } else {
                segment_embedded[s] = false;
                embedding.disconnected += 1;
                let length = (DVec3::from_array(input.samples[i as usize])
                    - DVec3::from_array(input.samples[j as usize]))
                .length();
                detours.push(Detour { segment: s as u32, path_length: f64::INFINITY, segment_length: length });
            }
        }
        // A segment of each sample, to name touches.
        let mut sample_segment = vec![INVALID; input.samples.len()];
        for (s, seg) in input.segments.iter().enumerate() {
            for &i in seg {
                if sample_segment[i as usize] == INVALID {
                    sample_segment[i as usize] = s as u32;
                }
            }
        }
        let mut sample_vertex = Vec::with_capacity(input.samples.len());
        for (i, &loc) in sample_loc.iter().enumerate() {
            if !sample_used[i] {
                sample_vertex.push(INVALID);
                continue;
            }
            let cv = reg.insert(loc, tol);
            let v = &mut reg.vertices[cv as usize];
            match v.curve {
                CurvePoint::Sample(j) if v.mask & SAMPLE != 0 => {
                    // Samples of two different curves projecting to one point touch there.
                    let (si, sj) = (sample_segment[i], sample_segment[j as usize]);
                    let curve = |s: u32| input.segment_curve.get(s as usize).copied();
                    if si != INVALID && sj != INVALID && curve(si) != curve(sj) {
                        reg.touches.push(Touch { segment: si, other: sj, vertex: cv, stretch: false });
                    }
                }
                _ => {
                    if v.mask & (SAMPLE | CROSSING) == 0 {
                        v.curve = CurvePoint::Sample(i as u32);
                    }
                }
            }
            let v = &mut reg.vertices[cv as usize];
            v.mask |= SAMPLE;
            sample_vertex.push(cv);
        }
        // 2. Segments.
        let mut pieces = Vec::new();
        let mut path = Path::default();
        let mut pos: Vec<DVec3> = Vec::new();
        for (s, &[i, j]) in input.segments.iter().enumerate() {
            input.cancel.check_every(s, "cutting")?;
            if !segment_embedded[s] {
                continue;
            }
            let (ca, cb) = (sample_vertex[i as usize], sample_vertex[j as usize]);
            if ca == cb {
                embedding.collapsed += 1;
                continue; // both samples project to one point: nothing to insert
            }
            let (la, lb) = (reg.vertices[ca as usize].loc, reg.vertices[cb as usize].loc);
            let method = super::trace::trace(surface, la, lb, tol, &mut path).map_err(|why| match why {
                TraceFailure::Disconnected | TraceFailure::LeftTheSurface | TraceFailure::Lost => {
                    Error::SegmentNotTraced { segment: input.segment(s as u32) }
                }
            })?;
            match method {
                PathMethod::Chord => embedding.chord += 1,
                PathMethod::Straightest => embedding.straightest += 1,
                PathMethod::Fallback => embedding.fallback += 1,
            }
            // Arc-length fractions of the path points.
            pos.clear();
            pos.extend(path.points.iter().map(|&l| surface.position(l)));
            let total: f64 = pos.windows(2).map(|w| (w[1] - w[0]).length()).sum();
            let length =
                (DVec3::from_array(input.samples[i as usize]) - DVec3::from_array(input.samples[j as usize])).length();
            if total > DETOUR_RATIO * length + DETOUR_EDGES * surface.mean_edge_length {
                detours.push(Detour { segment: s as u32, path_length: total, segment_length: length });
            }
            let mut prev = ca;
            let mut t_prev = 0.0;
            let mut acc = 0.0;
            for k in 1..path.points.len() {
                acc += (pos[k] - pos[k - 1]).length();
                let t = if k + 1 == path.points.len() { 1.0 } else { acc / total };
                let cv = if k + 1 == path.points.len() {
                    cb
                } else {
                    let cv = reg.insert(path.points[k], tol);
                    let point = CurvePoint::Crossing { segment: s as u32, t };
                    if reg.vertices[cv as usize].mask & (SAMPLE | CROSSING) != 0 {
                        // Another segment's sample or crossing: the paths touch here.
                        let other = reg.segment_at(cv, input);
                        reg.touches.push(Touch { segment: s as u32, other, vertex: cv, stretch: false });
                        reg.extra.entry(cv).or_default().push(point);
                    } else {
                        reg.vertices[cv as usize].curve = point;
                    }
                    reg.vertices[cv as usize].mask |= CROSSING;
                    cv
                };
                if cv != prev {
                    pieces.push(Piece {
                        a: prev,
                        b: cv,
                        face: path.faces[k - 1],
                        segment: s as u32,
                        ta: t_prev,
                        tb: t,
                    });
                }
                prev = cv;
                t_prev = t;
            }
        }
        let mut cut = reg.build(surface, input, pieces, sample_vertex)?;
        cut.embedding = embedding;
        cut.detours = detours;
        Ok(cut)
    }

    pub fn n_vertices(&self) -> usize {
        self.vertices.len()
    }
    pub fn n_halfedges(&self) -> usize {
        self.halfedges.n_halfedges()
    }
    pub fn n_faces(&self) -> usize {
        self.parent.len()
    }
    pub fn vertex(&self, v: u32) -> &CutVertex {
        &self.vertices[v as usize]
    }
    /// The cut-mesh's connectivity (its navigation is also offered below,
    /// as the cut-mesh's own: `cut.tail(h)` is `cut.halfedges().tail(h)`).
    pub fn halfedges(&self) -> &Halfedges {
        &self.halfedges
    }
    pub fn tail(&self, h: u32) -> u32 {
        self.halfedges.tail(h)
    }
    pub fn head(&self, h: u32) -> u32 {
        self.halfedges.head(h)
    }
    pub fn next(&self, h: u32) -> u32 {
        self.halfedges.next(h)
    }
    pub fn prev(&self, h: u32) -> u32 {
        self.halfedges.prev(h)
    }
    pub fn twin(&self, h: u32) -> u32 {
        self.halfedges.twin(h)
    }
    pub fn face(&self, h: u32) -> u32 {
        self.halfedges.face(h)
    }
    /// The halfedges (= corners) of cut-face `f`, in loop order.
    pub fn face_halfedges(&self, f: u32) -> std::ops::Range<u32> {
        self.halfedges.face_halfedges(f)
    }
    /// The input face cut-face `f` lies in.
    pub fn parent(&self, f: u32) -> u32 {
        self.parent[f as usize]
    }
    /// The segment halfedge `h` runs along and whether it runs forward, if any.
    pub fn segment(&self, h: u32) -> Option<(u32, bool)> {
        let s = self.segment[h as usize];
        (s != INVALID).then(|| (s, self.forward[h as usize]))
    }
    /// The cut-vertex of sample `i`, if it was not removed with an island.
    pub fn sample_vertex(&self, i: u32) -> Option<u32> {
        let v = self.sample_vertex[i as usize];
        (v != INVALID).then_some(v)
    }
    /// Number of cracks: edges whose two halfedges bound the same cut-face.
    pub fn n_cracks(&self) -> usize {
        self.n_cracks
    }
    /// Number of islands (chord clusters inside one face) removed, and the samples they held.
    pub fn islands_removed(&self) -> (usize, usize) {
        (self.n_islands_removed, self.n_islands_samples)
    }
    /// How the segments' surface paths were found.
    pub fn embedding(&self) -> EmbeddingCounts {
        self.embedding
    }
    /// Segments with a surface path much longer than themselves, or none.
    pub fn detours(&self) -> &[Detour] {
        &self.detours
    }
    /// Where two segments' paths meet at a cut-vertex that is not a shared knot.
    pub fn touches(&self) -> &[Touch] {
        &self.touches
    }
    /// Every curve point of cut-vertex `v`: its primary one, then those of
    /// further segments whose paths reach it (see [`Touch`]).
    pub fn curve_points(&self, v: u32) -> impl Iterator<Item = CurvePoint> + '_ {
        std::iter::once(self.vertices[v as usize].curve).chain(self.extra_curve.get(&v).into_iter().flatten().copied())
    }
    /// The arc-length fraction at which segment `segment` crosses cut-vertex
    /// `v`, if its path passes through `v` (not at one of its samples).
    pub fn crossing_t(&self, v: u32, segment: u32) -> Option<f64> {
        self.curve_points(v).find_map(|c| match c {
            CurvePoint::Crossing { segment: s, t } if s == segment => Some(t),
            _ => None,
        })
    }
}

/// Cut-vertices under construction, merged by location.
struct Registry<'s> {
    surface: &'s Surface,
    vertices: Vec<CutVertex>,
    /// Per canonical halfedge: (t, cut-vertex).
    on_edge: HashMap<u32, Vec<(f64, u32)>>,
    /// Per face: cut-vertices inside it.
    in_face: HashMap<u32, Vec<u32>>,
    /// Curve points beyond a vertex's primary one (see [`Touch`]).
    extra: HashMap<u32, Vec<CurvePoint>>,
    touches: Vec<Touch>,
}

impl<'s> Registry<'s> {
    fn new(surface: &'s Surface) -> Self {
        let vertices = (0..surface.mesh.n_vertices() as u32)
            .map(|v| CutVertex {
                loc: Location::Vertex(v),
                pos: surface.points[v as usize],
                mask: MESH_VERTEX,
                curve: CurvePoint::None,
            })
            .collect();
        Self {
            surface,
            vertices,
            on_edge: HashMap::default(),
            in_face: HashMap::default(),
            extra: HashMap::default(),
            touches: Vec::new(),
        }
    }

    /// The cut-vertex at `loc`, merging with one closer than `tol`.
    fn insert(&mut self, loc: Location, tol: f64) -> u32 {
        let pos = self.surface.position(loc);
        let new_id = self.vertices.len() as u32;
        match loc {
            Location::Vertex(v) => return v,
            Location::Edge { h, .. } => {
                let list = self.on_edge.entry(h).or_default();
                if let Some(&(_, id)) =
                    list.iter().find(|&&(_, id)| (self.vertices[id as usize].pos - pos).length() <= tol)
                {
                    return id;
                }
                let Location::Edge { t, .. } = loc else { unreachable!() };
                list.push((t, new_id));
            }
            Location::Face { face, .. } => {
                let list = self.in_face.entry(face).or_default();
                if let Some(&id) = list.iter().find(|&&id| (self.vertices[id as usize].pos - pos).length() <= tol) {
                    return id;
                }
                list.push(new_id);
            }
        }
        self.vertices.push(CutVertex { loc, pos, mask: 0, curve: CurvePoint::None });
        new_id
    }

    /// A segment through cut-vertex `cv`, for naming an overlap.
    fn segment_at(&self, cv: u32, input: CutInput<'_>) -> u32 {
        match self.vertices[cv as usize].curve {
            CurvePoint::Crossing { segment, .. } => segment,
            CurvePoint::Sample(i) => input.segments.iter().position(|s| s.contains(&i)).map_or(u32::MAX, |s| s as u32),
            CurvePoint::None => u32::MAX,
        }
    }

    /// Whether `a` and `b` lie on one edge of face `f`: that edge's canonical halfedge.
    fn common_edge(&self, f: u32, a: u32, b: u32) -> Option<u32> {
        let s = self.surface;
        let he = &s.halfedges;
        let on = |loc: Location, h: u32| match loc {
            Location::Vertex(v) => he.tail(h) == v || he.head(h) == v,
            Location::Edge { h: c, .. } => c == s.canonical(h),
            Location::Face { .. } => false,
        };
        let (la, lb) = (self.vertices[a as usize].loc, self.vertices[b as usize].loc);
        he.face_halfedges(f).find(|&h| on(la, h) && on(lb, h)).map(|h| s.canonical(h))
    }

    /// The chords of face `f` with every crossing between two of them made
    /// a cut-vertex on both (a [`Touch`]), and every chord end lying inside
    /// another chord made a vertex of that chord too, so that the face's
    /// graph is planar. Collinear chords are cut at each other's ends and
    /// their shared pieces merged (the first segment's is kept): a stretch
    /// [`Touch`].
    fn split_crossing_chords(&mut self, surface: &Surface, f: u32, chords: &[Piece]) -> Vec<Piece> {
        let n = chords.len();
        let p2 = |v: u32, this: &Self| surface.position_2d(f, this.vertices[v as usize].loc);
        // Per chord: (parameter along it, cut-vertex, arc-length fraction along its segment).
        let mut cuts: Vec<Vec<(f64, u32, f64)>> = vec![Vec::new(); n];
        let mut created: Vec<u32> = Vec::new();
        let eps = 1e-9;
        for i in 0..n {
            for j in i + 1..n {
                let (ci, cj) = (chords[i], chords[j]);
                let shared = [ci.a, ci.b].iter().filter(|v| [cj.a, cj.b].contains(v)).count();
                if shared == 2 {
                    continue; // the same chord twice: merged below
                }
                let (a, b, c, d) = (p2(ci.a, self), p2(ci.b, self), p2(cj.a, self), p2(cj.b, self));
                let (r, q) = (b - a, d - c);
                let den = r.perp_dot(q);
                let scale = r.length() * q.length();
                if den.abs() <= 1e-12 * scale {
                    // Parallel. Collinear and overlapping: each chord is cut at the
                    // other's ends that lie inside it; the shared piece is merged below.
                    let rr = r.length_squared();
                    let qq = q.length_squared();
                    if (c - a).perp_dot(r).abs() > 1e-12 * rr.max(1e-300) {
                        continue;
                    }
                    let (u0, u1) = ((c - a).dot(r) / rr, (d - a).dot(r) / rr);
                    if u0.max(u1) > eps && u0.min(u1) < 1.0 - eps && ci.segment != cj.segment {
                        let vertex = if (eps..1.0 - eps).contains(&u0) { cj.a } else { cj.b };
                        self.touches.push(Touch { segment: cj.segment, other: ci.segment, vertex, stretch: true });
                    }
                    for (v, x) in [(cj.a, c), (cj.b, d)] {
                        let u = (x - a).dot(r) / rr;
                        if u > eps && u < 1.0 - eps && v != ci.a && v != ci.b {
                            let t = ci.ta + u * (ci.tb - ci.ta);
                            self.touch(v, ci.segment, t, cj.segment);
                            cuts[i].push((u, v, t));
                        }
                    }
                    for (v, x) in [(ci.a, a), (ci.b, b)] {
                        let w = (x - c).dot(q) / qq;
                        if w > eps && w < 1.0 - eps && v != cj.a && v != cj.b {
                            let t = cj.ta + w * (cj.tb - cj.ta);
                            self.touch(v, cj.segment, t, ci.segment);
                            cuts[j].push((w, v, t));
                        }
                    }
                    continue;
                }
                if shared == 1 {
                    continue; // meeting at a node
                }
                let u = (c - a).perp_dot(q) / den;
                let w = (c - a).perp_dot(r) / den;
                if !(-eps..=1.0 + eps).contains(&u) || !(-eps..=1.0 + eps).contains(&w) {
                    continue;
                }
                let end_i = u <= eps || u >= 1.0 - eps;
                let end_j = w <= eps || w >= 1.0 - eps;
                let t_i = ci.ta + u.clamp(0.0, 1.0) * (ci.tb - ci.ta);
                let t_j = cj.ta + w.clamp(0.0, 1.0) * (cj.tb - cj.ta);
                match (end_i, end_j) {
                    (true, true) => continue, // two chord ends a hair apart: the merge tolerance's business
                    (true, false) => {
                        // An end of chord i lies inside chord j.
                        let v = if u < 0.5 { ci.a } else { ci.b };
                        self.touch(v, cj.segment, t_j, ci.segment);
                        cuts[j].push((w, v, t_j));
                    }
                    (false, true) => {
                        let v = if w < 0.5 { cj.a } else { cj.b };
                        self.touch(v, ci.segment, t_i, cj.segment);
                        cuts[i].push((u, v, t_i));
                    }
                    (false, false) => {
                        let x = a + r * u;
                        let loc = surface.face_point(f, x);
                        let pos = surface.position(loc);
                        let tol = 1e-9 * surface.diagonal;
                        let v = match created.iter().find(|&&v| (self.vertices[v as usize].pos - pos).length() <= tol) {
                            Some(&v) => v,
                            None => {
                                let v = self.vertices.len() as u32;
                                self.vertices.push(CutVertex {
                                    loc,
                                    pos,
                                    mask: CROSSING,
                                    curve: CurvePoint::Crossing { segment: ci.segment, t: t_i },
                                });
                                created.push(v);
                                v
                            }
                        };
                        if !matches!(self.vertices[v as usize].curve, CurvePoint::Crossing { segment, .. } if segment == ci.segment)
                        {
                            self.touch(v, ci.segment, t_i, cj.segment);
                        }
                        self.touch(v, cj.segment, t_j, ci.segment);
                        cuts[i].push((u, v, t_i));
                        cuts[j].push((w, v, t_j));
                    }
                }
            }
        }
        let mut out = Vec::with_capacity(n + created.len() * 2);
        for (c, mut at) in chords.iter().zip(cuts) {
            at.sort_by(|x, y| x.0.total_cmp(&y.0));
            let (mut a, mut ta) = (c.a, c.ta);
            for (_, v, t) in at {
                if v != a {
                    out.push(Piece { a, b: v, ta, tb: t, ..*c });
                }
                (a, ta) = (v, t);
            }
            if a != c.b {
                out.push(Piece { a, ta, ..*c });
            }
        }
        // Pieces of two segments between the same two vertices (a curve
        // folding back over itself, or two curves over one stretch): one
        // chord, the first segment's; the other segment's ends are touches.
        let mut seen: HashMap<(u32, u32), u32> = HashMap::default();
        let mut merged = Vec::with_capacity(out.len());
        for p in out {
            let key = (p.a.min(p.b), p.a.max(p.b));
            match seen.get(&key) {
                Some(&other) => {
                    if other != p.segment {
                        self.touches.push(Touch { segment: p.segment, other, vertex: p.a, stretch: true });
                        for (v, t) in [(p.a, p.ta), (p.b, p.tb)] {
                            if !self.on_segment(v, p.segment) {
                                self.touch(v, p.segment, t, other);
                            }
                        }
                    }
                }
                None => {
                    seen.insert(key, p.segment);
                    merged.push(p);
                }
            }
        }
        merged
    }

    /// Whether cut-vertex `v` already carries a curve point of `segment`
    /// (one of its crossings; its samples carry their slots through the
    /// segment's own halfedges).
    fn on_segment(&self, v: u32, segment: u32) -> bool {
        let is = |c: &CurvePoint| matches!(c, CurvePoint::Crossing { segment: s, .. } if *s == segment);
        is(&self.vertices[v as usize].curve) || self.extra.get(&v).is_some_and(|e| e.iter().any(is))
    }

    /// Records that `segment` passes through cut-vertex `v` (at arc-length
    /// fraction `t`), where `other`'s path already is.
    fn touch(&mut self, v: u32, segment: u32, t: f64, other: u32) {
        self.vertices[v as usize].mask |= CROSSING;
        self.extra.entry(v).or_default().push(CurvePoint::Crossing { segment, t });
        self.touches.push(Touch { segment, other, vertex: v, stretch: false });
    }

    fn build(
        mut self,
        surface: &Surface,
        input: CutInput<'_>,
        pieces: Vec<Piece>,
        mut sample_vertex: Vec<u32>,
    ) -> Result<CutMesh> {
        let he = &surface.halfedges;
        for list in self.on_edge.values_mut() {
            list.sort_by(|x, y| x.0.total_cmp(&y.0));
        }
        // Split pieces into chords (per face) and pieces along edges (per canonical edge).
        let mut chords: HashMap<u32, Vec<Piece>> = HashMap::default();
        let mut along: HashMap<(u32, u32), u32> = HashMap::default(); // (cv, cv) on an edge -> segment, directed a->b
        for (k, p) in pieces.iter().enumerate() {
            input.cancel.check_every(k, "cutting")?;
            if let Some(c) = self.common_edge(p.face, p.a, p.b) {
                // Every sub-piece of the edge between a and b runs along the segment.
                let t_of = |v: u32| -> f64 {
                    match self.vertices[v as usize].loc {
                        Location::Vertex(x) => {
                            if he.tail(c) == x {
                                0.0
                            } else {
                                1.0
                            }
                        }
                        Location::Edge { t, .. } => t,
                        Location::Face { .. } => unreachable!(),
                    }
                };
                let (ta, tb) = (t_of(p.a), t_of(p.b));
                let mut chain = vec![(0.0, he.tail(c))];
                chain.extend(self.on_edge.get(&c).into_iter().flatten().copied());
                chain.push((1.0, he.head(c)));
                let (lo, hi) = (ta.min(tb), ta.max(tb));
                let inside: Vec<(f64, u32)> = chain.iter().filter(|(t, _)| *t >= lo && *t <= hi).copied().collect();
                // Vertices of other segments inside the stretch are on this segment too.
                for &(t, v) in &inside {
                    if v != p.a && v != p.b && !self.on_segment(v, p.segment) {
                        let other = self.segment_at(v, input);
                        let along_t = p.ta + (t - ta) / (tb - ta) * (p.tb - p.ta);
                        self.touch(v, p.segment, along_t, other);
                    }
                }
                for w in inside.windows(2) {
                    let (x, y) = if ta <= tb { (w[0].1, w[1].1) } else { (w[1].1, w[0].1) };
                    // A stretch already along another segment (a curve folding back
                    // over itself along an edge) keeps the first; its ends touch.
                    let taken = along.get(&(x, y)).or_else(|| along.get(&(y, x))).copied();
                    match taken {
                        // Its ends carry the other segment's curve points already.
                        Some(other) if other != p.segment => {
                            self.touches.push(Touch { segment: p.segment, other, vertex: x, stretch: true });
                        }
                        Some(_) => {}
                        None => {
                            along.insert((x, y), p.segment);
                        }
                    }
                }
            } else {
                chords.entry(p.face).or_default().push(*p);
            }
        }

        let mut out = Builder::default();
        // Halfedges on input edges, `(tail, head, cut halfedge)`, twinned
        // below by their ends.
        let mut boundary: Vec<(u32, u32, u32)> = Vec::with_capacity(he.n_halfedges() + 4 * pieces.len());
        let mut removed_vertices = vec![false; self.vertices.len()];
        let (mut n_islands, mut n_island_samples) = (0usize, 0usize);
        let mut pslg = Pslg::default();
        for f in 0..surface.mesh.n_faces() as u32 {
            input.cancel.check("cutting")?; // per face: a face's graph costs up to its pieces squared
            // Fast path: a face no segment touches is its own single cut-face.
            let untouched = !chords.contains_key(&f)
                && he.face_halfedges(f).all(|h| !self.on_edge.contains_key(&surface.canonical(h)));
            if untouched {
                let face_id = out.parent.len() as u32;
                out.parent.push(f);
                for h in he.face_halfedges(f) {
                    let (ca, cb) = (he.tail(h), he.head(h));
                    let gh = out.tail.len() as u32;
                    out.tail.push(ca);
                    out.face.push(face_id);
                    let seg =
                        along.get(&(ca, cb)).map(|&s| (s, true)).or_else(|| along.get(&(cb, ca)).map(|&s| (s, false)));
                    out.segment.push(seg.map_or(INVALID, |x| x.0));
                    out.forward.push(seg.is_some_and(|x| x.1));
                    out.twin.push(INVALID);
                    boundary.push((ca, cb, gh));
                }
                out.face_start.push(out.tail.len() as u32);
                continue;
            }
            pslg.clear();
            // Boundary nodes, counter-clockwise.
            for h in he.face_halfedges(f) {
                pslg.node(he.tail(h), surface.position_2d(f, Location::Vertex(he.tail(h))), true);
                let c = surface.canonical(h);
                if let Some(list) = self.on_edge.get(&c) {
                    let iter: Box<dyn Iterator<Item = &(f64, u32)>> =
                        if c == h { Box::new(list.iter()) } else { Box::new(list.iter().rev()) };
                    for &(_, v) in iter {
                        pslg.node(v, surface.position_2d(f, self.vertices[v as usize].loc), true);
                    }
                }
            }
            let nb = pslg.pos.len() as u32;
            for k in 0..nb {
                pslg.edge(k, (k + 1) % nb, INVALID, false);
            }
            if let Some(list) = chords.get(&f) {
                let split = self.split_crossing_chords(surface, f, list);
                removed_vertices.resize(self.vertices.len(), false);
                for p in &split {
                    let (a, b) = (p.a, p.b);
                    let la = pslg.node(a, surface.position_2d(f, self.vertices[a as usize].loc), false);
                    let lb = pslg.node(b, surface.position_2d(f, self.vertices[b as usize].loc), false);
                    pslg.edge(la, lb, p.segment, true);
                }
            }
            pslg.check_crossings().map_err(|(segment, other)| match other {
                None => {
                    Error::SegmentCrossesFaceBoundary { segment: input.segment(segment), face: surface.input_face(f) }
                }
                Some(other) => Error::CurvesCross {
                    segment: input.segment(segment),
                    other: input.segment(other),
                    face: surface.input_face(f),
                },
            })?;
            let islands = pslg.remove_islands(nb);
            for &v in &islands.removed_nodes {
                removed_vertices[pslg.cut_vertex[v as usize] as usize] = true;
            }
            n_islands += islands.count;
            pslg.trace_faces(f)?;
            // Emit loops.
            for lp in &pslg.loops {
                let face_id = out.parent.len() as u32;
                out.parent.push(f);
                for &e in lp {
                    let (a, b) = pslg.halfedge_ends(e);
                    let (ca, cb) = (pslg.cut_vertex[a as usize], pslg.cut_vertex[b as usize]);
                    let gh = out.tail.len() as u32;
                    pslg.global[e as usize] = gh;
                    out.tail.push(ca);
                    out.face.push(face_id);
                    let (seg, fwd) = pslg.annotation(e, input, &along, ca, cb);
                    out.segment.push(seg);
                    out.forward.push(fwd);
                    out.twin.push(INVALID);
                    if pslg.is_boundary(e) {
                        boundary.push((ca, cb, gh));
                    }
                }
                out.face_start.push(out.tail.len() as u32);
            }
            // Chord twins within the face.
            for e in 0..pslg.n_halfedges() as u32 {
                if !pslg.is_boundary(e) && !pslg.dead(e) {
                    let (g, t) = (pslg.global[e as usize], pslg.global[(e ^ 1) as usize]);
                    out.twin[g as usize] = t;
                    if out.face[g as usize] == out.face[t as usize] && e % 2 == 0 {
                        out.n_cracks += 1;
                    }
                }
            }
        }
        // Boundary twins across input edges.
        twin_boundary(&boundary, self.vertices.len(), &mut out.twin);
        for v in &mut sample_vertex {
            if *v != INVALID && removed_vertices[*v as usize] {
                *v = INVALID;
                n_island_samples += 1;
            }
        }
        Ok(CutMesh {
            vertices: self.vertices,
            halfedges: Halfedges::from_loops(out.tail, out.twin, out.face, out.face_start),
            segment: out.segment,
            forward: out.forward,
            parent: out.parent,
            sample_vertex,
            n_cracks: out.n_cracks,
            n_islands_removed: n_islands,
            n_islands_samples: n_island_samples,
            embedding: EmbeddingCounts::default(),
            detours: Vec::new(),
            extra_curve: self.extra,
            touches: self.touches,
        })
    }
}

#[derive(Default)]
struct Builder {
    tail: Vec<u32>,
    twin: Vec<u32>,
    face: Vec<u32>,
    segment: Vec<u32>,
    forward: Vec<bool>,
    face_start: Vec<u32>,
    parent: Vec<u32>,
    n_cracks: usize,
}

impl Builder {
    fn default() -> Self {
        Self { face_start: vec![0], ..Default::default() }
    }
}

struct Islands {
    count: usize,
    removed_nodes: Vec<u32>,
}

/// The planar straight-line graph of one input face.
#[derive(Default)]
struct Pslg {
    cut_vertex: Vec<u32>,
    pos: Vec<DVec2>,
    local: HashMap<u32, u32>,
    /// Halfedges in pairs (2k, 2k+1); boundary edges use only 2k.
    from: Vec<u32>,
    seg: Vec<u32>,
    boundary: Vec<bool>,
    alive: Vec<bool>,
    /// Outgoing halfedges per node, sorted by angle.
    out: Vec<Vec<u32>>,
    next: Vec<u32>,
    loops: Vec<Vec<u32>>,
    global: Vec<u32>,
}

impl Pslg {
    fn clear(&mut self) {
        self.cut_vertex.clear();
        self.pos.clear();
        self.local.clear();
        self.from.clear();
        self.seg.clear();
        self.boundary.clear();
        self.alive.clear();
        self.out.clear();
        self.next.clear();
        self.loops.clear();
        self.global.clear();
    }

    fn node(&mut self, cv: u32, p: DVec2, _on_boundary: bool) -> u32 {
        if let Some(&k) = self.local.get(&cv) {
            return k;
        }
        let k = self.cut_vertex.len() as u32;
        self.cut_vertex.push(cv);
        self.pos.push(p);
        self.local.insert(cv, k);
        k
    }

    /// Adds edge a-b (boundary: only a->b is a halfedge of this face).
    fn edge(&mut self, a: u32, b: u32, segment: u32, chord: bool) {
        self.from.push(a);
        self.from.push(b);
        self.seg.push(segment);
        self.seg.push(segment);
        self.boundary.push(!chord);
        self.boundary.push(!chord);
        self.alive.push(true);
        self.alive.push(chord);
    }

    fn n_halfedges(&self) -> usize {
        self.from.len()
    }
    fn is_boundary(&self, e: u32) -> bool {
        self.boundary[e as usize]
    }
    fn dead(&self, e: u32) -> bool {
        !self.alive[e as usize]
    }
    fn halfedge_ends(&self, e: u32) -> (u32, u32) {
        (self.from[e as usize], self.from[(e ^ 1) as usize])
    }

    /// Chords that cross each other or a boundary piece inside the face:
    /// the chord's segment and the other chord's (`None` for the boundary).
    fn check_crossings(&self) -> std::result::Result<(), (u32, Option<u32>)> {
        let n_edges = self.from.len() / 2;
        for i in 0..n_edges {
            if self.boundary[2 * i] {
                continue;
            }
            let (a, b) = (self.from[2 * i], self.from[2 * i + 1]);
            for j in 0..n_edges {
                if j == i || (j < i && !self.boundary[2 * j]) {
                    continue;
                }
                let (c, d) = (self.from[2 * j], self.from[2 * j + 1]);
                if a == c || a == d || b == c || b == d {
                    continue; // sharing a node
                }
                if segments_cross(
                    self.pos[a as usize],
                    self.pos[b as usize],
                    self.pos[c as usize],
                    self.pos[d as usize],
                ) {
                    return Err((self.seg[2 * i], (!self.boundary[2 * j]).then_some(self.seg[2 * j])));
                }
            }
        }
        Ok(())
    }

    /// Removes chord clusters that touch no boundary node (the first `nb` nodes).
    fn remove_islands(&mut self, nb: u32) -> Islands {
        let n = self.pos.len();
        let mut comp: Vec<u32> = (0..n as u32).collect();
        for e in (0..self.from.len()).step_by(2) {
            let (a, b) = (disjoint_root(&mut comp, self.from[e]), disjoint_root(&mut comp, self.from[e + 1]));
            comp[a as usize] = b;
        }
        let mut touches = vec![false; n];
        for k in 0..nb {
            let r = disjoint_root(&mut comp, k);
            touches[r as usize] = true;
        }
        let mut removed_nodes = Vec::new();
        let mut roots = Vec::new();
        for k in nb..n as u32 {
            let r = disjoint_root(&mut comp, k);
            if !touches[r as usize] {
                removed_nodes.push(k);
                if !roots.contains(&r) {
                    roots.push(r);
                }
            }
        }
        for e in 0..self.from.len() {
            if removed_nodes.contains(&self.from[e]) {
                self.alive[e] = false;
            }
        }
        Islands { count: roots.len(), removed_nodes }
    }

    /// Sorts halfedges around nodes and follows them into loops.
    fn trace_faces(&mut self, f: u32) -> Result<()> {
        let n = self.pos.len();
        self.out = vec![Vec::new(); n];
        // Rays at each node: every live edge end (including the boundary edge
        // arriving at the node, whose reverse is not a halfedge here).
        let mut rays: Vec<Vec<(f64, u32)>> = vec![Vec::new(); n];
        for e in 0..self.from.len() {
            let (a, b) = (self.from[e], self.from[e ^ 1]);
            let live_edge = self.alive[e & !1];
            if !live_edge {
                continue;
            }
            let d = self.pos[b as usize] - self.pos[a as usize];
            rays[a as usize].push((d.y.atan2(d.x), e as u32));
        }
        for r in &mut rays {
            r.sort_by(|x, y| x.0.total_cmp(&y.0));
        }
        self.next = vec![INVALID; self.from.len()];
        self.global = vec![INVALID; self.from.len()];
        for e in 0..self.from.len() {
            if !self.alive[e] {
                continue;
            }
            // e: a -> b. At b, find the ray b -> a, take the one just clockwise of it.
            let b = self.from[e ^ 1] as usize;
            let back = (e ^ 1) as u32;
            let r = &rays[b];
            let k = r.iter().position(|x| x.1 == back).expect("every edge has its reverse ray");
            let m = r.len();
            let nxt = r[(k + m - 1) % m].1;
            if !self.alive[nxt as usize] {
                return Err(Error::Internal { what: format!("cut-face tracing in face {f} walked outside the face") });
            }
            self.next[e] = nxt;
        }
        let mut seen = vec![false; self.from.len()];
        for e in 0..self.from.len() {
            if !self.alive[e] || seen[e] {
                continue;
            }
            let mut lp = Vec::new();
            let mut x = e as u32;
            while !seen[x as usize] {
                seen[x as usize] = true;
                lp.push(x);
                x = self.next[x as usize];
            }
            if x != e as u32 {
                return Err(Error::Internal { what: format!("cut-face tracing in face {f} did not close a loop") });
            }
            self.loops.push(lp);
        }
        Ok(())
    }

    /// The segment a halfedge runs along, and whether forward.
    fn annotation(
        &self,
        e: u32,
        input: CutInput<'_>,
        along: &HashMap<(u32, u32), u32>,
        ca: u32,
        cb: u32,
    ) -> (u32, bool) {
        if !self.is_boundary(e) {
            let s = self.seg[e as usize];
            // Chord pairs were added a->b along the segment: even halfedges run forward.
            return (s, e.is_multiple_of(2));
        }
        let _ = input;
        if let Some(&s) = along.get(&(ca, cb)) {
            return (s, true);
        }
        if let Some(&s) = along.get(&(cb, ca)) {
            return (s, false);
        }
        (INVALID, false)
    }
}

impl CutMesh {
    /// Heap bytes held by the cut-mesh (its vertices and halfedge arrays).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.vertices)
            + self.halfedges.heap_bytes()
            + bytes(&self.segment)
            + bytes(&self.forward)
            + bytes(&self.parent)
            + bytes(&self.sample_vertex)
            + bytes(&self.detours)
            + bytes(&self.touches)
            + self.extra_curve.capacity() * std::mem::size_of::<(u32, Vec<crate::binding::cut::CurvePoint>)>()
            + self.extra_curve.values().map(bytes).sum::<usize>()
    }
}

/// Twins the halfedges on input edges: `(a, b, g)` and `(b, a, t)` are
/// twins. Bucketed by tail vertex (linear time; the hash map of all of
/// them that this replaces was among the 376k binding's largest costs). Should one directed edge appear twice
/// (it cannot on a validated manifold), the later entry is the edge's, as a
/// map's insert would keep it, and the earlier one gets no twin.
fn twin_boundary(boundary: &[(u32, u32, u32)], n_vertices: usize, twin: &mut [u32]) {
    let tails: Vec<u32> = boundary.iter().map(|e| e.0).collect();
    let (start, order) = crate::sparse::group_by_key(n_vertices, &tails);
    let by_tail: Vec<(u32, u32)> = order.iter().map(|&i| (boundary[i as usize].1, boundary[i as usize].2)).collect();
    let bucket = |v: u32| &by_tail[start[v as usize] as usize..start[v as usize + 1] as usize];
    // The last entry of the directed edge a -> b, if any.
    let last = |a: u32, b: u32| bucket(a).iter().rev().find(|e| e.0 == b).map(|e| e.1);
    for &(a, b, g) in boundary {
        if last(a, b) != Some(g) {
            continue;
        }
        if let Some(t) = last(b, a) {
            twin[g as usize] = t;
        }
    }
}
