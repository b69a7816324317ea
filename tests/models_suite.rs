//! The end-to-end tests that need only the runtime and the models (`forced-vi-models`), as
//! modules of one test binary; each file is one topic, and its tests keep their names
//! (`cargo test --workspace --release extreme_` still selects the extreme cases).

#[path = "constraint_fourbar.rs"]
mod constraint_fourbar;
#[path = "constraints.rs"]
mod constraints;
#[path = "extreme.rs"]
mod extreme;
#[path = "extreme_props.rs"]
mod extreme_props;
#[path = "final_state.rs"]
mod final_state;
#[path = "generated_models.rs"]
mod generated_models;
#[path = "held_out.rs"]
mod held_out;
#[path = "macro_kernels.rs"]
mod macro_kernels;
#[path = "predictor.rs"]
mod predictor;
#[path = "runs.rs"]
mod runs;
#[path = "sensitivity.rs"]
mod sensitivity;
#[path = "sensitivity_constrained.rs"]
mod sensitivity_constrained;
#[path = "sparse.rs"]
mod sparse;
#[path = "sparse_macro.rs"]
mod sparse_macro;
#[path = "trust_limits.rs"]
mod trust_limits;
#[path = "trust_macro.rs"]
mod trust_macro;
#[path = "trust_random.rs"]
mod trust_random;
#[path = "trust_runtime.rs"]
mod trust_runtime;
