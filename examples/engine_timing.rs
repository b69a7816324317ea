//! Step cost of the one stepper against a build of the code before a change: lobatto3 and
//! lobatto5 on the coupled van der Pol oscillators (dense backend, no diagnostics) and on the
//! FPU chain at n = 1024 (sparse backend), as medians of interleaved repeats.
//!
//! `cargo run --release --example engine_timing`; to compare two builds in one run, build
//! this example in both checkouts and run them alternately (`farm-bench --vs`).

use forced_vi::prelude::*;
use forced_vi_scenes::large::FpuChain;
use forced_vi_scenes::models::CoupledVanDerPol;

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
        let ns = time(&chain, 3, 0.05, FpuChain::<1024>::initial(), 2.0, 5);
        println!(
            "round {round} fpu_chain_1024 lobatto3: {:.1} us/step",
            ns / 1e3
        );
    }
}
