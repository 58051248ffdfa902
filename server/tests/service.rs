//! The HTTP service driven through its router (`app(state).oneshot`), plus
//! one test over a real socket with graceful shutdown.

use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use axum::Router;
use axum::body::{Body, Bytes};
use axum::http::{Request, StatusCode, header};
use curvenet_core::{CurvenetInput, Deformer, DeformerInput, DeformerOptions, Frame};
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingRequest, BindingResponse, FrameRequest};
use curvenet_server::{AppState, BakeJob, Baker, Code, Config, app};
use serde_json::{Value, json};

mod common;
use common::router::{get, metric, post_binding, post_json, send};

fn fixtures() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures")
}

/// The hand_1k4 fixture as a binding request (read once).
fn hand() -> &'static BindingRequest {
    static HAND: OnceLock<BindingRequest> = OnceLock::new();
    HAND.get_or_init(|| request_from_stage(&fixtures().join("hand/hand_1k4.usda")))
}

pub fn request_from_stage(path: &std::path::Path) -> BindingRequest {
    let stage = Stage::open(path).unwrap();
    let mesh = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
    let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    BindingRequest::from_stage(&mesh, &nets)
}

/// The same binding computed in-process.
fn reference(req: &BindingRequest) -> Deformer {
    let curvenets: Vec<CurvenetInput> = req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
    Deformer::new(&DeformerInput {
        mesh: req.mesh_input(),
        curvenets: &curvenets,
        blend_shapes: Vec::new(),
        skinning: None,
        cage: None,
        options: DeformerOptions::default(),
    })
    .unwrap()
}

fn hand_reference() -> &'static Deformer {
    static B: OnceLock<Deformer> = OnceLock::new();
    B.get_or_init(|| reference(hand()))
}

fn deform_reference(b: &Deformer, pool: Option<&[[f64; 3]]>) -> Vec<[f64; 3]> {
    let posed = [pool];
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.frame(&Frame { posed: &posed, ..Default::default() }, &mut out, None).unwrap();
    out
}

/// The pool rotated rigidly by `deg` about z and shifted.
fn rotated(pool: &[[f64; 3]], deg: f64) -> Vec<[f64; 3]> {
    let (s, c) = deg.to_radians().sin_cos();
    pool.iter().map(|p| [c * p[0] - s * p[1] + 0.01, s * p[0] + c * p[1], p[2] - 0.02]).collect()
}

fn to_f32(ps: &[[f64; 3]]) -> Vec<[f64; 3]> {
    ps.iter().map(|p| p.map(|x| x as f32 as f64)).collect()
}

/// Largest difference, relative to max(1, |reference|).
fn max_rel_diff(got: &[[f64; 3]], want: &[[f64; 3]]) -> f64 {
    assert_eq!(got.len(), want.len());
    got.iter()
        .zip(want)
        .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs() / b[i].abs().max(1.0)))
        .fold(0.0, f64::max)
}

/// f32 precision, with room for a few roundings.
const F32_TOL: f64 = 4.0 * f32::EPSILON as f64;

fn state_with(config: Config) -> AppState {
    AppState::new(config, None).unwrap()
}

fn test_config() -> Config {
    Config { solve_threads: 2, ..Config::default() }
}

fn post_binary(uri: &str, body: Vec<u8>) -> Request<Body> {
    Request::post(uri).header(header::CONTENT_TYPE, "application/octet-stream").body(Body::from(body)).unwrap()
}

fn error_code(body: &[u8]) -> String {
    let v: Value =
        serde_json::from_slice(body).unwrap_or_else(|_| panic!("not JSON: {}", String::from_utf8_lossy(body)));
    v["code"].as_str().unwrap().to_string()
}

fn json_points(v: &Value) -> Vec<[f64; 3]> {
    v.as_array().unwrap().iter().map(|p| [0, 1, 2].map(|i| p[i].as_f64().unwrap())).collect()
}

/// A binary frame body: header then arrays.
fn binary_frame(header: &Value, arrays: &[&[f32]]) -> Vec<u8> {
    let h = serde_json::to_vec(header).unwrap();
    let mut out = (h.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    for a in arrays {
        for x in *a {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    out
}

fn flat_f32(ps: &[[f64; 3]]) -> Vec<f32> {
    ps.iter().flat_map(|p| p.map(|x| x as f32)).collect()
}

/// Splits a binary answer into its header and f32 data.
fn parse_binary(body: &[u8]) -> (Value, Vec<f32>) {
    let h = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    assert_eq!((4 + h) % 4, 0, "arrays start aligned");
    let header: Value = serde_json::from_slice(&body[4..4 + h]).unwrap();
    let data = body[4 + h..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    (header, data)
}

fn triples(data: &[f32]) -> Vec<[f64; 3]> {
    data.chunks_exact(3).map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reposting_a_binding_returns_its_id_without_recomputing() {
    let app = app(state_with(test_config()));
    let first = post_binding(&app, hand()).await;
    assert!(!first.cached);
    assert_eq!(first.binding_id.len(), 64);
    assert_eq!(first.vertices, hand().projection_points.len());
    assert_eq!(first.control_points, vec![hand().curvenets[0].pool.len()]);
    assert!(first.stats.factor_nonzeros > 0 && first.timings.factor_ms >= 0.0);
    let again = post_binding(&app, hand()).await;
    assert!(again.cached);
    assert_eq!(again.binding_id, first.binding_id);
    // The USD spellings, reordered fields and an explicit default option hash alike.
    let mut v = serde_json::to_value(hand()).unwrap();
    let o = v.as_object_mut().unwrap();
    let counts = o.remove("face_vertex_counts").unwrap();
    o.insert("faceVertexCounts".into(), counts);
    o.insert("options".into(), json!({"snap_tolerance": 1e-5, "strict": false}));
    let (status, _, body) = send(&app, post_json("/v1/bindings", &v)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let third: BindingResponse = serde_json::from_slice(&body).unwrap();
    assert_eq!(third.binding_id, first.binding_id);
    assert!(third.cached);
    assert_eq!(metric(&app, "curvenet_bindings_computed_total").await, 1.0);
    assert_eq!(metric(&app, "curvenet_cache_hits_total").await, 2.0);
    assert_eq!(metric(&app, "curvenet_cache_misses_total").await, 1.0);
    assert!(metric(&app, "curvenet_cache_bytes").await > 0.0);
    // A different option is a different binding.
    let mut other = hand().clone();
    other.options.snap_tolerance = Some(2e-5);
    let other = post_binding(&app, &other).await;
    assert_ne!(other.binding_id, first.binding_id);
    assert_eq!(other.topology_hash, first.topology_hash);
    // GET describes a cached binding.
    let (status, _, body) = send(&app, get(&format!("/v1/bindings/{}", first.binding_id))).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id, first.binding_id);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eight_concurrent_posts_of_one_new_binding_compute_it_once() {
    let app = app(state_with(test_config()));
    let tasks: Vec<_> = (0..8)
        .map(|_| {
            let app = app.clone();
            tokio::spawn(async move { post_binding(&app, hand()).await })
        })
        .collect();
    let mut ids = Vec::new();
    let mut fresh = 0;
    for t in tasks {
        let r = t.await.unwrap();
        fresh += usize::from(!r.cached);
        ids.push(r.binding_id);
    }
    assert!(ids.iter().all(|i| *i == ids[0]));
    assert_eq!(fresh, 1);
    assert_eq!(metric(&app, "curvenet_bindings_computed_total").await, 1.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_and_binary_frames_equal_the_in_process_solve() {
    let app = app(state_with(test_config()));
    let id = post_binding(&app, hand()).await.binding_id;
    let b = hand_reference();
    let pool = &hand().curvenets[0].pool;
    let uri = format!("/v1/bindings/{id}/frames");

    // JSON: neutral (no posed pools) and a rigid rotation, with gradients.
    let (status, h, body) = send(&app, post_json(&uri, &json!({}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    assert!(h.get("x-request-id").is_some());
    let v: Value = serde_json::from_slice(&body).unwrap();
    let got = json_points(&v["points"]);
    assert!(max_rel_diff(&got, &deform_reference(b, None)) <= F32_TOL);
    assert!(v.get("gradients").is_none());

    let pose = rotated(pool, 35.0);
    let frame = FrameRequest { posed: Some(vec![Some(pose.clone())]), gradients: true, ..Default::default() };
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let v: Value = serde_json::from_slice(&body).unwrap();
    let want = deform_reference(b, Some(&pose));
    assert!(max_rel_diff(&json_points(&v["points"]), &want) <= F32_TOL);
    // A rigid motion: every vertex's gradient is the rotation.
    let g = v["gradients"][0].as_array().unwrap();
    assert_eq!(g.len(), 9);
    let (s, c) = 35f64.to_radians().sin_cos();
    for (x, r) in g.iter().zip([c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0]) {
        assert!((x.as_f64().unwrap() - r).abs() < 1e-4, "{g:?}");
    }

    // Binary: the same pose sent as f32; the reference gets the same f32-rounded pool.
    let pose32 = to_f32(&pose);
    let want = deform_reference(b, Some(&pose32));
    let body = binary_frame(
        &json!({"arrays": [{"name": "posed", "index": 0, "shape": [pool.len(), 3]}]}),
        &[&flat_f32(&pose)],
    );
    let (status, h, body) = send(&app, post_binary(&uri, body)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    assert_eq!(h[header::CONTENT_TYPE], "application/octet-stream");
    let (header, data) = parse_binary(&body);
    assert_eq!(header["arrays"][0]["name"], "points");
    assert_eq!(header["arrays"][0]["shape"], json!([b.n_vertices(), 3]));
    assert!(max_rel_diff(&triples(&data), &want) <= F32_TOL);

    // Binary with gradients and no posed array (neutral).
    let body = binary_frame(&json!({"arrays": [], "gradients": true}), &[]);
    let (status, _, body) = send(&app, post_binary(&uri, body)).await;
    assert_eq!(status, StatusCode::OK);
    let (header, data) = parse_binary(&body);
    assert_eq!(header["arrays"][1]["shape"], json!([b.n_vertices(), 9]));
    assert_eq!(data.len(), b.n_vertices() * 12);
    assert!(max_rel_diff(&triples(&data[..b.n_vertices() * 3]), &deform_reference(b, None)) <= F32_TOL);
}

/// A binding's size counts, from the start, the group workspaces batches
/// make it keep (per solve thread, the group's block: 96 bytes per frame
/// per unknown and constraint row, and its frames' workspaces), so the
/// cache's bytes do not grow behind its bound when batches come: neither a
/// single frame nor batches change them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn binding_sizes_count_group_workspaces_before_any_batch() {
    let app = app(state_with(test_config()));
    let bound = post_binding(&app, hand()).await;
    let id = &bound.binding_id;
    // A second solve thread adds a frame workspace and a group workspace,
    // which holds at least its block.
    let one = post_binding(&app_with(Config { solve_threads: 1, ..test_config() }), hand()).await;
    assert_eq!(test_config().solve_threads, 2);
    let rows = (bound.stats.unknowns + bound.stats.constraints) as u64;
    let block = curvenet_core::DEFAULT_BATCH_FRAMES as u64 * 96 * rows;
    let added = bound.size_bytes - one.size_bytes;
    assert!(added > block, "a second solve thread adds {added} bytes, less than a group's block ({block})");
    let before = metric(&app, "curvenet_cache_bytes").await;
    assert!(
        before >= bound.size_bytes as f64 && before < (bound.size_bytes + 1024) as f64,
        "{before} vs {}",
        bound.size_bytes
    );
    let pool = &hand().curvenets[0].pool;
    let frame = |a: f64| FrameRequest { posed: Some(vec![Some(rotated(pool, a))]), ..Default::default() };
    let (status, _, body) = send(&app, post_json(&format!("/v1/bindings/{id}/frames"), &frame(20.0))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let batch = json!({ "frames": [frame(0.0), frame(10.0), frame(-25.0), frame(40.0)] });
    let uri = format!("/v1/bindings/{id}/frames:batch");
    for _ in 0..2 {
        let (status, _, body) = send(&app, post_json(&uri, &batch)).await;
        assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
        assert_eq!(metric(&app, "curvenet_cache_bytes").await, before, "the cache's bytes moved");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_answer_in_frame_order() {
    let app = app(state_with(test_config()));
    let id = post_binding(&app, hand()).await.binding_id;
    let b = hand_reference();
    let pool = &hand().curvenets[0].pool;
    let angles = [0.0, 10.0, -25.0, 40.0, 5.0, 90.0];
    let poses: Vec<Vec<[f64; 3]>> = angles.iter().map(|&a| rotated(pool, a)).collect();
    let frames: Vec<FrameRequest> =
        poses.iter().map(|p| FrameRequest { posed: Some(vec![Some(p.clone())]), ..Default::default() }).collect();
    let uri = format!("/v1/bindings/{id}/frames:batch");
    let (status, _, body) = send(&app, post_json(&uri, &json!({ "frames": frames }))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let v: Value = serde_json::from_slice(&body).unwrap();
    let got = v["frames"].as_array().unwrap();
    assert_eq!(got.len(), angles.len());
    for (f, pose) in got.iter().zip(&poses) {
        assert!(max_rel_diff(&json_points(&f["points"]), &deform_reference(b, Some(pose))) <= F32_TOL);
    }
    // The binary batch.
    let header = json!({"frames": poses.iter().map(|_| json!({"arrays": [{"name": "posed", "index": 0, "shape": [pool.len(), 3]}]})).collect::<Vec<_>>()});
    let flats: Vec<Vec<f32>> = poses.iter().map(|p| flat_f32(p)).collect();
    let arrays: Vec<&[f32]> = flats.iter().map(|f| f.as_slice()).collect();
    let (status, _, body) = send(&app, post_binary(&uri, binary_frame(&header, &arrays))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let (header, data) = parse_binary(&body);
    assert_eq!(header["frames"].as_array().unwrap().len(), poses.len());
    let n = b.n_vertices() * 3;
    for (i, pose) in poses.iter().enumerate() {
        let want = deform_reference(b, Some(&to_f32(pose)));
        assert!(max_rel_diff(&triples(&data[i * n..(i + 1) * n]), &want) <= F32_TOL, "frame {i}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_bad_input_gets_its_status_and_code_and_a_good_frame_still_works() {
    let app = app(state_with(test_config()));
    let bound = post_binding(&app, hand()).await;
    let id = bound.binding_id.clone();
    let pool = hand().curvenets[0].pool.clone();
    let np = pool.len();
    let nv = hand().projection_points.len();
    let uri = format!("/v1/bindings/{id}/frames");
    let good = || post_json(&format!("/v1/bindings/{id}/frames"), &json!({"posed": [rotated(&pool, 20.0)]}));
    let mut nan_pool = flat_f32(&pool);
    nan_pool[3 * 17 + 1] = f32::NAN;
    let mut short_binding = hand().clone();
    short_binding.face_vertex_indices.pop();
    let mut oob_binding = hand().clone();
    oob_binding.face_vertex_indices[5] = nv as u32 + 3;
    let mut bad_spline = hand().clone();
    bad_spline.curvenets[0].splines[2][1] = np as u32 + 1;
    let mut no_nets = hand().clone();
    no_nets.curvenets.clear();
    let mut bad_density = hand().clone();
    bad_density.curvenets[0].sample_density = -1.0;
    let mut bad_snap = hand().clone();
    bad_snap.options.snap_tolerance = Some(0.5);
    let mut far = hand().clone();
    for p in &mut far.curvenets[0].pool {
        p[2] += 100.0;
    }
    let pool_needle = format!("posed[0] has {}", np - 1);
    let vertex_needle = format!("{}", nv + 3);
    let cases: Vec<(&str, Request<Body>, StatusCode, &str, &str)> = vec![
        (
            "syntax",
            post_json(&uri, &json!("{")).map(|_| Body::from("{\"posed\": [")),
            StatusCode::BAD_REQUEST,
            "malformed_json",
            "line",
        ),
        (
            "NaN literal",
            Request::post(&uri).body(Body::from("{\"posed\": [[[NaN, 0, 0]]]}")).unwrap(),
            StatusCode::BAD_REQUEST,
            "malformed_json",
            "",
        ),
        (
            "unknown field",
            post_json(&uri, &json!({"poses": []})),
            StatusCode::BAD_REQUEST,
            "malformed_json",
            "unknown field",
        ),
        (
            "media type",
            Request::post(&uri).header(header::CONTENT_TYPE, "text/plain").body(Body::from("x")).unwrap(),
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "text/plain",
        ),
        (
            "posed count",
            post_json(&uri, &json!({"posed": [null, null]})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "count_mismatch",
            "2 entries",
        ),
        (
            "pool size",
            post_json(&uri, &json!({"posed": [&pool[1..]]})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "count_mismatch",
            &pool_needle,
        ),
        (
            "rest size",
            post_json(&uri, &json!({"rest": [[0.0, 0.0, 0.0]]})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "count_mismatch",
            "rest has 1 points",
        ),
        (
            "weights without shapes",
            post_json(&uri, &json!({"blend_shape_weights": [1.0]})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "count_mismatch",
            "blend_shape_weights",
        ),
        (
            "binary NaN",
            post_binary(
                &uri,
                binary_frame(&json!({"arrays": [{"name": "posed", "index": 0, "shape": [np, 3]}]}), &[&nan_pool]),
            ),
            StatusCode::UNPROCESSABLE_ENTITY,
            "non_finite",
            "posed[0][17]",
        ),
        (
            "binary short",
            post_binary(
                &uri,
                binary_frame(&json!({"arrays": [{"name": "posed", "index": 0, "shape": [np, 3]}]}), &[&nan_pool[..30]]),
            ),
            StatusCode::BAD_REQUEST,
            "malformed_binary",
            "needs",
        ),
        (
            "binary trailing",
            post_binary(&uri, binary_frame(&json!({"arrays": []}), &[&[1.0]])),
            StatusCode::BAD_REQUEST,
            "malformed_binary",
            "4 bytes follow",
        ),
        (
            "binary dtype",
            post_binary(
                &uri,
                binary_frame(&json!({"arrays": [{"name": "rest", "dtype": "f64", "shape": [1, 3]}]}), &[&[0.0; 6]]),
            ),
            StatusCode::BAD_REQUEST,
            "malformed_binary",
            "dtype",
        ),
        (
            "binary curvenet index",
            post_binary(
                &uri,
                binary_frame(
                    &json!({"arrays": [{"name": "posed", "index": 3, "shape": [np, 3]}]}),
                    &[&flat_f32(&pool)],
                ),
            ),
            StatusCode::UNPROCESSABLE_ENTITY,
            "index_out_of_range",
            "posed index 3",
        ),
        (
            "binary header length",
            post_binary(&uri, vec![200, 0, 0, 0, b'{']),
            StatusCode::BAD_REQUEST,
            "malformed_binary",
            "header length",
        ),
        (
            "topology changed",
            post_json(&uri, &json!({"topology_hash": "00".repeat(32)})),
            StatusCode::CONFLICT,
            "topology_changed",
            &bound.topology_hash,
        ),
        (
            "unknown binding",
            post_json(&format!("/v1/bindings/{}/frames", "ab".repeat(32)), &json!({})),
            StatusCode::NOT_FOUND,
            "unknown_binding",
            "POST /v1/bindings",
        ),
        (
            "malformed id",
            post_json("/v1/bindings/xyz/frames", &json!({})),
            StatusCode::NOT_FOUND,
            "unknown_binding",
            "xyz",
        ),
        ("no route", get("/v2/nothing"), StatusCode::NOT_FOUND, "not_found", ""),
        ("method", get("/v1/bindings"), StatusCode::METHOD_NOT_ALLOWED, "method_not_allowed", ""),
        (
            "face counts",
            post_json("/v1/bindings", &short_binding),
            StatusCode::UNPROCESSABLE_ENTITY,
            "count_mismatch",
            "face vertex counts sum",
        ),
        (
            "vertex index",
            post_json("/v1/bindings", &oob_binding),
            StatusCode::UNPROCESSABLE_ENTITY,
            "index_out_of_range",
            &vertex_needle,
        ),
        (
            "spline index",
            post_json("/v1/bindings", &bad_spline),
            StatusCode::UNPROCESSABLE_ENTITY,
            "index_out_of_range",
            "curvenets[0].splines[2]",
        ),
        (
            "no curvenets",
            post_json("/v1/bindings", &no_nets),
            StatusCode::UNPROCESSABLE_ENTITY,
            "empty_input",
            "curvenets",
        ),
        (
            "density",
            post_json("/v1/bindings", &bad_density),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_parameter",
            "sample_density",
        ),
        (
            "snap",
            post_json("/v1/bindings", &bad_snap),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_parameter",
            "snap_tolerance",
        ),
        (
            "far from surface",
            post_json("/v1/bindings", &far),
            StatusCode::UNPROCESSABLE_ENTITY,
            "binding_failed",
            "from the surface",
        ),
        (
            "negative index",
            Request::post("/v1/bindings")
                .body(Body::from(serde_json::to_string(hand()).unwrap().replacen(
                    "\"face_vertex_indices\":[",
                    "\"face_vertex_indices\":[-1,",
                    1,
                )))
                .unwrap(),
            StatusCode::BAD_REQUEST,
            "malformed_json",
            "-1",
        ),
    ];
    for (name, req, status, code, needle) in cases {
        let (got, headers, body) = send(&app, req).await;
        let text = String::from_utf8_lossy(&body).to_string();
        assert_eq!(got, status, "{name}: {text}");
        assert_eq!(error_code(&body), code, "{name}: {text}");
        assert!(text.contains(needle), "{name}: {text} lacks {needle:?}");
        assert!(headers.get("x-request-id").is_some(), "{name}");
        let (ok, _, body) = send(&app, good()).await;
        assert_eq!(ok, StatusCode::OK, "after {name}: {}", String::from_utf8_lossy(&body));
    }
    // A pool of the wrong size names its curvenet in details, in both forms.
    let short_json = post_json(&uri, &json!({"posed": [&pool[1..]]}));
    let short_binary = post_binary(
        &uri,
        binary_frame(
            &json!({"arrays": [{"name": "posed", "index": 0, "shape": [np - 1, 3]}]}),
            &[&flat_f32(&pool[1..])],
        ),
    );
    for (form, req) in [("JSON", short_json), ("binary", short_binary)] {
        let (status, _, body) = send(&app, req).await;
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{form}: {v}");
        assert_eq!(v["code"], "count_mismatch", "{form}: {v}");
        assert_eq!(v["details"]["curvenet"], 0, "{form}: {v}");
        assert_eq!(v["details"]["what"], "posed", "{form}: {v}");
    }
    // A rest pose collapsed to a point collapses the curvenet tracked onto
    // it: a degenerate pose that names the rest pose and the curvenet.
    let collapsed = vec![[0.25, 0.5, -0.125]; nv];
    let (status, _, body) = send(&app, post_json(&uri, &json!({"rest": collapsed}))).await;
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{v}");
    assert_eq!(v["code"], "degenerate_pose", "{v}");
    assert!(v["message"].as_str().unwrap().starts_with("curvenets[0]: tracked onto the frame's rest pose: "), "{v}");
    assert_eq!(v["details"]["curvenet"], 0, "{v}");
    assert_eq!(v["details"]["what"], "rest", "{v}");
    // A bad frame in a batch is named by its index.
    let batch = json!({"frames": [{}, {"posed": [&pool[2..]]}]});
    let (status, _, body) = send(&app, post_json(&format!("/v1/bindings/{id}/frames:batch"), &batch)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(String::from_utf8_lossy(&body).contains("frames[1]: posed[0]"), "{}", String::from_utf8_lossy(&body));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bodies_over_the_limit_get_413() {
    let app = app(state_with(Config { body_limit: 4096, ..test_config() }));
    let big = vec![b' '; 10_000];
    let (status, _, body) = send(&app, Request::post("/v1/bindings").body(Body::from(big.clone())).unwrap()).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(error_code(&body), "payload_too_large");
    // A streamed body without Content-Length.
    let chunks: Vec<Result<Bytes, std::io::Error>> = (0..10).map(|_| Ok(Bytes::from(vec![b' '; 1000]))).collect();
    let stream = Body::from_stream(futures_util::stream::iter(chunks));
    let (status, _, body) = send(&app, Request::post("/v1/bindings").body(stream).unwrap()).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(error_code(&body), "payload_too_large");
    // Above axum's 2 MB default but within a larger configured limit: accepted (the binding parses).
    let app = app_with_limit(8 << 20);
    let mut padded = serde_json::to_vec(hand()).unwrap();
    padded.truncate(padded.len() - 1);
    padded.extend(std::iter::repeat_n(b' ', 3 << 20));
    padded.push(b'}');
    let (status, _, body) = send(&app, Request::post("/v1/bindings").body(Body::from(padded)).unwrap()).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
}

fn app_with_limit(limit: usize) -> Router {
    app(state_with(Config { body_limit: limit, ..test_config() }))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn saturation_answers_503_with_retry_after() {
    let app = app(state_with(Config { max_solves: 0, ..test_config() }));
    let (status, headers, body) = send(&app, post_json("/v1/bindings", hand())).await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(error_code(&body), "saturated");
    assert_eq!(headers[header::RETRY_AFTER], "1");
    // Health stays up.
    assert_eq!(send(&app, get("/healthz")).await.0, StatusCode::OK);
    assert_eq!(metric(&app, "curvenet_saturated_total").await, 1.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bearer_token_guards_everything_but_health() {
    let app = app(state_with(Config { token: Some("s3cret".into()), ..test_config() }));
    let (status, headers, body) = send(&app, post_json("/v1/bindings", hand())).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert_eq!(error_code(&body), "unauthorized");
    assert_eq!(headers[header::WWW_AUTHENTICATE], "Bearer");
    let wrong = Request::get("/metrics").header(header::AUTHORIZATION, "Bearer nope").body(Body::empty()).unwrap();
    let (status, _, body) = send(&app, wrong).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert!(String::from_utf8_lossy(&body).contains("wrong"));
    let right = Request::get("/metrics").header(header::AUTHORIZATION, "Bearer s3cret").body(Body::empty()).unwrap();
    assert_eq!(send(&app, right).await.0, StatusCode::OK);
    assert_eq!(send(&app, get("/healthz")).await.0, StatusCode::OK);
    assert_eq!(send(&app, get("/readyz")).await.0, StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bake_paths_must_stay_inside_the_roots() {
    let root = std::env::temp_dir().join(format!("curvenet-service-bake-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(root.join("shots")).unwrap();
    let outside = std::env::temp_dir().join(format!("curvenet-service-outside-{}", std::process::id()));
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(outside.join("secret.usda"), "#usda 1.0\n").unwrap();
    std::fs::write(root.join("shots/shot.usda"), "#usda 1.0\n").unwrap();
    #[cfg(unix)]
    {
        let _ = std::os::unix::fs::symlink(outside.join("secret.usda"), root.join("shots/link.usda"));
        let _ = std::os::unix::fs::symlink(&outside, root.join("escape"));
    }
    let jobs: Arc<Mutex<Vec<BakeJob>>> = Arc::default();
    let baker: Baker = {
        let jobs = jobs.clone();
        Arc::new(move |job: &BakeJob| {
            jobs.lock().unwrap().push(job.clone());
            Ok(vec![format!("{}: a warning", job.stage.display())])
        })
    };
    let state = AppState::new(Config { bake_roots: vec![root.clone()], ..test_config() }, Some(baker.clone())).unwrap();
    let app = app(state);
    let bake = |stage: String, output: String| post_json("/v1/bake", &json!({"stage": stage, "output": output}));
    let r = root.display().to_string();
    let forbidden = [
        (outside.join("secret.usda").display().to_string(), format!("{r}/out.usda")),
        (format!("{r}/../{}/secret.usda", outside.file_name().unwrap().to_string_lossy()), format!("{r}/out.usda")),
        ("../../etc/passwd".to_string(), "out.usda".to_string()),
        (format!("{r}/shots/link.usda"), format!("{r}/out.usda")),
        (format!("{r}/shots/shot.usda"), outside.join("out.usda").display().to_string()),
        (format!("{r}/shots/shot.usda"), format!("{r}/escape/out.usda")),
        (format!("{r}/shots/shot.usda"), format!("{r}/shots/../../out.usda")),
    ];
    for (stage, output) in forbidden {
        let (status, _, body) = send(&app, bake(stage.clone(), output.clone())).await;
        assert_eq!(status, StatusCode::FORBIDDEN, "{stage} → {output}: {}", String::from_utf8_lossy(&body));
        assert_eq!(error_code(&body), "path_forbidden");
    }
    assert!(jobs.lock().unwrap().is_empty());
    let (status, _, body) = send(&app, bake(format!("{r}/shots/missing.usda"), format!("{r}/out.usda"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{}", String::from_utf8_lossy(&body));
    assert_eq!(error_code(&body), "stage_not_found");
    // Inside: relative to the first root, and absolute.
    let (status, _, body) = send(&app, bake("shots/shot.usda".into(), "shots/baked.usda".into())).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let canonical = std::fs::canonicalize(&root).unwrap();
    let job = jobs.lock().unwrap()[0].clone();
    assert_eq!(job.stage, canonical.join("shots/shot.usda"));
    assert_eq!(job.output, canonical.join("shots/baked.usda"));
    // The baker's warnings are the answer's.
    let answer: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(answer["warnings"], json!([format!("{}: a warning", job.stage.display())]));
    // A root configured through a symlink takes absolute paths given
    // through that name (they resolve to the canonical root).
    #[cfg(unix)]
    {
        let link = std::env::temp_dir().join(format!("curvenet-service-bake-link-{}", std::process::id()));
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&root, &link).unwrap();
        let linked = curvenet_server::app(
            AppState::new(Config { bake_roots: vec![link.clone()], ..test_config() }, Some(baker.clone())).unwrap(),
        );
        let l = link.display().to_string();
        let (status, _, body) =
            send(&linked, bake(format!("{l}/shots/shot.usda"), format!("{l}/shots/linked.usda"))).await;
        assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
        let job = jobs.lock().unwrap().last().unwrap().clone();
        assert_eq!(job.stage, canonical.join("shots/shot.usda"));
        assert_eq!(job.output, canonical.join("shots/linked.usda"));
        // Its name does not widen the roots: outside stays outside.
        let (status, _, _) = send(&linked, bake(format!("{l}/../etc/passwd"), format!("{l}/x.usda"))).await;
        assert_eq!(status, StatusCode::FORBIDDEN);
        let _ = std::fs::remove_file(&link);
    }
    // No roots: baking is refused.
    let app = app_no_roots();
    let (status, _, body) = send(&app, bake(format!("{r}/shots/shot.usda"), format!("{r}/out.usda"))).await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    assert!(String::from_utf8_lossy(&body).contains("--bake-root"));
    let _ = std::fs::remove_dir_all(&root);
    let _ = std::fs::remove_dir_all(&outside);
}

fn app_with(config: Config) -> Router {
    app(state_with(config))
}

fn app_no_roots() -> Router {
    app(state_with(test_config()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evicted_bindings_answer_unknown_binding_and_are_counted() {
    // Room for one hand binding, not two.
    let probe = app(state_with(test_config()));
    let size = post_binding(&probe, hand()).await.size_bytes;
    let app = app(state_with(Config { cache_bytes: size * 3 / 2, ..test_config() }));
    let first = post_binding(&app, hand()).await;
    let mut other = hand().clone();
    other.options.snap_tolerance = Some(3e-5);
    let second = post_binding(&app, &other).await;
    // moka evicts during its maintenance; /metrics runs it.
    assert!(metric(&app, "curvenet_cache_evictions_total").await >= 1.0);
    let (status, _, body) =
        send(&app, post_json(&format!("/v1/bindings/{}/frames", first.binding_id), &json!({}))).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(error_code(&body), "unknown_binding");
    let (status, _, _) = send(&app, post_json(&format!("/v1/bindings/{}/frames", second.binding_id), &json!({}))).await;
    assert_eq!(status, StatusCode::OK);
    assert!(metric(&app, "curvenet_cache_bytes").await <= (size * 3 / 2) as f64);
    // Resending the evicted binding brings it back.
    let again = post_binding(&app, hand()).await;
    assert_eq!(again.binding_id, first.binding_id);
    assert!(!again.cached);
    // A binding larger than the whole cache is refused up front.
    let tiny = app_with_cache(1024);
    let (status, _, body) = send(&tiny, post_json("/v1/bindings", hand())).await;
    assert_eq!(status, StatusCode::INSUFFICIENT_STORAGE, "{}", String::from_utf8_lossy(&body));
    assert_eq!(error_code(&body), "cache_too_small");
}

fn app_with_cache(bytes: u64) -> Router {
    app(state_with(Config { cache_bytes: bytes, ..test_config() }))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_shot_deform_uses_the_cache_and_blend_shapes_apply() {
    let app = app(state_with(test_config()));
    let pool = &hand().curvenets[0].pool;
    let pose = rotated(pool, 15.0);
    let body = json!({"binding": hand(), "frame": {"posed": [pose]}});
    let (status, _, bytes) = send(&app, post_json("/v1/deform", &body)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&bytes));
    let v: Value = serde_json::from_slice(&bytes).unwrap();
    assert_eq!(v["cached"], false);
    assert!(
        max_rel_diff(&json_points(&v["frame"]["points"]), &deform_reference(hand_reference(), Some(&pose))) <= F32_TOL
    );
    let (_, _, bytes) = send(&app, post_json("/v1/deform", &body)).await;
    let again: Value = serde_json::from_slice(&bytes).unwrap();
    assert_eq!(again["cached"], true);
    assert_eq!(again["binding_id"], v["binding_id"]);
    assert_eq!(metric(&app, "curvenet_bindings_computed_total").await, 1.0);

    // A sparse blend shape lifting vertex 7: weight 0 changes nothing; in the
    // `before` mode at the neutral pose it moves the vertex by its offset.
    let mut with_shape = hand().clone();
    with_shape.blend_shapes = vec![
        serde_json::from_value(json!({"name": "lift", "offsets": [[0.0, 0.0, 0.01]], "point_indices": [7]})).unwrap(),
    ];
    let bound = post_binding(&app, &with_shape).await;
    assert_eq!(bound.blend_shapes, 1);
    assert_ne!(bound.binding_id, v["binding_id"].as_str().unwrap());
    let uri = format!("/v1/bindings/{}/frames", bound.binding_id);
    let neutral = deform_reference(hand_reference(), None);
    let (_, _, bytes) = send(&app, post_json(&uri, &json!({"blend_shape_weights": [0.0]}))).await;
    let zero = json_points(&serde_json::from_slice::<Value>(&bytes).unwrap()["points"]);
    assert!(max_rel_diff(&zero, &neutral) <= F32_TOL);
    let (_, _, bytes) = send(&app, post_json(&uri, &json!({"blend_shape_weights": [1.0]}))).await;
    let after = json_points(&serde_json::from_slice::<Value>(&bytes).unwrap()["points"]);
    // At the neutral pose F = I, so the sculpt adds its offset to vertex 7 only.
    assert!((after[7][2] - neutral[7][2] - 0.01).abs() < 1e-5, "{:?} vs {:?}", after[7], neutral[7]);
    assert!(max_rel_diff(&after[8..], &neutral[8..]) <= F32_TOL);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_describes_the_api() {
    let app = app(state_with(test_config()));
    let (status, _, body) = send(&app, get("/openapi.json")).await;
    assert_eq!(status, StatusCode::OK);
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert!(v["openapi"].as_str().unwrap().starts_with("3.1"));
    for path in [
        "/v1/bindings",
        "/v1/bindings/{id}/frames",
        "/v1/bindings/{id}/frames:batch",
        "/v1/deform",
        "/v1/bake",
        "/healthz",
    ] {
        assert!(v["paths"].get(path).is_some(), "{path} missing");
    }
    for schema in ["BindingRequest", "FrameRequest", "BinaryFrameHeader", "ErrorBody"] {
        assert!(v["components"]["schemas"].get(schema).is_some(), "{schema} missing");
    }
    // A client's request id is echoed.
    let req = Request::get("/healthz").header("x-request-id", "abc-123").body(Body::empty()).unwrap();
    assert_eq!(send(&app, req).await.1["x-request-id"], "abc-123");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_real_socket_serves_and_drains_on_shutdown() {
    let state = state_with(test_config());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(curvenet_server::run(listener, state.clone(), async move {
        let _ = stopped.await;
    }));
    let client = reqwest::Client::new();
    let base = format!("http://{addr}");
    assert_eq!(client.get(format!("{base}/healthz")).send().await.unwrap().status(), 200);
    let bound: BindingResponse =
        client.post(format!("{base}/v1/bindings")).json(hand()).send().await.unwrap().json().await.unwrap();
    let pool = &hand().curvenets[0].pool;
    let frames: Vec<FrameRequest> = (0..200)
        .map(|i| FrameRequest { posed: Some(vec![Some(rotated(pool, i as f64))]), ..Default::default() })
        .collect();
    // A batch in flight when the shutdown signal comes still completes.
    let in_flight = {
        let client = client.clone();
        let url = format!("{base}/v1/bindings/{}/frames:batch", bound.binding_id);
        tokio::spawn(async move { client.post(url).json(&json!({ "frames": frames })).send().await })
    };
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while state.solves_in_flight() == 0 {
        assert!(std::time::Instant::now() < deadline, "the batch never started");
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    stop.send(()).unwrap();
    let r = in_flight.await.unwrap().unwrap();
    assert_eq!(r.status(), 200);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["frames"].as_array().unwrap().len(), 200);
    tokio::time::timeout(Duration::from_secs(10), server).await.expect("the server stops").unwrap().unwrap();
    assert!(state.is_draining());
    // Nothing listens any more.
    assert!(tokio::net::TcpStream::connect(addr).await.is_err());
}

#[test]
fn the_readme_error_table_is_the_code_table() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let table =
        readme.split("<!-- error-codes: begin -->").nth(1).unwrap().split("<!-- error-codes: end -->").next().unwrap();
    let rows: Vec<(String, u16)> = table
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let code = cells.get(1)?.strip_prefix('`')?.strip_suffix('`')?;
            Some((code.to_string(), cells[2].parse().unwrap()))
        })
        .collect();
    assert_eq!(rows.len(), Code::ALL.len(), "{rows:?}");
    for (code, (name, status)) in Code::ALL.iter().zip(&rows) {
        assert_eq!(code.as_str(), name);
        assert_eq!(code.status().as_u16(), *status, "{name}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn error_bodies_name_the_elements_in_details() {
    let app = app(state_with(test_config()));
    let body = |b: &Bytes| serde_json::from_slice::<Value>(b).unwrap();

    // A curvenet far from the surface: the sample, its spline and curvenet.
    let mut far = hand().clone();
    for p in &mut far.curvenets[0].pool {
        p[2] += 100.0;
    }
    let (status, _, b) = send(&app, post_json("/v1/bindings", &far)).await;
    let v = body(&b);
    assert_eq!((status, v["code"].as_str()), (StatusCode::UNPROCESSABLE_ENTITY, Some("binding_failed")), "{v}");
    let d = &v["details"];
    assert_eq!(d["curvenet"], 0, "{v}");
    assert!(
        d["spline"].is_u64() && d["sample"].is_u64() && d["position"].as_array().is_some_and(|p| p.len() == 3),
        "{v}"
    );
    assert!(d.get("face").is_none() && d.get("frame").is_none(), "absent fields are omitted: {v}");

    // A spline whose control points coincide: its curvenet (from the
    // deformer's wrapping) and the spline, the message numbered as the request.
    let mut zero = hand().clone();
    let s0 = zero.curvenets[0].splines[0];
    let p0 = zero.curvenets[0].pool[s0[0] as usize];
    for k in s0 {
        zero.curvenets[0].pool[k as usize] = p0;
    }
    let (status, _, b) = send(&app, post_json("/v1/bindings", &zero)).await;
    let v = body(&b);
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{v}");
    assert!(v["message"].as_str().unwrap().starts_with("curvenets[0]: "), "{v}");
    assert_eq!(v["details"]["curvenet"], 0, "{v}");

    // Coincident corners of a face: invalid_mesh naming the face and both vertices.
    let mut flat = hand().clone();
    let (a, c) = (flat.face_vertex_indices[0], flat.face_vertex_indices[1]);
    flat.projection_points[c as usize] = flat.projection_points[a as usize];
    let (status, _, b) = send(&app, post_json("/v1/bindings", &flat)).await;
    let v = body(&b);
    assert_eq!((status, v["code"].as_str()), (StatusCode::UNPROCESSABLE_ENTITY, Some("invalid_mesh")), "{v}");
    assert!(v["message"].as_str().unwrap().starts_with("mesh: "), "{v}");
    assert_eq!(v["details"]["face"], 0, "{v}");
    assert_eq!(v["details"]["vertices"], json!([a, c]), "{v}");

    // A batch: the frame and the curvenet of a short pool, the counts.
    let id = post_binding(&app, hand()).await.binding_id;
    let pool = &hand().curvenets[0].pool;
    let frames = json!({"frames": [{}, {"posed": [&pool[1..]]}]});
    let (status, _, b) = send(&app, post_json(&format!("/v1/bindings/{id}/frames:batch"), &frames)).await;
    let v = body(&b);
    assert_eq!((status, v["code"].as_str()), (StatusCode::UNPROCESSABLE_ENTITY, Some("count_mismatch")), "{v}");
    assert!(v["message"].as_str().unwrap().starts_with("frames[1]: "), "{v}");
    assert_eq!(
        v["details"],
        json!({"frame": 1, "curvenet": 0, "what": "posed", "expected": pool.len(), "got": pool.len() - 1}),
        "{v}"
    );

    // An error about no element has no details at all.
    let (status, _, b) = send(&app, get("/v1/bindings/nope")).await;
    let v = body(&b);
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert!(v.get("details").is_none(), "{v}");
}
