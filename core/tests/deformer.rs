//! The deformer (the one way in and through): `Deformer::new` from plain
//! data and `Deformer::frame` give what the parts give, in both blend-shape
//! modes, with and without a rest pose, and errors name the curvenet.

mod common;

use common::*;
use curvenet_core::blend_shapes::{BlendShape, BlendShapes};
use curvenet_core::{
    Binding, BlendShapeMode, CurvenetInput, CurvenetLayout, Deformer, DeformerInput, DeformerOptions, Error, Frame,
    MeshInput, PolyMesh, SamplingOptions,
};

fn hand_with_grid() -> (PolyMesh, Vec<[f64; 3]>, NetBuilder) {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    (mesh, pts, net)
}

fn shapes(n: usize) -> Vec<BlendShape> {
    let dense: Vec<[f64; 3]> = (0..n).map(|i| [0.001 * (i % 7) as f64, -0.002, 0.0005 * (i % 3) as f64]).collect();
    let sparse_ix: Vec<u32> = (0..n as u32).step_by(5).collect();
    let sparse: Vec<[f64; 3]> = sparse_ix.iter().map(|&i| [0.0, 0.003, -0.001 * (i % 2) as f64]).collect();
    vec![
        BlendShape::new(n, dense, None, vec![]).unwrap(),
        BlendShape::new(n, sparse, Some(sparse_ix), vec![(0.5, vec![[0.001, 0.0, 0.0]; n.div_ceil(5)])]).unwrap(),
    ]
}

#[test]
fn a_frame_is_the_binding_solve_with_blend_shapes_before_or_after() {
    let (mesh, pts, net) = hand_with_grid();
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let nets = [CurvenetInput { splines: &net.splines, pool: &net.points, sample_density: 5.0 }];
    let input = DeformerInput {
        mesh: MeshInput {
            face_vertex_counts: &counts,
            face_vertex_indices: mesh.face_vertex_indices(),
            projection_points: &pts,
        },
        curvenets: &nets,
        blend_shapes: shapes(pts.len()),
        skinning: None,
        cage: None,
        options: DeformerOptions::default(),
    };
    let d = Deformer::new(&input).unwrap();
    // The parts, by hand.
    let c = curvenet_core::Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let b = Binding::new(&mesh, &pts, &[&layout], &Default::default()).unwrap();
    let bs = BlendShapes::new(pts.len(), shapes(pts.len()));
    let r = rotation(normalize([0.3, 1.0, -0.2]), 0.4);
    let posed: Vec<[f64; 3]> = net.points.iter().map(|&p| apply(&r, p)).collect();
    let rest: Vec<[f64; 3]> = pts.iter().map(|&p| [p[0] * 1.01, p[1], p[2] + 0.01 * p[0]]).collect();
    let weights = [0.7, 0.25];
    let n = pts.len();
    let mut ws = b.workspace();
    for rest in [None, Some(rest.as_slice())] {
        for mode in [BlendShapeMode::After, BlendShapeMode::Before] {
            let frame = Frame {
                posed: &[Some(&posed)],
                rest,
                blend_shape_weights: Some(&weights),
                blend_shape_mode: mode,
                ..Default::default()
            };
            let mut got = vec![[0.0; 3]; n];
            d.frame(&frame, &mut got, None).unwrap();
            let mut want = vec![[0.0; 3]; n];
            let mut g = vec![[0.0; 9]; n];
            match mode {
                BlendShapeMode::After => {
                    b.deform(
                        &Frame { posed: &[Some(&posed)], rest, ..Default::default() },
                        &mut ws,
                        &mut want,
                        Some(&mut g),
                    )
                    .unwrap();
                    bs.add_deformed(&weights, &g, &mut want).unwrap();
                }
                BlendShapeMode::Before => {
                    let mut sculpted = rest.unwrap_or(&pts).to_vec();
                    bs.add_to(&weights, &mut sculpted).unwrap();
                    b.deform(
                        &Frame { posed: &[Some(&posed)], rest: Some(&sculpted), ..Default::default() },
                        &mut ws,
                        &mut want,
                        None,
                    )
                    .unwrap();
                }
            }
            assert_eq!(got, want, "mode {mode:?}, rest {}", rest.is_some());
            // With gradients requested, the points are the same.
            let mut grads = vec![[0.0; 9]; n];
            let mut again = vec![[0.0; 3]; n];
            d.frame(&frame, &mut again, Some(&mut grads)).unwrap();
            assert_eq!(again, got);
            assert!(grads.iter().all(|m| m.iter().all(|x| x.is_finite())));
        }
    }
    // No articulation and zero weights: the mesh itself.
    let mut out = vec![[0.0; 3]; n];
    d.frame(&Frame { blend_shape_weights: Some(&[0.0, 0.0]), ..Default::default() }, &mut out, None).unwrap();
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    assert!(out.iter().zip(&pts).all(|(o, p)| norm(sub(*o, *p)) <= 1e-9 * diag));
    // Bad weights are named.
    assert_eq!(
        d.frame(&Frame { blend_shape_weights: Some(&[1.0]), ..Default::default() }, &mut out, None).unwrap_err(),
        Error::CountMismatch { what: "blend-shape weights", expected: 2, got: 1 }
    );
    assert!(matches!(
        d.frame(&Frame { blend_shape_weights: Some(&[1.0, f64::NAN]), ..Default::default() }, &mut out, None),
        Err(Error::NonFiniteScalar { index: 1, .. })
    ));
}

#[test]
fn errors_name_the_curvenet() {
    let (mesh, pts, net) = hand_with_grid();
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    // The second curvenet has a spline whose four control points coincide.
    let bad_pool = vec![[0.0, 0.4, 0.0]; 4];
    let nets = [
        CurvenetInput { splines: &net.splines, pool: &net.points, sample_density: 5.0 },
        CurvenetInput { splines: &[[0, 1, 2, 3]], pool: &bad_pool, sample_density: 5.0 },
    ];
    let input = DeformerInput {
        mesh: MeshInput {
            face_vertex_counts: &counts,
            face_vertex_indices: mesh.face_vertex_indices(),
            projection_points: &pts,
        },
        curvenets: &nets,
        blend_shapes: Vec::new(),
        skinning: None,
        cage: None,
        options: DeformerOptions::default(),
    };
    let e = Deformer::new(&input).unwrap_err();
    assert!(
        matches!(&e, Error::Curvenet { curvenet: 1, source } if matches!(**source, Error::ZeroLengthSpline { spline: 0 })),
        "{e}"
    );
    assert!(e.to_string().starts_with("curvenet 1: "), "{e}");
}

/// Two joints: 0 holds everything below `y = 0.42`, 1 everything above
/// `0.48`, blended between; joint 1 moves by a translation and a small
/// non-uniform scale.
fn two_joint_influences(points: &[[f64; 3]]) -> curvenet_core::skinning::Influences {
    let mut ji = Vec::new();
    let mut jw = Vec::new();
    for p in points {
        let b = ((p[1] - 0.42) / 0.06).clamp(0.0, 1.0);
        ji.extend([0, 1]);
        jw.extend([1.0 - b, b]);
    }
    curvenet_core::skinning::Influences::new(points.len(), 2, &ji, &jw, 2).unwrap()
}

#[test]
fn a_rigged_frame_is_skinning_then_spline_skinning_then_the_solve() {
    use curvenet_core::skinning::{self, ControlPointWeights, Skin, SkinningMethod, SplineSkinning};
    let (mesh, pts, net) = hand_with_grid();
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let nets = [CurvenetInput { splines: &net.splines, pool: &net.points, sample_density: 5.0 }];
    let n = pts.len();
    let mut moved = skinning::IDENTITY;
    (moved[10], moved[12], moved[13]) = (1.02, 0.004, 0.01);
    let transforms = [skinning::IDENTITY, moved];
    let weights = [0.7, 0.25];
    for method in [SkinningMethod::ClassicLinear, SkinningMethod::DualQuaternion] {
        let skin = Skin::new(two_joint_influences(&pts), skinning::IDENTITY, method).unwrap();
        let field = ControlPointWeights::new(two_joint_influences(&net.points));
        let spline =
            SplineSkinning::new(&net.points, &net.splines, &field, &skinning::IDENTITY, &Default::default()).unwrap();
        let input = |rig: Option<curvenet_core::Rig>| DeformerInput {
            mesh: MeshInput {
                face_vertex_counts: &counts,
                face_vertex_indices: mesh.face_vertex_indices(),
                projection_points: &pts,
            },
            curvenets: &nets,
            blend_shapes: shapes(n),
            skinning: rig,
            cage: None,
            options: DeformerOptions::default(),
        };
        let rig = curvenet_core::Rig {
            skin: skin.clone(),
            curvenets: vec![Some(spline.clone())],
            flexible_iterations: 0,
            skeleton: None,
        };
        let rigged = Deformer::new(&input(Some(rig))).unwrap();
        let plain = Deformer::new(&input(None)).unwrap();
        // By hand: blend shapes on the bind pose, skinning, the spline-skinned pool.
        let mut sculpted = pts.clone();
        BlendShapes::new(n, shapes(n)).add_to(&weights, &mut sculpted).unwrap();
        let mut rest = vec![[0.0; 3]; n];
        skin.skin_points(&sculpted, &transforms, &mut rest).unwrap();
        let mut pool = vec![[0.0; 3]; net.points.len()];
        spline.pose(&transforms, &mut pool).unwrap();
        let mut want = vec![[0.0; 3]; n];
        plain
            .frame(&Frame { posed: &[Some(&pool)], rest: Some(&rest), ..Default::default() }, &mut want, None)
            .unwrap();
        let mut got = vec![[0.0; 3]; n];
        let frame = Frame {
            blend_shape_weights: Some(&weights),
            blend_shape_mode: BlendShapeMode::Before,
            joint_transforms: Some(&transforms),
            ..Default::default()
        };
        rigged.frame(&frame, &mut got, None).unwrap();
        assert_eq!(got, want, "{method:?}");
        let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
        let moved_by = got.iter().zip(&pts).map(|(a, b)| norm(sub(*a, *b))).fold(0.0, f64::max);
        eprintln!("{method:?}: the rigged frame moves the hand by up to {:.3} x diagonal", moved_by / diag);
        assert!(moved_by > 1e-3 * diag, "the rig should move the hand");
        // Again on the same thread (reused buffers): the same points.
        let mut again = vec![[0.0; 3]; n];
        rigged.frame(&frame, &mut again, None).unwrap();
        assert_eq!(again, got);
        // Errors are named: transforms for a deformer without a rig, a wrong joint count.
        assert!(matches!(
            plain.frame(&Frame { joint_transforms: Some(&transforms), ..Default::default() }, &mut got, None),
            Err(Error::Unsupported { .. })
        ));
        let e = rigged
            .frame(&Frame { joint_transforms: Some(&transforms[..1]), ..Default::default() }, &mut got, None)
            .unwrap_err();
        assert!(e.to_string().contains("skinning transforms"), "{e}");
    }
    // A rig that does not fit the mesh or the curvenets is refused, naming the count.
    let skin = Skin::new(two_joint_influences(&pts[..10]), skinning::IDENTITY, SkinningMethod::ClassicLinear).unwrap();
    let bad = DeformerInput {
        mesh: MeshInput {
            face_vertex_counts: &counts,
            face_vertex_indices: mesh.face_vertex_indices(),
            projection_points: &pts,
        },
        curvenets: &nets,
        blend_shapes: Vec::new(),
        skinning: Some(curvenet_core::Rig { skin, curvenets: vec![None], flexible_iterations: 0, skeleton: None }),
        cage: None,
        options: DeformerOptions::default(),
    };
    assert!(matches!(Deformer::new(&bad), Err(Error::CountMismatch { expected, got: 10, .. }) if expected == n));
}

/// The content that names a stored bake binding: streamed in bounded
/// pieces that make up exactly the whole, and changed by any input bit.
#[test]
fn the_content_streams_in_bounded_pieces_and_follows_every_input() {
    let (mesh, pts, net) = hand_with_grid();
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let nets = [CurvenetInput { splines: &net.splines, pool: &net.points, sample_density: 5.0 }];
    // The whole content, and the pieces `write_content` hands on.
    let content = |pts: &[[f64; 3]], shapes: Vec<BlendShape>| {
        let input = DeformerInput {
            mesh: MeshInput {
                face_vertex_counts: &counts,
                face_vertex_indices: mesh.face_vertex_indices(),
                projection_points: pts,
            },
            curvenets: &nets,
            blend_shapes: shapes,
            skinning: None,
            cage: None,
            options: DeformerOptions::default(),
        };
        let mut pieces: Vec<Vec<u8>> = Vec::new();
        input.write_content(|p| pieces.push(p.to_vec()));
        (input.content_bytes(), pieces)
    };
    let (whole, pieces) = content(&pts, shapes(pts.len()));
    assert!(pieces.len() > 1, "{} bytes in one piece", whole.len());
    assert!(pieces.iter().all(|p| p.len() <= 1 << 16));
    assert_eq!(pieces.concat(), whole);
    // One point's last bit, or no blend shapes: other content.
    let mut moved = pts.clone();
    moved[pts.len() / 2][1] = f64::from_bits(moved[pts.len() / 2][1].to_bits() ^ 1);
    assert_ne!(content(&moved, shapes(pts.len())).0, whole);
    assert_ne!(content(&pts, Vec::new()).0, whole);
}
