//! The tangent of a constrained step (DESIGN §11, §12): the multipliers join the step's
//! unknowns, and the step's end projection is differentiated too.
//!
//! A constrained Lobatto step solves, besides the gradient rows, `g(x_j) = 0` for
//! `j = 1 … s − 1`, with unknowns `ŵ_j = h² λ_j` (`j = 0 … s − 2`) whose forces
//! `−(b_j/h) G(x_j)ᵀ ŵ_j` enter the gradient of control point `j`. Its end is the projection
//! `L_v(q₁, v₁) + G(q₁)ᵀ μ̂ = p̃`, `G(q₁) v₁ + ∂g/∂t = 0`, with `p̃ = G_{s−1}` and the impulse
//! `μ̂ = h b_{s−1} λ_{s−1}`; then `p₁ = p̃ − G(q₁)ᵀ μ̂ = L_v(q₁, v₁)`. A direction
//! `(dq, dp, dθ)` goes through it as the unconstrained one does ([`super::tangent`]), with
//!
//! - in the gradient rows `j ≤ s − 2`, the linearised constraint forces
//!   `−(b_j/h) [G_jᵀ dŵ_j + K_j dx_j + ∂(G_jᵀ ŵ_j)/∂θ dθ]`, `K_j = Σ_r ŵ_{j,r} ∂²g_r(x_j)`
//!   (the step Jacobian holds the first two for `j ≥ 1`; the right-hand side gets the rest);
//! - in the constraint rows, `G_j dx_j + ∂g/∂θ dθ`;
//! - at the end, `[[E₁, G₁ᵀ], [G₁, 0]] (dv₁, dμ̂) = (dp̃ − (C₁ + K_μ) dq₁ − ∂L_v/∂θ dθ −
//!   ∂(G₁ᵀ μ̂)/∂θ dθ, −H dq₁ − ∂(G₁ v₁ + ∂g/∂t)/∂θ dθ)`, `K_μ = Σ_r μ̂_r ∂²g_r(q₁)`,
//!   `H = ∂(G(q) v₁ + ∂g/∂t)/∂q` at `q₁`, and `dp₁ = dp̃ − G₁ᵀ dμ̂ − K_μ dq₁ −
//!   ∂(G₁ᵀ μ̂)/∂θ dθ`.
//!
//! Every term is exact (the step's own factors; on the dense backend, dual numbers over the
//! constraints in all `N` coordinates; on the sparse one, its kernels' `G` and curvature on
//! their patterns, the end's saddle point factored again at `(q₁, v₁)` by its sparse LU,
//! and `H` and the parameters' terms from hyper-dual numbers along each coordinate, `N`
//! evaluations of `g` per step): the result is the derivative of the discrete map, checked
//! against central differences of whole runs in the tests, on both backends. Directions off the constraints (`G(q₀) dq₀ ≠ 0`) are carried as
//! the map's linear extension; the map is only a flow on the constraints.

use nalgebra::{DMatrix, DVector, SVector};

use super::Stepper;
use super::linearized::{Tangent, linearized_gradients, parameter_gradient};
use crate::backend::{SparseConstraintTerms, StepBackend, StepFailure};
use crate::error::NewtonFailure;
use crate::model::ForcedLagrangian;
use crate::model::general::{
    Direction, constraint_curvature_at, constraint_jacobian_at, constraint_second_at,
};

/// The constraint terms of one solved step, evaluated once for all its tangent's columns.
pub(super) struct ConstraintTerms {
    m: usize,
    /// The matrices, dense or on the sparse backend's patterns.
    kind: Kind,
    /// Per parameter: `∂(G_jᵀ ŵ_j)/∂θ` (`j ≤ s − 2`), `∂g(x_j)/∂θ` (`j ≥ 1`, block `j − 1`),
    /// and at the end `∂L_v/∂θ + ∂(G₁ᵀ μ̂)/∂θ`, `∂(G₁ᵀ μ̂)/∂θ`, `∂(G₁ v₁ + ∂g/∂t)/∂θ`.
    params: Vec<ParameterTerms>,
}

/// The matrices of [`ConstraintTerms`].
enum Kind {
    /// The dense backend's, from the model's dense kernels.
    Dense {
        /// `G(x_j)`, `j = 0 … s − 1` (`m × N` each).
        g: Vec<DMatrix<f64>>,
        /// `K_j`, `j = 0 … s − 2`.
        k: Vec<DMatrix<f64>>,
        /// The end: `C₁ + K_μ`, `K_μ`, `H` and the factors of `[[E₁, G₁ᵀ], [G₁, 0]]`.
        c1k: DMatrix<f64>,
        kmu: DMatrix<f64>,
        rate: DMatrix<f64>,
        kkt: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
    },
    /// The sparse backend's, on its patterns, with `H` by its entries `(r, a, value)`; the
    /// backend holds the factors of the end projection.
    Sparse {
        terms: SparseConstraintTerms,
        rate: Vec<(usize, usize, f64)>,
    },
}

impl Kind {
    /// `K_j dq` (`j ≤ s − 2`).
    fn curvature(&self, j: usize, dq: &[f64], out: &mut [f64]) {
        match self {
            Kind::Dense { k, .. } => out.copy_from_slice((&k[j] * vector(dq)).as_slice()),
            Kind::Sparse { terms, .. } => {
                SparseConstraintTerms::times(&terms.node_entries, &terms.k[j], dq, out)
            }
        }
    }

    /// `G_j dq`.
    fn constraints(&self, j: usize, dq: &[f64], out: &mut [f64]) {
        match self {
            Kind::Dense { g, .. } => out.copy_from_slice((&g[j] * vector(dq)).as_slice()),
            Kind::Sparse { terms, .. } => {
                SparseConstraintTerms::times(&terms.g_entries, &terms.g[j], dq, out)
            }
        }
    }

    /// `G_jᵀ y`.
    fn constraints_transposed(&self, j: usize, y: &[f64], out: &mut [f64]) {
        match self {
            Kind::Dense { g, .. } => out.copy_from_slice((g[j].transpose() * vector(y)).as_slice()),
            Kind::Sparse { terms, .. } => {
                SparseConstraintTerms::times_transposed(&terms.g_entries, &terms.g[j], y, out)
            }
        }
    }

    /// At the end: `(C₁ + K_μ) dq₁`, `K_μ dq₁` and `H dq₁`.
    fn end(&self, dq1: &[f64], (c1k_dq, kmu_dq, rate_dq): (&mut [f64], &mut [f64], &mut [f64])) {
        match self {
            Kind::Dense { c1k, kmu, rate, .. } => {
                let d = vector(dq1);
                c1k_dq.copy_from_slice((c1k * &d).as_slice());
                kmu_dq.copy_from_slice((kmu * &d).as_slice());
                rate_dq.copy_from_slice((rate * &d).as_slice());
            }
            Kind::Sparse { terms, rate } => {
                let e = &terms.node_entries;
                SparseConstraintTerms::times(e, &terms.c1k, dq1, c1k_dq);
                SparseConstraintTerms::times(e, &terms.kmu, dq1, kmu_dq);
                rate_dq.fill(0.0);
                for &(r, a, x) in rate {
                    rate_dq[r] += x * dq1[a];
                }
            }
        }
    }

    /// The transposed end products: `out = K_μ a_p + (C₁ + K_μ)ᵀ y_top + Hᵀ y_bot`.
    fn end_transposed(&self, ap: &[f64], (y_top, y_bot): (&[f64], &[f64]), out: &mut [f64]) {
        match self {
            Kind::Dense { c1k, kmu, rate, .. } => {
                let x = kmu * vector(ap)
                    + c1k.transpose() * vector(y_top)
                    + rate.transpose() * vector(y_bot);
                out.copy_from_slice(x.as_slice());
            }
            Kind::Sparse { terms, rate } => {
                let e = &terms.node_entries;
                let mut t = vec![0.0; out.len()];
                SparseConstraintTerms::times(e, &terms.kmu, ap, out);
                SparseConstraintTerms::times_transposed(e, &terms.c1k, y_top, &mut t);
                out.iter_mut().zip(&t).for_each(|(o, x)| *o += x);
                for &(r, a, x) in rate {
                    out[a] += x * y_bot[r];
                }
            }
        }
    }

    /// Solves the end projection's `[[E₁, G₁ᵀ], [G₁, 0]] x = end` in place; false where it
    /// cannot.
    fn solve_end(&self, backend: &mut dyn StepBackend, end: &mut DVector<f64>) -> bool {
        match self {
            Kind::Dense { kkt, .. } => kkt.solve_mut(end),
            Kind::Sparse { .. } => {
                backend.solve_end_projection(end.as_mut_slice())
                    && end.iter().all(|x| x.is_finite())
            }
        }
    }
}

impl ConstraintTerms {
    /// The adjoint `(a_q, a_p)` of the end `(q₁, p₁)` taken back through the end projection
    /// (its transpose; the saddle-point matrix is symmetric): into `adq1` and `adpt`, the
    /// adjoints of `q₁` before the projection and of `p̃`. Returns `y`, the projection's
    /// transposed solution (`N + m` values), or `None` where it could not be solved.
    pub(super) fn end_adjoint(
        &self,
        backend: &mut dyn StepBackend,
        (aq, ap): (&[f64], &[f64]),
        (adq1, adpt): (&mut [f64], &mut [f64]),
    ) -> Option<DVector<f64>> {
        let (n, m, s) = (aq.len(), self.m, backend.scheme().stages());
        let mut y = DVector::zeros(n + m);
        let mut g1ap = vec![0.0; m];
        self.kind.constraints(s - 1, ap, &mut g1ap);
        for (k, x) in g1ap.iter().enumerate() {
            y[n + k] = -x;
        }
        if !self.kind.solve_end(backend, &mut y) {
            return None;
        }
        let (top, bottom) = (y.rows(0, n), y.rows(n, m));
        self.kind
            .end_transposed(ap, (top.as_slice(), bottom.as_slice()), adq1);
        for a in 0..n {
            adq1[a] = aq[a] - adq1[a];
            adpt[a] = ap[a] + y[a];
        }
        Some(y)
    }

    /// The adjoint of `dq` from the constraint terms of the step's equations, added to
    /// `aq`: `Σ_{j ≤ s−2} (b_j/h) K_j w_j − Σ_{j ≥ 1} G_jᵀ ω_{j−1}`, with `w` the transposed
    /// solution `c` in the gradient rows of control point `j + 1` and `ω` in the constraint
    /// rows; and each parameter's share into `grad`, with `y` from [`Self::end_adjoint`]
    /// and `ap` the adjoint of `p₁`.
    pub(super) fn step_adjoint(
        &self,
        backend: &dyn StepBackend,
        (c, y, ap, h): (&[f64], &DVector<f64>, &[f64], f64),
        aq: &mut [f64],
        grad: &mut [f64],
    ) {
        let (n, m) = (aq.len(), self.m);
        let sch = backend.scheme();
        let (s, lay) = (sch.stages(), backend.layout());
        let (mut w, mut om, mut t) = (vec![0.0; n], vec![0.0; m], vec![0.0; n]);
        let at_w = |j: usize, w: &mut [f64]| {
            for (a, x) in w.iter_mut().enumerate() {
                *x = c[lay.at(j + 1, a)];
            }
        };
        let at_om = |j: usize, om: &mut [f64]| {
            for (k, x) in om.iter_mut().enumerate() {
                *x = c[lay.multiplier(j, k)];
            }
        };
        for j in 0..s - 1 {
            at_w(j, &mut w);
            self.kind.curvature(j, &w, &mut t);
            let f = sch.b()[j] / h;
            aq.iter_mut().zip(&t).for_each(|(x, v)| *x += f * v);
            for (p, g) in grad.iter_mut().enumerate() {
                if let Some(pt) = self.params.get(p) {
                    *g += f * pt.force[j].iter().zip(&w).map(|(a, b)| a * b).sum::<f64>();
                }
            }
        }
        for j in 1..s {
            at_om(j - 1, &mut om);
            self.kind.constraints_transposed(j, &om, &mut t);
            aq.iter_mut().zip(&t).for_each(|(x, v)| *x -= v);
            for (p, g) in grad.iter_mut().enumerate() {
                if let Some(pt) = self.params.get(p) {
                    *g -= pt.rows[j - 1]
                        .iter()
                        .zip(&om)
                        .map(|(a, b)| a * b)
                        .sum::<f64>();
                }
            }
        }
        let (top, bottom) = (y.rows(0, n), y.rows(n, m));
        for (p, g) in grad.iter_mut().enumerate() {
            if let Some(pt) = self.params.get(p) {
                *g -= pt.end_lv.dot(&top) + pt.end_rate.dot(&bottom);
                *g -= pt.end_force.iter().zip(ap).map(|(a, b)| a * b).sum::<f64>();
            }
        }
    }
}

fn vector(x: &[f64]) -> DVector<f64> {
    DVector::from_column_slice(x)
}

struct ParameterTerms {
    force: Vec<DVector<f64>>,
    rows: Vec<DVector<f64>>,
    end_lv: DVector<f64>,
    end_force: DVector<f64>,
    end_rate: DVector<f64>,
}

fn non_finite() -> StepFailure {
    StepFailure::Newton(NewtonFailure::NonFinite)
}

fn checked(x: &DMatrix<f64>) -> Result<(), StepFailure> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(non_finite())
    }
}

/// The end of the constrained step whose terms are made: its size, end time, end momentum,
/// a guess of its projected end velocity (the step polynomial's slope) and its number.
pub(super) struct StepEnd {
    pub(super) h: f64,
    pub(super) t1: f64,
    pub(super) p1: Vec<f64>,
    pub(super) v_guess: Vec<f64>,
    pub(super) k: usize,
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// The end of the step just solved and committed.
    pub(super) fn step_end(&self) -> StepEnd {
        StepEnd {
            h: self.state.h_prev,
            t1: self.state.t_state,
            p1: self.state.p.sum.clone(),
            v_guess: self.state.v.clone(),
            k: self.k,
        }
    }

    /// The step ending at `end`: its stages, constraints, size and start time.
    fn solved_step(&self, end: &StepEnd) -> (usize, usize, f64, f64) {
        let m = self.model.constraint_count();
        (self.scheme.stages(), m, end.h, end.t1 - end.h)
    }

    /// The multipliers `ŵ_j` of control point `j ≤ s − 2` of the step just solved.
    fn multipliers(&self, j: usize) -> Vec<f64> {
        let (lay, z) = (self.backend.layout(), self.backend.z());
        (0..self.model.constraint_count())
            .map(|r| z[lay.multiplier(j, r)])
            .collect()
    }

    /// The constraint terms of the step ending at `end`, solved and linearised (see the module docs),
    /// at its control points, multipliers and projected end: from the sparse backend's
    /// kernels where it makes them, else from the model's dense ones.
    pub(super) fn constraint_terms(
        &mut self,
        theta: &[f64],
        end: &StepEnd,
    ) -> Result<ConstraintTerms, StepFailure> {
        let sparse = self.backend.sparse_constraint_terms()?;
        let (model, sch) = (self.model, self.scheme);
        let (s, m, h, _) = self.solved_step(end);
        let t1 = end.t1;
        let q1 = self.backend.node_x(s - 1).to_vec();
        let (kind, v1) = match sparse {
            Some(mut terms) => {
                // `H = ∂(G v₁ + ∂g/∂t)/∂q` by its entries: the backend's, from its kernels,
                // or the second derivative of `g` along `(1, v₁)` in `(t, q)` and along each
                // coordinate (`N` evaluations of `g`).
                let v1 = terms.v1.clone();
                if let Some(rate) = terms.rate.take() {
                    (Kind::Sparse { terms, rate }, v1)
                } else {
                    let mut rate = Vec::new();
                    let along = Direction {
                        t: if M::CONSTRAINTS_READ_TIME { 1.0 } else { 0.0 },
                        q: Some(&v1),
                        theta: None,
                    };
                    let mut finite = true;
                    along_coordinates(model, (t1, &q1, theta), along, |a, _, sec| {
                        for (r, &x) in sec.iter().enumerate() {
                            finite &= x.is_finite();
                            if x != 0.0 {
                                rate.push((r, a, x));
                            }
                        }
                    });
                    if !finite {
                        return Err(non_finite());
                    }
                    (Kind::Sparse { terms, rate }, v1)
                }
            }
            None => {
                let (kind, v1) = self.dense_terms(theta, end)?;
                (kind, v1.as_slice().to_vec())
            }
        };
        let wb = sch.b()[s - 1] / h;
        let mu: Vec<f64> = self
            .backend
            .end_multipliers()
            .iter()
            .map(|w| wb * w)
            .collect();
        let mut params = Vec::with_capacity(theta.len());
        for p in 0..theta.len() {
            params.push(self.parameter_terms(theta, p, (&mu, &v1), end)?);
        }
        Ok(ConstraintTerms { m, kind, params })
    }

    /// The dense terms of the step just solved, and its projected end velocity.
    fn dense_terms(
        &self,
        theta: &[f64],
        end: &StepEnd,
    ) -> Result<(Kind, SVector<f64, N>), StepFailure> {
        let (model, backend, sch) = (self.model, &self.backend, self.scheme);
        let (s, m, h, t0) = self.solved_step(end);
        let x_at = |j: usize| SVector::<f64, N>::from_column_slice(backend.node_x(j));
        let t_at = |j: usize| t0 + sch.c()[j] * h;
        let w_at = |j: usize| self.multipliers(j);
        let mut gval = vec![0.0; m];
        let mut g = Vec::with_capacity(s);
        for j in 0..s {
            let mut gj = DMatrix::zeros(m, N);
            constraint_jacobian_at(model, t_at(j), &x_at(j), &mut gval, &mut gj);
            checked(&gj)?;
            g.push(gj);
        }
        let mut k = Vec::with_capacity(s - 1);
        for j in 0..s - 1 {
            let kj = constraint_curvature_at(model, t_at(j), &x_at(j), &w_at(j));
            let kj = DMatrix::from_column_slice(N, N, kj.as_slice());
            checked(&kj)?;
            k.push(kj);
        }
        // The end: the projected velocity, and the impulse `μ̂ = (b_{s−1}/h) ŵ_{s−1}`.
        let (t1, q1) = (end.t1, x_at(s - 1));
        // The projected end velocity, `L_v(q₁, v₁) = p₁` (the state's is the step
        // polynomial's slope, a guess).
        let p1 = SVector::<f64, N>::from_column_slice(&end.p1);
        let guess = SVector::<f64, N>::from_column_slice(&end.v_guess);
        let v1 = crate::initial::solve_velocity(model, &q1, &p1, guess, end.k, t1)
            .map_err(|_| non_finite())?;
        let wb = sch.b()[s - 1] / h;
        let mu: Vec<f64> = backend.end_multipliers().iter().map(|w| wb * w).collect();
        let nj = model.node_jacobian_at(t1, &q1, &v1);
        let kmu = constraint_curvature_at(model, t1, &q1, &mu);
        let kmu = DMatrix::from_column_slice(N, N, kmu.as_slice());
        let c1k = DMatrix::from_column_slice(N, N, nj.c.as_slice()) + &kmu;
        // `∂(G v₁ + ∂g/∂t)/∂q`: the second derivative of `g` along `(1, v₁)` in `(t, q)` and
        // along each coordinate.
        let along = Direction {
            t: if M::CONSTRAINTS_READ_TIME { 1.0 } else { 0.0 },
            q: Some(v1.as_slice()),
            theta: None,
        };
        let mut rate = DMatrix::zeros(m, N);
        along_coordinates(model, (t1, q1.as_slice(), theta), along, |a, _, sec| {
            for (r, x) in sec.iter().enumerate() {
                rate[(r, a)] = *x;
            }
        });
        let g1 = &g[s - 1];
        let mut kkt = DMatrix::zeros(N + m, N + m);
        kkt.view_mut((0, 0), (N, N))
            .copy_from(&DMatrix::from_column_slice(N, N, nj.e.as_slice()));
        kkt.view_mut((0, N), (N, m)).copy_from(&g1.transpose());
        kkt.view_mut((N, 0), (m, N)).copy_from(g1);
        for x in [&c1k, &rate, &kkt] {
            checked(x)?;
        }
        // The step's own projection factored this matrix at the same point: singular here
        // only if it was there too.
        let kkt = kkt.lu();
        if !kkt.is_invertible() {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        }
        let kind = Kind::Dense {
            g,
            k,
            c1k,
            kmu,
            rate,
            kkt,
        };
        Ok((kind, v1))
    }

    /// The terms of parameter `p` (see [`ConstraintTerms::params`]), with the end impulse
    /// `mu` and velocity `v1`.
    fn parameter_terms(
        &self,
        theta: &[f64],
        p: usize,
        (mu, v1): (&[f64], &[f64]),
        end: &StepEnd,
    ) -> Result<ParameterTerms, StepFailure> {
        let (model, backend, sch) = (self.model, &self.backend, self.scheme);
        let (s, m, h, t0) = self.solved_step(end);
        let in_theta = Direction {
            t: 0.0,
            q: None,
            theta: Some(p),
        };
        // `∂(G(x)ᵀ w)/∂θ_p` at `(t, x)`, and `∂g/∂θ_p` there.
        let force_rows = |t: f64, x: &[f64], w: &[f64]| {
            let mut force = DVector::zeros(N);
            let mut rows = DVector::zeros(m);
            along_coordinates(model, (t, x, theta), in_theta, |a, first, sec| {
                force[a] = w.iter().zip(sec).map(|(w, s)| w * s).sum();
                rows.copy_from_slice(first);
            });
            (force, rows)
        };
        let mut force = Vec::with_capacity(s - 1);
        let mut rows = Vec::with_capacity(s - 1);
        let mut end_force = DVector::zeros(N);
        for j in 0..s {
            let w = if j + 1 < s {
                self.multipliers(j)
            } else {
                mu.to_vec()
            };
            let (f, r) = force_rows(t0 + sch.c()[j] * h, backend.node_x(j), &w);
            if j + 1 < s {
                force.push(f);
            } else {
                end_force = f;
            }
            if j >= 1 {
                rows.push(r);
            }
        }
        let (t1, q1) = (end.t1, backend.node_x(s - 1));
        let along = Direction {
            t: if M::CONSTRAINTS_READ_TIME { 1.0 } else { 0.0 },
            q: Some(v1),
            theta: None,
        };
        let (mut f1, mut f2, mut sec) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
        constraint_second_at(
            model,
            (t1, q1, theta),
            (along, in_theta),
            (&mut f1, &mut f2, &mut sec),
        );
        let end_rate = DVector::from_column_slice(&sec);
        let lv = parameter_gradient(model, (t1, q1, v1), theta, p).lv;
        let end_lv = DVector::from_column_slice(lv.as_slice()) + &end_force;
        let all = force
            .iter()
            .chain(&rows)
            .chain([&end_lv, &end_force, &end_rate]);
        for x in all {
            if !x.iter().all(|v| v.is_finite()) {
                return Err(non_finite());
            }
        }
        Ok(ParameterTerms {
            force,
            rows,
            end_lv,
            end_force,
            end_rate,
        })
    }
}

/// The constraints' derivatives at `at = (t, x, θ)` along `other`, first and mixed with
/// each coordinate in turn: `each(a, ∂g/∂other, ∂²g/∂x_a∂other)`.
fn along_coordinates<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    at: (f64, &[f64], &[f64]),
    other: Direction<'_>,
    mut each: impl FnMut(usize, &[f64], &[f64]),
) {
    let m = model.constraint_count();
    let (mut f1, mut f2, mut sec) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
    let mut unit = [0.0; N];
    for a in 0..N {
        unit.fill(0.0);
        unit[a] = 1.0;
        let d = Direction {
            t: 0.0,
            q: Some(&unit),
            theta: None,
        };
        constraint_second_at(model, at, (d, other), (&mut f1, &mut f2, &mut sec));
        each(a, &f2, &sec);
    }
}

/// Carries the columns of `tg` through the constrained step of size `h` that `backend`
/// holds, linearised, with its constraint terms `ct` (see the module docs).
pub(super) fn propagate_constrained(
    backend: &mut dyn StepBackend,
    tg: &mut Tangent,
    h: f64,
    n: usize,
    ct: &ConstraintTerms,
) {
    let s = backend.scheme().stages();
    let b = backend.scheme().b().to_vec();
    let lay = backend.layout();
    let (m, np) = (ct.m, tg.theta.len());
    let mut end = DVector::zeros(n + m);
    let (mut f, mut r) = (vec![0.0; n], vec![0.0; m]);
    let (mut c1k_dq, mut kmu_dq, mut rate_dq) = (vec![0.0; n], vec![0.0; n], vec![0.0; m]);
    let mut g1t_dmu = vec![0.0; n];
    for c in 0..tg.columns(n) {
        let col = c * 2 * n;
        let p = c.checked_sub(2 * n);
        let pt = p.and_then(|p| ct.params.get(p));
        let dq = tg.m[col..col + n].to_vec();
        tg.dx[..n].copy_from_slice(&dq);
        tg.dx[n..].fill(0.0);
        let param = p.map(|p| (&tg.pnode[..], p, np));
        linearized_gradients(backend, h, &tg.dx, param, &mut tg.g, &mut tg.node);
        // The constraint forces of the control points `j ≤ s − 2` moved by `dq` (and `dθ`).
        for (j, bj) in b.iter().enumerate().take(s - 1) {
            ct.kind.curvature(j, &dq, &mut f);
            if let Some(pt) = pt {
                f.iter_mut()
                    .zip(pt.force[j].iter())
                    .for_each(|(x, y)| *x += y);
            }
            let w = bj / h;
            for (g, fa) in tg.g[j * n..(j + 1) * n].iter_mut().zip(&f) {
                *g -= w * fa;
            }
        }
        for j in 0..s - 1 {
            for a in 0..n {
                let dp = if j == 0 { tg.m[col + n + a] } else { 0.0 };
                tg.rhs[lay.at(j + 1, a)] = -(tg.g[j * n + a] + dp);
            }
        }
        for j in 1..s {
            ct.kind.constraints(j, &dq, &mut r);
            if let Some(pt) = pt {
                r.iter_mut()
                    .zip(pt.rows[j - 1].iter())
                    .for_each(|(x, y)| *x += y);
            }
            for (k, rk) in r.iter().enumerate() {
                tg.rhs[lay.multiplier(j - 1, k)] = -rk;
            }
        }
        backend.solve_linearized(&mut tg.rhs);
        for mm in 1..s {
            for a in 0..n {
                tg.dx[mm * n + a] = tg.rhs[lay.at(mm, a)];
            }
        }
        linearized_gradients(backend, h, &tg.dx, param, &mut tg.g, &mut tg.node);
        // The projection at the end.
        let dq1: Vec<f64> = (0..n).map(|a| dq[a] + tg.dx[(s - 1) * n + a]).collect();
        let dpt = &tg.g[(s - 1) * n..s * n];
        ct.kind.end(&dq1, (&mut c1k_dq, &mut kmu_dq, &mut rate_dq));
        for a in 0..n {
            end[a] = dpt[a] - c1k_dq[a] - pt.map_or(0.0, |pt| pt.end_lv[a]);
        }
        for k in 0..m {
            end[n + k] = -rate_dq[k] - pt.map_or(0.0, |pt| pt.end_rate[k]);
        }
        let solved = ct.kind.solve_end(backend, &mut end);
        ct.kind
            .constraints_transposed(s - 1, end.rows(n, m).as_slice(), &mut g1t_dmu);
        for a in 0..n {
            let dp1 = dpt[a] - g1t_dmu[a] - kmu_dq[a] - pt.map_or(0.0, |pt| pt.end_force[a]);
            tg.m[col + a] += tg.dx[(s - 1) * n + a];
            tg.m[col + n + a] = if solved { dp1 } else { f64::NAN };
        }
    }
}
