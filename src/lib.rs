//! Scenes, models, baselines and the report of the forced-vi workspace.
//!
//! This package is not published; it holds what the tests, examples and the report command
//! share.
#![warn(missing_docs)]

pub mod baselines;
pub mod reference;
pub mod report;
pub mod scenes;

// The models are a package of their own (`models/`), so that the tests that need only them
// do not wait for this library; these paths stay as they were.
pub use forced_vi_models::{handwritten, large, models, rigid_chain};
