//! The combinatorial structure of a curvenet: intersections, anchors, curves.
//!
//! The *valence* of a control point is the number of spline ends at it (a
//! spline whose two endpoints are the same point counts twice). Endpoints of
//! valence ≥ 3 are **intersections**, of valence 1 **anchors**; valence-2
//! endpoints join two splines into one curve. A **curve** is a maximal chain
//! of splines joined through valence-2 endpoints; it runs between labelled
//! endpoints (intersections and/or anchors), or, if it meets none, it is an
//! **isolated closed curve**.
//!
//! # Orientation and numbering (deterministic)
//!
//! - Curves are numbered in increasing order of their lowest spline index.
//! - A curve is oriented so that its lowest-indexed spline is traversed
//!   forwards (from its control point 0 to its control point 3); the other
//!   splines follow, each flagged `reversed` when traversed from 3 to 0.
//! - An isolated closed curve starts (and ends) at control point 0 of its
//!   lowest-indexed spline. A curve that leaves an intersection and comes
//!   back to it (a loop through an intersection) starts and ends there and
//!   so emanates twice from it.

use super::Curvenet;

/// What a labelled curve endpoint is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EndpointKind {
    /// Shared by three or more spline ends.
    Intersection,
    /// The end of exactly one spline.
    Anchor,
}

/// One end of a curve: the control point there and what it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CurveEnd {
    /// The curve ends at an intersection (control point index).
    Intersection(u32),
    /// The curve ends at an anchor (control point index).
    Anchor(u32),
    /// The curve is an isolated closed curve; this is its (unlabelled)
    /// start and end point.
    Closed(u32),
}

impl CurveEnd {
    /// The control point at this end.
    pub fn point(self) -> u32 {
        match self {
            CurveEnd::Intersection(p) | CurveEnd::Anchor(p) | CurveEnd::Closed(p) => p,
        }
    }

    /// The intersection at this end, if any.
    pub fn intersection(self) -> Option<u32> {
        match self {
            CurveEnd::Intersection(p) => Some(p),
            _ => None,
        }
    }
}

/// A spline as traversed by a curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct CurveSpline {
    /// The spline index.
    pub spline: u32,
    /// `true` when the curve runs from the spline's control point 3 to 0.
    pub reversed: bool,
}

/// A curve: a chain of splines between labelled endpoints, or an isolated
/// closed chain.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Curve {
    /// The splines in curve order.
    pub splines: Vec<CurveSpline>,
    /// The first end.
    pub start: CurveEnd,
    /// The last end (the same point as `start` for closed curves).
    pub end: CurveEnd,
}

impl Curve {
    /// Whether the curve meets no intersection (both ends anchors, or an
    /// isolated closed curve). Such curves get no normals or widths; their
    /// deformation gradient is a rotation of the tangent times a stretch.
    pub fn is_isolated(&self) -> bool {
        self.start.intersection().is_none() && self.end.intersection().is_none()
    }

    /// Whether the curve returns to its start point: an isolated closed curve
    /// or a loop through an intersection.
    pub fn is_closed(&self) -> bool {
        self.start.point() == self.end.point()
    }
}

/// The combinatorial analysis of a [`Curvenet`]. Immutable.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Topology {
    #[serde(with = "crate::persist::pod")]
    valence: Vec<u32>,
    curves: Vec<Curve>,
    #[serde(with = "crate::persist::pod")]
    intersections: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    anchors: Vec<u32>,
    /// `(curve, position in the curve)` of every spline.
    spline_curve: Vec<(u32, u32)>,
}

impl Topology {
    /// Analyses the curvenet's connectivity (infallible for a validated curvenet).
    pub fn new(curvenet: &Curvenet) -> Self {
        let splines = curvenet.splines();
        let n_points = curvenet.n_points();
        // Spline ends per point, in (spline, end) order.
        let mut valence = vec![0u32; n_points];
        for s in splines {
            valence[s[0] as usize] += 1;
            valence[s[3] as usize] += 1;
        }
        let mut offsets = vec![0usize; n_points + 1];
        for p in 0..n_points {
            offsets[p + 1] = offsets[p] + valence[p] as usize;
        }
        let mut fill = offsets.clone();
        let mut ends = vec![(0u32, 0u8); offsets[n_points]];
        for (i, s) in splines.iter().enumerate() {
            for e in [0u8, 3] {
                let p = s[e as usize] as usize;
                ends[fill[p]] = (i as u32, e);
                fill[p] += 1;
            }
        }
        // At a valence-2 point, the spline end other than `from`.
        let other_end = |p: u32, from: (u32, u8)| -> (u32, u8) {
            let here = &ends[offsets[p as usize]..offsets[p as usize + 1]];
            if here[0] == from { here[1] } else { here[0] }
        };
        let opposite = |e: u8| 3 - e;

        let mut visited = vec![false; splines.len()];
        let mut curves = Vec::new();
        let mut spline_curve = vec![(0u32, 0u32); splines.len()];
        for s in 0..splines.len() {
            if visited[s] {
                continue;
            }
            visited[s] = true;
            let mut forward = vec![CurveSpline { spline: s as u32, reversed: false }];
            // Walk forwards from control point 3.
            let mut from = (s as u32, 3u8);
            let mut point = splines[s][3];
            let mut closed = false;
            while valence[point as usize] == 2 {
                let (next, e) = other_end(point, from);
                if next as usize == s {
                    closed = true;
                    break;
                }
                visited[next as usize] = true;
                forward.push(CurveSpline { spline: next, reversed: e == 3 });
                from = (next, opposite(e));
                point = splines[next as usize][opposite(e) as usize];
            }
            let end_point = point;
            // Walk backwards from control point 0.
            let mut backward = Vec::new();
            let mut start_point = splines[s][0];
            if !closed {
                let mut from = (s as u32, 0u8);
                while valence[start_point as usize] == 2 {
                    let (prev, e) = other_end(start_point, from);
                    visited[prev as usize] = true;
                    backward.push(CurveSpline { spline: prev, reversed: e == 0 });
                    from = (prev, opposite(e));
                    start_point = splines[prev as usize][opposite(e) as usize];
                }
            }
            backward.reverse();
            backward.extend(forward);
            let label = |p: u32| {
                if closed {
                    CurveEnd::Closed(p)
                } else if valence[p as usize] == 1 {
                    CurveEnd::Anchor(p)
                } else {
                    CurveEnd::Intersection(p)
                }
            };
            let c = curves.len() as u32;
            for (k, cs) in backward.iter().enumerate() {
                spline_curve[cs.spline as usize] = (c, k as u32);
            }
            curves.push(Curve { splines: backward, start: label(start_point), end: label(end_point) });
        }
        let intersections = (0..n_points as u32).filter(|&p| valence[p as usize] >= 3).collect();
        let anchors = (0..n_points as u32).filter(|&p| valence[p as usize] == 1).collect();
        Self { valence, curves, intersections, anchors, spline_curve }
    }

    /// The curves, numbered by their lowest spline index.
    pub fn curves(&self) -> &[Curve] {
        &self.curves
    }

    /// Control points that are intersections (valence ≥ 3), increasing.
    pub fn intersections(&self) -> &[u32] {
        &self.intersections
    }

    /// Control points that are anchors (valence 1), increasing.
    pub fn anchors(&self) -> &[u32] {
        &self.anchors
    }

    /// Indices of the isolated closed curves (closed curves through no intersection).
    pub fn isolated_closed_curves(&self) -> impl Iterator<Item = usize> + '_ {
        self.curves.iter().enumerate().filter(|(_, c)| matches!(c.start, CurveEnd::Closed(_))).map(|(i, _)| i)
    }

    /// Number of spline ends at control point `p` (0 for handles and unused points).
    pub fn valence(&self, p: usize) -> u32 {
        self.valence[p]
    }

    /// What endpoint `p` is, if it is labelled.
    pub fn endpoint_kind(&self, p: usize) -> Option<EndpointKind> {
        match self.valence[p] {
            1 => Some(EndpointKind::Anchor),
            v if v >= 3 => Some(EndpointKind::Intersection),
            _ => None,
        }
    }

    /// The curve containing spline `s` and the spline's position in it.
    pub fn spline_curve(&self, s: usize) -> (u32, u32) {
        self.spline_curve[s]
    }
}

impl Topology {
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.valence)
            + bytes(&self.curves)
            + self.curves.iter().map(|c| bytes(&c.splines)).sum::<usize>()
            + bytes(&self.intersections)
            + bytes(&self.anchors)
            + bytes(&self.spline_curve)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(n: usize) -> Vec<[f64; 3]> {
        (0..n).map(|i| [i as f64, (i as f64 * 0.7).sin(), 0.0]).collect()
    }

    #[test]
    fn chain_with_mixed_spline_directions() {
        // Points 0, 3, 6, 9 are endpoints; spline 1 is authored backwards.
        let pts = line(10);
        let net = Curvenet::new(&[[3, 4, 5, 6], [9, 8, 7, 6], [0, 1, 2, 3]], &pts).unwrap();
        let t = Topology::new(&net);
        assert_eq!(t.curves().len(), 1);
        let c = &t.curves()[0];
        // Oriented so that spline 0 (the lowest) runs forwards: 0 → 3 → 6 → 9.
        assert_eq!(c.start, CurveEnd::Anchor(0));
        assert_eq!(c.end, CurveEnd::Anchor(9));
        assert_eq!(
            c.splines,
            vec![
                CurveSpline { spline: 2, reversed: false },
                CurveSpline { spline: 0, reversed: false },
                CurveSpline { spline: 1, reversed: true },
            ]
        );
        assert!(c.is_isolated() && !c.is_closed());
        assert_eq!(t.anchors(), &[0, 9]);
        assert!(t.intersections().is_empty());
        assert_eq!(t.spline_curve(1), (0, 2));
    }

    #[test]
    fn single_spline_loop_and_loop_through_intersection() {
        let pts = line(12);
        // Spline 0 closes on itself at point 0 (an isolated closed curve).
        // Splines 1..3 form a loop 4 → 7 → 4 through intersection 4, which
        // also has the open curve 4 → 10 (spline 3).
        let net = Curvenet::new(&[[0, 1, 2, 0], [4, 5, 6, 7], [7, 8, 9, 4], [10, 11, 9, 4]], &pts).unwrap();
        let t = Topology::new(&net);
        assert_eq!(t.curves().len(), 3);
        assert_eq!(t.curves()[0].start, CurveEnd::Closed(0));
        assert_eq!(t.isolated_closed_curves().collect::<Vec<_>>(), vec![0]);
        let lp = &t.curves()[1];
        assert_eq!((lp.start, lp.end), (CurveEnd::Intersection(4), CurveEnd::Intersection(4)));
        assert!(lp.is_closed() && !lp.is_isolated());
        // Spline 3 runs 10 → 4 forwards.
        assert_eq!((t.curves()[2].start, t.curves()[2].end), (CurveEnd::Anchor(10), CurveEnd::Intersection(4)));
        assert_eq!(t.valence(4), 3);
        assert_eq!(t.valence(0), 2);
        assert_eq!(t.endpoint_kind(4), Some(EndpointKind::Intersection));
        assert_eq!(t.endpoint_kind(0), None);
        assert_eq!(t.endpoint_kind(10), Some(EndpointKind::Anchor));
    }
}
