//! Polygon mesh topology: faces as runs of vertex indices (the USD / OBJ layout).
//!
//! Topology is kept apart from positions, because one topology is posed many
//! times (projection pose, a rest pose per frame, the deformed result).

use crate::error::{Error, Result};

/// The topology of an oriented polygon mesh: `n_faces` faces, each a run of
/// vertex indices, counter-clockwise seen from outside.
///
/// Construction checks what topology alone can check: counts add up, every
/// face has at least 3 corners and no repeated corner, every index is below
/// `n_vertices`. Manifoldness and orientation are checked by the binding.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PolyMesh {
    /// `offsets[f]..offsets[f + 1]` is face `f`'s range in `indices`; `n_faces + 1` entries.
    #[serde(with = "crate::persist::pod")]
    offsets: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    indices: Vec<u32>,
    n_vertices: usize,
}

impl PolyMesh {
    /// Builds the topology from USD-style `face_vertex_counts` and
    /// `face_vertex_indices` for a mesh with `n_vertices` points.
    pub fn new(face_vertex_counts: &[u32], face_vertex_indices: &[u32], n_vertices: usize) -> Result<Self> {
        if face_vertex_counts.is_empty() {
            return Err(Error::Empty { what: "the mesh (it has no faces)" });
        }
        let counts_sum: usize = face_vertex_counts.iter().map(|&c| c as usize).sum();
        if counts_sum != face_vertex_indices.len() {
            return Err(Error::FaceCountMismatch { counts_sum, indices_len: face_vertex_indices.len() });
        }
        if face_vertex_indices.len() >= u32::MAX as usize {
            return Err(Error::CountMismatch {
                what: "face vertex indices (at most 2^32 - 1)",
                expected: u32::MAX as usize - 1,
                got: face_vertex_indices.len(),
            });
        }
        let mut offsets = Vec::with_capacity(face_vertex_counts.len() + 1);
        let mut at = 0u32;
        offsets.push(0);
        for (face, &count) in face_vertex_counts.iter().enumerate() {
            if count < 3 {
                return Err(Error::DegenerateFaceCount { face, count });
            }
            let corners = &face_vertex_indices[at as usize..(at + count) as usize];
            for (k, &v) in corners.iter().enumerate() {
                if v as usize >= n_vertices {
                    return Err(Error::IndexOutOfRange {
                        what: "face vertex index",
                        index: at as usize + k,
                        target: "vertex",
                        value: v,
                        len: n_vertices,
                    });
                }
                if corners[..k].contains(&v) {
                    return Err(Error::RepeatedFaceVertex { face, vertex: v });
                }
            }
            at += count;
            offsets.push(at);
        }
        Ok(Self { offsets, indices: face_vertex_indices.to_vec(), n_vertices })
    }

    /// Number of faces.
    pub fn n_faces(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Number of vertices (points) the faces index into.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// The corners of face `f`, counter-clockwise.
    pub fn face(&self, f: usize) -> &[u32] {
        &self.indices[self.offsets[f] as usize..self.offsets[f + 1] as usize]
    }

    /// Iterates the faces in order.
    pub fn faces(&self) -> impl ExactSizeIterator<Item = &[u32]> + '_ {
        self.offsets.windows(2).map(|w| &self.indices[w[0] as usize..w[1] as usize])
    }

    /// All face vertex indices, face after face.
    pub fn face_vertex_indices(&self) -> &[u32] {
        &self.indices
    }

    /// The number of corners of every face.
    pub fn face_vertex_counts(&self) -> impl ExactSizeIterator<Item = u32> + '_ {
        self.offsets.windows(2).map(|w| w[1] - w[0])
    }

    /// Checks that `points` has one finite point per vertex.
    pub fn check_points(&self, points: &[[f64; 3]], what: &'static str) -> Result<()> {
        if points.len() != self.n_vertices {
            return Err(Error::CountMismatch { what, expected: self.n_vertices, got: points.len() });
        }
        check_finite(points, what)
    }

    /// The undirected edges, each once, as `(low, high)` vertex pairs, sorted.
    pub fn edges(&self) -> Vec<(u32, u32)> {
        let mut edges: Vec<(u32, u32)> = self
            .faces()
            .flat_map(|face| (0..face.len()).map(move |k| (face[k], face[(k + 1) % face.len()])))
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        edges.dedup();
        edges
    }

    /// Mean length of the mesh's edges (each undirected edge once) in the pose `points`.
    pub fn mean_edge_length(&self, points: &[[f64; 3]]) -> f64 {
        let edges = self.edges();
        let sum: f64 = edges.iter().map(|&(a, b)| dist(points[a as usize], points[b as usize])).sum();
        sum / edges.len() as f64
    }

    /// Length of the diagonal of the axis-aligned bounding box of `points`.
    pub fn bounding_box_diagonal(points: &[[f64; 3]]) -> f64 {
        bounding_box_diagonal(points)
    }
}

/// Fails on the first point with a NaN or infinite coordinate, naming it.
pub fn check_finite(points: &[[f64; 3]], what: &'static str) -> Result<()> {
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(index) => Err(Error::NonFinite { what, index, value: points[index] }),
        None => Ok(()),
    }
}

/// Length of the diagonal of the axis-aligned bounding box of `points` (0 when empty).
pub fn bounding_box_diagonal(points: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if points.is_empty() { 0.0 } else { dist(lo, hi) }
}

fn dist(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

impl PolyMesh {
    /// Heap bytes held (offsets and indices; see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.offsets) + crate::heap::bytes(&self.indices)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quad_and_triangle() {
        let m = PolyMesh::new(&[4, 3], &[0, 1, 2, 3, 1, 4, 2], 5).unwrap();
        assert_eq!(m.n_faces(), 2);
        assert_eq!(m.face(1), &[1, 4, 2]);
        assert_eq!(m.face_vertex_counts().collect::<Vec<_>>(), vec![4, 3]);
    }

    #[test]
    fn errors_name_the_offending_element() {
        assert_eq!(
            PolyMesh::new(&[3, 3], &[0, 1, 2, 0, 2, 7], 5),
            Err(Error::IndexOutOfRange { what: "face vertex index", index: 5, target: "vertex", value: 7, len: 5 })
        );
        assert_eq!(PolyMesh::new(&[3, 2], &[0, 1, 2, 0, 2], 5), Err(Error::DegenerateFaceCount { face: 1, count: 2 }));
        assert_eq!(
            PolyMesh::new(&[3, 3], &[0, 1, 2, 0, 2], 5),
            Err(Error::FaceCountMismatch { counts_sum: 6, indices_len: 5 })
        );
        assert_eq!(PolyMesh::new(&[3], &[0, 1, 0], 5), Err(Error::RepeatedFaceVertex { face: 0, vertex: 0 }));
        let m = PolyMesh::new(&[3], &[0, 1, 2], 3).unwrap();
        let bad = [[0.0; 3], [1.0, f64::NAN, 0.0], [0.0; 3]];
        assert!(matches!(m.check_points(&bad, "point"), Err(Error::NonFinite { index: 1, .. })));
        assert!(matches!(m.check_points(&bad[..2], "point"), Err(Error::CountMismatch { expected: 3, got: 2, .. })));
    }
}
