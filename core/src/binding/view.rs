//! Read-only views of a binding for inspection tools (the service's viewer,
//! `/viewer`): the analysed curvenets, where each one's samples start in the
//! binding's global numbering, and the posed curvenet of a frame (samples
//! and scaled frames) computed exactly as [`Binding::deform`] computes it.

use super::Binding;
use crate::curvenet::{CurvenetLayout, ScaledFrame, scaled_frames};
use crate::error::{Error, Result};

/// A curvenet's samples and per-side scaled frames in one pose.
pub type CurvenetPose = (Vec<[f64; 3]>, Vec<[ScaledFrame; 2]>);

impl Binding {
    /// The bound curvenets as analysed (neutral samples, frames, topology), in binding order.
    pub fn layouts(&self) -> &[CurvenetLayout] {
        &self.layouts
    }

    /// The first global sample of curvenet `k` (global samples number the
    /// curvenets' samples one curvenet after another, as
    /// [`Binding::sample_projection`] and `CutMesh::sample_vertex` do).
    pub fn sample_offset(&self, k: usize) -> usize {
        self.nets[k].sample as usize
    }

    /// Curvenet `k` as a frame sees it: its samples and the scaled frames
    /// of both sides of every segment (`[segment][Side as usize]`), for the
    /// posed pool `posed`, else the pool tracked to the frame's `rest` pose,
    /// else the neutral pose — the samples and frames [`Binding::deform`]
    /// uses. Fails naming the curvenet when the pool has the wrong length or
    /// the pose is degenerate.
    pub fn curvenet_pose(
        &self,
        k: usize,
        posed: Option<&[[f64; 3]]>,
        rest: Option<&[[f64; 3]]>,
    ) -> Result<CurvenetPose> {
        let layout = self.layouts.get(k).ok_or(Error::IndexOutOfRange {
            what: "curvenet pose request",
            index: 0,
            target: "curvenet",
            value: k as u32,
            len: self.layouts.len(),
        })?;
        let samples = match (posed, rest) {
            (Some(pool), _) => layout.sampling().samples(pool)?,
            (None, Some(rest)) => {
                let mut tracked = vec![[0.0; 3]; layout.sampling().n_points()];
                self.tracked_pool_into(k, rest, &mut tracked)?;
                layout.sampling().samples(&tracked)?
            }
            (None, None) => layout.neutral_samples().to_vec(),
        };
        let frames = scaled_frames(layout, &samples)?;
        Ok((samples, frames))
    }
}
