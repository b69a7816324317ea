//! The Markdown section of the work-precision report.

use std::fmt::Write as _;

use forced_vi::Scheme;

use super::equal_error::{self, Line};
use super::external::{ExternalRow, HEYOKA_LABEL, HEYOKA_PATH};
use super::figures::{Figures, BALANCE_FLOOR};
use super::large;
use super::long_run::LONG_RUN_REFERENCE_H;
use super::rows::{BalanceCurve, Failure, LongRun, Mode, OrderRow, Paired, Restarted, Summary};
use super::sweep::reference_scale;
use super::RESTART_ROUNDS;
use crate::report::orders::{self, Fit};
use crate::report::plan::{Plan, ORDER2_TOL_FLOOR, PAPER_SCENE, PREDICTED_RUN_FACTOR};
use crate::report::table::{col, fmt_time, markdown};
use crate::report::{Method, Options};
use crate::scenes::Scene;

/// The error targets of the "cheapest method" table.
pub const TARGETS: [f64; 2] = [1e-6, 1e-10];

/// What the section is written from.
pub struct Inputs<'a> {
    /// The command's options.
    pub opts: &'a Options,
    /// The grids.
    pub plan: &'a Plan,
    /// The selected scenes.
    pub scenes: &'a [&'a dyn Scene],
    /// What was measured.
    pub summary: &'a Summary,
    /// The plots written.
    pub figures: &'a Figures,
}

/// The Markdown of the work-precision section.
pub fn markdown_section(i: &Inputs<'_>) -> String {
    let mut md = intro(i);
    md.push_str(&scenes_and_methods(i));
    md.push_str(&observed_orders(i.summary));
    md.push_str(&adaptive(i.plan, i.scenes, i.summary));
    md.push_str(&adaptive_cost(i.scenes, i.summary));
    md.push_str(&cheapest(i.scenes, i.summary));
    md.push_str(&paired(i.summary));
    md.push_str(&restarted(i.summary));
    md.push_str(&large_models(i.summary));
    md.push_str(&plots(i.scenes, i.figures));
    if let (Some(lr), Some(fig)) = (&i.summary.long_run, &i.figures.energy_balance) {
        md.push_str(&long_run(lr, fig));
    }
    if !i.summary.failures.is_empty() {
        md.push_str("### Runs without a result\n\n");
        md.push_str(&markdown(
            &i.summary.failures,
            &[
                col("scene", |f: &Failure| format!("`{}`", f.scene)),
                col("method", |f: &Failure| {
                    format!("`{}`", f.mode.label(&f.method))
                }),
                col("h or tol", |f: &Failure| format!("{:.3e}", f.h_or_tol)),
                col("error", |f: &Failure| f.message.replace('|', "/")),
            ],
        ));
    }
    md
}

fn intro(i: &Inputs<'_>) -> String {
    let (opts, s) = (i.opts, i.summary);
    let mode = if opts.quick {
        "quick (`--quick`)"
    } else {
        "full"
    };
    let filtered = if opts.scenes.is_empty() && opts.methods.is_empty() {
        ""
    } else {
        " Filtered with `--scene`/`--method`: only part of the report."
    };
    format!(
        "## Work-precision report\n\n\
         Command: `cargo run --release{}` — {mode} grid, {} measured runs, {} failed, \
         {:.0} s in all.{filtered}\n\n\
         Files: [`work_precision.csv`](work_precision.csv) (every run), \
         [`orders.csv`](orders.csv) (observed orders in q), [`ensemble.csv`](ensemble.csv) \
         (ensemble min/mean/max), [`energy_balance.csv`](energy_balance.csv) (the long run).\n\n",
        if opts.quick { " -- --quick" } else { "" },
        s.rows.len(),
        s.failures.len(),
        s.elapsed,
    )
}

fn fmt_vec(x: &[f64]) -> String {
    let parts: Vec<String> = x.iter().map(|v| format!("{v}")).collect();
    format!("({})", parts.join(", "))
}

fn initial(s: &dyn Scene) -> (String, String) {
    match (s.members(), s.initial(0)) {
        (1, Some((q, v))) => (fmt_vec(&q), fmt_vec(&v)),
        (_, Some((_, v))) => ("uniform in [−4, 4]² (seeded)".to_string(), fmt_vec(&v)),
        _ => ("?".to_string(), "?".to_string()),
    }
}

fn method_kind(m: &Method, plan: &Plan) -> (String, String) {
    match m {
        Method::Variational(id) => {
            let order = Scheme::new(*id).map(|s| s.order()).unwrap_or(0);
            let over = format!(
                "h = T/n from min(1, T) to {} ({} per decade)",
                plan.h_min, plan.per_decade
            );
            (
                format!("forced variational integrator, order {order}"),
                over,
            )
        }
        Method::Baseline(b) => {
            let (lo, hi) = (plan.tolerances.first(), plan.tolerances.last());
            let over = format!(
                "rtol = atol from {:.0e} to {:.0e}",
                lo.copied().unwrap_or(0.0),
                hi.copied().unwrap_or(0.0)
            );
            (b.description().to_string(), over)
        }
    }
}

fn scenes_and_methods(i: &Inputs<'_>) -> String {
    let plan = i.plan;
    let mut md = String::from("### Scenes\n\n");
    md.push_str(&markdown(
        i.scenes,
        &[
            col("scene", |s: &&dyn Scene| format!("`{}`", s.name())),
            col("model", |s: &&dyn Scene| s.summary().to_string()),
            col("members", |s: &&dyn Scene| s.members().to_string()),
            col("q₀", |s: &&dyn Scene| initial(*s).0),
            col("v₀", |s: &&dyn Scene| initial(*s).1),
            col("T", |s: &&dyn Scene| s.t_final().to_string()),
        ],
    ));
    let _ = write!(
        md,
        "\nReferences: `data/reference/<scene>.csv` from `scripts/reference.py` (Taylor series \
         in 30-digit arithmetic, or the exact solution), embedded in the binary. Errors are \
         max-norm errors at the final time; for the ensemble, means over the members, with \
         steps and Newton iterations summed over the members and the wall time of the whole \
         ensemble run in parallel (rayon): the variational schemes through \
         `Integrator::ensemble` (each worker restarts one stepper member to member, as a user's \
         ensemble runs), the baselines with a new solver per member.\n\n\
         Timing: the median of repeated runs, repeated until about {} s of timing per point \
         (at most {} repeats), on a machine with {} hardware threads shared with other work, \
         so differences below about 30 % are noise. Every run, variational or baseline, \
         computes its final state alone: the variational ones through \
         `Integrator::final_state` (no per-step records or diagnostics), as the baselines \
         return theirs.\n\n### Methods\n\n",
        plan.timing_budget,
        plan.max_repeats,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    md.push_str(&markdown(
        &i.summary.methods,
        &[
            col("method", |m: &Method| format!("`{m}`")),
            col("kind", |m: &Method| method_kind(m, plan).0),
            col("swept over", |m: &Method| method_kind(m, plan).1),
        ],
    ));
    let tail = if plan.full_paper_tail {
        format!(" (except the variational schemes on `{PAPER_SCENE}`, swept to the end)")
    } else {
        String::new()
    };
    let _ = write!(
        md,
        "\nThe baselines integrate the first-order form `q' = v`, `v' = E⁻¹(L_q + F − C v)` \
         built from the same exact node kernels as the variational schemes, and are checked \
         against the references by tests (`src/baselines.rs`). Sweeps stop early after {} \
         points at the round-off floor, after a run longer than {} s, or before a variational run \
         predicted (from the previous point's time, as `1/h` or `tol^(−1/p)`) to take longer \
         than {} s{tail}.\n\n",
        plan.floor_points,
        plan.max_run_seconds,
        PREDICTED_RUN_FACTOR * plan.max_run_seconds,
    );
    md.push_str(&external_method(i.summary));
    md
}

/// The paragraph on the external heyoka baseline (empty when none of its scenes is selected).
fn external_method(summary: &Summary) -> String {
    let ext = &summary.external;
    if ext.rows.is_empty() {
        return String::new();
    }
    let mut scenes: Vec<&str> = ext.rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let range = |f: fn(&ExternalRow) -> f64| {
        let lo = ext.rows.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = ext.rows.iter().map(f).fold(0.0, f64::max);
        (fmt_time(lo), fmt_time(hi))
    };
    let (jit_lo, jit_hi) = range(|r| r.jit_seconds);
    let (call_lo, call_hi) = range(|r| r.overhead_seconds);
    let tols = ext.rows.iter().map(|r| r.tol);
    let (tol_lo, tol_hi) = (
        tols.clone().fold(f64::INFINITY, f64::min),
        tols.fold(0.0, f64::max),
    );
    format!(
        "**External baseline: heyoka {}** (adaptive Taylor series, compiled just in time by \
         LLVM; the Python package), on {}: tol from {tol_hi:.0e} to {tol_lo:.0e}. It is not \
         run by this command: `scripts/heyoka_baseline.py` measured it when `{HEYOKA_PATH}` \
         was committed (the file says: “{}”), on the same initial data, final time and \
         reference (`data/reference/`), with the same error in q; its equations are written \
         by hand and checked against L and F by finite differences. Its times are medians of \
         repeated `propagate_until` calls and leave out the JIT build of the integrator, done \
         once per tolerance ({jit_lo} to {jit_hi}, in the cheapest-method table beside each \
         time); they include the Python call ({call_lo} to {call_hi}). Being measured \
         elsewhere and at another time, it is labelled external in the tables and plots (black \
         dashed line, hollow squares) and never counts as this report's cheapest method. On \
         the ensemble it ran member 0 alone: the table marks that time, and the ensemble's \
         plot, whose times are those of the whole ensemble, leaves it out. Not measured: the \
         constrained and stiff scenes and the large models.\n\n",
        ext.versions(),
        scenes
            .iter()
            .map(|s| format!("`{s}`"))
            .collect::<Vec<_>>()
            .join(", "),
        ext.provenance,
    )
}

fn fmt_order(f: &Option<Fit>) -> String {
    f.as_ref()
        .map_or("–".to_string(), |f| format!("{:.2}", f.order))
}

/// An order in q or p, marked `†` where it settled more than 0.3 from the scheme's.
fn fmt_order_against(f: &Option<Fit>, expected: usize) -> String {
    match f {
        Some(f) if (f.order - expected as f64).abs() > 0.3 => format!("{:.2}†", f.order),
        _ => fmt_order(f),
    }
}

fn observed_orders(summary: &Summary) -> String {
    let mut md = format!(
        "### Observed orders\n\n\
         Least-squares slopes of log(error) against log(h) over the asymptotic range, which \
         sits just above the round-off floor: of the points with error between {:.0e}·s \
         (round-off) and {:.0e}·s (pre-asymptotic), s = max(1, |reference|), and above a \
         scattered round-off tail at {} times its median error or more, the {} smallest \
         step sizes start the fit, and larger ones join while their segment's slope stays \
         within {} of the fit (`src/report/orders.rs`). A fit is shown only where it settles \
         the order: its slope's 95 % confidence half-width is at most {}, and its errors \
         fall by a factor {} or more across it; elsewhere a dash, and `orders.csv`'s note \
         gives the unsettled fit. †: a fit that settled more than 0.3 from the scheme's \
         order, a straight stretch that is not yet the asymptotic one (the energy balance \
         need not converge at the scheme's order). `orders.csv` holds the order in q.\n\n",
        orders::FLOOR,
        orders::CEILING,
        orders::FLOOR_MARGIN,
        orders::MIN_POINTS,
        orders::TRIM,
        orders::SETTLED,
        orders::MIN_FALL
    );
    md.push_str(&markdown(
        &summary.orders,
        &[
            col("scene", |o: &OrderRow| format!("`{}`", o.scene)),
            col("method", |o: &OrderRow| format!("`{}`", o.method)),
            col("s", |o: &OrderRow| o.stages.to_string()),
            col("expected", |o: &OrderRow| o.expected.to_string()),
            col("q", |o: &OrderRow| {
                fmt_order_against(&o.observed[0], o.expected)
            }),
            col("p", |o: &OrderRow| {
                fmt_order_against(&o.observed[1], o.expected)
            }),
            col("energy", |o: &OrderRow| fmt_order(&o.observed[2])),
        ],
    ));
    md
}

/// The tolerance proportionality of one adaptive sweep.
struct Proportionality {
    scene: &'static str,
    method: Method,
    points: usize,
    /// Of `points`, those the slope is fitted to.
    fitted: usize,
    slope: Option<f64>,
    worst_ratio: f64,
    /// The smallest final error in q over its tolerance among the fitted points (NaN
    /// without any).
    least_ratio: f64,
    steps: (usize, usize),
    /// The scene's amplification ([`Scene::amplification`]), if it could be measured.
    amplification: Option<f64>,
    /// The middle fitted run's tolerance and the budget it spends
    /// ([`Scene::budget_spent`]), if it could be measured.
    budget: Option<(f64, f64)>,
}

/// The fewest steps of a run whose error counts in the tolerance-proportionality slope.
const MIN_RUN_STEPS: usize = 4;

fn proportionality(plan: &Plan, scenes: &[&dyn Scene], summary: &Summary) -> Vec<Proportionality> {
    let mut out = Vec::new();
    for s in scenes {
        let mut amplification = None;
        for m in summary.methods.iter().filter(|m| m.is_variational()) {
            let rows = summary.rows_in(s.name(), m, Mode::Adaptive);
            if rows.is_empty() {
                continue;
            }
            if amplification.is_none() {
                amplification = Some(
                    s.amplification(plan.amplification_points, plan.amplification_steps)
                        .ok(),
                );
            }
            let scale = reference_scale(*s)[0];
            // The points of issue 23's rule, as in `tests/adaptive.rs`: errors above the
            // round-off floor, from runs of at least `MIN_RUN_STEPS` steps (every member's,
            // on an ensemble): in a run of 1 to 3 steps the error is set by the run's length,
            // not by the tolerance.
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.errors()[0] > 0.0 && !orders::at_floor(r.errors()[0], scale))
                .filter(|r| r.member_steps_min >= MIN_RUN_STEPS)
                .map(|r| (r.h_or_tol, r.errors()[0]))
                .collect();
            // The budget the controller spends, on the middle fitted run by tolerance (or
            // the middle run, with none fitted).
            let middle = if pts.is_empty() {
                rows.get(rows.len() / 2).map(|r| r.h_or_tol)
            } else {
                pts.get(pts.len() / 2).map(|&(tol, _)| tol)
            };
            let budget = middle.and_then(|tol| {
                let scheme = m.scheme()?;
                s.budget_spent(&scheme, tol).ok().map(|spent| (tol, spent))
            });
            out.push(Proportionality {
                scene: s.name(),
                method: *m,
                points: rows.len(),
                fitted: pts.len(),
                slope: orders::slope(&pts),
                worst_ratio: rows
                    .iter()
                    .map(|r| r.errors()[0] / r.h_or_tol)
                    .fold(0.0, f64::max),
                least_ratio: pts
                    .iter()
                    .map(|&(tol, err)| err / tol)
                    .fold(f64::NAN, f64::min),
                steps: (rows[rows.len() - 1].steps, rows[0].steps),
                amplification: amplification.flatten(),
                budget,
            });
        }
    }
    out
}

fn adaptive(plan: &Plan, scenes: &[&dyn Scene], summary: &Summary) -> String {
    let lines = proportionality(plan, scenes, summary);
    if lines.is_empty() {
        return String::new();
    }
    let tols: Vec<String> = plan
        .adaptive_tolerances
        .iter()
        .map(|t| format!("{t:.0e}"))
        .collect();
    let mut md = format!(
        "\n### Adaptive runs: tolerance proportionality\n\n\
         Each variational scheme also runs with error control (`Integrator::adaptive`: the \
         reference-scheme estimate, PI controller, automatic first step) at rtol = atol = tol \
         for tol in {{{}}} (`mode = adaptive` in `work_precision.csv`, `h_or_tol` = tol). \
         The second-order schemes (`lobatto2`, `midpoint`) stop at tol = {ORDER2_TOL_FLOOR:.0e}: \
         below it they need millions of steps (about 10⁷ at 10⁻¹²). Sweeps stop early in the \
         same ways as the fixed-step ones. Slope: least-squares slope of log err_q against \
         log tol over the points above the round-off floor whose runs took at least {MIN_RUN_STEPS} steps each \
         (every member's, on the ensemble: in a run of 1 to 3 steps the error is set by the run's length, not by the \
         tolerance; the points column gives all the points and, in brackets, those fitted) (target 0.8–1.2); worst err/tol: the largest final error in q \
         over its tolerance (target ≤ 10). The controller bounds the local error per unit step; the final error is \
         those local errors carried to T by the flow, so it is about tol times the flow's amplification A: the mean over \
         {} times t of ‖Φ_q(T, t)‖∞, the rows in q_T of the tangent map from (q, p) at t to (q, p) at T \
         (`output::Tangents`, lobatto4 at {} steps, member 0 of the ensemble). The next column divides by it: \
         on a chaotic scene, where A is large, it is the calibration that is left. Budget spent: the sum of the \
         accepted steps' estimated local errors in units of the tolerance, the mean of the estimates per unit step \
         weighted by the steps' lengths (at most 1; the controller steers it to its steady error, 0.25 and above), \
         on the middle fitted run by tolerance (member 0), with that tolerance in brackets: near its steady error, \
         a run makes the local errors its tolerance allows.\n\n",
        tols.join(", "),
        plan.amplification_points,
        plan.amplification_steps,
    );
    md.push_str(&markdown(
        &lines,
        &[
            col("scene", |p: &Proportionality| format!("`{}`", p.scene)),
            col("method", |p: &Proportionality| format!("`{}`", p.method)),
            col("points (fitted)", |p: &Proportionality| {
                format!("{} ({})", p.points, p.fitted)
            }),
            col("slope", |p: &Proportionality| {
                p.slope.map_or("–".into(), |x| format!("{x:.2}"))
            }),
            col("worst err/tol", |p: &Proportionality| {
                format!("{:.2}", p.worst_ratio)
            }),
            col("A", |p: &Proportionality| {
                p.amplification.map_or("–".into(), |a| format!("{a:.1}"))
            }),
            col("worst err/(tol·A)", |p: &Proportionality| {
                p.amplification
                    .map_or("–".into(), |a| format!("{:.2}", p.worst_ratio / a))
            }),
            col("budget spent (tol)", |p: &Proportionality| {
                p.budget
                    .map_or("–".into(), |(tol, mean)| format!("{mean:.2} ({tol:.0e})"))
            }),
            col("steps (loosest → tightest)", |p: &Proportionality| {
                format!("{} → {}", p.steps.0, p.steps.1)
            }),
        ],
    ));
    md.push_str(&amplified_calibration(&lines));
    md
}

/// The amplification at and above which a scene counts as amplifying errors strongly (the
/// chaotic scenes), for the calibration sentence under the proportionality table.
const STRONG_AMPLIFICATION: f64 = 100.0;

/// The budget spent ([`Scene::budget_spent`]) at and above which a run counts as spending
/// its error budget (the controller's steady error is 0.25 and above).
const SPENT: f64 = 0.2;

/// Issue 23's target for the chaotic scenes, measured: every fitted run's err/(tol·A)
/// within 0.1–10, per scheme, on each scene whose amplification is at least
/// [`STRONG_AMPLIFICATION`].
fn amplified_calibration(lines: &[Proportionality]) -> String {
    let mut md = String::new();
    let mut scenes: Vec<&str> = lines
        .iter()
        .filter(|p| p.amplification.is_some_and(|a| a >= STRONG_AMPLIFICATION))
        .map(|p| p.scene)
        .collect();
    scenes.dedup();
    for scene in scenes {
        let rows: Vec<&Proportionality> = lines.iter().filter(|p| p.scene == scene).collect();
        let Some(a) = rows.iter().find_map(|p| p.amplification) else {
            continue;
        };
        let within = |p: &&&Proportionality| p.least_ratio / a >= 0.1 && p.worst_ratio / a <= 10.0;
        let met: Vec<String> = rows
            .iter()
            .filter(within)
            .map(|p| format!("`{}`", p.method))
            .collect();
        let missed: Vec<String> = rows
            .iter()
            .filter(|p| !within(p))
            .map(|p| {
                let r = |x: f64| {
                    if x >= 0.01 {
                        format!("{x:.2}")
                    } else {
                        format!("{x:.0e}")
                    }
                };
                format!(
                    "`{}` {}–{}",
                    p.method,
                    r(p.least_ratio / a),
                    r(p.worst_ratio / a)
                )
            })
            .collect();
        // Of the schemes that miss the target, those whose middle run spends its budget
        // and those whose run does not.
        let short: Vec<&&Proportionality> = rows.iter().filter(|p| !within(p)).collect();
        let name_spent = |p: &&&Proportionality| {
            p.budget
                .map(|(_, mean)| format!("`{}` {mean:.2}", p.method))
        };
        let full: Vec<String> = short
            .iter()
            .filter(|p| p.budget.is_some_and(|b| b.1 >= SPENT))
            .filter_map(name_spent)
            .collect();
        let less: Vec<String> = short
            .iter()
            .filter(|p| p.budget.is_some_and(|b| b.1 < SPENT))
            .filter_map(name_spent)
            .collect();
        let mut spent = String::new();
        if !full.is_empty() {
            spent.push_str(&format!(
                " Of those, {} spend their budget (the sum of the middle run's estimated \
                 local errors over its tolerance, at or near the controller's steady error): \
                 their local errors are \
                 as large as the tolerance allows, and the flow carried them to T with less \
                 than a tenth of A's growth (along directions it amplifies less, or with signs \
                 that cancel), not the controller holding them smaller.",
                full.join(", ")
            ));
        }
        if !less.is_empty() {
            spent.push_str(&format!(
                " {} spend less (below {SPENT}): their local errors were smaller than the \
                 tolerance allows, which lowers the ratio too.",
                less.join(", ")
            ));
        }
        md.push_str(&format!(
            "\nOn `{scene}` (A = {a:.0}), every fitted run's err/(tol·A) is within 0.1–10 (issue \
             23's target) for {} of {} schemes{}{}. A is the growth of a perturbation in its worst \
             direction (the ∞-norm of the map's q rows, averaged over t); below 0.1, a run's \
             local errors grew by less than a tenth of that.{spent}\n",
            met.len(),
            rows.len(),
            if met.is_empty() {
                String::new()
            } else {
                format!(" ({})", met.join(", "))
            },
            if missed.is_empty() {
                String::new()
            } else {
                format!(
                    "; not for {} (least–worst ratio over the fitted runs)",
                    missed.join(", ")
                )
            },
        ));
    }
    md
}

/// Adaptive runs against the fixed-step curve of their scheme at equal error.
fn adaptive_cost(scenes: &[&dyn Scene], summary: &Summary) -> String {
    let lines: Vec<Line> = scenes
        .iter()
        .flat_map(|s| {
            let scale = reference_scale(*s)[0];
            equal_error::lines(summary, s.name(), |e| orders::at_floor(e, scale))
        })
        .collect();
    if lines.is_empty() {
        return String::new();
    }
    let timed = |l: &Line| {
        summary
            .equal_error
            .iter()
            .find(|t| t.scene == l.scene && t.method == l.method)
    };
    let again: Vec<f64> = lines
        .iter()
        .filter_map(|l| timed(l).and_then(|t| t.ratio.as_ref().ok().copied()))
        .collect();
    let span = |v: &[f64]| {
        v.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
    };
    let medians: Vec<f64> = lines.iter().map(|l| l.median(|p| p.time)).collect();
    let (lo, hi) = span(&medians);
    let met = medians
        .iter()
        .filter(|&&x| x <= ADAPTIVE_COST_TARGET)
        .count();
    let (a_lo, a_hi) = span(&again);
    let a_met = again.iter().filter(|&&x| x <= ADAPTIVE_COST_TARGET).count();
    let mut sorted = again.clone();
    let a_median = crate::report::timing::median(&mut sorted);
    let steps: Vec<f64> = lines.iter().map(|l| l.median(|p| p.steps)).collect();
    let per_step: Vec<f64> = lines.iter().map(|l| l.median(|p| p.per_step())).collect();
    let ((s_lo, s_hi), (c_lo, c_hi)) = (span(&steps), span(&per_step));
    let step_bound = steps.iter().filter(|&&x| x <= 1.1).count();
    let cost_bound = steps.iter().zip(&per_step).filter(|(s, c)| c > s).count();
    let mut md = format!(
        "\n### Adaptive against fixed steps at equal error\n\n\
         Each adaptive run above, set beside the fixed-step runs of the same scheme on the \
         same scene at the adaptive run's own error: the fixed curve's time and steps there, \
         by log-log interpolation between the two fixed runs around that error (as in the \
         large-model table below; runs within the round-off floor, adaptive runs of fewer \
         than {} steps and adaptive runs outside the fixed curve are left out). This does not \
         depend on the spacing of the two grids, as the cheapest run of each that reaches a \
         target would (a decade per adaptive point, a third of one per fixed point). `time`: \
         adaptive time over fixed time (target ≤ {ADAPTIVE_COST_TARGET}); `steps`: the \
         adaptive run's accepted steps over the fixed curve's (the controller's placement of \
         steps; below 1: fewer than uniform steps); `per step`: the two divided, what an \
         adaptive step costs (its solve, its error estimate, its rejected attempts) over a \
         fixed step. Medians over the runs compared, from the sweeps' times: each sweep is \
         timed at its own moment, and between the fixed and the adaptive sweep of a line \
         this machine's speed can drift by 2× or more, which moves a whole line. So each \
         line's middle adaptive run (by tolerance) and the two fixed runs around its error \
         are also timed again together, in rounds that run the three one after the other, \
         each round starting one further along, and the ratio is taken from their medians: \
         `time, timed again`, the figure to read against the target.\n\n\
         Timed again, the ratio is at most {ADAPTIVE_COST_TARGET} in {a_met} of {} lines \
         ({a_lo:.2} to {a_hi:.2}, median {a_median:.2}); from the sweeps' times, the line's \
         median is at most {ADAPTIVE_COST_TARGET} in {met} of {n} ({lo:.2} to {hi:.2}). \
         The steps ratio's medians are {s_lo:.2} to {s_hi:.2} ({step_bound} of {n} at most \
         1.1), the per-step ratio's {c_lo:.2} to {c_hi:.2}; the per-step factor is the \
         larger of the two in {cost_bound} of {n}.\n\n",
        equal_error::MIN_RUN_STEPS,
        again.len(),
        n = lines.len(),
    );
    md.push_str(&markdown(
        &lines,
        &[
            col("scene", |l: &Line| format!("`{}`", l.scene)),
            col("method", |l: &Line| format!("`{}`", l.method.name())),
            col("runs (tol)", |l: &Line| {
                let t = |x: f64| format!("{x:.0e}");
                let (a, b) = (l.pairs[0].tol, l.pairs[l.pairs.len() - 1].tol);
                format!("{} ({} → {})", l.pairs.len(), t(a), t(b))
            }),
            col("time (median)", |l: &Line| {
                format!("{:.2}", l.median(|p| p.time))
            }),
            col("time (range)", |l: &Line| {
                let (a, b) = l.time_range();
                format!("{a:.2}–{b:.2}")
            }),
            col("steps (median)", |l: &Line| {
                format!("{:.2}", l.median(|p| p.steps))
            }),
            col("per step (median)", |l: &Line| {
                format!("{:.2}", l.median(|p| p.per_step()))
            }),
            col(
                "time, timed again (tol, rounds)",
                move |l: &Line| match timed(l) {
                    Some(t) => match &t.ratio {
                        Ok(r) => format!("**{r:.2}** ({:.0e}, {})", t.tol, t.rounds),
                        Err(e) => format!("– ({:.0e}: {})", t.tol, e.replace('|', "/")),
                    },
                    None => "–".into(),
                },
            ),
        ],
    ));
    md
}

/// Issue 23's target for an adaptive run's time over the fixed curve's at equal error.
const ADAPTIVE_COST_TARGET: f64 = 1.3;

/// One line of the cheapest-method table: a scene, a target, each method's time and the
/// external baseline's cheapest run.
struct Cheapest<'a> {
    scene: &'static str,
    members: usize,
    target: f64,
    times: Vec<Option<f64>>,
    external: Option<&'a ExternalRow>,
}

impl Cheapest<'_> {
    /// The bold time: the cheapest of the methods timed by this run.
    fn best(&self) -> Option<f64> {
        self.times.iter().flatten().copied().min_by(f64::total_cmp)
    }
}

/// How the external baseline compares with the bold times, on the single-trajectory scenes
/// where both reached the target.
struct Tally {
    /// Rows compared.
    rows: usize,
    /// Rows where its run time is below the bold one.
    faster: usize,
    /// The smallest and largest factor bold time / its time among those.
    factors: (f64, f64),
    /// Rows where its run time plus its JIT build is below the bold time.
    faster_with_jit: usize,
}

fn external_tally(lines: &[Cheapest<'_>]) -> Tally {
    let pairs: Vec<(f64, &ExternalRow)> = lines
        .iter()
        .filter(|c| c.members == 1)
        .filter_map(|c| Some((c.best()?, c.external?)))
        .collect();
    let faster: Vec<f64> = pairs
        .iter()
        .filter(|(b, e)| e.run_seconds < *b)
        .map(|(b, e)| b / e.run_seconds)
        .collect();
    Tally {
        rows: pairs.len(),
        faster: faster.len(),
        factors: (
            faster.iter().copied().fold(f64::INFINITY, f64::min),
            faster.iter().copied().fold(0.0, f64::max),
        ),
        faster_with_jit: pairs
            .iter()
            .filter(|(b, e)| e.run_seconds + e.jit_seconds < *b)
            .count(),
    }
}

fn cheapest(scenes: &[&dyn Scene], summary: &Summary) -> String {
    let mut lines = Vec::new();
    for s in scenes {
        for target in TARGETS {
            let times = summary
                .series()
                .iter()
                .map(|(m, mode)| summary.cheapest_time(s.name(), (m, *mode), target))
                .collect();
            lines.push(Cheapest {
                scene: s.name(),
                members: s.members(),
                target,
                times,
                external: summary.external.cheapest(s.name(), target),
            });
        }
    }
    let mut cols = vec![
        col("scene", |c: &Cheapest| format!("`{}`", c.scene)),
        col("target", |c: &Cheapest| format!("{:.0e}", c.target)),
    ];
    for (k, (m, mode)) in summary.series().into_iter().enumerate() {
        cols.push(col(
            format!("`{}`", mode.label(&m)),
            move |c: &Cheapest| match c.times[k] {
                Some(t) if Some(t) == c.best() => format!("**{}**", fmt_time(t)),
                Some(t) => fmt_time(t),
                None => "–".into(),
            },
        ));
    }
    let mut text = String::from(
        "\n### Cheapest method per error target\n\n\
         Median wall time of the cheapest measured run whose error in q is at most the \
         target (– : never reached), fixed-step and adaptive (`(adaptive)`) runs alike. \
         **Bold**: the cheapest of the methods timed by this run.",
    );
    if !summary.external.rows.is_empty() {
        let unmeasured = |c: &Cheapest| summary.external.rows_of(c.scene).is_empty();
        cols.push(col(HEYOKA_LABEL, move |c: &Cheapest| {
            match (c.external, unmeasured(c)) {
                (_, true) => "not measured".into(),
                (None, false) => "–".into(),
                (Some(r), false) if c.members > 1 => {
                    format!("{} (member 0 alone)", fmt_time(r.run_seconds))
                }
                (Some(r), false) => fmt_time(r.run_seconds),
            }
        }));
        cols.push(col("heyoka JIT build (not in its time)", |c: &Cheapest| {
            c.external.map_or("–".into(), |r| fmt_time(r.jit_seconds))
        }));
        let tally = external_tally(&lines);
        let factors = if tally.faster > 0 {
            format!(
                ", by factors of {:.1} to {:.1}",
                tally.factors.0, tally.factors.1
            )
        } else {
            String::new()
        };
        let _ = write!(
            text,
            " The last two columns are the external heyoka baseline (see Methods), which is not \
             part of that comparison: its cheapest run from `{HEYOKA_PATH}` reaching the \
             target, timed by another process when that file was committed, and the JIT \
             build of that run, which its time leaves out. On the ensemble it ran member 0 \
             alone, against the whole ensemble in the other columns. On the single-trajectory \
             scenes, heyoka's time is below the bold one in {} of the {} rows where both \
             reached the target{factors}; with its JIT build added, in {}.",
            tally.faster,
            tally.rows,
            match tally.faster_with_jit {
                0 => "none".to_string(),
                n => n.to_string(),
            },
        );
    }
    let _ = write!(text, "\n\n{}", markdown(&lines, &cols));
    text
}

/// The best variational run against the best baseline, timed again in rotating rounds.
/// The paired variational runs timed with a new and a restarted stepper, against heyoka.
fn restarted(summary: &Summary) -> String {
    if summary.restarted.is_empty() {
        return String::new();
    }
    let heyoka = |r: &Restarted| summary.external.cheapest(r.scene, r.target);
    let cols = vec![
        col("scene", |r: &Restarted| format!("`{}`", r.scene)),
        col("target", |r: &Restarted| format!("{:.0e}", r.target)),
        col("variational run (h or tol)", |r: &Restarted| {
            let (m, mode, x) = r.variational;
            format!("`{}` at {x:.3e}", mode.label(&m))
        }),
        col("new stepper", |r: &Restarted| match &r.seconds {
            Ok((n, _)) => fmt_time(*n),
            Err(e) => format!("failed: {e}"),
        }),
        col("restarted", |r: &Restarted| {
            r.seconds.as_ref().map_or("–".into(), |(_, x)| fmt_time(*x))
        }),
        col("restarted ÷ new", |r: &Restarted| {
            r.seconds
                .as_ref()
                .map_or("–".into(), |(n, x)| format!("{:.2}", x / n))
        }),
        col("heyoka", move |r: &Restarted| {
            heyoka(r).map_or("–".into(), |h| fmt_time(h.run_seconds))
        }),
        col("restarted ÷ heyoka", move |r: &Restarted| {
            match (&r.seconds, heyoka(r)) {
                (Ok((_, x)), Some(h)) if h.run_seconds > 0.0 => {
                    format!("{:.2}", x / h.run_seconds)
                }
                _ => "–".into(),
            }
        }),
    ];
    let mut text = format!(
        "\n### A restarted stepper, against heyoka\n\n\
         heyoka's times are those of `propagate_until` on an integrator built once, its JIT \
         excluded, with the state reset before each call. The sweeps above build \
         forced-vi's integrator and stepper for every run: about 30 allocations and the \
         Newton iteration's set-up on a small model, which a run of a few steps feels. Here \
         each scene's paired variational run of the table above is timed both ways, \
         alternating which goes first over {RESTART_ROUNDS} rounds: with a new stepper, as \
         the sweeps time it, and restarted on one stepper (`Integrator::runs`), whose final \
         state is checked to be the new one's to the bit. heyoka: its cheapest committed run \
         reaching the target (see Methods), timed by another process."
    );
    let _ = write!(text, "\n\n{}", markdown(&summary.restarted, &cols));
    text
}

fn paired(summary: &Summary) -> String {
    if summary.paired.is_empty() {
        return String::new();
    }
    let run = |(m, mode, x): (Method, Mode, f64)| format!("`{}` at {x:.3e}", mode.label(&m));
    let cols = vec![
        col("scene", |p: &Paired| format!("`{}`", p.scene)),
        col("target", |p: &Paired| format!("{:.0e}", p.target)),
        col("variational run (h or tol)", move |p: &Paired| {
            run(p.variational)
        }),
        col("baseline run (tol)", move |p: &Paired| {
            run((p.baseline.0, Mode::Fixed, p.baseline.1))
        }),
        col("candidates", |p: &Paired| {
            format!("{} + {}", p.candidates.0, p.candidates.1)
        }),
        col("rounds", |p: &Paired| p.rounds.to_string()),
        col("variational", |p: &Paired| match &p.seconds {
            Ok((v, _)) => fmt_time(*v),
            Err(e) => format!("failed: {e}"),
        }),
        col("baseline", |p: &Paired| {
            p.seconds.as_ref().map_or("–".into(), |(_, b)| fmt_time(*b))
        }),
        col("ratio", |p: &Paired| {
            p.ratio().map_or("–".into(), |r| format!("{r:.2}"))
        }),
    ];
    let mut text = String::from(
        "\n### The best variational run against the best baseline, timed in alternation\n\n\
         The sweeps above time each run at its own moment, and on this machine, shared with \
         other jobs, the speed drifts between those moments (measured when this table was \
         added: the cheapest `tsit45` runs on `coupled_van_der_pol` and `kepler_drag` at 1e-6 \
         took 1.9 and 1.7 times as long in one report as in the one before, the variational \
         runs 1.0 and 1.2 times), and the ratio of two columns of the table above drifts with \
         it. So for each scene and target, the three cheapest \
         variational runs and the three cheapest baseline runs of the table that reach it \
         (fixed or adaptive, any scheme; any baseline) are timed again here, in rounds that \
         run all of them, each round starting one further along; each time is the median \
         over the rounds, and the table shows each side's fastest by these medians (the \
         sweeps' times only shortlist the candidates: a run timed at a quiet moment there \
         does not stand in for a faster one). Ratio: variational over baseline (below 1: the \
         variational run is faster).",
    );
    for target in TARGETS {
        let ratios: Vec<(f64, &str)> = summary
            .paired
            .iter()
            .filter(|p| p.target == target)
            .filter_map(|p| Some((p.ratio()?, p.scene)))
            .collect();
        let Some(&(worst, at)) = ratios.iter().max_by(|a, b| a.0.total_cmp(&b.0)) else {
            continue;
        };
        let faster = ratios.iter().filter(|(r, _)| *r < 1.0).count();
        let within = ratios.iter().filter(|(r, _)| *r <= 1.5).count();
        let _ = write!(
            text,
            " At {target:.0e}: the variational run is the faster on {faster} of {} scenes, \
             within 1.5 times the baseline on {within}; the largest ratio is {worst:.2} \
             (`{at}`).",
            ratios.len()
        );
    }
    let _ = write!(text, "\n\n{}", markdown(&summary.paired, &cols));
    text
}

fn plots(scenes: &[&dyn Scene], figures: &Figures) -> String {
    let mut md = String::from("\n### Plots\n\n");
    for s in scenes {
        let _ = writeln!(md, "#### `{}`\n", s.name());
        if let Some(f) = figures.error_vs_h.iter().find(|(n, _)| n == s.name()) {
            let _ = writeln!(md, "![error against h, {}]({})\n", s.name(), f.1);
        }
        if let Some(f) = figures.work_precision.iter().find(|(n, _)| n == s.name()) {
            let _ = writeln!(md, "![error against run time, {}]({})\n", s.name(), f.1);
        }
    }
    md
}

/// The largest |balance| among the samples up to time `t`.
fn worst_until(c: &BalanceCurve, t: f64) -> f64 {
    let samples = c.series.t.iter().zip(&c.series.balance);
    samples
        .filter(|(s, _)| **s <= t)
        .map(|(_, b)| b.abs())
        .fold(0.0, f64::max)
}

/// Issue 11: what variable steps do to the energy ledger, scheme by scheme, from the curves.
fn ledger_under_adaptivity(lr: &LongRun) -> String {
    let mut md = String::from(
        "With variable steps (issue 11): the ledger is summed per step with that step's h. \
         The ratio of the whole-run maximum to the maximum over the first tenth shows growth: \
         near 1 means the error stays bounded (near-conservation), ≫ 1 that it drifts.\n\n",
    );
    let growth = |c: &BalanceCurve| {
        let early = worst_until(c, lr.t_final / 10.0);
        let all = c.series.balance.iter().map(|b| b.abs()).fold(0.0, f64::max);
        (early > 0.0).then(|| all / early)
    };
    for c in lr.curves.iter().filter(|c| c.mode == Mode::Adaptive) {
        let fixed = lr
            .curves
            .iter()
            .find(|f| f.method == c.method && f.mode == Mode::Fixed);
        let fmt = |x: Option<f64>| x.map_or("–".to_string(), |x| format!("{x:.1}"));
        let _ = writeln!(
            md,
            "- `{}`: growth {} adaptive (tol {:.0e}) against {} fixed.",
            c.method,
            fmt(growth(c)),
            c.h_or_tol,
            fmt(fixed.and_then(growth))
        );
    }
    md.push('\n');
    md
}

fn long_run(lr: &LongRun, fig: &str) -> String {
    // The runs that could not get near the budget (an adaptive run's loosest tolerance may
    // cost more).
    let dear: Vec<String> = lr
        .curves
        .iter()
        .filter(|c| c.seconds > 1.5 * lr.budget)
        .map(|c| format!("`{}` {} ({})", c.method, c.mode, fmt_time(c.seconds)))
        .collect();
    let over = if dear.is_empty() {
        String::new()
    } else {
        format!(
            " More than 1.5 budgets even at the loosest setting tried: {}.",
            dear.join(", ")
        )
    };
    let mut md = format!(
        "### Energy balance over a long run\n\n\
         `{}` to t = {}: the energy-balance error E(t) − E(0) − W(t), with W the work of \
         the force (the variational schemes sum it with their own quadrature, the baselines \
         integrate W' = F·v as an extra ODE component). Each run is sized to cost about \
         the budget, {} (`lobatto3`, h = {LONG_RUN_REFERENCE_H}), by its step or its \
         tolerance.{over} Energy-balance errors \
         below {:.0e} (zero to round-off) are drawn at {:.0e}.\n\n\
         ![energy balance against time]({fig})\n\n",
        lr.scene,
        lr.t_final,
        fmt_time(lr.budget),
        BALANCE_FLOOR,
        BALANCE_FLOOR
    );
    let worst = |c: &BalanceCurve| c.series.balance.iter().map(|b| b.abs()).fold(0.0, f64::max);
    md.push_str(&markdown(
        &lr.curves,
        &[
            col("method", |c: &BalanceCurve| format!("`{}`", c.method)),
            col("mode", |c: &BalanceCurve| c.mode.to_string()),
            col("h or tol", |c: &BalanceCurve| format!("{:.3e}", c.h_or_tol)),
            col("steps", |c: &BalanceCurve| c.series.steps.to_string()),
            col("run time", |c: &BalanceCurve| fmt_time(c.seconds)),
            col("max abs balance, t ≤ T/10", move |c: &BalanceCurve| {
                format!("{:.2e}", worst_until(c, lr.t_final / 10.0))
            }),
            col("max abs energy-balance error", move |c: &BalanceCurve| {
                format!("{:.2e}", worst(c))
            }),
        ],
    ));
    md.push('\n');
    md.push_str(&ledger_under_adaptivity(lr));
    md
}

fn large_models(summary: &Summary) -> String {
    if summary.large.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "\n### Large models: fixed and adaptive steps\n\n\
         The FPU chain and the 2-D lattice at n = 1024 (`forced_vi_scenes::large`, sparse \
         backend), T = {} and {}, from their smooth \
         initial states: lobatto3 and lobatto4 with fixed \
         steps h = T/n, n ∈ {:?}, and adaptive (`Integrator::adaptive`, rtol = atol = tol) \
         for tol ∈ {:?}. Errors (max-norm, q) against lobatto5 with {} fixed steps, whose own \
         accuracy (its difference from lobatto5 at half the steps) is {}. `fixed at equal \
         error`: the time of the fixed-step curve at the adaptive run's error (log-log \
         interpolation between the fixed runs around it; – outside the curve). Rows in \
         `work_precision.csv` under the scene names `{}` and `{}`.\n\n",
        large::t_final(large::FPU_CHAIN),
        large::t_final(large::LATTICE_2D),
        large::FIXED_STEPS,
        large::TOLERANCES,
        large::REFERENCE_STEPS,
        summary
            .large
            .iter()
            .map(|(n, a)| format!("{a:.1e} (`{n}`)"))
            .collect::<Vec<_>>()
            .join(", "),
        large::FPU_CHAIN,
        large::LATTICE_2D,
    );
    md.push_str(
        "| scene | method | tol | steps | time | err_q | fixed at equal error | ratio |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for (scene, _) in &summary.large {
        for method in summary
            .rows
            .iter()
            .filter(|r| r.scene == *scene)
            .map(|r| r.method)
            .fold(Vec::new(), |mut v, m| {
                if !v.contains(&m) {
                    v.push(m);
                }
                v
            })
        {
            let fixed = summary.rows_in(scene, &method, Mode::Fixed);
            for r in summary.rows_in(scene, &method, Mode::Adaptive) {
                let err = r.errors()[0];
                let equal = equal_error::fixed_at(&fixed, err, |f| f.seconds);
                md.push_str(&format!(
                    "| `{scene}` | `{}` | {:.0e} | {} | {} | {:.2e} | {} | {} |\n",
                    method.name(),
                    r.h_or_tol,
                    r.steps,
                    fmt_time(r.seconds),
                    err,
                    equal.map_or("–".into(), fmt_time),
                    equal.map_or("–".into(), |t| format!("{:.2}", r.seconds / t)),
                ));
            }
        }
    }
    md
}
