//! The Markdown section of `step-cost`.

use std::fmt::Write as _;

use super::rows::{Row, Summary};
use crate::report::table::{col, markdown, met};

fn fmt_ns(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.0}"))
}

fn fmt_2(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.2}"))
}

fn fmt_plain(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v}"))
}

/// The Markdown of the step-cost section.
pub fn markdown_section(s: &Summary, quick: bool, plot: Option<&str>) -> String {
    let mut md = String::from("## Step cost\n\n");
    intro(&mut md, s, quick);
    let paper: Vec<&Row> = s
        .rows
        .iter()
        .filter(|r| r.scene == "coupled_van_der_pol" && r.diagnostics == "full")
        .collect();
    paper_table(&mut md, s, &paper);
    targets_speed(&mut md, &paper);
    // The same table: its rows 4–7 follow 1–3.
    targets_resources(&mut md, s);
    diagnostics_table(&mut md, s);
    ensemble_table(&mut md, s);
    slimplectic(&mut md, &paper);
    md.push_str(&super::scaling_section::markdown_section(s, plot));
    compile_and_memory(&mut md, s);
    super::first_run::markdown(&mut md, &s.first_run);
    md
}

fn intro(md: &mut String, s: &Summary, quick: bool) {
    let _ = writeln!(
        *md,
        "Written by `cargo run --release -- step-cost{}` in {:.0} s. Data: `step_cost.csv`. \
         Times are medians over repeats of whole `output::each_step` runs at h = 0.01 from the \
         paper's initial state, divided by the steps; generated (`#[forced_lagrangian]`) and \
         hand-written (`forced_vi_scenes::handwritten`, analytic kernels) runs alternate and \
         share the stepper, predictor, Newton options (`NewtonOptions::default()`) and \
         tolerances. Built with the plain release profile: a fat-LTO, one-codegen-unit build \
         of the same code measured the same within noise (the hot path is generic code \
         monomorphised in this crate anyway), so the workspace adds no profile settings. The machine has two cores shared with other jobs, so expect a few per \
         cent of noise{}.\n",
        if quick { " --quick" } else { "" },
        s.elapsed,
        if quick {
            "; this is the reduced --quick run"
        } else {
            ""
        }
    );
}

fn paper_table(md: &mut String, s: &Summary, paper: &[&Row]) {
    md.push_str(&markdown(
        paper.iter().copied(),
        &[
            col("scheme", |r: &Row| r.method.clone()),
            col("generated ns/step", |r: &Row| fmt_ns(r.generated)),
            col("hand-written ns/step", |r: &Row| fmt_ns(r.handwritten)),
            col("ratio", |r: &Row| fmt_2(r.ratio())),
            col("target ≤ 1.5", |r: &Row| {
                r.ratio().map_or("–", |x| met(x <= 1.5)).to_string()
            }),
            col("Newton iters/step", |r: &Row| fmt_2(r.iters)),
            col("allocs/step", |r: &Row| fmt_plain(r.allocs)),
        ],
    ));
    for r in paper.iter().filter(|r| !r.note.is_empty()) {
        let _ = writeln!(*md, "\n{}: {}", r.method, r.note);
    }
    if !s.same_iterations {
        md.push_str("\nNote: the generated and hand-written runs did not take the same number of Newton iterations for every scheme (the kernels differ in the last bits).\n");
    }
}

/// Targets 1–3 of the issue: the generated/hand-written ratio, lobatto3's step time, Newton.
fn targets_speed(md: &mut String, paper: &[&Row]) {
    md.push_str(
        "\n### Targets of the issue\n\n| target | goal | measured | verdict |\n|---|---|---|---|\n",
    );
    let worst = paper
        .iter()
        .filter_map(|r| Some((r.ratio()?, r.method.as_str())))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((w, m)) = worst {
        let _ = writeln!(
            *md,
            "| 1. generated ÷ hand-written | ≤ 1.5 for every scheme | worst {w:.2} ({m}) | {} |",
            met(w <= 1.5)
        );
    }
    let l3 = paper.iter().find(|r| r.method == "lobatto3");
    if let Some(t) = l3.and_then(|r| r.generated) {
        let us = t * 1e-3;
        let _ = writeln!(
            *md,
            "| 2. lobatto3 at h = 0.01 | ≤ 1 µs per step | {us:.3} µs per step | {} |",
            met(us <= 1.0)
        );
    }
    let iters = paper
        .iter()
        .filter_map(|r| Some((r.iters?, r.method.as_str())))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((it, m)) = iters {
        let all: Vec<String> = paper
            .iter()
            .filter_map(|r| Some(format!("{} {:.2}", r.method, r.iters?)))
            .collect();
        let _ = writeln!(
            *md,
            "| 3. Newton iterations | ≤ 2.5 per step | worst {it:.2} ({m}); {} | {} |",
            all.join(", "),
            met(it <= 2.5)
        );
    }
}

/// Issue 14: the paper model with and without per-step diagnostics, and its targets.
fn diagnostics_table(md: &mut String, s: &Summary) {
    let find = |m: &str, d: &str| {
        s.rows
            .iter()
            .find(|r| r.scene == "coupled_van_der_pol" && r.method == m && r.diagnostics == d)
    };
    md.push_str(
        "\n### Diagnostics on request\n\n`none` is `Integrator::final_state` (no records: no \
         velocity solve, energy, work or Newton statistics per step); `full` is \
         `output::each_step` with every record. Generated kernels, ns per step, medians.\n\n\
         | scheme | none | full | full ÷ none | hand-written none |\n|---|---|---|---|---|\n",
    );
    let mut worst: Option<(f64, &str)> = None;
    for m in super::SCHEMES {
        let none = find(m, "none").and_then(|r| r.generated);
        let full = find(m, "full").and_then(|r| r.generated);
        let ratio = none.zip(full).map(|(a, b)| b / a);
        if let Some(x) = ratio {
            if worst.is_none_or(|w| x > w.0) {
                worst = Some((x, m));
            }
        }
        let _ = writeln!(
            *md,
            "| {m} | {} | {} | {} | {} |",
            fmt_ns(none),
            fmt_ns(full),
            fmt_2(ratio),
            fmt_ns(find(m, "none").and_then(|r| r.handwritten))
        );
    }
    md.push_str("\n| target (issue 14) | goal | measured | verdict |\n|---|---|---|---|\n");
    for (m, goal) in [("lobatto3", 300.0), ("lobatto5", 800.0)] {
        if let Some(t) = find(m, "none").and_then(|r| r.generated) {
            let _ = writeln!(
                *md,
                "| {m}, final state only | ≤ {goal:.0} ns per step | {t:.0} ns | {} |",
                met(t <= goal)
            );
        }
    }
    if let Some((w, m)) = worst {
        let _ = writeln!(
            *md,
            "| full diagnostics | ≤ 1.3 × final-state cost | worst {w:.2}× ({m}) | {} |",
            met(w <= 1.3)
        );
    }
    // Issue 28's targets for the small-model step, with no diagnostics.
    md.push_str("\n| target (issue 28) | goal | measured | verdict |\n|---|---|---|---|\n");
    for (m, goal) in [("lobatto3", 250.0), ("lobatto5", 700.0)] {
        if let Some(t) = find(m, "none").and_then(|r| r.generated) {
            let _ = writeln!(
                *md,
                "| {m}, final state only | ≤ {goal:.0} ns per step | {t:.0} ns | {} |",
                met(t <= goal)
            );
        }
    }
    let ratios: Vec<(f64, &str)> = super::SCHEMES
        .iter()
        .filter_map(|m| {
            let r = find(m, "none")?;
            Some((r.generated? / r.handwritten?, *m))
        })
        .collect();
    if let Some((w, m)) = ratios.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0)) {
        let _ = writeln!(
            *md,
            "| generated ÷ hand-written, final state only | ≤ 1.05 | worst {w:.2} ({m}) | {} |",
            met(w <= 1.05)
        );
    }
}

/// Issue 14: the ensemble throughput on 1 and 2 threads.
fn ensemble_table(md: &mut String, s: &Summary) {
    md.push_str("\n### Ensembles\n\n");
    let t = match &s.ensemble {
        Ok(t) => t,
        Err(e) => {
            let _ = writeln!(*md, "Not measured: {e}");
            return;
        }
    };
    let _ = writeln!(
        *md,
        "The paper's ensemble through `Integrator::ensemble` with `output::Final` ({}, h = 0.01, T = {}), \
         on rayon pools of 1 and 2 threads, the two alternating over the repeats; \
         `ensemble_throughput.csv`. Members that failed: {}.\n",
        t.method, t.t_final, t.failed
    );
    md.push_str(&markdown(
        t.records.iter(),
        &[
            col("threads", |r: &super::ensemble::ThroughputRecord| {
                r.threads.to_string()
            }),
            col("members", |r: &super::ensemble::ThroughputRecord| {
                r.members.to_string()
            }),
            col(
                "member-steps per second",
                |r: &super::ensemble::ThroughputRecord| {
                    format!("{:.3e}", r.member_steps_per_second)
                },
            ),
        ],
    ));
    if let Some(x) = t.speedup() {
        let _ = writeln!(
            *md,
            "\nSpeed-up on 2 threads: {x:.2}× (target ≥ 1.8×: {}). The machine's two cores are \
             shared with other jobs, which caps what a second thread can give.",
            met(x >= 1.8)
        );
    }
}

/// The peak-RSS marks of the memory stream.
fn rss_marks(s: &Summary) -> Vec<String> {
    s.memory
        .at
        .iter()
        .map(|(k, r)| {
            format!(
                "{:.0e} steps: {}",
                *k as f64,
                r.map_or("n/a".into(), |v| format!("{v} KiB"))
            )
        })
        .collect()
}

/// Targets 4–7: allocations, scaling, compile time, memory.
fn targets_resources(md: &mut String, s: &Summary) {
    let allocs: Vec<f64> = s.rows.iter().filter_map(|r| r.allocs).collect();
    if allocs.is_empty() {
        md.push_str("| 4. allocations | 0 per step | not counted (no counting allocator) | – |\n");
    } else {
        let mx = allocs.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            *md,
            "| 4. allocations | 0 per step | max {mx} per step over all rows | {} |",
            met(mx == 0.0)
        );
    }
    let chain = s
        .exponents
        .iter()
        .filter(|e| e.scene == "fpu_chain" && e.path == "sparse")
        .map(|e| (e.exponent, e.method.as_str()))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    match chain {
        Some((e, m)) => {
            let _ = writeln!(
                *md,
                "| 5. scaling (fpu_chain, sparse path) | ≤ n^1.2 beyond n = 32 | worst n^{e:.2} ({m}); see the scaling section | {} |",
                met(e <= 1.2)
            );
        }
        None => md.push_str(
            "| 5. scaling (fpu_chain, sparse path) | ≤ n^1.2 beyond n = 32 | fewer than two sizes ≥ 32 measured | **not met** (not measured) |\n",
        ),
    }
    match &s.compile {
        Ok(c) => {
            let _ = writeln!(
                *md,
                "| 6. compile time | report | 1 model {:.1} s, 10 models {:.1} s (+{:.1} s, {:.1} s per extra model) | reported |",
                c.one,
                c.ten,
                c.ten - c.one,
                (c.ten - c.one) / 9.0
            );
        }
        Err(e) => {
            let _ = writeln!(*md, "| 6. compile time | report | {e} | – |");
        }
    }
    let rss = rss_marks(s);
    let vals: Vec<u64> = s.memory.at.iter().filter_map(|x| x.1).collect();
    // "Constant": no growth with the steps beyond page-granular noise. The last mark has 100×
    // the steps of the first; even one leaked byte per step would add megabytes.
    let growth = match (vals.first(), vals.last()) {
        (Some(a), Some(b)) => b.saturating_sub(*a),
        _ => 0,
    };
    let constant = vals.len() == s.memory.at.len() && !vals.is_empty() && growth <= 512;
    let _ = writeln!(
        *md,
        "| 7. memory | peak RSS constant in the steps | {} (growth {growth} KiB from the first to the last mark, tolerance 512 KiB) | {} |",
        rss.join("; "),
        if vals.is_empty() {
            "not measured"
        } else {
            met(constant)
        }
    );
}

/// The comparison with slimplectic's step times quoted in the issue.
fn slimplectic(md: &mut String, paper: &[&Row]) {
    let l3 = paper.iter().find(|r| r.method == "lobatto3");
    if let Some(t) = l3.and_then(|r| r.generated) {
        let us = t * 1e-3;
        let l5 = paper
            .iter()
            .find(|r| r.method == "lobatto5")
            .and_then(|r| r.generated)
            .map(|t| t * 1e-3);
        let _ = write!(
            *md,
            "\n**Against slimplectic.** The issue quotes 260–300 µs per step for slimplectic's \
             order-4 scheme and 580–770 µs for order 8 on the same problem. lobatto3 (order 4) \
             takes {us:.3} µs here: {:.0}–{:.0}× faster.",
            260.0 / us,
            300.0 / us
        );
        if let Some(u5) = l5 {
            let _ = write!(
                *md,
                " lobatto5 (order 8) takes {u5:.3} µs: {:.0}–{:.0}× faster.",
                580.0 / u5,
                770.0 / u5
            );
        }
        md.push('\n');
    }
}

fn compile_and_memory(md: &mut String, s: &Summary) {
    let rss = rss_marks(s);
    md.push_str("\n### Compile time and memory\n\n");
    match &s.compile {
        Ok(c) => {
            let _ = writeln!(
                *md,
                "Two throw-away crates under `target/step_cost_compile/` depend on `forced-vi` by \
                 path: one with one `#[forced_lagrangian]` model, one with ten (the report's \
                 models plus a Duffing oscillator, a pendulum and a 3-dof cubic coupling), each \
                 with a function that integrates it with lobatto3 so the stepper is \
                 monomorphised per model. After the dependencies are built, `cargo build \
                 --release` of the crate alone (median of 3 rebuilds) takes **{:.1} s** with one \
                 model and **{:.1} s** with ten: {:.1} s more, about {:.1} s per extra model.\n",
                c.one,
                c.ten,
                c.ten - c.one,
                (c.ten - c.one) / 9.0
            );
        }
        Err(e) => {
            let _ = writeln!(*md, "Compile time: {e}.\n");
        }
    }
    let _ = writeln!(
        *md,
        "Memory: {} steps of the paper model with {} streamed through `output::each_step` in \
         {:.1} s; peak RSS (VmHWM) before the run {}, then {}. The stream runs first, before \
         the large chain sizes, so that their memory does not mask it.",
        s.memory.at.last().map_or(0, |x| x.0),
        s.memory.method,
        s.memory.seconds,
        s.memory
            .before_kib
            .map_or("n/a".into(), |v| format!("{v} KiB")),
        rss.join(", ")
    );
}
