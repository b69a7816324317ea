//! The dual-number building blocks of the specialised dense node kernels: each
//! differentiates one term of the Lagrangian (or one force component) over only the slots
//! that the term uses, and adds the result to the node blocks.

use nalgebra::{SMatrix, SVector};
use num_dual::{Dual2SVec64, DualSVec64, HyperDualSVec64};
use num_dual::{gradient, hessian, jacobian, partial_hessian};

use crate::model::{NodeGradient, NodeJacobian};
use crate::scalar::{Scalar, lift};

/// A bound on the stack of one generated kernel helper whose dual number is `T`: arrays of
/// `N` of them (the lifted `q` and `v` and their copies), `values` more (the model code's
/// temporaries) and the node blocks.
pub const fn kernel_stack_bytes<T, const N: usize>(values: usize) -> usize {
    let t = core::mem::size_of::<T>();
    let arrays = t.saturating_mul(N).saturating_mul(16);
    let temps = t.saturating_mul(values);
    let blocks = core::mem::size_of::<NodeJacobian<N>>().saturating_mul(8);
    arrays
        .saturating_add(temps)
        .saturating_add(blocks)
        .saturating_add(256 * 1024)
}

/// The larger of two sizes (for const expressions).
pub const fn max_usize(a: usize, b: usize) -> usize {
    if a > b { a } else { b }
}

/// Zeroed gradient blocks.
#[inline(always)]
pub fn zero_gradient<const N: usize>() -> NodeGradient<N> {
    NodeGradient {
        fq: SVector::zeros(),
        lv: SVector::zeros(),
    }
}

/// Zeroed gradient and Jacobian blocks.
#[inline(always)]
pub fn zero_jacobian<const N: usize>() -> NodeJacobian<N> {
    NodeJacobian {
        grad: zero_gradient(),
        a: SMatrix::zeros(),
        b: SMatrix::zeros(),
        c: SMatrix::zeros(),
        e: SMatrix::zeros(),
    }
}

/// The slots `first, first + 1, …, first + K − 1`.
#[inline(always)]
pub fn slot_range<const K: usize>(first: usize) -> [usize; K] {
    core::array::from_fn(|k| first + k)
}

/// `(q, v)` lifted to `D`, with the slots replaced by the seeded variables `z`.
#[inline(always)]
fn place<D: Scalar, const N: usize, const K: usize>(
    q: &[f64; N],
    v: &[f64; N],
    slots: &[usize; K],
    z: &SVector<D, K>,
) -> ([D; N], [D; N]) {
    let mut qd: [D; N] = lift(q);
    let mut vd: [D; N] = lift(v);
    // A slot out of range (an index beyond a const-generic length) seeds nothing; its
    // start value and the kernel's output are NaN (see `start` and `poison`).
    for (k, &s) in slots.iter().enumerate() {
        if let Some(x) = qd.get_mut(s) {
            *x = z[k];
        } else if let Some(x) = s.checked_sub(N).and_then(|t| vd.get_mut(t)) {
            *x = z[k];
        }
    }
    (qd, vd)
}

#[inline(always)]
fn start<const N: usize, const K: usize>(
    q: &[f64; N],
    v: &[f64; N],
    slots: &[usize; K],
) -> SVector<f64, K> {
    SVector::from(core::array::from_fn(|k| {
        let s = slots[k];
        q.get(s)
            .or_else(|| s.checked_sub(N).and_then(|t| v.get(t)))
            .copied()
            .unwrap_or(f64::NAN)
    }))
}

/// Adds the first derivatives of one Lagrangian term over `slots` to `(L_q, L_v)`.
#[inline(always)]
pub fn term_gradient<F, const N: usize, const K: usize>(
    q: &[f64; N],
    v: &[f64; N],
    slots: &[usize; K],
    term: F,
    out: &mut NodeGradient<N>,
) where
    F: Fn(&[DualSVec64<K>; N], &[DualSVec64<K>; N]) -> DualSVec64<K>,
{
    let (_, g) = gradient(
        |z: SVector<DualSVec64<K>, K>| {
            let (qd, vd) = place(q, v, slots, &z);
            term(&qd, &vd)
        },
        &start(q, v, slots),
    );
    if poison(slots, out) {
        return;
    }
    for (k, &s) in slots.iter().enumerate() {
        if s < N {
            out.fq[s] += g[k];
        } else {
            out.lv[s - N] += g[k];
        }
    }
}

/// A slot beyond `2N` (an out-of-range index of the model): the outputs become NaN so that
/// the runtime reports a non-finite model instead of a wrong derivative.
fn poison<const N: usize, const K: usize>(slots: &[usize; K], out: &mut NodeGradient<N>) -> bool {
    let bad = slots.iter().any(|&s| s >= N.saturating_mul(2));
    if bad {
        out.fq.fill(f64::NAN);
        out.lv.fill(f64::NAN);
    }
    bad
}

/// Adds the first and second derivatives of one Lagrangian term over `slots` to the
/// gradient and the blocks `A = L_qq`, `B = L_qv`, `C = L_vq`, `E = L_vv`.
#[inline(always)]
pub fn term_hessian<F, const N: usize, const K: usize>(
    q: &[f64; N],
    v: &[f64; N],
    slots: &[usize; K],
    term: F,
    out: &mut NodeJacobian<N>,
) where
    F: Fn(&[Dual2SVec64<K>; N], &[Dual2SVec64<K>; N]) -> Dual2SVec64<K>,
{
    let (_, g, h) = hessian(
        |z: SVector<Dual2SVec64<K>, K>| {
            let (qd, vd) = place(q, v, slots, &z);
            term(&qd, &vd)
        },
        &start(q, v, slots),
    );
    if poison(slots, &mut out.grad) {
        return;
    }
    for (k, &s) in slots.iter().enumerate() {
        if s < N {
            out.grad.fq[s] += g[k];
        } else {
            out.grad.lv[s - N] += g[k];
        }
        for (l, &t) in slots.iter().enumerate() {
            let hkl = h[(k, l)];
            match (s < N, t < N) {
                (true, true) => out.a[(s, t)] += hkl,
                (true, false) => out.b[(s, t - N)] += hkl,
                (false, true) => out.c[(s - N, t)] += hkl,
                (false, false) => out.e[(s - N, t - N)] += hkl,
            }
        }
    }
}

/// Adds the mixed blocks `B = L_qv` and `C = L_vq` of one Lagrangian term over all `q` and
/// all `v` (for array models whose length is a const parameter).
#[inline(always)]
pub fn term_cross<F, const N: usize>(q: &[f64; N], v: &[f64; N], term: F, out: &mut NodeJacobian<N>)
where
    F: Fn(&[HyperDualSVec64<N, N>; N], &[HyperDualSVec64<N, N>; N]) -> HyperDualSVec64<N, N>,
{
    let (_, _, _, h) = partial_hessian(
        |(x, y): (
            SVector<HyperDualSVec64<N, N>, N>,
            SVector<HyperDualSVec64<N, N>, N>,
        )| {
            let xa: [HyperDualSVec64<N, N>; N] = x.into();
            let ya: [HyperDualSVec64<N, N>; N] = y.into();
            term(&xa, &ya)
        },
        (&SVector::from(*q), &SVector::from(*v)),
    );
    out.b += h;
    out.c += h.transpose();
}

/// Adds one force component (row `row`) and its first derivatives over `slots` to
/// `L_q + F`, `A` and `B`.
#[inline(always)]
pub fn force_row<F, const N: usize, const K: usize>(
    q: &[f64; N],
    v: &[f64; N],
    slots: &[usize; K],
    row: usize,
    component: F,
    out: &mut NodeJacobian<N>,
) where
    F: Fn(&[DualSVec64<K>; N], &[DualSVec64<K>; N]) -> DualSVec64<K>,
{
    let (f, g) = gradient(
        |z: SVector<DualSVec64<K>, K>| {
            let (qd, vd) = place(q, v, slots, &z);
            component(&qd, &vd)
        },
        &start(q, v, slots),
    );
    if row >= N || poison(slots, &mut out.grad) {
        out.grad.fq.fill(f64::NAN);
        return;
    }
    out.grad.fq[row] += f;
    for (k, &s) in slots.iter().enumerate() {
        if s < N {
            out.a[(row, s)] += g[k];
        } else {
            out.b[(row, s - N)] += g[k];
        }
    }
}

/// Adds `∂F/∂q` of the whole force to `A`, and `F` itself to `L_q + F` when `add_value`.
#[inline(always)]
pub fn force_jacobian_q<F, const N: usize>(
    q: &[f64; N],
    v: &[f64; N],
    add_value: bool,
    force: F,
    out: &mut NodeJacobian<N>,
) where
    F: FnOnce(&[DualSVec64<N>; N], &[DualSVec64<N>; N]) -> [DualSVec64<N>; N],
{
    let (f, jac) = jacobian(
        |x: SVector<DualSVec64<N>, N>| {
            let xa: [DualSVec64<N>; N] = x.into();
            SVector::from(force(&xa, &lift(v)))
        },
        &SVector::from(*q),
    );
    if add_value {
        out.grad.fq += f;
    }
    out.a += jac;
}

/// Adds `∂F/∂v` of the whole force to `B`, and `F` itself to `L_q + F` when `add_value`.
#[inline(always)]
pub fn force_jacobian_v<F, const N: usize>(
    q: &[f64; N],
    v: &[f64; N],
    add_value: bool,
    force: F,
    out: &mut NodeJacobian<N>,
) where
    F: FnOnce(&[DualSVec64<N>; N], &[DualSVec64<N>; N]) -> [DualSVec64<N>; N],
{
    let (f, jac) = jacobian(
        |y: SVector<DualSVec64<N>, N>| {
            let ya: [DualSVec64<N>; N] = y.into();
            SVector::from(force(&lift(q), &ya))
        },
        &SVector::from(*v),
    );
    if add_value {
        out.grad.fq += f;
    }
    out.b += jac;
}
