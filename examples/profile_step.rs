//! A fixed workload for instruction-count profiling (`valgrind --tool=callgrind`).
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn main() -> Result<(), forced_vi::Error> {
    let model = CoupledVanDerPol::PAPER;
    let integ = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?;
    let stats = integ.for_each_step(
        InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
        20.0,
        |_| {},
    )?;
    println!(
        "{} steps, {} Newton iterations",
        stats.steps, stats.newton_iterations
    );
    Ok(())
}
