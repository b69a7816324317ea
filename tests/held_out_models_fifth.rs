//! The fifth held-out set of `tests/held_out.rs`: five forced models of kinds the earlier
//! sets lack, added on 2026-11-30 (session 46) with no change to the controller.

use forced_vi::prelude::*;

/// The swinging Atwood machine (masses 3 and 1, g = 9.81) with drag on the cord: the
/// swinging mass's inertia `r² θ̇²` falls to a fifteenth of its start as the cord shortens
/// to r ≈ 0.25, where it whirls fast.
#[forced_lagrangian(
    coordinates(r, th),
    lagrangian = 2.0 * r_dot * r_dot + 0.5 * r * r * th_dot * th_dot
        - 9.81 * r * (3.0 - th.cos()),
    force(r = -0.05 * r_dot, th = 0.0)
)]
pub struct SwingingAtwood {}

/// A triple pendulum (unit masses and links) with drag on each angle: a full 3×3 mass
/// matrix of cosines of the angles' differences.
#[forced_lagrangian(
    coordinates(a, b, c),
    lagrangian = 0.5
        * (3.0 * a_dot * a_dot + 2.0 * b_dot * b_dot + c_dot * c_dot
            + 4.0 * a_dot * b_dot * (a - b).cos()
            + 2.0 * a_dot * c_dot * (a - c).cos()
            + 2.0 * b_dot * c_dot * (b - c).cos())
        + 9.81 * (3.0 * a.cos() + 2.0 * b.cos() + c.cos()),
    force(a = -0.1 * a_dot, b = -0.1 * b_dot, c = -0.1 * c_dot)
)]
pub struct TriplePendulum {}

/// A charge in a Penning trap (magnetic field 8 along z, electric quadrupole of axial
/// frequency 1) with drag: a Lagrangian linear in the velocity, three frequencies from
/// 0.06 (the magnetron drift, which drag makes grow) to 7.9 (the cyclotron motion).
#[forced_lagrangian(
    coordinates(x, y, z),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot + z_dot * z_dot)
        + 4.0 * (x * y_dot - y * x_dot)
        - 0.5 * (z * z - 0.5 * (x * x + y * y)),
    force(x = -0.02 * x_dot, y = -0.02 * y_dot, z = -0.02 * z_dot)
)]
pub struct PenningTrap {}

/// A particle pulled at about speed 20 over a washboard `−0.5 cos x`: its position grows
/// to 300, so the potential's phase carries the round-off of a large coordinate.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot + 0.5 * x.cos(),
    force(x = -0.1 * (x_dot - 20.0))
)]
pub struct Washboard {}

/// A damped oscillator about x = 10⁴: a position whose relative tolerance dwarfs its
/// absolute one, and whose motion is a part in 10⁴ of it.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * (x - 1.0e4) * (x - 1.0e4),
    force(x = -0.1 * x_dot)
)]
pub struct FarOscillator {}
