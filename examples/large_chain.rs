//! The FPU-β chain at n = 1024 on the sparse path (DESIGN §9): prints the path taken and the
//! median µs per step of lobatto2 and lobatto3. `--crossover` measures the dense and the
//! sparse path at small n (where `LinearPath::SPARSE_MIN_DOF` comes from); `--n4096` runs the
//! n = 4096 chain alone (for its peak memory). The scaling with n, for the chain and the 2-D
//! membrane, is the step-cost report's (`cargo run --release -- step-cost`).
//!
//! `cargo run --release --example large_chain [-- --crossover | --n4096]`

use std::time::Instant;

use forced_vi::{ForcedLagrangian, InitialState, Integrator, LinearPath, Scheme};
use forced_vi_scenes::large::FpuChain;

/// Median µs per step over `reps` runs of `steps` steps (final state only), after a warm-up.
fn us_per_step<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    s: usize,
    path: LinearPath,
    init: InitialState<N>,
    steps: usize,
) -> (f64, LinearPath) {
    let h = 0.05;
    let integ = Integrator::new(model, Scheme::lobatto(s).expect("a scheme"), h)
        .expect("an integrator")
        .linear_path(path);
    let taken = integ.path_for(&init).expect("a path");
    let t = steps as f64 * h;
    let _ = integ.final_state(init, t);
    let mut times: Vec<f64> = (0..5)
        .map(|_| {
            let start = Instant::now();
            integ.final_state(init, t).expect("a run");
            start.elapsed().as_secs_f64() * 1e6 / steps as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], taken)
}

fn chain<const N: usize>(s: usize, path: LinearPath, steps: usize) -> f64 {
    let (us, taken) = us_per_step(
        &FpuChain::<N>::default(),
        s,
        path,
        FpuChain::<N>::initial(),
        steps,
    );
    println!("fpu_chain  n = {N:5}  lobatto{s}  {taken:?}  {us:10.1} µs/step");
    us
}

fn main() {
    if std::env::args().any(|a| a == "--n4096") {
        // Alone, for the peak resident set of the largest chain.
        chain::<4096>(3, LinearPath::Auto, 20);
        return;
    }
    if std::env::args().any(|a| a == "--crossover") {
        for n_path in [LinearPath::Dense, LinearPath::Sparse] {
            chain::<4>(3, n_path, 400);
            chain::<8>(3, n_path, 200);
            chain::<16>(3, n_path, 50);
            chain::<32>(3, n_path, 20);
        }
        return;
    }
    chain::<1024>(2, LinearPath::Auto, 100);
    chain::<1024>(3, LinearPath::Auto, 100);
}
