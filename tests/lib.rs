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

use curvenet_core::{BindOptions, Binding, Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};
use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};

/// A fixture stage's first deformed mesh, bound to its curvenets.
pub struct Bound {
    pub stage: Stage,
    pub mesh: MeshData,
    pub topology: PolyMesh,
    pub nets: Vec<CurvenetData>,
    pub layouts: Vec<CurvenetLayout>,
    pub binding: Binding,
}

/// Opens `fixtures/<rel>` and binds its first deformed mesh.
pub fn bind_fixture(rel: &str) -> Bound {
    let stage = Stage::open(fixtures_dir().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    let mesh = stage.deformed_meshes().unwrap().into_iter().next().expect("a deformed mesh");
    let topology =
        PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, mesh.projection_points.len()).unwrap();
    let nets: Vec<CurvenetData> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    let layouts: Vec<CurvenetLayout> = nets
        .iter()
        .map(|n| {
            let c = Curvenet::new(&n.splines, &n.pool).unwrap();
            CurvenetLayout::new(
                &c,
                &topology,
                &mesh.projection_points,
                &SamplingOptions::default().with_density(n.sample_density),
            )
            .unwrap_or_else(|e| panic!("{rel} {}: {e}", n.path))
        })
        .collect();
    let refs: Vec<&CurvenetLayout> = layouts.iter().collect();
    let binding = Binding::new(&topology, &mesh.projection_points, &refs, &BindOptions::default())
        .unwrap_or_else(|e| panic!("{rel}: binding failed: {e}"));
    Bound { stage, mesh, topology, nets, layouts, binding }
}

impl Bound {
    /// Deforms with the curvenets posed at `time` (their neutral pools when not articulated).
    pub fn deform_at(&self, time: f64) -> Vec<[f64; 3]> {
        let pools: Vec<Vec<[f64; 3]>> = self
            .nets
            .iter()
            .map(|n| self.stage.posed_pool(n, Some(time)).unwrap().unwrap_or_else(|| n.pool.clone()))
            .collect();
        self.deform(&pools)
    }

    pub fn deform(&self, pools: &[Vec<[f64; 3]>]) -> Vec<[f64; 3]> {
        let refs: Vec<Option<&[[f64; 3]]>> = pools.iter().map(|p| Some(p.as_slice())).collect();
        let mut ws = self.binding.workspace();
        let mut out = vec![[0.0; 3]; self.binding.n_vertices()];
        self.binding
            .deform(
                &curvenet_core::FrameInput { posed: &refs, rest: None, ..Default::default() },
                &mut ws,
                &mut out,
                None,
            )
            .unwrap();
        out
    }

    pub fn diagonal(&self) -> f64 {
        curvenet_core::mesh::bounding_box_diagonal(&self.mesh.projection_points)
    }
}

/// Largest distance between corresponding points.
pub fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}
