//! The models behind the tests, examples and report scenes, written with
//! `#[forced_lagrangian]`.
//!
//! Each model's parameters are its `f64` fields; the attribute gives the Lagrangian and the
//! force over named coordinates (the velocity of `x` is `x_dot`) and writes the
//! [`ForcedLagrangian`] impl with kernels specialised to the
//! model's structure.

use forced_vi::prelude::*;
use forced_vi::Structure;

/// Two coupled van der Pol oscillators, the paper's numerical test (§5 of the paper).
///
/// `L = ½(v₁² + v₂²) − ½(q₁² + (1+ρ)q₂²) − λ(q₁ − q₂)²`, `F = ((ε − q₁²)v₁, (ε − q₂²)v₂)`.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + (1.0 + rho) * y * y)
        - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoupledVanDerPol {
    /// Damping parameter ε.
    pub eps: f64,
    /// Detuning ρ of the second oscillator.
    pub rho: f64,
    /// Coupling strength λ.
    pub lambda: f64,
}

impl CoupledVanDerPol {
    /// The paper's parameters `(ε, ρ, λ) = (0.5, 0.02, 0.8)`.
    pub const PAPER: CoupledVanDerPol = CoupledVanDerPol {
        eps: 0.5,
        rho: 0.02,
        lambda: 0.8,
    };
}

/// A linear damped oscillator `L = ½vᵀMv − ½qᵀKq`, `F = −Dv`, with 2×2 matrices given entry
/// by entry (`M` and `K` symmetric, `D` general).
#[forced_lagrangian(
    coordinates(q1, q2),
    lagrangian = 0.5 * (m11 * q1_dot * q1_dot + 2.0 * m12 * q1_dot * q2_dot + m22 * q2_dot * q2_dot)
        - 0.5 * (k11 * q1 * q1 + 2.0 * k12 * q1 * q2 + k22 * q2 * q2),
    force(
        q1 = -(d11 * q1_dot + d12 * q2_dot),
        q2 = -(d21 * q1_dot + d22 * q2_dot),
    ),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DampedOscillator {
    /// Mass matrix entry `M₁₁`.
    pub m11: f64,
    /// Mass matrix entry `M₁₂ = M₂₁`.
    pub m12: f64,
    /// Mass matrix entry `M₂₂`.
    pub m22: f64,
    /// Stiffness entry `K₁₁`.
    pub k11: f64,
    /// Stiffness entry `K₁₂ = K₂₁`.
    pub k12: f64,
    /// Stiffness entry `K₂₂`.
    pub k22: f64,
    /// Damping entry `D₁₁`.
    pub d11: f64,
    /// Damping entry `D₁₂`.
    pub d12: f64,
    /// Damping entry `D₂₁`.
    pub d21: f64,
    /// Damping entry `D₂₂`.
    pub d22: f64,
}

impl DampedOscillator {
    /// The matrices of the report scene and the tests: `M = [[2, 0.5], [0.5, 1]]`,
    /// `K = [[3, −1], [−1, 2]]`, `D = [[0.1, 0.02], [0.02, 0.05]]`.
    pub const DEFAULT: DampedOscillator = DampedOscillator {
        m11: 2.0,
        m12: 0.5,
        m22: 1.0,
        k11: 3.0,
        k12: -1.0,
        k22: 2.0,
        d11: 0.1,
        d12: 0.02,
        d21: 0.02,
        d22: 0.05,
    };

    /// `M`, row-major.
    pub fn mass(&self) -> [[f64; 2]; 2] {
        [[self.m11, self.m12], [self.m12, self.m22]]
    }

    /// `K`, row-major.
    pub fn stiffness(&self) -> [[f64; 2]; 2] {
        [[self.k11, self.k12], [self.k12, self.k22]]
    }

    /// `D`, row-major.
    pub fn damping(&self) -> [[f64; 2]; 2] {
        [[self.d11, self.d12], [self.d21, self.d22]]
    }
}

/// A double pendulum with joint friction: angles `θ₁, θ₂` from the downward vertical.
///
/// `L = ½(m₁+m₂)l₁²θ̇₁² + ½m₂l₂²θ̇₂² + m₂l₁l₂θ̇₁θ̇₂cos(θ₁−θ₂) + (m₁+m₂)gl₁cos θ₁ + m₂gl₂cos θ₂`,
/// `F = (−cθ̇₁, −cθ̇₂)`. Its mass matrix depends on the angles.
#[forced_lagrangian(
    coordinates(theta1, theta2),
    lagrangian = 0.5 * (m1 + m2) * l1 * l1 * theta1_dot * theta1_dot
        + 0.5 * m2 * l2 * l2 * theta2_dot * theta2_dot
        + m2 * l1 * l2 * theta1_dot * theta2_dot * (theta1 - theta2).cos()
        + (m1 + m2) * g * l1 * theta1.cos()
        + m2 * g * l2 * theta2.cos(),
    force(theta1 = -c * theta1_dot, theta2 = -c * theta2_dot),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DoublePendulumFriction {
    /// Mass of the first bob.
    pub m1: f64,
    /// Mass of the second bob.
    pub m2: f64,
    /// Length of the first rod.
    pub l1: f64,
    /// Length of the second rod.
    pub l2: f64,
    /// Gravitational acceleration.
    pub g: f64,
    /// Friction coefficient of both joints.
    pub c: f64,
}

impl DoublePendulumFriction {
    /// Unit masses and lengths, `g = 9.81`, `c = 0.05`.
    pub const DEFAULT: DoublePendulumFriction = DoublePendulumFriction {
        m1: 1.0,
        m2: 1.0,
        l1: 1.0,
        l2: 1.0,
        g: 9.81,
        c: 0.05,
    };
}

/// A Kepler orbit with linear drag: `L = ½|v|² + μ/|q|`, `F = −γv`.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + mu / (x * x + y * y).sqrt(),
    force(x = -gamma * x_dot, y = -gamma * y_dot),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeplerDrag {
    /// Gravitational parameter μ.
    pub mu: f64,
    /// Drag coefficient γ.
    pub gamma: f64,
}

impl KeplerDrag {
    /// `μ = 1`, `γ = 0.01`.
    pub const DEFAULT: KeplerDrag = KeplerDrag {
        mu: 1.0,
        gamma: 0.01,
    };
}

/// The van der Pol oscillator `x'' − μ(1 − x²)x' + x = 0`, stiff for large μ:
/// `L = ½v² − ½q²`, `F = μ(1 − q²)v`.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = mu * (1.0 - x * x) * x_dot),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StiffVanDerPol {
    /// Stiffness parameter μ.
    pub mu: f64,
}

impl StiffVanDerPol {
    /// `μ = 10³`.
    pub const DEFAULT: StiffVanDerPol = StiffVanDerPol { mu: 1.0e3 };
    /// `μ = 10⁶`.
    pub const VERY_STIFF: StiffVanDerPol = StiffVanDerPol { mu: 1.0e6 };
}

/// A linear oscillator with damping ratio ζ: `L = ½v² − ½ω²q²`, `F = −2ζωv`.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * omega * omega * x * x,
    force(x = -2.0 * zeta * omega * x_dot),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverdampedOscillator {
    /// Natural frequency ω.
    pub omega: f64,
    /// Damping ratio ζ (over-damped for ζ > 1).
    pub zeta: f64,
}

impl OverdampedOscillator {
    /// `ω = 1`, `ζ = 5`.
    pub const DEFAULT: OverdampedOscillator = OverdampedOscillator {
        omega: 1.0,
        zeta: 5.0,
    };
}

/// `N` unit-spaced masses between two fixed walls, joined by nonlinear springs with energy
/// `k Δ²/2 + β Δ⁴/4` (Δ the stretch), each mass damped by `−c v`.
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * m * q_dot[i] * q_dot[i]).sum()
        - (0..=N)
            .map(|i| {
                let left = if i == 0 { 0.0 } else { q[i - 1] };
                let right = if i == N { 0.0 } else { q[i] };
                let d = right - left;
                0.5 * k * d * d + 0.25 * beta * d.powi(4)
            })
            .sum(),
    force(q[i] = -c * q_dot[i]),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringChain<const N: usize> {
    /// Mass of each body.
    pub m: f64,
    /// Linear spring constant k.
    pub k: f64,
    /// Quartic spring constant β.
    pub beta: f64,
    /// Damping coefficient c.
    pub c: f64,
}

impl<const N: usize> SpringChain<N> {
    /// `m = 1`, `k = 1`, `β = 0.5`, `c = 0.01`.
    pub const DEFAULT: SpringChain<N> = SpringChain {
        m: 1.0,
        k: 1.0,
        beta: 0.5,
        c: 0.01,
    };
    /// A stiff chain: `k = 10⁴`, so `hω ≫ 1` for moderate steps; `β = 1`, `c = 1`.
    pub const STIFF: SpringChain<N> = SpringChain {
        m: 1.0,
        k: 1.0e4,
        beta: 1.0,
        c: 1.0,
    };
}

impl<const N: usize> SpringChain<N> {
    /// The parameters of the hand-written [`FpuChain`](crate::large::FpuChain) (`β = 1`), so
    /// that generated and hand-written kernels run the same model.
    pub const FPU: SpringChain<N> = SpringChain {
        m: 1.0,
        k: 1.0,
        beta: 1.0,
        c: 0.01,
    };
}

/// A `W × W` membrane (`N = W²` masses, row-major) with a fixed rim: each mass is bonded to
/// its four neighbours by springs of energy `k Δ²/2 + β Δ⁴/4` and damped by `−c v`. The same
/// model as the hand-written [`Lattice2d`](crate::large::Lattice2d), written for the macro,
/// which splits it into local terms (DESIGN §9).
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|s| 0.5 * m * q_dot[s] * q_dot[s]).sum()
        - (0..W)
            .map(|r| {
                (0..=W)
                    .map(|j| {
                        let left = if j == 0 { 0.0 } else { q[r * W + j - 1] };
                        let right = if j == W { 0.0 } else { q[r * W + j] };
                        let d = right - left;
                        0.5 * k * d * d + 0.25 * beta * d.powi(4)
                    })
                    .sum()
            })
            .sum()
        - (0..W)
            .map(|j| {
                (0..=W)
                    .map(|r| {
                        let up = if r == 0 { 0.0 } else { q[(r - 1) * W + j] };
                        let down = if r == W { 0.0 } else { q[r * W + j] };
                        let d = down - up;
                        0.5 * k * d * d + 0.25 * beta * d.powi(4)
                    })
                    .sum()
            })
            .sum(),
    force(q[i] = -c * q_dot[i]),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Membrane<const W: usize, const N: usize> {
    /// Mass of each site.
    pub m: f64,
    /// Linear spring constant k.
    pub k: f64,
    /// Quartic spring constant β.
    pub beta: f64,
    /// Damping coefficient c.
    pub c: f64,
}

impl<const W: usize, const N: usize> Membrane<W, N> {
    /// `m = 1`, `k = 1`, `β = 1`, `c = 0.01`: the hand-written lattice's defaults.
    pub const DEFAULT: Membrane<W, N> = Membrane {
        m: 1.0,
        k: 1.0,
        beta: 1.0,
        c: 0.01,
    };
}

/// A driven Duffing oscillator, `ẍ + δẋ + αx + βx³ = γ cos ωt` (issue 13), written by hand
/// with the time-dependent trait methods: `L = ½ẋ² − ½αx² − ¼βx⁴`,
/// `F(t, x, ẋ) = −δẋ + γ cos ωt`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrivenDuffing {
    /// Damping δ.
    pub delta: f64,
    /// Linear stiffness α.
    pub alpha: f64,
    /// Cubic stiffness β.
    pub beta: f64,
    /// Drive amplitude γ.
    pub gamma: f64,
    /// Drive frequency ω.
    pub omega: f64,
}

impl DrivenDuffing {
    /// The chaotic regime `(δ, α, β, γ, ω) = (0.3, −1, 1, 0.5, 1.2)`.
    pub const CHAOTIC: DrivenDuffing = DrivenDuffing {
        delta: 0.3,
        alpha: -1.0,
        beta: 1.0,
        gamma: 0.5,
        omega: 1.2,
    };
}

impl ForcedLagrangian<1> for DrivenDuffing {
    // No constraints: the runtime leaves their code out.
    const CONSTRAINED: bool = false;
    const STRUCTURE: Structure = Structure::GENERAL_DRIVEN;

    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        let x = q[0];
        v[0] * v[0] * 0.5 - x * x * (0.5 * self.alpha) - x.powi(4) * (0.25 * self.beta)
    }
    fn force<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        self.force_at(D::from(0.0), q, v)
    }
    fn force_at<D: Scalar>(&self, t: D, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [-v[0] * self.delta + (t * self.omega).cos() * self.gamma]
    }
}

/// Kapitza's pendulum: a pendulum whose pivot moves vertically, `y_s(t) = a cos Ωt`, with
/// joint friction (issue 13). With `θ` from the downward vertical,
/// `L(t, θ, θ̇) = ½m(l²θ̇² + 2l sin θ θ̇ ẏ_s + ẏ_s²) − mg(y_s − l cos θ)`, `F = −cθ̇`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KapitzaPendulum {
    /// Mass.
    pub m: f64,
    /// Length.
    pub l: f64,
    /// Gravity.
    pub g: f64,
    /// Pivot amplitude a.
    pub a: f64,
    /// Pivot frequency Ω.
    pub big_omega: f64,
    /// Joint friction c.
    pub c: f64,
}

impl KapitzaPendulum {
    /// A fast drive that holds the pendulum upright: `a²Ω² = 25 > 2gl`.
    pub const UPRIGHT: KapitzaPendulum = KapitzaPendulum {
        m: 1.0,
        l: 1.0,
        g: 9.81,
        a: 0.1,
        big_omega: 50.0,
        c: 0.1,
    };
}

impl ForcedLagrangian<1> for KapitzaPendulum {
    // No constraints: the runtime leaves their code out.
    const CONSTRAINED: bool = false;
    const STRUCTURE: Structure = Structure::GENERAL_DRIVEN;

    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        self.lagrangian_at(D::from(0.0), q, v)
    }
    fn lagrangian_at<D: Scalar>(&self, t: D, q: &[D; 1], v: &[D; 1]) -> D {
        let (th, w) = (q[0], v[0]);
        let phase = t * self.big_omega;
        let ys = phase.cos() * self.a;
        let yd = -phase.sin() * (self.a * self.big_omega);
        (w * w * (self.l * self.l) + th.sin() * w * yd * (2.0 * self.l) + yd * yd) * (0.5 * self.m)
            - (ys - th.cos() * self.l) * (self.m * self.g)
    }
    fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [-v[0] * self.c]
    }
}

/// A pendulum in Cartesian coordinates with linear air drag, held on its circle by a
/// holonomic constraint (DESIGN §11): `L = ½m|v|² − m g y`, `F = −c v`,
/// `g(q) = (x² + y² − l²)/2`.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * m * (x_dot * x_dot + y_dot * y_dot) - m * g * y,
    force(x = -c * x_dot, y = -c * y_dot),
    constraints(0.5 * (x * x + y * y - l * l)),
)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CartesianPendulum {
    /// Mass.
    pub m: f64,
    /// Gravity.
    pub g: f64,
    /// Rod length.
    pub l: f64,
    /// Drag coefficient.
    pub c: f64,
}

impl CartesianPendulum {
    /// `m = 1`, `g = 9.81`, `l = 1.5`, `c = 0.3`.
    pub const DEFAULT: CartesianPendulum = CartesianPendulum {
        m: 1.0,
        g: 9.81,
        l: 1.5,
        c: 0.3,
    };
}
