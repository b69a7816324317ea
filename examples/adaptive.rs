//! An adaptive run with dense output: `cargo run --release --example adaptive`.
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn main() -> Result<(), forced_vi::Error> {
    let run = Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(4)?, 0.1)?
        .tolerances(1e-8, 1e-8)? // rtol, atol: the run picks its steps
        .solve(
            InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
            10.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;
    println!(
        "{} steps, {} rejected",
        run.stats.steps, run.stats.rejected_steps
    );
    for t in [2.5, 5.0, 7.5] {
        let s = run.at(t).expect("inside the run"); // the step's own interpolant
        println!("t={t} q={:?} v={:?}", s.q.as_slice(), s.v.as_slice());
    }
    println!(
        "energy balance at T: {:.1e}",
        run.last().map_or(0.0, |r| r.energy_balance)
    );
    Ok(())
}
