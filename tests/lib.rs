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

use curvenet_core::{Binding, CurvenetInput, CurvenetLayout, Deformer, Frame, PolyMesh};
use curvenet_schema::usd::Stage;
use curvenet_schema::{CurvenetData, MeshData};

/// A fixture stage's first deformed mesh, bound to its curvenets through
/// the one way in ([`Deformer::new`]).
pub struct Bound {
    pub stage: Stage,
    pub mesh: MeshData,
    pub topology: PolyMesh,
    pub nets: Vec<CurvenetData>,
    pub deformer: Deformer,
}

/// The deformer input of a mesh and its curvenets (no blend shapes, default options).
pub use curvenet_schema::deformer_input;

/// The deformer inputs of curvenets read from a stage.
pub fn curvenet_inputs(nets: &[CurvenetData]) -> Vec<CurvenetInput<'_>> {
    nets.iter().map(CurvenetData::input).collect()
}

/// Opens `fixtures/<rel>` and binds its first deformed mesh.
pub fn bind_fixture(rel: &str) -> Bound {
    let stage = Stage::open(fixtures_dir().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    let mesh = stage.deformed_meshes().unwrap().into_iter().next().expect("a deformed mesh");
    let topology =
        PolyMesh::new(&mesh.face_vertex_counts, &mesh.face_vertex_indices, mesh.projection_points.len()).unwrap();
    let nets: Vec<CurvenetData> = mesh.curvenets.iter().map(|p| stage.curvenet(p).unwrap()).collect();
    let inputs = curvenet_inputs(&nets);
    let deformer =
        Deformer::new(&deformer_input(&mesh, &inputs)).unwrap_or_else(|e| panic!("{rel}: binding failed: {e}"));
    Bound { stage, mesh, topology, nets, deformer }
}

impl Bound {
    /// The binding (cut-mesh, factor, analysed curvenets).
    pub fn binding(&self) -> &Binding {
        self.deformer.binding()
    }

    /// The curvenets as analysed, in binding order.
    pub fn layouts(&self) -> &[CurvenetLayout] {
        self.binding().layouts()
    }

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
        let mut out = vec![[0.0; 3]; self.deformer.n_vertices()];
        self.deformer.frame(&Frame { posed: &refs, ..Default::default() }, &mut out, None).unwrap();
        out
    }

    pub fn diagonal(&self) -> f64 {
        curvenet_core::bounding_box_diagonal(&self.mesh.projection_points)
    }
}

/// Largest distance between corresponding points.
pub fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}

/// Pairs of splines of a curvenet whose projections onto the surface cross,
/// with a point near the crossing: every spline is sampled every tenth of a
/// mean edge and projected (closest points); consecutive samples in one
/// triangle make a segment in that triangle's barycentric plane (an affine
/// image of the triangle, so crossings are preserved); segments of two
/// splines in one triangle that properly intersect are a crossing, unless
/// all their ends are within half a mean edge of a knot both splines share.
/// (The same check as core/tests/draft.rs, written independently of the
/// drafter and of the binding.)
pub fn projected_crossings(
    pool: &[[f64; 3]],
    splines: &[[u32; 4]],
    bvh: &curvenet_core::ClosestPointBvh,
    edge: f64,
) -> Vec<(usize, usize, [f64; 3])> {
    type Seg = (usize, [f64; 2], [f64; 2], [f64; 3], [f64; 3]);
    let dist =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let bezier = |c: [[f64; 3]; 4], u: f64| -> [f64; 3] {
        let v = 1.0 - u;
        let w = [v * v * v, 3.0 * v * v * u, 3.0 * v * u * u, u * u * u];
        [0, 1, 2].map(|k| (0..4).map(|i| w[i] * c[i][k]).sum())
    };
    let mut by_triangle: std::collections::BTreeMap<u32, Vec<Seg>> = std::collections::BTreeMap::new();
    for (s, sp) in splines.iter().enumerate() {
        let c = sp.map(|i| pool[i as usize]);
        let polygon = dist(c[0], c[1]) + dist(c[1], c[2]) + dist(c[2], c[3]);
        let n = ((polygon / (0.1 * edge)).ceil() as usize).clamp(8, 1_000_000);
        let hits: Vec<_> = (0..=n).map(|i| bvh.closest_point(bezier(c, i as f64 / n as f64)).unwrap()).collect();
        for w in hits.windows(2) {
            if w[0].triangle == w[1].triangle {
                let uv = |h: &curvenet_core::Hit| [h.barycentric[1], h.barycentric[2]];
                by_triangle.entry(w[0].triangle).or_default().push((s, uv(&w[0]), uv(&w[1]), w[0].point, w[1].point));
            }
        }
    }
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let mut found = Vec::new();
    for segs in by_triangle.values() {
        for (i, a) in segs.iter().enumerate() {
            for b in &segs[i + 1..] {
                if a.0 == b.0 {
                    continue;
                }
                let crosses = orient(a.1, a.2, b.1) * orient(a.1, a.2, b.2) < 0.0
                    && orient(b.1, b.2, a.1) * orient(b.1, b.2, a.2) < 0.0;
                if !crosses {
                    continue;
                }
                let (sa, sb) = (splines[a.0], splines[b.0]);
                let at_shared_knot = [sa[0], sa[3]].into_iter().filter(|k| *k == sb[0] || *k == sb[3]).any(|k| {
                    let foot = bvh.closest_point(pool[k as usize]).unwrap().point;
                    [a.3, a.4, b.3, b.4].iter().all(|p| dist(*p, foot) < 0.5 * edge)
                });
                if !at_shared_knot {
                    found.push((a.0.min(b.0), a.0.max(b.0), a.3));
                }
            }
        }
    }
    found.sort_by_key(|x| (x.0, x.1));
    found.dedup_by(|x, y| (x.0, x.1) == (y.0, y.1));
    found
}
