//! Points on the surface: where a curvenet sample or a path point lies on the
//! input mesh (at a vertex, on an edge, inside a face), and the conversions
//! to 3D positions and to a face's 2D plane.

use glam::{DVec2, DVec3};

use super::surface::Surface;
use crate::halfedge::INVALID;

/// Where a point lies on the input mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Location {
    /// At mesh vertex `v`.
    Vertex(u32),
    /// On a mesh edge, at parameter `t` in (0, 1) from `tail(h)` to `head(h)`,
    /// where `h` is the edge's canonical halfedge ([`Surface::canonical`]).
    Edge { h: u32, t: f64 },
    /// Inside face `face`, in its triangle `tri` (index into the surface's
    /// triangles) with barycentric coordinates `bary`.
    Face { face: u32, tri: u32, bary: [f64; 3] },
}

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

/// Barycentric coordinates of `p` in the 2D triangle `t`.
pub(crate) fn barycentric_2d(p: DVec2, t: [DVec2; 3]) -> [f64; 3] {
    let d = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    let b1 = (p - t[0]).perp_dot(t[2] - t[0]) / d;
    let b2 = (t[1] - t[0]).perp_dot(p - t[0]) / d;
    [1.0 - b1 - b2, b1, b2]
}
