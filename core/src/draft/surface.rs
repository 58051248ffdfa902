//! The surface a draft is cut from: the mesh's fan triangles (as
//! [`ClosestPointBvh::new`] numbers them) with edge adjacency for walking
//! plane sections, area-weighted vertex normals, and the principal axes of
//! the area-weighted vertex distribution.

use glam::DVec3;
use rustc_hash::FxHashMap;

use crate::closest_point::ClosestPointBvh;
use crate::error::Result;
use crate::halfedge::{Halfedges, INVALID};
use crate::mesh::PolyMesh;

/// Fan triangles of a polygon mesh with their edges.
pub(crate) struct TriSurface {
    pub points: Vec<DVec3>,
    /// `(v0, v_k, v_{k+1})` of every face, face after face.
    pub tris: Vec<[u32; 3]>,
    /// Edge `k` of a triangle joins its corners `k` and `k + 1`.
    pub tri_edges: Vec<[u32; 3]>,
    /// The two vertices of every edge.
    pub edges: Vec<[u32; 2]>,
    /// The triangles on either side of every edge ([`INVALID`] on the boundary).
    pub edge_tris: Vec<[u32; 2]>,
    /// Unit normal of every triangle (zero when degenerate).
    pub tri_normals: Vec<DVec3>,
    /// Area-weighted unit vertex normals: the sum of the vector areas of the
    /// faces around the vertex, normalised (zero when they cancel).
    pub vertex_normals: Vec<DVec3>,
    pub bvh: ClosestPointBvh,
    pub mean_edge: f64,
    pub diagonal: f64,
    /// Vertex neighbours over the triangles' edges: `neighbours[start[v]..start[v + 1]]`.
    neighbour_start: Vec<u32>,
    neighbours: Vec<u32>,
}

impl TriSurface {
    /// Checks that the mesh is an oriented manifold (errors name the edge,
    /// vertex or faces) and builds the triangles.
    pub fn new(mesh: &PolyMesh, points: &[[f64; 3]]) -> Result<Self> {
        mesh.check_points(points, "mesh point")?;
        Halfedges::new(mesh)?;
        let p: Vec<DVec3> = points.iter().map(|&x| DVec3::from_array(x)).collect();
        let mut tris = Vec::new();
        let mut tri_edges = Vec::new();
        let mut edges: Vec<[u32; 2]> = Vec::new();
        let mut edge_tris: Vec<[u32; 2]> = Vec::new();
        // Mesh edges are shared by two faces (found by their vertex pair);
        // fan diagonals belong to one face, so they get their own edge even
        // when another face has an edge between the same two vertices.
        let mut mesh_edge: FxHashMap<(u32, u32), u32> = FxHashMap::default();
        let mut vertex_normals = vec![DVec3::ZERO; p.len()];
        let add_edge = |edges: &mut Vec<[u32; 2]>, edge_tris: &mut Vec<[u32; 2]>, a: u32, b: u32, t: u32| {
            edges.push([a, b]);
            edge_tris.push([t, INVALID]);
            (edges.len() - 1) as u32
        };
        for face in mesh.faces() {
            let n = face.len();
            let mut area = DVec3::ZERO;
            for k in 0..n {
                area += p[face[k] as usize].cross(p[face[(k + 1) % n] as usize]);
            }
            for &v in face {
                vertex_normals[v as usize] += 0.5 * area;
            }
            let mut previous_diagonal = INVALID;
            for k in 1..n - 1 {
                let t = tris.len() as u32;
                let corners = [face[0], face[k], face[k + 1]];
                tris.push(corners);
                let mut ids = [INVALID; 3];
                for (e, id) in ids.iter_mut().enumerate() {
                    let (a, b) = (corners[e], corners[(e + 1) % 3]);
                    let is_mesh_edge = match e {
                        0 => k == 1,
                        1 => true,
                        _ => k == n - 2,
                    };
                    *id = if is_mesh_edge {
                        let key = (a.min(b), a.max(b));
                        match mesh_edge.get(&key) {
                            Some(&id) => {
                                edge_tris[id as usize][1] = t;
                                id
                            }
                            None => {
                                let id = add_edge(&mut edges, &mut edge_tris, a, b, t);
                                mesh_edge.insert(key, id);
                                id
                            }
                        }
                    } else if e == 0 {
                        // (v0, v_k): the diagonal the previous fan triangle ended with.
                        edge_tris[previous_diagonal as usize][1] = t;
                        previous_diagonal
                    } else {
                        let id = add_edge(&mut edges, &mut edge_tris, a, b, t);
                        previous_diagonal = id;
                        id
                    };
                }
                tri_edges.push(ids);
            }
        }
        let tri_normals = tris
            .iter()
            .map(|t| {
                (p[t[1] as usize] - p[t[0] as usize]).cross(p[t[2] as usize] - p[t[0] as usize]).normalize_or_zero()
            })
            .collect();
        for n in &mut vertex_normals {
            *n = n.normalize_or_zero();
        }
        let bvh = ClosestPointBvh::new(mesh, points)?;
        let mut neighbour_start = vec![0u32; p.len() + 1];
        for [a, b] in &edges {
            neighbour_start[*a as usize + 1] += 1;
            neighbour_start[*b as usize + 1] += 1;
        }
        for v in 0..p.len() {
            neighbour_start[v + 1] += neighbour_start[v];
        }
        let mut fill = neighbour_start.clone();
        let mut neighbours = vec![0u32; 2 * edges.len()];
        for [a, b] in &edges {
            neighbours[fill[*a as usize] as usize] = *b;
            fill[*a as usize] += 1;
            neighbours[fill[*b as usize] as usize] = *a;
            fill[*b as usize] += 1;
        }
        Ok(Self {
            points: p,
            tris,
            tri_edges,
            edges,
            edge_tris,
            tri_normals,
            vertex_normals,
            bvh,
            mean_edge: mesh.mean_edge_length(points),
            diagonal: crate::mesh::bounding_box_diagonal(points),
            neighbour_start,
            neighbours,
        })
    }

    /// Whether two triangles are on one sheet of the surface, locally: they
    /// face the same way (normals less than 60° apart) and are neighbours
    /// (they share a vertex, or an edge joins a corner of one to a corner of
    /// the other). Points a fraction of a mean edge apart on one sheet are
    /// in such triangles; points as close in space on two sheets (a flipper
    /// against the body, the two sides of a thin fin) are not.
    pub fn same_sheet(&self, a: u32, b: u32) -> bool {
        if self.tri_normals[a as usize].dot(self.tri_normals[b as usize]) <= 0.5 {
            return false;
        }
        let (ta, tb) = (self.tris[a as usize], self.tris[b as usize]);
        ta.iter().any(|&v| {
            tb.contains(&v)
                || self.neighbours
                    [self.neighbour_start[v as usize] as usize..self.neighbour_start[v as usize + 1] as usize]
                    .iter()
                    .any(|w| tb.contains(w))
        })
    }

    /// The area-weighted centroid and covariance of the vertices, each
    /// vertex weighted by a third of the area of its triangles.
    pub fn weighted_covariance(&self) -> (DVec3, [[f64; 3]; 3]) {
        let mut weight = vec![0.0; self.points.len()];
        for t in &self.tris {
            let [a, b, c] = t.map(|v| self.points[v as usize]);
            let area = 0.5 * (b - a).cross(c - a).length();
            for &v in t {
                weight[v as usize] += area / 3.0;
            }
        }
        let total: f64 = weight.iter().sum();
        let centroid = self.points.iter().zip(&weight).map(|(p, w)| *p * *w).sum::<DVec3>() / total;
        let mut cov = [[0.0; 3]; 3];
        for (p, w) in self.points.iter().zip(&weight) {
            let d = (*p - centroid).to_array();
            for r in 0..3 {
                for c in 0..3 {
                    cov[r][c] += w * d[r] * d[c];
                }
            }
        }
        (centroid, cov)
    }
}

/// Unit eigenvectors of a symmetric 3×3 matrix by decreasing eigenvalue
/// (cyclic Jacobi rotations), each with its largest component positive.
pub(crate) fn symmetric_eigenvectors(mut a: [[f64; 3]; 3]) -> [DVec3; 3] {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A <- Jᵀ A J with J the rotation in the (p, q) plane.
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    order.map(|k| {
        let e = DVec3::new(v[0][k], v[1][k], v[2][k]).normalize();
        let big = if e.x.abs() >= e.y.abs() && e.x.abs() >= e.z.abs() {
            e.x
        } else if e.y.abs() >= e.z.abs() {
            e.y
        } else {
            e.z
        };
        if big < 0.0 { -e } else { e }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvectors_of_a_rotated_diagonal_matrix() {
        // R diag(5, 2, 1) Rᵀ with R a rotation: the columns of R come back.
        let r = glam::DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let m = r * glam::DMat3::from_diagonal(DVec3::new(5.0, 2.0, 1.0)) * r.transpose();
        let a = [0, 1, 2].map(|i| [0, 1, 2].map(|j| m.col(j)[i]));
        let e = symmetric_eigenvectors(a);
        for (k, col) in [r.x_axis, r.y_axis, r.z_axis].into_iter().enumerate() {
            assert!(e[k].dot(col).abs() > 1.0 - 1e-12, "axis {k}: {:?} vs {:?}", e[k], col);
        }
    }
}
