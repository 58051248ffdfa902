//! The cage over HTTP (issue 18, the service part), against a real
//! `curvenet serve` process: a binding carrying fixtures/shots/hand_caged's
//! cage, skin and skeleton (centres of rotation), and frames carrying joint
//! transforms, rest-cage edits and posed-cage offsets, answer what an
//! in-process `curvenet_core::Deformer` built from the stage's plain data
//! answers (rounded to f32), and what `curvenet bake` writes; bad cages,
//! bad cage arrays and a cage coupled with a skin that has no skeleton are
//! typed 422s naming what is wrong.

mod common;

use curvenet_core::{CageInput, Rig};
use curvenet_core::{CurvenetInput, Deformer, DeformerInput, Frame};
use curvenet_core::{Influences, Mat4, Skeleton, Skin, SkinningMethod};
use curvenet_schema::usd::{CurvenetSkinning, CurvenetSkinningMethod, Stage, read_points_overrides};
use curvenet_schema::wire::{
    BindingRequest, BindingResponse, CageSpec, FrameBatchResponse, FrameRequest, FrameResponse, SkeletonSpec,
    SkinMethod, SkinSpec,
};
use serde_json::{Value, json};

const CAGED: &str = "fixtures/shots/hand_caged/shot.usda";

use common::Served as Server;
use common::max_dist;

async fn post(client: &reqwest::Client, url: &str, body: &impl serde::Serialize) -> (u16, Vec<u8>) {
    let r = client.post(url).json(body).send().await.unwrap();
    (r.status().as_u16(), r.bytes().await.unwrap().to_vec())
}

async fn post_binary(client: &reqwest::Client, url: &str, body: Vec<u8>) -> (u16, Vec<u8>) {
    let r = client.post(url).header("content-type", "application/octet-stream").body(body).send().await.unwrap();
    (r.status().as_u16(), r.bytes().await.unwrap().to_vec())
}

fn error(status: u16, body: &[u8]) -> Value {
    assert_eq!(status, 422, "{}", String::from_utf8_lossy(body));
    serde_json::from_slice(body).unwrap()
}

/// The caged shot read the way a client reading USD itself would.
struct Shot {
    stage: Stage,
    mesh: curvenet_schema::MeshData,
    nets: Vec<curvenet_schema::CurvenetData>,
    cage: curvenet_schema::CageData,
    rig: curvenet_schema::usd::SkinRig,
    skeleton: Skeleton,
    request: BindingRequest,
    diagonal: f64,
}

impl Shot {
    fn new() -> Self {
        let stage = Stage::open(common::repo().join(CAGED)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        for n in &nets {
            assert!(
                matches!(stage.curvenet_skinning(n).unwrap(), CurvenetSkinning::None),
                "the shot's curvenets are not spline-skinned"
            );
        }
        assert!(mesh.blend_shapes.is_empty(), "the shot has no blend shapes");
        let cage = stage.cage(&mesh).unwrap().expect("the shot's mesh has a cage");
        let rig = stage.skin_rig(&mesh).unwrap().expect("the shot is skinned");
        assert_eq!(rig.curvenet_method, Some(CurvenetSkinningMethod::CentersOfRotation));
        let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
        let mut request = BindingRequest::from_stage(&mesh, &nets);
        request.skin = Some(SkinSpec {
            joints: rig.joints.len() as u32,
            element_size: rig.element_size as u32,
            joint_indices: rig.joint_indices.clone(),
            joint_weights: rig.joint_weights.clone(),
            geom_bind_transform: Some(rig.geom_bind_transform),
            method: SkinMethod::CentersOfRotation,
            curvenets: Vec::new(),
            flexible_iterations: 0,
            skeleton: Some(SkeletonSpec {
                parents: rig.parents.iter().map(|p| p.map_or(-1, i64::from)).collect(),
                bind_transforms: rig.bind_transforms.clone(),
            }),
        });
        request.cage = Some(CageSpec { points: cage.rest_points.clone(), triangles: cage.triangles.clone() });
        let diagonal = curvenet_core::bounding_box_diagonal(&mesh.projection_points);
        Self { stage, mesh, nets, cage, rig, skeleton, request, diagonal }
    }

    /// The coupled deformer built here from the stage's plain data, as core
    /// documents it (not through the service's request handling).
    fn deformer(&self) -> Deformer {
        let n = self.mesh.projection_points.len();
        let mut influences = Influences::new(
            n,
            self.rig.element_size,
            &self.rig.joint_indices,
            &self.rig.joint_weights,
            self.rig.joints.len(),
        )
        .unwrap();
        influences.renormalize(1e-4);
        let skin = Skin::new(influences, self.rig.geom_bind_transform, SkinningMethod::CentersOfRotation).unwrap();
        let rig = Rig {
            skin,
            curvenets: vec![None; self.nets.len()],
            flexible_iterations: 0,
            skeleton: Some(self.skeleton.clone()),
        };
        let inputs: Vec<CurvenetInput> = self.nets.iter().map(curvenet_schema::CurvenetData::input).collect();
        let input = DeformerInput {
            skinning: Some(rig),
            cage: Some(CageInput { points: &self.cage.rest_points, triangles: &self.cage.triangles }),
            ..curvenet_schema::deformer_input(&self.mesh, &inputs)
        };
        Deformer::new(&input).unwrap()
    }

    /// Frame `t`: joint transforms, the rest cage and the posed-cage offsets.
    fn frame(&self, t: f64) -> FrameRequest {
        let rest = self.stage.rest_points(&self.mesh, Some(t)).unwrap();
        assert_eq!(rest, self.mesh.projection_points, "the shot's mesh points are not animated");
        let edits = self.cage.frame(Some(t));
        FrameRequest {
            joint_transforms: Some(common::skinning_transforms(&self.stage, &self.rig, &self.skeleton, t)),
            rest_cage: edits.rest_cage().map(<[_]>::to_vec),
            posed_cage_offsets: edits.posed_cage_offsets().map(<[_]>::to_vec),
            ..FrameRequest::default()
        }
    }

    /// The in-process answer to `frame`.
    fn solve(&self, deformer: &Deformer, frame: &FrameRequest) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; self.mesh.projection_points.len()];
        let input = Frame {
            joint_transforms: frame.joint_transforms.as_deref(),
            rest_cage: frame.rest_cage.as_deref(),
            posed_cage_offsets: frame.posed_cage_offsets.as_deref(),
            ..Frame::default()
        };
        deformer.frame(&input, &mut out, None).unwrap();
        out
    }
}

/// Every coordinate of `got` (the f32 wire answer) is `want` rounded to
/// f32: within one f32 ulp of it, plus 1e-9 of the diagonal for the solve.
fn assert_f32_of(got: &[[f32; 3]], want: &[[f64; 3]], diagonal: f64, what: &str) {
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        for c in 0..3 {
            let tolerance = f64::from(f32::EPSILON) * w[c].abs() + 1e-9 * diagonal;
            assert!(
                (f64::from(g[c]) - w[c]).abs() <= tolerance,
                "{what}: vertex {i} coordinate {c} is {} over HTTP, {} in process",
                g[c],
                w[c]
            );
        }
    }
}

fn widen(points: &[[f32; 3]]) -> Vec<[f64; 3]> {
    points.iter().map(|p| p.map(f64::from)).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn caged_frames_over_http_answer_the_in_process_deformer_and_the_bake() {
    let shot = Shot::new();
    // The bake of every cage frame (1..=10: rest-cage edits, a pose, posed-cage edits).
    let dir = common::temp_dir("service-cage", "bake");
    let out = dir.join("baked.usda");
    let run = common::curvenet(&["bake", CAGED, "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", common::stderr(&run));
    let baked = read_points_overrides(&out).unwrap().prims.remove(0).samples;
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(baked.iter().map(|(t, _)| *t).collect::<Vec<_>>(), (1..=10).map(f64::from).collect::<Vec<_>>());

    let server = Server::start(&[]);
    let client = reqwest::Client::new();
    let base = &server.url;
    let (status, body) = post(&client, &format!("{base}/v1/bindings"), &shot.request).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let binding: BindingResponse = serde_json::from_slice(&body).unwrap();
    // The cage is reported, and its Φ (#V × #C f64) is weighed by the cache.
    let cage = binding.cage.as_ref().expect("the binding reports its cage");
    let (n, c) = (shot.mesh.projection_points.len(), shot.cage.rest_points.len());
    assert_eq!((cage.vertices, cage.triangles), (c, shot.cage.triangles.len()));
    assert_eq!(cage.maxvol_rows, c, "one MaxVol row per cage vertex");
    assert!(cage.condition.is_finite() && cage.condition >= 1.0, "{}", cage.condition);
    assert!(cage.phi_bytes >= (n * c * 8) as u64, "Φ is {} bytes for {n} × {c}", cage.phi_bytes);
    assert!(binding.size_bytes > cage.phi_bytes, "the entry's size counts Φ");

    // The cage and the skeleton are part of what the id hashes.
    let mut other = shot.request.clone();
    other.cage.as_mut().unwrap().points[0][0] += 1e-3;
    let mut other_skeleton = shot.request.clone();
    other_skeleton.skin.as_mut().unwrap().skeleton.as_mut().unwrap().bind_transforms[1][12] += 1e-3;
    for (what, req) in [("cage", &other), ("skeleton", &other_skeleton)] {
        let (status, body) = post(&client, &format!("{base}/v1/bindings"), req).await;
        assert_eq!(status, 200, "{what}: {}", String::from_utf8_lossy(&body));
        let id = serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id;
        assert_ne!(id, binding.binding_id, "a different {what} is a different binding");
    }

    let deformer = shot.deformer();
    let uri = format!("{base}/v1/bindings/{}/frames", binding.binding_id);
    let frames: Vec<FrameRequest> = baked.iter().map(|(t, _)| shot.frame(*t)).collect();
    assert!(frames.iter().any(|f| f.rest_cage.is_some()), "some frame edits the rest cage");
    assert!(frames.iter().any(|f| f.posed_cage_offsets.is_some()), "some frame edits the posed cage");
    let d = shot.diagonal;
    let mut worst_bake = 0.0f64;
    let mut wants = Vec::new();
    for ((t, bake), frame) in baked.iter().zip(&frames) {
        let (status, body) = post(&client, &uri, frame).await;
        assert_eq!(status, 200, "frame {t}: {}", String::from_utf8_lossy(&body));
        let got = serde_json::from_slice::<FrameResponse>(&body).unwrap().points;
        let want = shot.solve(&deformer, frame);
        assert_f32_of(&got, &want, d, &format!("frame {t}"));
        let bake = widen(bake);
        let e = max_dist(&widen(&got), &bake);
        worst_bake = worst_bake.max(e);
        assert!(e <= 1e-6 * d, "frame {t}: {:.2e} x diagonal off the bake", e / d);
        wants.push(want);
    }
    let moved = max_dist(&wants[9], &wants[0]);
    eprintln!(
        "caged hand over HTTP: <= 1 f32 ulp from the in-process deformer, {:.2e} x diagonal from the bake; \
         frame 10 moves {:.2e} x diagonal from frame 1",
        worst_bake / d,
        moved / d
    );
    assert!(moved > 1e-2 * d, "the frames are posed and edited");

    // The batch form (the grouped solve) answers the same.
    let (status, body) = post(&client, &format!("{uri}:batch"), &json!({ "frames": frames })).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let batch = serde_json::from_slice::<FrameBatchResponse>(&body).unwrap().frames;
    for (k, (got, want)) in batch.iter().zip(&wants).enumerate() {
        assert_f32_of(&got.points, want, d, &format!("batch frame {k}"));
    }
}

/// The binary frame: `u32` header length, JSON header, then the arrays as f32.
fn binary(header: &Value, arrays: &[&[f64]]) -> Vec<u8> {
    let h = serde_json::to_vec(header).unwrap();
    let mut out = (h.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    for a in arrays {
        for x in *a {
            out.extend_from_slice(&(*x as f32).to_le_bytes());
        }
    }
    out
}

fn round_points(p: &[[f64; 3]]) -> Vec<[f64; 3]> {
    p.iter().map(|q| q.map(|x| x as f32 as f64)).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cage_arrays_travel_in_the_binary_form_and_bad_ones_are_422s_naming_them() {
    let shot = Shot::new();
    let server = Server::start(&[]);
    let client = reqwest::Client::new();
    let base = &server.url;
    let (status, body) = post(&client, &format!("{base}/v1/bindings"), &shot.request).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let id = serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id;
    let uri = format!("{base}/v1/bindings/{id}/frames");
    let c = shot.cage.rest_points.len();

    // Frame 10 (every kind of edit) with its values rounded to f32: the
    // binary answer is the JSON answer.
    let mut frame = shot.frame(10.0);
    let transforms: Vec<Mat4> =
        frame.joint_transforms.take().unwrap().iter().map(|m| m.map(|x| x as f32 as f64)).collect();
    let rest_cage = round_points(frame.rest_cage.as_deref().expect("frame 10 edits the rest cage"));
    let offsets = round_points(frame.posed_cage_offsets.as_deref().expect("frame 10 edits the posed cage"));
    let frame = FrameRequest {
        joint_transforms: Some(transforms.clone()),
        rest_cage: Some(rest_cage.clone()),
        posed_cage_offsets: Some(offsets.clone()),
        ..FrameRequest::default()
    };
    let (status, body) = post(&client, &uri, &frame).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let json_points = serde_json::from_slice::<FrameResponse>(&body).unwrap().points;
    let header = json!({"arrays": [
        {"name": "joint_transforms", "shape": [transforms.len(), 16]},
        {"name": "rest_cage", "shape": [c, 3]},
        {"name": "posed_cage_offsets", "shape": [c, 3]},
    ]});
    let flat = |p: &[[f64; 3]]| p.iter().flatten().copied().collect::<Vec<f64>>();
    let xf: Vec<f64> = transforms.iter().flatten().copied().collect();
    let (status, body) = post_binary(&client, &uri, binary(&header, &[&xf, &flat(&rest_cage), &flat(&offsets)])).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let hl = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    let data: Vec<f32> = body[4 + hl..].chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    let points: Vec<[f32; 3]> = data.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    assert_eq!(points, json_points);

    // A binary cage array of the wrong length names it.
    let header = json!({"arrays": [{"name": "posed_cage_offsets", "shape": [c - 1, 3]}]});
    let (status, body) = post_binary(&client, &uri, binary(&header, &[&flat(&offsets[1..])])).await;
    let v = error(status, &body);
    assert_eq!(v["code"], "count_mismatch");
    assert_eq!(
        (v["details"]["what"].clone(), v["details"]["expected"].clone()),
        (json!("posed_cage_offsets"), json!(c))
    );

    // JSON: wrong counts, values beyond the limit, each naming the field (and index).
    let mut short = FrameRequest { rest_cage: Some(rest_cage[1..].to_vec()), ..FrameRequest::default() };
    let v = error_of(&client, &uri, &short).await;
    assert_eq!(v["code"], "count_mismatch");
    assert_eq!(v["details"]["what"], "rest_cage");
    assert_eq!((v["details"]["expected"].clone(), v["details"]["got"].clone()), (json!(c), json!(c - 1)));
    short.rest_cage = None;
    let mut far = offsets.clone();
    far[7][1] = 1e300;
    short.posed_cage_offsets = Some(far);
    let v = error_of(&client, &uri, &short).await;
    assert_eq!(v["code"], "invalid_parameter");
    assert_eq!((v["details"]["what"].clone(), v["details"]["index"].clone()), (json!("posed_cage_offsets"), json!(7)));

    // Cage edits on a binding without a cage.
    let mut plain = shot.request.clone();
    plain.cage = None;
    let (status, body) = post(&client, &format!("{base}/v1/bindings"), &plain).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let plain_id = serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id;
    assert!(serde_json::from_slice::<BindingResponse>(&body).unwrap().cage.is_none());
    let plain_uri = format!("{base}/v1/bindings/{plain_id}/frames");
    for what in ["rest_cage", "posed_cage_offsets"] {
        let f: FrameRequest = serde_json::from_value(json!({ what: rest_cage })).unwrap();
        let v = error_of(&client, &plain_uri, &f).await;
        assert_eq!((v["code"].clone(), v["details"]["what"].clone()), (json!("unsupported"), json!(what)));
        let header = json!({"arrays": [{"name": what, "shape": [c, 3]}]});
        let (status, body) = post_binary(&client, &plain_uri, binary(&header, &[&flat(&rest_cage)])).await;
        let v = error(status, &body);
        assert_eq!((v["code"].clone(), v["details"]["what"].clone()), (json!("unsupported"), json!(what)));
    }
}

async fn error_of(client: &reqwest::Client, uri: &str, body: &impl serde::Serialize) -> Value {
    let (status, body) = post(client, uri, body).await;
    error(status, &body)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_cages_and_a_cage_with_a_skin_but_no_skeleton_are_422s_naming_them() {
    let shot = Shot::new();
    let server = Server::start(&[]);
    let client = reqwest::Client::new();
    let uri = format!("{}/v1/bindings", server.url);

    // A cage coupled with a skin needs the skeleton.
    let mut req = shot.request.clone();
    req.skin.as_mut().unwrap().skeleton = None;
    let v = error_of(&client, &uri, &req).await;
    assert_eq!((v["code"].clone(), v["details"]["what"].clone()), (json!("invalid_parameter"), json!("skin.skeleton")));

    // A skeleton whose parents and bind transforms disagree.
    let mut req = shot.request.clone();
    req.skin.as_mut().unwrap().skeleton.as_mut().unwrap().bind_transforms.pop();
    let v = error_of(&client, &uri, &req).await;
    assert_eq!(v["code"], "count_mismatch");
    assert_eq!(v["details"]["what"], "skin.skeleton.bind_transforms");
    let mut req = shot.request.clone();
    req.skin.as_mut().unwrap().skeleton.as_mut().unwrap().parents[2] = 5;
    let v = error_of(&client, &uri, &req).await;
    assert_eq!(v["code"], "index_out_of_range");
    assert_eq!(
        (v["details"]["what"].clone(), v["details"]["index"].clone()),
        (json!("skin.skeleton.parents"), json!(2))
    );

    // A triangle naming a vertex past the cage.
    let c = shot.cage.rest_points.len() as u32;
    let mut req = shot.request.clone();
    req.cage.as_mut().unwrap().triangles[4][1] = c;
    let v = error_of(&client, &uri, &req).await;
    assert_eq!(v["code"], "index_out_of_range");
    assert_eq!((v["details"]["what"].clone(), v["details"]["index"].clone()), (json!("cage.triangles"), json!(4)));

    // An open cage (a triangle removed) names an open edge of that triangle.
    let mut req = shot.request.clone();
    let removed = req.cage.as_mut().unwrap().triangles.remove(0);
    let v = error_of(&client, &uri, &req).await;
    assert_eq!((v["code"].clone(), v["details"]["what"].clone()), (json!("invalid_mesh"), json!("cage")));
    let edge: [u32; 2] = serde_json::from_value(v["details"]["edge"].clone()).expect("the open edge is named");
    assert!(
        edge.iter().all(|e| removed.contains(e)),
        "the open edge {edge:?} is an edge of the removed triangle {removed:?}: {v}"
    );
    assert!(v["message"].as_str().unwrap().contains("not closed"), "{v}");

    // A flipped triangle names it and its neighbour across the shared edge.
    let mut req = shot.request.clone();
    let t = &mut req.cage.as_mut().unwrap().triangles[3];
    t.swap(1, 2);
    let flipped = *t;
    let v = error_of(&client, &uri, &req).await;
    assert_eq!((v["code"].clone(), v["details"]["what"].clone()), (json!("invalid_mesh"), json!("cage")));
    let faces: Vec<u32> = serde_json::from_value(v["details"]["faces"].clone()).expect("the faces are named");
    assert!(faces.contains(&3), "triangle 3 is named among {faces:?}: {v}");
    let edge: [u32; 2] = serde_json::from_value(v["details"]["edge"].clone()).expect("the shared edge is named");
    assert!(edge.iter().all(|e| flipped.contains(e)), "{edge:?} is an edge of the flipped triangle {flipped:?}");
    assert!(v["message"].as_str().unwrap().contains("flipped"), "{v}");

    // The OpenAPI describes the cage fields.
    let doc: Value = client.get(format!("{}/openapi.json", server.url)).send().await.unwrap().json().await.unwrap();
    let schemas = &doc["components"]["schemas"];
    assert!(schemas["BindingRequest"]["properties"].get("cage").is_some(), "BindingRequest.cage");
    assert!(schemas["SkinSpec"]["properties"].get("skeleton").is_some(), "SkinSpec.skeleton");
    for field in ["rest_cage", "posed_cage_offsets"] {
        assert!(schemas["FrameRequest"]["properties"].get(field).is_some(), "FrameRequest.{field}");
    }
    assert!(schemas["SkinMethod"].to_string().contains("centers_of_rotation"), "{}", schemas["SkinMethod"]);
    assert!(schemas["BindingResponse"]["properties"].get("cage").is_some(), "BindingResponse.cage");

    // A cage point beyond the coordinate limit names its index.
    let mut req = shot.request.clone();
    req.cage.as_mut().unwrap().points[9][2] = 1e300;
    let v = error_of(&client, &uri, &req).await;
    assert_eq!(v["code"], "invalid_parameter");
    assert_eq!((v["details"]["what"].clone(), v["details"]["index"].clone()), (json!("cage.points"), json!(9)));
}
