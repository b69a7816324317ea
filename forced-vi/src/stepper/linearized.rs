//! The pieces of a step's linearisation that the forward sensitivities share between
//! unconstrained and constrained models: the tangent's storage, the linearised gradients of
//! the control points, and the parameters' derivatives at a node.

use nalgebra::SVector;

use super::with_stack;
use crate::backend::{StepBackend, TANGENT_BLOCK};
use crate::error::Error;
use crate::model::{ForcedLagrangian, NodeGradient, general};
use crate::scalar::all_finite;

/// The tangent `∂(q_k, p_k)/∂(seed)` of a run and its scratch, made once per run.
pub(crate) struct Tangent {
    /// Columns of `2N` entries `(dq, dp)`, one after another.
    pub(crate) m: Vec<f64>,
    /// The columns before a subdivided step, restored if it fails.
    pub(super) saved: Vec<f64>,
    /// Control-point directions and linearised gradients, `s` blocks of `N`.
    pub(super) dx: Vec<f64>,
    pub(super) g: Vec<f64>,
    /// The right-hand side of a tangent solve, in the backend's layout.
    pub(super) rhs: Vec<f64>,
    /// One node's `dx`, `dv`, `d(L_q + F)`, `dL_v`.
    pub(super) node: [Vec<f64>; 4],
    /// The parameters' values, and per quadrature node and parameter `θ_k` the derivatives
    /// `∂(L_q + F)/∂θ_k`, `∂L_v/∂θ_k` (`2N` entries) of the step just solved.
    pub(super) theta: Vec<f64>,
    pub(super) pnode: Vec<f64>,
    /// Where the backend takes [`TANGENT_BLOCK`] columns at once: their `dx`, `g` and
    /// right-hand sides, and their node buffers, interleaved (empty otherwise).
    pub(super) block: [Vec<f64>; 3],
    pub(super) block_node: [Vec<f64>; 4],
}

impl Tangent {
    /// The number of columns.
    pub(crate) fn columns(&self, n: usize) -> usize {
        self.m.len() / (2 * n)
    }

    /// Keeps the columns before a subdivided step.
    pub(crate) fn save(&mut self) {
        self.saved.clone_from(&self.m);
    }

    /// Goes back to the columns kept by [`Tangent::save`].
    pub(crate) fn restore(&mut self) {
        self.m.clone_from(&self.saved);
    }
}

/// Whether the model's per-term kernels give its parameter derivatives
/// ([`crate::model::SparseNode::eval_parameter`]), in time linear in its size.
pub(super) fn per_term_parameters<M: ForcedLagrangian<N>, const N: usize>(model: &M) -> bool {
    model
        .sparse_node()
        .is_some_and(|node| node.has_parameter_kernels())
}

/// `∂(L_q + F)/∂θ_k`, `∂L_v/∂θ_k` at `(t, q, v)`: from the model's per-term kernels where
/// it has them, else from the general kernels on a stack deep enough for their dual
/// numbers.
pub(super) fn parameter_gradient<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    (t, q, v): (f64, &[f64], &[f64]),
    theta: &[f64],
    k: usize,
) -> NodeGradient<N> {
    if let Some(node) = model
        .sparse_node()
        .filter(|node| node.has_parameter_kernels())
    {
        let mut g = NodeGradient::<N> {
            fq: SVector::zeros(),
            lv: SVector::zeros(),
        };
        let (fq, lv) = (g.fq.as_mut_slice(), g.lv.as_mut_slice());
        if node.eval_parameter(t, q, v, theta, k, fq, lv) {
            return g;
        }
    }
    let (q, v) = (SVector::from_column_slice(q), SVector::from_column_slice(v));
    with_stack(general::parameter_stack_bytes::<N>(), || {
        general::node_parameter_gradient_at(model, (t, &q, &v), theta, k)
    })
}

pub(super) fn check_parameter_gradient<const N: usize>(
    g: &NodeGradient<N>,
    t: f64,
) -> Result<(), Error> {
    if all_finite(&g.fq) && all_finite(&g.lv) {
        Ok(())
    } else {
        Err(Error::NonFiniteModel { step: 0, t })
    }
}

/// `dG_j`, `j = 0 … s − 1`, for control-point directions `dx_0 = dq`, `dx_m = dq + dZ_m`
/// given as `dx` (`s` blocks of `N`: block 0 `dq`, block `m ≥ 1` the increment `dZ_m`),
/// with the node blocks of the last [`StepBackend::linearize`]; with `param = (pnode, k,
/// P)`, plus the terms of a unit change of parameter `θ_k`.
///
/// In increments, as the step's own unknowns: `dx_i = dq + Σ_{m≥1} Φ_im dZ_m` and
/// `dv_i = (1/h) Σ_{m≥1} Ψ_im dZ_m`, since `Σ_m Φ_im = 1` and `Σ_m Ψ_im = 0`. Summed over
/// the control points' directions instead, `dv_i` kept the round-off of that zero sum,
/// `ε |dq| / h`, and the tangent took it into `dp` at every step: on the coupled oscillators
/// of the tests, 3.6·10⁶ fixed lobatto3 steps ended 3.5e-7 off a reference Jacobian, against
/// 1e-10 for the adjoint of the same run.
pub(super) fn linearized_gradients(
    backend: &dyn StepBackend,
    h: f64,
    dx: &[f64],
    param: Option<(&[f64], usize, usize)>,
    g: &mut [f64],
    [dxi, dvi, dfq, dlv]: &mut [Vec<f64>; 4],
) {
    let sch = backend.scheme();
    let (s, n) = (sch.stages(), dxi.len());
    g.fill(0.0);
    for i in 0..sch.quadrature_nodes() {
        dxi.copy_from_slice(&dx[..n]);
        dvi.fill(0.0);
        for m in 1..s {
            let (phi, psi) = (sch.phi_at(i, m), sch.psi_at(i, m) / h);
            for a in 0..n {
                dxi[a] += phi * dx[m * n + a];
                dvi[a] += psi * dx[m * n + a];
            }
        }
        backend.apply_node(i, (dxi, dvi), dfq, dlv);
        if let Some((pnode, k, np)) = param {
            let o = (i * np + k) * 2 * n;
            for a in 0..n {
                dfq[a] += pnode[o + a];
                dlv[a] += pnode[o + n + a];
            }
        }
        let bi = sch.b()[i];
        for j in 0..s {
            let (cf, cl) = (bi * h * sch.phi_at(i, j), bi * sch.psi_at(i, j));
            for a in 0..n {
                g[j * n + a] += cf * dfq[a] + cl * dlv[a];
            }
        }
    }
}

/// [`linearized_gradients`] for [`TANGENT_BLOCK`] directions at once, interleaved (entry `e`
/// of direction `b` at `e * TANGENT_BLOCK + b` in `dx`, `g` and `node`'s buffers, which
/// hold `TANGENT_BLOCK` times the entries); `params[b]` is the parameter whose unit change
/// direction `b` carries, if any, with `(pnode, P)`. Each direction takes the operations
/// of [`linearized_gradients`], in its order: the same results to the bit.
pub(super) fn linearized_gradients_block(
    backend: &dyn StepBackend,
    h: f64,
    dx: &[f64],
    (params, pnode, np): ([Option<usize>; TANGENT_BLOCK], &[f64], usize),
    g: &mut [f64],
    [dxi, dvi, dfq, dlv]: &mut [Vec<f64>; 4],
) {
    const B: usize = TANGENT_BLOCK;
    let sch = backend.scheme();
    let s = sch.stages();
    let n = dxi.len() / B;
    g.fill(0.0);
    let (dxc, _) = dx.as_chunks::<B>();
    for i in 0..sch.quadrature_nodes() {
        dxi.copy_from_slice(&dx[..n * B]);
        dvi.fill(0.0);
        {
            let (xi, _) = dxi.as_chunks_mut::<B>();
            let (vi, _) = dvi.as_chunks_mut::<B>();
            for m in 1..s {
                let (phi, psi) = (sch.phi_at(i, m), sch.psi_at(i, m) / h);
                let dm = &dxc[m * n..(m + 1) * n];
                for ((x, v), d) in xi.iter_mut().zip(vi.iter_mut()).zip(dm) {
                    for b in 0..B {
                        x[b] += phi * d[b];
                        v[b] += psi * d[b];
                    }
                }
            }
        }
        backend.apply_node_block(i, (dxi, dvi), dfq, dlv);
        let (fq, _) = dfq.as_chunks_mut::<B>();
        let (lv, _) = dlv.as_chunks_mut::<B>();
        for (b, k) in params.iter().enumerate() {
            if let Some(k) = *k {
                let o = (i * np + k) * 2 * n;
                for a in 0..n {
                    fq[a][b] += pnode[o + a];
                    lv[a][b] += pnode[o + n + a];
                }
            }
        }
        let bi = sch.b()[i];
        let (gc, _) = g.as_chunks_mut::<B>();
        for j in 0..s {
            let (cf, cl) = (bi * h * sch.phi_at(i, j), bi * sch.psi_at(i, j));
            for ((gj, f), l) in gc[j * n..(j + 1) * n].iter_mut().zip(&*fq).zip(&*lv) {
                for b in 0..B {
                    gj[b] += cf * f[b] + cl * l[b];
                }
            }
        }
    }
}
