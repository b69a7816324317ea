//! What the stability study measures: its rows and the record of `stability.csv`.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::baselines::Baseline;
use crate::report::table::{sci, text};

/// Subdivision levels allowed per step: a failed step is retried as 2, 4, …, 64 substeps.
pub const MAX_SUBDIVISIONS: u32 = 6;

/// The step cap of the adaptive runs of lobatto5 and above, which the sweep added for the
/// stiff cost: on the scaled van der Pol (μ = 10⁶), lobatto5 and lobatto7 at tol 1e-7 had not
/// finished after 100 s, and lobatto5 at 1e-8 took 3.2·10⁸ steps (330 s, ending `Ok`),
/// where lobatto6 at 1e-7 takes 7465 (`report/stability.csv`). A run past the cap ends in `max_steps_reached`, a
/// typed error.
pub const HIGHER_ORDER_MAX_STEPS: usize = 1_000_000;

/// How one run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Finished without subdivision, with a finite final state and error.
    Ok,
    /// Finished, but some steps were subdivided.
    Recovered,
    /// Stopped; the error kind.
    Failed(String),
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Outcome::Ok => f.write_str("ok"),
            Outcome::Recovered => f.write_str("recovered"),
            Outcome::Failed(kind) => write!(f, "failed:{kind}"),
        }
    }
}

/// One run of a variational scheme: a row of `stability.csv`, plus what the section needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Scene name.
    pub scene: &'static str,
    /// Scheme name.
    pub method: String,
    /// Step size, in the scene's time unit (the first step of an adaptive run).
    pub h: f64,
    /// `rtol = atol` of an adaptive run; `None` for a fixed step.
    pub tol: Option<f64>,
    /// How the run ended.
    pub outcome: Outcome,
    /// Steps completed (accepted steps of an adaptive run).
    pub steps_done: usize,
    /// Largest Newton iteration count of one step.
    pub max_newton_iters: usize,
    /// Max-norm position error at the final time (`NaN` if the run failed).
    pub err_final: f64,
    /// Largest absolute energy-balance error over the steps done.
    pub max_energy_balance_err: f64,
    /// Steps that needed subdivision.
    pub subdivided_steps: usize,
    /// Attempts an adaptive run rejected (each a step solve and an estimate).
    pub rejected_steps: usize,
    /// Wall time of the run, seconds.
    pub seconds: f64,
}

/// One stiff-baseline run of the comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct BaselineRow {
    /// Scene name.
    pub scene: &'static str,
    /// The solver.
    pub solver: Baseline,
    /// Tolerance (`rtol = atol`).
    pub tol: f64,
    /// Max-norm position error at the final time (`NaN` if it failed).
    pub err_final: f64,
    /// Accepted steps.
    pub steps: usize,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Why it failed, if it did.
    pub failure: Option<String>,
}

/// What a `stability` run produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    /// The fixed-step variational rows, as written to `stability.csv`.
    pub rows: Vec<Row>,
    /// The adaptive variational rows, written after them.
    pub adaptive: Vec<Row>,
    /// The stiff-baseline runs of the comparison.
    pub baselines: Vec<BaselineRow>,
    /// The stiff-cost comparison's candidates timed again, one after the other.
    pub stiff_times: StiffTimes,
    /// Wall time of the whole command, seconds.
    pub elapsed: f64,
}

/// The candidates of the stiff-cost comparison timed again after the parallel sweeps, in
/// rounds that run them all one after the other, each to its final state alone (no records
/// or diagnostics, as the baselines run): indices into [`Summary::adaptive`] and
/// [`Summary::baselines`] with their median wall times.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StiffTimes {
    /// Rounds timed.
    pub rounds: usize,
    /// Adaptive variational runs: (index, median seconds).
    pub adaptive: Vec<(usize, f64)>,
    /// Baseline runs: (index, median seconds).
    pub baselines: Vec<(usize, f64)>,
    /// Why the runs could not be timed again (the table then shows the sweeps' times).
    pub failure: Option<String>,
}

impl FromStr for Outcome {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ok" => Ok(Outcome::Ok),
            "recovered" => Ok(Outcome::Recovered),
            _ => s
                .strip_prefix("failed:")
                .map(|k| Outcome::Failed(k.to_string()))
                .ok_or_else(|| format!("unknown outcome `{s}`")),
        }
    }
}

/// A line of `stability.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilityRecord {
    /// Scene name.
    pub scene: String,
    /// Scheme name.
    pub method: String,
    /// Step size.
    #[serde(with = "sci")]
    pub h: f64,
    /// How the run ended.
    #[serde(with = "text")]
    pub outcome: Outcome,
    /// Steps completed.
    pub steps_done: usize,
    /// Largest Newton iteration count of one step.
    pub max_newton_iters: usize,
    /// Max-norm position error at the final time.
    #[serde(with = "sci")]
    pub err_final: f64,
    /// Largest absolute energy-balance error.
    #[serde(with = "sci")]
    pub max_energy_balance_err: f64,
    /// `fixed` or `adaptive`.
    pub mode: String,
    /// `rtol = atol` of an adaptive row; empty for fixed rows.
    #[serde(with = "sci::opt")]
    pub tol: Option<f64>,
}

impl From<&Row> for StabilityRecord {
    fn from(r: &Row) -> Self {
        StabilityRecord {
            scene: r.scene.to_string(),
            method: r.method.clone(),
            h: r.h,
            outcome: r.outcome.clone(),
            steps_done: r.steps_done,
            max_newton_iters: r.max_newton_iters,
            err_final: r.err_final,
            max_energy_balance_err: r.max_energy_balance_err,
            mode: if r.tol.is_some() { "adaptive" } else { "fixed" }.to_string(),
            tol: r.tol,
        }
    }
}
