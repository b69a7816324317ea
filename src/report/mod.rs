//! The report: what `cargo run --release` writes into `report/`.
//!
//! # Layout of the output folder
//!
//! ```text
//! report/
//!   README.md              assembled from sections/ (never edit by hand)
//!   sections/<name>.md     one Markdown section per command
//!   work_precision.csv     scene,method,h_or_tol,steps,newton_iters,seconds,err_q,err_p,err_energy,mode
//!   orders.csv             scene,method,stages,expected_order,observed_order,note
//!   ensemble.csv           min/mean/max errors over the ensemble members
//!   ensemble_throughput.csv  member steps per second against threads
//!   energy_balance.csv     the long run's energy-balance error against time
//!   stability.csv          the stability report's runs (`stability`)
//!   step_cost.csv          the step-cost report's runs (`step-cost`)
//!   *.svg                  plots, embedded in README.md
//! ```
//!
//! # Commands, and how they share one README
//!
//! Each command of the `forced-vi-report` binary is a [`Command`] (name, help line, README
//! sections, run function) defined in its own module and listed once in [`COMMANDS`]; the
//! binary's command line and the section order of `README.md` both come from that list. A
//! command writes its own files plus its Markdown sections with [`readme::write_section`],
//! which stores each as `sections/<name>.md` and regenerates `README.md` by concatenating a
//! fixed header and every section file present, in the order of [`COMMANDS`] (unknown names
//! follow in alphabetical order). A command therefore replaces only its own sections and never
//! has to read or merge the others. To add a command: a module with its `COMMAND` constant,
//! and one line in [`COMMANDS`]. Section files start with a `## ` heading; they may link to
//! files in the report folder by their bare names.
//!
//! # Studies and their shared parts
//!
//! Every command is a study ([`study::Study`]): planned cases, run by [`study::run_cases`]
//! (rayon or one at a time, a progress bar, a catch for panics) into typed rows, which are
//! written as CSV ([`table::write_csv`]: serde rows, the header from the field names), a
//! Markdown section ([`table::markdown`]: rows and column specs) and figures ([`chart`] with the
//! styles of [`style`]). Timing goes through [`timing`], observed orders through [`orders`].
//! A command lives in its own folder: `rows.rs` (rows and CSV records), the cases and how one
//! runs, `section.rs`, and `mod.rs` with `run`.
//!
//! # The work-precision report
//!
//! [`work_precision::run`] sweeps every selected scene ([`crate::scenes`]) with every selected
//! method: the variational schemes over a grid of step sizes, the baselines
//! ([`crate::baselines`]) over a ladder of tolerances. See [`plan`] for the grids, [`orders`]
//! for how observed orders are fitted and [`work_precision`] for what is measured and timed.

pub mod chart;
pub mod command;
pub mod orders;
pub mod plan;
pub mod poincare;
pub mod readme;
pub mod stability;
pub mod step_cost;
pub mod study;
pub mod style;
pub mod table;
pub mod timing;
pub mod work_precision;

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use forced_vi::{Scheme, SchemeId};

pub use command::{Command, Hooks};

use crate::baselines::Baseline;
use crate::scenes::SceneError;

/// Every command of `forced-vi-report`, in README order; the first is what runs without a
/// command. A new command adds its module's `COMMAND` here (see [`command`]).
pub const COMMANDS: &[Command] = &[
    work_precision::COMMAND,
    stability::COMMAND,
    step_cost::COMMAND,
];

/// A method the report can run: a variational scheme or a baseline solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// A forced variational integrator, swept over step sizes `h`.
    Variational(SchemeId),
    /// A baseline ODE solver, swept over tolerances.
    Baseline(Baseline),
}

impl Method {
    /// The default methods, in report order.
    pub fn defaults() -> Vec<Method> {
        let mut v: Vec<Method> = (2..=5)
            .map(|s| Method::Variational(SchemeId::Lobatto(s)))
            .collect();
        v.push(Method::Variational(SchemeId::Midpoint));
        v.extend(Baseline::ALL.map(Method::Baseline));
        v
    }

    /// The higher orders the full report adds to [`Method::defaults`]: `lobatto6` and
    /// `lobatto7` (orders 10 and 12), whose fits need the full grids (see
    /// [`plan::Plan::step_sizes`]).
    pub fn high_orders() -> Vec<Method> {
        (6..=7)
            .map(|s| Method::Variational(SchemeId::Lobatto(s)))
            .collect()
    }

    /// Whether this is a variational scheme.
    pub fn is_variational(&self) -> bool {
        matches!(self, Method::Variational(_))
    }

    /// The name used on the command line and in the report.
    pub fn name(&self) -> String {
        match self {
            Method::Variational(id) => id.to_string(),
            Method::Baseline(b) => b.name().to_string(),
        }
    }

    /// The scheme of a variational method.
    pub fn scheme(&self) -> Option<Scheme> {
        match self {
            Method::Variational(id) => Scheme::new(*id).ok(),
            Method::Baseline(_) => None,
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for Method {
    type Err = ReportError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        if let Ok(b) = s.parse::<Baseline>() {
            return Ok(Method::Baseline(b));
        }
        match s.parse::<SchemeId>() {
            Ok(id) => Ok(Method::Variational(id)),
            Err(e) => Err(ReportError::UnknownMethod {
                name: s.to_string(),
                reason: e.to_string(),
            }),
        }
    }
}

/// What to run and where to write it.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// The output folder (default `report`).
    pub out: PathBuf,
    /// The reduced grid (under a minute on two cores).
    pub quick: bool,
    /// Scene names to run; empty means all.
    pub scenes: Vec<String>,
    /// Methods to run; empty means [`Method::defaults`].
    pub methods: Vec<Method>,
    /// Show a progress bar on a terminal.
    pub progress: bool,
}

impl Default for Options {
    /// `report/`, the full grid, all scenes and default methods, a progress bar.
    fn default() -> Self {
        Options {
            out: PathBuf::from("report"),
            quick: false,
            scenes: Vec::new(),
            methods: Vec::new(),
            progress: true,
        }
    }
}

/// Why the report could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// `--scene` names a scene that is not registered.
    #[error("unknown scene `{name}` (known: {known})")]
    UnknownScene {
        /// The requested name.
        name: String,
        /// The registered names, comma-separated.
        known: String,
    },
    /// `--method` names neither a scheme nor a baseline.
    #[error("unknown method `{name}`: {reason} (baselines: dop853, tsit45, bdf, esdirk34)")]
    UnknownMethod {
        /// The requested name.
        name: String,
        /// Why it did not parse as a scheme.
        reason: String,
    },
    /// A scene could not be built.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// Reading or writing a report file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A plot could not be drawn.
    #[error("plot {path}: {message}")]
    Plot {
        /// The SVG file.
        path: PathBuf,
        /// The drawing backend's message.
        message: String,
    },
}

impl ReportError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> ReportError {
        let path = path.into();
        move |source| ReportError::Io { path, source }
    }
}
