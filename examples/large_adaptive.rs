//! Adaptive steps on a large model (sparse backend): the FPU chain at n = 256, lobatto3 and
//! lobatto4 at rtol = atol = 1e-4, 1e-6, 1e-8 to T = 5, against a lobatto5 fixed-step
//! reference at h = 0.005; each adaptive run is timed against the fixed-step run of the same
//! scheme whose step is the adaptive run's mean step (the error it reaches is printed too).
//!
//! `cargo run --release --example large_adaptive`

use forced_vi::prelude::*;
use forced_vi::LinearPath;
use forced_vi_scenes::large::FpuChain;

const T: f64 = 5.0;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn main() -> Result<(), forced_vi::Error> {
    let chain = FpuChain::<256>::default();
    let init = FpuChain::<256>::initial();
    let reference = Integrator::new(&chain, Scheme::lobatto(5)?, 0.005)?.final_state(init, T)?;
    println!("scheme tol steps rejected error error/tol adaptive_ms fixed_ms(h = T/steps) fixed_error ratio");
    for s in [3, 4] {
        for tol in [1e-4, 1e-6, 1e-8] {
            let adaptive =
                Integrator::new(&chain, Scheme::lobatto(s)?, 0.05)?.tolerances(tol, tol)?;
            assert_eq!(adaptive.path_for(&init)?, LinearPath::Sparse);
            let mut end = None;
            let ta = median(
                (0..3)
                    .map(|_| {
                        let t0 = std::time::Instant::now();
                        end = adaptive.final_state(init, T).ok();
                        t0.elapsed().as_secs_f64() * 1e3
                    })
                    .collect(),
            );
            let end = end.expect("the adaptive run succeeds");
            let err = (end.q - reference.q).amax();
            let h = T / end.stats.steps as f64;
            let fixed = Integrator::new(&chain, Scheme::lobatto(s)?, h)?;
            let mut fend = None;
            let tf = median(
                (0..3)
                    .map(|_| {
                        let t0 = std::time::Instant::now();
                        fend = fixed.final_state(init, T).ok();
                        t0.elapsed().as_secs_f64() * 1e3
                    })
                    .collect(),
            );
            let ferr = fend.map_or(f64::NAN, |f| (f.q - reference.q).amax());
            println!(
                "lobatto{s} {tol:.0e} {} {} {err:.2e} {:.2} {ta:.1} {tf:.1} {ferr:.2e} {:.2}",
                end.stats.steps,
                end.stats.rejected_steps,
                err / tol,
                ta / tf
            );
        }
    }
    Ok(())
}
