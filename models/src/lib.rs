//! The models of the forced-vi workspace: the systems behind the report's scenes, the tests
//! and the examples, written with `#[forced_lagrangian]` ([`models`]); the large sparse chain
//! and membrane written by hand ([`large`]); and the paper's model with hand-derived kernels
//! ([`handwritten`]).
//!
//! Not published. The report library (`forced_vi_scenes`) re-exports these three modules; they
//! are a package of their own so that the tests that need only the runtime and the models
//! (the package's test targets, in the workspace's `tests/`) compile while the report and its
//! baselines (diffsol, plotters) are still building.
#![warn(missing_docs)]

pub mod handwritten;
pub mod large;
pub mod models;
pub mod rigid_chain;
