//! Linear blend skinning, UsdSkel's "classicLinear".

use rayon::prelude::*;

use super::influences::{Influences, PAR_CHUNK, check_skinning_input};
use super::transform::{Mat4, transform_point};
use crate::error::Result;

/// Linear blend skinning (Liu et al. 2015, Eq. 1; UsdSkel's `classicLinear`):
/// `out[p] = Σ_k w_pk · ([q 1] · transforms[j_pk])` with `q = [points[p] 1] ·
/// geom_bind`, over the point's influences (zero weights skipped).
///
/// - `points`: `#P` bind-pose points (the mesh's `points`).
/// - `influences`: `#P` points' (joint, weight) pairs.
/// - `geom_bind`: the mesh's `geomBindTransform` (row-vector convention).
/// - `transforms`: `#J` skinning transforms, `inverse(bind) · joint`.
/// - `out`: `#P` skinned points (skeleton space).
///
/// Weights are used as given, as usd-core does: a point whose weights sum
/// to `s` lands at `s` times the blend. Parallel over points. Fails with
/// [`crate::Error::CountMismatch`] or a [`super::SkinningError`] naming the
/// joint, or [`crate::Error::NonFinite`] naming the point.
pub fn skin_points_lbs(
    points: &[[f64; 3]],
    influences: &Influences,
    geom_bind: &Mat4,
    transforms: &[Mat4],
    out: &mut [[f64; 3]],
) -> Result<()> {
    check_skinning_input(points, influences, transforms, out)?;
    out.par_chunks_mut(PAR_CHUNK).enumerate().for_each(|(chunk, block)| {
        for (i, o) in block.iter_mut().enumerate() {
            let p = chunk * PAR_CHUNK + i;
            let q = transform_point(geom_bind, points[p]);
            let mut acc = [0.0; 3];
            for (j, w) in influences.point(p) {
                if w == 0.0 {
                    continue;
                }
                let x = transform_point(&transforms[j as usize], q);
                for c in 0..3 {
                    acc[c] += w * x[c];
                }
            }
            *o = acc;
        }
    });
    Ok(())
}
