//! Scenes, models, baselines and the report of the forced-vi workspace.
//!
//! This package is not published; it holds what the tests, examples and the report command
//! share.
#![warn(missing_docs)]

pub mod baselines;
pub mod handwritten;
pub mod large;
pub mod models;
pub mod reference;
pub mod report;
pub mod scenes;
