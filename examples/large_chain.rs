//! The FPU-β chain at n = 1024 on the sparse path (DESIGN §9): prints the path taken and the
//! median µs per step of lobatto2 and lobatto3. `--scaling` also measures n = 32 … 4096,
//! the 64 × 64 membrane, and the dense path at small n (the crossover); `--n4096` runs the
//! n = 4096 chain alone (for its peak memory).
//!
//! `cargo run --release --example large_chain [-- --scaling]`

use std::time::Instant;

use forced_vi::{ForcedLagrangian, InitialState, Integrator, LinearPath, Scheme};
use forced_vi_scenes::large::{FpuChain, Lattice2d};

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
    let scaling = std::env::args().any(|a| a == "--scaling");
    if std::env::args().any(|a| a == "--n4096") {
        // Alone, for the peak resident set of the largest chain.
        chain::<4096>(3, LinearPath::Auto, 20);
        return;
    }
    if !scaling {
        chain::<1024>(2, LinearPath::Auto, 100);
        chain::<1024>(3, LinearPath::Auto, 100);
        return;
    }
    for s in [2, 3] {
        let a = chain::<32>(s, LinearPath::Auto, 400);
        for us in [
            chain::<128>(s, LinearPath::Auto, 200),
            chain::<512>(s, LinearPath::Auto, 100),
            chain::<1024>(s, LinearPath::Auto, 60),
            chain::<2048>(s, LinearPath::Auto, 30),
        ] {
            let _ = us;
        }
        let b = chain::<4096>(s, LinearPath::Auto, 20);
        println!(
            "lobatto{s}: exponent 32 → 4096: {:.3}",
            (b / a).ln() / (4096f64 / 32.0).ln()
        );
    }
    for n_path in [LinearPath::Dense, LinearPath::Sparse] {
        chain::<4>(3, n_path, 400);
        chain::<8>(3, n_path, 200);
        chain::<12>(3, n_path, 100);
        chain::<16>(3, n_path, 50);
        chain::<32>(3, n_path, 20);
    }
    let (a, _) = us_per_step(
        &Lattice2d::<16, 256>::default(),
        3,
        LinearPath::Auto,
        Lattice2d::<16, 256>::initial(),
        50,
    );
    let (b, taken) = us_per_step(
        &Lattice2d::<64, 4096>::default(),
        3,
        LinearPath::Auto,
        Lattice2d::<64, 4096>::initial(),
        10,
    );
    println!("lattice_2d n = 256 lobatto3 {a:.1} µs/step; n = 4096 {taken:?} {b:.1} µs/step; exponent {:.3}", (b / a).ln() / 16f64.ln());
}
