//! What the step-cost study measures: its rows and the record of `step_cost.csv`.

use serde::{Deserialize, Serialize};

use super::compile::CompileTimes;
use crate::report::table::sci;

pub use crate::report::command::AllocCounter;

/// One row of `step_cost.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// `coupled_van_der_pol`, `fpu_chain` or `lattice_2d`.
    pub scene: String,
    /// The scheme.
    pub method: String,
    /// Degrees of freedom.
    pub n: usize,
    /// `full` (every record with velocity, energy, energy balance and Newton statistics,
    /// through `output::each_step`) or `none` (the final state only, `Integrator::final_state`).
    pub diagnostics: &'static str,
    /// `dense` or `sparse`: the linear algebra of the step.
    pub path: &'static str,
    /// Median ns per step with the `#[forced_lagrangian]` kernels (`None`: not measured).
    pub generated: Option<f64>,
    /// Median ns per step with the hand-written kernels, where there are some.
    pub handwritten: Option<f64>,
    /// Newton iterations per step (generated model).
    pub iters: Option<f64>,
    /// Heap allocations per step (generated model), if an allocation counter was given.
    pub allocs: Option<f64>,
    /// Why the row has no measurement, or other remarks.
    pub note: String,
}

impl Row {
    /// generated ÷ hand-written.
    pub fn ratio(&self) -> Option<f64> {
        Some(self.generated? / self.handwritten?)
    }
}

/// Peak RSS readings of the streamed run.
#[derive(Clone, Debug, PartialEq)]
pub struct Memory {
    /// The scheme streamed.
    pub method: String,
    /// VmHWM in KiB before the run.
    pub before_kib: Option<u64>,
    /// `(steps, VmHWM in KiB)` after that many steps.
    pub at: Vec<(usize, Option<u64>)>,
    /// Wall time of the whole stream, seconds.
    pub seconds: f64,
}

/// Everything the command measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// The CSV rows.
    pub rows: Vec<Row>,
    /// The fitted exponents of time per step against n for n ≥ 32.
    pub exponents: Vec<Exponent>,
    /// Peak RSS of the largest sparse runs.
    pub peaks: Vec<PeakRss>,
    /// The compile-time measurement, or why there is none.
    pub compile: Result<CompileTimes, String>,
    /// The first answer on a new large model, against heyoka, or why it was not measured.
    pub first_run: Result<super::first_run::FirstRun, String>,
    /// The streamed-memory measurement.
    pub memory: Memory,
    /// Whether the hand-written and generated runs took the same Newton iterations.
    pub same_iterations: bool,
    /// The ensemble throughput, or why it was not measured.
    pub ensemble: Result<super::ensemble::Throughput, String>,
    /// Wall time of the command.
    pub elapsed: f64,
}

/// A line of `step_cost.csv`: times in ns per step, empty where not measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepCostRecord {
    /// The scene.
    pub scene: String,
    /// The scheme.
    pub method: String,
    /// Degrees of freedom.
    pub n: usize,
    /// `full` or `none`: whether the run computed the per-step records and diagnostics.
    pub diagnostics: String,
    /// `dense` or `sparse`.
    pub path: String,
    /// Generated kernels, ns per step.
    #[serde(with = "sci::opt")]
    pub ns_per_step_generated: Option<f64>,
    /// Hand-written kernels, ns per step.
    #[serde(with = "sci::opt")]
    pub ns_per_step_handwritten: Option<f64>,
    /// generated ÷ hand-written.
    #[serde(with = "sci::opt")]
    pub ratio: Option<f64>,
    /// Newton iterations per step.
    #[serde(with = "sci::opt")]
    pub newton_iters_per_step: Option<f64>,
    /// Heap allocations per step.
    #[serde(with = "sci::opt")]
    pub allocs_per_step: Option<f64>,
}

impl From<&Row> for StepCostRecord {
    fn from(r: &Row) -> Self {
        StepCostRecord {
            scene: r.scene.clone(),
            method: r.method.clone(),
            n: r.n,
            diagnostics: r.diagnostics.into(),
            path: r.path.into(),
            ns_per_step_generated: r.generated,
            ns_per_step_handwritten: r.handwritten,
            ratio: r.ratio(),
            newton_iters_per_step: r.iters,
            allocs_per_step: r.allocs,
        }
    }
}

/// Peak RSS of the sparse path at the largest size measured, per scene and scheme.
#[derive(Clone, Debug, PartialEq)]
pub struct PeakRss {
    /// The scene.
    pub scene: String,
    /// The scheme.
    pub method: String,
    /// Degrees of freedom.
    pub n: usize,
    /// VmHWM in KiB after resetting it before the run.
    pub kib: u64,
}

/// A fitted exponent of time per step against n.
#[derive(Clone, Debug, PartialEq)]
pub struct Exponent {
    /// The scene.
    pub scene: String,
    /// The scheme.
    pub method: String,
    /// `dense` or `sparse`.
    pub path: &'static str,
    /// The slope of log(time per step) against log(n).
    pub exponent: f64,
    /// The sizes fitted.
    pub sizes: Vec<usize>,
}
