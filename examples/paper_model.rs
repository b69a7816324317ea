//! The README's example: the paper's coupled van der Pol oscillators, integrated with the
//! 3-stage Lobatto scheme (order 4). Run with `cargo run --release --example paper_model`.
use forced_vi::prelude::*;

/// Two coupled van der Pol oscillators (the paper's numerical test).
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + (1.0 + rho) * y * y)
        - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
)]
pub struct CoupledVanDerPol {
    pub eps: f64,
    pub rho: f64,
    pub lambda: f64,
}

fn main() -> Result<(), forced_vi::Error> {
    let model = CoupledVanDerPol {
        eps: 0.5,
        rho: 0.02,
        lambda: 0.8,
    };
    let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
        .solve(
            InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
            1.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;
    for r in run.records.iter().step_by(25) {
        println!(
            "t={:.2} q={:?} energy balance={:.1e}",
            r.t,
            r.q.as_slice(),
            r.energy_balance
        );
    }
    Ok(())
}
