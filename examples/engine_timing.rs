//! Step cost of the one stepper against a build of the code before a change: lobatto3 and
//! lobatto5 on the coupled van der Pol oscillators (dense backend, no diagnostics) and on the
//! FPU chain at n = 1024 (sparse backend), as medians of interleaved repeats; and the cost
//! of a whole short run as the report times it (integrator made from a cloned scheme, every
//! step's record with its energy): the van der Pol scene to T = 1 with lobatto5, in 4 fixed
//! steps and adaptive at tol 1e-6, where the run's set-up is a large part of its cost.
//!
//! `cargo run --release --example engine_timing`; to compare two builds in one run, build
//! this example in both checkouts and run them alternately (`farm-bench --vs`).

use forced_vi::prelude::*;
use forced_vi_scenes::large::FpuChain;
use forced_vi_scenes::models::CoupledVanDerPol;

/// Median µs of a whole run to `t`, as the report times one: the integrator made from a
/// clone of `scheme` (fixed steps `h`, or adaptive at `tol`), each record's state and energy
/// kept.
fn time_run<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    scheme: &Scheme,
    (h, tol): (f64, Option<f64>),
    init: InitialState<N>,
    t: f64,
    repeats: usize,
) -> f64 {
    let mut times: Vec<f64> = (0..repeats)
        .map(|_| {
            let t0 = std::time::Instant::now();
            let integ = match tol {
                Some(tol) => Integrator::adaptive(model, scheme.clone(), tol, tol),
                None => Integrator::new(model, scheme.clone(), h),
            }
            .unwrap();
            let mut last = None;
            integ
                .solve(
                    init,
                    t,
                    output::each_step(|r| last = Some((r.q, r.p, r.energy))),
                )
                .map_err(|f| f.error)
                .unwrap();
            std::hint::black_box(last);
            t0.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Median ns per step of `final_state` over `repeats` runs.
fn time<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    s: usize,
    h: f64,
    init: InitialState<N>,
    t: f64,
    repeats: usize,
) -> f64 {
    let integ = Integrator::new(model, Scheme::lobatto(s).unwrap(), h).unwrap();
    let mut times: Vec<f64> = (0..repeats)
        .map(|_| {
            let t0 = std::time::Instant::now();
            let end = integ.final_state(init, t).map_err(|f| f.error).unwrap();
            t0.elapsed().as_secs_f64() * 1e9 / end.stats.steps as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() {
    let vdp = CoupledVanDerPol::PAPER;
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let chain = FpuChain::<1024>::default();
    for round in 0..3 {
        for s in [3, 5] {
            let ns = time(&vdp, s, 0.01, init, 20.0, 9);
            println!("round {round} coupled_van_der_pol lobatto{s}: {ns:.0} ns/step");
        }
        let lobatto5 = Scheme::lobatto(5).unwrap();
        for (label, run) in [
            ("4 fixed steps", (0.25, None)),
            ("adaptive tol 1e-6", (1.0, Some(1e-6))),
        ] {
            let us = time_run(&vdp, &lobatto5, run, init, 1.0, 2001);
            println!(
                "round {round} coupled_van_der_pol lobatto5 to T = 1, {label}: {us:.2} us/run"
            );
        }
        let ns = time(&chain, 3, 0.05, FpuChain::<1024>::initial(), 2.0, 5);
        println!(
            "round {round} fpu_chain_1024 lobatto3: {:.1} us/step",
            ns / 1e3
        );
    }
}
