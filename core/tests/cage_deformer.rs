//! The cage wired into the deformer (DeformerInput::cage, Frame::rest_cage,
//! Frame::posed_cage_offsets): a frame of a deformer with a cage is the
//! curvenet solve over the coupled rig's result (cage alone, or coupled
//! with the rig's skeleton and skin), zero cage edits give the rig-only
//! frame, and cage input errors name the field.

mod cage_common;
mod common;

use cage_common::enclosing_cage;
use common::*;
use curvenet_core::cage::{CageError, CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
use curvenet_core::skinning::{self, Influences, Mat4, Skeleton, Skin, SkinningMethod};
use curvenet_core::{CageInput, CurvenetInput, Deformer, DeformerInput, DeformerOptions, Error, Frame, MeshInput, Rig};
use glam::{DMat3, DVec3};

fn influences(points: &[[f64; 3]]) -> Influences {
    let mut ji = Vec::new();
    let mut jw = Vec::new();
    for p in points {
        let b = ((p[1] - 0.42) / 0.06).clamp(0.0, 1.0);
        ji.extend([0, 1]);
        jw.extend([1.0 - b, b]);
    }
    Influences::new(points.len(), 2, &ji, &jw, 2).unwrap()
}

fn translate(t: DVec3) -> Mat4 {
    let mut m = skinning::IDENTITY;
    m[12..15].copy_from_slice(&t.to_array());
    m
}

fn rotate_about(axis: DVec3, deg: f64, pivot: DVec3) -> Mat4 {
    let r = DMat3::from_axis_angle(axis.normalize(), deg.to_radians());
    let shift = pivot - r * pivot;
    let c = r.to_cols_array();
    [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, shift.x, shift.y, shift.z, 1.0]
}

#[test]
fn a_frame_with_a_cage_is_the_solve_over_the_coupled_rig() {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let nets = [CurvenetInput { splines: &net.splines, pool: &net.points, sample_density: 5.0 }];
    let (cage, cage_tris) = enclosing_cage(&pts, 1);
    let n = pts.len();
    // Joints inside the hand: the centroid of the points near two heights.
    let at = |h: f64| {
        let near: Vec<DVec3> = pts.iter().filter(|p| (p[1] - h).abs() < 0.02).map(|p| DVec3::from_array(*p)).collect();
        near.iter().sum::<DVec3>() / near.len() as f64
    };
    let joints = [at(0.3), at(0.45)];
    let skeleton = Skeleton::new(&[None, Some(0)], &[translate(joints[0]), translate(joints[1])]).unwrap();
    let skin = Skin::new(influences(&pts), skinning::IDENTITY, SkinningMethod::ClassicLinear).unwrap();
    let rig = |skeleton: Option<Skeleton>| Rig {
        skin: skin.clone(),
        curvenets: vec![None],
        flexible_iterations: 0,
        skeleton,
    };
    let input = |rig: Option<Rig>, cage: Option<CageInput<'static>>| DeformerInput {
        mesh: MeshInput {
            face_vertex_counts: &counts,
            face_vertex_indices: mesh.face_vertex_indices(),
            projection_points: &pts,
        },
        curvenets: &nets,
        blend_shapes: Vec::new(),
        skinning: rig,
        cage,
        options: DeformerOptions::default(),
    };
    // The cage arrays, leaked to outlive the `input` helper's borrows.
    let cage_static: CageInput<'static> = CageInput {
        points: Box::leak(cage.clone().into_boxed_slice()),
        triangles: Box::leak(cage_tris.clone().into_boxed_slice()),
    };
    let plain = Deformer::new(&input(None, None)).unwrap();
    let caged = Deformer::new(&input(None, Some(cage_static))).unwrap();
    let coupled = Deformer::new(&input(Some(rig(Some(skeleton.clone()))), Some(cage_static))).unwrap();
    let skinned_only = Deformer::new(&input(Some(rig(None)), None)).unwrap();
    let c = coupled.cage().unwrap();
    println!(
        "deformer cage: {} vertices, {} triangles, {} MaxVol rows, cond {:.3e}, Φ {} bytes",
        c.n_cage_vertices(),
        c.n_cage_triangles(),
        c.maxvol_rows().len(),
        c.condition(),
        c.phi_bytes()
    );
    assert!(caged.cage().is_some() && plain.cage().is_none());
    // The standalone rigs, built as the deformer builds them.
    let tris = fan_triangles(&mesh);
    let alone = CoupledRig::new(&cage, &cage_tris, &pts, &tris, None, CageRevApproximation::default()).unwrap();
    let with_skel =
        CoupledRig::new(&cage, &cage_tris, &pts, &tris, Some((&skeleton, &skin)), CageRevApproximation::default())
            .unwrap();
    let (lo, hi) = cage_common::bbox(&cage);
    let edit: Vec<[f64; 3]> = cage
        .iter()
        .map(|p| {
            let q = DVec3::from_array(*p);
            let k = ((q.y - lo.y) / (hi.y - lo.y)).clamp(0.0, 1.0);
            (q + DVec3::new(0.02 * k, 0.0, 0.01 * k * k)).to_array()
        })
        .collect();
    let offsets: Vec<[f64; 3]> = (0..cage.len()).map(|k| [0.0, 0.002 * (k % 3) as f64, 0.0]).collect();
    let pose = [skinning::IDENTITY, rotate_about(DVec3::Z, 20.0, joints[1])];
    let mut ws = CoupledWorkspace::default();
    let mut rest = vec![[0.0; 3]; n];
    let (mut got, mut want) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    // Cage alone.
    alone
        .evaluate(
            &CageFrame { rest_cage: Some(&edit), posed_cage_offsets: Some(&offsets), ..Default::default() },
            &mut ws,
            &mut rest,
        )
        .unwrap();
    caged
        .frame(
            &Frame { rest_cage: Some(&edit), posed_cage_offsets: Some(&offsets), ..Default::default() },
            &mut got,
            None,
        )
        .unwrap();
    plain.frame(&Frame { rest: Some(&rest), ..Default::default() }, &mut want, None).unwrap();
    assert_eq!(got, want, "cage alone");
    // Coupled with the skeleton.
    let frame = Frame {
        joint_transforms: Some(&pose),
        rest_cage: Some(&edit),
        posed_cage_offsets: Some(&offsets),
        ..Default::default()
    };
    with_skel
        .evaluate(
            &CageFrame {
                rest_cage: Some(&edit),
                posed_cage_offsets: Some(&offsets),
                joint_transforms: Some(&pose),
                ..Default::default()
            },
            &mut ws,
            &mut rest,
        )
        .unwrap();
    coupled.frame(&frame, &mut got, None).unwrap();
    plain.frame(&Frame { rest: Some(&rest), ..Default::default() }, &mut want, None).unwrap();
    assert_eq!(got, want, "cage coupled with the skeleton");
    // Zero cage edits: the rig-only frame.
    coupled.frame(&Frame { joint_transforms: Some(&pose), ..Default::default() }, &mut got, None).unwrap();
    skinned_only.frame(&Frame { joint_transforms: Some(&pose), ..Default::default() }, &mut want, None).unwrap();
    assert_eq!(got, want, "zero cage edits");
    // Errors name the field.
    let err = plain.frame(&Frame { rest_cage: Some(&edit), ..Default::default() }, &mut got, None).unwrap_err();
    assert!(matches!(err, Error::Unsupported { .. }), "{err}");
    let err = caged.frame(&Frame { rest_cage: Some(&edit[2..]), ..Default::default() }, &mut got, None).unwrap_err();
    assert!(matches!(err, Error::CountMismatch { what: "Frame::rest_cage", .. }), "{err}");
    let mut nan = offsets.clone();
    nan[3][0] = f64::INFINITY;
    let err = coupled
        .frame(
            &Frame { joint_transforms: Some(&pose), posed_cage_offsets: Some(&nan), ..Default::default() },
            &mut got,
            None,
        )
        .unwrap_err();
    assert!(
        matches!(err, Error::Cage(CageError::NonFinite { what: "Frame::posed_cage_offsets", index: 3, .. })),
        "{err}"
    );
    println!("{err}");
    let err = Deformer::new(&input(Some(rig(None)), Some(cage_static))).unwrap_err();
    assert!(matches!(err, Error::Cage(CageError::Missing { .. })), "{err}");
    let mut open = cage_tris.clone();
    open.pop();
    let bad = CageInput { points: cage_static.points, triangles: Box::leak(open.into_boxed_slice()) };
    let err = Deformer::new(&input(None, Some(bad))).unwrap_err();
    assert!(matches!(err, Error::Cage(CageError::OpenEdge { .. })), "{err}");
}
