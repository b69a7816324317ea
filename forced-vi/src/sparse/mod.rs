//! Large models: the sparse linear algebra of a step (DESIGN §9).
//!
//! A model whose [`ForcedLagrangian::sparse_node`](crate::ForcedLagrangian::sparse_node)
//! returns kernels ([`SparseNode`]) can be stepped on sparse storage (see
//! [`LinearPath`](crate::LinearPath)): the node pattern is recorded at the first evaluation,
//! the step Jacobian's pattern and faer's symbolic LU analysis follow from it once per run,
//! and each step fills, factors and solves on those, with every buffer made once per run.
//! The stepping loop itself is the one [`Stepper`](crate::Stepper) of every model size; this
//! module is what its sparse backend is made of.
//!
//! | piece | module |
//! |---|---|
//! | the kernels' interface: [`SparseNode`], [`NodeSink`], [`NodePattern`] (re-exported from [`crate::model`]) | this one |
//! | recording the node pattern, the step Jacobian's pattern | `pattern` |
//! | the step equations (DESIGN §3) on sparse storage | `equations` |
//! | a sparse LU on a fixed pattern, allocation-free per factorisation, backed by faer's | `lu`, `supernodal` |
//! | the Newton iteration's sparse linear solver | `newton` |
//! | the velocity solve `L_v(q, v) = p` | `velocity` |
//! | holonomic constraints: `g`, `G`, the curvature, the saddle-point solve (DESIGN §11) | `constraints` |

#[cfg(feature = "sparse")]
pub(crate) mod constraints;
#[cfg(feature = "sparse")]
pub(crate) mod equations;
#[cfg(feature = "sparse")]
pub(crate) mod lu;
#[cfg(feature = "sparse")]
pub(crate) mod newton;
#[cfg(feature = "sparse")]
pub(crate) mod pattern;
#[cfg(feature = "sparse")]
mod supernodal;
#[cfg(feature = "sparse")]
pub(crate) mod velocity;

pub use crate::model::{Block, ConstraintSink, NodeBlocks, NodePattern, NodeSink, SparseNode};
#[cfg(feature = "sparse")]
pub(crate) use constraints::record_constraint_patterns;
#[cfg(feature = "sparse")]
pub(crate) use pattern::record_node_pattern;
