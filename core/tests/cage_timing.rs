//! Per-frame cost of the coupled rig's cage stages on the hand at two
//! resolutions (22k and 94k vertices) with the same cage (162 vertices,
//! fitted to the 22k hand) and the same three-joint skeleton: medians of
//! CageRev, SkelUp and CageUp over frames that edit the rest cage, pose
//! the skeleton and edit the posed cage — these do not grow with the mesh —
//! beside the two stages that touch every vertex (Φ·C and skinning).
//! Every frame's loop C′ → C → S → S′ → C′ is checked exact (LBS).

mod cage_common;
mod common;

use cage_common::{diagonal, hand_rig, max_dist};
use curvenet_core::cage::{CageFrame, CageRevApproximation, CoupledWorkspace};
use curvenet_core::skinning::SkinningMethod;
use std::time::Duration;

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64() * 1e3
}

#[test]
fn cage_stages_per_frame_do_not_grow_with_the_mesh() {
    let reference = hand_rig("hand_22k.obj", None, 2);
    let mut rows = Vec::new();
    for name in ["hand_22k.obj", "hand_94k.obj"] {
        let hand = if name == "hand_22k.obj" { None } else { Some(hand_rig(name, Some(&reference), 2)) };
        let hand = hand.as_ref().unwrap_or(&reference);
        let diag = diagonal(&hand.points);
        let t = std::time::Instant::now();
        let (rig, _) = hand.rig(SkinningMethod::ClassicLinear, CageRevApproximation::SmallIncrement);
        let build = t.elapsed().as_secs_f64() * 1e3;
        let edit = hand.edit();
        let mut ws = CoupledWorkspace::default();
        let mut out = vec![[0.0; 3]; hand.points.len()];
        let (mut rev, mut up, mut cu, mut phi, mut skin) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for f in 0..12 {
            let s = f as f64 / 11.0;
            let rest: Vec<[f64; 3]> = hand
                .cage
                .iter()
                .zip(&edit)
                .map(|(a, b)| [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), a[2] + s * (b[2] - a[2])])
                .collect();
            let pose = hand.pose(s);
            let frame = CageFrame { rest_cage: Some(&rest), joint_transforms: Some(&pose), ..Default::default() };
            rig.evaluate(&frame, &mut ws, &mut out).unwrap();
            let before = ws.posed_cage().to_vec();
            let d: Vec<[f64; 3]> = (0..rest.len()).map(|k| [0.0, 0.0, 1e-3 * diag * ((k % 5) as f64 - 2.0)]).collect();
            rig.evaluate(&CageFrame { posed_cage_offsets: Some(&d), ..frame }, &mut ws, &mut out).unwrap();
            let want: Vec<[f64; 3]> =
                before.iter().zip(&d).map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]).collect();
            let err = max_dist(ws.posed_cage(), &want);
            assert!(err <= 1e-9 * diag, "{name} frame {f}: loop error {err:e}");
            let t = ws.timings();
            rev.push(t.cage_rev);
            up.push(t.skel_up);
            cu.push(t.cage_up);
            phi.push(t.cage_to_mesh);
            skin.push(t.skinning);
        }
        rows.push(format!(
            "{name:>13}: {} vertices, {} cage vertices, {} joints, rig built in {build:.0} ms (Φ {:.0} MB); per-frame medians: CageRev {:.3} ms, SkelUp {:.4} ms, CageUp {:.3} ms | Φ·C {:.2} ms, skinning {:.2} ms",
            hand.points.len(),
            rig.n_cage_vertices(),
            rig.n_joints(),
            rig.phi_bytes() as f64 / 1e6,
            median(rev),
            median(up),
            median(cu),
            median(phi),
            median(skin)
        ));
    }
    for r in rows {
        println!("{r}");
    }
}
