//! The analysed curvenet: everything that depends only on the neutral pose,
//! computed once and immutable afterwards.

use super::constraints::ConstraintTable;
use super::frames::{FramePlan, ScaledFrame, frames, frames_into};
use super::intersections::{CurveEndSlots, IntersectionFan, intersection_fans};
use super::sampling::{Sampling, SamplingOptions};
use super::topology::Topology;
use super::{Curvenet, v3};
use crate::closest_point::ClosestPointBvh;
use crate::error::{Error, Result};
use crate::mesh::PolyMesh;

/// A segment shorter than this fraction of the mean neutral segment length
/// has collapsed ([`Error::SegmentCollapsed`]).
pub const COLLAPSE_TOLERANCE: f64 = 1e-10;

/// The neutral-pose analysis of a curvenet (§3): topology, the fixed
/// sampling plan, the counter-clockwise order of curves at every
/// intersection, the constraint slots, and the neutral samples and frames.
/// Immutable and `Send + Sync`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CurvenetLayout {
    topology: Topology,
    sampling: Sampling,
    fans: Vec<IntersectionFan>,
    curve_ends: CurveEndSlots,
    curve_isolated: Vec<bool>,
    constraints: ConstraintTable,
    #[serde(with = "crate::persist::pod")]
    neutral_pool: Vec<[f64; 3]>,
    #[serde(with = "crate::persist::pod")]
    neutral_samples: Vec<[f64; 3]>,
    neutral_frames: Vec<[ScaledFrame; 2]>,
    collapse_length: f64,
}

impl CurvenetLayout {
    /// Analyses `curvenet` (its neutral pose) against the surface `mesh`
    /// posed at `mesh_points` (`#V`; the pose the curvenet was drawn on,
    /// used both for the mean edge length of the sampling density and for
    /// the surface normals at intersections).
    pub fn new(
        curvenet: &Curvenet,
        mesh: &PolyMesh,
        mesh_points: &[[f64; 3]],
        options: &SamplingOptions,
    ) -> Result<Self> {
        let bvh = ClosestPointBvh::new(mesh, mesh_points)?;
        Self::with_closest_point(curvenet, &bvh, mesh.mean_edge_length(mesh_points), options)
    }

    /// Like [`Self::new`], reusing a closest-point hierarchy of the surface
    /// and its mean edge length.
    pub fn with_closest_point(
        curvenet: &Curvenet,
        bvh: &ClosestPointBvh,
        mean_edge_length: f64,
        options: &SamplingOptions,
    ) -> Result<Self> {
        let topology = Topology::new(curvenet);
        let sampling = Sampling::new(curvenet, &topology, mean_edge_length, options)?;
        let neutral_samples = sampling.samples(curvenet.points())?;
        let lengths: Vec<f64> = sampling
            .segments()
            .iter()
            .map(|s| (v3(neutral_samples[s.samples[1] as usize]) - v3(neutral_samples[s.samples[0] as usize])).length())
            .collect();
        let mean = lengths.iter().sum::<f64>() / lengths.len() as f64;
        let collapse_length = COLLAPSE_TOLERANCE * mean;
        if let Some((s, &length)) = lengths.iter().enumerate().find(|(_, l)| l.is_nan() || **l <= collapse_length) {
            let seg = sampling.segments()[s];
            return Err(Error::SegmentCollapsed {
                spline: seg.spline as usize,
                segment: seg.spline_segment as usize,
                length,
            });
        }
        let (fans, curve_ends) = intersection_fans(&topology, &sampling, &neutral_samples, bvh)?;
        let curve_isolated = topology.curves().iter().map(|c| c.is_isolated()).collect();
        let constraints = ConstraintTable::new(&sampling, &topology);
        let plan = FramePlan { sampling: &sampling, fans: &fans, curve_ends: &curve_ends, collapse_length };
        let neutral_frames = frames(plan, &neutral_samples)?;
        Ok(Self {
            topology,
            sampling,
            fans,
            curve_ends,
            curve_isolated,
            constraints,
            neutral_pool: curvenet.points().to_vec(),
            neutral_samples,
            neutral_frames,
            collapse_length,
        })
    }

    /// What the scaled frames need of this analysis.
    pub fn frame_plan(&self) -> FramePlan<'_> {
        FramePlan {
            sampling: &self.sampling,
            fans: &self.fans,
            curve_ends: &self.curve_ends,
            collapse_length: self.collapse_length,
        }
    }

    /// Intersections, anchors and curves.
    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// The fixed sampling plan; its `samples_into` evaluates a pose.
    pub fn sampling(&self) -> &Sampling {
        &self.sampling
    }

    /// One fan per intersection, in the order of `Topology::intersections`.
    pub fn intersections(&self) -> &[IntersectionFan] {
        &self.fans
    }

    /// The constraint slots (§4.3).
    pub fn constraints(&self) -> &ConstraintTable {
        &self.constraints
    }

    /// The control-point pool of the neutral pose (`#P`).
    pub fn neutral_pool(&self) -> &[[f64; 3]] {
        &self.neutral_pool
    }

    /// The samples of the neutral pose (`#Q`).
    pub fn neutral_samples(&self) -> &[[f64; 3]] {
        &self.neutral_samples
    }

    /// The scaled frames of the neutral pose (`#G` pairs), the default rest frames.
    pub fn neutral_frames(&self) -> &[[ScaledFrame; 2]] {
        &self.neutral_frames
    }

    /// Number of samples `#Q`.
    pub fn n_samples(&self) -> usize {
        self.sampling.n_samples()
    }

    /// Number of segments `#G`.
    pub fn n_segments(&self) -> usize {
        self.sampling.n_segments()
    }

    /// Whether curve `c` meets no intersection (tangent-only frames).
    pub fn curve_is_isolated(&self, c: usize) -> bool {
        self.curve_isolated[c]
    }

    /// `[start, end]` of curve `c`: `(fan, position in the fan)` where the
    /// end is at an intersection, `None` at an anchor or for closed isolated curves.
    pub fn curve_end_slots(&self, c: usize) -> [Option<(u32, u32)>; 2] {
        self.curve_ends[c]
    }

    /// Segments shorter than this length have collapsed
    /// ([`COLLAPSE_TOLERANCE`] × the mean neutral segment length).
    pub fn collapse_length(&self) -> f64 {
        self.collapse_length
    }
}

/// The scaled frames of both sides of every segment of `layout`'s curvenet
/// sampled at `samples`, into `out` (see [`frames_into`](super::frames::frames_into)). Allocation-free.
pub fn scaled_frames_into(layout: &CurvenetLayout, samples: &[[f64; 3]], out: &mut [[ScaledFrame; 2]]) -> Result<()> {
    frames_into(layout.frame_plan(), samples, out)
}

/// Allocating form of [`scaled_frames_into`].
pub fn scaled_frames(layout: &CurvenetLayout, samples: &[[f64; 3]]) -> Result<Vec<[ScaledFrame; 2]>> {
    frames(layout.frame_plan(), samples)
}

impl CurvenetLayout {
    /// Heap bytes held: topology, sampling plan, fans, constraint slots and
    /// the neutral pool, samples and frames (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        self.topology.heap_bytes()
            + self.sampling.heap_bytes()
            + bytes(&self.fans)
            + self.fans.iter().map(|f| f.heap_bytes()).sum::<usize>()
            + bytes(&self.curve_ends)
            + bytes(&self.curve_isolated)
            + self.constraints.heap_bytes()
            + bytes(&self.neutral_pool)
            + bytes(&self.neutral_samples)
            + bytes(&self.neutral_frames)
    }
}
