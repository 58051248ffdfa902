//! Helpers of the tests that run the `curvenet` binary (bake, stitch), and
//! (`router`) of those that send requests to a service in process.

#[allow(dead_code)]
pub mod router;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The shipped shot.
#[allow(dead_code)]
pub const SHOT: &str = "fixtures/shots/hand_wave/shot.usda";

/// The repository root (the binary runs there).
#[allow(dead_code)]
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Runs `curvenet ARGS` in the repository root.
#[allow(dead_code)]
pub fn curvenet(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_curvenet")).args(args).current_dir(repo()).output().expect("runs")
}

#[allow(dead_code)]
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A fresh, empty directory for one test, named after its test file's `kind` and `tag`.
#[allow(dead_code)]
pub fn temp_dir(kind: &str, tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("curvenet-{kind}-test-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `curvenet serve` on a free port with `extra` arguments (e.g.
/// `--open-stage SHOT`), run from the repository root; killed when dropped.
#[allow(dead_code)]
pub struct Served {
    child: std::process::Child,
    /// `http://127.0.0.1:PORT`, as the server prints it.
    pub url: String,
}

#[allow(dead_code)]
impl Served {
    pub fn start(extra: &[&str]) -> Self {
        use std::process::Stdio;
        let mut child = Command::new(env!("CARGO_BIN_EXE_curvenet"))
            .args(["serve", "--addr", "127.0.0.1:0", "--solve-threads", "2"])
            .args(extra)
            .env_remove("CURVENET_TOKEN")
            .current_dir(repo())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("curvenet serve starts");
        let first = first_stdout_line(&mut child, std::time::Duration::from_secs(120));
        let url = first.strip_prefix("listening on ").expect("listening on ...").to_string();
        Self { child, url }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The largest distance between corresponding points of `a` and `b` (same length).
#[allow(dead_code)]
pub fn max_dist(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}

/// The first line `child` prints on its (piped) stdout, waiting up to
/// `timeout`; a thread keeps draining the rest so the child never blocks
/// on a full pipe.
#[allow(dead_code)]
pub fn first_stdout_line(child: &mut std::process::Child, timeout: std::time::Duration) -> String {
    use std::io::Read as _;
    let mut stdout = child.stdout.take().expect("stdout is piped");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = Vec::new();
        let mut byte = [0u8; 1];
        while stdout.read(&mut byte).is_ok_and(|n| n == 1) {
            if byte[0] == b'\n' {
                let _ = tx.send(String::from_utf8_lossy(&line).into_owned());
                line.clear();
            } else {
                line.push(byte[0]);
            }
        }
    });
    rx.recv_timeout(timeout).expect("the server prints its address")
}

/// UsdSkel's skinning transforms of `rig` at `t`, in the mesh's space (the
/// client's side of a skinned frame request; the bake reads them through
/// `cli::rig::JointReader`).
#[allow(dead_code)]
pub fn skinning_transforms(
    stage: &curvenet_schema::usd::Stage,
    rig: &curvenet_schema::usd::SkinRig,
    skeleton: &curvenet_core::Skeleton,
    t: f64,
) -> Vec<curvenet_core::Mat4> {
    use curvenet_core::{MAT4_IDENTITY, mat4_mul};
    let local = stage.joint_local_transforms(rig, Some(t)).unwrap();
    let mut out = vec![MAT4_IDENTITY; local.len()];
    skeleton.skinning_transforms(&local, &mut out).unwrap();
    let to_mesh = stage.skel_to_mesh_transform(rig, Some(t)).unwrap();
    if to_mesh != MAT4_IDENTITY {
        for m in &mut out {
            *m = mat4_mul(m, &to_mesh);
        }
    }
    out
}

/// The hand_wave shot (its anim layer, the 1,400-vertex hand and the
/// curvenet beside it) copied into `root/shot`; returns that directory.
#[allow(dead_code)]
pub fn copy_shot(root: &std::path::Path) -> std::path::PathBuf {
    let shot_dir = root.join("shot");
    std::fs::create_dir_all(&shot_dir).unwrap();
    let fixtures = repo().join("fixtures");
    std::fs::copy(fixtures.join("shots/hand_wave/anim.usda"), shot_dir.join("anim.usda")).unwrap();
    std::fs::copy(fixtures.join("hand/hand_1k4.usda"), shot_dir.join("hand_1k4.usda")).unwrap();
    std::fs::copy(fixtures.join("hand/curvenet.usda"), shot_dir.join("curvenet.usda")).unwrap();
    let shot = std::fs::read_to_string(fixtures.join("shots/hand_wave/shot.usda")).unwrap();
    std::fs::write(shot_dir.join("shot.usda"), shot.replace("@../../hand/hand_1k4.usda@", "@./hand_1k4.usda@"))
        .unwrap();
    shot_dir
}

/// `GET url` answered 200 with JSON: the JSON (panics naming the url otherwise).
#[allow(dead_code)]
pub async fn get_json(client: reqwest::Client, url: String) -> serde_json::Value {
    let r = client.get(&url).send().await.unwrap();
    assert_eq!(r.status(), 200, "GET {url}");
    r.json::<serde_json::Value>().await.unwrap()
}
