//! The projection-pose Poisson right-hand side is a precomputed gather per
//! unknown (`binding::rhs::GradientRhs`); a frame that brings its own rest
//! pose builds the same sum face by face (paper Algorithm 1, lines 7–8).
//! With the projection pose given as that rest pose both paths must give the
//! same mesh (up to the order of the sums), on triangle and quad meshes;
//! and the unknowns' spatial numbering must not change what a frame solves
//! (rigid motions of a posed net are reproduced whatever the numbering).

mod common;

use common::*;
use curvenet_core::Frame;
use curvenet_core::binding::{BindOptions, Binding};
use curvenet_core::{ClosestPointBvh, Curvenet, CurvenetLayout, SamplingOptions};

fn bound(name: &str, center_vertex: usize) -> (Binding, Vec<[f64; 3]>, Vec<[f64; 3]>, f64) {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/{name}.obj"));
    let (lo, hi) = pts.iter().fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), p| {
        (std::array::from_fn(|k| lo[k].min(p[k])), std::array::from_fn(|k| hi[k].max(p[k])))
    });
    let diag = norm(sub(hi, lo));
    let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, pts[center_vertex], 0.03 * diag);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let b = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default())
        .unwrap_or_else(|e| panic!("{name}: binding around vertex {center_vertex}: {e}"));
    // A posed pool: the grid moved and bent (scaled to the mesh).
    let pool = net
        .points
        .iter()
        .map(|p| {
            let d = sub(*p, pts[center_vertex]);
            [p[0] + 0.01 * diag, p[1] + 3.0 * dot(d, d) / diag, p[2] - 0.005 * diag]
        })
        .collect();
    (b, pts, pool, diag)
}

#[test]
fn gathered_and_face_by_face_poisson_right_hand_sides_agree() {
    // Triangles (two hands) and quads (the fish's control cage).
    for (name, vertex) in [("hand_1k4", 700), ("hand_22k", 11000), ("fish_control_mesh", 60)] {
        let (b, pts, pool, diag) = bound(name, vertex);
        let mut ws = b.workspace();
        let n = b.n_vertices();
        let (mut gathered, mut faces) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        let posed = [Some(pool.as_slice())];
        b.deform(&Frame { posed: &posed, ..Default::default() }, &mut ws, &mut gathered, None).unwrap();
        b.deform(&Frame { posed: &posed, rest: Some(&pts), ..Default::default() }, &mut ws, &mut faces, None).unwrap();
        let moved = gathered.iter().zip(&pts).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max);
        let gap = gathered.iter().zip(&faces).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max);
        eprintln!(
            "{name}: {} unknowns, largest move {:.3e} × diag, gap {:.2e} × diag",
            b.n_unknowns(),
            moved / diag,
            gap / diag
        );
        assert!(moved > 1e-3 * diag, "{name}: the posed net moved the mesh");
        assert!(gap <= 1e-10 * diag, "{name}: gathered vs face-by-face right-hand side: {gap:e} (diag {diag})");
    }
}
