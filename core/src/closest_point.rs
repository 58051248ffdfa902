//! Closest points on a surface: an immutable bounding volume hierarchy over
//! its triangles.
//!
//! [`ClosestPointBvh::new`] fan-triangulates every polygon face
//! `(v0, v1, …, v_{n-1})` as `(v0, v_k, v_{k+1})` for `k = 1..n-1`;
//! [`ClosestPointBvh::from_triangles`] takes any triangulation. Each triangle
//! remembers its parent face, and a face's normal is its vector-area normal
//! (½ Σ x_i × x_{i+1}, normalised). Queries return the exact closest point
//! over all triangles (the hierarchy only prunes, it never approximates), so
//! a query agrees with a brute-force loop over [`closest_point_on_triangle`]
//! to the last bit of the distance, up to ties between equally close
//! triangles.
//!
//! Build is O(n log n) (median splits on the longest axis of the triangle
//! centroids, at most [`LEAF_SIZE`] triangles per leaf); a query visits
//! O(log n) nodes for points near the surface. The structure owns a copy of
//! the positions it was built on and is `Send + Sync`, so one instance can be
//! shared (behind an `Arc`) by the curvenet analysis and the binding.

use glam::DVec3;

use crate::error::{Error, Result};
use crate::mesh::PolyMesh;

/// Most triangles in one leaf of the hierarchy.
pub const LEAF_SIZE: usize = 4;

/// The closest point of a mesh to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// The polygon face hit.
    pub face: u32,
    /// The triangle hit, numbered as given to [`ClosestPointBvh::from_triangles`]
    /// (for [`ClosestPointBvh::new`]: fan triangles face after face).
    pub triangle: u32,
    /// The vertices of that triangle, in its order (for fan triangles
    /// `(v0, v_k, v_{k+1})`).
    pub corners: [u32; 3],
    /// Barycentric coordinates of `point` with respect to `corners`
    /// (non-negative, summing to 1).
    pub barycentric: [f64; 3],
    /// The closest point on the mesh.
    pub point: [f64; 3],
    /// Euclidean distance from the query to `point`.
    pub distance: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
struct Node {
    min: DVec3,
    max: DVec3,
    /// Leaf: first triangle slot in `order`. Inner: index of the right child
    /// (the left child is the next node).
    first_or_right: u32,
    /// Leaf: number of triangles (> 0). Inner: 0.
    count: u32,
}

/// An immutable bounding volume hierarchy over the triangles of a surface
/// (the fan triangles of a polygon mesh, or any triangulation with a parent
/// face per triangle) in one pose, answering closest-point queries.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ClosestPointBvh {
    #[serde(with = "crate::persist::pod")]
    points: Vec<DVec3>,
    /// `#T` triangles as vertex indices, in input order.
    #[serde(with = "crate::persist::pod")]
    triangles: Vec<[u32; 3]>,
    /// The parent face of every triangle, in input order.
    #[serde(with = "crate::persist::pod")]
    triangle_face: Vec<u32>,
    /// Input triangle index of every leaf slot.
    #[serde(with = "crate::persist::pod")]
    leaf_triangle: Vec<u32>,
    /// Corner positions of every leaf slot (leaf order, for locality).
    leaf_corners: Vec<[DVec3; 3]>,
    /// Unit vector-area normal of every face (zero for a zero-area face).
    #[serde(with = "crate::persist::pod")]
    face_normals: Vec<DVec3>,
    /// Vector area of every face.
    #[serde(with = "crate::persist::pod")]
    face_vector_areas: Vec<DVec3>,
    nodes: Vec<Node>,
}

impl ClosestPointBvh {
    /// Builds the hierarchy over the fan triangles of `mesh` posed at
    /// `points` (`#V` positions, one per mesh vertex, all finite). Face `f`'s
    /// triangles are numbered consecutively, face after face, `(v0, v_k,
    /// v_{k+1})` for `k = 1..n-1`.
    pub fn new(mesh: &PolyMesh, points: &[[f64; 3]]) -> Result<Self> {
        mesh.check_points(points, "surface mesh point")?;
        let mut tris = Vec::new();
        for (f, face) in mesh.faces().enumerate() {
            for k in 1..face.len() - 1 {
                tris.push(([face[0], face[k], face[k + 1]], f as u32));
            }
        }
        Self::from_triangles(points, &tris)
    }

    /// Builds the hierarchy over arbitrary triangles: `triangles` is `#T`
    /// pairs `(vertex indices into points, parent face)`. A face's vector
    /// area is the sum of its triangles' vector areas (equal to the polygon's
    /// ½ Σ x_i × x_{i+1} for any triangulation of it); faces are numbered
    /// `0..=max face`. Hits report triangles by their index in `triangles`.
    pub fn from_triangles(points: &[[f64; 3]], triangles: &[([u32; 3], u32)]) -> Result<Self> {
        if triangles.is_empty() {
            return Err(Error::Empty { what: "the closest-point surface (it has no triangles)" });
        }
        if triangles.len() >= u32::MAX as usize {
            return Err(Error::CountMismatch {
                what: "triangles (at most 2^32 - 1)",
                expected: u32::MAX as usize - 1,
                got: triangles.len(),
            });
        }
        crate::mesh::check_finite(points, "surface point")?;
        for (t, (tri, _)) in triangles.iter().enumerate() {
            if let Some(&value) = tri.iter().find(|&&v| v as usize >= points.len()) {
                return Err(Error::IndexOutOfRange {
                    what: "triangle",
                    index: t,
                    target: "point",
                    value,
                    len: points.len(),
                });
            }
        }
        let pts: Vec<DVec3> = points.iter().map(|&p| DVec3::from_array(p)).collect();
        let n_faces = triangles.iter().map(|&(_, f)| f as usize + 1).max().unwrap_or(0);
        let mut face_vector_areas = vec![DVec3::ZERO; n_faces];
        for &(t, f) in triangles {
            let [a, b, c] = t.map(|v| pts[v as usize]);
            face_vector_areas[f as usize] += 0.5 * (b - a).cross(c - a);
        }
        let face_normals = face_vector_areas
            .iter()
            .map(|a| {
                let len = a.length();
                if len > 0.0 { *a / len } else { DVec3::ZERO }
            })
            .collect();

        let tris: Vec<[u32; 3]> = triangles.iter().map(|&(t, _)| t).collect();
        let centroids: Vec<DVec3> =
            tris.iter().map(|t| (pts[t[0] as usize] + pts[t[1] as usize] + pts[t[2] as usize]) / 3.0).collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        build(&pts, &tris, &centroids, &mut order, 0, &mut nodes, PARALLEL_TRIANGLES);
        let leaf_corners = order.iter().map(|&t| tris[t as usize].map(|v| pts[v as usize])).collect();
        Ok(Self {
            points: pts,
            triangle_face: triangles.iter().map(|&(_, f)| f).collect(),
            triangles: tris,
            leaf_triangle: order,
            leaf_corners,
            face_normals,
            face_vector_areas,
            nodes,
        })
    }

    /// Number of triangles.
    pub fn n_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// Number of faces (one more than the largest parent face).
    pub fn n_faces(&self) -> usize {
        self.face_normals.len()
    }

    /// Triangle `t`: its three vertices and its parent face.
    pub fn triangle(&self, t: usize) -> ([u32; 3], u32) {
        (self.triangles[t], self.triangle_face[t])
    }

    /// The positions the hierarchy was built on.
    pub fn point(&self, v: usize) -> [f64; 3] {
        self.points[v].to_array()
    }

    /// Unit normal of face `f`: its vector area normalised (the zero vector
    /// for a face of zero vector area).
    pub fn face_normal(&self, f: usize) -> [f64; 3] {
        self.face_normals[f].to_array()
    }

    /// Vector area of face `f`, ½ Σ x_i × x_{i+1} over its corners (its
    /// length is the area of a planar face).
    pub fn face_vector_area(&self, f: usize) -> [f64; 3] {
        self.face_vector_areas[f].to_array()
    }

    /// The closest point of the mesh to `p`. Fails only for a non-finite `p`.
    pub fn closest_point(&self, p: [f64; 3]) -> Result<Hit> {
        if !p.iter().all(|c| c.is_finite()) {
            return Err(Error::NonFinite { what: "closest-point query", index: 0, value: p });
        }
        let q = DVec3::from_array(p);
        let mut best_d2 = f64::INFINITY;
        let mut best: Option<(usize, DVec3, DVec3)> = None;
        // Depth is at most ~log2(#T) + 1 for median splits; 64 slots are plenty.
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if aabb_distance2(node, q) >= best_d2 {
                continue;
            }
            if node.count > 0 {
                let first = node.first_or_right as usize;
                for t in first..first + node.count as usize {
                    let [a, b, c] = self.leaf_corners[t];
                    let (bary, x) = closest_on_triangle(q, a, b, c);
                    let d2 = (x - q).length_squared();
                    if d2 < best_d2 || best.is_none() {
                        best_d2 = d2;
                        best = Some((t, bary, x));
                    }
                }
            } else {
                let left = stack[top] + 1;
                let right = node.first_or_right;
                let dl = aabb_distance2(&self.nodes[left as usize], q);
                let dr = aabb_distance2(&self.nodes[right as usize], q);
                // Push the farther child first so the nearer one is visited first.
                let (near, far, dfar) = if dl <= dr { (left, right, dr) } else { (right, left, dl) };
                if dfar < best_d2 {
                    stack[top] = far;
                    top += 1;
                }
                stack[top] = near;
                top += 1;
            }
        }
        // There is at least one triangle (construction refuses none), so some
        // leaf was visited with `best` still None.
        let (slot, bary, x) = best.expect("a non-empty hierarchy always yields a hit");
        let t = self.leaf_triangle[slot] as usize;
        Ok(Hit {
            face: self.triangle_face[t],
            triangle: t as u32,
            corners: self.triangles[t],
            barycentric: bary.to_array(),
            point: x.to_array(),
            distance: best_d2.sqrt(),
        })
    }
}

/// A subtree over at least this many triangles builds its two halves on
/// two threads (rayon), into their own node lists appended in the order
/// the sequential build gives, so the hierarchy is the same node for node;
/// the 376k growth mesh's 752k triangles build in about half the time on
/// 2 cores.
const PARALLEL_TRIANGLES: usize = 1 << 15;

/// Builds the subtree over `order` (triangle slots `first..` of the
/// hierarchy's order) into `nodes`, depth first (left child right after its
/// parent); returns its root's index.
fn build(
    pts: &[DVec3],
    tris: &[[u32; 3]],
    centroids: &[DVec3],
    order: &mut [u32],
    first: usize,
    nodes: &mut Vec<Node>,
    parallel_from: usize,
) -> u32 {
    let mut min = DVec3::splat(f64::INFINITY);
    let mut max = DVec3::splat(f64::NEG_INFINITY);
    let mut cmin = min;
    let mut cmax = max;
    for &t in order.iter() {
        for &v in &tris[t as usize] {
            min = min.min(pts[v as usize]);
            max = max.max(pts[v as usize]);
        }
        cmin = cmin.min(centroids[t as usize]);
        cmax = cmax.max(centroids[t as usize]);
    }
    let index = nodes.len() as u32;
    nodes.push(Node { min, max, first_or_right: first as u32, count: order.len() as u32 });
    if order.len() <= LEAF_SIZE {
        return index;
    }
    let extent = cmax - cmin;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis]).then(a.cmp(&b))
    });
    let parallel = order.len() >= parallel_from;
    let (lo, hi) = order.split_at_mut(mid);
    let right = if parallel {
        let half = |order: &mut [u32], first: usize| {
            let mut nodes = Vec::with_capacity(2 * order.len() / LEAF_SIZE + 1);
            build(pts, tris, centroids, order, first, &mut nodes, parallel_from);
            nodes
        };
        let (left, right) = rayon::join(|| half(lo, first), || half(hi, first + mid));
        // Inner nodes point at their right child: offset them by where
        // their list lands (leaves point into `order`, already absolute).
        let mut append = |list: Vec<Node>| {
            let base = nodes.len() as u32;
            nodes.extend(list.into_iter().map(|mut n| {
                if n.count == 0 {
                    n.first_or_right += base;
                }
                n
            }));
            base
        };
        append(left);
        append(right)
    } else {
        build(pts, tris, centroids, lo, first, nodes, parallel_from);
        build(pts, tris, centroids, hi, first + mid, nodes, parallel_from)
    };
    nodes[index as usize].first_or_right = right;
    nodes[index as usize].count = 0;
    index
}

fn aabb_distance2(node: &Node, q: DVec3) -> f64 {
    let d = (node.min - q).max(q - node.max).max(DVec3::ZERO);
    d.length_squared()
}

/// The closest point to `p` on the triangle `(a, b, c)`: returns its
/// barycentric coordinates (non-negative, summing to 1) and the point.
/// Robust for degenerate (zero-area) triangles, where it returns the closest
/// point on the closest edge.
pub fn closest_point_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let (bary, x) =
        closest_on_triangle(DVec3::from_array(p), DVec3::from_array(a), DVec3::from_array(b), DVec3::from_array(c));
    (bary.to_array(), x.to_array())
}

/// Ericson, "Real-Time Collision Detection", §5.1.5, with a fallback to the
/// edges for degenerate triangles.
pub(crate) fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, DVec3) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (DVec3::X, a);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (DVec3::Y, b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 && d1 - d3 > 0.0 {
        let v = d1 / (d1 - d3);
        return (DVec3::new(1.0 - v, v, 0.0), a + v * ab);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (DVec3::Z, c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 && d2 - d6 > 0.0 {
        let w = d2 / (d2 - d6);
        return (DVec3::new(1.0 - w, 0.0, w), a + w * ac);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 && (d4 - d3) + (d5 - d6) > 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (DVec3::new(0.0, 1.0 - w, w), b + w * (c - b));
    }
    let denom = va + vb + vc;
    if denom > 0.0 && denom.is_finite() {
        let v = vb / denom;
        let w = vc / denom;
        if v >= 0.0 && w >= 0.0 && v + w <= 1.0 {
            return (DVec3::new(1.0 - v - w, v, w), a + v * ab + w * ac);
        }
    }
    // Degenerate triangle (or round-off at a region boundary): the closest of
    // the three edges.
    let candidates = [(segment(p, a, b), [0usize, 1]), (segment(p, b, c), [1, 2]), (segment(p, c, a), [2, 0])];
    let mut best = (f64::INFINITY, DVec3::X, a);
    for ((s, x), [i, j]) in candidates {
        let d = (x - p).length_squared();
        if d < best.0 {
            let mut bary = [0.0; 3];
            bary[i] = 1.0 - s;
            bary[j] += s;
            best = (d, DVec3::from_array(bary), x);
        }
    }
    (best.1, best.2)
}

/// Closest point on segment `[a, b]` to `p`, as `(s, a + s (b - a))`.
fn segment(p: DVec3, a: DVec3, b: DVec3) -> (f64, DVec3) {
    let d = b - a;
    let len2 = d.length_squared();
    let s = if len2 > 0.0 { ((p - a).dot(d) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (s, a + s * d)
}

impl ClosestPointBvh {
    /// Heap bytes held: points, triangles, leaves and nodes (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.points)
            + bytes(&self.triangles)
            + bytes(&self.triangle_face)
            + bytes(&self.leaf_triangle)
            + bytes(&self.leaf_corners)
            + bytes(&self.face_normals)
            + bytes(&self.face_vector_areas)
            + bytes(&self.nodes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel build gives the sequential build's hierarchy, node for
    /// node (random triangles, parallel from 64 triangles up).
    #[test]
    fn parallel_build_equals_the_sequential_one() {
        let mut rng = crate::polygon_laplacian::tests::Rng(0x5851_F42D_4C95_7F2D);
        let pts: Vec<DVec3> = (0..3000).map(|_| rng.vec3()).collect();
        let tris: Vec<[u32; 3]> =
            (0..5000).map(|_| std::array::from_fn(|_| ((rng.next() + 1.0) * 0.5 * 3000.0) as u32 % 3000)).collect();
        let centroids: Vec<DVec3> =
            tris.iter().map(|t| (pts[t[0] as usize] + pts[t[1] as usize] + pts[t[2] as usize]) / 3.0).collect();
        let run = |parallel_from| {
            let mut order: Vec<u32> = (0..tris.len() as u32).collect();
            let mut nodes = Vec::new();
            build(&pts, &tris, &centroids, &mut order, 0, &mut nodes, parallel_from);
            (order, nodes)
        };
        let (sequential, parallel) = (run(usize::MAX), run(64));
        assert!(parallel.1.len() > 1000);
        assert_eq!(sequential, parallel);
    }

    /// Vector area ½ Σ x_i × x_{i+1} of a polygon given by vertex indices.
    fn vector_area(points: &[DVec3], face: &[u32]) -> DVec3 {
        let n = face.len();
        let mut a = DVec3::ZERO;
        for k in 0..n {
            a += points[face[k] as usize].cross(points[face[(k + 1) % n] as usize]);
        }
        0.5 * a
    }

    fn brute(bvh: &ClosestPointBvh, p: DVec3) -> f64 {
        (0..bvh.n_triangles())
            .map(|t| {
                let [a, b, c] = bvh.triangle(t).0.map(|v| bvh.points[v as usize]);
                (closest_on_triangle(p, a, b, c).1 - p).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn triangle_regions() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let (bary, x) = closest_point_on_triangle([0.25, 0.25, 3.0], a, b, c);
        assert_eq!(x, [0.25, 0.25, 0.0]);
        assert!((bary[0] - 0.5).abs() < 1e-15 && (bary[1] - 0.25).abs() < 1e-15);
        assert_eq!(closest_point_on_triangle([-1.0, -1.0, 0.0], a, b, c).1, a);
        assert_eq!(closest_point_on_triangle([2.0, -1.0, 0.0], a, b, c).1, b);
        assert_eq!(closest_point_on_triangle([0.5, -1.0, 1.0], a, b, c).1, [0.5, 0.0, 0.0]);
        let (bary, x) = closest_point_on_triangle([1.0, 1.0, 0.0], a, b, c);
        assert_eq!(x, [0.5, 0.5, 0.0]);
        assert_eq!(bary, [0.0, 0.5, 0.5]);
        // Degenerate triangles give finite answers on their edges.
        let (bary, x) = closest_point_on_triangle([0.5, 1.0, 0.0], a, b, [2.0, 0.0, 0.0]);
        assert_eq!(x, [0.5, 0.0, 0.0]);
        assert!(bary.iter().all(|v| v.is_finite()) && (bary.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        let (_, x) = closest_point_on_triangle([0.5, 1.0, 0.0], a, a, a);
        assert_eq!(x, a);
    }

    #[test]
    fn polygon_faces_and_vector_area_normal() {
        // A unit square (one quad) and a non-planar pentagon.
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [3.0, 0.0, 0.0],
            [4.0, 0.0, 0.5],
            [4.0, 1.0, 0.0],
            [3.5, 2.0, 0.2],
            [3.0, 1.0, 0.0],
        ];
        let mesh = PolyMesh::new(&[4, 5], &[0, 1, 2, 3, 4, 5, 6, 7, 8], 9).unwrap();
        let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
        assert_eq!(bvh.n_triangles(), 2 + 3);
        assert_eq!(bvh.face_normal(0), [0.0, 0.0, 1.0]);
        assert_eq!(bvh.face_vector_area(0), [0.0, 0.0, 1.0]);
        let hit = bvh.closest_point([0.25, 0.75, 2.0]).unwrap();
        assert_eq!(hit.face, 0);
        assert_eq!(hit.point, [0.25, 0.75, 0.0]);
        assert_eq!(hit.distance, 2.0);
        let recon: DVec3 = (0..3).map(|k| hit.barycentric[k] * bvh.points[hit.corners[k] as usize]).sum();
        assert!((recon - DVec3::new(0.25, 0.75, 0.0)).length() < 1e-15);
        let hit = bvh.closest_point([3.6, 0.9, 1.0]).unwrap();
        assert_eq!(hit.face, 1);
        // The pentagon's normal is its normalised vector area.
        let va = vector_area(&bvh.points, &[4, 5, 6, 7, 8]);
        assert!((DVec3::from_array(bvh.face_normal(1)) - va.normalize()).length() < 1e-15);
        assert!(matches!(bvh.closest_point([f64::NAN, 0.0, 0.0]), Err(Error::NonFinite { .. })));
    }

    #[test]
    fn arbitrary_triangulations_keep_their_numbering() {
        // A unit square split along the other diagonal, listed in reverse,
        // plus a triangle of face 2 (face 1 is unused).
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 0.0, 1.0],
        ];
        let tris = [([1, 2, 3], 0), ([0, 1, 3], 0), ([4, 5, 6], 2)];
        let bvh = ClosestPointBvh::from_triangles(&pts, &tris).unwrap();
        assert_eq!(bvh.n_faces(), 3);
        assert_eq!(bvh.face_vector_area(0), [0.0, 0.0, 1.0]);
        assert_eq!(bvh.face_normal(1), [0.0; 3]);
        assert_eq!(bvh.face_normal(2), [0.0, -1.0, 0.0]);
        let hit = bvh.closest_point([0.9, 0.8, 0.5]).unwrap();
        assert_eq!((hit.triangle, hit.face, hit.corners), (0, 0, [1, 2, 3]));
        let hit = bvh.closest_point([0.1, 0.2, -0.5]).unwrap();
        assert_eq!((hit.triangle, hit.face, hit.corners), (1, 0, [0, 1, 3]));
        assert_eq!(bvh.closest_point([5.2, 3.0, 0.2]).unwrap().triangle, 2);
        assert_eq!(
            ClosestPointBvh::from_triangles(&pts, &[([0, 1, 9], 0)]).err(),
            Some(Error::IndexOutOfRange { what: "triangle", index: 0, target: "point", value: 9, len: 7 })
        );
        assert!(matches!(ClosestPointBvh::from_triangles(&pts, &[]), Err(Error::Empty { .. })));
    }

    #[test]
    fn agrees_with_brute_force_on_a_random_grid() {
        // A bumpy 30 x 30 quad grid, queried at pseudo-random points.
        let n = 30;
        let mut pts = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                pts.push([x, y, 0.1 * (7.0 * x).sin() * (5.0 * y).cos()]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = (j * (n + 1) + i) as u32;
                idx.extend([v, v + 1, v + n as u32 + 2, v + n as u32 + 1]);
            }
        }
        let mesh = PolyMesh::new(&vec![4; n * n], &idx, pts.len()).unwrap();
        let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
        let mut state = 12345u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let p = DVec3::new(1.4 * rnd() - 0.2, 1.4 * rnd() - 0.2, 0.6 * rnd() - 0.3);
            let hit = bvh.closest_point(p.to_array()).unwrap();
            assert_eq!(hit.distance, brute(&bvh, p));
        }
    }
}
