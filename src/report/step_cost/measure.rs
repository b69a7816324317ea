//! The measurements of `step-cost`: the paper model generated against hand-written (with and
//! without diagnostics) and the peak RSS of a streamed run.

use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi::{RunStats, SchemeId};

use super::rows::{AllocCounter, Memory, Row};
use crate::handwritten::HandCoupledVanDerPol;
use crate::models::CoupledVanDerPol;
use crate::report::timing::interleaved;

/// The paper-model schemes, in report order.
pub const SCHEMES: [&str; 5] = ["lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint"];

/// The step size of every run.
pub const H: f64 = 0.01;
const PAPER_INIT: InitialState<2> = InitialState::Velocity {
    q: [-0.5, -0.25],
    v: [0.0, 4.0],
};

fn scheme(name: &str) -> Result<Scheme, String> {
    let id: SchemeId = name.parse().map_err(|e| format!("{name}: {e}"))?;
    Scheme::new(id).map_err(|e| format!("{name}: {e}"))
}

/// Times one `output::each_step` run: (seconds, stats).
fn timed<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
) -> Result<(f64, RunStats), String> {
    let t0 = Instant::now();
    let stats = integ
        .solve(
            init,
            t_final,
            output::each_step(|r| {
                std::hint::black_box(r);
            }),
        )
        .map_err(|e| e.to_string())?;
    Ok((t0.elapsed().as_secs_f64(), stats))
}

/// Nanoseconds per step of one paper-model run: with every record (`full`) through
/// `output::each_step`, or the final state alone (`none`) through `final_state`.
fn ns_per_step<M: ForcedLagrangian<2>>(
    integ: &Integrator<'_, M, 2>,
    t_final: f64,
    diagnostics: &str,
) -> Result<f64, String> {
    let (t, st) = if diagnostics == "none" {
        let t0 = Instant::now();
        let end = integ
            .final_state(PAPER_INIT, t_final)
            .map_err(|e| e.to_string())?;
        std::hint::black_box(&end);
        (t0.elapsed().as_secs_f64(), end.stats)
    } else {
        timed(integ, PAPER_INIT, t_final)?
    };
    Ok(t / st.steps.max(1) as f64 * 1e9)
}

/// Allocations per step between the first record and the last.
fn allocs_per_step<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
    counter: AllocCounter,
) -> Result<f64, String> {
    let mut first: Option<u64> = None;
    let mut last = 0;
    let stats = integ
        .solve(
            init,
            t_final,
            output::each_step(|_| {
                let c = counter();
                first.get_or_insert(c);
                last = c;
            }),
        )
        .map_err(|e| e.to_string())?;
    let first = first.unwrap_or(last);
    Ok(last.saturating_sub(first) as f64 / stats.steps.max(1) as f64)
}

/// Allocations per step of the final-state run (no diagnostics): the difference between a
/// run to `t_final` and one to half of it, over the difference of their steps, so that what
/// a run allocates once (its buffers) cancels.
fn allocs_per_step_lean<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
    counter: AllocCounter,
) -> Result<f64, String> {
    let run = |t| {
        let before = counter();
        let end = integ.final_state(init, t).map_err(|e| e.to_string())?;
        Ok::<_, String>((counter() - before, end.stats.steps))
    };
    let (a_half, s_half) = run(0.5 * t_final)?;
    let (a_full, s_full) = run(t_final)?;
    Ok(a_full.saturating_sub(a_half) as f64 / s_full.saturating_sub(s_half).max(1) as f64)
}

/// Which run each paper-model row times, in report order.
pub const DIAGNOSTICS: [&str; 2] = ["full", "none"];

/// The paper-model rows: generated against hand-written, interleaved repeats, for each
/// scheme with full diagnostics and with the final state alone.
pub fn paper_rows(quick: bool, counter: Option<AllocCounter>) -> (Vec<Row>, bool) {
    let mut same = true;
    let mut rows = Vec::new();
    for diagnostics in DIAGNOSTICS {
        for name in SCHEMES {
            let mut row = Row {
                scene: "coupled_van_der_pol".into(),
                method: name.into(),
                n: 2,
                diagnostics,
                path: "dense",
                generated: None,
                handwritten: None,
                iters: None,
                allocs: None,
                note: String::new(),
            };
            if let Err(e) = paper_row(&mut row, quick, counter, &mut same) {
                row.note = format!("failed: {e}");
            }
            rows.push(row);
        }
    }
    (rows, same)
}

/// Measures one paper-model row in place.
fn paper_row(
    row: &mut Row,
    quick: bool,
    counter: Option<AllocCounter>,
    same: &mut bool,
) -> Result<(), String> {
    let (t_final, repeats) = if quick { (20.0, 7) } else { (100.0, 21) };
    let gen = CoupledVanDerPol::PAPER;
    let hand = HandCoupledVanDerPol::PAPER;
    let s = scheme(&row.method)?;
    let ig = Integrator::new(&gen, s.clone(), H).map_err(|e| e.to_string())?;
    let ih = Integrator::new(&hand, s, H).map_err(|e| e.to_string())?;
    // Warm-up, one of each.
    let (_, sg) = timed(&ig, PAPER_INIT, t_final)?;
    let (_, sh) = timed(&ih, PAPER_INIT, t_final)?;
    *same &= sg.newton_iterations == sh.newton_iterations;
    let d = row.diagnostics;
    let (g, h) = interleaved(
        repeats,
        || ns_per_step(&ig, t_final, d),
        || ns_per_step(&ih, t_final, d),
    )?;
    row.generated = Some(g);
    row.handwritten = Some(h);
    row.iters = Some(sg.newton_iterations as f64 / sg.steps.max(1) as f64);
    if let Some(c) = counter {
        let (ag, ah) = if d == "full" {
            let ag = allocs_per_step(&ig, PAPER_INIT, t_final, c)?;
            (ag, allocs_per_step(&ih, PAPER_INIT, t_final, c)?)
        } else {
            let ag = allocs_per_step_lean(&ig, PAPER_INIT, t_final, c)?;
            (ag, allocs_per_step_lean(&ih, PAPER_INIT, t_final, c)?)
        };
        row.allocs = Some(ag.max(ah));
    }
    Ok(())
}

/// VmHWM (peak RSS) of this process in KiB, from `/proc/self/status`.
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Streams the paper model and reads the peak RSS at the check points.
pub fn memory(quick: bool) -> Memory {
    let marks: Vec<usize> = if quick {
        vec![10_000, 100_000, 1_000_000]
    } else {
        vec![100_000, 1_000_000, 10_000_000]
    };
    let method = "midpoint";
    let mut mem = Memory {
        method: method.into(),
        before_kib: peak_rss_kib(),
        at: Vec::new(),
        seconds: 0.0,
    };
    let Ok(s) = scheme(method) else { return mem };
    let model = CoupledVanDerPol::PAPER;
    let Ok(integ) = Integrator::new(&model, s, H) else {
        return mem;
    };
    let total = marks.last().copied().unwrap_or(0);
    let t0 = Instant::now();
    let mut at = Vec::new();
    let _ = integ.solve(
        PAPER_INIT,
        total as f64 * H,
        output::each_step(|r| {
            if marks.contains(&r.step) {
                at.push((r.step, peak_rss_kib()));
            }
        }),
    );
    mem.seconds = t0.elapsed().as_secs_f64();
    mem.at = at;
    mem
}
