//! Curvenet Adjustments and knot orientations over HTTP (issue 16, the
//! service part): a frame carrying `adjustments` answers what core's
//! `Deformer::frame` answers with the same adjustments, `orientations`
//! answers core's `Binding::knot_orientations`, in the JSON and the binary
//! forms and in batches, and a bad knot is a 422 naming it.

use std::sync::OnceLock;

use axum::Router;
use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use curvenet_core::knot_tangents;
use curvenet_core::{Adjustment, CurvenetInput, Deformer, DeformerInput, DeformerOptions, Frame, Rotate};
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingRequest, BindingResponse, FrameResponse};
use curvenet_server::{AppState, Config, app};
use serde_json::{Value, json};

mod common;
use common::router::{post_json, send};

fn hand() -> &'static BindingRequest {
    static HAND: OnceLock<BindingRequest> = OnceLock::new();
    HAND.get_or_init(|| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/hand/hand_1k4.usda");
        let stage = Stage::open(&path).unwrap();
        let mesh = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        BindingRequest::from_stage(&mesh, &nets)
    })
}

/// The same binding, in-process through core's one deformer API.
fn reference() -> &'static Deformer {
    static D: OnceLock<Deformer> = OnceLock::new();
    D.get_or_init(|| {
        let req = hand();
        let curvenets: Vec<CurvenetInput> =
            req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
        Deformer::new(&DeformerInput {
            mesh: req.mesh_input(),
            curvenets: &curvenets,
            blend_shapes: Vec::new(),
            skinning: None,
            cage: None,
            options: DeformerOptions::default(),
        })
        .unwrap()
    })
}

fn state() -> AppState {
    AppState::new(Config { solve_threads: 2, ..Config::default() }, None).unwrap()
}

async fn bind(app: &Router) -> String {
    let (status, _, body) = send(app, post_json("/v1/bindings", hand())).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice::<BindingResponse>(&body).unwrap().binding_id
}

/// The pool rotated rigidly by `deg` about z and shifted (a posed frame).
fn posed_pool(deg: f64) -> Vec<[f64; 3]> {
    let (s, c) = deg.to_radians().sin_cos();
    hand().curvenets[0].pool.iter().map(|p| [c * p[0] - s * p[1] + 0.01, s * p[0] + c * p[1], p[2] - 0.02]).collect()
}

/// The endpoints of curvenet 0's splines (its knots), in pool order.
fn knots() -> Vec<u32> {
    let mut k: Vec<u32> = hand().curvenets[0].splines.iter().flat_map(|s| [s[0], s[3]]).collect();
    k.sort_unstable();
    k.dedup();
    k
}

/// A control point of curvenet 0 that is no spline's endpoint (a tangent).
fn not_a_knot() -> u32 {
    let k = knots();
    hand().curvenets[0].splines.iter().map(|s| s[1]).find(|p| !k.contains(p)).expect("a tangent control point")
}

/// Two adjustments, as JSON and as core's: knot A translated, rotated and
/// scaled with its tangents attached and each tangent translated; knot B
/// translated with its tangents left free.
fn adjustments() -> (Value, Vec<Adjustment>) {
    let k = knots();
    let (a, b) = (k[0], k[k.len() / 2]);
    let tangents = knot_tangents(&hand().curvenets[0].splines, a).len();
    assert!(tangents > 0, "knot {a} has tangents");
    let tangent_translates: Vec<[f64; 3]> = (0..tangents).map(|i| [0.001 * (i + 1) as f64, -0.002, 0.0005]).collect();
    let wire = json!([
        {"curvenet": 0, "knot": a, "translate": [0.004, -0.003, 0.006], "rotate": [10.0, -20.0, 35.0],
         "scale": [1.3, 0.8, 1.1], "attach_tangents": true, "tangent_translates": tangent_translates},
        {"curvenet": 0, "knot": b, "translate": [0.0, 0.005, -0.004], "attach_tangents": false},
    ]);
    let core = vec![
        Adjustment::new(0, a)
            .with_translate([0.004, -0.003, 0.006])
            .with_rotate(Rotate::EulerXyz([10.0, -20.0, 35.0]))
            .with_scale([1.3, 0.8, 1.1])
            .with_attach_tangents(true)
            .with_tangent_translates(tangent_translates),
        Adjustment::new(0, b).with_translate([0.0, 0.005, -0.004]).with_attach_tangents(false),
    ];
    (wire, core)
}

fn solve_reference(posed: &[[f64; 3]], adjustments: &[Adjustment]) -> Vec<[f32; 3]> {
    let d = reference();
    let posed = [Some(posed)];
    let mut out = vec![[0.0; 3]; d.n_vertices()];
    d.frame(&Frame { posed: &posed, adjustments, ..Default::default() }, &mut out, None).unwrap();
    out.iter().map(|p| p.map(|x| x as f32)).collect()
}

/// Posts one binary frame: `header` (its fields but `arrays`) with `posed`
/// as curvenet 0's pool in f32; answers the pool as sent (f32, widened),
/// the answer's JSON header and its points. Asserts 200.
async fn post_binary(
    app: &Router,
    uri: &str,
    mut header: Value,
    posed: &[[f64; 3]],
) -> (Vec<[f64; 3]>, Value, Vec<[f32; 3]>) {
    header["arrays"] = json!([{"name": "posed", "index": 0, "shape": [posed.len(), 3]}]);
    let h = serde_json::to_vec(&header).unwrap();
    let mut bin = (h.len() as u32).to_le_bytes().to_vec();
    bin.extend_from_slice(&h);
    let posed32: Vec<[f64; 3]> = posed.iter().map(|p| p.map(|x| x as f32 as f64)).collect();
    for x in posed32.iter().flatten() {
        bin.extend_from_slice(&(*x as f32).to_le_bytes());
    }
    let req =
        Request::post(uri).header(header::CONTENT_TYPE, "application/octet-stream").body(Body::from(bin)).unwrap();
    let (status, _, body) = send(app, req).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let hl = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    let rh: Value = serde_json::from_slice(&body[4..4 + hl]).unwrap();
    let data: Vec<f32> = body[4 + hl..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    (posed32, rh, data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Largest coordinate difference.
fn max_diff(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |i| (p[i] as f64 - q[i] as f64).abs())).fold(0.0, f64::max)
}

/// Checks answered orientations against core's for the posed pool: every
/// knot present, each matrix equal to core's (JSON round trip) and a rotation.
fn check_orientations(got: &[std::collections::BTreeMap<String, [f64; 9]>], posed: &[[f64; 3]]) {
    let want = reference().binding().knot_orientations(0, Some(posed), None).unwrap();
    assert_eq!(got.len(), 1, "one object per curvenet");
    assert_eq!(got[0].len(), want.len(), "one orientation per knot");
    assert_eq!(want.len(), knots().len());
    for (point, m) in &want {
        let o = got[0].get(&point.to_string()).unwrap_or_else(|| panic!("knot {point} missing"));
        for r in 0..3 {
            for c in 0..3 {
                assert!(
                    (o[3 * r + c] - m[r][c]).abs() <= 1e-12,
                    "knot {point} [{r}][{c}]: {} vs {}",
                    o[3 * r + c],
                    m[r][c]
                );
            }
        }
        // Orthonormal, determinant +1.
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| o[3 * k + i] * o[3 * k + j]).sum();
                assert!((dot - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9, "knot {point} not orthonormal");
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn adjusted_frames_match_core_in_json_binary_and_batch() {
    let app = app(state());
    let id = bind(&app).await;
    let uri = format!("/v1/bindings/{id}/frames");
    let posed = posed_pool(12.0);
    let (wire, core) = adjustments();
    let want = solve_reference(&posed, &core);
    let unadjusted = solve_reference(&posed, &[]);
    let moved = max_diff(&want, &unadjusted);
    assert!(moved > 1e-4, "the adjustments move the surface ({moved})");

    // JSON.
    let (status, _, body) =
        send(&app, post_json(&uri, &json!({"posed": [posed], "adjustments": wire, "orientations": true}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let r: FrameResponse = serde_json::from_slice(&body).unwrap();
    assert_eq!(r.points, want, "JSON: bit for bit after f32");
    check_orientations(r.knot_orientations.as_deref().expect("knot_orientations asked for"), &posed);

    // Without `orientations`, none are answered; zero adjustments change nothing.
    let identity: Vec<Value> = knots().iter().map(|k| json!({"curvenet": 0, "knot": k})).collect();
    let (status, _, body) = send(&app, post_json(&uri, &json!({"posed": [posed], "adjustments": identity}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let r: FrameResponse = serde_json::from_slice(&body).unwrap();
    assert!(r.knot_orientations.is_none());
    assert_eq!(r.points, unadjusted, "identity adjustments reproduce the unadjusted frame");

    // Binary: the same adjustments in the header.
    let (posed32, rh, points) =
        post_binary(&app, &uri, json!({"adjustments": wire, "orientations": true}), &posed).await;
    assert_eq!(points, solve_reference(&posed32, &core), "binary: bit for bit after f32 (f32 input)");
    let orientations: Vec<std::collections::BTreeMap<String, [f64; 9]>> =
        serde_json::from_value(rh["knot_orientations"].clone()).expect("knot_orientations in the binary header");
    check_orientations(&orientations, &posed32);

    // A batch: adjustments per frame.
    let batch = json!({"frames": [
        {"posed": [posed], "adjustments": wire},
        {"posed": [posed]},
        {"posed": [posed], "adjustments": wire, "orientations": true},
    ]});
    let (status, _, body) = send(&app, post_json(&format!("{uri}:batch"), &batch)).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let frames: Vec<FrameResponse> =
        serde_json::from_value(serde_json::from_slice::<Value>(&body).unwrap()["frames"].clone()).unwrap();
    assert_eq!(frames[0].points, want);
    assert_eq!(frames[1].points, unadjusted);
    assert_eq!(frames[2].points, want);
    assert!(frames[0].knot_orientations.is_none() && frames[1].knot_orientations.is_none());
    check_orientations(frames[2].knot_orientations.as_deref().unwrap(), &posed);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unposed_frames_answer_orientations_of_the_tracked_pool() {
    // No posed pool: the knots track the rest pose (here the projection pose),
    // and the orientations are those of that pool.
    let app = app(state());
    let id = bind(&app).await;
    let (wire, core) = adjustments();
    let (status, _, body) = send(
        &app,
        post_json(&format!("/v1/bindings/{id}/frames"), &json!({"adjustments": wire, "orientations": true})),
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let r: FrameResponse = serde_json::from_slice(&body).unwrap();
    let d = reference();
    let mut out = vec![[0.0; 3]; d.n_vertices()];
    d.frame(&Frame { adjustments: &core, ..Default::default() }, &mut out, None).unwrap();
    let want: Vec<[f32; 3]> = out.iter().map(|p| p.map(|x| x as f32)).collect();
    assert_eq!(r.points, want);
    let orientations = r.knot_orientations.unwrap();
    let neutral = d.binding().knot_orientations(0, None, None).unwrap();
    assert_eq!(orientations[0].len(), neutral.len());
    for (point, m) in &neutral {
        let o = orientations[0][&point.to_string()];
        let flat: Vec<f64> = m.iter().flatten().copied().collect();
        assert!(o.iter().zip(&flat).all(|(a, b)| (a - b).abs() <= 1e-12), "knot {point}: {o:?} vs {flat:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_knots_are_422_naming_them() {
    let app = app(state());
    let id = bind(&app).await;
    let uri = format!("/v1/bindings/{id}/frames");
    let good = knots()[0];
    let pool = hand().curvenets[0].pool.len() as u32;
    let tangent = not_a_knot();
    let details = |body: &[u8]| -> Value {
        let v: Value = serde_json::from_slice(body).unwrap();
        assert!(v["message"].as_str().is_some_and(|m| !m.is_empty()));
        v
    };

    // Not an endpoint: adjustment 1 names its knot.
    let frame = json!({"adjustments": [{"curvenet": 0, "knot": good, "translate": [0.0, 0.0, 0.001]},
                                       {"curvenet": 0, "knot": tangent}]});
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v = details(&body);
    assert_eq!(v["code"], "invalid_parameter");
    assert_eq!(v["details"]["adjustment"], 1);
    assert_eq!(v["details"]["curvenet"], 0);
    assert_eq!(v["details"]["control_point"], tangent);
    assert!(v["message"].as_str().unwrap().contains(&tangent.to_string()), "{}", v["message"]);

    // A value past the service's coordinate bound (1e15), in any field.
    for (field, value) in [
        ("translate", json!([0.0, 2e15, 0.0])),
        ("rotate", json!([0.0, 0.0, -1e300])),
        ("scale", json!([1.0, 1.0, 1e16])),
    ] {
        let frame = json!({"adjustments": [{"curvenet": 0, "knot": good},
                                           {"curvenet": 0, "knot": knots()[1], field: value}]});
        let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{field}: {}", String::from_utf8_lossy(&body));
        let v = details(&body);
        assert_eq!(v["code"], "invalid_parameter", "{field}: {v}");
        assert_eq!(v["details"]["adjustment"], 1, "{field}: {v}");
        assert_eq!(v["details"]["curvenet"], 0, "{field}: {v}");
        assert_eq!(v["details"]["control_point"], knots()[1], "{field}: {v}");
        assert_eq!(v["details"]["what"], format!("adjustments[1].{field}"), "{field}: {v}");
    }

    // Out of range.
    let frame = json!({"adjustments": [{"curvenet": 0, "knot": pool + 7}]});
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v = details(&body);
    assert_eq!(v["code"], "index_out_of_range");
    assert_eq!(v["details"]["adjustment"], 0);
    assert_eq!(v["details"]["curvenet"], 0);
    assert_eq!(v["details"]["control_point"], pool + 7);
    let message = v["message"].as_str().unwrap();
    assert!(message.contains(&(pool + 7).to_string()) && message.contains("adjustments[0]"), "{message}");

    // A curvenet the binding does not have.
    let frame = json!({"adjustments": [{"curvenet": 3, "knot": good}]});
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v = details(&body);
    assert_eq!(v["code"], "index_out_of_range");
    assert_eq!((v["details"]["adjustment"].clone(), v["details"]["curvenet"].clone()), (json!(0), json!(3)));

    // Wrong number of tangent translates.
    let nine = vec![[0.0f64; 3]; 9];
    let frame = json!({"adjustments": [{"curvenet": 0, "knot": good, "tangent_translates": nine}]});
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v = details(&body);
    assert_eq!(v["code"], "count_mismatch");
    assert_eq!((v["details"]["control_point"].clone(), v["details"]["got"].clone()), (json!(good), json!(9)));

    // In a batch: the frame too.
    let batch = json!({"frames": [{}, {"adjustments": [{"curvenet": 0, "knot": tangent}]}]});
    let (status, _, body) = send(&app, post_json(&format!("{uri}:batch"), &batch)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{}", String::from_utf8_lossy(&body));
    let v = details(&body);
    assert_eq!(v["details"]["frame"], 1);
    assert_eq!(v["details"]["control_point"], tangent);

    // Unknown fields are refused, not ignored.
    let frame = json!({"adjustments": [{"curvenet": 0, "knot": good, "rotation": [0.0, 0.0, 1.0]}]});
    let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{}", String::from_utf8_lossy(&body));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_frame_draws_the_adjusted_curvenet() {
    let app = app(state());
    let id = bind(&app).await;
    let posed = posed_pool(-8.0);
    let (wire, core) = adjustments();
    let uri = format!("/v1/bindings/{id}/viewer-frame");
    let view = |body: &[u8]| -> Value { serde_json::from_slice(body).unwrap() };
    let (status, _, body) = send(&app, post_json(&uri, &json!({"posed": [posed], "adjustments": wire}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let adjusted = view(&body);
    let (status, _, body) = send(&app, post_json(&uri, &json!({"posed": [posed]}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let plain = view(&body);

    let b = reference().binding();
    let pool = b.adjusted_pool(0, Some(&posed), None, &core).unwrap();
    let (samples, _) = b.curvenet_pose(0, Some(&pool), None).unwrap();
    let want: Vec<f32> = samples.iter().flat_map(|p| p.map(|x| x as f32)).collect();
    let got: Vec<f32> = serde_json::from_value(adjusted["curvenets"][0]["samples"].clone()).unwrap();
    assert_eq!(got, want, "the samples drawn are those of the adjusted pool");
    assert_ne!(adjusted["curvenets"][0]["samples"], plain["curvenets"][0]["samples"]);
    let points: Vec<f32> = serde_json::from_value(adjusted["points"].clone()).unwrap();
    let solved: Vec<f32> = solve_reference(&posed, &core).into_iter().flatten().collect();
    assert_eq!(points, solved);
}

/// `orient` rotates a knot by a quaternion `(w, x, y, z)` (USD's
/// `xformOp:orient`), answering core's `Rotate::Quaternion` bit for bit in
/// the JSON and the binary forms; with `rotate` too, or past the
/// coordinate bound, it is a 422 naming `adjustments[i].orient`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn orient_rotates_by_a_quaternion_and_not_beside_rotate() {
    let app = app(state());
    let id = bind(&app).await;
    let uri = format!("/v1/bindings/{id}/frames");
    let posed = posed_pool(-7.0);
    let knot = knots()[1];
    let q = [0.95, 0.12, -0.2, 0.21];
    let want = solve_reference(&posed, &[Adjustment::new(0, knot).with_rotate(Rotate::Quaternion(q))]);
    assert!(max_diff(&want, &solve_reference(&posed, &[])) > 1e-5, "the quaternion moves the surface");

    let wire = json!([{"curvenet": 0, "knot": knot, "orient": q}]);
    let (status, _, body) = send(&app, post_json(&uri, &json!({"posed": [posed], "adjustments": wire}))).await;
    assert_eq!(status, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let r: FrameResponse = serde_json::from_slice(&body).unwrap();
    assert_eq!(r.points, want, "JSON: bit for bit after f32");

    let (posed32, _, points) = post_binary(&app, &uri, json!({"adjustments": wire}), &posed).await;
    let want32 = solve_reference(&posed32, &[Adjustment::new(0, knot).with_rotate(Rotate::Quaternion(q))]);
    assert_eq!(points, want32, "binary: bit for bit after f32 (f32 input)");

    for (adjustment, what) in [
        (json!({"curvenet": 0, "knot": knot, "rotate": [0.0, 0.0, 10.0], "orient": q}), "both"),
        (json!({"curvenet": 0, "knot": knot, "orient": [1.0, 0.0, 2e15, 0.0]}), "beyond"),
    ] {
        let frame = json!({"adjustments": [{"curvenet": 0, "knot": knots()[0]}, adjustment]});
        let (status, _, body) = send(&app, post_json(&uri, &frame)).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{what}: {}", String::from_utf8_lossy(&body));
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["code"], "invalid_parameter", "{what}: {v}");
        assert_eq!(v["details"]["what"], "adjustments[1].orient", "{what}: {v}");
        assert_eq!(
            (v["details"]["adjustment"].clone(), v["details"]["control_point"].clone()),
            (json!(1), json!(knot))
        );
        assert!(v["message"].as_str().unwrap().contains(what), "{what}: {v}");
    }
}
