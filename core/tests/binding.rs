//! Binding invariants (paper §4.1–4.2) and frame solves (§4.3) on planes,
//! cylinders and the hand meshes.

mod common;

use common::*;
use curvenet_core::binding::{BindOptions, Binding};
use curvenet_core::{Curvenet, CurvenetLayout, PolyMesh, SamplingOptions};
use glam::DVec3;

fn layout(net: &NetBuilder, mesh: &PolyMesh, pts: &[[f64; 3]]) -> CurvenetLayout {
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    CurvenetLayout::new(&c, mesh, pts, &SamplingOptions::default()).unwrap()
}

fn bind(net: &NetBuilder, mesh: &PolyMesh, pts: &[[f64; 3]]) -> (Binding, CurvenetLayout) {
    let l = layout(net, mesh, pts);
    let b = Binding::new(mesh, pts, &[&l], &BindOptions::default()).unwrap();
    (b, l)
}

/// Cut-faces tile their parent faces: vector areas add up exactly.
fn check_tiling(b: &Binding) {
    let cut = b.cut_mesh();
    let s = b.surface();
    let mesh = s.mesh();
    let mut sums = vec![DVec3::ZERO; mesh.n_faces()];
    for f in 0..cut.n_faces() as u32 {
        let hs = cut.face_halfedges(f);
        let pts: Vec<DVec3> = hs.map(|h| cut.vertex(cut.tail(h)).pos).collect();
        sums[cut.parent(f) as usize] += curvenet_core::polygon_laplacian::vector_area(&pts);
    }
    for (f, face) in mesh.faces().enumerate() {
        let pts: Vec<DVec3> = face.iter().map(|&v| cut.vertex(v).pos).collect();
        let want = curvenet_core::polygon_laplacian::vector_area(&pts);
        assert!((sums[f] - want).length() <= 1e-9 * want.length(), "face {f}: {} vs {want}", sums[f]);
    }
}

/// Every sample is a cut-vertex, and both sides of every segment are a chain
/// of halfedges from one sample's cut-vertex to the other's.
fn check_sides(b: &Binding, l: &CurvenetLayout) {
    let cut = b.cut_mesh();
    for i in 0..l.n_samples() as u32 {
        assert!(cut.sample_vertex(i).is_some(), "sample {i} has no cut-vertex");
    }
    let mut by_segment: std::collections::HashMap<(u32, bool), Vec<u32>> = Default::default();
    for h in 0..cut.n_halfedges() as u32 {
        if let Some((s, fwd)) = cut.segment(h) {
            by_segment.entry((s, fwd)).or_default().push(h);
        }
    }
    for (s, seg) in l.sampling().segments().iter().enumerate() {
        let (a, z) = (cut.sample_vertex(seg.samples[0]).unwrap(), cut.sample_vertex(seg.samples[1]).unwrap());
        if a == z {
            continue;
        }
        for fwd in [true, false] {
            let hs =
                by_segment.get(&(s as u32, fwd)).unwrap_or_else(|| panic!("segment {s} side {fwd} has no halfedge"));
            let (mut at, end) = if fwd { (a, z) } else { (z, a) };
            for _ in 0..hs.len() {
                let h = hs
                    .iter()
                    .find(|&&h| cut.tail(h) == at)
                    .unwrap_or_else(|| panic!("segment {s}: chain breaks at {at}"));
                at = cut.head(*h);
            }
            assert_eq!(at, end, "segment {s} side {fwd}: the chain does not end at the other sample");
        }
    }
}

fn max_dist(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (DVec3::from_array(*p) - DVec3::from_array(*q)).length()).fold(0.0, f64::max)
}

fn deform(b: &Binding, pool: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(&curvenet_core::Frame { posed: &[Some(pool)], rest: None, ..Default::default() }, &mut ws, &mut out, None)
        .unwrap();
    out
}

#[test]
fn grid_on_a_plane_along_edges_and_across_faces() {
    // n = 24: the curves x, y ∈ {-1, 0, 1} run along mesh edges; n = 23: across faces.
    for n in [24, 23] {
        let (mesh, pts) = plane(3.0, n);
        let net = grid(0.0);
        let (b, l) = bind(&net, &mesh, &pts);
        check_tiling(&b);
        check_sides(&b, &l);
        let out = deform(&b, &net.points);
        let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
        let err = max_dist(&out, &pts);
        assert!(err <= 1e-9 * diag, "n = {n}: neutral pose moved the mesh by {err:e}");
    }
}

fn rotation_about(axis: [f64; 3], angle: f64) -> glam::DMat3 {
    glam::DMat3::from_axis_angle(DVec3::from_array(axis).normalize(), angle)
}

#[test]
fn rigid_motion_and_scaling_of_the_curvenet_move_the_mesh_alike() {
    for n in [24, 23] {
        let (mesh, pts) = plane(3.0, n);
        let net = grid(0.1); // larger bulges make the grid cross itself (CurvesCross)
        let (b, _) = bind(&net, &mesh, &pts);
        eprintln!("plane n={n}: {:?}", b.stats());
        let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
        let r = rotation_about([1.0, 2.0, 3.0], 0.7);
        let t = DVec3::new(0.3, -2.0, 0.5);
        let posed: Vec<[f64; 3]> = net.points.iter().map(|p| (r * DVec3::from_array(*p) + t).to_array()).collect();
        let out = deform(&b, &posed);
        let want: Vec<[f64; 3]> = pts.iter().map(|p| (r * DVec3::from_array(*p) + t).to_array()).collect();
        let err = max_dist(&out, &want);
        assert!(err <= 1e-6 * diag, "n = {n}: rigid motion off by {err:e}");
        // Without the curvenet moving, vertices far from it don't move either.
        let out = deform(&b, &net.points);
        assert!(max_dist(&out, &pts) <= 1e-9 * diag);
    }
}
