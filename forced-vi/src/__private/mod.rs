//! Paths and helpers for code written by `#[forced_lagrangian]`. Not a public API.
//!
//! Generated code reaches the runtime only through `::forced_vi::__private`, so a user crate
//! needs no direct num-dual or nalgebra dependency. The helpers are the dual-number
//! building blocks of the specialised node kernels: each differentiates one term of the
//! Lagrangian (or one force component) over only the variables that the term uses.
//!
//! Variables are numbered by *slot*: slot `s < N` is `q[s]`, slot `s ≥ N` is `v[s − N]`.
//!
//! Every helper is re-exported here, at the path generated code names:
//!
//! | piece | module |
//! |---|---|
//! | indexing and integer arithmetic of model code that never panics | `int` |
//! | the dense node kernels: term gradients and Hessians, force rows and Jacobians | `dense` |
//! | per-term kernels of split models (sparse kernels, DESIGN §9): slots, `Accum` | `terms` |
//! | elementary functions whose num-dual form overflows where they are finite (`tanh`) | `functions` |

mod dense;
mod functions;
mod int;
mod terms;

pub use nalgebra;
pub use num_dual;

pub use crate::doubled;
pub use crate::model::{ForcedLagrangian, NodeGradient, NodeJacobian, Structure, general};
pub use crate::scalar::{Scalar, lift};
pub use core::primitive::f64;
pub use nalgebra::{SMatrix, SVector};

pub use crate::model::{Block, NodeSink, SparseNode};

pub use dense::*;
pub use functions::*;
pub use int::*;
pub use terms::*;
