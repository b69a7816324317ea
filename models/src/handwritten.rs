//! Hand-written models: the limit the macro-generated kernels are measured against.
//!
//! [`HandCoupledVanDerPol`] is the paper's coupled van der Pol system
//! ([`CoupledVanDerPol`](crate::models::CoupledVanDerPol)) with its node kernels derived by
//! hand. It implements the same [`ForcedLagrangian<2>`] trait with the same
//! [`Structure`] flags, so it runs through the *same* stepper, predictor, Newton solver and
//! tolerances for every scheme: only the derivative code differs. The step-cost report
//! (`cargo run --release -- step-cost`) and `benches/step.rs` time the two side by side.

use forced_vi::prelude::*;
use forced_vi::{NodeGradient, NodeJacobian, Structure};
use nalgebra::{SMatrix, SVector};

/// Two coupled van der Pol oscillators with analytic, hand-coded node kernels.
///
/// `L = ½(v₁² + v₂²) − ½(q₁² + (1+ρ)q₂²) − λ(q₁ − q₂)²`, `F = ((ε − q₁²)v₁, (ε − q₂²)v₂)`,
/// exactly as [`CoupledVanDerPol`](crate::models::CoupledVanDerPol). The blocks are
///
/// - `L_q + F = (−q₁ − 2λ(q₁−q₂) + (ε−q₁²)v₁, −(1+ρ)q₂ + 2λ(q₁−q₂) + (ε−q₂²)v₂)`, `L_v = v`;
/// - `A = [[−1 − 2λ − 2q₁v₁, 2λ], [2λ, −(1+ρ) − 2λ − 2q₂v₂]]`;
/// - `B = diag(ε − q₁², ε − q₂²)`, `C = 0`, `E = I`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandCoupledVanDerPol {
    /// Damping parameter ε.
    pub eps: f64,
    /// Detuning ρ of the second oscillator.
    pub rho: f64,
    /// Coupling strength λ.
    pub lambda: f64,
}

impl HandCoupledVanDerPol {
    /// The paper's parameters `(ε, ρ, λ) = (0.5, 0.02, 0.8)`.
    pub const PAPER: HandCoupledVanDerPol = HandCoupledVanDerPol {
        eps: 0.5,
        rho: 0.02,
        lambda: 0.8,
    };
}

impl ForcedLagrangian<2> for HandCoupledVanDerPol {
    // No constraints: the runtime leaves their code out.
    const CONSTRAINED: bool = false;
    const STRUCTURE: Structure = Structure {
        has_force: true,
        force_uses_velocity: true,
        constant_mass: true,
        linear: false,
        uses_time: false,
    };

    fn coordinate_names(&self) -> [&'static str; 2] {
        ["x", "y"]
    }

    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let d = q[0] - q[1];
        (v[0] * v[0] + v[1] * v[1]) * 0.5
            - (q[0] * q[0] + q[1] * q[1] * (1.0 + self.rho)) * 0.5
            - d * d * self.lambda
    }

    fn force<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [
            (-(q[0] * q[0]) + self.eps) * v[0],
            (-(q[1] * q[1]) + self.eps) * v[1],
        ]
    }

    fn check_parameters(&self) -> Result<(), &'static str> {
        if !self.eps.is_finite() {
            return Err("eps");
        }
        if !self.rho.is_finite() {
            return Err("rho");
        }
        if !self.lambda.is_finite() {
            return Err("lambda");
        }
        Ok(())
    }

    #[inline]
    fn node_gradient(&self, q: &SVector<f64, 2>, v: &SVector<f64, 2>) -> NodeGradient<2> {
        let (x, y) = (q[0], q[1]);
        let c = 2.0 * self.lambda * (x - y);
        NodeGradient {
            fq: SVector::<f64, 2>::new(
                -x - c + (self.eps - x * x) * v[0],
                -(1.0 + self.rho) * y + c + (self.eps - y * y) * v[1],
            ),
            lv: *v,
        }
    }

    #[inline]
    fn node_jacobian(&self, q: &SVector<f64, 2>, v: &SVector<f64, 2>) -> NodeJacobian<2> {
        let (x, y) = (q[0], q[1]);
        let l2 = 2.0 * self.lambda;
        NodeJacobian {
            grad: self.node_gradient(q, v),
            a: SMatrix::<f64, 2, 2>::new(
                -1.0 - l2 - 2.0 * x * v[0],
                l2,
                l2,
                -(1.0 + self.rho) - l2 - 2.0 * y * v[1],
            ),
            b: SMatrix::<f64, 2, 2>::new(self.eps - x * x, 0.0, 0.0, self.eps - y * y),
            c: SMatrix::zeros(),
            e: SMatrix::identity(),
        }
    }

    #[inline]
    fn mass_matrix(&self, _q: &SVector<f64, 2>, _v: &SVector<f64, 2>) -> SMatrix<f64, 2, 2> {
        SMatrix::identity()
    }
}
