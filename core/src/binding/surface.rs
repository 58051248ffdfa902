//! The surface a curvenet is bound to: the input polygon mesh in the
//! projection pose, with a plane per face in which its cut-faces are built.
//!
//! Every face gets a 2D frame (origin at its first corner, axes orthonormal
//! to its vector-area normal) and its corners' positions in that frame. A
//! non-planar face is flattened by orthogonal projection onto that plane;
//! the projected polygon must be simple and counter-clockwise (a face folded
//! over itself under projection is refused, naming it). Faces are
//! triangulated in 2D (fan when convex, ear clipping otherwise), so every
//! point inside a face has barycentric coordinates in one of its triangles
//! that give both its 3D position on the surface and its 2D position in the
//! face's plane, consistently.

use glam::{DVec2, DVec3};

use crate::closest_point::ClosestPointBvh;
use crate::error::{Error, Result};
use crate::halfedge::{Components, Halfedges, INVALID};

use super::locate::{Location, barycentric_2d};
use crate::mesh::{PolyMesh, bounding_box_diagonal};
use crate::polygon_laplacian::vector_area;

/// A face's plane: `x ≈ origin + s u + t v`.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct FacePlane {
    pub origin: DVec3,
    pub u: DVec3,
    pub v: DVec3,
    pub normal: DVec3,
}

impl FacePlane {
    /// Orthogonal projection of `x` into the plane's 2D coordinates.
    pub fn to_2d(&self, x: DVec3) -> DVec2 {
        let d = x - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }
}

/// The mesh in the projection pose, prepared for binding. Immutable.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Surface {
    /// The input mesh, with folded faces split into triangles.
    pub(crate) mesh: PolyMesh,
    /// The input face of every face of `mesh`.
    #[serde(with = "crate::persist::pod")]
    pub(crate) input_face: Vec<u32>,
    /// The input faces that were split (see [`Surface::new`]).
    #[serde(with = "crate::persist::pod")]
    pub(crate) split_faces: Vec<u32>,
    pub(crate) halfedges: Halfedges,
    /// The connected components of `halfedges`' faces.
    pub(crate) components: Components,
    #[serde(with = "crate::persist::pod")]
    pub(crate) points: Vec<DVec3>,
    pub(crate) planes: Vec<FacePlane>,
    /// 2D position of every face corner (indexed like halfedges: corner h of
    /// face f is halfedge h).
    #[serde(with = "crate::persist::pod")]
    pub(crate) corners_2d: Vec<DVec2>,
    /// Triangles as face-corner (halfedge) indices.
    #[serde(with = "crate::persist::pod")]
    pub(crate) triangles: Vec<[u32; 3]>,
    /// Face `f`'s triangles are `face_tri_start[f]..face_tri_start[f + 1]`.
    #[serde(with = "crate::persist::pod")]
    pub(crate) face_tri_start: Vec<u32>,
    /// Outgoing halfedges of each vertex (CSR by `vertex_out_start`).
    #[serde(with = "crate::persist::pod")]
    pub(crate) vertex_out: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    pub(crate) vertex_out_start: Vec<u32>,
    pub(crate) bvh: ClosestPointBvh,
    pub(crate) diagonal: f64,
    pub(crate) mean_edge_length: f64,
}

impl Surface {
    /// Validates and prepares `mesh` posed at `points`. Errors name the
    /// offending face, edge or vertex: non-finite points, non-manifold or
    /// inconsistently oriented connectivity, coincident corners, zero-area
    /// faces. A face that folds over itself in its own plane (a strongly
    /// warped quad of a coarse subdivision cage) is split into triangles
    /// (see [`Surface::split_faces`]); one that cannot be split is refused.
    pub fn new(mesh: &PolyMesh, points: &[[f64; 3]]) -> Result<Self> {
        mesh.check_points(points, "mesh point")?;
        let input_halfedges = Halfedges::new(mesh)?;
        let p: Vec<DVec3> = points.iter().map(|&x| DVec3::from_array(x)).collect();
        let diagonal = bounding_box_diagonal(points);
        // One pass over the input's faces: their planes, 2-D corners and
        // triangles, and the folded faces to split. When nothing folds (the
        // usual case) that is the surface; otherwise the split mesh is
        // validated and planed again.
        let mut split_faces = Vec::new();
        let mut counts = Vec::with_capacity(mesh.n_faces());
        let mut indices = Vec::with_capacity(mesh.face_vertex_indices().len());
        let mut input_face = Vec::with_capacity(mesh.n_faces());
        let mut corners3 = Vec::new();
        let mut planed = Planed::with_capacity(mesh.n_faces(), input_halfedges.n_halfedges());
        for (f, face) in mesh.faces().enumerate() {
            corners3.clear();
            corners3.extend(face.iter().map(|&v| p[v as usize]));
            match face_plane(f, face, &corners3) {
                Err(Error::FoldedFace { .. }) => {
                    let fan = split_folded(&corners3).ok_or(Error::FoldedFace { face: f })?;
                    for t in fan {
                        counts.push(3);
                        indices.extend(t.map(|k| face[k]));
                        input_face.push(f as u32);
                    }
                    split_faces.push(f as u32);
                }
                Err(e) => return Err(e),
                Ok((plane, poly)) => {
                    counts.push(face.len() as u32);
                    indices.extend_from_slice(face);
                    input_face.push(f as u32);
                    if split_faces.is_empty() {
                        planed.push(plane, poly, f)?;
                    }
                }
            }
        }
        let (mesh, halfedges) = if split_faces.is_empty() {
            (mesh.clone(), input_halfedges)
        } else {
            drop(input_halfedges);
            let mesh = PolyMesh::new(&counts, &indices, mesh.n_vertices())?;
            let halfedges = Halfedges::new(&mesh)?;
            planed = Planed::with_capacity(mesh.n_faces(), halfedges.n_halfedges());
            for (f, face) in mesh.faces().enumerate() {
                corners3.clear();
                corners3.extend(face.iter().map(|&v| p[v as usize]));
                let named = |e: Error| match e {
                    Error::FoldedFace { .. } => Error::FoldedFace { face: input_face[f] as usize },
                    e => e,
                };
                let (plane, poly) = face_plane(input_face[f] as usize, face, &corners3).map_err(named)?;
                planed.push(plane, poly, input_face[f] as usize)?;
            }
            (mesh, halfedges)
        };
        let Planed { planes, corners_2d, triangles, face_tri_start, .. } = planed;
        let vertex_of = |h: u32| halfedges.tail(h);
        let tri_vertices: Vec<([u32; 3], u32)> =
            triangles.iter().map(|t| (t.map(vertex_of), halfedges.face(t[0]))).collect();
        let bvh = ClosestPointBvh::from_triangles(points, &tri_vertices)?;
        let mean_edge_length = mesh.mean_edge_length(points);
        let tails: Vec<u32> = (0..halfedges.n_halfedges() as u32).map(|h| halfedges.tail(h)).collect();
        let (vertex_out_start, vertex_out) = crate::sparse::group_by_key(mesh.n_vertices(), &tails);
        let components = Components::new(&halfedges);
        Ok(Self {
            mesh,
            input_face,
            split_faces,
            halfedges,
            components,
            points: p,
            planes,
            corners_2d,
            triangles,
            face_tri_start,
            vertex_out,
            vertex_out_start,
            bvh,
            diagonal,
            mean_edge_length,
        })
    }

    /// The corner positions of triangle `t` in the pose `points` (one per mesh vertex).
    pub(crate) fn triangle_points<P: Copy + Into<DVec3>>(&self, t: u32, points: &[P]) -> [DVec3; 3] {
        self.triangles[t as usize].map(|h| points[self.halfedges.tail(h) as usize].into())
    }

    /// The surface's mesh: the input mesh with folded faces split into
    /// triangles ([`Self::split_faces`]); same vertices, and the same faces
    /// in the same order when nothing was split.
    pub fn mesh(&self) -> &PolyMesh {
        &self.mesh
    }
    /// The triangulation the binding works in (every face triangulated in
    /// its own plane: a fan when convex, ear clipping otherwise; folded
    /// faces as their split fans): each triangle's mesh vertices,
    /// counter-clockwise like its face, and the input face it belongs to.
    /// A face's triangles are consecutive, faces in input order. Drawing
    /// these shows the surface exactly as the closest-point queries and the
    /// cut-faces see it.
    pub fn triangles(&self) -> impl ExactSizeIterator<Item = ([u32; 3], u32)> + '_ {
        self.triangles
            .iter()
            .map(|t| (t.map(|h| self.halfedges.tail(h)), self.input_face[self.halfedges.face(t[0]) as usize]))
    }
    /// The input face that face `f` of [`Self::mesh`] comes from.
    pub fn input_face(&self, f: u32) -> u32 {
        self.input_face[f as usize]
    }
    /// Input faces that folded over themselves under projection onto their
    /// own plane and were split into triangles (a fan from the corner whose
    /// triangles all face along the polygon's vector area, the most even
    /// such fan); the Laplacian there is the triangles' cotangent one.
    pub fn split_faces(&self) -> &[u32] {
        &self.split_faces
    }
    pub fn halfedges(&self) -> &Halfedges {
        &self.halfedges
    }
    /// The connected components of [`Self::mesh`]'s faces (through shared edges).
    pub fn components(&self) -> &Components {
        &self.components
    }
    /// Length of the bounding-box diagonal in the projection pose.
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }
    pub fn mean_edge_length(&self) -> f64 {
        self.mean_edge_length
    }
    pub fn closest_points(&self) -> &ClosestPointBvh {
        &self.bvh
    }
}

/// The per-face parts of a surface, face after face: planes, 2-D corners
/// (one per halfedge) and their triangulation.
struct Planed {
    planes: Vec<FacePlane>,
    corners_2d: Vec<DVec2>,
    triangles: Vec<[u32; 3]>,
    face_tri_start: Vec<u32>,
    scratch: Vec<[u32; 3]>,
}

impl Planed {
    fn with_capacity(faces: usize, halfedges: usize) -> Self {
        Self {
            planes: Vec::with_capacity(faces),
            corners_2d: Vec::with_capacity(halfedges),
            triangles: Vec::with_capacity(halfedges),
            face_tri_start: vec![0],
            scratch: Vec::new(),
        }
    }

    /// Appends the next face (`input_face`: its face in the input mesh, for errors).
    fn push(&mut self, plane: FacePlane, poly: Vec<DVec2>, input_face: usize) -> Result<()> {
        let start = self.corners_2d.len() as u32;
        self.corners_2d.extend(poly);
        triangulate(&self.corners_2d[start as usize..], &mut self.scratch)
            .ok_or(Error::FoldedFace { face: input_face })?;
        self.triangles.extend(self.scratch.iter().map(|t| t.map(|k| start + k)));
        self.face_tri_start.push(self.triangles.len() as u32);
        self.planes.push(plane);
        Ok(())
    }
}

/// The plane of face `f` (corners `face` at `corners3`) and its corners in
/// it: coincident corners, zero area and folding are typed errors.
fn face_plane(f: usize, face: &[u32], corners3: &[DVec3]) -> Result<(FacePlane, Vec<DVec2>)> {
    let va = vector_area(corners3);
    let area = va.length();
    let extent = corners3.iter().map(|c| (*c - corners3[0]).length()).fold(0.0, f64::max);
    let n = face.len();
    if let Some(i) = (0..n).find(|&i| (corners3[(i + 1) % n] - corners3[i]).length() <= 1e-12 * extent) {
        return Err(Error::CoincidentFaceVertices { face: f, a: face[i], b: face[(i + 1) % n] });
    }
    if !(area > 1e-12 * extent * extent) || extent == 0.0 {
        return Err(Error::ZeroAreaFace { face: f, vertices: face.to_vec(), area });
    }
    let normal = va / area;
    let u = (corners3[1] - corners3[0]).reject_from(normal).normalize_or_zero();
    let u = if u == DVec3::ZERO { normal.any_orthonormal_vector() } else { u };
    let plane = FacePlane { origin: corners3[0], u, v: normal.cross(u), normal };
    let poly: Vec<DVec2> = corners3.iter().map(|&c| plane.to_2d(c)).collect();
    if signed_area(&poly) <= 0.0 || !is_simple(&poly) {
        return Err(Error::FoldedFace { face: f });
    }
    Ok((plane, poly))
}

/// A fan of triangles (corner indices) for a folded polygon: the fan whose
/// triangles face most along the polygon's vector area (the largest
/// smallest projected area; a strongly warped quad can have one triangle
/// facing away, a crease sharper than a right angle, which the surface then
/// has). `None` when the polygon is (nearly) planar, since then it folds
/// because its edges cross and no split makes it a surface, or when every
/// fan has a triangle of zero area.
fn split_folded(corners3: &[DVec3]) -> Option<Vec<[usize; 3]>> {
    let n = corners3.len();
    let normal = vector_area(corners3).normalize_or_zero();
    let extent = corners3.iter().map(|c| (*c - corners3[0]).length()).fold(0.0, f64::max);
    let warp = corners3.iter().map(|c| (*c - corners3[0]).dot(normal).abs()).fold(0.0, f64::max);
    if warp <= 1e-3 * extent {
        return None;
    }
    let mut best: Option<(f64, usize)> = None;
    for c in 0..n {
        let tri = |k: usize| (corners3[(c + k) % n] - corners3[c]).cross(corners3[(c + k + 1) % n] - corners3[c]);
        if (1..n - 1).any(|k| !(tri(k).length() > 1e-12 * extent * extent)) {
            continue;
        }
        let smallest = (1..n - 1).map(|k| 0.5 * tri(k).dot(normal)).fold(f64::INFINITY, f64::min);
        if best.is_none_or(|(m, _)| smallest > m) {
            best = Some((smallest, c));
        }
    }
    let (_, c) = best?;
    Some((1..n - 1).map(|k| [c, (c + k) % n, (c + k + 1) % n]).collect())
}

/// Twice-free signed area of a 2D polygon (positive when counter-clockwise).
pub(crate) fn signed_area(poly: &[DVec2]) -> f64 {
    let n = poly.len();
    0.5 * (0..n).map(|i| poly[i].perp_dot(poly[(i + 1) % n])).sum::<f64>()
}

/// No two non-adjacent edges of the polygon intersect (O(n²); faces are small).
fn is_simple(poly: &[DVec2]) -> bool {
    let n = poly.len();
    if n <= 3 {
        return true;
    }
    for i in 0..n {
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            if segments_cross(poly[i], poly[(i + 1) % n], poly[j], poly[(j + 1) % n]) {
                return false;
            }
        }
    }
    true
}

fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// Whether closed segments ab and cd intersect (touching counts).
pub(crate) fn segments_cross(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let (o1, o2, o3, o4) = (orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b));
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0)) && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0)) {
        return true;
    }
    let on = |p: DVec2, q: DVec2, r: DVec2, o: f64| {
        o == 0.0 && r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    on(a, b, c, o1) || on(a, b, d, o2) || on(c, d, a, o3) || on(c, d, b, o4)
}

/// Triangulates a simple counter-clockwise polygon into `out` (corner
/// indices): a fan when convex, ear clipping otherwise. `None` if no ear is
/// found (a degenerate polygon).
pub(crate) fn triangulate(poly: &[DVec2], out: &mut Vec<[u32; 3]>) -> Option<()> {
    out.clear();
    let n = poly.len();
    let convex = (0..n).all(|i| orient(poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]) > 0.0);
    if convex {
        out.extend((1..n as u32 - 1).map(|k| [0, k, k + 1]));
        return Some(());
    }
    let mut idx: Vec<u32> = (0..n as u32).collect();
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).find(|&i| {
            let (a, b, c) =
                (poly[idx[(i + m - 1) % m] as usize], poly[idx[i] as usize], poly[idx[(i + 1) % m] as usize]);
            orient(a, b, c) > 0.0
                && idx.iter().all(|&k| {
                    let p = poly[k as usize];
                    p == a
                        || p == b
                        || p == c
                        || !(orient(a, b, p) >= 0.0 && orient(b, c, p) >= 0.0 && orient(c, a, p) >= 0.0)
                })
        })?;
        out.push([idx[(ear + m - 1) % m], idx[ear], idx[(ear + 1) % m]]);
        idx.remove(ear);
    }
    out.push([idx[0], idx[1], idx[2]]);
    Some(())
}

impl Surface {
    /// Heap bytes held by the surface: the mesh, its halfedges, points,
    /// face planes, triangulation, vertex stars and the closest-point BVH.
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        self.mesh.heap_bytes()
            + bytes(&self.input_face)
            + bytes(&self.split_faces)
            + self.halfedges.heap_bytes()
            + self.components.heap_bytes()
            + bytes(&self.points)
            + bytes(&self.planes)
            + bytes(&self.corners_2d)
            + bytes(&self.triangles)
            + bytes(&self.face_tri_start)
            + bytes(&self.vertex_out)
            + bytes(&self.vertex_out_start)
            + self.bvh.heap_bytes()
    }
}

/// Locations on the surface ([`Location`]): positions, faces, corners.
impl Surface {
    /// The canonical halfedge of `h`'s edge: the smaller of `h` and its twin.
    pub fn canonical(&self, h: u32) -> u32 {
        let t = self.halfedges.twin(h);
        if t == INVALID { h } else { h.min(t) }
    }

    /// 3D position of a location.
    pub fn position(&self, loc: Location) -> DVec3 {
        match loc {
            Location::Vertex(v) => self.points[v as usize],
            Location::Edge { h, t } => {
                let (a, b) = (self.halfedges.tail(h), self.halfedges.head(h));
                self.points[a as usize].lerp(self.points[b as usize], t)
            }
            Location::Face { tri, bary, .. } => {
                let t = self.triangles[tri as usize];
                (0..3).map(|k| self.points[self.halfedges.tail(t[k]) as usize] * bary[k]).sum()
            }
        }
    }

    /// Position of a location on the mesh posed at `points` (one per mesh vertex).
    pub fn position_in(&self, loc: Location, points: &[[f64; 3]]) -> DVec3 {
        let p = |v: u32| DVec3::from_array(points[v as usize]);
        match loc {
            Location::Vertex(v) => p(v),
            Location::Edge { h, t } => p(self.halfedges.tail(h)).lerp(p(self.halfedges.head(h)), t),
            Location::Face { tri, bary, .. } => {
                let t = self.triangles[tri as usize];
                (0..3).map(|k| p(self.halfedges.tail(t[k])) * bary[k]).sum()
            }
        }
    }

    /// The faces whose closure contains `loc`, into `out`.
    pub fn faces_of(&self, loc: Location, out: &mut Vec<u32>) {
        out.clear();
        match loc {
            Location::Vertex(v) => out.extend(self.vertex_halfedges(v).iter().map(|&h| self.halfedges.face(h))),
            Location::Edge { h, .. } => {
                out.push(self.halfedges.face(h));
                let t = self.halfedges.twin(h);
                if t != INVALID {
                    out.push(self.halfedges.face(t));
                }
            }
            Location::Face { face, .. } => out.push(face),
        }
    }

    /// The outgoing halfedges of vertex `v` (one per incident face corner).
    pub fn vertex_halfedges(&self, v: u32) -> &[u32] {
        &self.vertex_out[self.vertex_out_start[v as usize] as usize..self.vertex_out_start[v as usize + 1] as usize]
    }

    /// The corner (halfedge) of face `f` at vertex `v`, if `v` is a corner of `f`.
    pub fn corner_of(&self, f: u32, v: u32) -> Option<u32> {
        self.halfedges.face_halfedges(f).find(|&h| self.halfedges.tail(h) == v)
    }

    /// 2D position of `loc` in face `f`'s plane; `loc` must lie in `f`'s closure.
    pub fn position_2d(&self, f: u32, loc: Location) -> DVec2 {
        let c = &self.corners_2d;
        match loc {
            Location::Vertex(v) => match self.corner_of(f, v) {
                Some(h) => c[h as usize],
                None => self.planes[f as usize].to_2d(self.points[v as usize]),
            },
            Location::Edge { h, t } => {
                if self.halfedges.face(h) == f {
                    c[h as usize].lerp(c[self.halfedges.next(h) as usize], t)
                } else {
                    let w = self.halfedges.twin(h);
                    c[w as usize].lerp(c[self.halfedges.next(w) as usize], 1.0 - t)
                }
            }
            Location::Face { tri, bary, face } => {
                if face == f {
                    let t = self.triangles[tri as usize];
                    (0..3).map(|k| c[t[k] as usize] * bary[k]).sum()
                } else {
                    self.planes[f as usize].to_2d(self.position(loc))
                }
            }
        }
    }

    /// The location of the point at 2D position `p` of face `f`: a vertex or
    /// edge point when within `tol` (3D distance) of one, else a face point.
    pub fn locate_in_face(&self, f: u32, p: DVec2, tol: f64) -> Location {
        let he = &self.halfedges;
        let c = &self.corners_2d;
        for h in he.face_halfedges(f) {
            if (c[h as usize] - p).length() <= tol {
                return Location::Vertex(he.tail(h));
            }
        }
        for h in he.face_halfedges(f) {
            let (a, b) = (c[h as usize], c[he.next(h) as usize]);
            let e = b - a;
            let t = ((p - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
            if (a + e * t - p).length() <= tol {
                return self.edge_location(h, t);
            }
        }
        self.face_point(f, p)
    }

    /// The face location of the point at 2D position `p` of face `f`
    /// (inside or on its boundary; no snapping to vertices or edges).
    pub fn face_point(&self, f: u32, p: DVec2) -> Location {
        let c = &self.corners_2d;
        // The triangle with the largest minimum barycentric coordinate.
        let mut best = (f64::NEG_INFINITY, 0u32, [0.0; 3]);
        for (k, tri) in self.face_triangles(f) {
            let bary = barycentric_2d(p, tri.map(|i| c[i as usize]));
            let m = bary[0].min(bary[1]).min(bary[2]);
            if m > best.0 {
                best = (m, k, bary);
            }
        }
        let mut bary = best.2.map(|x| x.max(0.0));
        let s: f64 = bary.iter().sum();
        bary = bary.map(|x| x / s);
        Location::Face { face: f, tri: best.1, bary }
    }

    /// An edge location for parameter `t` along halfedge `h` (any of the pair),
    /// expressed on the canonical halfedge.
    pub fn edge_location(&self, h: u32, t: f64) -> Location {
        let c = self.canonical(h);
        if c == h { Location::Edge { h, t } } else { Location::Edge { h: c, t: 1.0 - t } }
    }

    /// The triangles of face `f` with their global indices.
    pub fn face_triangles(&self, f: u32) -> impl Iterator<Item = (u32, [u32; 3])> + '_ {
        let (s, e) = (self.face_tri_start[f as usize], self.face_tri_start[f as usize + 1]);
        (s..e).map(move |k| (k, self.triangles[k as usize]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ear_clipping_tiles_a_nonconvex_polygon() {
        // An L-shape (counter-clockwise).
        let l = [(0., 0.), (2., 0.), (2., 1.), (1., 1.), (1., 2.), (0., 2.)].map(|(x, y)| DVec2::new(x, y));
        let mut tris = Vec::new();
        triangulate(&l, &mut tris).unwrap();
        assert_eq!(tris.len(), 4);
        let total: f64 = tris.iter().map(|t| signed_area(&t.map(|k| l[k as usize]))).sum();
        assert!((total - 3.0).abs() < 1e-12);
        assert!(tris.iter().all(|t| signed_area(&t.map(|k| l[k as usize])) > 0.0));
    }

    #[test]
    fn folded_and_zero_area_faces_are_named() {
        let pts = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [2., 0., 0.]];
        // A pentagram (corners of a regular pentagon visited with stride 2):
        // positive vector area, but its edges cross.
        let star: Vec<[f64; 3]> = (0..5)
            .map(|k| {
                let a = std::f64::consts::TAU * (2 * k) as f64 / 5.0;
                [a.cos(), a.sin(), 0.0]
            })
            .collect();
        let m = PolyMesh::new(&[5], &[0, 1, 2, 3, 4], 5).unwrap();
        assert!(matches!(Surface::new(&m, &star), Err(Error::FoldedFace { face: 0 })));
        // Collinear triangle 0-1-4.
        let m = PolyMesh::new(&[3, 3], &[0, 1, 2, 0, 4, 1], 5).unwrap();
        assert!(matches!(Surface::new(&m, &pts), Err(Error::ZeroAreaFace { face: 1, .. })));
    }
}
