//! Topology counts on hand-built curvenets, and the counter-clockwise order
//! of curves at an intersection.

mod common;

use common::*;
use curvenet_core::curvenet::{CurveEnd, Topology};
use curvenet_core::{Curvenet, CurvenetLayout, SamplingOptions};

fn counts(t: &Topology) -> (usize, usize, usize, usize) {
    (t.intersections().len(), t.anchors().len(), t.curves().len(), t.isolated_closed_curves().count())
}

#[test]
fn grid_3x3() {
    let b = grid(0.05);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    // 9 crossings; each of the 6 lines has 2 anchors and 4 curves
    // (anchor–int, int–int, int–int, int–anchor); the int–int curves are two
    // splines joined at a valence-2 joint.
    assert_eq!(counts(&t), (9, 12, 24, 0));
    assert_eq!(b.splines.len(), 36);
    for &p in t.intersections() {
        assert_eq!(t.valence(p as usize), 4);
    }
    let n_two_spline = t.curves().iter().filter(|c| c.splines.len() == 2).count();
    assert_eq!(n_two_spline, 12);
    // Every spline is in exactly one curve, and curves follow spline order.
    let mut seen = vec![0; b.splines.len()];
    for c in t.curves() {
        for cs in &c.splines {
            seen[cs.spline as usize] += 1;
            assert!(!cs.reversed, "all splines of the grid are authored along their lines");
        }
    }
    assert!(seen.iter().all(|&n| n == 1));
    let firsts: Vec<u32> = t.curves().iter().map(|c| c.splines.iter().map(|s| s.spline).min().unwrap()).collect();
    assert!(firsts.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn star_valence_5_and_ccw_order() {
    let b = star();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    assert_eq!(counts(&t), (1, 5, 5, 0));
    let center = t.intersections()[0];
    assert_eq!(t.valence(center as usize), 5);
    // Arms authored from the tip inwards end at the intersection; orientation
    // follows the (single) spline's direction.
    for (k, c) in t.curves().iter().enumerate() {
        if k % 2 == 0 {
            assert_eq!(c.start, CurveEnd::Intersection(center));
            assert!(matches!(c.end, CurveEnd::Anchor(_)));
        } else {
            assert!(matches!(c.start, CurveEnd::Anchor(_)));
            assert_eq!(c.end, CurveEnd::Intersection(center));
        }
    }
    let (mesh, pts) = plane(3.0, 12);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let fan = &layout.intersections()[0];
    assert_eq!(fan.normal(), [0.0, 0.0, 1.0]);
    let order: Vec<u32> = fan.emanations().iter().map(|e| e.curve).collect();
    // Arms sorted by angle: 10° (1), 80° (3), 145° (4), 200° (0), 290° (2),
    // up to a cyclic rotation.
    let expected = [1, 3, 4, 0, 2];
    let r = order.iter().position(|&c| c == expected[0]).unwrap();
    let rotated: Vec<u32> = (0..5).map(|k| order[(r + k) % 5]).collect();
    assert_eq!(rotated, expected);
    for e in fan.emanations() {
        assert_eq!(e.at_start, e.curve % 2 == 0);
    }
    // Upside down (surface normal -z) the order reverses.
    let flipped: Vec<u32> = mesh.faces().flat_map(|f| f.iter().rev().copied().collect::<Vec<_>>()).collect();
    let mesh_down = curvenet_core::PolyMesh::new(&vec![4; mesh.n_faces()], &flipped, pts.len()).unwrap();
    let layout = CurvenetLayout::new(&net, &mesh_down, &pts, &SamplingOptions::default()).unwrap();
    let fan = &layout.intersections()[0];
    assert_eq!(fan.normal(), [0.0, 0.0, -1.0]);
    let order: Vec<u32> = fan.emanations().iter().map(|e| e.curve).collect();
    let r = order.iter().position(|&c| c == expected[0]).unwrap();
    let rotated: Vec<u32> = (0..5).map(|k| order[(r + 5 - k) % 5]).collect();
    assert_eq!(rotated, expected);
}

#[test]
fn t_junction() {
    let mut b = NetBuilder::default();
    b.segment([-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0, -1.0, 0.0], [0.0, 0.0, 0.0], [0.0; 3]);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    assert_eq!(counts(&t), (1, 3, 3, 0));
    let (mesh, pts) = plane(2.0, 8);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    assert_eq!(layout.intersections()[0].valence(), 3);
}

#[test]
fn lone_closed_ring_of_four_splines() {
    let b = {
        let mut b = cylinder_net();
        // Keep only the isolated ring at z = 3 (splines 12..16).
        b.splines = b.splines[12..16].to_vec();
        b
    };
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    assert_eq!(counts(&t), (0, 0, 1, 1));
    let c = &t.curves()[0];
    assert_eq!(c.splines.len(), 4);
    assert!(c.is_closed() && c.is_isolated());
    assert_eq!(c.start, CurveEnd::Closed(b.splines[0][0]));
    // Sampled: every sample listed once, segments close the loop.
    let (mesh, pts) = cylinder(1.0, 2.0, 4.0, 32, 8);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let s = layout.sampling();
    assert_eq!(s.curve_samples(0).len(), s.n_segments());
    assert_eq!(s.n_samples(), s.n_segments());
    let segs = s.segments();
    assert_eq!(segs.last().unwrap().samples[1], segs[0].samples[0]);
    // n_c = 2 × samples (all interior).
    assert_eq!(layout.constraints().len(), 2 * s.n_samples());
}

#[test]
fn curve_with_two_anchors() {
    let mut b = NetBuilder::default();
    b.segment([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.1, 0.0]);
    // authored backwards: 2 → 1
    b.segment([2.0, 0.5, 0.0], [1.0, 0.0, 0.0], [0.0, 0.1, 0.0]);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    assert_eq!(counts(&t), (0, 2, 1, 0));
    let c = &t.curves()[0];
    assert!(c.is_isolated() && !c.is_closed());
    assert!(c.splines[1].reversed);
    let (mesh, pts) = plane(3.0, 12);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let s = layout.sampling();
    let n0 = s.spline_segments(0) as usize;
    let n1 = s.spline_segments(1) as usize;
    assert_eq!(s.n_segments(), n0 + n1);
    // Shared joint sample: samples = segments + 1.
    assert_eq!(s.n_samples(), n0 + n1 + 1);
    assert_eq!(s.curve_samples(0).len(), n0 + n1 + 1);
    assert_eq!(layout.constraints().len(), 2 * (n0 + n1 + 1));
    // The reversed spline's segments count from its own control point 0.
    let last = s.segments().last().unwrap();
    assert_eq!((last.spline, last.spline_segment), (1, 0));
}

#[test]
fn cylinder_rings_and_lines() {
    let b = cylinder_net();
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let t = Topology::new(&net);
    // 12 crossings; 8 line anchors + 2 for the arc; curves: 3 rings × 4,
    // 4 lines × 4, the isolated ring, the arc.
    assert_eq!(counts(&t), (12, 10, 30, 1));
}

#[test]
fn constraint_slots_count_curve_endpoints_once_per_curve() {
    let b = grid(0.05);
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    let (mesh, pts) = plane(3.0, 12);
    let layout = CurvenetLayout::new(&net, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let s = layout.sampling();
    let per_curve: usize = (0..s.n_curves()).map(|c| s.curve_samples(c).len()).sum();
    assert_eq!(layout.constraints().len(), 2 * per_curve);
    // An intersection's sample appears in one slot pair per emanating curve end.
    for fan in layout.intersections() {
        let n = layout.constraints().slots().iter().filter(|sl| sl.sample == fan.sample()).count();
        assert_eq!(n, 2 * fan.valence());
    }
    // Open curves: first slot has no incoming segment, last no outgoing.
    for c in 0..s.n_curves() {
        let slots = layout.constraints().curve_slots(c);
        // Two slots (plus, minus) per sample.
        assert!(slots[..2].iter().all(|sl| sl.incoming.is_none() && sl.outgoing.is_some()));
        assert!(slots[slots.len() - 2..].iter().all(|sl| sl.outgoing.is_none() && sl.incoming.is_some()));
        assert!(slots[2..slots.len() - 2].iter().all(|sl| sl.incoming.is_some() && sl.outgoing.is_some()));
        assert_eq!(slots[0].side, curvenet_core::Side::Plus);
        assert_eq!(slots[1].side, curvenet_core::Side::Minus);
    }
    // Unique samples: knots + interior; the grid's joints are shared.
    let n_knots = 9 + 12 + 12;
    assert_eq!(s.n_knots(), n_knots);
}
