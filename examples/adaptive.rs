//! An adaptive run with dense output: `cargo run --release --example adaptive`.
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn main() -> Result<(), forced_vi::Error> {
    let integ = Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(4)?, 0.1)?
        .tolerances(1e-8, 1e-8)?; // rtol, atol: the run picks its steps
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let run = integ
        .solve(init, 10.0, output::Records)
        .map_err(|failure| failure.error)?;
    println!(
        "{} steps, {} rejected",
        run.stats.steps, run.stats.rejected_steps
    );
    // The state at given times, to the tolerance: a step over one of them ends on it.
    // (`run.at(t)` interpolates the records as they are, with a cubic: less accurate than
    // lobatto4's steps.)
    let samples = integ
        .solve(init, 10.0, output::Samples(&[2.5, 5.0, 7.5]))
        .map_err(|failure| failure.error)?;
    for s in &samples {
        println!("t={} q={:?} v={:?}", s.t, s.q.as_slice(), s.v.as_slice());
    }
    println!(
        "energy balance at T: {:.1e}",
        run.last().map_or(0.0, |r| r.energy_balance)
    );
    Ok(())
}
