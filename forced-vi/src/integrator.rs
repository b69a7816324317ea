//! The stepping loop: one residual/Jacobian assembly shared by every scheme (DESIGN §3),
//! solved each step by the shared [`Newton`] solver.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::{Error, NewtonFailure};
use crate::model::{ForcedLagrangian, NodeGradient, NodeJacobian};
use crate::newton::{Newton, NewtonOptions, NonlinearSystem};
use crate::scheme::Scheme;

/// Initial data: `(q₀, v₀)` as in the paper, or `(q₀, p₀)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InitialState<const N: usize> {
    /// Position and velocity; the momentum is `p₀ = L_v(q₀, v₀)`.
    Velocity {
        /// `q₀`.
        q: [f64; N],
        /// `v₀`.
        v: [f64; N],
    },
    /// Position and momentum; the velocity solves `L_v(q₀, v₀) = p₀`.
    Momentum {
        /// `q₀`.
        q: [f64; N],
        /// `p₀`.
        p: [f64; N],
    },
}

impl<const N: usize> InitialState<N> {
    /// `(q₀, v₀)`.
    pub fn from_velocity(q: [f64; N], v: [f64; N]) -> Self {
        InitialState::Velocity { q, v }
    }
    /// `(q₀, p₀)`.
    pub fn from_momentum(q: [f64; N], p: [f64; N]) -> Self {
        InitialState::Momentum { q, p }
    }
}

/// The state after one step, with its diagnostics (DESIGN §4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRecord<const N: usize> {
    /// Step index; 0 is the initial state.
    pub step: usize,
    /// Time `t_k`.
    pub t: f64,
    /// Positions `q_k`.
    pub q: SVector<f64, N>,
    /// Momenta `p_k`.
    pub p: SVector<f64, N>,
    /// Velocities, solving `L_v(q_k, v_k) = p_k`.
    pub v: SVector<f64, N>,
    /// Energy `v · L_v − L`.
    pub energy: f64,
    /// Energy-balance error `E(t_k) − E(0) − W_k`, with `W_k` the work of the force summed with
    /// the scheme's own quadrature.
    pub energy_balance: f64,
    /// Newton iterations (linear solves) this step took, over all attempts.
    pub newton_iterations: usize,
    /// Max-norm of the final Newton residual.
    pub residual: f64,
    /// Substeps used: 1 normally, 2, 4, … when the step was subdivided to recover.
    pub substeps: usize,
}

/// Totals over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunStats {
    /// Steps completed.
    pub steps: usize,
    /// Newton iterations over all steps.
    pub newton_iterations: usize,
    /// Steps that needed subdivision.
    pub subdivided_steps: usize,
    /// Largest Newton iteration count of one step.
    pub max_newton_iterations: usize,
}

/// A finished run: every record, initial state first.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory<const N: usize> {
    /// The records, `records[0]` being the initial state.
    pub records: Vec<StepRecord<N>>,
    /// Totals.
    pub stats: RunStats,
}

impl<const N: usize> Trajectory<N> {
    /// The last record, if any.
    pub fn last(&self) -> Option<&StepRecord<N>> {
        self.records.last()
    }
}

/// A run that stopped early: the error and everything computed before it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{error} ({} records kept)", trajectory.records.len())]
pub struct RunFailure<const N: usize> {
    /// What stopped the run.
    #[source]
    pub error: Error,
    /// The records up to the failure.
    pub trajectory: Trajectory<N>,
}

/// A streamed run that stopped early: the error and the totals up to it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{error} (after {} steps)", stats.steps)]
pub struct StreamFailure {
    /// What stopped the run.
    #[source]
    pub error: Error,
    /// The totals up to the failure.
    pub stats: RunStats,
}

impl From<StreamFailure> for Error {
    fn from(f: StreamFailure) -> Error {
        f.error
    }
}

/// Options of the stepper. `Default`: default [`NewtonOptions`], no subdivision, at most
/// [`StepOptions::DEFAULT_MAX_STEPS`] steps.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct StepOptions {
    /// The Newton solver's options.
    pub newton: NewtonOptions,
    /// A failed step is retried as 2, 4, …, `2^max_subdivisions` substeps (default 0: off).
    pub max_subdivisions: u32,
    /// The most steps a run may take; a longer run is refused before it starts
    /// ([`Error::TooManySteps`]).
    pub max_steps: usize,
}

impl StepOptions {
    /// The default cap on steps per run: 10⁹.
    pub const DEFAULT_MAX_STEPS: usize = 1_000_000_000;
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            newton: NewtonOptions::default(),
            max_subdivisions: 0,
            max_steps: Self::DEFAULT_MAX_STEPS,
        }
    }
}

/// The deepest stack the integrator provides for a model's node kernels (4 GiB, mapped
/// lazily: only the pages the kernels touch use memory).
pub const MAX_KERNEL_STACK: usize = 4 << 30;

/// Runs `f` on a stack with room for the model's node kernels: the caller's own stack when
/// it has `M::KERNEL_STACK_BYTES` to spare, else a fresh one on the heap (`stacker`).
#[inline]
fn with_kernel_stack<M: ForcedLagrangian<N>, const N: usize, R>(f: impl FnOnce() -> R) -> R {
    // The stepper's own frames: a few records, snapshots and matrices of the model's size.
    let own = 64 * std::mem::size_of::<StepRecord<N>>() + 256 * 1024;
    let need = M::KERNEL_STACK_BYTES.saturating_add(own);
    if need <= 256 * 1024 {
        f()
    } else {
        stacker::maybe_grow(need, need.saturating_mul(2), f)
    }
}

/// A fixed-step variational integrator for one model and one scheme.
///
/// ```
/// use forced_vi::prelude::*;
///
/// struct Oscillator;
/// impl ForcedLagrangian<1> for Oscillator {
///     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
///         (v[0] * v[0] - q[0] * q[0]) * 0.5
///     }
/// }
///
/// let run = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?
///     .run(InitialState::from_velocity([1.0], [0.0]), 1.0)
///     .map_err(|f| f.error)?;
/// let end = run.last().unwrap();
/// assert!((end.q[0] - 1f64.cos()).abs() < 1e-9);
/// # Ok::<(), forced_vi::Error>(())
/// ```
pub struct Integrator<'m, M, const N: usize> {
    model: &'m M,
    scheme: Scheme,
    h: f64,
    options: StepOptions,
}

// By hand: the model is borrowed, so neither needs `M: Clone` or `M: Debug`.
impl<M, const N: usize> Clone for Integrator<'_, M, N> {
    fn clone(&self) -> Self {
        Integrator {
            model: self.model,
            scheme: self.scheme.clone(),
            h: self.h,
            options: self.options,
        }
    }
}

impl<M, const N: usize> std::fmt::Debug for Integrator<'_, M, N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Integrator")
            .field("model", &std::any::type_name::<M>())
            .field("scheme", &self.scheme.id())
            .field("h", &self.h)
            .field("options", &self.options)
            .finish()
    }
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> Integrator<'m, M, N> {
    /// The most subdivision levels a step may use: 2²⁰ substeps.
    pub const MAX_SUBDIVISION_LEVELS: u32 = 20;

    /// An integrator with step `h`. Defaults: [`StepOptions::default`].
    ///
    /// Fails if `h` is not positive and finite (with `1/h` finite too), a model parameter
    /// is not finite, the model's own check fails ([`ForcedLagrangian::check_model`]), or its
    /// kernels need more than [`MAX_KERNEL_STACK`] bytes of stack.
    pub fn new(model: &'m M, scheme: Scheme, h: f64) -> Result<Self, Error> {
        if !(h.is_finite() && h > 0.0 && (1.0 / h).is_finite()) {
            return Err(Error::InvalidStepSize { h });
        }
        if M::KERNEL_STACK_BYTES > MAX_KERNEL_STACK {
            return Err(Error::ModelTooLarge {
                stack_bytes: M::KERNEL_STACK_BYTES,
                max: MAX_KERNEL_STACK,
            });
        }
        model
            .check_parameters()
            .map_err(|name| Error::NonFiniteParameter { name })?;
        model
            .check_model()
            .map_err(|message| Error::InvalidModel { message })?;
        Ok(Integrator {
            model,
            scheme,
            h,
            options: StepOptions::default(),
        })
    }

    /// Replaces the Newton options.
    #[must_use]
    pub fn newton(mut self, newton: NewtonOptions) -> Self {
        self.options.newton = newton;
        self
    }

    /// Allows a failed step to be retried as up to `2^levels` substeps; `levels` is capped
    /// at [`Self::MAX_SUBDIVISION_LEVELS`].
    #[must_use]
    pub fn max_subdivisions(mut self, levels: u32) -> Self {
        self.options.max_subdivisions = levels.min(Self::MAX_SUBDIVISION_LEVELS);
        self
    }

    /// Caps the steps of a run ([`StepOptions::DEFAULT_MAX_STEPS`] by default).
    #[must_use]
    pub fn max_steps(mut self, steps: usize) -> Self {
        self.options.max_steps = steps;
        self
    }

    /// The scheme.
    pub fn scheme(&self) -> &Scheme {
        &self.scheme
    }

    /// The step size.
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// A streaming stepper from `init` to `t_final`: an iterator of records, initial state
    /// first, that holds only the current state.
    pub fn stepper(&self, init: InitialState<N>, t_final: f64) -> Result<Stepper<'_, M, N>, Error> {
        Stepper::new(self, init, t_final)
    }

    /// Streams every record to `f` and returns the totals. Memory use does not grow with
    /// the number of steps. On failure the totals up to it come back with the error.
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        mut f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, StreamFailure> {
        let mut stepper = self.stepper(init, t_final).map_err(|error| StreamFailure {
            error,
            stats: RunStats::default(),
        })?;
        for rec in stepper.by_ref() {
            match rec {
                Ok(r) => f(&r),
                Err(error) => {
                    return Err(StreamFailure {
                        error,
                        stats: stepper.stats(),
                    })
                }
            }
        }
        Ok(stepper.stats())
    }

    /// Runs to `t_final` and collects every record. On failure the records computed so far
    /// come back with the error.
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        let mut traj = Trajectory::default();
        let mut stepper = match self.stepper(init, t_final) {
            Ok(s) => s,
            Err(error) => {
                return Err(RunFailure {
                    error,
                    trajectory: traj,
                })
            }
        };
        // All records are reserved up front, so that a run that cannot hold them fails
        // before its first step rather than aborting in the middle.
        let records = stepper.total_steps().saturating_add(1);
        if traj.records.try_reserve_exact(records).is_err() {
            return Err(RunFailure {
                error: Error::TooManyRecords { records },
                trajectory: traj,
            });
        }
        for rec in stepper.by_ref() {
            match rec {
                Ok(r) => traj.records.push(r),
                Err(error) => {
                    traj.stats = stepper.stats();
                    return Err(RunFailure {
                        error,
                        trajectory: traj,
                    });
                }
            }
        }
        traj.stats = stepper.stats();
        Ok(traj)
    }
}

/// Compensated (Kahan) accumulation of a vector.
#[derive(Clone, Copy, Debug)]
struct Kahan<const N: usize> {
    sum: SVector<f64, N>,
    comp: SVector<f64, N>,
}

impl<const N: usize> Kahan<N> {
    fn new(x: SVector<f64, N>) -> Self {
        Kahan {
            sum: x,
            comp: SVector::zeros(),
        }
    }
    fn add(&mut self, dx: &SVector<f64, N>) {
        for i in 0..N {
            let y = dx[i] - self.comp[i];
            let t = self.sum[i] + y;
            self.comp[i] = (t - self.sum[i]) - y;
            self.sum[i] = t;
        }
    }
}

/// The nonlinear system of one step, in the increments `Z_j = x_j − q_k` (DESIGN §3).
struct StepProblem<'a, M, const N: usize> {
    model: &'a M,
    scheme: &'a Scheme,
    h: f64,
    q0: SVector<f64, N>,
    p0: SVector<f64, N>,
    xs: Vec<SVector<f64, N>>,
    vs: Vec<SVector<f64, N>>,
    grads: Vec<NodeGradient<N>>,
    jacs: Vec<NodeJacobian<N>>,
    /// For a constant mass matrix, the `E` part of the Jacobian for the step size `base_h`.
    base: DMatrix<f64>,
    base_h: f64,
}

impl<M: ForcedLagrangian<N>, const N: usize> StepProblem<'_, M, N> {
    fn nodes(&mut self, z: &DVector<f64>) {
        let s = self.scheme.stages();
        let zs = z.as_slice();
        let inv_h = 1.0 / self.h;
        for i in 0..self.scheme.quadrature_nodes() {
            let mut x = self.q0;
            let mut v = SVector::<f64, N>::zeros();
            for j in 1..s {
                let zj = &zs[(j - 1) * N..j * N];
                let (phi, psi) = (self.scheme.phi(i, j), self.scheme.psi(i, j));
                if phi != 0.0 {
                    for a in 0..N {
                        x[a] += phi * zj[a];
                    }
                }
                for a in 0..N {
                    v[a] += psi * zj[a];
                }
            }
            self.xs[i] = x;
            self.vs[i] = v * inv_h;
        }
    }
}

fn all_finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.iter().all(|x| x.is_finite())
}

impl<M: ForcedLagrangian<N>, const N: usize> NonlinearSystem for StepProblem<'_, M, N> {
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        self.nodes(z);
        let (sch, h) = (self.scheme, self.h);
        for i in 0..sch.quadrature_nodes() {
            let g = self.model.node_gradient(&self.xs[i], &self.vs[i]);
            if !(all_finite(&g.fq) && all_finite(&g.lv)) {
                return Err(NewtonFailure::NonFinite);
            }
            self.grads[i] = g;
        }
        let rs = r.as_mut_slice();
        for j in 0..sch.stages() - 1 {
            let mut gj = if j == 0 { self.p0 } else { SVector::zeros() };
            for (i, g) in self.grads.iter().enumerate() {
                let bi = sch.b()[i];
                let (cf, cl) = (bi * h * sch.phi(i, j), bi * sch.psi(i, j));
                for a in 0..N {
                    gj[a] += cf * g.fq[a] + cl * g.lv[a];
                }
            }
            rs[j * N..(j + 1) * N].copy_from_slice(gj.as_slice());
        }
        Ok(())
    }

    fn jacobian(&mut self, z: &DVector<f64>, jac: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        self.nodes(z);
        let (sch, h) = (self.scheme, self.h);
        for i in 0..sch.quadrature_nodes() {
            let nj = self.model.node_jacobian(&self.xs[i], &self.vs[i]);
            if !(all_finite(&nj.a) && all_finite(&nj.b) && all_finite(&nj.c) && all_finite(&nj.e)) {
                return Err(NewtonFailure::NonFinite);
            }
            self.jacs[i] = nj;
        }
        let constant_mass = M::STRUCTURE.constant_mass;
        let rows = (sch.stages() - 1) * N;
        if constant_mass {
            // E is the same at every node and every step: its part is built once per h.
            if self.base_h != h {
                let e = self.jacs[0].e;
                let bs = self.base.as_mut_slice();
                bs.fill(0.0);
                for t in sch.jacobian_terms() {
                    add_block(bs, rows, t.j, t.m, t.e / h, &e);
                }
                self.base_h = h;
            }
            jac.copy_from(&self.base);
        } else {
            jac.fill(0.0);
        }
        let js = jac.as_mut_slice();
        for t in sch.jacobian_terms() {
            let nj = &self.jacs[t.i];
            if t.a != 0.0 {
                add_block(js, rows, t.j, t.m, t.a * h, &nj.a);
            }
            if t.b != 0.0 {
                add_block(js, rows, t.j, t.m, t.b, &nj.b);
            }
            if !constant_mass {
                if t.c != 0.0 {
                    add_block(js, rows, t.j, t.m, t.c, &nj.c);
                }
                add_block(js, rows, t.j, t.m, t.e / h, &nj.e);
            }
        }
        Ok(())
    }
}

/// Adds `coef · blk` to block `(j, m − 1)` of a column-major matrix with `rows` rows.
#[inline(always)]
fn add_block<const N: usize>(
    js: &mut [f64],
    rows: usize,
    j: usize,
    m: usize,
    coef: f64,
    blk: &SMatrix<f64, N, N>,
) {
    let origin = (m - 1) * N * rows + j * N;
    for c in 0..N {
        let col = &mut js[origin + c * rows..origin + c * rows + N];
        for (x, y) in col.iter_mut().zip(blk.column(c).iter()) {
            *x += coef * y;
        }
    }
}

/// Saved state for retrying a step as substeps.
#[derive(Clone, Copy, Debug)]
struct Snapshot<const N: usize> {
    q: Kahan<N>,
    p: Kahan<N>,
    work: (f64, f64),
    v: SVector<f64, N>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
}

/// Steps a model through time; an iterator over [`StepRecord`]s, initial state first.
///
/// After an error the iterator yields that error once and then ends.
pub struct Stepper<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    options: StepOptions,
    h: f64,
    t_final: f64,
    n_steps: usize,
    k: usize,
    q: Kahan<N>,
    p: Kahan<N>,
    v: SVector<f64, N>,
    energy0: f64,
    work: (f64, f64),
    z: DVector<f64>,
    z_prev: Vec<SVector<f64, N>>,
    z_saved: Vec<SVector<f64, N>>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
    /// Sign of the mass matrix's determinant at the start: a step that changes it has
    /// crossed a singular mass.
    mass_sign: f64,
    stats: RunStats,
    started: bool,
    done: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> Stepper<'a, M, N> {
    fn new(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        with_kernel_stack::<M, N, _>(|| Self::start(integ, init, t_final))
    }

    fn start(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        if !(t_final.is_finite() && t_final >= 0.0) {
            return Err(Error::InvalidFinalTime { t_final });
        }
        integ
            .options
            .newton
            .validate()
            .map_err(|(field, value)| Error::InvalidNewtonOptions { field, value })?;
        let h = integ.h;
        let n_steps = step_count(t_final, h, integ.options.max_steps)?;
        let check = |what: &'static str, x: &[f64; N]| match x.iter().position(|c| !c.is_finite()) {
            Some(index) => Err(Error::NonFiniteInitialData { what, index }),
            None => Ok(()),
        };
        let model = integ.model;
        let (q0, v0, p0) = match init {
            InitialState::Velocity { q, v } => {
                check("q", &q)?;
                check("v", &v)?;
                let (q, v) = (SVector::from(q), SVector::from(v));
                let g = model.node_gradient(&q, &v);
                if !(all_finite(&g.lv) && all_finite(&g.fq)) {
                    return Err(Error::NonFiniteModel { step: 0, t: 0.0 });
                }
                (q, v, g.lv)
            }
            InitialState::Momentum { q, p } => {
                check("q", &q)?;
                check("p", &p)?;
                let (q, p) = (SVector::from(q), SVector::from(p));
                let v = solve_velocity(model, &q, &p, SVector::zeros(), 0, 0.0)?;
                (q, v, p)
            }
        };
        let mass_sign = mass_check(model, &q0, &v0, 0, 0.0)?;
        let scheme = &integ.scheme;
        let s = scheme.stages();
        let r = scheme.quadrature_nodes();
        let energy0 = energy(model, &q0, &v0, &p0)
            .ok_or_else(|| non_finite(q0.amax().max(v0.amax()).max(p0.amax()), 0, 0.0, "energy"))?;
        let g0 = model.node_gradient(&q0, &v0);
        let zero_jac = NodeJacobian {
            grad: g0,
            a: SMatrix::zeros(),
            b: SMatrix::zeros(),
            c: SMatrix::zeros(),
            e: SMatrix::zeros(),
        };
        Ok(Stepper {
            prob: StepProblem {
                model,
                scheme,
                h,
                q0,
                p0,
                xs: vec![q0; r],
                vs: vec![v0; r],
                grads: vec![g0; r],
                jacs: vec![zero_jac; r],
                base: DMatrix::zeros((s - 1) * N, (s - 1) * N),
                base_h: f64::NAN,
            },
            newton: Newton::new((s - 1) * N, integ.options.newton),
            options: integ.options,
            h,
            t_final,
            n_steps,
            k: 0,
            q: Kahan::new(q0),
            p: Kahan::new(p0),
            v: v0,
            energy0,
            work: (0.0, 0.0),
            z: DVector::zeros((s - 1) * N),
            z_prev: vec![SVector::zeros(); s],
            z_saved: vec![SVector::zeros(); s],
            has_prev: false,
            h_prev: h,
            scale_f: g0.fq.amax(),
            mass_sign,
            stats: RunStats::default(),
            started: false,
            done: false,
        })
    }

    /// Number of steps the run will take.
    pub fn total_steps(&self) -> usize {
        self.n_steps
    }

    /// Totals so far.
    pub fn stats(&self) -> RunStats {
        self.stats
    }

    fn time_of(&self, k: usize) -> f64 {
        if k >= self.n_steps {
            self.t_final
        } else {
            k as f64 * self.h
        }
    }

    fn record(&self, newton_iterations: usize, residual: f64, substeps: usize) -> StepRecord<N> {
        let (q, p, v) = (self.q.sum, self.p.sum, self.v);
        let e = energy(self.prob.model, &q, &v, &p).unwrap_or(f64::NAN);
        StepRecord {
            step: self.k,
            t: self.time_of(self.k),
            q,
            p,
            v,
            energy: e,
            energy_balance: e - self.energy0 - self.work.0,
            newton_iterations,
            residual,
            substeps,
        }
    }

    fn snapshot(&mut self) -> Snapshot<N> {
        self.z_saved.copy_from_slice(&self.z_prev);
        Snapshot {
            q: self.q,
            p: self.p,
            work: self.work,
            v: self.v,
            has_prev: self.has_prev,
            h_prev: self.h_prev,
            scale_f: self.scale_f,
        }
    }

    fn restore(&mut self, s: &Snapshot<N>) {
        self.z_prev.copy_from_slice(&self.z_saved);
        self.q = s.q;
        self.p = s.p;
        self.work = s.work;
        self.v = s.v;
        self.has_prev = s.has_prev;
        self.h_prev = s.h_prev;
        self.scale_f = s.scale_f;
    }

    /// Fills `z` with the predictor: the previous step's polynomial extrapolated, or a
    /// straight line along `v` on the first step.
    fn predict(&mut self, h: f64) {
        let sch = self.prob.scheme;
        let s = sch.stages();
        let d = sch.d();
        for (j, &dj) in d.iter().enumerate().skip(1) {
            let zj = if self.has_prev && sch.extrapolates() {
                let same = h == self.h_prev;
                let tau = 1.0 + dj * h / self.h_prev;
                let mut x = -self.z_prev[s - 1];
                for m in 1..s {
                    let l = if same {
                        sch.extrapolation(j, m)
                    } else {
                        sch.basis_at(tau, m)
                    };
                    x += self.z_prev[m] * l;
                }
                x
            } else {
                self.v * (dj * h)
            };
            self.z.fixed_rows_mut::<N>((j - 1) * N).copy_from(&zj);
        }
    }

    /// One step of size `h` from the current state.
    fn advance(&mut self, h: f64) -> Result<(usize, f64), StepFailure> {
        self.predict(h);
        self.prob.h = h;
        self.prob.q0 = self.q.sum;
        self.prob.p0 = self.p.sum;
        self.newton.invalidate();
        let scale = self
            .p
            .sum
            .amax()
            .max(h * self.scale_f)
            .max(f64::MIN_POSITIVE);
        let rep = self
            .newton
            .solve(&mut self.prob, &mut self.z, scale)
            .map_err(StepFailure::Newton)?;
        // The last residual evaluation was at the accepted iterate, so the node gradients in
        // `prob` belong to the solution. Σ_j G_j = h Σ_i b_i (L_q + F)_i gives the momentum
        // update as a small increment, which keeps round-off low (DESIGN §3).
        let sch = self.prob.scheme;
        let s = sch.stages();
        let mut dp = SVector::<f64, N>::zeros();
        let mut dw = 0.0;
        let mut fmax: f64 = 0.0;
        for i in 0..sch.quadrature_nodes() {
            let bi = sch.b()[i];
            dp.axpy(h * bi, &self.prob.grads[i].fq, 1.0);
            fmax = fmax.max(self.prob.grads[i].fq.amax());
            if M::STRUCTURE.has_force {
                let (x, v) = (self.prob.xs[i], self.prob.vs[i]);
                let f = SVector::from(self.prob.model.force::<f64>(&x.into(), &v.into()));
                dw += h * bi * f.dot(&v);
            }
        }
        let dq: SVector<f64, N> = self.z.fixed_rows::<N>((s - 2) * N).into_owned();
        // Velocity guess: the polynomial's slope at the end of the step.
        let mut vguess = SVector::<f64, N>::zeros();
        for m in 1..s {
            let zm = self.z.fixed_rows::<N>((m - 1) * N);
            vguess.axpy(sch.end_slope(m) / h, &zm, 1.0);
        }
        if !M::STRUCTURE.constant_mass {
            // A step may not end where the mass matrix is singular or has changed the sign
            // of its determinant: the path crossed a singular mass, where the
            // Euler–Lagrange equations stop being an ODE.
            let q_end = self.q.sum + dq;
            let e = self.prob.model.mass_matrix(&q_end, &vguess);
            match mass_factor(&e) {
                Some((rcond, sign)) if rcond >= MIN_MASS_RCOND && sign == self.mass_sign => {}
                other => {
                    // A change of sign means a singular mass was crossed: condition 0.
                    let rcond = match other {
                        Some((rc, sign)) if sign == self.mass_sign => rc,
                        _ => 0.0,
                    };
                    return Err(StepFailure::SingularMass { rcond });
                }
            }
        }
        self.q.add(&dq);
        self.p.add(&dp);
        let (w, c) = self.work;
        let y = dw - c;
        let t = w + y;
        self.work = (t, (t - w) - y);
        self.z_prev[0] = SVector::zeros();
        for m in 1..s {
            self.z_prev[m] = self.z.fixed_rows::<N>((m - 1) * N).into_owned();
        }
        self.has_prev = true;
        self.h_prev = h;
        self.scale_f = fmax;
        self.v = vguess;
        Ok((rep.iterations, rep.residual))
    }

    /// Advances over `[t_k, t_{k+1}]`, subdividing on failure if allowed.
    fn step(&mut self) -> Result<StepRecord<N>, Error> {
        let t0 = self.time_of(self.k);
        let h = self.time_of(self.k + 1) - t0;
        let snap = self.snapshot();
        let mut iters = 0;
        let mut last_failure = None;
        for level in 0..=self
            .options
            .max_subdivisions
            .min(Integrator::<M, N>::MAX_SUBDIVISION_LEVELS)
        {
            let parts = 1usize << level;
            let hs = h / parts as f64;
            let mut outcome = Ok(0.0);
            for _ in 0..parts {
                match self.advance(hs) {
                    Ok((it, res)) => {
                        iters += it;
                        outcome = Ok(res);
                    }
                    Err(f) => {
                        iters += self.newton.last_iterations();
                        outcome = Err(f);
                        break;
                    }
                }
            }
            match outcome {
                Ok(res) => {
                    self.k += 1;
                    let t = self.time_of(self.k);
                    self.v = solve_velocity(
                        self.prob.model,
                        &self.q.sum,
                        &self.p.sum,
                        self.v,
                        self.k,
                        t,
                    )?;
                    if parts > 1 {
                        self.stats.subdivided_steps += 1;
                        // The predictor's polynomial covered a substep; start afresh.
                        self.has_prev = false;
                    }
                    self.stats.steps += 1;
                    self.stats.newton_iterations += iters;
                    self.stats.max_newton_iterations = self.stats.max_newton_iterations.max(iters);
                    let rec = self.record(iters, res, parts);
                    if let Some(quantity) = non_finite_field(&rec) {
                        return Err(Error::Overflow {
                            step: self.k,
                            t,
                            quantity,
                        });
                    }
                    return Ok(rec);
                }
                Err(f) => {
                    last_failure = Some(f);
                    self.restore(&snap);
                    // Retry without the (possibly bad) extrapolation.
                    self.has_prev = false;
                }
            }
        }
        self.restore(&snap);
        let step = self.k + 1;
        let failure = match last_failure {
            Some(StepFailure::SingularMass { rcond }) => {
                return Err(Error::SingularMassMatrix { step, t: t0, rcond })
            }
            Some(StepFailure::Newton(f)) => f,
            None => NewtonFailure::NonFinite,
        };
        let residual = match failure {
            NewtonFailure::MaxIterations { residual }
            | NewtonFailure::Diverged { residual }
            | NewtonFailure::Stagnated { residual } => residual,
            _ => f64::NAN,
        };
        if failure == NewtonFailure::NonFinite {
            let size = self.q.sum.amax().max(self.p.sum.amax()).max(self.v.amax());
            return Err(non_finite(size, step, t0, "state"));
        }
        Err(Error::NewtonFailed {
            step,
            t: t0,
            residual,
            failure,
        })
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Iterator for Stepper<'_, M, N> {
    type Item = Result<StepRecord<N>, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if !self.started {
            self.started = true;
            return Some(Ok(self.record(0, 0.0, 1)));
        }
        if self.k >= self.n_steps {
            self.done = true;
            return None;
        }
        let out = with_kernel_stack::<M, N, _>(|| self.step());
        if out.is_err() {
            self.done = true;
        }
        Some(out)
    }
}

/// `E = v · p − L(q, v)` with `p = L_v`; `None` if not finite.
fn energy<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
    p: &SVector<f64, N>,
) -> Option<f64> {
    let e = v.dot(p) - model.lagrangian::<f64>(&(*q).into(), &(*v).into());
    e.is_finite().then_some(e)
}

/// Why one attempt at a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
enum StepFailure {
    Newton(NewtonFailure),
    /// The step ended at a singular mass matrix or across one.
    SingularMass {
        rcond: f64,
    },
}

/// The number of steps of size `h` (the last one shortened) that reach `t_final`.
///
/// A ratio within 1e-10 of an integer is that integer, so that `t_final = n·h` does not
/// end with a sliver of a step; any positive `t_final` takes at least one step.
fn step_count(t_final: f64, h: f64, max: usize) -> Result<usize, Error> {
    let ratio = t_final / h;
    let steps = if (ratio - ratio.round()).abs() <= 1e-10 * ratio.max(1.0) {
        ratio.round()
    } else {
        ratio.ceil()
    };
    let steps = if t_final > 0.0 { steps.max(1.0) } else { 0.0 };
    if !(steps <= max as f64) {
        return Err(Error::TooManySteps { steps, max });
    }
    // Exact: steps ≤ max ≤ usize::MAX, and the float is an integer.
    Ok(steps as usize)
}

/// The error for a non-finite value computed from a state of max-norm `size`.
///
/// Past `√f64::MAX`, products of two state components overflow: the model is not at
/// fault, the solution has left the range of `f64` ([`Error::Overflow`]). Below, the model
/// returned a non-finite value at a representable point ([`Error::NonFiniteModel`]).
fn non_finite(size: f64, step: usize, t: f64, quantity: &'static str) -> Error {
    if size >= f64::MAX.sqrt() {
        Error::Overflow { step, t, quantity }
    } else {
        Error::NonFiniteModel { step, t }
    }
}

/// The first field of a record that is not finite, by name.
fn non_finite_field<const N: usize>(r: &StepRecord<N>) -> Option<&'static str> {
    [
        ("q", all_finite(&r.q)),
        ("p", all_finite(&r.p)),
        ("v", all_finite(&r.v)),
        ("energy", r.energy.is_finite()),
        ("energy_balance", r.energy_balance.is_finite()),
        ("residual", r.residual.is_finite()),
    ]
    .into_iter()
    .find(|(_, ok)| !ok)
    .map(|(name, _)| name)
}

/// Mass matrices whose equilibrated reciprocal condition is below this are singular.
const MIN_MASS_RCOND: f64 = 1e-13;

/// The reciprocal condition estimate and the sign of the determinant of a mass matrix,
/// from the LU pivots of its equilibrated form `D⁻¹ E D⁻¹`, `D = diag(√max_j |E_ij|)`.
///
/// Equilibration makes the test scale-invariant: `diag(1e-14, 1)` is as well conditioned
/// as the identity. `None` if a row is zero or a value is not finite.
fn mass_factor<const N: usize>(e: &SMatrix<f64, N, N>) -> Option<(f64, f64)> {
    let mut d = [0.0f64; N];
    for (i, di) in d.iter_mut().enumerate() {
        let m = e.row(i).amax();
        if !(m.is_finite() && m > 0.0) {
            return None;
        }
        *di = 1.0 / m.sqrt();
    }
    let mut a = SMatrix::<f64, N, N>::from_fn(|i, j| e[(i, j)] * d[i] * d[j]);
    let (mut lo, mut hi, mut sign) = (f64::INFINITY, 0.0f64, 1.0f64);
    for k in 0..N {
        let p = (k..N).max_by(|&i, &j| a[(i, k)].abs().total_cmp(&a[(j, k)].abs()))?;
        let piv = a[(p, k)];
        if piv == 0.0 || !piv.is_finite() {
            return None;
        }
        if p != k {
            a.swap_rows(k, p);
            sign = -sign;
        }
        sign *= piv.signum();
        lo = lo.min(piv.abs());
        hi = hi.max(piv.abs());
        for i in k + 1..N {
            let l = a[(i, k)] / piv;
            for j in k + 1..N {
                let u = a[(k, j)];
                a[(i, j)] -= l * u;
            }
        }
    }
    Some((if N == 0 { 1.0 } else { lo / hi }, sign))
}

/// Checks the mass matrix at `(q, v)`; returns the sign of its determinant.
fn mass_check<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
    step: usize,
    t: f64,
) -> Result<f64, Error> {
    let e = model.mass_matrix(q, v);
    if !all_finite(&e) {
        return Err(Error::NonFiniteModel { step, t });
    }
    match mass_factor(&e) {
        Some((rcond, sign)) if rcond >= MIN_MASS_RCOND => Ok(sign),
        other => Err(Error::SingularMassMatrix {
            step,
            t,
            rcond: other.map_or(0.0, |(rc, _)| rc),
        }),
    }
}

/// Solves `L_v(q, v) = p` for `v` by a damped Newton method from `guess`.
///
/// One step is exact for a kinetic energy quadratic in `v` with a constant mass matrix.
/// Otherwise it iterates, halving steps that do not reduce the residual (or leave the
/// model's domain), until `|L_v(q, v) − p| ≤ 1e-13 (|p| + |E| |v|)` or the round-off floor
/// of those terms, and fails with [`Error::VelocitySolveFailed`] after 60 iterations.
fn solve_velocity<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    p: &SVector<f64, N>,
    guess: SVector<f64, N>,
    step: usize,
    t: f64,
) -> Result<SVector<f64, N>, Error> {
    let singular = |rcond| Error::SingularMassMatrix { step, t, rcond };
    let residual_at = |v: &SVector<f64, N>| -> Option<SVector<f64, N>> {
        let r = model.node_gradient(q, v).lv - p;
        all_finite(&r).then_some(r)
    };
    let mut v = guess;
    if M::STRUCTURE.constant_mass {
        let e = model.mass_matrix(q, &v);
        let r = residual_at(&v).ok_or(Error::NonFiniteModel { step, t })?;
        let (dv, _) = crate::newton::solve_small(&e, &(-r)).ok_or(singular(0.0))?;
        v += dv;
        return if all_finite(&v) {
            Ok(v)
        } else {
            Err(Error::NonFiniteModel { step, t })
        };
    }
    let mut r = residual_at(&v).ok_or(Error::NonFiniteModel { step, t })?;
    for _ in 0..60 {
        let e = model.mass_matrix(q, &v);
        if !all_finite(&e) {
            return Err(Error::NonFiniteModel { step, t });
        }
        let tol = 1e-13 * (p.amax() + e.amax() * v.amax()) + 4.0 * f64::MIN_POSITIVE;
        if r.amax() <= tol {
            return Ok(v);
        }
        let (dv, _) = crate::newton::solve_small(&e, &(-r)).ok_or(singular(0.0))?;
        let mut lambda = 1.0;
        loop {
            let trial = v + dv * lambda;
            if let Some(rt) = residual_at(&trial).filter(|_| all_finite(&trial)) {
                if rt.amax() < r.amax() * (1.0 - 1e-4 * lambda) {
                    v = trial;
                    r = rt;
                    break;
                }
            }
            lambda *= 0.5;
            if lambda < 1e-10 {
                // No step reduces the residual: at the round-off floor, or stuck.
                let floor = 64.0 * f64::EPSILON * (p.amax() + e.amax() * v.amax());
                return if r.amax() <= floor {
                    Ok(v)
                } else {
                    Err(Error::VelocitySolveFailed {
                        step,
                        t,
                        residual: r.amax(),
                    })
                };
            }
        }
    }
    Err(Error::VelocitySolveFailed {
        step,
        t,
        residual: r.amax(),
    })
}
