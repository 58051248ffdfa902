//! Separate projection and rest poses (paper §5, Elemental §3): a binding
//! built once in the projection pose deforms frames whose rest pose is
//! anything of the same topology (skinning, cloth), with knot tracking.

use curvenet_core::Frame;
use curvenet_e2e::{Bound, bind_fixture, max_distance};

fn solve(b: &Bound, posed: &[Option<&[[f64; 3]]>], rest: Option<&[[f64; 3]]>) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; b.deformer.n_vertices()];
    b.deformer.frame(&Frame { posed, rest, ..Default::default() }, &mut out, None).unwrap();
    out
}

fn rotate_y(p: [f64; 3], angle: f64, pivot: [f64; 3]) -> [f64; 3] {
    let (c, s) = (angle.cos(), angle.sin());
    let (x, z) = (p[0] - pivot[0], p[2] - pivot[2]);
    [pivot[0] + c * x + s * z, p[1], pivot[2] - s * x + c * z]
}

fn rigid(p: [f64; 3]) -> [f64; 3] {
    let q = rotate_y(p, 0.6, [0.0, 0.4, 0.0]);
    [q[0] + 0.2, q[1] - 0.1, q[2] + 0.3]
}

/// A smooth non-rigid deformation of the hand: the upper part (fingers,
/// y > 0.5) bends about the x axis with a weight ramping over y ∈ [0.5, 0.9].
fn bend(p: [f64; 3]) -> [f64; 3] {
    let w = ((p[1] - 0.5) / 0.4).clamp(0.0, 1.0);
    let w = w * w * (3.0 - 2.0 * w);
    let a = 0.5 * w;
    let (c, s) = (a.cos(), a.sin());
    let (y, z) = (p[1] - 0.5, p[2]);
    [p[0], 0.5 + c * y - s * z, s * y + c * z]
}

/// The pool `tracked` with the wrist ring (the hand curvenet's isolated
/// closed curve, fixtures/README.md) scaled by `factor` about its centre.
fn widen_wrist_ring(b: &Bound, tracked: &[[f64; 3]], factor: f64) -> Vec<[f64; 3]> {
    let topo = b.layouts()[0].topology();
    let ring = topo.isolated_closed_curves().next().expect("the hand curvenet has a wrist ring");
    let mut points: Vec<u32> =
        topo.curves()[ring].splines.iter().flat_map(|cs| b.nets[0].splines[cs.spline as usize]).collect();
    points.sort();
    points.dedup();
    let centre: [f64; 3] =
        std::array::from_fn(|i| points.iter().map(|&p| tracked[p as usize][i]).sum::<f64>() / points.len() as f64);
    let mut posed = tracked.to_vec();
    for &p in &points {
        posed[p as usize] = std::array::from_fn(|i| centre[i] + factor * (tracked[p as usize][i] - centre[i]));
    }
    posed
}

#[test]
fn rest_equal_to_projection_reproduces_the_single_pose_solve() {
    let b = bind_fixture("shots/hand_wave/shot.usda");
    let pool = b.stage.posed_pool(&b.nets[0], Some(13.0)).unwrap().unwrap();
    let single = solve(&b, &[Some(&pool)], None);
    let layered = solve(&b, &[Some(&pool)], Some(&b.mesh.projection_points));
    let err = max_distance(&single, &layered);
    eprintln!("rest = projection: {:.2e} x diagonal from the single-pose solve", err / b.diagonal());
    assert!(err <= 1e-12 * b.diagonal(), "{err:e}");
}

#[test]
fn unarticulated_curvenets_follow_rigid_and_bent_rest_poses_exactly() {
    let b = bind_fixture("hand/hand_1k4.usda");
    for (name, f) in [("rigid", rigid as fn([f64; 3]) -> [f64; 3]), ("bent", bend)] {
        let rest: Vec<[f64; 3]> = b.mesh.projection_points.iter().map(|p| f(*p)).collect();
        let moved = max_distance(&rest, &b.mesh.projection_points);
        let out = solve(&b, &[None], Some(&rest));
        let err = max_distance(&out, &rest);
        eprintln!(
            "{name} rest pose (moves up to {:.3} x diagonal): output = rest to {:.2e} x diagonal",
            moved / b.diagonal(),
            err / b.diagonal()
        );
        assert!(moved > 0.05 * b.diagonal(), "the {name} rest pose should move the hand");
        assert!(err <= 1e-9 * b.diagonal(), "{name}: output differs from the rest pose by {err:e}");
    }
}

#[test]
fn an_articulated_ring_changes_only_the_surface_it_bounds() {
    let b = bind_fixture("hand/hand_1k4.usda");
    let rest: Vec<[f64; 3]> = b.mesh.projection_points.iter().map(|p| rigid(*p)).collect();
    let mut tracked = vec![[0.0; 3]; b.nets[0].pool.len()];
    b.binding().tracked_pool_into(0, &rest, &mut tracked).unwrap();
    let posed = widen_wrist_ring(&b, &tracked, 1.15);
    let out = solve(&b, &[Some(&posed)], Some(&rest));
    let unposed = solve(&b, &[Some(&tracked)], Some(&rest));
    assert!(max_distance(&unposed, &rest) <= 1e-9 * b.diagonal());
    // Displacement against the rest-pose height (y before the rigid motion).
    let diag = b.diagonal();
    let mut near = 0.0f64;
    let mut beyond_palm = 0.0f64;
    for (v, p) in b.mesh.projection_points.iter().enumerate() {
        let d = max_distance(&out[v..v + 1], &rest[v..v + 1]);
        if p[1] < 0.2 {
            near = near.max(d);
        }
        if p[1] > 0.34 {
            beyond_palm = beyond_palm.max(d);
        }
    }
    eprintln!(
        "wrist ring scaled by 1.15: max displacement below y = 0.2 is {:.3e}, beyond the palm ring (y > 0.34) {:.3e} (x diagonal)",
        near / diag,
        beyond_palm / diag
    );
    assert!(near > 2e-3 * diag, "the articulated ring should move the wrist ({near:e})");
    // The palm ring (y = 0.30) is a closed constrained curve around the hand:
    // nothing beyond it can move.
    assert!(beyond_palm <= 1e-9 * diag, "the change leaks past the palm ring: {beyond_palm:e}");
}

#[test]
fn over_a_skinned_rest_pose_an_articulated_wrist_ring_changes_only_its_sides() {
    // hand_skinned: the rest pose at frame 12 is linear blend skinning (index
    // finger bent 115 degrees, wrist turned 15); the projection pose is the
    // neutral hand. The wrist ring (the isolated closed curve) is widened by
    // 15% about its centre in the tracked (rest) pose.
    let b = bind_fixture("shots/hand_skinned/shot.usda");
    let rest = b.stage.rest_points(&b.mesh, Some(12.0)).unwrap();
    let diag = b.diagonal();
    assert!(max_distance(&rest, &b.mesh.projection_points) > 0.2 * diag, "the skinned rest pose should move the hand");
    let mut tracked = vec![[0.0; 3]; b.nets[0].pool.len()];
    b.binding().tracked_pool_into(0, &rest, &mut tracked).unwrap();
    let unposed = solve(&b, &[None], Some(&rest));
    let err = max_distance(&unposed, &rest);
    assert!(err <= 1e-9 * diag, "not articulated: output differs from the skinned rest pose by {err:e}");

    let posed = widen_wrist_ring(&b, &tracked, 1.15);
    let out = solve(&b, &[Some(&posed)], Some(&rest));
    // Falloff by height in the neutral hand: the wrist ring sits at y = 0.08,
    // the palm ring (the next constrained curve towards the fingers) at y = 0.30.
    let bands = [(0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.34), (0.34, f64::INFINITY)];
    let mut largest = [0.0f64; 5];
    for (v, p) in b.mesh.projection_points.iter().enumerate() {
        let d = max_distance(&out[v..v + 1], &rest[v..v + 1]);
        let k = bands.iter().position(|&(lo, hi)| p[1] >= lo && p[1] < hi).unwrap_or(0);
        largest[k] = largest[k].max(d);
    }
    let table: Vec<String> =
        bands.iter().zip(&largest).map(|((lo, hi), d)| format!("y in [{lo}, {hi}): {:.2e}", d / diag)).collect();
    eprintln!("skinned rest, wrist ring widened 15%: largest displacement (x diagonal) {}", table.join("; "));
    assert!(largest[0] > 5e-3 * diag, "the widened ring should move the wrist ({:e})", largest[0]);
    // Falling off away from the ring, and nothing past the palm ring.
    assert!(largest[2] < largest[0], "no falloff towards the palm: {table:?}");
    assert!(largest[4] <= 1e-9 * diag, "the change leaks past the palm ring: {:e}", largest[4]);
}

/// A rig's global scale: the rest pose and the posed curvenet both scaled
/// by `s` give the frame scaled by `s`. Knot
/// tracking keeps each knot's offset from its triangle in units of the
/// triangle's size, so the tracked curvenet scales with the rest pose (a
/// hostile review found offsets kept in absolute units: 1e-3 of the
/// diagonal wrong at s = 1.1, and a rest pose scaled by 1e-20 came back at
/// the projection pose's size).
#[test]
fn a_scaled_rest_pose_and_curvenet_give_the_scaled_frame() {
    let b = bind_fixture("shots/hand_wave/shot.usda");
    let pool = b.stage.posed_pool(&b.nets[0], Some(13.0)).unwrap().unwrap();
    let base = solve(&b, &[Some(&pool)], Some(&b.mesh.projection_points));
    let pts = &b.mesh.projection_points;
    // About the origin: scaled about a point away from it, small poses
    // would carry that point's rounding (5e-17 at 0.4 is 5e-11 of a hand
    // scaled by 1e-6) into every coordinate.
    let scale = |p: &[f64; 3], s: f64| -> [f64; 3] { p.map(|x| s * x) };
    for s in [1.1, 0.5, 2.5, 1e4, 1e-6, 1e-20] {
        let rest: Vec<[f64; 3]> = pts.iter().map(|p| scale(p, s)).collect();
        let posed: Vec<[f64; 3]> = pool.iter().map(|p| scale(p, s)).collect();
        let mut out = vec![[0.0; 3]; b.deformer.n_vertices()];
        let frame = Frame { posed: &[Some(&posed)], rest: Some(&rest), ..Default::default() };
        match b.deformer.frame(&frame, &mut out, None) {
            Ok(()) => {
                let want: Vec<[f64; 3]> = base.iter().map(|p| scale(p, s)).collect();
                let err = max_distance(&out, &want) / (s * b.diagonal());
                eprintln!(
                    "rest pose and curvenet scaled by {s:e}: {err:.2e} x the scaled diagonal from the scaled frame"
                );
                assert!(err <= 1e-9, "scale {s:e}: {err:e} of the scaled diagonal");
            }
            // Far below the bound curvenet's size a segment is refused as
            // collapsed (its threshold is relative to the binding): an error,
            // never a mesh of the wrong size.
            Err(e) => {
                eprintln!("rest pose and curvenet scaled by {s:e}: {e}");
                assert!(s < 1e-9, "scale {s:e}: {e}");
                // The curvenet tracked onto the rest pose is the one refused.
                let tracked = match &e {
                    curvenet_core::Error::Curvenet { source, .. } => match source.as_ref() {
                        curvenet_core::Error::RestPose { source } => Some(source.as_ref()),
                        _ => None,
                    },
                    _ => None,
                };
                assert!(matches!(tracked, Some(curvenet_core::Error::SegmentCollapsed { .. })), "scale {s:e}: {e:?}");
            }
        }
    }
}
