//! `curvenet bake` and `curvenet inspect` on the caged hands
//! (fixtures/shots/hand_caged: a cage coupled with the rigged hand's
//! skeleton, centres-of-rotation skinning, rest-cage edits, a pose and
//! posed-cage edits; fixtures/shots/hand_cage_only: the cage alone). The
//! bake, read back from its layer, equals the core's coupled rig
//! (`CoupledRig`, Corda et al. 2020) evaluated in this process from the
//! stage's plain data and fed to the plain curvenet solve as the frame's
//! rest pose.

use curvenet_core::{CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
use curvenet_core::{CurvenetInput, Deformer, Frame, PolyMesh};
use curvenet_core::{Influences, MAT4_IDENTITY, Mat4, Skeleton, Skin, SkinningMethod};
use curvenet_schema::usd::{CurvenetSkinningMethod, Stage, read_points_overrides};

mod common;
use common::{curvenet, max_dist, repo, stderr};

const CAGED: &str = "fixtures/shots/hand_caged/shot.usda";
const CAGE_ONLY: &str = "fixtures/shots/hand_cage_only/shot.usda";

/// The shot evaluated in process: the coupled rig built from the stage's
/// cage, skeleton and skin, then the plain curvenet solve (no rig) with the
/// coupled result as the frame's rest pose.
struct Reference {
    stage: Stage,
    cage: curvenet_schema::CageData,
    coupled: CoupledRig,
    skel: Option<(curvenet_schema::usd::SkinRig, Skeleton)>,
    deformer: Deformer,
    diagonal: f64,
}

impl Reference {
    fn new(rel: &str) -> Self {
        let stage = Stage::open(repo().join(rel)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let n = mesh.projection_points.len();
        let cage = stage.cage(&mesh).unwrap().expect("the fixture's mesh has a cage");
        let topology = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n).unwrap();
        let triangles = fan_triangles(&topology);
        let skel = stage.skin_rig(&mesh).unwrap().map(|rig| {
            let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
            (rig, skeleton)
        });
        let skin = skel.as_ref().map(|(rig, _)| {
            let mut inf =
                Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
            inf.renormalize(1e-4);
            // The fixture asks for centres of rotation (curvenet:skinningMethod).
            assert_eq!(rig.curvenet_method, Some(CurvenetSkinningMethod::CentersOfRotation));
            Skin::new(inf, rig.geom_bind_transform, SkinningMethod::CentersOfRotation).unwrap()
        });
        let skinning = skel.as_ref().zip(skin.as_ref()).map(|((_, s), k)| (s, k));
        let coupled = CoupledRig::new(
            &cage.rest_points,
            &cage.triangles,
            &mesh.projection_points,
            &triangles,
            skinning,
            CageRevApproximation::default(),
        )
        .unwrap();
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let inputs: Vec<CurvenetInput> = nets.iter().map(curvenet_schema::CurvenetData::input).collect();
        let deformer = Deformer::new(&curvenet_schema::deformer_input(&mesh, &inputs)).unwrap();
        let diagonal = curvenet_core::bounding_box_diagonal(&mesh.projection_points);
        Self { stage, cage, coupled, skel, deformer, diagonal }
    }

    fn transforms(&self, t: f64) -> Option<Vec<Mat4>> {
        let (rig, skeleton) = self.skel.as_ref()?;
        let local = self.stage.joint_local_transforms(rig, Some(t)).unwrap();
        let mut out = vec![MAT4_IDENTITY; local.len()];
        skeleton.skinning_transforms(&local, &mut out).unwrap();
        Some(out)
    }

    /// The coupled rig's mesh at `t` (the curvenet's rest pose).
    fn rest(&self, t: f64) -> Vec<[f64; 3]> {
        let xf = self.transforms(t);
        let edits = self.cage.frame(Some(t));
        let mut ws = CoupledWorkspace::default();
        let mut rest = vec![[0.0; 3]; self.coupled.n_points()];
        let frame = CageFrame {
            base: None,
            rest_cage: edits.rest_cage(),
            joint_transforms: xf.as_deref(),
            posed_cage_offsets: edits.posed_cage_offsets(),
        };
        self.coupled.evaluate(&frame, &mut ws, &mut rest).unwrap();
        rest
    }

    fn deform(&self, t: f64) -> Vec<[f64; 3]> {
        let rest = self.rest(t);
        let mut out = vec![[0.0; 3]; rest.len()];
        self.deformer.frame(&Frame { rest: Some(&rest), ..Default::default() }, &mut out, None).unwrap();
        out
    }
}

fn bake(rel: &str, tag: &str) -> Vec<(f64, Vec<[f64; 3]>)> {
    let dir = common::temp_dir("cage", tag);
    let out = dir.join("bake.usda");
    let run = curvenet(&["bake", rel, "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{rel}: {}", stderr(&run));
    let baked = read_points_overrides(&out).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(baked.prims.len(), 1);
    baked.prims[0]
        .samples
        .iter()
        .map(|(t, p)| (*t, p.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect()))
        .collect()
}

#[test]
fn a_bake_of_the_caged_hand_equals_the_coupled_rig_then_the_curvenet_solve() {
    let baked = bake(CAGED, "coupled");
    let times: Vec<f64> = baked.iter().map(|(t, _)| *t).collect();
    assert_eq!(times, (1..=10).map(f64::from).collect::<Vec<_>>(), "the bake covers the cage's frames");
    let reference = Reference::new(CAGED);
    let d = reference.diagonal;
    let mut worst = 0.0f64;
    for (t, got) in &baked {
        let want = reference.deform(*t);
        let e = max_dist(got, &want);
        worst = worst.max(e);
        assert!(e <= 1e-6 * d, "frame {t}: the bake is {:.2e} x diagonal off the in-process evaluation", e / d);
    }
    // Each kind of edit changes the result: rest-cage edits (frames 2, 3), the
    // pose (4, 5), posed-cage edits (6, 7), against frame 1 (no edit).
    let first = &baked[0].1;
    let moved: Vec<f64> = baked.iter().map(|(_, p)| max_dist(p, first) / d).collect();
    eprintln!(
        "caged hand: the bake equals the in-process coupled rig + curvenet solve to {:.2e} x diagonal; largest \
         move from frame 1 per frame (x diagonal): {moved:.3?}",
        worst / d
    );
    for (k, label) in [(2, "rest-cage edit"), (4, "pose"), (6, "posed-cage edit"), (9, "all three")] {
        assert!(moved[k] > 1e-2, "frame {}: the {label} moves the mesh only {:.2e} x diagonal", k + 1, moved[k]);
    }
    // A posed-cage edit is honoured: frame 7's cage (no rest edit, no pose)
    // reproduces the edited posed cage at the MaxVol rows, so the rest pose
    // moves by about the authored 0.03 puff.
    let rest7 = reference.rest(7.0);
    let rest1 = reference.rest(1.0);
    let puff = max_dist(&rest7, &rest1);
    assert!(puff > 0.01 && puff < 0.1, "the posed-cage edit of frame 7 moves the rest pose by {puff}");
}

#[test]
fn a_bake_of_the_cage_alone_is_phi_times_the_edited_cage() {
    let baked = bake(CAGE_ONLY, "alone");
    let reference = Reference::new(CAGE_ONLY);
    assert!(reference.skel.is_none());
    let d = reference.diagonal;
    for (t, got) in &baked {
        let want = reference.deform(*t);
        let e = max_dist(got, &want);
        assert!(e <= 1e-6 * d, "frame {t}: {:.2e} x diagonal", e / d);
    }
    // Frame 1 is the bind cage: the input mesh (the curvenet tracks it).
    let mesh = reference.stage.deformed_meshes().unwrap().remove(0);
    assert!(max_dist(&baked[0].1, &mesh.projection_points) <= 1e-6 * d);
    assert!(max_dist(&baked[2].1, &mesh.projection_points) > 1e-2 * d, "the rest-cage edit moves the mesh");
}

#[test]
fn inspect_reports_the_cage_its_maxvol_rows_and_conditioning() {
    let run = curvenet(&["inspect", CAGED, "--json"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let mesh = &report["meshes"][0];
    let cage = &mesh["cage"];
    assert_eq!(cage["vertices"], 170, "{cage}");
    assert_eq!(cage["triangles"], 336);
    assert_eq!(cage["coupled"], true);
    assert_eq!(cage["maxvol_rows"].as_array().unwrap().len(), 170, "one MaxVol row per cage vertex");
    let condition = cage["condition"].as_f64().unwrap();
    assert!(condition.is_finite() && condition >= 1.0, "{condition}");
    assert!(cage["bind_residual"].as_f64().unwrap() < 1e-9);
    assert_eq!(mesh["rig"]["method"], "centersOfRotation");
    let text = String::from_utf8(curvenet(&["inspect", CAGED]).stdout).unwrap();
    assert!(text.contains("cage: /"), "{text}");
    assert!(text.contains("coupled with the skeleton"), "{text}");
    let alone: serde_json::Value = serde_json::from_slice(&curvenet(&["inspect", CAGE_ONLY, "--json"]).stdout).unwrap();
    assert_eq!(alone["meshes"][0]["cage"]["coupled"], false);
}

/// A layer over the cage-only shot that re-targets or moves the cage.
fn over_cage_only(dir: &std::path::Path, name: &str, body: &str) -> std::path::PathBuf {
    let shot = repo().join(CAGE_ONLY);
    let path = dir.join(format!("{name}.usda"));
    std::fs::write(&path, format!("#usda 1.0\n(\n    subLayers = [@{}@]\n)\n\n{body}\n", shot.display())).unwrap();
    path
}

#[test]
fn a_cage_that_is_the_mesh_itself_or_leaves_points_outside_is_refused_naming_it() {
    let dir = common::temp_dir("cage", "refused");
    let out = dir.join("out.usda");
    let self_cage = over_cage_only(
        &dir,
        "self",
        "over \"Hand\"\n{\n    over \"Mesh\"\n    {\n        rel curvenet:cage = </Hand/Mesh>\n    }\n}",
    );
    let run = curvenet(&["bake", self_cage.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("curvenet:cage") && stderr(&run).contains("the mesh itself"), "{}", stderr(&run));
    assert!(!out.exists(), "nothing is written on failure");
    // Moving every cage point far away (its points default re-authored).
    let stage = Stage::open(repo().join(CAGE_ONLY)).unwrap();
    let mesh = stage.deformed_meshes().unwrap().remove(0);
    let cage = stage.cage(&mesh).unwrap().unwrap();
    let moved: Vec<String> =
        cage.rest_points.iter().map(|p| format!("({}, {}, {})", p[0] + 100.0, p[1], p[2])).collect();
    let far_points = over_cage_only(
        &dir,
        "far_points",
        &format!(
            "over \"Hand\"\n{{\n    over \"Cage\"\n    {{\n        point3f[] points = [{}]\n    }}\n}}",
            moved.join(", ")
        ),
    );
    let run = curvenet(&["bake", far_points.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", "1"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("outside the cage"), "{}", stderr(&run));
    std::fs::remove_dir_all(&dir).unwrap();
}
