//! The tangent of the flow (DESIGN §12), carried step by step beside the state.
//!
//! One step solves `R(Z; q_k, p_k) = 0` for the increments `Z`, and sets `q_{k+1} = q_k +
//! Z_{s−1}`, `p_{k+1} = G_{s−1}`. With `J = ∂R/∂Z` factored at the solution, a direction
//! `(dq_k, dp_k)` goes through the step as
//!
//! ```text
//! J dZ = −(∂R/∂q_k dq_k + ∂R/∂p_k dp_k),   dq_{k+1} = dq_k + dZ_{s−1},   dp_{k+1} = dG_{s−1}
//! ```
//!
//! where every `dG_j` is the linearised gradient of control point `j` (DESIGN §3) with the
//! control points moved by `dx_0 = dq_k`, `dx_m = dq_k + dZ_m`: at quadrature node `i`,
//! `dx_i = Σ_m Φ_im dx_m`, `dv_i = (1/h) Σ_m Ψ_im dx_m`, the node blocks give
//! `d(L_q + F) = A dx_i + B dv_i`, `dL_v = C dx_i + E dv_i`, and the quadrature sums them
//! into `dG_j = Σ_i b_i [h Φ_ij d(L_q + F)_i + Ψ_ij dL_v_i]`. The blocks are evaluated and
//! `J` is factored at the accepted solution ([`StepBackend::linearize`]), so the tangent is
//! that of the discrete map itself, with no finite differences; each column costs one
//! solve with those factors and two products with the node blocks. Only accepted steps
//! (and substeps) enter: the step sequence is held fixed.

use nalgebra::DMatrix;

use super::linearized::{
    Tangent, check_parameter_gradient, linearized_gradients, linearized_gradients_block,
    parameter_gradient, per_term_parameters,
};
use super::tangent_constrained::propagate_constrained;
use super::{Stepper, with_stack};
use crate::backend::{StepBackend, StepFailure, TANGENT_BLOCK};
use crate::error::{Error, NewtonFailure};
use crate::model::{ForcedLagrangian, general};
use crate::scalar::all_finite;
impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// Starts carrying the tangent with respect to the initial data `(q_0, v_0)` and the
    /// parameters `θ`: `2N + P` columns, `dp_0 = C dq_0 + E dv_0 + ∂L_v/∂θ dθ` (DESIGN §12).
    /// Only before the first step.
    pub(crate) fn track_tangent(&mut self) -> Result<(), Error> {
        // On the step's stack: the momentum's tangent takes the node blocks (see
        // [`super::step_stack_bytes`]).
        with_stack(self.stack, || self.track_tangent_here())
    }

    fn track_tangent_here(&mut self) -> Result<(), Error> {
        let s = self.scheme.stages();
        let dim = self.backend.z().len();
        let theta = super::checks::parameter_values(self.model)?;
        let np = theta.len();
        let cols = 2 * N + np;
        let mut m = vec![0.0; 2 * N * cols];
        let (q0, v0) = (&self.state.q.sum[..], &self.state.v[..]);
        let (mut dq, mut dv) = (vec![0.0; N], vec![0.0; N]);
        for c in 0..2 * N {
            dq.fill(0.0);
            dv.fill(0.0);
            if c < N {
                dq[c] = 1.0;
            } else {
                dv[c - N] = 1.0;
            }
            let col = &mut m[c * 2 * N..(c + 1) * 2 * N];
            col[..N].copy_from_slice(&dq);
            self.backend
                .momentum_tangent((0.0, q0, v0), (&dq, &dv), &mut col[N..])?;
        }
        for k in 0..np {
            let g = parameter_gradient(self.model, (0.0, q0, v0), &theta, k);
            check_parameter_gradient(&g, 0.0)?;
            let c = 2 * N + k;
            m[c * 2 * N + N..(c + 1) * 2 * N].copy_from_slice(g.lv.as_slice());
        }
        // Blocks of columns where the backend takes them (see `propagate_blocks`).
        let b = if self.backend.tangent_blocks() {
            TANGENT_BLOCK
        } else {
            0
        };
        let block = [
            vec![0.0; s * N * b],
            vec![0.0; s * N * b],
            vec![0.0; dim * b],
        ];
        let block_node = [(); 4].map(|()| vec![0.0; N * b]);
        self.tangent = Some(Box::new(Tangent {
            saved: Vec::new(),
            m,
            dx: vec![0.0; s * N],
            g: vec![0.0; s * N],
            rhs: vec![0.0; dim],
            node: [vec![0.0; N], vec![0.0; N], vec![0.0; N], vec![0.0; N]],
            pnode: vec![0.0; self.scheme.quadrature_nodes() * np * 2 * N],
            theta,
            block,
            block_node,
        }));
        Ok(())
    }

    /// Carries the tangent through the step just solved (size `state.h_prev`), whose
    /// solution the backend still holds. Nothing changes on failure, but for columns that
    /// overflowed ([`StepFailure::TangentOverflow`]), which end the run.
    pub(super) fn tangent_step(&mut self) -> Result<(), StepFailure> {
        let Some(theta) = self.tangent.as_ref().map(|tg| tg.theta.clone()) else {
            return Ok(());
        };
        self.backend.linearize()?;
        // A constrained step's own terms (see `super::tangent_constrained`).
        let terms = if M::CONSTRAINED && self.model.constraint_count() > 0 {
            // The dense terms take second-order dual numbers over all `N` coordinates; the
            // sparse backend's come from its kernels, and the rest of either from
            // hyper-dual numbers held on the heap.
            let dense = self.path() == crate::LinearPath::Dense;
            let curvature = if dense {
                general::constraint_stack_bytes::<N>()
            } else {
                0
            };
            // The parameters' terms take the general kernels' stack unless the per-term kernels
            // give them.
            let parameters = if per_term_parameters(self.model) {
                0
            } else {
                general::parameter_stack_bytes::<N>()
            };
            let need = curvature.max(parameters);
            let end = self.step_end();
            Some(with_stack(need, || self.constraint_terms(&theta, &end))?)
        } else {
            None
        };
        let Some(tg) = self.tangent.as_mut() else {
            return Ok(());
        };
        let backend = &mut self.backend;
        let sch = self.scheme;
        let h = self.state.h_prev;
        let np = tg.theta.len();
        // The parameters' terms at the nodes of the solution, all on one stack deep enough
        // for their duals: each call on a stack of its own mapped and unmapped that stack
        // (16 MiB at N = 256) for every node and parameter, and its page faults and
        // `munmap` took about a third of the forward sensitivities' time (FPU chain,
        // n = 256, 4 parameters).
        let t0 = self.state.t_state - h;
        let model = self.model;
        let nodes = |pnode: &mut [f64], theta: &[f64]| {
            for i in 0..sch.quadrature_nodes() {
                let at = (t0 + sch.c()[i] * h, backend.node_x(i), backend.node_v(i));
                for k in 0..np {
                    let g = parameter_gradient(model, at, theta, k);
                    if !(all_finite(&g.fq) && all_finite(&g.lv)) {
                        return Err(StepFailure::Newton(NewtonFailure::NonFinite));
                    }
                    let o = (i * np + k) * 2 * N;
                    pnode[o..o + N].copy_from_slice(g.fq.as_slice());
                    pnode[o + N..o + 2 * N].copy_from_slice(g.lv.as_slice());
                }
            }
            Ok(())
        };
        if np > 0 && per_term_parameters(model) {
            nodes(&mut tg.pnode, &tg.theta)?;
        } else if np > 0 {
            with_stack(general::parameter_stack_bytes::<N>(), || {
                nodes(&mut tg.pnode, &tg.theta)
            })?;
        }
        match &terms {
            Some(terms) => propagate_constrained(backend, tg, h, N, terms),
            None if backend.tangent_blocks() => propagate_blocks(backend, tg, h, N),
            None => propagate(backend, tg, h, N),
        }
        // Columns that left the range of `f64` (the flow stretches perturbations beyond it)
        // end the run here, at the step where they did: nothing after it could be finite.
        if tg.m.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(StepFailure::TangentOverflow)
        }
    }

    /// The tangent at the current state in `(q, v)`, from `E dv = dp − C dq` at the current
    /// `(t, q, v)` (after the final velocity solve): the columns of the initial data
    /// (`2N × 2N`) and those of the parameters (`2N × P`).
    pub(crate) fn tangent_in_velocities(&mut self) -> Result<(DMatrix<f64>, DMatrix<f64>), Error> {
        // On the step's stack, as `track_tangent`: the velocity's tangent takes the blocks.
        with_stack(self.stack, || self.tangent_in_velocities_here())
    }

    fn tangent_in_velocities_here(&mut self) -> Result<(DMatrix<f64>, DMatrix<f64>), Error> {
        // Taken, not copied: the tangent is the run's last use of it, and up to
        // `crate::MAX_TANGENT_BYTES` large.
        let Some(tg) = self.tangent.take() else {
            return Ok((DMatrix::zeros(2 * N, 0), DMatrix::zeros(2 * N, 0)));
        };
        let Tangent { mut m, theta, .. } = *tg;
        let cols = m.len() / (2 * N);
        let params = m.split_off(4 * N * N);
        let mut wrt_initial = DMatrix::from_vec(2 * N, 2 * N, m);
        let mut wrt_parameters = DMatrix::from_vec(2 * N, cols - 2 * N, params);
        let st = &self.state;
        let at = (self.t, &st.q.sum[..], &st.v[..]);
        let mut dv = vec![0.0; N];
        let columns = (wrt_initial.column_iter_mut().map(|c| (None, c)))
            .chain((wrt_parameters.column_iter_mut().enumerate()).map(|(k, c)| (Some(k), c)));
        for (k, mut col) in columns {
            let (dq, dp) = col.as_mut_slice().split_at_mut(N);
            if let Some(k) = k {
                // E dv = dp − C dq − ∂L_v/∂θ_k.
                let g = parameter_gradient(self.model, at, &theta, k);
                check_parameter_gradient(&g, self.t)?;
                dp.iter_mut().zip(g.lv.iter()).for_each(|(x, y)| *x -= y);
            }
            self.backend
                .velocity_tangent(at, (dq, dp), &mut dv)
                .map_err(|e| e.at_step(self.k))?;
            dp.copy_from_slice(&dv);
        }
        Ok((wrt_initial, wrt_parameters))
    }
}

/// Carries the columns of `tg` through the step of size `h` that `backend` holds,
/// linearised, for a model of `n` coordinates (see the module's docs). Not generic: one
/// copy serves every model.
fn propagate(backend: &mut dyn StepBackend, tg: &mut Tangent, h: f64, n: usize) {
    let s = backend.scheme().stages();
    let lay = backend.layout();
    let np = tg.theta.len();
    for c in 0..tg.columns(n) {
        let col = c * 2 * n;
        // `dq`, then no increments: the right-hand side's directions.
        tg.dx[..n].copy_from_slice(&tg.m[col..col + n]);
        tg.dx[n..].fill(0.0);
        let param = (c >= 2 * n).then(|| (&tg.pnode[..], c - 2 * n, np));
        linearized_gradients(backend, h, &tg.dx, param, &mut tg.g, &mut tg.node);
        for j in 0..s - 1 {
            for a in 0..n {
                let dp = if j == 0 { tg.m[col + n + a] } else { 0.0 };
                tg.rhs[lay.at(j + 1, a)] = -(tg.g[j * n + a] + dp);
            }
        }
        backend.solve_linearized(&mut tg.rhs);
        for m in 1..s {
            for a in 0..n {
                tg.dx[m * n + a] = tg.rhs[lay.at(m, a)];
            }
        }
        linearized_gradients(backend, h, &tg.dx, param, &mut tg.g, &mut tg.node);
        for a in 0..n {
            tg.m[col + a] += tg.dx[(s - 1) * n + a];
            tg.m[col + n + a] = tg.g[(s - 1) * n + a];
        }
    }
}

/// [`propagate`] for [`TANGENT_BLOCK`] columns at a time, interleaved in `tg.block` (the
/// sparse backend's node products and solves then load each factor entry once for all of
/// them); the last block is filled with zero columns. The same results as [`propagate`], to
/// the bit.
fn propagate_blocks(backend: &mut dyn StepBackend, tg: &mut Tangent, h: f64, n: usize) {
    const B: usize = TANGENT_BLOCK;
    let s = backend.scheme().stages();
    let lay = backend.layout();
    let (np, cols, dim) = (tg.theta.len(), tg.columns(n), tg.rhs.len());
    let Tangent {
        m,
        pnode,
        block: [dx, g, rhs],
        block_node,
        ..
    } = tg;
    for c0 in (0..cols).step_by(B) {
        let width = B.min(cols - c0);
        let mut params = [None; B];
        dx.fill(0.0);
        for b in 0..width {
            let col = (c0 + b) * 2 * n;
            for a in 0..n {
                dx[a * B + b] = m[col + a];
            }
            params[b] = (c0 + b).checked_sub(2 * n);
        }
        let param = (params, &pnode[..], np);
        linearized_gradients_block(&*backend, h, dx, param, g, block_node);
        for j in 0..s - 1 {
            for a in 0..n {
                let at = lay.at(j + 1, a) * B;
                for b in 0..B {
                    let dp = match (j, b < width) {
                        (0, true) => m[(c0 + b) * 2 * n + n + a],
                        _ => 0.0,
                    };
                    rhs[at + b] = -(g[(j * n + a) * B + b] + dp);
                }
            }
        }
        backend.solve_linearized_block(&mut rhs[..dim * B]);
        for k in 1..s {
            for a in 0..n {
                let (from, to) = (lay.at(k, a) * B, (k * n + a) * B);
                dx[to..to + B].copy_from_slice(&rhs[from..from + B]);
            }
        }
        linearized_gradients_block(&*backend, h, dx, param, g, block_node);
        for b in 0..width {
            let col = (c0 + b) * 2 * n;
            for a in 0..n {
                m[col + a] += dx[((s - 1) * n + a) * B + b];
                m[col + n + a] = g[((s - 1) * n + a) * B + b];
            }
        }
    }
}
