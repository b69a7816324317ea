//! One stiff or extreme problem: a model with its initial data, final time and reference, run
//! with the variational schemes (with subdivision) or a stiff baseline.

use std::time::Instant;

use forced_vi::{output, ForcedLagrangian, InitialState, Integrator, Scheme, SchemeId, Stepper};

use super::rows::{BaselineRow, Outcome, Row, HIGHER_ORDER_MAX_STEPS, MAX_SUBDIVISIONS};
use crate::baselines::{self, Baseline, OdeSystem};
use crate::reference::Reference;
use crate::report::timing::timed;
use crate::report::ReportError;

/// A stiff or extreme scene: a model, its initial data, final time and reference.
pub(super) struct Problem<M, const N: usize> {
    pub(super) name: &'static str,
    pub(super) description: String,
    pub(super) model: M,
    pub(super) q0: [f64; N],
    pub(super) v0: [f64; N],
    /// Final time in the model's time.
    pub(super) t_final: f64,
    /// Model time per unit of the scene's time (`h_model = time_scale · h`).
    pub(super) time_scale: f64,
    /// Reference positions at `t_final`.
    pub(super) reference: Vec<f64>,
    /// Where the reference comes from and how accurate it is.
    pub(super) reference_note: String,
    /// Estimated absolute error of the reference.
    pub(super) reference_accuracy: f64,
}

/// A problem with its model type erased.
pub trait Case: Sync {
    fn name(&self) -> &'static str;
    fn description(&self) -> &str;
    fn reference_note(&self) -> &str;
    /// The size of the solution: max-norm of the initial and the reference positions.
    fn scale(&self) -> f64;
    /// Estimated absolute error of the reference.
    fn accuracy(&self) -> f64;
    fn variational(&self, id: SchemeId, h: f64) -> Row;
    /// An adaptive run at `rtol = atol = tol`, first step the whole interval.
    fn adaptive(&self, id: SchemeId, tol: f64) -> Row;
    fn baseline(&self, solver: Baseline, tol: f64) -> BaselineRow;
    /// The wall time of [`Case::adaptive`]'s run to its final state alone: no records, no
    /// diagnostics, as [`Case::time_baseline`] runs.
    fn time_adaptive(&self, id: SchemeId, tol: f64) -> Result<f64, String>;
    /// The wall time of [`Case::baseline`]'s run.
    fn time_baseline(&self, solver: Baseline, tol: f64) -> Result<f64, String>;
}

pub(super) fn q_error(q: &[f64], reference: &[f64]) -> f64 {
    if q.len() != reference.len() {
        return f64::NAN;
    }
    q.iter()
        .zip(reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, |m: f64, e| {
            if e.is_nan() || m.is_nan() {
                f64::NAN
            } else {
                m.max(e)
            }
        })
}

impl<M: ForcedLagrangian<N> + Sync, const N: usize> Problem<M, N> {
    /// Runs `id` with step `h_model` (model time) and subdivision, or adaptively at
    /// `rtol = atol = tol` from a first step `h_model` (no subdivision: the controller
    /// rejects and shrinks failed steps).
    fn run(&self, id: SchemeId, h_model: f64, tol: Option<f64>) -> Row {
        let start = Instant::now();
        let mut row = Row {
            scene: self.name,
            method: id.to_string(),
            h: h_model / self.time_scale,
            tol,
            outcome: Outcome::Ok,
            steps_done: 0,
            max_newton_iters: 0,
            err_final: f64::NAN,
            max_energy_balance_err: 0.0,
            subdivided_steps: 0,
            rejected_steps: 0,
            seconds: 0.0,
        };
        let init = InitialState::from_velocity(self.q0, self.v0);
        let opened = self.integrator(id, h_model, tol).and_then(|integ| {
            let mut stepper = integ.stepper(init, self.t_final)?;
            self.drain(&mut stepper, &mut row);
            Ok(())
        });
        if let Err(e) = opened {
            row.outcome = Outcome::Failed(e.kind());
        }
        row.seconds = start.elapsed().as_secs_f64();
        row
    }

    /// The integrator of a run: fixed steps with subdivision, or adaptive at `rtol = atol = tol`.
    fn integrator(
        &self,
        id: SchemeId,
        h_model: f64,
        tol: Option<f64>,
    ) -> Result<Integrator<'_, M, N>, forced_vi::Error> {
        let integ = Integrator::new(&self.model, Scheme::new(id)?, h_model)?;
        match tol {
            Some(t) if matches!(id, SchemeId::Lobatto(s) if s >= 5) => integ
                .tolerances(t, t)
                .map(|i| i.max_steps(HIGHER_ORDER_MAX_STEPS)),
            Some(t) => integ.tolerances(t, t),
            None => Ok(integ.max_subdivisions(MAX_SUBDIVISIONS)),
        }
    }

    /// Runs `stepper` to its end or its first error and fills the row's outcome and totals.
    fn drain(&self, stepper: &mut Stepper<'_, M, N>, row: &mut Row) {
        let mut last_q: Option<Vec<f64>> = None;
        let mut max_eb: f64 = 0.0;
        let mut error = None;
        for rec in stepper.by_ref() {
            match rec {
                Ok(r) => {
                    let eb = r.energy_balance.abs();
                    max_eb = if eb.is_nan() || max_eb.is_nan() {
                        f64::NAN
                    } else {
                        max_eb.max(eb)
                    };
                    last_q = Some(r.q.iter().copied().collect());
                }
                Err(e) => {
                    error = Some(e);
                    break;
                }
            }
        }
        let stats = stepper.stats();
        row.steps_done = stats.steps;
        row.max_newton_iters = stats.max_newton_iterations;
        row.subdivided_steps = stats.subdivided_steps;
        row.rejected_steps = stats.rejected_steps;
        row.max_energy_balance_err = max_eb;
        row.outcome = match error {
            Some(e) => Outcome::Failed(e.kind()),
            None => {
                row.err_final = last_q.map_or(f64::NAN, |q| q_error(&q, &self.reference));
                if !(row.err_final.is_finite() && max_eb.is_finite()) {
                    Outcome::Failed("non_finite_result".into())
                } else if stats.subdivided_steps > 0 {
                    Outcome::Recovered
                } else {
                    Outcome::Ok
                }
            }
        };
    }

    /// The final positions of a baseline run.
    pub(super) fn baseline_q(
        &self,
        solver: Baseline,
        tol: f64,
    ) -> Result<(Vec<f64>, usize), String> {
        let sys = OdeSystem::new(&self.model, &self.q0, &self.v0);
        let y0 = sys.initial_state(&self.q0, &self.v0);
        let run = baselines::solve(&sys, solver, tol, &y0, self.t_final, |_, _| {})
            .map_err(|e| e.to_string())?;
        Ok((run.y[..N].to_vec(), run.steps))
    }
}

impl<M: ForcedLagrangian<N> + Sync, const N: usize> Case for Problem<M, N> {
    fn name(&self) -> &'static str {
        self.name
    }
    fn description(&self) -> &str {
        &self.description
    }
    fn reference_note(&self) -> &str {
        &self.reference_note
    }
    fn scale(&self) -> f64 {
        self.q0
            .iter()
            .chain(&self.reference)
            .fold(0.0, |m: f64, x| m.max(x.abs()))
    }
    fn accuracy(&self) -> f64 {
        self.reference_accuracy
    }
    fn variational(&self, id: SchemeId, h: f64) -> Row {
        self.run(id, h * self.time_scale, None)
    }
    fn adaptive(&self, id: SchemeId, tol: f64) -> Row {
        self.run(id, self.t_final, Some(tol))
    }
    fn time_adaptive(&self, id: SchemeId, tol: f64) -> Result<f64, String> {
        let init = InitialState::from_velocity(self.q0, self.v0);
        let (res, seconds) = timed(|| {
            let integ = self
                .integrator(id, self.t_final, Some(tol))
                .map_err(|e| e.to_string())?;
            integ
                .final_state(init, self.t_final)
                .map_err(|e| e.to_string())
        });
        std::hint::black_box(res?);
        Ok(seconds)
    }
    fn time_baseline(&self, solver: Baseline, tol: f64) -> Result<f64, String> {
        let (res, seconds) = timed(|| self.baseline_q(solver, tol));
        std::hint::black_box(res?);
        Ok(seconds)
    }
    fn baseline(&self, solver: Baseline, tol: f64) -> BaselineRow {
        let (res, seconds) = timed(|| self.baseline_q(solver, tol));
        let (err_final, steps, failure) = match res {
            Ok((q, steps)) => {
                let e = q_error(&q, &self.reference);
                if e.is_finite() {
                    (e, steps, None)
                } else {
                    (f64::NAN, steps, Some("non-finite result".to_string()))
                }
            }
            Err(msg) => (f64::NAN, 0, Some(msg)),
        };
        BaselineRow {
            scene: self.name,
            solver,
            tol,
            err_final,
            steps,
            seconds,
            failure,
        }
    }
}

/// The last row of a reference file: `(t, q)`.
pub(super) fn reference_end(csv: &str) -> Result<(f64, Vec<f64>), ReportError> {
    let bad = |message: String| {
        ReportError::Scene(crate::scenes::SceneError::Reference {
            scene: "stability",
            message,
        })
    };
    let parsed = Reference::parse(csv).map_err(|e| bad(e.to_string()))?;
    let end = parsed
        .points
        .iter()
        .max_by(|a, b| a.t.total_cmp(&b.t))
        .ok_or_else(|| bad("empty reference".into()))?;
    Ok((end.t, end.q.clone()))
}

/// A fine-step variational run to use as a reference, cross-checked by a second scheme.
pub(super) fn fine_reference<M: ForcedLagrangian<N> + Sync, const N: usize>(
    p: &Problem<M, N>,
    h_model: f64,
) -> (Vec<f64>, String, f64) {
    let end = |id: SchemeId| -> Option<Vec<f64>> {
        let scheme = Scheme::new(id).ok()?;
        let integ = Integrator::new(&p.model, scheme, h_model).ok()?;
        let traj = integ
            .solve(
                InitialState::from_velocity(p.q0, p.v0),
                p.t_final,
                output::Records,
            )
            .ok()?;
        let q: Vec<f64> = traj.last()?.q.iter().copied().collect();
        q.iter().all(|x| x.is_finite()).then_some(q)
    };
    let a = end(SchemeId::Lobatto(5));
    let b = end(SchemeId::Lobatto(4));
    match (a, b) {
        (Some(a), Some(b)) => {
            let d = q_error(&a, &b);
            (
                a,
                format!("lobatto5 at h = {h_model:e} (lobatto4 at the same h differs by {d:.1e})"),
                d.max(1e-15),
            )
        }
        (Some(a), None) => (
            a,
            format!("lobatto5 at h = {h_model:e} (no cross-check)"),
            f64::NAN,
        ),
        _ => (
            vec![f64::NAN; N],
            "reference run failed".to_string(),
            f64::NAN,
        ),
    }
}
