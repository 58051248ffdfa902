//! Cages and skeletons coupled under the curvenet (Corda, Thiery, Livesu,
//! Puppo, Boubekeur, Scateni 2020, "Real-time deformation with coupled
//! cages and skeletons"): a rig layer whose result is a frame's rest pose,
//! like [`crate::skinning`], over plain arrays.
//!
//! ```text
//! Mvc::new(cage points, cage triangles, mesh points)      once: Φ (mvc.rs)
//! MaxVol::new(&mvc)                                       once: #C rows, Φ̃⁻¹ (maxvol.rs)
//! CentersOfRotation::new(points, triangles, influences)   once, CoR skinning (cor.rs)
//! CoupledRig::new(cage, mesh, Some((&skeleton, &skin)))   once: all of the above, Ψ, Λ (coupled.rs)
//! per frame, CoupledRig::evaluate(&CageFrame, &mut CoupledWorkspace, out):
//!   C = the frame's rest cage (or C₀)
//!   CageRev  ∂C′ → ∂C, C += ∂C   Eq. 19, LBS-linearised, 3c × 3c LU    only with posed-cage offsets
//!   SkelUp   A = A₀ + Ψ(C − C₀), translations re-chained (Eq. 13, 16)   O(#J·c)
//!   C → M    M = base + Φ(C − C₀)                                        O(#P·c)
//!   skinning M → M′ (LBS, DQS, or CoR with centres p₀ + Λ(C − C₀))       O(#P)
//!   CageUp   Φ̃ C′ = M̃′ − G·D̃  (back-substitution with Φ̃⁻¹)             O(c²)
//! ```
//!
//! CageRev, SkelUp and CageUp cost the same whatever the mesh's size (see
//! tests/cage_timing.rs); only `Φ·C` and the skinning touch every vertex.
//! A frame allocates nothing once its workspace has seen one, except the
//! per-joint decomposition (`#J` entries) that dual-quaternion and
//! centre-of-rotation skinning make per call, as [`crate::skinning`]'s
//! dual quaternions do. The decisions the paper leaves open are listed in
//! [`coupled`]'s docs.
//!
//! # Conventions
//!
//! - The cage is in the **mesh's space** (the space of the mesh's points);
//!   the skinning happens in skeleton space after `geomBindTransform` `G`
//!   ([`crate::skinning`]). Because `Φ` has partition of unity, `Φ(C·G) =
//!   (ΦC)·G`, so the coupled rig maps the cage through `G` once and works
//!   in skeleton space: joints, CoRs, the posed cage `C′` and the
//!   posed-cage offsets `∂C′` are all in skeleton space (the space of the
//!   skinned points).
//! - Transforms are the skinning module's [`Mat4`](crate::skinning::Mat4)
//!   (row-major, row vectors); a frame's joint transforms are **skinning
//!   transforms** (`inverse(bind) · jointSkel`, the identity at bind).

pub mod cor;
pub mod coupled;
pub mod maxvol;
pub mod mvc;

pub use cor::{COR_SIGMA, CentersOfRotation, skin_points_cor};
pub use coupled::{CageFrame, CageRevApproximation, CageTimings, CoupledRig, CoupledWorkspace, LOCALIZATION_EXPONENT};
pub use maxvol::{MAXVOL_TOLERANCE, MaxVol};
pub use mvc::{Cage, MAX_CAGE_VERTICES, MAX_PHI_BYTES, MVC_EPSILON, Mvc};

use crate::error::Error;

/// Why cage input was refused. Every variant names the element.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CageError {
    /// Fewer than 4 points or no triangles: no closed cage.
    #[error("a cage needs at least 4 vertices and some triangles, got {vertices} vertices and {triangles} triangles")]
    TooSmall { vertices: usize, triangles: usize },
    /// A triangle corner refers past the last cage point.
    #[error("cage triangle {face}, corner {corner}: vertex {vertex} is outside 0..{n_vertices}")]
    IndexOutOfRange { face: usize, corner: usize, vertex: u32, n_vertices: usize },
    /// A triangle repeats a vertex or has zero area.
    #[error("cage triangle {face} (vertices {vertices:?}) is degenerate: a repeated vertex or zero area")]
    DegenerateFace { face: usize, vertices: [u32; 3] },
    /// A NaN or infinite coordinate.
    #[error("{what} {index} has a non-finite coordinate {value:?}")]
    NonFinite { what: &'static str, index: usize, value: [f64; 3] },
    /// A cage vertex no triangle uses (its coordinates would all be zero).
    #[error("cage vertex {vertex} is used by no triangle")]
    UnusedVertex { vertex: usize },
    /// An edge with a single triangle: the cage is open there.
    #[error("cage edge ({a}, {b}) has only triangle {face}: the cage is not closed")]
    OpenEdge { a: u32, b: u32, face: usize },
    /// An edge shared by more than two triangles.
    #[error("cage edge ({a}, {b}) is shared by triangles {faces:?}; a cage edge must have exactly two")]
    NonManifoldEdge { a: u32, b: u32, faces: Vec<u32> },
    /// Two triangles run their shared edge the same way: one is flipped.
    #[error("cage triangle {face} is flipped: it runs edge ({a}, {b}) the same way as triangle {neighbour}")]
    FlippedFace { face: usize, neighbour: usize, a: u32, b: u32 },
    /// Consistently oriented but with inward normals (negative volume).
    #[error(
        "the cage is inside out: its signed volume is {volume:e} (triangles must wind counter-clockwise seen from outside)"
    )]
    InsideOut { volume: f64 },
    /// The cage is too fine for dense coordinates ([`mvc::MAX_CAGE_VERTICES`], [`mvc::MAX_PHI_BYTES`]).
    #[error(
        "a cage of {cage_vertices} vertices over {points} points needs {bytes} bytes of mean value coordinates; a cage \
         is a coarse control mesh (at most {max_vertices} vertices and {max_bytes} bytes of coordinates)",
        max_vertices = mvc::MAX_CAGE_VERTICES,
        max_bytes = mvc::MAX_PHI_BYTES
    )]
    TooLarge { points: usize, cage_vertices: usize, bytes: usize },
    /// A point lies outside the cage (winding number below ½).
    #[error(
        "point {point} ({position:?}) is outside the cage ({outside} points are): a cage must enclose every point it deforms"
    )]
    NotEnclosing { point: usize, position: [f64; 3], outside: usize },
    /// An array has the wrong length.
    #[error("{what}: expected {expected} entries, got {got}")]
    Count { what: &'static str, expected: usize, got: usize },
    /// The MaxVol square system is singular (the cage's coordinates of the
    /// points do not span every cage vertex: some cage vertex influences no point).
    #[error(
        "the MaxVol system of the cage is singular (condition number {condition:e}): cage vertex {vertex} influences the points too little"
    )]
    SingularMaxVol { vertex: usize, condition: f64 },
    /// The CageRev system (Eq. 19) is singular at this pose.
    #[error("the reverse cage system (CageRev) is singular at this pose (pivot {pivot})")]
    SingularCageRev { pivot: usize },
    /// A joint no skin weight reaches, so SkelUp cannot place it.
    #[error("joint {joint} has no localised skin weight: SkelUp cannot relocate it")]
    UnlocalizedJoint { joint: usize },
    /// The maximum-entropy projection of a joint's coordinates (Eq. 11) did not converge.
    #[error("the barycentric coordinates of joint {joint} (Eq. 11) did not converge (residual {residual:e})")]
    JointCoordinates { joint: usize, residual: f64 },
    /// The rig is missing something the coupling needs.
    #[error("{what}")]
    Missing { what: &'static str },
}

impl From<CageError> for Error {
    fn from(e: CageError) -> Self {
        Error::Cage(e)
    }
}

/// A fan triangulation of a polygon mesh's faces (`[f0, f_k, f_{k+1}]`),
/// for the centres of rotation and the joints' localisation, which need
/// triangles.
pub fn fan_triangles(mesh: &crate::mesh::PolyMesh) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    for f in mesh.faces() {
        for k in 1..f.len().saturating_sub(1) {
            out.push([f[0], f[k], f[k + 1]]);
        }
    }
    out
}
