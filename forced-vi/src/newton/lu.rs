//! Dense LU with partial pivoting: [`DenseLu`] in buffers made once, for the step Jacobian,
//! and [`solve_small`] on the stack, for `N × N` blocks.

use crate::buffers::{zero_matrix, zeros};
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::NewtonFailure;

/// LU with partial pivoting, in place in a buffer made once.
///
/// nalgebra's `LU` allocates a permutation for each factorisation of a dynamically sized
/// matrix; the stepper factors a small matrix every iteration, so it keeps its own buffers.
#[derive(Clone, Debug)]
pub struct DenseLu {
    lu: DMatrix<f64>,
    piv: Vec<usize>,
    row_scale: Vec<f64>,
}

impl DenseLu {
    /// Buffers for `n × n` systems.
    pub fn new(n: usize) -> Self {
        DenseLu {
            lu: zero_matrix(n, n),
            piv: vec![0; n],
            row_scale: zeros(n),
        }
    }

    /// Factors `a`. Fails if a pivot is zero or negligible against the scale of its own
    /// row (a scale-invariant test: rows of very different sizes are not singular).
    ///
    /// Orders up to 24 run a copy of the same elimination compiled for their size
    /// (the loops unrolled, the bounds known). Its column updates run over every row and
    /// subtract exact zeros above the pivot, which leaves those entries as they were: the
    /// factors are those of the general loop, bit for bit but for the sign of a zero.
    pub fn factor(&mut self, a: &DMatrix<f64>) -> Result<(), NewtonFailure> {
        let n = a.nrows();
        self.lu.as_mut_slice().copy_from_slice(a.as_slice());
        let (m, piv, scale) = (
            self.lu.as_mut_slice(),
            &mut self.piv[..],
            &mut self.row_scale[..],
        );
        macro_rules! fixed {
            ($($k:literal)*) => {
                match n {
                    $($k => factor_in_place::<$k>(m, piv, scale),)*
                    _ => {
                        if m.iter().any(|x| !x.is_finite()) {
                            return Err(NewtonFailure::NonFinite);
                        }
                        factor_general(n, m, piv, scale)
                    }
                }
            };
        }
        fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24)
    }

    /// Solves `A x = b` in place with the last factors.
    pub fn solve_in_place(&self, b: &mut DVector<f64>) {
        let n = self.piv.len();
        let (m, piv, x) = (self.lu.as_slice(), &self.piv[..], b.as_mut_slice());
        macro_rules! fixed {
            ($($k:literal)*) => {
                match n {
                    $($k => solve_fixed::<$k>(m, piv, x),)*
                    _ => solve_general(n, m, piv, x),
                }
            };
        }
        fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24)
    }
}

/// The elimination of [`DenseLu::factor`] for order `K`, known at compile time: the
/// columns as `[f64; K]` arrays, so that every bound is a constant and no index is checked
/// at run time; the operations and their order are those of [`eliminate`], but that the
/// loops run over all `K` rows, masked at and above the pivot (constant lengths unroll: on
/// the coupled van der Pol oscillators, about 1.0k instead of 1.3k instructions per
/// factorisation of order 6, with the test for non-finite entries folded into the row
/// scales). On an x86-64 processor with AVX the same code runs compiled for AVX (see
/// [`factor_avx`]): about 8 % fewer instructions for a whole run of lobatto7 on the Kepler
/// problem (12 unknowns), 6 % for lobatto5 on the coupled van der Pol oscillators.
#[inline(never)]
fn factor_in_place<const K: usize>(
    m: &mut [f64],
    piv: &mut [usize],
    scale: &mut [f64],
) -> Result<(), NewtonFailure> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has AVX, checked just above.
        return unsafe { factor_avx::<K>(m, piv, scale) };
    }
    factor_body::<K>(m, piv, scale)
}

/// [`factor_body`] compiled for AVX (four lanes of `f64` instead of two; separate
/// multiplies and subtractions as in the scalar code, no fused multiply-add, so the
/// factors are the same bit for bit).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn factor_avx<const K: usize>(
    m: &mut [f64],
    piv: &mut [usize],
    scale: &mut [f64],
) -> Result<(), NewtonFailure> {
    factor_body::<K>(m, piv, scale)
}

/// The elimination of [`factor_in_place`].
#[inline(always)]
fn factor_body<const K: usize>(
    m: &mut [f64],
    piv: &mut [usize],
    scale: &mut [f64],
) -> Result<(), NewtonFailure> {
    let (cols, _) = m.as_chunks_mut::<K>();
    let (Some(cols), Some(piv)) = (cols.get_mut(..K), piv.get_mut(..K)) else {
        if m.iter().any(|x| !x.is_finite()) {
            return Err(NewtonFailure::NonFinite);
        }
        return eliminate(K, m, piv, scale);
    };
    // The row scales, and the test for non-finite entries in the same pass.
    let (mut sc, mut finite) = ([0.0f64; K], true);
    for col in cols.iter() {
        for (r, x) in sc.iter_mut().zip(col) {
            *r = r.max(x.abs());
            finite &= x.is_finite();
        }
    }
    if !finite {
        return Err(NewtonFailure::NonFinite);
    }
    for k in 0..K {
        // Loops of constant length `K`, rows at or above the pivot masked out, so that
        // they unroll: the first strictly largest entry below the diagonal, as in
        // `eliminate`.
        let (mut p, mut best) = (k, cols[k][k].abs());
        for (i, x) in cols[k].iter().enumerate() {
            let better = i > k && x.abs() > best;
            best = if better { x.abs() } else { best };
            p = if better { i } else { p };
        }
        if best <= sc[p] * f64::EPSILON * 1e-3 || best == 0.0 {
            return Err(NewtonFailure::SingularJacobian);
        }
        piv[k] = p;
        if p != k {
            for col in cols.iter_mut() {
                col.swap(k, p);
            }
            sc.swap(k, p);
        }
        let inv = 1.0 / cols[k][k];
        // The multipliers below the pivot, zeros above it: every column update then runs
        // over all `K` rows too.
        let mut l = [0.0f64; K];
        for (i, (x, li)) in cols[k].iter_mut().zip(&mut l).enumerate() {
            if i > k {
                *x *= inv;
                *li = *x;
            }
        }
        for col in &mut cols[k + 1..] {
            let u = col[k];
            for i in 0..K {
                col[i] -= l[i] * u;
            }
        }
    }
    Ok(())
}

/// [`DenseLu::factor`]'s elimination for any order.
fn factor_general(
    n: usize,
    m: &mut [f64],
    piv: &mut [usize],
    scale: &mut [f64],
) -> Result<(), NewtonFailure> {
    eliminate(n, m, piv, scale)
}

/// LU with partial pivoting of the column-major `n × n` matrix in `m` (`m[i + j n]` is row
/// `i`, column `j`), in place; `scale` is scratch for the row scales.
#[inline(always)]
fn eliminate(
    n: usize,
    m: &mut [f64],
    piv: &mut [usize],
    scale: &mut [f64],
) -> Result<(), NewtonFailure> {
    for (i, r) in scale.iter_mut().enumerate().take(n) {
        *r = (0..n).fold(0.0f64, |s, j| s.max(m[i + j * n].abs()));
    }
    for k in 0..n {
        let col = &m[k * n..(k + 1) * n];
        let (mut p, mut best) = (k, col[k].abs());
        for (i, x) in col.iter().enumerate().skip(k + 1) {
            if x.abs() > best {
                best = x.abs();
                p = i;
            }
        }
        if best <= scale[p] * f64::EPSILON * 1e-3 || best == 0.0 {
            return Err(NewtonFailure::SingularJacobian);
        }
        piv[k] = p;
        if p != k {
            for j in 0..n {
                m.swap(k + j * n, p + j * n);
            }
            scale.swap(k, p);
        }
        let inv = 1.0 / m[k + k * n];
        for x in &mut m[k * n + k + 1..(k + 1) * n] {
            *x *= inv;
        }
        for j in k + 1..n {
            let u = m[k + j * n];
            if u != 0.0 {
                let (left, right) = m.split_at_mut(j * n);
                let lcol = &left[k * n + k + 1..(k + 1) * n];
                for (x, l) in right[k + 1..n].iter_mut().zip(lcol) {
                    *x -= l * u;
                }
            }
        }
    }
    Ok(())
}

/// The substitutions of [`DenseLu::solve_in_place`] for order `K`, known at compile time
/// (the columns as arrays, as in [`factor_in_place`]; the operations of [`substitute`]).
/// Divisions by the pivots, not products with their reciprocals: those were about a third
/// of this function's time in sampled profiles of lobatto5 on coupled van der Pol, but whole
/// runs moved by less than this machine's noise, and the extra rounding turned three
/// adaptive runs of the stability report's scaled van der Pol (μ = 10⁶, lobatto4 at tol 1
/// and 1e-2, lobatto5 at 1e-6), which end `Ok` near the step-size floor, into
/// `StepSizeTooSmall` and `MaxStepsReached`.
#[inline(never)]
fn solve_fixed<const K: usize>(m: &[f64], piv: &[usize], x: &mut [f64]) {
    let (cols, _) = m.as_chunks::<K>();
    let (Some(cols), Some(piv), Some(x)) = (cols.get(..K), piv.get(..K), x.get_mut(..K)) else {
        return substitute(K, m, piv, x);
    };
    // In a local array, which the unrolled loops keep in registers: updated in place in
    // the caller's buffer, each entry was stored and loaded again once per column.
    let mut y = [0.0; K];
    y.copy_from_slice(x);
    for (k, &p) in piv.iter().enumerate() {
        if let Some(&v) = y.get(p) {
            y[p] = y[k];
            y[k] = v;
        }
    }
    for j in 0..K {
        let yj = y[j];
        if yj != 0.0 {
            for i in j + 1..K {
                y[i] -= cols[j][i] * yj;
            }
        }
    }
    for j in (0..K).rev() {
        y[j] /= cols[j][j];
        let yj = y[j];
        if yj != 0.0 {
            for i in 0..j {
                y[i] -= cols[j][i] * yj;
            }
        }
    }
    x.copy_from_slice(&y);
}

/// [`DenseLu::solve_in_place`]'s substitutions for any order.
fn solve_general(n: usize, m: &[f64], piv: &[usize], x: &mut [f64]) {
    substitute(n, m, piv, x);
}

/// Forward and back substitution with the factors in `m` and the pivots `piv`.
#[inline(always)]
fn substitute(n: usize, m: &[f64], piv: &[usize], x: &mut [f64]) {
    for (k, &p) in piv.iter().enumerate().take(n) {
        x.swap(k, p);
    }
    for j in 0..n {
        let xj = x[j];
        if xj != 0.0 {
            for (xi, l) in x[j + 1..n].iter_mut().zip(&m[j * n + j + 1..(j + 1) * n]) {
                *xi -= l * xj;
            }
        }
    }
    for j in (0..n).rev() {
        x[j] /= m[j + j * n];
        let xj = x[j];
        if xj != 0.0 {
            for (xi, u) in x[..j].iter_mut().zip(&m[j * n..j * n + j]) {
                *xi -= u * xj;
            }
        }
    }
}

/// Solves `a x = b` for a small static matrix by LU with partial pivoting, on the stack.
///
/// Returns `x` and a reciprocal condition estimate (smallest over largest pivot), or `None`
/// if a pivot is exactly zero or a value is not finite. nalgebra's own LU needs typenum
/// bounds that a generic `const N` cannot meet.
pub fn solve_small<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
) -> Option<(SVector<f64, N>, f64)> {
    let (mut a, mut x) = (*a, *b);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for k in 0..N {
        let p = (k..N).max_by(|&i, &j| a[(i, k)].abs().total_cmp(&a[(j, k)].abs()))?;
        let piv = a[(p, k)];
        if piv == 0.0 || !piv.is_finite() {
            return None;
        }
        lo = lo.min(piv.abs());
        hi = hi.max(piv.abs());
        a.swap_rows(k, p);
        x.swap_rows(k, p);
        for i in k + 1..N {
            let l = a[(i, k)] / piv;
            for j in k..N {
                let u = a[(k, j)];
                a[(i, j)] -= l * u;
            }
            let xk = x[k];
            x[i] -= l * xk;
        }
    }
    for i in (0..N).rev() {
        let mut s = x[i];
        for j in i + 1..N {
            s -= a[(i, j)] * x[j];
        }
        x[i] = s / a[(i, i)];
    }
    Some((x, if N == 0 { 1.0 } else { lo / hi }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The orders compiled apart (`factor_in_place`, `solve_fixed`) give bit for bit the
    /// factors, pivots and solutions of the general loops, pivoting included.
    #[test]
    fn fixed_orders_match_the_general_loop_bit_for_bit() {
        // A deterministic scramble (no rand dependency): entries of mixed signs and sizes.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        for n in 1..=25 {
            for _ in 0..20 {
                let a = DMatrix::from_fn(n, n, |_, _| next());
                let b = DVector::from_fn(n, |_, _| next());
                let mut lu = DenseLu::new(n);
                let fixed = lu.factor(&a);
                let (mut m, mut piv, mut sc) = (a.clone(), vec![0; n], vec![0.0; n]);
                let general = factor_general(n, m.as_mut_slice(), &mut piv, &mut sc);
                // The body compiled without AVX too (`factor` takes the AVX copy where the
                // processor has it).
                let (mut m0, mut piv0, mut sc0) = (a.clone(), vec![0; n], vec![0.0; n]);
                let (m0s, p0, s0) = (m0.as_mut_slice(), &mut piv0[..], &mut sc0[..]);
                macro_rules! body {
                    ($($k:literal)*) => {
                        match n {
                            $($k => factor_body::<$k>(m0s, p0, s0),)*
                            _ => factor_general(n, m0s, p0, s0),
                        }
                    };
                }
                let plain = body!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24);
                assert_eq!(fixed.is_ok(), general.is_ok(), "n = {n}");
                assert_eq!(plain.is_ok(), general.is_ok(), "n = {n}");
                if fixed.is_err() {
                    continue;
                }
                assert_eq!(lu.piv, piv, "n = {n}");
                assert_eq!(piv0, piv, "n = {n}");
                let same =
                    |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(u, v)| u.to_bits() == v.to_bits());
                assert!(same(lu.lu.as_slice(), m.as_slice()), "n = {n}");
                assert!(same(m0.as_slice(), m.as_slice()), "n = {n}");
                let (mut x1, mut x2) = (b.clone(), b.clone());
                lu.solve_in_place(&mut x1);
                solve_general(n, m.as_slice(), &piv, x2.as_mut_slice());
                assert!(same(x1.as_slice(), x2.as_slice()), "n = {n}");
            }
        }
    }

    /// A non-finite entry is an error, not factors, for the orders compiled apart and the
    /// general loop alike.
    #[test]
    fn non_finite_entries_are_refused_at_every_order() {
        for n in [1, 2, 6, 12, 16, 17, 20, 24, 25, 30] {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let mut a = DMatrix::<f64>::identity(n, n);
                a[(n - 1, n / 2)] = bad;
                let err = DenseLu::new(n).factor(&a);
                assert!(
                    matches!(err, Err(NewtonFailure::NonFinite)),
                    "n = {n}: {err:?}"
                );
            }
        }
    }
}
