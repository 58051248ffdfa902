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

/// `--time nan` or `inf` is refused as a usage error (found by a hostile
/// review: they were read as some sample); a negative time is a time.
#[test]
fn inspect_refuses_a_time_that_is_no_time_code() {
    for bad in ["nan", "inf", "-inf", "soon"] {
        let out = curvenet(&["inspect", "fixtures/grid/grid.usda", "--time", bad]);
        assert_eq!(out.status.code(), Some(2), "--time {bad}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--time") && err.contains(bad), "--time {bad}: {err}");
    }
    let out = curvenet(&["inspect", "fixtures/grid/grid.usda", "--time", "-1", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
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

/// A misspelt `CURVENET_SIMD` (meant to rule a vector unit out) is warned
/// about, naming the value, and the command still runs; a known value is not.
/// Hostile review (tenth session): `--threads 100000` started every
/// thread, `serve --max-solves 0` served 503 forever, and `bake --frames
/// 1-1000000` grew until the machine ran out of memory.
#[test]
fn runaway_thread_counts_zero_limits_and_oversized_bakes_are_refused_up_front() {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let too_many = (4 * cpus + 1).to_string();
    let wave = "fixtures/shots/hand_wave/shot.usda";
    let out = std::env::temp_dir().join(format!("curvenet-cli-refused-{}.usdc", std::process::id()));
    let out = out.to_str().unwrap();
    let runs: [(&[&str], &str); 10] = [
        (&["bake", wave, "--out", out, "--threads", &too_many], "--threads"),
        (&["bench", "--meshes", "hand_1k4", "--no-growth", "--threads", &too_many], "--threads"),
        (&["serve", "--addr", "127.0.0.1:0", "--solve-threads", &too_many], "--solve-threads"),
        (&["serve", "--addr", "127.0.0.1:0", "--max-solves", "0"], "--max-solves"),
        (&["serve", "--addr", "127.0.0.1:0", "--cache-bytes", "0"], "--cache-bytes"),
        (&["serve", "--addr", "127.0.0.1:0", "--max-connections", "0"], "--max-connections"),
        (&["serve", "--addr", "127.0.0.1:0", "--max-batch-memory", "0"], "--max-batch-memory"),
        (&["serve", "--addr", "127.0.0.1:0", "--max-batch-bytes", "0B"], "--max-batch-bytes"),
        (&["serve", "--addr", "127.0.0.1:0", "--max-bake-bytes", "0"], "--max-bake-bytes"),
        // 24 frames × 1400 vertices × 12 bytes = 403,200 bytes.
        (&["bake", wave, "--out", out, "--max-points-bytes", "400KB"], "403200 bytes of points"),
    ];
    for (args, names) in runs {
        let run = curvenet(args);
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(names), "{args:?}: {err}");
        assert!(!std::path::Path::new(out).exists(), "{args:?} wrote {out}");
    }
    let run = curvenet(&["bake", wave, "--out", out, "--threads", &(4 * cpus).to_string(), "--quiet"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let run = curvenet(&["bake", wave, "--out", out, "--max-points-bytes", "404KB", "--quiet"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    std::fs::remove_file(out).unwrap();
}

#[test]
fn an_unknown_curvenet_simd_value_is_warned_about() {
    let run = |value: &str| {
        Command::new(env!("CARGO_BIN_EXE_curvenet"))
            .args(["inspect", "fixtures/grid/grid.usda"])
            .env("CURVENET_SIMD", value)
            .current_dir(repo())
            .output()
            .expect("runs")
    };
    let out = run("sse2");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("warning") && stderr.contains("CURVENET_SIMD=\"sse2\""), "{stderr}");
    for known in ["baseline", "AVX2", "avx512"] {
        let out = run(known);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && !stderr.contains("CURVENET_SIMD"), "{known}: {stderr}");
    }
}

// ---------------------------------------------------------------------------
// The curvenet analysis in `inspect`. Expected counts are derived by hand from
// fixtures/README.md (see the comments), not copied from the program.

fn inspect_json(stage: &str) -> serde_json::Value {
    let out = curvenet(&["inspect", stage, "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON document")
}

fn inspect_text(stage: &str) -> String {
    let out = curvenet(&["inspect", stage]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

fn len(v: &serde_json::Value) -> usize {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).len()
}

/// The number written just before ` {word}` in `line` (e.g. `21` in `21 intersections`).
fn number_before(line: &str, word: &str) -> u64 {
    let at = line.find(&format!(" {word}")).unwrap_or_else(|| panic!("no {word:?} in {line:?}"));
    let digits: String = line[..at].chars().rev().take_while(|c| c.is_ascii_digit()).collect();
    digits.chars().rev().collect::<String>().parse().unwrap_or_else(|_| panic!("no number before {word:?} in {line:?}"))
}

/// The text's analysis summary line of `curvenet`.
fn summary_line<'a>(text: &'a str, curvenet: &str) -> &'a str {
    let header = text
        .lines()
        .position(|l| l.starts_with(&format!("curvenet {curvenet}:")))
        .unwrap_or_else(|| panic!("no curvenet {curvenet} in {text}"));
    let line = text.lines().nth(header + 1).unwrap();
    assert!(line.starts_with("  analysis against "), "{text}");
    line
}

/// Every spline appears in exactly one curve.
fn assert_curves_partition_splines(a: &serde_json::Value, n_splines: usize) {
    let mut seen = vec![0; n_splines];
    for c in a["curves"].as_array().unwrap() {
        for s in c["splines"].as_array().unwrap() {
            seen[s["spline"].as_u64().unwrap() as usize] += 1;
        }
    }
    assert!(seen.iter().all(|&n| n == 1), "splines not covered once: {seen:?}");
}

fn curvenet_warnings(v: &serde_json::Value, prim: &str) -> Vec<String> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .filter(|w| w.starts_with(prim))
        .collect()
}

#[test]
fn inspect_analyses_the_grid_curvenet() {
    let v = inspect_json("fixtures/grid/grid.usda");
    let c = &v["curvenets"][0];
    assert_eq!(c["path"], "/Grid/Curvenet");
    assert!(c["error"].is_null());
    let a = &c["analysis"];
    assert_eq!(a["mesh"], "/Grid/Mesh");
    // 25 knots on a 5×5 lattice, pool index i + 5j (i along x, j along y).
    // Interior knots (i, j ∈ 1..=3): 2 splines along x + 2 along y = valence 4 (9).
    // Border knots other than corners: 2 along the border + 1 inwards = valence 3 (12).
    // Corners: 1 + 1 = valence 2, not intersections. No valence-1 knot: no anchors.
    let mut expected_valence = std::collections::BTreeMap::new();
    for j in 0..5u64 {
        for i in 0..5u64 {
            let border = [i == 0 || i == 4, j == 0 || j == 4];
            match border {
                [true, true] => {}
                [false, false] => {
                    expected_valence.insert(i + 5 * j, 4);
                }
                _ => {
                    expected_valence.insert(i + 5 * j, 3);
                }
            }
        }
    }
    let got: std::collections::BTreeMap<u64, u64> = a["intersections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| (i["point"].as_u64().unwrap(), i["valence"].as_u64().unwrap()))
        .collect();
    assert_eq!(got, expected_valence);
    assert_eq!(len(&a["intersections"]), 21);
    assert_eq!(a["intersections_by_valence"], serde_json::json!({"3": 12, "4": 9}));
    for i in a["intersections"].as_array().unwrap() {
        assert_eq!(len(&i["curves_ccw"]) as u64, i["valence"].as_u64().unwrap(), "{i}");
    }
    assert_eq!(len(&a["anchors"]), 0);
    // Curve ends: 9·4 + 12·3 = 72 → 36 curves, all open. A corner joins its two
    // border splines into one 2-spline curve (4 of them); the other 40 − 8 = 32
    // splines are one curve each.
    assert_eq!(len(&a["curves"]), 36);
    assert_eq!(len(&a["isolated_closed_curves"]), 0);
    let two_spline: Vec<&serde_json::Value> =
        a["curves"].as_array().unwrap().iter().filter(|c| len(&c["splines"]) == 2).collect();
    assert_eq!(two_spline.len(), 4);
    assert_eq!(a["curves"].as_array().unwrap().iter().filter(|c| len(&c["splines"]) == 1).count(), 32);
    assert_curves_partition_splines(a, 40);
    for c in a["curves"].as_array().unwrap() {
        assert_eq!(c["start"]["kind"], "intersection", "{c}");
        assert_eq!(c["end"]["kind"], "intersection", "{c}");
    }
    // Sampling: mesh edges are all 2/30; each straight spline's control polygon
    // is 0.35, so round(5 · 0.35 / (2/30)) = round(26.25) = 26 segments per spline.
    // Segments 40 · 26 = 1040; samples 25 knots + 40 · 25 interior = 1025.
    assert_eq!(a["segments"], 1040);
    assert_eq!(a["samples"], 1025);
    for c in a["curves"].as_array().unwrap() {
        let n = len(&c["splines"]);
        assert_eq!(c["segments"].as_u64().unwrap() as usize, 26 * n, "{c}");
        assert_eq!(c["samples"].as_u64().unwrap() as usize, 26 * n + 1, "{c}");
        assert!((c["length"].as_f64().unwrap() - 0.35 * n as f64).abs() < 1e-6, "{c}");
    }
    // The curvenet lies on the plane of the mesh; every pool point is used.
    assert!(a["max_distance_to_surface"].as_f64().unwrap() < 1e-6);
    assert_eq!(len(&a["unused_control_points"]), 0);
    assert!(curvenet_warnings(&v, "/Grid/Curvenet").is_empty(), "{}", v["warnings"]);
}

#[test]
fn inspect_analyses_the_cylinder_curvenet() {
    let v = inspect_json("fixtures/cylinder/cylinder.usda");
    let a = &v["curvenets"][0]["analysis"];
    assert_eq!(a["mesh"], "/Cylinder/Mesh");
    // 5 rings × 4 knots = 20 knots (pool 0..20, ring r knot k = 4r + k).
    // Interior rings (z = −0.45, 0, 0.45): 2 ring splines + 2 lengthwise = valence 4 (12).
    // End rings (z = ±0.9): 2 ring splines + 1 lengthwise = valence 3 (8).
    assert_eq!(len(&a["intersections"]), 20);
    assert_eq!(a["intersections_by_valence"], serde_json::json!({"3": 8, "4": 12}));
    for i in a["intersections"].as_array().unwrap() {
        let p = i["point"].as_u64().unwrap();
        let want = if !(4..16).contains(&p) { 3 } else { 4 };
        assert_eq!(i["valence"], want, "{i}");
    }
    // Every knot is an intersection, so every spline is a curve of its own:
    // 20 ring splines + 4 lines × 4 splines = 36 curves; no anchors, and no
    // isolated closed curve (every ring passes through intersections).
    assert_eq!(len(&a["anchors"]), 0);
    assert_eq!(len(&a["curves"]), 36);
    assert!(a["curves"].as_array().unwrap().iter().all(|c| len(&c["splines"]) == 1));
    assert_curves_partition_splines(a, 36);
    assert_eq!(len(&a["isolated_closed_curves"]), 0);
    // Mean edge: 33 rings × 48 edges of 2·0.5·sin(π/48) = 0.065403, 48 × 32
    // lengthwise edges of 2/32, 2 × 48 cap spokes of 0.5: 247.60 / 3216 = 0.076990.
    let mean_edge = (33.0 * 48.0 * (std::f64::consts::PI / 48.0).sin() + 1536.0 * 0.0625 + 96.0 * 0.5) / 3216.0;
    assert!((a["mean_edge_length"].as_f64().unwrap() - mean_edge).abs() < 1e-6);
    // A quarter-ring control polygon: 2 · 0.27614 + √2 · (0.5 − 0.27614) = 0.86888
    // → round(5 · 0.86888 / 0.076990) = round(56.43) = 56 segments; a
    // lengthwise spline of 0.45 → round(29.22) = 29. Segments 20 · 56 + 16 · 29
    // = 1584; samples 20 knots + 20 · 55 + 16 · 28 = 1568.
    assert_eq!(a["segments"], 1584);
    assert_eq!(a["samples"], 1568);
    // Rings follow the 48-gon to within r(1 − cos(π/48)) ≈ 0.0011.
    assert!(a["max_distance_to_surface"].as_f64().unwrap() < 0.002);
    assert!(curvenet_warnings(&v, "/Cylinder/Curvenet").is_empty(), "{}", v["warnings"]);
}

#[test]
fn inspect_analyses_the_hand_curvenet() {
    let v = inspect_json("fixtures/hand/hand_1k4.usda");
    let c = &v["curvenets"][0];
    assert_eq!(c["path"], "/Hand/Curvenet");
    let a = &c["analysis"];
    assert_eq!(a["mesh"], "/Hand/Mesh");
    // The fixture designer's totals (fixtures/README.md): 13 valence-4
    // intersections, 5 T-junctions, 5 anchors, 1 isolated closed ring (wrist).
    assert_eq!(len(&a["intersections"]), 18);
    assert_eq!(a["intersections_by_valence"], serde_json::json!({"3": 5, "4": 13}));
    assert_eq!(len(&a["anchors"]), 5);
    assert_eq!(len(&a["isolated_closed_curves"]), 1);
    // Curve ends: 5 anchors + 13 · 4 + 5 · 3 = 72 → 36 open curves, + the wrist ring.
    assert_eq!(len(&a["curves"]), 37);
    assert_curves_partition_splines(a, 88);
    // The wrist ring: 4 knots, 4 splines, closed.
    let ring = &a["curves"][a["isolated_closed_curves"][0].as_u64().unwrap() as usize];
    assert_eq!(ring["start"]["kind"], "closed");
    assert_eq!(len(&ring["splines"]), 4);
    // Each anchor ends exactly one curve.
    let anchor_ends = a["curves"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| [&c["start"], &c["end"]])
        .filter(|e| e["kind"] == "anchor")
        .count();
    assert_eq!(anchor_ends, 5);
    // Every curve stays within 1 % of the diagonal (the generator's guarantee).
    let d = a["max_distance_to_surface"].as_f64().unwrap() / a["bounding_box_diagonal"].as_f64().unwrap();
    assert!(d < 0.01, "{d}");
    assert_eq!(a["splines"], 88);
    assert_eq!(a["control_points"], 251);
}

#[test]
fn inspect_text_and_json_agree_on_the_analysis() {
    for (stage, curvenet) in [
        ("fixtures/grid/grid.usda", "/Grid/Curvenet"),
        ("fixtures/cylinder/cylinder.usda", "/Cylinder/Curvenet"),
        ("fixtures/hand/hand_1k4.usda", "/Hand/Curvenet"),
    ] {
        let v = inspect_json(stage);
        let a = &v["curvenets"][0]["analysis"];
        let text = inspect_text(stage);
        let line = summary_line(&text, curvenet);
        assert!(line.contains(&format!("against {}", a["mesh"].as_str().unwrap())), "{line}");
        assert_eq!(number_before(line, "intersections") as usize, len(&a["intersections"]), "{line}");
        assert_eq!(number_before(line, "anchors") as usize, len(&a["anchors"]), "{line}");
        assert_eq!(number_before(line, "curves,") as usize, len(&a["curves"]), "{line}");
        assert_eq!(number_before(line, "isolated closed curve") as usize, len(&a["isolated_closed_curves"]), "{line}");
        assert_eq!(number_before(line, "samples"), a["samples"].as_u64().unwrap(), "{line}");
        assert_eq!(number_before(line, "segments"), a["segments"].as_u64().unwrap(), "{line}");
        for (valence, n) in a["intersections_by_valence"].as_object().unwrap() {
            assert!(line.contains(&format!("{n} of valence {valence}")), "{line}");
        }
        // One line per intersection and per curve, with the same valences and samples.
        let intersections: Vec<&str> =
            text.lines().filter(|l| l.starts_with("  intersection at control point ")).collect();
        assert_eq!(intersections.len(), len(&a["intersections"]));
        for (l, i) in intersections.iter().zip(a["intersections"].as_array().unwrap()) {
            assert!(l.contains(&format!("control point {}: valence {},", i["point"], i["valence"])), "{l} vs {i}");
        }
        let curves: Vec<&str> = text.lines().filter(|l| l.starts_with("  curve ")).collect();
        assert_eq!(curves.len(), len(&a["curves"]));
        for (l, c) in curves.iter().zip(a["curves"].as_array().unwrap()) {
            assert!(l.contains(&format!(", {} samples, {} segments", c["samples"], c["segments"])), "{l} vs {c}");
        }
    }
}

/// A stage written for one test, in the test target's scratch directory.
fn scratch_stage(name: &str, text: &str) -> String {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-inspect");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.to_string_lossy().into_owned()
}

/// A flat 4×4-quad mesh on [−2, 2]² at z = 0 (edges of length 1), deforming `targets`.
fn plane_mesh(name: &str, targets: &[&str]) -> String {
    let mut points = Vec::new();
    for j in 0..5 {
        for i in 0..5 {
            points.push(format!("({}, {}, 0)", i - 2, j - 2));
        }
    }
    let mut indices = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            let a = i + 5 * j;
            indices.extend([a, a + 1, a + 6, a + 5].map(|x: i32| x.to_string()));
        }
    }
    let targets: Vec<String> = targets.iter().map(|t| format!("<{t}>")).collect();
    format!(
        "    def Mesh \"{name}\"\n    {{\n        rel curvenet:curvenets = [{}]\n        int[] faceVertexCounts = [{}]\n        \
         int[] faceVertexIndices = [{}]\n        point3f[] points = [{}]\n    }}\n",
        targets.join(", "),
        vec!["4"; 16].join(", "),
        indices.join(", "),
        points.join(", ")
    )
}

fn curvenet_prim(name: &str, pool: &[[f64; 3]], splines: &[[u32; 4]], extra: &str) -> String {
    let pool: Vec<String> = pool.iter().map(|p| format!("({}, {}, {})", p[0], p[1], p[2])).collect();
    let indices: Vec<String> = splines.iter().flatten().map(|i| i.to_string()).collect();
    format!(
        "    def BasisCurves \"{name}\"\n    {{\n        uniform token type = \"cubic\"\n        uniform token basis = \"bezier\"\n        \
         uniform token wrap = \"nonperiodic\"\n        int[] curveVertexCounts = [{}]\n        \
         point3f[] primvars:curvenet:cv = [{}]\n        int[] primvars:curvenet:cv:indices = [{}]\n{extra}    }}\n",
        vec!["4"; splines.len()].join(", "),
        pool.join(", "),
        indices.join(", ")
    )
}

/// A straight spline's control points from `a` to `b` (handles at 1/3, 2/3).
fn straight(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 4] {
    let at = |t: f64| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])];
    [a, at(1.0 / 3.0), at(2.0 / 3.0), b]
}

#[test]
fn a_failed_analysis_names_the_prim_exits_2_and_reports_the_other_curvenets() {
    let good = curvenet_prim("Good", &straight([-1.5, -1.0, 0.0], [1.5, -1.0, 0.0]), &[[0, 1, 2, 3]], "");
    // Splines 0 and 1 both leave the intersection at control point 0 along +x
    // (collinear, one 1 long, one 1.5 long); spline 2 leaves along +y.
    let o = [0.0, 0.0, 0.0];
    let mut pool = vec![o];
    let mut splines = Vec::new();
    for end in [[1.0, 0.0, 0.0], [1.5, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        let s = straight(o, end);
        let first = pool.len() as u32;
        pool.extend_from_slice(&s[1..]);
        splines.push([0, first, first + 1, first + 2]);
    }
    let tangents = curvenet_prim("Tangents", &pool, &splines, "");
    // Spline 1's four control points coincide.
    let mut pool = straight([-1.5, 1.5, 0.0], [1.5, 1.5, 0.0]).to_vec();
    pool.extend([[0.5, 0.5, 0.0]; 4]);
    let zero = curvenet_prim("Zero", &pool, &[[0, 1, 2, 3], [4, 5, 6, 7]], "");
    let stage = scratch_stage(
        "broken.usda",
        &format!(
            "#usda 1.0\n(\n    defaultPrim = \"S\"\n    upAxis = \"Z\"\n)\n\ndef Xform \"S\"\n{{\n{}{}{}{}}}\n",
            plane_mesh("Mesh", &["/S/Tangents", "/S/Good", "/S/Zero"]),
            tangents,
            good,
            zero
        ),
    );

    let out = curvenet(&["inspect", &stage, "--json"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("/S/Tangents: splines [0, 1] leave the intersection at control point 0"), "{stderr}");
    assert!(stderr.contains("/S/Zero: spline 1 has zero length"), "{stderr}");
    assert!(!stderr.contains("/S/Good"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the report is still printed");
    let by_path = |p: &str| v["curvenets"].as_array().unwrap().iter().find(|c| c["path"] == p).unwrap().clone();
    let t = by_path("/S/Tangents");
    assert_eq!(t["error"]["kind"], "CoincidentTangents");
    assert!(t["error"]["message"].as_str().unwrap().starts_with("/S/Tangents: "), "{t}");
    assert!(t["analysis"].is_null());
    assert_eq!(t["splines"], 3);
    let z = by_path("/S/Zero");
    assert_eq!(z["error"]["kind"], "ZeroLengthSpline");
    assert!(z["error"]["message"].as_str().unwrap().starts_with("/S/Zero: "), "{z}");
    // The good curvenet: one straight spline of length 3 between two anchors;
    // mesh edges are 1, so 5 · 3 / 1 = 15 segments and 16 samples.
    let g = by_path("/S/Good");
    assert!(g["error"].is_null(), "{g}");
    let a = &g["analysis"];
    assert_eq!(len(&a["intersections"]), 0);
    assert_eq!(a["anchors"], serde_json::json!([0, 3]));
    assert_eq!(len(&a["curves"]), 1);
    assert_eq!(a["curves"][0]["start"], serde_json::json!({"kind": "anchor", "point": 0}));
    assert_eq!(a["curves"][0]["end"], serde_json::json!({"kind": "anchor", "point": 3}));
    assert_eq!(a["segments"], 15);
    assert_eq!(a["samples"], 16);

    // The text report says the same, and the good curvenet is still analysed.
    let out = curvenet(&["inspect", &stage]);
    assert_eq!(out.status.code(), Some(2));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("  error (CoincidentTangents): /S/Tangents: splines [0, 1]"), "{text}");
    assert!(text.contains("  error (ZeroLengthSpline): /S/Zero: spline 1 has zero length"), "{text}");
    let line = summary_line(&text, "/S/Good");
    assert_eq!(number_before(line, "anchors"), 2, "{line}");
    assert_eq!(number_before(line, "segments"), 15, "{line}");

    // Selecting the good curvenet alone succeeds (its mesh is found anyway).
    let out = curvenet(&["inspect", &stage, "--prim", "/S/Good", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["curvenets"][0]["analysis"]["mesh"], "/S/Mesh");
}

#[test]
fn inspect_warns_about_suspicious_curvenets() {
    // Spline 0: 3 long on the plane (fine). Spline 1: lifted 0.6 above the
    // plane, more than 5 % of the mesh diagonal 4√2 = 5.657 (0.283). Spline 2:
    // 0.08 long, shorter than one mesh edge (1) and round(5 · 0.08) = 0 → 1
    // segment. Pool point 12 is used by no spline.
    let mut pool = Vec::new();
    for (a, b) in [
        ([-1.5, -1.0, 0.0], [1.5, -1.0, 0.0]),
        ([-1.5, 1.0, 0.6], [1.5, 1.0, 0.6]),
        ([0.0, 0.5, 0.0], [0.08, 0.5, 0.0]),
    ] {
        pool.extend(straight(a, b));
    }
    pool.push([0.0, 0.0, 0.0]);
    let splines = [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]];
    // At time 2 the posed pool has a non-finite point (control point 5).
    let mut posed: Vec<String> = pool.iter().map(|p| format!("({}, {}, {})", p[0], p[1], p[2])).collect();
    posed[5] = "(inf, 1, 0.6)".to_string();
    let samples = format!(
        "        point3f[] primvars:curvenet:cv.timeSamples = {{\n            1: [{}],\n            2: [{}],\n        }}\n",
        pool.iter().map(|p| format!("({}, {}, {})", p[0], p[1], p[2])).collect::<Vec<_>>().join(", "),
        posed.join(", ")
    );
    let stage = scratch_stage(
        "warnings.usda",
        &format!(
            "#usda 1.0\n(\n    defaultPrim = \"W\"\n    startTimeCode = 1\n    endTimeCode = 2\n    upAxis = \"Z\"\n)\n\n\
             def Xform \"W\"\n{{\n{}{}{}{}}}\n",
            plane_mesh("Mesh", &["/W/Net"]),
            plane_mesh("Other", &["/W/Net"]),
            curvenet_prim("Net", &pool, &splines, &samples),
            curvenet_prim("Orphan", &straight([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]), &[[0, 1, 2, 3]], "")
        ),
    );
    let out = curvenet(&["inspect", &stage, "--time", "2", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let w = curvenet_warnings(&v, "/W/Net");
    let has = |needle: &str| w.iter().any(|x| x.contains(needle));
    assert!(
        has("2 meshes target this curvenet (/W/Mesh, /W/Other); it is analysed against the first, /W/Mesh"),
        "{w:#?}"
    );
    assert!(has("1 control point of the pool is used by no spline: 12"), "{w:#?}");
    assert!(has("spline 1 is 0.6000 from the surface of /W/Mesh"), "{w:#?}");
    assert!(!has("spline 0 is") && !has("spline 2 is"), "{w:#?}");
    assert!(has("curve 2 (spline 2) is 0.0800 long, shorter than one mean mesh edge (1.0000)"), "{w:#?}");
    assert!(has("curve 2 (spline 2) has 1 segment"), "{w:#?}");
    assert!(!has("curve 0 ") && !has("curve 1 "), "{w:#?}");
    assert!(has("at time 2 the posed pool (primvars:curvenet:cv) has 1 non-finite control point: 5"), "{w:#?}");
    assert_eq!(w.len(), 6, "{w:#?}");
    // The per-curvenet list holds the same warnings.
    assert_eq!(
        v["curvenets"].as_array().unwrap().iter().find(|c| c["path"] == "/W/Net").unwrap()["warnings"],
        serde_json::json!(w)
    );
    let a = &v["curvenets"].as_array().unwrap().iter().find(|c| c["path"] == "/W/Net").unwrap()["analysis"];
    assert_eq!(a["unused_control_points"], serde_json::json!([12]));
    assert_eq!(a["max_distance_spline"], 1);
    // The orphan curvenet: no mesh, so no analysis, only the raw counts and a warning.
    let orphan = v["curvenets"].as_array().unwrap().iter().find(|c| c["path"] == "/W/Orphan").unwrap();
    assert!(orphan["analysis"].is_null() && orphan["error"].is_null());
    assert_eq!(orphan["splines"], 1);
    let w = curvenet_warnings(&v, "/W/Orphan");
    assert_eq!(w.len(), 1, "{w:#?}");
    assert!(w[0].contains("no deformed mesh targets this curvenet"), "{w:#?}");
    // Without --time the posed pool is not read: no non-finite warning.
    let v = inspect_json(&stage);
    assert!(!curvenet_warnings(&v, "/W/Net").iter().any(|w| w.contains("non-finite")));
}

#[test]
fn inspect_bind_reports_the_binding_of_the_hand() {
    let out = curvenet(&["inspect", "fixtures/hand/hand_1k4.usda", "--bind", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mesh = &v["meshes"][0];
    let b = &mesh["binding"];
    assert!(b["error"].is_null(), "{b}");
    let stats = &b["stats"];
    let n = |k: &str| stats[k].as_u64().unwrap_or_else(|| panic!("{k}: {stats}"));
    let vertices = mesh["vertices"].as_u64().unwrap();
    let samples = v["curvenets"][0]["analysis"]["samples"].as_u64().unwrap();
    assert_eq!(n("samples"), samples, "the binding samples the curvenet as the analysis does");
    // Every mesh vertex and every sample is a cut-vertex (a sample on a
    // vertex is one cut-vertex, so at most `vertices` fewer), plus crossings.
    assert!(n("cut_vertices") >= vertices.max(samples), "{stats}");
    assert!(n("cut_faces") > mesh["faces"].as_u64().unwrap(), "cutting splits faces: {stats}");
    assert!(n("unknowns") > 0 && n("unknowns") <= vertices, "{stats}");
    assert!(n("factor_nonzeros") >= n("unknowns"));
    assert_eq!(n("islands_removed"), 0);
    // The service's timing names (`BindingTimings`).
    let t = |k: &str| b["timings"][k].as_f64().unwrap_or_else(|| panic!("{k}: {b}"));
    for k in ["analysis_ms", "surface_ms", "cutting_ms", "assembly_ms", "factor_ms"] {
        assert!(t(k).is_finite() && t(k) >= 0.0, "{k}: {}", t(k));
    }
    let stages: f64 =
        ["analysis_ms", "surface_ms", "cutting_ms", "assembly_ms", "factor_ms"].iter().map(|k| t(k)).sum();
    assert!(t("total_ms") > 0.0 && t("total_ms") >= 0.99 * stages, "the total covers its stages: {b}");
    assert_eq!(b["warnings"], serde_json::json!([]));
    // Without --bind there is no binding in the report.
    assert!(inspect_json("fixtures/hand/hand_1k4.usda")["meshes"][0].get("binding").is_none());

    let out = curvenet(&["inspect", "fixtures/hand/hand_1k4.usda", "--bind"]);
    let text = String::from_utf8(out.stdout).unwrap();
    let line = text.lines().find(|l| l.contains("cut-vertices")).unwrap_or_else(|| panic!("{text}"));
    assert_eq!(number_before(line, "cut-vertices"), n("cut_vertices"), "{line}");
    assert!(text.contains("binding time:"), "{text}");
}

#[test]
fn inspect_bind_reports_a_failed_binding_naming_the_mesh_and_exits_2() {
    // A curvenet hovering 3 above a 4 x 4 plane (more than half the diagonal away).
    let far = curvenet_prim("Far", &straight([-1.5, 0.5, 3.0], [1.5, 0.5, 3.0]), &[[0, 1, 2, 3]], "");
    let stage = scratch_stage(
        "far.usda",
        &format!("#usda 1.0\ndef Xform \"Root\"\n{{\n{}{far}}}\n", plane_mesh("Plane", &["/Root/Far"])),
    );
    let out = curvenet(&["inspect", &stage, "--bind", "--json"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let error = v["meshes"][0]["binding"]["error"].as_str().unwrap_or_else(|| panic!("{v}"));
    assert!(error.contains("/Root/Plane") || error.contains("/Root/Far"), "{error}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(error), "{err}");
}
