//! Frame solves on the USD fixtures: the paper's invariants and figures.

use curvenet_e2e::{bind_fixture, max_distance};

#[test]
fn every_hand_tessellation_binds_and_reproduces_the_neutral_pose() {
    for rel in [
        "hand/hand_1k4.usda",
        "hand/hand_closed.usda",
        "hand/hand_lowres.usda",
        "hand/hand_22k.usdc",
        "hand/hand_94k.usdc",
    ] {
        let t = std::time::Instant::now();
        let b = bind_fixture(rel);
        let s = b.binding().stats();
        eprintln!("{rel}: bound in {:.0} ms: {s:?} {:?}", t.elapsed().as_secs_f64() * 1e3, b.binding().timings());
        for w in b.binding().warnings() {
            eprintln!("  warning: {w}");
        }
        let pools: Vec<Vec<[f64; 3]>> = b.nets.iter().map(|n| n.pool.clone()).collect();
        let out = b.deform(&pools);
        let err = max_distance(&out, &b.mesh.projection_points);
        assert!(err <= 1e-9 * b.diagonal(), "{rel}: neutral pose moved the mesh by {err:e}");
    }
}

fn rotate(axis: [f64; 3], angle: f64, p: [f64; 3]) -> [f64; 3] {
    // Rodrigues' formula.
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let k = [axis[0] / n, axis[1] / n, axis[2] / n];
    let (c, s) = (angle.cos(), angle.sin());
    let kxp = [k[1] * p[2] - k[2] * p[1], k[2] * p[0] - k[0] * p[2], k[0] * p[1] - k[1] * p[0]];
    let kdp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
    std::array::from_fn(|i| p[i] * c + kxp[i] * s + k[i] * kdp * (1.0 - c))
}

#[test]
fn grid_rigid_motion_and_uniform_scaling_carry_the_mesh_alike() {
    let b = bind_fixture("grid/grid.usda");
    let rest = &b.mesh.projection_points;
    let motion = |p: &[f64; 3]| {
        let r = rotate([1.0, 2.0, 3.0], 30f64.to_radians(), *p);
        [r[0] + 0.3, r[1] - 0.2, r[2] + 0.5]
    };
    let want: Vec<[f64; 3]> = rest.iter().map(motion).collect();
    // The motion applied in f64 to the neutral pool: the algorithm's own error.
    let pools: Vec<Vec<[f64; 3]>> = b.nets.iter().map(|n| n.pool.iter().map(motion).collect()).collect();
    let err = max_distance(&b.deform(&pools), &want);
    eprintln!("grid rigid motion (f64 pool): max error {:.3e} x diagonal", err / b.diagonal());
    assert!(err <= 1e-6 * b.diagonal(), "rigid motion off by {err:e}");
    // Frame 2 of the fixture is the same motion stored as 32-bit floats: the
    // rounding of control points ~1e-7 apart over segments ~0.01 long perturbs
    // F by ~1e-5, which is what remains here.
    let err = max_distance(&b.deform_at(2.0), &want);
    eprintln!("grid rigid motion (frame 2, f32 pool): max error {:.3e} x diagonal", err / b.diagonal());
    assert!(err <= 1e-5 * b.diagonal(), "rigid motion (f32) off by {err:e}");
    // Frame 4: uniform scaling by 1.5 about the origin.
    let pools: Vec<Vec<[f64; 3]>> =
        b.nets.iter().map(|n| n.pool.iter().map(|p| p.map(|x| 1.5 * x)).collect()).collect();
    let want: Vec<[f64; 3]> = rest.iter().map(|p| p.map(|x| 1.5 * x)).collect();
    let err = max_distance(&b.deform(&pools), &want);
    eprintln!("grid scaling: max error {:.3e} x diagonal", err / b.diagonal());
    assert!(err <= 1e-6 * b.diagonal(), "scaling off by {err:e}");
}

/// Least-squares plane through points: (centroid, unit normal), via the
/// smallest eigenvector of the covariance (power iteration on its inverse
/// would need a solver; the cross-product of the two largest directions is enough here).
fn plane_fit(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let n = points.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|i| points.iter().map(|p| p[i]).sum::<f64>() / n);
    let mut cov = [[0.0; 3]; 3];
    for p in points {
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += (p[i] - c[i]) * (p[j] - c[j]);
            }
        }
    }
    // Smallest eigenvector by inverse iteration with a shifted Jacobi sweep:
    // use the Jacobi eigenvalue algorithm on the symmetric 3x3 matrix.
    let mut a = cov;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let (cs, sn) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = cs * akp - sn * akq;
                a[k][q] = sn * akp + cs * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = cs * apk - sn * aqk;
                a[q][k] = sn * apk + cs * aqk;
            }
            for k in 0..3 {
                let (vkp, vkq) = (v[k][p], v[k][q]);
                v[k][p] = cs * vkp - sn * vkq;
                v[k][q] = sn * vkp + cs * vkq;
            }
        }
    }
    let m = (0..3).min_by(|&i, &j| a[i][i].total_cmp(&a[j][j])).unwrap();
    (c, [v[0][m], v[1][m], v[2][m]])
}

fn plane_distance(points: &[[f64; 3]], (c, n): ([f64; 3], [f64; 3])) -> f64 {
    points
        .iter()
        .map(|p| ((p[0] - c[0]) * n[0] + (p[1] - c[1]) * n[1] + (p[2] - c[2]) * n[2]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn hinge_fig_11_each_half_stays_planar_and_the_fold_is_sharp() {
    let b = bind_fixture("grid/grid.usda");
    let rest = &b.mesh.projection_points;
    let out = b.deform_at(3.0); // control points with x > 0 rotated 90° about the y axis
    let diag = b.diagonal();
    // Inside the curvenet's span (|x|, |y| <= 0.7) and away from the fold (|x| >= 0.1).
    // Outside the span the border strip is bounded by no curve on the fold
    // line, so it bends smoothly there by design.
    let pick = |left: bool| -> Vec<[f64; 3]> {
        rest.iter()
            .zip(&out)
            .filter(|(r, _)| r[1].abs() <= 0.7 && r[0].abs() <= 0.7 && if left { r[0] <= -0.1 } else { r[0] >= 0.1 })
            .map(|(_, o)| *o)
            .collect()
    };
    let (left, right) = (pick(true), pick(false));
    let (pl, pr) = (plane_fit(&left), plane_fit(&right));
    let (dl, dr) = (plane_distance(&left, pl), plane_distance(&right, pr));
    let cos = (pl.1[0] * pr.1[0] + pl.1[1] * pr.1[1] + pl.1[2] * pr.1[2]).abs();
    eprintln!(
        "hinge: left half off its plane by {:.2e}, right by {:.2e} (x diagonal); angle between halves {:.3}°",
        dl / diag,
        dr / diag,
        cos.acos().to_degrees()
    );
    assert!(dl <= 1e-3 * diag && dr <= 1e-3 * diag, "halves not planar: {dl:e}, {dr:e}");
    assert!((cos.acos().to_degrees() - 90.0).abs() < 1.0, "the halves meet at {}°", cos.acos().to_degrees());
    // Sharp, not bowed: the vertices on the fold line (x = 0 in the rest
    // pose, where the middle curve runs along mesh edges) stay on both planes,
    // and the left half stays in z = 0 right up to the fold.
    let fold: Vec<[f64; 3]> =
        rest.iter().zip(&out).filter(|(r, _)| r[0].abs() < 1e-9 && r[1].abs() <= 0.7).map(|(_, o)| *o).collect();
    assert!(!fold.is_empty());
    let (fl, fr) = (plane_distance(&fold, pl), plane_distance(&fold, pr));
    assert!(fl <= 1e-3 * diag && fr <= 1e-3 * diag, "fold line off the planes: {fl:e}, {fr:e}");
    let near_left: Vec<[f64; 3]> = rest
        .iter()
        .zip(&out)
        .filter(|(r, _)| r[0] < 0.0 && r[0] > -0.1 && r[1].abs() <= 0.7)
        .map(|(_, o)| *o)
        .collect();
    let bow = near_left.iter().map(|p| p[2].abs()).fold(0.0, f64::max);
    eprintln!("hinge: left of the fold, max |z| = {:.2e} x diagonal", bow / diag);
    assert!(bow <= 1e-3 * diag, "the left half bows up near the fold by {bow:e}");
}

/// Volume of a closed polygon mesh (fan triangulation, divergence theorem).
fn volume(b: &curvenet_e2e::Bound, points: &[[f64; 3]]) -> f64 {
    let mut v = 0.0;
    for face in b.topology.faces() {
        let a = points[face[0] as usize];
        for k in 1..face.len() - 1 {
            let (p, q) = (points[face[k] as usize], points[face[k + 1] as usize]);
            v += a[0] * (p[1] * q[2] - p[2] * q[1]) - a[1] * (p[0] * q[2] - p[2] * q[0])
                + a[2] * (p[0] * q[1] - p[1] * q[0]);
        }
    }
    v / 6.0
}

#[test]
fn twist_fig_12_keeps_volume_within_bounds_and_is_deterministic() {
    let b = bind_fixture("cylinder/cylinder.usda");
    let v0 = volume(&b, &b.mesh.projection_points);
    for (frame, degrees, paper) in [(2.0, 90, 0.93), (3.0, 180, 0.81)] {
        let out = b.deform_at(frame);
        assert!(out.iter().flatten().all(|x| x.is_finite()), "NaN in the {degrees}° twist");
        let ratio = volume(&b, &out) / v0;
        eprintln!("twist {degrees}°: volume ratio {ratio:.4} (paper: {paper})");
        assert!((0.7..=1.05).contains(&ratio), "twist {degrees}°: volume ratio {ratio}");
        let again = b.deform_at(frame);
        assert!(out == again, "twist {degrees}°: two solves differ");
    }
}

/// Largest distance from a vertex of `a` to the surface of `b`.
fn one_sided(a: &[[f64; 3]], b_mesh: &curvenet_core::PolyMesh, b: &[[f64; 3]]) -> f64 {
    let bvh = curvenet_core::ClosestPointBvh::new(b_mesh, b).unwrap();
    a.iter().map(|p| bvh.closest_point(*p).unwrap().distance).fold(0.0, f64::max)
}

#[test]
fn tessellation_fig_8_three_meshes_deform_alike() {
    // One curvenet pose (the shot's frame 13: the index finger curled 60°)
    // on three tessellations of the hand.
    let shot = bind_fixture("shots/hand_wave/shot.usda");
    let pool = shot.stage.posed_pool(&shot.nets[0], Some(13.0)).unwrap().unwrap();
    let meshes: Vec<_> = ["hand/hand_1k4.usda", "hand/hand_closed.usda", "hand/hand_22k.usdc"]
        .iter()
        .map(|rel| {
            let b = bind_fixture(rel);
            assert_eq!(b.nets[0].pool.len(), pool.len(), "{rel}: the same curvenet");
            let out = b.deform(std::slice::from_ref(&pool));
            (rel, b, out)
        })
        .collect();
    let diag = meshes[0].1.diagonal();
    for i in 0..meshes.len() {
        for j in i + 1..meshes.len() {
            let (a, b) = (&meshes[i], &meshes[j]);
            let rest = one_sided(&a.1.mesh.projection_points, &b.1.topology, &b.1.mesh.projection_points)
                .max(one_sided(&b.1.mesh.projection_points, &a.1.topology, &a.1.mesh.projection_points));
            let posed = one_sided(&a.2, &b.1.topology, &b.2).max(one_sided(&b.2, &a.1.topology, &a.2));
            eprintln!(
                "{} vs {}: Hausdorff {:.4} x diagonal posed ({:.4} at rest)",
                a.0,
                b.0,
                posed / diag,
                rest / diag
            );
            assert!(posed <= 0.02 * diag, "{} vs {}: {:.4} of the diagonal apart", a.0, b.0, posed / diag);
        }
    }
    // The pose does move the finger (so the comparison is not vacuous).
    let moved = max_distance(&meshes[0].2, &meshes[0].1.mesh.projection_points);
    assert!(moved > 0.05 * diag, "the curl moved the mesh by only {:.3} x diagonal", moved / diag);
}
