//! The curves emanating from every intersection, sorted counter-clockwise
//! around the normal of the closest surface point (neutral pose).
//!
//! Each curve end at an intersection is one [`Emanation`]; a loop through an
//! intersection emanates twice. Its direction is the tangent of the curve's
//! segment at that end, walked away from the intersection. Directions are
//! projected on the plane orthogonal to the surface normal `N` (the
//! vector-area normal of the closest mesh face) and sorted by angle,
//! counter-clockwise seen from the tip of `N`. Corner `k` lies between
//! emanation `k` and emanation `k + 1` (cyclically), i.e. on the left of
//! emanation `k` and on the right of emanation `k + 1`.

use glam::DVec3;

use super::sampling::Sampling;
use super::topology::Topology;
use super::v3;
use crate::closest_point::ClosestPointBvh;
use crate::error::{Error, Result};

/// Two emanation directions whose projected angles differ by less than this
/// (radians) are coincident ([`Error::CoincidentTangents`]).
pub const COINCIDENT_ANGLE: f64 = 1e-6;

/// A projected direction shorter than this fraction of the tangent counts as
/// along the normal ([`Error::TangentAlongNormal`]).
const ALONG_NORMAL: f64 = 1e-9;

/// Corners with `|t_i × t_{i+1}|` below this (about 1.15°) in the neutral
/// pose are T-junction corners (see [`IntersectionFan::corner_sign`]).
pub const T_JUNCTION_SIN: f64 = 0.02;

/// A corner whose neutral corner vector `t_i × t_{i+1}` makes more than 60°
/// with the surface normal is a T-junction corner too: its two curves leave
/// nearly opposite each other in the tangent plane (the cap side of a ring
/// met by a single line), so their cross product is set by how the curves
/// bend off the surface, not by the surface, and its direction (along the
/// ring's axis) and orientation (decided by round-off) mean nothing. In a
/// fan whose curves all leave steeply off the surface the bar is half the
/// best corner's alignment instead, so the best aligned corner always counts.
pub const CORNER_NORMAL_COS: f64 = 0.5;

/// One curve end at an intersection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Emanation {
    /// The curve.
    pub curve: u32,
    /// `true` when the curve starts here (it leaves in its own direction),
    /// `false` when it ends here (it leaves walked backwards).
    pub at_start: bool,
    /// The curve's segment at this end (its first or last segment).
    pub segment: u32,
    /// The spline of that segment.
    pub spline: u32,
}

/// An intersection with its emanating curve ends in counter-clockwise order.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IntersectionFan {
    point: u32,
    sample: u32,
    face: u32,
    normal: [f64; 3],
    emanations: Vec<Emanation>,
    /// Orientation of corner k in the neutral pose: +1 when t_k × t_{k+1}
    /// points along the surface normal, −1 against it (a reflex corner),
    /// 0 for a T-junction corner.
    corner_signs: Vec<i8>,
}

impl IntersectionFan {
    /// The intersection's control point.
    pub fn point(&self) -> u32 {
        self.point
    }

    /// The intersection's (knot) sample.
    pub fn sample(&self) -> u32 {
        self.sample
    }

    /// The surface face closest to the intersection (neutral pose).
    pub fn face(&self) -> u32 {
        self.face
    }

    /// The unit surface normal used for the ordering (the face's vector-area normal).
    pub fn normal(&self) -> [f64; 3] {
        self.normal
    }

    /// The emanating curve ends, counter-clockwise around [`Self::normal`].
    pub fn emanations(&self) -> &[Emanation] {
        &self.emanations
    }

    /// Number of emanating curve ends (the valence, ≥ 3).
    pub fn valence(&self) -> usize {
        self.emanations.len()
    }

    /// Orientation of corner `k` (between emanations `k` and `k + 1`) fixed in
    /// the neutral pose: `1`, `-1` (reflex corner; its corner vector is
    /// negated so that corner normals follow the surface normal) or `0`
    /// (T-junction corner: `|t_k × t_{k+1}|` below [`T_JUNCTION_SIN`], or
    /// that vector more than 60° from the surface normal, see
    /// [`CORNER_NORMAL_COS`]; its normal comes from its neighbours in every pose).
    pub fn corner_sign(&self, k: usize) -> i8 {
        self.corner_signs[k]
    }
}

/// Which fan slot `(fan, position)` each curve's start and end occupy.
pub(crate) type CurveEndSlots = Vec<[Option<(u32, u32)>; 2]>;

/// Builds the fans of all intersections from the neutral samples.
pub(crate) fn intersection_fans(
    topology: &Topology,
    sampling: &Sampling,
    neutral: &[[f64; 3]],
    bvh: &ClosestPointBvh,
) -> Result<(Vec<IntersectionFan>, CurveEndSlots)> {
    let points = topology.intersections();
    let fan_of = |p: u32| points.binary_search(&p).expect("curve ends at a listed intersection");
    let mut emanations: Vec<Vec<Emanation>> = vec![Vec::new(); points.len()];
    for (c, curve) in topology.curves().iter().enumerate() {
        let segs = sampling.curve_segments(c);
        for (at_start, end, seg) in [(true, curve.start, segs.start), (false, curve.end, segs.end - 1)] {
            if let Some(p) = end.intersection() {
                let spline = sampling.segments()[seg].spline;
                emanations[fan_of(p)].push(Emanation { curve: c as u32, at_start, segment: seg as u32, spline });
            }
        }
    }
    let direction = |e: &Emanation| {
        let [a, b] = sampling.segments()[e.segment as usize].samples;
        let d = v3(neutral[b as usize]) - v3(neutral[a as usize]);
        (if e.at_start { d } else { -d }).normalize_or_zero()
    };

    let mut fans = Vec::with_capacity(points.len());
    let mut ends: CurveEndSlots = vec![[None, None]; topology.curves().len()];
    for (f, (&point, ems)) in points.iter().zip(emanations).enumerate() {
        let sample = sampling.knot_sample(point as usize).expect("an intersection is a spline endpoint");
        let hit = bvh.closest_point(neutral[sample as usize])?;
        let normal = v3(bvh.face_normal(hit.face as usize));
        if normal == DVec3::ZERO {
            return Err(Error::DegenerateSurfaceFace { point, face: hit.face as usize });
        }
        let e1 = normal.any_orthonormal_vector();
        let e2 = normal.cross(e1);
        let mut keyed = Vec::with_capacity(ems.len());
        for e in ems {
            let t = direction(&e);
            let tp = t - t.dot(normal) * normal;
            if tp.length() <= ALONG_NORMAL {
                return Err(Error::TangentAlongNormal { point, spline: e.spline as usize });
            }
            keyed.push((tp.dot(e2).atan2(tp.dot(e1)), e));
        }
        keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
        let v = keyed.len();
        for k in 0..v {
            let next = (k + 1) % v;
            let mut gap = keyed[next].0 - keyed[k].0;
            if next == 0 {
                gap += std::f64::consts::TAU;
            }
            if gap < COINCIDENT_ANGLE {
                let (a, b) = (keyed[k].1.spline as usize, keyed[next].1.spline as usize);
                return Err(Error::CoincidentTangents { point, splines: [a.min(b), a.max(b)] });
            }
        }
        let emanations: Vec<Emanation> = keyed.into_iter().map(|(_, e)| e).collect();
        // A corner whose vector lies far off the surface normal is a
        // T-junction corner; "far" is relative to the fan's best aligned
        // corner, so a fan drawn steeply off the surface keeps its best corner.
        let corners: Vec<DVec3> =
            (0..v).map(|k| direction(&emanations[k]).cross(direction(&emanations[(k + 1) % v]))).collect();
        let alignment = |c: DVec3| if c.length() < T_JUNCTION_SIN { 0.0 } else { c.dot(normal).abs() / c.length() };
        let best = corners.iter().map(|&c| alignment(c)).fold(0.0, f64::max);
        let corner_signs = corners
            .iter()
            .map(|&c| {
                if c.length() < T_JUNCTION_SIN || alignment(c) < CORNER_NORMAL_COS.min(CORNER_NORMAL_COS * best) {
                    0
                } else if c.dot(normal) >= 0.0 {
                    1
                } else {
                    -1
                }
            })
            .collect();
        for (k, e) in emanations.iter().enumerate() {
            ends[e.curve as usize][if e.at_start { 0 } else { 1 }] = Some((f as u32, k as u32));
        }
        fans.push(IntersectionFan {
            point,
            sample,
            face: hit.face,
            normal: normal.to_array(),
            emanations,
            corner_signs,
        });
    }
    Ok((fans, ends))
}

impl IntersectionFan {
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        crate::heap::bytes(&self.emanations) + crate::heap::bytes(&self.corner_signs)
    }
}
