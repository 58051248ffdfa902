//! The rigged hand (fixtures/shots/hand_rigged) read through the schema
//! crate's UsdSkel reader and skinned by the core, against usd-core's own
//! skinning of the same stages (`UsdSkel.BakeSkinning`, written by
//! fixtures/generate.py into usdskel.usda); and its curvenets spline-skinned.

use curvenet_core::{BlendShape, BlendShapes};
use curvenet_core::{ClosestPointBvh, PolyMesh};
use curvenet_core::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, Influences, JunctionKind, MAT4_IDENTITY, Mat4, Skeleton, Skin,
    SkinningMethod, SplineSkinning, SurfaceWeights, transform_point,
};
use curvenet_e2e::{fixtures_dir, max_distance};
use curvenet_schema::usd::{CurvenetSkinning, SkinRig, Stage};
use curvenet_schema::{CurvenetData, MeshData};
use glam::DVec3;
use openusd::sdf::Value;

const SHOT: &str = "shots/hand_rigged/shot.usda";
const DQS: &str = "shots/hand_rigged/dqs.usda";
const FRAMES: std::ops::RangeInclusive<i32> = 1..=12;

/// usd-core's skinned points of `prim` (`/LBS` or `/DQS`) at `t`.
fn usdskel(prim: &str, t: f64) -> Vec<[f64; 3]> {
    let path = fixtures_dir().join("shots/hand_rigged/usdskel.usdc");
    let stage = openusd::usd::Stage::open(path.to_str().unwrap()).unwrap();
    let v = stage
        .prim(prim)
        .unwrap()
        .attribute("points")
        .get_at::<Value>(Some(openusd::usd::TimeCode::new(t)))
        .unwrap()
        .expect("points");
    match v {
        Value::Vec3fVec(p) => p.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect(),
        other => panic!("{prim}.points is {other:?}"),
    }
}

/// A rigged stage read into the core's plain inputs.
struct Rigged {
    stage: Stage,
    mesh: MeshData,
    nets: Vec<CurvenetData>,
    rig: SkinRig,
    skeleton: Skeleton,
    skin: Skin,
    shapes: BlendShapes,
    diagonal: f64,
}

impl Rigged {
    fn open(rel: &str) -> Self {
        let stage = Stage::open(fixtures_dir().join(rel)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let nets = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let rig = stage.skin_rig(&mesh).unwrap().expect("the mesh is rigged");
        let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
        let n = mesh.projection_points.len();
        let mut inf =
            Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
        assert!(inf.renormalize(1e-4).is_empty(), "the fixture's weights sum to 1");
        let skin = Skin::new(inf, rig.geom_bind_transform, rig.method).unwrap();
        let shapes = BlendShapes::new(
            n,
            mesh.blend_shapes
                .iter()
                .map(|s| {
                    let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
                    BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib).unwrap()
                })
                .collect(),
        );
        let diagonal = curvenet_core::bounding_box_diagonal(&mesh.projection_points);
        Self { stage, mesh, nets, rig, skeleton, skin, shapes, diagonal }
    }

    fn transforms(&self, t: f64) -> Vec<Mat4> {
        let local = self.stage.joint_local_transforms(&self.rig, Some(t)).unwrap();
        let mut out = vec![MAT4_IDENTITY; local.len()];
        self.skeleton.skinning_transforms(&local, &mut out).unwrap();
        assert_eq!(self.stage.skel_to_mesh_transform(&self.rig, Some(t)).unwrap(), MAT4_IDENTITY);
        out
    }

    /// UsdSkel's order: blend shapes on the bind pose, then skinning.
    fn skinned(&self, t: f64) -> Vec<[f64; 3]> {
        let mut points = self.stage.rest_points(&self.mesh, Some(t)).unwrap();
        let weights = self.stage.blend_shape_weights(&self.mesh, Some(t)).unwrap();
        self.shapes.add_to(&weights, &mut points).unwrap();
        let mut out = vec![[0.0; 3]; points.len()];
        self.skin.skin_points(&points, &self.transforms(t), &mut out).unwrap();
        out
    }
}

#[test]
fn the_reader_finds_the_rig_of_the_rigged_hand() {
    let r = Rigged::open(SHOT);
    assert_eq!(r.rig.skeleton, "/Hand/Skel");
    assert_eq!(r.rig.skel_root, "/Hand");
    assert_eq!(r.rig.animation.as_deref(), Some("/Hand/Skel/Anim"));
    assert_eq!(r.rig.joints.len(), 8);
    assert_eq!(r.rig.parents, vec![None, Some(0), Some(1), Some(2), Some(3), Some(1), Some(5), Some(6)]);
    assert_eq!((r.rig.element_size, r.rig.method), (4, SkinningMethod::ClassicLinear));
    assert_eq!(r.rig.time_samples, FRAMES.map(f64::from).collect::<Vec<_>>());
    // The points have no time samples: the rest pose is the skinning.
    assert!(r.mesh.rest_sample_times.is_empty());
    assert_eq!(Rigged::open(DQS).rig.method, SkinningMethod::DualQuaternion);
    let modes: Vec<CurvenetSkinning> = r.nets.iter().map(|n| r.stage.curvenet_skinning(n).unwrap()).collect();
    assert!(matches!(modes[0], CurvenetSkinning::Weights { element_size: 4, .. }), "{:?}", r.nets[0].path);
    assert_eq!(modes[1], CurvenetSkinning::FromMesh);
    assert_eq!(modes[2], CurvenetSkinning::None);
    // Frame 1 is the bind pose: every skinning transform is the identity.
    for m in r.transforms(1.0) {
        let err = m.iter().zip(&MAT4_IDENTITY).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-12, "{m:?}");
    }
}

/// Both methods against usd-core at every frame.
#[test]
fn skinning_matches_usd_core_at_every_frame() {
    for (rel, prim) in [(SHOT, "/LBS"), (DQS, "/DQS")] {
        let r = Rigged::open(rel);
        let (mut worst, mut moved) = (0.0f64, 0.0f64);
        for t in FRAMES.map(f64::from) {
            let got = r.skinned(t);
            let want = usdskel(prim, t);
            worst = worst.max(max_distance(&got, &want));
            moved = moved.max(max_distance(&want, &r.mesh.projection_points));
        }
        eprintln!(
            "{rel} ({}): largest difference from usd-core over frames 1-12: {:.2e} x diagonal (the skinning moves points by up to {:.3})",
            r.rig.method.token(),
            worst / r.diagonal,
            moved / r.diagonal
        );
        assert!(moved > 0.2 * r.diagonal, "the rig should move the hand");
        assert!(worst <= 1e-5 * r.diagonal, "{rel}: {worst:e}");
    }
    // The two methods differ visibly: the test above tells them apart.
    let (lbs, dqs) = (usdskel("/LBS", 12.0), usdskel("/DQS", 12.0));
    let diag = Rigged::open(SHOT).diagonal;
    assert!(max_distance(&lbs, &dqs) > 1e-3 * diag, "LBS and DQS differ by {:e}", max_distance(&lbs, &dqs));
}

fn spline_skinnings(r: &Rigged) -> Vec<(String, SplineSkinning)> {
    let n = r.mesh.projection_points.len();
    let topo = PolyMesh::new(&r.mesh.face_vertex_counts, &r.mesh.face_vertex_indices, n).unwrap();
    let bvh = ClosestPointBvh::new(&topo, &r.mesh.projection_points).unwrap();
    let mut mesh_inf =
        Influences::new(n, r.rig.element_size, &r.rig.joint_indices, &r.rig.joint_weights, r.rig.joints.len()).unwrap();
    mesh_inf.renormalize(1e-4);
    let mut out = Vec::new();
    for net in &r.nets {
        let options = Default::default();
        let spline = match r.stage.curvenet_skinning(net).unwrap() {
            CurvenetSkinning::None => continue,
            CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                let inf =
                    Influences::new(net.pool.len(), element_size, &joint_indices, &joint_weights, r.rig.joints.len())
                        .unwrap();
                let field = ControlPointWeights::new(inf);
                SplineSkinning::new(&net.pool, &net.splines, &field, &r.rig.geom_bind_transform, &options).unwrap()
            }
            CurvenetSkinning::FromMesh => {
                let surface = SurfaceWeights::new(&bvh, &mesh_inf).unwrap();
                let (field, deviation) =
                    ControlPointWeights::from_surface(&net.pool, &net.splines, &surface, DERIVED_WEIGHT_SAMPLES)
                        .unwrap();
                // (A cubic across a spline cannot follow a joint's blend over
                // 0.04: the derived weights differ from the mesh's by up to this.)
                eprintln!("{}: weights derived from the mesh's, within {deviation:.3} of them", net.path);
                assert!(deviation < 0.5, "{deviation}");
                SplineSkinning::new(&net.pool, &net.splines, &field, &r.rig.geom_bind_transform, &options).unwrap()
            }
        };
        out.push((net.path.clone(), spline));
    }
    out
}

#[test]
fn spline_skinning_of_the_rigged_curvenets_reproduces_identity_and_rigid_motions() {
    let r = Rigged::open(SHOT);
    let rigid = {
        let rot = glam::DMat3::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 1.1);
        let c = rot.to_cols_array();
        [c[0], c[1], c[2], 0.0, c[3], c[4], c[5], 0.0, c[6], c[7], c[8], 0.0, 0.2, -0.4, 0.1, 1.0]
    };
    for (path, sk) in spline_skinnings(&r) {
        let net = r.nets.iter().find(|n| n.path == path).unwrap();
        let mut out = vec![[0.0; 3]; net.pool.len()];
        sk.pose(&vec![MAT4_IDENTITY; r.rig.joints.len()], &mut out).unwrap();
        let identity = max_distance(&out, &net.pool);
        sk.pose(&vec![rigid; r.rig.joints.len()], &mut out).unwrap();
        let want: Vec<[f64; 3]> = net.pool.iter().map(|p| transform_point(&rigid, *p)).collect();
        let moved = max_distance(&out, &want);
        eprintln!(
            "{path}: identity transforms reproduce the pool to {:.1e}, one rigid transform to {:.1e} (x diagonal)",
            identity / r.diagonal,
            moved / r.diagonal
        );
        assert!(identity <= 1e-12 * r.diagonal && moved <= 1e-12 * r.diagonal);
    }
}

#[test]
fn spline_skinning_keeps_its_constraints_and_beats_naive_skinning_on_the_rigged_hand() {
    let r = Rigged::open(SHOT);
    let skinnings = spline_skinnings(&r);
    assert_eq!(skinnings.len(), 2, "IndexNet and MiddleNet are spline-skinned");
    for (path, sk) in &skinnings {
        let kinds = |f: fn(&JunctionKind) -> bool| sk.junctions().iter().filter(|j| f(&j.kind)).count();
        let (c1, g1, angle) = (
            kinds(|k| *k == JunctionKind::C1),
            kinds(|k| *k == JunctionKind::G1),
            kinds(|k| matches!(k, JunctionKind::Angle(_))),
        );
        eprintln!("{path}: {c1} C1, {g1} G1, {angle} angle junctions; joints {:?}", sk.joints());
        assert!(g1 + c1 > 0 && angle > 0, "{path}: the finger's rings and line give smooth and right-angle junctions");
        let mut lines = Vec::new();
        for t in FRAMES.map(f64::from) {
            let xf = r.transforms(t);
            let mut fit = vec![[0.0; 3]; sk.n_points()];
            let mut naive = fit.clone();
            sk.pose(&xf, &mut fit).unwrap();
            sk.pose_naive(&xf, &mut naive).unwrap();
            let residual = sk.junction_residuals(&fit, &xf).unwrap().into_iter().fold(0.0, f64::max);
            assert!(residual <= 1e-9 * r.diagonal, "{path} frame {t}: residual {residual:e}");
            // The geometry: G1/C1 tangents opposite (to the neutral pose's own
            // tolerance, carried along), angles kept.
            for j in sk.junctions() {
                let k = DVec3::from_array(fit[j.knot as usize]);
                let ua = DVec3::from_array(fit[j.ends[0].handle as usize]) - k;
                let ub = DVec3::from_array(fit[j.ends[1].handle as usize]) - k;
                match j.kind {
                    JunctionKind::Angle(a) => {
                        assert!((ua.angle_between(ub) - a).abs() <= 1e-9, "{path} frame {t}: {j:?}");
                    }
                    _ => assert!(ua.normalize().cross(ub.normalize()).length() < 2e-4 && ua.dot(ub) < 0.0, "{j:?}"),
                }
            }
            let (ours, theirs) =
                (sk.distance_to_skinned(&fit, &xf).unwrap(), sk.distance_to_skinned(&naive, &xf).unwrap());
            lines.push(format!(
                "frame {t}: spline {:.3e} (max {:.3e}), naive {:.3e} (max {:.3e})",
                ours.mean / r.diagonal,
                ours.max / r.diagonal,
                theirs.mean / r.diagonal,
                theirs.max / r.diagonal
            ));
            if t > 1.0 {
                assert!(ours.mean < theirs.mean, "{path} frame {t}: spline {ours:?}, naive {theirs:?}");
            } else {
                assert!(ours.mean <= 1e-12 * r.diagonal && theirs.mean <= 1e-12 * r.diagonal);
            }
        }
        eprintln!("{path}: integrated distance to the skinned curves (x diagonal):\n  {}", lines.join("\n  "));
        let xf = r.transforms(12.0);
        let mut flex = vec![[0.0; 3]; sk.n_points()];
        let report = sk.pose_flexible(&xf, 10, &mut flex).unwrap();
        eprintln!(
            "{path} frame 12, flexible G1: {} iterations, energy {:.4e} -> {:.4e}",
            report.iterations,
            report.energies[0],
            report.energies.last().unwrap()
        );
        assert!(report.energies.windows(2).all(|w| w[1] <= w[0] * (1.0 + 1e-9)), "{:?}", report.energies);
    }
}
