//! The discrete adjoint (DESIGN §12): the gradient of a loss of the final state by
//! transposed solves backwards over the stored steps.
//!
//! The forward run keeps, per accepted step and substep, its size, start time, start
//! `(q_k, p_k)` and solution `Z` (the tape). Backwards, with `a = (a_q, a_p)` the gradient
//! of the loss in `(q_{k+1}, p_{k+1})`, each step is linearised again at its stored
//! solution and, with `K` the map from control-point directions to the linearised
//! gradients `dG_j` (see the `tangent` module),
//!
//! ```text
//! Jᵀ w = c,   c_m = [Kᵀ (0, …, 0, a_p)]_m + δ_{m,s−1} a_q      (m = 1 … s − 1)
//! μ_j = −w_j (j ≤ s − 2),   μ_{s−1} = a_p,   u = Kᵀ μ
//! a_q ← a_q + Σ_m u_m,   a_p ← μ_0,   ∇_θ ℓ += Σ_i ∂/∂θ [νf_i · (L_q + F)_i + νl_i · L_v,i]
//! ```
//!
//! with `νf_i = b_i h Σ_j Φ_ij μ_j` and `νl_i = b_i Σ_j Ψ_ij μ_j`. One transposed solve and
//! two products with the node blocks per step, whatever the number of parameters; each
//! parameter adds one hyper-dual evaluation of `L` per node
//! ([`general::parameter_contraction`]). The ends go through `p_0 = L_v(q_0, v_0; θ)` and
//! `E v_T = …` as in the forward tangent.
//!
//! A constrained step (see `super::tangent_constrained`) keeps its end too: `t₁`, `p₁`,
//! the velocity guess, the end multipliers and the projected velocity. Backwards, `(a_q,
//! a_p)` first goes through the transposed end projection, whose saddle-point matrix is
//! symmetric: `y = [[E₁, G₁ᵀ], [G₁, 0]]⁻¹ (0, −G₁ a_p)`, then `a_p ← a_p + y_top` (the
//! adjoint of `p̃`) and `a_q ← a_q − K_μ a_p − (C₁ + K_μ)ᵀ y_top − Hᵀ y_bot`. The transposed
//! step solve then has zeros in its constraint rows, and its solution `(w, ω)` adds
//! `Σ_{j≤s−2} (b_j/h) K_j w_j − Σ_{j≥1} G_jᵀ ω_{j−1}` to `a_q`; each parameter gains the
//! same products with its constraint terms. It equals the forward tangent's
//! `wrt_initialᵀ g` to round-off on both backends (tested).

use nalgebra::DVector;

use super::{Stepper, with_stack};
use crate::backend::{StepBackend, StepFailure};
use crate::error::Error;
use crate::model::{ForcedLagrangian, general};

/// The steps of a run, kept for its adjoint.
pub(crate) struct Tape {
    /// Per accepted step or substep: `h`, `t0`, `q0`, `p0`, `Z`.
    data: Vec<f64>,
    width: usize,
    /// The length before a subdivided step, restored if it fails.
    saved: usize,
    /// The initial `(q_0, v_0)`.
    start: (Vec<f64>, Vec<f64>),
}

impl Tape {
    pub(crate) fn save(&mut self) {
        self.saved = self.data.len();
    }

    pub(crate) fn restore(&mut self) {
        self.data.truncate(self.saved);
    }

    /// The bytes the tape holds.
    pub(crate) fn bytes(&self) -> usize {
        self.data.len() * std::mem::size_of::<f64>()
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// Starts keeping the steps of the run for [`Self::adjoint`]. Only before the first
    /// step. Refuses a model whose parameter lists disagree before any step is taken.
    pub(crate) fn keep_tape(&mut self) -> Result<(), Error> {
        super::checks::parameter_values(self.model)?;
        // A constrained step also keeps its end (see `constrained_end`).
        let width = 2 + 2 * N + self.backend.z().len() + self.end_width();
        self.tape = Some(Box::new(Tape {
            data: Vec::new(),
            width,
            saved: 0,
            start: (self.state.q.sum.clone(), self.state.v.clone()),
        }));
        Ok(())
    }

    /// Keeps the step just solved (the backend still holds it).
    pub(super) fn tape_step(&mut self) -> Result<(), StepFailure> {
        let end_width = self.end_width();
        let Some(tape) = self.tape.as_mut() else {
            return Ok(());
        };
        if tape.data.try_reserve(tape.width).is_err() {
            return Err(StepFailure::Memory {
                records: tape.data.len() / tape.width + 1,
            });
        }
        let (h, t0, q0, p0) = self.backend.step_data();
        tape.data.extend_from_slice(&[h, t0]);
        tape.data.extend_from_slice(q0);
        tape.data.extend_from_slice(p0);
        tape.data.extend_from_slice(self.backend.z());
        if end_width > 0 {
            // The end of the step: `t₁`, `p₁`, the velocity guess, the end multipliers and
            // the projected velocity where the backend keeps it.
            let st = &self.state;
            tape.data.push(st.t_state);
            tape.data.extend_from_slice(&st.p.sum);
            tape.data.extend_from_slice(&st.v);
            tape.data.extend_from_slice(self.backend.end_multipliers());
            let v1 = self.backend.end_velocity().unwrap_or(&st.v);
            tape.data.extend_from_slice(v1);
        }
        Ok(())
    }

    /// The values a constrained step keeps of its end on the tape (0 without constraints).
    fn end_width(&self) -> usize {
        let m = self.model.constraint_count();
        if M::CONSTRAINED && m > 0 {
            1 + 3 * N + m
        } else {
            0
        }
    }

    /// The bytes of the tape kept so far.
    pub(crate) fn tape_bytes(&self) -> usize {
        self.tape.as_ref().map_or(0, |t| t.bytes())
    }

    /// The gradient of a loss `ℓ(q_T, v_T)` whose gradient at the final state is `(gq, gv)`:
    /// with respect to `(q_0, v_0)` (`2N` entries) and to the parameters (`P`). Call after
    /// the run, at its final state with the velocity solved.
    pub(crate) fn adjoint(
        &mut self,
        g: (&[f64], &[f64]),
    ) -> Result<(DVector<f64>, DVector<f64>), Error> {
        // On the step's stack: each step of the backward pass takes the node blocks (see
        // [`super::step_stack_bytes`]).
        with_stack(self.stack, || self.adjoint_here(g))
    }

    fn adjoint_here(
        &mut self,
        (gq, gv): (&[f64], &[f64]),
    ) -> Result<(DVector<f64>, DVector<f64>), Error> {
        let Some(tape) = self.tape.take() else {
            return Ok((DVector::zeros(2 * N), DVector::zeros(0)));
        };
        let theta = super::checks::parameter_values(self.model)?;
        let np = theta.len();
        let mut grad_theta = vec![0.0; np];
        let sch = self.scheme;
        let (s, r) = (sch.stages(), sch.quadrature_nodes());
        let dim = self.backend.z().len();
        let lay = self.backend.layout();
        // The end: v_T from E dv = dp − C dq − L_vθ dθ, so with y = E⁻¹ g_v (E symmetric):
        // a_q = g_q − Cᵀ y, a_p = y, ∇_θ −= ∂/∂θ (y · L_v).
        let (t_end, q_end, v_end) = (self.t, self.state.q.sum.clone(), self.state.v.clone());
        let at = (t_end, &q_end[..], &v_end[..]);
        let zero = vec![0.0; N];
        let mut y = vec![0.0; N];
        let k_end = self.k;
        self.backend
            .velocity_tangent(at, (&zero, gv), &mut y)
            .map_err(|e| match e {
                Error::Overflow { t, .. } => Error::Overflow {
                    step: k_end,
                    t,
                    quantity: "adjoint",
                },
                e => e.at_step(k_end),
            })?;
        let (mut cq, mut ev) = (vec![0.0; N], vec![0.0; N]);
        self.backend
            .momentum_cotangent(at, &y, (&mut cq, &mut ev))?;
        let mut aq: Vec<f64> = gq.iter().zip(&cq).map(|(g, c)| g - c).collect();
        let mut ap = y.clone();
        for (k, g) in grad_theta.iter_mut().enumerate() {
            *g -= contraction(self.model, at, (&zero, &y), &theta, k);
        }
        // Backwards over the steps.
        let (mut mu, mut u) = (vec![0.0; s * N], vec![0.0; s * N]);
        let mut c = vec![0.0; dim];
        let mut scratch = [vec![0.0; N], vec![0.0; N], vec![0.0; N], vec![0.0; N]];
        let (mut nf, mut nl) = (vec![0.0; r * N], vec![0.0; r * N]);
        let step_fail = |f: StepFailure, k: usize, t0: f64| self_error(f, k, t0);
        for (i, rec) in tape.data.chunks_exact(tape.width).enumerate().rev() {
            // The step of the run this record is (counted from 1; substeps count as
            // steps), and the size of the
            // adjoint before it: an adjoint that leaves `f64`'s range from a huge one
            // overflowed, one that turns NaN from a moderate one met the model's NaN.
            let k = i + 1;
            let size = aq.iter().chain(&ap).fold(0.0f64, |m, x| m.max(x.abs()));
            let (h, t0) = (rec[0], rec[1]);
            let (q0, rest) = rec[2..].split_at(N);
            let (p0, rest) = rest.split_at(N);
            let (z, end) = rest.split_at(dim);
            self.backend.restore(h, t0, (q0, p0), z);
            self.backend
                .linearize_transposed()
                .map_err(|f| step_fail(f, k, t0))?;
            // A constrained step: its terms, and the adjoint taken back through its end
            // projection first (see `super::tangent_constrained`).
            let constrained = match self.constrained_end(end, h, k, &theta) {
                Some(ct) => {
                    let ct = ct.map_err(|f| step_fail(f, k, t0))?;
                    let (mut adq1, mut adpt) = (vec![0.0; N], vec![0.0; N]);
                    let y = ct
                        .end_adjoint(&mut self.backend, (&aq, &ap), (&mut adq1, &mut adpt))
                        .ok_or_else(|| super::checks::non_finite(size, k, t0, "adjoint"))?;
                    let ap1 = std::mem::replace(&mut ap, adpt);
                    aq = adq1;
                    Some((ct, y, ap1))
                }
                None => None,
            };
            // c = S_Zᵀ Kᵀ (0, …, 0, a_p) + a_q at the last control point.
            c.fill(0.0);
            mu.fill(0.0);
            mu[(s - 1) * N..].copy_from_slice(&ap);
            transposed_gradients(
                &self.backend,
                h,
                &mu,
                (&mut nf, &mut nl),
                &mut u,
                &mut scratch,
            );
            for m in 1..s {
                for a in 0..N {
                    let last = if m == s - 1 { aq[a] } else { 0.0 };
                    c[lay.at(m, a)] = u[m * N + a] + last;
                }
            }
            self.backend.solve_transposed(&mut c);
            for j in 0..s - 1 {
                for a in 0..N {
                    mu[j * N + a] = -c[lay.at(j + 1, a)];
                }
            }
            mu[(s - 1) * N..].copy_from_slice(&ap);
            transposed_gradients(
                &self.backend,
                h,
                &mu,
                (&mut nf, &mut nl),
                &mut u,
                &mut scratch,
            );
            for (a, x) in aq.iter_mut().enumerate() {
                *x += (0..s).map(|m| u[m * N + a]).sum::<f64>();
            }
            if let Some((ct, y, ap1)) = &constrained {
                ct.step_adjoint(&self.backend, (&c, y, ap1, h), &mut aq, &mut grad_theta);
            }
            ap.copy_from_slice(&mu[..N]);
            for i in 0..r {
                let ti = t0 + sch.c()[i] * h;
                let at = (ti, self.backend.node_x(i), self.backend.node_v(i));
                let w = (&nf[i * N..(i + 1) * N], &nl[i * N..(i + 1) * N]);
                for (k, g) in grad_theta.iter_mut().enumerate() {
                    *g += contraction(self.model, at, w, &theta, k);
                }
            }
            if !(aq.iter().chain(&ap).all(|x| x.is_finite())) {
                return Err(super::checks::non_finite(size, k, t0, "adjoint"));
            }
        }
        // The start: p_0 = L_v(q_0, v_0; θ).
        let st = &tape.start;
        let at = (0.0, &st.0[..], &st.1[..]);
        self.backend
            .momentum_cotangent(at, &ap, (&mut cq, &mut ev))?;
        let mut grad = DVector::zeros(2 * N);
        for a in 0..N {
            grad[a] = aq[a] + cq[a];
            grad[N + a] = ev[a];
        }
        for (k, g) in grad_theta.iter_mut().enumerate() {
            *g += contraction(self.model, at, (&zero, &ap), &theta, k);
        }
        if !(grad.iter().chain(&grad_theta).all(|x| x.is_finite())) {
            let size = aq.iter().chain(&ap).fold(0.0f64, |m, x| m.max(x.abs()));
            return Err(super::checks::non_finite(size, 0, 0.0, "adjoint"));
        }
        Ok((grad, DVector::from_vec(grad_theta)))
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// A constrained step's terms for the backward pass, from the end it kept on the tape
    /// (see [`Self::tape_step`]), with the backend restored to the step and linearised;
    /// `None` without constraints.
    fn constrained_end(
        &mut self,
        end: &[f64],
        h: f64,
        k: usize,
        theta: &[f64],
    ) -> Option<Result<super::tangent_constrained::ConstraintTerms, StepFailure>> {
        if self.end_width() == 0 || end.len() < self.end_width() {
            return None;
        }
        let m = self.model.constraint_count();
        let t1 = end[0];
        let (p1, rest) = end[1..].split_at(N);
        let (v_guess, rest) = rest.split_at(N);
        let (mu, v1) = rest.split_at(m);
        self.backend.restore_end(mu, &v1[..N]);
        let step_end = super::tangent_constrained::StepEnd {
            h,
            t1,
            p1: p1.to_vec(),
            v_guess: v_guess.to_vec(),
            k,
        };
        let dense = self.path() == crate::LinearPath::Dense;
        let curvature = if dense {
            general::constraint_stack_bytes::<N>()
        } else {
            0
        };
        // The parameters' terms take the general kernels' stack unless the per-term kernels
        // give them.
        let parameters = if super::linearized::per_term_parameters(self.model) {
            0
        } else {
            general::parameter_stack_bytes::<N>()
        };
        let need = curvature.max(parameters);
        Some(with_stack(need, || self.constraint_terms(theta, &step_end)))
    }
}

/// The error of a step that the backward pass could not linearise again.
fn self_error(f: StepFailure, step: usize, t: f64) -> Error {
    match f {
        StepFailure::Memory { records } => Error::TooManyRecords { records },
        _ => Error::NonFiniteModel { step, t },
    }
}

/// `∂/∂θ_k [nf · (L_q + F) + nl · L_v]` at `at`, on a stack deep enough for its duals.
fn contraction<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    at: (f64, &[f64], &[f64]),
    w: (&[f64], &[f64]),
    theta: &[f64],
    k: usize,
) -> f64 {
    with_stack(general::contraction_stack_bytes::<N>(), || {
        general::parameter_contraction(model, at, w, theta, k)
    })
}

/// `u = Kᵀ μ` (`s` blocks of `N`, block 0 the start), with the node weights
/// `νf_i = b_i h Σ_j Φ_ij μ_j`, `νl_i = b_i Σ_j Ψ_ij μ_j` left in `(nf, nl)`.
fn transposed_gradients<B: StepBackend>(
    backend: &B,
    h: f64,
    mu: &[f64],
    (nf, nl): (&mut [f64], &mut [f64]),
    u: &mut [f64],
    [ux, uv, _, _]: &mut [Vec<f64>; 4],
) {
    let sch = backend.scheme();
    let (s, n) = (sch.stages(), ux.len());
    u.fill(0.0);
    for i in 0..sch.quadrature_nodes() {
        let bi = sch.b()[i];
        let (fi, li) = (&mut nf[i * n..(i + 1) * n], &mut nl[i * n..(i + 1) * n]);
        fi.fill(0.0);
        li.fill(0.0);
        for j in 0..s {
            let (cf, cl) = (bi * h * sch.phi_at(i, j), bi * sch.psi_at(i, j));
            for a in 0..n {
                fi[a] += cf * mu[j * n + a];
                li[a] += cl * mu[j * n + a];
            }
        }
        backend.apply_node_transposed(i, (fi, li), ux, uv);
        for m in 0..s {
            let (phi, psi) = (sch.phi_at(i, m), sch.psi_at(i, m) / h);
            for a in 0..n {
                u[m * n + a] += phi * ux[a] + psi * uv[a];
            }
        }
    }
}
