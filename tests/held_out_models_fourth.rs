//! The fourth held-out set of `examples/tolerance_sweep.rs` and `tests/held_out.rs`: five
//! forced models of kinds the earlier sets lack, added on 2026-11-30 with no change to the
//! controller.

use forced_vi::prelude::*;

/// A particle in a Lennard-Jones well, `1/x¹² − 2/x⁶`, with light drag: a repulsive wall that
/// steepens like `x⁻¹³` at each turn.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - (1.0 / x.powi(12) - 2.0 / x.powi(6)),
    force(x = -0.01 * x_dot)
)]
pub struct LjWall {}

/// Two unit masses joined by a spring of 10⁴ with a light damper, one tied to the origin by a
/// unit spring: a fast undamped-looking mode (ω ≈ 141) beside a slow one.
#[forced_lagrangian(
    coordinates(a, b),
    lagrangian = 0.5 * (a_dot * a_dot + b_dot * b_dot)
        - 0.5 * 1.0e4 * (b - a) * (b - a)
        - 0.5 * a * a,
    force(a = 0.01 * (b_dot - a_dot), b = -0.01 * (b_dot - a_dot))
)]
pub struct StiffPair {}

/// A slow oscillator (ω = 10⁻³) run over T = 10⁴: steps in the hundreds of time units.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5e-6 * x * x,
    force(x = -1.0e-5 * x_dot)
)]
pub struct Slow {}

/// A purely quartic well with drag: the period grows as the amplitude decays.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - x * x * x * x,
    force(x = -0.05 * x_dot)
)]
pub struct Quartic {}

/// A Lennard-Jones pair in the plane with angular momentum and light drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - (1.0 / (x * x + y * y).powi(6) - 2.0 / (x * x + y * y).powi(3)),
    force(x = -0.01 * x_dot, y = -0.01 * y_dot)
)]
pub struct LjDimer {}
