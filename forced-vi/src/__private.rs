//! Paths and helpers for code written by `#[forced_lagrangian]`. Not a public API.
//!
//! Generated code reaches the runtime only through `::forced_vi::__private`, so a user crate
//! needs no direct num-dual or nalgebra dependency. The helpers below are the dual-number
//! building blocks of the specialised node kernels: each differentiates one term of the
//! Lagrangian (or one force component) over only the variables that the term uses.
//!
//! Variables are numbered by *slot*: slot `s < N` is `q[s]`, slot `s ≥ N` is `v[s − N]`.

pub use nalgebra;
pub use num_dual;

pub use crate::doubled;
pub use crate::model::{general, ForcedLagrangian, NodeGradient, NodeJacobian, Structure};
pub use crate::scalar::{lift, Scalar};
pub use core::primitive::f64;
pub use nalgebra::{SMatrix, SVector};

use core::cell::Cell;

use num_dual::{gradient, hessian, jacobian, partial_hessian};
use num_dual::{Dual2SVec64, DualSVec64, HyperDualSVec64};

std::thread_local! {
    static INDEX_FAULT: Cell<Option<&'static str>> = const { Cell::new(None) };
}

/// `a[i]`, or NaN when `i` is out of range (never a panic); the first such index expression
/// `what` is recorded for [`take_index_fault`]. Generated code uses it for every index that the macro
/// could not prove in range.
#[inline(always)]
pub fn at<D: Scalar, I: Int>(a: &[D], i: I, what: &'static str) -> D {
    match i.to_index().and_then(|k| a.get(k)) {
        Some(x) => *x,
        None => {
            INDEX_FAULT.with(|f| {
                if f.get().is_none() {
                    f.set(Some(what));
                }
            });
            D::from(f64::NAN)
        }
    }
}

/// The index expression of the last out-of-range [`at`] on this thread, cleared.
pub fn take_index_fault() -> Option<&'static str> {
    INDEX_FAULT.with(|f| f.take())
}

/// The integers of model code: arithmetic wraps (an index that wraps is out of range, and
/// [`at`] reports it) instead of panicking.
pub trait Int: Copy {
    /// Wrapping `+`.
    fn wrapping_add_(self, o: Self) -> Self;
    /// Wrapping `-`.
    fn wrapping_sub_(self, o: Self) -> Self;
    /// Wrapping `*`.
    fn wrapping_mul_(self, o: Self) -> Self;
    /// `/`, with the type's maximum for a division by zero.
    fn div_(self, o: Self) -> Self;
    /// `%`, with the type's maximum for a division by zero.
    fn rem_(self, o: Self) -> Self;
    /// The value as an index, if it is one.
    fn to_index(self) -> Option<usize>;
}

macro_rules! impl_int {
    ($($t:ty),*) => {$(
        impl Int for $t {
            #[inline(always)]
            fn wrapping_add_(self, o: Self) -> Self { self.wrapping_add(o) }
            #[inline(always)]
            fn wrapping_sub_(self, o: Self) -> Self { self.wrapping_sub(o) }
            #[inline(always)]
            fn wrapping_mul_(self, o: Self) -> Self { self.wrapping_mul(o) }
            #[inline(always)]
            fn div_(self, o: Self) -> Self { self.checked_div(o).unwrap_or(<$t>::MAX) }
            #[inline(always)]
            fn rem_(self, o: Self) -> Self { self.checked_rem(o).unwrap_or(<$t>::MAX) }
            #[inline(always)]
            fn to_index(self) -> Option<usize> { usize::try_from(self).ok() }
        }
    )*};
}
impl_int!(u8, u16, u32, u64, u128, usize, i8, i16, i32, i64, i128, isize);

/// `a + b` in model code.
#[inline(always)]
pub fn int_add<I: Int>(a: I, b: I) -> I {
    a.wrapping_add_(b)
}
/// `a - b` in model code.
#[inline(always)]
pub fn int_sub<I: Int>(a: I, b: I) -> I {
    a.wrapping_sub_(b)
}
/// `a * b` in model code.
#[inline(always)]
pub fn int_mul<I: Int>(a: I, b: I) -> I {
    a.wrapping_mul_(b)
}
/// `a / b` in model code.
#[inline(always)]
pub fn int_div<I: Int>(a: I, b: I) -> I {
    a.div_(b)
}
/// `a % b` in model code.
#[inline(always)]
pub fn int_rem<I: Int>(a: I, b: I) -> I {
    a.rem_(b)
}

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
    if a > b {
        a
    } else {
        b
    }
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

// ---------------------------------------------------------------------------------------
// Sparse node kernels (DESIGN §9): generated per-term code evaluates each term of `L` and
// each force entry over a dual number of only the K slots it reads, and scatters the small
// gradient and Hessian through an [`Accum`] (the runtime's `NodeSink`, or dense blocks).

pub use crate::sparse::{Block, NodeSink, SparseNode};

/// The slot index of a coordinate that does not exist at this term (an index out of
/// range): it is neither read nor written.
pub const ABSENT: usize = usize::MAX;

/// Where generated per-term kernels add their results.
pub trait Accum {
    /// Whether block entries are wanted.
    fn wants_blocks(&self) -> bool;
    /// Adds to `(L_q + F)_i`.
    fn add_lq_f(&mut self, i: usize, x: f64);
    /// Adds to `(L_v)_i`.
    fn add_lv(&mut self, i: usize, x: f64);
    /// Adds to entry `(row, col)` of `block`.
    fn add(&mut self, block: Block, row: usize, col: usize, x: f64);
}

impl Accum for NodeSink<'_> {
    #[inline(always)]
    fn wants_blocks(&self) -> bool {
        NodeSink::wants_blocks(self)
    }
    #[inline(always)]
    fn add_lq_f(&mut self, i: usize, x: f64) {
        NodeSink::add_lq_f(self, i, x);
    }
    #[inline(always)]
    fn add_lv(&mut self, i: usize, x: f64) {
        NodeSink::add_lv(self, i, x);
    }
    #[inline(always)]
    fn add(&mut self, block: Block, row: usize, col: usize, x: f64) {
        NodeSink::add(self, block, row, col, x);
    }
}

/// Dense node blocks as an [`Accum`] (the dense kernels of a model that splits into terms).
pub struct DenseAccum<'a, const N: usize> {
    grad: &'a mut NodeGradient<N>,
    blocks: Option<[&'a mut SMatrix<f64, N, N>; 4]>,
}

impl<'a, const N: usize> DenseAccum<'a, N> {
    /// The gradient alone.
    pub fn gradient(grad: &'a mut NodeGradient<N>) -> Self {
        DenseAccum { grad, blocks: None }
    }
    /// The gradient and the blocks `A, B, C, E`.
    pub fn jacobian(j: &'a mut NodeJacobian<N>) -> Self {
        let NodeJacobian { grad, a, b, c, e } = j;
        DenseAccum {
            grad,
            blocks: Some([a, b, c, e]),
        }
    }
}

impl<const N: usize> Accum for DenseAccum<'_, N> {
    #[inline(always)]
    fn wants_blocks(&self) -> bool {
        self.blocks.is_some()
    }
    #[inline(always)]
    fn add_lq_f(&mut self, i: usize, x: f64) {
        if let Some(s) = self.grad.fq.get_mut(i) {
            *s += x;
        }
    }
    #[inline(always)]
    fn add_lv(&mut self, i: usize, x: f64) {
        if let Some(s) = self.grad.lv.get_mut(i) {
            *s += x;
        }
    }
    #[inline(always)]
    fn add(&mut self, block: Block, row: usize, col: usize, x: f64) {
        let k = match block {
            Block::A => 0,
            Block::B => 1,
            Block::C => 2,
            Block::E => 3,
        };
        if let Some(s) = self.blocks.as_mut().and_then(|b| b[k].get_mut((row, col))) {
            *s += x;
        }
    }
}

/// A bound on the stack of the dense kernels of a model that splits into terms: the node
/// blocks they return and small dual numbers.
pub const fn split_stack_bytes<const N: usize>() -> usize {
    core::mem::size_of::<NodeJacobian<N>>()
        .saturating_mul(3)
        .saturating_add(512 * 1024)
}

/// The slot of index `k` into a group of `len` coordinates starting at `offset`, or
/// [`ABSENT`] when `k` is out of range.
#[inline(always)]
pub fn slot_index<I: Int>(k: I, offset: usize, len: usize) -> usize {
    match k.to_index() {
        Some(k) if k < len => offset.checked_add(k).unwrap_or(ABSENT),
        _ => ABSENT,
    }
}

/// The values of the slots (`v[s]` where `vel[s]`, else `q[s]`; NaN for an absent slot).
#[inline(always)]
pub fn slot_values<const K: usize>(
    q: &[f64],
    v: &[f64],
    slots: &[usize; K],
    vel: &[bool; K],
) -> SVector<f64, K> {
    SVector::from(core::array::from_fn(|k| {
        let a = if vel[k] { v } else { q };
        a.get(slots[k]).copied().unwrap_or(f64::NAN)
    }))
}

/// Adds one Lagrangian term's gradient over its slots, and its Hessian into the blocks.
#[inline(always)]
pub fn add_term<A: Accum, const K: usize>(
    acc: &mut A,
    slots: &[usize; K],
    vel: &[bool; K],
    g: &SVector<f64, K>,
    h: Option<&SMatrix<f64, K, K>>,
) {
    for k in 0..K {
        let s = slots[k];
        if s == ABSENT {
            continue;
        }
        if vel[k] {
            acc.add_lv(s, g[k]);
        } else {
            acc.add_lq_f(s, g[k]);
        }
        let Some(h) = h else { continue };
        for l in 0..K {
            let t = slots[l];
            if t == ABSENT {
                continue;
            }
            let block = match (vel[k], vel[l]) {
                (false, false) => Block::A,
                (false, true) => Block::B,
                (true, false) => Block::C,
                (true, true) => Block::E,
            };
            acc.add(block, s, t, h[(k, l)]);
        }
    }
}

/// Adds one force component `F_row` and, when given, its derivatives over the slots to
/// `A(row, ·)` and `B(row, ·)`.
#[inline(always)]
pub fn add_force<A: Accum, const K: usize>(
    acc: &mut A,
    row: usize,
    slots: &[usize; K],
    vel: &[bool; K],
    f: f64,
    g: Option<&SVector<f64, K>>,
) {
    acc.add_lq_f(row, f);
    let Some(g) = g else { return };
    for k in 0..K {
        let s = slots[k];
        if s == ABSENT {
            continue;
        }
        let block = if vel[k] { Block::B } else { Block::A };
        acc.add(block, row, s, g[k]);
    }
}
