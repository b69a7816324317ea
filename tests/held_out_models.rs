//! The second held-out set of `examples/tolerance_sweep.rs`, shared with
//! `tests/held_out.rs`: five small forced models of kinds the report's scenes and the
//! controller's tuning set lack.

use forced_vi::prelude::*;

/// A pendulum whose gravity oscillates (a Lagrangian that reads the time), with drag.
#[forced_lagrangian(
    coordinates(th),
    lagrangian = 0.5 * th_dot * th_dot + (1.0 + 0.3 * (2.0 * t).cos()) * th.cos(),
    force(th = -0.05 * th_dot)
)]
pub struct Parametric {}

/// Two masses (2 and 0.5) on a soft and a hardening spring, joined by a damper.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (2.0 * x_dot * x_dot + 0.5 * y_dot * y_dot)
        - 0.5 * x * x
        - 0.5 * (y - x) * (y - x)
        - 0.1 * (y - x) * (y - x) * (y - x) * (y - x),
    force(x = 0.02 * (y_dot - x_dot), y = -0.02 * (y_dot - x_dot))
)]
pub struct TwoMass {}

/// A charge in a uniform magnetic field, pushed by an oscillating electric field, with
/// quadratic drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + 0.75 * (x * y_dot - y * x_dot),
    force(
        x = -0.1 * x_dot * (x_dot * x_dot + y_dot * y_dot).sqrt() + 0.3 * t.cos(),
        y = -0.1 * y_dot * (x_dot * x_dot + y_dot * y_dot).sqrt()
    )
)]
pub struct Lorentz {}

/// A relativistic oscillator with drag: a mass that depends on the velocity.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = -(1.0 - x_dot * x_dot).sqrt() - 0.5 * x * x,
    force(x = -0.05 * x_dot)
)]
pub struct Relativistic {}

/// A softened Kepler potential with weak drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + 1.0 / (x * x + y * y + 0.1).sqrt(),
    force(x = -0.02 * x_dot, y = -0.02 * y_dot)
)]
pub struct SoftKepler {}
