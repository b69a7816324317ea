//! The cost of derivatives on a large model (issue 24): the damped FPU chain at n = 1024 on
//! the sparse backend, lobatto3, h = 0.05 to T = 5 (100 steps). For the loss
//! `ℓ = ½|q_T|²` it times, median of 3 runs:
//! - the run alone (`final_state`);
//! - the adjoint gradient with respect to the 2n initial values and the 4 parameters of the
//!   macro's chain (`output::adjoint`), and the memory its tape keeps;
//! - the same model written by hand, which declares no parameters (the adjoint without
//!   parameter terms), to show what the parameters add;
//! - the forward sensitivities (`sensitivities`, 2n + 4 columns) at n = 64, 128 and 256,
//!   whose cost grows with the columns.
//!
//! `cargo run --release --example adjoint_cost`

use forced_vi::prelude::*;
use forced_vi::LinearPath;
use forced_vi_scenes::large::FpuChain;
use forced_vi_scenes::models::SpringChain;
use nalgebra::SVector;

const T: f64 = 5.0;
const H: f64 = 0.05;

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut xs: Vec<f64> = (0..3)
        .map(|_| {
            let t0 = std::time::Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    xs.sort_by(f64::total_cmp);
    xs[1]
}

fn forward<const N: usize>() -> Result<(), forced_vi::Error> {
    let chain = SpringChain::<N>::FPU;
    let init = FpuChain::<N>::initial();
    let integ = Integrator::new(&chain, Scheme::lobatto(3)?, H)?;
    let run = median_ms(|| {
        integ.final_state(init, T).expect("run");
    });
    let sens = median_ms(|| {
        integ
            .solve(init, T, output::Tangents)
            .expect("sensitivities");
    });
    let adj = median_ms(|| {
        integ
            .solve(init, T, output::adjoint(|e| (e.q, SVector::zeros())))
            .expect("adjoint");
    });
    println!(
        "n = {N:5} ({:?}): run {run:8.1} ms, forward sensitivities ({} columns) {sens:9.1} ms ({:.0}x), adjoint {adj:7.1} ms ({:.1}x)",
        integ.path_for(&init)?,
        2 * N + 4,
        sens / run,
        adj / run
    );
    Ok(())
}

fn main() -> Result<(), forced_vi::Error> {
    const N: usize = 1024;
    let chain = SpringChain::<N>::FPU;
    let by_hand = FpuChain::<N>::default();
    let init = FpuChain::<N>::initial();
    let integ = Integrator::new(&chain, Scheme::lobatto(3)?, H)?;
    let hand = Integrator::new(&by_hand, Scheme::lobatto(3)?, H)?;
    assert_eq!(integ.path_for(&init)?, LinearPath::Sparse);
    let run = median_ms(|| {
        integ.final_state(init, T).expect("run");
    });
    let mut grad = None;
    let adj = median_ms(|| {
        grad = Some(
            integ
                .solve(init, T, output::adjoint(|e| (e.q, SVector::zeros())))
                .expect("adjoint"),
        );
    });
    let grad = grad.expect("a gradient");
    let hand_run = median_ms(|| {
        hand.final_state(init, T).expect("run");
    });
    let hand_adj = median_ms(|| {
        hand.solve(init, T, output::adjoint(|e| (e.q, SVector::zeros())))
            .expect("adjoint");
    });
    println!(
        "n = {N}, lobatto3, h = {H}, T = {T}: {} steps on the sparse backend",
        grad.stats.steps
    );
    println!(
        "macro chain (P = {}): run {run:.1} ms, adjoint gradient {adj:.1} ms ({:.2}x the run), tape {:.1} MB",
        grad.wrt_parameters.len(),
        adj / run,
        grad.tape_bytes as f64 / 1e6
    );
    println!(
        "hand-written chain (P = 0): run {hand_run:.1} ms, adjoint gradient {hand_adj:.1} ms ({:.2}x the run)",
        hand_adj / hand_run
    );
    println!(
        "dl/dtheta (m, k, beta, c) = {:?}",
        grad.wrt_parameters.as_slice()
    );
    forward::<64>()?;
    forward::<128>()?;
    forward::<256>()?;
    Ok(())
}
