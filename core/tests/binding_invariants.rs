//! Binding invariants (issue: cut-mesh and cut-aware Laplacian): the polygon
//! Laplacian assembled on real meshes, the cut-mesh Laplacian, polygon and
//! non-planar meshes, untouched components, and typed errors.

mod common;

use std::collections::HashMap;

use common::*;
use curvenet_core::binding::{BindOptions, BindWarning, Binding};
use curvenet_core::polygon_laplacian::{PolygonScratch, polygon_laplacian};
use curvenet_core::{Curvenet, CurvenetLayout, Error, PolyMesh, SamplingOptions};
use glam::DVec3;

fn hand() -> (PolyMesh, Vec<[f64; 3]>) {
    load_obj(&format!("{MESH_DIR}/hand_1k4.obj"))
}

/// The vertex Laplacian assembled from per-face polygon Laplacians.
fn assemble(mesh: &PolyMesh, pts: &[[f64; 3]]) -> HashMap<(u32, u32), f64> {
    let mut l = HashMap::new();
    let mut scratch = PolygonScratch::default();
    let mut lf = Vec::new();
    for face in mesh.faces() {
        let x: Vec<DVec3> = face.iter().map(|&v| DVec3::from_array(pts[v as usize])).collect();
        polygon_laplacian(&x, 1.0, &mut scratch, &mut lf).unwrap();
        let n = face.len();
        for j in 0..n {
            for k in 0..n {
                *l.entry((face[j], face[k])).or_insert(0.0) += lf[j * n + k];
            }
        }
    }
    l
}

/// The cotangent Laplacian (½ cot weights, positive semi-definite sign).
fn cotangent(mesh: &PolyMesh, pts: &[[f64; 3]]) -> HashMap<(u32, u32), f64> {
    let mut l = HashMap::new();
    for face in mesh.faces() {
        for k in 0..3 {
            let (i, j, o) = (face[k], face[(k + 1) % 3], face[(k + 2) % 3]);
            let (u, v) = (
                DVec3::from_array(pts[i as usize]) - DVec3::from_array(pts[o as usize]),
                DVec3::from_array(pts[j as usize]) - DVec3::from_array(pts[o as usize]),
            );
            let w = 0.5 * u.dot(v) / u.cross(v).length();
            *l.entry((i, j)).or_insert(0.0) -= w;
            *l.entry((j, i)).or_insert(0.0) -= w;
            *l.entry((i, i)).or_insert(0.0) += w;
            *l.entry((j, j)).or_insert(0.0) += w;
        }
    }
    l
}

#[test]
fn uncut_laplacian_is_the_cotangent_laplacian_on_the_hand_at_any_scale() {
    let (mesh, pts) = hand();
    for s in [1.0, 1e6, 1e-6] {
        let p: Vec<[f64; 3]> = pts.iter().map(|x| x.map(|c| c * s)).collect();
        let (a, b) = (assemble(&mesh, &p), cotangent(&mesh, &p));
        let scale = b.values().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = a.iter().map(|(k, v)| (v - b.get(k).copied().unwrap_or(0.0)).abs()).fold(0.0f64, f64::max);
        assert!(worst <= 1e-9 * scale, "scale {s}: differs from cotangent by {worst:e} (largest entry {scale:e})");
        // Symmetric, constants in the kernel.
        let mut row = vec![0.0; mesh.n_vertices()];
        for (&(i, j), v) in &a {
            row[i as usize] += v;
            assert!((v - a[&(j, i)]).abs() <= 1e-12 * scale);
        }
        assert!(row.iter().all(|r| r.abs() <= 1e-10 * scale));
    }
}

/// A planar mesh of quads whose interior vertices are jittered so that some
/// quads are non-convex.
fn jittered_plane(n: usize) -> (PolyMesh, Vec<[f64; 3]>, usize) {
    let (mesh, mut pts) = plane(1.0, n);
    let h = 2.0 / n as f64;
    let mut seed = 12345u64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for j in 1..n {
        for i in 1..n {
            let p = &mut pts[j * (n + 1) + i];
            p[0] += 0.45 * h * rnd();
            p[1] += 0.45 * h * rnd();
        }
    }
    let nonconvex = mesh
        .faces()
        .filter(|f| {
            (0..4).any(|k| {
                let (a, b, c) = (pts[f[k] as usize], pts[f[(k + 1) % 4] as usize], pts[f[(k + 2) % 4] as usize]);
                (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) < 0.0
            })
        })
        .count();
    (mesh, pts, nonconvex)
}

#[test]
fn linear_precision_on_planar_nonconvex_polygon_meshes() {
    let (mesh, pts, nonconvex) = jittered_plane(16);
    assert!(nonconvex > 5, "only {nonconvex} non-convex quads");
    for s in [1.0, 1e6, 1e-6] {
        let p: Vec<[f64; 3]> = pts.iter().map(|x| x.map(|c| c * s)).collect();
        let l = assemble(&mesh, &p);
        let phi: Vec<f64> = p.iter().map(|x| 0.3 * x[0] - 1.7 * x[1] + 2.0 * s).collect();
        let mut lphi = vec![0.0; p.len()];
        for (&(i, j), v) in &l {
            lphi[i as usize] += v * phi[j as usize];
        }
        let boundary = |v: usize| {
            let x = pts[v];
            x[0].abs() > 0.999 || x[1].abs() > 0.999
        };
        let worst = (0..p.len()).filter(|&v| !boundary(v)).map(|v| lphi[v].abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-9 * s, "scale {s}: L(linear) = {worst:e} at an interior vertex");
    }
}

#[test]
fn the_cut_mesh_laplacian_is_linearly_precise_and_tiles_with_cracks() {
    // A planar jittered mesh cut by a grid curvenet with dangling ends (cracks).
    let (mesh, pts, _) = jittered_plane(23);
    let net = {
        let mut b = NetBuilder::default();
        for x in [-0.4, 0.1, 0.5] {
            b.segment([x, -0.7, 0.0], [x, 0.75, 0.0], [0.0; 3]);
        }
        for y in [-0.5, 0.2] {
            b.segment([-0.8, y, 0.0], [0.85, y, 0.0], [0.0; 3]);
        }
        b
    };
    // Lines that cross must share knots: split them at the crossings.
    let net = split_at_crossings(&net);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let b = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default()).unwrap();
    let cut = b.cut_mesh();
    assert!(cut.n_cracks() > 0, "dangling curve ends make cracks");
    // Σ over the corners at each cut-vertex of (L_f φ)_corner = 0 for a linear φ,
    // except on the mesh boundary.
    let mut acc = vec![0.0; cut.n_vertices()];
    let phi = |x: DVec3| 0.3 * x.x - 1.7 * x.y + 2.0;
    let mut scale = 0.0f64;
    for f in 0..cut.n_faces() as u32 {
        let hs = cut.face_halfedges(f);
        let n = hs.len();
        let lf = b.face_laplacian(curvenet_core::ids::CutFace(f));
        for j in 0..n {
            for k in j..n {
                let d = (lf[j * n + k] - lf[k * n + j]).abs();
                assert!(d <= 1e-12 * lf[j * n + j].abs().max(1.0), "cut-face {f} not symmetric");
            }
            let row: f64 = (0..n).map(|k| lf[j * n + k]).sum();
            assert!(row.abs() <= 1e-10 * lf[j * n + j].abs().max(1e-300), "cut-face {f}: constants not in the kernel");
            let v = cut.tail(hs.start + j as u32);
            acc[v as usize] +=
                (0..n).map(|k| lf[j * n + k] * phi(cut.vertex(cut.tail(hs.start + k as u32)).pos)).sum::<f64>();
            scale = scale.max(lf[j * n + j].abs());
        }
    }
    let worst = (0..cut.n_vertices())
        .filter(|&v| {
            let p = cut.vertex(v as u32).pos;
            p.x.abs() < 0.999 && p.y.abs() < 0.999
        })
        .map(|v| acc[v].abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-9 * scale, "cut Laplacian of a linear function: {worst:e} at an interior cut-vertex");
}

/// Splits straight lines of `net` where they cross, sharing a knot there.
fn split_at_crossings(net: &NetBuilder) -> NetBuilder {
    let lines: Vec<([f64; 3], [f64; 3])> =
        net.splines.iter().map(|s| (net.points[s[0] as usize], net.points[s[3] as usize])).collect();
    let mut out = NetBuilder::default();
    for (i, &(a, b)) in lines.iter().enumerate() {
        let mut ts = vec![0.0, 1.0];
        for (j, &(c, d)) in lines.iter().enumerate() {
            if i == j {
                continue;
            }
            let (r, s) = ([b[0] - a[0], b[1] - a[1]], [d[0] - c[0], d[1] - c[1]]);
            let den = r[0] * s[1] - r[1] * s[0];
            if den.abs() < 1e-12 {
                continue;
            }
            let t = ((c[0] - a[0]) * s[1] - (c[1] - a[1]) * s[0]) / den;
            let u = ((c[0] - a[0]) * r[1] - (c[1] - a[1]) * r[0]) / den;
            if (0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u) {
                ts.push(t);
            }
        }
        ts.sort_by(f64::total_cmp);
        for w in ts.windows(2) {
            let p = |t: f64| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), 0.0];
            out.segment(p(w[0]), p(w[1]), [0.0; 3]);
        }
    }
    weld(&mut out, 1e-12);
    out
}

/// Quads with a midpoint inserted on every other row of horizontal edges
/// (pentagons), lifted to a bumpy surface (non-planar faces).
fn bumpy_pentagons(n: usize) -> (PolyMesh, Vec<[f64; 3]>) {
    let h = 2.0 / n as f64;
    let mut pts = Vec::new();
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..=n {
        for i in 0..=n {
            pts.push([-1.0 + h * i as f64, -1.0 + h * j as f64, 0.0]);
        }
    }
    // Midpoints of horizontal edges on rows j odd.
    let mut mid = HashMap::new();
    for j in (1..n).step_by(2) {
        for i in 0..n {
            mid.insert((i, j), pts.len() as u32);
            pts.push([-1.0 + h * (i as f64 + 0.5), -1.0 + h * j as f64, 0.0]);
        }
    }
    let (mut counts, mut idx) = (Vec::new(), Vec::new());
    for j in 0..n {
        for i in 0..n {
            let mut f = vec![id(i, j)];
            if let Some(&m) = mid.get(&(i, j)) {
                f.push(m);
            }
            f.push(id(i + 1, j));
            f.push(id(i + 1, j + 1));
            if let Some(&m) = mid.get(&(i, j + 1)) {
                f.push(m);
            }
            f.push(id(i, j + 1));
            counts.push(f.len() as u32);
            idx.extend(f);
        }
    }
    for p in &mut pts {
        p[2] = 0.15 * (2.0 * p[0]).sin() * (1.5 * p[1]).cos();
    }
    (PolyMesh::new(&counts, &idx, pts.len()).unwrap(), pts)
}

#[test]
fn quad_and_nonplanar_pentagon_meshes_bind_and_reproduce_rigid_motions() {
    let (pent, pent_pts) = bumpy_pentagons(14);
    assert!(pent.face_vertex_counts().any(|c| c == 5));
    let (quad, quad_pts) = plane(1.0, 17);
    for (name, mesh, pts) in [("quads", &quad, &quad_pts), ("non-planar pentagons", &pent, &pent_pts)] {
        let bvh = curvenet_core::ClosestPointBvh::new(mesh, pts).unwrap();
        let net = surface_grid(&bvh, [0.05, -0.03, 0.0], 0.18);
        let c = Curvenet::new(&net.splines, &net.points).unwrap();
        let layout = CurvenetLayout::new(&c, mesh, pts, &SamplingOptions::default()).unwrap();
        let b = Binding::new(mesh, pts, &[&layout], &BindOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let r = glam::DMat3::from_axis_angle(DVec3::new(0.2, -1.0, 0.4).normalize(), 0.9);
        let t = DVec3::new(0.1, 0.2, -0.3);
        let m = |p: &[f64; 3]| (r * DVec3::from_array(*p) + t).to_array();
        let pool: Vec<[f64; 3]> = net.points.iter().map(m).collect();
        let mut ws = b.workspace();
        let mut out = vec![[0.0; 3]; b.n_vertices()];
        b.deform(
            &curvenet_core::Frame { posed: &[Some(&pool)], rest: None, ..Default::default() },
            &mut ws,
            &mut out,
            None,
        )
        .unwrap();
        let err = out
            .iter()
            .zip(pts.iter())
            .map(|(o, p)| (DVec3::from_array(*o) - DVec3::from_array(m(p))).length())
            .fold(0.0, f64::max);
        assert!(err <= 1e-9, "{name}: rigid motion off by {err:e}");
    }
}

/// The hand with `n` small closed octahedra ("eyeballs", "buttons") in a
/// row far from the curvenet; the hand's points come first.
fn hand_and_octahedra(n: usize) -> (PolyMesh, Vec<[f64; 3]>, PolyMesh, Vec<[f64; 3]>) {
    let (hand_mesh, hand_pts) = hand();
    let mut pts = hand_pts.clone();
    let mut counts: Vec<u32> = hand_mesh.face_vertex_counts().collect();
    let mut idx = hand_mesh.face_vertex_indices().to_vec();
    let oct = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    for k in 0..n {
        let base = pts.len() as u32;
        for p in [[1., 0., 0.], [-1., 0., 0.], [0., 1., 0.], [0., -1., 0.], [0., 0., 1.], [0., 0., -1.]] {
            pts.push([3.0 + 0.2 * k as f64 + 0.05 * p[0], 0.5 + 0.05 * p[1], 0.05 * p[2]]);
        }
        for f in oct {
            counts.push(3);
            idx.extend(f.map(|v| base + v));
        }
    }
    let mesh = PolyMesh::new(&counts, &idx, pts.len()).unwrap();
    (mesh, pts, hand_mesh, hand_pts)
}

/// The hand's surface grid curvenet bound to `mesh` (the hand plus octahedra).
fn bind_hand_grid(
    mesh: &PolyMesh,
    pts: &[[f64; 3]],
    hand_mesh: &PolyMesh,
    hand_pts: &[[f64; 3]],
    strict: bool,
) -> (Result<Binding, Error>, Vec<[f64; 3]>) {
    let bvh = curvenet_core::ClosestPointBvh::new(hand_mesh, hand_pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, mesh, pts, &SamplingOptions::default()).unwrap();
    (Binding::new(mesh, pts, &[&layout], &BindOptions::default().with_strict(strict)), net.points)
}

#[test]
fn an_untouched_component_passes_through_with_a_warning_and_strict_refuses_it() {
    // A small closed "eyeball" (an octahedron) far from the curvenet.
    let (mesh, pts, hand_mesh, hand_pts) = hand_and_octahedra(1);
    let base = hand_pts.len() as u32;
    let (b, net_points) = bind_hand_grid(&mesh, &pts, &hand_mesh, &hand_pts, false);
    let b = b.unwrap();
    assert!(
        b.warnings().contains(&BindWarning::UntouchedComponents { count: 1, vertices: 6, examples: vec![(1, 6)] }),
        "{:?}",
        b.warnings()
    );
    let pool: Vec<[f64; 3]> = net_points.iter().map(|p| [p[0] + 0.1, p[1], p[2]]).collect();
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(
        &curvenet_core::Frame { posed: &[Some(&pool)], rest: None, ..Default::default() },
        &mut ws,
        &mut out,
        None,
    )
    .unwrap();
    assert_eq!(&out[base as usize..], &pts[base as usize..], "the eyeball passes through");
    assert!((out[0][0] - pts[0][0] - 0.1).abs() < 1e-9, "the hand moves with the curvenet");
    let (strict, _) = bind_hand_grid(&mesh, &pts, &hand_mesh, &hand_pts, true);
    assert_eq!(strict.unwrap_err(), Error::UntouchedComponent { component: 1, vertices: 6 });
}

#[test]
fn many_untouched_components_give_one_warning_with_their_count() {
    // Seven small octahedra ("buttons") in a row, far from the curvenet.
    let (mesh, pts, hand_mesh, hand_pts) = hand_and_octahedra(7);
    let b = bind_hand_grid(&mesh, &pts, &hand_mesh, &hand_pts, false).0.unwrap();
    let untouched: Vec<&BindWarning> =
        b.warnings().iter().filter(|w| matches!(w, BindWarning::UntouchedComponents { .. })).collect();
    let examples: Vec<(usize, usize)> = (1..=BindWarning::EXAMPLES).map(|c| (c, 6)).collect();
    assert_eq!(untouched, [&BindWarning::UntouchedComponents { count: 7, vertices: 42, examples }]);
    let message = untouched[0].to_string();
    assert!(message.starts_with("7 mesh components (42 vertices in all)") && message.ends_with(", ..."), "{message}");
}

#[test]
fn far_self_overlapping_and_nonmanifold_inputs_are_typed_errors() {
    let (mesh, pts) = hand();
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    // Far: the whole curvenet lifted 0.3 away (a quarter of the diagonal).
    let far: Vec<[f64; 3]> = net.points.iter().map(|p| [p[0], p[1], p[2] - 0.3]).collect();
    let c = Curvenet::new(&net.splines, &far).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let e = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default()).unwrap_err();
    assert!(matches!(e, Error::SampleFarFromSurface { .. }), "{e}");
    // One curvenet bound twice: refused in either mode, naming both copies
    // (bound, the second copy moved nothing: a silently wrong mesh).
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let l1 = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    for strict in [false, true] {
        let e = Binding::new(&mesh, &pts, &[&l1, &l1], &BindOptions::default().with_strict(strict)).unwrap_err();
        let Error::CurvesOverlap { segment, other } = e else { panic!("strict {strict}: {e}") };
        assert_eq!((segment.curvenet, other.curvenet), (1, 0), "{e}");
    }
    // A non-manifold mesh: a third triangle on an edge of the hand.
    let mut counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let mut idx = mesh.face_vertex_indices().to_vec();
    let f0 = mesh.face(0).to_vec();
    let mut p2 = pts.clone();
    p2.push([0.0, 0.0, 5.0]);
    counts.push(3);
    idx.extend([f0[0], f0[1], p2.len() as u32 - 1]);
    let bad = PolyMesh::new(&counts, &idx, p2.len()).unwrap();
    let e = Binding::new(&bad, &p2, &[&l1], &BindOptions::default()).unwrap_err();
    assert!(matches!(e, Error::NonManifoldEdge { .. } | Error::InconsistentOrientation { .. }), "{e}");
}

#[test]
fn two_curvenets_bind_to_one_mesh() {
    let (mesh, pts) = hand();
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let a = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    let b = surface_grid(&bvh, [0.1, 0.2, 0.0], 0.03);
    let la =
        CurvenetLayout::new(&Curvenet::new(&a.splines, &a.points).unwrap(), &mesh, &pts, &SamplingOptions::default())
            .unwrap();
    let lb =
        CurvenetLayout::new(&Curvenet::new(&b.splines, &b.points).unwrap(), &mesh, &pts, &SamplingOptions::default())
            .unwrap();
    let binding = Binding::new(&mesh, &pts, &[&la, &lb], &BindOptions::default()).unwrap();
    assert_eq!(binding.n_curvenets(), 2);
    // Move only the second curvenet: vertices near the first stay put.
    let moved: Vec<[f64; 3]> = b.points.iter().map(|p| [p[0], p[1], p[2] + 0.02]).collect();
    let mut ws = binding.workspace();
    let mut out = vec![[0.0; 3]; binding.n_vertices()];
    binding
        .deform(
            &curvenet_core::Frame { posed: &[None, Some(&moved)], rest: None, ..Default::default() },
            &mut ws,
            &mut out,
            None,
        )
        .unwrap();
    let hit_a = bvh.closest_point([-0.05, 0.45, 0.0]).unwrap();
    let va = mesh.face(hit_a.face as usize)[0] as usize;
    let hit_b = bvh.closest_point([0.1, 0.2, 0.0]).unwrap();
    let vb = mesh.face(hit_b.face as usize)[0] as usize;
    let d = |v: usize| (DVec3::from_array(out[v]) - DVec3::from_array(pts[v])).length();
    assert!(d(vb) > 1e-3, "the second curvenet's surface moves ({})", d(vb));
    assert!(d(va) < d(vb) * 0.5, "the first curvenet's surface moves less ({} vs {})", d(va), d(vb));
}
