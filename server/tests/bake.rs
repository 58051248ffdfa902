//! `curvenet bake` as a farm runs it: the binary on the shipped shot, its
//! output read back (composed over the input) and compared with an
//! in-process solve through the same binding code path.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use curvenet_core::BlendShape;
use curvenet_core::{CurvenetInput, Deformer, DeformerInput, Frame};
use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};

mod common;
use common::{SHOT, curvenet, repo, stderr};

/// A fresh, empty directory for one test.
fn temp_dir(tag: &str) -> PathBuf {
    common::temp_dir("bake", tag)
}

fn bake(input: &str, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["bake", input, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    curvenet(&args)
}

fn dir_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A root layer composing `layers` (strongest first), written beside them.
fn compose(dir: &Path, name: &str, layers: &[&Path]) -> Stage {
    let subs: Vec<String> = layers.iter().map(|p| format!("@{}@", p.display())).collect();
    let root = dir.join(name);
    std::fs::write(&root, format!("#usda 1.0\n(\n    subLayers = [{}]\n)\n", subs.join(", "))).unwrap();
    Stage::open(&root).unwrap_or_else(|e| panic!("{e}"))
}

/// The shot's mesh bound as `curvenet bake` binds it.
struct Reference {
    stage: Stage,
    mesh: MeshData,
    nets: Vec<CurvenetData>,
    deformer: Deformer,
}

impl Reference {
    fn new(input: &Path) -> Self {
        let stage = Stage::open(input).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let nets: Vec<CurvenetData> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
        let n = mesh.projection_points.len();
        let blend_shapes = mesh
            .blend_shapes
            .iter()
            .map(|s| {
                let ib = s.inbetweens.iter().map(|i| (i.weight, i.offsets.clone())).collect();
                BlendShape::new(n, s.offsets.clone(), s.point_indices.clone(), ib).unwrap()
            })
            .collect();
        let curvenets: Vec<CurvenetInput> = nets.iter().map(curvenet_schema::CurvenetData::input).collect();
        let deformer =
            Deformer::new(&DeformerInput { blend_shapes, ..curvenet_schema::deformer_input(&mesh, &curvenets) })
                .unwrap();
        Self { stage, mesh, nets, deformer }
    }

    /// The frame as the core deforms it: posed pools, the rest pose when the
    /// mesh animates it, blend shapes after the deformation.
    fn deform(&self, t: f64) -> Vec<[f64; 3]> {
        let pools: Vec<Option<Vec<[f64; 3]>>> =
            self.nets.iter().map(|n| self.stage.posed_pool(n, Some(t)).unwrap()).collect();
        let posed: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| p.as_deref()).collect();
        let rest =
            (!self.mesh.rest_sample_times.is_empty()).then(|| self.stage.rest_points(&self.mesh, Some(t)).unwrap());
        let weights = self.stage.blend_shape_weights(&self.mesh, Some(t)).unwrap();
        let mut out = vec![[0.0; 3]; self.deformer.n_vertices()];
        let frame =
            Frame { posed: &posed, rest: rest.as_deref(), blend_shape_weights: Some(&weights), ..Default::default() };
        self.deformer.frame(&frame, &mut out, None).unwrap();
        out
    }
}

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |i| (p[i] - q[i]).abs())).fold(0.0, f64::max)
}

#[test]
fn bakes_the_shot_to_usda_and_usdc_matching_an_in_process_solve() {
    let dir = temp_dir("shot");
    let input = repo().join(SHOT);
    let usda = dir.join("bake.usda");
    let usdc = dir.join("bake.usdc");
    for out in [&usda, &usdc] {
        let run = bake(SHOT, out, &["--frames", "1-24"]);
        assert!(run.status.success(), "{}", stderr(&run));
        // Not a terminal: no progress, one summary line naming the output.
        let err = stderr(&run);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains("1 mesh") && err.contains("24 frames") && err.contains(out.to_str().unwrap()), "{err}");
    }
    assert_eq!(dir_names(&dir), ["bake.usda", "bake.usdc"], "temporary files left behind");

    // Idempotent: the same bake writes the same bytes.
    for out in [&usda, &usdc] {
        let first = std::fs::read(out).unwrap();
        let run = bake(SHOT, out, &["--frames", "1-24", "--quiet", "--threads", "3"]);
        assert!(run.status.success(), "{}", stderr(&run));
        assert!(run.stderr.is_empty(), "--quiet printed {}", stderr(&run));
        assert_eq!(first, std::fs::read(out).unwrap(), "{}: a second bake wrote different bytes", out.display());
    }

    // The text layer: over opinions and points only.
    let text = std::fs::read_to_string(&usda).unwrap();
    assert!(text.contains("over \"Hand\"") && text.contains("over \"Mesh\""), "{}", &text[..text.len().min(2000)]);
    // (The layer's doc string, in its header, may name anything.)
    let body = text.split_once("\n)\n").expect("a layer header").1;
    for absent in ["def ", "faceVertex", "curvenet", "primvars", "extent", "skel"] {
        assert!(!body.contains(absent), "the bake layer holds {absent:?}");
    }
    assert_eq!(body.matches("over ").count(), 2, "{}", &body[..body.len().min(500)]);
    assert!(text.contains("startTimeCode = 1") && text.contains("endTimeCode = 24"));

    // Composed over the input, both files give the in-process solve's points.
    let reference = Reference::new(&input);
    let composed_a = compose(&dir, "over_a.usda", &[&usda, &input]);
    let composed_c = compose(&dir, "over_c.usda", &[&usdc, &input]);
    let mesh_a = composed_a.deformed_meshes().unwrap().remove(0);
    let mesh_c = composed_c.deformed_meshes().unwrap().remove(0);
    assert_eq!(mesh_a.rest_sample_times, (1..=24).map(f64::from).collect::<Vec<_>>());
    // Composition changes nothing but the points.
    assert_eq!(mesh_a.face_vertex_indices, reference.mesh.face_vertex_indices);
    assert_eq!(mesh_a.curvenets, reference.mesh.curvenets);
    assert_eq!(composed_a.curvenet("/Hand/Curvenet").unwrap(), reference.nets[0]);
    let diagonal = curvenet_core::bounding_box_diagonal(&reference.mesh.projection_points);
    let mut moved = 0.0f64;
    for t in [1.0, 7.0, 13.0, 24.0] {
        let want = reference.deform(t);
        let a = composed_a.rest_points(&mesh_a, Some(t)).unwrap();
        let c = composed_c.rest_points(&mesh_c, Some(t)).unwrap();
        assert_eq!(a, c, "frame {t}: .usda and .usdc disagree");
        let d = max_diff(&a, &want);
        assert!(d <= 1e-6, "frame {t}: baked points differ from the in-process solve by {d:e}");
        moved = moved.max(max_diff(&a, &reference.mesh.projection_points));
        if t == 1.0 {
            let d = max_diff(&a, &reference.mesh.projection_points);
            assert!(d <= 1e-5 * diagonal, "frame 1 (neutral) moved the mesh by {d:e}");
        }
    }
    assert!(moved > 0.01 * diagonal, "the curl did not move the mesh ({moved:e})");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_frame_range_bakes_exactly_those_frames() {
    let dir = temp_dir("range");
    let out = dir.join("part.usda");
    let run = bake(SHOT, &out, &["--frames", "5-7"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("startTimeCode = 5") && text.contains("endTimeCode = 7"));
    let composed = compose(&dir, "root.usda", &[&out, &repo().join(SHOT)]);
    let mesh = composed.deformed_meshes().unwrap().remove(0);
    assert_eq!(mesh.rest_sample_times, [5.0, 6.0, 7.0]);
    assert!(!stderr(&run).contains("warning"), "{}", stderr(&run));
    // A single frame.
    let run = bake(SHOT, &out, &["--frames", "9"]);
    assert!(run.status.success(), "{}", stderr(&run));
    // Past the shot's end (1 .. 24): baked (USD holds the last samples), with a warning naming both ranges.
    let run = bake(SHOT, &dir.join("late.usda"), &["--frames", "23-26", "--quiet"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(err.contains("warning") && err.contains("23-26") && err.contains("endTimeCode 24"), "{err}");
    let composed = compose(&dir, "root.usda", &[&out, &repo().join(SHOT)]);
    assert_eq!(composed.deformed_meshes().unwrap()[0].rest_sample_times, [9.0]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_commands_exit_2_and_a_missing_output_directory_exits_75() {
    let dir = temp_dir("bad");
    let run = bake(SHOT, &dir.join("x.usda"), &["--frames", "7-5"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("7-5"), "{}", stderr(&run));
    let run = bake(SHOT, &dir.join("x.usda"), &["--frames", "one-two"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let run = bake(SHOT, &dir.join("x.obj"), &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains(".usda or .usdc"), "{}", stderr(&run));
    let run = bake("fixtures/nope.usda", &dir.join("x.usda"), &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("nope.usda"), "{}", stderr(&run));
    // A stage without a frame range or time samples needs --frames.
    let run = bake("fixtures/hand/hand_1k4.usda", &dir.join("x.usda"), &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("--frames"), "{}", stderr(&run));
    // Documented in --help: a missing output directory is an I/O failure (75), found before any work.
    let missing = dir.join("no/such/dir/x.usda");
    let run = bake(SHOT, &missing, &[]);
    assert_eq!(run.status.code(), Some(75), "{}", stderr(&run));
    assert!(stderr(&run).contains("no/such/dir"), "{}", stderr(&run));
    assert_eq!(dir_names(&dir), Vec::<String>::new());
    // Outputs that can never be written are bad input (2), before any work:
    // a directory, a path naming one, a file where a directory must be.
    std::fs::create_dir_all(dir.join("d.usda")).unwrap();
    std::fs::write(dir.join("afile"), "").unwrap();
    for out in [dir.join("d.usda"), dir.join("x.usda/"), dir.join("afile/x.usda")] {
        let run = bake(SHOT, &out, &[]);
        assert_eq!(run.status.code(), Some(2), "{}: {}", out.display(), stderr(&run));
        assert!(stderr(&run).contains(out.parent().unwrap().to_str().unwrap()), "{}", stderr(&run));
    }
    assert_eq!(dir_names(&dir), ["afile", "d.usda"]);
    // A layer the stage reads is never replaced: the shot's animation
    // sublayer, the mesh layer (copies, so a failure harms no fixture).
    let shot_dir = common::copy_shot(&dir);
    let before: Vec<Vec<u8>> =
        ["anim.usda", "hand_1k4.usda"].iter().map(|f| std::fs::read(shot_dir.join(f)).unwrap()).collect();
    for (i, f) in ["anim.usda", "hand_1k4.usda"].iter().enumerate() {
        let run = bake(shot_dir.join("shot.usda").to_str().unwrap(), &shot_dir.join(f), &["--frames", "1-2"]);
        assert_eq!(run.status.code(), Some(2), "{f}: {}", stderr(&run));
        assert!(stderr(&run).contains("a layer of the stage"), "{}", stderr(&run));
        assert_eq!(std::fs::read(shot_dir.join(f)).unwrap(), before[i], "{f} changed");
    }
    std::fs::remove_dir_all(&shot_dir).unwrap();
    std::fs::remove_dir(dir.join("d.usda")).unwrap();
    std::fs::remove_file(dir.join("afile")).unwrap();
    let help = String::from_utf8(curvenet(&["bake", "--help"]).stdout).unwrap();
    assert!(help.contains("75") && help.contains("does not exist"), "{help}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// fixtures/grid's shot with its curvenet's frames 1-4 as in the grid
/// (samples of a stronger layer replace all of the weaker layer's), each
/// pool first passed to `edit(frame, pool)`; written into `dir`.
fn grid_shot(dir: &Path, edit: impl Fn(u32, &mut Vec<[f64; 3]>)) -> PathBuf {
    let grid = repo().join("fixtures/grid/grid.usda");
    let stage = Stage::open(&grid).unwrap();
    let net = stage.curvenet("/Grid/Curvenet").unwrap();
    let mut samples = Vec::new();
    for t in 1..=4 {
        let mut pool = stage.posed_pool(&net, Some(t as f64)).unwrap().unwrap();
        edit(t, &mut pool);
        let points: Vec<String> = pool
            .iter()
            .map(|p| {
                let c: Vec<String> =
                    p.iter().map(|&x| if x.is_nan() { "nan".into() } else { format!("{:?}", x as f32) }).collect();
                format!("({})", c.join(", "))
            })
            .collect();
        samples.push(format!("            {t}: [{}],", points.join(", ")));
    }
    let over = format!(
        "#usda 1.0\n\nover \"Grid\"\n{{\n    over \"Curvenet\"\n    {{\n        point3f[] primvars:curvenet:cv.timeSamples = {{\n{}\n        }}\n    }}\n}}\n",
        samples.join("\n")
    );
    std::fs::write(dir.join("over.usda"), over).unwrap();
    let shot = dir.join("shot.usda");
    std::fs::write(
        &shot,
        format!(
            "#usda 1.0\n(\n    startTimeCode = 1\n    endTimeCode = 4\n    subLayers = [@./over.usda@, @{}@]\n)\n",
            grid.display()
        ),
    )
    .unwrap();
    shot
}

#[test]
fn a_collapsed_curvenet_fails_the_bake_naming_frame_and_curvenet() {
    let dir = temp_dir("collapsed");
    let shot = grid_shot(&dir, |t, pool| {
        if t == 3 {
            let p = pool[0];
            pool.iter_mut().for_each(|x| *x = p);
        }
    });
    for k in ["1", "4"] {
        let run = bake(shot.to_str().unwrap(), &dir.join("bake.usdc"), &["--batch-frames", k]);
        assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
        let err = stderr(&run);
        assert!(err.contains("frame 3, /Grid/Curvenet (deforming /Grid/"), "--batch-frames {k}: {err}");
        assert!(err.contains("collapsed"), "--batch-frames {k}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_non_finite_control_point_fails_the_bake_naming_frame_and_prim_and_writes_nothing() {
    let dir = temp_dir("nan");
    // One NaN at frame 3.
    let shot = grid_shot(&dir, |t, pool| {
        if t == 3 {
            pool[17][1] = f64::NAN;
        }
    });
    let out_dir = dir.join("out");
    std::fs::create_dir(&out_dir).unwrap();
    for name in ["bake.usda", "bake.usdc"] {
        let run = bake(shot.to_str().unwrap(), &out_dir.join(name), &[]);
        assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
        let err = stderr(&run);
        assert!(err.contains("frame 3, /Grid/Curvenet:") && err.contains("control point 17"), "{err}");
        assert_eq!(dir_names(&out_dir), Vec::<String>::new(), "a failed bake left files");
    }
    // An existing output is left as it was.
    let keep = out_dir.join("keep.usda");
    std::fs::write(&keep, "previous").unwrap();
    let run = bake(shot.to_str().unwrap(), &keep, &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert_eq!(std::fs::read_to_string(&keep).unwrap(), "previous");
    assert_eq!(dir_names(&out_dir), ["keep.usda"]);
    std::fs::remove_file(&keep).unwrap();
    // Frames before the bad one still bake.
    let run = bake(shot.to_str().unwrap(), &out_dir.join("ok.usda"), &["--frames", "1-2"]);
    assert!(run.status.success(), "{}", stderr(&run));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_control_point_beyond_1e15_fails_the_bake_as_the_service_refuses_it() {
    // Finite in f32, but beyond the service's MAX_COORDINATE (hostile review F3).
    let dir = temp_dir("huge");
    let shot = grid_shot(&dir, |t, pool| {
        if t == 2 {
            pool[5][0] = -3.0e20;
            pool[9][2] = 2.0e16;
        }
    });
    let run = bake(shot.to_str().unwrap(), &dir.join("bake.usdc"), &[]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(err.contains("frame 2, /Grid/Curvenet:") && err.contains("control point 5"), "{err}");
    assert!(err.contains("beyond 1e15 in magnitude (2 such control points in all)"), "{err}");
    assert!(!dir.join("bake.usdc").exists(), "a failed bake wrote its output");
    // At the bound the frame reaches the core, which finds the curves there
    // degenerate (as the service would).
    let shot = grid_shot(&dir, |t, pool| {
        if t == 2 {
            pool[5][0] = -1.0e15;
        }
    });
    let run = bake(shot.to_str().unwrap(), &dir.join("bake.usdc"), &["--frames", "1-2"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(!err.contains("beyond") && err.contains("collinear"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The hand_wave shot under an over layer on /Hand (its body given).
fn wave_over(dir: &Path, body: &str) -> PathBuf {
    std::fs::write(dir.join("over.usda"), format!("#usda 1.0\n\nover \"Hand\"\n{{\n{body}\n}}\n")).unwrap();
    let shot = dir.join("shot.usda");
    let wave = repo().join(SHOT);
    let text = format!(
        "#usda 1.0\n(\n    startTimeCode = 1\n    endTimeCode = 24\n    subLayers = [@./over.usda@, @{}@]\n)\n",
        wave.display()
    );
    std::fs::write(&shot, text).unwrap();
    shot
}

#[test]
fn a_blend_shape_weight_beyond_1e6_fails_the_bake_as_the_service_refuses_it() {
    // Hostile review (tenth session): a weight of 3e38 wrote inf points with exit 0.
    let dir = temp_dir("weight");
    let weights = "    over \"Skel\"\n    {\n        over \"Anim\"\n        {\n            float[] blendShapeWeights.timeSamples = {\n                9: [0.5],\n                10: [1e7],\n            }\n        }\n    }";
    let shot = wave_over(&dir, weights);
    let out = dir.join("bake.usdc");
    let run = bake(shot.to_str().unwrap(), &out, &["--frames", "9-10"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(err.contains("frame 10, /Hand/Mesh: skel:blendShapeWeights weight 0 is 10000000"), "{err}");
    assert!(!out.exists(), "a failed bake wrote its output");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_frame_deformed_past_f32_fails_the_bake_and_writes_nothing() {
    // Weight 1e6 (allowed) times offsets of 1e33 (the bake does not bound a
    // blend shape's offsets) is past f32's largest value: refused, not
    // written as inf.
    let dir = temp_dir("overflow");
    let offsets = vec!["(1e33, 0, 0)"; 23].join(", ");
    let body = format!(
        "    over \"Mesh\"\n    {{\n        over \"Bulge\"\n        {{\n            uniform vector3f[] offsets = [{offsets}]\n        }}\n    }}\n    over \"Skel\"\n    {{\n        over \"Anim\"\n        {{\n            float[] blendShapeWeights.timeSamples = {{\n                9: [0],\n                10: [1e6],\n            }}\n        }}\n    }}"
    );
    let shot = wave_over(&dir, &body);
    let out = dir.join("bake.usda");
    let run = bake(shot.to_str().unwrap(), &out, &["--frames", "9-10"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(err.contains("frame 10, /Hand/Mesh: deformed point ") && err.contains("not finite in f32"), "{err}");
    assert!(!out.exists(), "a failed bake wrote its output");
    // Offsets of 1e12 at weight 1e6 fit in f32 but are beyond the 1e15 the
    // bake accepts as input: refused too (the bake could not read them back).
    let body = body.replace("1e33", "1e12");
    let shot = wave_over(&dir, &body);
    let run = bake(shot.to_str().unwrap(), &out, &["--frames", "9-10"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(err.contains("frame 10, /Hand/Mesh: deformed point ") && err.contains("beyond 1e15"), "{err}");
    assert!(!out.exists(), "a failed bake wrote its output");
    // Frame 9 (weight 0) alone bakes.
    let run = bake(shot.to_str().unwrap(), &out, &["--frames", "9"]);
    assert!(run.status.success(), "{}", stderr(&run));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_output_may_not_replace_the_input() {
    let run = bake(SHOT, &repo().join(SHOT), &["--frames", "1"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("replace the input"), "{}", stderr(&run));
}

#[test]
fn a_skinned_rest_pose_with_a_tracking_curvenet_bakes_to_the_rest_pose() {
    // hand_skinned: the rest pose is linear blend skinning (index finger bent
    // 115 degrees, wrist turned 15), the curvenet has no time samples, so its
    // knots track the rest pose and the output is the rest pose (issue #6).
    let dir = temp_dir("rest");
    let out = dir.join("bake.usdc");
    let shot = repo().join("fixtures/shots/hand_skinned/shot.usda");
    let run = bake(shot.to_str().unwrap(), &out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let composed = compose(&dir, "root.usda", &[&out, &shot]);
    let mesh = composed.deformed_meshes().unwrap().remove(0);
    assert_eq!(mesh.rest_sample_times, (1..=12).map(f64::from).collect::<Vec<_>>());
    let input = Stage::open(&shot).unwrap();
    let input_mesh = input.deformed_meshes().unwrap().remove(0);
    let reference = Reference::new(&shot);
    let diagonal = curvenet_core::bounding_box_diagonal(&input_mesh.projection_points);
    let mut largest_motion = 0.0f64;
    for t in [1.0, 6.0, 12.0] {
        let rest = input.rest_points(&input_mesh, Some(t)).unwrap();
        let baked = composed.rest_points(&mesh, Some(t)).unwrap();
        // f32 output: 1e-6 of the diagonal is a few float32 ulps.
        let d = max_diff(&baked, &rest);
        assert!(
            d <= 1e-6 * diagonal,
            "frame {t}: the output is {:e} of the diagonal away from the rest pose",
            d / diagonal
        );
        let d = max_diff(&baked, &reference.deform(t));
        assert!(d <= 1e-6 * diagonal, "frame {t}: the bake differs from the in-process solve by {d:e}");
        largest_motion = largest_motion.max(max_diff(&rest, &input_mesh.projection_points));
    }
    assert!(largest_motion > 0.1 * diagonal, "the skinned rest pose hardly moves ({largest_motion:e})");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// usd-core (the reference implementation, from `.venv`) composes the bake
/// over its input and reads `/Hand/Mesh.points` at `frames`.
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
fn usd_core_reads_the_bake_composed_over_its_input_as_the_in_process_solve() {
    let dir = temp_dir("usd-core");
    for shot in ["fixtures/shots/hand_wave/shot.usda", "fixtures/shots/hand_skinned/shot.usda"] {
        let input = repo().join(shot);
        let reference = Reference::new(&input);
        let diagonal = curvenet_core::bounding_box_diagonal(&reference.mesh.projection_points);
        for ext in ["usda", "usdc"] {
            let out = dir.join(format!("bake.{ext}"));
            let run = bake(shot, &out, &["--frames", "1-12", "--quiet"]);
            assert!(run.status.success(), "{}", stderr(&run));
            let frames = [1.0, 6.0, 9.0, 12.0];
            for (t, points) in frames.iter().zip(usd_core_points(&out, &input, &frames)) {
                // float32 output: within a few ulps of the f64 solve.
                let d = max_diff(&points, &reference.deform(*t));
                assert!(
                    d <= 1e-6 * diagonal,
                    "{shot} ({ext}), frame {t}: usd-core reads {:e} of the diagonal away",
                    d / diagonal
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Frames are solved in groups (`--batch-frames K`, one multi-frame solve
/// per group of one mesh): the output's bytes do not depend on K nor on the
/// number of solve threads, on the shipped shot (blend shapes after the
/// solve), the skinned one (a rest pose per frame, blend shapes before) and
/// the adjusted one (Curvenet Adjustments); 24 frames, so K = 8 and 3 make
/// several groups and K = 32 (the largest) one shorter than itself. Nor on
/// the vector unit the triangular sweeps run on (`CURVENET_SIMD=baseline`
/// forces the portable build of them; the default takes AVX2/AVX-512 where
/// the CPU has them): a mixed farm bakes the same bytes.
#[test]
fn bake_bytes_do_not_depend_on_the_group_size_or_the_thread_count() {
    let dir = temp_dir("batch");
    for shot in [SHOT, "fixtures/shots/hand_rigged/shot.usda", "fixtures/shots/hand_adjusted/shot.usda"] {
        let mut first: Option<Vec<u8>> = None;
        for (k, threads, simd) in
            [("1", "1", ""), ("3", "2", ""), ("8", "1", ""), ("8", "2", ""), ("32", "2", ""), ("8", "2", "baseline")]
        {
            let out = dir.join(format!("k{k}_t{threads}_{simd}.usda"));
            let run = Command::new(env!("CARGO_BIN_EXE_curvenet"))
                .args(["bake", shot, "--out", out.to_str().unwrap(), "--frames", "1-24", "--quiet"])
                .args(["--batch-frames", k])
                .env("RAYON_NUM_THREADS", threads)
                .env("CURVENET_SIMD", simd)
                .current_dir(repo())
                .output()
                .unwrap();
            assert!(run.status.success(), "{shot} K={k}: {}", stderr(&run));
            let bytes = std::fs::read(&out).unwrap();
            match &first {
                None => first = Some(bytes),
                Some(f) => assert!(
                    f == &bytes,
                    "{shot}: K={k} on {threads} thread(s), CURVENET_SIMD={simd:?} wrote different bytes than K=1"
                ),
            }
        }
    }
    // K is 1..=32.
    for k in ["0", "33"] {
        let run = bake(SHOT, &dir.join("bad.usda"), &["--batch-frames", k]);
        assert_eq!(run.status.code(), Some(2), "--batch-frames {k}: {}", stderr(&run));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
