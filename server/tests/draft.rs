//! `curvenet draft` as a TD runs it: the layer it writes composes over the
//! input with the curvenet bound to the mesh, `inspect` reads and binds it,
//! `--json` gives the same curvenet, the same options write the same bytes,
//! and bad input exits 2 (75 for an output directory that is missing).

#[allow(dead_code)] // the helpers the bake and stitch tests share; this file needs fewer
mod common;

use common::{curvenet, stderr, temp_dir};

const CYLINDER: &str = "fixtures/cylinder/cylinder.usda";

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", stderr(out));
    serde_json::from_slice(&out.stdout).expect("one JSON document")
}

fn len(v: &serde_json::Value) -> usize {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).len()
}

#[test]
fn the_layer_binds_the_drafted_curvenet_to_the_mesh() {
    let dir = temp_dir("draft", "layer");
    let out = dir.join("cylinder.draft.usda");
    let args = ["--rings", "5", "--lines", "3", "--offset", "0.01"];
    let run = curvenet(&[&["draft", CYLINDER, "--out", out.to_str().unwrap(), "--json"][..], &args].concat());
    let drafted = json(&run);
    // The cylinder stage already has /Cylinder/Curvenet: the draft takes the next free name.
    assert_eq!(drafted["mesh"], "/Cylinder/Mesh");
    assert_eq!(drafted["curvenet"], "/Cylinder/Curvenet1");
    let (n_pool, n_splines) = (len(&drafted["pool"]), len(&drafted["splines"]));
    // Rings around the cylinder's axis and 3 lines: each line plane cuts each
    // ring twice, the 3 inner rings are crossed (valence 4), the end rings
    // end the lines (T-junctions).
    assert_eq!(drafted["report"]["intersections"], 2 * 3 * 3);
    assert_eq!(drafted["report"]["t_junctions"], 2 * 3 * 2);

    // The layer sublayers the input (relative to the layer's directory, or
    // absolute) and binds only the new curvenet.
    let text = std::fs::read_to_string(&out).unwrap();
    let sublayer = text.split("subLayers = [@").nth(1).and_then(|t| t.split("@]").next()).expect("one sublayer");
    let resolved = std::fs::canonicalize(out.parent().unwrap().join(sublayer)).unwrap();
    assert_eq!(resolved, std::fs::canonicalize(common::repo().join(CYLINDER)).unwrap());
    let report = json(&curvenet(&["inspect", out.to_str().unwrap(), "--json"]));
    let mesh = &report["meshes"][0];
    assert_eq!(mesh["path"], "/Cylinder/Mesh");
    assert_eq!(mesh["curvenets"], serde_json::json!(["/Cylinder/Curvenet1"]));
    let net = report["curvenets"].as_array().unwrap().iter().find(|c| c["path"] == "/Cylinder/Curvenet1").unwrap();
    assert_eq!(net["control_points"], n_pool);
    assert_eq!(net["splines"], n_splines);
    // It binds as the bake binds.
    let bound = curvenet(&["inspect", out.to_str().unwrap(), "--bind", "--prim", "/Cylinder/Mesh"]);
    assert!(bound.status.success(), "{}", stderr(&bound));

    // The same draft writes the same bytes.
    let again = dir.join("again.usda");
    let run = curvenet(&[&["draft", CYLINDER, "--out", again.to_str().unwrap()][..], &args].concat());
    assert!(run.status.success(), "{}", stderr(&run));
    let text_again = std::fs::read_to_string(&again).unwrap();
    assert_eq!(
        text.replace("cylinder.draft.usda", "again.usda"),
        text_again.replace("cylinder.draft.usda", "again.usda")
    );
    // Beside the input (in the same tree), the sublayer path is relative.
    let near = common::repo().join("target").join(format!("curvenet-draft-test-{}", std::process::id()));
    std::fs::create_dir_all(&near).unwrap();
    let run =
        curvenet(&["draft", CYLINDER, "--out", near.join("d.usda").to_str().unwrap(), "--rings", "3", "--lines", "0"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let text = std::fs::read_to_string(near.join("d.usda")).unwrap();
    assert!(text.contains("subLayers = [@../../fixtures/cylinder/cylinder.usda@]"), "{}", &text[..text.len().min(400)]);
    let _ = std::fs::remove_dir_all(&near);
    // A seed gives another draft.
    let seeded = json(&curvenet(&[&["draft", CYLINDER, "--json", "--seed", "3"][..], &args].concat()));
    assert_ne!(seeded["pool"], drafted["pool"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn usdc_output_and_json_only() {
    let dir = temp_dir("draft", "usdc");
    let out = dir.join("d.usdc");
    let run = curvenet(&["draft", CYLINDER, "--out", out.to_str().unwrap(), "--rings", "3", "--lines", "0"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let text = String::from_utf8(run.stdout).unwrap();
    assert!(
        text.contains("drafted /Cylinder/Curvenet1 on /Cylinder/Mesh") && text.contains("3 isolated loops"),
        "{text}"
    );
    let report = json(&curvenet(&["inspect", out.to_str().unwrap(), "--json", "--prim", "/Cylinder/Curvenet1"]));
    // Three isolated rings of four splines each.
    assert_eq!(report["curvenets"][0]["splines"], 12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_exits_2_and_a_missing_directory_75() {
    let dir = temp_dir("draft", "errors");
    let expect = |args: &[&str], code: i32, words: &[&str]| {
        let run = curvenet(args);
        let err = stderr(&run);
        assert_eq!(run.status.code(), Some(code), "{args:?}: {err}");
        for w in words {
            assert!(err.contains(w), "{args:?}: {w:?} not in {err}");
        }
    };
    expect(&["draft", CYLINDER], 2, &["--out", "--json"]);
    expect(&["draft", CYLINDER, "--json", "--mesh", "/Nope"], 2, &["/Nope"]);
    expect(&["draft", CYLINDER, "--json", "--mesh", "/Cylinder/Curvenet"], 2, &["/Cylinder/Curvenet", "Mesh"]);
    expect(&["draft", CYLINDER, "--json", "--offset", "0.5"], 2, &["offset"]);
    expect(&["draft", CYLINDER, "--json", "--rings", "1"], 2, &["rings"]);
    expect(&["draft", CYLINDER, "--json", "--axis", "1,2"], 2, &["X,Y,Z"]);
    expect(&["draft", CYLINDER, "--json", "--span", "0.9,0.1"], 2, &["span"]);
    expect(&["draft", "fixtures/nope.usda", "--json"], 2, &["nope.usda"]);
    expect(&["draft", CYLINDER, "--out", "out.txt"], 2, &["out.txt", ".usda"]);
    expect(&["draft", CYLINDER, "--out", CYLINDER], 2, &["must not be the input"]);
    let missing = dir.join("no/such/dir/d.usda");
    expect(&["draft", CYLINDER, "--out", missing.to_str().unwrap()], 75, &["no/such/dir"]);
    // A stage with two meshes needs --mesh, and the message lists them.
    let two = dir.join("two.usda");
    std::fs::write(
        &two,
        "#usda 1.0\ndef Mesh \"A\" {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n \
         point3f[] points = [(0,0,0), (1,0,0), (0,1,0)]\n}\ndef Mesh \"B\" {\n int[] faceVertexCounts = [3]\n \
         int[] faceVertexIndices = [0, 1, 2]\n point3f[] points = [(0,0,0), (1,0,0), (0,1,0)]\n}\n",
    )
    .unwrap();
    expect(&["draft", two.to_str().unwrap(), "--json"], 2, &["/A", "/B", "--mesh"]);
    let _ = std::fs::remove_dir_all(&dir);
}
