//! Per-term kernels of models that split into local terms (DESIGN §9): generated code
//! evaluates each term of `L` and each force entry over a dual number of only the K slots it
//! reads, and scatters the small gradient and Hessian through an [`Accum`] (the runtime's
//! `NodeSink`, or dense blocks).

use nalgebra::{SMatrix, SVector};
use num_dual::{DualSVec64, HyperDualSVec64};

use super::int::Int;
use crate::model::{NodeGradient, NodeJacobian};
use crate::sparse::{Block, NodeSink};

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

/// A parameter derivative `∂/∂θ_k` of the node gradient as an [`Accum`]: `∂(L_q + F)/∂θ_k`
/// into `fq`, `∂L_v/∂θ_k` into `lv` (both zeroed by the caller), no blocks.
pub struct ThetaAccum<'a> {
    /// `∂(L_q + F)/∂θ_k`.
    pub fq: &'a mut [f64],
    /// `∂L_v/∂θ_k`.
    pub lv: &'a mut [f64],
}

impl Accum for ThetaAccum<'_> {
    #[inline(always)]
    fn wants_blocks(&self) -> bool {
        false
    }
    #[inline(always)]
    fn add_lq_f(&mut self, i: usize, x: f64) {
        if let Some(s) = self.fq.get_mut(i) {
            *s += x;
        }
    }
    #[inline(always)]
    fn add_lv(&mut self, i: usize, x: f64) {
        if let Some(s) = self.lv.get_mut(i) {
            *s += x;
        }
    }
    #[inline(always)]
    fn add(&mut self, _: Block, _: usize, _: usize, _: f64) {}
}

/// The parameters `theta` with `θ_k` seeded along `ε₂`, as the hyper-dual numbers of a term
/// of `K` slots (see [`term_theta_gradient`]).
pub fn theta_hyper<const K: usize>(theta: &[f64], k: usize) -> Vec<HyperDualSVec64<K, 1>> {
    (theta.iter().enumerate())
        .map(|(j, &x)| {
            let h = HyperDualSVec64::<K, 1>::from_re(x);
            if j == k { h.derivative2(0) } else { h }
        })
        .collect()
}

/// The parameters `theta` with `θ_k` seeded, as dual numbers (for the force entries).
pub fn theta_dual(theta: &[f64], k: usize) -> Vec<DualSVec64<1>> {
    (theta.iter().enumerate())
        .map(|(j, &x)| {
            let d = DualSVec64::<1>::from_re(x);
            if j == k { d.derivative(0) } else { d }
        })
        .collect()
}

/// `∂²T/∂z_j∂θ_k` for every slot `j` of one term `T(z; θ)` at the slot values `x`, where
/// `term` evaluates it with the parameters from [`theta_hyper`]: one evaluation with `ε₁`
/// along the slots. The same kind of numbers as the general kernels' (num-dual's vector
/// hyper-duals, whose parts a value does not depend on are absent rather than zero), so a
/// term whose value is NaN where its derivatives are finite (a logarithm of a negative
/// number) gives the same finite derivatives here: with scalar hyper-duals, `0 · NaN` made
/// them NaN (found by the generated models' comparison).
#[inline(always)]
pub fn term_theta_gradient<const K: usize>(
    x: &SVector<f64, K>,
    term: impl Fn(&[HyperDualSVec64<K, 1>; K]) -> HyperDualSVec64<K, 1>,
) -> SVector<f64, K> {
    let z: [HyperDualSVec64<K, 1>; K] =
        core::array::from_fn(|i| HyperDualSVec64::<K, 1>::from_re(x[i]).derivative1(i));
    match term(&z).eps1eps2.0 {
        Some(m) => SVector::from(core::array::from_fn(|i| m[(i, 0)])),
        None => SVector::zeros(),
    }
}

/// The slot values as constant dual numbers (a force entry differentiated in a parameter).
#[inline(always)]
pub fn dual_constants<const K: usize>(x: &SVector<f64, K>) -> [DualSVec64<1>; K] {
    core::array::from_fn(|i| DualSVec64::<1>::from_re(x[i]))
}

/// The derivative part of a force entry evaluated with [`theta_dual`].
#[inline(always)]
pub fn dual_part(f: &DualSVec64<1>) -> f64 {
    f.eps.0.map_or(0.0, |e| e[0])
}
