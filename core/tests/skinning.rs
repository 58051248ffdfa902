//! Mesh skinning (linear blend, dual quaternions) and spline skinning
//! (Liu et al. 2015) on the hand mesh and hand-built curvenets: identity and
//! rigid transforms are reproduced exactly, dual quaternions keep volume
//! where linear blending collapses it, and the spline fit keeps its
//! constraints and beats naive control-point skinning.
//! (The comparisons with usd-core's own skinning are in tests/skinning_usd.rs.)

mod common;

use common::{MESH_DIR, NetBuilder, cylinder_net, load_obj};
use curvenet_core::skinning::{
    self, ControlPointWeights, Influences, JunctionKind, Mat4, SkinningMethod, SplineSkinning, SplineSkinningOptions,
};
use glam::{DMat3, DVec3};

/// The skinning transform "rotate by `deg` about `axis` through `pivot`,
/// then translate by `t`", in the row-vector convention.
fn rotate_about(axis: [f64; 3], deg: f64, pivot: [f64; 3], t: [f64; 3]) -> Mat4 {
    let r = DMat3::from_axis_angle(DVec3::from_array(axis).normalize(), deg.to_radians());
    let p = DVec3::from_array(pivot);
    let shift = p - r * p + DVec3::from_array(t);
    let c = r.to_cols_array(); // columns of R = rows of the row-vector matrix
    [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, shift.x, shift.y, shift.z, 1.0]
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

fn max_dist(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (DVec3::from_array(*p) - DVec3::from_array(*q)).length()).fold(0.0, f64::max)
}

fn diagonal(p: &[[f64; 3]]) -> f64 {
    curvenet_core::mesh::bounding_box_diagonal(p)
}

/// Three joints along the hand's height: the wrist, the palm, the fingers
/// (float weights as a USD file holds them, renormalised).
fn hand_influences(points: &[[f64; 3]]) -> Influences {
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for p in points {
        let a = smoothstep((p[1] - 0.25) / 0.2);
        let b = smoothstep((p[1] - 0.55) / 0.15);
        for (j, x) in [(0, 1.0 - a), (1, a - b), (2, b)] {
            idx.push(j);
            w.push(x as f32 as f64);
        }
    }
    let mut inf = Influences::new(points.len(), 3, &idx, &w, 3).unwrap();
    let left = inf.renormalize(1e-4);
    assert!(left.is_empty(), "float weights sum to 1 within 1e-4: {left:?}");
    inf
}

#[test]
fn identity_and_single_joint_transforms_reproduce_the_hand_exactly() {
    let (_, points) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let diag = diagonal(&points);
    let inf = hand_influences(&points);
    let rigid = rotate_about([0.3, 1.0, -0.2], 75.0, [0.1, 0.4, 0.0], [0.2, -0.1, 0.5]);
    let mut one_joint = Influences::new(points.len(), 1, &vec![1; points.len()], &vec![1.0; points.len()], 3).unwrap();
    assert!(one_joint.renormalize(0.0).is_empty());
    for method in [SkinningMethod::ClassicLinear, SkinningMethod::DualQuaternion] {
        let mut out = vec![[0.0; 3]; points.len()];
        skinning::skin_points(method, &points, &inf, &skinning::IDENTITY, &[skinning::IDENTITY; 3], &mut out).unwrap();
        let err = max_dist(&out, &points);
        // Rigid: joint 1 carries every vertex; the other joints move elsewhere.
        let others = rotate_about([1.0, 0.0, 0.0], 40.0, [0.0; 3], [1.0, 2.0, 3.0]);
        let mut moved = vec![[0.0; 3]; points.len()];
        skinning::skin_points(method, &points, &one_joint, &skinning::IDENTITY, &[others, rigid, others], &mut moved)
            .unwrap();
        let want: Vec<[f64; 3]> = points.iter().map(|p| skinning::transform_point(&rigid, *p)).collect();
        let rigid_err = max_dist(&moved, &want);
        eprintln!(
            "{}: identity transforms reproduce the hand to {:.1e} x diagonal, one joint moves it rigidly to {:.1e}",
            method.token(),
            err / diag,
            rigid_err / diag
        );
        assert!(err <= 1e-15 * diag, "{method:?} identity: {err:e}");
        assert!(rigid_err <= 1e-14 * diag, "{method:?} rigid: {rigid_err:e}");
    }
}

#[test]
fn dual_quaternions_equal_linear_blending_where_weights_are_zero_or_one() {
    let (_, points) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let n = points.len();
    // Each vertex follows one of three joints entirely (the others at weight 0).
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for p in &points {
        let j = if p[1] < 0.3 {
            0
        } else if p[1] < 0.6 {
            1
        } else {
            2
        };
        idx.extend([j, (j + 1) % 3]);
        w.extend([1.0, 0.0]);
    }
    let inf = Influences::new(n, 2, &idx, &w, 3).unwrap();
    let xf = [
        rotate_about([0.0, 0.0, 1.0], 15.0, [0.0, 0.08, 0.0], [0.0; 3]),
        rotate_about([1.0, 0.0, 0.0], 50.0, [0.0, 0.3, 0.0], [0.01, 0.0, 0.0]),
        rotate_about([1.0, 0.2, 0.0], -80.0, [0.0, 0.6, 0.05], [0.0, 0.1, 0.0]),
    ];
    let (mut lbs, mut dqs) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    skinning::skin_points_lbs(&points, &inf, &skinning::IDENTITY, &xf, &mut lbs).unwrap();
    skinning::skin_points_dqs(&points, &inf, &skinning::IDENTITY, &xf, &mut dqs).unwrap();
    let err = max_dist(&lbs, &dqs);
    eprintln!("weights 0/1: dual quaternions = linear blending to {:.1e} x diagonal", err / diagonal(&points));
    assert!(err <= 1e-14 * diagonal(&points), "{err:e}");
    assert!(max_dist(&lbs, &points) > 0.1 * diagonal(&points), "the transforms should move the hand");
}

/// A closed cylinder along z (radius 0.3, z ∈ [0, 2]) with fan caps.
fn closed_cylinder(around: usize, up: usize) -> (Vec<u32>, Vec<u32>, Vec<[f64; 3]>) {
    let (mesh, mut points) = common::cylinder(0.3, 0.0, 2.0, around, up);
    let mut counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let mut idx = mesh.face_vertex_indices().to_vec();
    let bottom = points.len() as u32;
    points.push([0.0, 0.0, 0.0]);
    let top = points.len() as u32;
    points.push([0.0, 0.0, 2.0]);
    for i in 0..around as u32 {
        let j = (i + 1) % around as u32;
        // Outward: the bottom cap faces -z, the top +z.
        idx.extend([bottom, j, i]);
        let (a, b) = (up as u32 * around as u32 + i, up as u32 * around as u32 + j);
        idx.extend([top, a, b]);
        counts.extend([3, 3]);
    }
    (counts, idx, points)
}

fn volume(counts: &[u32], idx: &[u32], p: &[[f64; 3]]) -> f64 {
    let mut at = 0;
    let mut v = 0.0;
    for &c in counts {
        let f = &idx[at..at + c as usize];
        let a = DVec3::from_array(p[f[0] as usize]);
        for k in 1..f.len() - 1 {
            let (b, cc) = (DVec3::from_array(p[f[k] as usize]), DVec3::from_array(p[f[k + 1] as usize]));
            v += a.dot(b.cross(cc)) / 6.0;
        }
        at += c as usize;
    }
    v
}

#[test]
fn dual_quaternions_keep_volume_where_linear_blending_collapses_a_twist() {
    let (counts, idx, points) = closed_cylinder(48, 40);
    let rest = volume(&counts, &idx, &points);
    assert!((rest - std::f64::consts::PI * 0.09 * 2.0).abs() < 0.01 * rest, "rest volume {rest}");
    // Joint 0 holds the bottom, joint 1 the top; the blend spans the middle.
    let mut ji = Vec::new();
    let mut jw = Vec::new();
    for p in &points {
        let b = smoothstep((p[2] - 0.5) / 1.0);
        ji.extend([0, 1]);
        jw.extend([1.0 - b, b]);
    }
    let inf = Influences::new(points.len(), 2, &ji, &jw, 2).unwrap();
    let twist = [skinning::IDENTITY, rotate_about([0.0, 0.0, 1.0], 90.0, [0.0; 3], [0.0; 3])];
    let mut ratios = Vec::new();
    for method in [SkinningMethod::ClassicLinear, SkinningMethod::DualQuaternion] {
        let mut out = vec![[0.0; 3]; points.len()];
        skinning::skin_points(method, &points, &inf, &skinning::IDENTITY, &twist, &mut out).unwrap();
        ratios.push(volume(&counts, &idx, &out) / rest);
    }
    eprintln!(
        "cylinder twisted 90 degrees: volume / rest volume = {:.4} (linear blend), {:.4} (dual quaternions)",
        ratios[0], ratios[1]
    );
    assert!(ratios[1] > ratios[0] + 0.02, "dual quaternions should keep more volume: {ratios:?}");
    assert!((ratios[1] - 1.0).abs() < 0.01, "a pure twist keeps the volume under dual quaternions: {ratios:?}");
}

/// `cylinder_net` (rings at z = 0, 1, 2, 3 crossed by four lines, an arc)
/// with control-point weights: joint 0 below, joint 1 above, blended over z ∈ [0.5, 1.5].
fn cylinder_rig() -> (NetBuilder, ControlPointWeights) {
    let net = cylinder_net();
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for p in &net.points {
        let b = smoothstep(p[2] - 0.5);
        idx.extend([0, 1]);
        w.extend([1.0 - b, b]);
    }
    (net.clone(), ControlPointWeights::new(Influences::new(net.points.len(), 2, &idx, &w, 2).unwrap()))
}

fn bend(deg: f64) -> [Mat4; 2] {
    [skinning::IDENTITY, rotate_about([1.0, 0.0, 0.0], deg, [0.0, 0.0, 1.0], [0.0; 3])]
}

#[test]
fn spline_skinning_detects_the_junctions_of_the_cylinder_net() {
    let (net, weights) = cylinder_rig();
    let sk =
        SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &Default::default()).unwrap();
    let count = |f: fn(&JunctionKind) -> bool| sk.junctions().iter().filter(|j| f(&j.kind)).count();
    let (c1, g1, angle) = (
        count(|k| *k == JunctionKind::C1),
        count(|k| *k == JunctionKind::G1),
        count(|k| matches!(k, JunctionKind::Angle(_))),
    );
    eprintln!("cylinder net: {c1} C1, {g1} G1, {angle} angle junctions");
    // 12 crossings (rings z = 0, 1, 2 x 4 lines): the ring passes through C1
    // (equal quarter-circle handles), the line G1 at z = 0 and 2 (segments of
    // lengths 0.5 and 1 meet) and C1 at z = 1, and one right angle between
    // them; the isolated ring at z = 3 has 4 C1 knots; the arc has none.
    assert_eq!((c1, g1, angle), (12 + 4 + 4, 8, 12));
    for j in sk.junctions() {
        if let JunctionKind::Angle(a) = j.kind {
            assert!((a - std::f64::consts::FRAC_PI_2).abs() < 1e-9, "{j:?}");
        }
    }
}

#[test]
fn spline_skinning_reproduces_identity_and_rigid_transforms_exactly() {
    let (net, weights) = cylinder_rig();
    let diag = diagonal(&net.points);
    let sk =
        SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &Default::default()).unwrap();
    let mut out = vec![[0.0; 3]; net.points.len()];
    sk.pose(&[skinning::IDENTITY; 2], &mut out).unwrap();
    let identity_err = max_dist(&out, &net.points);
    let rigid = rotate_about([0.2, -1.0, 0.5], 120.0, [0.3, 0.0, 1.0], [1.0, -2.0, 0.5]);
    sk.pose(&[rigid; 2], &mut out).unwrap();
    let want: Vec<[f64; 3]> = net.points.iter().map(|p| skinning::transform_point(&rigid, *p)).collect();
    let rigid_err = max_dist(&out, &want);
    eprintln!(
        "spline skinning: identity reproduces the net to {:.1e} x diagonal, a rigid transform to {:.1e}",
        identity_err / diag,
        rigid_err / diag
    );
    assert!(identity_err <= 1e-12 * diag, "{identity_err:e}");
    assert!(rigid_err <= 1e-12 * diag, "{rigid_err:e}");
}

#[test]
fn spline_skinning_keeps_its_constraints_and_beats_naive_skinning_through_a_bend() {
    let (net, weights) = cylinder_rig();
    let diag = diagonal(&net.points);
    let sk =
        SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &Default::default()).unwrap();
    for deg in [30.0, 60.0, 90.0] {
        let xf = bend(deg);
        let mut fit = vec![[0.0; 3]; net.points.len()];
        let mut naive = fit.clone();
        sk.pose(&xf, &mut fit).unwrap();
        sk.pose_naive(&xf, &mut naive).unwrap();
        // The constraints, measured on the geometry: tangents at each junction.
        let mut worst = [0.0f64; 3];
        for j in sk.junctions() {
            let k = DVec3::from_array(fit[j.knot as usize]);
            let ua = DVec3::from_array(fit[j.ends[0].handle as usize]) - k;
            let ub = DVec3::from_array(fit[j.ends[1].handle as usize]) - k;
            match j.kind {
                // Exact junctions in the neutral net: u_a = -ratio u_b.
                JunctionKind::C1 | JunctionKind::G1 => {
                    let slot = usize::from(j.kind == JunctionKind::G1);
                    worst[slot] = worst[slot].max((ua + j.ratio * ub).length());
                }
                JunctionKind::Angle(a) => worst[2] = worst[2].max((ua.angle_between(ub) - a).abs()),
            }
        }
        let residual = sk.junction_residuals(&fit, &xf).unwrap().into_iter().fold(0.0, f64::max);
        let (ours, theirs) = (sk.distance_to_skinned(&fit, &xf).unwrap(), sk.distance_to_skinned(&naive, &xf).unwrap());
        eprintln!(
            "bend {deg} deg: C1 {:.1e}, G1 {:.1e} (x diagonal), angle {:.1e} rad, residual {:.1e}; \
             integrated distance to the skinned curves: ours {:.3e}, naive {:.3e} (x diagonal; max {:.3e} vs {:.3e})",
            worst[0] / diag,
            worst[1] / diag,
            worst[2],
            residual / diag,
            ours.mean / diag,
            theirs.mean / diag,
            ours.max / diag,
            theirs.max / diag
        );
        assert!(worst[0] <= 1e-9 * diag && worst[1] <= 1e-9 * diag && worst[2] <= 1e-9, "{worst:?}");
        assert!(residual <= 1e-9 * diag, "{residual:e}");
        assert!(ours.mean < theirs.mean, "ours {ours:?} naive {theirs:?}");
    }
}

#[test]
fn flexible_tangent_ratios_lower_the_energy_monotonically() {
    let (net, weights) = cylinder_rig();
    let sk =
        SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &Default::default()).unwrap();
    let xf = bend(75.0);
    let mut fixed = vec![[0.0; 3]; net.points.len()];
    sk.pose(&xf, &mut fixed).unwrap();
    let mut flex = fixed.clone();
    let report = sk.pose_flexible(&xf, 20, &mut flex).unwrap();
    let e = &report.energies;
    eprintln!(
        "flexible G1: {} iterations, energy {:.4e} -> {:.4e} ({} clamped)",
        report.iterations,
        e[0],
        e[e.len() - 1],
        report.clamped
    );
    assert!(report.iterations >= 2);
    assert_eq!(report.clamped, 0);
    assert!((e[0] - sk.energy(&fixed, &xf).unwrap()).abs() <= 1e-12 * e[0]);
    for w in e.windows(2) {
        assert!(w[1] <= w[0] * (1.0 + 1e-9), "the energy rose: {e:?}");
    }
    assert!(e[e.len() - 1] < e[0], "flexibility should lower the energy: {e:?}");
    // Still G1 and still the right angles.
    for j in sk.junctions() {
        let k = DVec3::from_array(flex[j.knot as usize]);
        let ua = DVec3::from_array(flex[j.ends[0].handle as usize]) - k;
        let ub = DVec3::from_array(flex[j.ends[1].handle as usize]) - k;
        match j.kind {
            JunctionKind::Angle(a) => assert!((ua.angle_between(ub) - a).abs() < 1e-8, "{j:?}"),
            _ => assert!(ua.normalize().cross(ub.normalize()).length() < 1e-8 && ua.dot(ub) < 0.0, "{j:?}"),
        }
    }
}

#[test]
fn spline_skinning_refuses_bad_input_naming_it() {
    let (net, weights) = cylinder_rig();
    let sk =
        SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &Default::default()).unwrap();
    let mut out = vec![[0.0; 3]; net.points.len()];
    let err = sk.pose(&[skinning::IDENTITY; 3], &mut out).unwrap_err();
    assert!(err.to_string().contains("expected 2 joints, got 3"), "{err}");
    let mut bad = [skinning::IDENTITY; 2];
    bad[1][13] = f64::NAN;
    let err = sk.pose(&bad, &mut out).unwrap_err();
    assert!(err.to_string().contains("joint 1"), "{err}");
    // A control point nobody weighs.
    let n = net.points.len();
    let mut w = vec![1.0; n];
    w[7] = 0.0;
    let inf = ControlPointWeights::new(Influences::new(n, 1, &vec![0; n], &w, 1).unwrap());
    let err =
        SplineSkinning::new(&net.points, &net.splines, &inf, &skinning::IDENTITY, &SplineSkinningOptions::default())
            .unwrap_err();
    assert!(err.to_string().contains("7 has no joint weight"), "{err}");
}

#[test]
fn angle_constraints_cost_little_energy_and_still_beat_naive_skinning() {
    let (net, weights) = cylinder_rig();
    let xf = bend(60.0);
    let mut energies = Vec::new();
    for angles in [true, false] {
        let options = SplineSkinningOptions::default().with_angle_constraints(angles);
        let sk = SplineSkinning::new(&net.points, &net.splines, &weights, &skinning::IDENTITY, &options).unwrap();
        let mut fit = vec![[0.0; 3]; net.points.len()];
        let mut naive = fit.clone();
        sk.pose(&xf, &mut fit).unwrap();
        sk.pose_naive(&xf, &mut naive).unwrap();
        energies.push((sk.energy(&fit, &xf).unwrap(), sk.energy(&naive, &xf).unwrap()));
    }
    let [(with, naive), (without, _)] = [energies[0], energies[1]];
    eprintln!(
        "bend 60 deg, fitting energy: naive {naive:.4e}, spline skinning {with:.4e} with the right angles kept, \
         {without:.4e} without them"
    );
    // More constraints can only raise the minimum; the angles keep it far below naive skinning's.
    assert!(without <= with * (1.0 + 1e-12) && with < 0.1 * naive, "{energies:?}");
}

#[test]
fn weights_derived_from_a_surface_reproduce_weights_linear_along_the_curves() {
    use curvenet_core::closest_point::ClosestPointBvh;
    use curvenet_core::skinning::{DERIVED_WEIGHT_SAMPLES, SurfaceWeights, WeightField};
    // A plane whose skin weights are linear in x (exact under barycentric
    // interpolation), and straight curves on it: along each curve the
    // weights are linear in t, which the Bernstein basis represents exactly.
    let (mesh, points) = common::plane(1.0, 8);
    let ramp = |x: f64| (x + 1.0) / 2.0;
    let mut idx = Vec::new();
    let mut w = Vec::new();
    for p in &points {
        idx.extend([0, 1]);
        w.extend([1.0 - ramp(p[0]), ramp(p[0])]);
    }
    let inf = Influences::new(points.len(), 2, &idx, &w, 2).unwrap();
    let bvh = ClosestPointBvh::new(&mesh, &points).unwrap();
    let surface = SurfaceWeights::new(&bvh, &inf).unwrap();
    let mut net = NetBuilder::default();
    net.segment([-0.8, -0.5, 0.0], [0.1, 0.2, 0.0], [0.0; 3]);
    net.segment([0.1, 0.2, 0.0], [0.7, 0.6, 0.0], [0.0; 3]);
    net.segment([0.1, 0.2, 0.0], [0.2, -0.7, 0.0], [0.0; 3]);
    let (derived, deviation) =
        ControlPointWeights::from_surface(&net.points, &net.splines, &surface, DERIVED_WEIGHT_SAMPLES).unwrap();
    let mut out = Vec::new();
    let mut worst = 0.0f64;
    for (k, p) in net.points.iter().enumerate() {
        derived.at_control_point(k, *p, &mut out).unwrap();
        let w1 = out.iter().find(|x| x.0 == 1).map_or(0.0, |x| x.1);
        worst = worst.max((w1 - ramp(p[0])).abs());
    }
    eprintln!("derived weights: {deviation:.1e} from the surface's at the samples, {worst:.1e} at the control points");
    assert!(deviation < 1e-12 && worst < 1e-12, "{deviation:e} {worst:e}");
}
