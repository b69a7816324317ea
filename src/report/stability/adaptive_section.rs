//! The adaptive rows of the stability section (issue 11): outcomes against the tolerance,
//! every run, and the stiff cost against the BDF and ESDIRK baselines.

use super::problem::Case;
use super::rows::{BaselineRow, Outcome, Row, Summary};
use super::tally::{best_baseline, best_variational, failed_by_kind, is_wrong, Counts};
use crate::baselines::Baseline;
use crate::report::table::{col, fmt_time, markdown};

/// Whether a finished adaptive run misses its tolerance: `err_final > 100·tol`, or more than
/// ten times the reference's own error where that is larger (the reference cannot judge
/// below it).
fn misses_tol(r: &Row, accuracy: f64) -> bool {
    let tol = r.tol.unwrap_or(f64::INFINITY);
    let bound = (100.0 * tol).max(if accuracy.is_finite() {
        10.0 * accuracy
    } else {
        0.0
    });
    let within = r.err_final <= bound;
    !matches!(r.outcome, Outcome::Failed(_)) && !within
}

/// The adaptive rows: outcomes by scene, then every run.
pub fn adaptive(s: &Summary, cases: &[&dyn Case]) -> String {
    if s.adaptive.is_empty() {
        return String::new();
    }
    let case = |r: &Row| cases.iter().find(|c| c.name() == r.scene).copied();
    let accuracy = move |r: &Row| case(r).map_or(f64::NAN, |c| c.accuracy());
    let scale = move |r: &Row| case(r).map_or(f64::INFINITY, |c| c.scale());
    let mut counts: Vec<Counts> = cases
        .iter()
        .map(|c| {
            let rs: Vec<&Row> = s.adaptive.iter().filter(|r| r.scene == c.name()).collect();
            let mut k = Counts::of(c.name(), &rs, c.scale());
            k.wrong = rs.iter().filter(|r| misses_tol(r, c.accuracy())).count();
            k
        })
        .filter(|k| k.runs > 0)
        .collect();
    let wrong: usize = counts.iter().map(|c| c.wrong).sum();
    let gross = s.adaptive.iter().filter(|r| is_wrong(r, scale(r))).count();
    counts.push(Counts {
        scene: "all".into(),
        runs: counts.iter().map(|c| c.runs).sum(),
        ok: counts.iter().map(|c| c.ok).sum(),
        recovered: 0,
        wrong,
        failed: vec![(String::new(), counts.iter().map(Counts::failed_total).sum())],
    });
    let mut md = format!(
        "### Adaptive runs\n\n\
         The same scenes rerun with error control (`mode = adaptive` in `stability.csv`): \
         rtol = atol = tol (`lobatto2` and `midpoint` down to {:.0e} only: below it a stiff run takes 10⁷ steps and more), first step the whole interval (the `h` column), no subdivision \
         (the controller rejects a step whose Newton solve fails and shrinks it). An adaptive \
         run should either finish with err_final ≤ 100·tol or stop with a typed error \
         (`step_size_too_small`, `max_steps_reached`, …). `wrong` here counts the finished \
         runs with err_final above 100·tol (or above ten times the reference's own error, \
         where that is larger): **{wrong} of {} adaptive runs** (target 0); {gross} of them \
         are off by more than half the solution's size.\n\n",
        super::ORDER2_ADAPTIVE_FLOOR,
        s.adaptive.len()
    );
    md.push_str(&markdown(
        &counts,
        &[
            col("scene", |c: &Counts| c.scene.clone()),
            col("runs", |c: &Counts| c.runs.to_string()),
            col("ok", |c: &Counts| c.ok.to_string()),
            col("wrong (err > 100·tol)", |c: &Counts| c.wrong.to_string()),
            col("failed (by kind)", failed_by_kind),
        ],
    ));
    md.push('\n');
    md.push_str(&markdown(
        &s.adaptive,
        &[
            col("scene", |r: &Row| format!("`{}`", r.scene)),
            col("method", |r: &Row| format!("`{}`", r.method)),
            col("tol", |r: &Row| {
                format!("{:.0e}", r.tol.unwrap_or(f64::NAN))
            }),
            col("outcome", move |r: &Row| {
                let w = if misses_tol(r, accuracy(r)) {
                    " (wrong)"
                } else {
                    ""
                };
                format!("{}{w}", r.outcome)
            }),
            col("steps", |r: &Row| r.steps_done.to_string()),
            col("err_final", |r: &Row| format!("{:.2e}", r.err_final)),
            col("err/tol", |r: &Row| {
                format!("{:.2}", r.err_final / r.tol.unwrap_or(f64::NAN))
            }),
            col("run time", |r: &Row| fmt_time(r.seconds)),
        ],
    ));
    md.push('\n');
    md
}

/// The scene of the stiff-cost comparison.
const STIFF_COST_SCENE: &str = "stiff_van_der_pol";

/// One error target of the stiff-cost comparison: the cheapest adaptive variational run and
/// the cheapest run of each stiff baseline reaching it.
struct StiffCost<'a> {
    target: f64,
    variational: Option<&'a Row>,
    baselines: [Option<&'a BaselineRow>; 2],
}

/// Wall time of the best adaptive variational run over the best stiff baselines' at equal
/// final error, on stiff van der Pol (μ = 10³, T = 2000), from this run's own rows.
pub fn stiff_cost(s: &Summary) -> String {
    let scene = STIFF_COST_SCENE;
    let solvers = [Baseline::Bdf, Baseline::Esdirk34];
    let lines: Vec<StiffCost> = [1e-3, 1e-5, 1e-7]
        .into_iter()
        .map(|target| StiffCost {
            target,
            variational: best_variational(&s.adaptive, scene, target),
            baselines: solvers.map(|b| best_baseline(&s.baselines, scene, b, target)),
        })
        .filter(|c| c.variational.is_some())
        .collect();
    if lines.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "### Stiff cost: adaptive against BDF and ESDIRK34\n\n\
         `{scene}` (μ = 10³, T = 2000): for each error target, the cheapest adaptive \
         variational run with err_final at most the target against the cheapest run of each \
         stiff baseline reaching it, all from this command's rows (one run each, timed while \
         rayon runs other cases beside it: ratios within about 2× are noise). Ratio > 1: the \
         variational run is slower.\n\n"
    );
    let time = |r: Option<f64>| r.map_or("–".to_string(), fmt_time);
    let ratio = |c: &StiffCost, k: usize| match (c.variational, c.baselines[k]) {
        (Some(v), Some(b)) if b.seconds > 0.0 => format!("{:.1}", v.seconds / b.seconds),
        _ => "–".to_string(),
    };
    md.push_str(&markdown(
        &lines,
        &[
            col("target", |c: &StiffCost| format!("{:.0e}", c.target)),
            col("best adaptive", |c: &StiffCost| {
                c.variational.map_or("–".into(), |r| {
                    format!("`{}` tol {:.0e}", r.method, r.tol.unwrap_or(f64::NAN))
                })
            }),
            col("its steps", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |r| r.steps_done.to_string())
            }),
            col("its rejected", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |r| r.rejected_steps.to_string())
            }),
            col("its err", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |r| format!("{:.1e}", r.err_final))
            }),
            col("its time", move |c: &StiffCost| {
                time(c.variational.map(|r| r.seconds))
            }),
            col("bdf steps", |c: &StiffCost| {
                c.baselines[0].map_or("–".into(), |r| r.steps.to_string())
            }),
            col("bdf time", move |c: &StiffCost| {
                time(c.baselines[0].map(|r| r.seconds))
            }),
            col("esdirk34 time", move |c: &StiffCost| {
                time(c.baselines[1].map(|r| r.seconds))
            }),
            col("ratio to bdf", move |c: &StiffCost| ratio(c, 0)),
            col("ratio to esdirk34", move |c: &StiffCost| ratio(c, 1)),
        ],
    ));
    md.push_str(
        "\nWhat limits it, read from the table rather than assumed: the time ratio is the \
         ratio of step counts times the ratio of cost per step. The `steps` columns give the \
         first; each attempt of the variational run, accepted or `rejected`, is one step solve \
         of an s-stage Galerkin system with Newton and one Newton iteration of the (s+1)-stage \
         reference scheme for the estimate, against one BDF step (which typically reuses its \
         Jacobian). The rejections come in runs where the fast mode turns (after the start \
         and before each relaxation jump): there the estimate is outside its asymptotic range \
         and grows as the step shrinks (traced on lobatto4 at tol 1: from 4.5 at h = 55 to \
         1.2e3 at h = 0.09 near t = 730, 15 rejections before a step of 2.7e-3 is accepted), \
         so the controller, which assumes err ∝ h^p, backs off one rejection at a time. \
         Where the best adaptive run is far more accurate than the target (its tolerance is \
         the loosest swept, yet err_final is orders below it), the steps between those runs \
         are set by the same estimate: the local error of the propagated solution, larger than \
         the global error left after the dissipative fast mode damps it.\n\n",
    );
    md
}
