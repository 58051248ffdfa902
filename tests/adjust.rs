//! The Curvenet Adjuster (Elemental 2023) on the hand fixtures: knot
//! orientations that follow the surface, and adjustments in them.

use curvenet_core::ClosestPointBvh;
use curvenet_core::fit_rotation;
use curvenet_core::{Adjustment, Error, Frame, Mat3, Rotate};
use curvenet_e2e::{Bound, bind_fixture, max_distance};
use glam::{DMat3, DVec3};

type Pool = Vec<[f64; 3]>;

/// One frame: points and per-vertex gradients.
fn solve(
    b: &Bound,
    posed: Option<&[[f64; 3]]>,
    rest: Option<&[[f64; 3]]>,
    adj: &[Adjustment],
) -> (Pool, Vec<[f64; 9]>) {
    let n = b.deformer.n_vertices();
    let (mut out, mut grads) = (vec![[0.0; 3]; n], vec![[0.0; 9]; n]);
    let input = Frame { posed: &[posed], rest, adjustments: adj, ..Default::default() };
    b.deformer.frame(&input, &mut out, Some(&mut grads)).unwrap_or_else(|e| panic!("{e}"));
    (out, grads)
}

fn m(a: &Mat3) -> DMat3 {
    DMat3::from_cols_array_2d(a).transpose()
}

fn v(p: [f64; 3]) -> DVec3 {
    DVec3::from_array(p)
}

/// The angle of the rotation `aᵀ b` (radians).
fn angle_between(a: DMat3, b: DMat3) -> f64 {
    let r = a.transpose() * b;
    ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0).acos()
}

fn max_entry(a: DMat3) -> f64 {
    a.to_cols_array().iter().fold(0.0f64, |x, y| x.max(y.abs()))
}

fn bits(p: &[[f64; 3]]) -> Vec<u64> {
    p.iter().flatten().map(|x| x.to_bits()).collect()
}

/// An identity adjustment of every knot of curvenet 0, in several spellings
/// (tangent translates of zeros, a unit quaternion, free tangents).
fn identity_adjustments(b: &Bound) -> Vec<Adjustment> {
    let sampling = b.layouts()[0].sampling();
    let plan = b.binding().orientation_plan(0);
    (0..sampling.n_knots())
        .map(|k| {
            let a = Adjustment::new(0, sampling.knot_point(k));
            match k % 3 {
                0 => a.with_tangent_translates(vec![[0.0; 3]; plan.knot_tangents(k).len()]),
                1 => a.with_rotate(Rotate::Quaternion([1.0, 0.0, 0.0, 0.0])).with_attach_tangents(false),
                _ => a.with_translate([-0.0, 0.0, -0.0]),
            }
        })
        .collect()
}

#[test]
fn zero_adjustments_reproduce_the_unadjusted_frame_bit_for_bit() {
    let cases: [(&str, Option<f64>, Option<f64>); 3] = [
        ("shots/hand_wave/shot.usda", Some(13.0), None),    // articulated pool
        ("shots/hand_skinned/shot.usda", None, Some(12.0)), // knot tracking to a skinned rest pose
        ("hand/hand_1k4.usda", None, None),                 // the neutral pool
    ];
    for (rel, posed_at, rest_at) in cases {
        let b = bind_fixture(rel);
        let posed = posed_at.map(|t| b.stage.posed_pool(&b.nets[0], Some(t)).unwrap().unwrap());
        let rest = rest_at.map(|t| b.stage.rest_points(&b.mesh, Some(t)).unwrap());
        let identity = identity_adjustments(&b);
        assert_eq!(identity.len(), 75, "{rel}: the hand curvenet has 75 knots");
        let (plain, plain_g) = solve(&b, posed.as_deref(), rest.as_deref(), &[]);
        let (zero, zero_g) = solve(&b, posed.as_deref(), rest.as_deref(), &identity);
        assert_eq!(bits(&plain), bits(&zero), "{rel}: identity adjustments changed the points");
        let gbits = |g: &[[f64; 9]]| g.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(gbits(&plain_g), gbits(&zero_g), "{rel}: identity adjustments changed the gradients");
        // The adjusted path is live: a small translate of one knot moves the mesh.
        let nudged = [Adjustment::new(0, identity[7].knot).with_translate([0.0, 0.0, 1e-3])];
        let (moved, _) = solve(&b, posed.as_deref(), rest.as_deref(), &nudged);
        let d = max_distance(&moved, &plain);
        eprintln!(
            "{rel}: 75 identity adjustments bit-identical; a 1e-3 nudge moves the mesh by {d:.2e}; frame {:.2} ms, \
             with the 75 adjustments {:.2} ms (medians)",
            frame_ms(&b, posed.as_deref(), rest.as_deref(), &[]),
            frame_ms(&b, posed.as_deref(), rest.as_deref(), &identity)
        );
        assert!(d > 1e-4, "{rel}: a nudged knot left the mesh unchanged ({d:e})");
    }
}

/// Median wall time of a frame (one workspace, 15 runs).
fn frame_ms(b: &Bound, posed: Option<&[[f64; 3]]>, rest: Option<&[[f64; 3]]>, adj: &[Adjustment]) -> f64 {
    let mut out = vec![[0.0; 3]; b.deformer.n_vertices()];
    let input = Frame { posed: &[posed], rest, adjustments: adj, ..Default::default() };
    let mut times: Vec<f64> = (0..15)
        .map(|_| {
            let t0 = std::time::Instant::now();
            b.deformer.frame(&input, &mut out, None).unwrap();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn rigid(r: DMat3, t: DVec3, p: &[[f64; 3]]) -> Pool {
    p.iter().map(|x| (r * v(*x) + t).to_array()).collect()
}

#[test]
fn orientations_turn_with_a_rigid_rotation_of_the_whole_character() {
    let r = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.8);
    let t = DVec3::new(0.3, -0.2, 0.5);
    // Knot tracking over the skinned hand, and an articulated pool over the projection pose.
    let skinned = bind_fixture("shots/hand_skinned/shot.usda");
    let wave = bind_fixture("shots/hand_wave/shot.usda");
    let skinned_rest = skinned.stage.rest_points(&skinned.mesh, Some(12.0)).unwrap();
    let wave_pool = wave.stage.posed_pool(&wave.nets[0], Some(13.0)).unwrap().unwrap();
    let cases: [(&str, &Bound, Option<Pool>, Pool); 2] = [
        ("skinned frame 12, tracked", &skinned, None, skinned_rest),
        ("hand_wave frame 13, articulated", &wave, Some(wave_pool), wave.mesh.projection_points.clone()),
    ];
    for (name, b, posed, rest) in cases {
        let diag = b.diagonal();
        let posed_r = posed.as_ref().map(|p| rigid(r, t, p));
        let rest_r = rigid(r, t, &rest);
        let rest_ref = posed.is_none().then_some(rest.as_slice());
        let o = b.binding().knot_orientations(0, posed.as_deref(), rest_ref).unwrap();
        let o_r = b.binding().knot_orientations(0, posed_r.as_deref(), Some(&rest_r)).unwrap();
        let mut worst = 0.0f64;
        let mut moved = 0.0f64;
        for ((p, a), (q, b_)) in o.iter().zip(&o_r) {
            assert_eq!(p, q);
            worst = worst.max(max_entry(m(b_) - r * m(a)));
            moved = moved.max(angle_between(DMat3::IDENTITY, m(a)));
        }
        eprintln!(
            "{name}: max |O' - R O| = {worst:.2e} over {} knots (the pose itself turns knots by up to {:.1} deg)",
            o.len(),
            moved.to_degrees()
        );
        assert!(worst <= 1e-9, "{name}: orientations are not equivariant ({worst:e})");
        assert!(moved > 0.3, "{name}: the reference pose should turn some knots");

        // A translate along a knot's local normal moves the surface along the rotated normal.
        let fan = b.layouts()[0].intersections().iter().find(|f| f.valence() == 4).expect("a valence-4 intersection");
        let knot = fan.point();
        let k = b.layouts()[0].sampling().knot_sample(knot as usize).unwrap() as usize;
        let base = b.binding().adjusted_pool(0, posed.as_deref(), rest_ref, &[]).unwrap();
        let surface = ClosestPointBvh::new(&b.topology, &rest).unwrap();
        let hit = surface.closest_point(base[knot as usize]).unwrap();
        let normal = v(surface.face_normal(hit.face as usize)); // outward: faces are counter-clockwise
        let eps = 0.01 * diag;
        let local = (m(&o[k].1).transpose() * normal * eps).to_array();
        let adj = [Adjustment::new(0, knot).with_translate(local)];
        let moved_knot = b.binding().adjusted_pool(0, posed.as_deref(), rest_ref, &adj).unwrap();
        let step = v(moved_knot[knot as usize]) - v(base[knot as usize]);
        assert!((step - normal * eps).length() <= 1e-12 * diag, "the knot moves along its local normal");
        let (plain, _) = solve(b, posed.as_deref(), rest_ref, &[]);
        let (pushed, _) = solve(b, posed.as_deref(), rest_ref, &adj);
        let (plain_r, _) = solve(b, posed_r.as_deref(), Some(&rest_r), &[]);
        let (pushed_r, _) = solve(b, posed_r.as_deref(), Some(&rest_r), &adj);
        let mut field_err = 0.0f64;
        let (mut nearest, mut nearest_d) = (0usize, f64::INFINITY);
        for i in 0..plain.len() {
            let d = v(pushed[i]) - v(plain[i]);
            let d_r = v(pushed_r[i]) - v(plain_r[i]);
            field_err = field_err.max((d_r - r * d).length());
            let dist = (v(plain[i]) - v(base[knot as usize])).length();
            if dist < nearest_d {
                (nearest, nearest_d) = (i, dist);
            }
        }
        let d_r = v(pushed_r[nearest]) - v(plain_r[nearest]);
        let along = d_r.dot(r * normal);
        eprintln!(
            "{name}: knot {knot} pushed {eps:.4} along its normal: displacement fields differ by {:.2e} x diagonal \
             after the rotation; its nearest vertex moves {:.4} along the rotated normal ({:.4} in all)",
            field_err / diag,
            along,
            d_r.length()
        );
        assert!(field_err <= 1e-9 * diag, "{name}: the adjusted displacement is not rotated with the character");
        assert!(along > 0.3 * eps && along > 0.8 * d_r.length(), "{name}: the surface does not follow the normal");
    }
}

/// The local rotation of the deformation `from` → `to` around `centre`:
/// the Kabsch fit of the (centred) mesh vertices within `radius` of it,
/// the radius grown until at least 8 vertices count.
fn local_rotation(from: &[[f64; 3]], to: &[[f64; 3]], centre: [f64; 3], radius: f64) -> DMat3 {
    let mut radius = radius;
    let mut near: Vec<usize> = Vec::new();
    while near.len() < 8 {
        near = (0..from.len()).filter(|&i| (v(from[i]) - v(centre)).length() < radius).collect();
        radius *= 1.25;
    }
    let mean = |p: &[[f64; 3]]| near.iter().map(|&i| v(p[i])).sum::<DVec3>() / near.len() as f64;
    let (ca, cb) = (mean(from), mean(to));
    let a: Vec<[f64; 3]> = near.iter().map(|&i| (v(from[i]) - ca).to_array()).collect();
    let b: Vec<[f64; 3]> = near.iter().map(|&i| (v(to[i]) - cb).to_array()).collect();
    m(&fit_rotation(&a, &b, &vec![1.0; near.len()]).unwrap().expect("vertices around a knot span a plane"))
}

#[test]
fn orientations_vary_continuously_along_every_curve_through_the_animated_bend_of_the_hand() {
    // hand_skinned, frames 1-12: the index finger bends at MCP, PIP and DIP
    // (50, 40, 25 degrees by frame 12) and the hand turns 15 degrees at the
    // wrist; the curvenet tracks the skinned rest pose. "The angle the bend
    // puts between two knots" is the angle between the deformation's local
    // rotations there (a Kabsch fit of the mesh vertices within 0.03).
    let b = bind_fixture("shots/hand_skinned/shot.usda");
    let sampling = b.layouts()[0].sampling();
    let n_knots = sampling.n_knots();
    // The knots of every curve in curve order (intersections and anchors at the ends).
    let chains: Vec<Vec<usize>> = (0..sampling.n_curves())
        .map(|c| sampling.curve_samples(c).iter().map(|&q| q as usize).filter(|&q| q < n_knots).collect())
        .collect();
    let projection = &b.mesh.projection_points;
    let neutral = b.layouts()[0].neutral_pool();
    let tolerance = 30f64.to_radians();
    let (mut along, mut between_frames, mut off_surface) = (f64::NEG_INFINITY, f64::NEG_INFINITY, 0.0f64);
    let (mut where_along, mut largest_turn) = (String::new(), 0.0f64);
    let mut previous: Option<(Vec<DMat3>, Vec<DMat3>)> = None;
    let mut pairs = 0;
    for t in 1..=12 {
        let rest = b.stage.rest_points(&b.mesh, Some(t as f64)).unwrap();
        let o: Vec<DMat3> =
            b.binding().knot_orientations(0, None, Some(&rest)).unwrap().iter().map(|(_, r)| m(r)).collect();
        let local: Vec<DMat3> = (0..n_knots)
            .map(|q| local_rotation(projection, &rest, neutral[sampling.knot_point(q) as usize], 0.03))
            .collect();
        for (c, chain) in chains.iter().enumerate() {
            for w in chain.windows(2) {
                let excess = angle_between(o[w[0]], o[w[1]]) - angle_between(local[w[0]], local[w[1]]);
                if excess > along {
                    along = excess;
                    where_along = format!(
                        "frame {t}, curve {c}, knots {} and {}",
                        sampling.knot_point(w[0]),
                        sampling.knot_point(w[1])
                    );
                }
                pairs += 1;
            }
        }
        for q in 0..n_knots {
            off_surface = off_surface.max(angle_between(o[q], local[q]));
            largest_turn = largest_turn.max(angle_between(DMat3::IDENTITY, o[q]));
        }
        if let Some((o0, l0)) = &previous {
            for q in 0..n_knots {
                between_frames = between_frames.max(angle_between(o0[q], o[q]) - angle_between(l0[q], local[q]));
            }
        }
        previous = Some((o, local));
    }
    eprintln!(
        "skinned bend, frames 1-12 ({pairs} consecutive knot pairs; knots turn by up to {:.1} deg): neighbours along \
         a curve differ by at most {:.1} deg more than the surface's local rotations there ({where_along}); a knot \
         turns between frames by at most {:.1} deg more than the surface under it; orientations stay within {:.1} deg \
         of the surface's local rotation (tolerance {:.0} deg)",
        largest_turn.to_degrees(),
        along.to_degrees(),
        between_frames.to_degrees(),
        off_surface.to_degrees(),
        tolerance.to_degrees()
    );
    assert!(largest_turn > 60f64.to_radians(), "the bend should turn knots a lot");
    assert!(along <= tolerance, "a flip along a curve: {:.1} deg", along.to_degrees());
    assert!(between_frames <= tolerance, "a flip between frames: {:.1} deg", between_frames.to_degrees());
    assert!(off_surface <= tolerance, "orientations leave the surface: {:.1} deg", off_surface.to_degrees());
}

#[test]
fn rotating_an_adjustment_turns_attached_tangents_about_the_knot_and_leaves_free_ones() {
    let b = bind_fixture("shots/hand_skinned/shot.usda");
    let rest = b.stage.rest_points(&b.mesh, Some(12.0)).unwrap();
    let diag = b.diagonal();
    let sampling = b.layouts()[0].sampling();
    let fan = b.layouts()[0].intersections().iter().find(|f| f.valence() == 4).unwrap();
    let knot = fan.point();
    let k = sampling.knot_sample(knot as usize).unwrap() as usize;
    let tangents = b.binding().orientation_plan(0).knot_tangents(k).to_vec();
    assert_eq!(tangents.len(), 4, "a valence-4 intersection has 4 handles");
    let o = m(&b.binding().knot_orientations(0, None, Some(&rest)).unwrap()[k].1);
    let pool = |adj: &[Adjustment]| b.binding().adjusted_pool(0, None, Some(&rest), adj).unwrap();
    let base = pool(&[]);
    let kp = v(base[knot as usize]);
    let others =
        |p: &Pool, skip: &[u32]| (0..p.len()).filter(|i| !skip.contains(&(*i as u32))).all(|i| p[i] == base[i]);

    // Attached: every tangent turns by O Rz(90) Oᵀ about the knot; nothing else moves.
    let turn = Adjustment::new(0, knot).with_rotate(Rotate::EulerXyz([0.0, 0.0, 90.0]));
    let turned = pool(std::slice::from_ref(&turn));
    let rz = o * DMat3::from_rotation_z(90f64.to_radians()) * o.transpose();
    let mut err = 0.0f64;
    for &h in &tangents {
        let want = kp + rz * (v(base[h as usize]) - kp);
        err = err.max((v(turned[h as usize]) - want).length());
        assert!((v(turned[h as usize]) - v(base[h as usize])).length() > 1e-3, "tangent {h} did not turn");
    }
    assert!(err <= 1e-12 * diag, "attached tangents off the rotation about the knot by {err:e}");
    assert!(others(&turned, &tangents), "a rotate moved a point that is not the knot's tangent");
    assert_eq!(turned[knot as usize], base[knot as usize], "a rotate moves the knot");

    // Free: a rotate and a scale change nothing, bit for bit, down to the mesh.
    let free = turn.clone().with_scale([2.0, 1.0, 0.5]).with_attach_tangents(false);
    assert_eq!(bits(&pool(std::slice::from_ref(&free))), bits(&base));
    let (plain, _) = solve(&b, None, Some(&rest), &[]);
    let (free_mesh, _) = solve(&b, None, Some(&rest), std::slice::from_ref(&free));
    assert_eq!(bits(&free_mesh), bits(&plain), "free tangents: the mesh changed");
    let (turned_mesh, _) = solve(&b, None, Some(&rest), std::slice::from_ref(&turn));
    let d = max_distance(&turned_mesh, &plain);
    eprintln!("turning the tangents of knot {knot} by 90 degrees moves the mesh by {:.2e} x diagonal", d / diag);
    assert!(d > 1e-3 * diag);

    // Translate: the knot moves by O t, attached tangents with it, free ones stay.
    let t = [0.01, -0.02, 0.005];
    let step = o * v(t);
    for attach in [true, false] {
        let moved = pool(&[Adjustment::new(0, knot).with_translate(t).with_attach_tangents(attach)]);
        assert!((v(moved[knot as usize]) - kp - step).length() <= 1e-15, "the knot did not move by O t");
        for &h in &tangents {
            let delta = v(moved[h as usize]) - v(base[h as usize]);
            match attach {
                true => assert!((delta - step).length() <= 1e-14, "attached tangent {h} did not follow"),
                false => assert_eq!(delta, DVec3::ZERO, "free tangent {h} moved"),
            }
        }
        let mut skip = tangents.clone();
        skip.push(knot);
        assert!(others(&moved, &skip));
    }

    // Tangent translates: each tangent by its own O t_h, in pool order.
    let tt = vec![[0.0, 0.0, 0.01], [0.0; 3], [0.005, 0.0, 0.0], [0.0; 3]];
    let moved = pool(&[Adjustment::new(0, knot).with_tangent_translates(tt.clone())]);
    for (h, t) in tangents.iter().zip(&tt) {
        let delta = v(moved[*h as usize]) - v(base[*h as usize]);
        assert!((delta - o * v(*t)).length() <= 1e-15, "tangent {h}");
    }
}

#[test]
fn bad_adjustments_are_refused_naming_the_knot_and_the_workspace_stays_usable() {
    let b = bind_fixture("hand/hand_1k4.usda");
    let sampling = b.layouts()[0].sampling();
    let knot = sampling.knot_point(5);
    let handle = (0..sampling.n_points() as u32).find(|&p| sampling.knot_sample(p as usize).is_none()).unwrap();
    let n_tangents = b.binding().orientation_plan(0).knot_tangents(5).len();
    let mut out = vec![[0.0; 3]; b.deformer.n_vertices()];
    let ok = Adjustment::new(0, knot).with_translate([0.0, 0.0, 0.002]);
    let cases: Vec<(Vec<Adjustment>, Error)> = vec![
        (vec![Adjustment::new(0, handle)], Error::NotAKnot { adjustment: 0, curvenet: 0, point: handle }),
        (
            vec![ok.clone(), Adjustment::new(0, 9999)],
            Error::IndexOutOfRange {
                what: "adjustment",
                index: 1,
                target: "control point",
                value: 9999,
                len: sampling.n_points(),
            },
        ),
        (
            vec![Adjustment::new(2, knot)],
            Error::IndexOutOfRange { what: "adjustment", index: 0, target: "curvenet", value: 2, len: 1 },
        ),
        (vec![ok.clone(), ok.clone()], Error::DuplicateAdjustment { curvenet: 0, point: knot, adjustments: [0, 1] }),
        (
            vec![Adjustment::new(0, knot).with_tangent_translates(vec![[0.0; 3]; n_tangents + 1])],
            Error::TangentTranslateCount {
                adjustment: 0,
                curvenet: 0,
                point: knot,
                expected: n_tangents,
                got: n_tangents + 1,
            },
        ),
        (
            vec![Adjustment::new(0, knot).with_translate([f64::NAN, 0.0, 0.0])],
            Error::InvalidAdjustment {
                adjustment: 0,
                curvenet: 0,
                point: knot,
                problem: "its translate is not finite",
            },
        ),
        (
            vec![Adjustment::new(0, knot).with_rotate(Rotate::Quaternion([0.0; 4]))],
            Error::InvalidAdjustment { adjustment: 0, curvenet: 0, point: knot, problem: "its quaternion is zero" },
        ),
    ];
    for (adjustments, want) in cases {
        let input = Frame { posed: &[None], adjustments: &adjustments, ..Default::default() };
        let got = b.deformer.frame(&input, &mut out, None).unwrap_err();
        eprintln!("refused: {got}");
        assert_eq!(got, want);
        assert_eq!(b.binding().check_adjustments(&adjustments).unwrap_err(), want);
    }
    // The failed frames left no knot claimed: the deformer's pooled workspace
    // (the one the failed frames used) solves a valid frame as a fresh one does.
    let input = Frame { posed: &[None], adjustments: std::slice::from_ref(&ok), ..Default::default() };
    b.deformer.frame(&input, &mut out, None).unwrap();
    let (fresh, _) = solve(&b, None, None, std::slice::from_ref(&ok));
    assert_eq!(bits(&out), bits(&fresh));
}
