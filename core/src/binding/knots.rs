//! The curvenets' knots on the surface: the orientation plan of every
//! bound curvenet, built with the binding from the triangles its knots are
//! bound to (Elemental 2023's neutral knot frames). Below `mod.rs`; the
//! adjuster (`adjust/frame.rs`) reads the same triangle normals per frame.

use glam::DVec3;

use super::parts::KnotBinding;
use super::surface::Surface;
use crate::adjust::OrientationPlan;
use crate::curvenet::CurvenetLayout;
use crate::error::Result;

/// The orientation plan of every bound curvenet: the neutral normal of a
/// knot is the normal of the surface triangle it is bound to, in the
/// projection pose (the posed normal is the same triangle's in the frame's
/// rest pose, `Binding::knot_normal`).
pub(crate) fn orientation_plans(
    surface: &Surface,
    layouts: &[&CurvenetLayout],
    knots: &[Vec<KnotBinding>],
) -> Result<Vec<OrientationPlan>> {
    layouts
        .iter()
        .zip(knots)
        .map(|(layout, bound)| {
            OrientationPlan::new(layout, |p| triangle_normal(surface, bound[p as usize].tri, &surface.points))
        })
        .collect()
}

pub(crate) fn triangle_normal<P: Copy + Into<DVec3>>(surface: &Surface, tri: u32, points: &[P]) -> [f64; 3] {
    let [a, b, c] = surface.triangle_points(tri, points);
    (b - a).cross(c - a).normalize_or_zero().to_array()
}
