//! Large models in the work-precision report: the FPU chain and the 2-D lattice at
//! n = 1024 on the sparse backend, fixed steps (lobatto3, lobatto4 over `h`) beside
//! adaptive ones (`Integrator::adaptive` over the tolerance), against a lobatto5 reference
//! with fixed steps, as the large-model tests use. The rows go to `work_precision.csv` with
//! the scene names [`FPU_CHAIN`] and [`LATTICE_2D`]; the section gets a table of them.
//!
//! Left out of `--quick` (a lattice reference alone takes a few seconds).

use forced_vi::prelude::*;
use forced_vi::RunStats;

use super::rows::{Failure, Mode, Row, Spread};
use crate::large::{FpuChain, Lattice2d};
use crate::report::timing::{median, timed};
use crate::report::Method;

/// The chain's scene name in `work_precision.csv`.
pub const FPU_CHAIN: &str = "fpu_chain_1024";
/// The lattice's scene name in `work_precision.csv`.
pub const LATTICE_2D: &str = "lattice_2d_1024";
/// The runs' lengths: long enough for the smooth initial modes to move by order one (at
/// `T = 1` both models barely move: two steps reach round-off).
pub const T_FINAL: [(&str, f64); 2] = [(FPU_CHAIN, 100.0), (LATTICE_2D, 25.0)];
/// The reference: lobatto5 with this many fixed steps over the run.
pub const REFERENCE_STEPS: usize = 256;
/// Fixed-step runs: `h = T / n` for these `n`.
pub const FIXED_STEPS: [usize; 6] = [8, 16, 32, 64, 128, 256];
/// Adaptive runs: `rtol = atol = tol` for these.
pub const TOLERANCES: [f64; 3] = [1e-4, 1e-6, 1e-8];
/// Timed repeats per run (median).
const REPEATS: usize = 3;

/// The rows and failures of both large models, with the reference's own accuracy per
/// model (the difference between the reference and lobatto5 at half its steps).
pub fn measure() -> (Vec<Row>, Vec<Failure>, Vec<(&'static str, f64)>) {
    let (mut rows, mut failures, mut accuracy) = (Vec::new(), Vec::new(), Vec::new());
    let chain = FpuChain::<1024>::default();
    let lattice = Lattice2d::<32, 1024>::default();
    for (name, (r, f, a)) in [
        (
            FPU_CHAIN,
            sweep(FPU_CHAIN, &chain, FpuChain::<1024>::initial()),
        ),
        (
            LATTICE_2D,
            sweep(LATTICE_2D, &lattice, Lattice2d::<32, 1024>::initial()),
        ),
    ] {
        rows.extend(r);
        failures.extend(f);
        accuracy.push((name, a));
    }
    (rows, failures, accuracy)
}

/// The final `(q, p)` of a run, its energy and its totals.
type End = (Vec<f64>, Vec<f64>, f64, RunStats);

/// The run's length of scene `name`.
pub fn t_final(name: &str) -> f64 {
    T_FINAL
        .iter()
        .find(|(n, _)| *n == name)
        .map_or(1.0, |(_, t)| *t)
}

fn end<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
) -> Result<End, forced_vi::Error> {
    let end = integ.final_state(init, t_final).map_err(|f| f.error)?;
    Ok((
        end.q.as_slice().to_vec(),
        end.p.as_slice().to_vec(),
        end.energy,
        end.stats,
    ))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn sweep<M: ForcedLagrangian<N>, const N: usize>(
    name: &'static str,
    model: &M,
    init: InitialState<N>,
) -> (Vec<Row>, Vec<Failure>, f64) {
    let (mut rows, mut failures) = (Vec::new(), Vec::new());
    let t = t_final(name);
    let reference = |steps: usize| {
        let lobatto5 = Scheme::lobatto(5).ok()?;
        let integ = Integrator::new(model, lobatto5, t / steps as f64).ok()?;
        end(&integ, init, t).ok()
    };
    let (Some(fine), Some(half)) = (reference(REFERENCE_STEPS), reference(REFERENCE_STEPS / 2))
    else {
        return (rows, failures, f64::NAN);
    };
    let accuracy = max_diff(&fine.0, &half.0).max(max_diff(&fine.1, &half.1));
    for s in [3, 4] {
        let Ok(scheme) = Scheme::lobatto(s) else {
            continue;
        };
        let method = Method::Variational(scheme.id());
        let runs = FIXED_STEPS
            .iter()
            .map(|&n| (Mode::Fixed, t / n as f64))
            .chain(TOLERANCES.iter().map(|&tol| (Mode::Adaptive, tol)));
        for (mode, x) in runs {
            let integ = match mode {
                Mode::Fixed => Integrator::new(model, scheme.clone(), x),
                Mode::Adaptive => Integrator::adaptive(model, scheme.clone(), x, x),
            };
            let mut times = Vec::new();
            let mut out = None;
            for _ in 0..REPEATS {
                let (r, secs) = timed(|| {
                    integ
                        .as_ref()
                        .map_err(Clone::clone)
                        .and_then(|i| end(i, init, t))
                });
                times.push(secs);
                out = Some(r);
            }
            match out {
                Some(Ok((q, p, energy, stats))) => {
                    let (eq, ep) = (max_diff(&q, &fine.0), max_diff(&p, &fine.1));
                    let ee = (energy - fine.2).abs();
                    let spread = |e: f64| Spread {
                        min: e,
                        mean: e,
                        max: e,
                    };
                    rows.push(Row {
                        scene: name,
                        method,
                        mode,
                        h_or_tol: x,
                        steps: stats.steps,
                        member_steps_min: stats.steps,
                        newton_iters: stats.newton_iterations,
                        seconds: median(&mut times),
                        err: [spread(eq), spread(ep), spread(ee)],
                    });
                }
                Some(Err(e)) => failures.push(Failure {
                    scene: name,
                    method,
                    mode,
                    h_or_tol: x,
                    message: e.to_string(),
                }),
                None => {}
            }
        }
    }
    (rows, failures, accuracy)
}
