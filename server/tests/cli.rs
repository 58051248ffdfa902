//! The `curvenet` binary as a user runs it.

use std::process::Command;

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn curvenet(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_curvenet")).args(args).current_dir(repo()).output().expect("runs")
}

#[test]
fn inspect_json_describes_the_grid_fixture() {
    let out = curvenet(&["inspect", "fixtures/grid/grid.usda", "--time", "3", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    assert_eq!(v["meshes"][0]["path"], "/Grid/Mesh");
    assert_eq!(v["meshes"][0]["vertices"], 961);
    assert_eq!(v["meshes"][0]["face_sizes"]["quads"], 900);
    assert_eq!(v["curvenets"][0]["splines"], 40);
    assert_eq!(v["curvenets"][0]["posed_frames"], 4);
    // At frame 3 (the hinge) a control point right of the middle line is rotated to +z.
    let cps = v["curvenets"][0]["control_points_at_time"].as_array().unwrap();
    assert_eq!(cps.len(), 105);
    assert!(cps.iter().any(|p| p[2].as_f64().unwrap() > 0.5), "no control point rotated up at frame 3");
    assert_eq!(v["time_code_range"], serde_json::json!([1.0, 4.0]));
}

#[test]
fn inspect_text_names_prims_and_counts() {
    let out = curvenet(&["inspect", "fixtures/shots/hand_wave/shot.usda", "--time", "7"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("mesh /Hand/Mesh: 1400 vertices, 2796 faces"), "{text}");
    assert!(text.contains("curvenet /Hand/Curvenet: 251 control points, 88 splines"), "{text}");
    // The blend-shape weight is exactly 0.5 at frame 7 (fixtures/README.md).
    assert!(text.contains("blend shape \"bulge\"") && text.contains("weight 0.5"), "{text}");
}

#[test]
fn bad_input_exits_2_and_names_the_problem() {
    let out = curvenet(&["inspect", "fixtures/does-not-exist.usda"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("does-not-exist.usda"));
    let out = curvenet(&["inspect", "fixtures/grid/grid.usda", "--prim", "/Nope"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/Nope"));
}
