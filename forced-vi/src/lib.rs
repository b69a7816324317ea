//! Variational integrators of any order for forced Lagrangian systems.
//!
//! A model is a Lagrangian `L(q, v)` and a non-conservative force `F(q, v)`, written once
//! over a generic [`Scalar`]. The integrator discretises Galley's doubled Lagrangian with
//! Galerkin Lobatto schemes (order `2s − 2`) or the midpoint, trapezoidal and α rules, and
//! solves each step with a shared Newton solver. Exact derivatives come from num-dual.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// Two coupled van der Pol oscillators (the paper's numerical test).
//! struct CoupledVanDerPol { eps: f64, rho: f64, lambda: f64 }
//!
//! impl ForcedLagrangian<2> for CoupledVanDerPol {
//!     fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
//!         let [x, y] = *q;
//!         (v[0] * v[0] + v[1] * v[1]) * 0.5
//!             - (x * x + y * y * (1.0 + self.rho)) * 0.5
//!             - (x - y) * (x - y) * self.lambda
//!     }
//!     fn force<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
//!         [(-q[0] * q[0] + self.eps) * v[0], (-q[1] * q[1] + self.eps) * v[1]]
//!     }
//! }
//!
//! let model = CoupledVanDerPol { eps: 0.5, rho: 0.02, lambda: 0.8 };
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .run(InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]), 1.0)
//!     .map_err(|failure| failure.error)?;
//! let end = run.last().expect("a run has its initial record");
//! assert_eq!(end.step, 100);
//! assert!(end.energy_balance.abs() < 1e-7); // order 4: about 2e-8 at h = 0.01
//! # Ok::<(), forced_vi::Error>(())
//! ```
#![warn(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod doubled;
mod error;
pub mod integrator;
pub mod model;
pub mod newton;
mod scalar;
pub mod scheme;

pub use error::{Error, NewtonFailure, SchemeError};
pub use integrator::{
    InitialState, Integrator, RunFailure, RunStats, StepOptions, StepRecord, Stepper, Trajectory,
};
pub use model::{ForcedLagrangian, NodeGradient, NodeJacobian, Structure};
pub use newton::{Newton, NewtonOptions, NewtonReport, NonlinearSystem};
pub use scalar::{lift, Scalar};
pub use scheme::{Scheme, SchemeId};

/// Writes the [`ForcedLagrangian`] impl of a model from its Lagrangian and force.
///
/// See the crate README, section "Writing a model", for the syntax.
pub use forced_vi_macros::forced_lagrangian;

/// The names most programs need.
pub mod prelude {
    pub use crate::{
        forced_lagrangian, ForcedLagrangian, InitialState, Integrator, Scalar, Scheme, SchemeId,
        StepRecord, Trajectory,
    };
}

/// Paths used by macro-generated code. Not a public API.
#[doc(hidden)]
pub mod __private;
