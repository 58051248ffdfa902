//! Deformation gradients: invariants under the neutral pose, uniform scaling
//! and rigid motions on several curvenets, and the bent grid.

mod common;

use common::*;
use curvenet_core::closest_point::ClosestPointBvh;
use curvenet_core::curvenet::{ScaledFrame, deformation_gradients, scaled_frames};
use curvenet_core::{Curvenet, CurvenetLayout, Mat3, PolyMesh, SamplingOptions, Side};

fn layout_of(b: &NetBuilder, mesh: &PolyMesh, pts: &[[f64; 3]]) -> CurvenetLayout {
    let net = Curvenet::new(&b.splines, &b.points).unwrap();
    CurvenetLayout::new(&net, mesh, pts, &SamplingOptions::default()).unwrap()
}

fn gradients_for_pose(layout: &CurvenetLayout, pose: &[[f64; 3]]) -> Vec<[Mat3; 2]> {
    let posed = layout.sampling().samples(pose).unwrap();
    deformation_gradients(layout, layout.neutral_samples(), &posed).unwrap()
}

/// Frames are orthonormal, right-handed, finite, with positive scales.
fn check_frames(frames: &[[ScaledFrame; 2]]) {
    for pair in frames {
        for f in pair {
            assert!(f.scale.iter().all(|s| s.is_finite() && *s > 0.0));
            assert!((norm(f.tangent) - 1.0).abs() < 1e-12);
            if f.has_normal() {
                assert!((norm(f.normal) - 1.0).abs() < 1e-12);
                assert!(dot(f.normal, f.tangent).abs() < 1e-12);
                let b = cross(f.normal, f.tangent);
                assert!(norm(sub(b, f.binormal)) < 1e-15);
                assert!((f.scale[2] - (f.scale[0] * f.scale[1]).sqrt()).abs() < 1e-15 * f.scale[2].max(1.0));
            }
        }
    }
}

/// Neutral → I, scaling by s → s I, rigid motion → R (curves meeting an
/// intersection, and curved isolated curves) or the smallest rotation of the
/// tangent (straight isolated curves).
fn check_invariants(name: &str, b: &NetBuilder, mesh: &PolyMesh, pts: &[[f64; 3]]) -> usize {
    let layout = layout_of(b, mesh, pts);
    check_frames(layout.neutral_frames());
    let n_isolated_segments =
        layout.sampling().segments().iter().filter(|s| layout.curve_is_isolated(s.curve as usize)).count();

    let f = gradients_for_pose(&layout, &b.points);
    let worst = f.iter().flatten().map(|m| max_diff(m, &I3)).fold(0.0, f64::max);
    assert!(worst < 1e-12, "{name}: neutral pose gives F != I by {worst}");

    for s in [1.7, 0.25, 1e-6] {
        let pose: Vec<[f64; 3]> = b.points.iter().map(|p| p.map(|x| s * x)).collect();
        let f = gradients_for_pose(&layout, &pose);
        let worst = f.iter().flatten().map(|m| max_diff(m, &scaled(&I3, s))).fold(0.0, f64::max);
        assert!(worst < 1e-9 * s, "{name}: scaling by {s} gives F != sI by {worst}");
    }

    for (axis, angle) in [([0.3, -0.5, 0.8], 1.1), ([1.0, 0.0, 0.0], std::f64::consts::PI), ([0.0, 1.0, 0.2], -2.5)] {
        let r = rotation(axis, angle);
        let diag = curvenet_core::mesh::bounding_box_diagonal(&b.points);
        let shift = [0.4 * diag, -2.0 * diag, 3.0 * diag];
        let pose: Vec<[f64; 3]> = b
            .points
            .iter()
            .map(|&p| {
                let q = apply(&r, p);
                [q[0] + shift[0], q[1] + shift[1], q[2] + shift[2]]
            })
            .collect();
        let f = gradients_for_pose(&layout, &pose);
        let posed = scaled_frames(&layout, &layout.sampling().samples(&pose).unwrap()).unwrap();
        check_frames(&posed);
        for (s, seg) in layout.sampling().segments().iter().enumerate() {
            if layout.curve_is_isolated(seg.curve as usize) {
                // F maps the rest tangent to the posed one and is a rotation.
                let rest_t = layout.neutral_frames()[s][0].tangent;
                let posed_t = posed[s][0].tangent;
                for fs in &f[s] {
                    assert!(norm(sub(apply(fs, rest_t), posed_t)) < 1e-9);
                    assert!(max_diff(&mat_mul(&transpose(fs), fs), &I3) < 1e-9);
                    // A curved isolated curve has a normal of its own: F is the rotation.
                    if posed[s][0].has_normal() {
                        let d = max_diff(fs, &r);
                        assert!(d < 1e-9, "{name}: rigid motion gives F != R by {d} at isolated segment {s}");
                    }
                }
            } else {
                for (side, fs) in f[s].iter().enumerate() {
                    let d = max_diff(fs, &r);
                    assert!(d < 1e-9, "{name}: rigid motion gives F != R by {d} at segment {s} side {side}");
                }
            }
        }
    }
    n_isolated_segments
}

#[test]
fn invariants_grid() {
    let (mesh, pts) = plane(3.0, 12);
    assert_eq!(check_invariants("grid", &grid(0.05), &mesh, &pts), 0);
    assert_eq!(check_invariants("straight grid", &grid(0.0), &mesh, &pts), 0);
}

#[test]
fn invariants_grid_at_extreme_scales() {
    for s in [1e-8, 1e8] {
        let (mesh, pts) = plane(3.0, 12);
        let pts: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|x| s * x)).collect();
        let mut b = grid(0.05);
        b.points.iter_mut().for_each(|p| *p = p.map(|x| s * x));
        check_invariants("scaled grid", &b, &mesh, &pts);
    }
}

#[test]
fn invariants_star() {
    let (mesh, pts) = plane(3.0, 12);
    check_invariants("star", &star(), &mesh, &pts);
}

#[test]
fn invariants_cylinder_rings_and_lines() {
    let (mesh, pts) = cylinder(1.0, -1.0, 4.0, 48, 30);
    let isolated = check_invariants("cylinder", &cylinder_net(), &mesh, &pts);
    assert!(isolated > 0, "the isolated ring and the arc are tested too");
}

#[test]
fn invariants_on_the_hand() {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
    let b = surface_grid(&bvh, pts[0], 1.5 * mesh.mean_edge_length(&pts));
    check_invariants("hand", &b, &mesh, &pts);
}

#[test]
fn neutral_frames_on_a_plane_follow_the_surface_normal() {
    let (mesh, pts) = plane(3.0, 12);
    for b in [grid(0.05), star()] {
        let layout = layout_of(&b, &mesh, &pts);
        for (s, pair) in layout.neutral_frames().iter().enumerate() {
            for f in pair {
                assert!(norm(sub(f.normal, [0.0, 0.0, 1.0])) < 1e-9, "segment {s}: normal {:?}", f.normal);
                // b = n × t is the left of the curve direction.
                assert!(norm(sub(f.binormal, cross([0.0, 0.0, 1.0], f.tangent))) < 1e-9);
            }
        }
    }
}

#[test]
fn t_junction_normals_and_widths() {
    // Bar −1 → 0 → 1 along x (two curves), stem from (0, −0.6) up to the bar.
    let mut b = NetBuilder::default();
    b.segment([-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3]);
    b.segment([0.0, -0.6, 0.0], [0.0, 0.0, 0.0], [0.0; 3]);
    let (mesh, pts) = plane(2.0, 8);
    let layout = layout_of(&b, &mesh, &pts);
    let fan = &layout.intersections()[0];
    // The straight corner between the two bar halves is a T-junction corner.
    let signs: Vec<i8> = (0..3).map(|k| fan.corner_sign(k)).collect();
    assert_eq!(signs.iter().filter(|&&s| s == 0).count(), 1);
    let frames = layout.neutral_frames();
    let seg_len = |c: usize| frames[layout.sampling().curve_segments(c).start][0].scale[0];
    let first = |c: usize| frames[layout.sampling().curve_segments(c).start];
    let last = |c: usize| frames[layout.sampling().curve_segments(c).end - 1];
    let l_stem = frames[layout.sampling().curve_segments(2).end - 1][0].scale[0];
    // Right bar half (curve 1) starts at the T: left (+) faces the straight
    // corner → w = l; right (−) faces the stem's right angle → w = l_stem.
    let right = first(1);
    assert!((right[Side::Plus as usize].scale[1] - seg_len(1)).abs() < 1e-12);
    assert!((right[Side::Minus as usize].scale[1] - l_stem).abs() < 1e-12);
    // Left bar half (curve 0) ends at the T: walked backwards from it, its
    // plus side (the +y side, the straight corner) keeps w = l.
    let left = last(0);
    let l0 = left[0].scale[0];
    assert!((left[Side::Plus as usize].scale[1] - l0).abs() < 1e-12);
    assert!((left[Side::Minus as usize].scale[1] - l_stem).abs() < 1e-12);
    for pair in frames {
        for f in pair {
            assert!(norm(sub(f.normal, [0.0, 0.0, 1.0])) < 1e-12);
        }
    }

    // Bending the bar a little in the plane, either way, keeps the normals
    // close to +z (no flip through the T-junction corner).
    for bend in [-0.02, -0.005, 0.0, 0.005, 0.02, 0.1] {
        let r = rotation([0.0, 0.0, 1.0], bend);
        let pose: Vec<[f64; 3]> = b.points.iter().map(|&p| if p[0] > 0.0 { apply(&r, p) } else { p }).collect();
        let frames = scaled_frames(&layout, &layout.sampling().samples(&pose).unwrap()).unwrap();
        for pair in &frames {
            for f in pair {
                assert!(norm(sub(f.normal, [0.0, 0.0, 1.0])) < 1e-9, "bend {bend}: normal {:?}", f.normal);
            }
        }
    }
}

/// Control points with x > 0 rotated by 90° about the y axis.
fn bend(points: &[[f64; 3]]) -> (Vec<[f64; 3]>, Mat3) {
    let r = rotation([0.0, 1.0, 0.0], std::f64::consts::FRAC_PI_2);
    (points.iter().map(|&p| if p[0] > 0.0 { apply(&r, p) } else { p }).collect(), r)
}

#[test]
fn bent_grid_straight_lines_exact() {
    let (mesh, pts) = plane(3.0, 12);
    let b = grid(0.0);
    let layout = layout_of(&b, &mesh, &pts);
    let (pose, r) = bend(&b.points);
    let f = gradients_for_pose(&layout, &pose);
    let samples = layout.neutral_samples();
    for (s, seg) in layout.sampling().segments().iter().enumerate() {
        let [a, c] = seg.samples.map(|k| samples[k as usize]);
        let mid_x = 0.5 * (a[0] + c[0]);
        let on_middle = a[0] == 0.0 && c[0] == 0.0;
        let expected: [Mat3; 2] = if on_middle {
            // Vertical middle line runs in +y: its left (+) is x < 0 (flat).
            [I3, r]
        } else if mid_x < 0.0 {
            [I3, I3]
        } else {
            [r, r]
        };
        for side in 0..2 {
            let d = max_diff(&f[s][side], &expected[side]);
            assert!(d < 1e-9, "segment {s} (x {mid_x}, middle {on_middle}) side {side}: off by {d}");
        }
    }
}

#[test]
fn bent_grid_curved_lines() {
    // The in-plane bulge moves handles of the middle line off x = 0, so the
    // fold is no longer exactly along the middle curve: its handles on the
    // x > 0 side rotate too. Away from the fold the result is still exact;
    // on the middle curve the two sides still differ, approximately I and R.
    let (mesh, pts) = plane(3.0, 12);
    let b = grid(0.02);
    let layout = layout_of(&b, &mesh, &pts);
    let (pose, r) = bend(&b.points);
    let f = gradients_for_pose(&layout, &pose);
    let samples = layout.neutral_samples();
    let posed_frames = scaled_frames(&layout, &layout.sampling().samples(&pose).unwrap()).unwrap();
    let mut tangent_turn: f64 = 0.0;
    let mut worst_middle: f64 = 0.0;
    let mut worst_middle_away: f64 = 0.0;
    let mut worst_far: f64 = 0.0;
    for (s, seg) in layout.sampling().segments().iter().enumerate() {
        let curve = &layout.topology().curves()[seg.curve as usize];
        let [p, q] = [curve.start.point(), curve.end.point()].map(|k| b.points[k as usize]);
        let [a, c] = seg.samples.map(|k| samples[k as usize]);
        let mid_y = 0.5 * (a[1] + c[1]);
        if p[0] == 0.0 && q[0] == 0.0 {
            // A segment of the middle vertical line.
            let d = max_diff(&f[s][0], &I3).max(max_diff(&f[s][1], &r));
            worst_middle = worst_middle.max(d);
            let (t0, t1) = (layout.neutral_frames()[s][0].tangent, posed_frames[s][0].tangent);
            tangent_turn = tangent_turn.max(norm(cross(t0, t1)).asin());
            // Away from the intersections (y = ±1, 0) and from the joints.
            if (mid_y - mid_y.round()).abs() > 0.15 {
                worst_middle_away = worst_middle_away.max(d);
            }
        } else if p[0].abs() >= 1.0 && q[0].abs() >= 1.0 {
            // Curves between the outer intersections and anchors: rigid.
            let expected = if p[0] < 0.0 { I3 } else { r };
            let d = max_diff(&f[s][0], &expected).max(max_diff(&f[s][1], &expected));
            worst_far = worst_far.max(d);
        }
    }
    println!(
        "bent curved grid: worst |F - (I | R)| on the middle curve {worst_middle:.3e} \
         ({worst_middle_away:.3e} farther than 0.15 from intersections and joints), \
         on the outer rigid curves {worst_far:.3e}; the middle curve's own tangents turn by up to {tangent_turn:.3e} rad"
    );
    // The middle curve itself deforms (its x > 0 handles rotate), so F there
    // departs from I / R by about its tangent turn.
    assert!(worst_middle < 2.0 * tangent_turn.max(0.01), "{worst_middle}");
    assert!(worst_middle < 0.1, "{worst_middle}");
    assert!(worst_far < 1e-9);
}

#[test]
fn invariants_loop_through_an_intersection_and_reflex_corner() {
    let (mesh, pts) = plane(3.0, 12);
    // A teardrop loop leaving and re-entering the origin, plus one arm: the
    // three curve ends at the origin span less than a half plane, so one
    // corner is reflex.
    let mut b = NetBuilder::default();
    b.spline([0.0; 3], [1.5, 0.3, 0.0], [1.2, 1.5, 0.0], [0.0; 3]);
    b.segment([0.0; 3], [1.0, 0.6, 0.0], [0.0, 0.05, 0.0]);
    let layout = layout_of(&b, &mesh, &pts);
    let fan = &layout.intersections()[0];
    assert_eq!(fan.valence(), 3);
    let lp = &layout.topology().curves()[0];
    assert!(lp.is_closed() && !lp.is_isolated());
    assert_eq!((0..3).filter(|&k| fan.corner_sign(k) == -1).count(), 1);
    for pair in layout.neutral_frames() {
        for f in pair {
            assert!(norm(sub(f.normal, [0.0, 0.0, 1.0])) < 1e-9);
        }
    }
    check_invariants("loop", &b, &mesh, &pts);
}

#[test]
fn torsion_is_blended_by_arc_length() {
    // A straight curve along x from intersection A = (0,0,0) to B = (2,0,0);
    // both carry two arms along ±y. Posing B's arms rotated by φ about the x
    // axis twists the curve's normals from 0 at A to φ at B.
    let (mesh, pts) = plane(3.0, 12);
    let mut b = NetBuilder::default();
    b.segment([0.0; 3], [2.0, 0.0, 0.0], [0.0; 3]);
    for x in [0.0, 2.0] {
        b.segment([x, 0.0, 0.0], [x, 1.0, 0.0], [0.0; 3]);
        b.segment([x, 0.0, 0.0], [x, -1.0, 0.0], [0.0; 3]);
        b.segment([x, 0.0, 0.0], [x + if x == 0.0 { -1.0 } else { 1.0 }, 0.0, 0.0], [0.0; 3]);
    }
    let layout = layout_of(&b, &mesh, &pts);
    let phi = 0.8;
    let r = rotation([1.0, 0.0, 0.0], phi);
    let pose: Vec<[f64; 3]> = b
        .points
        .iter()
        .map(|&p| {
            if p[0] >= 2.0 {
                let q = apply(&r, sub(p, [2.0, 0.0, 0.0]));
                [q[0] + 2.0, q[1], q[2]]
            } else {
                p
            }
        })
        .collect();
    let frames = scaled_frames(&layout, &layout.sampling().samples(&pose).unwrap()).unwrap();
    let segs = layout.sampling().curve_segments(0);
    let k = segs.len();
    assert!(k > 3);
    let total: f64 = segs.clone().map(|s| frames[s][0].scale[0]).sum();
    let mut arc = 0.0;
    for s in segs {
        let alpha = arc / total;
        let expected = apply(&rotation([1.0, 0.0, 0.0], alpha * phi), [0.0, 0.0, 1.0]);
        for f in &frames[s] {
            assert!(norm(sub(f.normal, expected)) < 1e-12, "segment {s}: {:?}", f.normal);
        }
        arc += frames[s][0].scale[0];
    }
}

#[test]
fn constraint_slots_average_interior_and_copy_endpoints() {
    use curvenet_core::curvenet::constraint_gradients;
    let (mesh, pts) = plane(3.0, 12);
    let b = grid(0.05);
    let layout = layout_of(&b, &mesh, &pts);
    let (pose, _) = bend(&b.points);
    let f = gradients_for_pose(&layout, &pose);
    let fc = constraint_gradients(layout.constraints(), &f).unwrap();
    for (slot, m) in layout.constraints().slots().iter().zip(&fc) {
        let side = slot.side as usize;
        let expected = match (slot.incoming, slot.outgoing) {
            (Some(a), Some(c)) => std::array::from_fn(|r| {
                std::array::from_fn(|q| 0.5 * (f[a as usize][side][r][q] + f[c as usize][side][r][q]))
            }),
            (Some(a), None) | (None, Some(a)) => f[a as usize][side],
            (None, None) => unreachable!(),
        };
        assert_eq!(*m, expected);
        // The slot's segments touch its sample.
        for s in [slot.incoming, slot.outgoing].into_iter().flatten() {
            assert!(layout.sampling().segments()[s as usize].samples.contains(&slot.sample));
        }
    }
}
