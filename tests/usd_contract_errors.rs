//! Stages that break the contract are refused with an error naming the prim
//! and the attribute; the edge cases the contract allows read correctly.

use curvenet_schema::usd::{Stage, UsdError};

/// A small valid stage; each test replaces one line of it.
const BASE: &str = r#"#usda 1.0
(
    startTimeCode = 1
    endTimeCode = 2
)
def Xform "W" {
    def Mesh "M" (prepend apiSchemas = ["SkelBindingAPI"]) {
        int[] faceVertexCounts = [3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]
        point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0)]
        point3f[] points.timeSamples = { 1: [(0,0,0), (1,0,0), (1,1,0), (0,1,0)], 2: [(0,0,1), (1,0,1), (1,1,1), (0,1,1)] }
        rel curvenet:curvenets = </W/C>
        uniform token[] skel:blendShapes = ["b"]
        rel skel:blendShapeTargets = </W/M/B>
        rel skel:skeleton = </W/S>
        def BlendShape "B" {
            uniform vector3f[] offsets = [(0,0,1)]
            uniform int[] pointIndices = [2]
            uniform vector3f[] inbetweens:half = [(0,0,0.2)] ( weight = 0.5 )
        }
    }
    def Skeleton "S" {
        rel skel:animationSource = </W/S/A>
        def SkelAnimation "A" {
            uniform token[] blendShapes = ["b"]
            float[] blendShapeWeights.timeSamples = { 1: [0], 2: [0.75] }
        }
    }
    def BasisCurves "C" {
        uniform token type = "cubic"
        uniform token basis = "bezier"
        uniform token wrap = "nonperiodic"
        int[] curveVertexCounts = [4]
        point3f[] primvars:curvenet:cv = [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,0)] ( interpolation = "vertex" )
        point3f[] primvars:curvenet:cv.timeSamples = { 1: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,0)], 2: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,1)] }
        int[] primvars:curvenet:cv:indices = [0, 1, 2, 3]
        uniform float curvenet:sampleDensity = 4
    }
}
"#;

fn write(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("curvenet-usd-contract-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// BASE with `from` replaced by `to` (which must occur exactly once).
fn variant(name: &str, from: &str, to: &str) -> std::path::PathBuf {
    assert_eq!(BASE.matches(from).count(), 1, "{from:?} must occur once in BASE");
    write(name, &BASE.replacen(from, to, 1))
}

fn contract(e: UsdError) -> (String, String, String) {
    match e {
        UsdError::Contract { prim, attribute, problem } => (prim, attribute, problem),
        other => panic!("expected a contract error, got {other}"),
    }
}

#[test]
fn the_base_stage_reads() {
    let stage = Stage::open(write("base.usda", BASE)).unwrap();
    assert_eq!(stage.time_code_range(), Some((1.0, 2.0)));
    let meshes = stage.deformed_meshes().unwrap();
    assert_eq!(meshes.len(), 1);
    let m = &meshes[0];
    assert_eq!(m.path, "/W/M");
    assert_eq!(m.curvenets, ["/W/C"]);
    assert_eq!(m.rest_sample_times, [1.0, 2.0]);
    assert_eq!(stage.rest_points(m, Some(2.0)).unwrap()[3], [0.0, 1.0, 1.0]);
    assert_eq!(m.blend_shapes[0].point_indices, Some(vec![2]));
    assert_eq!(m.blend_shapes[0].inbetweens[0].weight, 0.5);
    assert_eq!(m.blend_shape_animation.as_deref(), Some("/W/S/A"));
    assert_eq!(stage.blend_shape_weights(m, Some(2.0)).unwrap(), [0.75]);
    // Linear interpolation between samples, as USD does.
    assert!((stage.blend_shape_weights(m, Some(1.5)).unwrap()[0] - 0.375).abs() < 1e-7);
    let c = stage.curvenet("/W/C").unwrap();
    assert_eq!(c.splines, [[0, 1, 2, 3]]);
    assert_eq!(c.sample_density, 4.0);
    assert_eq!(stage.posed_pool(&c, Some(2.0)).unwrap().unwrap()[3], [1.0, 1.0, 1.0]);
}

#[test]
fn left_handed_meshes_are_read_counter_clockwise() {
    let path = variant(
        "left.usda",
        "int[] faceVertexCounts = [3, 3]",
        "uniform token orientation = \"leftHanded\"\n        int[] faceVertexCounts = [3, 3]",
    );
    let m = &Stage::open(path).unwrap().deformed_meshes().unwrap()[0];
    assert_eq!(m.face_vertex_indices, [2, 1, 0, 3, 2, 0]);
}

#[test]
fn an_unarticulated_curvenet_has_no_posed_pool() {
    let path = variant(
        "static.usda",
        "        point3f[] primvars:curvenet:cv.timeSamples = { 1: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,0)], 2: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,1)] }\n",
        "",
    );
    let stage = Stage::open(path).unwrap();
    let c = stage.curvenet("/W/C").unwrap();
    assert!(c.sample_times.is_empty());
    assert_eq!(stage.posed_pool(&c, Some(2.0)).unwrap(), None);
}

#[test]
fn curvenet_errors_name_prim_and_attribute() {
    let cases = [
        (
            "int[] primvars:curvenet:cv:indices = [0, 1, 2, 3]",
            "int[] primvars:curvenet:cv:indices = [0, 1, 2, 9]",
            "primvars:curvenet:cv:indices",
            "entry 3 is 9",
        ),
        (
            "int[] primvars:curvenet:cv:indices = [0, 1, 2, 3]",
            "int[] primvars:curvenet:cv:indices = [0, 1, -2, 3]",
            "primvars:curvenet:cv:indices",
            "entry 2 is -2",
        ),
        ("int[] curveVertexCounts = [4]", "int[] curveVertexCounts = [3]", "curveVertexCounts", "entry 0 is 3"),
        (
            "int[] curveVertexCounts = [4]",
            "int[] curveVertexCounts = [4, 4]",
            "primvars:curvenet:cv:indices",
            "4 per spline (2 splines)",
        ),
        ("uniform token basis = \"bezier\"", "uniform token basis = \"bspline\"", "basis", "\"bspline\""),
        ("uniform token wrap = \"nonperiodic\"", "uniform token wrap = \"periodic\"", "wrap", "\"periodic\""),
        (
            "uniform float curvenet:sampleDensity = 4",
            "uniform float curvenet:sampleDensity = -1",
            "curvenet:sampleDensity",
            "positive",
        ),
        ("int[] primvars:curvenet:cv:indices = [0, 1, 2, 3]", "", "primvars:curvenet:cv:indices", "missing"),
    ];
    for (k, (from, to, attr, needle)) in cases.iter().enumerate() {
        let stage = Stage::open(variant(&format!("net{k}.usda"), from, to)).unwrap();
        let (prim, attribute, problem) = contract(stage.curvenet("/W/C").unwrap_err());
        assert_eq!((prim.as_str(), attribute.as_str()), ("/W/C", *attr), "case {k}: {problem}");
        assert!(problem.contains(needle), "case {k}: {problem:?} should mention {needle:?}");
    }
    // A posed pool with the wrong number of points names the time.
    let stage = Stage::open(variant(
        "net_pose.usda",
        "2: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0), (1,1,1)] }",
        "2: [(0,0,0), (0.3,0.3,0), (0.6,0.6,0)] }",
    ))
    .unwrap();
    let c = stage.curvenet("/W/C").unwrap();
    let (_, attribute, problem) = contract(stage.posed_pool(&c, Some(2.0)).unwrap_err());
    assert_eq!(attribute, "primvars:curvenet:cv");
    assert!(problem.contains("3 control points at time 2"), "{problem}");
}

#[test]
fn mesh_errors_name_prim_and_attribute() {
    let cases = [
        (
            "int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]",
            "int[] faceVertexIndices = [0, 1, 2, 0, 2, 4]",
            "faceVertexIndices",
            "entry 5 is 4",
        ),
        (
            "int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]",
            "int[] faceVertexIndices = [0, 1, 2, 0, 2]",
            "faceVertexIndices",
            "faceVertexCounts sum to 6",
        ),
        (
            "int[] faceVertexCounts = [3, 3]",
            "int[] faceVertexCounts.timeSamples = { 1: [3, 3] }",
            "faceVertexCounts",
            "time samples",
        ),
        (
            "rel curvenet:curvenets = </W/C>",
            "rel curvenet:curvenets = </W/C>\n        point3f[] primvars:curvenet:projectionPoints = [(0,0,0)]",
            "primvars:curvenet:projectionPoints",
            "has 1 points, the mesh has 4",
        ),
        ("uniform int[] pointIndices = [2]", "uniform int[] pointIndices = [2, 3]", "offsets", "pointIndices has 2"),
        ("uniform int[] pointIndices = [2]", "uniform int[] pointIndices = [7]", "pointIndices", "entry 0 is 7"),
        ("( weight = 0.5 )", "", "inbetweens:half", "no weight"),
    ];
    for (k, (from, to, attr, needle)) in cases.iter().enumerate() {
        let stage = Stage::open(variant(&format!("mesh{k}.usda"), from, to)).unwrap();
        let (prim, attribute, problem) = contract(stage.deformed_meshes().unwrap_err());
        assert!(prim.starts_with("/W/M"), "case {k}: prim {prim}");
        assert_eq!(attribute, *attr, "case {k}: {problem}");
        assert!(problem.contains(needle), "case {k}: {problem:?} should mention {needle:?}");
    }
    // A rest-pose sample with the wrong count names the time.
    let stage =
        Stage::open(variant("rest.usda", "2: [(0,0,1), (1,0,1), (1,1,1), (0,1,1)] }", "2: [(0,0,1), (1,0,1)] }"))
            .unwrap();
    let m = &stage.deformed_meshes().unwrap()[0];
    let (_, attribute, problem) = contract(stage.rest_points(m, Some(2.0)).unwrap_err());
    assert_eq!(attribute, "points");
    assert!(problem.contains("2 points at time 2, the mesh has 4"), "{problem}");
    // Weights that don't match the animation's shape list name the animation.
    let stage = Stage::open(variant("weights.usda", "2: [0.75] }", "2: [0.75, 1] }")).unwrap();
    let m = &stage.deformed_meshes().unwrap()[0];
    let (prim, attribute, _) = contract(stage.blend_shape_weights(m, Some(2.0)).unwrap_err());
    assert_eq!((prim.as_str(), attribute.as_str()), ("/W/S/A", "blendShapeWeights"));
    // A curvenet relationship that targets a mesh.
    let stage =
        Stage::open(variant("target.usda", "rel curvenet:curvenets = </W/C>", "rel curvenet:curvenets = </W/M>"))
            .unwrap();
    let (prim, _, problem) = contract(stage.curvenet("/W/M").unwrap_err());
    assert_eq!(prim, "/W/M");
    assert!(problem.contains("BasisCurves"), "{problem}");
}

#[test]
fn unresolvable_stages_are_refused_at_open() {
    let missing = std::env::temp_dir().join("curvenet-definitely-missing.usda");
    assert!(matches!(Stage::open(&missing), Err(UsdError::Open { .. })));
    let base = write("sub_base.usda", BASE);
    let top =
        write("sub_top.usda", &format!("#usda 1.0\n(\n    subLayers = [@./nope.usda@, @{}@]\n)\n", base.display()));
    match Stage::open(&top) {
        Err(UsdError::Open { message, .. }) => assert!(message.contains("nope.usda"), "{message}"),
        other => panic!("expected an open error, got {:?}", other.map(|_| ())),
    }
    let garbage = write("garbage.usda", "#usda 1.0\ndef Mesh \"M\" { int[] faceVertexCounts = [3, \n");
    assert!(matches!(Stage::open(&garbage), Err(UsdError::Open { .. })));
}

#[test]
fn indexed_projection_points_are_flattened() {
    let path = variant(
        "indexed_projection.usda",
        "rel curvenet:curvenets = </W/C>",
        "rel curvenet:curvenets = </W/C>\n        point3f[] primvars:curvenet:projectionPoints = [(5,0,0), (0,5,0), (0,0,5)] ( interpolation = \"vertex\" )\n        int[] primvars:curvenet:projectionPoints:indices = [2, 0, 0, 1]",
    );
    let stage = Stage::open(&path).unwrap();
    let m = stage.mesh("/W/M").unwrap();
    assert_eq!(m.projection_points, vec![[0.0, 0.0, 5.0], [5.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0]]);
    // An index past the values is named.
    let bad = variant(
        "indexed_projection_bad.usda",
        "rel curvenet:curvenets = </W/C>",
        "rel curvenet:curvenets = </W/C>\n        point3f[] primvars:curvenet:projectionPoints = [(5,0,0), (0,5,0)] ( interpolation = \"vertex\" )\n        int[] primvars:curvenet:projectionPoints:indices = [0, 1, 2, 1]",
    );
    let (prim, attr, why) = contract(Stage::open(&bad).unwrap().mesh("/W/M").unwrap_err());
    assert_eq!((prim.as_str(), attr.as_str()), ("/W/M", "primvars:curvenet:projectionPoints:indices"));
    assert!(why.contains("entry 2 is 2"), "{why}");
}
