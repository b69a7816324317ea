//! A fixed workload for instruction-count profiling (`valgrind --tool=callgrind`): the paper
//! model to T = 20 at h = 0.01, final state only. The first argument picks the scheme
//! (default `lobatto3`).
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let id: SchemeId = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "lobatto3".into())
        .parse()?;
    let t_final: f64 = std::env::args()
        .nth(2)
        .and_then(|t| t.parse().ok())
        .unwrap_or(20.0);
    let model = CoupledVanDerPol::PAPER;
    let integ = Integrator::new(&model, Scheme::new(id)?, 0.01)?;
    let end = integ.final_state(
        InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
        t_final,
    )?;
    println!(
        "{} steps, {} Newton iterations",
        end.stats.steps, end.stats.newton_iterations
    );
    Ok(())
}
