//! The closest-point hierarchy against brute force on a real mesh, and the
//! timing of curvenet analysis + sampling on the hand meshes (printed, not
//! asserted; run with `--nocapture`).

mod common;

use std::time::Instant;

use common::*;
use curvenet_core::closest_point::{ClosestPointBvh, closest_point_on_triangle};
use curvenet_core::curvenet::{ScaledFrame, deformation_gradients_into, scaled_frames_into};
use curvenet_core::{Curvenet, CurvenetLayout, Mat3, SamplingOptions};

fn lcg(state: &mut u64) -> f64 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn agrees_with_brute_force_on_hand_1k4() {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
    assert_eq!(bvh.n_triangles(), 2796);
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    let mut state = 7u64;
    let mut checked = 0;
    for i in 0..2000 {
        // Half near the surface (a vertex plus noise), half anywhere in a box
        // around the mesh.
        let q: [f64; 3] = if i % 2 == 0 {
            let v = pts[(lcg(&mut state) * pts.len() as f64) as usize];
            std::array::from_fn(|k| v[k] + 0.02 * diag * (lcg(&mut state) - 0.5))
        } else {
            std::array::from_fn(|k| pts[0][k] + 1.5 * diag * (lcg(&mut state) - 0.5))
        };
        let hit = bvh.closest_point(q).unwrap();
        let mut best = f64::INFINITY;
        for f in mesh.faces() {
            let (_, x) = closest_point_on_triangle(q, pts[f[0] as usize], pts[f[1] as usize], pts[f[2] as usize]);
            best = best.min(norm(sub(x, q)));
        }
        assert!((hit.distance - best).abs() <= 1e-12, "query {q:?}: {} vs brute force {best}", hit.distance);
        assert!((norm(sub(hit.point, q)) - hit.distance).abs() <= 1e-15);
        let recon: [f64; 3] =
            std::array::from_fn(|k| (0..3).map(|c| hit.barycentric[c] * pts[hit.corners[c] as usize][k]).sum());
        assert!(norm(sub(recon, hit.point)) < 1e-12);
        assert_eq!(mesh.face(hit.face as usize), &hit.corners[..]);
        checked += 1;
    }
    assert_eq!(checked, 2000);
}

fn time_hand(file: &str, center_from: &[[f64; 3]]) {
    let t0 = Instant::now();
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/{file}"));
    let t_load = t0.elapsed();

    let t0 = Instant::now();
    let bvh = ClosestPointBvh::new(&mesh, &pts).unwrap();
    let t_bvh = t0.elapsed();
    let t0 = Instant::now();
    let mean_edge = mesh.mean_edge_length(&pts);
    let t_edges = t0.elapsed();

    // The same curvenet on every resolution: a grid of curves around the
    // 1k4 mesh's vertex 0, knots 1.5 mean 1k4 edges apart.
    let (m14, p14) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh14 = ClosestPointBvh::new(&m14, &p14).unwrap();
    let b = surface_grid(&bvh14, center_from[0], 1.5 * m14.mean_edge_length(&p14));
    let net = Curvenet::new(&b.splines, &b.points).unwrap();

    let t0 = Instant::now();
    let layout = CurvenetLayout::with_closest_point(&net, &bvh, mean_edge, &SamplingOptions::default()).unwrap();
    let t_analysis = t0.elapsed();

    let mut samples = vec![[0.0; 3]; layout.n_samples()];
    let mut frames = vec![[ScaledFrame::default(); 2]; layout.n_segments()];
    let mut f: Vec<[Mat3; 2]> = vec![[[[0.0; 3]; 3]; 2]; layout.n_segments()];
    let reps = 200;
    let t0 = Instant::now();
    for _ in 0..reps {
        layout.sampling().samples_into(&b.points, &mut samples).unwrap();
        scaled_frames_into(&layout, &samples, &mut frames).unwrap();
        deformation_gradients_into(&layout, layout.neutral_frames(), &frames, &mut f).unwrap();
    }
    let t_frame = t0.elapsed() / reps;
    let t0 = Instant::now();
    for _ in 0..reps {
        layout.sampling().samples_into(&b.points, &mut samples).unwrap();
    }
    let t_samples = t0.elapsed() / reps;

    println!(
        "{file}: {} faces, {} splines → {} samples, {} segments; load {:.1?}, closest-point BVH {:.1?}, \
         mean edge {:.1?}, analysis+sampling {:.2?} (total incl. BVH and edges {:.1?}); per frame \
         samples+frames+gradients {:.1?} (of which sampling {:.1?})",
        mesh.n_faces(),
        b.splines.len(),
        layout.n_samples(),
        layout.n_segments(),
        t_load,
        t_bvh,
        t_edges,
        t_analysis,
        t_bvh + t_edges + t_analysis,
        t_frame,
        t_samples,
    );

    // Query speed.
    let mut state = 3u64;
    let queries: Vec<[f64; 3]> = (0..100_000)
        .map(|_| {
            let v = pts[(lcg(&mut state) * pts.len() as f64) as usize];
            std::array::from_fn(|k| v[k] + 0.01 * (lcg(&mut state) - 0.5))
        })
        .collect();
    let t0 = Instant::now();
    let mut sum = 0.0;
    for q in &queries {
        sum += bvh.closest_point(*q).unwrap().distance;
    }
    let per = t0.elapsed() / queries.len() as u32;
    println!("{file}: closest-point query {per:.2?} each (near-surface queries; checksum {sum:.3})");
}

#[test]
fn timing_analysis_and_sampling_on_hands() {
    let (_, p14) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    for file in ["hand_1k4.obj", "hand_94k.obj"] {
        time_hand(file, &p14);
    }
}
