//! The robustness corpus (fixtures/corpus, issue 13) and the hand fixtures:
//! every fixture binds; the neutral pose gives back the input mesh (within
//! 1e-9 of the diagonal); a rigid motion of the whole curvenet moves every
//! vertex by the same motion (within 1e-6 of the diagonal, caps included);
//! a 35° bend of the curvenet beyond the middle ring gives finite points,
//! and the largest edge stretch is printed (`--nocapture`).
//!
//! The draft's rings (normal, centre, position) come from
//! fixtures/manifest.json, which fixtures/generate.py writes from the
//! `curvenet draft --json` report.

use curvenet_e2e::{Bound, bind_fixture, fixtures_dir, max_distance, projected_crossings};

fn manifest() -> serde_json::Value {
    let text = std::fs::read_to_string(fixtures_dir().join("manifest.json")).expect("fixtures/manifest.json");
    serde_json::from_str(&text).expect("the manifest is JSON")
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().unwrap_or_else(|| panic!("not a vector: {v}"));
    [0, 1, 2].map(|k| a[k].as_f64().expect("a number"))
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    a.map(|x| x / n)
}

/// The rotation by `degrees` about the unit `axis` (Rodrigues), row-major.
fn rotation(axis: [f64; 3], degrees: f64) -> [[f64; 3]; 3] {
    let [x, y, z] = axis;
    let (s, c) = degrees.to_radians().sin_cos();
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

fn apply(m: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| dot(m[r], p))
}

fn pools(b: &Bound) -> Vec<Vec<[f64; 3]>> {
    b.nets.iter().map(|n| n.pool.clone()).collect()
}

fn neutral(rel: &str) {
    let b = bind_fixture(rel);
    let out = b.deform(&pools(&b));
    let err = max_distance(&out, &b.mesh.projection_points) / b.diagonal();
    println!("{rel}: neutral pose off the input by {err:.2e} of the diagonal");
    assert!(err <= 1e-9, "{rel}: the neutral pose moves a vertex by {err:e} of the diagonal");
}

fn rigid(rel: &str) {
    let b = bind_fixture(rel);
    let r = rotation(normalize([1.0, 2.0, 3.0]), 40.0);
    let d = b.diagonal();
    let t = [0.3 * d, -0.2 * d, 0.5 * d];
    let motion = |p: [f64; 3]| {
        let q = apply(&r, p);
        [q[0] + t[0], q[1] + t[1], q[2] + t[2]]
    };
    let moved: Vec<Vec<[f64; 3]>> = pools(&b).iter().map(|p| p.iter().map(|&x| motion(x)).collect()).collect();
    let out = b.deform(&moved);
    let want: Vec<[f64; 3]> = b.mesh.projection_points.iter().map(|&x| motion(x)).collect();
    let (worst, err) = out
        .iter()
        .zip(&want)
        .map(|(p, q)| dot(sub(*p, *q), sub(*p, *q)).sqrt())
        .enumerate()
        .fold((0, 0.0), |best, (i, e)| if e > best.1 { (i, e) } else { best });
    println!("{rel}: rigid motion off by {:.2e} of the diagonal (vertex {worst})", err / d);
    assert!(
        err <= 1e-6 * d,
        "{rel}: a rigid motion of the curvenet moves vertex {worst} off by {:e} of the diagonal",
        err / d
    );
}

fn bend(rel: &str) {
    let manifest = manifest();
    let draft = &manifest["stages"][rel]["draft"];
    let rings = draft["rings"].as_array().unwrap_or_else(|| panic!("{rel}: no draft in the manifest"));
    let m = rings.len() / 2;
    let (normal, centre) = (vec3(&rings[m]["normal"]), vec3(&rings[m]["centre"]));
    let neighbour = if m + 1 < rings.len() { m + 1 } else { m - 1 };
    let spacing = (rings[neighbour]["position"].as_f64().unwrap() - rings[m]["position"].as_f64().unwrap()).abs();
    let across = vec3(&draft["across"]);
    let pivot = normalize(sub(across, normal.map(|x| x * dot(across, normal))));
    let r = rotation(pivot, 35.0);
    // Control points beyond the middle ring by a fifth of the ring spacing
    // turn about the axis through the ring's centre; the ring's own points
    // (within the offset of its plane) stay.
    let b = bind_fixture(rel);
    let mut turned = 0;
    let bent: Vec<Vec<[f64; 3]>> = pools(&b)
        .iter()
        .map(|pool| {
            pool.iter()
                .map(|&p| {
                    let d = sub(p, centre);
                    if dot(d, normal) > 0.2 * spacing {
                        turned += 1;
                        let q = apply(&r, d);
                        [q[0] + centre[0], q[1] + centre[1], q[2] + centre[2]]
                    } else {
                        p
                    }
                })
                .collect()
        })
        .collect();
    let out = b.deform(&bent);
    assert!(turned > 0, "{rel}: nothing beyond the middle ring");
    if let Some(i) = out.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        panic!("{rel}: vertex {i} is not finite after the bend");
    }
    let rest = &b.mesh.projection_points;
    let (mut most, mut least, mut at) = (0.0f64, f64::INFINITY, (0, 0));
    for (a, c) in b.topology.edges() {
        let (a, c) = (a as usize, c as usize);
        let len = |p: &[[f64; 3]]| dot(sub(p[a], p[c]), sub(p[a], p[c])).sqrt();
        let s = len(&out) / len(rest);
        if s > most {
            (most, at) = (s, (a, c));
        }
        least = least.min(s);
    }
    println!(
        "{rel}: 35° bend beyond ring {m} ({turned} control points turned): largest edge stretch {most:.3} (edge {}-{}), smallest {least:.3}",
        at.0, at.1
    );
    assert!(most.is_finite() && least > 0.0, "{rel}: degenerate edges after the bend");
}

/// One module per fixture with its three (or two) tests; an attribute list
/// before a test marks it (e.g. ``).
macro_rules! fixture {
    ($name:ident, $rel:literal, neutral: [$(#[$n:meta])*], rigid: [$(#[$r:meta])*], bend: [$(#[$b:meta])*]) => {
        mod $name {
            $(#[$n])*
            #[test]
            fn binds_and_the_neutral_pose_gives_the_input_mesh() {
                super::neutral($rel)
            }
            $(#[$r])*
            #[test]
            fn rigid_motion_of_the_curvenet_moves_the_mesh_rigidly() {
                super::rigid($rel)
            }
            $(#[$b])*
            #[test]
            fn bend_beyond_the_middle_ring_gives_finite_points() {
                super::bend($rel)
            }
        }
    };
    ($name:ident, $rel:literal, neutral: [$(#[$n:meta])*], rigid: [$(#[$r:meta])*]) => {
        mod $name {
            $(#[$n])*
            #[test]
            fn binds_and_the_neutral_pose_gives_the_input_mesh() {
                super::neutral($rel)
            }
            $(#[$r])*
            #[test]
            fn rigid_motion_of_the_curvenet_moves_the_mesh_rigidly() {
                super::rigid($rel)
            }
        }
    };
}

// Every corpus fixture and hand, every check (none is ignored).
fixture!(fish_cc2, "corpus/fish_cc2.usda", neutral: [], rigid: [], bend: []);
fixture!(fish_cc3, "corpus/fish_cc3.usdc", neutral: [], rigid: [], bend: []);
fixture!(penguin_cc2, "corpus/penguin_cc2.usda", neutral: [], rigid: [], bend: []);
fixture!(penguin_cc3, "corpus/penguin_cc3.usdc", neutral: [], rigid: [], bend: []);
fixture!(fish, "corpus/fish.usdc", neutral: [], rigid: [], bend: []);
fixture!(penguin, "corpus/penguin.usda", neutral: [], rigid: [], bend: []);
fixture!(scorpion, "corpus/scorpion.usdc", neutral: [], rigid: [], bend: []);
fixture!(koala, "corpus/koala.usdc", neutral: [], rigid: [], bend: []);
fixture!(hand_1k4, "hand/hand_1k4.usda", neutral: [], rigid: []);
fixture!(hand_closed, "hand/hand_closed.usda", neutral: [], rigid: []);
fixture!(hand_lowres, "hand/hand_lowres.usda", neutral: [], rigid: []);
fixture!(hand_22k, "hand/hand_22k.usdc", neutral: [], rigid: []);
fixture!(hand_94k, "hand/hand_94k.usdc", neutral: [], rigid: []);

/// The drafted curvenets themselves (no binding): their splines' projections
/// onto the surface never cross.
#[test]
fn corpus_curves_do_not_cross_on_the_surface() {
    for rel in CORPUS {
        let stage = curvenet_schema::usd::Stage::open(fixtures_dir().join(rel)).unwrap();
        let mesh = stage.deformed_meshes().unwrap().remove(0);
        let net = stage.curvenet(&mesh.curvenets[0]).unwrap();
        let points = &mesh.projection_points;
        let topology =
            curvenet_core::PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, points.len()).unwrap();
        let bvh = curvenet_core::ClosestPointBvh::new(&topology, points).unwrap();
        let crossings = projected_crossings(&net.pool, &net.splines, &bvh, topology.mean_edge_length(points));
        assert!(crossings.is_empty(), "{rel}: splines cross: {crossings:?}");
    }
}

const CORPUS: [&str; 8] = [
    "corpus/fish.usdc",
    "corpus/fish_cc2.usda",
    "corpus/fish_cc3.usdc",
    "corpus/koala.usdc",
    "corpus/penguin.usda",
    "corpus/penguin_cc2.usda",
    "corpus/penguin_cc3.usdc",
    "corpus/scorpion.usdc",
];

#[test]
fn every_corpus_stage_of_the_manifest_is_tested() {
    let manifest = manifest();
    let listed: Vec<&String> =
        manifest["stages"].as_object().unwrap().keys().filter(|k| k.starts_with("corpus/")).collect();
    assert_eq!(listed, CORPUS);
}
