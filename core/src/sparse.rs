//! A compressed sparse row matrix with `u32` indices, multiplying
//! right-hand sides stored per row (`[f64; K]`), as the frame solve keeps
//! them. (faer's sparse × dense takes column-major dense matrices; the
//! frame's data are row-interleaved, so this small kernel is written here.)

/// `nrows × ncols` in compressed rows; duplicates summed at construction.
#[derive(Debug, Clone, Default)]
pub struct Csr {
    nrows: usize,
    ncols: usize,
    row_ptr: Vec<u32>,
    col: Vec<u32>,
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
}
