//! Sparse Cholesky factorisation `P A Pᵀ = L Lᵀ` of a symmetric positive
//! definite matrix, with triangular solves over right-hand sides stored
//! interleaved per row (`[f64; K]` per unknown).
//!
//! The ordering (AMD), symbolic analysis and numeric factorisation are faer's
//! (`Par::Seq`: frames are parallelised across, not inside, solves).
//!
//! **Uncoupled blocks, factored apart.** A curvenet cuts the surface into
//! regions whose unknowns are coupled only inside each region, so the
//! binding's matrix falls apart into connected components (the 94k hand:
//! 17, the largest 29% of the unknowns). [`Cholesky::new`] finds them
//! (union-find over the entries), merges consecutive small ones into
//! blocks of about 1/16 of the entries each, and orders, analyses and
//! factors every block on its own, the blocks in parallel on rayon's pool;
//! L is their block-diagonal concatenation, the same bits on any thread
//! count. On the bench's meshes the fill is the same at 22k and 94k and a
//! little less at 376k (AMD on the whole matrix is not quite AMD on each
//! piece), and the 94k factorisation about a third faster (docs/
//! performance.md, "Uncoupled blocks, the transport chain, and group
//! memory in the cache"). METIS (below) orders the whole matrix.
//!
//! **Ordering: AMD, measured against METIS.** [`Ordering::Metis`] orders
//! with METIS nested dissection (`METIS_NodeND` through `metis-sys`, which
//! compiles METIS's vendored C sources; default options, seed 1, one call
//! at a time because METIS's random generator is global) and hands the
//! permutation to faer as a custom ordering; [`Cholesky::new`] uses AMD.
//! `curvenet bench --orderings` factors the bindings' own matrices with
//! both (the figures: docs/performance.md, "Ordering, memory, growth and
//! export"): on the hands and on every corpus mesh METIS gave 3-11% *more*
//! fill and a 3-9× slower factorisation; with `METIS_OPTION_CCORDER`
//! (components ordered apart) the same. The curvenet cuts these surfaces into regions
//! whose unknowns are coupled only inside each region, and the fill of
//! such a matrix is small and local, which minimum degree already finds;
//! nested dissection's separators pay off on the plain mesh Laplacians the
//! earlier measurement (22-37% less fill) was made on, not on these. Built
//! with METIS, the 22k binding took 504 ms and the 94k 1.7 s in the same
//! run: the binding targets (150 ms, 560 ms) rule it out. The solutions of
//! both orderings agree to 1e-13 relative (`core/tests/ordering_export.rs`
//! checks 1e-10 on the 22k hand). A geometric nested dissection was not
//! tried: METIS's separators are at least as good as geometric ones on a
//! surface mesh, and they lose here. A nested dissection by level
//! structures (George's, AMD on the small parts) was written and measured
//! and dropped: 1.5× AMD's fill at 376k (docs/performance.md,
//! "Nested dissection of our own"). Only on the 94k hand subdivided 1-to-4
//! (375,911 unknowns, the bench's growth row) does METIS win: 12.6M → 9.1M
//! nonzeros (0.72×), the two solves 376 → 296 ms, but the factorisation
//! 4.3 → 6.5 s (its ordering alone 5.6 s at load 9.5); AMD stays the
//! default at every size, since every binding pays the ordering and the
//! binding time is what the targets bound. A caller binding one very large
//! mesh for a long bake could choose METIS; none does yet. The
//! solves are written here: faer's solves take column-major right-hand sides
//! and scatter one column at a time, while a frame solves 9 and then 3
//! columns at once; keeping the K values of a row together makes each
//! factor entry one K-wide fused update (measured about 1.5× faster than
//! faer's simplicial solve on this machine, by the team's notes). The factor
//! is copied once into plain CSC arrays (`u32` indices) for that purpose.
//!
//! The symbolic analysis is kept (`Arc`) so a matrix with the same pattern
//! and new values refactors without reordering ([`Cholesky::refactor`]).

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Par, Side};

use crate::error::{Error, Result};
use crate::simd::Simd;
use crate::sparse::disjoint_root;

/// A symmetric matrix given by its lower triangle as `(row, col, value)`
/// triplets with `row >= col`; duplicates are summed.
#[derive(Debug, Clone, Default)]
pub struct SymmetricTriplets {
    pub n: usize,
    pub entries: Vec<(u32, u32, f64)>,
}

/// `P A Pᵀ = L Lᵀ`, immutable once built, `Send + Sync`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Cholesky {
    n: usize,
    /// `perm[k]` = original index of permuted row `k` (the identity once
    /// the caller renumbered its unknowns: [`Self::into_factor_order`]).
    #[serde(with = "crate::persist::pod")]
    perm: Vec<u32>,
    /// After [`Self::into_factor_order`]: the order the symbolic analysis
    /// was made in (`renumbered[k]` = the analysed matrix's row of the
    /// caller's row `k`), for [`Self::refactor`]; `None` before.
    renumbered: Option<Vec<u32>>,
    /// L in compressed columns, the diagonal first in each column.
    #[serde(with = "crate::persist::pod")]
    col_ptr: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    row_idx: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    values: Vec<f64>,
    /// L's strictly lower entries again, in compressed rows ([`Rows`]),
    /// made at the first wide sweep: the forward sweep of a group's
    /// columns reads them. Not stored ([`crate::persist`]): a loaded factor
    /// makes it again at its first wide sweep.
    #[serde(skip)]
    rows: std::sync::OnceLock<Rows>,
    /// faer's ordering and symbolic analysis of each block ([`Block`]),
    /// shared with refactored copies. Not stored: empty in a factor read
    /// back from a store, which [`Self::refactor`] refuses (frames never
    /// refactor).
    #[serde(skip)]
    blocks: Arc<[Block]>,
    /// The ordering used ([`Ordering::Amd`] or [`Ordering::Metis`]).
    ordering: Ordering,
    /// Wall time of the ordering and symbolic analysis (0 for a refactored copy).
    analysis_ms: f64,
}

impl Cholesky {
    /// Orders (AMD, see the module docs), analyses and factors `a`. Fails with
    /// [`Error::NotPositiveDefinite`] naming the row (in `a`'s order) of the
    /// first non-positive pivot when `a` is not numerically SPD.
    pub fn new(a: &SymmetricTriplets) -> Result<Self> {
        Self::with_threshold(a, Ordering::Amd, SupernodalThreshold::AUTO)
    }

    /// Like [`Self::new`] with the fill-reducing ordering chosen by the
    /// caller (`curvenet bench --orderings` compares them; tests check that
    /// they solve alike).
    pub fn with_ordering(a: &SymmetricTriplets, ordering: Ordering) -> Result<Self> {
        Self::with_threshold(a, ordering, SupernodalThreshold::AUTO)
    }

    fn with_threshold(a: &SymmetricTriplets, ordering: Ordering, threshold: SupernodalThreshold) -> Result<Self> {
        let mat = to_faer(a)?;
        #[cfg(feature = "counters")]
        crate::counters::numeric_factorization_done();
        let t0 = std::time::Instant::now();
        let params = CholeskySymbolicParams { supernodal_flop_ratio_threshold: threshold, ..Default::default() };
        if ordering == Ordering::Amd {
            let groups = uncoupled_blocks(&mat);
            if groups.len() > 1 {
                return Self::blockwise(&mat, groups, params);
            }
        }
        let metis = match ordering {
            Ordering::Metis => metis_permutation(&mat),
            _ => None,
        };
        // METIS refusing the graph (it should not) falls back to AMD.
        let (ordering, faer_ordering) = match &metis {
            Some((fwd, inv)) => (Ordering::Metis, SymmetricOrdering::Custom(PermRef::new_checked(fwd, inv, a.n))),
            None => (Ordering::Amd, SymmetricOrdering::Amd),
        };
        let symbolic = factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, faer_ordering, params)
            .map_err(|e| Error::Internal { what: format!("symbolic Cholesky failed: {e:?}") })?;
        let analysis_ms = t0.elapsed().as_secs_f64() * 1e3;
        let lower = numeric(&symbolic, &mat)?;
        Ok(Self::from_lower(lower, Arc::new([Block { rows: Vec::new(), symbolic }]), ordering, analysis_ms))
    }

    /// [`Self::with_threshold`] for a matrix whose rows fall into blocks no
    /// entry couples (`groups`, from [`uncoupled_blocks`]): each block is
    /// ordered (AMD), analysed and factored on its own, the blocks in
    /// parallel (rayon), and L is their block-diagonal concatenation, the
    /// blocks in the order given. The result does not depend on the thread
    /// count. `analysis_ms` is the blocks' ordering and analysis times summed.
    fn blockwise(mat: &SparseColMat<u32, f64>, groups: Vec<Vec<u32>>, params: CholeskySymbolicParams) -> Result<Self> {
        use rayon::prelude::*;
        let local = local_rows(mat.nrows(), groups.iter().map(|r| &r[..]));
        let done: Vec<Result<(Block, Lower, f64)>> = groups
            .into_par_iter()
            .map(|rows| {
                let sub = submatrix(mat, &rows, &local);
                let t0 = std::time::Instant::now();
                let symbolic = factorize_symbolic_cholesky(sub.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
                    .map_err(|e| Error::Internal { what: format!("symbolic Cholesky failed: {e:?}") })?;
                let analysis_ms = t0.elapsed().as_secs_f64() * 1e3;
                let lower = numeric(&symbolic, &sub).map_err(|e| global_pivot(e, &rows))?;
                Ok((Block { rows, symbolic }, lower, analysis_ms))
            })
            .collect();
        let (mut blocks, mut lowers, mut analysis_ms) = (Vec::new(), Vec::new(), 0.0);
        for d in done {
            let (block, lower, ms) = d?;
            blocks.push(block);
            lowers.push(lower);
            analysis_ms += ms;
        }
        let lower = concatenate(mat.nrows(), &blocks, lowers);
        Ok(Self::from_lower(lower, blocks.into(), Ordering::Amd, analysis_ms))
    }

    fn from_lower(lower: Lower, blocks: Arc<[Block]>, ordering: Ordering, analysis_ms: f64) -> Self {
        let Lower { perm, col_ptr, row_idx, values } = lower;
        Self {
            n: perm.len(),
            perm,
            renumbered: None,
            col_ptr,
            row_idx,
            values,
            rows: Default::default(),
            blocks,
            ordering,
            analysis_ms,
        }
    }

    /// Factors a matrix with the same pattern as the one this factor was
    /// built from (new values), reusing the ordering and symbolic analysis.
    pub fn refactor(&self, a: &SymmetricTriplets) -> Result<Self> {
        if a.n != self.n {
            return Err(Error::CountMismatch { what: "refactored matrix size", expected: self.n, got: a.n });
        }
        if self.blocks.is_empty() && self.n > 0 {
            return Err(Error::Internal {
                what: "a factor read back from a store has no symbolic analysis to refactor with".into(),
            });
        }
        let mat = match &self.renumbered {
            None => to_faer(a)?,
            Some(p) => {
                // The caller's rows are in the factor's order: back to the
                // order the symbolic analysis was made in.
                let mut entries = Vec::with_capacity(a.entries.len());
                for &(r, c, v) in &a.entries {
                    let (pr, pc) = match (p.get(r as usize), p.get(c as usize)) {
                        (Some(&pr), Some(&pc)) if r >= c => (pr, pc),
                        _ => {
                            return Err(Error::Internal {
                                what: format!(
                                    "triplet ({r}, {c}) is not in the lower triangle of a {0}×{0} matrix",
                                    a.n
                                ),
                            });
                        }
                    };
                    entries.push((pr.max(pc), pr.min(pc), v));
                }
                to_faer(&SymmetricTriplets { n: a.n, entries })?
            }
        };
        #[cfg(feature = "counters")]
        crate::counters::numeric_factorization_done();
        let lower = factor_blocks(&self.blocks, &mat)?;
        let mut f = Self::from_lower(lower, self.blocks.clone(), self.ordering, 0.0);
        if let Some(p) = &self.renumbered {
            f = f.into_factor_order().0;
            debug_assert_eq!(f.renumbered.as_deref(), Some(&p[..]));
        }
        Ok(f)
    }

    /// For a caller that renumbers its unknowns into the factor's order:
    /// returns the factor of that renumbered matrix (`P A Pᵀ = L Lᵀ`, so
    /// the same L with the identity permutation) and the permutation
    /// (`perm[k]` = the old index of new row `k`). Solves then need no
    /// gather and scatter ([`Self::solve_in_place`] works on the rows as
    /// they are; [`Self::permutation`] is the identity), and rows the
    /// factor visits one after another are next to each other in the
    /// caller's arrays too. [`Self::refactor`] takes matrices in the new
    /// numbering.
    pub fn into_factor_order(mut self) -> (Self, Vec<u32>) {
        let identity: Vec<u32> = (0..self.n as u32).collect();
        let perm = std::mem::replace(&mut self.perm, identity);
        let analysed = match self.renumbered.take() {
            // Already renumbered: the analysed order composes.
            Some(old) => perm.iter().map(|&k| old[k as usize]).collect(),
            None => perm.clone(),
        };
        self.renumbered = Some(analysed);
        (self, perm)
    }

    /// Whether rows are already in the factor's order (the permutation is
    /// the identity: [`Self::into_factor_order`]).
    pub fn in_factor_order(&self) -> bool {
        self.renumbered.is_some()
    }

    /// Size of the factored matrix.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Whether faer chose its supernodal factorisation (large, fill-heavy
    /// matrices) rather than the simplicial one.
    pub fn is_supernodal(&self) -> bool {
        self.blocks.iter().any(|b| matches!(b.symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_)))
    }

    /// The fill-reducing ordering this factor was built with (AMD when
    /// METIS was asked for but refused the graph).
    pub fn ordering(&self) -> Ordering {
        self.ordering
    }

    /// Milliseconds spent on the ordering and symbolic analysis when this
    /// factor was built (0 for [`Self::refactor`]ed copies, which reuse them).
    pub fn analysis_ms(&self) -> f64 {
        self.analysis_ms
    }

    /// Number of stored entries of L.
    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    /// Heap bytes of the row copy of L that the first sweep of a group's
    /// columns makes (`Rows`: by rows, the forward sweep of 16 or more
    /// columns runs faster), whether made yet or not: callers that budget a
    /// binding's memory before its first group count it with
    /// [`Self::heap_bytes`], which counts it only once it is made.
    pub fn row_copy_bytes(&self) -> usize {
        Rows::bytes_for(self.n, self.values.len())
    }

    /// Whether the row copy ([`Self::row_copy_bytes`]) is made (and so
    /// counted in [`Self::heap_bytes`]).
    pub fn rows_made(&self) -> bool {
        self.rows.get().is_some()
    }

    /// The row copy of L, made on first use.
    fn rows(&self) -> &Rows {
        self.rows.get_or_init(|| Rows::of(self.n, &self.col_ptr, &self.row_idx, &self.values))
    }

    /// Solves `A X = B` for K right-hand sides stored per row: `rhs[i]` holds
    /// row i of B on entry and row i of X on return. `work` is scratch of the
    /// same length (reuse it across calls: no allocation here); a factor in
    /// its own order ([`Self::into_factor_order`]) solves in place and does
    /// not use it, so it may be empty.
    pub fn solve_in_place<const K: usize>(&self, rhs: &mut [[f64; K]], work: &mut [[f64; K]]) {
        let n = self.n;
        assert_eq!(rhs.len(), n, "right-hand side rows");
        if self.renumbered.is_some() {
            // The identity permutation: the same sweeps on the rows in place.
            self.sweep::<K>(rhs);
            return;
        }
        assert_eq!(work.len(), n, "scratch rows");
        for (k, w) in work.iter_mut().enumerate() {
            *w = rhs[self.perm[k] as usize];
        }
        // Forward L z = y, then backward Lᵀ x = z (a gather), in the factor's order.
        self.sweep::<K>(work);
        for (k, w) in work.iter().enumerate() {
            rhs[self.perm[k] as usize] = *w;
        }
    }
}

/// The fill-reducing ordering of the factorisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Ordering {
    /// faer's approximate minimum degree.
    Amd,
    /// METIS nested dissection (`METIS_NodeND`, default options, fixed seed).
    Metis,
}

impl Ordering {
    /// The name the bench prints (`amd`, `metis`).
    pub fn name(self) -> &'static str {
        match self {
            Ordering::Amd => "amd",
            Ordering::Metis => "metis",
        }
    }
}

/// METIS's global state (GKlib's random number generator) is not thread-safe:
/// bindings built concurrently take turns ordering.
static METIS_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// METIS nested dissection of `mat`'s graph (its off-diagonal pattern):
/// `(forward, inverse)` with `forward[k]` the original index of permuted row
/// `k`. `None` when METIS refuses (an error code) or the matrix is too
/// small to be worth it; the caller falls back to AMD.
fn metis_permutation(mat: &SparseColMat<u32, f64>) -> Option<(Vec<u32>, Vec<u32>)> {
    use metis_sys::idx_t;
    let n = mat.nrows();
    if n < 2 || n > idx_t::MAX as usize {
        return None;
    }
    // Symmetric adjacency (CSR) from the lower triangle, without the diagonal.
    let (cp, ri) = (mat.symbolic().col_ptr(), mat.symbolic().row_idx());
    let mut degree = vec![0 as idx_t; n + 1];
    for j in 0..n {
        for &i in &ri[cp[j] as usize..cp[j + 1] as usize] {
            if i as usize != j {
                degree[i as usize + 1] += 1;
                degree[j + 1] += 1;
            }
        }
    }
    for k in 0..n {
        degree[k + 1] += degree[k];
    }
    let mut xadj = degree;
    if xadj[n] == 0 {
        return None;
    }
    let mut next: Vec<idx_t> = xadj[..n].to_vec();
    let mut adjncy = vec![0 as idx_t; xadj[n] as usize];
    for j in 0..n {
        for &i in &ri[cp[j] as usize..cp[j + 1] as usize] {
            let i = i as usize;
            if i != j {
                adjncy[next[i] as usize] = j as idx_t;
                next[i] += 1;
                adjncy[next[j] as usize] = i as idx_t;
                next[j] += 1;
            }
        }
    }
    let mut options = [-1 as idx_t; metis_sys::METIS_NOPTIONS as usize];
    options[metis_sys::moptions_et_METIS_OPTION_NUMBERING as usize] = 0;
    options[metis_sys::moptions_et_METIS_OPTION_SEED as usize] = 1;
    let mut nvtxs = n as idx_t;
    let mut perm = vec![0 as idx_t; n];
    let mut iperm = vec![0 as idx_t; n];
    let status = {
        let _turn = METIS_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: every pointer is to a live buffer of the length METIS_NodeND
        // reads or writes: nvtxs one value, xadj n + 1, adjncy xadj[n],
        // options METIS_NOPTIONS, perm and iperm n; vwgt may be null. The
        // graph is symmetric without self-loops, as METIS requires.
        unsafe {
            metis_sys::METIS_NodeND(
                &mut nvtxs,
                xadj.as_mut_ptr(),
                adjncy.as_mut_ptr(),
                std::ptr::null_mut(),
                options.as_mut_ptr(),
                perm.as_mut_ptr(),
                iperm.as_mut_ptr(),
            )
        }
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return None;
    }
    // METIS: row k of the permuted matrix is row perm[k] of the original
    // (faer's forward array); iperm is its inverse. Checked, not trusted.
    let fwd: Vec<u32> = perm.iter().map(|&p| p as u32).collect();
    let inv: Vec<u32> = iperm.iter().map(|&p| p as u32).collect();
    let valid = fwd.iter().enumerate().all(|(k, &p)| (p as usize) < n && inv[p as usize] as usize == k);
    valid.then_some((fwd, inv))
}

impl Cholesky {
    /// `perm[k]`: the row of the original matrix that is row `k` of the
    /// factor's order (what [`Self::solve_permuted`] takes its rows in).
    pub fn permutation(&self) -> &[u32] {
        &self.perm
    }

    /// Solves `A X = B` for `width` right-hand sides given in the factor's
    /// row order: `rows` holds `n × width` values, row `k` (the original
    /// matrix's row `perm[k]`, [`Self::permutation`]) at `k * width`, its
    /// columns side by side; on return it holds X in the same layout. One
    /// sweep of each triangular solve serves every column: the multi-frame
    /// solve stacks K frames' columns in one such block, so each factor
    /// entry is read once for K frames. Each column sees exactly the
    /// operations of [`Self::solve_in_place`] in the same order, so the
    /// results are bit for bit those of solving the columns one block at a
    /// time. The widths of K frames of 9 and 3 columns up to K = 8 and K =
    /// 16, 32 run monomorphised kernels; any other width a runtime-width one.
    pub fn solve_permuted(&self, width: usize, rows: &mut [f64]) {
        assert_eq!(rows.len(), self.n * width, "right-hand side values");
        macro_rules! widths {
            ($($w:literal)*) => {
                match width {
                    0 => {}
                    $($w => self.sweep::<$w>(rows.as_chunks_mut::<$w>().0),)*
                    _ => self.sweep_dyn(width, rows),
                }
            };
        }
        widths!(1 2 3 4 6 8 9 12 15 18 21 24 27 36 45 48 54 63 72 96 144 288);
    }

    /// Both triangular sweeps over rows of `W` interleaved columns, in the
    /// factor's order, compiled for the widest vector unit the CPU has (see
    /// [`Simd`]; every variant does the same operations in the same order,
    /// so the results are bit for bit the same on every machine).
    fn sweep<const W: usize>(&self, work: &mut [[f64; W]]) {
        match Simd::detect() {
            // SAFETY: `Simd::detect` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.sweep_avx512::<W>(work) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.sweep_avx2::<W>(work) },
            Simd::Baseline => self.sweep_body::<W>(work),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn sweep_avx512<const W: usize>(&self, work: &mut [[f64; W]]) {
        self.sweep_body::<W>(work)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn sweep_avx2<const W: usize>(&self, work: &mut [[f64; W]]) {
        self.sweep_body::<W>(work)
    }

    #[inline(always)]
    fn sweep_body<const W: usize>(&self, work: &mut [[f64; W]]) {
        let n = self.n;
        let (cp, ri, lv) = (&self.col_ptr, &self.row_idx, &self.values);
        if W >= GATHER_WIDTH {
            // Forward by rows: row i gathers the finished z_j of its entries.
            let Rows { ptr: rp, col: rc, values: rv } = self.rows();
            for i in 0..n {
                let mut acc = work[i];
                for p in rp[i] as usize..rp[i + 1] as usize {
                    let l = rv[p];
                    let z = &work[rc[p] as usize];
                    for c in 0..W {
                        acc[c] -= l * z[c];
                    }
                }
                let inv = 1.0 / lv[cp[i] as usize];
                for c in acc.iter_mut() {
                    *c *= inv;
                }
                work[i] = acc;
            }
        } else {
            // Forward by columns: z_j, once finished, is scattered into the rows below.
            for j in 0..n {
                let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
                let inv = 1.0 / lv[s];
                let mut zj = work[j];
                for c in zj.iter_mut() {
                    *c *= inv;
                }
                work[j] = zj;
                for p in s + 1..e {
                    let l = lv[p];
                    let row = &mut work[ri[p] as usize];
                    for c in 0..W {
                        row[c] -= l * zj[c];
                    }
                }
            }
        }
        for j in (0..n).rev() {
            let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
            let mut acc = work[j];
            for p in s + 1..e {
                let l = lv[p];
                let xr = &work[ri[p] as usize];
                for c in 0..W {
                    acc[c] -= l * xr[c];
                }
            }
            let inv = 1.0 / lv[s];
            for c in acc.iter_mut() {
                *c *= inv;
            }
            work[j] = acc;
        }
    }

    /// [`Self::sweep`] for a width known only at run time (a row of L's
    /// strictly lower part reads only earlier rows, a column only later
    /// ones, so the row being updated and the ones read never alias).
    fn sweep_dyn(&self, w: usize, work: &mut [f64]) {
        let n = self.n;
        let (cp, ri, lv) = (&self.col_ptr, &self.row_idx, &self.values);
        if w >= GATHER_WIDTH {
            let Rows { ptr: rp, col: rc, values: rv } = self.rows();
            for i in 0..n {
                let (head, tail) = work.split_at_mut(i * w);
                let acc = &mut tail[..w];
                for p in rp[i] as usize..rp[i + 1] as usize {
                    let l = rv[p];
                    let r = rc[p] as usize;
                    for (a, z) in acc.iter_mut().zip(&head[r * w..(r + 1) * w]) {
                        *a -= l * z;
                    }
                }
                let inv = 1.0 / lv[cp[i] as usize];
                acc.iter_mut().for_each(|c| *c *= inv);
            }
        } else {
            for j in 0..n {
                let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
                let inv = 1.0 / lv[s];
                let (head, tail) = work.split_at_mut((j + 1) * w);
                let zj = &mut head[j * w..];
                zj.iter_mut().for_each(|c| *c *= inv);
                for p in s + 1..e {
                    let l = lv[p];
                    let r = ri[p] as usize - j - 1;
                    for (x, z) in tail[r * w..(r + 1) * w].iter_mut().zip(&*zj) {
                        *x -= l * z;
                    }
                }
            }
        }
        for j in (0..n).rev() {
            let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
            let (head, tail) = work.split_at_mut((j + 1) * w);
            let acc = &mut head[j * w..];
            for p in s + 1..e {
                let l = lv[p];
                let r = ri[p] as usize - j - 1;
                for (a, x) in acc.iter_mut().zip(&tail[r * w..(r + 1) * w]) {
                    *a -= l * x;
                }
            }
            let inv = 1.0 / lv[s];
            acc.iter_mut().for_each(|c| *c *= inv);
        }
    }
}

/// One block of a factorisation: rows of `A` that no entry couples with
/// any other block's, with faer's ordering and symbolic analysis of their
/// submatrix.
#[derive(Debug)]
struct Block {
    /// `A`'s rows in this block, ascending; empty when the block is all of `A`.
    rows: Vec<u32>,
    symbolic: SymbolicCholesky<u32>,
}

/// `P A Pᵀ = L Lᵀ` of one matrix or block: `perm[k]` = the row of `A` that
/// is row `k` of L; L in compressed columns, the diagonal first.
struct Lower {
    perm: Vec<u32>,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    values: Vec<f64>,
}

/// Sweeps at least this wide (a group's columns: 9 · K for K ≥ 2, 3 · K
/// for K ≥ 8) run the forward sweep by rows ([`Rows`]); narrower ones
/// (a single frame's 9 and 3 columns) by columns.
const GATHER_WIDTH: usize = 16;

/// L's strictly lower entries in compressed rows (`ptr`, `col`, `values`;
/// columns ascending in each row), for the forward sweep `L z = y` of wide
/// sweeps ([`GATHER_WIDTH`]). By rows, row i gathers the finished `z_j` of
/// its entries into registers and is stored once; by columns, each
/// finished `z_j` is scattered into the rows below, a load and a store of
/// the whole row per entry. Subtracting a row's entries in ascending column
/// order is the order the column-by-column scatter applies them in, so
/// both give the same bits (tested), and the width decides only the speed.
///
/// Measured on the hands' own factors (docs/performance.md, "Row-gathered
/// forward sweeps, and what did not pay"): by rows is faster from about 18
/// columns up (a group's 72 most), even at 9 and 12, and slower for 3 and 6.
/// Narrow rows gather through one short dependency
/// chain per entry, which the scatter's independent updates do not have.
/// A whole group of 8 frames gains less than the sweeps alone (22k: about
/// 2%, 94k: none measurable): the sweep of a frame's group runs with the
/// caches full of the group's other data. The copy costs 12 bytes
/// per entry of L (19 MB for the 94k hand) and 13 ms to make at 94k, so it
/// is made at the first wide sweep, not with the factor: a binding that
/// only ever solves single frames (most of the service's) never pays it,
/// and neither does the binding time. [`Cholesky::heap_bytes`] counts it
/// once made; [`Cholesky::row_copy_bytes`] says what it will take.
#[derive(Debug, Clone, Default)]
struct Rows {
    ptr: Vec<u32>,
    col: Vec<u32>,
    values: Vec<f64>,
}

impl Rows {
    /// Heap bytes of the copy for a factor of `n` rows and `nnz` entries.
    fn bytes_for(n: usize, nnz: usize) -> usize {
        (n + 1) * std::mem::size_of::<u32>()
            + nnz.saturating_sub(n) * (std::mem::size_of::<u32>() + std::mem::size_of::<f64>())
    }

    /// The transpose of L's strictly lower part given in compressed columns.
    fn of(n: usize, col_ptr: &[u32], row_idx: &[u32], values: &[f64]) -> Self {
        let mut ptr = vec![0u32; n + 1];
        for j in 0..n {
            for &r in &row_idx[col_ptr[j] as usize + 1..col_ptr[j + 1] as usize] {
                ptr[r as usize + 1] += 1;
            }
        }
        for i in 0..n {
            ptr[i + 1] += ptr[i];
        }
        let m = ptr[n] as usize;
        let (mut col, mut vals) = (vec![0u32; m], vec![0.0; m]);
        let mut next: Vec<u32> = ptr[..n].to_vec();
        // Columns in ascending order, so each row's entries come out sorted.
        for j in 0..n {
            for p in col_ptr[j] as usize + 1..col_ptr[j + 1] as usize {
                let r = row_idx[p] as usize;
                let q = next[r] as usize;
                col[q] = j as u32;
                vals[q] = values[p];
                next[r] += 1;
            }
        }
        Self { ptr, col, values: vals }
    }
}

/// The block sizes [`uncoupled_blocks`] aims at: about this many blocks
/// of equal stored entries, the larger components alone. Enough to keep
/// two or more threads busy to the end; few enough that the per-block
/// overhead (an analysis, a few allocations) stays negligible for a mesh
/// of thousands of tiny pieces.
const TARGET_BLOCKS: usize = 16;

/// The rows of `mat` (lower triangle) grouped into blocks that no entry
/// couples: its graph's connected components (a curvenet cuts a surface
/// into regions whose unknowns are coupled only inside each region),
/// consecutive small ones merged until a block holds about
/// 1/[`TARGET_BLOCKS`] of the entries. Blocks in the order of their first
/// row, rows ascending in each. One block when `mat` is connected.
fn uncoupled_blocks(mat: &SparseColMat<u32, f64>) -> Vec<Vec<u32>> {
    let n = mat.nrows();
    let (cp, ri) = (mat.symbolic().col_ptr(), mat.symbolic().row_idx());
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for j in 0..n {
        for &i in &ri[cp[j] as usize..cp[j + 1] as usize] {
            let (a, b) = (disjoint_root(&mut parent, i), disjoint_root(&mut parent, j as u32));
            if a != b {
                // The smaller index is the root: deterministic.
                let (lo, hi) = (a.min(b), a.max(b));
                parent[hi as usize] = lo;
            }
        }
    }
    // Components numbered by their first row, with their entry counts.
    let mut component = vec![u32::MAX; n];
    let (mut rows, mut weight): (Vec<Vec<u32>>, Vec<usize>) = (Vec::new(), Vec::new());
    for v in 0..n {
        let r = disjoint_root(&mut parent, v as u32) as usize;
        if component[r] == u32::MAX {
            component[r] = rows.len() as u32;
            rows.push(Vec::new());
            weight.push(0);
        }
        let c = component[r] as usize;
        rows[c].push(v as u32);
        weight[c] += (cp[v + 1] - cp[v]) as usize;
    }
    if rows.len() < 2 {
        return rows;
    }
    let target = (cp[n] as usize).div_ceil(TARGET_BLOCKS).max(1);
    let mut blocks: Vec<Vec<u32>> = Vec::new();
    let mut open = 0usize;
    for (r, w) in rows.into_iter().zip(weight) {
        match blocks.last_mut() {
            Some(last) if open > 0 && open < target => {
                last.extend(r);
                open += w;
            }
            _ => {
                blocks.push(r);
                open = w;
            }
        }
    }
    for b in &mut blocks {
        b.sort_unstable();
    }
    blocks
}

/// Each row's position in its block.
fn local_rows<'a>(n: usize, blocks: impl IntoIterator<Item = &'a [u32]>) -> Vec<u32> {
    let mut local = vec![0u32; n];
    for rows in blocks {
        for (k, &r) in rows.iter().enumerate() {
            local[r as usize] = k as u32;
        }
    }
    local
}

/// The submatrix of `mat` on `rows` (ascending, a union of components),
/// renumbered by `local`: a column's rows stay sorted and below the diagonal.
fn submatrix(mat: &SparseColMat<u32, f64>, rows: &[u32], local: &[u32]) -> SparseColMat<u32, f64> {
    let (cp, ri, val) = (mat.symbolic().col_ptr(), mat.symbolic().row_idx(), mat.val());
    let nnz: usize = rows.iter().map(|&c| (cp[c as usize + 1] - cp[c as usize]) as usize).sum();
    let mut col_ptr = Vec::with_capacity(rows.len() + 1);
    let (mut row_idx, mut values) = (Vec::with_capacity(nnz), Vec::with_capacity(nnz));
    col_ptr.push(0u32);
    for &c in rows {
        let range = cp[c as usize] as usize..cp[c as usize + 1] as usize;
        row_idx.extend(ri[range.clone()].iter().map(|&i| local[i as usize]));
        values.extend_from_slice(&val[range]);
        col_ptr.push(row_idx.len() as u32);
    }
    let m = rows.len();
    SparseColMat::new(SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx), values)
}

/// A block's failing pivot named by its row of the whole matrix.
fn global_pivot(e: Error, rows: &[u32]) -> Error {
    match e {
        Error::NotPositiveDefinite { pivot } => {
            Error::NotPositiveDefinite { pivot: pivot.and_then(|p| rows.get(p)).map(|&r| r as usize) }
        }
        other => other,
    }
}

/// The blocks' factors as one block-diagonal L of the `n`-row matrix.
fn concatenate(n: usize, blocks: &[Block], lowers: Vec<Lower>) -> Lower {
    let nnz: usize = lowers.iter().map(|l| l.values.len()).sum();
    let mut out = Lower {
        perm: Vec::with_capacity(n),
        col_ptr: Vec::with_capacity(n + 1),
        row_idx: Vec::with_capacity(nnz),
        values: Vec::with_capacity(nnz),
    };
    out.col_ptr.push(0);
    for (block, lower) in blocks.iter().zip(lowers) {
        let (row0, entry0) = (out.perm.len() as u32, out.values.len() as u32);
        out.perm.extend(lower.perm.iter().map(|&k| block.rows[k as usize]));
        out.col_ptr.extend(lower.col_ptr[1..].iter().map(|&p| p + entry0));
        out.row_idx.extend(lower.row_idx.iter().map(|&r| r + row0));
        out.values.extend_from_slice(&lower.values);
    }
    out
}

/// Numeric factorisation of `mat` with the analysis of `blocks` (a
/// refactor): the blocks in parallel, as [`Cholesky::blockwise`] made them.
fn factor_blocks(blocks: &[Block], mat: &SparseColMat<u32, f64>) -> Result<Lower> {
    use rayon::prelude::*;
    if let [only] = blocks
        && only.rows.is_empty()
    {
        return numeric(&only.symbolic, mat);
    }
    let local = local_rows(mat.nrows(), blocks.iter().map(|b| &b.rows[..]));
    let lowers: Vec<Result<Lower>> = blocks
        .par_iter()
        .map(|b| numeric(&b.symbolic, &submatrix(mat, &b.rows, &local)).map_err(|e| global_pivot(e, &b.rows)))
        .collect();
    let lowers = lowers.into_iter().collect::<Result<Vec<_>>>()?;
    Ok(concatenate(mat.nrows(), blocks, lowers))
}

/// faer's numeric factorisation of `mat` with its analysis `symbolic`,
/// copied into plain compressed columns (see the module docs).
fn numeric(symbolic: &SymbolicCholesky<u32>, mat: &SparseColMat<u32, f64>) -> Result<Lower> {
    let n = mat.nrows();
    let mut l_values = vec![0.0f64; symbolic.len_val()];
    let req = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
    let mut mem = MemBuffer::new(req);
    symbolic
        .factorize_numeric_llt(
            &mut l_values,
            mat.as_ref(),
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map_err(|e| {
            // faer names the failing pivot 1-based in the permuted order; map it back.
            let faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } = e;
            let pivot = index.checked_sub(1).and_then(|p| match symbolic.perm() {
                Some(perm) => perm.arrays().0.get(p).map(|&i| i as usize),
                None => Some(p),
            });
            Error::NotPositiveDefinite { pivot }
        })?;
    let perm: Vec<u32> = match symbolic.perm() {
        Some(p) => p.arrays().0.to_vec(),
        None => (0..n as u32).collect(),
    };
    let (col_ptr, row_idx, values) = match symbolic.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            // Simplicial L: compressed columns, diagonal first.
            (s.col_ptr().to_vec(), s.row_idx().to_vec(), l_values)
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            // Each supernode is a dense column-major block: its own columns'
            // rows first (lower triangle valid), then the rows in row_idx.
            let mut col_ptr = Vec::with_capacity(n + 1);
            let mut row_idx = Vec::new();
            let mut values = Vec::new();
            col_ptr.push(0u32);
            let (begin, end) = (s.supernode_begin(), s.supernode_end());
            for k in 0..s.n_supernodes() {
                let (b, e) = (begin[k] as usize, end[k] as usize);
                let ncols = e - b;
                let rows = &s.row_idx()[s.col_ptr_for_row_idx()[k] as usize..s.col_ptr_for_row_idx()[k + 1] as usize];
                let nrows = ncols + rows.len();
                let block = &l_values[s.col_ptr_for_val()[k] as usize..s.col_ptr_for_val()[k + 1] as usize];
                debug_assert_eq!(block.len(), nrows * ncols);
                for j in 0..ncols {
                    let col = &block[j * nrows..(j + 1) * nrows];
                    for i in j..ncols {
                        row_idx.push((b + i) as u32);
                        values.push(col[i]);
                    }
                    for (r, &gi) in rows.iter().enumerate() {
                        row_idx.push(gi);
                        values.push(col[ncols + r]);
                    }
                    col_ptr.push(row_idx.len() as u32);
                }
            }
            (col_ptr, row_idx, values)
        }
    };
    Ok(Lower { perm, col_ptr, row_idx, values })
}

fn to_faer(a: &SymmetricTriplets) -> Result<SparseColMat<u32, f64>> {
    if let Some(&(r, c, _)) = a.entries.iter().find(|&&(r, c, _)| r < c || r as usize >= a.n) {
        return Err(Error::Internal {
            what: format!("triplet ({r}, {c}) is not in the lower triangle of a {0}×{0} matrix", a.n),
        });
    }
    if let Some(&(r, c, v)) = a.entries.iter().find(|e| !e.2.is_finite()) {
        return Err(Error::Internal { what: format!("matrix entry ({r}, {c}) is {v}") });
    }
    Ok(compressed_columns(a))
}

/// The lower triangle `a` (checked: in range, finite) in compressed
/// columns, rows sorted, duplicates summed in the order given: what faer's
/// `try_new_from_triplets` makes (which sums duplicates in another order,
/// so the values differ by rounding), by a counting sort by column and a
/// sort of each short column.
fn compressed_columns(a: &SymmetricTriplets) -> SparseColMat<u32, f64> {
    let cols: Vec<u32> = a.entries.iter().map(|e| e.1).collect();
    let (start, order) = crate::sparse::group_by_key(a.n, &cols);
    drop(cols);
    let mut col_ptr = Vec::with_capacity(a.n + 1);
    let mut row_idx = Vec::with_capacity(a.entries.len());
    let mut values = Vec::with_capacity(a.entries.len());
    let mut column: Vec<(u32, f64)> = Vec::new();
    col_ptr.push(0u32);
    for c in 0..a.n {
        column.clear();
        column.extend(order[start[c] as usize..start[c + 1] as usize].iter().map(|&i| {
            let (r, _, v) = a.entries[i as usize];
            (r, v)
        }));
        // Stable: duplicates keep the order given.
        column.sort_by_key(|e| e.0);
        for &(r, v) in &column {
            if row_idx.len() > col_ptr[c] as usize && row_idx.last() == Some(&r) {
                *values.last_mut().expect("an entry") += v;
            } else {
                row_idx.push(r);
                values.push(v);
            }
        }
        col_ptr.push(row_idx.len() as u32);
    }
    let symbolic = SymbolicSparseColMat::new_checked(a.n, a.n, col_ptr, None, row_idx);
    SparseColMat::new(symbolic, values)
}

impl Cholesky {
    /// Heap bytes held: the permutation, the factor's CSC arrays (and its
    /// row copy once a wide sweep made it: [`Self::row_copy_bytes`]) and faer's
    /// symbolic analyses (their permutations and index arrays, by length)
    /// and blocks' rows, shared with refactored copies (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        let idx = std::mem::size_of::<u32>();
        let analysis: usize = self
            .blocks
            .iter()
            .map(|b| {
                let perm = b.symbolic.perm().map_or(0, |p| 2 * p.arrays().0.len() * idx);
                let raw = match b.symbolic.raw() {
                    SymbolicCholeskyRaw::Simplicial(s) => (s.col_ptr().len() + s.row_idx().len()) * idx,
                    SymbolicCholeskyRaw::Supernodal(s) => {
                        (s.supernode_begin().len()
                            + s.supernode_end().len()
                            + s.col_ptr_for_row_idx().len()
                            + s.col_ptr_for_val().len()
                            + s.row_idx().len())
                            * idx
                    }
                };
                bytes(&b.rows) + perm + raw
            })
            .sum::<usize>()
            + std::mem::size_of_val(&*self.blocks);
        let renumbered = self.renumbered.as_ref().map_or(0, bytes);
        let rows = self.rows.get().map_or(0, |r| bytes(&r.ptr) + bytes(&r.col) + bytes(&r.values));
        bytes(&self.perm)
            + renumbered
            + bytes(&self.col_ptr)
            + bytes(&self.row_idx)
            + bytes(&self.values)
            + rows
            + analysis
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D grid Laplacian plus a diagonal shift: SPD, with enough fill to
    /// exercise supernodes at larger sizes.
    fn grid(m: usize, shift: f64) -> SymmetricTriplets {
        let n = m * m;
        let mut entries = Vec::new();
        for i in 0..m {
            for j in 0..m {
                let v = (i * m + j) as u32;
                entries.push((v, v, 4.0 + shift + 0.01 * (v % 7) as f64));
                if j + 1 < m {
                    entries.push((v + 1, v, -1.0));
                }
                if i + 1 < m {
                    entries.push((v + m as u32, v, -1.0));
                }
            }
        }
        SymmetricTriplets { n, entries }
    }

    /// The direct assembly gives faer's own from the same triplets: the
    /// same pattern, rows sorted, and duplicates summed (faer sums them in
    /// another order, so values agree to rounding: within 8 ulps of the sum
    /// of the duplicates' magnitudes). Random triplets, most entries
    /// repeated, some columns empty.
    #[test]
    fn compressed_columns_equal_faers_assembly() {
        use faer::sparse::Triplet;
        let mut rng = crate::polygon_laplacian::tests::Rng(0xA076_1D64_78BD_642F);
        let n = 300;
        let mut entries = Vec::new();
        for _ in 0..6000 {
            let a = ((rng.next() + 1.0) * 0.5 * n as f64) as u32;
            let b = ((rng.next() + 1.0) * 0.5 * n as f64) as u32 % 200;
            entries.push((a.max(b), a.min(b), rng.next() * 10f64.powi((rng.next() * 8.0) as i32)));
        }
        let a = SymmetricTriplets { n, entries };
        let ours = compressed_columns(&a);
        let triplets: Vec<Triplet<u32, u32, f64>> = a.entries.iter().map(|&(r, c, v)| Triplet::new(r, c, v)).collect();
        let theirs = SparseColMat::try_new_from_triplets(n, n, &triplets).unwrap();
        assert_eq!(ours.symbolic().col_ptr(), theirs.symbolic().col_ptr());
        assert_eq!(ours.symbolic().row_idx(), theirs.symbolic().row_idx());
        let mut magnitude = std::collections::HashMap::new();
        for &(r, c, v) in &a.entries {
            *magnitude.entry((r, c)).or_insert(0.0) += v.abs();
        }
        let (cp, ri) = (ours.symbolic().col_ptr(), ours.symbolic().row_idx());
        for c in 0..n {
            for p in cp[c] as usize..cp[c + 1] as usize {
                let (x, y) = (ours.val()[p], theirs.val()[p]);
                let bound = 8.0 * f64::EPSILON * magnitude[&(ri[p], c as u32)];
                assert!((x - y).abs() <= bound, "({}, {c}): {x} vs faer's {y}", ri[p]);
            }
        }
        assert!(cp[201..].windows(2).all(|w| w[0] == w[1]), "columns from 200 on are empty");
        // Ours sums each entry's duplicates left to right in the order given.
        let mut in_order = std::collections::HashMap::new();
        for &(r, c, v) in &a.entries {
            in_order.entry((r, c)).and_modify(|s: &mut f64| *s += v).or_insert(v);
        }
        for c in 0..n {
            for p in cp[c] as usize..cp[c + 1] as usize {
                assert_eq!(ours.val()[p].to_bits(), in_order[&(ri[p], c as u32)].to_bits(), "({}, {c})", ri[p]);
            }
        }
    }

    fn multiply<const K: usize>(a: &SymmetricTriplets, x: &[[f64; K]]) -> Vec<[f64; K]> {
        let mut y = vec![[0.0; K]; a.n];
        for &(r, c, v) in &a.entries {
            for k in 0..K {
                y[r as usize][k] += v * x[c as usize][k];
                if r != c {
                    y[c as usize][k] += v * x[r as usize][k];
                }
            }
        }
        y
    }

    fn check_solve(a: &SymmetricTriplets, supernodal: bool) {
        let threshold =
            if supernodal { SupernodalThreshold::FORCE_SUPERNODAL } else { SupernodalThreshold::FORCE_SIMPLICIAL };
        let f = Cholesky::with_threshold(a, Ordering::Amd, threshold).unwrap();
        assert_eq!(f.is_supernodal(), supernodal);
        let x: Vec<[f64; 3]> = (0..a.n).map(|i| [i as f64, (i % 5) as f64 - 2.0, 1.0]).collect();
        let mut b = multiply(a, &x);
        let mut work = vec![[0.0; 3]; a.n];
        f.solve_in_place(&mut b, &mut work);
        let err = b.iter().zip(&x).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f64::max);
        assert!(err < 1e-9 * a.n as f64, "max error {err}");
    }

    #[test]
    fn simplicial_and_supernodal_factors_solve() {
        check_solve(&grid(6, 0.1), false);
        check_solve(&grid(40, 0.0), false);
        check_solve(&grid(6, 0.1), true);
        check_solve(&grid(70, 0.0), true);
    }

    #[test]
    fn metis_orders_a_grid_and_solves_as_amd_does() {
        let a = grid(50, 0.0);
        let amd = Cholesky::with_ordering(&a, Ordering::Amd).unwrap();
        let metis = Cholesky::with_ordering(&a, Ordering::Metis).unwrap();
        assert_eq!((amd.ordering(), metis.ordering()), (Ordering::Amd, Ordering::Metis));
        assert_ne!(amd.perm, metis.perm, "a different ordering");
        let mut sorted = metis.perm.clone();
        sorted.sort_unstable();
        assert!(sorted.iter().enumerate().all(|(i, &p)| p as usize == i), "a permutation");
        let b: Vec<[f64; 2]> = (0..a.n).map(|i| [(i % 13) as f64 - 6.0, 1.0]).collect();
        let (mut xa, mut xm, mut w) = (b.clone(), b.clone(), vec![[0.0; 2]; a.n]);
        amd.solve_in_place(&mut xa, &mut w);
        metis.solve_in_place(&mut xm, &mut w);
        let scale = xa.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = xa.iter().flatten().zip(xm.iter().flatten()).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
        assert!(diff <= 1e-12 * scale, "{diff:e}");
        // The same seed, the same ordering (METIS's generator is seeded per call).
        assert_eq!(Cholesky::with_ordering(&a, Ordering::Metis).unwrap().perm, metis.perm);
        // A refactored copy keeps its ordering.
        assert_eq!(metis.refactor(&a).unwrap().ordering(), Ordering::Metis);
        // A 1×1 METIS request falls back to AMD; `new` orders with AMD.
        let one = SymmetricTriplets { n: 1, entries: vec![(0, 0, 2.0)] };
        assert_eq!(Cholesky::with_ordering(&one, Ordering::Metis).unwrap().ordering(), Ordering::Amd);
        assert_eq!(Cholesky::new(&a).unwrap().ordering(), Ordering::Amd);
    }

    /// Both sweeps as written out by columns: the reference the wide
    /// sweeps' forward gather by rows must equal bit for bit.
    fn sweep_by_columns(f: &Cholesky, w: usize, rows: &mut [f64]) {
        let (cp, ri, lv) = (&f.col_ptr, &f.row_idx, &f.values);
        for j in 0..f.n {
            let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
            let inv = 1.0 / lv[s];
            for c in 0..w {
                rows[j * w + c] *= inv;
                for p in s + 1..e {
                    rows[ri[p] as usize * w + c] -= lv[p] * rows[j * w + c];
                }
            }
        }
        for j in (0..f.n).rev() {
            let (s, e) = (cp[j] as usize, cp[j + 1] as usize);
            for c in 0..w {
                let mut acc = rows[j * w + c];
                for p in s + 1..e {
                    acc -= lv[p] * rows[ri[p] as usize * w + c];
                }
                rows[j * w + c] = acc * (1.0 / lv[s]);
            }
        }
    }

    #[test]
    fn the_forward_sweep_by_rows_is_the_column_scatter_bit_for_bit() {
        // Two blocks (grids), so rows gather within each block's own ordering.
        let (a, b) = (grid(30, 0.1), grid(17, 0.0));
        let mut entries = a.entries.clone();
        let shift = a.n as u32;
        entries.extend(b.entries.iter().map(|&(r, c, v)| (r + shift, c + shift, v)));
        let m = SymmetricTriplets { n: a.n + b.n, entries };
        let f = Cholesky::new(&m).unwrap();
        let n = f.n;
        assert!(f.rows.get().is_none(), "no row copy before a wide sweep");
        let values =
            |w: usize| -> Vec<f64> { (0..n * w).map(|i| ((i * 13) % 7) as f64 - 3.0 + (i as f64).sin()).collect() };
        // Monomorphised and run-time widths on both sides of GATHER_WIDTH.
        for w in [2, 5, GATHER_WIDTH - 1, GATHER_WIDTH, 17, 18] {
            let mut want = values(w);
            sweep_by_columns(&f, w, &mut want);
            let mut got = values(w);
            match w {
                2 => f.sweep::<2>(got.as_chunks_mut::<2>().0),
                18 => f.sweep::<18>(got.as_chunks_mut::<18>().0),
                _ => f.sweep_dyn(w, &mut got),
            }
            assert!(got.iter().zip(&want).all(|(g, w)| g.to_bits() == w.to_bits()), "width {w}");
        }
        // The row copy: every strictly lower entry once, columns ascending in each row, counted once made.
        let rows = f.rows.get().expect("made by the wide sweeps");
        assert_eq!(rows.values.len(), f.values.len() - n);
        for i in 0..n {
            let cols = &rows.col[rows.ptr[i] as usize..rows.ptr[i + 1] as usize];
            assert!(cols.windows(2).all(|w| w[0] < w[1]) && cols.iter().all(|&j| (j as usize) < i), "row {i}");
        }
        let made = f.row_copy_bytes();
        assert_eq!(made, rows.ptr.len() * 4 + rows.col.len() * 12);
        let unmade = Cholesky::new(&m).unwrap();
        assert_eq!((unmade.heap_bytes() + made, unmade.row_copy_bytes()), (f.heap_bytes(), made));
    }

    #[test]
    fn permuted_multi_column_solves_match_the_per_row_solve_bit_for_bit() {
        for (a, supernodal) in [(grid(40, 0.0), false), (grid(70, 0.0), true)] {
            let threshold =
                if supernodal { SupernodalThreshold::FORCE_SUPERNODAL } else { SupernodalThreshold::FORCE_SIMPLICIAL };
            let f = Cholesky::with_threshold(&a, Ordering::Amd, threshold).unwrap();
            let n = a.n;
            let column = |c: usize| -> Vec<[f64; 3]> {
                (0..n).map(|i| [((i * 7 + c) % 11) as f64 - 5.0, (i % (c + 2)) as f64, c as f64 + 0.5]).collect()
            };
            // A monomorphised width (12 = 4 blocks of 3) and a runtime one (15 = 5 blocks, 21 = 7 blocks are
            // listed; 33 = 11 blocks is not).
            for blocks in [4usize, 5, 11] {
                let w = 3 * blocks;
                let mut rows = vec![0.0; n * w];
                for b in 0..blocks {
                    let x = column(b);
                    for (k, &orig) in f.permutation().iter().enumerate() {
                        rows[k * w + 3 * b..k * w + 3 * b + 3].copy_from_slice(&x[orig as usize]);
                    }
                }
                f.solve_permuted(w, &mut rows);
                for b in 0..blocks {
                    let mut x = column(b);
                    let mut work = vec![[0.0; 3]; n];
                    f.solve_in_place(&mut x, &mut work);
                    for (k, &orig) in f.permutation().iter().enumerate() {
                        assert_eq!(&rows[k * w + 3 * b..k * w + 3 * b + 3], &x[orig as usize], "width {w}, block {b}");
                    }
                }
            }
        }
    }

    /// The AVX2 and AVX-512 builds of the sweeps give the portable one's
    /// bits (same operations, same order, no FMA), for widths that fill a
    /// register exactly, leave a remainder, or are narrower than one.
    #[test]
    fn vector_unit_variants_solve_bit_for_bit_alike() {
        fn check<const W: usize>(f: &Cholesky) {
            let n = f.n();
            let rhs: Vec<[f64; W]> = (0..n)
                .map(|i| std::array::from_fn(|c| ((i * 13 + c * 5) % 17) as f64 - 8.0 + 1.0 / (c + 1) as f64))
                .collect();
            let mut portable = rhs.clone();
            f.sweep_body::<W>(&mut portable);
            assert!(portable.iter().flatten().all(|x| x.is_finite()));
            #[cfg(target_arch = "x86_64")]
            {
                let mut tried = 0;
                if std::arch::is_x86_feature_detected!("avx2") {
                    let mut x = rhs.clone();
                    // SAFETY: the CPU has AVX2 (checked above).
                    unsafe { f.sweep_avx2::<W>(&mut x) };
                    assert_eq!(x, portable, "AVX2, width {W}");
                    tried += 1;
                }
                if std::arch::is_x86_feature_detected!("avx512f") {
                    let mut x = rhs.clone();
                    // SAFETY: the CPU has AVX-512F (checked above).
                    unsafe { f.sweep_avx512::<W>(&mut x) };
                    assert_eq!(x, portable, "AVX-512, width {W}");
                    tried += 1;
                }
                eprintln!("width {W}: {tried} vector variant(s) compared (detected: {})", Simd::detect().name());
            }
            // The dispatching entry point is one of them.
            let mut x = rhs.clone();
            f.sweep::<W>(&mut x);
            assert_eq!(x, portable, "dispatched ({}), width {W}", Simd::detect().name());
        }
        let f = Cholesky::new(&grid(45, 0.0)).unwrap();
        check::<1>(&f);
        check::<3>(&f);
        check::<9>(&f);
        check::<13>(&f);
        check::<72>(&f);
    }

    /// A factor renumbered into its own order solves the renumbered matrix
    /// (rows permuted by the returned permutation) bit for bit as the
    /// original factor solves the original one, without a permutation, and
    /// refactors matrices given in the new numbering.
    #[test]
    fn a_factor_in_its_own_order_solves_the_renumbered_matrix() {
        let a = grid(40, 0.0);
        let f = Cholesky::new(&a).unwrap();
        let (g, perm) = f.clone().into_factor_order();
        assert!(g.in_factor_order() && !f.in_factor_order());
        assert!(g.permutation().iter().enumerate().all(|(k, &p)| p as usize == k));
        assert_ne!(perm, g.permutation(), "AMD moved rows of the grid");
        let mut inv = vec![0u32; a.n];
        for (k, &p) in perm.iter().enumerate() {
            inv[p as usize] = k as u32;
        }
        let renumber = |m: &SymmetricTriplets| SymmetricTriplets {
            n: m.n,
            entries: m
                .entries
                .iter()
                .map(|&(r, c, v)| {
                    let (r, c) = (inv[r as usize], inv[c as usize]);
                    (r.max(c), r.min(c), v)
                })
                .collect(),
        };
        let rhs: Vec<[f64; 3]> = (0..a.n).map(|i| [i as f64, ((i * 7) % 5) as f64 - 2.0, 1.0]).collect();
        let (mut x, mut work) = (rhs.clone(), vec![[0.0; 3]; a.n]);
        f.solve_in_place(&mut x, &mut work);
        let mut y: Vec<[f64; 3]> = perm.iter().map(|&p| rhs[p as usize]).collect();
        g.solve_in_place(&mut y, &mut work);
        for (k, &p) in perm.iter().enumerate() {
            assert_eq!(y[k], x[p as usize], "row {k}");
        }
        // Refactoring the renumbered matrix with doubled values halves the solution.
        let mut doubled = renumber(&a);
        doubled.entries.iter_mut().for_each(|e| e.2 *= 2.0);
        let h = g.refactor(&doubled).unwrap();
        assert!(h.in_factor_order());
        let mut z: Vec<[f64; 3]> = perm.iter().map(|&p| rhs[p as usize]).collect();
        h.solve_in_place(&mut z, &mut work);
        for (k, &p) in perm.iter().enumerate() {
            for c in 0..3 {
                assert!((2.0 * z[k][c] - x[p as usize][c]).abs() <= 1e-12 * (1.0 + x[p as usize][c].abs()));
            }
        }
        // An upper-triangle triplet is refused, naming it.
        let bad = SymmetricTriplets { n: a.n, entries: vec![(0, 1, 1.0)] };
        assert!(matches!(g.refactor(&bad), Err(Error::Internal { .. })));
    }

    #[test]
    fn refactor_reuses_the_pattern() {
        let a = grid(30, 0.0);
        let f = Cholesky::new(&a).unwrap();
        let mut b2 = a.clone();
        for e in &mut b2.entries {
            e.2 *= 2.0;
        }
        let g = f.refactor(&b2).unwrap();
        assert!(Arc::ptr_eq(&f.blocks, &g.blocks));
        let mut rhs = vec![[1.0; 1]; a.n];
        let mut rhs2 = rhs.clone();
        let mut w = vec![[0.0; 1]; a.n];
        f.solve_in_place(&mut rhs, &mut w);
        g.solve_in_place(&mut rhs2, &mut w);
        for (p, q) in rhs.iter().zip(&rhs2) {
            assert!((p[0] - 2.0 * q[0]).abs() < 1e-10);
        }
    }

    /// A matrix of uncoupled pieces (grids of several sizes and single
    /// rows, their rows shuffled together) factors block by block: L
    /// couples no two pieces, solves to rounding, has no more fill than the
    /// pieces factored alone (within 10%), is bit-identical on one thread
    /// and on two, refactors, and names a failing pivot by its own row.
    #[test]
    fn uncoupled_blocks_factor_apart_and_alike() {
        let seed = 0x5eed_b10c_u64;
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        let pieces: Vec<SymmetricTriplets> = [12usize, 20, 5, 1, 30, 7]
            .iter()
            .map(|&m| grid(m, 0.0))
            .chain((0..40).map(|i| SymmetricTriplets { n: 1, entries: vec![(0, 0, 1.0 + i as f64)] }))
            .collect();
        let n: usize = pieces.iter().map(|p| p.n).sum();
        // A random placement of every piece's rows among all rows.
        let mut place: Vec<u32> = (0..n as u32).collect();
        for i in (1..n).rev() {
            place.swap(i, next() % (i + 1));
        }
        let (mut entries, mut piece_of, mut first) = (Vec::new(), vec![0usize; n], 0);
        for (k, p) in pieces.iter().enumerate() {
            for &(r, c, v) in &p.entries {
                let (r, c) = (place[first + r as usize], place[first + c as usize]);
                entries.push((r.max(c), r.min(c), v));
            }
            for i in 0..p.n {
                piece_of[place[first + i] as usize] = k;
            }
            first += p.n;
        }
        let a = SymmetricTriplets { n, entries };
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| Cholesky::new(&a).unwrap())
        };
        let (f, g) = (on(1), on(2));
        assert!(f.blocks.len() > 1, "seed {seed:#x}: one block");
        assert_eq!((&f.perm, &f.col_ptr, &f.row_idx), (&g.perm, &g.col_ptr, &g.row_idx), "seed {seed:#x}");
        assert!(f.values.iter().zip(&g.values).all(|(x, y)| x.to_bits() == y.to_bits()), "seed {seed:#x}");
        let mut seen = vec![false; n];
        for &p in &f.perm {
            assert!(!std::mem::replace(&mut seen[p as usize], true), "seed {seed:#x}: row {p} twice in perm");
        }
        for k in 0..n {
            for &r in &f.row_idx[f.col_ptr[k] as usize..f.col_ptr[k + 1] as usize] {
                let (pr, pk) = (f.perm[r as usize] as usize, f.perm[k] as usize);
                assert_eq!(piece_of[pr], piece_of[pk], "seed {seed:#x}: L couples rows {pr} and {pk}");
            }
        }
        let alone: usize = pieces.iter().map(|p| Cholesky::new(p).unwrap().nnz()).sum();
        assert!(f.nnz() as f64 <= 1.1 * alone as f64, "seed {seed:#x}: {} nonzeros, {alone} alone", f.nnz());
        let x: Vec<[f64; 2]> = (0..n).map(|i| [i as f64, (i % 3) as f64 - 1.0]).collect();
        let check = |f: &Cholesky, scale: f64| {
            let mut b = multiply(&a, &x);
            f.solve_in_place(&mut b, &mut vec![[0.0; 2]; n]);
            let err = b.iter().zip(&x).flat_map(|(p, q)| (0..2).map(move |k| (scale * p[k] - q[k]).abs()));
            let err = err.fold(0.0, f64::max);
            assert!(err < 1e-9 * n as f64, "seed {seed:#x}: max error {err}");
        };
        check(&f, 1.0);
        // Refactored with doubled values (the blocks' analyses reused): half the solution.
        let doubled = SymmetricTriplets { n, entries: a.entries.iter().map(|&(r, c, v)| (r, c, 2.0 * v)).collect() };
        let h = f.refactor(&doubled).unwrap();
        assert!(Arc::ptr_eq(&f.blocks, &h.blocks));
        check(&h, 2.0);
        // A negative single-row piece: the error names its row.
        let bad_row = place[n - 1];
        let mut bad = a.clone();
        for e in &mut bad.entries {
            if e.0 == bad_row && e.1 == bad_row {
                e.2 = -1.0;
            }
        }
        assert_eq!(Cholesky::new(&bad).unwrap_err(), Error::NotPositiveDefinite { pivot: Some(bad_row as usize) });
    }

    #[test]
    fn indefinite_matrices_are_refused() {
        let a = SymmetricTriplets { n: 2, entries: vec![(0, 0, 1.0), (1, 0, 2.0), (1, 1, 1.0)] };
        assert!(matches!(Cholesky::new(&a).unwrap_err(), Error::NotPositiveDefinite { pivot: Some(_) }));
        // A diagonal matrix, positive but for row 3 of 5: the error names row 3, whatever the ordering.
        let d = SymmetricTriplets {
            n: 5,
            entries: (0..5).map(|i| (i, i, if i == 3 { -1.0 } else { 1.0 + i as f64 })).collect(),
        };
        assert_eq!(Cholesky::new(&d).unwrap_err(), Error::NotPositiveDefinite { pivot: Some(3) });
    }
}
