//! The energy ledger `E − E0 − W` over a long run (coupled van der Pol, T = 1000), fixed
//! step against adaptive: `cargo run --release --example adaptive_long_run`.
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn ledger(integ: &Integrator<'_, CoupledVanDerPol, 2>, label: &str) {
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let (mut worst, mut at_100, mut last) = (0.0f64, 0.0, 0.0);
    let start = std::time::Instant::now();
    let stats = integ
        .solve(
            init,
            1000.0,
            output::each_step(|r| {
                worst = worst.max(r.energy_balance.abs());
                if r.t <= 100.0 {
                    at_100 = r.energy_balance;
                }
                last = r.energy_balance;
            }),
        )
        .expect("the run completes");
    println!(
        "{label}: steps {}, rejected {}, {:.2} s, |balance| max {worst:.2e}, at t≈100 {at_100:.2e}, at T {last:.2e}",
        stats.steps,
        stats.rejected_steps,
        start.elapsed().as_secs_f64()
    );
}

fn main() -> Result<(), forced_vi::Error> {
    let m = CoupledVanDerPol::PAPER;
    for s in [3, 5] {
        let fixed = Integrator::new(&m, Scheme::lobatto(s)?, 0.02)?;
        ledger(&fixed, &format!("lobatto{s} fixed h = 0.02"));
        for tol in [1e-6, 1e-9] {
            let adaptive = Integrator::new(&m, Scheme::lobatto(s)?, 0.02)?.tolerances(tol, tol)?;
            ledger(&adaptive, &format!("lobatto{s} adaptive tol = {tol:e}"));
        }
    }
    Ok(())
}
