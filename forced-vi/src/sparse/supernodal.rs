//! The supernodal LU of [`super::lu::SparseLu`] on a structure fixed by the analysis (see
//! that module for why it is ours and how faer's LU backs it up): the pattern of `A + Aᵀ`
//! ordered by faer's AMD and split into supernodes by faer's symbolic Cholesky, each
//! supernode one panel factored by faer's dense LU with partial pivoting, the updates from
//! earlier supernodes dense products gathered left-looking, in buffers sized once.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::factor::{lu_in_place, lu_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_unit_lower_triangular_in_place,
    solve_upper_triangular_in_place,
};
use faer::sparse::SymbolicSparseColMatRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, SymbolicSupernodalParams};
use faer::{Accum, MatMut, MatRef, Par, Side};

/// The supernode amalgamation: two supernodes of `n` columns in all merge when their
/// explicit zeros would be less than the given fraction (faer's default merges up to 80 %
/// zeros at 16 columns, which slows banded patterns by a quarter).
/// Supernodes of at least this many columns are solved with faer's dense kernels (a
/// triangular solve and a matrix-vector product on the panel); smaller ones by plain loops,
/// which cost less than the kernels' set-up. Measured (callgrind, whole runs at n = 1024):
/// at 8, the 2-D lattice's adaptive lobatto4 run (tol 1e-6) took 0.900G instructions
/// against 0.969G with loops only (0.924G at 16, 0.951G at 32), and the FPU chain's, whose
/// supernodes are smaller, the same; at 4 the chain's took 3 to 10 % more.
const DENSE_KERNELS: usize = 8;

/// The right-hand sides of [`Supernodal::solve_block_in_place`].
pub(crate) const BLOCK: usize = crate::backend::TANGENT_BLOCK;

const RELAX: &[(usize, f64)] = &[(4, 1.0), (16, 0.2), (48, 0.05)];

/// The supernodal LU of `B = P A Pᵀ` (`B[i, j] = A[perm[i], perm[j]]`) on a fixed structure.
///
/// Supernode `s` has the columns `begin[s] .. begin[s + 1]` (`ns` of them) and below them the
/// rows `rows(s)` (`nr`, sorted, in `B`'s order). Its storage, at `val_ptr[s]`, is the panel
/// `[L₁₁\U₁₁  U₁₂]` (`ns × (ns + nr)`, column-major), whose columns are the supernode's and
/// then `rows(s)`, with its rows in pivot order (`piv`), followed by `L₂₁` (`nr × ns`).
pub(crate) struct Supernodal {
    perm: Vec<usize>,
    begin: Vec<usize>,
    rows_ptr: Vec<usize>,
    rows: Vec<usize>,
    val_ptr: Vec<usize>,
    val: Vec<f64>,
    /// Where each entry of `A` goes in `val`.
    dest: Vec<usize>,
    /// The updates that supernode `t` gathers: `(d, k0, k1)` for each earlier supernode `d`
    /// whose rows `rows(d)[k0..k1]` are columns of `t`.
    upd_ptr: Vec<usize>,
    upd: Vec<(usize, usize, usize)>,
    /// The pivot order of each supernode's rows (local indices), at the supernode's columns.
    piv: Vec<usize>,
    piv_inv: Vec<usize>,
    /// Position in the current supernode's panel of each of its `rows`.
    map: Vec<usize>,
    /// Update products.
    work: Vec<f64>,
    /// The solve's vector in `B`'s order, and one supernode's part of it.
    y: Vec<f64>,
    tmp: Vec<f64>,
    /// Scratch of a solve: the rows below a supernode (their share, or their values).
    below: Vec<f64>,
    /// [`Supernodal::solve_block_in_place`]'s `y`, `tmp` and `below` for [`BLOCK`] right-hand
    /// sides, made on its first call.
    block: Vec<f64>,
    /// Scratch of faer's dense LU.
    mem: MemBuffer,
}

impl Supernodal {
    /// The analysis of the pattern; `None` if faer's symbolic Cholesky fails or its structure
    /// is not the one expected (then faer's LU does every factorisation).
    pub(crate) fn new(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> Option<Supernodal> {
        // The upper triangle of the pattern of A + Aᵀ, with the diagonal: entry `(r, c)`
        // goes to column `max(r, c)` at row `min(r, c)`. Bucketed by column (a counting
        // sort), then each column's few rows sorted and deduplicated in place: one sort of
        // all the pairs cost more than the rest of the analysis on the 1024-coordinate chain.
        let mut up_ptr = vec![0usize; n + 1];
        for c in 0..n {
            up_ptr[c + 1] += 1;
            for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                up_ptr[r.max(c) + 1] += 1;
            }
        }
        for c in 0..n {
            up_ptr[c + 1] += up_ptr[c];
        }
        let mut up_idx = vec![0usize; up_ptr[n]];
        let mut next = up_ptr.clone();
        for c in 0..n {
            up_idx[next[c]] = c;
            next[c] += 1;
            for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                let col = r.max(c);
                up_idx[next[col]] = r.min(c);
                next[col] += 1;
            }
        }
        drop(next);
        // Sort and deduplicate column by column, compacting towards the front.
        let mut kept = 0;
        for c in 0..n {
            let (a, b) = (up_ptr[c], up_ptr[c + 1]);
            up_idx[a..b].sort_unstable();
            up_ptr[c] = kept;
            let mut last = None;
            for k in a..b {
                let r = up_idx[k];
                if last != Some(r) {
                    up_idx[kept] = r;
                    kept += 1;
                    last = Some(r);
                }
            }
        }
        up_ptr[n] = kept;
        up_idx.truncate(kept);

        let (perm, begin, rows_ptr, rows) = if n == 0 {
            (Vec::new(), vec![0], vec![0], Vec::new())
        } else {
            let upper = SymbolicSparseColMatRef::new_checked(n, n, &up_ptr, None, &up_idx);
            let params = CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                supernodal_params: SymbolicSupernodalParams { relax: Some(RELAX) },
                ..Default::default()
            };
            let symbolic =
                factorize_symbolic_cholesky(upper, Side::Upper, SymmetricOrdering::Amd, params)
                    .ok()?;
            let perm = symbolic.perm()?.arrays().0.to_vec();
            let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
                return None;
            };
            let mut begin = sn.supernode_begin().to_vec();
            begin.push(n);
            let mut rows_ptr = vec![0usize];
            let mut rows = Vec::new();
            for s in 0..sn.n_supernodes() {
                let start = rows.len();
                rows.extend_from_slice(sn.supernode(s).pattern());
                rows[start..].sort_unstable();
                rows_ptr.push(rows.len());
            }
            (perm, begin, rows_ptr, rows)
        };
        let n_super = begin.len() - 1;
        let mut super_of = vec![0usize; n];
        for s in 0..n_super {
            super_of[begin[s]..begin[s + 1]].fill(s);
        }
        let size = |s: usize| (begin[s + 1] - begin[s], rows_ptr[s + 1] - rows_ptr[s]);
        let rows_of = |s: usize| &rows[rows_ptr[s]..rows_ptr[s + 1]];
        // Every row below a supernode is after it.
        if (0..n_super).any(|s| rows_of(s).first().is_some_and(|&r| r < begin[s + 1])) {
            return None;
        }
        let mut val_ptr = vec![0usize; n_super + 1];
        for s in 0..n_super {
            let (ns, nr) = size(s);
            val_ptr[s + 1] = val_ptr[s] + ns * (ns + 2 * nr);
        }

        // Where each entry of A goes.
        let mut inv = vec![0usize; n];
        for (i, &p) in perm.iter().enumerate() {
            inv[p] = i;
        }
        let mut dest = Vec::with_capacity(row_idx.len());
        for c in 0..n {
            for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                let (bi, bj) = (inv[r], inv[c]);
                let (si, sj) = (super_of[bi], super_of[bj]);
                let at = if si == sj {
                    let (ns, _) = size(si);
                    val_ptr[si] + (bi - begin[si]) + (bj - begin[si]) * ns
                } else if bi < bj {
                    let (ns, _) = size(si);
                    let k = rows_of(si).binary_search(&bj).ok()?;
                    val_ptr[si] + (bi - begin[si]) + (ns + k) * ns
                } else {
                    let (ns, nr) = size(sj);
                    let k = rows_of(sj).binary_search(&bi).ok()?;
                    val_ptr[sj] + ns * (ns + nr) + k + (bj - begin[sj]) * nr
                };
                dest.push(at);
            }
        }

        // The updates, grouped by the supernode that gathers them; the rows of `d` from
        // `k0` on must be columns or rows of that supernode.
        let mut groups = Vec::new();
        for d in 0..n_super {
            let r = rows_of(d);
            let mut k0 = 0;
            while k0 < r.len() {
                let t = super_of[r[k0]];
                let k1 = k0 + r[k0..].partition_point(|&x| x < begin[t + 1]);
                if r[k1..].iter().any(|x| rows_of(t).binary_search(x).is_err()) {
                    return None;
                }
                groups.push((t, d, k0, k1));
                k0 = k1;
            }
        }
        let mut upd_ptr = vec![0usize; n_super + 1];
        for &(t, ..) in &groups {
            upd_ptr[t + 1] += 1;
        }
        for t in 0..n_super {
            upd_ptr[t + 1] += upd_ptr[t];
        }
        let mut next = upd_ptr.clone();
        let mut upd = vec![(0, 0, 0); groups.len()];
        let mut work_len = 0;
        for &(t, d, k0, k1) in &groups {
            upd[next[t]] = (d, k0, k1);
            next[t] += 1;
            let m = size(d).1;
            work_len = work_len.max((k1 - k0) * (m - k0));
        }
        let max_ns = (0..n_super).map(|s| size(s).0).max().unwrap_or(0);
        let max_nr = (0..n_super).map(|s| size(s).1).max().unwrap_or(0);
        let req = lu_in_place_scratch::<usize, f64>(
            max_ns,
            max_ns + max_nr,
            Par::Seq,
            Default::default(),
        );
        let mem = MemBuffer::try_new(req).ok()?;
        Some(Supernodal {
            perm,
            begin,
            rows_ptr,
            rows,
            val: vec![0.0; val_ptr[n_super]],
            val_ptr,
            dest,
            upd_ptr,
            upd,
            piv: vec![0; n],
            piv_inv: vec![0; max_ns],
            map: vec![0; n],
            work: vec![0.0; work_len],
            y: vec![0.0; n],
            tmp: vec![0.0; max_ns],
            below: vec![0.0; max_nr],
            block: Vec::new(),
            mem,
        })
    }

    /// Factors `values` (on `A`'s pattern); `false` at a zero (or non-finite) pivot.
    pub(crate) fn factor(&mut self, values: &[f64]) -> bool {
        self.val.fill(0.0);
        for (&at, &v) in self.dest.iter().zip(values) {
            self.val[at] = v;
        }
        let n_super = self.begin.len() - 1;
        for s in 0..n_super {
            let (c0, c1) = (self.begin[s], self.begin[s + 1]);
            let ns = c1 - c0;
            let rows_s = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
            let nr = rows_s.len();
            for (k, &r) in rows_s.iter().enumerate() {
                self.map[r] = ns + k;
            }
            let (done, rest) = self.val.split_at_mut(self.val_ptr[s]);
            let (panel, l21) =
                rest[..self.val_ptr[s + 1] - self.val_ptr[s]].split_at_mut(ns * (ns + nr));
            for &(d, k0, k1) in &self.upd[self.upd_ptr[s]..self.upd_ptr[s + 1]] {
                let nd = self.begin[d + 1] - self.begin[d];
                let rows_d = &self.rows[self.rows_ptr[d]..self.rows_ptr[d + 1]];
                let m = rows_d.len();
                let storage = &done[self.val_ptr[d]..self.val_ptr[d + 1]];
                let (u_d, l_d) = storage.split_at(nd * (nd + m));
                let u_d = MatRef::from_column_major_slice(u_d, nd, nd + m);
                let l_d = MatRef::from_column_major_slice(l_d, m, nd);
                let k = k1 - k0;
                // Rows of the panel: L_d[k0..k1] U_d[:, k0..] (columns: the supernode's, then
                // its rows).
                {
                    let w = &mut self.work[..k * (m - k0)];
                    matmul(
                        MatMut::from_column_major_slice_mut(w, k, m - k0),
                        Accum::Replace,
                        l_d.subrows(k0, k),
                        u_d.subcols(nd + k0, m - k0),
                        1.0,
                        Par::Seq,
                    );
                    for (jj, &cj) in rows_d[k0..].iter().enumerate() {
                        let col = if cj < c1 { cj - c0 } else { self.map[cj] };
                        let dst = &mut panel[col * ns..(col + 1) * ns];
                        for (&ri, &x) in rows_d[k0..k1].iter().zip(&w[jj * k..(jj + 1) * k]) {
                            dst[ri - c0] -= x;
                        }
                    }
                }
                // Columns of L₂₁: L_d[k1..] U_d[:, k0..k1].
                if m > k1 {
                    let mk = m - k1;
                    let w = &mut self.work[..mk * k];
                    matmul(
                        MatMut::from_column_major_slice_mut(w, mk, k),
                        Accum::Replace,
                        l_d.subrows(k1, mk),
                        u_d.subcols(nd + k0, k),
                        1.0,
                        Par::Seq,
                    );
                    for (jj, &cj) in rows_d[k0..k1].iter().enumerate() {
                        let dst = &mut l21[(cj - c0) * nr..(cj - c0 + 1) * nr];
                        for (&ri, &x) in rows_d[k1..].iter().zip(&w[jj * mk..(jj + 1) * mk]) {
                            dst[self.map[ri] - ns] -= x;
                        }
                    }
                }
            }
            // P [A₁₁ A₁₂] = L₁₁ [U₁₁ U₁₂], pivots from the diagonal block only.
            lu_in_place(
                MatMut::from_column_major_slice_mut(panel, ns, ns + nr),
                &mut self.piv[c0..c1],
                &mut self.piv_inv[..ns],
                Par::Seq,
                MemStack::new(&mut self.mem),
                Default::default(),
            );
            if (0..ns).any(|k| {
                let p = panel[k + k * ns];
                p == 0.0 || !p.is_finite()
            }) {
                return false;
            }
            if nr > 0 {
                // L₂₁ = A₂₁ U₁₁⁻¹, from U₁₁ᵀ L₂₁ᵀ = A₂₁ᵀ.
                let u11 = MatRef::from_column_major_slice(&panel[..ns * ns], ns, ns);
                let l = MatMut::from_column_major_slice_mut(l21, nr, ns);
                solve_lower_triangular_in_place(u11.transpose(), l.transpose_mut(), Par::Seq);
            }
        }
        true
    }

    /// Solves with the last factors.
    pub(crate) fn solve_in_place(&mut self, x: &mut [f64]) {
        let y = &mut self.y;
        for (yi, &p) in y.iter_mut().zip(&self.perm) {
            *yi = x[p];
        }
        let n_super = self.begin.len() - 1;
        // The loops run over zipped slices (no index arithmetic per entry); the operations,
        // and their order on each entry, are the plain column-oriented substitution's.
        // L: P_s on the supernode's part, L₁₁⁻¹, then the rows below take L₂₁'s share.
        for s in 0..n_super {
            let (c0, c1) = (self.begin[s], self.begin[s + 1]);
            let ns = c1 - c0;
            let rows_s = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
            let nr = rows_s.len();
            let storage = &self.val[self.val_ptr[s]..self.val_ptr[s + 1]];
            let (panel, l21) = storage.split_at(ns * (ns + nr));
            let tmp = &mut self.tmp[..ns];
            let ys = &mut y[c0..c1];
            for (t, &p) in tmp.iter_mut().zip(&self.piv[c0..c1]) {
                *t = ys[p];
            }
            if ns >= DENSE_KERNELS {
                // A large supernode (a 2-D lattice's): faer's triangular solve and
                // matrix-vector product on the panel.
                let l11 = MatRef::from_column_major_slice(&panel[..ns * ns], ns, ns);
                let t = MatMut::from_column_major_slice_mut(tmp, ns, 1);
                solve_unit_lower_triangular_in_place(l11, t, Par::Seq);
                ys.copy_from_slice(tmp);
                if nr > 0 {
                    let w = &mut self.below[..nr];
                    matmul(
                        MatMut::from_column_major_slice_mut(w, nr, 1),
                        Accum::Replace,
                        MatRef::from_column_major_slice(l21, nr, ns),
                        MatRef::from_column_major_slice(tmp, ns, 1),
                        1.0,
                        Par::Seq,
                    );
                    for (&r, &x) in rows_s.iter().zip(w.iter()) {
                        y[r] -= x;
                    }
                }
                continue;
            }
            for k in 0..ns {
                let yk = tmp[k];
                let col = &panel[k * ns + k + 1..(k + 1) * ns];
                for (t, &l) in tmp[k + 1..].iter_mut().zip(col) {
                    *t -= l * yk;
                }
            }
            ys.copy_from_slice(tmp);
            // Column by column: `L₂₁` is stored by columns, and a large supernode (a 2-D
            // lattice's) reads it in order.
            for (&yk, l21k) in tmp.iter().zip(l21.chunks_exact(nr.max(1))) {
                for (&r, &l) in rows_s.iter().zip(l21k) {
                    y[r] -= l * yk;
                }
            }
        }
        // U: the rows below give U₁₂'s share, then U₁₁⁻¹.
        for s in (0..n_super).rev() {
            let (c0, c1) = (self.begin[s], self.begin[s + 1]);
            let ns = c1 - c0;
            let rows_s = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
            let panel = &self.val[self.val_ptr[s]..self.val_ptr[s] + ns * (ns + rows_s.len())];
            let (head, tail) = y.split_at_mut(c1);
            let ys = &mut head[c0..];
            if ns >= DENSE_KERNELS {
                let nr = rows_s.len();
                if nr > 0 {
                    let g = &mut self.below[..nr];
                    for (gi, &r) in g.iter_mut().zip(rows_s) {
                        *gi = tail[r - c1];
                    }
                    matmul(
                        MatMut::from_column_major_slice_mut(ys, ns, 1),
                        Accum::Add,
                        MatRef::from_column_major_slice(&panel[ns * ns..], ns, nr),
                        MatRef::from_column_major_slice(g, nr, 1),
                        -1.0,
                        Par::Seq,
                    );
                }
                let u11 = MatRef::from_column_major_slice(&panel[..ns * ns], ns, ns);
                solve_upper_triangular_in_place(
                    u11,
                    MatMut::from_column_major_slice_mut(ys, ns, 1),
                    Par::Seq,
                );
                continue;
            }
            for (&r, u12) in rows_s.iter().zip(panel[ns * ns..].chunks_exact(ns)) {
                let yr = tail[r - c1];
                for (yi, &u) in ys.iter_mut().zip(u12) {
                    *yi -= u * yr;
                }
            }
            for k in (0..ns).rev() {
                let col = &panel[k * ns..k * ns + k + 1];
                ys[k] /= col[k];
                let yk = ys[k];
                for (yi, &u) in ys[..k].iter_mut().zip(col) {
                    *yi -= u * yk;
                }
            }
        }
        for (&yi, &p) in y.iter().zip(&self.perm) {
            x[p] = yi;
        }
    }

    /// Solves with the last factors for [`BLOCK`] right-hand sides at once, interleaved:
    /// entry `i` of right-hand side `b` at `x[i * BLOCK + b]`. Each right-hand side goes
    /// through the same operations, in the same order, as in [`Self::solve_in_place`] (so
    /// the results are the same to the bit); on the small supernodes' loops the `BLOCK`
    /// of them share each factor entry's load.
    pub(crate) fn solve_block_in_place(&mut self, x: &mut [f64]) {
        let n = self.perm.len();
        let max_ns = self.tmp.len();
        let max_nr = self.below.len();
        let need = (n + max_ns + max_nr) * BLOCK;
        if self.block.len() < need {
            self.block.resize(need, 0.0);
        }
        let (y, rest) = self.block.split_at_mut(n * BLOCK);
        let (tmp, below) = rest.split_at_mut(max_ns * BLOCK);
        let (y, _) = y.as_chunks_mut::<BLOCK>();
        let (tmp, _) = tmp.as_chunks_mut::<BLOCK>();
        let (below, _) = below.as_chunks_mut::<BLOCK>();
        let (xs, _) = x.as_chunks_mut::<BLOCK>();
        for (yi, &p) in y.iter_mut().zip(&self.perm) {
            *yi = xs[p];
        }
        let n_super = self.begin.len() - 1;
        // One column at a time through faer's kernels, for a large supernode: its entries
        // gathered into `self.tmp` and `self.below`, as the single solve has them.
        let column = |y: &[[f64; BLOCK]], b: usize, out: &mut [f64]| {
            for (o, yi) in out.iter_mut().zip(y) {
                *o = yi[b];
            }
        };
        for s in 0..n_super {
            let (c0, c1) = (self.begin[s], self.begin[s + 1]);
            let ns = c1 - c0;
            let rows_s = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
            let nr = rows_s.len();
            let storage = &self.val[self.val_ptr[s]..self.val_ptr[s + 1]];
            let (panel, l21) = storage.split_at(ns * (ns + nr));
            if ns >= DENSE_KERNELS {
                for b in 0..BLOCK {
                    let t1 = &mut self.tmp[..ns];
                    for (t, &p) in t1.iter_mut().zip(&self.piv[c0..c1]) {
                        *t = y[c0 + p][b];
                    }
                    let l11 = MatRef::from_column_major_slice(&panel[..ns * ns], ns, ns);
                    let t = MatMut::from_column_major_slice_mut(&mut *t1, ns, 1);
                    solve_unit_lower_triangular_in_place(l11, t, Par::Seq);
                    for (yi, &t) in y[c0..c1].iter_mut().zip(t1.iter()) {
                        yi[b] = t;
                    }
                    if nr > 0 {
                        let w = &mut self.below[..nr];
                        matmul(
                            MatMut::from_column_major_slice_mut(w, nr, 1),
                            Accum::Replace,
                            MatRef::from_column_major_slice(l21, nr, ns),
                            MatRef::from_column_major_slice(&self.tmp[..ns], ns, 1),
                            1.0,
                            Par::Seq,
                        );
                        for (&r, &x) in rows_s.iter().zip(w.iter()) {
                            y[r][b] -= x;
                        }
                    }
                }
                continue;
            }
            let tmp = &mut tmp[..ns];
            for (t, &p) in tmp.iter_mut().zip(&self.piv[c0..c1]) {
                *t = y[c0 + p];
            }
            for k in 0..ns {
                let yk = tmp[k];
                let col = &panel[k * ns + k + 1..(k + 1) * ns];
                for (t, &l) in tmp[k + 1..].iter_mut().zip(col) {
                    for (tb, yb) in t.iter_mut().zip(yk) {
                        *tb -= l * yb;
                    }
                }
            }
            y[c0..c1].copy_from_slice(tmp);
            for (yk, l21k) in tmp.iter().zip(l21.chunks_exact(nr.max(1))) {
                for (&r, &l) in rows_s.iter().zip(l21k) {
                    for (rb, yb) in y[r].iter_mut().zip(yk) {
                        *rb -= l * yb;
                    }
                }
            }
        }
        for s in (0..n_super).rev() {
            let (c0, c1) = (self.begin[s], self.begin[s + 1]);
            let ns = c1 - c0;
            let rows_s = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
            let nr = rows_s.len();
            let panel = &self.val[self.val_ptr[s]..self.val_ptr[s] + ns * (ns + nr)];
            if ns >= DENSE_KERNELS {
                for b in 0..BLOCK {
                    let ys = &mut self.tmp[..ns];
                    column(&y[c0..c1], b, ys);
                    if nr > 0 {
                        let g = &mut self.below[..nr];
                        for (gi, &r) in g.iter_mut().zip(rows_s) {
                            *gi = y[r][b];
                        }
                        matmul(
                            MatMut::from_column_major_slice_mut(&mut *ys, ns, 1),
                            Accum::Add,
                            MatRef::from_column_major_slice(&panel[ns * ns..], ns, nr),
                            MatRef::from_column_major_slice(&*g, nr, 1),
                            -1.0,
                            Par::Seq,
                        );
                    }
                    let u11 = MatRef::from_column_major_slice(&panel[..ns * ns], ns, ns);
                    solve_upper_triangular_in_place(
                        u11,
                        MatMut::from_column_major_slice_mut(&mut *ys, ns, 1),
                        Par::Seq,
                    );
                    for (yi, &v) in y[c0..c1].iter_mut().zip(ys.iter()) {
                        yi[b] = v;
                    }
                }
                continue;
            }
            let g = &mut below[..nr];
            for (gi, &r) in g.iter_mut().zip(rows_s) {
                *gi = y[r];
            }
            let ys = &mut y[c0..c1];
            for (yr, u12) in g.iter().zip(panel[ns * ns..].chunks_exact(ns)) {
                for (yi, &u) in ys.iter_mut().zip(u12) {
                    for (ib, rb) in yi.iter_mut().zip(yr) {
                        *ib -= u * rb;
                    }
                }
            }
            for k in (0..ns).rev() {
                let col = &panel[k * ns..k * ns + k + 1];
                let d = col[k];
                ys[k].iter_mut().for_each(|v| *v /= d);
                let yk = ys[k];
                for (yi, &u) in ys[..k].iter_mut().zip(col) {
                    for (ib, kb) in yi.iter_mut().zip(yk) {
                        *ib -= u * kb;
                    }
                }
            }
        }
        for (yi, &p) in y.iter().zip(&self.perm) {
            xs[p] = *yi;
        }
    }
}
