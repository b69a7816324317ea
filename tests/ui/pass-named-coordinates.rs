#![deny(warnings)]
//! Named scalar coordinates with a force; the model runs through the integrator.
use forced_vi::prelude::*;

/// Two coupled van der Pol oscillators.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + (1.0 + rho) * y * y)
        - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
)]
pub struct CoupledVanDerPol {
    /// ε
    pub eps: f64,
    /// ρ
    pub rho: f64,
    /// λ
    pub lambda: f64,
}

fn main() -> Result<(), forced_vi::Error> {
    let model = CoupledVanDerPol {
        eps: 0.5,
        rho: 0.02,
        lambda: 0.8,
    };
    let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.1)?
        .solve(
            InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
            1.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;
    assert!(run.last().is_some());
    let lambda = model.doubled_lagrangian::<f64>(0.0, &[0.0; 2], &[1.0; 2], &[0.1; 2], &[1.0; 2]);
    assert!(lambda.is_finite());
    Ok(())
}
