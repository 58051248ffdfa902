//! The viewer's page and read-only endpoints (server/src/service/viewer.rs),
//! driven through `app(state)`: the page is self-contained, the geometry it
//! draws agrees with the binding's counts, frames solve through the service
//! path (neutral pose reproduced, rigid motions carried), and stages opened
//! with a frame source are listed, bound and solved.

use std::sync::Arc;

use axum::Router;
use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use curvenet_core::PolyMesh;
use curvenet_core::Surface;
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingRequest, FrameRequest};
use curvenet_server::{AppState, Config, FrameSource, ViewerStage, app};
use serde_json::{Value, json};

#[allow(dead_code)] // the helpers this file does not use
mod common;
use common::router::{get, post_json, send};

fn hand() -> BindingRequest {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/hand/hand_1k4.usda");
    let stage = Stage::open(&path).unwrap();
    let mesh = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
    let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    BindingRequest::from_stage(&mesh, &nets)
}

fn state(token: Option<&str>) -> AppState {
    AppState::new(Config { solve_threads: 2, token: token.map(String::from), ..Config::default() }, None).unwrap()
}

async fn json_of(app: &Router, req: Request<Body>) -> Value {
    let (status, _, body) = send(app, req).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn ints(v: &Value) -> Vec<u64> {
    v.as_array().unwrap().iter().map(|x| x.as_u64().unwrap()).collect()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// f32 output of values of order 1, with room for the solve's rounding.
const TOL: f64 = 1e-5;

fn shifted(pool: &[[f64; 3]], d: [f64; 3]) -> Vec<[f64; 3]> {
    pool.iter().map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]]).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_is_self_contained_and_open_without_the_token() {
    let app = app(state(Some("secret")));
    let modules = [
        "main",
        "dom",
        "state",
        "context",
        "api",
        "math",
        "camera",
        "shapes",
        "gl",
        "scene",
        "render",
        "pick",
        "frames",
        "panel",
        "loading",
        "knots",
        "live",
        "input",
        "highlight",
        "adjust",
    ];
    let mut assets = vec![("/viewer".to_string(), "text/html"), ("/viewer/viewer.css".to_string(), "text/css")];
    assets.extend(modules.iter().map(|m| (format!("/viewer/js/{m}.js"), "text/javascript")));
    for (path, kind) in &assets {
        let path = path.as_str();
        let (status, headers, body) = send(&app, get(path)).await;
        assert_eq!(status, StatusCode::OK, "{path}");
        assert!(headers[header::CONTENT_TYPE].to_str().unwrap().starts_with(kind), "{path}");
        let csp = headers[header::CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(csp.starts_with("default-src 'self'") && !csp.contains("http"), "{csp}");
        let text = String::from_utf8(body.to_vec()).unwrap();
        // Nothing is fetched from anywhere else: no absolute URLs at all.
        assert!(!text.contains("://"), "{path} names an absolute URL");
        // Every module a module imports is served (relative, beside it).
        for line in text.lines().filter(|l| l.starts_with("import ")) {
            let from = line.rsplit("from '").next().and_then(|r| r.split('\'').next()).unwrap_or("");
            let name = from.strip_prefix("./").and_then(|n| n.strip_suffix(".js"));
            assert!(name.is_some_and(|n| modules.contains(&n)), "{path}: `{line}` imports no served module");
        }
    }
    let (_, _, page) = send(&app, get("/viewer")).await;
    let page = String::from_utf8(page.to_vec()).unwrap();
    assert!(
        page.contains(r#"<script type="module" src="viewer/js/main.js">"#)
            && page.contains(r#"href="viewer/viewer.css""#)
    );
    let (status, _, body) = send(&app, get("/viewer/js/nothing.js")).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(serde_json::from_slice::<Value>(&body).unwrap()["code"], "not_found");
    // The data needs the token.
    let (status, _, body) = send(&app, get("/v1/viewer/stages")).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert_eq!(serde_json::from_slice::<Value>(&body).unwrap()["code"], "unauthorized");
    let req =
        Request::get("/v1/viewer/stages").header(header::AUTHORIZATION, "Bearer secret").body(Body::empty()).unwrap();
    assert_eq!(json_of(&app, req).await, json!({"stages": []}));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn viewer_data_agrees_with_the_binding_and_frames_solve() {
    let app = app(state(None));
    let req = hand();
    let bound = json_of(&app, post_json("/v1/bindings", &req)).await;
    let id = bound["binding_id"].as_str().unwrap();
    let stats = &bound["stats"];
    let n = |k: &str| stats[k].as_u64().unwrap() as usize;
    let data = json_of(&app, get(&format!("/v1/bindings/{id}/viewer-data"))).await;
    assert_eq!(data["binding"]["stats"], *stats);

    // The mesh.
    let mesh = &data["mesh"];
    assert_eq!(floats(&mesh["points"]).len(), 3 * n("mesh_vertices"));
    let faces = ints(&mesh["triangle_face"]);
    assert_eq!(faces.iter().max().map(|&f| f as usize + 1), Some(n("mesh_faces")));
    assert_eq!(ints(&mesh["triangles"]).len(), 3 * faces.len());
    let corners: usize = req.face_vertex_counts.iter().map(|&c| c as usize).sum();
    assert_eq!(faces.len(), corners - 2 * req.face_vertex_counts.len(), "c - 2 triangles per face");
    // They are core's own triangulation of the faces, the one the binding works in.
    let poly = PolyMesh::new(&req.face_vertex_counts, &req.face_vertex_indices, req.projection_points.len()).unwrap();
    let surface = Surface::new(&poly, &req.projection_points).unwrap();
    let (core_triangles, core_faces): (Vec<[u32; 3]>, Vec<u32>) = surface.triangles().unzip();
    assert_eq!(ints(&mesh["triangles"]), core_triangles.iter().flatten().map(|&v| v as u64).collect::<Vec<_>>());
    assert_eq!(faces, core_faces.iter().map(|&f| f as u64).collect::<Vec<_>>());
    assert_eq!(mesh["triangulation"], "surface");

    // The cut-mesh: every count of the binding is visible in it.
    let cut = &data["cut"];
    assert_eq!(floats(&cut["points"]).len(), 3 * n("cut_vertices"));
    assert_eq!(ints(&cut["face_parent"]).len(), n("cut_faces"));
    assert_eq!(ints(&cut["face_vertices"]).len(), n("cut_halfedges"));
    let kinds = ints(&cut["edge_kind"]);
    assert_eq!(ints(&cut["edges"]).len(), 2 * kinds.len());
    assert_eq!(kinds.iter().filter(|&&k| k == 2).count(), n("cracks"));
    let boundary = kinds.iter().filter(|&&k| k == 3).count();
    assert_eq!(2 * (kinds.len() - boundary) + boundary, n("cut_halfedges"), "one edge per halfedge pair");
    assert!(kinds.contains(&1), "no cut-mesh edge runs along the curvenet");

    // The curvenet: samples, segments, marked points, frames.
    let nets = data["curvenets"].as_array().unwrap();
    assert_eq!(nets.len(), 1);
    let net = &nets[0];
    let samples = floats(&net["samples"]);
    assert_eq!(samples.len(), 3 * n("samples"));
    assert_eq!(ints(&net["segments"]).len(), 2 * n("segments"));
    assert_eq!(floats(&net["frames"]).len(), 18 * n("segments"));
    assert_eq!(floats(&net["projections"]).len(), samples.len());
    assert!(!ints(&net["intersections"]).is_empty() && !ints(&net["anchors"]).is_empty());
    assert!(ints(&net["intersections"]).iter().chain(&ints(&net["anchors"])).all(|&i| (i as usize) < n("samples")));
    assert!(ints(&net["removed_samples"]).is_empty() && n("islands_removed") == 0);
    // Projections are on the surface, within the binding's limit of the samples.
    let diag = data["diagonal"].as_f64().unwrap();
    assert!(max_diff(&samples, &floats(&net["projections"])) < 0.05 * diag);

    // The neutral frame reproduces the projection pose; its curvenet is the neutral one.
    let uri = format!("/v1/bindings/{id}/viewer-frame");
    let neutral = json_of(&app, post_json(&uri, &json!({}))).await;
    assert!(max_diff(&floats(&neutral["points"]), &floats(&mesh["points"])) < TOL);
    assert!(max_diff(&floats(&neutral["cut_points"]), &floats(&cut["points"])) < TOL);
    assert!(max_diff(&floats(&neutral["curvenets"][0]["samples"]), &samples) < TOL);
    assert!(max_diff(&floats(&neutral["curvenets"][0]["frames"]), &floats(&net["frames"])) < TOL);
    assert!(neutral.get("rest").is_none());

    // A translated pool: everything moves with it, and the frames do not change.
    let d = [0.05, -0.02, 0.03];
    let moved = json_of(&app, post_json(&uri, &json!({"posed": [shifted(&req.curvenets[0].pool, d)]}))).await;
    let expect = |flat: &[f64]| flat.iter().enumerate().map(|(i, x)| x + d[i % 3]).collect::<Vec<_>>();
    assert!(max_diff(&floats(&moved["points"]), &expect(&floats(&mesh["points"]))) < TOL);
    assert!(max_diff(&floats(&moved["cut_points"]), &expect(&floats(&cut["points"]))) < TOL);
    assert!(max_diff(&floats(&moved["curvenets"][0]["samples"]), &expect(&samples)) < TOL);
    assert!(max_diff(&floats(&moved["curvenets"][0]["frames"]), &floats(&net["frames"])) < TOL);

    // A frame with its own rest pose (the projection pose shifted): the rest
    // view carries the mesh, the cut-vertices and the tracked curvenet.
    let rest = shifted(&req.projection_points, d);
    let with_rest = json_of(&app, post_json(&uri, &json!({"rest": rest}))).await;
    let r = &with_rest["rest"];
    assert!(max_diff(&floats(&r["points"]), &expect(&floats(&mesh["points"]))) < TOL);
    assert!(max_diff(&floats(&r["cut_points"]), &expect(&floats(&cut["points"]))) < TOL);
    assert!(max_diff(&floats(&r["curvenets"][0]["samples"]), &expect(&samples)) < TOL);
    assert!(max_diff(&floats(&with_rest["points"]), &expect(&floats(&mesh["points"]))) < TOL);

    // Errors are the service's: a wrong pool, an unknown binding.
    let (status, _, body) = send(&app, post_json(&uri, &json!({"posed": [[[0.0, 0.0, 0.0]]]}))).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let e: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(e["code"], "count_mismatch", "{e}");
    let unknown = format!("/v1/bindings/{}/viewer-data", "0".repeat(64));
    let (status, _, body) = send(&app, get(&unknown)).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(serde_json::from_slice::<Value>(&body).unwrap()["code"], "unknown_binding");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_opened_stage_is_listed_bound_and_solved_frame_by_frame() {
    let state = state(None);
    let req = hand();
    let pool = req.curvenets[0].pool.clone();
    // Frame k: the pool shifted by k cm along x; frame 2 cannot be read.
    let frame: FrameSource = Arc::new(move |k: usize| {
        if k == 2 {
            return Err(
                "/Hand/Curvenet: primvars:curvenet:cv has 3 control points at time 12, the neutral pose has 251".into(),
            );
        }
        Ok(FrameRequest {
            posed: Some(vec![Some(shifted(&pool, [0.01 * k as f64, 0.0, 0.0]))]),
            ..FrameRequest::default()
        })
    });
    let index = state.open_in_viewer(ViewerStage::new(
        "shots/wave.usda".into(),
        "/Hand/Mesh".into(),
        vec!["/Hand/Curvenet".into()],
        vec![10.0, 11.0, 12.0],
        req.clone(),
        frame,
    ));
    assert_eq!(index, 0);
    let app = app(state);
    let listed = json_of(&app, get("/v1/viewer/stages")).await;
    assert_eq!(listed["stages"][0]["mesh"], "/Hand/Mesh");
    assert_eq!(listed["stages"][0]["times"], json!([10.0, 11.0, 12.0]));

    // Bound through the cache: the same id as posting the binding by hand.
    let stage = json_of(&app, get("/v1/viewer/stages/0")).await;
    assert_eq!(stage["binding"]["cached"], false);
    let posted = json_of(&app, post_json("/v1/bindings", &req)).await;
    assert_eq!(posted["cached"], true);
    assert_eq!(stage["binding"]["binding_id"], posted["binding_id"]);

    let f0 = json_of(&app, get("/v1/viewer/stages/0/frames/0")).await;
    let f1 = json_of(&app, get("/v1/viewer/stages/0/frames/1")).await;
    assert_eq!((f0["time"].as_f64(), f1["time"].as_f64()), (Some(10.0), Some(11.0)));
    let (p0, p1) = (floats(&f0["points"]), floats(&f1["points"]));
    let moved: Vec<f64> = p0.iter().enumerate().map(|(i, x)| if i % 3 == 0 { x + 0.01 } else { *x }).collect();
    assert!(max_diff(&p1, &moved) < TOL, "frame 11 is frame 10 shifted by 1 cm");

    // Errors name the stage and the frame.
    let (status, _, body) = send(&app, get("/v1/viewer/stages/0/frames/2")).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let e: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(e["code"], "invalid_parameter");
    assert!(e["message"].as_str().unwrap().contains("shots/wave.usda, frame 12"), "{e}");
    for (uri, what) in [("/v1/viewer/stages/0/frames/3", "frame 3"), ("/v1/viewer/stages/1", "no stage 1")] {
        let (status, _, body) = send(&app, get(uri)).await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{uri}");
        let e: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(e["code"], "not_found");
        assert!(e["message"].as_str().unwrap().contains(what), "{e}");
    }

    // The OpenAPI document lists the viewer's routes.
    let doc = json_of(&app, get("/openapi.json")).await;
    for path in [
        "/v1/viewer/stages",
        "/v1/viewer/stages/{index}/frames/{k}",
        "/v1/viewer/stages/{index}/export",
        "/v1/bindings/{id}/viewer-data",
        "/v1/bindings/{id}/viewer-frame",
    ] {
        assert!(doc["paths"].get(path).is_some(), "{path} missing");
    }
    let frames = &doc["paths"]["/v1/viewer/stages/{index}/frames/{k}"];
    assert!(frames.get("get").is_some() && frames.get("post").is_some(), "{frames}");
}

fn no_frames() -> FrameSource {
    Arc::new(|_| Ok(FrameRequest::default()))
}

fn open(state: &AppState, req: BindingRequest) -> usize {
    state.open_in_viewer(ViewerStage::new(
        "refused.usda".into(),
        "/Hand/Mesh".into(),
        vec!["/Hand/Curvenet".into()],
        vec![0.0],
        req,
        no_frames(),
    ))
}

/// A stage whose binding is refused is drawn anyway: `/refusal` sends the
/// mesh, the curvenets and the element core's error names, with its
/// geometry and a box to frame.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_stage_is_drawn_with_the_element_its_error_names() {
    let state = state(None);
    let good = hand();
    // A curve drawn far from the surface: a control point lifted by half
    // the diagonal (the binding refuses samples beyond 5%).
    let mut far = good.clone();
    let lo = far.projection_points.iter().fold([f64::MAX; 3], |a, p| std::array::from_fn(|k| a[k].min(p[k])));
    let hi = far.projection_points.iter().fold([f64::MIN; 3], |a, p| std::array::from_fn(|k| a[k].max(p[k])));
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let lifted = far.curvenets[0].splines[3][1] as usize; // a handle of spline 3
    far.curvenets[0].pool[lifted][2] -= 0.5 * diag;
    // A degenerate mesh: a vertex moved onto its neighbour along face 10's first side.
    let mut degenerate = good.clone();
    let start: usize = degenerate.face_vertex_counts[..10].iter().map(|&c| c as usize).sum();
    let (a, b) = (degenerate.face_vertex_indices[start], degenerate.face_vertex_indices[start + 1]);
    degenerate.projection_points[a as usize] = degenerate.projection_points[b as usize];
    let (i_far, i_degenerate, i_good) = (open(&state, far), open(&state, degenerate), open(&state, good));
    let app = app(state);

    // The stage itself is refused, as before.
    let (status, _, body) = send(&app, get(&format!("/v1/viewer/stages/{i_far}"))).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let refused: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(refused["code"], "binding_failed", "{refused}");

    // Its refusal: the mesh in core's triangulation, the curvenet's samples,
    // and the far sample of spline 3 highlighted.
    let r = json_of(&app, get(&format!("/v1/viewer/stages/{i_far}/refusal"))).await;
    assert_eq!(r["code"], "binding_failed");
    assert_eq!(r["stage"]["mesh"], "/Hand/Mesh");
    assert!(r["message"].as_str().unwrap().contains("from the surface"), "{}", r["message"]);
    assert_eq!(r["mesh"]["triangulation"], "surface");
    assert_eq!(floats(&r["mesh"]["points"]).len(), 3 * hand().projection_points.len());
    assert!(!ints(&r["mesh"]["triangles"]).is_empty());
    assert!(!floats(&r["curvenets"][0]["samples"]).is_empty(), "the curvenet was sampled");
    let h = &r["highlight"];
    assert_eq!(h["element"], "sample", "{h}");
    assert_eq!(h["curvenet"], 0);
    let spline = h["splines"][0].as_u64().unwrap() as usize;
    assert!(hand().curvenets[0].splines[spline].contains(&(lifted as u32)) || spline == 3, "{h}");
    let marker = floats(&h["points"]);
    assert_eq!(marker.len(), 3);
    assert!(!floats(&h["lines"]).is_empty(), "the spline is drawn");
    let bounds = floats(&h["bounds"]);
    assert!((0..3).all(|k| bounds[k] <= marker[k] + 1e-6 && marker[k] <= bounds[k + 3] + 1e-6));
    // The marked sample is far from the surface (so from every vertex too).
    let nearest = hand()
        .projection_points
        .iter()
        .map(|p| (0..3).map(|k| (p[k] - marker[k]).powi(2)).sum::<f64>().sqrt())
        .fold(f64::MAX, f64::min);
    assert!(nearest > 0.05 * diag, "the marked sample is {nearest} from the mesh, the diagonal is {diag}");

    // A degenerate mesh: no surface, so a fan per face; the face and its
    // coincident vertices are named.
    let (status, _, body) = send(&app, get(&format!("/v1/viewer/stages/{i_degenerate}"))).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    let answered: Value = serde_json::from_slice(&body).unwrap();
    let r = json_of(&app, get(&format!("/v1/viewer/stages/{i_degenerate}/refusal"))).await;
    assert_eq!(r["code"], answered["code"], "the refusal carries the service's code: {r}");
    assert!(r["message"].as_str().unwrap().contains("coincident"), "{r}");
    assert_eq!(r["mesh"]["triangulation"], "fan");
    let h = &r["highlight"];
    assert_eq!(h["element"], "faces", "{h}");
    let faces = ints(&h["faces"]);
    assert!(!faces.is_empty());
    assert!(ints(&h["vertices"]).contains(&(a as u64)) && ints(&h["vertices"]).contains(&(b as u64)), "{h}");
    assert!(!ints(&h["triangles"]).is_empty(), "the named face is filled");
    assert!(h.get("bounds").is_some());

    // A stage that binds has no refusal.
    let (status, _, body) = send(&app, get(&format!("/v1/viewer/stages/{i_good}/refusal"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{}", String::from_utf8_lossy(&body));
    let doc = json_of(&app, get("/openapi.json")).await;
    assert!(doc["paths"].get("/v1/viewer/stages/{index}/refusal").is_some());
}

use common::Served;

/// An opened caged stage (fixtures/shots/hand_caged: a cage coupled with
/// the skeleton): the viewer's data carry the cage's wireframe, and each
/// frame is what `curvenet bake` writes and carries the cage where it
/// deforms the mesh: the posed cage of core's coupled rig, evaluated here
/// from the stage's own data.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_opened_caged_stage_draws_its_posed_cage_and_bakes_alike() {
    use curvenet_core::{CageFrame, CageRevApproximation, CoupledRig, CoupledWorkspace, fan_triangles};
    use curvenet_core::{Influences, MAT4_IDENTITY, Skeleton, Skin, SkinningMethod};
    const CAGED: &str = "fixtures/shots/hand_caged/shot.usda";
    let stage = Stage::open(common::repo().join(CAGED)).unwrap();
    let mesh = stage.deformed_meshes().unwrap().remove(0);
    let n = mesh.projection_points.len();
    let cage = stage.cage(&mesh).unwrap().unwrap();
    let rig = stage.skin_rig(&mesh).unwrap().unwrap();
    let skeleton = Skeleton::new(&rig.parents, &rig.bind_transforms).unwrap();
    let mut influences =
        Influences::new(n, rig.element_size, &rig.joint_indices, &rig.joint_weights, rig.joints.len()).unwrap();
    influences.renormalize(1e-4);
    let skin = Skin::new(influences, rig.geom_bind_transform, SkinningMethod::CentersOfRotation).unwrap();
    let topology = PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, n).unwrap();
    let coupled = CoupledRig::new(
        &cage.rest_points,
        &cage.triangles,
        &mesh.projection_points,
        &fan_triangles(&topology),
        Some((&skeleton, &skin)),
        CageRevApproximation::default(),
    )
    .unwrap();

    let server = Served::start(&["--open-stage", CAGED]);
    let client = reqwest::Client::new();
    let base = &server.url;
    let get = |url: String| common::get_json(client.clone(), url);
    let listed = get(format!("{base}/v1/viewer/stages")).await;
    let times = floats(&listed["stages"][0]["times"]);
    assert_eq!(times, (1..=10).map(f64::from).collect::<Vec<_>>(), "the cage's frames");
    let opened = get(format!("{base}/v1/viewer/stages/0")).await;
    let id = opened["binding"]["binding_id"].as_str().unwrap().to_string();
    assert_eq!(opened["binding"]["cage"]["vertices"], cage.rest_points.len());
    let data = get(format!("{base}/v1/bindings/{id}/viewer-data")).await;
    let view = &data["cage"];
    let c = cage.rest_points.len();
    let bind: Vec<f64> = cage.rest_points.iter().flatten().map(|x| *x as f32 as f64).collect();
    // f32 values written as their shortest decimals, read back as those f32.
    let f32s = |v: &Value| floats(v).into_iter().map(|x| x as f32 as f64).collect::<Vec<f64>>();
    assert!(f32s(&view["points"]) == bind, "the bind cage");
    assert_eq!(ints(&view["triangles"]).len(), 3 * cage.triangles.len());
    // A closed triangle cage has 3T/2 edges, each drawn once.
    let edges = ints(&view["edges"]);
    assert_eq!(edges.len() / 2, 3 * cage.triangles.len() / 2);
    assert!(edges.iter().all(|&v| (v as usize) < c));

    let diagonal = data["diagonal"].as_f64().unwrap();
    let dir = common::temp_dir("viewer", "caged");
    let out = dir.join("baked.usda");
    let run = common::curvenet(&["bake", CAGED, "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", common::stderr(&run));
    let baked = curvenet_schema::usd::read_points_overrides(&out).unwrap().prims.remove(0).samples;
    std::fs::remove_dir_all(&dir).unwrap();
    let mut moved = 0.0f64;
    for (k, &t) in times.iter().enumerate() {
        let frame = get(format!("{base}/v1/viewer/stages/0/frames/{k}")).await;
        let shown = f32s(&frame["points"]);
        let bake: Vec<f64> = baked[k].1.iter().flat_map(|p| p.map(f64::from)).collect();
        assert_eq!(baked[k].0, t);
        let d = max_diff(&shown, &bake);
        assert!(d <= 1e-6 * diagonal, "frame {t}: the viewer is {d} off the bake");
        // The posed cage of the coupled rig at this frame, from the stage's data.
        let local = stage.joint_local_transforms(&rig, Some(t)).unwrap();
        let mut transforms = vec![MAT4_IDENTITY; local.len()];
        skeleton.skinning_transforms(&local, &mut transforms).unwrap();
        assert_eq!(stage.skel_to_mesh_transform(&rig, Some(t)).unwrap(), MAT4_IDENTITY);
        let edits = cage.frame(Some(t));
        let mut ws = CoupledWorkspace::default();
        let mut rest = vec![[0.0; 3]; n];
        let input = CageFrame {
            base: None,
            rest_cage: edits.rest_cage(),
            joint_transforms: Some(&transforms),
            posed_cage_offsets: edits.posed_cage_offsets(),
        };
        coupled.evaluate(&input, &mut ws, &mut rest).unwrap();
        let want: Vec<f64> = ws.posed_cage().iter().flatten().copied().collect();
        let got = f32s(&frame["cage"]);
        assert_eq!(got.len(), 3 * c, "frame {t}: one point per cage vertex");
        let e = max_diff(&got, &want);
        assert!(e <= 1e-6 * diagonal, "frame {t}: the drawn cage is {e} off the posed cage");
        moved = moved.max(max_diff(&got, &bind));
    }
    assert!(moved > 1e-2 * diagonal, "the cage drawn moves with the frames ({moved})");
}
