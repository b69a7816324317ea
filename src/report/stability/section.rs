//! The Markdown section of the stability study.

use std::fmt::Write as _;

use super::adaptive_section::{adaptive, stiff_cost};
use super::problem::Case;
use super::rows::{BaselineRow, Row, Summary, MAX_SUBDIVISIONS};
use super::scenes::Planned;
use super::tally::{best_baseline, best_variational, failed_by_kind, is_wrong, Counts};
use crate::baselines::Baseline;
use crate::report::table::{col, fmt_e, markdown};

/// The error targets of the comparison with the stiff baselines.
const TARGETS: [f64; 4] = [1e-2, 1e-4, 1e-6, 1e-8];

/// The Markdown of the stability section.
pub fn markdown_section(s: &Summary, planned: &[&Planned], quick: bool) -> String {
    let cases: Vec<&dyn Case> = planned.iter().map(|(c, _)| c.as_ref()).collect();
    let mut md = String::from("## Stability on stiff and extreme cases\n\n");
    let _ = writeln!(
        md,
        "Written by `cargo run --release -- stability{}` in {:.0} s (two threads; rayon runs \
         the cases in parallel). Every case runs with step subdivision allowed: a step whose \
         Newton solve fails is retried as 2, 4, …, {} substeps that land back on the output \
         grid. Rows are in [stability.csv](stability.csv): `outcome` is `ok`, `recovered` (the \
         run finished and some step was subdivided) or `failed:<kind>` (the error that stopped \
         the run; the steps before it are kept), `err_final` is the max-norm position error at \
         the final time, `max_energy_balance_err` the largest |E(t) − E(0) − W(t)| over the \
         steps done. A run whose final state, error or energy balance is not finite is never \
         `ok` (it would show as `failed:non_finite_result`), and a panic would show as \
         `failed:panic`.\n",
        if quick { " --quick" } else { "" },
        s.elapsed,
        1u32 << MAX_SUBDIVISIONS
    );
    md.push_str(&scenes_table(planned));
    md.push_str(&outcomes(s, &cases));
    md.push_str(&runs(s, &cases));
    md.push_str(&adaptive(s, &cases));
    md.push_str(&stiff_cost(s));
    md.push_str(&against_baselines(s, planned, &cases));
    md.push_str(&baseline_failures(s));
    md.push_str(&super::remarks::remarks(s, &cases, &TARGETS));
    md.push('\n');
    md
}

fn scenes_table(planned: &[&Planned]) -> String {
    let mut md = String::from("### Scenes and grids\n\n");
    md.push_str(&markdown(
        planned,
        &[
            col("scene", |p: &&Planned| format!("`{}`", p.0.name())),
            col("what", |p: &&Planned| p.0.description().to_string()),
            col("methods", |p: &&Planned| {
                let ms: Vec<String> = p.1.methods.iter().map(|m| m.to_string()).collect();
                ms.join(", ")
            }),
            col("h", |p: &&Planned| {
                let hs: Vec<String> = p.1.hs.iter().map(|h| format!("{h:.3e}")).collect();
                hs.join(", ")
            }),
            col("reference (estimated error)", |p: &&Planned| {
                format!("{} (~{:.0e})", p.0.reference_note(), p.0.accuracy())
            }),
        ],
    ));
    let _ = writeln!(
        md,
        "\nLong runs: on `stiff_van_der_pol` (T = 2000) h = 2e-3 is 10⁶ steps and h = 1e-4 is \
         2·10⁷ steps per method; its grid stops at 1e-4 because 5e-5 would double the cost of \
         the whole command. The scaled μ = 10⁶ form, the over-damped oscillator and the \
         large-amplitude scene cover h = 1 down to 5e-5 (the chain's h is set by hω instead). \
         With `--quick` the grids shrink to the values shown by that run.\n"
    );
    md
}

fn outcomes(s: &Summary, cases: &[&dyn Case]) -> String {
    let mut counts: Vec<Counts> = cases
        .iter()
        .map(|c| {
            let rs: Vec<&Row> = s.rows.iter().filter(|r| r.scene == c.name()).collect();
            Counts::of(c.name(), &rs, c.scale())
        })
        .collect();
    let total = Counts {
        scene: "all".into(),
        runs: counts.iter().map(|c| c.runs).sum(),
        ok: counts.iter().map(|c| c.ok).sum(),
        recovered: counts.iter().map(|c| c.recovered).sum(),
        wrong: counts.iter().map(|c| c.wrong).sum(),
        failed: vec![(String::new(), counts.iter().map(Counts::failed_total).sum())],
    };
    counts.push(total);
    let mut md = String::from(
        "### Outcomes\n\n`wrong` counts the runs that finished (`ok` or `recovered`) with \
         `err_final` above half the solution's size (max-norm of q(0) and the reference): \
         finite, but no better than a guess. The runtime has no way to see this; the outcome \
         column does not either.\n\n",
    );
    md.push_str(&markdown(
        &counts,
        &[
            col("scene", |c: &Counts| c.scene.clone()),
            col("runs", |c: &Counts| c.runs.to_string()),
            col("ok", |c: &Counts| c.ok.to_string()),
            col("recovered", |c: &Counts| c.recovered.to_string()),
            col("of which wrong", |c: &Counts| c.wrong.to_string()),
            col("failed (by kind)", failed_by_kind),
        ],
    ));
    md.push('\n');
    md
}

fn runs(s: &Summary, cases: &[&dyn Case]) -> String {
    let scale = |r: &Row| {
        cases
            .iter()
            .find(|c| c.name() == r.scene)
            .map_or(f64::INFINITY, |c| c.scale())
    };
    let wrong = move |r: &Row| {
        if is_wrong(r, scale(r)) {
            " (wrong)"
        } else {
            ""
        }
    };
    let mut md = String::from("### Runs\n\n");
    md.push_str(&markdown(
        &s.rows,
        &[
            col("scene", |r: &Row| format!("`{}`", r.scene)),
            col("method", |r: &Row| r.method.clone()),
            col("h", |r: &Row| format!("{:.3e}", r.h)),
            col("outcome", move |r: &Row| {
                format!("{}{}", r.outcome, wrong(r))
            }),
            col("steps", |r: &Row| r.steps_done.to_string()),
            col("subdivided", |r: &Row| r.subdivided_steps.to_string()),
            col("max Newton", |r: &Row| r.max_newton_iters.to_string()),
            col("err_final", |r: &Row| fmt_e(r.err_final, 1)),
            col("max energy balance", |r: &Row| {
                fmt_e(r.max_energy_balance_err, 1)
            }),
            col("s", |r: &Row| format!("{:.2}", r.seconds)),
        ],
    ));
    md
}

/// One line of the comparison: a scene, a target and the cheapest run of each side.
struct Comparison {
    scene: &'static str,
    target: f64,
    cells: [String; 5],
}

/// Who was faster, counted over the measurable (scene, target) pairs.
#[derive(Default)]
struct Wins {
    pairs: usize,
    variational: usize,
    baseline: usize,
    tie: usize,
}

/// The verdict of one comparison, counted into `wins`.
fn faster(v: Option<&Row>, best: Option<&BaselineRow>, wins: &mut Wins) -> String {
    match (v, best) {
        (None, None) => "neither".to_string(),
        (Some(_), None) => {
            wins.variational += 1;
            "variational (baselines never reach it)".to_string()
        }
        (None, Some(bb)) => {
            wins.baseline += 1;
            format!("{} (variational never reaches it)", bb.solver)
        }
        (Some(vr), Some(bb)) => {
            let ratio = vr.seconds / bb.seconds.max(1e-9);
            if ratio < 0.5 {
                wins.variational += 1;
                format!("variational ({:.1}× faster)", 1.0 / ratio)
            } else if ratio > 2.0 {
                wins.baseline += 1;
                format!("{} ({:.1}× faster)", bb.solver, ratio)
            } else {
                wins.tie += 1;
                format!("tie ({ratio:.2}×)")
            }
        }
    }
}

fn compare(s: &Summary, c: &dyn Case, target: f64, wins: &mut Wins) -> Comparison {
    // Targets within 10x of the reference's own error are not measurable.
    if c.accuracy() * 10.0 > target {
        let note = format!(
            "not measurable: the reference is only good to about {:.0e}",
            c.accuracy()
        );
        return Comparison {
            scene: c.name(),
            target,
            cells: [
                note,
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ],
        };
    }
    wins.pairs += 1;
    let v = best_variational(&s.rows, c.name(), target);
    let a = best_variational(&s.adaptive, c.name(), target);
    let b = best_baseline(&s.baselines, c.name(), Baseline::Bdf, target);
    let e = best_baseline(&s.baselines, c.name(), Baseline::Esdirk34, target);
    let vs = v.map_or("—".to_string(), |r| {
        format!("{} h={:.1e}: {:.2e} s", r.method, r.h, r.seconds)
    });
    let as_ = a.map_or("—".to_string(), |r| {
        let tol = r.tol.unwrap_or(f64::NAN);
        format!("{} tol {tol:.0e}: {:.2e} s", r.method, r.seconds)
    });
    let v = [v, a]
        .into_iter()
        .flatten()
        .min_by(|x, y| x.seconds.total_cmp(&y.seconds));
    let bs = |x: Option<&BaselineRow>| {
        x.map_or("—".to_string(), |r| {
            format!("{:.0e}: {:.2e} s", r.tol, r.seconds)
        })
    };
    let best = [b, e]
        .into_iter()
        .flatten()
        .min_by(|x, y| x.seconds.total_cmp(&y.seconds));
    Comparison {
        scene: c.name(),
        target,
        cells: [vs, as_, bs(b), bs(e), faster(v, best, wins)],
    }
}

fn against_baselines(s: &Summary, planned: &[&Planned], cases: &[&dyn Case]) -> String {
    let tols = planned.first().map_or(String::new(), |p| {
        let ts: Vec<String> = p.1.tols.iter().map(|t| format!("{t:.0e}")).collect();
        ts.join(", ")
    });
    let mut md = format!(
        "\n### Against the stiff baselines\n\n\
         The same scenes with diffsol's BDF and ESDIRK34 (`rtol = atol = tol`, Jacobian by \
         forward differences) over tolerances {tols}. For each error target the table gives the \
         cheapest measured run, by wall time, whose final position error is at most the \
         target (variational: over all schemes and step sizes above, and apart over the \
         adaptive runs; `—`: no run reached it). The verdict takes the faster of the two \
         variational runs. Times are single runs on a shared two-core machine, with another case running \
         alongside: read ratios below about 2 as ties.\n\n"
    );
    let mut wins = Wins::default();
    let lines: Vec<Comparison> = cases
        .iter()
        .flat_map(|c| TARGETS.map(|t| (*c, t)))
        .map(|(c, t)| compare(s, c, t, &mut wins))
        .collect();
    let cell = |k: usize| move |c: &Comparison| c.cells[k].clone();
    md.push_str(&markdown(
        &lines,
        &[
            col("scene", |c: &Comparison| format!("`{}`", c.scene)),
            col("target", |c: &Comparison| format!("{:.0e}", c.target)),
            col("variational: best (method, h, s)", cell(0)),
            col("adaptive: best (method, tol, s)", cell(1)),
            col("bdf (tol, s)", cell(2)),
            col("esdirk34 (tol, s)", cell(3)),
            col("faster", cell(4)),
        ],
    ));
    let _ = writeln!(
        md,
        "\nOver these {} (scene, target) pairs, as measured: the variational schemes are \
         clearly faster in {}, a stiff baseline in {}, and {} are within a factor 2.\n",
        wins.pairs, wins.variational, wins.baseline, wins.tie
    );
    md
}

fn baseline_failures(s: &Summary) -> String {
    let failures: Vec<&BaselineRow> = s.baselines.iter().filter(|r| r.failure.is_some()).collect();
    if failures.is_empty() {
        return String::new();
    }
    let mut md = String::from("Baseline runs that failed:\n\n");
    for r in failures {
        let why = r.failure.as_deref().unwrap_or("");
        let _ = writeln!(
            md,
            "- `{}` {} at tol {:.0e}: {why}",
            r.scene, r.solver, r.tol
        );
    }
    md.push('\n');
    md
}
