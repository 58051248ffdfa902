//! Blend shapes (paper §5, UsdSkel semantics): weights interpolate through
//! inbetweens as usd-core's BlendShapeQuery does, weight 0 changes nothing,
//! and after a rigid motion of the whole curvenet the sculpt moves with the surface.

use curvenet_core::Frame;
use curvenet_core::{BlendShape, BlendShapes};
use curvenet_e2e::{Bound, bind_fixture, max_distance, repo_root};

fn shapes(b: &Bound) -> BlendShapes {
    let n = b.mesh.projection_points.len();
    let shapes = b
        .mesh
        .blend_shapes
        .iter()
        .map(|s| {
            let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
            BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib).unwrap()
        })
        .collect();
    BlendShapes::new(n, shapes)
}

const WEIGHTS: [f64; 7] = [-0.5, 0.0, 0.25, 0.5, 0.75, 1.0, 1.5];

/// usd-core's BlendShapeQuery offsets of /Hand/Mesh in the shot at WEIGHTS.
fn usd_core_offsets() -> Vec<Vec<[f64; 3]>> {
    let python = repo_root().join(".venv/bin/python");
    assert!(python.exists(), "{} is missing: run scripts/python-env (scripts/test does)", python.display());
    let script = r#"
import json, sys
from pxr import Usd, UsdSkel, Vt
stage = Usd.Stage.Open(sys.argv[1])
mesh = stage.GetPrimAtPath('/Hand/Mesh')
q = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh))
n = len(mesh.GetAttribute('points').Get())
out = []
for w in json.loads(sys.argv[2]):
    sw, bi, si = q.ComputeSubShapeWeights(Vt.FloatArray([w]))
    pts = Vt.Vec3fArray(n)
    assert q.ComputeDeformedPoints(sw, bi, si, q.ComputeBlendShapePointIndices(), q.ComputeSubShapePointOffsets(), pts)
    out.append([[float(c) for c in p] for p in pts])
print(json.dumps(out))
"#;
    let stage = repo_root().join("fixtures/shots/hand_wave/shot.usda");
    let weights = format!("{:?}", WEIGHTS);
    let out =
        std::process::Command::new(python).args(["-c", script, stage.to_str().unwrap(), &weights]).output().unwrap();
    assert!(out.status.success(), "usd-core: {}", String::from_utf8_lossy(&out.stderr));
    let v: Vec<Vec<Vec<f64>>> = serde_json::from_slice(&out.stdout).unwrap();
    v.into_iter().map(|pts| pts.into_iter().map(|p| [p[0], p[1], p[2]]).collect()).collect()
}

#[test]
fn weights_interpolate_through_inbetweens_as_usd_core_does() {
    let b = bind_fixture("shots/hand_wave/shot.usda");
    let s = shapes(&b);
    assert_eq!(s.len(), 1);
    let want = usd_core_offsets();
    let scale = b.diagonal();
    for (w, expected) in WEIGHTS.iter().zip(&want) {
        let mut got = vec![[0.0; 3]; b.mesh.projection_points.len()];
        s.add_to(&[*w], &mut got).unwrap();
        let err = max_distance(&got, expected);
        // usd-core computes in f32.
        assert!(err <= 1e-7 * scale, "weight {w}: {err:e} from usd-core");
        let moved = got.iter().flatten().any(|x| *x != 0.0);
        assert_eq!(moved, *w != 0.0, "weight {w}");
    }
}

#[test]
fn sculpts_move_with_the_surface_and_weight_zero_changes_nothing() {
    let b = bind_fixture("shots/hand_wave/shot.usda");
    let s = shapes(&b);
    let n = b.binding().n_vertices();
    let (mut out, mut grads) = (vec![[0.0; 3]; n], vec![[0.0; 9]; n]);
    // A rigid rotation of the whole curvenet: 70° about z, then a translation.
    let (c, sn) = (70f64.to_radians().cos(), 70f64.to_radians().sin());
    let rot = |p: &[f64; 3]| [c * p[0] - sn * p[1] + 0.1, sn * p[0] + c * p[1], p[2] - 0.2];
    let pool: Vec<[f64; 3]> = b.nets[0].pool.iter().map(rot).collect();
    b.deformer.frame(&Frame { posed: &[Some(&pool)], ..Default::default() }, &mut out, Some(&mut grads)).unwrap();
    let base = out.clone();
    let rigid: Vec<[f64; 3]> = b.mesh.projection_points.iter().map(rot).collect();
    let base_err = max_distance(&base, &rigid);
    eprintln!("rigid motion of the hand: off by {:.2e} x diagonal", base_err / b.diagonal());
    assert!(base_err <= 1e-9 * b.diagonal(), "{base_err:e}");
    s.add_deformed(&[0.0], &grads, &mut out).unwrap();
    assert_eq!(out, base, "weight 0 changed the mesh");
    s.add_deformed(&[1.0], &grads, &mut out).unwrap();
    // The sculpt on the rest mesh, rotated: rot(rest + offset).
    let mut sculpted = b.mesh.projection_points.clone();
    s.add_to(&[1.0], &mut sculpted).unwrap();
    let want: Vec<[f64; 3]> = sculpted.iter().map(rot).collect();
    let err = max_distance(&out, &want);
    let size = max_distance(&sculpted, &b.mesh.projection_points);
    eprintln!(
        "sculpt of {:.2e} after a rigid motion: off by {:.2e} (x diagonal)",
        size / b.diagonal(),
        err / b.diagonal()
    );
    assert!(size > 1e-3 * b.diagonal());
    assert!(err <= 1e-9 * b.diagonal(), "{err:e}");
}
