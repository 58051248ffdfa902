//! Halfedge connectivity, the one structure both the input mesh and the
//! binding's cut-mesh are navigated by, and the checks that make a polygon
//! mesh one: manifold edges, manifold vertices, consistent orientation.
//!
//! Struct-of-arrays with `u32` handles (geometry-central style). Faces are
//! loops of contiguous halfedges: halfedge `h` of face `f`'s `k`-th corner
//! runs from corner `k` to corner `k + 1`, so for a [`PolyMesh`] the
//! halfedges are in the order of `PolyMesh::face_vertex_indices` and
//! halfedge `h` *is* face corner `h`. `next` and `prev` follow from the
//! loops (no array of their own). The cut-mesh builds the same structure
//! from its cut-faces with [`Halfedges::from_loops`]: a crack's two
//! halfedges may bound one face there, which a mesh's never do.

use crate::error::{Error, Result};
use crate::mesh::PolyMesh;

/// Marks a missing twin (a boundary halfedge).
pub const INVALID: u32 = u32::MAX;

/// Immutable halfedge connectivity: faces as loops of contiguous halfedges.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Halfedges {
    /// Tail vertex of each halfedge (= the face corner's vertex).
    #[serde(with = "crate::persist::pod")]
    tail: Vec<u32>,
    /// Opposite halfedge, or [`INVALID`] on the boundary.
    #[serde(with = "crate::persist::pod")]
    twin: Vec<u32>,
    /// Face of each halfedge.
    #[serde(with = "crate::persist::pod")]
    face: Vec<u32>,
    /// First halfedge of each face (`n_faces + 1` entries: face `f` owns `face_start[f]..face_start[f+1]`).
    #[serde(with = "crate::persist::pod")]
    face_start: Vec<u32>,
}

impl Halfedges {
    /// Builds the connectivity and checks that the mesh is an oriented
    /// manifold (possibly with boundary and several components). Errors name
    /// the offending edge, vertex or faces.
    pub fn new(mesh: &PolyMesh) -> Result<Self> {
        let n_he = mesh.face_vertex_indices().len();
        let mut tail = Vec::with_capacity(n_he);
        let mut face = Vec::with_capacity(n_he);
        let mut face_start = Vec::with_capacity(mesh.n_faces() + 1);
        for (f, corners) in mesh.faces().enumerate() {
            let start = tail.len() as u32;
            face_start.push(start);
            let n = corners.len() as u32;
            for k in 0..n {
                tail.push(corners[k as usize]);
                face.push(f as u32);
            }
        }
        face_start.push(n_he as u32);
        let mut he = Self::from_loops(tail, vec![INVALID; n_he], face, face_start);

        // Twins: sort halfedges by undirected edge `(a, b)`, `a < b`: a
        // counting sort on `a` (the mesh's vertex indices are in range),
        // then each vertex's few entries by `(b, h)` — the order a full sort
        // of the triples gives, in linear time (the whole-array sort stood
        // out in the 376k-vertex binding's profile).
        let key = |h: usize| {
            let (a, b) = (he.tail(h as u32), he.head(h as u32));
            (a.min(b), a.max(b))
        };
        let n_vertices = mesh.n_vertices();
        let lower: Vec<u32> = (0..n_he).map(|h| key(h).0).collect();
        let (bucket, order) = crate::sparse::group_by_key(n_vertices, &lower);
        let mut keyed: Vec<(u32, u32, u32)> = order
            .iter()
            .map(|&h| {
                let (a, b) = key(h as usize);
                (a, b, h)
            })
            .collect();
        for v in 0..n_vertices {
            keyed[bucket[v] as usize..bucket[v + 1] as usize].sort_unstable();
        }
        let mut i = 0;
        while i < keyed.len() {
            let mut j = i + 1;
            while j < keyed.len() && keyed[j].0 == keyed[i].0 && keyed[j].1 == keyed[i].1 {
                j += 1;
            }
            let (a, b) = (keyed[i].0, keyed[i].1);
            match j - i {
                1 => {}
                2 => {
                    let (h1, h2) = (keyed[i].2 as usize, keyed[i + 1].2 as usize);
                    if he.tail[h1] == he.tail[h2] {
                        return Err(Error::InconsistentOrientation { a, b, faces: [he.face[h1], he.face[h2]] });
                    }
                    he.twin[h1] = h2 as u32;
                    he.twin[h2] = h1 as u32;
                }
                count => {
                    let faces = keyed[i..j].iter().map(|k| he.face[k.2 as usize]).collect();
                    return Err(Error::NonManifoldEdge { a, b, faces, count });
                }
            }
            i = j;
        }

        he.check_manifold_vertices(mesh.n_vertices())?;
        Ok(he)
    }

    /// The connectivity of faces given as loops, unchecked: face `f` owns
    /// halfedges `face_start[f]..face_start[f + 1]` in loop order, `tail`,
    /// `twin` ([`INVALID`] on the boundary) and `face` are per halfedge. For
    /// structures whose builder guarantees them (the cut-mesh).
    pub(crate) fn from_loops(tail: Vec<u32>, twin: Vec<u32>, face: Vec<u32>, face_start: Vec<u32>) -> Self {
        debug_assert!(tail.len() == twin.len() && tail.len() == face.len());
        debug_assert_eq!(face_start.last().copied(), Some(tail.len() as u32));
        Self { tail, twin, face, face_start }
    }

    /// A vertex is manifold when its incident faces form a single fan: walking
    /// around it from one outgoing halfedge reaches all of them.
    fn check_manifold_vertices(&self, n_vertices: usize) -> Result<()> {
        let mut degree = vec![0u32; n_vertices];
        let mut some_out = vec![INVALID; n_vertices];
        for h in 0..self.n_halfedges() {
            let v = self.tail[h] as usize;
            degree[v] += 1;
            // Prefer a boundary halfedge (no twin of its previous) as the start of the walk.
            if some_out[v] == INVALID || self.twin[self.prev(h as u32) as usize] == INVALID {
                some_out[v] = h as u32;
            }
        }
        for v in 0..n_vertices {
            let start = some_out[v];
            if start == INVALID {
                continue; // unreferenced vertex: passes through untouched
            }
            // Walk clockwise: h -> twin(h) -> next. Stops at the boundary or back at start.
            let mut seen = 1u32;
            let mut h = start;
            loop {
                let t = self.twin[h as usize];
                if t == INVALID {
                    break;
                }
                h = self.next(t);
                if h == start {
                    break;
                }
                seen += 1;
                if seen > degree[v] {
                    break;
                }
            }
            if seen != degree[v] {
                return Err(Error::NonManifoldVertex { vertex: v as u32, fans_cover: seen, faces: degree[v] });
            }
        }
        Ok(())
    }

    pub fn n_halfedges(&self) -> usize {
        self.tail.len()
    }
    pub fn n_faces(&self) -> usize {
        self.face_start.len() - 1
    }
    /// Tail vertex of `h`.
    pub fn tail(&self, h: u32) -> u32 {
        self.tail[h as usize]
    }
    /// Head vertex of `h`.
    pub fn head(&self, h: u32) -> u32 {
        self.tail[self.next(h) as usize]
    }
    /// Next halfedge around the face.
    pub fn next(&self, h: u32) -> u32 {
        let f = self.face[h as usize] as usize;
        if h + 1 == self.face_start[f + 1] { self.face_start[f] } else { h + 1 }
    }
    /// Previous halfedge around the face.
    pub fn prev(&self, h: u32) -> u32 {
        let f = self.face[h as usize] as usize;
        let (s, e) = (self.face_start[f], self.face_start[f + 1]);
        if h == s { e - 1 } else { h - 1 }
    }
    /// Opposite halfedge, or [`INVALID`] on the boundary.
    pub fn twin(&self, h: u32) -> u32 {
        self.twin[h as usize]
    }
    pub fn face(&self, h: u32) -> u32 {
        self.face[h as usize]
    }
    /// The halfedges of face `f`, in order.
    pub fn face_halfedges(&self, f: u32) -> std::ops::Range<u32> {
        self.face_start[f as usize]..self.face_start[f as usize + 1]
    }
    pub fn is_boundary(&self, h: u32) -> bool {
        self.twin[h as usize] == INVALID
    }
}

impl Halfedges {
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.tail) + bytes(&self.twin) + bytes(&self.face) + bytes(&self.face_start)
    }
}

/// The connected components of a [`Halfedges`] (faces connected through
/// shared edges).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Components {
    n: usize,
    /// Component of each face.
    #[serde(with = "crate::persist::pod")]
    face_component: Vec<u32>,
}

impl Components {
    /// Labels the faces of `he` by connected component.
    pub fn new(he: &Halfedges) -> Self {
        let n_faces = he.n_faces();
        let mut comp = vec![INVALID; n_faces];
        let mut stack = Vec::new();
        let mut n = 0u32;
        for seed in 0..n_faces {
            if comp[seed] != INVALID {
                continue;
            }
            comp[seed] = n;
            stack.push(seed as u32);
            while let Some(f) = stack.pop() {
                for h in he.face_halfedges(f) {
                    let t = he.twin(h);
                    if t != INVALID {
                        let g = he.face(t);
                        if comp[g as usize] == INVALID {
                            comp[g as usize] = n;
                            stack.push(g);
                        }
                    }
                }
            }
            n += 1;
        }
        Self { n: n as usize, face_component: comp }
    }

    /// Number of connected components.
    pub fn len(&self) -> usize {
        self.n
    }
    /// Whether there are no faces.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    /// Component of face `f`.
    pub fn of_face(&self, f: u32) -> u32 {
        self.face_component[f as usize]
    }
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.face_component)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn he(counts: &[u32], idx: &[u32], n: usize) -> Result<Halfedges> {
        Halfedges::new(&PolyMesh::new(counts, idx, n)?)
    }

    #[test]
    fn a_quad_strip_with_boundary() {
        // 0-1-2 / 3-4-5 : two quads
        let h = he(&[4, 4], &[0, 1, 4, 3, 1, 2, 5, 4], 6).unwrap();
        assert_eq!(h.n_halfedges(), 8);
        assert_eq!(h.twin(1), 7); // 1->4 and 4->1
        assert_eq!(h.head(1), 4);
        assert!(h.is_boundary(0));
        assert_eq!(h.prev(4), 7);
        assert_eq!(Components::new(&h).len(), 1);
    }

    #[test]
    fn closed_tetrahedron_and_two_components() {
        let tet = [0, 2, 1, 0, 1, 3, 1, 2, 3, 2, 0, 3];
        let h = he(&[3; 4], &tet, 4).unwrap();
        assert!((0..12).all(|k| h.twin(k) != INVALID && h.twin(h.twin(k)) == k));
        let mut two = tet.to_vec();
        two.extend(tet.iter().map(|v| v + 4));
        let h = he(&[3; 8], &two, 8).unwrap();
        let c = Components::new(&h);
        assert_eq!(c.len(), 2);
        assert_eq!(c.of_face(5), 1);
    }

    #[test]
    fn errors_name_edges_faces_and_vertices() {
        // Three triangles on edge (0,1).
        assert!(matches!(
            he(&[3, 3, 3], &[0, 1, 2, 1, 0, 3, 0, 1, 4], 5),
            Err(Error::NonManifoldEdge { a: 0, b: 1, count: 3, .. })
        ));
        // Two triangles traversing edge (0,1) the same way.
        assert_eq!(
            he(&[3, 3], &[0, 1, 2, 0, 1, 3], 4).unwrap_err(),
            Error::InconsistentOrientation { a: 0, b: 1, faces: [0, 1] }
        );
        // Bowtie: two triangles sharing only vertex 0.
        assert!(matches!(he(&[3, 3], &[0, 1, 2, 0, 3, 4], 5), Err(Error::NonManifoldVertex { vertex: 0, .. })));
    }
}
