//! The remarks that close the stability section. Every figure in them is this run's,
//! formatted from its rows: a remark written once by hand, with the figures of the run it
//! was written from, went stale as the integrator changed (a stiff-cost ratio of 1.9 quoted
//! beside a regenerated table of 3.0), so the words here only say what the rows show.

use std::fmt::Write as _;

use super::problem::Case;
use super::rows::{BaselineRow, Outcome, Row, Summary};
use super::tally::{best_baseline, best_variational, is_wrong};
use crate::baselines::Baseline;
use crate::report::table::fmt_e;

/// The scenes the remarks speak of (names in [`super::scenes::SCENES`]).
const RELAXATION: &str = "stiff_van_der_pol";
const SCALED: &str = "van_der_pol_scaled_1e6";
const CHAIN: &str = "stiff_spring_chain";
const MILD: [&str; 2] = ["overdamped_oscillator", "coupled_van_der_pol_x100"];

/// A value in at most two significant digits, plainly where it is of moderate size.
fn sig(x: f64) -> String {
    let a = x.abs();
    if !x.is_finite() {
        return "—".into();
    }
    if a != 0.0 && !(1e-2..1e4).contains(&a) {
        return format!("{x:.1e}");
    }
    let decimals = if a == 0.0 {
        0
    } else {
        (1 - a.log10().floor() as i32).max(0) as usize
    };
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `a to b`, or `a` where the two are equal as printed.
fn span(a: String, b: String) -> String {
    if a == b {
        a
    } else {
        format!("{a} to {b}")
    }
}

/// The smallest and largest of some values (`None` if there are none).
fn extent(xs: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    xs.fold(None, |m, x| match m {
        None => Some((x, x)),
        Some((lo, hi)) => Some((lo.min(x), hi.max(x))),
    })
}

/// How a run ended, as the tables above write it (`wrong`: off by more than half the
/// solution's size).
fn label(r: &Row, scale: f64) -> String {
    let wrong = if is_wrong(r, scale) { " (wrong)" } else { "" };
    match &r.outcome {
        Outcome::Failed(kind) => format!("`failed:{kind}`"),
        other => format!("`{other}`{wrong}"),
    }
}

/// A run of equal outcome within one scheme's runs (see [`stretches`]).
struct Stretch {
    /// How the runs ended, as the tables above write it.
    outcome: String,
    /// Their `h`, `hω` or tolerance, first to last.
    at: String,
    /// The steps they took (adaptive runs).
    steps: Option<String>,
    /// Their final errors (finished runs).
    err: Option<String>,
}

/// One scheme's runs, in the order given (by step or tolerance, `x` of each row, `tol`
/// printed as a power of ten), as the stretches of equal outcome: `ok` at h 1 to 0.1 with
/// errors 1e-3 to 1e-6, then `failed:overflow` at h 0.05; with the steps taken where
/// `steps` is set.
fn stretches(
    rows: &[&Row],
    scale: f64,
    tol: bool,
    x: impl Fn(&Row) -> f64,
    steps: bool,
) -> Vec<Stretch> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < rows.len() {
        let l = label(rows[i], scale);
        let mut j = i + 1;
        while j < rows.len() && label(rows[j], scale) == l {
            j += 1;
        }
        let group = &rows[i..j];
        let fmt = |v: f64| if tol { format!("{v:.0e}") } else { sig(v) };
        let at = span(fmt(x(group[0])), fmt(x(group[j - i - 1])));
        let finished = !matches!(group[0].outcome, Outcome::Failed(_));
        let steps = steps.then(|| {
            let (lo, hi) = extent(group.iter().map(|r| r.steps_done as f64)).unwrap_or_default();
            span(format!("{lo}"), format!("{hi}"))
        });
        let err = finished
            .then(|| extent(group.iter().map(|r| r.err_final)))
            .flatten()
            .map(|(lo, hi)| span(fmt_e(lo, 1), fmt_e(hi, 1)));
        out.push(Stretch {
            outcome: l,
            at,
            steps,
            err,
        });
        i = j;
    }
    out
}

/// The stretches of several schemes as one table: a row per stretch, the scheme named on
/// its first; `what` heads the column of steps or tolerances.
fn table(what: &str, schemes: &[(String, Vec<Stretch>)]) -> String {
    let with_steps = schemes
        .iter()
        .any(|(_, st)| st.iter().any(|x| x.steps.is_some()));
    let mut md = format!("\n| scheme | outcome | {what} |");
    md.push_str(if with_steps { " steps |" } else { "" });
    md.push_str(" error |\n|---|---|---|");
    md.push_str(if with_steps { "---|" } else { "" });
    md.push_str("---|\n");
    for (scheme, st) in schemes {
        for (k, x) in st.iter().enumerate() {
            let name = if k == 0 {
                format!("`{scheme}`")
            } else {
                String::new()
            };
            let _ = write!(md, "| {name} | {} | {} |", x.outcome, x.at);
            if with_steps {
                let _ = write!(md, " {} |", x.steps.as_deref().unwrap_or("–"));
            }
            let _ = writeln!(md, " {} |", x.err.as_deref().unwrap_or("–"));
        }
    }
    md.push('\n');
    md
}

/// Each scheme's stretches on `scene`, from `rows` (fixed steps by `h`, largest first, or
/// adaptive runs by tolerance, loosest first), as a table.
fn by_scheme(rows: &[Row], scene: &str, scale: f64, adaptive: bool) -> String {
    let mut methods: Vec<&str> = Vec::new();
    for r in rows.iter().filter(|r| r.scene == scene) {
        if !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    let mut schemes = Vec::new();
    for m in methods {
        let mut rs: Vec<&Row> = rows
            .iter()
            .filter(|r| r.scene == scene && r.method == m)
            .collect();
        let x = |r: &Row| {
            if adaptive {
                r.tol.unwrap_or(f64::NAN)
            } else {
                r.h
            }
        };
        rs.sort_by(|a, b| x(b).total_cmp(&x(a)));
        schemes.push((m.to_string(), stretches(&rs, scale, adaptive, x, adaptive)));
    }
    table(if adaptive { "tol" } else { "h" }, &schemes)
}

/// Each stiff baseline's tolerances on `scene`, those it finished and those it failed.
fn baselines(rows: &[BaselineRow], scene: &str) -> String {
    let mut parts = Vec::new();
    for solver in [Baseline::Bdf, Baseline::Esdirk34] {
        let rs: Vec<&BaselineRow> = rows
            .iter()
            .filter(|r| r.scene == scene && r.solver == solver)
            .collect();
        if rs.is_empty() {
            continue;
        }
        let tols = |ok: bool| {
            let ts: Vec<String> = rs
                .iter()
                .filter(|r| r.failure.is_none() == ok)
                .map(|r| format!("{:.0e}", r.tol))
                .collect();
            if ts.is_empty() {
                None
            } else {
                Some(format!("tol {}", ts.join(", ")))
            }
        };
        let part = match (tols(true), tols(false)) {
            (Some(ok), Some(failed)) => format!("{solver} finished at {ok} and failed at {failed}"),
            (Some(ok), None) => format!("{solver} finished at every {ok}"),
            (None, Some(failed)) => format!("{solver} failed at every {failed}"),
            (None, None) => continue,
        };
        parts.push(part);
    }
    parts.join("; ")
}

/// The chain's `hω` of a step `h`.
fn h_omega(h: f64) -> f64 {
    h * super::scenes::chain_omega_max()
}

/// The remarks, from the run's rows; a scene this run left out (a `--only` run) gets none.
pub fn remarks(s: &Summary, cases: &[&dyn Case], targets: &[f64]) -> String {
    let has = |scene: &str| cases.iter().find(|c| c.name() == scene).copied();
    let mut md = String::from(
        "### Remarks\n\nEvery figure below is this run's, read from the rows above.\n\n",
    );
    if let Some(c) = has(CHAIN) {
        let scale = c.scale();
        let mut rs: Vec<&Row> = s.rows.iter().filter(|r| r.scene == CHAIN).collect();
        rs.sort_by(|a, b| a.h.total_cmp(&b.h));
        let mut methods: Vec<&str> = Vec::new();
        for r in &rs {
            if !methods.contains(&r.method.as_str()) {
                methods.push(&r.method);
            }
        }
        let schemes: Vec<(String, Vec<Stretch>)> = methods
            .iter()
            .map(|m| {
                let mine: Vec<&Row> = rs.iter().copied().filter(|r| r.method == *m).collect();
                let st = stretches(&mine, scale, false, |r| h_omega(r.h), false);
                (m.to_string(), st)
            })
            .collect();
        let _ = write!(
            md,
            "- **The Lobatto schemes are only conditionally stable on stiff oscillations.** \
             With Lobatto quadrature the Galerkin schemes are of partitioned Lobatto \
             IIIA–IIIB type (lobatto2 is Störmer–Verlet), and the midpoint rule is the \
             implicit midpoint rule. None of them is L-stable: they do not damp what they do \
             not resolve. On `{CHAIN}`, by hω (smallest first), each scheme's runs of equal \
             outcome:\n{}",
            table("hω", &schemes)
        );
    }
    if let Some(c) = has(RELAXATION) {
        let _ = write!(
            md,
            "- **Relaxation jumps.** `{RELAXATION}` with fixed steps, by h (largest first), \
             in the table below."
        );
        if let Some(line) = super::adaptive_section::stiff_lines(s).first() {
            if let Some((r, secs)) = line.variational {
                let _ = write!(
                    md,
                    " With error control (Stiff cost above) the cheapest run to {:.0e} is `{}` \
                     at tol {:.0e}: {} steps, {} off",
                    line.target,
                    r.method,
                    r.tol.unwrap_or(f64::NAN),
                    r.steps_done,
                    fmt_e(r.err_final, 1)
                );
                if let Some((_, b)) = line.baselines[0].filter(|(_, b)| *b > 0.0) {
                    let _ = write!(md, ", {:.1} times BDF's time to the same error", secs / b);
                }
                md.push('.');
            }
        }
        md.push('\n');
        md.push_str(&by_scheme(&s.rows, RELAXATION, c.scale(), false));
    }
    if let Some(c) = has(SCALED) {
        let _ = write!(
            md,
            "- **Hairer's scaled form with μ = 10⁶.** Error control per unit step (see \
             Adaptive runs) gives a step of size h the budget tol·h/T of the local error, \
             with T = 2·10⁶ in t: at a jump the steps shrink until the scheme resolves it, \
             and a scheme that cannot before the clock's floor 16ε·t ends in \
             `step_size_too_small`. The stiff baselines: {}. Fixed steps, by h (largest \
             first):\n{}With error control, by tolerance (loosest first):\n{}",
            baselines(&s.baselines, SCALED),
            by_scheme(&s.rows, SCALED, c.scale(), false),
            by_scheme(&s.adaptive, SCALED, c.scale(), true)
        );
    }
    let mild: Vec<&dyn Case> = MILD.iter().filter_map(|n| has(n)).collect();
    if !mild.is_empty() {
        let rows: Vec<&Row> = s
            .rows
            .iter()
            .filter(|r| mild.iter().any(|c| c.name() == r.scene))
            .collect();
        let ok = rows.iter().filter(|r| r.outcome == Outcome::Ok).count();
        let mut ratios = Vec::new();
        for c in &mild {
            for &target in targets.iter().filter(|&&t| c.accuracy() * 10.0 <= t) {
                let v = [
                    best_variational(&s.rows, c.name(), target),
                    best_variational(&s.adaptive, c.name(), target),
                ]
                .into_iter()
                .flatten()
                .map(|r| r.seconds)
                .min_by(f64::total_cmp);
                let b = [Baseline::Bdf, Baseline::Esdirk34]
                    .into_iter()
                    .filter_map(|solver| best_baseline(&s.baselines, c.name(), solver, target))
                    .map(|r| r.seconds)
                    .min_by(f64::total_cmp);
                if let (Some(v), Some(b)) = (v, b) {
                    if b > 0.0 {
                        ratios.push(v / b);
                    }
                }
            }
        }
        let names: Vec<String> = mild.iter().map(|c| format!("`{}`", c.name())).collect();
        let _ = write!(
            md,
            "- **Mildly stiff problems.** On {}, {ok} of {} fixed-step runs finish `ok`",
            names.join(" and "),
            rows.len()
        );
        if let Some((lo, hi)) = extent(ratios.iter().copied()) {
            let _ = write!(
                md,
                "; the cheapest variational run to a target takes {} times the cheapest stiff \
                 baseline's time ({} targets; single runs on a shared machine: read ratios \
                 within about 2 as ties)",
                span(sig(lo), sig(hi)),
                ratios.len()
            );
        }
        md.push_str(".\n");
    }
    let scale = |r: &Row| {
        cases
            .iter()
            .find(|c| c.name() == r.scene)
            .map_or(f64::INFINITY, |c| c.scale())
    };
    let balance = extent(
        s.rows
            .iter()
            .filter(|r| r.method == "midpoint" && is_wrong(r, scale(r)))
            .map(|r| r.max_energy_balance_err),
    );
    md.push_str(
        "- **`ok` is not `accurate`.** The runtime sees finite values and a converged Newton \
         solve; it cannot see a run that is stable but wrong. The `wrong` column and \
         `err_final` do.",
    );
    if let Some((_, hi)) = balance {
        let _ = write!(
            md,
            " Where the midpoint rule finishes wrong, its energy balance error is at most {}: \
             a small energy-balance error is no evidence of accuracy either.",
            fmt_e(hi, 1)
        );
    }
    md.push('\n');
    md
}
