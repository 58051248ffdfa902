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
pub(crate) mod limits;
pub mod maxvol;
pub mod mvc;

pub use crate::error::CageError;
pub use cor::{COR_SIGMA, CentersOfRotation, skin_points_cor};
pub use coupled::{CageFrame, CageRevApproximation, CageTimings, CoupledRig, CoupledWorkspace, LOCALIZATION_EXPONENT};
pub use limits::{MAX_CAGE_VERTICES, MAX_PHI_BYTES};
pub use maxvol::{MAXVOL_TOLERANCE, MaxVol};
pub use mvc::{Cage, MVC_EPSILON, Mvc};

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
