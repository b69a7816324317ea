//! The end-to-end tests that need the report's library or its binary (the scenes, the
//! baselines, `forced-vi-report --quick`), as modules of one test binary: one link instead
//! of eight, and the tests share the two test threads. Each file is one topic, and its tests
//! keep their names (`cargo test --workspace --release paper_` selects the paper's).

#[path = "adaptive.rs"]
mod adaptive;
#[path = "driven.rs"]
mod driven;
#[path = "ensemble.rs"]
mod ensemble;
#[path = "high_order.rs"]
mod high_order;
#[path = "paper.rs"]
mod paper;
#[path = "report_quick.rs"]
mod report_quick;
#[path = "stability_quick.rs"]
mod stability_quick;
#[path = "step_cost_quick.rs"]
mod step_cost_quick;
#[path = "units.rs"]
mod units;
