//! Binding stage 1: the curvenets joined into one list of samples and
//! segments, numbered globally (curvenet after curvenet), with each
//! sample's and segment's [`SampleRef`]/[`SegmentRef`] for messages and
//! the constraint slots of every segment end.

use rustc_hash::FxHashMap as HashMap;

use crate::curvenet::{CurvenetLayout, Side};
use crate::error::{Error, Result, SampleRef, SegmentRef};

use super::parts::NetRange;

/// Which end of a segment a slot or a cut-vertex is.
pub(crate) const TAIL: u8 = 0;
pub(crate) const HEAD: u8 = 1;

/// The curvenets of one binding, joined.
#[derive(Debug, Default)]
pub(crate) struct Joined {
    /// Neutral samples, global numbering.
    pub samples: Vec<[f64; 3]>,
    /// Global sample pairs of every segment, global numbering.
    pub segments: Vec<[u32; 2]>,
    pub sample_ref: Vec<SampleRef>,
    pub segment_ref: Vec<SegmentRef>,
    /// The curve (global over all curvenets) each segment lies on.
    pub segment_curve: Vec<u32>,
    /// Where each curvenet's samples, segments and slots start.
    pub nets: Vec<NetRange>,
    /// (global segment, TAIL/HEAD, side) → global slot.
    slot_of: HashMap<(u32, u8, Side), u32>,
    /// Slots over all curvenets (the first constraint rows).
    pub n_slots: u32,
}

impl Joined {
    /// The constraint slot of `segment`'s `end` (TAIL/HEAD) on `side`.
    pub fn slot(&self, segment: u32, end: u8, side: Side) -> Result<u32> {
        self.slot_of.get(&(segment, end, side)).copied().ok_or_else(|| Error::Internal {
            what: format!("no constraint slot for segment {segment} end {end} side {side:?}"),
        })
    }
}

/// Refuses a spline drawn twice: two splines, in one curvenet or in two
/// (a curvenet bound twice), over the same four control-point positions,
/// in either direction. Bound, they would cut the surface along one path,
/// and the second copy would silently move nothing. (Curves that only run
/// together over part of their length bind with a `curves_touch` warning.)
fn check_duplicate_splines(curvenets: &[&CurvenetLayout]) -> Result<()> {
    let mut seen: HashMap<[[u64; 3]; 4], (u32, u32)> = HashMap::default();
    for (k, layout) in curvenets.iter().enumerate() {
        let pool = layout.neutral_pool();
        for (s, spline) in layout.sampling().splines().iter().enumerate() {
            let mut key = spline.map(|i| pool[i as usize].map(f64::to_bits));
            let mut reversed = key;
            reversed.reverse();
            key = key.min(reversed);
            if let Some(&(c, t)) = seen.get(&key) {
                return Err(Error::CurvesOverlap {
                    segment: SegmentRef { curvenet: k as u32, spline: s as u32, segment: 0 },
                    other: SegmentRef { curvenet: c, spline: t, segment: 0 },
                });
            }
            seen.insert(key, (k as u32, s as u32));
        }
    }
    Ok(())
}

/// Joins `curvenets` in order (refusing a spline drawn twice).
pub(crate) fn join(curvenets: &[&CurvenetLayout]) -> Result<Joined> {
    check_duplicate_splines(curvenets)?;
    let mut j = Joined::default();
    let mut n_curves = 0u32;
    for (k, layout) in curvenets.iter().enumerate() {
        let curvenet = k as u32;
        let range = NetRange { sample: j.samples.len() as u32, segment: j.segments.len() as u32, slot: j.n_slots };
        j.nets.push(range);
        j.samples.extend_from_slice(layout.neutral_samples());
        let first = j.sample_ref.len();
        j.sample_ref.extend((0..layout.n_samples() as u32).map(|sample| SampleRef {
            curvenet,
            spline: u32::MAX,
            sample,
        }));
        for seg in layout.sampling().segments() {
            j.segments.push(seg.samples.map(|i| i + range.sample));
            j.segment_ref.push(SegmentRef { curvenet, spline: seg.spline, segment: seg.spline_segment });
            j.segment_curve.push(n_curves + seg.curve);
            for &i in &seg.samples {
                j.sample_ref[first + i as usize].spline = seg.spline;
            }
        }
        for (k, slot) in layout.constraints().slots().iter().enumerate() {
            let id = range.slot + k as u32;
            if let Some(s) = slot.outgoing {
                j.slot_of.insert((s + range.segment, TAIL, slot.side), id);
            }
            if let Some(s) = slot.incoming {
                j.slot_of.insert((s + range.segment, HEAD, slot.side), id);
            }
        }
        j.n_slots += layout.constraints().len() as u32;
        n_curves += layout.sampling().n_curves() as u32;
    }
    Ok(j)
}
