//! `curvenet bench --export DIR` on the 1.4k hand: the MatrixMarket file is
//! read back independently of the code that wrote it, multiplied by the
//! exported solutions, and must reproduce the exported right-hand sides.
//! The same run's `--orderings` comparison is checked too.

use std::process::Command;

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// A lower-triangle symmetric MatrixMarket file: (n, 0-based (row, col, value)).
fn read_matrix_market(text: &str) -> (usize, Vec<(usize, usize, f64)>) {
    let mut lines = text.lines();
    let header = lines.next().expect("a header line");
    assert_eq!(header, "%%MatrixMarket matrix coordinate real symmetric", "header");
    let mut lines = lines.filter(|l| !l.starts_with('%'));
    let size: Vec<usize> = lines.next().expect("a size line").split_whitespace().map(|x| x.parse().unwrap()).collect();
    assert_eq!(size.len(), 3, "size line: rows columns entries");
    assert_eq!(size[0], size[1], "square");
    let n = size[0];
    let mut entries = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(f.len(), 3, "entry line `{line}`");
        let (r, c): (usize, usize) = (f[0].parse().unwrap(), f[1].parse().unwrap());
        assert!(r >= 1 && c >= 1 && r <= n && c <= n, "1-based indices in range: `{line}`");
        assert!(r >= c, "lower triangle only: `{line}`");
        entries.push((r - 1, c - 1, f[2].parse::<f64>().unwrap()));
    }
    assert_eq!(entries.len(), size[2], "entry count matches the size line");
    (n, entries)
}

fn read_f64(path: &std::path::Path) -> Vec<f64> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(bytes.len() % 8, 0);
    bytes.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap())).collect()
}

#[test]
fn exported_systems_are_solved_by_the_exported_solutions() {
    let dir = std::env::temp_dir().join(format!("curvenet-bench-export-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_curvenet"))
        .args([
            "bench",
            "--json",
            "--meshes",
            "hand_1k4",
            "--repeats",
            "1",
            "--frames",
            "2",
            "--no-corpus",
            "--orderings",
            "--export",
        ])
        .arg(&dir)
        .current_dir(repo())
        .output()
        .expect("runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the report");
    let unknowns = report["meshes"][0]["unknowns"].as_u64().unwrap() as usize;
    let bpv = report["meshes"][0]["binding_bytes_per_vertex"].as_f64().unwrap();
    assert!(bpv > 0.0 && bpv.is_finite(), "binding_bytes_per_vertex {bpv}");
    assert!(report["growth"].is_null(), "no growth row without its base mesh");
    // --orderings: both orderings factor this binding's matrix and solve alike.
    let o = &report["meshes"][0]["orderings"];
    assert_eq!((o["amd"]["ordering"].as_str(), o["metis"]["ordering"].as_str()), (Some("amd"), Some("metis")));
    for key in ["amd", "metis"] {
        assert!(o[key]["factor_nonzeros"].as_u64().unwrap() as usize >= unknowns, "{key}: {}", o[key]);
    }
    let diff = o["max_relative_difference"].as_f64().unwrap();
    assert!(diff <= 1e-10, "METIS and AMD solutions differ by {diff:e}");

    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    let meshes = manifest["meshes"].as_array().unwrap();
    assert_eq!(meshes.len(), 1);
    let m = &meshes[0];
    assert_eq!(m["mesh"], "hand_1k4");
    let n = m["n"].as_u64().unwrap() as usize;
    assert_eq!(n, unknowns, "the system has one row per unknown");
    assert_eq!(m["frame"]["index"], 1);
    assert_eq!(m["frame"]["frames"], 4);

    let (size, a) = read_matrix_market(&std::fs::read_to_string(dir.join(m["matrix"].as_str().unwrap())).unwrap());
    assert_eq!(size, n);
    assert_eq!(a.len() as u64, m["nnz"].as_u64().unwrap());
    assert!(a.iter().filter(|e| e.0 == e.1).count() == n, "every diagonal entry stored once");
    let file = |key: &str| dir.join(m[key].as_str().unwrap());
    // Each row's mesh vertex: n distinct vertices of the 1,400.
    let rows: Vec<u32> = std::fs::read(file("unknown_vertex"))
        .unwrap()
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(rows.len(), n, "one vertex per unknown");
    let mut distinct = rows.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(distinct.len(), n, "unknowns map to distinct vertices");
    assert!(rows.iter().all(|&v| v < 1400), "vertices of the 1.4k hand");
    for (rhs, sol, k) in [("rhs9", "x9", 9), ("rhs3", "x3", 3)] {
        let (b, x) = (read_f64(&file(rhs)), read_f64(&file(sol)));
        assert_eq!((b.len(), x.len()), (n * k, n * k), "{rhs}, {sol}: n×{k}");
        // A x with A symmetric from its lower triangle, columns stored one after another.
        let mut ax = vec![0.0; n * k];
        for &(r, c, v) in &a {
            for col in 0..k {
                ax[col * n + r] += v * x[col * n + c];
                if r != c {
                    ax[col * n + c] += v * x[col * n + r];
                }
            }
        }
        let scale = b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        assert!(scale > 0.0, "{rhs} is not all zeros");
        let err = ax.iter().zip(&b).fold(0.0f64, |e, (p, q)| e.max((p - q).abs()));
        assert!(err <= 1e-10 * scale, "{rhs}: max |A x − b| = {err:e} against max |b| = {scale:e}");
        // The solutions are not the right-hand sides (A is not the identity here).
        assert!(x.iter().zip(&b).any(|(p, q)| (p - q).abs() > 1e-6 * scale), "{sol} differs from {rhs}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
