//! Curvenet Adjustments through the command line: `curvenet bake` of the
//! adjusted shot (fixtures/shots/hand_adjusted) read back with usd-core
//! composed over its input equals an in-process solve, and `curvenet
//! inspect` lists the adjustments.

use std::path::Path;
use std::process::Command;

use curvenet_core::{Adjustment, CurvenetInput, Deformer, DeformerInput, Frame};
use curvenet_schema::usd::Stage;
use curvenet_schema::{AdjustmentData, MeshData};

#[allow(dead_code)] // the helpers this file does not use
mod common;
use common::{curvenet, repo, stderr};

const ADJUSTED: &str = "fixtures/shots/hand_adjusted/shot.usda";

/// The adjusted shot read and bound in-process through core's `Deformer`,
/// independently of the bake's stage handling.
struct Reference {
    stage: Stage,
    mesh: MeshData,
    adjustments: Vec<Vec<AdjustmentData>>,
    deformer: Deformer,
}

impl Reference {
    fn new(input: &Path) -> Self {
        let stage = Stage::open(input).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let nets: Vec<_> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let curvenets: Vec<CurvenetInput> = nets.iter().map(curvenet_schema::CurvenetData::input).collect();
        let deformer = Deformer::new(&DeformerInput { ..curvenet_schema::deformer_input(&mesh, &curvenets) }).unwrap();
        let adjustments = nets.iter().map(|n| stage.curvenet_adjustments(n).unwrap()).collect();
        Self { stage, mesh, adjustments, deformer }
    }

    /// Frame `t` with the stage's adjustments (`adjusted`) or without.
    fn deform(&self, t: f64, adjusted: bool) -> Vec<[f64; 3]> {
        let rest = self.stage.rest_points(&self.mesh, Some(t)).unwrap();
        let adjustments: Vec<Adjustment> = match adjusted {
            true => self.stage.adjustments_at(&self.adjustments, Some(t)).unwrap(),
            false => Vec::new(),
        };
        let mut out = vec![[0.0; 3]; self.deformer.n_vertices()];
        let frame = Frame { posed: &[None], rest: Some(&rest), adjustments: &adjustments, ..Default::default() };
        self.deformer.frame(&frame, &mut out, None).unwrap();
        out
    }
}

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}

/// usd-core (from `.venv`) composes `bake` over `input` and reads
/// `/Hand/Mesh.points` at `frames`.
fn usd_core_points(bake: &Path, input: &Path, frames: &[f64]) -> Vec<Vec<[f64; 3]>> {
    let python = repo().join(".venv/bin/python");
    assert!(python.exists(), "{} is missing: run scripts/python-env (scripts/test does)", python.display());
    let script = r#"
import json, sys
from pxr import Sdf, Usd, UsdGeom
root = Sdf.Layer.CreateAnonymous(".usda")
root.subLayerPaths = [sys.argv[1], sys.argv[2]]
stage = Usd.Stage.Open(root)
points = UsdGeom.Mesh(stage.GetPrimAtPath("/Hand/Mesh")).GetPointsAttr()
print(json.dumps([[list(p) for p in points.Get(t)] for t in json.loads(sys.argv[3])]))
"#;
    let frames = serde_json::to_string(frames).unwrap();
    let out = Command::new(python)
        .args(["-c", script, bake.to_str().unwrap(), input.to_str().unwrap(), &frames])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn the_bake_of_the_adjusted_shot_read_back_by_usd_core_is_the_in_process_solve() {
    let dir = common::temp_dir("adjust", "bake");
    let input = repo().join(ADJUSTED);
    let reference = Reference::new(&input);
    assert_eq!(reference.adjustments[0].len(), 4, "the shot adjusts four knots");
    let diagonal = curvenet_core::bounding_box_diagonal(&reference.mesh.projection_points);
    // The adjustments are identity at frame 1 and largest at frame 12.
    let first = reference.deform(1.0, true);
    assert_eq!(first, reference.deform(1.0, false), "frame 1 adjusts nothing");
    let effect = max_diff(&reference.deform(12.0, true), &reference.deform(12.0, false));
    eprintln!("the adjustments move the skinned hand by up to {:.2e} x diagonal at frame 12", effect / diagonal);
    assert!(effect > 5e-3 * diagonal, "the adjustments hardly move the mesh ({effect:e})");

    let frames = [1.0, 4.0, 6.0, 9.0, 12.0];
    for ext in ["usdc", "usda"] {
        let out = dir.join(format!("adjusted.bake.{ext}"));
        let run = curvenet(&["bake", ADJUSTED, "--out", out.to_str().unwrap(), "--quiet"]);
        assert!(run.status.success(), "{}", stderr(&run));
        let mut worst = 0.0f64;
        for (t, points) in frames.iter().zip(usd_core_points(&out, &input, &frames)) {
            // float32 output: within a few ulps of the f64 solve.
            let d = max_diff(&points, &reference.deform(*t, true));
            worst = worst.max(d);
            assert!(d <= 1e-6 * diagonal, "{ext}, frame {t}: usd-core reads {:e} of the diagonal away", d / diagonal);
        }
        eprintln!("{ext}: usd-core reads the bake within {:.2e} x diagonal of the in-process solve", worst / diagonal);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn inspect_lists_the_adjustments_with_their_values() {
    let out = curvenet(&["inspect", ADJUSTED, "--json", "--time", "6"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let list = v["curvenets"][0]["adjustments"].as_array().expect("adjustments");
    // fixtures/README.md: IndexPipDorsal (an intersection), WristDorsal (the
    // wrist ring), MiddleAnchor (an anchor), PalmMiddle (pass-through).
    let kinds: Vec<(&str, &str)> =
        list.iter().map(|a| (a["path"].as_str().unwrap(), a["knot_kind"].as_str().unwrap())).collect();
    assert_eq!(
        kinds,
        [
            ("/Hand/Curvenet/IndexPipDorsal", "intersection"),
            ("/Hand/Curvenet/WristDorsal", "pass-through"),
            ("/Hand/Curvenet/MiddleAnchor", "anchor"),
            ("/Hand/Curvenet/PalmMiddle", "pass-through"),
        ]
    );
    let pip = &list[0];
    assert_eq!(pip["valence"], 4);
    assert_eq!(pip["tangents"].as_array().unwrap().len(), 4);
    assert_eq!(pip["attributes"]["xformOp:translate"], 3, "three keys");
    // Frame 6 is the translate's middle key, (0, 0.003, -0.004).
    assert_eq!(pip["values"]["translate"], serde_json::json!([0.0, 0.003, -0.004]));
    assert_eq!(list[2]["attach_tangents"], false);
    assert_eq!(list[3]["attach_tangents"], true, "not authored: attached");
    assert!(list[1]["values"]["quaternion_wxyz"].is_array());

    let out = curvenet(&["inspect", ADJUSTED]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("adjustment /Hand/Curvenet/IndexPipDorsal: knot 41 (intersection, valence 4), tangents attached"),
        "{text}"
    );
    assert!(text.contains("xformOp:translate (3 time samples)"), "{text}");
}
