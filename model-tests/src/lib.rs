//! Nothing: the package holds the test binary `models_suite` (`tests/models_suite.rs` at the
//! workspace root), so that its release build has a profile of its own (see the workspace's
//! `Cargo.toml`).
