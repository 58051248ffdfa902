//! A bounded load benchmark of the service over loopback (not a test):
//!
//! ```sh
//! cargo run --release --ignore-rust-version -p curvenet-server --example load
//! cargo run --release --ignore-rust-version -p curvenet-server --example load -- --clients 8 --frames 200 --mesh hand_22k
//! ```
//!
//! Starts the service in-process on 127.0.0.1:0, posts the hand binding,
//! then (1) one client sends frames one after another, to compare the
//! binary round trip with the core solve alone, and (2) `--clients`
//! clients each send `--frames` binary frames concurrently. Every answer is
//! compared with an in-process `Deformer::frame` of the same (f32) pose;
//! any mismatch or error makes the command exit 1. Prints throughput,
//! p50/p99 latency and the core solve median. Stops by itself.

use std::sync::Arc;
use std::time::{Duration, Instant};

use curvenet_core::{CurvenetInput, Deformer, DeformerInput, DeformerOptions, Frame};
use curvenet_schema::usd::Stage;
use curvenet_schema::wire::{BindingRequest, BindingResponse};
use curvenet_server::{AppState, Config};

/// Distinct poses cycled through by the clients.
const POSES: usize = 24;
/// Frames of the sequential single-client phase.
const SEQUENTIAL: usize = 60;

struct Opts {
    clients: usize,
    frames: usize,
    mesh: String,
}

fn opts() -> Opts {
    let mut o = Opts { clients: 8, frames: 200, mesh: "hand_22k".into() };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let value = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--clients" => o.clients = value.parse().expect("--clients N"),
            "--frames" => o.frames = value.parse().expect("--frames N"),
            "--mesh" => o.mesh = value,
            other => panic!("unknown argument {other} (--clients N, --frames N, --mesh NAME)"),
        }
        i += 2;
    }
    o.clients = o.clients.clamp(1, 64);
    o.frames = o.frames.clamp(1, 10_000);
    o
}

fn request(mesh: &str) -> BindingRequest {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/hand");
    let path = ["usdc", "usda"]
        .iter()
        .map(|e| dir.join(format!("{mesh}.{e}")))
        .find(|p| p.exists())
        .expect("the hand fixture");
    let stage = Stage::open(&path).unwrap();
    let m = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
    let nets: Vec<_> = m.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    BindingRequest::from_stage(&m, &nets)
}

/// Pose `i`: the control points beyond 55 % of the pool's y extent curl
/// about the x axis by up to 50°, blended over 10 % of the extent (a
/// finger curl); rounded to f32 as the binary form sends it.
fn pose(pool: &[[f64; 3]], i: usize) -> Vec<[f64; 3]> {
    let (lo, hi) = pool.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[1]), b.max(p[1])));
    let ext = hi - lo;
    let plane = lo + 0.55 * ext;
    let z0 = pool.iter().map(|p| p[2]).sum::<f64>() / pool.len() as f64;
    let angle = 50f64.to_radians() * 0.5 * (1.0 - (std::f64::consts::TAU * i as f64 / POSES as f64).cos());
    pool.iter()
        .map(|p| {
            let t = ((p[1] - plane) / (0.1 * ext) + 0.5).clamp(0.0, 1.0);
            let a = angle * t * t * (3.0 - 2.0 * t);
            let (s, c) = a.sin_cos();
            let (y, z) = (p[1] - plane, p[2] - z0);
            [p[0], plane + c * y - s * z, z0 + s * y + c * z].map(|x| x as f32 as f64)
        })
        .collect()
}

fn body(pose: &[[f64; 3]]) -> Vec<u8> {
    let header =
        serde_json::to_vec(&serde_json::json!({"arrays": [{"name": "posed", "index": 0, "shape": [pose.len(), 3]}]}))
            .unwrap();
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&header);
    for p in pose {
        for x in p {
            out.extend_from_slice(&(*x as f32).to_le_bytes());
        }
    }
    out
}

/// The f32 points of a binary answer.
fn points(body: &[u8]) -> Vec<f32> {
    let h = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    body[4 + h..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}

/// Equal to f32 precision (the service binds its own copy of the mesh).
fn same(got: &[f32], want: &[f32]) -> bool {
    got.len() == want.len() && got.iter().zip(want).all(|(a, b)| (a - b).abs() <= 4.0 * f32::EPSILON * b.abs().max(1.0))
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let o = opts();
    let req = request(&o.mesh);
    println!("mesh {}: {} vertices, {} faces", o.mesh, req.projection_points.len(), req.face_vertex_counts.len());

    // The in-process reference: bind, then solve every pose (single thread).
    let t = Instant::now();
    let curvenets: Vec<CurvenetInput> = req.curvenets.iter().map(curvenet_schema::wire::CurvenetSpec::input).collect();
    let deformer = Deformer::new(&DeformerInput {
        mesh: req.mesh_input(),
        curvenets: &curvenets,
        blend_shapes: Vec::new(),
        skinning: None,
        cage: None,
        options: DeformerOptions::default(),
    })
    .unwrap();
    println!("in-process binding: {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    let poses: Vec<Vec<[f64; 3]>> = (0..POSES).map(|i| pose(&req.curvenets[0].pool, i)).collect();
    let mut out = vec![[0.0; 3]; deformer.n_vertices()];
    let mut core_ms = Vec::new();
    let mut expected: Vec<Vec<f32>> = Vec::new();
    for round in 0..3 {
        for p in &poses {
            let t = Instant::now();
            deformer.frame(&Frame { posed: &[Some(p.as_slice())], ..Default::default() }, &mut out, None).unwrap();
            core_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if round == 0 {
                expected.push(out.iter().flat_map(|q| q.map(|x| x as f32)).collect());
            }
        }
    }
    core_ms.sort_by(f64::total_cmp);
    let core_median = percentile(&core_ms, 0.5);
    let expected = Arc::new(expected);
    let bodies: Arc<Vec<Vec<u8>>> = Arc::new(poses.iter().map(|p| body(p)).collect());

    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let failed = runtime.block_on(async move {
        let state = AppState::new(Config::default(), None).unwrap();
        let threads = state.config().solve_threads;
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(curvenet_server::run(listener, state, async move {
            let _ = stopped.await;
        }));
        let client = reqwest::Client::builder().timeout(Duration::from_secs(60)).build().unwrap();
        let t = Instant::now();
        let bound: BindingResponse =
            client.post(format!("http://{addr}/v1/bindings")).json(&req).send().await.unwrap().json().await.unwrap();
        println!(
            "service binding: {:.0} ms round trip (cut {:.0} ms, factor {:.0} ms), {} factor nonzeros, cache weight {:.1} MB, solve threads {}",
            t.elapsed().as_secs_f64() * 1e3,
            bound.timings.cutting_ms,
            bound.timings.factor_ms,
            bound.stats.factor_nonzeros,
            bound.size_bytes as f64 / 1e6,
            if threads == 0 { "one per core".to_string() } else { threads.to_string() }
        );
        let url = Arc::new(format!("http://{addr}/v1/bindings/{}/frames", bound.binding_id));

        // One frame at a time.
        let mut seq = Vec::new();
        let mut errors = 0usize;
        for i in 0..SEQUENTIAL {
            let k = i % POSES;
            let t = Instant::now();
            let r = client.post(url.as_str()).header("content-type", "application/octet-stream").body(bodies[k].clone()).send().await;
            let ok = match r {
                Ok(r) if r.status() == 200 => same(&points(&r.bytes().await.unwrap()), &expected[k]),
                _ => false,
            };
            seq.push(t.elapsed().as_secs_f64() * 1e3);
            errors += usize::from(!ok);
        }
        seq.sort_by(f64::total_cmp);
        let seq_p50 = percentile(&seq, 0.5);
        println!(
            "sequential, 1 client x {SEQUENTIAL} frames: round trip p50 {seq_p50:.2} ms, p99 {:.2} ms; core solve median {core_median:.2} ms; \
             overhead p50 {:+.2} ms (target <= 2 ms)",
            percentile(&seq, 0.99),
            seq_p50 - core_median
        );

        // Concurrent clients.
        let t = Instant::now();
        let tasks: Vec<_> = (0..o.clients)
            .map(|c| {
                let (client, url, bodies, expected) = (client.clone(), url.clone(), bodies.clone(), expected.clone());
                tokio::spawn(async move {
                    let mut lat = Vec::with_capacity(o.frames);
                    let mut bad = 0usize;
                    for i in 0..o.frames {
                        let k = (c * 7 + i) % POSES;
                        let t = Instant::now();
                        let r = client
                            .post(url.as_str())
                            .header("content-type", "application/octet-stream")
                            .body(bodies[k].clone())
                            .send()
                            .await;
                        let ok = match r {
                            Ok(r) if r.status() == 200 => same(&points(&r.bytes().await.unwrap()), &expected[k]),
                            Ok(r) => {
                                eprintln!("client {c} frame {i}: {} {}", r.status(), r.text().await.unwrap_or_default());
                                false
                            }
                            Err(e) => {
                                eprintln!("client {c} frame {i}: {e}");
                                false
                            }
                        };
                        lat.push(t.elapsed().as_secs_f64() * 1e3);
                        bad += usize::from(!ok);
                    }
                    (lat, bad)
                })
            })
            .collect();
        let mut lat = Vec::new();
        for task in tasks {
            let (l, b) = task.await.unwrap();
            lat.extend(l);
            errors += b;
        }
        let wall = t.elapsed().as_secs_f64();
        lat.sort_by(f64::total_cmp);
        println!(
            "concurrent, {} clients x {} frames: {:.0} frames/s ({:.2} s), latency p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
            o.clients,
            o.frames,
            lat.len() as f64 / wall,
            wall,
            percentile(&lat, 0.5),
            percentile(&lat, 0.99),
            lat[lat.len() - 1]
        );
        println!("answers differing from the in-process solve or failing: {errors}");
        let _ = stop.send(());
        let _ = tokio::time::timeout(Duration::from_secs(30), server).await;
        errors > 0
    });
    if failed {
        std::process::exit(1);
    }
}
