//! Nothing: the package holds `tests/ui.rs`, the runner of the compile-fail cases in the
//! workspace's `tests/ui/`.
