//! The rig underneath over HTTP (issue 17, the service part): a binding
//! carrying the mesh's UsdSkel skin and its curvenets' spline skinning, and
//! frames carrying only joint transforms (and blend-shape weights), answer
//! what `curvenet bake` writes for fixtures/shots/hand_rigged.

use axum::Router;
use axum::body::{Body, Bytes};
use axum::http::{Request, StatusCode, header};
use curvenet_core::{Mat4, Skeleton, SkinningMethod};
use curvenet_schema::usd::{CurvenetSkinning, Stage, read_points_overrides};
use curvenet_schema::wire::{
    BindingRequest, BindingResponse, BlendShapeMode, CurvenetSkinSpec, FrameRequest, FrameResponse, SkinMethod,
    SkinSpec,
};
use curvenet_server::{AppState, Config, app};
use serde_json::Value;
use tower::ServiceExt as _;

#[allow(dead_code)] // the helpers this file does not use
mod common;
use common::{curvenet, max_dist, repo, stderr};

const SHOT: &str = "fixtures/shots/hand_rigged/shot.usda";

async fn send(app: &Router, uri: &str, body: &impl serde::Serialize) -> (StatusCode, Bytes) {
    let req = Request::post(uri)
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(serde_json::to_vec(body).unwrap()))
        .unwrap();
    let r = app.clone().oneshot(req).await.unwrap();
    let status = r.status();
    (status, axum::body::to_bytes(r.into_body(), usize::MAX).await.unwrap())
}

/// The shot read the way a client reading USD itself would: the binding
/// request with its skin, and each frame's skinning transforms.
struct Shot {
    stage: Stage,
    mesh: curvenet_schema::MeshData,
    rig: curvenet_schema::usd::SkinRig,
    skeleton: Skeleton,
    request: BindingRequest,
}

impl Shot {
    fn new() -> Self {
        let stage = Stage::open(repo().join(SHOT)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let rig = stage.skin_rig(&mesh).unwrap().expect("the shot is skinned");
        let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
        let mut request = BindingRequest::from_stage(&mesh, &nets);
        let curvenets = nets
            .iter()
            .map(|n| match stage.curvenet_skinning(n).unwrap() {
                CurvenetSkinning::None => CurvenetSkinSpec::None,
                CurvenetSkinning::FromMesh => CurvenetSkinSpec::Mesh,
                CurvenetSkinning::Weights { element_size, joint_indices, joint_weights } => {
                    CurvenetSkinSpec::Weights { element_size: element_size as u32, joint_indices, joint_weights }
                }
            })
            .collect::<Vec<_>>();
        assert!(curvenets.contains(&CurvenetSkinSpec::Mesh), "the shot has a curvenet skinned from the mesh");
        assert!(curvenets.iter().any(|c| matches!(c, CurvenetSkinSpec::Weights { .. })), "and one with weights");
        request.skin = Some(SkinSpec {
            joints: rig.joints.len() as u32,
            element_size: rig.element_size as u32,
            joint_indices: rig.joint_indices.clone(),
            joint_weights: rig.joint_weights.clone(),
            geom_bind_transform: Some(rig.geom_bind_transform),
            method: match rig.method {
                SkinningMethod::ClassicLinear => SkinMethod::ClassicLinear,
                SkinningMethod::DualQuaternion => SkinMethod::DualQuaternion,
                other => panic!("the shot's skinning method {other:?} has no wire spelling"),
            },
            curvenets,
            flexible_iterations: 0,
            skeleton: None,
        });
        Self { stage, mesh, rig, skeleton, request }
    }

    /// Frame `t` as joint transforms and blend-shape weights (the mesh's own
    /// points only when they differ from the projection pose).
    fn frame(&self, t: f64) -> FrameRequest {
        let rest = self.stage.rest_points(&self.mesh, Some(t)).unwrap();
        FrameRequest {
            rest: (rest != self.mesh.projection_points).then_some(rest),
            blend_shape_weights: Some(self.stage.blend_shape_weights(&self.mesh, Some(t)).unwrap()),
            blend_shape_mode: BlendShapeMode::Before,
            joint_transforms: Some(common::skinning_transforms(&self.stage, &self.rig, &self.skeleton, t)),
            ..FrameRequest::default()
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn joint_transforms_over_http_answer_the_bake_of_the_rigged_shot() {
    let shot = Shot::new();
    let dir = common::temp_dir("service-skin", "bake");
    let out = dir.join("baked.usda");
    let run = curvenet(&["bake", SHOT, "--out", out.to_str().unwrap(), "--frames", "8"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let overrides = read_points_overrides(&out).unwrap();
    let (time, baked) = &overrides.prims[0].samples[0];
    assert_eq!(*time, 8.0);
    let baked: Vec<[f64; 3]> = baked.iter().map(|q| q.map(f64::from)).collect();

    let app = app(AppState::new(Config { solve_threads: 2, ..Config::default() }, None).unwrap());
    let (status, body) = send(&app, "/v1/bindings", &shot.request).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let binding: BindingResponse = serde_json::from_slice(&body).unwrap();
    // The skin is part of what the id hashes.
    let mut plain = shot.request.clone();
    plain.skin = None;
    let (status, body) = send(&app, "/v1/bindings", &plain).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let plain_id = serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id;
    assert_ne!(plain_id, binding.binding_id);

    let uri = format!("/v1/bindings/{}/frames", binding.binding_id);
    let frame = shot.frame(8.0);
    let (status, body) = send(&app, &uri, &frame).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let got: Vec<[f64; 3]> =
        serde_json::from_slice::<FrameResponse>(&body).unwrap().points.iter().map(|p| p.map(f64::from)).collect();
    let diagonal = curvenet_core::bounding_box_diagonal(&shot.mesh.projection_points);
    let err = max_dist(&got, &baked);
    let moved = max_dist(&baked, &shot.mesh.projection_points);
    eprintln!(
        "frame 8 over HTTP vs curvenet bake: {:.2e} x diagonal (the frame moves {:.2e} x diagonal)",
        err / diagonal,
        moved / diagonal
    );
    assert!(moved > 1e-2 * diagonal, "the frame is posed");
    assert!(err <= 1e-6 * diagonal, "{err:e}");

    // Wrong counts and a binding without a skin are refused, naming the array.
    let mut short = shot.frame(8.0);
    short.joint_transforms.as_mut().unwrap().pop();
    let (status, body) = send(&app, &uri, &short).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["code"], "count_mismatch");
    assert_eq!(v["details"]["what"], "joint_transforms");
    assert_eq!(v["details"]["expected"], shot.rig.joints.len());
    let (status, body) = send(&app, &format!("/v1/bindings/{plain_id}/frames"), &frame).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(
        (v["code"].clone(), v["details"]["what"].clone()),
        (Value::from("unsupported"), Value::from("joint_transforms"))
    );

    // A pose that collapses one of the three curvenets names that curvenet
    // (`details.curvenet`, a message starting `curvenets[k]: `), alone and
    // as frame 1 of a batch of 8, made lane by lane.
    let pools: Vec<Vec<[f64; 3]>> = plain.curvenets.iter().map(|c| c.pool.clone()).collect();
    assert_eq!(pools.len(), 3, "the rigged shot has three curvenets");
    let mut bad = pools.clone();
    bad[2] = vec![bad[2][0]; bad[2].len()];
    let plain_uri = format!("/v1/bindings/{plain_id}/frames");
    let (status, body) = send(&app, &plain_uri, &serde_json::json!({ "posed": bad })).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!((v["code"].as_str(), v["details"]["curvenet"].as_u64()), (Some("degenerate_pose"), Some(2)), "{v}");
    assert!(v["message"].as_str().unwrap().starts_with("curvenets[2]: "), "{v}");
    let mut batch: Vec<Value> = (0..8).map(|_| serde_json::json!({ "posed": pools })).collect();
    batch[1] = serde_json::json!({ "posed": bad });
    let (status, body) = send(&app, &format!("{plain_uri}:batch"), &serde_json::json!({ "frames": batch })).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!((v["details"]["frame"].as_u64(), v["details"]["curvenet"].as_u64()), (Some(1), Some(2)), "{v}");
    assert!(v["message"].as_str().unwrap().contains("curvenets[2]: "), "{v}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn joint_transforms_travel_in_the_binary_form() {
    // The same frame as JSON and as binary f32 arrays: the binary answer is
    // the JSON answer to a frame whose transforms and weights were rounded to f32.
    let shot = Shot::new();
    let app = app(AppState::new(Config { solve_threads: 2, ..Config::default() }, None).unwrap());
    let (status, body) = send(&app, "/v1/bindings", &shot.request).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let id = serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id;
    let uri = format!("/v1/bindings/{id}/frames");
    let mut frame = shot.frame(5.0);
    assert!(frame.rest.is_none(), "the shot's mesh has no animated points");
    let round = |x: &f64| *x as f32 as f64;
    let transforms: Vec<Mat4> = frame.joint_transforms.take().unwrap().iter().map(|m| m.map(|x| round(&x))).collect();
    let weights: Vec<f64> = frame.blend_shape_weights.take().unwrap().iter().map(round).collect();
    frame.joint_transforms = Some(transforms.clone());
    frame.blend_shape_weights = Some(weights.clone());
    let (status, body) = send(&app, &uri, &frame).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let json_points = serde_json::from_slice::<FrameResponse>(&body).unwrap().points;

    let header = serde_json::json!({"arrays": [
        {"name": "joint_transforms", "shape": [transforms.len(), 16]},
        {"name": "blend_shape_weights", "shape": [weights.len()]},
    ], "blend_shape_mode": "before"});
    let h = serde_json::to_vec(&header).unwrap();
    let mut bin = (h.len() as u32).to_le_bytes().to_vec();
    bin.extend_from_slice(&h);
    for x in transforms.iter().flatten().chain(&weights) {
        bin.extend_from_slice(&(*x as f32).to_le_bytes());
    }
    let req =
        Request::post(&uri).header(header::CONTENT_TYPE, "application/octet-stream").body(Body::from(bin)).unwrap();
    let r = app.clone().oneshot(req).await.unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    let body = axum::body::to_bytes(r.into_body(), usize::MAX).await.unwrap();
    let hl = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    let data: Vec<f32> = body[4 + hl..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    let points: Vec<[f32; 3]> = data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    assert_eq!(points, json_points);

    // A binary joint_transforms array of the wrong length names it.
    let header = serde_json::json!({"arrays": [{"name": "joint_transforms", "shape": [2, 16]}]});
    let h = serde_json::to_vec(&header).unwrap();
    let mut bin = (h.len() as u32).to_le_bytes().to_vec();
    bin.extend_from_slice(&h);
    bin.extend(std::iter::repeat_n(0u8, 2 * 16 * 4));
    let req =
        Request::post(&uri).header(header::CONTENT_TYPE, "application/octet-stream").body(Body::from(bin)).unwrap();
    let r = app.clone().oneshot(req).await.unwrap();
    assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let body = axum::body::to_bytes(r.into_body(), usize::MAX).await.unwrap();
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["code"], "count_mismatch");
    assert!(v["message"].as_str().unwrap().contains("joint_transforms"), "{}", v["message"]);
}
