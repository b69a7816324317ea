//! A chain of 256 rigid links (512 coordinates, 256 constraints) on the sparse backend:
//! `cargo run --release --example rigid_chain`.
//!
//! The chain of `forced_vi_models::rigid_chain` (hand-written sparse node and constraint
//! kernels), released from rest with a bend. Fixed steps of lobatto2 and lobatto3 (timed per
//! step, median of 5 runs) and an adaptive run that picks its own order
//! (`Integrator::auto`); each prints `max(|g|, |G v|)` over the run.
use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi_scenes::rigid_chain::RigidChain;

const N: usize = 512;

fn main() -> Result<(), forced_vi::Error> {
    let model = RigidChain::<N>::default();
    let init = model.initial();
    for (s, h) in [(2, 1e-3), (3, 1e-3)] {
        let integ = Integrator::new(&model, Scheme::lobatto(s)?, h)?;
        let mut per_step: Vec<f64> = (0..5)
            .map(|_| {
                let t0 = Instant::now();
                let end = integ.final_state(init, 0.2);
                let steps = end.map_or(1, |e| e.stats.steps.max(1));
                t0.elapsed().as_secs_f64() / steps as f64
            })
            .collect();
        per_step.sort_by(f64::total_cmp);
        let run = integ
            .solve(init, 0.2, output::Records)
            .map_err(|f| f.error)?;
        let worst = run
            .records
            .iter()
            .map(|r| r.constraint_residual)
            .fold(0.0, f64::max);
        println!(
            "lobatto{s}, h = {h}: path {:?}, {:.0} µs per step, max(|g|, |G v|) {worst:.1e}",
            integ.path_for(&init)?,
            per_step[2] * 1e6
        );
    }
    let auto = Integrator::auto(&model, 1e-8, 1e-8)?;
    let t0 = Instant::now();
    let run = auto
        .solve(init, 1.0, output::Records)
        .map_err(|f| f.error)?;
    let worst = run
        .records
        .iter()
        .map(|r| r.constraint_residual)
        .fold(0.0, f64::max);
    let end = run
        .last()
        .map(|r| (r.q[N - 2], r.q[N - 1]))
        .unwrap_or_default();
    println!(
        "auto ({}), tol 1e-8: {} steps in {:.2} s, max(|g|, |G v|) {worst:.1e}, free end at ({:.4}, {:.4})",
        auto.scheme().id(),
        run.stats.steps,
        t0.elapsed().as_secs_f64(),
        end.0,
        end.1
    );
    Ok(())
}
