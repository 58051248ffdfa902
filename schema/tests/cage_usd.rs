//! Cages (schema/README.md, "Cage"): the two cage fixtures read as the
//! manifest says (counts, checksums, per-frame samples, the skinning-method
//! override), frames evaluated between samples as openusd evaluates them,
//! and stages that break the contract refused naming the prim, the
//! attribute and the face, edge, entry or time at fault.

use std::path::{Path, PathBuf};

use curvenet_schema::CageData;
use curvenet_schema::usd::{CurvenetSkinningMethod, Stage, UsdError};
use serde_json::Value;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures")
}

fn manifest() -> Value {
    serde_json::from_str(&std::fs::read_to_string(fixtures().join("manifest.json")).unwrap()).unwrap()
}

/// The manifest's checksum of a point array: sum_i (i+1)(x_i + 2y_i + 3z_i) / n.
fn checksum(points: &[[f64; 3]]) -> f64 {
    let sum: f64 = points.iter().enumerate().map(|(i, p)| (i + 1) as f64 * (p[0] + 2.0 * p[1] + 3.0 * p[2])).sum();
    if points.is_empty() { 0.0 } else { sum / points.len() as f64 }
}

fn assert_close(what: &str, got: f64, want: f64) {
    assert!((got - want).abs() <= 1e-9 * want.abs().max(1.0), "{what}: read {got}, manifest {want}");
}

fn read_cage(rel: &str) -> (Stage, CageData) {
    let stage = Stage::open(fixtures().join(rel)).unwrap();
    let meshes = stage.deformed_meshes().unwrap();
    assert_eq!(meshes.len(), 1, "{rel}");
    let cage = stage.cage(&meshes[0]).unwrap().expect("the mesh has a cage");
    (stage, cage)
}

/// The fixture's cage against its manifest entry: counts, topology checksum,
/// the bind cage and every sample (through `CageData::frame`, which must
/// hand back the sample itself at its time).
fn check_against_manifest(rel: &str, cage: &CageData) {
    let manifest = manifest();
    let want = &manifest["stages"][rel]["cages"][&cage.path];
    assert!(want.is_object(), "{rel}: no manifest entry for {}", cage.path);
    assert_eq!(cage.mesh, want["mesh"].as_str().unwrap());
    assert_eq!(cage.rest_points.len() as u64, want["n_points"].as_u64().unwrap());
    assert_eq!(cage.triangles.len() as u64, want["n_triangles"].as_u64().unwrap());
    let indices: i64 =
        cage.triangles.iter().flatten().enumerate().map(|(i, &v)| (i as i64 + 1) * v as i64).sum::<i64>();
    assert_eq!(indices, want["indices_checksum"].as_i64().unwrap());
    assert_close("rest default", checksum(&cage.rest_points), want["rest_default_checksum"].as_f64().unwrap());
    assert!(cage.frame(None).rest_cage().is_none(), "the default time is the bind cage");
    for (samples, key, name) in [
        (&cage.rest_samples, "rest_samples", "rest cage"),
        (&cage.posed_offset_samples, "posed_offset_samples", "posed offsets"),
    ] {
        let entries = want[key].as_array().unwrap();
        assert_eq!(samples.len(), entries.len(), "{rel}: {name} samples");
        for (s, e) in samples.iter().zip(entries) {
            let (t, c) = (e[0].as_f64().unwrap(), e[1].as_f64().unwrap());
            assert_eq!(s.time, t);
            assert_eq!(s.points.len(), cage.rest_points.len(), "{name} at {t}");
            assert_close(&format!("{rel} {name} at {t}"), checksum(&s.points), c);
            let frame = cage.frame(Some(t));
            let got = if key == "rest_samples" { frame.rest_cage() } else { frame.posed_cage_offsets() };
            assert_eq!(got, Some(s.points.as_slice()), "{name} evaluated at its sample time {t}");
        }
    }
}

#[test]
fn hand_caged_reads_as_the_manifest_says() {
    let rel = "shots/hand_caged/shot.usda";
    let (stage, cage) = read_cage(rel);
    assert_eq!(cage.path, "/Hand/Cage");
    assert_eq!((cage.rest_points.len(), cage.triangles.len()), (170, 336));
    check_against_manifest(rel, &cage);
    let times: Vec<f64> = (1..=10).map(f64::from).collect();
    assert_eq!(cage.sample_times(), times);
    assert!(cage.posed_offsets_default.is_none());

    // The schedule (fixtures/README.md): rest edits on 2, 3, 8, 10; posed edits on 6, 7, 9, 10.
    let rest = |t: f64| cage.rest_cage_at(Some(t)).into_owned();
    let offsets = |t: f64| cage.frame(Some(t)).posed_cage_offsets().unwrap().to_vec();
    let moved = |p: &[[f64; 3]], q: &[[f64; 3]]| {
        p.iter().zip(q).map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max)).fold(0.0, f64::max)
    };
    let zero = vec![[0.0; 3]; cage.rest_points.len()];
    for t in 1..=10 {
        let t = f64::from(t);
        let edited = moved(&rest(t), &cage.rest_points) > 1e-6;
        let pushed = moved(&offsets(t), &zero) > 1e-6;
        assert_eq!(edited, [2.0, 3.0, 8.0, 10.0].contains(&t), "rest edit at frame {t}");
        assert_eq!(pushed, [6.0, 7.0, 9.0, 10.0].contains(&t), "posed edit at frame {t}");
    }
    assert_eq!(rest(8.0), rest(3.0));
    assert_eq!(offsets(10.0), offsets(7.0));
    let full = moved(&rest(3.0), &cage.rest_points);
    assert!(full > 0.05 && full < 0.07, "the full rest edit moves the cage by {full}");

    // Skinned by the hand_rigged skeleton, with our tools' method override.
    let mesh = &stage.deformed_meshes().unwrap()[0];
    let rig = stage.skin_rig(mesh).unwrap().expect("the caged hand is skinned");
    assert_eq!(rig.joints.len(), 8);
    assert_eq!(rig.curvenet_method, Some(CurvenetSkinningMethod::CentersOfRotation));
    assert_eq!(stage.curvenet_skinning_method(mesh).unwrap(), Some(CurvenetSkinningMethod::CentersOfRotation));
    assert_eq!(rig.method, curvenet_core::SkinningMethod::ClassicLinear, "UsdSkel's token stays");
    assert_eq!(rig.time_samples, times);
}

/// Between samples a frame is USD's linear interpolation, outside them the
/// end samples are held: compared with openusd's own evaluation of the
/// composed attributes (f32 arithmetic there, f64 here).
#[test]
fn frames_between_and_outside_samples_evaluate_as_usd_does() {
    let rel = "shots/hand_caged/shot.usda";
    let (_, cage) = read_cage(rel);
    let usd = openusd::usd::Stage::open(fixtures().join(rel).to_str().unwrap()).unwrap();
    let prim = usd.prim("/Hand/Cage").unwrap();
    let read = |name: &str, t: f64| -> Vec<[f64; 3]> {
        match prim.attribute(name).get_at::<openusd::sdf::Value>(Some(openusd::usd::TimeCode::new(t))).unwrap() {
            Some(openusd::sdf::Value::Vec3fVec(v)) => v.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect(),
            other => panic!("{name} at {t}: {other:?}"),
        }
    };
    let mut compared = 0;
    for t in [-3.0, 1.0, 1.5, 2.25, 2.5, 5.5, 6.75, 9.5, 10.0, 42.0] {
        let frame = cage.frame(Some(t));
        for (name, got) in [
            ("points", frame.rest_cage().unwrap()),
            ("primvars:curvenet:posedCageOffsets", frame.posed_cage_offsets().unwrap()),
        ] {
            let want = read(name, t);
            assert_eq!(got.len(), want.len());
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                for k in 0..3 {
                    assert!((g[k] - w[k]).abs() <= 1e-6, "{name} at {t}, vertex {i}: {g:?} vs openusd {w:?}");
                }
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 20);
    // a fractional time between two different samples is neither of them
    let mid = cage.rest_cage_at(Some(2.5));
    assert_ne!(mid.as_ref(), cage.rest_cage_at(Some(2.0)).as_ref());
    assert_ne!(mid.as_ref(), cage.rest_cage_at(Some(3.0)).as_ref());
}

#[test]
fn hand_cage_only_has_a_cage_and_no_skeleton() {
    let rel = "shots/hand_cage_only/shot.usda";
    let (stage, cage) = read_cage(rel);
    check_against_manifest(rel, &cage);
    assert_eq!(cage.sample_times(), vec![1.0, 2.0, 3.0]);
    assert!(cage.posed_offset_samples.is_empty() && cage.posed_offsets_default.is_none());
    assert!(cage.frame(Some(2.0)).posed_cage_offsets().is_none());
    assert_eq!(cage.rest_cage_at(Some(1.0)).as_ref(), cage.rest_points.as_slice(), "frame 1 is the bind cage");
    let mesh = &stage.deformed_meshes().unwrap()[0];
    assert!(stage.skin_rig(mesh).unwrap().is_none());
    assert_eq!(stage.curvenet_skinning_method(mesh).unwrap(), None);
    // the same cage as hand_caged's
    let (_, caged) = read_cage("shots/hand_caged/shot.usda");
    assert_eq!((cage.rest_points.clone(), cage.triangles.clone()), (caged.rest_points, caged.triangles));
}

#[test]
fn meshes_without_a_cage_read_none() {
    for rel in ["shots/hand_rigged/shot.usda", "hand/hand_1k4.usda", "grid/grid.usda"] {
        let stage = Stage::open(fixtures().join(rel)).unwrap();
        for mesh in stage.deformed_meshes().unwrap() {
            assert_eq!(stage.cage(&mesh).unwrap(), None, "{rel} {}", mesh.path);
        }
    }
}

// ---------------------------------------------------------------------------
// Broken stages

/// A tetrahedron cage (outward) around a one-triangle mesh, with time
/// samples at 1 and 2; `edit` rewrites the text.
const TETRA: &str = r#"#usda 1.0
(
    startTimeCode = 1
    endTimeCode = 2
)

def Xform "World"
{
    def Mesh "Mesh"
    {
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points = [(0.1, 0.1, 0.1), (0.2, 0.1, 0.1), (0.1, 0.2, 0.1)]
        rel curvenet:cage = </World/Cage>
    }

    def Mesh "Cage"
    {
        int[] faceVertexCounts = [3, 3, 3, 3]
        int[] faceVertexIndices = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
        point3f[] points.timeSamples = {
            1: [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)],
            2: [(0, 0, 0), (2, 0, 0), (0, 1, 0), (0, 0, 1)],
        }
        point3f[] primvars:curvenet:posedCageOffsets (
            interpolation = "vertex"
        )
        point3f[] primvars:curvenet:posedCageOffsets.timeSamples = {
            1: [(0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)],
            2: [(0, 0, 0), (0.5, 0, 0), (0, 0, 0), (0, 0, 0)],
        }
    }
}
"#;

fn read_edited(tag: &str, edits: &[(&str, &str)]) -> Result<Option<CageData>, UsdError> {
    let mut text = TETRA.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "{tag}: the template has no {from:?}");
        text = text.replacen(from, to, 1);
    }
    let dir = std::env::temp_dir().join(format!("curvenet-cage-usd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{tag}.usda"));
    std::fs::write(&path, text).unwrap();
    let stage = Stage::open(&path).unwrap_or_else(|e| panic!("{tag}: {e}"));
    let mesh = stage.mesh("/World/Mesh").unwrap();
    let out = stage.cage(&mesh);
    let _ = std::fs::remove_file(&path);
    out
}

fn refused(tag: &str, edits: &[(&str, &str)], prim: &str, attribute: &str, says: &[&str]) {
    match read_edited(tag, edits) {
        Err(UsdError::Contract { prim: p, attribute: a, problem }) => {
            assert_eq!((p.as_str(), a.as_str()), (prim, attribute), "{tag}: {problem}");
            for s in says {
                assert!(problem.contains(s), "{tag}: {problem:?} does not say {s:?}");
            }
        }
        other => panic!("{tag}: expected a contract error, got {other:?}"),
    }
}

#[test]
fn the_template_reads() {
    let cage = read_edited("valid", &[]).unwrap().unwrap();
    assert_eq!(cage.triangles, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]);
    assert_eq!(cage.rest_cage_at(Some(1.5))[1], [1.5, 0.0, 0.0]);
    assert_eq!(cage.frame(Some(1.5)).posed_cage_offsets().unwrap()[1], [0.25, 0.0, 0.0]);
    // a leftHanded cage listed clockwise is read counter-clockwise
    let left = read_edited(
        "left_handed",
        &[
            ("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2]"),
            (
                "int[] faceVertexCounts = [3, 3, 3, 3]",
                "uniform token orientation = \"leftHanded\"\n        int[] faceVertexCounts = [3, 3, 3, 3]",
            ),
        ],
    )
    .unwrap()
    .unwrap();
    assert_eq!(left.triangles, cage.triangles);
    // no relationship: no cage
    assert_eq!(read_edited("no_rel", &[("rel curvenet:cage = </World/Cage>", "")]).unwrap(), None);
}

#[test]
fn a_relationship_to_nothing_or_to_a_non_mesh_is_refused() {
    refused(
        "to_nothing",
        &[("rel curvenet:cage = </World/Cage>", "rel curvenet:cage = </World/Nope>")],
        "/World/Mesh",
        "curvenet:cage",
        &["/World/Nope", "not on the stage"],
    );
    refused(
        "empty",
        &[("rel curvenet:cage = </World/Cage>", "rel curvenet:cage = []")],
        "/World/Mesh",
        "curvenet:cage",
        &["targets nothing"],
    );
    refused(
        "two",
        &[("rel curvenet:cage = </World/Cage>", "rel curvenet:cage = [</World/Cage>, </World/Mesh>]")],
        "/World/Mesh",
        "curvenet:cage",
        &["2 prims", "one cage"],
    );
    refused(
        "xform",
        &[("rel curvenet:cage = </World/Cage>", "rel curvenet:cage = </World>")],
        "/World/Mesh",
        "curvenet:cage",
        &["/World", "\"Xform\"", "triangle Mesh"],
    );
}

#[test]
fn a_face_that_is_not_a_triangle_is_refused_by_index() {
    refused(
        "quad",
        &[("[3, 3, 3, 3]", "[3, 3, 4, 2]")],
        "/World/Cage",
        "faceVertexCounts",
        &["face 2 has 4 vertices", "triangles"],
    );
}

#[test]
fn an_open_inconsistent_or_inward_cage_is_refused() {
    refused(
        "open",
        &[("[3, 3, 3, 3]", "[3, 3, 3]"), ("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 2, 1, 0, 1, 3, 0, 3, 2]")],
        "/World/Cage",
        "faceVertexIndices",
        &["no opposite edge", "not closed"],
    );
    refused(
        "flipped_face",
        &[("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 3, 2]")],
        "/World/Cage",
        "faceVertexIndices",
        &["same direction", "triangles"],
    );
    refused(
        "inward",
        &[("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2]")],
        "/World/Cage",
        "faceVertexIndices",
        &["faces inwards"],
    );
    refused(
        "repeated_vertex",
        &[("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 2, 2, 0, 1, 3, 0, 3, 2, 1, 2, 3]")],
        "/World/Cage",
        "faceVertexIndices",
        &["triangle 0", "repeats a vertex"],
    );
    refused(
        "out_of_range",
        &[("[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]", "[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 7]")],
        "/World/Cage",
        "faceVertexIndices",
        &["entry 11 is 7"],
    );
}

#[test]
fn a_sample_with_the_wrong_count_or_not_finite_is_refused_naming_the_time() {
    refused(
        "rest_count",
        &[("2: [(0, 0, 0), (2, 0, 0), (0, 1, 0), (0, 0, 1)]", "2: [(0, 0, 0), (2, 0, 0), (0, 1, 0)]")],
        "/World/Cage",
        "points",
        &["has 3 entries at time 2", "4 vertices"],
    );
    refused(
        "offsets_count",
        &[(
            "2: [(0, 0, 0), (0.5, 0, 0), (0, 0, 0), (0, 0, 0)]",
            "2: [(0, 0, 0), (0.5, 0, 0), (0, 0, 0), (0, 0, 0), (1, 1, 1)]",
        )],
        "/World/Cage",
        "primvars:curvenet:posedCageOffsets",
        &["has 5 entries at time 2", "4 vertices"],
    );
    refused(
        "rest_nan",
        &[("2: [(0, 0, 0), (2, 0, 0), (0, 1, 0), (0, 0, 1)]", "2: [(0, 0, 0), (2, 0, 0), (0, nan, 0), (0, 0, 1)]")],
        "/World/Cage",
        "points",
        &["entry 2", "at time 2", "not finite"],
    );
    refused(
        "offsets_interpolation",
        &[("interpolation = \"vertex\"", "interpolation = \"constant\"")],
        "/World/Cage",
        "primvars:curvenet:posedCageOffsets",
        &["\"constant\"", "vertex"],
    );
    refused(
        "animated_topology",
        &[(
            "int[] faceVertexCounts = [3, 3, 3, 3]",
            "int[] faceVertexCounts = [3, 3, 3, 3]\n        int[] faceVertexCounts.timeSamples = { 1: [3, 3, 3, 3] }",
        )],
        "/World/Cage",
        "faceVertexCounts",
        &["time samples"],
    );
}

#[test]
fn the_skinning_method_override_is_checked() {
    let dir = std::env::temp_dir().join(format!("curvenet-cage-method-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let read = |tag: &str, method: &str| {
        let text = TETRA.replacen(
            "rel curvenet:cage = </World/Cage>",
            &format!("rel curvenet:cage = </World/Cage>\n        {method}"),
            1,
        );
        let path = dir.join(format!("{tag}.usda"));
        std::fs::write(&path, text).unwrap();
        let stage = Stage::open(&path).unwrap();
        let mesh = stage.mesh("/World/Mesh").unwrap();
        (stage.curvenet_skinning_method(&mesh), stage.skin_rig(&mesh))
    };
    let (method, rig) = read("bogus", "uniform token curvenet:skinningMethod = \"bogus\"");
    let e = method.unwrap_err().to_string();
    assert!(e.starts_with("/World/Mesh: curvenet:skinningMethod is \"bogus\""), "{e}");
    assert!(rig.is_err());
    // authored on a mesh with no skin: nothing to apply it to
    let (method, rig) = read("no_skin", "uniform token curvenet:skinningMethod = \"centersOfRotation\"");
    assert_eq!(method.unwrap(), Some(CurvenetSkinningMethod::CentersOfRotation));
    let e = rig.unwrap_err().to_string();
    assert!(e.contains("curvenet:skinningMethod is authored but the mesh has no skin"), "{e}");
    let (method, _) = read("string", "uniform string curvenet:skinningMethod = \"centersOfRotation\"");
    assert!(method.unwrap_err().to_string().contains("expected a uniform token"));
    let _ = std::fs::remove_dir_all(&dir);
}
