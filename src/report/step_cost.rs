//! `step-cost`: the cost of one step, generated kernels against hand-written ones, and how it
//! scales with the model size.
//!
//! Writes into the report folder:
//!
//! ```text
//! step_cost.csv           scene,method,n,ns_per_step_generated,ns_per_step_handwritten,ratio,
//!                         newton_iters_per_step,allocs_per_step
//! step_cost_scaling.svg   time per step against n for the damped spring chain
//! sections/step_cost.md   the section of README.md (targets of issue 6, met or not)
//! ```
//!
//! - `coupled_van_der_pol` rows: the paper's model ([`CoupledVanDerPol::PAPER`]) against
//!   [`HandCoupledVanDerPol::PAPER`] for each scheme at `h = 0.01`, through the same
//!   [`Integrator`] (same predictor, Newton options and tolerances). Repeats alternate
//!   generated and hand-written runs so that machine noise hits both alike; the medians are
//!   reported.
//! - `spring_chain` rows: [`SpringChain<N>`] with `lobatto2` for `n = 2 … 2048`, no
//!   hand-written counterpart. Each size runs in its own thread with a stack large enough for
//!   the runtime's static `N × N` node blocks.
//! - allocations: counted by the binary's counting allocator between the first and the last
//!   record of a `for_each_step` run (so the stepper's one-off buffers are excluded), divided
//!   by the steps.
//! - compile time of a crate with one model against one with ten, and the peak RSS of a long
//!   streamed run (full run only for the compile time).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi::{RunStats, SchemeId};
use plotters::prelude::*;

use super::{csv_float, readme, Options, ReportError};
use crate::handwritten::HandCoupledVanDerPol;
use crate::models::{CoupledVanDerPol, SpringChain};

/// Reads the process's heap-allocation count (the binary's counting allocator).
pub type AllocCounter = fn() -> u64;

/// The section name in `report/sections/`.
pub const SECTION: &str = "step_cost";

/// The chain sizes of the scaling rows.
pub const CHAIN_SIZES: [usize; 6] = [2, 8, 32, 128, 512, 2048];

/// The paper-model schemes, in report order.
pub const SCHEMES: [&str; 5] = ["lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint"];

const H: f64 = 0.01;
const PAPER_INIT: InitialState<2> = InitialState::Velocity {
    q: [-0.5, -0.25],
    v: [0.0, 4.0],
};

/// One row of `step_cost.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// `coupled_van_der_pol` or `spring_chain`.
    pub scene: String,
    /// The scheme.
    pub method: String,
    /// Degrees of freedom.
    pub n: usize,
    /// Median ns per step with the `#[forced_lagrangian]` kernels (`None`: not measured).
    pub generated: Option<f64>,
    /// Median ns per step with the hand-written kernels, where there are some.
    pub handwritten: Option<f64>,
    /// Newton iterations per step (generated model).
    pub iters: Option<f64>,
    /// Heap allocations per step (generated model), if an allocation counter was given.
    pub allocs: Option<f64>,
    /// Why the row has no measurement, or other remarks.
    pub note: String,
}

impl Row {
    /// generated ÷ hand-written.
    pub fn ratio(&self) -> Option<f64> {
        Some(self.generated? / self.handwritten?)
    }
}

/// Build times of the one-model and ten-model crates.
#[derive(Clone, Debug, PartialEq)]
pub struct CompileTimes {
    /// Seconds to rebuild the crate with one model (median of the repeats).
    pub one: f64,
    /// Seconds to rebuild the crate with ten models.
    pub ten: f64,
}

/// Peak RSS readings of the streamed run.
#[derive(Clone, Debug, PartialEq)]
pub struct Memory {
    /// The scheme streamed.
    pub method: String,
    /// VmHWM in KiB before the run.
    pub before_kib: Option<u64>,
    /// `(steps, VmHWM in KiB)` after that many steps.
    pub at: Vec<(usize, Option<u64>)>,
    /// Wall time of the whole stream, seconds.
    pub seconds: f64,
}

/// Everything the command measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// The CSV rows.
    pub rows: Vec<Row>,
    /// The fitted exponent of time per step against n for n ≥ 32, and the sizes used.
    pub exponent: Option<(f64, Vec<usize>)>,
    /// The compile-time measurement, or why there is none.
    pub compile: Result<CompileTimes, String>,
    /// The streamed-memory measurement.
    pub memory: Memory,
    /// Whether the hand-written and generated runs took the same Newton iterations.
    pub same_iterations: bool,
    /// Wall time of the command.
    pub elapsed: f64,
}

fn median(xs: &mut [f64]) -> f64 {
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

/// The paper-model rows: generated against hand-written, interleaved repeats.
fn paper_rows(quick: bool, counter: Option<AllocCounter>) -> (Vec<Row>, bool) {
    let (t_final, repeats) = if quick { (20.0, 7) } else { (100.0, 21) };
    let gen = CoupledVanDerPol::PAPER;
    let hand = HandCoupledVanDerPol::PAPER;
    let mut same = true;
    let mut rows = Vec::new();
    for name in SCHEMES {
        let mut row = Row {
            scene: "coupled_van_der_pol".into(),
            method: name.into(),
            n: 2,
            generated: None,
            handwritten: None,
            iters: None,
            allocs: None,
            note: String::new(),
        };
        let result = (|| -> Result<(), String> {
            let s = scheme(name)?;
            let ig = Integrator::new(&gen, s.clone(), H).map_err(|e| e.to_string())?;
            let ih = Integrator::new(&hand, s, H).map_err(|e| e.to_string())?;
            // Warm-up, one of each.
            let (_, sg) = timed(&ig, PAPER_INIT, t_final)?;
            let (_, sh) = timed(&ih, PAPER_INIT, t_final)?;
            same &= sg.newton_iterations == sh.newton_iterations;
            let (mut tg, mut th) = (Vec::new(), Vec::new());
            for k in 0..repeats {
                // Alternate which goes first, so drifts in machine load hit both alike.
                let order: [bool; 2] = if k % 2 == 0 {
                    [true, false]
                } else {
                    [false, true]
                };
                for generated in order {
                    if generated {
                        let (t, st) = timed(&ig, PAPER_INIT, t_final)?;
                        tg.push(t / st.steps.max(1) as f64 * 1e9);
                    } else {
                        let (t, st) = timed(&ih, PAPER_INIT, t_final)?;
                        th.push(t / st.steps.max(1) as f64 * 1e9);
                    }
                }
            }
            row.generated = Some(median(&mut tg));
            row.handwritten = Some(median(&mut th));
            row.iters = Some(sg.newton_iterations as f64 / sg.steps.max(1) as f64);
            if let Some(c) = counter {
                let ag = allocs_per_step(&ig, PAPER_INIT, t_final, c)?;
                let ah = allocs_per_step(&ih, PAPER_INIT, t_final, c)?;
                row.allocs = Some(ag.max(ah));
            }
            Ok(())
        })();
        if let Err(e) = result {
            row.note = format!("failed: {e}");
        }
        rows.push(row);
    }
    (rows, same)
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

fn skipped_chain(n: usize, why: String) -> Row {
    Row {
        scene: "spring_chain".into(),
        method: "lobatto2".into(),
        n,
        generated: None,
        handwritten: None,
        iters: None,
        allocs: None,
        note: why,
    }
}

/// The chain rows. A size is skipped when its stack need exceeds [`MAX_STACK`] or when the
/// last measured size's step cost, extrapolated as n³, exceeds the per-step time limit.
fn chain_rows(quick: bool, counter: Option<AllocCounter>) -> Vec<Row> {
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
fn fit_exponent(rows: &[Row]) -> Option<(f64, Vec<usize>)> {
    let pts: Vec<(usize, f64)> = rows
        .iter()
        .filter(|r| r.scene == "spring_chain" && r.n >= 32)
        .filter_map(|r| Some((r.n, r.generated?)))
        .collect();
    let slope = super::orders::slope(&pts.iter().map(|&(n, t)| (n as f64, t)).collect::<Vec<_>>())?;
    Some((slope, pts.iter().map(|p| p.0).collect()))
}

/// VmHWM (peak RSS) of this process in KiB, from `/proc/self/status`.
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Streams the paper model and reads the peak RSS at the check points.
fn memory(quick: bool) -> Memory {
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

/// The models of the compile-time crates, as `#[forced_lagrangian]` items.
const MODELS: [&str; 10] = [
    r#"#[forced_lagrangian(coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + (1.0 + rho) * y * y) - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot))]
pub struct M0 { pub eps: f64, pub rho: f64, pub lambda: f64 }"#,
    r#"#[forced_lagrangian(coordinates(q1, q2),
    lagrangian = 0.5 * (m11 * q1_dot * q1_dot + 2.0 * m12 * q1_dot * q2_dot + m22 * q2_dot * q2_dot) - 0.5 * (k11 * q1 * q1 + 2.0 * k12 * q1 * q2 + k22 * q2 * q2),
    force(q1 = -(d11 * q1_dot + d12 * q2_dot), q2 = -(d21 * q1_dot + d22 * q2_dot)))]
pub struct M1 { pub m11: f64, pub m12: f64, pub m22: f64, pub k11: f64, pub k12: f64, pub k22: f64, pub d11: f64, pub d12: f64, pub d21: f64, pub d22: f64 }"#,
    r#"#[forced_lagrangian(coordinates(a, b),
    lagrangian = 0.5 * (m1 + m2) * l1 * l1 * a_dot * a_dot + 0.5 * m2 * l2 * l2 * b_dot * b_dot + m2 * l1 * l2 * a_dot * b_dot * (a - b).cos() + (m1 + m2) * g * l1 * a.cos() + m2 * g * l2 * b.cos(),
    force(a = -c * a_dot, b = -c * b_dot))]
pub struct M2 { pub m1: f64, pub m2: f64, pub l1: f64, pub l2: f64, pub g: f64, pub c: f64 }"#,
    r#"#[forced_lagrangian(coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + mu / (x * x + y * y).sqrt(),
    force(x = -gamma * x_dot, y = -gamma * y_dot))]
pub struct M3 { pub mu: f64, pub gamma: f64 }"#,
    r#"#[forced_lagrangian(coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = mu * (1.0 - x * x) * x_dot))]
pub struct M4 { pub mu: f64 }"#,
    r#"#[forced_lagrangian(coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * omega * omega * x * x,
    force(x = -2.0 * zeta * omega * x_dot))]
pub struct M5 { pub omega: f64, pub zeta: f64 }"#,
    r#"#[forced_lagrangian(coordinates(q: [f64; 8]),
    lagrangian = (0..8).map(|i| 0.5 * m * q_dot[i] * q_dot[i]).sum()
        - (0..=8).map(|i| { let left = if i == 0 { 0.0 } else { q[i - 1] }; let right = if i == 8 { 0.0 } else { q[i] }; let d = right - left; 0.5 * k * d * d + 0.25 * beta * d.powi(4) }).sum(),
    force(q[i] = -c * q_dot[i]))]
pub struct M6 { pub m: f64, pub k: f64, pub beta: f64, pub c: f64 }"#,
    r#"#[forced_lagrangian(coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * alpha * x * x - 0.25 * beta * x * x * x * x,
    force(x = -delta * x_dot))]
pub struct M7 { pub alpha: f64, pub beta: f64, pub delta: f64 }"#,
    r#"#[forced_lagrangian(coordinates(th),
    lagrangian = 0.5 * l * l * th_dot * th_dot + g * l * th.cos(),
    force(th = -c * th_dot))]
pub struct M8 { pub g: f64, pub l: f64, pub c: f64 }"#,
    r#"#[forced_lagrangian(coordinates(x, y, z),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot + z_dot * z_dot) - 0.5 * k * (x * x + y * y + z * z) - a * x * y * z,
    force(x = -c * x_dot, y = -c * y_dot, z = -c * z_dot))]
pub struct M9 { pub k: f64, pub a: f64, pub c: f64 }"#,
];

/// Dimension of model `i` of [`MODELS`].
const MODEL_DIMS: [usize; 10] = [2, 2, 2, 2, 1, 1, 8, 1, 1, 3];

fn crate_source(models: usize) -> String {
    let mut src = String::from(
        "//! Generated by `forced-vi-report step-cost` to time compilation.\n#![allow(missing_docs)]\nuse forced_vi::prelude::*;\n\n",
    );
    for (i, m) in MODELS.iter().take(models).enumerate() {
        let n = MODEL_DIMS[i];
        let fields = m
            .rsplit_once('{')
            .map(|(_, f)| f.trim_end_matches('}'))
            .unwrap_or("");
        let init: Vec<String> = fields
            .split(',')
            .filter_map(|f| f.trim().strip_prefix("pub "))
            .filter_map(|f| f.split(':').next())
            .map(|name| format!("{}: 0.5", name.trim()))
            .collect();
        let _ = write!(
            src,
            "{m}\n\n/// One lobatto3 run of M{i}.\npub fn run{i}() -> f64 {{\n    let m = M{i} {{ {} }};\n    let s = Scheme::new(SchemeId::Lobatto(3)).expect(\"scheme\");\n    let integ = Integrator::new(&m, s, 0.01).expect(\"integrator\");\n    let init = InitialState::from_velocity([0.1; {n}], [0.0; {n}]);\n    integ.run(init, 0.1).map(|t| t.last().map_or(0.0, |r| r.q[0])).unwrap_or(f64::NAN)\n}}\n\n",
            init.join(", ")
        );
    }
    src
}

fn run_cargo(dir: &Path, target: &Path) -> Result<f64, String> {
    let t0 = Instant::now();
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["build", "--release", "--offline", "--quiet"])
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", target)
        .output()
        .map_err(|e| format!("cargo: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "cargo build failed in {}: {}",
            dir.display(),
            err.lines().take(8).collect::<Vec<_>>().join(" / ")
        ));
    }
    Ok(t0.elapsed().as_secs_f64())
}

/// Builds a one-model and a ten-model crate under `target/step_cost_compile/` (dependencies
/// first, untimed), then times rebuilds of each crate alone.
fn compile_times() -> Result<CompileTimes, String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let base = root.join("target").join("step_cost_compile");
    let target = base.join("target");
    let lock = root.join("Cargo.lock");
    let mut times = Vec::new();
    for models in [1usize, 10] {
        let dir = base.join(format!("models{models}"));
        let src = dir.join("src");
        std::fs::create_dir_all(&src).map_err(|e| format!("{}: {e}", src.display()))?;
        let manifest = format!(
            "[package]\nname = \"models{models}\"\nversion = \"0.0.0\"\nedition = \"2021\"\npublish = false\n\n[dependencies]\nforced-vi = {{ path = {:?} }}\n\n[workspace]\n",
            root.join("forced-vi").display().to_string()
        );
        std::fs::write(dir.join("Cargo.toml"), manifest).map_err(|e| e.to_string())?;
        if !dir.join("Cargo.lock").exists() {
            std::fs::copy(&lock, dir.join("Cargo.lock")).map_err(|e| e.to_string())?;
        }
        let lib = src.join("lib.rs");
        std::fs::write(&lib, crate_source(models)).map_err(|e| e.to_string())?;
        // Dependencies (and a first build of the crate), untimed.
        run_cargo(&dir, &target)?;
        let mut ts = Vec::new();
        for k in 0..3 {
            // A changed comment forces the crate (only) to rebuild.
            let text = format!("{}// rebuild {k}\n", crate_source(models));
            std::fs::write(&lib, text).map_err(|e| e.to_string())?;
            ts.push(run_cargo(&dir, &target)?);
        }
        times.push(median(&mut ts));
    }
    Ok(CompileTimes {
        one: times[0],
        ten: times[1],
    })
}

fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), csv_float)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<(), ReportError> {
    let mut s = String::from(
        "scene,method,n,ns_per_step_generated,ns_per_step_handwritten,ratio,newton_iters_per_step,allocs_per_step\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            r.scene,
            r.method,
            r.n,
            opt(r.generated),
            opt(r.handwritten),
            opt(r.ratio()),
            opt(r.iters),
            opt(r.allocs)
        );
    }
    std::fs::write(path, s).map_err(ReportError::io(path))
}

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .map_err(|_| "the bundled font is not a valid TrueType file".to_string())
    })
    .clone()
}

/// Time per step against n, log-log, with the fitted slope and an n^1.2 reference line.
fn plot_scaling(path: &Path, rows: &[Row], exponent: Option<f64>) -> Result<bool, String> {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.scene == "spring_chain")
        .filter_map(|r| Some((r.n as f64, r.generated? * 1e-3)))
        .collect();
    if pts.len() < 2 {
        return Ok(false);
    }
    register_font()?;
    let (ylo, yhi) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "spring_chain (lobatto2, h = 0.01): time per step against n",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (1.5f64..3000.0).log_scale(),
            (ylo / 3.0..yhi * 3.0).log_scale(),
        )
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("degrees of freedom n")
        .y_desc("µs per step (median)")
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(|e| e.to_string())?;
    let blue = RGBColor(31, 119, 180);
    let label = match exponent {
        Some(e) => format!("generated kernels, dense LU (slope {e:.2} for n ≥ 32)"),
        None => "generated kernels, dense LU".to_string(),
    };
    chart
        .draw_series(LineSeries::new(
            pts.iter().copied(),
            ShapeStyle::from(blue).stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], blue.stroke_width(2)));
    chart
        .draw_series(
            pts.iter()
                .map(|&p| Circle::new(p, 4, ShapeStyle::from(blue).filled())),
        )
        .map_err(|e| e.to_string())?;
    if let Some(&(n0, t0)) = pts.iter().find(|p| p.0 >= 32.0) {
        let grey = RGBColor(120, 120, 120);
        let line: Vec<(f64, f64)> = [n0, 2048.0]
            .iter()
            .map(|&n| (n, t0 * (n / n0).powf(1.2)))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(
                line,
                8,
                5,
                ShapeStyle::from(grey).stroke_width(2),
            ))
            .map_err(|e| e.to_string())?
            .label("target: n^1.2 from n = 32")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], grey.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

fn met(ok: bool) -> &'static str {
    if ok {
        "**met**"
    } else {
        "**not met**"
    }
}

fn fmt_ns(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.0}"))
}

fn section(s: &Summary, quick: bool, plot: Option<&str>) -> String {
    let mut md = String::from("## Step cost\n\n");
    let _ = writeln!(
        md,
        "Written by `cargo run --release -- step-cost{}` in {:.0} s. Data: `step_cost.csv`. \
         Times are medians over repeats of whole `for_each_step` runs at h = 0.01 from the \
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
    let paper: Vec<&Row> = s
        .rows
        .iter()
        .filter(|r| r.scene == "coupled_van_der_pol")
        .collect();
    md.push_str("| scheme | generated ns/step | hand-written ns/step | ratio | target ≤ 1.5 | Newton iters/step | allocs/step |\n|---|---|---|---|---|---|---|\n");
    for r in &paper {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.method,
            fmt_ns(r.generated),
            fmt_ns(r.handwritten),
            r.ratio().map_or("–".into(), |x| format!("{x:.2}")),
            r.ratio().map_or("–", |x| met(x <= 1.5)),
            r.iters.map_or("–".into(), |x| format!("{x:.2}")),
            r.allocs.map_or("–".into(), |x| format!("{x}")),
        );
    }
    for r in paper.iter().filter(|r| !r.note.is_empty()) {
        let _ = writeln!(md, "\n{}: {}", r.method, r.note);
    }
    if !s.same_iterations {
        md.push_str("\nNote: the generated and hand-written runs did not take the same number of Newton iterations for every scheme (the kernels differ in the last bits).\n");
    }

    md.push_str(
        "\n### Targets of the issue\n\n| target | goal | measured | verdict |\n|---|---|---|---|\n",
    );
    let worst = paper
        .iter()
        .filter_map(|r| Some((r.ratio()?, r.method.as_str())))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((w, m)) = worst {
        let _ = writeln!(
            md,
            "| 1. generated ÷ hand-written | ≤ 1.5 for every scheme | worst {w:.2} ({m}) | {} |",
            met(w <= 1.5)
        );
    }
    let l3 = paper.iter().find(|r| r.method == "lobatto3");
    if let Some(t) = l3.and_then(|r| r.generated) {
        let us = t * 1e-3;
        let _ = writeln!(
            md,
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
            md,
            "| 3. Newton iterations | ≤ 2.5 per step | worst {it:.2} ({m}); {} | {} |",
            all.join(", "),
            met(it <= 2.5)
        );
    }
    let allocs: Vec<f64> = s.rows.iter().filter_map(|r| r.allocs).collect();
    if allocs.is_empty() {
        md.push_str("| 4. allocations | 0 per step | not counted (no counting allocator) | – |\n");
    } else {
        let mx = allocs.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            md,
            "| 4. allocations | 0 per step | max {mx} per step over all rows | {} |",
            met(mx == 0.0)
        );
    }
    match &s.exponent {
        Some((e, ns)) => {
            let _ = writeln!(
                md,
                "| 5. scaling (spring chain) | ≤ n^1.2 beyond n = 32 | n^{e:.2} (fit over n = {}) | {} |",
                ns.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", "),
                met(*e <= 1.2)
            );
        }
        None => md.push_str(
            "| 5. scaling (spring chain) | ≤ n^1.2 beyond n = 32 | fewer than two sizes ≥ 32 measured | **not met** (not measured) |\n",
        ),
    }
    match &s.compile {
        Ok(c) => {
            let _ = writeln!(
                md,
                "| 6. compile time | report | 1 model {:.1} s, 10 models {:.1} s (+{:.1} s, {:.1} s per extra model) | reported |",
                c.one,
                c.ten,
                c.ten - c.one,
                (c.ten - c.one) / 9.0
            );
        }
        Err(e) => {
            let _ = writeln!(md, "| 6. compile time | report | {e} | – |");
        }
    }
    let rss: Vec<String> = s
        .memory
        .at
        .iter()
        .map(|(k, r)| {
            format!(
                "{:.0e} steps: {}",
                *k as f64,
                r.map_or("n/a".into(), |v| format!("{v} KiB"))
            )
        })
        .collect();
    let vals: Vec<u64> = s.memory.at.iter().filter_map(|x| x.1).collect();
    // "Constant": no growth with the steps beyond page-granular noise. The last mark has 100×
    // the steps of the first; even one leaked byte per step would add megabytes.
    let growth = match (vals.first(), vals.last()) {
        (Some(a), Some(b)) => b.saturating_sub(*a),
        _ => 0,
    };
    let constant = vals.len() == s.memory.at.len() && !vals.is_empty() && growth <= 512;
    let _ = writeln!(
        md,
        "| 7. memory | peak RSS constant in the steps | {} (growth {growth} KiB from the first to the last mark, tolerance 512 KiB) | {} |",
        rss.join("; "),
        if vals.is_empty() {
            "not measured"
        } else {
            met(constant)
        }
    );

    if let Some(t) = l3.and_then(|r| r.generated) {
        let us = t * 1e-3;
        let l5 = paper
            .iter()
            .find(|r| r.method == "lobatto5")
            .and_then(|r| r.generated)
            .map(|t| t * 1e-3);
        let _ = write!(
            md,
            "\n**Against slimplectic.** The issue quotes 260–300 µs per step for slimplectic's \
             order-4 scheme and 580–770 µs for order 8 on the same problem. lobatto3 (order 4) \
             takes {us:.3} µs here: {:.0}–{:.0}× faster.",
            260.0 / us,
            300.0 / us
        );
        if let Some(u5) = l5 {
            let _ = write!(
                md,
                " lobatto5 (order 8) takes {u5:.3} µs: {:.0}–{:.0}× faster.",
                580.0 / u5,
                770.0 / u5
            );
        }
        md.push('\n');
    }

    md.push_str("\n### Scaling: damped spring chain\n\n");
    md.push_str(
        "`SpringChain<N>` (nearest-neighbour springs `kΔ²/2 + βΔ⁴/4`, damping `−cv`) with \
         lobatto2 at h = 0.01 from a half-sine displacement, generated kernels only. The \
         runtime is dense: static `SMatrix<f64, N, N>` node blocks, a dense Jacobian \
         assembly and a dense LU of the `(s−1)n` unknowns, O(n³) per Newton iteration. But \
         the LU is not what dominates here: for a const-generic array model the macro's kernel \
         differentiates the whole Lagrangian with `Dual2SVec64<N>` numbers (each carrying an \
         `N × N` Hessian) over O(n) operations, so one node Jacobian costs O(n³) flops and \
         about n³·8 bytes of stack per array of duals (n = 128: a 128-unknown LU is about \
         0.7 Mflop, far below the measured step time). Each size runs in a thread with a stack \
         sized for those duals.\n\n",
    );
    md.push_str(
        "| n | µs per step | Newton iters/step | allocs/step | note |\n|---|---|---|---|---|\n",
    );
    for r in s.rows.iter().filter(|r| r.scene == "spring_chain") {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} |",
            r.n,
            r.generated
                .map_or("–".into(), |v| format!("{:.3}", v * 1e-3)),
            r.iters.map_or("–".into(), |x| format!("{x:.2}")),
            r.allocs.map_or("–".into(), |x| format!("{x}")),
            r.note
        );
    }
    if let Some((e, _)) = &s.exponent {
        let _ = writeln!(
            md,
            "\nFitted growth beyond n = 32: time per step ∝ n^{e:.2}, against the target n^1.2: {}. \
             Meeting it needs a block-banded or sparse Jacobian and a sparse LU (the issue \
             suggests faer `sp_lu`), which this dense runtime does not have, and first of all a kernel for array models \
             that differentiates each Lagrangian term over the few coordinates it touches \
             instead of all n at once.",
            met(*e <= 1.2)
        );
    }
    if let Some(p) = plot {
        let _ = writeln!(md, "\n![time per step against n]({p})");
    }

    md.push_str("\n### Compile time and memory\n\n");
    match &s.compile {
        Ok(c) => {
            let _ = writeln!(
                md,
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
            let _ = writeln!(md, "Compile time: {e}.\n");
        }
    }
    let _ = writeln!(
        md,
        "Memory: {} steps of the paper model with {} streamed through `for_each_step` in \
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
    md
}

/// Runs the step-cost measurements and writes `step_cost.csv`, the scaling plot and the
/// section. `counter` reads the binary's counting allocator; without it the allocation
/// column stays empty.
pub fn run(opts: &Options, counter: Option<AllocCounter>) -> Result<Summary, ReportError> {
    let t0 = Instant::now();
    std::fs::create_dir_all(&opts.out).map_err(ReportError::io(&opts.out))?;
    eprintln!("step-cost: streaming the paper model for peak RSS …");
    let memory = memory(opts.quick);
    eprintln!("step-cost: generated against hand-written …");
    let (mut rows, same_iterations) = paper_rows(opts.quick, counter);
    eprintln!("step-cost: spring-chain scaling …");
    rows.extend(chain_rows(opts.quick, counter));
    let exponent = fit_exponent(&rows);
    let compile = if opts.quick {
        Err("not measured in --quick (it builds two crates; see the full run)".to_string())
    } else {
        eprintln!("step-cost: compile times …");
        compile_times()
    };
    let csv = opts.out.join("step_cost.csv");
    write_csv(&csv, &rows)?;
    let svg = opts.out.join("step_cost_scaling.svg");
    let plotted = plot_scaling(&svg, &rows, exponent.as_ref().map(|e| e.0)).map_err(|message| {
        ReportError::Plot {
            path: svg.clone(),
            message,
        }
    })?;
    let mut summary = Summary {
        rows,
        exponent,
        compile,
        memory,
        same_iterations,
        elapsed: 0.0,
    };
    summary.elapsed = t0.elapsed().as_secs_f64();
    let md = section(
        &summary,
        opts.quick,
        plotted.then_some("step_cost_scaling.svg"),
    );
    readme::write_section(&opts.out, SECTION, &md)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_fit() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        let rows: Vec<Row> = [32usize, 128, 512]
            .iter()
            .map(|&n| Row {
                generated: Some((n as f64).powi(2)),
                ..skipped_chain(n, String::new())
            })
            .collect();
        let (e, ns) = fit_exponent(&rows).unwrap();
        assert!((e - 2.0).abs() < 1e-9);
        assert_eq!(ns, [32, 128, 512]);
    }

    #[test]
    fn compile_crate_source_has_every_model() {
        let src = crate_source(10);
        for i in 0..10 {
            assert!(src.contains(&format!("pub fn run{i}()")));
            assert!(src.contains(&format!("pub struct M{i}")));
        }
        assert!(crate_source(1).contains("M0 { eps: 0.5, rho: 0.5, lambda: 0.5 }"));
    }
}
