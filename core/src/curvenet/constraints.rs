//! Constraint slots: the per-sample, per-side deformation gradients of §4.3.
//!
//! Segment gradients are remapped to samples. A sample inside a curve gets,
//! per side, the average of the gradients of the segments before and after
//! it. A curve endpoint gets one copy per incident segment (one per curve
//! end: an intersection of valence `v` gets `v` copies, one per emanating
//! curve end), each with that segment's two sides. An isolated closed curve
//! has no endpoint: its start sample averages its last and first segments.
//!
//! # Slot numbering
//!
//! Curve after curve, along each curve's [`Sampling::curve_samples`], two
//! slots per listed sample, plus side first: slot `2 j + side`, so
//! `n_c = 2 × Σ_curves (samples listed by the curve)`. The table is the map
//! the binding uses to attach each slot to the cut-mesh halfedges on that
//! side of that sample.

use super::sampling::Sampling;
use super::topology::{CurveEnd, Topology};
use super::{Mat3, Side};
use crate::error::{Error, Result};

/// One constraint slot: a sample of a curve seen from one side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct ConstraintSlot {
    /// The sample (global sample index).
    pub sample: u32,
    /// The curve.
    pub curve: u32,
    /// The side of the curve (in curve direction).
    pub side: Side,
    /// The segment arriving at the sample along the curve (`None` at the
    /// start of an open curve or of a loop through an intersection).
    pub incoming: Option<u32>,
    /// The segment leaving the sample along the curve (`None` at the end).
    pub outgoing: Option<u32>,
}

/// The immutable table of all `n_c` constraint slots (see the module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConstraintTable {
    slots: Vec<ConstraintSlot>,
    #[serde(with = "crate::persist::pod")]
    curve_offsets: Vec<u32>,
    n_segments: usize,
}

impl ConstraintTable {
    /// Builds the slots of a sampling plan.
    pub fn new(sampling: &Sampling, topology: &Topology) -> Self {
        let mut slots = Vec::new();
        let mut curve_offsets = vec![0u32];
        for c in 0..sampling.n_curves() {
            let samples = sampling.curve_samples(c);
            let segs = sampling.curve_segments(c);
            let k = segs.len();
            let closed = matches!(topology.curves()[c].start, CurveEnd::Closed(_));
            for (j, &sample) in samples.iter().enumerate() {
                let incoming = if j > 0 {
                    Some((segs.start + j - 1) as u32)
                } else if closed {
                    Some((segs.start + k - 1) as u32)
                } else {
                    None
                };
                let outgoing = if j < k { Some((segs.start + j) as u32) } else { None };
                for side in Side::BOTH {
                    slots.push(ConstraintSlot { sample, curve: c as u32, side, incoming, outgoing });
                }
            }
            curve_offsets.push(slots.len() as u32);
        }
        Self { slots, curve_offsets, n_segments: sampling.n_segments() }
    }

    /// All slots, `n_c` of them.
    pub fn slots(&self) -> &[ConstraintSlot] {
        &self.slots
    }

    /// `n_c`, the number of slots.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether there are no slots (never, for a valid curvenet).
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The slots of curve `c`.
    pub fn curve_slots(&self, c: usize) -> &[ConstraintSlot] {
        &self.slots[self.curve_offsets[c] as usize..self.curve_offsets[c + 1] as usize]
    }
}

/// Writes the gradient of every slot into `out` (`n_c` matrices, row-major;
/// flattening each row by row gives the rows of the paper's `f_c`), from
/// per-segment gradients `gradients` (`#G` pairs, `[segment][side]`).
/// Allocation-free. Fails only with [`Error::CountMismatch`].
pub fn constraint_gradients_into(table: &ConstraintTable, gradients: &[[Mat3; 2]], out: &mut [Mat3]) -> Result<()> {
    if out.len() != table.len() {
        return Err(Error::CountMismatch { what: "constraint gradient buffer", expected: table.len(), got: out.len() });
    }
    if gradients.len() != table.n_segments {
        return Err(Error::CountMismatch {
            what: "segment deformation gradients",
            expected: table.n_segments,
            got: gradients.len(),
        });
    }
    for (slot, o) in table.slots.iter().zip(out.iter_mut()) {
        let side = slot.side as usize;
        *o = match (slot.incoming, slot.outgoing) {
            (Some(a), Some(b)) => {
                let (fa, fb) = (&gradients[a as usize][side], &gradients[b as usize][side]);
                let mut m = [[0.0; 3]; 3];
                for r in 0..3 {
                    for c in 0..3 {
                        m[r][c] = 0.5 * (fa[r][c] + fb[r][c]);
                    }
                }
                m
            }
            (Some(a), None) | (None, Some(a)) => gradients[a as usize][side],
            (None, None) => unreachable!("every curve sample touches a segment"),
        };
    }
    Ok(())
}

/// Allocating form of [`constraint_gradients_into`].
pub fn constraint_gradients(table: &ConstraintTable, gradients: &[[Mat3; 2]]) -> Result<Vec<Mat3>> {
    let mut out = vec![[[0.0; 3]; 3]; table.len()];
    constraint_gradients_into(table, gradients, &mut out)?;
    Ok(out)
}

impl ConstraintTable {
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.slots) + crate::heap::bytes(&self.curve_offsets)
    }
}
