//! The dense backend: `N × N` node blocks from the model's node kernels, the step Jacobian
//! of DESIGN §3 as a dense matrix, factored by LU with partial pivoting ([`crate::Newton`]).
//!
//! *Measured and not kept: a step map for linear models.* A model whose `STRUCTURE.linear`
//! is true has step equations affine in the unknowns and in the step's start `y = (q_k,
//! p_k)`, so a fixed step of one size is `z = Z y + z₀`, with `Z` and `z₀` made once from
//! the factors and `2N + 1` residuals. Taken as the step's solution (its residual tested as
//! a first correction's), it cut the instructions of the damped oscillator's restarted run
//! (lobatto7, 12 steps) by 37 %, but `Z`'s rounding is a fixed perturbation of the step, so
//! its error adds up linearly rather than as a random walk: over 2·10⁵ steps of the
//! undamped oscillator the energy drifted 10 to 30 times as far as with Newton (lobatto5 at
//! h = 0.05: 7.7e-13 against 2.5e-14; lobatto7 at h = 0.3: 1.0e-11 against 6.7e-13), and
//! its residual failed that test within the first 30 to 400 steps of every run (lobatto2–7,
//! h = 0.01 to 0.3). With one Newton correction after
//! it (node values shifted through the constant node blocks instead of a second
//! residual), the drift was Newton's (1.3e-13 against 1.2e-13, 2.2e-14 against 2.5e-14),
//! but the instructions fell by only 7 to 12 % (that run 116k against 125k; runs of 1000
//! steps, lobatto2–5: −9 to −12 %): a residual and a solve per step remain, and the shift
//! of the node values and of the residual cost about what the second residual did.

use crate::buffers::{zero_vector, zeros};
use nalgebra::{DMatrix, DVector, SVector};

use super::{Layout, StepBackend, StepFailure};
use crate::error::{Error, NewtonFailure};
use crate::initial::{MIN_MASS_RCOND, mass_check, mass_factor, solve_velocity};
use crate::model::{ForcedLagrangian, NodeGradient, NodeJacobian};
use crate::newton::{DenseLu, Newton, NewtonOptions, NewtonReport, solve_small};
use crate::scalar::all_finite;
use crate::scheme::Scheme;
use crate::step_equations::StepProblem;

/// The fewest unknowns at which a fixed step starts from the last step's factors (see
/// [`DenseBackend`]'s `solve`). The factors save a Jacobian and its LU at the cost of a
/// second residual and solve; measured on the coupled van der Pol oscillators (callgrind,
/// 2000 fixed steps, `N = 2`), instructions against fresh factors at every step: lobatto2
/// (2 unknowns) +7 %, lobatto3 (4) +5 %, lobatto4 (6) −7 %, lobatto5 (8) −13 %, lobatto6
/// (10) −20 %, lobatto7 (12) −25 %, lobatto9 (16) −27 %.
///
/// Where the steps are long for the model they do not serve, and the iteration's backoff
/// (see `crate::newton`'s iteration) makes fresh factors on most steps. Measured on the
/// double pendulum with friction, lobatto7 at `h = 5/61` (the report's cheapest run to
/// 1e-10): the last step's factors contract the first correction by only 0.05–0.2, so the
/// 61 steps took 69 Jacobians and 169 iterations. Letting such factors run up to six
/// iterations instead of two changed nothing (the same 169): from a first correction of
/// 1e-4 to 6e-3 of the increments, a contraction of 0.1 needs more than six to reach
/// round-off, and a Jacobian with its LU costs about four residuals there.
const ACROSS_MIN_UNKNOWNS: usize = 6;

/// Step sizes within this relative difference count as the same for the factors carried
/// across steps (fixed steps differ by the rounding of the clock).
const SAME_STEP: f64 = 1e-8;

/// The dense step equations, their Newton solver and the unknowns.
pub(crate) struct DenseBackend<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    z: DVector<f64>,
    /// The right-hand side of a tangent solve (made on the first one).
    rhs: DVector<f64>,
    /// The transposed step Jacobian and its factors, for adjoints (made on first use).
    adjoint: Option<(DMatrix<f64>, DenseLu)>,
    /// The step Jacobian at the solution and its factors, for tangents (made on first
    /// use): the Newton's own factors carry over to the next step, so they stay as a run
    /// without tangents leaves them.
    tangent: Option<Newton>,
    /// A constrained model: the momentum of the constraint forces over the last step,
    /// `h Σ_j b_j G(x_j)ᵀ λ_j` (DESIGN §11), and the multipliers `λ_{s−1}` at its end.
    impulse: Vec<f64>,
    mu: Vec<f64>,
    /// A constrained model: `∂g/∂t` at the end of the last step.
    rate: Vec<f64>,
    /// The next solve starts from the last one's factors ([`StepBackend::carry_factors`]).
    carry: bool,
    /// Scratch for the step problem's per-row noise while a tangent's Jacobian is made
    /// (see [`StepBackend::linearize`]).
    noise_keep: Vec<f64>,
    /// A solve of the same step size as the last may start from its factors
    /// ([`StepBackend::factors_across_steps`]).
    across_steps: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> DenseBackend<'a, M, N> {
    /// Buffers for `model` and `scheme`.
    pub(crate) fn new(model: &'a M, scheme: &'a Scheme, newton: NewtonOptions) -> Self {
        let cons = model.constraint_count();
        let dim = (scheme.stages() - 1) * (N + cons);
        DenseBackend {
            prob: StepProblem::new(model, scheme),
            impulse: Vec::new(),
            mu: zeros(cons),
            rate: zeros(cons),
            newton: Newton::new(dim, newton),
            z: zero_vector(dim),
            rhs: zero_vector(0),
            adjoint: None,
            tangent: None,
            carry: false,
            noise_keep: zeros(N),
            across_steps: false,
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> DenseBackend<'_, M, N> {
    /// Back to the state [`DenseBackend::new`] made, keeping its buffers, for a new run
    /// ([`crate::Stepper`]'s restart); `across_steps` stays as the run's set-up left it.
    /// Every field is named, so that a field added later must be decided on here.
    pub(crate) fn restart(&mut self) {
        let DenseBackend {
            prob,
            newton,
            z,
            rhs: _,
            adjoint,
            tangent,
            impulse,
            mu,
            rate,
            carry,
            noise_keep: _,
            across_steps: _,
        } = self;
        prob.restart();
        newton.iteration.restart();
        z.fill(0.0);
        // Made on first use, as in a new run (an adjoint or tangent run makes them again).
        *adjoint = None;
        *tangent = None;
        impulse.clear();
        mu.fill(0.0);
        rate.fill(0.0);
        *carry = false;
    }

    /// Gives the next [`StepBackend::solve`] its node blocks instead of evaluating them:
    /// `Σ_i w_{ji} B_i` at its quadrature node `j`, from the blocks `B_i` of the last
    /// Jacobian that `from` evaluated (row `j` of `weights`: the Lagrange basis of `from`'s
    /// quadrature nodes at node `j`). The error estimate's cheap Jacobian
    /// ([`crate::control`]). Returns false, and gives nothing, if `from` has no blocks or
    /// the sizes do not match.
    pub(crate) fn seed_node_blocks(&mut self, from: &Self, weights: &[f64]) -> bool {
        let (r, src) = (self.prob.scheme.quadrature_nodes(), &from.prob.jacs);
        if src.is_empty() || weights.len() != r * src.len() {
            return false;
        }
        let jacs = &mut self.prob.jacs;
        // In place: an `N × N` block is not copied through the stack per node.
        if jacs.len() != r {
            jacs.clear();
            jacs.extend((0..r).map(|_| src[0]));
        }
        for (nj, row) in jacs.iter_mut().zip(weights.chunks_exact(src.len())) {
            for blk in [&mut nj.a, &mut nj.b, &mut nj.c, &mut nj.e] {
                blk.fill(0.0);
            }
            for (&w, b) in row.iter().zip(src) {
                nj.a.zip_apply(&b.a, |x, y| *x += w * y);
                nj.b.zip_apply(&b.b, |x, y| *x += w * y);
                nj.c.zip_apply(&b.c, |x, y| *x += w * y);
                nj.e.zip_apply(&b.e, |x, y| *x += w * y);
            }
        }
        self.prob.blocks_given = true;
        true
    }

    /// A constrained step's Newton result, ended by its projection ([`Self::project`]).
    fn end_constrained(
        &mut self,
        solved: Result<NewtonReport, NewtonFailure>,
    ) -> Result<NewtonReport, StepFailure> {
        match solved {
            Ok(report) => {
                self.project()?;
                Ok(report)
            }
            // The one Newton iteration of the error estimate (`crate::control`) ends its
            // step too, so that its momentum carries its constraint impulse.
            Err(f @ NewtonFailure::MaxIterations { .. })
                if self.newton.options().max_iterations == 1 =>
            {
                self.project()?;
                Err(StepFailure::Newton(f))
            }
            Err(f) => Err(StepFailure::Newton(f)),
        }
    }

    /// The end of a constrained step (DESIGN §11): the multiplier `μ = λ_{s−1}` and the
    /// velocity `v_{k+1}` with `L_v(q_{k+1}, v_{k+1}) + h b_{s−1} G(q_{k+1})ᵀ μ = p̃` and
    /// `G(q_{k+1}) v_{k+1} + ∂g/∂t = 0`, by Newton on the saddle-point matrix
    /// `[[E, h b Gᵀ], [G, 0]]`; then the impulse of the constraint forces over the step.
    /// `G(x_j)` are those of the last residual evaluation, which was at the solution.
    fn project(&mut self) -> Result<(), StepFailure> {
        let prob = &self.prob;
        let model = prob.model;
        let kernel =
            |t: f64, q: &SVector<f64, N>, v: &SVector<f64, N>| model.node_jacobian_at(t, q, v);
        let s = prob.scheme.stages();
        let (t1, q1) = (prob.t0 + prob.h, prob.xs[s - 1].as_slice());
        crate::model::general::constraint_rate_at(model, t1, q1, &mut self.rate);
        let step = (prob.scheme, prob.h, prob.t0, &prob.p0);
        let nodes = (&prob.grads[..], &prob.gjac[..], &prob.xs[..], &prob.vs[..]);
        let out = (&mut self.impulse, &mut self.mu[..]);
        project::<N>(
            step,
            (nodes, &self.rate),
            prob.cons,
            self.z.as_slice(),
            &kernel,
            out,
        )
    }
}

/// A model's node kernel `(t, q, v) ↦` its [`NodeJacobian`].
type NodeKernel<'a, const N: usize> =
    dyn Fn(f64, &SVector<f64, N>, &SVector<f64, N>) -> NodeJacobian<N> + 'a;

/// The node values a projection reads: gradients, `G(x_j)`, `x_j`, `v_j`.
type ProjectNodes<'a, const N: usize> = (
    &'a [NodeGradient<N>],
    &'a [DMatrix<f64>],
    &'a [SVector<f64, N>],
    &'a [SVector<f64, N>],
);

/// `DenseBackend::project` for a step `(scheme, h, t0, p0)` with the node values `(grads,
/// G(x_j), x_j, v_j)` of its solution `zs` and `rate = ∂g/∂t` at its end, `m` constraints
/// and the model's node kernel `kernel`; writes the impulse and the end multipliers to
/// `out`. Generic over the number of coordinates only: one copy serves every model of `N`
/// coordinates.
fn project<const N: usize>(
    (sch, h, t0, p0): (&Scheme, f64, f64, &SVector<f64, N>),
    ((grads, gjac, xs, vs), rate): (ProjectNodes<'_, N>, &[f64]),
    m: usize,
    zs: &[f64],
    kernel: &NodeKernel<'_, N>,
    (impulse, mu_out): (&mut Vec<f64>, &mut [f64]),
) -> Result<(), StepFailure> {
    let s = sch.stages();
    let nz = (s - 1) * N;
    let mut ptil = *p0;
    for (i, g) in grads.iter().enumerate() {
        ptil += g.fq * (h * sch.b()[i]);
    }
    let mut imp = SVector::<f64, N>::zeros();
    for j in 0..s - 1 {
        let lam = &zs[nz + j * m..nz + (j + 1) * m];
        let gj = &gjac[j];
        // `z` holds `ŵ_j = h² λ_j` (see `StepProblem`).
        for a in 0..N {
            imp[a] += sch.b()[j] / h * (0..m).map(|k| gj[(k, a)] * lam[k]).sum::<f64>();
        }
    }
    ptil -= imp;
    let g1 = &gjac[s - 1];
    let (t1, q1) = (t0 + h, xs[s - 1]);
    let mut v = vs[s - 1];
    let mut mu = DVector::<f64>::zeros(m);
    let mut kkt = DMatrix::<f64>::zeros(N + m, N + m);
    let mut rhs = DVector::<f64>::zeros(N + m);
    let mut converged = false;
    for it in 0..30 {
        let nj = kernel(t1, &q1, &v);
        let mut size = (0.0f64, 0.0f64);
        for a in 0..N {
            // `mu` is the impulse `h b_{s−1} μ`, so that the matrix is well scaled for
            // any step size.
            let gt_mu: f64 = (0..m).map(|k| g1[(k, a)] * mu[k]).sum();
            rhs[a] = -(nj.grad.lv[a] + gt_mu - ptil[a]);
            size.0 = size
                .0
                .max(nj.grad.lv[a].abs() + gt_mu.abs() + ptil[a].abs());
            for b in 0..N {
                kkt[(a, b)] = nj.e[(a, b)];
            }
            for k in 0..m {
                kkt[(a, N + k)] = g1[(k, a)];
                kkt[(N + k, a)] = g1[(k, a)];
            }
        }
        for k in 0..m {
            let rk = rate.get(k).copied().unwrap_or(0.0);
            rhs[N + k] = -((0..N).map(|a| g1[(k, a)] * v[a]).sum::<f64>() + rk);
            size.1 = size
                .1
                .max((0..N).map(|a| (g1[(k, a)] * v[a]).abs()).sum::<f64>() + rk.abs());
        }
        // Converged when both residuals are at the round-off of their terms.
        let noise = 16.0 * f64::EPSILON * (N + m) as f64;
        let (r1, r2) = (rhs.rows(0, N).amax(), rhs.rows(N, m).amax());
        if it > 0 && r1 <= noise * size.0 && r2 <= noise * size.1.max(f64::MIN_POSITIVE) {
            converged = true;
            break;
        }
        let Some(d) = kkt.clone().lu().solve(&rhs) else {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        };
        if !d.iter().all(|x| x.is_finite()) {
            return Err(StepFailure::Newton(NewtonFailure::NonFinite));
        }
        for a in 0..N {
            v[a] += d[a];
        }
        for k in 0..m {
            mu[k] += d[N + k];
        }
    }
    if !converged {
        return Err(StepFailure::Newton(NewtonFailure::MaxIterations {
            residual: rhs.amax(),
        }));
    }
    for a in 0..N {
        imp[a] += (0..m).map(|k| g1[(k, a)] * mu[k]).sum::<f64>();
    }
    impulse.clear();
    impulse.extend_from_slice(imp.as_slice());
    // In the units of the step's unknowns: `ŵ = h² λ = h (c μ) / b_{s−1}`.
    for (w, x) in mu_out.iter_mut().zip(mu.iter()) {
        *w = h * x / sch.b()[s - 1];
    }
    Ok(())
}

/// `x` as a vector of the model's size (a caller's slice always has `N` entries).
#[inline(always)]
fn vector<const N: usize>(x: &[f64]) -> SVector<f64, N> {
    SVector::from_column_slice(x)
}

impl<M: ForcedLagrangian<N>, const N: usize> StepBackend for DenseBackend<'_, M, N> {
    #[inline(always)]
    fn layout(&self) -> Layout {
        Layout::new(N, self.prob.cons, self.prob.scheme.stages() - 1, false)
    }

    #[inline(always)]
    fn scheme(&self) -> &Scheme {
        self.prob.scheme
    }

    #[inline(always)]
    fn z(&self) -> &[f64] {
        self.z.as_slice()
    }

    #[inline(always)]
    fn z_mut(&mut self) -> &mut [f64] {
        self.z.as_mut_slice()
    }

    #[inline]
    fn solve(
        &mut self,
        h: f64,
        t0: f64,
        (q0, p0): (&[f64], &[f64]),
        (scale, force): (f64, &[f64]),
    ) -> Result<NewtonReport, StepFailure> {
        let prob = &mut self.prob;
        prob.nodes_valid = false;
        prob.scale = scale;
        super::coordinate_scales(h, (p0, force), &mut prob.coord_scale);
        let same_h = (prob.h - h).abs() <= SAME_STEP * h.abs();
        prob.h = h;
        prob.t0 = t0;
        prob.q0.as_mut_slice().copy_from_slice(q0);
        prob.p0.as_mut_slice().copy_from_slice(p0);
        // Fixed steps of one size (`across_steps`) start from the factors of the step
        // before where the system has at least `ACROSS_MIN_UNKNOWNS` unknowns: the Newton
        // iteration then accepts an iterate only once its estimated error is below the
        // round-off of the increments, and makes fresh factors for a while after a solve
        // that took more than two iterations (see `crate::newton`'s iteration). Otherwise a
        // fresh Jacobian at each step, which from the predictor lands in one iteration. Not
        // for a constrained model: its steps already take two iterations, and with carried
        // factors its constraint residuals grew from 1e-15 to up to 1e-12 (Cartesian
        // pendulum, lobatto3–7). The error estimate's one iteration may carry them
        // ([`StepBackend::carry_factors`]).
        let carry = std::mem::take(&mut self.carry);
        // A linear model's factors at one step size are exact: carried at any size.
        let across = self.across_steps
            && same_h
            && prob.cons == 0
            && (self.z.len() >= ACROSS_MIN_UNKNOWNS || M::STRUCTURE.linear);
        if !(carry || across) {
            self.newton.invalidate();
        }
        let constrained = M::CONSTRAINED && prob.cons > 0;
        if constrained {
            prob.scale_constraints(scale, self.z.as_mut_slice());
        }
        let solved = self.newton.solve(prob, &mut self.z, scale);
        if constrained {
            self.prob.unscale_multipliers(self.z.as_mut_slice());
        }
        self.prob.blocks_given = false;
        if M::CONSTRAINED && self.prob.cons > 0 {
            self.end_constrained(solved)
        } else {
            solved.map_err(StepFailure::Newton)
        }
    }

    #[inline(always)]
    fn last_iterations(&self) -> usize {
        self.newton.last_iterations()
    }

    fn carry_factors(&mut self, h: f64, negligible: f64) -> bool {
        // A constrained model's step Jacobian has constraint rows that do not scale with
        // `1 / h`: its factors are not carried.
        self.carry = self.prob.cons == 0 && self.newton.iteration.carry_factors(h, negligible);
        self.carry
    }

    fn solve_within(&mut self, bound: f64) {
        if self.prob.cons == 0 {
            self.newton.iteration.solve_within(bound);
        }
    }

    fn carried_error(&self) -> f64 {
        self.newton.iteration.carried_error()
    }

    fn reject_carry(&mut self) {
        self.newton.iteration.reject_carry()
    }

    fn next_correction(&mut self) -> (f64, f64, bool) {
        self.newton.next_correction()
    }

    fn factors_across_steps(&mut self, on: bool) {
        self.across_steps = on;
    }

    fn set_costly_factors(&mut self, costly: bool) {
        self.newton.iteration.set_costly_factors(costly)
    }

    #[inline(always)]
    fn node_fq(&self, i: usize) -> &[f64] {
        self.prob.grads[i].fq.as_slice()
    }

    #[inline(always)]
    fn node_x(&self, i: usize) -> &[f64] {
        self.prob.xs[i].as_slice()
    }

    #[inline(always)]
    fn node_v(&self, i: usize) -> &[f64] {
        self.prob.vs[i].as_slice()
    }

    fn gradient(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> Result<(), Error> {
        let g = self
            .prob
            .model
            .node_gradient_at(t, &vector::<N>(q), &vector::<N>(v));
        if !(all_finite(&g.lv) && all_finite(&g.fq)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        fq.copy_from_slice(g.fq.as_slice());
        lv.copy_from_slice(g.lv.as_slice());
        Ok(())
    }

    fn velocity(
        &mut self,
        (t, q, p): (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error> {
        let model = self.prob.model;
        let solved = solve_velocity(model, &vector(q), &vector(p), vector(v), step, t)?;
        v.copy_from_slice(solved.as_slice());
        Ok(())
    }

    fn mass_sign(&mut self, (t, q, v): (f64, &[f64], &[f64])) -> Result<f64, Error> {
        mass_check(self.prob.model, &vector(q), &vector(v), 0, t)
    }

    fn mass_at_end(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        sign: f64,
    ) -> Result<(), StepFailure> {
        let e = self.prob.model.mass_matrix_at(t, &vector(q), &vector(v));
        match mass_factor(&e) {
            Some((rcond, s)) if rcond >= MIN_MASS_RCOND && s == sign => Ok(()),
            other => {
                // A change of sign means a singular mass was crossed: condition 0.
                let rcond = match other {
                    Some((rc, s)) if s == sign => rc,
                    _ => 0.0,
                };
                Err(StepFailure::SingularMass { rcond })
            }
        }
    }

    fn linearize(&mut self) -> Result<(), StepFailure> {
        let (dim, opts) = (self.z.len(), *self.newton.options());
        // The tangent's Jacobian leaves the noise of the step's own (the next step's
        // Newton floors count it), so that a run with tangents takes the same steps.
        let prob = &mut self.prob;
        let noise = (prob.noise, prob.noise_h);
        std::mem::swap(&mut prob.noise_rows, &mut self.noise_keep);
        // A constrained step's Jacobian is that of the iteration's units: its multipliers
        // over their factors (see `StepProblem::scale_constraints`); `solve_linearized`
        // takes the factors on rows and unknowns back out.
        let constrained = M::CONSTRAINED && prob.cons > 0;
        let scaled;
        let z = if constrained {
            let nz = (prob.scheme.stages() - 1) * N;
            let mut zs = self.z.clone();
            for (i, w) in zs.iter_mut().enumerate().skip(nz) {
                *w /= prob.col_scale[(i - nz) % prob.cons];
            }
            scaled = zs;
            &scaled
        } else {
            &self.z
        };
        let made = self
            .tangent
            .get_or_insert_with(|| Newton::new(dim, opts))
            .factor_at(prob, z)
            .map_err(StepFailure::Newton);
        std::mem::swap(&mut prob.noise_rows, &mut self.noise_keep);
        (prob.noise, prob.noise_h) = noise;
        made
    }

    fn apply_node(&self, i: usize, (dx, dv): (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        let Some(nj) = self.prob.jacs.get(i) else {
            dfq.fill(f64::NAN);
            dlv.fill(f64::NAN);
            return;
        };
        let (dx, dv) = (vector::<N>(dx), vector::<N>(dv));
        dfq.copy_from_slice((nj.a * dx + nj.b * dv).as_slice());
        dlv.copy_from_slice((nj.c * dx + nj.e * dv).as_slice());
    }

    fn solve_linearized(&mut self, b: &mut [f64]) {
        if self.rhs.len() != b.len() {
            self.rhs = DVector::zeros(b.len());
        }
        self.rhs.as_mut_slice().copy_from_slice(b);
        // A constrained step's rows `g(x_j)` and unknowns `ŵ_j` in the iteration's units
        // (see `linearize`): each constraint's rows times its factor, its unknowns over it.
        let prob = &self.prob;
        let m = if M::CONSTRAINED { prob.cons } else { 0 };
        let nz = if m > 0 {
            (prob.scheme.stages() - 1) * N
        } else {
            b.len()
        };
        let (rows, cols) = (&prob.row_scale, &prob.col_scale);
        for (i, x) in self.rhs.iter_mut().enumerate().skip(nz) {
            *x *= rows[(i - nz) % m];
        }
        match &self.tangent {
            Some(t) => t.solve_factored(&mut self.rhs),
            None => self.rhs.fill(f64::NAN),
        }
        for (i, x) in self.rhs.iter_mut().enumerate().skip(nz) {
            *x *= cols[(i - nz) % m];
        }
        b.copy_from_slice(self.rhs.as_slice());
    }

    fn momentum_tangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        (dq, dv): (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let out = nj.c * vector::<N>(dq) + nj.e * vector::<N>(dv);
        if !all_finite(&out) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        dp.copy_from_slice(out.as_slice());
        Ok(())
    }

    fn velocity_tangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        (dq, dp): (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let rhs = vector::<N>(dp) - nj.c * vector::<N>(dq);
        match solve_small(&nj.e, &rhs) {
            Some((x, rcond)) if rcond >= MIN_MASS_RCOND && all_finite(&x) => {
                dv.copy_from_slice(x.as_slice());
                Ok(())
            }
            // A well-conditioned mass: the direction itself is beyond `f64`'s range.
            Some((_, rcond)) if rcond >= MIN_MASS_RCOND => {
                let size = dq.iter().chain(dp).fold(0.0f64, |m, x| m.max(x.abs()));
                Err(crate::stepper::non_finite(size, 0, t, "tangent"))
            }
            other => Err(Error::SingularMassMatrix {
                step: 0,
                t,
                rcond: other.map_or(0.0, |(_, rc)| rc),
            }),
        }
    }

    fn constraint_impulse(&self) -> Option<&[f64]> {
        (self.prob.cons > 0).then_some(&self.impulse[..])
    }

    fn end_multipliers(&self) -> &[f64] {
        &self.mu
    }

    fn constraint_residuals(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
    ) -> Result<[f64; 4], Error> {
        if M::CONSTRAINED {
            Ok(crate::initial::constraint_residuals_at(
                self.prob.model,
                t,
                q,
                v,
            ))
        } else {
            Ok([0.0; 4])
        }
    }

    fn step_data(&self) -> (f64, f64, &[f64], &[f64]) {
        let p = &self.prob;
        (p.h, p.t0, p.q0.as_slice(), p.p0.as_slice())
    }

    fn force_round_off_rate(&self) -> f64 {
        let p = &self.prob;
        let velocities = crate::newton::force_round_off(
            1.0,
            p.jacs.iter().map(|j| j.b.as_slice()),
            p.vs.iter().map(|v| v.as_slice()),
        );
        crate::newton::force_round_off_rate(p.noise, p.noise_h) + velocities
    }

    fn force_gain(&self, h: f64) -> f64 {
        let row_sums = |m: &nalgebra::SMatrix<f64, N, N>| {
            (0..N).fold(0.0f64, |best, r| {
                best.max((0..N).map(|c| m[(r, c)].abs()).sum::<f64>())
            })
        };
        let (a, b) = self.prob.jacs.iter().fold((0.0f64, 0.0f64), |(a, b), j| {
            (a.max(row_sums(&j.a)), b.max(row_sums(&j.b)))
        });
        h * a + b
    }

    fn restore(&mut self, h: f64, t0: f64, (q0, p0): (&[f64], &[f64]), z: &[f64]) {
        let prob = &mut self.prob;
        prob.nodes_valid = false;
        prob.h = h;
        prob.t0 = t0;
        prob.q0.as_mut_slice().copy_from_slice(q0);
        prob.p0.as_mut_slice().copy_from_slice(p0);
        self.z.as_mut_slice().copy_from_slice(z);
        self.newton.invalidate();
    }

    fn linearize_transposed(&mut self) -> Result<(), StepFailure> {
        self.linearize()?;
        let Some(tangent) = self.tangent.as_ref() else {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        };
        let jac = tangent.jacobian();
        let dim = jac.nrows();
        let (jt, lu) = self
            .adjoint
            .get_or_insert_with(|| (DMatrix::zeros(dim, dim), DenseLu::new(dim)));
        jac.transpose_to(jt);
        lu.factor(jt).map_err(StepFailure::Newton)
    }

    fn solve_transposed(&mut self, b: &mut [f64]) {
        let Some((_, lu)) = self.adjoint.as_ref() else {
            b.fill(f64::NAN);
            return;
        };
        if self.rhs.len() != b.len() {
            self.rhs = DVector::zeros(b.len());
        }
        self.rhs.as_mut_slice().copy_from_slice(b);
        // A constrained step's Jacobian is factored in the iteration's units (see
        // `solve_linearized`, `J⁻¹ = C J_it⁻¹ R`): here `J⁻ᵀ = R J_it⁻ᵀ C`.
        let prob = &self.prob;
        let m = if M::CONSTRAINED { prob.cons } else { 0 };
        let nz = (prob.scheme.stages() - 1) * N;
        if m > 0 {
            for (i, x) in self.rhs.iter_mut().enumerate().skip(nz) {
                *x *= prob.col_scale[(i - nz) % m];
            }
        }
        lu.solve_in_place(&mut self.rhs);
        if m > 0 {
            for (i, x) in self.rhs.iter_mut().enumerate().skip(nz) {
                *x *= prob.row_scale[(i - nz) % m];
            }
        }
        b.copy_from_slice(self.rhs.as_slice());
    }

    fn apply_node_transposed(
        &self,
        i: usize,
        (mf, ml): (&[f64], &[f64]),
        ux: &mut [f64],
        uv: &mut [f64],
    ) {
        let Some(nj) = self.prob.jacs.get(i) else {
            ux.fill(f64::NAN);
            uv.fill(f64::NAN);
            return;
        };
        let (mf, ml) = (vector::<N>(mf), vector::<N>(ml));
        ux.copy_from_slice((nj.a.tr_mul(&mf) + nj.c.tr_mul(&ml)).as_slice());
        uv.copy_from_slice((nj.b.tr_mul(&mf) + nj.e.tr_mul(&ml)).as_slice());
    }

    fn momentum_cotangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        y: &[f64],
        (cq, ev): (&mut [f64], &mut [f64]),
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let y = vector::<N>(y);
        let (a, b) = (nj.c.tr_mul(&y), nj.e.tr_mul(&y));
        if !(all_finite(&a) && all_finite(&b)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        cq.copy_from_slice(a.as_slice());
        ev.copy_from_slice(b.as_slice());
        Ok(())
    }

    #[inline(always)]
    fn deep_stack(&self) -> bool {
        true
    }
    // The stepper makes a dense step's terms from the model (`tangent_constrained`).
    fn sparse_constraint_terms(
        &mut self,
    ) -> Result<Option<super::SparseConstraintTerms>, StepFailure> {
        Ok(None)
    }
    fn solve_end_projection(&mut self, _rhs: &mut [f64]) -> bool {
        false
    }
    // The stepper solves a dense step's end velocity again from its momentum.
    fn end_velocity(&self) -> Option<&[f64]> {
        None
    }
    fn restore_end(&mut self, mu: &[f64], _v1: &[f64]) {
        if self.mu.len() == mu.len() {
            self.mu.copy_from_slice(mu);
        }
    }
}
