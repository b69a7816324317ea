//! The `stability` command: stiff and extreme cases (DESIGN §6).
//!
//! Every case runs the variational integrator with step subdivision allowed
//! ([`MAX_SUBDIVISIONS`] levels, so a failed step is retried as up to 64 substeps) and records
//! one row of `stability.csv`:
//!
//! ```text
//! scene,method,h,outcome,steps_done,max_newton_iters,err_final,max_energy_balance_err,mode,tol
//! ```
//!
//! - `mode` is `fixed` (step `h`, subdivision allowed) or `adaptive`: error control at
//!   `rtol = atol = tol` (`tol` is empty in fixed rows), first step `h` = the whole interval,
//!   no subdivision (the controller rejects and shrinks failed steps). Adaptive rows follow
//!   the fixed ones.
//!
//! - `outcome` is `ok`, `recovered` (the run finished but at least one step needed
//!   subdivision) or `failed:<kind>` with the [`forced_vi::Error::kind`] of the error that
//!   stopped it. Two kinds come from this module, not from the runtime: `failed:panic` (the
//!   run panicked; the panic is caught so that the sweep goes on) and
//!   `failed:non_finite_result` (the runtime reported success but the final state, its error
//!   or the energy balance is not finite). Neither should ever appear.
//! - `steps_done`: steps completed (of the output grid; a subdivided step counts once).
//! - `max_newton_iters`: the largest Newton iteration count of one step (over all attempts).
//! - `err_final`: max-norm error of the positions at the final time against the scene's
//!   reference; `NaN` for a failed run.
//! - `max_energy_balance_err`: the largest `|E(t_k) − E(0) − W_k|` over the steps done.
//!
//! On the same stiff scenes the stiff baselines ([`Baseline::Bdf`], [`Baseline::Esdirk34`])
//! run over a ladder of tolerances, and the section compares the cost (wall time) at which
//! each method reaches a given error: the cheapest candidates by the sweeps' times are timed
//! again after the sweeps, one after the other, to their final states alone
//! ([`StiffTimes`]).
//!
//! # The study
//!
//! Two studies share the scenes of `scenes` (`problem` runs one case): the variational
//! runs, one case per scene × scheme × step size, and the stiff-baseline runs, one per scene ×
//! solver × tolerance. Both run in parallel (rayon), longest first. `section` writes the
//! Markdown.

use forced_vi::SchemeId;

use crate::baselines::Baseline;
use crate::report::study::{self, run_cases, Study};
use crate::report::table::write_csv;
use crate::report::{readme, Command, Method, Options, ReportError};

mod adaptive_section;
mod problem;
mod remarks;
pub mod rows;
mod scenes;
mod section;
mod tally;

pub use adaptive_section::stiff_cost;
pub use rows::{BaselineRow, Outcome, Row, StabilityRecord, StiffTimes, Summary, MAX_SUBDIVISIONS};
pub use scenes::{CHAIN_DOF, OVERDAMPED_ZETA_100, SCENES};

use scenes::{Grid, Planned};

/// The section name (`sections/stability.md`).
pub const SECTION: &str = "stability";

/// The variational runs: one case per scene (index) × scheme × step size.
struct VariationalRuns<'a>(&'a [&'a Planned]);

impl Study for VariationalRuns<'_> {
    type Case = (usize, SchemeId, f64);
    type Row = Row;
    const PARALLEL: bool = true;

    fn label(&self, &(i, id, h): &Self::Case) -> String {
        format!("{} {id} {h:.1e}", self.0[i].0.name())
    }

    fn run(&self, &(i, id, h): &Self::Case) -> Row {
        self.0[i].0.variational(id, h)
    }

    fn panicked(&self, &(i, id, h): &Self::Case) -> Row {
        Row {
            scene: self.0[i].0.name(),
            method: id.to_string(),
            h,
            tol: None,
            outcome: Outcome::Failed("panic".into()),
            steps_done: 0,
            max_newton_iters: 0,
            err_final: f64::NAN,
            max_energy_balance_err: f64::NAN,
            subdivided_steps: 0,
            rejected_steps: 0,
            seconds: 0.0,
        }
    }
}

/// The adaptive variational runs: one case per scene (index) × scheme × tolerance.
struct AdaptiveRuns<'a>(&'a [&'a Planned]);

impl Study for AdaptiveRuns<'_> {
    type Case = (usize, SchemeId, f64);
    type Row = Row;
    const PARALLEL: bool = true;

    fn label(&self, &(i, id, tol): &Self::Case) -> String {
        format!("{} {id} adaptive {tol:.0e}", self.0[i].0.name())
    }

    fn run(&self, &(i, id, tol): &Self::Case) -> Row {
        self.0[i].0.adaptive(id, tol)
    }

    fn panicked(&self, &(i, id, tol): &Self::Case) -> Row {
        Row {
            tol: Some(tol),
            ..VariationalRuns(self.0).panicked(&(i, id, f64::NAN))
        }
    }
}

/// The stiff-baseline runs: one case per scene (index) × solver × tolerance.
struct BaselineRuns<'a>(&'a [&'a Planned]);

impl Study for BaselineRuns<'_> {
    type Case = (usize, Baseline, f64);
    type Row = BaselineRow;
    const PARALLEL: bool = true;

    fn label(&self, &(i, b, tol): &Self::Case) -> String {
        format!("{} {b} {tol:.0e}", self.0[i].0.name())
    }

    fn run(&self, &(i, b, tol): &Self::Case) -> BaselineRow {
        self.0[i].0.baseline(b, tol)
    }

    fn panicked(&self, &(i, b, tol): &Self::Case) -> BaselineRow {
        BaselineRow {
            scene: self.0[i].0.name(),
            solver: b,
            tol,
            err_final: f64::NAN,
            steps: 0,
            seconds: 0.0,
            failure: Some("panic".into()),
        }
    }
}

/// The variational cases, longest runs first so that the cores finish together.
fn variational_cases(selected: &[&Planned], methods: &[Method]) -> Vec<(usize, SchemeId, f64)> {
    scheme_cases(selected, methods, |grid| (&grid.methods, &grid.hs))
}

/// The adaptive cases: the scene's schemes (or `--method`) × its adaptive tolerances,
/// tightest first.
fn adaptive_cases(selected: &[&Planned], methods: &[Method]) -> Vec<(usize, SchemeId, f64)> {
    let mut cases = scheme_cases(selected, methods, |grid| {
        (&grid.adaptive_methods, &grid.adaptive_tols)
    });
    let second_order = |id: SchemeId| matches!(id, SchemeId::Lobatto(2) | SchemeId::Midpoint);
    cases.retain(|&(_, id, tol)| !second_order(id) || tol >= ORDER2_ADAPTIVE_FLOOR);
    cases
}

/// The second-order schemes (`lobatto2`, `midpoint`) run adaptively down to this tolerance
/// only: on stiff van der Pol, with the error per unit step over T = 2000, lobatto2 needs
/// 1.6·10⁷ steps at 1e-4 and midpoint 7.3·10⁶ (`report/stability.csv`), each ending within
/// its tolerance; at 1e-6 they took 1.2·10⁸ and 2.0·10⁷ (measured 2026-11-25, before
/// later changes to the controller).
pub const ORDER2_ADAPTIVE_FLOOR: f64 = 1e-4;

/// Every scene × scheme × parameter, smallest parameter first. `pick` gives a scene's
/// schemes and parameters (step sizes or tolerances); `--method` replaces the schemes.
fn scheme_cases(
    selected: &[&Planned],
    methods: &[Method],
    pick: impl Fn(&Grid) -> (&Vec<SchemeId>, &Vec<f64>),
) -> Vec<(usize, SchemeId, f64)> {
    let filter: Vec<SchemeId> = methods
        .iter()
        .filter_map(|m| match m {
            Method::Variational(id) => Some(*id),
            Method::Baseline(_) => None,
        })
        .collect();
    let mut jobs = Vec::new();
    for (i, (_, grid)) in selected.iter().enumerate() {
        let (ids, params) = pick(grid);
        let ids = if filter.is_empty() { ids } else { &filter };
        for &id in ids {
            jobs.extend(params.iter().map(|&x| (i, id, x)));
        }
    }
    jobs.sort_by(|a, b| a.2.total_cmp(&b.2));
    jobs
}

/// The baseline cases: the stiff solvers, or the implicit ones among `--method`.
fn baseline_cases(selected: &[&Planned], methods: &[Method]) -> Vec<(usize, Baseline, f64)> {
    let solvers: Vec<Baseline> = if methods.is_empty() {
        vec![Baseline::Bdf, Baseline::Esdirk34]
    } else {
        methods
            .iter()
            .filter_map(|m| match m {
                Method::Baseline(b) if b.is_implicit() => Some(*b),
                _ => None,
            })
            .collect()
    };
    let mut jobs = Vec::new();
    for (i, (_, grid)) in selected.iter().enumerate() {
        for &b in &solvers {
            jobs.extend(grid.tols.iter().map(|&tol| (i, b, tol)));
        }
    }
    jobs
}

/// `forced-vi-report stability`.
pub const COMMAND: Command = Command {
    name: "stability",
    about: "Stiff and extreme cases: writes stability.csv and the stability section.",
    sections: &[SECTION],
    run: |opts, _| {
        let s = run(opts)?;
        let done = s
            .rows
            .iter()
            .filter(|r| !r.outcome.to_string().starts_with("failed"))
            .count();
        Ok(format!(
            "wrote {} ({} runs, {} finished) in {:.1} s",
            opts.out.join("stability.csv").display(),
            s.rows.len(),
            done,
            s.elapsed
        ))
    },
};

/// Runs the stability sweep and the stiff-baseline comparison, writes `stability.csv` and
/// the `stability` section.
pub fn run(opts: &Options) -> Result<Summary, ReportError> {
    let started = std::time::Instant::now();
    study::check_scenes(&opts.scenes, &SCENES)?;
    let planned = scenes::plan(opts.quick)?;
    let selected: Vec<&Planned> = planned
        .iter()
        .filter(|(c, _)| study::selected(&opts.scenes, c.name()))
        .collect();
    let jobs = variational_cases(&selected, &opts.methods);
    let mut rows = run_cases(&VariationalRuns(&selected), &jobs, opts.progress);
    let pos = |s: &str| SCENES.iter().position(|x| *x == s).unwrap_or(SCENES.len());
    rows.sort_by(|a, b| {
        (pos(a.scene), &a.method)
            .cmp(&(pos(b.scene), &b.method))
            .then(b.h.total_cmp(&a.h))
    });
    let ajobs = adaptive_cases(&selected, &opts.methods);
    let mut adaptive = run_cases(&AdaptiveRuns(&selected), &ajobs, opts.progress);
    adaptive.sort_by(|a, b| {
        (pos(a.scene), &a.method)
            .cmp(&(pos(b.scene), &b.method))
            .then(b.tol.unwrap_or(0.0).total_cmp(&a.tol.unwrap_or(0.0)))
    });
    let bjobs = baseline_cases(&selected, &opts.methods);
    let baselines = run_cases(&BaselineRuns(&selected), &bjobs, opts.progress);

    std::fs::create_dir_all(&opts.out).map_err(ReportError::io(&opts.out))?;
    let records: Vec<StabilityRecord> = rows.iter().chain(&adaptive).map(Into::into).collect();
    write_csv(&opts.out.join("stability.csv"), &records)?;
    let cases: Vec<&dyn problem::Case> = selected.iter().map(|(c, _)| &**c).collect();
    let stiff_times = adaptive_section::retime(&adaptive, &baselines, &cases);
    let summary = Summary {
        rows,
        adaptive,
        baselines,
        stiff_times,
        elapsed: started.elapsed().as_secs_f64(),
    };
    let md = section::markdown_section(&summary, &selected, opts.quick);
    readme::write_section(&opts.out, SECTION, &md)?;
    Ok(summary)
}
