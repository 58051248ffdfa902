//! Points on the surface: where a curvenet sample or a path point lies on the
//! input mesh (at a vertex, on an edge, inside a face), and the conversions
//! to 3D positions and to a face's 2D plane.

use glam::DVec2;

/// Where a point lies on the input mesh.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Location {
    /// At mesh vertex `v`.
    Vertex(u32),
    /// On a mesh edge, at parameter `t` in (0, 1) from `tail(h)` to `head(h)`,
    /// where `h` is the edge's canonical halfedge ([`Surface::canonical`](super::Surface::canonical)).
    Edge { h: u32, t: f64 },
    /// Inside face `face`, in its triangle `tri` (index into the surface's
    /// triangles) with barycentric coordinates `bary`.
    Face { face: u32, tri: u32, bary: [f64; 3] },
}

/// Barycentric coordinates of `p` in the 2D triangle `t`.
pub(crate) fn barycentric_2d(p: DVec2, t: [DVec2; 3]) -> [f64; 3] {
    let d = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    let b1 = (p - t[0]).perp_dot(t[2] - t[0]) / d;
    let b2 = (t[1] - t[0]).perp_dot(p - t[0]) / d;
    [1.0 - b1 - b2, b1, b2]
}
