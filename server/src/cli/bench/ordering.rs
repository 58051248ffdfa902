//! `curvenet bench --orderings`: the binding's own matrix (`VᵀL_hV`, from
//! `Binding::system_matrix`) factored with each fill-reducing ordering,
//! alternating AMD and METIS in every repeat so both see the same machine
//! load: factor nonzeros, ordering + symbolic analysis time, the whole
//! factorisation, and the two triangular solves of a frame (9 then 3
//! columns, `Cholesky::solve_in_place` on fixed random right-hand sides),
//! medians; and the largest difference between the two factors' solutions
//! of the same right-hand sides, relative to the solution's largest entry.

use std::hint::black_box;

use curvenet_core::Binding;
use curvenet_core::{Cholesky, FillOrdering, SymmetricTriplets};
use serde::Serialize;

use super::measure::{Series, Stopwatch, median, uniform};
use crate::cli::{CliError, CliResult};

/// One ordering on one binding's matrix.
#[derive(Serialize, Clone)]
pub(super) struct OrderingBench {
    pub ordering: &'static str,
    pub factor_nonzeros: usize,
    /// Ordering and symbolic analysis (`Cholesky::analysis_ms`).
    pub ordering_ms: f64,
    /// The whole `Cholesky::with_ordering` (conversion, ordering, symbolic, numeric).
    pub factor_ms: f64,
    /// `factor_ms − ordering_ms`.
    pub numeric_ms: f64,
    /// Triangular solves of one frame: 9 then 3 columns.
    pub solve_ms: f64,
    pub supernodal: bool,
}

/// AMD and METIS on one binding's matrix.
#[derive(Serialize, Clone)]
pub(super) struct OrderingComparison {
    pub unknowns: usize,
    pub amd: OrderingBench,
    pub metis: OrderingBench,
    /// METIS / AMD.
    pub nonzeros_ratio: f64,
    pub factor_ratio: f64,
    pub solve_ratio: f64,
    /// max |x_metis − x_amd| / max |x_amd| over the same 9 + 3 right-hand sides.
    pub max_relative_difference: f64,
}

struct Runs {
    ordering: FillOrdering,
    factor: Option<Cholesky>,
    analysis: Vec<f64>,
    total: Vec<f64>,
    solves: Series,
}

/// Compares the orderings on `binding`'s matrix: `repeats` factorisations
/// and `solves` frame solves each.
pub(super) fn compare(binding: &Binding, repeats: usize, solves: usize) -> CliResult<OrderingComparison> {
    let a: SymmetricTriplets = binding.system_matrix();
    let n = a.n;
    let mut runs: Vec<Runs> = [FillOrdering::Amd, FillOrdering::Metis]
        .into_iter()
        .map(|ordering| Runs { ordering, factor: None, analysis: vec![], total: vec![], solves: Series::default() })
        .collect();
    let err = |source| CliError::Core { context: "bench --orderings".into(), source };
    for _ in 0..repeats.max(1) {
        for run in &mut runs {
            drop(run.factor.take());
            let clock = Stopwatch::start();
            let f = Cholesky::with_ordering(&a, run.ordering).map_err(err)?;
            run.total.push(clock.stop().wall_ms);
            run.analysis.push(f.analysis_ms());
            run.factor = Some(f);
        }
    }
    let mut rng = 0x5EED_0F0D_u64;
    let src9: Vec<[f64; 9]> = (0..n).map(|_| std::array::from_fn(|_| uniform(&mut rng))).collect();
    let src3: Vec<[f64; 3]> = (0..n).map(|_| std::array::from_fn(|_| uniform(&mut rng))).collect();
    let (mut rhs9, mut work9) = (src9.clone(), vec![[0.0; 9]; n]);
    let (mut rhs3, mut work3) = (src3.clone(), vec![[0.0; 3]; n]);
    // Each ordering's first solutions, flattened (9 columns, then 3).
    let mut solutions: Vec<Vec<f64>> = Vec::new();
    for i in 0..solves.max(1) + 1 {
        for run in &mut runs {
            let f = run.factor.as_ref().expect("factored above");
            rhs9.copy_from_slice(&src9);
            rhs3.copy_from_slice(&src3);
            let clock = Stopwatch::start();
            f.solve_in_place(black_box(&mut rhs9), &mut work9);
            f.solve_in_place(black_box(&mut rhs3), &mut work3);
            let lap = clock.stop();
            if i > 0 {
                run.solves.push(lap); // the first is a warm-up
            } else {
                solutions.push(rhs9.iter().flatten().chain(rhs3.iter().flatten()).copied().collect());
            }
        }
    }
    let (xa, xm) = (&solutions[0], &solutions[1]);
    let scale = xa.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = xa.iter().zip(xm).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    let bench = |run: &Runs| {
        let f = run.factor.as_ref().expect("factored above");
        let (ordering_ms, factor_ms) = (median(run.analysis.clone()), median(run.total.clone()));
        OrderingBench {
            ordering: f.ordering().name(),
            factor_nonzeros: f.nnz(),
            ordering_ms,
            factor_ms,
            // The analysis of a blockwise factorisation sums its blocks'
            // times across threads, so it can exceed the wall time: never
            // a negative numeric stage.
            numeric_ms: (factor_ms - ordering_ms).max(0.0),
            solve_ms: run.solves.wall(),
            supernodal: f.is_supernodal(),
        }
    };
    let (amd, metis) = (bench(&runs[0]), bench(&runs[1]));
    let r = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    Ok(OrderingComparison {
        unknowns: n,
        nonzeros_ratio: r(metis.factor_nonzeros as f64, amd.factor_nonzeros as f64),
        factor_ratio: r(metis.factor_ms, amd.factor_ms),
        solve_ratio: r(metis.solve_ms, amd.solve_ms),
        max_relative_difference: if scale > 0.0 { diff / scale } else { diff },
        amd,
        metis,
    })
}

/// The comparison as a table (one row per mesh and ordering).
pub(super) fn text(rows: &[(&str, &OrderingComparison)], repeats: usize, solves: usize) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    if rows.is_empty() {
        return s;
    }
    let w = rows.iter().map(|(m, _)| m.len()).max().unwrap_or(4).max(10);
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "Orderings (the binding's matrix factored {repeats}× per ordering, alternating; ms, medians; solve = tri9 + tri3 on random right-hand sides, {solves}×; diff = max |x_metis − x_amd| / max |x_amd|)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:>9} {:>8} {:>11} {:>10} {:>9} {:>8} {:>8} {:>11} {:>9}",
        "mesh", "unknowns", "ordering", "L nnz", "order+sym", "numeric", "factor", "solve", "supernodal", "diff"
    );
    for (mesh, c) in rows {
        for (o, b) in [(&c.amd, 0.0), (&c.metis, c.max_relative_difference)] {
            let diff = if b > 0.0 || o.ordering == "metis" { format!("{b:.1e}") } else { String::new() };
            let _ = writeln!(
                s,
                "{:<w$} {:>9} {:>8} {:>11} {:>10.1} {:>9.1} {:>8.1} {:>8.3} {:>11} {:>9}",
                mesh,
                c.unknowns,
                o.ordering,
                o.factor_nonzeros,
                o.ordering_ms,
                o.numeric_ms,
                o.factor_ms,
                o.solve_ms,
                o.supernodal,
                diff
            );
        }
        let _ = writeln!(
            s,
            "{:<w$} {:>9} {:>8} {:>10.2}× {:>10} {:>9} {:>7.2}× {:>7.2}×",
            "", "", "m/a", c.nonzeros_ratio, "", "", c.factor_ratio, c.solve_ratio
        );
    }
    s
}
