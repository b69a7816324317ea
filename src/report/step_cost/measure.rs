//! The measurements of `step-cost`: the paper model generated against hand-written, the
//! spring-chain scaling, and the peak RSS of a streamed run.

use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi::{RunStats, SchemeId};

use super::rows::{AllocCounter, Memory, Row};
use crate::handwritten::HandCoupledVanDerPol;
use crate::models::{CoupledVanDerPol, SpringChain};
use crate::report::timing::{interleaved, median};

/// The chain sizes of the scaling rows.
pub const CHAIN_SIZES: [usize; 6] = [2, 8, 32, 128, 512, 2048];

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

/// Times one `for_each_step` run: (seconds, stats).
fn timed<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
) -> Result<(f64, RunStats), String> {
    let t0 = Instant::now();
    let stats = integ
        .for_each_step(init, t_final, |r| {
            std::hint::black_box(r);
        })
        .map_err(|e| e.to_string())?;
    Ok((t0.elapsed().as_secs_f64(), stats))
}

/// Nanoseconds per step of one paper-model run: with every record (`full`) through
/// `for_each_step`, or the final state alone (`none`) through `final_state`.
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
        .for_each_step(init, t_final, |_| {
            let c = counter();
            first.get_or_insert(c);
            last = c;
        })
        .map_err(|e| e.to_string())?;
    let first = first.unwrap_or(last);
    Ok(last.saturating_sub(first) as f64 / stats.steps.max(1) as f64)
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
            let counter = counter.filter(|_| diagnostics == "full");
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
        let ag = allocs_per_step(&ig, PAPER_INIT, t_final, c)?;
        let ah = allocs_per_step(&ih, PAPER_INIT, t_final, c)?;
        row.allocs = Some(ag.max(ah));
    }
    Ok(())
}

/// A chain state with a smooth initial displacement.
fn chain_init<const N: usize>() -> InitialState<N> {
    let q = std::array::from_fn(|i| {
        0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64).sin()
    });
    InitialState::from_velocity(q, [0.0; N])
}

/// Measures the chain of `N` masses with `lobatto2`: (ns per step, iterations per step,
/// allocations per step). Allocations are counted inside the timed runs (one relaxed atomic
/// load per step), between the first and the last record.
fn chain_measure<const N: usize>(
    quick: bool,
    counter: Option<AllocCounter>,
) -> Result<(f64, f64, Option<f64>), String> {
    let model = SpringChain::<N>::DEFAULT;
    let integ = Integrator::new(&model, scheme("lobatto2")?, H).map_err(|e| e.to_string())?;
    let init = chain_init::<N>();
    let run = |t_final: f64| -> Result<(f64, RunStats, Option<f64>), String> {
        let mut first: Option<u64> = None;
        let mut last = 0;
        let t0 = Instant::now();
        let stats = integ
            .for_each_step(init, t_final, |r| {
                std::hint::black_box(r);
                if let Some(c) = counter {
                    let c = c();
                    first.get_or_insert(c);
                    last = c;
                }
            })
            .map_err(|e| e.to_string())?;
        let secs = t0.elapsed().as_secs_f64();
        let allocs = first.map(|f| last.saturating_sub(f) as f64 / stats.steps.max(1) as f64);
        Ok((secs, stats, allocs))
    };
    // One step to calibrate; then enough steps for about `budget` seconds per repeat.
    let (t1, s1, _) = run(H)?;
    let per = t1 / s1.steps.max(1) as f64;
    let budget = if quick { 0.1 } else { 1.0 };
    let steps = ((budget / per) as usize).clamp(2, 50_000);
    let repeats = if per * steps as f64 > 1.5 { 1 } else { 5 };
    let t_final = steps as f64 * H;
    let mut ts = Vec::new();
    let mut iters = 0.0;
    let mut allocs = None;
    for _ in 0..repeats {
        let (t, st, al) = run(t_final)?;
        ts.push(t / st.steps.max(1) as f64 * 1e9);
        iters = st.newton_iterations as f64 / st.steps.max(1) as f64;
        allocs = al;
    }
    Ok((median(&mut ts), iters, allocs))
}

/// Stack bytes for the chain of `N` masses. The generated kernel of a const-generic array
/// model differentiates the Lagrangian with `Dual2SVec64<N>` numbers, each holding an `N × N`
/// Hessian, and keeps arrays of `N` of them (positions, velocities, the seed vector) on the
/// stack: about `N³ · 8` bytes per array.
fn chain_stack(n: usize) -> u128 {
    let n = n as u128;
    6 * n * n * n * 8 + (64 << 20)
}

/// The largest stack this command asks for: beyond it a size is reported as infeasible.
const MAX_STACK: u128 = 12 << 30;

/// Runs [`chain_measure`] in a thread with a stack for the kernel's dual numbers.
fn chain_row<const N: usize>(quick: bool, counter: Option<AllocCounter>) -> Row {
    let mut row = skipped_chain(N, String::new());
    let stack = chain_stack(N);
    let spawned = std::thread::Builder::new()
        .name(format!("chain{N}"))
        .stack_size(stack as usize)
        .spawn(move || chain_measure::<N>(quick, counter));
    let out = match spawned {
        Ok(h) => h
            .join()
            .unwrap_or_else(|_| Err("the measuring thread panicked".into())),
        Err(e) => Err(format!(
            "could not start a thread with a {:.1} GiB stack: {e}",
            stack as f64 / (1u64 << 30) as f64
        )),
    };
    match out {
        Ok((ns, it, al)) => {
            row.generated = Some(ns);
            row.iters = Some(it);
            row.allocs = al;
            row.note = "no hand-written chain".into();
        }
        Err(e) => row.note = format!("failed: {e}"),
    }
    row
}

/// A chain row without a measurement, with the reason.
pub fn skipped_chain(n: usize, why: String) -> Row {
    Row {
        scene: "spring_chain".into(),
        method: "lobatto2".into(),
        n,
        diagnostics: "full",
        path: "dense",
        generated: None,
        handwritten: None,
        iters: None,
        allocs: None,
        note: why,
    }
}

/// The chain rows. A size is skipped when its stack need exceeds [`MAX_STACK`] or when the
/// last measured size's step cost, extrapolated as n³, exceeds the per-step time limit.
pub fn chain_rows(quick: bool, counter: Option<AllocCounter>) -> Vec<Row> {
    let limit = if quick { 0.5 } else { 30.0 };
    let mut rows: Vec<Row> = Vec::new();
    let mut last: Option<(usize, f64)> = None;
    for n in CHAIN_SIZES {
        let stack = chain_stack(n);
        if stack > MAX_STACK {
            rows.push(skipped_chain(
                n,
                format!(
                    "infeasible: the generated kernel of SpringChain<N> uses Dual2SVec64<N> (an N×N Hessian per number) and needs about {:.0} GiB of stack and O(n³) work per node",
                    stack as f64 / (1u64 << 30) as f64
                ),
            ));
            continue;
        }
        if let Some((n0, ns)) = last {
            let predicted = ns * 1e-9 * (n as f64 / n0 as f64).powi(3);
            if predicted > limit {
                rows.push(skipped_chain(
                    n,
                    format!(
                        "not run{}: about {predicted:.1} s per step predicted (n³ from n = {n0}), limit {limit} s",
                        if quick { " in --quick" } else { "" }
                    ),
                ));
                continue;
            }
        }
        let row = match n {
            2 => chain_row::<2>(quick, counter),
            8 => chain_row::<8>(quick, counter),
            32 => chain_row::<32>(quick, counter),
            128 => chain_row::<128>(quick, counter),
            512 => chain_row::<512>(quick, counter),
            2048 => chain_row::<2048>(quick, counter),
            _ => skipped_chain(n, "not a compiled size".into()),
        };
        if let Some(ns) = row.generated {
            last = Some((n, ns));
        }
        rows.push(row);
    }
    rows
}

/// Least-squares slope of log(ns) against log(n) for n ≥ 32.
pub fn fit_exponent(rows: &[Row]) -> Option<(f64, Vec<usize>)> {
    let pts: Vec<(usize, f64)> = rows
        .iter()
        .filter(|r| r.scene == "spring_chain" && r.n >= 32)
        .filter_map(|r| Some((r.n, r.generated?)))
        .collect();
    let slope =
        crate::report::orders::slope(&pts.iter().map(|&(n, t)| (n as f64, t)).collect::<Vec<_>>())?;
    Some((slope, pts.iter().map(|p| p.0).collect()))
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
    let _ = integ.for_each_step(PAPER_INIT, total as f64 * H, |r| {
        if marks.contains(&r.step) {
            at.push((r.step, peak_rss_kib()));
        }
    });
    mem.seconds = t0.elapsed().as_secs_f64();
    mem.at = at;
    mem
}
