//! Plane sections of the fan-triangulated surface: closed loops (and open
//! polylines on a mesh with boundary) through the points where triangle
//! edges cross the plane.

use glam::DVec3;

use super::surface::TriSurface;
use crate::halfedge::INVALID;

/// An oriented plane `{x : normal · x = offset}` (unit normal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: DVec3,
    pub offset: f64,
}

impl Plane {
    pub fn through(normal: DVec3, point: DVec3) -> Self {
        Self { normal, offset: normal.dot(point) }
    }

    pub fn distance(&self, x: DVec3) -> f64 {
        self.normal.dot(x) - self.offset
    }

    /// The side of `x`: a point on the plane counts as positive, so an edge
    /// crosses the plane exactly when its ends have different sides.
    pub fn side(&self, x: DVec3) -> bool {
        self.distance(x) >= 0.0
    }

    /// Moves the plane along its normal by the smallest of a few tiny steps
    /// after which no vertex lies within `1e-9 · diagonal` of it, so that
    /// every crossing point is well inside its edge.
    pub fn clear_of_vertices(mut self, surface: &TriSurface) -> Self {
        let eps = 1e-9 * surface.diagonal;
        for step in 0..8 {
            if surface.points.iter().all(|&p| self.distance(p).abs() > eps) {
                break;
            }
            self.offset += eps * (3.0 + step as f64);
        }
        self
    }
}

/// A point of a section on the surface.
#[derive(Debug, Clone, Copy)]
pub struct SurfacePoint {
    pub pos: DVec3,
    /// The vertex normals interpolated at the point, normalised.
    pub normal: DVec3,
}

/// A section polyline: `points` joined in order by segments, segment `i`
/// (from point `i` to point `i + 1`, cyclically when `closed`) inside the fan
/// triangle `tris[i]`.
#[derive(Debug, Clone)]
pub struct Polyline {
    pub closed: bool,
    pub points: Vec<SurfacePoint>,
    pub tris: Vec<u32>,
}

impl Polyline {
    pub fn n_segments(&self) -> usize {
        self.tris.len()
    }

    pub fn segment(&self, i: usize) -> (DVec3, DVec3) {
        (self.points[i].pos, self.points[(i + 1) % self.points.len()].pos)
    }

    /// The triangle of point `i`: that of the segment starting there (the
    /// last segment's for the end of an open polyline).
    pub fn tri_of_point(&self, i: usize) -> u32 {
        self.tris[i.min(self.tris.len() - 1)]
    }

    pub fn length(&self) -> f64 {
        (0..self.n_segments()).map(|i| self.segment(i)).map(|(a, b)| a.distance(b)).sum()
    }

    fn reverse(&mut self) {
        if self.closed {
            // Keep point 0 first: segment i of the reversed loop runs from
            // point n-i to point n-i-1, i.e. it is the old segment n-1-i.
            self.points[1..].reverse();
        } else {
            self.points.reverse();
        }
        self.tris.reverse();
    }
}

/// Every polyline of the section of `surface` by `plane`, in the order of
/// their first triangle. Loops turn counter-clockwise about
/// `orientation` (when it is not in the plane); open polylines keep the
/// order of their walk.
pub fn section(surface: &TriSurface, plane: &Plane, orientation: DVec3) -> Vec<Polyline> {
    let side: Vec<bool> = surface.points.iter().map(|&p| plane.side(p)).collect();
    let crosses = |e: u32| {
        let [a, b] = surface.edges[e as usize];
        side[a as usize] != side[b as usize]
    };
    let crossing_point = |e: u32| {
        let [a, b] = surface.edges[e as usize];
        let (pa, pb) = (surface.points[a as usize], surface.points[b as usize]);
        let (da, db) = (plane.distance(pa), plane.distance(pb));
        let t = (da / (da - db)).clamp(0.0, 1.0);
        let normal = surface.vertex_normals[a as usize].lerp(surface.vertex_normals[b as usize], t).normalize_or_zero();
        SurfacePoint { pos: pa.lerp(pb, t), normal }
    };
    // The two crossing edges of a triangle the plane cuts.
    let cut_edges = |t: u32| -> Option<[u32; 2]> {
        let ids = surface.tri_edges[t as usize];
        let mut found = ids.iter().copied().filter(|&e| crosses(e));
        let first = found.next()?;
        Some([first, found.next().expect("a plane cuts a triangle's edges twice or not at all")])
    };
    let other_tri = |e: u32, t: u32| {
        let [a, b] = surface.edge_tris[e as usize];
        if a == t { b } else { a }
    };
    // Walks from triangle `t`, leaving through edge `out`, until the walk
    // comes back to `start` (closed) or leaves the surface (open). Returns
    // the crossing edges after `out` and the triangles entered.
    let walk = |start: u32, mut t: u32, mut out: u32, visited: &mut Vec<bool>| -> (Vec<u32>, Vec<u32>, bool) {
        let mut edges = Vec::new();
        let mut tris = Vec::new();
        loop {
            let next = other_tri(out, t);
            if next == INVALID {
                return (edges, tris, false);
            }
            if next == start {
                return (edges, tris, true);
            }
            visited[next as usize] = true;
            let [e0, e1] = cut_edges(next).expect("the next triangle shares a crossing edge");
            let leave = if e0 == out { e1 } else { e0 };
            tris.push(next);
            edges.push(leave);
            t = next;
            out = leave;
        }
    };
    let mut visited = vec![false; surface.tris.len()];
    let mut out = Vec::new();
    for t0 in 0..surface.tris.len() as u32 {
        if visited[t0 as usize] {
            continue;
        }
        let Some([ea, eb]) = cut_edges(t0) else { continue };
        visited[t0 as usize] = true;
        // Forward from t0 through eb.
        let (fwd_edges, fwd_tris, closed) = walk(t0, t0, eb, &mut visited);
        let (edges, tris) = if closed {
            // ea, eb, fwd...: the last forward triangle leaves through ea.
            let mut edges = vec![ea, eb];
            edges.extend(&fwd_edges[..fwd_edges.len().saturating_sub(1)]);
            let mut tris = vec![t0];
            tris.extend(&fwd_tris);
            (edges, tris)
        } else {
            // Backward from t0 through ea, then reversed, then forward.
            let (bwd_edges, bwd_tris, _) = walk(t0, t0, ea, &mut visited);
            let mut edges: Vec<u32> = bwd_edges.iter().rev().copied().collect();
            edges.push(ea);
            edges.push(eb);
            edges.extend(&fwd_edges);
            let mut tris: Vec<u32> = bwd_tris.iter().rev().copied().collect();
            tris.push(t0);
            tris.extend(&fwd_tris);
            (edges, tris)
        };
        let mut poly = Polyline { closed, points: edges.iter().map(|&e| crossing_point(e)).collect(), tris };
        debug_assert_eq!(poly.tris.len(), if closed { poly.points.len() } else { poly.points.len() - 1 });
        if closed {
            let n = poly.points.len();
            let area: DVec3 = (0..n).map(|i| poly.points[i].pos.cross(poly.points[(i + 1) % n].pos)).sum();
            if area.dot(orientation) < 0.0 {
                poly.reverse();
            }
        }
        out.push(poly);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    /// A closed quad cylinder (radius 1, z in [0, 2]) with fan-capped ends.
    fn tube(segments: u32, stacks: u32) -> (PolyMesh, Vec<[f64; 3]>) {
        let mut points = Vec::new();
        for j in 0..=stacks {
            for i in 0..segments {
                let a = std::f64::consts::TAU * i as f64 / segments as f64;
                points.push([a.cos(), a.sin(), 2.0 * j as f64 / stacks as f64]);
            }
        }
        let mut counts = Vec::new();
        let mut indices = Vec::new();
        let at = |i: u32, j: u32| j * segments + i % segments;
        for j in 0..stacks {
            for i in 0..segments {
                counts.push(4);
                indices.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        counts.push(segments);
        indices.extend((0..segments).rev().map(|i| at(i, 0)));
        counts.push(segments);
        indices.extend((0..segments).map(|i| at(i, stacks)));
        let n = points.len();
        (PolyMesh::new(&counts, &indices, n).unwrap(), points)
    }

    #[test]
    fn sections_of_a_tube() {
        let (mesh, points) = tube(24, 8);
        let s = TriSurface::new(&mesh, &points).unwrap();
        // Across the axis: one loop around the tube, every point on the
        // plane and on the surface, counter-clockwise about +z.
        let plane = Plane::through(DVec3::Z, DVec3::new(0.0, 0.0, 0.7)).clear_of_vertices(&s);
        let loops = section(&s, &plane, DVec3::Z);
        assert_eq!(loops.len(), 1);
        let l = &loops[0];
        assert!(l.closed);
        assert_eq!(l.points.len(), l.tris.len());
        for p in &l.points {
            assert!(plane.distance(p.pos).abs() < 1e-12);
            assert!(s.bvh.closest_point(p.pos.to_array()).unwrap().distance < 1e-12);
        }
        let n = l.points.len();
        let turn: f64 = (0..n).map(|i| l.points[i].pos.cross(l.points[(i + 1) % n].pos).z).sum();
        assert!(turn > 0.0);
        // The perimeter of the inscribed 24-gon.
        let want = 24.0 * 2.0 * (std::f64::consts::PI / 24.0).sin();
        assert!((l.length() - want).abs() < 1e-9, "{} vs {want}", l.length());
        // Along the axis (x = 0.3): one loop over the caps and down both sides.
        let lengthwise = section(&s, &Plane::through(DVec3::X, DVec3::new(0.3, 0.0, 0.0)), DVec3::X);
        assert_eq!(lengthwise.len(), 1);
        assert!(lengthwise[0].closed);
        // Every segment's two points are on the edges of its own triangle.
        for (i, &t) in lengthwise[0].tris.iter().enumerate() {
            let (a, b) = lengthwise[0].segment(i);
            let [p, q, r] = s.tris[t as usize].map(|v| s.points[v as usize]);
            let normal = (q - p).cross(r - p).normalize();
            assert!(normal.dot(a - p).abs() < 1e-9 && normal.dot(b - p).abs() < 1e-9);
        }
        // A plane missing the mesh gives nothing.
        assert!(section(&s, &Plane::through(DVec3::Z, DVec3::new(0.0, 0.0, 5.0)), DVec3::Z).is_empty());
    }
}
