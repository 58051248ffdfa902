//! The coupled cage-and-skeleton rig (Corda et al. 2020) on the hand with
//! a coarse enclosing cage (tests/cage_common) and a three-joint chain
//! (wrist, palm, fingers): rest consistency at bind, zero edits give the
//! skinning-only result, SkelUp keeps the joints inside the edited skin,
//! the loop C′ → C → S → S′ → C′ is exact under LBS (and the error under
//! DQS and CoR after a small posed-cage edit), the cage alone reproduces
//! affine edits, and the frame's cage arrays are checked.

mod cage_common;
mod common;

use cage_common::{diagonal, enclosing_cage, hand_rig, max_dist, winding_number};
use common::{MESH_DIR, load_obj};
use curvenet_core::Error;
use curvenet_core::cage::{CageError, CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
use curvenet_core::skinning::{self, SkinningMethod};
use glam::{DMat3, DVec3};

/// Deterministic small offsets, `amplitude` times the diagonal.
fn offsets(n: usize, amplitude: f64) -> Vec<[f64; 3]> {
    let mut s = 0x2545F4914F6CDD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..n).map(|_| [next() * amplitude, next() * amplitude, next() * amplitude]).collect()
}

/// A smooth posed-cage edit: the cage vertices on the +x side pushed
/// outward, up to `amplitude` (a user dragging one side of the cage).
fn push_side(cage: &[[f64; 3]], amplitude: f64) -> Vec<[f64; 3]> {
    let (lo, hi) = cage_common::bbox(cage);
    let c = (lo + hi) / 2.0;
    cage.iter()
        .map(|p| {
            let d = (DVec3::from_array(*p) - c).normalize();
            (d * amplitude * d.x.max(0.0)).to_array()
        })
        .collect()
}

#[test]
fn rest_consistency_zero_edits_and_skel_up_on_the_hand() {
    let hand = hand_rig("hand_22k.obj", None, 1);
    let diag = diagonal(&hand.points);
    let t = std::time::Instant::now();
    let (rig, skin) = hand.rig(SkinningMethod::ClassicLinear, CageRevApproximation::SmallIncrement);
    println!(
        "coupled rig of {} points, {} cage vertices / {} triangles, {} joints in {:.0} ms: Φ {:.1} MB, MaxVol {} swaps, cond(Φ̃) = {:.3e}",
        rig.n_points(),
        rig.n_cage_vertices(),
        rig.n_cage_triangles(),
        rig.n_joints(),
        t.elapsed().as_secs_f64() * 1e3,
        rig.phi_bytes() as f64 / 1e6,
        rig.maxvol().swaps(),
        rig.condition()
    );
    assert_eq!(rig.maxvol_rows().len(), rig.n_cage_vertices());
    // Rest consistency: M = ΦC₀ (+D) at bind.
    println!("bind residual max |M₀ - ΦC₀| = {:e} x diag", rig.max_bind_residual() / diag);
    assert!(rig.max_bind_residual() <= 1e-10 * diag);
    // Ψ reproduces the joints from the rest cage (Eq. 11's constraints).
    let psi = rig.psi().unwrap();
    let c = rig.n_cage_vertices();
    for (j, a) in hand.joints.iter().enumerate() {
        let row = &psi[j * c..(j + 1) * c];
        let sum: f64 = row.iter().sum();
        let rec: DVec3 = row.iter().zip(&hand.cage).map(|(w, p)| DVec3::from_array(*p) * *w).sum();
        println!(
            "joint {j}: Σψ - 1 = {:e}, |Ψ C₀ - a| = {:e} x diag, min ψ {:e}",
            sum - 1.0,
            rec.distance(*a) / diag,
            row.iter().fold(f64::MAX, |m, x| m.min(*x))
        );
        assert!((sum - 1.0).abs() < 1e-9 && rec.distance(*a) < 1e-9 * diag);
    }
    // Zero edits: exactly the skinning-only result, and C′ fits it.
    let pose = hand.pose(1.0);
    let mut ws = CoupledWorkspace::default();
    let mut out = vec![[0.0; 3]; hand.points.len()];
    rig.evaluate(&CageFrame { joint_transforms: Some(&pose), ..Default::default() }, &mut ws, &mut out).unwrap();
    let mut skinned = vec![[0.0; 3]; hand.points.len()];
    skin.skin_points(&hand.points, &pose, &mut skinned).unwrap();
    assert_eq!(out, skinned, "zero cage edits give the skinning-only result");
    rig.evaluate(&CageFrame::default(), &mut ws, &mut out).unwrap();
    let err = max_dist(ws.posed_cage(), &hand.cage);
    println!("identity pose: |C′ - C₀| = {:e} x diag", err / diag);
    assert!(err <= 1e-9 * diag);
    // SkelUp after an affine rest-cage edit moves the joints by that map
    // (Ψ's linear precision).
    let (lo, hi) = cage_common::bbox(&hand.cage);
    let affine =
        |p: DVec3| (lo + hi) / 2.0 + (p - (lo + hi) / 2.0) * DVec3::new(1.3, 0.8, 1.1) + DVec3::new(0.2, 0.0, -0.1);
    let stretched: Vec<[f64; 3]> = hand.cage.iter().map(|p| affine(DVec3::from_array(*p)).to_array()).collect();
    rig.evaluate(&CageFrame { rest_cage: Some(&stretched), ..Default::default() }, &mut ws, &mut out).unwrap();
    for (j, a) in ws.joints().iter().enumerate() {
        let err = a.distance(affine(hand.joints[j]));
        assert!(err <= 1e-10 * diag, "joint {j}: {err:e}");
    }
    // After a non-affine edit (stretch and bump): joints stay inside the
    // edited skin, and as near the weighted centroid of their skin
    // vertices (weights ω_ij) as the stretch allows.
    let centroid = |rest: &[[f64; 3]], j: usize| {
        let (mut sum, mut total) = (DVec3::ZERO, 0.0);
        for (i, p) in rest.iter().enumerate() {
            for (k, w) in hand.influences.point(i) {
                if k as usize == j {
                    sum += DVec3::from_array(*p) * w;
                    total += w;
                }
            }
        }
        sum / total
    };
    let edit = hand.edit();
    rig.evaluate(
        &CageFrame { rest_cage: Some(&edit), joint_transforms: Some(&pose), ..Default::default() },
        &mut ws,
        &mut out,
    )
    .unwrap();
    let rest = ws.rest_mesh().to_vec();
    for (j, a) in ws.joints().iter().enumerate() {
        let (c0, c1) = (centroid(&hand.points, j), centroid(&rest, j));
        let (d0, d1) = (hand.joints[j].distance(c0), a.distance(c1));
        let unmoved = hand.joints[j].distance(c1);
        let wn = winding_number(&rest, &hand.triangles, *a);
        let wn0 = winding_number(&hand.points, &hand.triangles, hand.joints[j]);
        assert!(wn0 > 0.5, "joint {j} is inside the skin at bind: {wn0}");
        println!(
            "joint {j}: {:.4} x diag from the weighted centroid of its skin vertices at bind, {:.4} after the rest-cage edit with SkelUp (winding number {wn:.3}), {:.4} if it were not moved",
            d0 / diag,
            d1 / diag,
            unmoved / diag
        );
        assert!(wn > 0.5, "joint {j} is inside the edited skin");
        assert!(d1 <= 1.3 * d0 + 0.01 * diag, "joint {j} keeps its place in the skin");
    }
    // The skinned result follows SkelUp's transforms: the rest mesh skinned by them.
    skin.skin_points(&rest, ws.transforms(), &mut skinned).unwrap();
    assert!(max_dist(&out, &skinned) <= 1e-12 * diag);
}

#[test]
fn the_loop_is_exact_under_lbs_and_close_under_dqs_and_cor() {
    for (name, methods) in [
        ("hand_22k.obj", &[SkinningMethod::ClassicLinear, SkinningMethod::DualQuaternion][..]),
        ("hand_1k4.obj", &[SkinningMethod::CentersOfRotation][..]),
    ] {
        let hand = hand_rig(name, None, 1);
        let diag = diagonal(&hand.points);
        let edit = hand.edit();
        let pose = hand.pose(1.0);
        let d = push_side(&hand.cage, 0.01 * diag);
        for &method in methods {
            for approx in [CageRevApproximation::SmallIncrement, CageRevApproximation::LbsGhost] {
                if method == SkinningMethod::ClassicLinear && approx == CageRevApproximation::LbsGhost {
                    continue;
                }
                let t = std::time::Instant::now();
                let (rig, _) = hand.rig(method, approx);
                let build = t.elapsed().as_secs_f64() * 1e3;
                let mut ws = CoupledWorkspace::default();
                let mut out = vec![[0.0; 3]; hand.points.len()];
                let frame = CageFrame { rest_cage: Some(&edit), joint_transforms: Some(&pose), ..Default::default() };
                rig.evaluate(&frame, &mut ws, &mut out).unwrap();
                let before = ws.posed_cage().to_vec();
                let want: Vec<[f64; 3]> =
                    before.iter().zip(&d).map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]).collect();
                rig.evaluate(&CageFrame { posed_cage_offsets: Some(&d), ..frame }, &mut ws, &mut out).unwrap();
                let after = ws.posed_cage().to_vec();
                let moved = max_dist(ws.rest_cage(), &edit);
                let err = max_dist(&after, &want);
                println!(
                    "{name} {:>18} {approx:?}: loop C′→C→S→S′→C′ error {:.3e} x diag after a posed-cage edit of 1% diag (rest cage moved {:.3e} x diag; CageRev {:.2} ms; rig built in {build:.0} ms)",
                    method.token(),
                    err / diag,
                    moved / diag,
                    ws.timings().cage_rev.as_secs_f64() * 1e3
                );
                assert!(moved > 1e-3 * diag);
                if method == SkinningMethod::ClassicLinear || approx == CageRevApproximation::LbsGhost {
                    assert!(err <= 1e-9 * diag, "exact loop: {err:e}");
                } else {
                    assert!(err <= 0.5 * 0.01 * diag, "the loop lands closer than the edit's size: {err:e}");
                }
            }
        }
    }
}

#[test]
fn the_cage_alone_deforms_the_mesh_and_frames_are_checked() {
    let (mesh, points) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let triangles = fan_triangles(&mesh);
    let (cage, tris) = enclosing_cage(&points, 1);
    let rig = CoupledRig::new(&cage, &tris, &points, &triangles, None, CageRevApproximation::default()).unwrap();
    let diag = diagonal(&points);
    let a = DMat3::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 0.8)
        * DMat3::from_diagonal(DVec3::new(1.2, 0.7, 1.1));
    let f = |p: &[f64; 3]| (a * DVec3::from_array(*p) + DVec3::new(1.0, 2.0, -0.5)).to_array();
    let edited: Vec<[f64; 3]> = cage.iter().map(f).collect();
    let mut ws = CoupledWorkspace::default();
    let mut out = vec![[0.0; 3]; points.len()];
    rig.evaluate(&CageFrame { rest_cage: Some(&edited), ..Default::default() }, &mut ws, &mut out).unwrap();
    let want: Vec<[f64; 3]> = points.iter().map(f).collect();
    let err = max_dist(&out, &want);
    println!("cage alone: an affine cage edit reproduced to {:e} x diag", err / diag);
    assert!(err <= 1e-10 * diag);
    // Posed-cage offsets without a skeleton are rest-cage offsets.
    let d = offsets(cage.len(), 0.01 * diag);
    rig.evaluate(&CageFrame { posed_cage_offsets: Some(&d), ..Default::default() }, &mut ws, &mut out).unwrap();
    let moved: Vec<[f64; 3]> = cage.iter().zip(&d).map(|(p, q)| [p[0] + q[0], p[1] + q[1], p[2] + q[2]]).collect();
    assert_eq!(ws.rest_cage(), &moved[..]);
    // Frame errors name the field and the index.
    let err = rig
        .evaluate(&CageFrame { rest_cage: Some(&edited[1..]), ..Default::default() }, &mut ws, &mut out)
        .unwrap_err();
    assert!(matches!(err, Error::CountMismatch { what: "Frame::rest_cage", .. }), "{err}");
    let mut nan = d.clone();
    nan[7][2] = f64::NAN;
    let err = rig
        .evaluate(&CageFrame { posed_cage_offsets: Some(&nan), ..Default::default() }, &mut ws, &mut out)
        .unwrap_err();
    assert!(
        matches!(err, Error::Cage(CageError::NonFinite { what: "Frame::posed_cage_offsets", index: 7, .. })),
        "{err}"
    );
    println!("{err}");
    let err = rig
        .evaluate(&CageFrame { joint_transforms: Some(&[skinning::IDENTITY]), ..Default::default() }, &mut ws, &mut out)
        .unwrap_err();
    assert!(matches!(err, Error::Cage(CageError::Missing { .. })), "{err}");
}
