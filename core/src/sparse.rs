//! A compressed sparse row matrix with `u32` indices, multiplying
//! right-hand sides stored per row (`[f64; K]`), as the frame solve keeps
//! them. (faer's sparse × dense takes column-major dense matrices; the
//! frame's data are row-interleaved, so this small kernel is written here.)

/// `nrows × ncols` in compressed rows; duplicates summed at construction.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Csr {
    nrows: usize,
    ncols: usize,
    #[serde(with = "crate::persist::pod")]
    row_ptr: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    col: Vec<u32>,
    #[serde(with = "crate::persist::pod")]
    val: Vec<f64>,
}

impl Csr {
    /// Builds from `(row, col, value)` triplets; duplicates are summed.
    pub fn from_triplets(nrows: usize, ncols: usize, mut entries: Vec<(u32, u32, f64)>) -> Self {
        entries.sort_unstable_by_key(|e| (e.0, e.1));
        let mut row_ptr = vec![0u32; nrows + 1];
        let mut col = Vec::with_capacity(entries.len());
        let mut val: Vec<f64> = Vec::with_capacity(entries.len());
        let mut last = (u32::MAX, u32::MAX);
        for (r, c, v) in entries {
            if (r, c) == last {
                *val.last_mut().expect("a previous entry") += v;
                continue;
            }
            last = (r, c);
            row_ptr[r as usize + 1] += 1;
            col.push(c);
            val.push(v);
        }
        for r in 0..nrows {
            row_ptr[r + 1] += row_ptr[r];
        }
        Self { nrows, ncols, row_ptr, col, val }
    }

    /// The matrix with its rows reordered: row `k` of the result is row
    /// `perm[k]` of `self` (`perm` a permutation of the rows).
    pub fn permute_rows(&self, perm: &[u32]) -> Self {
        assert_eq!(perm.len(), self.nrows, "a permutation of the rows");
        let mut row_ptr = Vec::with_capacity(self.nrows + 1);
        let mut col = Vec::with_capacity(self.col.len());
        let mut val = Vec::with_capacity(self.val.len());
        row_ptr.push(0u32);
        for &r in perm {
            let range = self.row_ptr[r as usize] as usize..self.row_ptr[r as usize + 1] as usize;
            col.extend_from_slice(&self.col[range.clone()]);
            val.extend_from_slice(&self.val[range]);
            row_ptr.push(col.len() as u32);
        }
        Self { nrows: self.nrows, ncols: self.ncols, row_ptr, col, val }
    }

    pub fn nrows(&self) -> usize {
        self.nrows
    }
    pub fn ncols(&self) -> usize {
        self.ncols
    }
    pub fn nnz(&self) -> usize {
        self.val.len()
    }

    /// `y += alpha · A x`, K columns per row.
    pub fn mul_add<const K: usize>(&self, x: &[[f64; K]], y: &mut [[f64; K]], alpha: f64) {
        debug_assert_eq!(x.len(), self.ncols);
        debug_assert_eq!(y.len(), self.nrows);
        for (r, yr) in y.iter_mut().enumerate() {
            let (s, e) = (self.row_ptr[r] as usize, self.row_ptr[r + 1] as usize);
            let mut acc = [0.0; K];
            for p in s..e {
                let (v, xr) = (self.val[p], &x[self.col[p] as usize]);
                for k in 0..K {
                    acc[k] += v * xr[k];
                }
            }
            for k in 0..K {
                yr[k] += alpha * acc[k];
            }
        }
    }
}

/// The most frames a lane-interleaved product takes ([`Csr::mul_add_lanes`]):
/// its per-row accumulator lives on the stack.
pub const MAX_LANES: usize = 32;

impl Csr {
    /// `y = alpha · A x` (`set`) or `y += alpha · A x` for `lanes`
    /// right-hand sides at once, on lane-interleaved rows: row `r` of `x`
    /// (and of `y`) holds `C · lanes` values, component `c` of lane `i` at
    /// `c · lanes + i`. Each lane gets the operations of [`Self::mul_add`]
    /// with `K = C`, in the same order (`set` adds into a zero, as
    /// `mul_add` into a zeroed `y` would), so its result is bit for bit
    /// that of its own product; the matrix is read once for all lanes, and
    /// each entry is one multiply-add of `C · lanes` contiguous values
    /// (vectorised for the widest unit the CPU has,
    /// [`Simd`](crate::simd::Simd); no fused multiply-add, as everywhere in
    /// the frame).
    ///
    /// # Panics
    /// If `lanes` or `C` is 0, `lanes` above [`MAX_LANES`], `C` above 9, or `x`/`y` are
    /// not `ncols`/`nrows` rows of `C · lanes`.
    pub fn mul_add_lanes<const C: usize>(&self, x: &[f64], y: &mut [f64], lanes: usize, alpha: f64, set: bool) {
        assert!((1..=MAX_LANES).contains(&lanes), "1 to {MAX_LANES} lanes, not {lanes}");
        assert!((1..=9).contains(&C), "1 to 9 components per lane");
        let w = C * lanes;
        assert_eq!(x.len(), self.ncols * w, "x: ncols rows of C · lanes");
        assert_eq!(y.len(), self.nrows * w, "y: nrows rows of C · lanes");
        use crate::simd::Simd;
        match Simd::detect() {
            // SAFETY: `Simd::detect` found the feature on this CPU.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { self.mul_add_lanes_avx512::<C>(x, y, lanes, alpha, set) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { self.mul_add_lanes_avx2::<C>(x, y, lanes, alpha, set) },
            Simd::Baseline => self.mul_add_lanes_any::<C>(x, y, lanes, alpha, set),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn mul_add_lanes_avx512<const C: usize>(
        &self,
        x: &[f64],
        y: &mut [f64],
        lanes: usize,
        alpha: f64,
        set: bool,
    ) {
        self.mul_add_lanes_any::<C>(x, y, lanes, alpha, set);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn mul_add_lanes_avx2<const C: usize>(&self, x: &[f64], y: &mut [f64], lanes: usize, alpha: f64, set: bool) {
        self.mul_add_lanes_any::<C>(x, y, lanes, alpha, set);
    }

    /// [`Self::mul_add_lanes`], compiled for the common group sizes so
    /// that a row's accumulator stays in registers.
    #[inline(always)]
    fn mul_add_lanes_any<const C: usize>(&self, x: &[f64], y: &mut [f64], lanes: usize, alpha: f64, set: bool) {
        match lanes {
            2 => self.mul_add_lanes_fixed::<C, 2>(x, y, alpha, set),
            4 => self.mul_add_lanes_fixed::<C, 4>(x, y, alpha, set),
            8 => self.mul_add_lanes_fixed::<C, 8>(x, y, alpha, set),
            16 => self.mul_add_lanes_fixed::<C, 16>(x, y, alpha, set),
            _ => self.mul_add_lanes_dyn(x, y, C * lanes, alpha, set),
        }
    }

    #[inline(always)]
    fn mul_add_lanes_fixed<const C: usize, const L: usize>(&self, x: &[f64], y: &mut [f64], alpha: f64, set: bool) {
        let (x, _) = x.as_chunks::<L>();
        let (y, _) = y.as_chunks_mut::<L>();
        for (r, yr) in y.chunks_exact_mut(C).enumerate() {
            let mut acc = [[0.0; L]; C];
            for p in self.row_ptr[r] as usize..self.row_ptr[r + 1] as usize {
                let (v, c) = (self.val[p], self.col[p] as usize);
                let xr = &x[c * C..(c + 1) * C];
                for (a, xc) in acc.iter_mut().zip(xr) {
                    for i in 0..L {
                        a[i] += v * xc[i];
                    }
                }
            }
            for (yc, a) in yr.iter_mut().zip(&acc) {
                for i in 0..L {
                    yc[i] = if set { 0.0 } else { yc[i] } + alpha * a[i];
                }
            }
        }
    }

    /// [`Self::mul_add_lanes`] with rows of `w` values, any `w` up to `9 · MAX_LANES`.
    #[inline(always)]
    fn mul_add_lanes_dyn(&self, x: &[f64], y: &mut [f64], w: usize, alpha: f64, set: bool) {
        let mut acc = [0.0; 9 * MAX_LANES];
        let acc = &mut acc[..w];
        for (r, yr) in y.chunks_exact_mut(w).enumerate() {
            acc.fill(0.0);
            for p in self.row_ptr[r] as usize..self.row_ptr[r + 1] as usize {
                let (v, c) = (self.val[p], self.col[p] as usize);
                let xr = &x[c * w..(c + 1) * w];
                for (a, &xv) in acc.iter_mut().zip(xr) {
                    *a += v * xv;
                }
            }
            for (yv, &a) in yr.iter_mut().zip(acc.iter()) {
                *yv = if set { 0.0 } else { *yv } + alpha * a;
            }
        }
    }
}

/// The root of `x` in the disjoint-set forest `parent` (`parent[r] == r`
/// at a root), halving the path on the way (each visited node then points
/// to its grandparent).
pub(crate) fn disjoint_root(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

/// Groups items `i = 0..keys.len()` by their key `keys[i] < n_keys` (a
/// counting sort): returns `start` (`n_keys + 1` offsets) and `order`, the
/// items of key `k` at `order[start[k]..start[k + 1]]`, in increasing `i`.
/// Linear time; the adjacency lists of the binding (outgoing halfedges,
/// twins, the transposed right-hand-side operator) are built with it.
pub(crate) fn group_by_key(n_keys: usize, keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; n_keys + 1];
    for &k in keys {
        start[k as usize + 1] += 1;
    }
    for k in 0..n_keys {
        start[k + 1] += start[k];
    }
    let mut fill = start.clone();
    let mut order = vec![0u32; keys.len()];
    for (i, &k) in keys.iter().enumerate() {
        order[fill[k as usize] as usize] = i as u32;
        fill[k as usize] += 1;
    }
    (start, order)
}

impl Csr {
    /// Heap bytes held (see [`crate::heap`]).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::bytes;
        bytes(&self.row_ptr) + bytes(&self.col) + bytes(&self.val)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicates_sum_and_multiply() {
        let a = Csr::from_triplets(2, 3, vec![(1, 2, 1.0), (0, 0, 2.0), (1, 2, 3.0), (0, 1, -1.0)]);
        assert_eq!(a.nnz(), 3);
        let x = [[1.0, 0.0], [2.0, 1.0], [3.0, -1.0]];
        let mut y = [[1.0, 1.0], [0.0, 0.0]];
        a.mul_add(&x, &mut y, 2.0);
        assert_eq!(y, [[1.0 + 2.0 * (2.0 - 2.0), 1.0 + 2.0 * (0.0 - 1.0)], [2.0 * 12.0, 2.0 * -4.0]]);
    }

    /// Every lane of a lane-interleaved product is bit for bit its own
    /// `mul_add` (into a zeroed `y` for `set`), for every group size, both
    /// modes and every vector variant this CPU has.
    #[test]
    fn lanes_equal_their_own_products_bit_for_bit() {
        fn check<const C: usize>(seed: u64) {
            let mut rng = crate::polygon_laplacian::tests::Rng(seed);
            let (nrows, ncols) = (37, 29);
            let mut triplets = Vec::new();
            for r in 0..nrows as u32 {
                // Some rows empty, some long, with duplicates.
                for _ in 0..((rng.next() + 1.0) * 4.0) as usize * (r % 5 != 3) as usize {
                    triplets.push((r, ((rng.next() + 1.0) * 0.5 * ncols as f64) as u32, rng.next() * 1e3));
                }
            }
            let a = Csr::from_triplets(nrows, ncols, triplets);
            for lanes in 1..=MAX_LANES {
                let w = C * lanes;
                let x: Vec<f64> = (0..ncols * w).map(|_| rng.next()).collect();
                let y0: Vec<f64> = (0..nrows * w).map(|_| rng.next()).collect();
                for set in [true, false] {
                    let alpha = if set { -1.0 } else { 0.37 };
                    let mut variants: Vec<(&str, Vec<f64>)> = Vec::new();
                    let mut y = y0.clone();
                    a.mul_add_lanes::<C>(&x, &mut y, lanes, alpha, set);
                    variants.push(("dispatched", y));
                    let mut y = y0.clone();
                    a.mul_add_lanes_any::<C>(&x, &mut y, lanes, alpha, set);
                    variants.push(("portable", y));
                    #[cfg(target_arch = "x86_64")]
                    {
                        if std::arch::is_x86_feature_detected!("avx2") {
                            let mut y = y0.clone();
                            // SAFETY: the feature was detected.
                            unsafe { a.mul_add_lanes_avx2::<C>(&x, &mut y, lanes, alpha, set) };
                            variants.push(("avx2", y));
                        }
                        if std::arch::is_x86_feature_detected!("avx512f") {
                            let mut y = y0.clone();
                            // SAFETY: the feature was detected.
                            unsafe { a.mul_add_lanes_avx512::<C>(&x, &mut y, lanes, alpha, set) };
                            variants.push(("avx512", y));
                        }
                    }
                    for i in 0..lanes {
                        let xi: Vec<[f64; C]> =
                            (0..ncols).map(|r| std::array::from_fn(|c| x[r * w + c * lanes + i])).collect();
                        let mut yi: Vec<[f64; C]> = (0..nrows)
                            .map(|r| std::array::from_fn(|c| if set { 0.0 } else { y0[r * w + c * lanes + i] }))
                            .collect();
                        a.mul_add(&xi, &mut yi, alpha);
                        for (name, y) in &variants {
                            for (r, want) in yi.iter().enumerate() {
                                for c in 0..C {
                                    let got = y[r * w + c * lanes + i];
                                    assert_eq!(
                                        got.to_bits(),
                                        want[c].to_bits(),
                                        "C = {C}, {lanes} lanes, set {set}, {name}: lane {i}, row {r}, component {c}"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
        check::<9>(0x2545_F491_4F6C_DD1D);
        check::<3>(0x9E37_79B9_7F4A_7C15);
    }
}
