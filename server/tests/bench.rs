//! `curvenet bench --json` on the smallest hand: the report's shape and
//! counts (no timing assertions: the numbers depend on the machine).

use std::process::Command;

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn curvenet(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_curvenet")).args(args).current_dir(repo()).output().expect("runs")
}

fn positive_finite(m: &serde_json::Value, key: &str) -> f64 {
    let x = m[key].as_f64().unwrap_or_else(|| panic!("`{key}` is not a number: {}", m[key]));
    assert!(x.is_finite() && x > 0.0, "`{key}` = {x}");
    x
}

fn count(m: &serde_json::Value, key: &str) -> u64 {
    m[key].as_u64().unwrap_or_else(|| panic!("`{key}` is not a count: {}", m[key]))
}

#[test]
fn bench_json_reports_the_hand_1k4_fixture() {
    let out = curvenet(&["bench", "--json", "--meshes", "hand_1k4", "--repeats", "2", "--frames", "3"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    assert_eq!(v["repeats"], 2);
    assert_eq!(v["frames"], 3);
    assert!(count(&v, "threads") >= 1);
    let simd = v["simd"].as_str().expect("the sweeps' vector unit");
    assert!(["baseline", "avx2", "avx512"].contains(&simd), "simd {simd}");
    let meshes = v["meshes"].as_array().expect("a `meshes` array");
    assert_eq!(meshes.len(), 1);
    let m = &meshes[0];
    assert_eq!(m["mesh"], "hand_1k4");
    assert_eq!(count(m, "vertices"), 1400);
    assert_eq!(count(m, "faces"), 2796);
    assert_eq!(count(m, "repeats"), 2);
    assert_eq!(count(m, "frames"), 3);
    // The shared hand curvenet: 75 knots (fixtures/README.md), more samples than knots.
    let knots = count(m, "knots");
    assert!(knots > 0 && knots <= count(m, "control_points"), "knots {knots}");
    assert!(count(m, "samples") >= knots);
    let unknowns = count(m, "unknowns");
    assert!(unknowns > 0 && unknowns <= 1400, "unknowns {unknowns}");
    assert!(count(m, "constraints") > 0);
    assert!(count(m, "factor_nonzeros") >= unknowns);
    for key in [
        "cutting_ms",
        "factor_ms",
        "solve_ms",
        "binding_ms",
        "surface_ms",
        "assembly_ms",
        "analysis_ms",
        "solve_min_ms",
        "solve_max_ms",
        "tri9_ms",
        "tri3_ms",
        "rest_pose_frame_ms",
        "reference_ms",
        "solve_over_reference",
        "serial_frames_per_s",
        "parallel_frames_per_s",
    ] {
        positive_finite(m, key);
    }
    // Frames in groups of K = 1..32 (issue 19): every K measured, the best named.
    let batch = m["batch"].as_array().expect("a `batch` array");
    let ks: Vec<u64> = batch.iter().map(|r| count(r, "k")).collect();
    assert_eq!(ks, [1, 2, 4, 8, 16, 32]);
    for r in batch {
        for key in ["per_frame_ms", "per_frame_over_reference", "frames_per_s"] {
            positive_finite(r, key);
        }
    }
    let best = count(m, "batch_k");
    let row = batch.iter().find(|r| count(r, "k") == best).expect("batch_k is a measured K");
    assert_eq!(m["batch_frames_per_s"], row["frames_per_s"]);
    assert!(batch.iter().all(|r| r["frames_per_s"].as_f64() <= m["batch_frames_per_s"].as_f64()));
    let over = positive_finite(m, "batch_over_reference");
    let want = row["per_frame_ms"].as_f64().unwrap() / m["reference_ms"].as_f64().unwrap();
    assert!((over - want).abs() <= 1e-9 * want, "batch_over_reference {over}, per frame / reference {want}");
    // Groups of 8 frames with their own rest pose, beside them.
    let rest = &m["rest_batch"];
    assert_eq!(count(rest, "k"), 8);
    for key in ["per_frame_ms", "per_frame_over_reference", "frames_per_s"] {
        positive_finite(rest, key);
    }
    assert!(m["solve_min_ms"].as_f64() <= m["solve_ms"].as_f64());
    assert!(m["solve_ms"].as_f64() <= m["solve_max_ms"].as_f64());
    // No targets are set for the 1.4k hand; the frames stay close to the mesh in the neutral pose.
    assert!(m["targets"].is_null());
    let neutral = m["neutral_max_error"].as_f64().unwrap();
    assert!(neutral < 1e-6, "neutral pose error {neutral}");
    assert!(m["max_displacement"].as_f64().unwrap() > 0.0);
    // The coupled cage's per-frame stages (issue 18): hand_caged's cage and skeleton on the benched hand.
    let cage = &v["cage"][0];
    assert_eq!(cage["mesh"], "hand_1k4");
    assert_eq!((count(cage, "cage_vertices"), count(cage, "joints")), (170, 8));
    for key in ["build_ms", "condition", "cage_rev_ms", "cage_up_ms", "phi_c_ms", "skinning_ms"] {
        positive_finite(cage, key);
    }
}

#[test]
fn bench_refuses_a_missing_fixtures_directory() {
    let out = curvenet(&["bench", "--json", "--fixtures", "no/such/dir", "--meshes", "hand_1k4"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no/such/dir") && err.contains("--fixtures"), "{err}");
}

/// Hostile review (tenth session): these ran, or ran to the end, before
/// failing or being ignored.
#[test]
fn bench_refuses_repeated_meshes_a_foreign_growth_mesh_and_bad_export_paths_up_front() {
    let dir = std::env::temp_dir().join(format!("curvenet-bench-refusals-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let afile = dir.join("afile");
    std::fs::write(&afile, "x").unwrap();
    let quick = ["bench", "--json", "--repeats", "1", "--frames", "2", "--no-corpus", "--no-cage"];
    let runs: [(Vec<&str>, &str); 4] = [
        (vec!["--meshes", "hand_1k4,hand_1k4"], "--meshes names hand_1k4 twice"),
        (vec!["--meshes", "hand_1k4", "--growth-mesh", "nosuch"], "--growth-mesh nosuch is not among --meshes"),
        (vec!["--meshes", "hand_1k4", "--fixtures", "README.md"], "`README.md` is not a directory"),
        (vec!["--meshes", "hand_1k4", "--export", afile.to_str().unwrap()], "exists and is not a directory"),
    ];
    for (args, says) in runs {
        let all: Vec<&str> = quick.iter().copied().chain(args.iter().copied()).collect();
        let out = curvenet(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    // The manifest cannot be written (a directory holds its name): the run
    // fails and removes the mesh files it wrote, so no export is left
    // without its manifest.
    let export_to = |to: &std::path::Path| {
        let all: Vec<&str> = quick
            .iter()
            .copied()
            .chain(["--meshes", "hand_1k4", "--no-growth", "--export", to.to_str().unwrap()])
            .collect();
        curvenet(&all)
    };
    let export = dir.join("export");
    std::fs::create_dir_all(export.join("manifest.json")).unwrap();
    let out = export_to(&export);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let left: Vec<String> =
        std::fs::read_dir(&export).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["manifest.json"], "a failed export left files");
    // A failed export over an earlier one leaves no manifest naming files
    // it overwrote or removed (second review).
    let again = dir.join("again");
    let out = export_to(&again);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(again.join("manifest.json").is_file());
    std::fs::remove_file(again.join("hand_1k4.x3.f64")).unwrap();
    std::fs::create_dir(again.join("hand_1k4.x3.f64")).unwrap();
    let out = export_to(&again);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!again.join("manifest.json").exists(), "a failed export left the earlier manifest");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bench_json_judges_the_hand_22k_against_both_issues_targets() {
    let out = curvenet(&[
        "bench",
        "--json",
        "--meshes",
        "hand_22k",
        "--repeats",
        "1",
        "--frames",
        "2",
        "--no-corpus",
        "--no-cage",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    let m = &v["meshes"][0];
    let t = &m["targets"];
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"));
    assert_eq!((f(t, "frame_ms"), f(t, "batch_frames_per_s"), f(t, "group16_over_reference")), (3.0, 1200.0, 3.0));
    assert_eq!(t["frame_met"].as_bool(), Some(f(m, "solve_ms") <= 3.0), "{t}");
    assert_eq!(t["batch_met"].as_bool(), Some(f(m, "batch_frames_per_s") >= 1200.0), "{t}");
    let k16 = m["batch"].as_array().unwrap().iter().find(|r| r["k"] == 16).expect("a group of 16 is timed");
    assert_eq!(t["group16_met"].as_bool(), Some(f(k16, "per_frame_over_reference") <= 3.0), "{t}");
    assert_eq!(t["binding_met"].as_bool(), Some(f(m, "binding_ms") <= 150.0), "{t}");
}
