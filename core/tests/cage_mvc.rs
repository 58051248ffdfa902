//! Mean value coordinates (Ju, Schaefer, Warren 2005) of the hand's
//! vertices with respect to a coarse enclosing cage (tests/cage_common):
//! partition of unity, linear precision (an affine map of the cage is
//! reproduced on every vertex), cage vertices, edges and faces reproduce
//! themselves, and every malformed cage is refused naming the element.

mod cage_common;
mod common;

use cage_common::{diagonal, enclosing_cage};
use common::{MESH_DIR, load_obj};
use curvenet_core::Error;
use curvenet_core::cage::{Cage, CageError, Mvc};
use glam::{DMat3, DVec3};

#[test]
fn mvc_partition_of_unity_and_linear_precision_on_the_hand() {
    let (_, points) = load_obj(&format!("{MESH_DIR}/hand_22k.obj"));
    let (cage, tris) = enclosing_cage(&points, 2);
    let t = std::time::Instant::now();
    let mvc = Mvc::new(&cage, &tris, &points).unwrap();
    let c = cage.len();
    println!(
        "Φ: {} points x {} cage vertices in {:.0} ms, {:.1} MB (f64); 100k x 200 would take {:.0} MB",
        points.len(),
        c,
        t.elapsed().as_secs_f64() * 1e3,
        mvc.heap_bytes() as f64 / 1e6,
        100_000.0 * 200.0 * 8.0 / 1e6
    );
    let diag = diagonal(&points);
    // Partition of unity.
    let unity = (0..points.len()).map(|i| (mvc.row(i).iter().sum::<f64>() - 1.0).abs()).fold(0.0, f64::max);
    println!("partition of unity: max |Σφ - 1| = {unity:e}");
    assert!(unity <= 1e-10, "{unity:e}");
    // Rest: Φ·C₀ reproduces the mesh (linear precision with the identity map).
    let mut out = vec![[0.0; 3]; points.len()];
    mvc.apply(&cage, &mut out).unwrap();
    let rest = cage_common::max_dist(&out, &points);
    println!("Φ·C₀ vs the mesh: {rest:e} ({:e} x diag)", rest / diag);
    assert!(rest <= 1e-10 * diag, "{rest:e}");
    // An affine map of the cage: rotation, anisotropic scale, shear, translation.
    let a = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7)
        * DMat3::from_cols(DVec3::new(1.3, 0.0, 0.2), DVec3::new(0.1, 0.8, 0.0), DVec3::new(0.0, -0.3, 1.7));
    let b = DVec3::new(0.4, -1.2, 3.0);
    let f = |p: [f64; 3]| (a * DVec3::from_array(p) + b).to_array();
    let mapped: Vec<[f64; 3]> = cage.iter().map(|p| f(*p)).collect();
    mvc.apply(&mapped, &mut out).unwrap();
    let want: Vec<[f64; 3]> = points.iter().map(|p| f(*p)).collect();
    let err = cage_common::max_dist(&out, &want);
    println!("affine map reproduced to {err:e} ({:e} x diag)", err / diag);
    assert!(err <= 1e-10 * diag, "{err:e}");
    // Counts are checked.
    assert!(matches!(
        mvc.apply(&mapped[1..], &mut out),
        Err(Error::Cage(CageError::Count { what: "cage points", expected, got })) if expected == c && got == c - 1
    ));
}

#[test]
fn points_on_the_cage_reproduce_themselves() {
    let (_, points) = load_obj(&format!("{MESH_DIR}/hand_1k4.obj"));
    let (cage, tris) = enclosing_cage(&points, 1);
    let cage_obj = Cage::new(&cage, &tris).unwrap();
    let mut on = cage.clone();
    // Edge midpoints, face centroids and a point near (1e-13 inside) a face.
    for t in tris.iter().take(20) {
        let p: Vec<DVec3> = t.iter().map(|&i| DVec3::from_array(cage[i as usize])).collect();
        on.push(((p[0] + p[1]) / 2.0).to_array());
        on.push(((p[0] + p[1] + p[2]) / 3.0).to_array());
        on.push((0.2 * p[0] + 0.3 * p[1] + 0.5 * p[2]).to_array());
    }
    let mvc = Mvc::with_cage(cage_obj, &on).unwrap();
    for k in 0..cage.len() {
        let row = mvc.row(k);
        for (j, w) in row.iter().enumerate() {
            assert_eq!(*w, if j == k { 1.0 } else { 0.0 }, "cage vertex {k}: φ_{j} = {w}");
        }
    }
    let mut out = vec![[0.0; 3]; on.len()];
    mvc.apply(&cage, &mut out).unwrap();
    let err = cage_common::max_dist(&out, &on);
    println!("points on cage vertices, edges and faces reproduced to {err:e}");
    assert!(err <= 1e-12 * diagonal(&cage), "{err:e}");
    // On a face, only the face's three vertices have weight.
    let t = tris[0];
    let row = mvc.row(cage.len() + 1);
    for (j, w) in row.iter().enumerate() {
        if !t.contains(&(j as u32)) {
            assert_eq!(*w, 0.0);
        } else {
            assert!((w - 1.0 / 3.0).abs() < 1e-12, "{w}");
        }
    }
}

#[test]
fn malformed_cages_are_refused_naming_the_element() {
    let (cage, tris) = cage_common::icosphere(1);
    let cage: Vec<[f64; 3]> = cage.iter().map(|p| p.to_array()).collect();
    Cage::new(&cage, &tris).unwrap();
    // Open: one triangle removed.
    let err = Cage::new(&cage, &tris[1..]).unwrap_err();
    let t0 = tris[0];
    match err {
        Error::Cage(CageError::OpenEdge { a, b, .. }) => {
            assert!(t0.contains(&a) && t0.contains(&b), "edge ({a}, {b}) of the removed triangle {t0:?}")
        }
        e => panic!("{e}"),
    }
    // A flipped face.
    let mut flipped = tris.clone();
    flipped[7].swap(1, 2);
    let err = Cage::new(&cage, &flipped).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Cage(CageError::FlippedFace { face: 7, .. })
                | Error::Cage(CageError::FlippedFace { neighbour: 7, .. })
        ),
        "{err}"
    );
    println!("{err}");
    // All flipped: inside out.
    let inside_out: Vec<[u32; 3]> = tris.iter().map(|t| [t[0], t[2], t[1]]).collect();
    assert!(matches!(Cage::new(&cage, &inside_out), Err(Error::Cage(CageError::InsideOut { .. }))));
    // NaN.
    let mut nan = cage.clone();
    nan[5][1] = f64::NAN;
    assert!(matches!(
        Cage::new(&nan, &tris),
        Err(Error::Cage(CageError::NonFinite { what: "cage point", index: 5, .. }))
    ));
    // Index out of range.
    let mut bad = tris.clone();
    bad[3][2] = 999;
    let err = Cage::new(&cage, &bad).unwrap_err();
    assert_eq!(
        err,
        Error::Cage(CageError::IndexOutOfRange { face: 3, corner: 2, vertex: 999, n_vertices: cage.len() })
    );
    println!("{err}");
    // A repeated vertex, an unused vertex, a non-manifold edge.
    let mut rep = tris.clone();
    rep[2][1] = rep[2][0];
    assert!(matches!(Cage::new(&cage, &rep), Err(Error::Cage(CageError::DegenerateFace { face: 2, .. }))));
    let mut extra = cage.clone();
    extra.push([9.0, 9.0, 9.0]);
    assert_eq!(Cage::new(&extra, &tris).unwrap_err(), Error::Cage(CageError::UnusedVertex { vertex: cage.len() }));
    let mut twice = tris.clone();
    twice.push(tris[0]);
    twice.push([tris[0][0], tris[0][2], tris[0][1]]);
    assert!(matches!(Cage::new(&cage, &twice), Err(Error::Cage(CageError::NonManifoldEdge { .. }))));
    // A NaN mesh point.
    let err = Mvc::new(&cage, &tris, &[[0.0; 3], [f64::INFINITY, 0.0, 0.0]]).unwrap_err();
    assert!(matches!(err, Error::Cage(CageError::NonFinite { what: "point", index: 1, .. })), "{err}");
}

#[test]
fn a_cage_that_misses_points_or_is_too_fine_is_refused_naming_why() {
    use curvenet_core::cage::{CageError, Mvc};
    // A unit tetrahedron (outward) and a point outside it.
    let cage = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let tris = [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let points = [[0.1, 0.1, 0.1], [2.0, 2.0, 2.0], [0.2, 0.2, 0.2], [-1.0, 0.1, 0.1]];
    match Mvc::new(&cage, &tris, &points) {
        Err(curvenet_core::Error::Cage(CageError::NotEnclosing { point, outside, .. })) => {
            assert_eq!((point, outside), (1, 2));
        }
        other => panic!("{other:?}"),
    }
    // Points on the cage (a vertex, an edge midpoint, a face point) are inside.
    let on = [[1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.2, 0.2, 0.6]];
    assert!(Mvc::new(&cage, &tris, &on).is_ok());
    // A cage finer than a cage (an octahedron split 1-to-4 five times:
    // 4098 vertices) is refused before its coordinates are allocated.
    let (fine, fine_tris) = split_octahedron(5);
    assert!(fine.len() > curvenet_core::cage::MAX_CAGE_VERTICES);
    match Mvc::new(&fine, &fine_tris, &[[0.0, 0.0, 0.0]]) {
        Err(curvenet_core::Error::Cage(CageError::TooLarge { cage_vertices, .. })) => {
            assert_eq!(cage_vertices, fine.len())
        }
        other => panic!("{:?}", other.map(|_| ())),
    }
}

/// The unit octahedron, its triangles split 1-to-4 `levels` times (outward).
fn split_octahedron(levels: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut points =
        vec![[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    let mut tris: Vec<[u32; 3]> =
        vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        for t in &tris {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    let (p, q) = (points[a as usize], points[b as usize]);
                    let c: [f64; 3] = [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0, (p[2] + q[2]) / 2.0];
                    let l: f64 = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                    points.push([c[0] / l, c[1] / l, c[2] / l]);
                    points.len() as u32 - 1
                });
            }
            next.extend([[t[0], m[0], m[2]], [m[0], t[1], m[1]], [m[2], m[1], t[2]], [m[0], m[1], m[2]]]);
        }
        tris = next;
    }
    (points, tris)
}
