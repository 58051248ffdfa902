//! A coupled cage frame (CageRev, SkelUp, Φ·C, LBS skinning, CageUp)
//! makes no heap allocation once its workspace has seen a frame. This
//! binary holds a single test so the counting allocator sees no other test.

mod cage_common;
mod common;
mod counting;

use cage_common::hand_rig;
use curvenet_core::cage::{CageFrame, CageRevApproximation, CoupledWorkspace};
use curvenet_core::skinning::SkinningMethod;

#[global_allocator]
static GLOBAL: counting::Counting = counting::Counting;

#[test]
fn a_coupled_cage_frame_does_not_allocate() {
    let hand = hand_rig("hand_1k4.obj", None, 1);
    let (rig, _) = hand.rig(SkinningMethod::ClassicLinear, CageRevApproximation::SmallIncrement);
    let edit = hand.edit();
    let offsets: Vec<[f64; 3]> = (0..hand.cage.len()).map(|k| [0.0, 1e-3 * (k % 3) as f64, 0.0]).collect();
    let mut out = vec![[0.0; 3]; hand.points.len()];
    let mut ws = CoupledWorkspace::default();
    let frames: Vec<_> = (0..3).map(|k| hand.pose(k as f64 / 2.0)).collect();
    let frame = |pose| CageFrame {
        rest_cage: Some(&edit),
        joint_transforms: Some(pose),
        posed_cage_offsets: Some(&offsets),
        ..Default::default()
    };
    rig.evaluate(&frame(&frames[0]), &mut ws, &mut out).unwrap();
    let before = counting::allocations();
    for pose in &frames {
        rig.evaluate(&frame(pose), &mut ws, &mut out).unwrap();
        rig.evaluate(&CageFrame { joint_transforms: Some(pose), ..Default::default() }, &mut ws, &mut out).unwrap();
    }
    let made = counting::allocations() - before;
    assert_eq!(made, 0, "allocations in 6 coupled frames after the first");
}
