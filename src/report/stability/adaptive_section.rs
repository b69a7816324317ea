//! The adaptive rows of the stability section (issue 11): outcomes against the tolerance,
//! every run, and the stiff cost against the BDF and ESDIRK baselines.

use std::fmt::Write as _;

use super::problem::Case;
use forced_vi::SchemeId;

use super::rows::{BaselineRow, Outcome, Row, StiffTimes, Summary};
use super::tally::{failed_by_kind, is_wrong, Counts};
use crate::baselines::Baseline;
use crate::report::table::{col, fmt_time, markdown};
use crate::report::timing;

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
         rtol = atol = tol (`lobatto2` and `midpoint` down to {:.0e} only: below it a stiff run takes 10⁷ steps and more), with the fixed-step schemes and lobatto5–8 (these capped at {} steps: `max_steps_reached` past it), first step the whole interval (the `h` column), no subdivision \
         (the controller rejects a step whose Newton solve fails and shrinks it). An adaptive \
         run should either finish with err_final ≤ 100·tol or stop with a typed error \
         (`step_size_too_small`, `pace_too_slow`, `max_steps_reached`, …). `wrong` here counts the finished \
         runs with err_final above 100·tol (or above ten times the reference's own error, \
         where that is larger): **{wrong} of {} adaptive runs** (target 0); {gross} of them \
         are off by more than half the solution's size.\n\n",
        super::ORDER2_ADAPTIVE_FLOOR,
        super::rows::HIGHER_ORDER_MAX_STEPS,
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

/// The error targets of the stiff-cost comparison.
const STIFF_TARGETS: [f64; 3] = [1e-3, 1e-5, 1e-7];

/// The stiff baselines, in table order.
const STIFF_SOLVERS: [Baseline; 2] = [Baseline::Bdf, Baseline::Esdirk34];

/// How many of the cheapest runs reaching a target (by the sweeps' times) [`retime`] times
/// again: adaptive variational runs, and runs of each stiff baseline. The sweeps time each
/// run once beside other cases, so the adaptive shortlist is long: with 3, it left out the
/// cheapest run to 1e-3 (lobatto4 at tol 0.3, 850 µs timed alone against 991 µs for the
/// run the table then showed). Each adaptive run here takes about a millisecond.
const STIFF_CANDIDATES: (usize, usize) = (8, 2);

/// The rounds of [`retime`].
const STIFF_ROUNDS: usize = 7;

/// Whether an adaptive row of the stiff-cost scene reaches `target`.
fn reaches(r: &Row, target: f64) -> bool {
    r.scene == STIFF_COST_SCENE && !matches!(r.outcome, Outcome::Failed(_)) && r.err_final <= target
}

/// Whether a baseline row of the stiff-cost scene by `solver` reaches `target` (a run
/// identical to the reference is the reference itself: left out).
fn baseline_reaches(r: &BaselineRow, solver: Baseline, target: f64) -> bool {
    r.scene == STIFF_COST_SCENE
        && r.solver == solver
        && r.failure.is_none()
        && r.err_final > 0.0
        && r.err_final <= target
}

/// The `k` cheapest of `n` rows by the sweeps' times among those `ok` keeps, added to `to`.
fn shortlist(
    to: &mut Vec<usize>,
    n: usize,
    k: usize,
    ok: impl Fn(usize) -> bool,
    secs: impl Fn(usize) -> f64,
) {
    let mut v: Vec<usize> = (0..n).filter(|&i| ok(i)).collect();
    v.sort_by(|&a, &b| secs(a).total_cmp(&secs(b)));
    for i in v.into_iter().take(k) {
        if !to.contains(&i) {
            to.push(i);
        }
    }
}

/// Times the stiff-cost comparison's candidates again, after the parallel sweeps: the sweeps
/// time each run once, while rayon runs other cases beside it, and through the stepper with
/// every record and the energy balance, where a baseline run returns its final state alone.
/// Here each candidate runs to its final state alone, in [`STIFF_ROUNDS`] rounds that run
/// them all one after the other, each round starting one further along; each time is the
/// median over the rounds.
pub fn retime(adaptive: &[Row], baselines: &[BaselineRow], cases: &[&dyn Case]) -> StiffTimes {
    let Some(case) = cases.iter().find(|c| c.name() == STIFF_COST_SCENE).copied() else {
        return StiffTimes::default();
    };
    let (mut va, mut ba) = (Vec::new(), Vec::new());
    for target in STIFF_TARGETS {
        let ok = |i: usize| reaches(&adaptive[i], target) && adaptive[i].tol.is_some();
        shortlist(&mut va, adaptive.len(), STIFF_CANDIDATES.0, ok, |i| {
            adaptive[i].seconds
        });
        for solver in STIFF_SOLVERS {
            let ok = |i: usize| baseline_reaches(&baselines[i], solver, target);
            shortlist(&mut ba, baselines.len(), STIFF_CANDIDATES.1, ok, |i| {
                baselines[i].seconds
            });
        }
    }
    va.retain(|&i| adaptive[i].method.parse::<SchemeId>().is_ok());
    if va.is_empty() {
        return StiffTimes::default();
    }
    type Sampler<'a> = Box<dyn FnMut() -> Result<f64, String> + 'a>;
    let mut samplers: Vec<Sampler<'_>> = Vec::new();
    for &i in &va {
        let r = &adaptive[i];
        let (id, tol) = (r.method.parse::<SchemeId>(), r.tol.unwrap_or(f64::NAN));
        samplers.push(Box::new(move || {
            let id = id.clone().map_err(|e| e.to_string())?;
            case.time_adaptive(id, tol)
        }));
    }
    for &i in &ba {
        let r = &baselines[i];
        samplers.push(Box::new(move || case.time_baseline(r.solver, r.tol)));
    }
    let mut fs: Vec<&mut dyn FnMut() -> Result<f64, String>> =
        samplers.iter_mut().map(|f| &mut **f as _).collect();
    match timing::rotated(STIFF_ROUNDS, &mut fs) {
        Ok(m) => StiffTimes {
            rounds: STIFF_ROUNDS,
            adaptive: va.iter().copied().zip(m.iter().copied()).collect(),
            baselines: ba
                .iter()
                .copied()
                .zip(m[va.len()..].iter().copied())
                .collect(),
            failure: None,
        },
        Err(e) => StiffTimes {
            failure: Some(e),
            ..StiffTimes::default()
        },
    }
}

/// One error target of the stiff-cost comparison: the cheapest adaptive variational run and
/// the cheapest run of each stiff baseline reaching it, with their times.
pub(super) struct StiffCost<'a> {
    pub(super) target: f64,
    /// The run and its time.
    pub(super) variational: Option<(&'a Row, f64)>,
    /// Each of [`STIFF_SOLVERS`]' cheapest run and its time.
    pub(super) baselines: [Option<(&'a BaselineRow, f64)>; 2],
}

/// The lines of the stiff-cost comparison: for each target of [`STIFF_TARGETS`] that an
/// adaptive run reaches, the cheapest such run and the cheapest run of each stiff baseline
/// (times from `retime`, or the sweeps' own where they could not be taken again).
pub(super) fn stiff_lines(s: &Summary) -> Vec<StiffCost<'_>> {
    let t = &s.stiff_times;
    let retimed = t.failure.is_none() && !t.adaptive.is_empty();
    let best = |cands: Vec<(usize, f64)>| cands.into_iter().min_by(|a, b| a.1.total_cmp(&b.1));
    STIFF_TARGETS
        .into_iter()
        .map(|target| {
            let v: Vec<(usize, f64)> = if retimed {
                t.adaptive.clone()
            } else {
                s.adaptive
                    .iter()
                    .enumerate()
                    .map(|(i, r)| (i, r.seconds))
                    .collect()
            };
            let b: Vec<(usize, f64)> = if retimed {
                t.baselines.clone()
            } else {
                s.baselines
                    .iter()
                    .enumerate()
                    .map(|(i, r)| (i, r.seconds))
                    .collect()
            };
            let v = v
                .into_iter()
                .filter(|&(i, _)| reaches(&s.adaptive[i], target));
            StiffCost {
                target,
                variational: best(v.collect()).map(|(i, x)| (&s.adaptive[i], x)),
                baselines: STIFF_SOLVERS.map(|solver| {
                    let b = b
                        .iter()
                        .copied()
                        .filter(|&(i, _)| baseline_reaches(&s.baselines[i], solver, target));
                    best(b.collect()).map(|(i, x)| (&s.baselines[i], x))
                }),
            }
        })
        .filter(|c| c.variational.is_some())
        .collect()
}

/// Wall time of the best adaptive variational run over the best stiff baselines' at equal
/// final error, on stiff van der Pol (μ = 10³, T = 2000): the candidates timed again by
/// `retime`, or the sweeps' own times where they could not be.
pub fn stiff_cost(s: &Summary) -> String {
    let scene = STIFF_COST_SCENE;
    let t = &s.stiff_times;
    let retimed = t.failure.is_none() && !t.adaptive.is_empty();
    let lines = stiff_lines(s);
    if lines.is_empty() {
        return String::new();
    }
    let how = if retimed {
        format!(
            "The sweeps time each run once, while rayon runs other cases beside it, and a \
             variational run there goes through the stepper with every record and its energy \
             balance; so the {} cheapest adaptive runs reaching each target and the {} \
             cheapest runs of each baseline (by the sweeps' times) are timed again after the \
             sweeps, one after the other, each to its final state alone as a baseline run \
             returns it, in {} rounds that each start one further along; the times below are \
             the medians over the rounds, and the cheapest by them is shown.",
            STIFF_CANDIDATES.0, STIFF_CANDIDATES.1, t.rounds
        )
    } else {
        format!(
            "Times from the sweeps (one run each, timed while rayon runs other cases beside \
             it: ratios within about 2× are noise){}.",
            t.failure.as_ref().map_or(String::new(), |e| format!(
                "; timing them again failed: {e}"
            ))
        )
    };
    let mut md = format!(
        "### Stiff cost: adaptive against BDF and ESDIRK34\n\n\
         `{scene}` (μ = 10³, T = 2000): for each error target, the cheapest adaptive \
         variational run with err_final at most the target against the cheapest run of each \
         stiff baseline reaching it. {how} Ratio > 1: the variational run is slower.\n\n"
    );
    let time = |r: Option<f64>| r.map_or("–".to_string(), fmt_time);
    let ratio = |c: &StiffCost, k: usize| match (c.variational, c.baselines[k]) {
        (Some((_, v)), Some((_, b))) if b > 0.0 => format!("{:.1}", v / b),
        _ => "–".to_string(),
    };
    md.push_str(&markdown(
        &lines,
        &[
            col("target", |c: &StiffCost| format!("{:.0e}", c.target)),
            col("best adaptive", |c: &StiffCost| {
                c.variational.map_or("–".into(), |(r, _)| {
                    format!("`{}` tol {:.0e}", r.method, r.tol.unwrap_or(f64::NAN))
                })
            }),
            col("its steps", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |(r, _)| r.steps_done.to_string())
            }),
            col("its rejected", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |(r, _)| r.rejected_steps.to_string())
            }),
            col("its err", |c: &StiffCost| {
                c.variational
                    .map_or("–".into(), |(r, _)| format!("{:.1e}", r.err_final))
            }),
            col("its time", move |c: &StiffCost| {
                time(c.variational.map(|(_, x)| x))
            }),
            col("bdf steps", |c: &StiffCost| {
                c.baselines[0].map_or("–".into(), |(r, _)| r.steps.to_string())
            }),
            col("bdf time", move |c: &StiffCost| {
                time(c.baselines[0].map(|(_, x)| x))
            }),
            col("esdirk34 time", move |c: &StiffCost| {
                time(c.baselines[1].map(|(_, x)| x))
            }),
            col("ratio to bdf", move |c: &StiffCost| ratio(c, 0)),
            col("ratio to esdirk34", move |c: &StiffCost| ratio(c, 1)),
        ],
    ));
    md.push_str(&limits(s, &lines));
    md
}

/// What limits the stiff cost, with this run's figures: the rejections of the cheapest run
/// to the first target, the accuracy of the runs at tol 1e-1, and the ladders' tops.
fn limits(s: &Summary, lines: &[StiffCost]) -> String {
    let mut md = String::from(
        "\nWhat limits it, read from the table rather than assumed: the time ratio is the \
         ratio of step counts times the ratio of cost per step. The `steps` columns give the \
         first; each attempt of the variational run, accepted or `rejected`, is one step solve \
         of an s-stage Galerkin system with Newton and one Newton iteration of the (s+1)-stage \
         reference scheme for the estimate, against one BDF step (which typically reuses its \
         Jacobian).",
    );
    if let Some((c, r)) = lines
        .first()
        .and_then(|c| c.variational.map(|(r, _)| (c, r)))
    {
        let attempts = r.steps_done + r.rejected_steps;
        let _ = write!(
            md,
            " The cheapest run to {:.0e} rejected {} of its {attempts} attempts. Rejections \
             come where the solution's time scale changes fastest (the turns of the fast mode, \
             after the start and before each relaxation jump), where the controller's \
             prediction, which assumes an error proportional to h^p from one step to the \
             next, does not hold.",
            c.target, r.rejected_steps
        );
    }
    let at = 1e-1;
    let loose: Vec<&Row> = s
        .adaptive
        .iter()
        .filter(|r| {
            r.scene == STIFF_COST_SCENE
                && r.tol == Some(at)
                && !matches!(r.outcome, Outcome::Failed(_))
        })
        .collect();
    let lo = loose
        .iter()
        .map(|r| r.err_final)
        .fold(f64::INFINITY, f64::min);
    let hi = loose.iter().map(|r| r.err_final).fold(0.0, f64::max);
    if !loose.is_empty() {
        let _ = write!(
            md,
            " The adaptive runs are far more accurate than their tolerance: at tol {at:.0e} \
             the {} schemes that finished ended between {lo:.1e} and {hi:.1e} off. The steps \
             are set by the local error of the propagated solution, which is larger than the \
             global error left after the dissipative fast mode damps it.",
            loose.len()
        );
    }
    let top = |xs: &mut dyn Iterator<Item = f64>| xs.fold(f64::NAN, f64::max);
    let (ta, tb) = (
        top(&mut s.adaptive.iter().filter_map(|r| r.tol)),
        top(&mut s.baselines.iter().map(|r| r.tol)),
    );
    if ta.is_finite() && tb.is_finite() {
        let _ = write!(
            md,
            " The adaptive ladder starts at tol {ta:.0e} and the baselines' at {tb:.0e}"
        );
        if let Some((c, r)) = lines
            .first()
            .and_then(|c| c.variational.map(|(r, _)| (c, r)))
        {
            let _ = write!(
                md,
                ": the cheapest run to {:.0e} is `{}` at tol {:.0e} ({:.1e} off)",
                c.target,
                r.method,
                r.tol.unwrap_or(f64::NAN),
                r.err_final
            );
        }
        md.push('.');
    }
    md.push_str("\n\n");
    md
}
