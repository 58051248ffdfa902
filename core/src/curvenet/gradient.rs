//! Deformation gradients of both sides of every segment (§3 "Deformation
//! Gradient").
//!
//! For curves that meet an intersection, `F = (B S)(B̌ Š)⁻¹`, which expands to
//! `(l/ľ) t ⊗ ť + (w/w̌) b ⊗ b̌ + (h/ȟ) n ⊗ ň` (posed axis ⊗ rest axis, i.e.
//! `a bᵀ`; the paper's Eq. (1) swaps the first product by a typo). For
//! curves with no intersection (isolated closed curves, or both ends
//! anchors), the same formula with the curve's own normal (frames.rs) gives
//! `(l/ľ)` times a rotation, the same on both sides; for a straight such
//! curve (no normal) `F = (l/ľ) R(ť → t)` with `R` the smallest rotation
//! taking the rest tangent to the posed one, as in the paper; for exactly
//! opposite tangents `R` is the half turn about `normalize(ť × e)`, `e` the
//! coordinate axis least aligned with `ť`.
//!
//! `F` maps rest vectors to posed ones: a uniform scaling by `s` gives `s I`,
//! a rigid rotation `R` of a curve that meets an intersection gives `R`.

use glam::DMat3;

use super::frames::ScaledFrame;
use super::layout::{CurvenetLayout, scaled_frames};
use super::rotation::{outer, smallest_rotation};
use super::{Mat3, v3};
use crate::error::{Error, Result};

/// Writes `F` for both sides of every segment into `out` (`#G` pairs indexed
/// `[segment][side as usize]`, row-major), from the scaled frames of the
/// rest pose (`rest`) and the posed one (`posed`), both from
/// [`scaled_frames_into`](super::scaled_frames_into) with this layout.
/// Allocation-free. Fails with [`Error::CountMismatch`] for wrong buffer
/// lengths and [`Error::InvalidParameter`] for a rest frame whose scales are
/// not positive (not produced by `scaled_frames_into`).
pub fn deformation_gradients_into(
    layout: &CurvenetLayout,
    rest: &[[ScaledFrame; 2]],
    posed: &[[ScaledFrame; 2]],
    out: &mut [[Mat3; 2]],
) -> Result<()> {
    let n = layout.sampling().n_segments();
    for (what, len) in [
        ("rest scaled frames", rest.len()),
        ("posed scaled frames", posed.len()),
        ("deformation gradient buffer", out.len()),
    ] {
        if len != n {
            return Err(Error::CountMismatch { what, expected: n, got: len });
        }
    }
    for (s, seg) in layout.sampling().segments().iter().enumerate() {
        // Rest frames from `scaled_frames_into` have positive scales; refuse
        // anything else rather than divide by zero.
        if let Some(&value) = rest[s].iter().flat_map(|f| f.scale.iter()).find(|x| !(x.is_finite() && **x > 0.0)) {
            return Err(Error::InvalidParameter { what: "a rest scaled frame's scale", value });
        }
        out[s] = segment_gradients(layout.curve_is_isolated(seg.curve as usize), &rest[s], &posed[s]);
    }
    Ok(())
}

/// `F` of both sides of one segment from its rest and posed scaled frames
/// (rest scales positive); `isolated`: the segment's curve meets no
/// intersection.
pub(crate) fn segment_gradients(isolated: bool, rest: &[ScaledFrame; 2], posed: &[ScaledFrame; 2]) -> [Mat3; 2] {
    if isolated && !(rest[0].has_normal() && posed[0].has_normal()) {
        let (r, p) = (&rest[0], &posed[0]);
        let f = smallest_rotation(v3(r.tangent), v3(p.tangent)) * (p.scale[0] / r.scale[0]);
        return [to_rows(f); 2];
    }
    std::array::from_fn(|side| {
        let (r, p) = (&rest[side], &posed[side]);
        let f = outer(v3(p.tangent), v3(r.tangent)) * (p.scale[0] / r.scale[0])
            + outer(v3(p.binormal), v3(r.binormal)) * (p.scale[1] / r.scale[1])
            + outer(v3(p.normal), v3(r.normal)) * (p.scale[2] / r.scale[2]);
        to_rows(f)
    })
}

/// Allocating convenience: samples → frames → gradients, for `rest` and
/// `posed` sample sets (`#Q` each, e.g. from `Sampling::samples`).
pub fn deformation_gradients(layout: &CurvenetLayout, rest: &[[f64; 3]], posed: &[[f64; 3]]) -> Result<Vec<[Mat3; 2]>> {
    let rest = scaled_frames(layout, rest)?;
    let posed = scaled_frames(layout, posed)?;
    let mut out = vec![[[[0.0; 3]; 3]; 2]; rest.len()];
    deformation_gradients_into(layout, &rest, &posed, &mut out)?;
    Ok(out)
}

fn to_rows(m: DMat3) -> Mat3 {
    m.transpose().to_cols_array_2d()
}
