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
//!     .solve(InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]), 1.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! let end = run.last().expect("a run has its initial record");
//! assert_eq!(end.step, 100);
//! assert!(end.energy_balance.abs() < 1e-7); // order 4: about 2e-8 at h = 0.01
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! The same model is three lines with the attribute
//! [`#[forced_lagrangian]`](forced_lagrangian), which writes the impl, checks the model at
//! compile time and specialises its derivatives. The [`guide`] is its reference, every form
//! with an example that runs, and says what `STRUCTURE` means, when the sparse backend is
//! taken, what an `Ok` promises and which errors bad input gets.
//!
//! # Cargo features
//!
//! - `rayon` (default): ensemble members run in parallel ([`ensemble`]).
//! - `sparse` (default): the sparse backend for large models (faer's sparse LU); without
//!   it every run is dense and [`LinearPath::Sparse`] is a typed error.
//! - `serde`: `Serialize`/`Deserialize` on the results ([`Trajectory`], [`StepRecord`],
//!   [`FinalState`], ...) and `Serialize` on the errors; see the [guide](guide#export).
#![warn(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
// `RunFailure` carries what a run computed before it failed (records, samples, the last
// record, the totals) by value, so that `?` and field access stay plain; a failure is the
// rare path, and its size is a few hundred bytes.
#![allow(clippy::result_large_err)]

//! # Where things live
//!
//! The data path, from a model to a trajectory, one module per concern:
//!
//! | stage | module |
//! |---|---|
//! | the model: `L`, `F`, node kernels `(L_q + F, L_v)` and `A, B, C, E` (DESIGN §2); sparse node kernels (DESIGN §9) | [`model`], [`scalar`](Scalar) |
//! | Galley's doubled Lagrangian Λ, for tests and users | [`doubled`] |
//! | a scheme as coefficients `(d, c, b)`, `Φ`, `Ψ`, the Jacobian terms (DESIGN §3) | [`scheme`] |
//! | the step equations: residual `G_j` and Jacobian `∂G_j/∂x_m` (DESIGN §3), dense and sparse | `step_equations`, [`sparse`] |
//! | Newton's method, knowing nothing of time or schemes; dense LU, faer's sparse LU | [`newton`], [`sparse`] |
//! | initial data, the velocity solve `L_v(q, v) = p`, mass-matrix checks | [`initial`] |
//! | the linear algebra of a step behind one trait: the dense and the sparse backend (DESIGN §10) | `backend` |
//! | the one stepping loop of every model size: predictor, solve, update, subdivision, adaptive steps, checks | [`stepper`] |
//! | records, energy and energy balance (DESIGN §4), run totals, [`RunFailure`] | [`trajectory`] |
//! | error control: tolerances, the reference-scheme estimate, PI controller, first step (DESIGN §8) | [`control`] |
//! | the integrator builder, the choice of backend ([`LinearPath`]), `solve` and the outputs of a run ([`output`]), runs restarted on one stepper ([`Runs`]) | [`integrator`] |
//! | ensembles: many initial states or parameter sets, in parallel with the feature `rayon` | [`ensemble`] |
//! | typed errors | [`Error`], [`NewtonFailure`], [`SchemeError`] |
//! | the reference of `#[forced_lagrangian]`, the promises of a run, bad input, export | [`guide`] |
//!
//! Data flows one way: model → step equations → Newton and linear algebra → backend →
//! stepper → integrator → ensemble; no module imports one that imports it.

mod backend;
mod buffers;
pub mod control;
pub mod doubled;
pub mod ensemble;
mod error;
pub mod guide;
pub mod initial;
pub mod integrator;
pub mod model;
pub mod newton;
mod scalar;
pub mod scheme;
pub mod sparse;
mod stack;
mod step_equations;
pub mod stepper;
pub mod trajectory;

pub use control::Tolerance;
pub use error::{Error, NewtonFailure, SchemeError};
pub use initial::InitialState;
pub use integrator::{
    Integrator, LinearPath, MAX_KERNEL_STACK, MAX_TANGENT_BYTES, Runs, StepOptions, output,
};
pub use model::{ForcedLagrangian, NodeGradient, NodeJacobian, Structure};
pub use newton::{Newton, NewtonOptions, NewtonReport, NonlinearSystem};
pub use scalar::{Scalar, lift};
pub use scheme::{Scheme, SchemeId};
pub use stepper::Stepper;
pub use trajectory::{
    AdjointGradient, DenseState, FinalState, RunFailure, RunStats, Sensitivities, StepRecord,
    Trajectory,
};

/// The runnable reference of every form, with the compile errors, is the [`guide`]
/// ([Writing a model](guide#writing-a-model)).
pub use forced_vi_macros::forced_lagrangian;

/// The names most programs need.
pub mod prelude {
    pub use crate::{
        FinalState, ForcedLagrangian, InitialState, Integrator, Scalar, Scheme, SchemeId,
        StepRecord, Tolerance, Trajectory, forced_lagrangian, output,
    };
}

// The Rust code blocks of the READMEs compile and run as doctests (`cfg(doctest)`: nothing
// of this is in the library itself). The workspace README is outside this package, so a
// packaged crate never reads it.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct CrateReadme;

#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
pub struct WorkspaceReadme;

#[cfg(doctest)]
#[doc = include_str!("../../forced-vi-macros/README.md")]
pub struct MacrosReadme;

/// Paths used by macro-generated code. Not a public API.
#[doc(hidden)]
pub mod __private;
