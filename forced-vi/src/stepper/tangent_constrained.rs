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
//! Every term is exact (dual numbers over the constraints, the step's own factors): the
//! result is the derivative of the discrete map, checked against central differences of
//! whole runs in the tests. Directions off the constraints (`G(q₀) dq₀ ≠ 0`) are carried as
//! the map's linear extension; the map is only a flow on the constraints.

use nalgebra::{DMatrix, DVector, SVector};

use super::Stepper;
use super::tangent::{Tangent, linearized_gradients, parameter_gradient};
use crate::backend::{StepBackend, StepFailure};
use crate::error::NewtonFailure;
use crate::model::ForcedLagrangian;
use crate::model::general::{
    Direction, constraint_curvature_at, constraint_jacobian_at, constraint_second_at,
};

/// The constraint terms of one solved step, evaluated once for all its tangent's columns.
pub(super) struct ConstraintTerms {
    m: usize,
    /// `G(x_j)`, `j = 0 … s − 1` (`m × N` each).
    g: Vec<DMatrix<f64>>,
    /// `K_j`, `j = 0 … s − 2`.
    k: Vec<DMatrix<f64>>,
    /// The end: `C₁ + K_μ`, `K_μ`, `H` and the factors of `[[E₁, G₁ᵀ], [G₁, 0]]`.
    c1k: DMatrix<f64>,
    kmu: DMatrix<f64>,
    rate: DMatrix<f64>,
    kkt: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
    /// Per parameter: `∂(G_jᵀ ŵ_j)/∂θ` (`j ≤ s − 2`), `∂g(x_j)/∂θ` (`j ≥ 1`, block `j − 1`),
    /// and at the end `∂L_v/∂θ + ∂(G₁ᵀ μ̂)/∂θ`, `∂(G₁ᵀ μ̂)/∂θ`, `∂(G₁ v₁ + ∂g/∂t)/∂θ`.
    params: Vec<ParameterTerms>,
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

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// The step just solved: its stages, constraints, size and start time.
    fn solved_step(&self) -> (usize, usize, f64, f64) {
        let h = self.state.h_prev;
        let m = self.model.constraint_count();
        (self.scheme.stages(), m, h, self.state.t_state - h)
    }

    /// The multipliers `ŵ_j` of control point `j ≤ s − 2` of the step just solved.
    fn multipliers(&self, j: usize) -> Vec<f64> {
        let (lay, z) = (self.backend.layout(), self.backend.z());
        (0..self.model.constraint_count())
            .map(|r| z[lay.multiplier(j, r)])
            .collect()
    }

    /// The constraint terms of the step just solved and committed (see the module docs),
    /// at its control points, multipliers and projected end.
    pub(super) fn constraint_terms(&self, theta: &[f64]) -> Result<ConstraintTerms, StepFailure> {
        let (model, backend, sch) = (self.model, &self.backend, self.scheme);
        let (s, m, h, t0) = self.solved_step();
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
        let (t1, q1) = (self.state.t_state, x_at(s - 1));
        // The projected end velocity, `L_v(q₁, v₁) = p₁` (the state's is the step
        // polynomial's slope, a guess).
        let p1 = SVector::<f64, N>::from_column_slice(&self.state.p.sum);
        let guess = SVector::<f64, N>::from_column_slice(&self.state.v);
        let v1 = crate::initial::solve_velocity(model, &q1, &p1, guess, self.k, t1)
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
        let mut params = Vec::with_capacity(theta.len());
        for p in 0..theta.len() {
            params.push(self.parameter_terms(theta, p, (&mu, v1.as_slice()))?);
        }
        Ok(ConstraintTerms {
            m,
            g,
            k,
            c1k,
            kmu,
            rate,
            kkt,
            params,
        })
    }

    /// The terms of parameter `p` (see [`ConstraintTerms::params`]), with the end impulse
    /// `mu` and velocity `v1`.
    fn parameter_terms(
        &self,
        theta: &[f64],
        p: usize,
        (mu, v1): (&[f64], &[f64]),
    ) -> Result<ParameterTerms, StepFailure> {
        let (model, backend, sch) = (self.model, &self.backend, self.scheme);
        let (s, m, h, t0) = self.solved_step();
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
        let (t1, q1) = (self.state.t_state, backend.node_x(s - 1));
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
    for c in 0..tg.columns(n) {
        let col = c * 2 * n;
        let p = c.checked_sub(2 * n);
        let pt = p.and_then(|p| ct.params.get(p));
        let dq = DVector::from_column_slice(&tg.m[col..col + n]);
        tg.dx[..n].copy_from_slice(dq.as_slice());
        tg.dx[n..].fill(0.0);
        let param = p.map(|p| (&tg.pnode[..], p, np));
        linearized_gradients(backend, h, &tg.dx, param, &mut tg.g, &mut tg.node);
        // The constraint forces of the control points `j ≤ s − 2` moved by `dq` (and `dθ`).
        for (j, (kj, bj)) in ct.k.iter().zip(&b).enumerate() {
            let mut f = kj * &dq;
            if let Some(pt) = pt {
                f += &pt.force[j];
            }
            let w = bj / h;
            for (g, fa) in tg.g[j * n..(j + 1) * n].iter_mut().zip(f.iter()) {
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
            let mut r = &ct.g[j] * &dq;
            if let Some(pt) = pt {
                r += &pt.rows[j - 1];
            }
            for k in 0..m {
                tg.rhs[lay.multiplier(j - 1, k)] = -r[k];
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
        let dq1 = DVector::from_fn(n, |a, _| dq[a] + tg.dx[(s - 1) * n + a]);
        let dpt = DVector::from_column_slice(&tg.g[(s - 1) * n..s * n]);
        let mut top = &dpt - &ct.c1k * &dq1;
        let mut bottom = -(&ct.rate * &dq1);
        if let Some(pt) = pt {
            top -= &pt.end_lv;
            bottom -= &pt.end_rate;
        }
        end.rows_mut(0, n).copy_from(&top);
        end.rows_mut(n, m).copy_from(&bottom);
        let solved = ct.kkt.solve_mut(&mut end);
        let dmu = end.rows(n, m);
        let mut dp1 = dpt - ct.g[s - 1].transpose() * dmu - &ct.kmu * &dq1;
        if let Some(pt) = pt {
            dp1 -= &pt.end_force;
        }
        for a in 0..n {
            tg.m[col + a] += tg.dx[(s - 1) * n + a];
            tg.m[col + n + a] = if solved { dp1[a] } else { f64::NAN };
        }
    }
}
