//! Surface paths between two points (issue 13): the binding must always
//! find one when both points lie on one connected component. The straightest
//! path is tried first; the fallback (shortest path in a strip of faces,
//! `Surface::trace_in_strip`) must succeed on its own for any pair of
//! points, on triangle, quad, mixed-polygon, open and thin-part meshes.

mod common;

use common::*;
use curvenet_core::PolyMesh;
use curvenet_core::binding::locate::Location;
use curvenet_core::binding::trace::{Path, PathMethod, TraceFailure};
use curvenet_core::binding::{Surface, strip, trace};
use glam::DVec3;

/// A random point of the surface: inside a face, on an edge or at a vertex.
fn random_location(s: &Surface, rng: &mut Rng) -> Location {
    let he = s.halfedges();
    match rng.below(10) {
        0 => Location::Vertex(rng.below(s.mesh().n_vertices()) as u32),
        1 => {
            let h = rng.below(he.n_halfedges()) as u32;
            s.edge_location(h, 0.05 + 0.9 * rng.unit())
        }
        _ => {
            let f = rng.below(s.mesh().n_faces()) as u32;
            let tris: Vec<(u32, [u32; 3])> = s.face_triangles(f).collect();
            let (tri, _) = tris[rng.below(tris.len())];
            let (mut u, mut v) = (rng.unit(), rng.unit());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            Location::Face { face: f, tri, bary: [1.0 - u - v, u, v] }
        }
    }
}

/// The path's structure as the cutter needs it: it starts at `a`, ends at
/// `b`, and every piece lies in a face holding both its ends. Returns its length.
fn check_path(s: &Surface, path: &Path, a: Location, b: Location, what: &str) -> f64 {
    assert_eq!(path.points.first(), Some(&a), "{what}: the path starts at a");
    assert_eq!(path.points.last(), Some(&b), "{what}: the path ends exactly at b");
    assert_eq!(path.faces.len() + 1, path.points.len(), "{what}: one face per piece");
    let mut faces = Vec::new();
    let mut length = 0.0;
    for (k, &f) in path.faces.iter().enumerate() {
        for end in [path.points[k], path.points[k + 1]] {
            s.faces_of(end, &mut faces);
            assert!(faces.contains(&f), "{what}: piece {k} lies in face {f}, which does not hold {end:?}");
        }
        length += (s.position(path.points[k + 1]) - s.position(path.points[k])).length();
    }
    let chord = (s.position(b) - s.position(a)).length();
    assert!(length >= chord * (1.0 - 1e-9), "{what}: path {length} shorter than the chord {chord}");
    length
}

fn mesh_surface(name: &str) -> Surface {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/{name}.obj"));
    Surface::new(&mesh, &pts).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn any_two_points_of_a_component_are_joined_on_every_mesh() {
    let seed = test_seed(13);
    let meshes = [
        ("hand_1k4", 300),
        ("hand_lowres", 200), // open at the wrist
        // Subdivision cages: quads, pentagons and triangles, strongly non-planar
        // (the fish's has four folded faces, split into triangles).
        ("fish_control_mesh", 300),
        ("penguin_control_mesh", 300),
        ("penguin", 200),
        ("scorpion_low_resolution", 200),
        ("fish", 100),
    ];
    let mut path = Path::default();
    for (name, pairs) in meshes {
        let s = mesh_surface(name);
        let mut rng = Rng(seed ^ name.len() as u64);
        let tol = 1e-5 * s.diagonal();
        let mut methods = [0usize; 3];
        for pair in 0..pairs {
            let (a, b) = (random_location(&s, &mut rng), random_location(&s, &mut rng));
            let what = format!("{name} pair {pair} (seed {seed}): {a:?} -> {b:?}");
            strip::trace_in_strip(&s, a, b, tol, &mut path)
                .unwrap_or_else(|e| panic!("{what}: fallback failed: {e:?}"));
            let strip_length = check_path(&s, &path, a, b, &what);
            let method =
                trace::trace(&s, a, b, tol, &mut path).unwrap_or_else(|e| panic!("{what}: trace failed: {e:?}"));
            check_path(&s, &path, a, b, &what);
            methods[method as usize] += 1;
            assert!(strip_length.is_finite());
        }
        println!(
            "{name}: {pairs} pairs joined; chord {} straightest {} fallback {}",
            methods[0], methods[1], methods[2]
        );
    }
}

#[test]
fn points_on_different_components_have_no_path() {
    // Two disjoint unit squares.
    let pts = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [3.0, 0.0, 0.0],
        [4.0, 0.0, 0.0],
        [4.0, 1.0, 0.0],
        [3.0, 1.0, 0.0],
    ];
    let mesh = PolyMesh::new(&[4, 4], &[0, 1, 2, 3, 4, 5, 6, 7], 8).unwrap();
    let s = Surface::new(&mesh, &pts).unwrap();
    let mut path = Path::default();
    assert_eq!(
        trace::trace(&s, Location::Vertex(0), Location::Vertex(6), 1e-9, &mut path),
        Err(TraceFailure::Disconnected)
    );
}

/// A band one quad wide folded by 90° across its length: the only strip is
/// the band, and its shortest path is the straight line of the unfolded band.
#[test]
fn strip_path_is_the_geodesic_of_a_folded_band() {
    let (n, width) = (20usize, 0.7);
    // Along x from 0 to 1 (n/2 quads), then up z from 0 to 1 (n/2 quads).
    let along = |s: f64, w: f64| if s <= 1.0 { [s, w, 0.0] } else { [1.0, w, s - 1.0] };
    let mut pts = Vec::new();
    for i in 0..=n {
        let s = 2.0 * i as f64 / n as f64;
        pts.push(along(s, 0.0));
        pts.push(along(s, width));
    }
    let mut idx = Vec::new();
    for i in 0..n as u32 {
        idx.extend([2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1]);
    }
    let mesh = PolyMesh::new(&vec![4; n], &idx, pts.len()).unwrap();
    let s = Surface::new(&mesh, &pts).unwrap();
    let locate = |sd: f64, w: f64| -> Location {
        let q = ((sd * n as f64 / 2.0).floor() as usize).min(n - 1) as u32;
        let p = DVec3::from_array(along(sd, w));
        // The face's triangle holding p (fan of the quad).
        for (tri, corners) in s.face_triangles(q) {
            let c = corners.map(|h| DVec3::from_array(pts[s.halfedges().tail(h) as usize]));
            let (e1, e2, d) = (c[1] - c[0], c[2] - c[0], p - c[0]);
            let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
            let (d1, d2) = (d.dot(e1), d.dot(e2));
            let den = d11 * d22 - d12 * d12;
            let (u, v) = ((d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den);
            if u >= -1e-12 && v >= -1e-12 && u + v <= 1.0 + 1e-12 {
                return Location::Face { face: q, tri, bary: [1.0 - u - v, u, v] };
            }
        }
        panic!("no triangle holds the point");
    };
    for (sa, wa, sb, wb) in [(0.13, 0.1, 1.71, 0.6), (0.5, 0.65, 1.05, 0.05), (0.02, 0.35, 1.98, 0.35)] {
        let (a, b) = (locate(sa, wa), locate(sb, wb));
        let mut path = Path::default();
        strip::trace_in_strip(&s, a, b, 1e-9, &mut path).unwrap();
        let length = check_path(&s, &path, a, b, "band");
        let geodesic = ((sb - sa).powi(2) + (wb - wa).powi(2)).sqrt();
        assert!((length - geodesic).abs() <= 1e-12, "band path {length} vs the unfolded straight line {geodesic}");
        let method = trace::trace(&s, a, b, 1e-9, &mut path).unwrap();
        assert_ne!(method, PathMethod::Chord);
    }
}
