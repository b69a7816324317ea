//! The third held-out set of `examples/tolerance_sweep.rs`: five forced models of kinds the
//! earlier sets lack, added on 2026-11-30 with no change to the controller.

use forced_vi::prelude::*;

/// A heavy symmetric top in Euler angles `(θ, φ, ψ)`, spinning fast, with drag on its
/// nutation: a mass matrix that depends on `θ` and couples `φ` and `ψ`.
#[forced_lagrangian(
    coordinates(th, ph, ps),
    lagrangian = 0.5 * (th_dot * th_dot + ph_dot * ph_dot * th.sin() * th.sin())
        + 0.25 * (ps_dot + ph_dot * th.cos()) * (ps_dot + ph_dot * th.cos())
        - th.cos(),
    force(th = -0.05 * th_dot, ph = 0.0, ps = 0.0)
)]
pub struct HeavyTop {}

/// A chain of eight masses between fixed walls on FPU-β springs, damped at one end: eight
/// coordinates, frequencies from 0.35 to 2.
#[forced_lagrangian(
    coordinates(q: [f64; 8]),
    lagrangian = (0..8).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - {
            let mut v = 0.0;
            for i in 0..9 {
                let left = if i == 0 { 0.0 } else { q[i - 1] };
                let right = if i == 8 { 0.0 } else { q[i] };
                let d = right - left;
                v += 0.5 * d * d + 0.25 * d * d * d * d;
            }
            v
        },
    force(q[i] = if i == 7 { -0.2 * q_dot[i] } else { 0.0 })
)]
pub struct FpuChain {}

/// The Caldirola–Kanai oscillator: damping written as a Lagrangian that grows with the
/// time, `e^{0.3 t} (ẋ² − x²) / 2`, and no force; its momentum grows like `e^{0.3 t}`.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = (0.3 * t).exp() * (0.5 * x_dot * x_dot - 0.5 * x * x),
)]
pub struct CaldirolaKanai {}

/// An oscillator with smoothed dry friction, `−0.3 tanh(ẋ / 0.02)`: nearly a jump in the
/// force at every turn, and a friction stiffness of 15 while it creeps.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = -0.3 * (x_dot / 0.02).tanh())
)]
pub struct DryFriction {}

/// A pendulum on a cart that is pushed back and forth, with friction on the cart: an
/// off-diagonal mass term `ẋ θ̇ cos θ`.
#[forced_lagrangian(
    coordinates(x, th),
    lagrangian = x_dot * x_dot + 0.5 * x_dot * th_dot * th.cos()
        + 0.125 * th_dot * th_dot
        + 0.5 * 9.81 * 0.5 * th.cos(),
    force(x = -0.5 * x_dot + 0.8 * (1.3 * t).sin(), th = 0.0)
)]
pub struct CartPendulum {}
