//! What the work-precision study measures: its rows, and the records of its CSV files.

use serde::{Deserialize, Serialize};

use super::external::External;
use crate::report::orders::Fit;
use crate::report::table::{sci, text};
use crate::report::Method;
use crate::scenes::BalanceSeries;

/// How a variational scheme chooses its steps: `fixed` (a step size `h`, and every baseline
/// row, swept over its own tolerance) or `adaptive` (error control at `rtol = atol = tol`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Mode {
    /// A fixed step `h` (and the baselines' rows).
    #[default]
    Fixed,
    /// Tolerance-driven steps of a variational scheme.
    Adaptive,
}

impl Mode {
    /// `fixed` or `adaptive`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Fixed => "fixed",
            Mode::Adaptive => "adaptive",
        }
    }

    /// The label of `method` run in this mode: `lobatto3` or `lobatto3 (adaptive)`.
    pub fn label(self, method: &Method) -> String {
        match self {
            Mode::Fixed => method.to_string(),
            Mode::Adaptive => format!("{method} (adaptive)"),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Mode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fixed" => Ok(Mode::Fixed),
            "adaptive" => Ok(Mode::Adaptive),
            other => Err(format!("unknown mode `{other}`")),
        }
    }
}

/// Minimum, mean and maximum over ensemble members.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    /// Smallest member error.
    pub min: f64,
    /// Mean member error.
    pub mean: f64,
    /// Largest member error.
    pub max: f64,
}

/// One measured point.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The scene.
    pub scene: &'static str,
    /// The method.
    pub method: Method,
    /// Fixed or adaptive steps.
    pub mode: Mode,
    /// `h` for fixed-step variational runs, the tolerance otherwise.
    pub h_or_tol: f64,
    /// Steps (summed over members; accepted steps of adaptive runs).
    pub steps: usize,
    /// The fewest steps of one member's run (the run's own steps for a single initial
    /// state).
    pub member_steps_min: usize,
    /// Newton iterations (summed over members).
    pub newton_iters: usize,
    /// Median wall time in seconds.
    pub seconds: f64,
    /// Errors in q, p and energy (means over members); spreads for ensembles.
    pub err: [Spread; 3],
}

impl Row {
    /// `err_q`, `err_p`, `err_energy` (member means).
    pub fn errors(&self) -> [f64; 3] {
        self.err.map(|s| s.mean)
    }
}

/// A run that produced no result.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    /// The scene.
    pub scene: &'static str,
    /// The method.
    pub method: Method,
    /// Fixed or adaptive steps.
    pub mode: Mode,
    /// Its step size or tolerance.
    pub h_or_tol: f64,
    /// What went wrong.
    pub message: String,
}

/// The fitted orders of one variational method on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct OrderRow {
    /// The scene.
    pub scene: &'static str,
    /// The method.
    pub method: Method,
    /// Control points `s`.
    pub stages: usize,
    /// The scheme's order.
    pub expected: usize,
    /// Observed orders in q, p and energy.
    pub observed: [Option<Fit>; 3],
    /// Why the order in q is blank or off: empty when it is within 0.3 of `expected`.
    pub note: String,
}

/// One curve of the energy-balance plot.
#[derive(Clone, Debug, PartialEq)]
pub struct BalanceCurve {
    /// The method.
    pub method: Method,
    /// Fixed steps or adaptive ones.
    pub mode: Mode,
    /// Its step size or tolerance (`rtol = atol`).
    pub h_or_tol: f64,
    /// Wall time of the run.
    pub seconds: f64,
    /// The sampled energy-balance error.
    pub series: BalanceSeries,
}

/// The energy-balance long run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LongRun {
    /// The scene.
    pub scene: &'static str,
    /// Final time.
    pub t_final: f64,
    /// The cost budget in seconds.
    pub budget: f64,
    /// One curve per method.
    pub curves: Vec<BalanceCurve>,
}

/// Everything the report measured.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Names of the scenes run, in order.
    pub scenes: Vec<&'static str>,
    /// The methods run, in order.
    pub methods: Vec<Method>,
    /// Measured points.
    pub rows: Vec<Row>,
    /// Failed runs.
    pub failures: Vec<Failure>,
    /// Fitted orders.
    pub orders: Vec<OrderRow>,
    /// The long run, if its scene was selected.
    pub long_run: Option<LongRun>,
    /// The large models' scene names and their references' own accuracy (empty when they
    /// were not run: `--quick`, or a `--scene` filter that names none of them).
    pub large: Vec<(&'static str, f64)>,
    /// Wall time of the whole report in seconds.
    pub elapsed: f64,
    /// External baselines on the selected scenes (heyoka): committed measurements, not
    /// runs of this report.
    pub external: External,
    /// The cheapest variational run against the cheapest baseline per scene and target,
    /// timed again in alternation (see [`super::sweep::paired`]).
    pub paired: Vec<Paired>,
    /// Each adaptive-against-fixed line's middle run and its fixed curve timed again
    /// together (see [`super::equal_error`]).
    pub equal_error: Vec<Timed>,
    /// The paired variational runs on the scenes heyoka ran, timed with a new stepper and
    /// with a restarted one (see [`Restarted`]).
    pub restarted: Vec<Restarted>,
}

/// One line's middle adaptive run and the two fixed runs around its error, timed again
/// together (see [`super::sweep::time_again`] and [`super::equal_error`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Timed {
    /// The scene.
    pub scene: &'static str,
    /// The scheme.
    pub method: Method,
    /// The adaptive run's tolerance.
    pub tol: f64,
    /// Rounds timed.
    pub rounds: usize,
    /// The adaptive run's median time over the fixed curve's at its error, or why a run
    /// failed this time.
    pub ratio: Result<f64, String>,
}

/// A paired variational run ([`Paired`]) timed again two ways: built anew each run, as the
/// sweeps time every run, and restarted on one stepper (`Integrator::runs`), as heyoka's
/// integrator is built once and timed on `propagate_until` alone.
#[derive(Clone, Debug, PartialEq)]
pub struct Restarted {
    /// The scene.
    pub scene: &'static str,
    /// The error target in q.
    pub target: f64,
    /// The variational run: method, mode and `h` or tolerance.
    pub variational: (Method, Mode, f64),
    /// Median wall times, new and restarted, seconds; or why it could not be timed.
    pub seconds: Result<(f64, f64), String>,
    /// Rounds, each timing both.
    pub rounds: usize,
}

/// The cheapest variational run and the cheapest baseline run reaching one error target on
/// one scene, timed again in alternating rounds right after each other.
#[derive(Clone, Debug, PartialEq)]
pub struct Paired {
    /// The scene.
    pub scene: &'static str,
    /// The error target in q.
    pub target: f64,
    /// The variational run: method, mode and `h` or tolerance.
    pub variational: (Method, Mode, f64),
    /// The baseline run: method and tolerance.
    pub baseline: (Method, f64),
    /// Their median wall times over the rounds, seconds, or why a run failed this time.
    pub seconds: Result<(f64, f64), String>,
    /// The rounds (each runs every candidate, rotating which goes first).
    pub rounds: usize,
    /// The candidates timed in the rounds: variational runs and baseline runs.
    pub candidates: (usize, usize),
}

impl Paired {
    /// Variational time over baseline time (below 1: the variational run is faster).
    pub fn ratio(&self) -> Option<f64> {
        self.seconds.as_ref().ok().map(|(v, b)| v / b)
    }
}

impl Summary {
    /// The fixed-step rows of `method` on `scene` (every row of a baseline), by increasing
    /// `h` or tolerance.
    pub fn rows_of(&self, scene: &str, method: &Method) -> Vec<&Row> {
        self.rows_in(scene, method, Mode::Fixed)
    }

    /// The rows of `method` run in `mode` on `scene`, by increasing `h` or tolerance.
    pub fn rows_in(&self, scene: &str, method: &Method, mode: Mode) -> Vec<&Row> {
        let mut rows: Vec<&Row> = self
            .rows
            .iter()
            .filter(|r| r.scene == scene && &r.method == method && r.mode == mode)
            .collect();
        rows.sort_by(|a, b| a.h_or_tol.total_cmp(&b.h_or_tol));
        rows
    }

    /// The `(method, mode)` pairs measured, in method order, each method's adaptive runs
    /// right after its fixed ones.
    pub fn series(&self) -> Vec<(Method, Mode)> {
        let mut out = Vec::new();
        for m in &self.methods {
            for mode in [Mode::Fixed, Mode::Adaptive] {
                if self.rows.iter().any(|r| &r.method == m && r.mode == mode) {
                    out.push((*m, mode));
                }
            }
        }
        out
    }

    /// The cheapest measured run of `method` in `mode` on `scene` with `err_q ≤ target`.
    pub fn cheapest_time(
        &self,
        scene: &str,
        (method, mode): (&Method, Mode),
        target: f64,
    ) -> Option<f64> {
        self.rows_in(scene, method, mode)
            .into_iter()
            .filter(|r| r.errors()[0] <= target)
            .map(|r| r.seconds)
            .min_by(f64::total_cmp)
    }
}

/// A line of `work_precision.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorkPrecisionRecord {
    /// The scene.
    pub scene: String,
    /// The method.
    #[serde(with = "text")]
    pub method: Method,
    /// `h` or the tolerance.
    #[serde(with = "sci")]
    pub h_or_tol: f64,
    /// Steps.
    pub steps: usize,
    /// Newton iterations.
    pub newton_iters: usize,
    /// Median wall time, seconds.
    #[serde(with = "sci")]
    pub seconds: f64,
    /// Error in q.
    #[serde(with = "sci")]
    pub err_q: f64,
    /// Error in p.
    #[serde(with = "sci")]
    pub err_p: f64,
    /// Error in the energy.
    #[serde(with = "sci")]
    pub err_energy: f64,
    /// `fixed` or `adaptive` (appended, so older readers of the columns before it still work).
    #[serde(with = "text")]
    pub mode: Mode,
}

impl From<&Row> for WorkPrecisionRecord {
    fn from(r: &Row) -> Self {
        let [err_q, err_p, err_energy] = r.errors();
        WorkPrecisionRecord {
            scene: r.scene.to_string(),
            method: r.method,
            h_or_tol: r.h_or_tol,
            steps: r.steps,
            newton_iters: r.newton_iters,
            seconds: r.seconds,
            err_q,
            err_p,
            err_energy,
            mode: r.mode,
        }
    }
}

/// A line of `orders.csv`: the order in q, three decimals, empty where none was fitted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrderRecord {
    /// The scene.
    pub scene: String,
    /// The method.
    #[serde(with = "text")]
    pub method: Method,
    /// Control points `s`.
    pub stages: usize,
    /// The scheme's order.
    pub expected_order: usize,
    /// The observed order in q, `{:.3}`.
    pub observed_order: String,
    /// Why the order is blank (or off by more than 0.3); empty otherwise.
    pub note: String,
}

impl From<&OrderRow> for OrderRecord {
    fn from(o: &OrderRow) -> Self {
        OrderRecord {
            scene: o.scene.to_string(),
            method: o.method,
            stages: o.stages,
            expected_order: o.expected,
            observed_order: o.observed[0]
                .as_ref()
                .map_or(String::new(), |f| format!("{:.3}", f.order)),
            note: o.note.clone(),
        }
    }
}

/// A line of `ensemble.csv`: min, mean and max over the members.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnsembleRecord {
    /// The scene.
    pub scene: String,
    /// The method.
    #[serde(with = "text")]
    pub method: Method,
    /// Its step size or tolerance.
    #[serde(with = "sci")]
    pub h_or_tol: f64,
    /// Smallest error in q over the members.
    #[serde(with = "sci")]
    pub err_q_min: f64,
    /// Mean error in q over the members.
    #[serde(with = "sci")]
    pub err_q_mean: f64,
    /// Largest error in q over the members.
    #[serde(with = "sci")]
    pub err_q_max: f64,
    /// Smallest error in p over the members.
    #[serde(with = "sci")]
    pub err_p_min: f64,
    /// Mean error in p over the members.
    #[serde(with = "sci")]
    pub err_p_mean: f64,
    /// Largest error in p over the members.
    #[serde(with = "sci")]
    pub err_p_max: f64,
    /// Smallest error in the energy over the members.
    #[serde(with = "sci")]
    pub err_energy_min: f64,
    /// Mean error in the energy over the members.
    #[serde(with = "sci")]
    pub err_energy_mean: f64,
    /// Largest error in the energy over the members.
    #[serde(with = "sci")]
    pub err_energy_max: f64,
}

impl From<&Row> for EnsembleRecord {
    fn from(r: &Row) -> Self {
        let [q, p, e] = r.err;
        EnsembleRecord {
            scene: r.scene.to_string(),
            method: r.method,
            h_or_tol: r.h_or_tol,
            err_q_min: q.min,
            err_q_mean: q.mean,
            err_q_max: q.max,
            err_p_min: p.min,
            err_p_mean: p.mean,
            err_p_max: p.max,
            err_energy_min: e.min,
            err_energy_mean: e.mean,
            err_energy_max: e.max,
        }
    }
}

/// A line of `energy_balance.csv`: one sample of one long-run curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BalanceRecord {
    /// The scene.
    pub scene: String,
    /// The method.
    #[serde(with = "text")]
    pub method: Method,
    /// Its step size or tolerance.
    #[serde(with = "sci")]
    pub h_or_tol: f64,
    /// Wall time of the run.
    #[serde(with = "sci")]
    pub seconds: f64,
    /// The sample time.
    #[serde(with = "sci")]
    pub t: f64,
    /// `E(t) − E(0) − W(t)`.
    #[serde(with = "sci")]
    pub energy_balance: f64,
    /// `fixed` or `adaptive` (appended, as in `work_precision.csv`).
    #[serde(with = "text")]
    pub mode: Mode,
}

impl LongRun {
    /// The samples of every curve, as `energy_balance.csv` lines.
    pub fn records(&self) -> Vec<BalanceRecord> {
        let mut out = Vec::new();
        for c in &self.curves {
            for (t, b) in c.series.t.iter().zip(&c.series.balance) {
                out.push(BalanceRecord {
                    scene: self.scene.to_string(),
                    method: c.method,
                    h_or_tol: c.h_or_tol,
                    seconds: c.seconds,
                    t: *t,
                    energy_balance: *b,
                    mode: c.mode,
                });
            }
        }
        out
    }
}
