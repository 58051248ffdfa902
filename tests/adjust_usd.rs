//! `CurvenetAdjustment` prims (schema/README.md, "Curvenet adjustment"): what
//! a valid one reads as at a frame, and every broken one refused naming the
//! prim and the attribute.

use curvenet_core::{Adjustment, Rotate};
use curvenet_schema::usd::{Stage, UsdError};

/// A curvenet of two splines 0-1-2-3 and 3-4-5-6 (knots 0, 3, 6; the
/// handles 1, 2, 4, 5) with one adjustment of knot 3, whose tangents are the
/// handles 2 and 4. Each test replaces one line of it.
const BASE: &str = r#"#usda 1.0
(
    startTimeCode = 1
    endTimeCode = 3
)
def Xform "W" {
    def BasisCurves "C" {
        uniform token type = "cubic"
        uniform token basis = "bezier"
        uniform token wrap = "nonperiodic"
        int[] curveVertexCounts = [4, 4]
        point3f[] primvars:curvenet:cv = [(0,0,0), (1,0,0), (2,0,0), (3,0,0), (4,0,0), (5,0,0), (6,0,0)] ( interpolation = "vertex" )
        int[] primvars:curvenet:cv:indices = [0, 1, 2, 3, 3, 4, 5, 6]
        def CurvenetAdjustment "K" {
            uniform int curvenet:knot = 3
            uniform bool curvenet:attachTangents = 0
            double3 xformOp:translate.timeSamples = { 1: (0, 0, 0), 3: (0, 0.2, -0.4) }
            float3 xformOp:rotateXYZ = (10, 0, 30)
            float3 xformOp:scale = (1, 2, 1)
            float3[] curvenet:tangentTranslates.timeSamples = { 1: [(0, 0, 0), (0, 0, 0)], 3: [(0, 1, 0), (0, 0, 2)] }
            uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]
        }
        def Xform "NotAnAdjustment" {
        }
    }
}
"#;

fn write(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("curvenet-adjust-usd-{}", std::process::id()));
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

/// The adjustments of /W/C at `time`, or the reader's error.
fn read(path: &std::path::Path, time: Option<f64>) -> Result<Vec<Adjustment>, UsdError> {
    let stage = Stage::open(path).unwrap();
    let net = stage.curvenet("/W/C").unwrap();
    let list = stage.curvenet_adjustments(&net)?;
    stage.adjustments_at(&[list], time)
}

fn contract(r: Result<Vec<Adjustment>, UsdError>) -> (String, String, String) {
    match r {
        Err(UsdError::Contract { prim, attribute, problem }) => (prim, attribute, problem),
        other => panic!("expected a contract error, got {other:?}"),
    }
}

#[test]
fn the_base_adjustment_reads_with_interpolated_values() {
    let path = write("base.usda", BASE);
    let stage = Stage::open(&path).unwrap();
    let net = stage.curvenet("/W/C").unwrap();
    let list = stage.curvenet_adjustments(&net).unwrap();
    assert_eq!(list.len(), 1, "only the CurvenetAdjustment child counts");
    let a = &list[0];
    assert_eq!((a.path.as_str(), a.curvenet.as_str(), a.knot), ("/W/C/K", "/W/C", 3));
    assert!(!a.attach_tangents);
    assert_eq!(a.tangents, [2, 4]);
    assert_eq!(a.rotate.as_deref(), Some("xformOp:rotateXYZ"));
    let names: Vec<(&str, usize)> = a.attributes.iter().map(|(n, t)| (n.as_str(), t.len())).collect();
    assert_eq!(
        names,
        [("xformOp:translate", 2), ("xformOp:rotateXYZ", 0), ("xformOp:scale", 0), ("curvenet:tangentTranslates", 2)]
    );
    // Frame 2 lies halfway between the samples at 1 and 3: linear interpolation.
    let at2 = stage.adjustments_at(std::slice::from_ref(&list), Some(2.0)).unwrap();
    let want = Adjustment::new(0, 3)
        .with_attach_tangents(false)
        .with_translate([0.0, 0.1, -0.2])
        .with_rotate(Rotate::EulerXyz([10.0, 0.0, 30.0]))
        .with_scale([1.0, 2.0, 1.0])
        .with_tangent_translates(vec![[0.0, 0.5, 0.0], [0.0, 0.0, 1.0]]);
    let close = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(a, b)| (a - b).abs() < 1e-12);
    assert_eq!((at2[0].curvenet, at2[0].knot, at2[0].attach_tangents, at2[0].rotate), (0, 3, false, want.rotate));
    assert!(close(&at2[0].translate, &want.translate), "{:?}", at2[0].translate);
    assert_eq!(at2[0].scale, want.scale);
    assert!(close(at2[0].tangent_translates.as_flattened(), want.tangent_translates.as_flattened()));
    // The curvenet index is the list's position (the binding's curvenet order).
    let two = stage.adjustments_at(&[Vec::new(), list], Some(1.0)).unwrap();
    assert_eq!(two[0].curvenet, 1);
}

#[test]
fn unauthored_values_are_no_change_and_the_quaternion_form_reads() {
    let path = variant(
        "orient.usda",
        "            float3 xformOp:rotateXYZ = (10, 0, 30)\n",
        "            quatf xformOp:orient = (0.5, 0.5, 0.5, 0.5)\n",
    );
    let a = read(&path, Some(1.0)).unwrap();
    assert_eq!(a[0].rotate, Rotate::Quaternion([0.5, 0.5, 0.5, 0.5]));
    let bare = variant(
        "bare.usda",
        r#"            uniform bool curvenet:attachTangents = 0
            double3 xformOp:translate.timeSamples = { 1: (0, 0, 0), 3: (0, 0.2, -0.4) }
            float3 xformOp:rotateXYZ = (10, 0, 30)
            float3 xformOp:scale = (1, 2, 1)
            float3[] curvenet:tangentTranslates.timeSamples = { 1: [(0, 0, 0), (0, 0, 0)], 3: [(0, 1, 0), (0, 0, 2)] }
"#,
        "",
    );
    let a = read(&bare, Some(2.0)).unwrap();
    assert_eq!(a, [Adjustment::new(0, 3)], "nothing authored: the identity, tangents attached");
    assert!(a[0].is_identity());
}

#[test]
fn broken_adjustments_are_refused_naming_the_prim_and_attribute() {
    let knot = "            uniform int curvenet:knot = 3\n";
    let cases: [(&str, &str, &str, &str, &str); 9] = [
        ("handle", knot, "            uniform int curvenet:knot = 2\n", "curvenet:knot", "not a knot"),
        ("range", knot, "            uniform int curvenet:knot = 7\n", "curvenet:knot", "outside the pool"),
        ("missing", knot, "", "curvenet:knot", "is missing"),
        (
            "animated-knot",
            knot,
            "            int curvenet:knot.timeSamples = { 1: 3 }\n",
            "curvenet:knot",
            "must not have time samples",
        ),
        (
            "both-rotates",
            "            float3 xformOp:scale = (1, 2, 1)\n",
            "            float3 xformOp:scale = (1, 2, 1)\n            quatf xformOp:orient = (1, 0, 0, 0)\n",
            "xformOp:orient",
            "together with xformOp:rotateXYZ",
        ),
        (
            "op-order",
            r#"["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]"#,
            r#"["xformOp:scale", "xformOp:translate"]"#,
            "xformOpOrder",
            "then one rotate",
        ),
        (
            "tangent-count",
            "3: [(0, 1, 0), (0, 0, 2)] }",
            "3: [(0, 1, 0)] }",
            "curvenet:tangentTranslates",
            "has 1 entries at time 3, the knot 3 has 2 tangents",
        ),
        (
            "zero-quaternion",
            "            float3 xformOp:rotateXYZ = (10, 0, 30)\n",
            "            quatf xformOp:orient = (0, 0, 0, 0)\n",
            "xformOp:orient",
            "zero quaternion",
        ),
        (
            "not-finite",
            "float3 xformOp:scale = (1, 2, 1)",
            "float3 xformOp:scale = (1, inf, 1)",
            "xformOp:scale",
            "not finite",
        ),
    ];
    for (name, from, to, attribute, problem) in cases {
        let (p, a, msg) = contract(read(&variant(&format!("{name}.usda"), from, to), Some(3.0)));
        assert_eq!((p.as_str(), a.as_str()), ("/W/C/K", attribute), "{name}: {msg}");
        assert!(msg.contains(problem), "{name}: {msg:?} should say {problem:?}");
    }
    // Two adjustments of one knot: the second is named, with the first.
    let twice = BASE.replacen(
        "        def Xform \"NotAnAdjustment\" {",
        "        def CurvenetAdjustment \"Again\" {\n            uniform int curvenet:knot = 3\n        }\n        def Xform \"NotAnAdjustment\" {",
        1,
    );
    let (p, a, msg) = contract(read(&write("twice.usda", &twice), None));
    assert_eq!((p.as_str(), a.as_str()), ("/W/C/Again", "curvenet:knot"));
    assert!(msg.contains("/W/C/K already adjusts"), "{msg}");
}
