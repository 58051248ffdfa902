//! The viewer draws what the service answers and what `curvenet bake`
//! writes (issue #35): for a skinned shot (hand_skinned: a skinned rest pose
//! per frame), a rigged shot (hand_rigged: a UsdSkel skeleton bound to the
//! mesh, skinned in process, and a blend shape), a caged shot (hand_caged: a
//! cage coupled with the skeleton, skinned in process) and a blend-shaped
//! shot (hand_wave: a blend shape weighted per frame), every frame of `curvenet serve --open-stage SHOT`'s
//! viewer (`GET /v1/viewer/stages/0/frames/{k}`) has, bit for bit, the
//! points of
//!
//! - the service's answer to the same frame (`POST /v1/bindings/{id}/frames`
//!   on the same server, the frame read from the stage here as the bake
//!   reads it: posed pools, rest pose, blend-shape weights, joint transforms,
//!   cage edits), and
//! - `curvenet bake SHOT --out baked.usdc` at that time code.
//!
//! All three are `f32` (the viewer's and the service's JSON numbers, the
//! bake's `point3f[]` in USD's binary format), so they are compared as
//! `f32` bit patterns. For the caged shot the viewer's posed cage (`f32`)
//! is also, at `f32`, the posed cage of core's coupled rig evaluated here
//! from the stage's own data (`CoupledRig::evaluate`, CageUp).

use curvenet_core::{CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, PolyMesh, fan_triangles};
use curvenet_core::{Influences, MAT4_IDENTITY, Mat4, Skeleton, Skin, SkinningMethod, mat4_mul};
use curvenet_schema::usd::{SkinRig, Stage};
use curvenet_schema::wire::{BlendShapeMode, FrameRequest, FrameResponse};
use curvenet_schema::{CageData, MeshData};
use serde_json::Value;

#[allow(dead_code)] // the helpers this file does not use
mod common;

use common::Served;

const SKINNED: &str = "fixtures/shots/hand_skinned/shot.usda";
const RIGGED: &str = "fixtures/shots/hand_rigged/shot.usda";
const CAGED: &str = "fixtures/shots/hand_caged/shot.usda";
const BLEND_SHAPED: &str = "fixtures/shots/hand_wave/shot.usda";

/// A mesh's frames read from its stage as `curvenet bake` (and `serve
/// --open-stage`) read them.
struct Shot {
    stage: Stage,
    mesh: MeshData,
    nets: Vec<curvenet_schema::CurvenetData>,
    reads_rest: bool,
    /// The skeleton of a skinned mesh's rig.
    rig: Option<(SkinRig, Skeleton)>,
    cage: Option<CageData>,
}

impl Shot {
    fn open(path: &str) -> Self {
        let stage = Stage::open(common::repo().join(path)).unwrap();
        let mut meshes = stage.deformed_meshes().unwrap();
        assert_eq!(meshes.len(), 1, "{path}: one deformed mesh");
        let mesh = meshes.remove(0);
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        for n in &nets {
            assert!(stage.curvenet_adjustments(n).unwrap().is_empty(), "{path}: no Curvenet Adjustments");
        }
        let cage = stage.cage(&mesh).unwrap();
        let rig = stage.skin_rig(&mesh).unwrap().map(|rig| {
            let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
            (rig, skeleton)
        });
        // A skinned mesh reads its points per frame only when they are
        // animated; otherwise every frame's rest is its bind pose (the
        // stage's default points).
        let reads_rest = !mesh.rest_sample_times.is_empty()
            || (rig.is_none() && stage.rest_points(&mesh, None).unwrap() != mesh.projection_points);
        Self { stage, mesh, nets, reads_rest, rig, cage }
    }

    /// The skinning transforms at `time`, in the mesh's space.
    fn joint_transforms(&self, time: f64) -> Option<Vec<Mat4>> {
        let (rig, skeleton) = self.rig.as_ref()?;
        let local = self.stage.joint_local_transforms(rig, Some(time)).unwrap();
        let mut out = vec![MAT4_IDENTITY; local.len()];
        skeleton.skinning_transforms(&local, &mut out).unwrap();
        let to_mesh = self.stage.skel_to_mesh_transform(rig, Some(time)).unwrap();
        if to_mesh != MAT4_IDENTITY {
            for m in &mut out {
                *m = mat4_mul(m, &to_mesh);
            }
        }
        Some(out)
    }

    /// The frame at `time` as the service takes it.
    fn frame(&self, time: f64) -> FrameRequest {
        let t = Some(time);
        let posed = self.nets.iter().map(|n| self.stage.posed_pool(n, t).unwrap()).collect();
        let rest = match (self.reads_rest, &self.rig) {
            (true, _) => Some(self.stage.rest_points(&self.mesh, t).unwrap()),
            (false, Some(_)) => Some(self.stage.rest_points(&self.mesh, None).unwrap()),
            (false, None) => None,
        };
        // The shots author no curvenet:blendShapeOrder: UsdSkel's order
        // (before skinning) for a mesh skinned in process, after the solve
        // otherwise.
        let blend_shape_mode = if self.rig.is_some() { BlendShapeMode::Before } else { BlendShapeMode::After };
        let mut frame = FrameRequest {
            posed: Some(posed),
            rest,
            blend_shape_mode,
            blend_shape_weights: (!self.mesh.blend_shapes.is_empty())
                .then(|| self.stage.blend_shape_weights(&self.mesh, t).unwrap()),
            joint_transforms: self.joint_transforms(time),
            ..FrameRequest::default()
        };
        if let Some(cage) = &self.cage {
            let edits = cage.frame(t);
            frame.rest_cage = edits.rest_cage().map(<[_]>::to_vec);
            frame.posed_cage_offsets = edits.posed_cage_offsets().map(<[_]>::to_vec);
        }
        frame
    }

    /// The posed cage of core's coupled rig at `time`, from the stage's data.
    fn posed_cage(&self, coupled: &CoupledRig, time: f64) -> Vec<[f64; 3]> {
        let cage = self.cage.as_ref().unwrap();
        let transforms = self.joint_transforms(time);
        let edits = cage.frame(Some(time));
        let input = CageFrame {
            base: None,
            rest_cage: edits.rest_cage(),
            joint_transforms: transforms.as_deref(),
            posed_cage_offsets: edits.posed_cage_offsets(),
        };
        let mut ws = CoupledWorkspace::default();
        let mut rest = vec![[0.0; 3]; self.mesh.projection_points.len()];
        coupled.evaluate(&input, &mut ws, &mut rest).unwrap();
        ws.posed_cage().to_vec()
    }

    /// Core's coupled rig of a caged mesh with its skeleton.
    fn coupled_rig(&self) -> CoupledRig {
        let (rig, skeleton) = self.rig.as_ref().unwrap();
        let cage = self.cage.as_ref().unwrap();
        let mesh = &self.mesh;
        let n = mesh.projection_points.len();
        let mut influences =
            Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
        influences.renormalize(1e-4);
        let skin = Skin::new(influences, rig.geom_bind_transform, SkinningMethod::CentersOfRotation).unwrap();
        let topology = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n).unwrap();
        CoupledRig::new(
            &cage.rest_points,
            &cage.triangles,
            &mesh.projection_points,
            &fan_triangles(&topology),
            Some((skeleton, &skin)),
            CageRevApproximation::default(),
        )
        .unwrap()
    }
}

/// f32 values sent as JSON numbers (their shortest decimals), read back as those f32.
fn f32s(v: &Value) -> Vec<f32> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The largest difference of two equally long f32 arrays (for the message).
fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Opens `path` in `curvenet serve --open-stage`, bakes it, and checks every
/// frame: the viewer's points are the service's and the bake's, bit for bit
/// (and, for a caged shot, the viewer's cage is core's posed cage at f32).
/// Returns how far the frames moved from the first (to show they move).
async fn agrees(path: &str, frames: usize) -> f32 {
    let shot = Shot::open(path);
    let server = Served::start(&["--open-stage", path]);
    let client = reqwest::Client::new();
    let base = &server.url;
    let get = |url: String| common::get_json(client.clone(), url);
    let listed = get(format!("{base}/v1/viewer/stages")).await;
    let times: Vec<f64> =
        listed["stages"][0]["times"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap()).collect();
    assert_eq!(times.len(), frames, "{path}: its frames");
    let opened = get(format!("{base}/v1/viewer/stages/0")).await;
    let id = opened["binding"]["binding_id"].as_str().unwrap().to_string();

    let dir = common::temp_dir("viewer-agrees", path.split('/').nth(2).unwrap());
    let out = dir.join("baked.usdc");
    let run = common::curvenet(&["bake", path, "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", common::stderr(&run));
    let mut baked = curvenet_schema::usd::read_points_overrides(&out).unwrap().prims;
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(baked.len(), 1, "{path}: one mesh baked");
    let baked = baked.remove(0).samples;
    assert_eq!(baked.iter().map(|(t, _)| *t).collect::<Vec<_>>(), times, "{path}: the bake's time codes");

    let coupled = shot.cage.as_ref().map(|_| shot.coupled_rig());
    let mut first: Option<Vec<f32>> = None;
    let mut moved = 0.0f32;
    for (k, &t) in times.iter().enumerate() {
        let viewer = get(format!("{base}/v1/viewer/stages/0/frames/{k}")).await;
        let shown = f32s(&viewer["points"]);
        let r = client.post(format!("{base}/v1/bindings/{id}/frames")).json(&shot.frame(t)).send().await.unwrap();
        assert_eq!(r.status(), 200, "{path} frame {t}: {}", r.text().await.unwrap());
        let answered: FrameResponse = r.json().await.unwrap();
        let service: Vec<f32> = answered.points.as_flattened().to_vec();
        let bake: Vec<f32> = baked[k].1.as_flattened().to_vec();
        assert_eq!(shown.len(), 3 * shot.mesh.projection_points.len(), "{path} frame {t}: one point per vertex");
        assert!(
            bits(&shown) == bits(&service),
            "{path} frame {t}: the viewer is {} off the service's frame",
            max_diff(&shown, &service)
        );
        assert!(
            bits(&shown) == bits(&bake),
            "{path} frame {t}: the viewer is {} off the bake",
            max_diff(&shown, &bake)
        );
        match &coupled {
            None => assert!(viewer.get("cage").is_none(), "{path}: no cage"),
            Some(coupled) => {
                let want: Vec<f32> = shot.posed_cage(coupled, t).as_flattened().iter().map(|&x| x as f32).collect();
                let drawn = f32s(&viewer["cage"]);
                assert!(
                    bits(&drawn) == bits(&want),
                    "{path} frame {t}: the drawn cage is {} off core's posed cage",
                    max_diff(&drawn, &want)
                );
            }
        }
        match &first {
            None => first = Some(shown),
            Some(f) => moved = moved.max(max_diff(&shown, f)),
        }
    }
    moved
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_skinned_shot_is_drawn_as_served_and_baked() {
    let moved = agrees(SKINNED, 12).await;
    assert!(moved > 1e-2, "the skinned frames move ({moved})");
}

/// A rigged mesh without a cage is skinned by the viewer as the bake skins
/// it (found by a hostile review: the viewer had read the rig of caged
/// meshes only, and drew hand_rigged up to 0.40 off the bake).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rigged_shot_is_drawn_as_served_and_baked() {
    let shot = Shot::open(RIGGED);
    assert!(shot.cage.is_none() && shot.rig.is_some(), "hand_rigged: a skeleton, no cage");
    let moved = agrees(RIGGED, 12).await;
    assert!(moved > 1e-2, "the rigged frames move ({moved})");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_caged_shot_is_drawn_as_served_and_baked() {
    let shot = Shot::open(CAGED);
    assert!(shot.cage.is_some() && shot.rig.is_some(), "hand_caged: a cage coupled with a skeleton");
    let moved = agrees(CAGED, 10).await;
    assert!(moved > 1e-2, "the caged frames move ({moved})");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_blend_shaped_shot_is_drawn_as_served_and_baked() {
    let shot = Shot::open(BLEND_SHAPED);
    assert!(!shot.mesh.blend_shapes.is_empty(), "hand_wave: blend shapes");
    let moved = agrees(BLEND_SHAPED, 24).await;
    assert!(moved > 1e-2, "the blend-shaped frames move ({moved})");
}
