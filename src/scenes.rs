//! Report scenes: a model with its parameters, initial data, final time and reference.
//!
//! A scene is one registration line in [`all`]: a name, a model value (its fields are the
//! parameters) and a one-line summary. The initial data and the final time come from the
//! scene's reference file `data/reference/<name>.csv` (written by `scripts/reference.py` and
//! embedded with `include_str!`): its `t = 0` rows give `(q₀, v₀)` of each member and its last
//! row per member gives the final time and the reference state. Scene and reference therefore
//! cannot disagree about where a run starts or ends; the model's parameters must match the
//! script's, which the report's own convergence tables check (a mismatch shows as errors that
//! stop shrinking).
//!
//! To add a scene: add the model (in [`crate::models`]), add it to `scripts/reference.py` and
//! regenerate the references, then add one `scene!(...)` line to [`all`].

use forced_vi::{output, ForcedLagrangian, InitialState, Integrator, Scheme};
use nalgebra::DMatrix;

use crate::baselines::{self, Baseline, BaselineError, OdeSystem};
use crate::models::{
    CartesianPendulum, CoupledVanDerPol, DampedOscillator, DoublePendulumFriction, DrivenDuffing,
    KapitzaPendulum, KeplerDrag,
};
use crate::reference::Reference;
use crate::report::timing;

/// The reference state of one member at the final time.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalState {
    /// Positions.
    pub q: Vec<f64>,
    /// Momenta `L_v`.
    pub p: Vec<f64>,
    /// Energy `v · L_v − L`.
    pub energy: f64,
}

/// The end of one run and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// Final state.
    pub end: FinalState,
    /// Steps taken (accepted steps for adaptive baselines).
    pub steps: usize,
    /// Newton iterations (0 for explicit baselines).
    pub newton_iterations: usize,
}

/// The energy-balance error `E(t) − E(0) − W(t)` sampled along one long run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BalanceSeries {
    /// Sample times (step times of the method, about evenly spread).
    pub t: Vec<f64>,
    /// The energy-balance error at those times.
    pub balance: Vec<f64>,
    /// Steps taken.
    pub steps: usize,
    /// Newton iterations.
    pub newton_iterations: usize,
}

/// Why a scene could not be built or run.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The embedded reference file does not fit the scene.
    #[error("scene `{scene}`: bad reference data: {message}")]
    Reference {
        /// The scene.
        scene: &'static str,
        /// What is wrong.
        message: String,
    },
    /// There is no such ensemble member.
    #[error("scene `{scene}` has no member {member}")]
    NoSuchMember {
        /// The scene.
        scene: &'static str,
        /// The requested member.
        member: usize,
    },
    /// The variational integrator stopped.
    #[error(transparent)]
    Variational(#[from] forced_vi::Error),
    /// A baseline solver failed.
    #[error(transparent)]
    Baseline(#[from] BaselineError),
}

/// A runnable scene, with its model type and size erased.
pub trait Scene: Send + Sync {
    /// The scene's name (`--scene` filter, file names, CSV rows).
    fn name(&self) -> &'static str;
    /// The model and its parameters in one line.
    fn summary(&self) -> &'static str;
    /// Degrees of freedom.
    fn dof(&self) -> usize;
    /// Ensemble members (1 for a single trajectory).
    fn members(&self) -> usize;
    /// Final time.
    fn t_final(&self) -> f64;
    /// Initial positions and velocities of a member.
    fn initial(&self, member: usize) -> Option<(Vec<f64>, Vec<f64>)>;
    /// The reference state of a member at the final time.
    fn reference(&self, member: usize) -> Option<&FinalState>;
    /// Runs a variational scheme with step `h` to the final time (no step subdivision).
    fn run_variational(
        &self,
        scheme: &Scheme,
        h: f64,
        member: usize,
    ) -> Result<Outcome, SceneError>;
    /// Runs a variational scheme adaptively at `rtol = atol = tol` to the final time, from
    /// the automatic first step ([`Integrator::adaptive`]).
    fn run_adaptive(&self, scheme: &Scheme, tol: f64, member: usize)
        -> Result<Outcome, SceneError>;
    /// The same with the error estimated over pairs of steps or not, as `paired` says
    /// ([`Integrator::paired_estimates`]; by default a run takes them on the dense path).
    fn run_adaptive_pairs(
        &self,
        scheme: &Scheme,
        tol: f64,
        member: usize,
        paired: bool,
    ) -> Result<Outcome, SceneError>;
    /// Runs a variational scheme on every member to the final time (fixed steps of `x`, or
    /// adaptive at `rtol = atol = x` as [`Scene::run_adaptive`]), as an ensemble is run
    /// with the library: [`Integrator::ensemble`], the members in parallel, each worker
    /// restarting one stepper member to member. Outcomes in the members' order; the first
    /// member's error if any fails. By default, member by member.
    fn run_variational_members(
        &self,
        scheme: &Scheme,
        x: f64,
        adaptive: bool,
    ) -> Result<Vec<Outcome>, SceneError> {
        (0..self.members())
            .map(|m| match adaptive {
                true => self.run_adaptive(scheme, x, m),
                false => self.run_variational(scheme, x, m),
            })
            .collect()
    }
    /// Times a variational run of member 0 to the final time (`adaptive`: at
    /// `rtol = atol = h_or_tol` from the automatic first step; else fixed steps of
    /// `h_or_tol`) two ways, alternating over `rounds`: with a new integrator and stepper
    /// each run (as the sweeps time it), and restarted on one stepper
    /// ([`Integrator::runs`]), as an integrator built once is timed. Their medians in
    /// seconds, new first; an error if the two give different final states.
    fn time_restarted(
        &self,
        scheme: &Scheme,
        adaptive: bool,
        h_or_tol: f64,
        rounds: usize,
    ) -> Result<(f64, f64), SceneError>;
    /// Runs a baseline at tolerance `tol` to the final time.
    fn run_baseline(
        &self,
        solver: Baseline,
        tol: f64,
        member: usize,
    ) -> Result<Outcome, SceneError>;
    /// How much the flow amplifies an error made along a run of member 0: the mean over
    /// `points` times `t ∈ (0, T)` of `‖Φ_q(T, t)‖∞`, the rows in `q_T` of the tangent map
    /// from `(q, p)` at `t` to `(q, p)` at `T` (max row sum). Local errors of size `δ` per
    /// unit step add up to a final error of about `δ` times this. From
    /// [`forced_vi::output::Tangents`] (lobatto4, `steps` steps over the run).
    fn amplification(&self, points: usize, steps: usize) -> Result<f64, SceneError>;
    /// How much of its error budget an adaptive run of member 0 at `rtol = atol = tol`
    /// spends: the sum over its accepted steps of their estimated local errors
    /// ([`forced_vi::StepRecord::error_estimate`], in units of the tolerance), the mean of
    /// the estimates per unit step weighted by the steps' lengths. The controller keeps
    /// each step's share at most `h / T`, so the sum at most 1, and steers it to its steady
    /// error (0.25 and above).
    fn budget_spent(&self, scheme: &Scheme, tol: f64) -> Result<f64, SceneError>;
    /// The energy-balance error of member 0 along a run to `t_final`, about `samples` points.
    fn balance_variational(
        &self,
        scheme: &Scheme,
        h: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError>;
    /// The same with adaptive steps at `rtol = atol = tol` (first step `t_final`, as
    /// [`Scene::run_adaptive`]).
    fn balance_adaptive(
        &self,
        scheme: &Scheme,
        tol: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError>;
    /// The same for a baseline, whose work integral is an extra ODE component.
    fn balance_baseline(
        &self,
        solver: Baseline,
        tol: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError>;
}

/// A scene built from a model with `N` degrees of freedom and its reference file.
#[derive(Clone, Debug)]
pub struct ModelScene<M, const N: usize> {
    name: &'static str,
    summary: &'static str,
    model: M,
    t_final: f64,
    initial: Vec<([f64; N], [f64; N])>,
    reference: Vec<FinalState>,
}

impl<M: ForcedLagrangian<N>, const N: usize> ModelScene<M, N> {
    /// Builds a scene from the CSV text of its reference file (see the module docs).
    pub fn from_reference(
        name: &'static str,
        summary: &'static str,
        model: M,
        csv: &str,
    ) -> Result<Self, SceneError> {
        let bad = |message: String| SceneError::Reference {
            scene: name,
            message,
        };
        let parsed = Reference::parse(csv).map_err(|e| bad(e.to_string()))?;
        if parsed.dim != N {
            return Err(bad(format!(
                "{} coordinates, the model has {N}",
                parsed.dim
            )));
        }
        let mut initial = Vec::new();
        let mut reference = Vec::new();
        let mut t_final = None;
        for member in 0..parsed.members() {
            let start = parsed
                .initial(member)
                .ok_or_else(|| bad(format!("member {member} has no t = 0 row")))?;
            let end = parsed
                .points
                .iter()
                .filter(|p| p.member == member)
                .max_by(|a, b| a.t.total_cmp(&b.t))
                .ok_or_else(|| bad(format!("member {member} has no rows")))?;
            if end.t.is_nan() || end.t <= 0.0 {
                return Err(bad(format!("member {member} has no row with t > 0")));
            }
            match t_final {
                None => t_final = Some(end.t),
                Some(t) if t != end.t => {
                    return Err(bad(format!("members end at {t} and {}", end.t)));
                }
                Some(_) => {}
            }
            let arr = |x: &[f64]| -> [f64; N] { std::array::from_fn(|i| x[i]) };
            initial.push((arr(&start.q), arr(&start.v)));
            reference.push(FinalState {
                q: end.q.clone(),
                p: end.p.clone(),
                energy: end.energy,
            });
        }
        let t_final = t_final.ok_or_else(|| bad("no members".to_string()))?;
        Ok(ModelScene {
            name,
            summary,
            model,
            t_final,
            initial,
            reference,
        })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    fn start(&self, member: usize) -> Result<([f64; N], [f64; N]), SceneError> {
        self.initial
            .get(member)
            .copied()
            .ok_or(SceneError::NoSuchMember {
                scene: self.name,
                member,
            })
    }
}

/// Indices of about `samples` evenly spread points: keeps a step when its time reaches the next
/// sample time.
#[derive(Clone, Debug)]
pub struct Sampler {
    next: f64,
    dt: f64,
}

impl Sampler {
    /// About `samples` points over `[0, t_final]`.
    pub fn new(t_final: f64, samples: usize) -> Self {
        Sampler {
            next: 0.0,
            dt: t_final / samples.max(1) as f64,
        }
    }
    /// Whether to keep the point at time `t` (times must not decrease).
    pub fn take(&mut self, t: f64) -> bool {
        if t >= self.next {
            while self.next <= t {
                self.next += self.dt;
            }
            true
        } else {
            false
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> ModelScene<M, N> {
    /// Runs `integ` on a member to its final state alone (`Integrator::final_state`: no
    /// per-step records or diagnostics, as a baseline run returns its final state alone).
    fn run_with(&self, integ: Integrator<'_, M, N>, member: usize) -> Result<Outcome, SceneError> {
        let (q0, v0) = self.start(member)?;
        let end = integ
            .final_state(InitialState::from_velocity(q0, v0), self.t_final)
            .map_err(|f| f.error)?;
        Ok(Outcome {
            end: FinalState {
                q: end.q.as_slice().to_vec(),
                p: end.p.as_slice().to_vec(),
                energy: end.energy,
            },
            steps: end.stats.steps,
            newton_iterations: end.stats.newton_iterations,
        })
    }
}

impl<M, const N: usize> Scene for ModelScene<M, N>
where
    M: ForcedLagrangian<N> + Send + Sync,
{
    fn name(&self) -> &'static str {
        self.name
    }
    fn summary(&self) -> &'static str {
        self.summary
    }
    fn dof(&self) -> usize {
        N
    }
    fn members(&self) -> usize {
        self.initial.len()
    }
    fn t_final(&self) -> f64 {
        self.t_final
    }
    fn initial(&self, member: usize) -> Option<(Vec<f64>, Vec<f64>)> {
        self.initial
            .get(member)
            .map(|(q, v)| (q.to_vec(), v.to_vec()))
    }
    fn reference(&self, member: usize) -> Option<&FinalState> {
        self.reference.get(member)
    }

    fn run_variational(
        &self,
        scheme: &Scheme,
        h: f64,
        member: usize,
    ) -> Result<Outcome, SceneError> {
        self.run_with(Integrator::new(&self.model, scheme.clone(), h)?, member)
    }

    fn run_adaptive(
        &self,
        scheme: &Scheme,
        tol: f64,
        member: usize,
    ) -> Result<Outcome, SceneError> {
        let integ = Integrator::adaptive(&self.model, scheme.clone(), tol, tol)?;
        self.run_with(integ, member)
    }

    fn run_adaptive_pairs(
        &self,
        scheme: &Scheme,
        tol: f64,
        member: usize,
        paired: bool,
    ) -> Result<Outcome, SceneError> {
        let integ = Integrator::adaptive(&self.model, scheme.clone(), tol, tol)?;
        self.run_with(integ.paired_estimates(paired), member)
    }

    fn run_variational_members(
        &self,
        scheme: &Scheme,
        x: f64,
        adaptive: bool,
    ) -> Result<Vec<Outcome>, SceneError> {
        let integ = match adaptive {
            true => Integrator::adaptive(&self.model, scheme.clone(), x, x)?,
            false => Integrator::new(&self.model, scheme.clone(), x)?,
        };
        let members: Vec<InitialState<N>> = self
            .initial
            .iter()
            .map(|(q, v)| InitialState::from_velocity(*q, *v))
            .collect();
        integ
            .ensemble(&members, self.t_final, output::Final)
            .into_iter()
            .map(|end| {
                let end = end.map_err(|f| f.error)?;
                Ok(Outcome {
                    end: FinalState {
                        q: end.q.as_slice().to_vec(),
                        p: end.p.as_slice().to_vec(),
                        energy: end.energy,
                    },
                    steps: end.stats.steps,
                    newton_iterations: end.stats.newton_iterations,
                })
            })
            .collect()
    }
    fn time_restarted(
        &self,
        scheme: &Scheme,
        adaptive: bool,
        h_or_tol: f64,
        rounds: usize,
    ) -> Result<(f64, f64), SceneError> {
        let (q0, v0) = self.start(0)?;
        let init = InitialState::from_velocity(q0, v0);
        let build = || match adaptive {
            true => Integrator::adaptive(&self.model, scheme.clone(), h_or_tol, h_or_tol),
            false => Integrator::new(&self.model, scheme.clone(), h_or_tol),
        };
        let kept = build()?;
        let mut runs = kept.runs();
        let (mut new, mut restarted) = (Vec::new(), Vec::new());
        for round in 0..rounds.max(1) {
            // Which goes first alternates, so that a drift in the machine's load hits both.
            let fresh =
                || timing::timed(|| build().and_then(|i| Ok(i.final_state(init, self.t_final)?)));
            let mut again = || {
                timing::timed(|| {
                    runs.solve(init, self.t_final, output::Final)
                        .map_err(|f| f.error)
                })
            };
            let ((a, ta), (b, tb)) = if round % 2 == 0 {
                let a = fresh();
                (a, again())
            } else {
                let b = again();
                (fresh(), b)
            };
            let (a, b) = (a?, b?);
            if a.q != b.q || a.p != b.p {
                return Err(SceneError::Reference {
                    scene: self.name,
                    message: "a restarted run differs from a new one".into(),
                });
            }
            new.push(ta);
            restarted.push(tb);
        }
        Ok((timing::median(&mut new), timing::median(&mut restarted)))
    }
    fn budget_spent(&self, scheme: &Scheme, tol: f64) -> Result<f64, SceneError> {
        let (q0, v0) = self.start(0)?;
        let integ = Integrator::adaptive(&self.model, scheme.clone(), tol, tol)?;
        let mut sum = 0.0;
        integ
            .solve(
                InitialState::from_velocity(q0, v0),
                self.t_final,
                output::each_step(|r| sum += r.error_estimate),
            )
            .map_err(|f| f.error)?;
        Ok(sum)
    }
    fn amplification(&self, points: usize, steps: usize) -> Result<f64, SceneError> {
        // A constrained map's tangent is singular off the constraints (it takes every
        // direction onto them), so the inverse below does not exist: A would need a basis of
        // the constraints' tangent space. Not measured ("–" in the report).
        if self.model.constraint_count() > 0 {
            return Err(SceneError::Reference {
                scene: self.name,
                message: "the amplification of a constrained scene is not measured".into(),
            });
        }
        let (q0, v0) = self.start(0)?;
        let init = InitialState::from_velocity(q0, v0);
        let h = self.t_final / steps.max(1) as f64;
        let scheme = Scheme::lobatto(4).map_err(forced_vi::Error::from)?;
        let integ = Integrator::new(&self.model, scheme, h)?;
        // The (q, p) tangent M(t, 0) = P(t) S(t) P(0)⁻¹, with P = [[I, 0], [C, E]].
        let to_p = |t: f64, q: &[f64], v: &[f64]| {
            let j = self.model.node_jacobian_at(
                t,
                &nalgebra::SVector::from_column_slice(q),
                &nalgebra::SVector::from_column_slice(v),
            );
            let mut m = DMatrix::<f64>::identity(2 * N, 2 * N);
            for r in 0..N {
                for c in 0..N {
                    m[(N + r, c)] = j.c[(r, c)];
                    m[(N + r, N + c)] = j.e[(r, c)];
                }
            }
            m
        };
        let singular = || SceneError::Reference {
            scene: self.name,
            message: "a singular tangent map".into(),
        };
        let p0_inv = to_p(0.0, &q0, &v0).try_inverse().ok_or_else(singular)?;
        let tangent = |t: f64| -> Result<DMatrix<f64>, SceneError> {
            let s = integ
                .solve(init, t, output::Tangents)
                .map_err(|f| f.error)?;
            Ok(to_p(s.t, s.q.as_slice(), s.v.as_slice()) * s.wrt_initial * &p0_inv)
        };
        let end = tangent(self.t_final)?;
        let mut sum = 0.0;
        for j in 0..points {
            let t = self.t_final * (j as f64 + 0.5) / points as f64;
            let phi = &end * tangent(t)?.try_inverse().ok_or_else(singular)?;
            sum += (0..N)
                .map(|r| phi.row(r).iter().map(|x| x.abs()).sum::<f64>())
                .fold(0.0, f64::max);
        }
        Ok(sum / points as f64)
    }
    fn run_baseline(
        &self,
        solver: Baseline,
        tol: f64,
        member: usize,
    ) -> Result<Outcome, SceneError> {
        let (q0, v0) = self.start(member)?;
        let sys = OdeSystem::new(&self.model, &q0, &v0);
        let y0 = sys.initial_state(&q0, &v0);
        let run = baselines::solve(&sys, solver, tol, &y0, self.t_final, |_, _| {})?;
        let (p, energy) = sys.momentum_energy(run.t, &run.y);
        Ok(Outcome {
            end: FinalState {
                q: run.y[..N].to_vec(),
                p: p.as_slice().to_vec(),
                energy,
            },
            steps: run.steps,
            newton_iterations: run.newton_iterations,
        })
    }

    fn balance_variational(
        &self,
        scheme: &Scheme,
        h: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError> {
        let integ = Integrator::new(&self.model, scheme.clone(), h)?;
        self.balance_with(&integ, t_final, samples)
    }

    fn balance_adaptive(
        &self,
        scheme: &Scheme,
        tol: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError> {
        let integ = Integrator::new(&self.model, scheme.clone(), t_final)?.tolerances(tol, tol)?;
        self.balance_with(&integ, t_final, samples)
    }

    fn balance_baseline(
        &self,
        solver: Baseline,
        tol: f64,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError> {
        let (q0, v0) = self.start(0)?;
        let sys = OdeSystem::new(&self.model, &q0, &v0).with_work();
        let y0 = sys.initial_state(&q0, &v0);
        let (_, e0) = sys.momentum_energy(0.0, &y0);
        let mut out = BalanceSeries::default();
        let mut sampler = Sampler::new(t_final, samples);
        let balance = |t: f64, y: &[f64]| sys.momentum_energy(t, y).1 - e0 - y[2 * N];
        let run = baselines::solve(&sys, solver, tol, &y0, t_final, |t, y| {
            if sampler.take(t) {
                out.t.push(t);
                out.balance.push(balance(t, y));
            }
        })?;
        if out.t.last() != Some(&run.t) {
            out.t.push(run.t);
            out.balance.push(balance(run.t, &run.y));
        }
        out.steps = run.steps;
        out.newton_iterations = run.newton_iterations;
        Ok(out)
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> ModelScene<M, N> {
    /// The sampled energy-balance error of member 0 along one run of `integ`.
    fn balance_with(
        &self,
        integ: &Integrator<'_, M, N>,
        t_final: f64,
        samples: usize,
    ) -> Result<BalanceSeries, SceneError> {
        let (q0, v0) = self.start(0)?;
        let mut out = BalanceSeries::default();
        let mut sampler = Sampler::new(t_final, samples);
        let mut last = (0.0, 0.0);
        let stats = integ
            .solve(
                InitialState::from_velocity(q0, v0),
                t_final,
                output::each_step(|r| {
                    if sampler.take(r.t) {
                        out.t.push(r.t);
                        out.balance.push(r.energy_balance);
                    }
                    last = (r.t, r.energy_balance);
                }),
            )
            .map_err(|f| f.error)?;
        if out.t.last() != Some(&last.0) {
            out.t.push(last.0);
            out.balance.push(last.1);
        }
        out.steps = stats.steps;
        out.newton_iterations = stats.newton_iterations;
        Ok(out)
    }
}

/// Registers a scene: name (also its reference file's stem), model value, summary.
macro_rules! scene {
    ($name:literal, $model:expr, $summary:literal) => {
        ModelScene::from_reference(
            $name,
            $summary,
            $model,
            include_str!(concat!("../data/reference/", $name, ".csv")),
        )
        .map(|s| Box::new(s) as Box<dyn Scene>)
    };
}

/// Every registered scene, in report order.
pub fn all() -> Result<Vec<Box<dyn Scene>>, SceneError> {
    [
        scene!(
            "coupled_van_der_pol",
            CoupledVanDerPol::PAPER,
            "Two coupled van der Pol oscillators, (ε, ρ, λ) = (0.5, 0.02, 0.8): the paper's test"
        ),
        scene!(
            "coupled_van_der_pol_ensemble",
            CoupledVanDerPol::PAPER,
            "The paper's ensemble: 25 seeded initial positions uniform in [−4, 4]², v₀ = (0, 4)"
        ),
        scene!(
            "damped_oscillator",
            DampedOscillator::DEFAULT,
            "Linear oscillator with full mass, stiffness and damping matrices (exact solution)"
        ),
        scene!(
            "double_pendulum_friction",
            DoublePendulumFriction::DEFAULT,
            "Double pendulum with joint friction c = 0.05: angle-dependent mass matrix"
        ),
        scene!(
            "kepler_drag",
            KeplerDrag::DEFAULT,
            "Kepler orbit (μ = 1) with linear drag γ = 0.01: non-polynomial potential"
        ),
        scene!(
            "driven_duffing",
            DrivenDuffing::CHAOTIC,
            "Driven Duffing oscillator in its chaotic regime, (δ, α, β, γ, ω) = (0.3, −1, 1, 0.5, 1.2), 5 periods: F(t, x, ẋ)"
        ),
        scene!(
            "cartesian_pendulum",
            CartesianPendulum::DEFAULT,
            "Pendulum in Cartesian coordinates (x, y) held on its circle by the constraint x² + y² = l², air drag c = 0.3: holonomic constraints (DESIGN §11)"
        ),
        scene!(
            "kapitza_pendulum",
            KapitzaPendulum::UPRIGHT,
            "Kapitza's pendulum held upright by a vibrating pivot (a = 0.1, Ω = 50) with joint friction: L(t, θ, θ̇)"
        ),
    ]
    .into_iter()
    .collect()
}
