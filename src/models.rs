//! The models behind the tests, examples and report scenes.
//!
//! Hand-written impls for now; they move to `#[forced_lagrangian]` with the macro.

use forced_vi::prelude::*;

/// Two coupled van der Pol oscillators, the paper's numerical test (§5 of the paper).
///
/// `L = ½(v₁² + v₂²) − ½(q₁² + (1+ρ)q₂²) − λ(q₁ − q₂)²`, `F = ((ε − q₁²)v₁, (ε − q₂²)v₂)`.
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

impl ForcedLagrangian<2> for CoupledVanDerPol {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let [x, y] = *q;
        (v[0] * v[0] + v[1] * v[1]) * 0.5
            - (x * x + y * y * (1.0 + self.rho)) * 0.5
            - (x - y) * (x - y) * self.lambda
    }
    fn force<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [
            (-q[0] * q[0] + self.eps) * v[0],
            (-q[1] * q[1] + self.eps) * v[1],
        ]
    }
}

/// A linear damped oscillator `L = ½vᵀMv − ½qᵀKq`, `F = −Dv`, with full 2×2 matrices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DampedOscillator {
    /// Mass matrix (symmetric positive definite), row-major.
    pub m: [[f64; 2]; 2],
    /// Stiffness matrix (symmetric), row-major.
    pub k: [[f64; 2]; 2],
    /// Damping matrix, row-major.
    pub d: [[f64; 2]; 2],
}

impl DampedOscillator {
    /// The matrices of the report scene and the tests.
    pub const DEFAULT: DampedOscillator = DampedOscillator {
        m: [[2.0, 0.5], [0.5, 1.0]],
        k: [[3.0, -1.0], [-1.0, 2.0]],
        d: [[0.1, 0.02], [0.02, 0.05]],
    };
}

impl ForcedLagrangian<2> for DampedOscillator {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let mut l = D::from(0.0);
        for i in 0..2 {
            for j in 0..2 {
                l += (v[i] * v[j] * self.m[i][j] - q[i] * q[j] * self.k[i][j]) * 0.5;
            }
        }
        l
    }
    fn force<D: Scalar>(&self, _q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        std::array::from_fn(|i| -(v[0] * self.d[i][0] + v[1] * self.d[i][1]))
    }
}
