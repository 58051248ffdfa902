//! A new rest pose (or pose) never rebuilds the cut-mesh or refactors
//! `VᵀL_hV`. Alone in its test binary, so the process-wide counters see only
//! this test.

use curvenet_core::Frame;
use curvenet_core::{cut_mesh_builds, numeric_factorizations};
use curvenet_e2e::bind_fixture;

#[test]
fn frames_with_new_rest_poses_reuse_the_binding() {
    let b = bind_fixture("hand/hand_1k4.usda");
    let (cuts, factors) = (cut_mesh_builds(), numeric_factorizations());
    assert_eq!((cuts, factors), (1, 1), "binding one mesh builds one cut-mesh and one factor");
    let mut out = vec![[0.0; 3]; b.deformer.n_vertices()];
    for k in 0..5 {
        let s = 1.0 + 0.1 * k as f64;
        let rest: Vec<[f64; 3]> =
            b.mesh.projection_points.iter().map(|p| [p[0] * s, p[1], p[2] + 0.01 * k as f64]).collect();
        b.deformer.frame(&Frame { posed: &[None], rest: Some(&rest), ..Default::default() }, &mut out, None).unwrap();
        assert!(out.iter().zip(&rest).all(|(o, r)| (0..3).all(|i| (o[i] - r[i]).abs() < 1e-9)));
    }
    assert_eq!((cut_mesh_builds(), numeric_factorizations()), (cuts, factors), "a frame rebuilt the binding");
}
