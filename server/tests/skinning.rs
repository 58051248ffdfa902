//! `curvenet bake` and `curvenet inspect` on the rigged hand
//! (fixtures/shots/hand_rigged): one command skins the mesh and
//! spline-skins its curvenets; the result equals usd-core's skinning fed to
//! the existing curvenet solve with the spline-skinned pools.

use curvenet_core::{ClosestPointBvh, CurvenetInput, Deformer, DeformerInput, Frame, PolyMesh};
use curvenet_core::{
    ControlPointWeights, DERIVED_WEIGHT_SAMPLES, Influences, MAT4_IDENTITY, Mat4, Skeleton, SplineSkinning,
    SurfaceWeights, skin_points,
};
use curvenet_schema::usd::{CurvenetSkinning, Stage, read_points_overrides};
use openusd::sdf::Value;

mod common;
use common::{curvenet, max_dist, repo, stderr};

const SHOT: &str = "fixtures/shots/hand_rigged/shot.usda";
const DQS: &str = "fixtures/shots/hand_rigged/dqs.usda";

fn usdskel(prim: &str, t: f64) -> Vec<[f64; 3]> {
    let path = repo().join("fixtures/shots/hand_rigged/usdskel.usdc");
    let stage = openusd::usd::Stage::open(path.to_str().unwrap()).unwrap();
    match stage.prim(prim).unwrap().attribute("points").get_at::<Value>(Some(openusd::usd::TimeCode::new(t))) {
        Ok(Some(Value::Vec3fVec(p))) => p.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect(),
        other => panic!("{prim}.points: {other:?}"),
    }
}

/// The existing curvenet solve of the rigged shot with a given rest pose per
/// frame, the pools of the spline-skinned curvenets computed from the
/// stage's plain data, and knot tracking for the other one.
struct Reference {
    stage: Stage,
    /// The plain deformer (no rig): the existing curvenet solve.
    deformer: Deformer,
    rig: curvenet_schema::usd::SkinRig,
    skeleton: Skeleton,
    splines: Vec<Option<SplineSkinning>>,
    diagonal: f64,
    /// Blend shapes to add after the solve (`afterSolve`).
    after: Option<curvenet_core::BlendShapes>,
}

impl Reference {
    /// `rel`: relative to the repository, or absolute.
    fn new(rel: &str) -> Self {
        let stage = Stage::open(repo().join(rel)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let n = mesh.projection_points.len();
        let topology = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n).unwrap();
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let inputs: Vec<CurvenetInput> = nets.iter().map(curvenet_schema::CurvenetData::input).collect();
        let deformer = Deformer::new(&DeformerInput { ..curvenet_schema::deformer_input(&mesh, &inputs) }).unwrap();
        let rig = stage.skin_rig(&mesh).unwrap().unwrap();
        let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
        let bvh = ClosestPointBvh::new(&topology, &mesh.projection_points).unwrap();
        let mut mesh_weights =
            Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
        mesh_weights.renormalize(1e-4);
        let splines = nets
            .iter()
            .map(|c| {
                let o = Default::default();
                match stage.curvenet_skinning(c).unwrap() {
                    CurvenetSkinning::None => None,
                    CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                        let inf =
                            Influences::new(c.pool.len(), element_size, &joint_indices, &joint_weights, 8).unwrap();
                        let f = ControlPointWeights::new(inf);
                        Some(SplineSkinning::new(&c.pool, &c.splines, &f, &rig.geom_bind_transform, &o).unwrap())
                    }
                    CurvenetSkinning::FromMesh => {
                        let surface = SurfaceWeights::new(&bvh, &mesh_weights).unwrap();
                        let (f, _) =
                            ControlPointWeights::from_surface(&c.pool, &c.splines, &surface, DERIVED_WEIGHT_SAMPLES)
                                .unwrap();
                        Some(SplineSkinning::new(&c.pool, &c.splines, &f, &rig.geom_bind_transform, &o).unwrap())
                    }
                }
            })
            .collect();
        let diagonal = curvenet_core::bounding_box_diagonal(&mesh.projection_points);
        Self { stage, deformer, rig, skeleton, splines, diagonal, after: None }
    }

    fn transforms(&self, t: f64) -> Vec<Mat4> {
        let local = self.stage.joint_local_transforms(&self.rig, Some(t)).unwrap();
        let mut out = vec![MAT4_IDENTITY; local.len()];
        self.skeleton.skinning_transforms(&local, &mut out).unwrap();
        out
    }

    fn deform(&self, t: f64, rest: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let xf = self.transforms(t);
        let pools: Vec<Option<Vec<[f64; 3]>>> = self
            .splines
            .iter()
            .map(|s| {
                s.as_ref().map(|s| {
                    let mut out = vec![[0.0; 3]; s.n_points()];
                    s.pose(&xf, &mut out).unwrap();
                    out
                })
            })
            .collect();
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| p.as_deref()).collect();
        let mut out = vec![[0.0; 3]; self.deformer.n_vertices()];
        let mut gradients = vec![[0.0; 9]; out.len()];
        self.deformer
            .frame(&Frame { posed: &posed, rest: Some(rest), ..Default::default() }, &mut out, Some(&mut gradients))
            .unwrap();
        if let Some(shapes) = &self.after {
            let mesh = self.stage.deformed_meshes().unwrap().remove(0);
            let weights = self.stage.blend_shape_weights(&mesh, Some(t)).unwrap();
            shapes.add_deformed(&weights, &gradients, &mut out).unwrap();
        }
        out
    }

    /// The mesh's points skinned by the core (no blend shapes).
    fn skinned(&self, t: f64) -> Vec<[f64; 3]> {
        let mesh = self.stage.deformed_meshes().unwrap().remove(0);
        let n = mesh.projection_points.len();
        let rig = &self.rig;
        let mut inf =
            Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
        inf.renormalize(1e-4);
        let points = self.stage.rest_points(&mesh, Some(t)).unwrap();
        let mut out = vec![[0.0; 3]; n];
        skin_points(rig.method, &points, &inf, &rig.geom_bind_transform, &self.transforms(t), &mut out).unwrap();
        out
    }
}

#[test]
fn blend_shapes_asked_after_the_solve_are_added_in_the_deformed_frames() {
    use curvenet_core::{BlendShape, BlendShapes};
    let dir = common::temp_dir("skinning", "after");
    let layer = dir.join("after.usda");
    std::fs::write(
        &layer,
        format!(
            "#usda 1.0\n(\n    subLayers = [@{}@]\n    startTimeCode = 1\n    endTimeCode = 12\n)\n\
             over \"Hand\" {{\n over \"Mesh\" {{\n uniform token curvenet:blendShapeOrder = \"afterSolve\"\n }}\n}}\n",
            repo().join(SHOT).display()
        ),
    )
    .unwrap();
    let (after, before) = (dir.join("after_bake.usda"), dir.join("before_bake.usda"));
    for (input, out) in [(layer.to_str().unwrap(), &after), (SHOT, &before)] {
        let run = curvenet(&["bake", input, "--out", out.to_str().unwrap(), "--frames", "12"]);
        assert!(run.status.success(), "{}", stderr(&run));
    }
    let mut reference = Reference::new(layer.to_str().unwrap());
    let mesh = reference.stage.deformed_meshes().unwrap().remove(0);
    let n = mesh.projection_points.len();
    let shapes = mesh
        .blend_shapes
        .iter()
        .map(|s| {
            let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
            BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib).unwrap()
        })
        .collect();
    reference.after = Some(BlendShapes::new(n, shapes));
    let want = reference.deform(12.0, &reference.skinned(12.0));
    let read = |p: &std::path::Path| -> Vec<[f64; 3]> {
        read_points_overrides(p).unwrap().prims[0].samples[0].1.iter().map(|q| q.map(f64::from)).collect()
    };
    let (got, other) = (read(&after), read(&before));
    let (err, order) = (max_dist(&got, &want), max_dist(&got, &other));
    eprintln!(
        "afterSolve: the bake equals skinning, the solve, then the blend shape in the deformed frames to {:.2e} x \
         diagonal; it differs from UsdSkel's order by {:.2e}",
        err / reference.diagonal,
        order / reference.diagonal
    );
    assert!(err <= 1e-6 * reference.diagonal, "{err:e}");
    assert!(order > 1e-4 * reference.diagonal, "the order should matter at frame 12 ({order:e})");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn one_bake_of_the_rigged_shot_equals_usd_core_skinning_then_the_curvenet_solve() {
    let dir = common::temp_dir("skinning", "bake");
    for (rel, prim) in [(SHOT, "/LBS"), (DQS, "/DQS")] {
        let out = dir.join("bake.usda");
        let run = curvenet(&["bake", rel, "--out", out.to_str().unwrap()]);
        assert!(run.status.success(), "{rel}: {}", stderr(&run));
        let baked = read_points_overrides(&out).unwrap();
        assert_eq!(baked.time_range, (1.0, 12.0));
        assert_eq!(baked.prims.len(), 1);
        assert_eq!(baked.prims[0].prim, "/Hand/Mesh");
        let reference = Reference::new(rel);
        let (mut worst, mut moved, mut articulated) = (0.0f64, 0.0f64, 0.0f64);
        for (t, points) in &baked.prims[0].samples {
            let got: Vec<[f64; 3]> = points.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect();
            let rest = usdskel(prim, *t);
            let want = reference.deform(*t, &rest);
            worst = worst.max(max_dist(&got, &want));
            moved = moved.max(max_dist(&got, &usdskel("/LBS", 1.0)));
            articulated = articulated.max(max_dist(&want, &rest));
        }
        eprintln!(
            "{rel}: the bake equals usd-core skinning + the curvenet solve to {:.2e} x diagonal over 12 frames \
             (the points move up to {:.3}; the curvenets move them off the skinned rest pose by up to {:.2e})",
            worst / reference.diagonal,
            moved / reference.diagonal,
            articulated / reference.diagonal
        );
        assert!(worst <= 1e-6 * reference.diagonal, "{rel}: {worst:e}");
        assert!(moved > 0.2 * reference.diagonal);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn inspect_reports_the_rig_and_the_spline_skinning() {
    let run = curvenet(&["inspect", SHOT, "--json", "--time", "12"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let rig = &report["meshes"][0]["rig"];
    assert_eq!(rig["skeleton"], "/Hand/Skel");
    assert_eq!(rig["animation"], "/Hand/Skel/Anim");
    assert_eq!(rig["joints"].as_array().unwrap().len(), 8);
    assert_eq!(rig["method"], "classicLinear");
    assert_eq!(rig["influences_per_point"], 4);
    assert_eq!(rig["animation_frames"], 12);
    assert_eq!(rig["blend_shape_order"], "beforeSkinning");
    let nets = rig["curvenets"].as_array().unwrap();
    let modes: Vec<&str> = nets.iter().map(|n| n["skinning"].as_str().unwrap()).collect();
    assert_eq!(modes, ["weights", "mesh", "none"]);
    for n in &nets[..2] {
        let d = &n["distance_at_time"];
        let (ours, naive) = (d["spline_mean"].as_f64().unwrap(), d["naive_mean"].as_f64().unwrap());
        assert!(ours < naive, "{n}");
        assert!(n["angle_junctions"].as_u64().unwrap() > 0, "{n}");
    }
    let text = curvenet(&["inspect", SHOT, "--time", "12"]);
    let text = String::from_utf8(text.stdout).unwrap();
    assert!(text.contains("rig: skeleton /Hand/Skel (8 joints: wrist, palm, index_mcp"), "{text}");
    assert!(
        text.contains("curvenet /Hand/MiddleNet: spline-skinned (weights from the mesh, per control point"),
        "{text}"
    );
    assert!(
        nets[1]["derived_weight_deviation"].as_f64().unwrap() < 0.5 && nets[0]["derived_weight_deviation"].is_null()
    );
    assert!(text.contains("naive control points"), "{text}");
}

#[test]
fn curvenet_skinning_without_a_rig_or_with_bad_weights_is_refused_naming_the_prim() {
    let dir = common::temp_dir("skinning", "bad");
    let layer = |name: &str, body: &str| {
        let path = dir.join(name);
        let hand = repo().join("fixtures/hand/hand_1k4.usda");
        std::fs::write(&path, format!("#usda 1.0\n(\n    subLayers = [@{}@]\n)\n{body}\n", hand.display())).unwrap();
        path
    };
    let out = dir.join("out.usda");
    let no_rig = layer(
        "no_rig.usda",
        "over \"Hand\" {\n over \"Curvenet\" {\n uniform token curvenet:skinning = \"mesh\"\n }\n}",
    );
    let run = curvenet(&["bake", no_rig.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", "1"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("/Hand/Curvenet: asks for spline skinning") && stderr(&run).contains("/Hand/Mesh"));

    let bad_token = layer(
        "bad_token.usda",
        "over \"Hand\" {\n over \"Curvenet\" {\n uniform token curvenet:skinning = \"lbs\"\n }\n}",
    );
    let run = curvenet(&["bake", bad_token.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", "1"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("/Hand/Curvenet: curvenet:skinning is \"lbs\""), "{}", stderr(&run));

    // A joint index past the skeleton's 8 joints, in the rigged shot.
    let rigged = repo().join(SHOT);
    let path = dir.join("bad_index.usda");
    let n = 43;
    let mut idx = vec!["0"; 4 * n];
    idx[4 * 5 + 1] = "99";
    let w: Vec<&str> = (0..4 * n).map(|k| if k % 4 == 0 { "1" } else { "0" }).collect();
    std::fs::write(
        &path,
        format!(
            "#usda 1.0\n(\n    subLayers = [@{}@]\n)\nover \"Hand\" {{\n over \"IndexNet\" {{\n \
             int[] primvars:curvenet:skel:jointIndices = [{}] (elementSize = 4 interpolation = \"vertex\")\n \
             float[] primvars:curvenet:skel:jointWeights = [{}] (elementSize = 4 interpolation = \"vertex\")\n }}\n}}\n",
            rigged.display(),
            idx.join(", "),
            w.join(", ")
        ),
    )
    .unwrap();
    let run = curvenet(&["bake", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", "1"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(
        err.contains("/Hand/IndexNet") && err.contains("point 5, influence 1: joint index 99 is outside 0..8"),
        "{err}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn g1_flexible_spline_skinning_is_an_option_whose_iterations_the_bake_reports() {
    let dir = common::temp_dir("skinning", "flexible");
    let (fixed, flexible) = (dir.join("fixed.usda"), dir.join("flexible.usda"));
    let run = curvenet(&["bake", SHOT, "--out", fixed.to_str().unwrap(), "--frames", "12"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(!stderr(&run).contains("G1-flexible"), "{}", stderr(&run));
    let run = curvenet(&["bake", SHOT, "--out", flexible.to_str().unwrap(), "--frames", "12", "--g1-flexible", "6"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let err = stderr(&run);
    eprintln!("{err}");
    // Two spline-skinned curvenets, one frame: two poses, 1 to 6 iterations each.
    let iterations: usize = err
        .split("G1-flexible spline skinning: ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no iteration count in {err}"));
    assert!((2..=12).contains(&iterations) && err.contains("over 2 curvenet poses"), "{err}");
    let a = &read_points_overrides(&fixed).unwrap().prims[0].samples[0].1;
    let b = &read_points_overrides(&flexible).unwrap().prims[0].samples[0].1;
    let moved =
        a.iter().zip(b).map(|(p, q)| (0..3).map(|i| (p[i] - q[i]).abs()).fold(0.0f32, f32::max)).fold(0.0, f32::max);
    assert!(moved > 0.0, "the flexible ratios should change the posed curvenets, hence the mesh");
    std::fs::remove_dir_all(&dir).unwrap();
}
