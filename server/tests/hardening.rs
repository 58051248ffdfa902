//! Issue #15, against a real `curvenet serve` process on loopback, as a
//! hostile but fair client: hostile frames get their 4xx at once with
//! bounded memory, expensive bindings are refused, timed out or cancelled
//! when their client leaves, SIGTERM exits within the drain timeout even
//! mid-binding, slow and idle clients are cut off while others are served,
//! the cache stays within its bytes (RSS measured), batches are admitted
//! under contention, and the small things; and a frame waits
//! for one wave of long batches, not all of them, a batch stops when its
//! client leaves, and batches in flight stay within `--max-batch-memory`.
//! Every loop is bounded in count and time.

#[allow(dead_code)]
mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use curvenet_schema::usd::Stage;
use curvenet_schema::wire::BindingRequest;
use serde_json::{Value, json};

// ---------------------------------------------------------------- the server

/// The tests measure times and memory: one at a time, so they do not load
/// the 2-core machine for each other.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// A `curvenet serve` child process on 127.0.0.1 (killed when dropped).
struct Server {
    child: Child,
    addr: SocketAddr,
    log: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Server {
    fn start(args: &[&str]) -> Self {
        Self::start_with_env(args, &[])
    }

    fn start_with_env(args: &[&str], env: &[(&str, &str)]) -> Self {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_curvenet"));
        cmd.arg("serve").args(["--addr", "127.0.0.1:0", "--solve-threads", "2"]).args(args);
        for (k, _) in std::env::vars() {
            if k.starts_with("CURVENET_") || k == "RUST_LOG" {
                cmd.env_remove(k);
            }
        }
        cmd.env("CURVENET_LOG", "info").envs(env.iter().copied());
        let mut child = cmd
            .current_dir(common::repo())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("curvenet serve starts");
        let log = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        {
            let log = log.clone();
            let mut stderr = child.stderr.take().unwrap();
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                while let Ok(n) = stderr.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    log.lock().unwrap().push_str(&String::from_utf8_lossy(&buf[..n]));
                }
            });
        }
        let first = common::first_stdout_line(&mut child, Duration::from_secs(30));
        let addr = first.strip_prefix("listening on http://").expect("listening on ...").parse().unwrap();
        Self { child, addr, log }
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Resident memory, KiB (/proc/PID/status VmRSS).
    fn rss_kib(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap()
    }

    fn terminate(&self) {
        let ok = Command::new("kill").args(["-TERM", &self.pid().to_string()]).status().unwrap().success();
        assert!(ok, "kill -TERM");
    }

    /// Waits at most `limit` for the process to exit.
    fn wait(&mut self, limit: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Some(s) = self.child.try_wait().unwrap() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }

    fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    fn metric(&self, name: &str) -> f64 {
        let a = get(self.addr, "/metrics");
        assert_eq!(a.status, 200);
        let text = String::from_utf8_lossy(&a.body).into_owned();
        text.lines()
            .find_map(|l| l.strip_prefix(name).and_then(|r| r.strip_prefix(' ')))
            .map(|v| v.trim().parse().unwrap())
            .unwrap_or_else(|| panic!("{name} not in /metrics"))
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

// ------------------------------------------------------------ a tiny client

struct Answer {
    status: u16,
    head: String,
    body: Vec<u8>,
}

impl Answer {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|_| panic!("not JSON ({}): {}", self.status, String::from_utf8_lossy(&self.body)))
    }
    fn code(&self) -> String {
        self.json()["code"].as_str().unwrap_or_default().to_string()
    }
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

/// One HTTP/1.1 request on a fresh connection (`Connection: close`).
fn request(addr: SocketAddr, method: &str, path: &str, headers: &[(&str, &str)], body: &[u8]) -> Answer {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let mut head = format!("{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str(&format!("Content-Length: {}\r\n\r\n", body.len()));
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    read_answer(&mut s).expect("an answer")
}

fn read_answer(s: &mut TcpStream) -> Option<Answer> {
    let mut raw = Vec::new();
    let _ = s.read_to_end(&mut raw);
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = String::from_utf8_lossy(&raw[..end]).into_owned();
    let status = head.split(' ').nth(1)?.parse().ok()?;
    Some(Answer { status, head, body: raw[end + 4..].to_vec() })
}

fn get(addr: SocketAddr, path: &str) -> Answer {
    request(addr, "GET", path, &[], b"")
}

fn post_json(addr: SocketAddr, path: &str, body: &impl serde::Serialize) -> Answer {
    request(addr, "POST", path, &[("Content-Type", "application/json")], &serde_json::to_vec(body).unwrap())
}

fn post_binary(addr: SocketAddr, path: &str, body: &[u8]) -> Answer {
    request(addr, "POST", path, &[("Content-Type", "application/octet-stream")], body)
}

/// A binary frame body: header then f32 arrays.
fn binary_frame(header: &Value, data: &[f32]) -> Vec<u8> {
    let h = serde_json::to_vec(header).unwrap();
    let mut out = (h.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    for x in data {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

// ---------------------------------------------------------------- the inputs

fn request_from_stage(path: &str) -> BindingRequest {
    let stage = Stage::open(common::repo().join(path)).unwrap();
    let mesh = stage.deformed_meshes().unwrap().into_iter().next().unwrap();
    let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    BindingRequest::from_stage(&mesh, &nets)
}

fn hand() -> &'static BindingRequest {
    static HAND: OnceLock<BindingRequest> = OnceLock::new();
    HAND.get_or_init(|| request_from_stage("fixtures/hand/hand_1k4.usda"))
}

/// A sample density that makes the 1.4k hand's binding slow (1.4-2.4 s on a
/// 2-core machine, about 0.7 GB) for the tests of limits, cancellation and
/// shutdown mid-binding. If the binding gets much faster, raise it: memory
/// grows with its square (the cut faces' corner counts).
const HEAVY_DENSITY: f64 = 400.0;

fn hand_with_density(d: f64) -> BindingRequest {
    let mut r = hand().clone();
    r.curvenets[0].sample_density = d;
    r
}

fn bind(addr: SocketAddr, req: &BindingRequest) -> String {
    let a = post_json(addr, "/v1/bindings", req);
    assert_eq!(a.status, 200, "{}", a.text());
    a.json()["binding_id"].as_str().unwrap().to_string()
}

/// The 22k hand (long enough batches to watch them run).
fn hand_22k() -> &'static BindingRequest {
    static HAND: OnceLock<BindingRequest> = OnceLock::new();
    HAND.get_or_init(|| request_from_stage("fixtures/hand/hand_22k.usdc"))
}

/// A binary `frames:batch` body of `n` frames, frame `i` posing every
/// curvenet's pool scaled by `1 + i·1e-4`.
fn binary_batch(req: &BindingRequest, n: usize) -> Vec<u8> {
    let arrays: Vec<Value> = req
        .curvenets
        .iter()
        .enumerate()
        .map(|(k, c)| json!({"name": "posed", "index": k, "shape": [c.pool.len(), 3]}))
        .collect();
    let header = json!({ "frames": vec![json!({ "arrays": arrays }); n] });
    let data: Vec<f32> = (0..n)
        .flat_map(|i| {
            req.curvenets.iter().flat_map(move |c| scaled(&c.pool, 1.0 + i as f64 * 1e-4).into_iter().flatten())
        })
        .map(|x| x as f32)
        .collect();
    binary_frame(&header, &data)
}

/// Sends a request without reading its answer: the open connection.
fn send(addr: SocketAddr, path: &str, content_type: &str, body: &[u8]) -> TcpStream {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let head = format!(
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: {content_type}\r\n\
         Content-Length: {}\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    s
}

fn scaled(pool: &[[f64; 3]], s: f64) -> Vec<[f64; 3]> {
    pool.iter().map(|p| p.map(|x| x * s)).collect()
}

// -------------------------------------------------------------------- tests

#[test]
fn hostile_frames_get_their_4xx_at_once_with_bounded_memory() {
    let _serial = one_at_a_time();
    let server = Server::start(&[]);
    let addr = server.addr;
    let id = bind(addr, hand());
    let np = hand().curvenets[0].pool.len();
    let pool_f32: Vec<f32> = hand().curvenets[0].pool.iter().flat_map(|p| p.map(|x| x as f32)).collect();
    // A binding with a sparse blend shape whose inbetween sits at weight 1e-12:
    // a weight of -1e6 extrapolates its offset to 1e33, and a pose scaled by
    // 1e6 scales that again in the `after` mode: every input within bounds,
    // the result beyond f32.
    let mut shaped = hand().clone();
    shaped.blend_shapes = vec![
        serde_json::from_value(json!({
            "name": "spike", "offsets": [[0.0, 0.0, 0.0]], "point_indices": [7],
            "inbetweens": [{"weight": 1e-12, "offsets": [[0.0, 0.0, 1e15]]}],
        }))
        .unwrap(),
    ];
    let shaped_id = bind(addr, &shaped);
    let frames = format!("/v1/bindings/{id}/frames");
    let shaped_frames = format!("/v1/bindings/{shaped_id}/frames");
    let before = server.rss_kib();
    let posed = |index: u64, rows: u64| json!({"arrays": [{"name": "posed", "index": index, "shape": [rows, 3]}]});
    let many_empty_frames = {
        let one = json!({"arrays": []});
        json!({ "frames": vec![one; 100_000] })
    };
    // Empty JSON frames whose answer would fit the default 256 MiB limit as
    // f32 (90% of it) but not as JSON text (about four times as large).
    let n_vertices = hand().projection_points.len() as u64;
    let json_frames = (0.9 * (256u64 << 20) as f64 / (12 * n_vertices) as f64) as usize;
    let many_empty_json_frames = json!({ "frames": vec![json!({}); json_frames] });
    let big_pose: Vec<f32> = pool_f32.iter().map(|x| x * 1e6).collect();
    let mut overflow_data = big_pose.clone();
    overflow_data.push(-1e6);
    let overflow_binary = json!({"arrays": [
        {"name": "posed", "index": 0, "shape": [np, 3]},
        {"name": "blend_shape_weights", "shape": [1]},
    ]});
    let cases: Vec<(&str, Answer, u16, &str, &str)> = vec![
        (
            "posed index u32::MAX",
            post_binary(addr, &frames, &binary_frame(&posed(4294967295, np as u64), &pool_f32)),
            422,
            "index_out_of_range",
            "posed index 4294967295",
        ),
        (
            "posed index 5e7",
            post_binary(addr, &frames, &binary_frame(&posed(50_000_000, np as u64), &pool_f32)),
            422,
            "index_out_of_range",
            "50000000",
        ),
        (
            "posed rows 2^32",
            post_binary(addr, &frames, &binary_frame(&posed(0, 1 << 32), &pool_f32)),
            422,
            "count_mismatch",
            "posed[0] has 4294967296 control points",
        ),
        (
            "rest rows u64::MAX",
            post_binary(
                addr,
                &frames,
                &binary_frame(&json!({"arrays": [{"name": "rest", "shape": [u64::MAX, 3]}]}), &[]),
            ),
            422,
            "count_mismatch",
            "rest has 18446744073709551615 points",
        ),
        (
            "weights 1e9",
            post_binary(
                addr,
                &frames,
                &binary_frame(&json!({"arrays": [{"name": "blend_shape_weights", "shape": [1_000_000_000]}]}), &[]),
            ),
            422,
            "count_mismatch",
            "blend_shape_weights",
        ),
        (
            "header length u32::MAX",
            post_binary(addr, &frames, &[0xff, 0xff, 0xff, 0xff, b'{']),
            400,
            "malformed_binary",
            "header length",
        ),
        (
            "100k empty frames in a batch",
            post_binary(addr, &format!("{frames}:batch"), &binary_frame(&many_empty_frames, &[])),
            422,
            "limit_exceeded",
            "--max-batch-bytes",
        ),
        (
            "a JSON batch whose f32 would fit but whose JSON would not",
            post_json(addr, &format!("{frames}:batch"), &many_empty_json_frames),
            422,
            "limit_exceeded",
            "--max-batch-bytes",
        ),
        (
            "JSON pose x 1e40",
            post_json(addr, &frames, &json!({"posed": [scaled(&hand().curvenets[0].pool, 1e40)]})),
            422,
            "invalid_parameter",
            "posed[0][0]",
        ),
        (
            "JSON weight 1e300",
            post_json(addr, &shaped_frames, &json!({"blend_shape_weights": [1e300]})),
            422,
            "invalid_parameter",
            "blend_shape_weights[0]",
        ),
        (
            "JSON result overflows f32",
            post_json(
                addr,
                &shaped_frames,
                &json!({"posed": [scaled(&hand().curvenets[0].pool, 1e6)], "blend_shape_weights": [-1e6]}),
            ),
            422,
            "non_finite",
            "points[7]",
        ),
        (
            "binary result overflows f32",
            post_binary(addr, &shaped_frames, &binary_frame(&overflow_binary, &overflow_data)),
            422,
            "non_finite",
            "points[7]",
        ),
        (
            "batch result overflows f32",
            post_json(
                addr,
                &format!("{shaped_frames}:batch"),
                &json!({"frames": [{}, {"posed": [scaled(&hand().curvenets[0].pool, 1e6)], "blend_shape_weights": [-1e6]}]}),
            ),
            422,
            "non_finite",
            "frames[1]: the frame's result is not finite: points[7]",
        ),
    ];
    let mut worst = Duration::ZERO;
    for (name, answer, status, code, needle) in cases {
        assert_eq!(answer.status, status, "{name}: {}", answer.text());
        assert_eq!(answer.code(), code, "{name}: {}", answer.text());
        assert!(answer.text().contains(needle), "{name}: {} lacks {needle:?}", answer.text());
    }
    // The same requests, timed one by one.
    for body in [binary_frame(&posed(4294967295, np as u64), &pool_f32), binary_frame(&posed(0, 1 << 32), &pool_f32)] {
        let t = Instant::now();
        assert_eq!(post_binary(addr, &frames, &body).status, 422);
        worst = worst.max(t.elapsed());
    }
    let grown_mib = server.rss_kib().saturating_sub(before) / 1024;
    println!("hostile frames: RSS grew {grown_mib} MiB, slowest refusal {worst:?}");
    assert!(worst < Duration::from_secs(2), "{worst:?}");
    assert!(grown_mib < 64, "RSS grew {grown_mib} MiB");
    // The same pose within bounds still deforms.
    let a = post_json(
        addr,
        &shaped_frames,
        &json!({"posed": [scaled(&hand().curvenets[0].pool, 1e6)], "blend_shape_weights": [1.0]}),
    );
    assert_eq!(a.status, 200, "{}", a.text());
    let good = post_binary(addr, &frames, &binary_frame(&posed(0, np as u64), &pool_f32));
    assert_eq!(good.status, 200, "{}", good.text());
}

#[test]
fn expensive_bindings_are_refused_timed_out_or_cancelled_when_their_client_leaves() {
    let _serial = one_at_a_time();
    // Defaults: a density beyond the limit, and segments beyond it.
    let server = Server::start(&[]);
    let t = Instant::now();
    let a = post_json(server.addr, "/v1/bindings", &hand_with_density(3000.0));
    assert_eq!((a.status, a.code().as_str()), (422, "limit_exceeded"), "{}", a.text());
    assert!(a.text().contains("curvenets[0].sample_density 3000") && a.text().contains("--max-sample-density"));
    let mut many = hand_with_density(50.0);
    let splines = many.curvenets[0].splines.clone();
    for _ in 0..9 {
        many.curvenets[0].splines.extend_from_slice(&splines);
    }
    let a = post_json(server.addr, "/v1/bindings", &many);
    assert_eq!((a.status, a.code().as_str()), (422, "limit_exceeded"), "{}", a.text());
    assert!(a.text().contains("curvenets[0] would be sampled into") && a.text().contains("--max-segments-per-vertex"));
    assert!(t.elapsed() < Duration::from_secs(3), "{:?}", t.elapsed());
    assert_eq!(server.metric("curvenet_bindings_computed_total"), 0.0);
    drop(server);

    // Density 400 on the 1.4k hand binds in 1.4-2.4 s on a 2-core machine (it
    // took over ten before the polygon Laplacian's stabilisation was expanded):
    // with a 0.25 s limit it is stopped at 0.25 s. The limits here are kept
    // well under the binding's time so that a faster machine or binding still
    // exercises them; the assertions name `HEAVY_DENSITY` if it ever does not.
    let server = Server::start(&[
        "--max-sample-density",
        "1000",
        "--max-segments-per-vertex",
        "100",
        "--max-binding-seconds",
        "0.25",
    ]);
    let t = Instant::now();
    let a = post_json(server.addr, "/v1/bindings", &hand_with_density(HEAVY_DENSITY));
    let took = t.elapsed();
    assert_eq!(
        (a.status, a.code().as_str()),
        (422, "limit_exceeded"),
        "{} (a 200 means the binding beat the limit: raise HEAVY_DENSITY)",
        a.text()
    );
    assert!(a.text().contains("--max-binding-seconds"), "{}", a.text());
    println!("time limit 0.25 s: answered after {took:?}");
    assert!(took < Duration::from_secs(2), "{took:?}");
    drop(server);

    // A client that disconnects mid-binding: the binding is cancelled.
    let server = Server::start(&["--max-sample-density", "1000", "--max-segments-per-vertex", "100"]);
    let body = serde_json::to_vec(&hand_with_density(HEAVY_DENSITY)).unwrap();
    let mut s = TcpStream::connect(server.addr).unwrap();
    write!(
        s,
        "POST /v1/bindings HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )
    .unwrap();
    s.write_all(&body).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while server.metric("curvenet_bindings_running") < 1.0 {
        assert!(Instant::now() < deadline, "the binding never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(s);
    let t = Instant::now();
    while server.metric("curvenet_bindings_cancelled_total") < 1.0 || server.metric("curvenet_bindings_running") > 0.0 {
        assert!(t.elapsed() < Duration::from_secs(5), "the abandoned binding was not cancelled");
        std::thread::sleep(Duration::from_millis(20));
    }
    println!("abandoned binding cancelled {:?} after its client left", t.elapsed());
    // And the work itself stopped: the process uses (almost) no CPU any more.
    let cpu = || {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", server.pid())).unwrap();
        let fields: Vec<&str> = stat.rsplit_once(')').unwrap().1.split_whitespace().collect();
        // utime and stime, fields 14 and 15 of the line (11 and 12 after the command name), in ticks.
        fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap()
    };
    let (before, t) = (cpu(), Instant::now());
    std::thread::sleep(Duration::from_secs(1));
    let busy = (cpu() - before) as f64 / 100.0 / t.elapsed().as_secs_f64();
    println!("CPU use in the second after: {:.0}%", busy * 100.0);
    assert!(busy < 0.25, "the server still computes ({:.0}% of a core)", busy * 100.0);
    assert_eq!(server.metric("curvenet_bindings_computed_total"), 0.0);
    // The server is idle again: a normal binding is served.
    bind(server.addr, hand());
}

#[test]
fn sigterm_mid_binding_exits_within_the_drain_timeout() {
    let _serial = one_at_a_time();
    let mut server =
        Server::start(&["--max-sample-density", "1000", "--max-segments-per-vertex", "100", "--drain-timeout", "0.25"]);
    let addr = server.addr;
    let client = std::thread::spawn(move || {
        let body = serde_json::to_vec(&hand_with_density(HEAVY_DENSITY)).unwrap();
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        write!(s, "POST /v1/bindings HTTP/1.1\r\nHost: x\r\nContent-Length: {}\r\n\r\n", body.len()).unwrap();
        s.write_all(&body).unwrap();
        read_answer(&mut s).map(|a| a.status)
    });
    let deadline = Instant::now() + Duration::from_secs(10);
    while server.metric("curvenet_bindings_running") < 1.0 {
        assert!(Instant::now() < deadline, "the binding never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let t = Instant::now();
    server.terminate();
    let status = server.wait(Duration::from_secs(10)).expect("the server exits");
    let took = t.elapsed();
    println!("SIGTERM mid-binding, drain timeout 0.25 s: exited after {took:?} with {status}");
    assert!(took < Duration::from_secs(1), "exited after {took:?}");
    assert_eq!(
        status.code(),
        Some(1),
        "cut short: {status} (exit 0: the binding finished within the drain timeout; raise HEAVY_DENSITY)\n{}",
        server.log()
    );
    assert!(server.log().contains("drain timeout reached"), "{}", server.log());
    // The client got no 200.
    assert_ne!(client.join().unwrap(), Some(200));

    // With nothing in flight, SIGTERM exits 0 at once.
    let mut idle = Server::start(&["--drain-timeout", "30"]);
    let t = Instant::now();
    idle.terminate();
    let status = idle.wait(Duration::from_secs(5)).expect("the idle server exits");
    assert!(status.success(), "{status}");
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
}

/// Seconds until the server closes `s` (reads EOF or an error), at most `limit`;
/// also returns what it sent.
fn until_closed(s: &mut TcpStream, limit: Duration) -> (Duration, Vec<u8>) {
    let t = Instant::now();
    s.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 1024];
    while t.elapsed() < limit {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => break,
        }
    }
    (t.elapsed(), got)
}

#[test]
fn slow_and_idle_clients_are_cut_off_while_others_are_served() {
    let _serial = one_at_a_time();
    let server = Server::start(&[
        "--header-timeout",
        "1",
        "--idle-timeout",
        "2",
        "--body-timeout",
        "1",
        "--body-min-rate",
        "1000",
    ]);
    let addr = server.addr;
    let limit = Duration::from_secs(6);
    // Header tricklers: a byte of a header every 200 ms (at most 40 bytes).
    let headers: Vec<_> = (0..10)
        .map(|_| {
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(addr).unwrap();
                s.write_all(b"POST /v1/bindings HTTP/1.1\r\nX-Slow: ").unwrap();
                let t = Instant::now();
                for _ in 0..40 {
                    if s.write_all(b"a").is_err() {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(200));
                    s.set_nonblocking(true).unwrap();
                    let mut b = [0u8; 64];
                    let closed = matches!(s.read(&mut b), Ok(0)) || t.elapsed() > limit;
                    s.set_nonblocking(false).unwrap();
                    if closed {
                        break;
                    }
                }
                t.elapsed()
            })
        })
        .collect();
    // Body tricklers: whole headers, then a byte of body every 200 ms.
    let bodies: Vec<_> = (0..10)
        .map(|_| {
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(addr).unwrap();
                s.write_all(b"POST /v1/bindings HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 100000\r\n\r\n{").unwrap();
                let t = Instant::now();
                let writer = s.try_clone().unwrap();
                let trickle = std::thread::spawn(move || {
                    let mut w = writer;
                    for _ in 0..40 {
                        std::thread::sleep(Duration::from_millis(200));
                        if w.write_all(b" ").is_err() {
                            break;
                        }
                    }
                });
                let (took, got) = until_closed(&mut s, limit);
                let _ = s.shutdown(std::net::Shutdown::Both);
                let _ = trickle.join();
                (took, String::from_utf8_lossy(&got).into_owned(), t)
            })
        })
        .collect();
    // Idle connections: connect and say nothing.
    let idle: Vec<_> = (0..10)
        .map(|_| {
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(addr).unwrap();
                until_closed(&mut s, limit).0
            })
        })
        .collect();
    // A keep-alive connection that goes idle after one request.
    let kept = std::thread::spawn(move || {
        let mut s = TcpStream::connect(addr).unwrap();
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        let (took, got) = until_closed(&mut s, limit);
        (took, String::from_utf8_lossy(&got).into_owned())
    });
    // Meanwhile other clients are served promptly.
    let mut slowest = Duration::ZERO;
    for _ in 0..30 {
        let t = Instant::now();
        assert_eq!(get(addr, "/healthz").status, 200);
        slowest = slowest.max(t.elapsed());
        std::thread::sleep(Duration::from_millis(50));
    }
    let headers: Vec<Duration> = headers.into_iter().map(|h| h.join().unwrap()).collect();
    let idle: Vec<Duration> = idle.into_iter().map(|h| h.join().unwrap()).collect();
    let bodies: Vec<(Duration, String, Instant)> = bodies.into_iter().map(|h| h.join().unwrap()).collect();
    let (kept_took, kept_got) = kept.join().unwrap();
    println!(
        "cut off after: headers {:?}, idle {:?}, bodies {:?}, kept-alive {kept_took:?}; slowest healthz {slowest:?}",
        headers.iter().max(),
        idle.iter().max(),
        bodies.iter().map(|b| b.0).max()
    );
    for h in &headers {
        assert!(*h >= Duration::from_millis(800) && *h < Duration::from_secs(3), "header trickler cut at {h:?}");
    }
    for i in &idle {
        assert!(*i >= Duration::from_millis(1800) && *i < Duration::from_secs(4), "idle connection cut at {i:?}");
    }
    for (took, got, _) in &bodies {
        assert!(*took >= Duration::from_millis(800) && *took < Duration::from_secs(4), "body trickler cut at {took:?}");
        assert!(got.starts_with("HTTP/1.1 408"), "body trickler got {got:?}");
        assert!(got.contains("request_timeout"), "{got}");
    }
    assert!(kept_got.starts_with("HTTP/1.1 200"), "{kept_got}");
    assert!(kept_took >= Duration::from_millis(1800) && kept_took < Duration::from_secs(4), "{kept_took:?}");
    assert!(slowest < Duration::from_millis(500), "{slowest:?}");

    // The connection cap: beyond it a client gets 503 and is disconnected.
    let capped = Server::start(&["--max-connections", "4"]);
    let held: Vec<TcpStream> = (0..4).map(|_| TcpStream::connect(capped.addr).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(200));
    let refused = get(capped.addr, "/healthz");
    assert_eq!(refused.status, 503, "{}", refused.text());
    assert_eq!(refused.code(), "saturated");
    assert!(refused.head.to_ascii_lowercase().contains("retry-after: 1"), "{}", refused.head);
    drop(held);
    let t = Instant::now();
    loop {
        if get(capped.addr, "/healthz").status == 200 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(3), "never served again after the idle connections closed");
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(capped.metric("curvenet_connections_refused_total") >= 1.0);
}

#[test]
fn the_cache_stays_within_its_bytes_under_a_churn_of_distinct_bindings() {
    let _serial = one_at_a_time();
    let hand22 = request_from_stage("fixtures/hand/hand_22k.usdc");
    // One binding's measured size, and what it adds to RSS in a fresh server.
    let probe = Server::start(&[]);
    let before = probe.rss_kib();
    let a = post_json(probe.addr, "/v1/bindings", &hand22);
    assert_eq!(a.status, 200, "{}", a.text());
    let size = a.json()["size_bytes"].as_u64().unwrap();
    // The size counts the group workspaces batches make the binding keep:
    // solve one, so that they exist.
    let id = a.json()["binding_id"].as_str().unwrap().to_string();
    let frames: Vec<serde_json::Value> = (0..16).map(|_| serde_json::json!({})).collect();
    let b = post_json(probe.addr, &format!("/v1/bindings/{id}/frames:batch"), &serde_json::json!({ "frames": frames }));
    assert_eq!(b.status, 200, "{}", b.text());
    let grown = (probe.rss_kib() - before) * 1024;
    println!("one hand_22k binding and a batch: size_bytes {} MB, RSS grew {} MB", size / 1_000_000, grown / 1_000_000);
    // RSS also holds the requests' JSON and the freed temporaries the
    // allocator keeps (and the batch's answer); the binding with its
    // workspaces must not be much larger than measured, nor much smaller
    // (the two groups of 8 may run one after the other on one thread, so
    // only one group workspace may exist).
    assert!((grown as f64) < 2.0 * size as f64 + 64e6, "RSS grew {grown} for a binding of {size}");
    assert!((grown as f64) > 0.5 * size as f64, "RSS grew {grown} for a binding of {size}");
    drop(probe);

    // Room for two; eight distinct ones posted one after another.
    let capacity = 2 * size + size / 2;
    let server = Server::start(&["--cache-bytes", &capacity.to_string()]);
    let baseline = server.rss_kib() * 1024;
    let mut peak = 0u64;
    for k in 0..8 {
        let mut r = hand22.clone();
        r.options.snap_tolerance = Some(1e-5 + k as f64 * 1e-7);
        let a = post_json(server.addr, "/v1/bindings", &r);
        assert_eq!(a.status, 200, "{}", a.text());
        assert!(!a.json()["cached"].as_bool().unwrap());
        peak = peak.max(server.rss_kib() * 1024);
        assert!(server.metric("curvenet_cache_bytes") <= capacity as f64);
    }
    assert!(server.metric("curvenet_cache_evictions_total") >= 5.0);
    let over = peak.saturating_sub(baseline);
    println!(
        "churn of 8 distinct hand_22k bindings, cache {} MB: RSS baseline {} MB, peak {} MB (+{} MB over the baseline)",
        capacity / 1_000_000,
        baseline / 1_000_000,
        peak / 1_000_000,
        over / 1_000_000
    );
    // The documented bound (server/README.md, "Limits and timeouts"): the
    // cache's bytes plus a fixed overhead of 2 bindings being computed (one
    // per solve thread) and 128 MB.
    let bound = capacity + 2 * size + 128_000_000;
    assert!(over < bound, "RSS rose {over} bytes over its baseline, more than {bound}");
}

#[test]
fn batches_are_admitted_under_contention() {
    let _serial = one_at_a_time();
    let server = Server::start(&["--max-solves", "2"]);
    let addr = server.addr;
    let id = bind(addr, hand());
    let pool = hand().curvenets[0].pool.clone();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let singles: Vec<_> = (0..4)
        .map(|_| {
            let (stop, id, pool) = (stop.clone(), id.clone(), pool.clone());
            std::thread::spawn(move || {
                let mut statuses = std::collections::BTreeMap::new();
                let t = Instant::now();
                for _ in 0..20_000 {
                    if stop.load(std::sync::atomic::Ordering::Relaxed) || t.elapsed() > Duration::from_secs(60) {
                        break;
                    }
                    let a = post_json(addr, &format!("/v1/bindings/{id}/frames"), &json!({"posed": [pool]}));
                    *statuses.entry(a.status).or_insert(0) += 1;
                }
                statuses
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let frames: Vec<Value> = (0..8).map(|_| json!({"posed": [pool]})).collect();
    let mut batch_statuses = Vec::new();
    for _ in 0..20 {
        let a = post_json(addr, &format!("/v1/bindings/{id}/frames:batch"), &json!({ "frames": frames }));
        if a.status == 200 {
            assert_eq!(a.json()["frames"].as_array().unwrap().len(), 8);
        }
        batch_statuses.push(a.status);
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let singles: Vec<_> = singles.into_iter().map(|h| h.join().unwrap()).collect();
    let admitted = batch_statuses.iter().filter(|&&s| s == 200).count();
    println!("batches admitted {admitted}/20 ({batch_statuses:?}); single-frame clients: {singles:?}");
    assert_eq!(admitted, 20, "{batch_statuses:?}");
    for s in &singles {
        assert!(s.get(&200).copied().unwrap_or(0) > 0, "a single-frame client was starved: {s:?}");
    }
}

#[test]
fn the_small_things() {
    let _serial = one_at_a_time();
    let token = "s3cret";
    let root = common::temp_dir("hardening", "bake");
    // 200 KB of points: the 1,400-vertex shot's 24 frames are 403 KB.
    let server = Server::start_with_env(
        &["--bake-root", root.to_str().unwrap(), "--max-bake-bytes", "200KB"],
        &[("CURVENET_TOKEN", token)],
    );
    let addr = server.addr;
    // The bearer scheme is case-insensitive.
    for scheme in ["Bearer", "bearer", "BEARER", "bEaReR"] {
        let a = request(addr, "GET", "/metrics", &[("Authorization", &format!("{scheme} {token}"))], b"");
        assert_eq!(a.status, 200, "{scheme}: {}", a.text());
    }
    assert_eq!(request(addr, "GET", "/metrics", &[("Authorization", "Basic s3cret")], b"").status, 401);
    let auth = format!("Bearer {token}");
    let call = |method: &str, path: &str, body: &Value| {
        request(
            addr,
            method,
            path,
            &[("Authorization", &auth), ("Content-Type", "application/json")],
            &serde_json::to_vec(body).unwrap(),
        )
    };
    // A path parameter that does not parse is a JSON error.
    let a = call("GET", "/v1/viewer/stages/-1", &json!(null));
    assert_eq!((a.status, a.code().as_str()), (404, "not_found"), "{}", a.text());
    // An empty pool is empty_input.
    let mut empty = hand().clone();
    empty.curvenets[0].pool.clear();
    let a = call("POST", "/v1/bindings", &serde_json::to_value(&empty).unwrap());
    assert_eq!((a.status, a.code().as_str()), (422, "empty_input"), "{}", a.text());
    assert!(a.text().contains("curvenets[0].pool"));
    // Repeated blend-shape point indices are refused, naming both.
    let mut repeated = hand().clone();
    repeated.blend_shapes = vec![
        serde_json::from_value(
            json!({"name": "s", "offsets": [[0.0, 0.0, 0.1], [0.0, 0.0, 0.2]], "point_indices": [7, 7]}),
        )
        .unwrap(),
    ];
    let a = call("POST", "/v1/bindings", &serde_json::to_value(&repeated).unwrap());
    assert_eq!((a.status, a.code().as_str()), (422, "invalid_parameter"), "{}", a.text());
    assert!(a.text().contains("point_indices[1] repeats vertex 7"), "{}", a.text());

    // Bakes: a copy of the shipped shot inside the root.
    let shot_dir = common::copy_shot(&root);
    let fixtures = common::repo().join("fixtures");
    let shot = std::fs::read_to_string(fixtures.join("shots/hand_wave/shot.usda")).unwrap();
    // Its hand layer as an absolute path outside the root: refused.
    let outside =
        shot.replace("@../../hand/hand_1k4.usda@", &format!("@{}@", fixtures.join("hand/hand_1k4.usda").display()));
    std::fs::write(shot_dir.join("outside.usda"), outside).unwrap();
    let bake = |stage: &str, output: &str, frames: Option<&str>| {
        let mut body = json!({"stage": stage, "output": output});
        if let Some(f) = frames {
            body["frames"] = json!(f);
        }
        call("POST", "/v1/bake", &body)
    };
    let a = bake("shot/outside.usda", "shot/out.usda", Some("1-2"));
    assert_eq!((a.status, a.code().as_str()), (403, "path_forbidden"), "{}", a.text());
    assert!(a.text().contains("hand_1k4.usda") && a.text().contains("outside the allowed directories"), "{}", a.text());
    // A bad frame range names the field, with no command-line text.
    let a = bake("shot/shot.usda", "shot/out.usda", Some("5-1"));
    assert_eq!((a.status, a.code().as_str()), (422, "bake_failed"), "{}", a.text());
    assert!(a.text().contains("frames \\\"5-1\\\"") || a.text().contains("frames \"5-1\""), "{}", a.text());
    assert!(!a.text().contains("--help") && !a.text().contains("--frames"), "{}", a.text());
    // A killed bake's temporary file beside the output is removed by the next bake.
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    let host: String =
        host.trim().chars().map(|c| if c.is_ascii_alphanumeric() || c == '.' || c == '_' { c } else { '_' }).collect();
    let mut gone = Command::new("true").spawn().unwrap();
    let dead = gone.id();
    gone.wait().unwrap();
    let stale = shot_dir.join(format!(".out.usda.tmp-{host}-{dead}-0-00000000000000aa"));
    std::fs::write(&stale, "half a layer").unwrap();
    let a = bake("shot/shot.usda", "shot/out.usda", Some("1-2"));
    assert_eq!(a.status, 200, "{}", a.text());
    assert!(!stale.exists(), "the stale temporary file is still there");
    assert!(shot_dir.join("out.usda").is_file());
    assert_eq!(a.json()["warnings"], json!([]), "{}", a.text());
    // A bake's warnings come back in its answer (the command line prints them
    // on stderr): frames past the shot's endTimeCode 24 are baked, and said.
    let a = bake("shot/shot.usda", "shot/late.usda", Some("23-26"));
    assert_eq!(a.status, 200, "{}", a.text());
    let warnings = a.json()["warnings"].as_array().cloned().unwrap_or_default();
    assert_eq!(warnings.len(), 1, "{}", a.text());
    let w = warnings[0].as_str().unwrap_or_default();
    assert!(w.contains("shot.usda") && w.contains("23-26") && w.contains("endTimeCode 24"), "{w}");
    assert!(shot_dir.join("late.usda").is_file());
    // An output directory that does not exist: worth retrying (503, as the
    // command line's exit 75), naming the directory; nothing is written.
    let a = bake("shot/shot.usda", "shot/no/such/x.usda", Some("1-2"));
    assert_eq!((a.status, a.code().as_str()), (503, "unavailable"), "{}", a.text());
    assert!(a.text().contains("shot/no/such"), "{}", a.text());
    assert!(a.head.to_ascii_lowercase().contains("retry-after:"), "{}", a.head);
    assert!(!shot_dir.join("no").exists());
    // A path naming a directory is never a layer: refused (the command line exits 2).
    let a = bake("shot/shot.usda", "shot/x.usda/", Some("1-2"));
    assert_eq!((a.status, a.code().as_str()), (422, "bake_failed"), "{}", a.text());
    assert!(!shot_dir.join("x.usda").exists());
    // Over --max-bake-bytes: refused before any work, naming the limit.
    let a = bake("shot/shot.usda", "shot/all.usda", None);
    assert_eq!((a.status, a.code().as_str()), (422, "limit_exceeded"), "{}", a.text());
    assert!(a.text().contains("24 frames of 1400 vertices") && a.text().contains("--max-bake-bytes"), "{}", a.text());
    assert!(!shot_dir.join("all.usda").exists());
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn a_bake_stops_when_its_client_leaves() {
    let _serial = one_at_a_time();
    let root = common::temp_dir("hardening", "bake-leaves");
    let shot_dir = common::copy_shot(&root);
    let server = Server::start(&["--bake-root", root.to_str().unwrap()]);
    // 50,000 frames (840 MB of points, under the default 1 GiB): about a
    // minute of solving. The client waits until it runs, then leaves.
    let body = serde_json::to_vec(&json!({"stage": "shot/shot.usda", "output": "shot/long.usda", "frames": "1-50000"}))
        .unwrap();
    let mut s = TcpStream::connect(server.addr).unwrap();
    let head = format!(
        "POST /v1/bake HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\n\r\n",
        server.addr,
        body.len()
    );
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(&body).unwrap();
    let until = |want: f64, limit: Duration| {
        let t = Instant::now();
        while server.metric("curvenet_solves_in_flight") != want {
            assert!(t.elapsed() < limit, "curvenet_solves_in_flight never became {want}");
            std::thread::sleep(Duration::from_millis(50));
        }
        t.elapsed()
    };
    until(1.0, Duration::from_secs(30));
    std::thread::sleep(Duration::from_millis(500));
    drop(s);
    // Stopped at its next chunk of frames (milliseconds), not after the minute.
    let stopped = until(0.0, Duration::from_secs(10));
    assert!(!shot_dir.join("long.usda").exists(), "a cancelled bake wrote its output");
    let left: Vec<_> = std::fs::read_dir(&shot_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("long"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // And says so in the log, naming the stage.
    let t = Instant::now();
    while !server.log().contains("bake stopped before writing anything") {
        assert!(t.elapsed() < Duration::from_secs(5), "no log line for the stopped bake:\n{}", server.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(server.log().contains("shot.usda"), "{}", server.log());
    eprintln!("the bake stopped {stopped:?} after its client left");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn the_command_line_exits_quietly_when_its_reader_goes_away() {
    let _serial = one_at_a_time();
    for args in [
        &["inspect", "fixtures/shots/hand_wave/shot.usda", "--bind", "--json"][..],
        &["bake", "--help"][..],
        &["inspect", "fixtures/hand/hand_22k.usdc", "--bind"][..],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_curvenet"))
            .args(args)
            .current_dir(common::repo())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Read a few bytes, then close the pipe (as `| head -c 10` does).
        let mut out = child.stdout.take().unwrap();
        let mut first = [0u8; 10];
        out.read_exact(&mut first).unwrap();
        drop(out);
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!stderr.contains("panicked") && !stderr.contains("Broken pipe"), "{args:?}: {stderr}");
        // Killed by SIGPIPE (what `head` leaves a C tool with), or done before it noticed.
        use std::os::unix::process::ExitStatusExt as _;
        assert!(output.status.success() || output.status.signal() == Some(13), "{args:?}: {:?}", output.status);
    }
}

/// One answer off a keep-alive connection: status, head, body (by its Content-Length).
fn read_one(s: &mut TcpStream) -> (u16, String, Vec<u8>) {
    let mut raw = Vec::new();
    let mut byte = [0u8; 1];
    while !raw.ends_with(b"\r\n\r\n") {
        assert_eq!(s.read(&mut byte).unwrap(), 1, "the connection closed mid-head: {}", String::from_utf8_lossy(&raw));
        raw.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&raw).to_ascii_lowercase();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    let len: usize =
        head.lines().find_map(|l| l.strip_prefix("content-length:")).map_or(0, |v| v.trim().parse().unwrap());
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).unwrap();
    (status, head, body)
}

#[test]
fn an_answer_that_leaves_the_body_unread_closes_the_connection_and_says_so() {
    let _serial = one_at_a_time();
    let server = Server::start(&["--body-limit", "1MiB"]);
    let addr = server.addr;
    let head = |path: &str, len: usize| {
        format!(
            "POST {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\nContent-Length: {len}\r\n\r\n"
        )
    };
    let unknown = format!("/v1/bindings/{}/frames:batch", "0".repeat(64));
    // Refused before the body is read: an unknown binding (1 KB of 200 KB sent), a declared length over the limit.
    for (path, len) in [(unknown.as_str(), 200_000), ("/v1/deform", 2 << 20)] {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        s.write_all(head(path, len).as_bytes()).unwrap();
        s.write_all(&[b' '; 1024]).unwrap();
        let (status, answer, _) = read_one(&mut s);
        assert!(matches!(status, 404 | 413), "{path}: {answer}");
        assert!(answer.contains("connection: close"), "{path}: {answer}");
        // The server closes it: the read ends (or is reset) instead of waiting for more.
        let mut rest = Vec::new();
        let _ = s.read_to_end(&mut rest);
    }
    // An answer after the whole body was read keeps the connection for the next request.
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let body = b"{\"not\": \"a deform request\"}";
    s.write_all(head("/v1/deform", body.len()).as_bytes()).unwrap();
    s.write_all(body).unwrap();
    let (status, answer, _) = read_one(&mut s);
    assert!((400..500).contains(&status) && !answer.contains("connection: close"), "{answer}");
    s.write_all(format!("GET /healthz HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes()).unwrap();
    let (status, answer, _) = read_one(&mut s);
    assert_eq!(status, 200, "{answer}");
}

/// A server started with `args` and the 22k hand bound on it.
fn hand_22k_server(args: &[&str]) -> (Server, SocketAddr, &'static BindingRequest, String) {
    let server = Server::start(args);
    let id = bind(server.addr, hand_22k());
    let addr = server.addr;
    (server, addr, hand_22k(), id)
}

/// `count` clients posting `body` to binding `id`'s `frames:batch` at once;
/// each returns its answer and when it came (from this call).
fn post_batches(
    addr: SocketAddr,
    id: &str,
    body: Vec<u8>,
    count: usize,
) -> Vec<std::thread::JoinHandle<(Answer, Duration)>> {
    let (t0, body) = (Instant::now(), std::sync::Arc::new(body));
    (0..count)
        .map(|_| {
            let (body, path) = (body.clone(), format!("/v1/bindings/{id}/frames:batch"));
            std::thread::spawn(move || (post_binary(addr, &path, &body), t0.elapsed()))
        })
        .collect()
}

/// Waits (bounded) until `metric` reaches `want`; returns how long it took.
fn until_at_least(server: &Server, metric: &str, want: f64, limit: Duration) -> Duration {
    let t = Instant::now();
    while server.metric(metric) < want {
        assert!(t.elapsed() < limit, "{metric} never reached {want}");
        std::thread::sleep(Duration::from_millis(5));
    }
    t.elapsed()
}

#[test]
fn a_frame_posted_during_long_batches_waits_for_one_wave_of_them_not_for_all() {
    let _serial = one_at_a_time();
    let (server, addr, req, id) = hand_22k_server(&["--max-batch-bytes", "1GiB"]);
    // Two batches of 400 frames of the 22k hand: each about 0.3-1 s of
    // solving on both solve threads, in waves of two groups of 8 frames.
    const N: usize = 400;
    let t0 = Instant::now();
    let batches = post_batches(addr, &id, binary_batch(req, N), 2);
    // Once their first groups are solved, one frame.
    until_at_least(&server, "curvenet_frames_solved_total", 1.0, Duration::from_secs(60));
    let asked = t0.elapsed();
    let pools: Vec<_> = req.curvenets.iter().map(|c| c.pool.clone()).collect();
    let single = post_json(addr, &format!("/v1/bindings/{id}/frames"), &json!({ "posed": pools }));
    let answered = t0.elapsed();
    let solved_then = server.metric("curvenet_frames_solved_total");
    assert_eq!(single.status, 200, "{}", single.text());
    let done: Vec<_> = batches.into_iter().map(|h| h.join().unwrap()).collect();
    let vertices = req.projection_points.len();
    for (a, _) in &done {
        assert_eq!(a.status, 200);
        assert!(a.body.len() > N * vertices * 12, "a batch answer of {} bytes", a.body.len());
    }
    let first_batch = done.iter().map(|d| d.1).min().unwrap();
    eprintln!(
        "frame asked at {asked:?}, answered at {answered:?} ({solved_then} frames solved then); batches done at {:?}",
        done.iter().map(|d| d.1).collect::<Vec<_>>()
    );
    // Between the frame's asking and its answer the pool ran at most a wave
    // of each batch (16 frames each) besides it; frame by frame it waited
    // for most of the batches (769 of their 800 frames solved when it was
    // answered, measured with each batch one job on the pool).
    assert!(
        answered < first_batch && solved_then < (N / 2) as f64,
        "the frame (asked at {asked:?}, answered at {answered:?}, {solved_then} of the batches' {} frames solved \
         then) waited for the batches (the first done at {first_batch:?})",
        2 * N
    );
}

#[test]
fn a_batch_stops_solving_when_its_client_leaves() {
    let _serial = one_at_a_time();
    let (server, addr, req, id) = hand_22k_server(&["--max-batch-bytes", "1GiB"]);
    // 2,000 frames: a few seconds of solving. The client leaves after the first groups.
    const N: usize = 2000;
    let s = send(addr, &format!("/v1/bindings/{id}/frames:batch"), "application/octet-stream", &binary_batch(req, N));
    until_at_least(&server, "curvenet_frames_solved_total", 16.0, Duration::from_secs(60));
    drop(s);
    let t = Instant::now();
    while server.metric("curvenet_solves_in_flight") != 0.0 {
        assert!(t.elapsed() < Duration::from_secs(10), "the batch still holds its permit");
        std::thread::sleep(Duration::from_millis(20));
    }
    let stopped = server.metric("curvenet_frames_solved_total");
    std::thread::sleep(Duration::from_millis(500));
    let later = server.metric("curvenet_frames_solved_total");
    eprintln!("the batch stopped after {stopped} of {N} frames, {:?} after its client left", t.elapsed());
    assert_eq!(stopped, later, "frames were still solved after the batch stopped");
    assert!(stopped < (N / 2) as f64, "the batch solved {stopped} of its {N} frames after its client left");
    assert_eq!(server.metric("curvenet_batch_memory_bytes"), 0.0);
}

#[test]
fn batches_in_flight_hold_at_most_the_batch_memory_together() {
    let _serial = one_at_a_time();
    let (server, addr, req, id) = hand_22k_server(&["--max-batch-memory", "64MiB", "--queue-timeout", "0.5"]);
    let path = format!("/v1/bindings/{id}/frames:batch");
    let vertices = req.projection_points.len();
    // Larger than all of it (200 frames hold 24 bytes a vertex: 105 MB): 422.
    let a = post_binary(addr, &path, &binary_batch(req, 200));
    assert_eq!((a.status, a.code().as_str()), (422, "limit_exceeded"), "{}", a.text());
    assert!(a.text().contains("--max-batch-memory"), "{}", a.text());
    // 100 frames (about 53 MB) whose client does not read the answer hold their share while it is unsent.
    let body = binary_batch(req, 100);
    let mut held = send(addr, &path, "application/octet-stream", &body);
    until_at_least(&server, "curvenet_frames_solved_total", 100.0, Duration::from_secs(60));
    let reserved = server.metric("curvenet_batch_memory_bytes");
    assert!(reserved >= (100 * vertices * 24) as f64 && reserved <= (64 << 20) as f64, "{reserved} bytes reserved");
    // Another such batch waits in line for the queue timeout, then 503 naming
    // the limit; while it waits, only what is granted is counted.
    let t = Instant::now();
    let waiting = {
        let (path, body) = (path.clone(), body.clone());
        std::thread::spawn(move || post_binary(addr, &path, &body))
    };
    std::thread::sleep(Duration::from_millis(200));
    let counted = server.metric("curvenet_batch_memory_bytes");
    assert!(counted <= reserved + (1 << 20) as f64, "{counted} bytes counted while a batch waits, {reserved} held");
    let b = waiting.join().unwrap();
    assert_eq!((b.status, b.code().as_str()), (503, "saturated"), "{}", b.text());
    assert!(b.text().contains("--max-batch-memory"), "{}", b.text());
    assert!(b.head.to_ascii_lowercase().contains("retry-after"), "{}", b.head);
    assert!(t.elapsed() >= Duration::from_millis(450), "answered after {:?}, not after waiting in line", t.elapsed());
    // The first answer, read now, is whole; then its share is free and the second batch runs.
    let first = read_answer(&mut held).expect("an answer");
    assert_eq!(first.status, 200);
    assert!(first.body.len() > 100 * vertices * 12);
    let t = Instant::now();
    while server.metric("curvenet_batch_memory_bytes") != 0.0 {
        assert!(t.elapsed() < Duration::from_secs(10), "the sent answer still holds its share");
        std::thread::sleep(Duration::from_millis(10));
    }
    let b = post_binary(addr, &path, &body);
    assert_eq!(b.status, 200, "{}", b.text());
}

#[test]
fn single_frames_find_permits_while_batches_fill_the_server() {
    let _serial = one_at_a_time();
    // 4 solve permits: batches may hold at most 2 of them (a slot each, and
    // spare permits only while half stay free), so a single frame never
    // waits in line for a permit. Each batch held one or two of them before:
    // single frames waited 1.1-1.5 s for a permit here, and get 503 after
    // the 0.5 s queue timeout.
    let (server, addr, req, id) =
        hand_22k_server(&["--max-solves", "4", "--max-batch-bytes", "1GiB", "--queue-timeout", "0.5"]);
    let body = std::sync::Arc::new(binary_batch(req, 200));
    let batches: Vec<_> = (0..6)
        .map(|_| {
            let (body, id) = (body.clone(), id.clone());
            std::thread::spawn(move || post_binary(addr, &format!("/v1/bindings/{id}/frames:batch"), &body).status)
        })
        .collect();
    until_at_least(&server, "curvenet_frames_solved_total", 1.0, Duration::from_secs(60));
    let pools: Vec<_> = req.curvenets.iter().map(|c| c.pool.clone()).collect();
    let mut singles = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        let a = post_json(addr, &format!("/v1/bindings/{id}/frames"), &json!({ "posed": pools }));
        singles.push((a.status, t.elapsed()));
    }
    let statuses: Vec<u16> = batches.into_iter().map(|h| h.join().unwrap()).collect();
    eprintln!("single frames {singles:?}; batches {statuses:?}");
    assert!(singles.iter().all(|(s, _)| *s == 200), "a single frame was refused: {singles:?}");
    assert!(statuses.iter().all(|s| [200, 503].contains(s)), "{statuses:?}");
    assert!(statuses.contains(&200), "{statuses:?}");
}

#[test]
fn batches_that_fit_one_at_a_time_run_one_after_the_other() {
    let _serial = one_at_a_time();
    // Frames with a rest pose each: a batch's body is most of it, so its
    // first share (reserved before parsing: its body and a bound on its
    // frames, about 79 MB here) is most of its full share (about 105 MB).
    // Two first shares fit the budget, a first and a full share do not:
    // both batches holding a first share would wait for each other (the
    // server idle) until the queue timeout. The batch gate lets one at a
    // time hold a part, so the second runs once the first is done.
    let (server, addr, req, id) = hand_22k_server(&["--max-batch-memory", "170MB", "--queue-timeout", "20"]);
    let n = 100;
    let mut arrays: Vec<Value> = req
        .curvenets
        .iter()
        .enumerate()
        .map(|(k, c)| json!({"name": "posed", "index": k, "shape": [c.pool.len(), 3]}))
        .collect();
    arrays.push(json!({"name": "rest", "shape": [req.projection_points.len(), 3]}));
    let header = json!({ "frames": vec![json!({ "arrays": arrays }); n] });
    let frame: Vec<f32> = req
        .curvenets
        .iter()
        .flat_map(|c| c.pool.iter().flatten())
        .chain(req.projection_points.iter().flatten())
        .map(|&x| x as f32)
        .collect();
    let batches = post_batches(addr, &id, binary_frame(&header, &frame.repeat(n)), 2);
    let done: Vec<_> = batches.into_iter().map(|h| h.join().unwrap()).collect();
    eprintln!("{:?}", done.iter().map(|(a, at)| (a.status, at)).collect::<Vec<_>>());
    for (a, _) in &done {
        assert_eq!(a.status, 200, "{}", a.text().chars().take(300).collect::<String>());
    }
    // One after the other, not after waiting out the 20 s queue timeout.
    let last = done.iter().map(|d| d.1).max().unwrap();
    assert!(last < Duration::from_secs(15), "the batches took {last:?}");
    assert_eq!(server.metric("curvenet_batch_memory_bytes"), 0.0);
}

#[test]
fn requests_that_leave_the_line_for_a_permit_are_not_counted_in_it() {
    let _serial = one_at_a_time();
    // One permit, and a line of at most 4 waiting for it. A long batch holds
    // the permit; five single frames wait in line and their clients leave.
    // Their places must be given back: before, the count of those in line
    // kept them, so the line stayed full and every later request that found
    // the permit taken got 503 at once, for the life of the process.
    let (server, addr, req, id) =
        hand_22k_server(&["--max-solves", "1", "--queue-timeout", "30", "--max-batch-bytes", "1GiB"]);
    let batch = post_batches(addr, &id, binary_batch(req, 1500), 1);
    until_at_least(&server, "curvenet_frames_solved_total", 1.0, Duration::from_secs(60));
    let pools: Vec<_> = req.curvenets.iter().map(|c| c.pool.clone()).collect();
    let body = serde_json::to_vec(&json!({ "posed": pools })).unwrap();
    let path = format!("/v1/bindings/{id}/frames");
    let leaving: Vec<TcpStream> = (0..5).map(|_| send(addr, &path, "application/json", &body)).collect();
    std::thread::sleep(Duration::from_millis(300));
    drop(leaving);
    std::thread::sleep(Duration::from_millis(300));
    let solved = server.metric("curvenet_frames_solved_total");
    assert!(solved < 1500.0, "the batch finished ({solved} frames) before the frame was posted: make it longer");
    // This frame waits for the permit (the batch still holds it), then is solved.
    let a = post_json(addr, &path, &json!({ "posed": pools }));
    assert_eq!(a.status, 200, "{}", a.text());
    let (b, _) = batch.into_iter().next().unwrap().join().unwrap();
    assert_eq!(b.status, 200, "{}", b.text().chars().take(300).collect::<String>());
}
