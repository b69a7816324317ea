//! The non-variational solvers a user would pick instead, run on the same models.
//!
//! A forced Lagrangian system is handed to a general ODE solver in first-order form. The forced
//! Euler–Lagrange equation `d/dt L_v = L_q + F` expands to `E v' + C v = L_q + F` with the mass
//! matrix `E = ∂L_v/∂v` and `C = ∂L_v/∂q`, so with `y = (q, v)`
//!
//! ```text
//! q' = v,    v' = E⁻¹ (L_q + F − C v).
//! ```
//!
//! [`OdeSystem`] builds this right-hand side from the model's node kernels
//! ([`ForcedLagrangian::node_gradient`], [`ForcedLagrangian::node_jacobian`]), the same exact
//! derivatives the variational integrator uses. When the model promises a constant mass
//! matrix ([`forced_vi::Structure::constant_mass`]) `E` is factored once and only the gradient
//! kernel is evaluated. With [`OdeSystem::with_work`] the state gains a last component, the
//! work `W' = F · v` of the force, so that the energy balance `E(t) − E(0) − W(t)` can be
//! measured the same way as for the variational schemes.
//!
//! Solvers ([`Baseline`]): `dop853` (ode_solvers' Dormand–Prince 8(5,3), explicit), `tsit45`
//! (diffsol's Tsitouras 5(4), explicit), `bdf` (diffsol's variable-order BDF, implicit) and
//! `esdirk34` (diffsol's ESDIRK 3(4), implicit). All are adaptive with `rtol = atol = tol`.
//! The implicit ones get the Jacobian of the first-order system by forward differences of
//! the right-hand side (one extra evaluation per column), as a user without a hand-written
//! Jacobian would.

use std::fmt;
use std::str::FromStr;

use forced_vi::newton::solve_small;
use forced_vi::ForcedLagrangian;
use nalgebra::{SMatrix, SVector};

/// A baseline ODE solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Baseline {
    /// ode_solvers `Dop853` (explicit Runge–Kutta of order 8), sparse output.
    Dop853,
    /// diffsol `tsit45` (explicit Runge–Kutta of order 5 with an embedded order-4 estimate).
    Tsit45,
    /// diffsol `bdf` (variable order 1–5, implicit, for stiff problems).
    Bdf,
    /// diffsol `esdirk34` (singly diagonally implicit Runge–Kutta of order 3).
    Esdirk34,
}

impl Baseline {
    /// Every baseline, in report order.
    pub const ALL: [Baseline; 4] = [
        Baseline::Dop853,
        Baseline::Tsit45,
        Baseline::Bdf,
        Baseline::Esdirk34,
    ];

    /// The name used on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Dop853 => "dop853",
            Baseline::Tsit45 => "tsit45",
            Baseline::Bdf => "bdf",
            Baseline::Esdirk34 => "esdirk34",
        }
    }

    /// One line for the report: the library and the kind of method.
    pub fn description(self) -> &'static str {
        match self {
            Baseline::Dop853 => "ode_solvers Dop853: explicit Runge–Kutta, order 8",
            Baseline::Tsit45 => "diffsol Tsit45: explicit Runge–Kutta, order 5",
            Baseline::Bdf => "diffsol BDF: implicit multistep, orders 1–5 (stiff solver)",
            Baseline::Esdirk34 => "diffsol ESDIRK34: implicit Runge–Kutta, order 3 (stiff solver)",
        }
    }

    /// Whether the method solves nonlinear systems (and reports Newton iterations).
    pub fn is_implicit(self) -> bool {
        matches!(self, Baseline::Bdf | Baseline::Esdirk34)
    }
}

impl fmt::Display for Baseline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Baseline {
    type Err = BaselineError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Baseline::ALL
            .into_iter()
            .find(|b| b.name() == s.trim())
            .ok_or_else(|| BaselineError::Unknown(s.trim().to_string()))
    }
}

/// Why a baseline run did not produce a result.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BaselineError {
    /// The name is not one of [`Baseline::ALL`].
    #[error("unknown baseline `{0}` (expected dop853, tsit45, bdf or esdirk34)")]
    Unknown(String),
    /// The tolerance is not a positive finite number.
    #[error("tolerance {0} must be positive and finite")]
    InvalidTolerance(f64),
    /// The solver library reported an error.
    #[error("{solver} failed: {message}")]
    Solver {
        /// The baseline.
        solver: &'static str,
        /// The library's message.
        message: String,
    },
    /// The solver returned NaN or infinity.
    #[error("{solver} produced a non-finite state at t = {t}")]
    NonFinite {
        /// The baseline.
        solver: &'static str,
        /// The time of the bad state.
        t: f64,
    },
}

/// `∂L_v/∂t` at `(t, q, v)`: zero for an autonomous model, else exact, by a hyper-dual
/// number over `t` and `v`.
fn lagrangian_v_dt<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    t: f64,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> SVector<f64, N> {
    use num_dual::{partial_hessian, HyperDualSVec64};
    if !M::STRUCTURE.uses_time {
        return SVector::zeros();
    }
    let qa: [f64; N] = (*q).into();
    let (_, _, _, h) = partial_hessian(
        |(tt, vv): (
            SVector<HyperDualSVec64<1, N>, 1>,
            SVector<HyperDualSVec64<1, N>, N>,
        )| {
            let va: [HyperDualSVec64<1, N>; N] = vv.into();
            model.lagrangian_at(tt[0], &forced_vi::lift(&qa), &va)
        },
        (&SVector::from([t]), v),
    );
    h.transpose().column(0).into_owned()
}

/// The first-order form `y' = f(y)` of a forced Lagrangian system (see the module docs).
#[derive(Clone, Debug)]
pub struct OdeSystem<'m, M, const N: usize> {
    model: &'m M,
    /// `E⁻¹` when the model promises a constant mass matrix.
    mass_inverse: Option<SMatrix<f64, N, N>>,
    with_work: bool,
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> OdeSystem<'m, M, N> {
    /// The system for `model`; `q0`, `v0` give the point where a constant mass matrix is
    /// evaluated (any point would do).
    pub fn new(model: &'m M, q0: &[f64; N], v0: &[f64; N]) -> Self {
        let mass_inverse = if M::STRUCTURE.constant_mass {
            let e = model.mass_matrix(&SVector::from(*q0), &SVector::from(*v0));
            let mut inv = SMatrix::<f64, N, N>::zeros();
            let mut ok = true;
            for k in 0..N {
                match solve_small(&e, &SVector::from_fn(|i, _| f64::from(u8::from(i == k)))) {
                    Some((col, _)) => inv.set_column(k, &col),
                    None => ok = false,
                }
            }
            ok.then_some(inv)
        } else {
            None
        };
        OdeSystem {
            model,
            mass_inverse,
            with_work: false,
        }
    }

    /// Adds the work of the force as a last state component, `W' = F · v`, `W(0) = 0`.
    #[must_use]
    pub fn with_work(mut self) -> Self {
        self.with_work = true;
        self
    }

    /// The state dimension: `2N`, plus one with the work component.
    pub fn dim(&self) -> usize {
        2 * N + usize::from(self.with_work)
    }

    /// The initial state `(q0, v0[, 0])`.
    pub fn initial_state(&self, q0: &[f64; N], v0: &[f64; N]) -> Vec<f64> {
        let mut y = Vec::with_capacity(self.dim());
        y.extend_from_slice(q0);
        y.extend_from_slice(v0);
        if self.with_work {
            y.push(0.0);
        }
        y
    }

    /// `dy = f(t, y)`. A singular mass matrix gives NaN, which the solvers reject.
    ///
    /// The accelerations solve `E a = L_q + F − C v − ∂L_v/∂t`; the last term is zero for an
    /// autonomous model. The work component is `W' = F · v − ∂L/∂t`, so that
    /// `E − E0 − W` is the energy balance of a driven model too (DESIGN §7).
    pub fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        let q = SVector::<f64, N>::from_fn(|i, _| y[i]);
        let v = SVector::<f64, N>::from_fn(|i, _| y[N + i]);
        let accel = match &self.mass_inverse {
            _ if self.model.constraint_count() > 0 => self.constrained_accel(t, &q, &v),
            Some(inv) if !M::STRUCTURE.uses_time => Some(inv * self.model.node_gradient(&q, &v).fq),
            _ => {
                let j = self.model.node_jacobian_at(t, &q, &v);
                let lv_t = lagrangian_v_dt(self.model, t, &q, &v);
                solve_small(&j.e, &(j.grad.fq - j.c * v - lv_t)).map(|(a, _)| a)
            }
        };
        let accel = accel.unwrap_or_else(|| SVector::repeat(f64::NAN));
        dy[..N].copy_from_slice(v.as_slice());
        dy[N..2 * N].copy_from_slice(accel.as_slice());
        if self.with_work {
            let f = SVector::from(self.model.force_at::<f64>(t, &q.into(), &v.into()));
            dy[2 * N] = f.dot(&v) - self.model.lagrangian_dt(t, &q, &v);
        }
    }

    /// The accelerations of a constrained model in index-1 form (DESIGN §11): `E a + Gᵀλ =
    /// L_q + F − C v − ∂L_v/∂t` with `G a = −d²g/dt²|_{a = 0}`, the second derivative of
    /// `g(t + ε, q + ε v)` in `ε` (one second-order dual number). The constraints then hold
    /// only to the solver's tolerance, drifting slowly (no projection).
    fn constrained_accel(
        &self,
        t: f64,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> Option<SVector<f64, N>> {
        use num_dual::Dual2_64;
        let m = self.model.constraint_count();
        let j = self.model.node_jacobian_at(t, q, v);
        let lv_t = lagrangian_v_dt(self.model, t, q, v);
        let mut g = vec![0.0; m];
        let mut gq = nalgebra::DMatrix::zeros(m, N);
        forced_vi::model::general::constraint_jacobian_at(self.model, t, q, &mut g, &mut gq);
        let qd: [Dual2_64; N] = std::array::from_fn(|a| Dual2_64::new(q[a], v[a], 0.0));
        let mut w = vec![Dual2_64::from(0.0); m];
        self.model
            .constraints(Dual2_64::new(t, 1.0, 0.0), &qd, &mut w);
        let n = N + m;
        let mut k = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut rhs = nalgebra::DVector::<f64>::zeros(n);
        let f = j.grad.fq - j.c * v - lv_t;
        for a in 0..N {
            rhs[a] = f[a];
            for b in 0..N {
                k[(a, b)] = j.e[(a, b)];
            }
            for r in 0..m {
                k[(a, N + r)] = gq[(r, a)];
                k[(N + r, a)] = gq[(r, a)];
            }
        }
        for r in 0..m {
            // `v2` of num-dual's second-order dual is the second derivative itself.
            rhs[N + r] = -w[r].v2;
        }
        let sol = k.lu().solve(&rhs)?;
        Some(SVector::from_fn(|a, _| sol[a]))
    }

    /// `out = J(t, y) w` by a forward difference of [`rhs`](Self::rhs).
    pub fn jacobian_times(&self, t: f64, y: &[f64], w: &[f64], out: &mut [f64]) {
        let wmax = w.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if wmax == 0.0 {
            out.fill(0.0);
            return;
        }
        let ymax = y.iter().fold(1.0f64, |m, x| m.max(x.abs()));
        let delta = f64::EPSILON.sqrt() * ymax / wmax;
        let shifted: Vec<f64> = y.iter().zip(w).map(|(a, b)| a + delta * b).collect();
        let mut f0 = vec![0.0; y.len()];
        self.rhs(t, y, &mut f0);
        self.rhs(t, &shifted, out);
        for (o, f) in out.iter_mut().zip(&f0) {
            *o = (*o - f) / delta;
        }
    }

    /// The momentum `p = L_v(t, q, v)` and energy `E = v · L_v − L` of a state `y` at `t`.
    pub fn momentum_energy(&self, t: f64, y: &[f64]) -> (SVector<f64, N>, f64) {
        let q = SVector::<f64, N>::from_fn(|i, _| y[i]);
        let v = SVector::<f64, N>::from_fn(|i, _| y[N + i]);
        let p = self.model.node_gradient_at(t, &q, &v).lv;
        let l = self.model.lagrangian_at::<f64>(t, &q.into(), &v.into());
        (p, v.dot(&p) - l)
    }
}

/// The end of a baseline run and its statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct BaselineRun {
    /// The final time reached.
    pub t: f64,
    /// The final state.
    pub y: Vec<f64>,
    /// Accepted steps.
    pub steps: usize,
    /// Nonlinear (Newton) iterations; 0 for explicit solvers.
    pub newton_iterations: usize,
}

/// Integrates `system` from `y0` at `t = 0` to `t_final` with `solver` at `rtol = atol = tol`.
///
/// `on_step(t, y)` sees every accepted step, the initial state first and the final state
/// last (`ode_solvers` reports its steps after the run, diffsol while it runs).
pub fn solve<M, const N: usize>(
    system: &OdeSystem<'_, M, N>,
    solver: Baseline,
    tol: f64,
    y0: &[f64],
    t_final: f64,
    mut on_step: impl FnMut(f64, &[f64]),
) -> Result<BaselineRun, BaselineError>
where
    M: ForcedLagrangian<N>,
{
    if !(tol.is_finite() && tol > 0.0) {
        return Err(BaselineError::InvalidTolerance(tol));
    }
    let run = match solver {
        // ode_solvers' DOP853 (0.6) evaluates its stages 12 and 13 at c = 0 instead of c = 1
        // (srenevey/ode-solvers, pull request 42): invisible on autonomous systems, it stops
        // the method from converging on time-dependent ones (measured on the driven Duffing
        // scene: 1.9e-3 at tol 1e-10). So a time-dependent model is given to it in
        // autonomous form, with `t` as one more state, `t' = 1`.
        Baseline::Dop853 => dop853(
            system,
            M::STRUCTURE.uses_time,
            tol,
            y0,
            t_final,
            &mut on_step,
        )?,
        _ => diffsol_run(system, system.dim(), solver, tol, y0, t_final, &mut on_step)?,
    };
    if run.y.iter().all(|x| x.is_finite()) {
        Ok(run)
    } else {
        Err(BaselineError::NonFinite {
            solver: solver.name(),
            t: run.t,
        })
    }
}

/// `y' = f(t, y)` with the model's type erased: the solvers' code below is compiled once, not
/// once per model (it was about a quarter of this crate's machine code).
trait Rhs {
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]);
    fn jacobian_times(&self, t: f64, y: &[f64], w: &[f64], out: &mut [f64]);
}

impl<M: ForcedLagrangian<N>, const N: usize> Rhs for OdeSystem<'_, M, N> {
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        OdeSystem::rhs(self, t, y, dy)
    }
    fn jacobian_times(&self, t: f64, y: &[f64], w: &[f64], out: &mut [f64]) {
        OdeSystem::jacobian_times(self, t, y, w, out)
    }
}

/// A reported step: `(t, y)`.
type OnStep<'a> = &'a mut dyn FnMut(f64, &[f64]);

/// ode_solvers' `System` for an [`OdeSystem`]; in autonomous form (`.1`), the last state
/// is the time, with `t' = 1`.
struct Dop853System<'a>(&'a dyn Rhs, bool);

impl ode_solvers::System<f64, ode_solvers::DVector<f64>> for Dop853System<'_> {
    fn system(&self, t: f64, y: &ode_solvers::DVector<f64>, dy: &mut ode_solvers::DVector<f64>) {
        let (y, dy) = (y.as_slice(), dy.as_mut_slice());
        if self.1 {
            let n = y.len() - 1;
            self.0.rhs(y[n], &y[..n], &mut dy[..n]);
            dy[n] = 1.0;
        } else {
            self.0.rhs(t, y, dy);
        }
    }
}

fn dop853(
    system: &dyn Rhs,
    autonomous_form: bool,
    tol: f64,
    y0: &[f64],
    t_final: f64,
    on_step: OnStep<'_>,
) -> Result<BaselineRun, BaselineError> {
    let fail = |message: String| BaselineError::Solver {
        solver: "dop853",
        message,
    };
    // Defaults of `Dop853::new` except the step cap (10⁵ is too few for long runs) and the
    // output type: sparse output reports the accepted steps themselves. (Dense output with an
    // output step of `t_final` returns a wrong final state in ode_solvers 0.6.)
    let mut init = y0.to_vec();
    if autonomous_form {
        init.push(0.0);
    }
    let n = y0.len();
    let mut stepper = ode_solvers::Dop853::from_param(
        Dop853System(system, autonomous_form),
        0.0,
        t_final,
        t_final,
        ode_solvers::DVector::from_vec(init),
        tol,
        tol,
        0.9,
        0.0,
        0.333,
        6.0,
        t_final,
        0.0,
        u32::MAX,
        1000,
        ode_solvers::OutputType::Sparse,
    );
    let stats = stepper.integrate().map_err(|e| fail(e.to_string()))?;
    let (ts, ys) = stepper.results().get();
    for (t, y) in ts.iter().zip(ys) {
        on_step(*t, &y.as_slice()[..n]);
    }
    let (t, y) = ts
        .last()
        .zip(ys.last())
        .ok_or_else(|| fail("no output".to_string()))?;
    if (t - t_final).abs() > 1e-12 * t_final.abs().max(1.0) {
        return Err(fail(format!("stopped at t = {t} before {t_final}")));
    }
    Ok(BaselineRun {
        t: *t,
        y: y.as_slice()[..n].to_vec(),
        steps: stats.accepted_steps as usize,
        newton_iterations: 0,
    })
}

fn diffsol_run(
    system: &dyn Rhs,
    n: usize,
    solver: Baseline,
    tol: f64,
    y0: &[f64],
    t_final: f64,
    on_step: OnStep<'_>,
) -> Result<BaselineRun, BaselineError> {
    use diffsol::{NalgebraLU, NalgebraMat, OdeBuilder};
    type Lu = NalgebraLU<f64>;
    let fail = |message: String| BaselineError::Solver {
        solver: solver.name(),
        message,
    };
    let init = y0.to_vec();
    let problem = OdeBuilder::<NalgebraMat<f64>>::new()
        .rtol(tol)
        .atol([tol])
        .rhs_implicit(
            |y: &[f64], _p: &[f64], t: f64, dy: &mut [f64]| system.rhs(t, y, dy),
            |y: &[f64], _p: &[f64], t: f64, w: &[f64], out: &mut [f64]| {
                system.jacobian_times(t, y, w, out)
            },
        )
        .init(
            move |_p: &[f64], _t: f64, y: &mut [f64]| y.copy_from_slice(&init),
            n,
        )
        .build()
        .map_err(|e| fail(e.to_string()))?;
    match solver {
        Baseline::Tsit45 => {
            let mut s = problem.tsit45().map_err(|e| fail(e.to_string()))?;
            drive(&mut s, t_final, on_step).map_err(fail)
        }
        Baseline::Bdf => {
            let mut s = problem.bdf::<Lu>().map_err(|e| fail(e.to_string()))?;
            drive(&mut s, t_final, on_step).map_err(fail)
        }
        Baseline::Esdirk34 => {
            let mut s = problem.esdirk34::<Lu>().map_err(|e| fail(e.to_string()))?;
            drive(&mut s, t_final, on_step).map_err(fail)
        }
        Baseline::Dop853 => Err(fail("not a diffsol solver".to_string())),
    }
}

/// Steps a diffsol solver to `t_final` exactly, reporting every accepted step.
fn drive<'a, Eqn, S>(s: &mut S, t_final: f64, on_step: OnStep<'_>) -> Result<BaselineRun, String>
where
    Eqn: diffsol::OdeEquations<T = f64, V = diffsol::NalgebraVec<f64>> + 'a,
    S: diffsol::OdeSolverMethod<'a, Eqn>,
{
    use diffsol::{OdeSolverStopReason, VectorCommon};
    {
        let st = s.state();
        on_step(st.t, st.y.inner().as_slice());
    }
    s.set_stop_time(t_final).map_err(|e| e.to_string())?;
    loop {
        let reason = s.step().map_err(|e| e.to_string())?;
        let st = s.state();
        on_step(st.t, st.y.inner().as_slice());
        if !st.y.inner().as_slice().iter().all(|x| x.is_finite()) {
            return Err(format!("non-finite state at t = {}", st.t));
        }
        if matches!(reason, OdeSolverStopReason::TstopReached) {
            break;
        }
    }
    let stats = s.get_statistics();
    let st = s.state();
    Ok(BaselineRun {
        t: st.t,
        y: st.y.inner().as_slice().to_vec(),
        steps: stats.number_of_steps,
        newton_iterations: stats.number_of_nonlinear_solver_iterations,
    })
}
