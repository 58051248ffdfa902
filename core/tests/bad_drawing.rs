//! Issue 13: what the binding does with badly drawn curves and degenerate
//! meshes. A curve that bridges a concavity binds along its detour with a
//! warning naming the segment (an error in strict mode); a segment whose
//! samples land on two components is left out with a warning; slivers bind;
//! meshes that cannot be bound get a typed error naming the element.

mod common;

use common::*;
use curvenet_core::binding::{BindOptions, BindWarning, Binding};
use curvenet_core::error::SegmentRef;
use curvenet_core::{Curvenet, CurvenetLayout, Error, Frame, PolyMesh, SamplingOptions};

/// A heightfield grid over [0, 1]² (`n` quads a side) at z = `height(x, y)`.
fn heightfield(n: usize, height: impl Fn(f64, f64) -> f64) -> (PolyMesh, Vec<[f64; 3]>) {
    let (mesh, pts) = plane(0.5, n);
    let pts = pts
        .iter()
        .map(|p| {
            let (x, y) = (p[0] + 0.5, p[1] + 0.5);
            [x, y, height(x, y)]
        })
        .collect();
    (mesh, pts)
}

fn bind(mesh: &PolyMesh, pts: &[[f64; 3]], net: &NetBuilder, strict: bool) -> Result<Binding, Error> {
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, mesh, pts, &SamplingOptions::default())?;
    Binding::new(mesh, pts, &[&layout], &BindOptions::default().with_strict(strict))
}

fn neutral(b: &Binding, net: &NetBuilder) -> Vec<[f64; 3]> {
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(&Frame { posed: &[Some(&net.points)], rest: None, ..Default::default() }, &mut ws, &mut out, None)
        .unwrap();
    out
}

fn max_error(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)
}

/// A trench 0.04 wide and 0.3 deep across a plate; the curve crosses it in
/// the air, so the samples above the trench project onto its two rims.
#[test]
fn a_curve_bridging_a_trench_binds_along_its_detour_with_a_warning() {
    let (mesh, pts) = heightfield(100, |x, _| if (x - 0.5).abs() < 0.02 { -0.3 } else { 0.0 });
    let mut net = NetBuilder::default();
    net.segment([0.1, 0.5, 0.002], [0.9, 0.5, 0.002], [0.0; 3]);
    let b = bind(&mesh, &pts, &net, false).unwrap();
    let detours: Vec<&BindWarning> =
        b.warnings().iter().filter(|w| matches!(w, BindWarning::SegmentDetour { .. })).collect();
    assert!(!detours.is_empty(), "the trench crossing is reported: {:?}", b.warnings());
    for w in &detours {
        let BindWarning::SegmentDetour { segment, position, path_length, segment_length, t } = w else {
            unreachable!()
        };
        println!("warning: {w}");
        assert_eq!((segment.curvenet, segment.spline), (0, 0));
        assert!((position[0] - 0.5).abs() < 0.03, "the detour is over the trench: {position:?}");
        assert!((0.0..=1.0).contains(t));
        assert!(*path_length > 0.6 && *path_length > 3.0 * segment_length, "down and up the trench: {path_length}");
    }
    assert_eq!(b.stats().detours, detours.len());
    // It deforms: the neutral pose gives the mesh back.
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    assert!(max_error(&neutral(&b, &net), &pts) <= 1e-9 * diag);
    // Strict mode refuses it, naming the segment.
    let e = bind(&mesh, &pts, &net, true).unwrap_err();
    let Error::SegmentDetour { segment, .. } = e else { panic!("{e}") };
    assert_eq!((segment.curvenet, segment.spline), (0, 0));
    println!("strict: {e}");
}

/// Two plates with a gap between them; one curve spans both.
#[test]
fn a_segment_across_two_components_is_left_out_with_a_warning() {
    let (m1, p1) = heightfield(20, |_, _| 0.0);
    let mut pts = p1.clone();
    pts.extend(p1.iter().map(|p| [p[0] + 1.02, p[1], p[2]]));
    let n = p1.len() as u32;
    let mut idx = m1.face_vertex_indices().to_vec();
    idx.extend(m1.face_vertex_indices().iter().map(|&v| v + n));
    let counts: Vec<u32> = m1.face_vertex_counts().chain(m1.face_vertex_counts()).collect();
    let mesh = PolyMesh::new(&counts, &idx, pts.len()).unwrap();
    let mut net = NetBuilder::default();
    net.segment([0.2, 0.5, 0.001], [1.8, 0.5, 0.001], [0.0; 3]);
    let b = bind(&mesh, &pts, &net, false).unwrap();
    let gaps: Vec<SegmentRef> = b
        .warnings()
        .iter()
        .filter_map(|w| match w {
            BindWarning::SegmentDetour { segment, path_length, .. } if path_length.is_infinite() => Some(*segment),
            _ => None,
        })
        .collect();
    assert_eq!(gaps.len(), 1, "one segment spans the gap: {:?}", b.warnings());
    assert_eq!(b.stats().embedding.disconnected, 1);
    println!("warning: {}", b.warnings().iter().find(|w| matches!(w, BindWarning::SegmentDetour { .. })).unwrap());
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    assert!(max_error(&neutral(&b, &net), &pts) <= 1e-9 * diag);
    // Both plates follow the curve: a translation moves both.
    let moved: Vec<[f64; 3]> = net.points.iter().map(|p| [p[0], p[1] + 0.25, p[2]]).collect();
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(&Frame { posed: &[Some(&moved)], rest: None, ..Default::default() }, &mut ws, &mut out, None).unwrap();
    let shifted: Vec<[f64; 3]> = pts.iter().map(|p| [p[0], p[1] + 0.25, p[2]]).collect();
    assert!(max_error(&out, &shifted) <= 1e-9 * diag);
    assert!(matches!(bind(&mesh, &pts, &net, true), Err(Error::SegmentDetour { .. })));
}

/// Triangles of aspect ratio up to 1e5 bind and reproduce the mesh.
#[test]
fn slivers_bind() {
    let n = 30;
    let (quads, pts) = heightfield(n, |x, y| 0.1 * (3.0 * x).sin() * (2.0 * y).cos());
    // Split every quad into two triangles, then squash one row of vertices
    // onto the next row up to 1e-5 of the spacing: that row's triangles become slivers.
    let mut idx = Vec::new();
    for q in quads.faces() {
        idx.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
    }
    let mut pts = pts;
    let h = 1.0 / n as f64;
    for p in pts.iter_mut() {
        if (p[1] - 0.5).abs() < 1e-9 {
            p[1] += h * (1.0 - 1e-5);
            p[2] = 0.1 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos();
        }
    }
    let mesh = PolyMesh::new(&vec![3; idx.len() / 3], &idx, pts.len()).unwrap();
    let mut net = NetBuilder::default();
    net.segment([0.1, 0.2, 0.2], [0.9, 0.85, 0.2], [0.0; 3]);
    net.segment([0.15, 0.8, 0.2], [0.85, 0.25, 0.2], [0.0; 3]);
    // Project the curves onto the surface height.
    for p in &mut net.points {
        p[2] = 0.1 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos() + 0.001;
    }
    // The two lines cross: split them at their crossing with a shared knot.
    let net = split_crossing(&net);
    let b = bind(&mesh, &pts, &net, false).unwrap_or_else(|e| panic!("slivers: {e}"));
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    let e = max_error(&neutral(&b, &net), &pts);
    println!("slivers: neutral pose off by {:.2e} of the diagonal", e / diag);
    assert!(e <= 1e-9 * diag);
}

/// Two straight splines that cross, rebuilt as four splines meeting at a shared knot.
fn split_crossing(net: &NetBuilder) -> NetBuilder {
    let [a0, _, _, a1] = net.splines[0].map(|i| net.points[i as usize]);
    let [b0, _, _, b1] = net.splines[1].map(|i| net.points[i as usize]);
    // Intersection in xy.
    let (d1, d2) = (sub(a1, a0), sub(b1, b0));
    let den = d1[0] * d2[1] - d1[1] * d2[0];
    let s = ((b0[0] - a0[0]) * d2[1] - (b0[1] - a0[1]) * d2[0]) / den;
    let x = [a0[0] + s * d1[0], a0[1] + s * d1[1], 0.5 * (a0[2] + a1[2])];
    let mut out = NetBuilder::default();
    for (p, q) in [(a0, x), (x, a1), (b0, x), (x, b1)] {
        out.segment(p, q, [0.0; 3]);
    }
    out
}

#[test]
fn degenerate_meshes_are_typed_errors_naming_the_element() {
    let (mesh, pts) = heightfield(10, |_, _| 0.0);
    let mut net = NetBuilder::default();
    net.segment([0.2, 0.5, 0.001], [0.8, 0.5, 0.001], [0.0; 3]);
    let counts: Vec<u32> = mesh.face_vertex_counts().collect();
    let idx = mesh.face_vertex_indices().to_vec();
    // Coincident vertices: vertex 12 moved onto vertex 13. The faces sharing
    // their edge now have a zero-length edge: named with both vertices.
    let mut p = pts.clone();
    p[12] = p[13];
    let e = bind(&mesh, &p, &net, false).unwrap_err();
    let Error::CoincidentFaceVertices { face, a, b } = e else { panic!("{e}") };
    assert!([a, b] == [12, 13] || [a, b] == [13, 12], "{e}");
    assert!(mesh.face(face).contains(&12) && mesh.face(face).contains(&13), "{e}");
    println!("coincident vertices: {e}");
    // Coincident vertices that share no face (two components touching at a
    // point, a common modelling accident) bind.
    let (m1, p1) = heightfield(6, |_, _| 0.0);
    let mut p2 = p1.clone();
    p2.extend(p1.iter().map(|q| [q[0] + 1.0, q[1], q[2]])); // the right column of one meets the left of the other
    let k = p1.len() as u32;
    let mut i2 = m1.face_vertex_indices().to_vec();
    i2.extend(m1.face_vertex_indices().iter().map(|&v| v + k));
    let c2: Vec<u32> = m1.face_vertex_counts().chain(m1.face_vertex_counts()).collect();
    let touching = PolyMesh::new(&c2, &i2, p2.len()).unwrap();
    let mut across = NetBuilder::default();
    across.segment([0.2, 0.5, 0.001], [0.8, 0.5, 0.001], [0.0; 3]);
    across.segment([1.2, 0.5, 0.001], [1.8, 0.5, 0.001], [0.0; 3]);
    let b = bind(&touching, &p2, &across, false).unwrap_or_else(|e| panic!("touching components: {e}"));
    assert!(max_error(&neutral(&b, &across), &p2) <= 1e-9);
    // A zero-area face: a triangle fan whose middle vertex sits on its neighbour.
    let mut tri_idx = Vec::new();
    for q in mesh.faces() {
        tri_idx.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
    }
    let tris = PolyMesh::new(&vec![3; tri_idx.len() / 3], &tri_idx, pts.len()).unwrap();
    let mut p = pts.clone();
    p[12] = p[13];
    let e = bind(&tris, &p, &net, false).unwrap_err();
    let Error::CoincidentFaceVertices { face, .. } = e else { panic!("{e}") };
    assert!(tris.face(face).contains(&12), "the error names a face at the collapsed vertex: face {face}");
    // A zero-area triangle with distinct corners: A, B and M on AB (face 3)
    // beside a unit square cut into triangles at M.
    let sq = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 0.0]];
    let m = PolyMesh::new(&[3, 3, 3, 3], &[0, 4, 3, 4, 1, 2, 4, 2, 3, 0, 1, 4], 5).unwrap();
    let e = bind(&m, &sq, &net, false).unwrap_err();
    assert!(matches!(e, Error::ZeroAreaFace { face: 3, .. }), "{e}");
    println!("zero area: {e}");
    // A face repeating a vertex.
    let mut bad = idx.clone();
    bad[4 * 7 + 2] = bad[4 * 7];
    let e = PolyMesh::new(&counts, &bad, pts.len()).and_then(|m| bind(&m, &pts, &net, false).map(|_| ())).unwrap_err();
    assert!(matches!(e, Error::RepeatedFaceVertex { face: 7, .. }), "{e}");
    println!("repeated vertex: {e}");
    // A non-manifold vertex: two plates touching at one corner.
    let (m1, p1) = heightfield(4, |_, _| 0.0);
    let mut p2 = p1.clone();
    p2.extend(p1.iter().map(|q| [q[0] + 1.0, q[1] + 1.0, q[2]]));
    let n = p1.len() as u32;
    let corner = 4 * 5 + 4; // (1, 1) of the first plate
    let mut i2 = m1.face_vertex_indices().to_vec();
    i2.extend(m1.face_vertex_indices().iter().map(|&v| if v == 0 { corner } else { v + n }));
    let c2: Vec<u32> = m1.face_vertex_counts().chain(m1.face_vertex_counts()).collect();
    let bowtie = PolyMesh::new(&c2, &i2, p2.len()).unwrap();
    let e = bind(&bowtie, &p2, &net, false).unwrap_err();
    assert!(matches!(e, Error::NonManifoldVertex { vertex, .. } if vertex == corner), "{e}");
    println!("non-manifold vertex: {e}");
}

/// A sliver that passes the zero-area check (a corner of the hand's face
/// 10 moved to within 1e-9 of its height of the opposite edge's midpoint;
/// found by the hostile review through the service) makes the
/// Laplacian's factorisation fail: a typed error naming the sliver as the
/// thinnest face, not an internal one.
#[test]
fn a_sliver_face_is_named_when_the_factorisation_fails() {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    bind(&mesh, &pts, &net, false).unwrap_or_else(|e| panic!("the hand as it is: {e}"));
    // Face 10's corner c goes almost onto the midpoint of its opposite edge.
    let face = 10;
    let f = mesh.face(face);
    let (c, a, b) = (f[2], f[0], f[1]);
    let mut p = pts.clone();
    let mid: [f64; 3] = std::array::from_fn(|k| 0.5 * (pts[a as usize][k] + pts[b as usize][k]));
    p[c as usize] = std::array::from_fn(|k| mid[k] + 1e-9 * (pts[c as usize][k] - mid[k]));
    let e = bind(&mesh, &p, &net, false).map(|_| ()).unwrap_err();
    println!("sliver: {e}");
    let Error::IllConditionedFace { face: named, vertices, angle_deg, .. } = e else { panic!("{e}") };
    assert_eq!(named, face, "the sliver is named");
    assert!(vertices.contains(&c) && angle_deg < 1e-6, "{vertices:?} {angle_deg}");
}

/// The fish's subdivision cage has four quads and pentagons so warped that
/// they fold over themselves in their own plane: they are split into
/// triangles (named in a warning) and the cage binds like any mesh.
#[test]
fn a_cage_with_folded_faces_binds_with_them_split() {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/fish_control_mesh.obj"));
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    // A grid of curves on the side of the body, a tenth of the diagonal wide.
    // Centred on the largest face (the middle of the body's side).
    let face_area = |f: &[u32]| {
        let p: Vec<glam::DVec3> = f.iter().map(|&v| glam::DVec3::from_array(pts[v as usize])).collect();
        curvenet_core::polygon_laplacian::vector_area(&p).length()
    };
    let big = mesh.faces().max_by(|a, b| face_area(a).total_cmp(&face_area(b))).unwrap();
    let c: [f64; 3] = std::array::from_fn(|k| big.iter().map(|&v| pts[v as usize][k]).sum::<f64>() / big.len() as f64);
    let net = surface_grid(&bvh, c, 0.03 * diag);
    let b = bind(&mesh, &pts, &net, false).unwrap_or_else(|e| panic!("fish cage: {e}"));
    let split: Vec<&BindWarning> =
        b.warnings().iter().filter(|w| matches!(w, BindWarning::FacesSplit { .. })).collect();
    assert_eq!(split.len(), 1, "{:?}", b.warnings());
    let BindWarning::FacesSplit { faces } = split[0] else { unreachable!() };
    assert_eq!(faces, &[18, 19, 74, 75]);
    println!("warning: {}", split[0]);
    assert!(b.surface().mesh().n_faces() > mesh.n_faces());
    assert!(max_error(&neutral(&b, &net), &pts) <= 1e-9 * diag);
    let rot = rotation(normalize([0.2, 1.0, -0.4]), 0.7);
    let posed: Vec<[f64; 3]> = net.points.iter().map(|&p| apply(&rot, p)).collect();
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(&Frame { posed: &[Some(&posed)], rest: None, ..Default::default() }, &mut ws, &mut out, None).unwrap();
    let moved: Vec<[f64; 3]> = pts.iter().map(|&p| apply(&rot, p)).collect();
    let e = max_error(&out, &moved);
    println!("fish cage: a rotation of the curvenet moves the cage {:.1e} of the diagonal off the rotation", e / diag);
    assert!(e <= 1e-6 * diag);
}

/// Two lines 0.02 apart in height cross when projected onto a plate: their
/// paths meet at a point that is no shared knot. They bind as if they met
/// there, with a warning naming both; strict mode refuses.
#[test]
fn curves_whose_projections_cross_bind_with_a_warning() {
    let (mesh, pts) = heightfield(20, |_, _| 0.0);
    let mut net = NetBuilder::default();
    net.segment([0.1, 0.2, 0.01], [0.9, 0.8, 0.01], [0.0; 3]);
    net.segment([0.1, 0.8, 0.03], [0.9, 0.2, 0.03], [0.0; 3]);
    let b = bind(&mesh, &pts, &net, false).unwrap();
    let touches: Vec<&BindWarning> =
        b.warnings().iter().filter(|w| matches!(w, BindWarning::CurvesTouch { .. })).collect();
    assert_eq!(touches.len(), 1, "{:?}", b.warnings());
    let BindWarning::CurvesTouch { count, examples } = touches[0] else { unreachable!() };
    println!("warning: {}", touches[0]);
    assert_eq!(*count, 1);
    let (s, o, at) = examples[0];
    assert_eq!([s.spline.min(o.spline), s.spline.max(o.spline)], [0, 1]);
    assert!((at[0] - 0.5).abs() < 1e-6 && (at[1] - 0.5).abs() < 1e-6, "they cross at the middle: {at:?}");
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    assert!(max_error(&neutral(&b, &net), &pts) <= 1e-9 * diag);
    // A rotation about the plate's normal (straight curves with no
    // intersection carry only their tangent's rotation, as in the paper).
    let rot = rotation([0.0, 0.0, 1.0], 0.9);
    let posed: Vec<[f64; 3]> = net.points.iter().map(|&p| apply(&rot, p)).collect();
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    b.deform(&Frame { posed: &[Some(&posed)], rest: None, ..Default::default() }, &mut ws, &mut out, None).unwrap();
    let moved: Vec<[f64; 3]> = pts.iter().map(|&p| apply(&rot, p)).collect();
    let e = max_error(&out, &moved);
    assert!(e <= 1e-9 * diag, "a rotation of both lines rotates the plate: {e:e}");
    assert!(matches!(bind(&mesh, &pts, &net, true), Err(Error::CurvesCross { .. })));
    // Two curves drawn over one stretch (as on either side of a thin part)
    // bind along it with a warning; strict mode refuses, naming both.
    let mut twice = NetBuilder::default();
    twice.segment([0.1, 0.5, 0.01], [0.7, 0.5, 0.01], [0.0; 3]);
    twice.segment([0.3, 0.5, 0.02], [0.9, 0.5, 0.02], [0.0; 3]);
    let b = bind(&mesh, &pts, &twice, false).unwrap();
    assert!(b.warnings().iter().any(|w| matches!(w, BindWarning::CurvesTouch { .. })), "{:?}", b.warnings());
    assert!(b.cut_mesh().touches().iter().any(|t| t.stretch));
    assert!(max_error(&neutral(&b, &twice), &pts) <= 1e-9 * diag);
    let e = bind(&mesh, &pts, &twice, true).unwrap_err();
    assert!(matches!(e, Error::CurvesOverlap { .. }), "{e}");
    println!("overlap (strict): {e}");
}

/// A curve that doubles back in height as it goes (its projection runs
/// forwards, back over itself, and forwards again) binds: a curve may fold
/// over itself in projection, as curves drawn beyond a concavity's centre
/// of curvature do.
#[test]
fn a_curve_folding_back_over_itself_in_projection_binds() {
    let (mesh, pts) = heightfield(20, |_, _| 0.0);
    let mut net = NetBuilder::default();
    // Forwards to b, back to c above the first stretch, forwards again across it.
    let (a, b, c, d) = ([0.1, 0.47, 0.01], [0.6, 0.53, 0.01], [0.4, 0.56, 0.05], [0.9, 0.45, 0.05]);
    let lerp = |p: [f64; 3], q: [f64; 3], t: f64| std::array::from_fn(|k| p[k] + t * (q[k] - p[k]));
    net.spline(a, lerp(a, b, 1.0 / 3.0), lerp(a, b, 2.0 / 3.0), b);
    net.spline(b, lerp(b, c, 1.0 / 3.0), lerp(b, c, 2.0 / 3.0), c);
    net.spline(c, lerp(c, d, 1.0 / 3.0), lerp(c, d, 2.0 / 3.0), d);
    let bound = bind(&mesh, &pts, &net, false).unwrap_or_else(|e| panic!("a folded curve: {e}"));
    assert!(bound.warnings().iter().any(|w| matches!(w, BindWarning::CurvesTouch { .. })), "{:?}", bound.warnings());
    let diag = curvenet_core::mesh::bounding_box_diagonal(&pts);
    assert!(max_error(&neutral(&bound, &net), &pts) <= 1e-9 * diag);
    let moved: Vec<[f64; 3]> = net.points.iter().map(|p| [p[0] + 0.1, p[1] - 0.2, p[2] + 0.3]).collect();
    let mut ws = bound.workspace();
    let mut out = vec![[0.0; 3]; bound.n_vertices()];
    bound.deform(&Frame { posed: &[Some(&moved)], rest: None, ..Default::default() }, &mut ws, &mut out, None).unwrap();
    let shifted: Vec<[f64; 3]> = pts.iter().map(|p| [p[0] + 0.1, p[1] - 0.2, p[2] + 0.3]).collect();
    assert!(max_error(&out, &shifted) <= 1e-9 * diag);
}

/// A spline drawn twice (the same four control points again, as a
/// copy-paste leaves it) and a curvenet bound twice are refused naming both
/// copies: bound, the second copy would silently move nothing.
#[test]
fn a_curve_drawn_twice_and_a_curvenet_bound_twice_are_refused() {
    let (mesh, pts) = heightfield(20, |_, _| 0.0);
    let mut net = NetBuilder::default();
    net.spline([0.1, 0.5, 0.01], [0.3, 0.55, 0.01], [0.6, 0.45, 0.01], [0.9, 0.5, 0.01]);
    net.segment([0.5, 0.1, 0.01], [0.5, 0.9, 0.01], [0.0; 3]);
    assert!(bind(&mesh, &pts, &net, false).is_ok(), "the curvenet binds once");
    // The first spline again, reversed, over copies of its points.
    let mut doubled = NetBuilder::default();
    doubled.points = net.points.clone();
    doubled.splines = net.splines.clone();
    let n = doubled.points.len() as u32;
    doubled.points.extend(net.points.clone());
    let mut copy = net.splines[0].map(|i| i + n);
    copy.reverse();
    doubled.splines.push(copy);
    let e = bind(&mesh, &pts, &doubled, false).unwrap_err();
    let Error::CurvesOverlap { segment, other } = e else { panic!("{e}") };
    assert_eq!((segment.curvenet, segment.spline, other.curvenet, other.spline), (0, 2, 0, 0), "{e}");
    println!("drawn twice: {e}");
    // One curvenet bound twice.
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let e = Binding::new(&mesh, &pts, &[&layout, &layout], &BindOptions::default()).unwrap_err();
    let Error::CurvesOverlap { segment, other } = e else { panic!("{e}") };
    assert_eq!((segment.curvenet, other.curvenet), (1, 0), "{e}");
    println!("bound twice: {e}");
}

/// A whole curve far shorter than the snapping tolerance drawn over a mesh
/// vertex or edge: its samples all land on one point of the surface, so it
/// has nothing to cut along. Refused naming the curve's spline and the
/// point (it was an internal error); the same curve inside a face is an
/// island and binds.
#[test]
fn a_curve_collapsing_onto_one_surface_point_is_refused_naming_it() {
    let (mesh, pts) = heightfield(20, |_, _| 0.0);
    // Over vertex (0.5, 0.5) and over the midpoint of an edge, alone and beside a curve that binds.
    for (at, len) in [([0.5, 0.5], 1e-7), ([0.525, 0.5], 1e-7), ([0.5, 0.5], 1e-5)] {
        for beside in [false, true] {
            let mut net = NetBuilder::default();
            if beside {
                net.segment([0.1, 0.3, 0.01], [0.9, 0.3, 0.01], [0.0; 3]);
            }
            let tiny = net.segment([at[0], at[1], 0.001], [at[0] + len, at[1], 0.001], [0.0; 3]);
            let e = bind(&mesh, &pts, &net, false).unwrap_err();
            let Error::CurveCollapsedOnSurface { segment, position } = e else {
                panic!("tiny curve at {at:?} (length {len:e}, beside another: {beside}): {e}")
            };
            assert_eq!((segment.curvenet, segment.spline), (0, tiny as u32), "{e}");
            assert!((position[0] - at[0]).abs() < 1e-3 && (position[1] - at[1]).abs() < 1e-3, "{e}");
            println!("{e}");
        }
    }
    // Inside a face: removed as an island, the rest binds.
    let mut net = NetBuilder::default();
    net.segment([0.1, 0.3, 0.01], [0.9, 0.3, 0.01], [0.0; 3]);
    net.segment([0.53, 0.47, 0.001], [0.53 + 1e-7, 0.47, 0.001], [0.0; 3]);
    bind(&mesh, &pts, &net, false).unwrap();
}
