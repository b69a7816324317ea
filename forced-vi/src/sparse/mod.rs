//! Large models: sparse node kernels and the sparse step (DESIGN §9).
//!
//! A model whose [`ForcedLagrangian::sparse_node`](crate::ForcedLagrangian::sparse_node)
//! returns kernels is stepped on sparse storage when it is large and sparse enough (see
//! [`LinearPath`](crate::LinearPath)): the node pattern is recorded at the first evaluation,
//! the step Jacobian's pattern and faer's symbolic LU analysis follow from it once per run,
//! and each step fills, factors and solves on those, with every buffer made once per run.
//!
//! | piece | module |
//! |---|---|
//! | the kernels' interface: [`SparseNode`], [`NodeSink`], [`NodePattern`] | `node` |
//! | recording the node pattern, the step Jacobian's pattern | `pattern` |
//! | the step equations (DESIGN §3) on sparse storage | `equations` |
//! | faer's sparse LU on a fixed pattern | `lu` |
//! | Newton on a sparse Jacobian | `newton` |
//! | the velocity solve `L_v(q, v) = p` | `velocity` |
//! | the stepping loop: [`SparseStepper`] | `stepper`, `advance`, `state` |

#[cfg(feature = "sparse")]
mod advance;
#[cfg(feature = "sparse")]
mod equations;
#[cfg(feature = "sparse")]
mod lu;
#[cfg(feature = "sparse")]
mod newton;
mod node;
#[cfg(feature = "sparse")]
mod pattern;
#[cfg(feature = "sparse")]
mod state;
#[cfg(feature = "sparse")]
mod stepper;
#[cfg(feature = "sparse")]
mod velocity;

pub use node::{Block, NodeBlocks, NodePattern, NodeSink, SparseNode};
#[cfg(feature = "sparse")]
pub(crate) use pattern::record_node_pattern;
#[cfg(feature = "sparse")]
pub use stepper::SparseStepper;
