//! Every fixture read back with the Rust reader agrees with fixtures/manifest.json,
//! which the generator writes from its in-memory arrays. tests/python/test_fixtures.py
//! checks the same manifest through usd-core, so the two readers agree with each other.

use curvenet_e2e::{close, fixtures_dir, index_checksum, points_checksum};
use curvenet_schema::usd::Stage;
use serde_json::Value;

fn manifest() -> Value {
    let text = std::fs::read_to_string(fixtures_dir().join("manifest.json")).expect("fixtures/manifest.json exists");
    serde_json::from_str(&text).expect("manifest is JSON")
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, got {v}"))
}

fn check_close(what: &str, got: f64, want: f64, failures: &mut Vec<String>) {
    if !close(got, want) {
        failures.push(format!("{what}: Rust reads {got:.17e}, manifest says {want:.17e}"));
    }
}

#[test]
fn every_fixture_reads_back_as_the_manifest_says() {
    let manifest = manifest();
    let stages = manifest["stages"].as_object().expect("stages object");
    assert!(
        stages.len() >= 8,
        "the manifest lists {} stages; expected grid, cylinder, 5 hands and a shot",
        stages.len()
    );
    let mut failures = Vec::new();
    let mut checked_samples = 0usize;
    for (rel, want) in stages {
        let stage = Stage::open(fixtures_dir().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let range = stage.time_code_range();
        match (range, want["start"].as_f64(), want["end"].as_f64()) {
            (Some((a, b)), Some(wa), Some(wb)) => {
                check_close(&format!("{rel} start"), a, wa, &mut failures);
                check_close(&format!("{rel} end"), b, wb, &mut failures);
            }
            (None, None, None) => {}
            (got, ..) => {
                failures.push(format!("{rel}: time range {got:?}, manifest {} - {}", want["start"], want["end"]))
            }
        }

        let meshes = stage.deformed_meshes().unwrap_or_else(|e| panic!("{rel}: {e}"));
        let want_meshes = want["meshes"].as_object().expect("meshes");
        let got_paths: Vec<&str> = meshes.iter().map(|m| m.path.as_str()).collect();
        let mut want_paths: Vec<&str> = want_meshes.keys().map(String::as_str).collect();
        want_paths.sort();
        let mut sorted = got_paths.clone();
        sorted.sort();
        assert_eq!(sorted, want_paths, "{rel}: deformed meshes");
        for mesh in &meshes {
            let w = &want_meshes[&mesh.path];
            let tag = format!("{rel} {}", mesh.path);
            assert_eq!(mesh.projection_points.len() as u64, w["n_points"].as_u64().unwrap(), "{tag} n_points");
            assert_eq!(mesh.face_vertex_counts.len() as u64, w["n_faces"].as_u64().unwrap(), "{tag} n_faces");
            assert_eq!(mesh.face_vertex_indices.len() as u64, w["n_face_vertex_indices"].as_u64().unwrap(), "{tag}");
            let topo = index_checksum(mesh.face_vertex_indices.iter().copied())
                + index_checksum(mesh.face_vertex_counts.iter().copied());
            assert_eq!(topo, w["topology_checksum"].as_i64().unwrap(), "{tag} topology checksum");
            check_close(
                &format!("{tag} projection"),
                points_checksum(&mesh.projection_points),
                f(&w["projection_checksum"]),
                &mut failures,
            );
            let rest_default = stage.rest_points(mesh, None).unwrap();
            check_close(
                &format!("{tag} rest default"),
                points_checksum(&rest_default),
                f(&w["rest_default_checksum"]),
                &mut failures,
            );
            let samples = w["rest_samples"].as_array().unwrap();
            assert_eq!(mesh.rest_sample_times.len(), samples.len(), "{tag} rest sample count");
            for (t, s) in samples.iter().map(|s| (f(&s[0]), f(&s[1]))) {
                let p = stage.rest_points(mesh, Some(t)).unwrap();
                check_close(&format!("{tag} rest at {t}"), points_checksum(&p), s, &mut failures);
                checked_samples += 1;
            }
            let want_nets: Vec<&str> = w["curvenets"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
            assert_eq!(mesh.curvenets, want_nets, "{tag} curvenets");

            let want_shapes = w["blend_shapes"].as_array().unwrap();
            assert_eq!(mesh.blend_shapes.len(), want_shapes.len(), "{tag} blend shapes");
            for (b, wb) in mesh.blend_shapes.iter().zip(want_shapes) {
                assert_eq!(b.name, wb["name"].as_str().unwrap());
                assert_eq!(b.prim, wb["prim"].as_str().unwrap());
                assert_eq!(b.offsets.len() as u64, wb["n_offsets"].as_u64().unwrap());
                check_close(
                    &format!("{tag} {} offsets", b.name),
                    points_checksum(&b.offsets),
                    f(&wb["offsets_checksum"]),
                    &mut failures,
                );
                let pi = b.point_indices.as_ref().map(|p| index_checksum(p.iter().copied()));
                assert_eq!(pi, wb["point_indices_checksum"].as_i64(), "{tag} {} pointIndices", b.name);
                let wi = wb["inbetweens"].as_array().unwrap();
                assert_eq!(b.inbetweens.len(), wi.len(), "{tag} {} inbetweens", b.name);
                for (ib, wib) in b.inbetweens.iter().zip(wi) {
                    assert_eq!(ib.name, wib["name"].as_str().unwrap());
                    check_close(&format!("{tag} {} weight", ib.name), ib.weight, f(&wib["weight"]), &mut failures);
                    check_close(
                        &format!("{tag} {} inbetween", ib.name),
                        points_checksum(&ib.offsets),
                        f(&wib["offsets_checksum"]),
                        &mut failures,
                    );
                }
            }
            for ws in w["blend_shape_weights"].as_array().unwrap() {
                let t = f(&ws[0]);
                let got = stage.blend_shape_weights(mesh, Some(t)).unwrap();
                let want_w: Vec<f64> = ws[1].as_array().unwrap().iter().map(f).collect();
                assert_eq!(got.len(), want_w.len(), "{tag} weights at {t}");
                for (g, x) in got.iter().zip(&want_w) {
                    check_close(&format!("{tag} weight at {t}"), *g, *x, &mut failures);
                }
                checked_samples += 1;
            }
        }

        let want_nets = want["curvenets"].as_object().expect("curvenets");
        let nets = stage.curvenets().unwrap_or_else(|e| panic!("{rel}: {e}"));
        assert_eq!(nets.len(), want_nets.len(), "{rel}: curvenet count");
        for net in &nets {
            let w = want_nets.get(&net.path).unwrap_or_else(|| panic!("{rel}: unexpected curvenet {}", net.path));
            let tag = format!("{rel} {}", net.path);
            assert_eq!(net.pool.len() as u64, w["n_cv"].as_u64().unwrap(), "{tag} n_cv");
            assert_eq!(net.splines.len() as u64, w["n_splines"].as_u64().unwrap(), "{tag} n_splines");
            assert_eq!(
                index_checksum(net.splines.iter().flatten().copied()),
                w["indices_checksum"].as_i64().unwrap(),
                "{tag}"
            );
            check_close(&format!("{tag} density"), net.sample_density, f(&w["sample_density"]), &mut failures);
            check_close(
                &format!("{tag} cv default"),
                points_checksum(&net.pool),
                f(&w["cv_default_checksum"]),
                &mut failures,
            );
            let samples = w["cv_samples"].as_array().unwrap();
            assert_eq!(net.sample_times.len(), samples.len(), "{tag} cv sample count");
            for (t, s) in samples.iter().map(|s| (f(&s[0]), f(&s[1]))) {
                let p = stage.posed_pool(net, Some(t)).unwrap().expect("posed samples");
                check_close(&format!("{tag} cv at {t}"), points_checksum(&p), s, &mut failures);
                checked_samples += 1;
            }
        }
    }
    assert!(failures.is_empty(), "{} mismatches:\n{}", failures.len(), failures.join("\n"));
    assert!(checked_samples > 20, "only {checked_samples} time samples checked");
}

/// The `CurvenetAdjustment` prims of every fixture read back with the Rust
/// reader as the manifest says (its tangents computed by the generator on
/// its own), and stages without an `adjustments` entry have none.
#[test]
fn every_adjustment_reads_back_as_the_manifest_says() {
    use curvenet_core::Rotate;
    let manifest = manifest();
    let mut checked = 0usize;
    for (rel, want) in manifest["stages"].as_object().expect("stages object") {
        let stage = Stage::open(fixtures_dir().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let empty = serde_json::Map::new();
        let want = want.get("adjustments").map_or(&empty, |a| a.as_object().expect("adjustments object"));
        let mut seen = 0;
        for net in stage.curvenets().unwrap() {
            let list = stage.curvenet_adjustments(&net).unwrap_or_else(|e| panic!("{rel}: {e}"));
            for a in &list {
                seen += 1;
                let w = want.get(&a.path).unwrap_or_else(|| panic!("{rel}: unexpected adjustment {}", a.path));
                let tag = format!("{rel} {}", a.path);
                assert_eq!(a.curvenet, w["curvenet"].as_str().unwrap(), "{tag}");
                assert_eq!(a.knot as u64, w["knot"].as_u64().unwrap(), "{tag}");
                assert_eq!(a.attach_tangents, w["attach_tangents"].as_bool().unwrap(), "{tag}");
                let tangents: Vec<u32> =
                    w["tangents"].as_array().unwrap().iter().map(|t| t.as_u64().unwrap() as u32).collect();
                assert_eq!(a.tangents, tangents, "{tag} tangents");
                assert_eq!(a.rotate.as_deref(), w["rotate"].as_str(), "{tag} rotate");
                for (attribute, samples) in w["values"].as_object().unwrap() {
                    for s in samples.as_array().unwrap() {
                        let t = s[0].as_f64();
                        let got = stage.adjustments_at(std::slice::from_ref(&list), t).unwrap();
                        let got = got.iter().find(|g| g.knot == a.knot).unwrap();
                        let want_v = numbers_of(&s[1]);
                        let got_v: Vec<f64> = match attribute.as_str() {
                            "xformOp:translate" => got.translate.to_vec(),
                            "xformOp:scale" => got.scale.to_vec(),
                            "xformOp:rotateXYZ" => match got.rotate {
                                Rotate::EulerXyz(e) => e.to_vec(),
                                other => panic!("{tag}: {other:?}"),
                            },
                            "xformOp:orient" => match got.rotate {
                                Rotate::Quaternion(q) => q.to_vec(),
                                other => panic!("{tag}: {other:?}"),
                            },
                            "curvenet:tangentTranslates" => got.tangent_translates.as_flattened().to_vec(),
                            other => panic!("{tag}: unknown attribute {other}"),
                        };
                        assert_eq!(got_v.len(), want_v.len(), "{tag} {attribute} at {t:?}");
                        for (g, x) in got_v.iter().zip(&want_v) {
                            assert!(
                                close(*g, *x),
                                "{tag} {attribute} at {t:?}: Rust reads {got_v:?}, manifest {want_v:?}"
                            );
                        }
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(seen, want.len(), "{rel}: adjustment count");
    }
    assert!(checked >= 8, "only {checked} adjustment values checked");
}

fn numbers_of(v: &Value) -> Vec<f64> {
    match v {
        Value::Array(items) => items.iter().flat_map(numbers_of).collect(),
        other => vec![f(other)],
    }
}
