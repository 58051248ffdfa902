//! The pieces of a binding its stages share (warnings, what a corner reads,
//! crossing rows, bound knots, per-curvenet ranges): a leaf below
//! `mod.rs` and its stage files (join, classify, drawing, rhs, assemble), so
//! none of them imports the binding module back.

use glam::DVec3;

use crate::error::SegmentRef;
use crate::ids::{ConstraintRow, Unknown};

/// Something a binding did that the user should know about.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
#[derive(serde::Serialize, serde::Deserialize)]
pub enum BindWarning {
    /// Connected components of the mesh touched by no curvenet: their
    /// vertices pass through at the rest pose. One warning for all of
    /// them (a mesh of many loose pieces would otherwise give one per
    /// piece): `count` components, `vertices` vertices in all, and the
    /// first [`BindWarning::EXAMPLES`] as `(component, vertices)`.
    UntouchedComponents { count: usize, vertices: usize, examples: Vec<(usize, usize)> },
    /// Curvenet clusters held inside single faces were removed (too fine for the mesh).
    IslandsRemoved { islands: usize, samples: usize },
    /// Cut-faces of (numerically) zero area were left out of the Laplacian.
    DegenerateCutFaces { count: usize },
    /// Segments whose surface paths meet where there is no shared knot
    /// (`super::cut::Touch`): a path through another segment's sample or crossing,
    /// two paths crossing inside a face, or two paths over one stretch.
    /// Bound as if the curves met there. `examples` names the first few:
    /// (segment, other, position).
    CurvesTouch { count: usize, examples: Vec<(SegmentRef, SegmentRef, [f64; 3])> },
    /// Input faces folded over themselves in their own plane (strongly
    /// warped polygons) and were split into triangles ([`super::Surface::split_faces`]).
    FacesSplit { faces: Vec<u32> },
    /// A segment whose surface path is much longer than the segment
    /// (longer than [`super::DETOUR_RATIO`] × its length + [`super::DETOUR_EDGES`] mean
    /// edges: its samples project across a concavity or onto the far side
    /// of a thin part), bound along that path; or, with an infinite
    /// `path_length`, one whose samples project onto different mesh
    /// components, left out. `t` is the segment's midpoint as a fraction of
    /// its spline's arc length, `position` that midpoint in the projection
    /// pose.
    SegmentDetour { segment: SegmentRef, t: f64, position: [f64; 3], path_length: f64, segment_length: f64 },
}

impl BindWarning {
    /// How many elements a warning lists at most.
    pub const EXAMPLES: usize = 5;
}

impl std::fmt::Display for BindWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BindWarning::UntouchedComponents { count, vertices, examples } => {
                if let [(component, _)] = examples[..]
                    && *count == 1
                {
                    return write!(
                        f,
                        "mesh component {component} ({vertices} vertices) is touched by no curvenet; its vertices pass through at the rest pose"
                    );
                }
                let shown: Vec<String> = examples.iter().map(|(c, v)| format!("{c} ({v} vertices)")).collect();
                write!(
                    f,
                    "{count} mesh components ({vertices} vertices in all) are touched by no curvenet; their vertices pass through at the rest pose: components {}{}",
                    shown.join(", "),
                    if *count > examples.len() { ", ..." } else { "" }
                )
            }
            BindWarning::IslandsRemoved { islands, samples } => {
                write!(f, "{islands} curvenet islands inside single faces were removed ({samples} samples)")
            }
            BindWarning::DegenerateCutFaces { count } => {
                write!(f, "{count} zero-area cut-faces were left out of the Laplacian")
            }
            BindWarning::CurvesTouch { count, examples } => {
                let shown: Vec<String> = examples
                    .iter()
                    .map(|(a, b, [x, y, z])| format!("{a} and {b} at ({x:.4}, {y:.4}, {z:.4})"))
                    .collect();
                write!(
                    f,
                    "{count} point{} where two curves' projections onto the surface meet without a shared knot (a curve drawn across a concavity or a thin part, or two curves drawn close together), bound as if the curves met there: {}{}",
                    if *count == 1 { "" } else { "s" },
                    shown.join("; "),
                    if *count > examples.len() { "; ..." } else { "" }
                )
            }
            BindWarning::FacesSplit { faces } => {
                let shown: Vec<String> = faces.iter().take(10).map(|f| f.to_string()).collect();
                let more = if faces.len() > 10 { format!(" and {} more", faces.len() - 10) } else { String::new() };
                write!(
                    f,
                    "{} faces fold over themselves in their own plane and were split into triangles: {}{more}",
                    faces.len(),
                    shown.join(", ")
                )
            }
            BindWarning::SegmentDetour { segment, t, position, path_length, segment_length } => {
                let [x, y, z] = position;
                if path_length.is_finite() {
                    write!(
                        f,
                        "{segment} at ({x:.4}, {y:.4}, {z:.4}) (spline parameter {t:.3}): its samples project {path_length:.4} apart over the surface for a segment {segment_length:.4} long (the curve bridges a concavity or a thin part there); bound along that path"
                    )
                } else {
                    write!(
                        f,
                        "{segment} at ({x:.4}, {y:.4}, {z:.4}) (spline parameter {t:.3}): its samples project onto two different mesh components; the segment is left out"
                    )
                }
            }
        }
    }
}

/// What a corner takes its value from.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) enum Corner {
    /// Unknown `u` (row of `V`'s column space).
    Unknown(Unknown),
    /// Constraint row `k`.
    Constraint(ConstraintRow),
    /// A vertex passed through (an untouched component): contributes nothing.
    Fixed,
}

/// A constraint row at a segment–edge crossing: interpolates the slots
/// `lo` (segment tail) and `hi` (segment head) at `t`.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub(crate) struct CrossingRow {
    pub lo: u32,
    pub hi: u32,
    pub t: f64,
    /// The crossing's cut-vertex.
    pub vertex: u32,
}

/// A curvenet control point bound to the surface: a triangle (index into
/// the surface's triangles), barycentric coordinates of its closest point,
/// and its offset from that point in the triangle's orthonormal frame, in
/// units of the triangle's size ([`triangle_frame`]), so that a tracked
/// knot keeps its place relative to the surface when the rest pose scales
/// it (a rig's global scale). Elemental's knot tracking says the offset is
/// kept in the triangle's local frame but not in which units; absolute
/// units made a curvenet tracked onto a rest pose scaled by 1.1 wrong by
/// 1e-3 of the diagonal, and one scaled by 1e-20 come back at full size.
/// A triangle degenerate at binding (no frame) keeps the offset as it is,
/// in the mesh's units (`size` 0).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub(crate) struct KnotBinding {
    pub tri: u32,
    pub bary: [f64; 3],
    pub local: [f64; 3],
    /// The triangle's size at binding, or 0 when it had no frame.
    pub size: f64,
}

impl KnotBinding {
    /// The knot's offset from its closest point on a triangle `a b c` of
    /// the rest pose: `local` in that triangle's frame and size. A rest
    /// triangle degenerate (no frame) keeps the binding's offset as it was
    /// in the projection pose's orientation and size, which is all there is.
    pub(crate) fn offset_on(&self, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
        let l = self.local;
        match triangle_frame(a, b, c) {
            Some(([e1, e2, n], size)) => {
                let unit = if self.size > 0.0 { size } else { 1.0 };
                (e1 * l[0] + e2 * l[1] + n * l[2]) * unit
            }
            None => DVec3::from_array(l) * if self.size > 0.0 { self.size } else { 1.0 },
        }
    }
}

/// An orthonormal frame of a triangle: (edge direction, in-plane normal to
/// it, triangle normal), and its size `√|(b − a) × (c − a)|` (the side of
/// a square of twice its area), or `None` for a degenerate triangle.
pub(crate) fn triangle_frame(a: DVec3, b: DVec3, c: DVec3) -> Option<([DVec3; 3], f64)> {
    let e1 = (b - a).normalize_or_zero();
    let cross = (b - a).cross(c - a);
    // The cross product's length once, for its normal (as `normalize_or_zero`
    // scales by its reciprocal) and the size.
    let length = cross.length();
    let rcp = 1.0 / length;
    if e1 == DVec3::ZERO || !(rcp.is_finite() && rcp > 0.0) {
        return None;
    }
    let n = cross * rcp;
    Some(([e1, n.cross(e1), n], length.sqrt()))
}

/// Per-curvenet offsets into the concatenated samples, segments and slots.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub(crate) struct NetRange {
    pub sample: u32,
    pub segment: u32,
    pub slot: u32,
}
