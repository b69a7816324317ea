#![deny(warnings)]
//! Driven models: `t` (the time) in the force and in the Lagrangian.
use forced_vi::prelude::*;

/// The driven Duffing oscillator `ẍ + δẋ + αx + βx³ = γ cos ωt`.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = x_dot * x_dot / 2 - alpha * x * x / 2 - beta * x.powi(4) / 4,
    force(x = -delta * x_dot + gamma * (omega * t).cos()),
)]
pub struct DrivenDuffing {
    /// δ
    pub delta: f64,
    /// α
    pub alpha: f64,
    /// β
    pub beta: f64,
    /// γ
    pub gamma: f64,
    /// ω
    pub omega: f64,
}

/// A spring whose stiffness is modulated in time (Mathieu), with a time-dependent mass,
/// over an array of coordinates.
#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = (0..2)
        .map(|i| 0.5 * (1.0 + eps * (w * t).sin()) * q_dot[i] * q_dot[i]
            - 0.5 * (1.0 + eps * (w * t).cos()) * q[i] * q[i])
        .sum(),
    force(q[i] = -c * q_dot[i]),
)]
pub struct Mathieu {
    /// ε
    pub eps: f64,
    /// w
    pub w: f64,
    /// c
    pub c: f64,
}

fn main() -> Result<(), forced_vi::Error> {
    let model = DrivenDuffing {
        delta: 0.3,
        alpha: -1.0,
        beta: 1.0,
        gamma: 0.5,
        omega: 1.2,
    };
    const { assert!(<DrivenDuffing as ForcedLagrangian<1>>::STRUCTURE.uses_time) };
    let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.1)?
        .solve(
            InitialState::from_velocity([1.0], [0.0]),
            1.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;
    assert!(run.last().is_some());
    let lambda = model.doubled_lagrangian::<f64>(0.5, &[0.0], &[1.0], &[0.1], &[1.0]);
    assert!(lambda.is_finite());

    let m = Mathieu {
        eps: 0.2,
        w: 2.0,
        c: 0.1,
    };
    let s = <Mathieu as ForcedLagrangian<2>>::STRUCTURE;
    assert!(s.uses_time && !s.constant_mass);
    let run = Integrator::new(&m, Scheme::lobatto(2)?, 0.05)?
        .solve(
            InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]),
            1.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;
    assert!(run.last().is_some());
    Ok(())
}
