//! The sparse stepping loop: the dense [`Stepper`](crate::Stepper)'s predictor, Newton
//! solve, compensated update, subdivision and checks, on heap buffers made once per run and
//! the sparse step equations. A step allocates nothing.

use nalgebra::SVector;

use crate::error::Error;
use crate::initial::InitialState;
use crate::integrator::{Integrator, StepOptions};
use crate::model::ForcedLagrangian;
use crate::sparse::equations::SparseStep;
use crate::sparse::lu::SparseLu;
use crate::sparse::newton::SparseNewton;
use crate::sparse::node::{NodePattern, NodeSink, SparseNode};
use crate::sparse::state::{energy, State};
use crate::sparse::velocity::{outside_pattern, VelocitySolver};
use crate::stepper::{check_finite, check_run, step_count};
use crate::trajectory::{non_finite_field, RunStats, StepRecord};

/// Steps a model with sparse node kernels; an iterator over [`StepRecord`]s, initial state
/// first (made by [`Integrator::sparse_stepper`]). After an error it yields that error once
/// and ends.
pub struct SparseStepper<'a, M, const N: usize> {
    pub(super) model: &'a M,
    pub(super) prob: SparseStep<'a>,
    pub(super) newton: SparseNewton,
    pub(super) velocity: VelocitySolver,
    pub(super) options: StepOptions,
    pub(super) h: f64,
    pub(super) t_final: f64,
    pub(super) n_steps: usize,
    pub(super) k: usize,
    pub(super) state: State,
    pub(super) saved: State,
    pub(super) energy0: f64,
    pub(super) z: Vec<f64>,
    /// The time of the record last handed out.
    pub(super) t: f64,
    pub(super) lean: bool,
    pub(super) stats: RunStats,
    pub(super) started: bool,
    pub(super) done: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> SparseStepper<'a, M, N> {
    /// A stepper on the node pattern recorded by `record_node_pattern`.
    pub(crate) fn new(
        integ: &'a Integrator<'a, M, N>,
        node: &'a dyn SparseNode,
        pattern: NodePattern,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        check_run(&integ.options, t_final)?;
        if pattern.n() != N || node.dof() != N {
            return Err(Error::InvalidModel {
                message: format!(
                    "the sparse node kernels have {} degrees of freedom, the model {N}",
                    node.dof()
                ),
            });
        }
        let (h, scheme) = (integ.h, &integ.scheme);
        let n_steps = step_count(t_final, h, integ.options.max_steps)?;
        let mut velocity = VelocitySolver::new(&pattern, M::STRUCTURE.constant_mass)?;
        let mut prob = SparseStep::new(node, scheme, pattern);
        let lu = SparseLu::new(
            prob.step_pattern.dim,
            std::mem::take(&mut prob.step_pattern.col_ptr),
            std::mem::take(&mut prob.step_pattern.row_idx),
        )
        .map_err(|_| Error::InvalidModel {
            message: "the sparse step pattern cannot be analysed".into(),
        })?;
        let mut state = State::new(N, scheme.stages());
        initial_state::<N>(&mut prob, &mut velocity, &mut state, init)?;
        state.h_prev = h;
        let energy0 = energy(node, 0.0, &state.q.sum, &state.v, &state.p.sum)
            .ok_or(Error::NonFiniteModel { step: 0, t: 0.0 })?;
        let saved = state.clone();
        Ok(SparseStepper {
            model: integ.model,
            newton: SparseNewton::new(lu, integ.options.newton),
            velocity,
            options: integ.options,
            h,
            t_final,
            n_steps,
            k: 0,
            z: vec![0.0; prob.step_pattern.dim],
            prob,
            state,
            saved,
            energy0,
            t: 0.0,
            lean: false,
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

    /// Leaves out the per-step diagnostics (see [`crate::Integrator::final_state`]).
    pub(crate) fn set_lean(&mut self, lean: bool) {
        self.lean = lean;
    }

    pub(super) fn time_of(&self, k: usize) -> f64 {
        if k >= self.n_steps {
            self.t_final
        } else {
            k as f64 * self.h
        }
    }

    /// The record of the current state; with `diagnostics`, its energy and balance too.
    pub(super) fn record(
        &self,
        iters: usize,
        residual: f64,
        substeps: usize,
        diagnostics: bool,
    ) -> StepRecord<N> {
        let st = &self.state;
        let (energy, balance) = if diagnostics {
            let e = energy(self.prob.node, self.t, &st.q.sum, &st.v, &st.p.sum).unwrap_or(f64::NAN);
            (e, e - self.energy0 - st.work.0)
        } else {
            (0.0, 0.0)
        };
        StepRecord {
            step: self.k,
            t: self.t,
            q: SVector::from_column_slice(&st.q.sum),
            p: SVector::from_column_slice(&st.p.sum),
            v: SVector::from_column_slice(&st.v),
            energy,
            energy_balance: balance,
            newton_iterations: iters,
            residual,
            substeps,
        }
    }

    /// The full record of the current state, after a lean run (the balance is zero: the
    /// work was not summed).
    pub(crate) fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        if self.lean && self.k > 0 {
            self.solve_velocity()?;
        }
        let mut rec = self.record(0, 0.0, 1, true);
        if self.lean {
            rec.energy_balance = 0.0;
        }
        match non_finite_field(&rec) {
            Some(quantity) => Err(Error::Overflow {
                step: self.k,
                t: self.t,
                quantity,
            }),
            None => Ok(rec),
        }
    }

    pub(super) fn solve_velocity(&mut self) -> Result<(), Error> {
        let st = &mut self.state;
        let at = (self.t, &st.q.sum[..], &st.p.sum[..]);
        let (node, pattern) = (self.prob.node, &self.prob.pattern);
        self.velocity.solve(node, pattern, at, &mut st.v, self.k)
    }

    /// Fills `z` with the predictor: the previous step's polynomial extrapolated, or a
    /// straight line along `v` on the first step.
    pub(super) fn predict(&mut self, h: f64) {
        let sch = self.prob.scheme;
        let s1 = sch.stages() - 1;
        let st = &self.state;
        let extrapolate = st.has_prev && sch.extrapolates();
        let same = h == st.h_prev;
        for j in 1..=s1 {
            let dj = sch.d()[j];
            let tau = 1.0 + dj * h / st.h_prev;
            for a in 0..N {
                let prev = &st.z_prev[a * s1..(a + 1) * s1];
                self.z[a * s1 + j - 1] = if extrapolate {
                    let mut x = -prev[s1 - 1];
                    for (m, &zm) in prev.iter().enumerate() {
                        let l = if same {
                            sch.extrapolation(j, m + 1)
                        } else {
                            sch.basis_at(tau, m + 1)
                        };
                        x += zm * l;
                    }
                    x
                } else {
                    st.v[a] * (dj * h)
                };
            }
        }
    }
}

/// Checks the initial data and fills `(q, v, p)` of `state` from it (`p_0 = L_v(q_0, v_0)`, or
/// `v_0` by the velocity solve) and the force scale `|L_q + F|` at the start.
fn initial_state<const N: usize>(
    prob: &mut SparseStep<'_>,
    velocity: &mut VelocitySolver,
    state: &mut State,
    init: InitialState<N>,
) -> Result<(), Error> {
    let node = prob.node;
    let (q0, p0, v0) = (&mut state.q.sum, &mut state.p.sum, &mut state.v);
    match init {
        InitialState::Velocity { q, v } => {
            check_finite("q", &q)?;
            check_finite("v", &v)?;
            q0.copy_from_slice(&q);
            v0.copy_from_slice(&v);
            velocity.check_mass(node, &prob.pattern, (0.0, q0, v0))?;
            let mut sink = NodeSink::gradient(&mut prob.fq[..N], p0);
            node.eval(0.0, q0, v0, &mut sink);
            if sink.outside() {
                return Err(outside_pattern());
            }
        }
        InitialState::Momentum { q, p } => {
            check_finite("q", &q)?;
            check_finite("p", &p)?;
            q0.copy_from_slice(&q);
            p0.copy_from_slice(&p);
            velocity.solve(node, &prob.pattern, (0.0, q0, p0), v0, 0)?;
        }
    }
    let mut lv = vec![0.0; N];
    let mut sink = NodeSink::gradient(&mut prob.fq[..N], &mut lv);
    node.eval(0.0, q0, v0, &mut sink);
    let finite = |x: &[f64]| x.iter().all(|c| c.is_finite());
    if !(finite(&prob.fq[..N]) && finite(p0)) {
        return Err(Error::NonFiniteModel { step: 0, t: 0.0 });
    }
    state.scale_f = prob.fq[..N].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    Ok(())
}
