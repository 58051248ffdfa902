//! The fill-reducing ordering changes nothing but speed (METIS and AMD
//! factors solve a real binding's system to the same answer), and the
//! binding's exported systems are the ones a frame solves.

mod common;

use common::*;
use curvenet_core::binding::{BindOptions, Binding};
use curvenet_core::cholesky::{Cholesky, Ordering, SymmetricTriplets};
use curvenet_core::{Curvenet, CurvenetLayout, SamplingOptions};

fn hand_binding(name: &str) -> (Binding, Vec<[f64; 3]>) {
    let (mesh, pts) = load_obj(&format!("{MESH_DIR}/{name}.obj"));
    let bvh = curvenet_core::ClosestPointBvh::new(&mesh, &pts).unwrap();
    let net = surface_grid(&bvh, [-0.05, 0.45, 0.0], 0.03);
    let c = Curvenet::new(&net.splines, &net.points).unwrap();
    let layout = CurvenetLayout::new(&c, &mesh, &pts, &SamplingOptions::default()).unwrap();
    let b = Binding::new(&mesh, &pts, &[&layout], &BindOptions::default()).unwrap();
    // A posed pool: the grid moved and bent a little.
    let pool = net.points.iter().map(|p| [p[0] + 0.01, p[1] + 0.3 * (p[0] + 0.05).powi(2), p[2] - 0.005]).collect();
    (b, pool)
}

/// `A x` for a lower-triangle symmetric `a` and column-major `x` (n×k).
fn multiply(a: &SymmetricTriplets, x: &[f64], k: usize) -> Vec<f64> {
    let n = a.n;
    let mut y = vec![0.0; n * k];
    for &(r, c, v) in &a.entries {
        for col in 0..k {
            y[col * n + r as usize] += v * x[col * n + c as usize];
            if r != c {
                y[col * n + c as usize] += v * x[col * n + r as usize];
            }
        }
    }
    y
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn relative_residual(a: &SymmetricTriplets, x: &[f64], b: &[f64], k: usize) -> f64 {
    let ax = multiply(a, x, k);
    let diff: Vec<f64> = ax.iter().zip(b).map(|(p, q)| p - q).collect();
    max_abs(&diff) / max_abs(b)
}

#[test]
fn metis_and_amd_solve_a_hand_binding_alike() {
    let (b, _) = hand_binding("hand_22k");
    let a = b.system_matrix();
    assert_eq!(a.n, b.n_unknowns());
    assert!(a.entries.iter().all(|&(r, c, _)| r >= c), "lower triangle only");
    let amd = Cholesky::with_ordering(&a, Ordering::Amd).unwrap();
    let metis = Cholesky::with_ordering(&a, Ordering::Metis).unwrap();
    assert_eq!(amd.ordering(), Ordering::Amd);
    assert_eq!(metis.ordering(), Ordering::Metis, "METIS ordered the hand (no fallback to AMD)");
    // The factor the binding holds is AMD's (the module docs give the
    // measurement), with the unknowns renumbered into its order: its
    // permutation is the identity. AMD run again on that renumbered matrix
    // finds a slightly different order (it is not idempotent), so the fill
    // is compared, not equated.
    assert_eq!(b.factor().ordering(), Ordering::Amd);
    assert!(b.factor().in_factor_order());
    assert!(b.factor().permutation().iter().enumerate().all(|(k, &p)| p as usize == k));
    let fill = b.factor().nnz() as f64 / amd.nnz() as f64;
    eprintln!(
        "binding's factor {} nonzeros, AMD of its renumbered matrix {} ({fill:.3}×)",
        b.factor().nnz(),
        amd.nnz()
    );
    assert!((0.9..=1.1).contains(&fill), "fill {fill}");
    // Same right-hand sides, both factors: solutions agree to 1e-10 relative.
    let n = a.n;
    let mut state = 12345u64;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let rhs: Vec<[f64; 9]> = (0..n).map(|_| std::array::from_fn(|_| rnd())).collect();
    let (mut xa, mut xm, mut work) = (rhs.clone(), rhs.clone(), vec![[0.0; 9]; n]);
    amd.solve_in_place(&mut xa, &mut work);
    metis.solve_in_place(&mut xm, &mut work);
    // The binding's own factor solves it alike too.
    let mut xb = rhs.clone();
    b.solve_in_place(&mut xb, &mut work);
    let gap = xa.iter().flatten().zip(xb.iter().flatten()).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    let size = xa.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(gap <= 1e-10 * size, "binding's factor vs AMD: {gap:e} against {size:e}");
    let scale = xa.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = xa.iter().flatten().zip(xm.iter().flatten()).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    assert!(diff <= 1e-10 * scale, "METIS vs AMD: max difference {diff:e}, solution scale {scale:e}");
    // And both actually solve the system.
    let col_major = |x: &[[f64; 9]]| {
        let mut out = vec![0.0; n * 9];
        for (u, row) in x.iter().enumerate() {
            for c in 0..9 {
                out[c * n + u] = row[c];
            }
        }
        out
    };
    assert!(relative_residual(&a, &col_major(&xm), &col_major(&rhs), 9) <= 1e-10);
}

#[test]
fn a_frames_exported_systems_are_the_ones_it_solves() {
    let (b, pool) = hand_binding("hand_1k4");
    let a = b.system_matrix();
    let sys = b.frame_system(&[Some(&pool)]).unwrap();
    let n = b.n_unknowns();
    assert_eq!((sys.n, sys.rhs9.len(), sys.x9.len(), sys.rhs3.len(), sys.x3.len()), (n, 9 * n, 9 * n, 3 * n, 3 * n));
    assert!(max_abs(&sys.rhs9) > 0.0 && max_abs(&sys.rhs3) > 0.0, "non-trivial right-hand sides");
    // The exported matrix times the recorded solutions gives the recorded right-hand sides.
    let r9 = relative_residual(&a, &sys.x9, &sys.rhs9, 9);
    let r3 = relative_residual(&a, &sys.x3, &sys.rhs3, 3);
    assert!(r9 <= 1e-10 && r3 <= 1e-10, "residuals {r9:e}, {r3:e}");
    // The recorded positions are the frame's output at the unknowns' vertices.
    let mut ws = b.workspace();
    let mut out = vec![[0.0; 3]; b.n_vertices()];
    let input = curvenet_core::Frame { posed: &[Some(&pool)], ..Default::default() };
    b.deform(&input, &mut ws, &mut out, None).unwrap();
    for u in 0..n {
        let v = b.unknown_vertex(curvenet_core::ids::Unknown(u as u32)).index();
        for c in 0..3 {
            assert_eq!(sys.x3[c * n + u], out[v][c], "unknown {u}, coordinate {c}");
        }
    }
    // Recording stops with the frame: a later frame on this thread records nothing.
    let again = b.frame_system(&[Some(&pool)]).unwrap();
    assert_eq!(again, sys, "the same frame exports the same systems");
}
