//! The work-precision report: sweeps, measurements, CSV files, plots and the README section.
//!
//! # What is measured
//!
//! For each scene × method × step size (variational) or tolerance (baseline):
//! - `err_q`, `err_p`: max-norm errors of the positions and momenta at the final time against
//!   the scene's reference; `err_energy`: the absolute energy error there. For the ensemble
//!   scene these are means over the members (`ensemble.csv` has the min and max too).
//! - `seconds`: the median wall time of several repeats of the whole run ([`Plan::repeats`]
//!   adapts the count to the run time). Ensemble members run in parallel with rayon, and the
//!   time is the wall time of the whole ensemble; every other run is sequential, one at a time.
//! - `steps`, `newton_iters`: totals over the run (over all members for the ensemble); for the
//!   baselines, accepted steps and nonlinear-solver iterations (0 for explicit solvers).
//!
//! A run that fails (a Newton failure at a large step, a solver error) is listed in the
//! README's failure table and left out of the CSV; no NaN is ever written as a result.
//!
//! # The long run
//!
//! On [`LONG_RUN_SCENE`] to `t = 1000`, the energy-balance error `E(t) − E(0) − W(t)` is
//! recorded for every selected method at about equal cost: the budget is the wall time of
//! `lobatto3` with `h = 0.02` ([`LONG_RUN_REFERENCE_H`]). Each variational scheme gets the step
//! size whose cost meets the budget (predicted from a pilot run over a tenth of the time, then
//! corrected once); each baseline gets, from a ladder of tolerances `10^(−2 − k/2)`, the one
//! whose measured time is nearest to it.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;
use std::time::Instant;

use forced_vi::{Scheme, SchemeId};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;

use super::orders::{self, Fit};
use super::plan::{Plan, LONG_RUN_SCENE, PAPER_SCENE};
use super::{csv_float, plots, readme, Method, Options, ReportError};
use crate::scenes::{self, BalanceSeries, Outcome, Scene, SceneError};

/// The column names of `work_precision.csv`.
pub const WORK_PRECISION_HEADER: &str =
    "scene,method,h_or_tol,steps,newton_iters,seconds,err_q,err_p,err_energy";
/// The column names of `orders.csv`.
pub const ORDERS_HEADER: &str = "scene,method,stages,expected_order,observed_order";
/// The column names of `ensemble.csv`.
pub const ENSEMBLE_HEADER: &str = "scene,method,h_or_tol,err_q_min,err_q_mean,err_q_max,\
err_p_min,err_p_mean,err_p_max,err_energy_min,err_energy_mean,err_energy_max";
/// The column names of `energy_balance.csv`.
pub const ENERGY_BALANCE_HEADER: &str = "scene,method,h_or_tol,seconds,t,energy_balance";

/// The error targets of the "cheapest method" table.
pub const TARGETS: [f64; 2] = [1e-6, 1e-10];

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

/// One measured point: a row of `work_precision.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The scene.
    pub scene: &'static str,
    /// The method.
    pub method: Method,
    /// `h` for variational schemes, the tolerance for baselines.
    pub h_or_tol: f64,
    /// Steps (summed over members).
    pub steps: usize,
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
}

/// One curve of the energy-balance plot.
#[derive(Clone, Debug, PartialEq)]
pub struct BalanceCurve {
    /// The method.
    pub method: Method,
    /// Its step size or tolerance.
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
    /// Wall time of the whole report in seconds.
    pub elapsed: f64,
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        xs[n / 2]
    } else {
        0.5 * (xs[n / 2 - 1] + xs[n / 2])
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().map(|x| x.abs()).fold(0.0, f64::max)
}

/// The size of the reference values of a scene: `[|q|∞, |p|∞, |E|]` over all members.
fn reference_scale(scene: &dyn Scene) -> [f64; 3] {
    let mut s = [0.0f64; 3];
    for m in 0..scene.members() {
        if let Some(r) = scene.reference(m) {
            s[0] = s[0].max(max_abs(&r.q));
            s[1] = s[1].max(max_abs(&r.p));
            s[2] = s[2].max(r.energy.abs());
        }
    }
    s
}

/// Runs one method at one `h` or tolerance on every member of a scene.
fn run_members(
    scene: &dyn Scene,
    method: &Method,
    scheme: Option<&Scheme>,
    x: f64,
) -> Result<Vec<Outcome>, SceneError> {
    let one = |member: usize| match (method, scheme) {
        (Method::Variational(_), Some(s)) => scene.run_variational(s, x, member),
        (Method::Baseline(b), _) => scene.run_baseline(*b, x, member),
        (Method::Variational(id), None) => Err(SceneError::Variational(
            forced_vi::SchemeError::Unknown(id.to_string()).into(),
        )),
    };
    if scene.members() == 1 {
        Ok(vec![one(0)?])
    } else {
        (0..scene.members()).into_par_iter().map(one).collect()
    }
}

/// Measures one point: errors, steps and the median wall time. Returns the row and the time of
/// the first repeat.
fn measure(
    scene: &dyn Scene,
    method: &Method,
    scheme: Option<&Scheme>,
    x: f64,
    plan: &Plan,
) -> Result<(Row, f64), String> {
    let start = Instant::now();
    let outcomes = run_members(scene, method, scheme, x).map_err(|e| e.to_string())?;
    let first = start.elapsed().as_secs_f64();
    let mut times = vec![first];
    for _ in 1..plan.repeats(first) {
        let t = Instant::now();
        run_members(scene, method, scheme, x).map_err(|e| e.to_string())?;
        times.push(t.elapsed().as_secs_f64());
    }
    let mut member_errs: [Vec<f64>; 3] = Default::default();
    for (m, o) in outcomes.iter().enumerate() {
        let r = scene
            .reference(m)
            .ok_or_else(|| format!("no reference for member {m}"))?;
        let e = [
            max_abs_diff(&o.end.q, &r.q),
            max_abs_diff(&o.end.p, &r.p),
            (o.end.energy - r.energy).abs(),
        ];
        if !e.iter().all(|x| x.is_finite()) {
            return Err(format!("non-finite result for member {m}"));
        }
        for (k, ek) in e.into_iter().enumerate() {
            member_errs[k].push(ek);
        }
    }
    let spread = |v: &Vec<f64>| Spread {
        min: v.iter().copied().fold(f64::INFINITY, f64::min),
        mean: v.iter().sum::<f64>() / v.len() as f64,
        max: v.iter().copied().fold(0.0, f64::max),
    };
    let row = Row {
        scene: scene.name(),
        method: *method,
        h_or_tol: x,
        steps: outcomes.iter().map(|o| o.steps).sum(),
        newton_iters: outcomes.iter().map(|o| o.newton_iterations).sum(),
        seconds: median(times),
        err: [
            spread(&member_errs[0]),
            spread(&member_errs[1]),
            spread(&member_errs[2]),
        ],
    };
    Ok((row, first))
}

fn progress_bar(total: u64, show: bool) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(
        Some(total),
        if show {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs  {msg}")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// Sweeps one method over its grid on one scene.
fn sweep(scene: &dyn Scene, method: &Method, plan: &Plan, pb: &ProgressBar, summary: &mut Summary) {
    let scheme = method.scheme();
    let grid = match method {
        Method::Variational(_) => plan.step_sizes(scene.t_final()),
        Method::Baseline(_) => plan.tolerances.clone(),
    };
    let scale = reference_scale(scene);
    let keep_tail = plan.full_paper_tail && method.is_variational() && scene.name() == PAPER_SCENE;
    let mut floor_run = 0;
    for (i, &x) in grid.iter().enumerate() {
        pb.set_message(format!("{} {} {}", scene.name(), method, short(x)));
        match measure(scene, method, scheme.as_ref(), x, plan) {
            Ok((row, first)) => {
                let e = row.errors();
                if orders::at_floor(e[0], scale[0]) && orders::at_floor(e[1], scale[1]) {
                    floor_run += 1;
                } else {
                    floor_run = 0;
                }
                summary.rows.push(row);
                let done =
                    !keep_tail && (floor_run >= plan.floor_points || first > plan.max_run_seconds);
                if done {
                    pb.inc((grid.len() - i) as u64);
                    return;
                }
            }
            Err(message) => summary.failures.push(Failure {
                scene: scene.name(),
                method: *method,
                h_or_tol: x,
                message,
            }),
        }
        pb.inc(1);
    }
}

fn short(x: f64) -> String {
    format!("{x:.3e}")
}

/// Fits the observed orders of every variational method on every scene.
fn fit_orders(scenes: &[&dyn Scene], summary: &mut Summary) {
    for scene in scenes {
        let scale = reference_scale(*scene);
        for method in summary.methods.clone() {
            let Method::Variational(id) = method else {
                continue;
            };
            let Ok(scheme) = Scheme::new(id) else {
                continue;
            };
            let observed = [0, 1, 2].map(|k| {
                let pts: Vec<(f64, f64)> = summary
                    .rows
                    .iter()
                    .filter(|r| r.scene == scene.name() && r.method == method)
                    .map(|r| (r.h_or_tol, r.errors()[k]))
                    .collect();
                orders::observed_order(&pts, scale[k])
            });
            summary.orders.push(OrderRow {
                scene: scene.name(),
                method,
                stages: scheme.stages(),
                expected: scheme.order(),
                observed,
            });
        }
    }
}

/// The step size of the reference run that sets the long run's cost budget.
pub const LONG_RUN_REFERENCE_H: f64 = 0.02;

/// The energy-balance long run at about equal cost (see the module docs).
fn long_run(scene: &dyn Scene, methods: &[Method], plan: &Plan, pb: &ProgressBar) -> LongRun {
    let t_final = plan.long_run_t;
    let samples = plan.long_run_samples;
    let mut out = LongRun {
        scene: scene.name(),
        t_final,
        ..LongRun::default()
    };
    let timed_vi = |scheme: &Scheme, h: f64, t: f64| {
        let start = Instant::now();
        let r = scene.balance_variational(scheme, h, t, samples);
        (r, start.elapsed().as_secs_f64())
    };
    let Ok(reference) = Scheme::new(SchemeId::Lobatto(3)) else {
        return out;
    };
    pb.set_message(format!("{} long run: budget", scene.name()));
    let budget = median(
        (0..3)
            .map(|_| timed_vi(&reference, LONG_RUN_REFERENCE_H, t_final).1)
            .collect(),
    );
    out.budget = budget;
    // Whole step counts, so that every run ends exactly at t_final.
    let step_for = |steps: f64| t_final / steps.round().clamp(t_final / 0.25, 1e8);
    for method in methods {
        pb.set_message(format!("{} long run: {method}", scene.name()));
        match method {
            Method::Variational(id) => {
                let Ok(scheme) = Scheme::new(*id) else {
                    continue;
                };
                // Pilot over a tenth of the run, then one correction of the step count.
                let (pilot, secs) = timed_vi(&scheme, 0.1, t_final / 10.0);
                let Ok(pilot) = pilot else { continue };
                let mut steps = budget / (secs / pilot.steps.max(1) as f64);
                let mut h = step_for(steps);
                let (mut result, mut seconds) = timed_vi(&scheme, h, t_final);
                if result.is_ok() && (seconds / budget).ln().abs() > 1.25f64.ln() {
                    steps *= budget / seconds;
                    h = step_for(steps);
                    (result, seconds) = timed_vi(&scheme, h, t_final);
                }
                if let Ok(series) = result {
                    out.curves.push(BalanceCurve {
                        method: *method,
                        h_or_tol: h,
                        seconds,
                        series,
                    });
                }
            }
            Method::Baseline(b) => {
                let mut best: Option<BalanceCurve> = None;
                for k in 0..=22 {
                    let tol = 10f64.powf(-2.0 - 0.5 * f64::from(k));
                    let start = Instant::now();
                    let result = scene.balance_baseline(*b, tol, t_final, samples);
                    let seconds = start.elapsed().as_secs_f64();
                    // A loose tolerance may fail where a tighter one succeeds.
                    let Ok(series) = result else { continue };
                    let gap = (seconds / budget).ln().abs();
                    let better = best
                        .as_ref()
                        .is_none_or(|c| gap < (c.seconds / budget).ln().abs());
                    if better {
                        best = Some(BalanceCurve {
                            method: *method,
                            h_or_tol: tol,
                            seconds,
                            series,
                        });
                    }
                    if seconds > 1.5 * budget {
                        break;
                    }
                }
                out.curves.extend(best);
            }
        }
        pb.inc(1);
    }
    out
}

/// Runs the work-precision report and writes its files into `opts.out`.
pub fn run(opts: &Options) -> Result<Summary, ReportError> {
    let started = Instant::now();
    let plan = Plan::new(opts.quick);
    let all = scenes::all()?;
    let known = || all.iter().map(|s| s.name()).collect::<Vec<_>>().join(", ");
    for name in &opts.scenes {
        if !all.iter().any(|s| s.name() == name) {
            return Err(ReportError::UnknownScene {
                name: name.clone(),
                known: known(),
            });
        }
    }
    let selected: Vec<&dyn Scene> = all
        .iter()
        .map(|s| s.as_ref())
        .filter(|s| opts.scenes.is_empty() || opts.scenes.iter().any(|n| n == s.name()))
        .collect();
    let methods = if opts.methods.is_empty() {
        Method::defaults()
    } else {
        opts.methods.clone()
    };
    let mut summary = Summary {
        scenes: selected.iter().map(|s| s.name()).collect(),
        methods: methods.clone(),
        ..Summary::default()
    };
    let long_scene = selected
        .iter()
        .find(|s| s.name() == LONG_RUN_SCENE)
        .copied();
    let planned: usize = selected
        .iter()
        .map(|s| {
            methods
                .iter()
                .map(|m| match m {
                    Method::Variational(_) => plan.step_sizes(s.t_final()).len(),
                    Method::Baseline(_) => plan.tolerances.len(),
                })
                .sum::<usize>()
        })
        .sum::<usize>()
        + long_scene.map_or(0, |_| methods.len());
    let pb = progress_bar(planned as u64, opts.progress);
    for scene in &selected {
        for method in &methods {
            sweep(*scene, method, &plan, &pb, &mut summary);
        }
    }
    summary.long_run = long_scene.map(|s| long_run(s, &methods, &plan, &pb));
    pb.finish_and_clear();
    fit_orders(&selected, &mut summary);
    summary.elapsed = started.elapsed().as_secs_f64();
    write_outputs(opts, &plan, &selected, &summary)?;
    Ok(summary)
}

fn write_file(path: &Path, text: &str) -> Result<(), ReportError> {
    fs::write(path, text).map_err(ReportError::io(path))
}

fn write_outputs(
    opts: &Options,
    plan: &Plan,
    scenes: &[&dyn Scene],
    summary: &Summary,
) -> Result<(), ReportError> {
    let out = &opts.out;
    fs::create_dir_all(out).map_err(ReportError::io(out))?;

    let mut csv = format!("{WORK_PRECISION_HEADER}\n");
    let mut ens = format!("{ENSEMBLE_HEADER}\n");
    for r in &summary.rows {
        let [q, p, e] = r.errors();
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{}",
            r.scene,
            r.method,
            csv_float(r.h_or_tol),
            r.steps,
            r.newton_iters,
            csv_float(r.seconds),
            csv_float(q),
            csv_float(p),
            csv_float(e)
        );
        let is_ensemble = scenes
            .iter()
            .any(|s| s.name() == r.scene && s.members() > 1);
        if is_ensemble {
            let _ = write!(ens, "{},{},{}", r.scene, r.method, csv_float(r.h_or_tol));
            for s in &r.err {
                let _ = write!(
                    ens,
                    ",{},{},{}",
                    csv_float(s.min),
                    csv_float(s.mean),
                    csv_float(s.max)
                );
            }
            ens.push('\n');
        }
    }
    write_file(&out.join("work_precision.csv"), &csv)?;
    write_file(&out.join("ensemble.csv"), &ens)?;

    let mut ord = format!("{ORDERS_HEADER}\n");
    for o in &summary.orders {
        let observed = o.observed[0]
            .as_ref()
            .map_or(String::new(), |f| format!("{:.3}", f.order));
        let _ = writeln!(
            ord,
            "{},{},{},{},{}",
            o.scene, o.method, o.stages, o.expected, observed
        );
    }
    write_file(&out.join("orders.csv"), &ord)?;

    let mut bal = format!("{ENERGY_BALANCE_HEADER}\n");
    if let Some(lr) = &summary.long_run {
        for c in &lr.curves {
            for (t, b) in c.series.t.iter().zip(&c.series.balance) {
                let _ = writeln!(
                    bal,
                    "{},{},{},{},{},{}",
                    lr.scene,
                    c.method,
                    csv_float(c.h_or_tol),
                    csv_float(c.seconds),
                    csv_float(*t),
                    csv_float(*b)
                );
            }
        }
    }
    write_file(&out.join("energy_balance.csv"), &bal)?;

    let figures = plots::draw_all(out, scenes, summary)?;
    let section = section_markdown(opts, plan, scenes, summary, &figures);
    readme::write_section(out, "work_precision", &section)
}

/// The cheapest measured run of `method` on `scene` with `err_q ≤ target`.
pub fn cheapest_time(summary: &Summary, scene: &str, method: &Method, target: f64) -> Option<f64> {
    summary
        .rows
        .iter()
        .filter(|r| r.scene == scene && &r.method == method && r.errors()[0] <= target)
        .map(|r| r.seconds)
        .min_by(f64::total_cmp)
}

fn fmt_order(f: &Option<Fit>) -> String {
    f.as_ref()
        .map_or("–".to_string(), |f| format!("{:.2}", f.order))
}

fn fmt_time(t: f64) -> String {
    if t >= 1.0 {
        format!("{t:.2} s")
    } else if t >= 1e-3 {
        format!("{:.2} ms", t * 1e3)
    } else {
        format!("{:.1} µs", t * 1e6)
    }
}

fn fmt_vec(x: &[f64]) -> String {
    let parts: Vec<String> = x.iter().map(|v| format!("{v}")).collect();
    format!("({})", parts.join(", "))
}

/// The Markdown of the work-precision section.
fn section_markdown(
    opts: &Options,
    plan: &Plan,
    scenes: &[&dyn Scene],
    summary: &Summary,
    figures: &plots::Figures,
) -> String {
    let mut md = String::new();
    let mode = if opts.quick {
        "quick (`--quick`)"
    } else {
        "full"
    };
    let _ = writeln!(md, "## Work-precision report\n");
    let _ = writeln!(
        md,
        "Command: `cargo run --release{}` — {mode} grid, {} measured runs, {} failed, \
         {:.0} s in all.{}\n",
        if opts.quick { " -- --quick" } else { "" },
        summary.rows.len(),
        summary.failures.len(),
        summary.elapsed,
        if opts.scenes.is_empty() && opts.methods.is_empty() {
            ""
        } else {
            " Filtered with `--scene`/`--method`: only part of the report."
        }
    );
    let _ = writeln!(
        md,
        "Files: [`work_precision.csv`](work_precision.csv) (every run), \
         [`orders.csv`](orders.csv) (observed orders in q), [`ensemble.csv`](ensemble.csv) \
         (ensemble min/mean/max), [`energy_balance.csv`](energy_balance.csv) (the long run).\n"
    );

    let _ = writeln!(md, "### Scenes\n");
    let _ = writeln!(md, "| scene | model | members | q₀ | v₀ | T |");
    let _ = writeln!(md, "|---|---|---|---|---|---|");
    for s in scenes {
        let (q0, v0) = match (s.members(), s.initial(0)) {
            (1, Some((q, v))) => (fmt_vec(&q), fmt_vec(&v)),
            (_, Some((_, v))) => ("uniform in [−4, 4]² (seeded)".to_string(), fmt_vec(&v)),
            _ => ("?".to_string(), "?".to_string()),
        };
        let _ = writeln!(
            md,
            "| `{}` | {} | {} | {q0} | {v0} | {} |",
            s.name(),
            s.summary(),
            s.members(),
            s.t_final()
        );
    }
    let _ = writeln!(
        md,
        "\nReferences: `data/reference/<scene>.csv` from `scripts/reference.py` (Taylor series \
         in 30-digit arithmetic, or the exact solution), embedded in the binary. Errors are \
         max-norm errors at the final time; for the ensemble, means over the members, with \
         steps and Newton iterations summed over the members and the wall time of the whole \
         ensemble run in parallel (rayon).\n"
    );
    let _ = writeln!(
        md,
        "Timing: the median of repeated runs, repeated until about {} s of timing per point \
         (at most {} repeats), on a machine with {} hardware threads shared with other work, \
         so differences below about 30 % are noise.\n",
        plan.timing_budget,
        plan.max_repeats,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );

    let _ = writeln!(md, "### Methods\n");
    let _ = writeln!(md, "| method | kind | swept over |");
    let _ = writeln!(md, "|---|---|---|");
    for m in &summary.methods {
        let (kind, over) = match m {
            Method::Variational(id) => {
                let order = Scheme::new(*id).map(|s| s.order()).unwrap_or(0);
                (
                    format!("forced variational integrator, order {order}"),
                    format!(
                        "h = T/n from min(1, T) to {} ({} per decade)",
                        plan.h_min, plan.per_decade
                    ),
                )
            }
            Method::Baseline(b) => (
                b.description().to_string(),
                format!(
                    "rtol = atol from {:.0e} to {:.0e}",
                    plan.tolerances.first().copied().unwrap_or(0.0),
                    plan.tolerances.last().copied().unwrap_or(0.0)
                ),
            ),
        };
        let _ = writeln!(md, "| `{m}` | {kind} | {over} |");
    }
    let _ = writeln!(
        md,
        "\nThe baselines integrate the first-order form `q' = v`, `v' = E⁻¹(L_q + F − C v)` \
         built from the same exact node kernels as the variational schemes, and are checked \
         against the references by tests (`src/baselines.rs`). Sweeps stop early after {} \
         points at the round-off floor or a run longer than {} s{}.\n",
        plan.floor_points,
        plan.max_run_seconds,
        if plan.full_paper_tail {
            format!(" (except the variational schemes on `{PAPER_SCENE}`, swept to the end)")
        } else {
            String::new()
        }
    );

    let _ = writeln!(md, "### Observed orders\n");
    let _ = writeln!(
        md,
        "Least-squares slopes of log(error) against log(h) over the asymptotic range, which \
         sits just above the round-off floor: of the points with error between {:.0e}·s \
         (round-off) and {:.0e}·s (pre-asymptotic), s = max(1, |reference|), the {} smallest \
         step sizes start the fit, and larger ones join while their segment's slope stays \
         within {} of the fit (`src/report/orders.rs`). `orders.csv` holds the order in q.\n",
        orders::FLOOR,
        orders::CEILING,
        orders::MIN_POINTS,
        orders::TRIM
    );
    let _ = writeln!(md, "| scene | method | s | expected | q | p | energy |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    for o in &summary.orders {
        let _ = writeln!(
            md,
            "| `{}` | `{}` | {} | {} | {} | {} | {} |",
            o.scene,
            o.method,
            o.stages,
            o.expected,
            fmt_order(&o.observed[0]),
            fmt_order(&o.observed[1]),
            fmt_order(&o.observed[2])
        );
    }

    let _ = writeln!(md, "\n### Cheapest method per error target\n");
    let _ = writeln!(
        md,
        "Median wall time of the cheapest measured run whose error in q is at most the \
         target (– : never reached). **Bold**: the cheapest method.\n"
    );
    let _ = write!(md, "| scene | target |");
    for m in &summary.methods {
        let _ = write!(md, " `{m}` |");
    }
    let _ = write!(md, "\n|---|---|");
    for _ in &summary.methods {
        let _ = write!(md, "---|");
    }
    md.push('\n');
    for s in scenes {
        for target in TARGETS {
            let times: Vec<Option<f64>> = summary
                .methods
                .iter()
                .map(|m| cheapest_time(summary, s.name(), m, target))
                .collect();
            let best = times.iter().flatten().copied().min_by(f64::total_cmp);
            let _ = write!(md, "| `{}` | {target:.0e} |", s.name());
            for t in &times {
                match t {
                    Some(t) if Some(*t) == best => {
                        let _ = write!(md, " **{}** |", fmt_time(*t));
                    }
                    Some(t) => {
                        let _ = write!(md, " {} |", fmt_time(*t));
                    }
                    None => md.push_str(" – |"),
                }
            }
            md.push('\n');
        }
    }

    let _ = writeln!(md, "\n### Plots\n");
    for s in scenes {
        let _ = writeln!(md, "#### `{}`\n", s.name());
        if let Some(f) = figures.error_vs_h.iter().find(|(n, _)| n == s.name()) {
            let _ = writeln!(md, "![error against h, {}]({})\n", s.name(), f.1);
        }
        if let Some(f) = figures.work_precision.iter().find(|(n, _)| n == s.name()) {
            let _ = writeln!(md, "![error against run time, {}]({})\n", s.name(), f.1);
        }
    }

    if let (Some(lr), Some(fig)) = (&summary.long_run, &figures.energy_balance) {
        let _ = writeln!(md, "### Energy balance over a long run\n");
        let _ = writeln!(
            md,
            "`{}` to t = {}: the energy-balance error E(t) − E(0) − W(t), with W the work of \
             the force (the variational schemes sum it with their own quadrature, the baselines \
             integrate W' = F·v as an extra ODE component). All runs cost about the same: the \
             budget is {} (`lobatto3`, h = {LONG_RUN_REFERENCE_H}). Energy-balance errors \
             below {:.0e} (zero to round-off) are drawn at {:.0e}.\n",
            lr.scene,
            lr.t_final,
            fmt_time(lr.budget),
            plots::BALANCE_FLOOR,
            plots::BALANCE_FLOOR
        );
        let _ = writeln!(md, "![energy balance against time]({fig})\n");
        let _ = writeln!(
            md,
            "| method | h or tol | steps | run time | max abs energy-balance error |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|");
        for c in &lr.curves {
            let worst = c.series.balance.iter().map(|b| b.abs()).fold(0.0, f64::max);
            let _ = writeln!(
                md,
                "| `{}` | {:.3e} | {} | {} | {:.2e} |",
                c.method,
                c.h_or_tol,
                c.series.steps,
                fmt_time(c.seconds),
                worst
            );
        }
        md.push('\n');
    }

    if !summary.failures.is_empty() {
        let _ = writeln!(md, "### Runs without a result\n");
        let _ = writeln!(md, "| scene | method | h or tol | error |");
        let _ = writeln!(md, "|---|---|---|---|");
        for f in &summary.failures {
            let _ = writeln!(
                md,
                "| `{}` | `{}` | {:.3e} | {} |",
                f.scene,
                f.method,
                f.h_or_tol,
                f.message.replace('|', "/")
            );
        }
    }
    md
}
