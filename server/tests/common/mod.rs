//! Helpers of the tests that run the `curvenet` binary (bake, stitch).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The shipped shot.
#[allow(dead_code)]
pub const SHOT: &str = "fixtures/shots/hand_wave/shot.usda";

/// The repository root (the binary runs there).
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Runs `curvenet ARGS` in the repository root.
pub fn curvenet(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_curvenet")).args(args).current_dir(repo()).output().expect("runs")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A fresh, empty directory for one test, named after its test file's `kind` and `tag`.
pub fn temp_dir(kind: &str, tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("curvenet-{kind}-test-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
