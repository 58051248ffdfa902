//! Shared helpers for the end-to-end tests (the `[[test]]` targets in Cargo.toml).

use std::path::PathBuf;

/// The repository root (the parent of this crate's directory).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ has a parent").to_path_buf()
}

/// The fixture directory, `<repo>/fixtures`.
pub fn fixtures_dir() -> PathBuf {
    repo_root().join("fixtures")
}

/// The checksum fixtures/manifest.json records for a point array:
/// `sum_i (i+1) * (x_i + 2 y_i + 3 z_i) / n`, in f64 from the (f32) values.
pub fn points_checksum(points: &[[f64; 3]]) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let s: f64 = points.iter().enumerate().map(|(i, p)| (i as f64 + 1.0) * (p[0] + 2.0 * p[1] + 3.0 * p[2])).sum();
    s / points.len() as f64
}

/// `sum_i (i+1) * v_i`, as the manifest's integer checksums.
pub fn index_checksum(values: impl IntoIterator<Item = u32>) -> i64 {
    values.into_iter().enumerate().map(|(i, v)| (i as i64 + 1) * v as i64).sum()
}

/// Relative comparison used for checksums: |a - b| <= 1e-9 * max(1, |b|).
pub fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}
