//! The work-precision report: sweeps, measurements, CSV files, plots and the README section.
//!
//! # What is measured
//!
//! For each scene × method × step size (variational, `mode = fixed`), tolerance (variational,
//! `mode = adaptive`: error control at `rtol = atol = tol`, first step `T`) or tolerance
//! (baseline, written with `mode = fixed`: the mode is the variational scheme's step control):
//! - `err_q`, `err_p`: max-norm errors of the positions and momenta at the final time against
//!   the scene's reference; `err_energy`: the absolute energy error there. For the ensemble
//!   scene these are means over the members (`ensemble.csv` has the min and max too).
//! - `seconds`: the median wall time of several repeats of the whole run ([`Plan::repeats`](crate::report::plan::Plan::repeats)
//!   adapts the count to the run time); a variational run computes its final state alone
//!   (`Integrator::final_state`), as a baseline run does. Ensemble members run in parallel with rayon (the
//!   variational ones through `Integrator::ensemble`, one stepper per worker restarted member to
//!   member), and the time is the wall time of the whole ensemble; every other run is
//!   sequential, one at a time.
//! - `steps`, `newton_iters`: totals over the run (over all members for the ensemble); for the
//!   baselines, accepted steps and nonlinear-solver iterations (0 for explicit solvers).
//!
//! A run that fails (a Newton failure at a large step, a solver error) is listed in the
//! README's failure table and left out of the CSV; no NaN is ever written as a result.
//!
//! # The long run
//!
//! On [`LONG_RUN_SCENE`] to `t = 1000`, the energy-balance error `E(t) − E(0) − W(t)` is
//! recorded for every selected method at about equal cost (see [`long_run`]).
//!
//! # The external baseline
//!
//! heyoka, an adaptive Taylor integrator, is not run by the report: [`external`] embeds its
//! timings on the non-stiff scenes from `data/baselines/heyoka.csv` (measured by
//! `scripts/heyoka_baseline.py` when the file was committed), and the cheapest-method table and
//! the error-against-time plots show them as a separate, labelled series, never in the bold
//! marks of the methods timed here.
//!
//! # The study
//!
//! One case is one method swept over its grid on one scene ([`sweep`]); cases run one at a
//! time because they are timed. The rows ([`rows`]) go to four CSV files, the figures
//! ([`figures`]) and the section ([`section`]).

use std::fs;

use crate::report::command::Command;
use crate::report::plan::{Plan, LONG_RUN_SCENE};
use crate::report::poincare;
use crate::report::study::{self, run_cases};
use crate::report::table::write_csv;
use crate::report::{readme, Method, Options, ReportError};
use crate::scenes::{self, Scene};

/// Rounds of the restarted-stepper timing (each times a new and a restarted run; the runs
/// take microseconds to a few hundred).
pub const RESTART_ROUNDS: usize = 41;

pub mod equal_error;
pub mod external;
pub mod figures;
pub mod large;
pub mod long_run;
pub mod rows;
pub mod section;
pub mod sweep;

pub use long_run::LONG_RUN_REFERENCE_H;
pub use rows::{
    BalanceCurve, BalanceRecord, EnsembleRecord, Failure, LongRun, Mode, OrderRecord, OrderRow,
    Row, Spread, Summary, WorkPrecisionRecord,
};
pub use section::TARGETS;

/// The section name (`sections/work_precision.md`).
pub const SECTION: &str = "work_precision";

/// `forced-vi-report work-precision`, also what runs without a command.
pub const COMMAND: Command = Command {
    name: "work-precision",
    about: "The work-precision report (what runs when no command is given).",
    sections: &[SECTION, poincare::SECTION],
    run: |opts, _| {
        let summary = run(opts)?;
        let mut line = String::new();
        if opts.scenes.is_empty() || opts.scenes.iter().any(|s| s == poincare::SCENE) {
            let points = poincare::run(opts)?;
            line.push_str(&format!("Poincaré section: {points} points\n"));
            readme::assemble(&opts.out)?;
        }
        line.push_str(&format!(
            "wrote {} ({} runs, {} failed) in {:.1} s",
            opts.out.join("README.md").display(),
            summary.rows.len(),
            summary.failures.len(),
            summary.elapsed
        ));
        Ok(line)
    },
};

/// Runs the work-precision report and writes its files into `opts.out`.
pub fn run(opts: &Options) -> Result<Summary, ReportError> {
    let started = std::time::Instant::now();
    let plan = Plan::new(opts.quick);
    let all = scenes::all()?;
    let names: Vec<&str> = all.iter().map(|s| s.name()).collect();
    study::check_scenes(&opts.scenes, &names)?;
    let selected: Vec<&dyn Scene> = all
        .iter()
        .map(|s| s.as_ref())
        .filter(|s| study::selected(&opts.scenes, s.name()))
        .collect();
    let methods = if opts.methods.is_empty() {
        let mut m = Method::defaults();
        if !opts.quick {
            m.extend(Method::high_orders());
        }
        m
    } else {
        opts.methods.clone()
    };
    let modes = |m: &Method| {
        let adaptive = m.is_variational().then_some(Mode::Adaptive);
        std::iter::once(Mode::Fixed).chain(adaptive)
    };
    let cases: Vec<(usize, Method, Mode)> = (0..selected.len())
        .flat_map(|i| {
            methods
                .iter()
                .flat_map(move |m| modes(m).map(move |d| (i, *m, d)))
        })
        .collect();
    let sweeps = sweep::Sweeps {
        scenes: &selected,
        plan: &plan,
    };
    let scene_names: Vec<&'static str> = selected.iter().map(|s| s.name()).collect();
    let external = external::External::heyoka()
        .map_err(|message| ReportError::Io {
            path: external::HEYOKA_PATH.into(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, message),
        })?
        .of_scenes(&scene_names);
    let mut summary = Summary {
        scenes: scene_names,
        methods: methods.clone(),
        external,
        ..Summary::default()
    };
    for swept in run_cases(&sweeps, &cases, opts.progress) {
        summary.rows.extend(swept.rows);
        summary.failures.extend(swept.failures);
    }
    let long_scene = selected.iter().find(|s| s.name() == LONG_RUN_SCENE);
    summary.long_run = long_scene
        .and_then(|s| long_run::LongRunStudy::new(*s, &plan))
        .map(|lr| {
            let fixed = methods.iter().map(|m| (*m, Mode::Fixed));
            let adaptive = methods
                .iter()
                .filter(|m| m.is_variational())
                .map(|m| (*m, Mode::Adaptive));
            let cases: Vec<_> = fixed.chain(adaptive).collect();
            let curves = run_cases(&lr, &cases, opts.progress);
            LongRun {
                scene: lr.scene.name(),
                t_final: lr.t_final,
                budget: lr.budget,
                curves: curves.into_iter().flatten().collect(),
            }
        });
    let large_selected = [large::FPU_CHAIN, large::LATTICE_2D]
        .iter()
        .any(|n| opts.scenes.is_empty() || opts.scenes.iter().any(|s| s == n));
    if !opts.quick && large_selected {
        let (rows, failures, accuracy) = large::measure();
        summary.rows.extend(rows);
        summary.failures.extend(failures);
        summary.large = accuracy;
    }
    for scene in &selected {
        for target in section::TARGETS {
            summary
                .paired
                .extend(sweep::paired(*scene, &summary, target, &plan));
        }
    }
    // The paired variational runs again, restarted on one stepper, where heyoka (timed on
    // an integrator built once) ran the scene alone.
    for p in &summary.paired {
        let Some(scene) = selected.iter().find(|s| s.name() == p.scene) else {
            continue;
        };
        if scene.members() != 1 || summary.external.rows_of(p.scene).is_empty() {
            continue;
        }
        let (method, mode, x) = p.variational;
        let Some(scheme) = method.scheme() else {
            continue;
        };
        let rounds = RESTART_ROUNDS;
        let seconds = scene
            .time_restarted(&scheme, mode == Mode::Adaptive, x, rounds)
            .map_err(|e| e.to_string());
        summary.restarted.push(rows::Restarted {
            scene: p.scene,
            target: p.target,
            variational: p.variational,
            seconds,
            rounds,
        });
    }
    for scene in &selected {
        let scale = sweep::reference_scale(*scene)[0];
        let at_floor = |e: f64| crate::report::orders::at_floor(e, scale);
        for line in equal_error::lines(&summary, scene.name(), at_floor) {
            let Some((a, f0, f1, x)) = equal_error::middle_runs(&summary, &line, at_floor) else {
                continue;
            };
            let rounds = plan
                .repeats(a.seconds.max(f0.seconds).max(f1.seconds))
                .max(plan.max_repeats.min(5));
            let ratio = sweep::time_again(*scene, &[a, f0, f1], rounds).and_then(|t| {
                equal_error::ratio_from(&t, x).ok_or_else(|| "no positive time".to_string())
            });
            summary.equal_error.push(equal_error::Timed {
                scene: line.scene,
                method: line.method,
                tol: a.h_or_tol,
                rounds,
                ratio,
            });
        }
    }
    sweep::fit_orders(&selected, &mut summary);
    summary.elapsed = started.elapsed().as_secs_f64();
    write_outputs(opts, &plan, &selected, &summary)?;
    Ok(summary)
}

/// Writes the four CSV files, the figures and the section.
fn write_outputs(
    opts: &Options,
    plan: &Plan,
    scenes: &[&dyn Scene],
    summary: &Summary,
) -> Result<(), ReportError> {
    let out = &opts.out;
    fs::create_dir_all(out).map_err(ReportError::io(out))?;
    let records: Vec<WorkPrecisionRecord> = summary.rows.iter().map(Into::into).collect();
    write_csv(&out.join("work_precision.csv"), &records)?;
    let is_ensemble = |r: &&Row| {
        scenes
            .iter()
            .any(|s| s.name() == r.scene && s.members() > 1)
    };
    let ensemble: Vec<EnsembleRecord> = summary
        .rows
        .iter()
        .filter(is_ensemble)
        .map(Into::into)
        .collect();
    write_csv(&out.join("ensemble.csv"), &ensemble)?;
    let orders: Vec<OrderRecord> = summary.orders.iter().map(Into::into).collect();
    write_csv(&out.join("orders.csv"), &orders)?;
    let balance = summary
        .long_run
        .as_ref()
        .map_or(Vec::new(), LongRun::records);
    write_csv(&out.join("energy_balance.csv"), &balance)?;

    let figures = figures::draw_all(out, scenes, summary)?;
    let md = section::markdown_section(&section::Inputs {
        opts,
        plan,
        scenes,
        summary,
        figures: &figures,
    });
    readme::write_section(out, SECTION, &md)
}
