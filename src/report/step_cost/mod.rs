//! `step-cost`: the cost of one step, generated kernels against hand-written ones, and how it
//! scales with the model size.
//!
//! Writes into the report folder:
//!
//! ```text
//! step_cost.csv           scene,method,n,diagnostics,path,ns_per_step_generated,
//!                         ns_per_step_handwritten,ratio,newton_iters_per_step,allocs_per_step
//! ensemble_throughput.csv threads,members,member_steps_per_second
//! step_cost_scaling.svg   time per step against n: fpu_chain and lattice_2d, dense and sparse
//! sections/step_cost.md   the section of README.md (targets of issue 6, met or not)
//! ```
//!
//! - `coupled_van_der_pol` rows: the paper's model ([`CoupledVanDerPol::PAPER`](crate::models::CoupledVanDerPol::PAPER)) against
//!   [`HandCoupledVanDerPol::PAPER`](crate::handwritten::HandCoupledVanDerPol::PAPER) for each scheme at `h = 0.01`, through the same
//!   [`Integrator`](forced_vi::Integrator) (same predictor, Newton options and tolerances). Repeats alternate
//!   generated and hand-written runs so that machine noise hits both alike; the medians are
//!   reported.
//! - `fpu_chain` and `lattice_2d` rows (issue 12): the FPU-β chain (n = 2 … 4096) and the
//!   W × W membrane (n = 4 … 4096), generated against hand-written sparse kernels, lobatto2
//!   and lobatto3, on the dense and the sparse path ([`scaling`]). Each size runs in its own
//!   thread, with a stack for the dense path's `N × N` node blocks.
//! - allocations: counted by the binary's counting allocator between the first and the last
//!   record of a `output::each_step` run (so the stepper's one-off buffers are excluded), divided
//!   by the steps.
//! - compile time of a crate with one model against one with ten, and the peak RSS of a long
//!   streamed run (full run only for the compile time);
//! - the first answer on a new large model: a crate with a 256-coordinate chain built and
//!   run, against heyoka's committed JIT build and run ([`first_run`]; full run only).
//!
//! # The study
//!
//! The paper-model rows are a study of one case per scheme, run one at a time (they are
//! timed); the scaling sizes run in order, each deciding from the last measured size whether
//! the next fits the time limit. `measure`, `compile`, `figures` and `section` hold the parts.

use std::time::Instant;

use crate::report::command::Command;
use crate::report::style;
use crate::report::table::write_csv;
use crate::report::{readme, Options, ReportError};

pub mod compile;
pub mod ensemble;
mod figures;
pub mod first_run;
pub mod measure;
pub mod rows;
pub mod scaling;
mod scaling_section;
mod section;

pub use compile::CompileTimes;
pub use measure::{peak_rss_kib, SCHEMES};
pub use rows::{AllocCounter, Memory, Row, StepCostRecord, Summary};

/// The section name in `report/sections/`.
pub const SECTION: &str = "step_cost";

/// `forced-vi-report step-cost`.
pub const COMMAND: Command = Command {
    name: "step-cost",
    about: "Per-step cost: generated against hand-written kernels, chain scaling, allocations, \
            compile time and peak RSS (writes step_cost.csv and its section).",
    sections: &[SECTION],
    run: |opts, hooks| {
        let summary = run(opts, hooks.allocations)?;
        Ok(format!(
            "wrote {} ({} rows) in {:.1} s",
            opts.out.join("step_cost.csv").display(),
            summary.rows.len(),
            summary.elapsed
        ))
    },
};

/// Runs the step-cost measurements and writes `step_cost.csv`, the scaling plot and the
/// section. `counter` reads the binary's counting allocator; without it the allocation
/// column stays empty.
pub fn run(opts: &Options, counter: Option<AllocCounter>) -> Result<Summary, ReportError> {
    let t0 = Instant::now();
    std::fs::create_dir_all(&opts.out).map_err(ReportError::io(&opts.out))?;
    eprintln!("step-cost: streaming the paper model for peak RSS …");
    let memory = measure::memory(opts.quick);
    eprintln!("step-cost: generated against hand-written …");
    let (mut rows, same_iterations) = measure::paper_rows(opts.quick, counter);
    eprintln!("step-cost: fpu_chain and lattice_2d scaling, dense and sparse …");
    let (scaling_rows, peaks) = scaling::rows(opts.quick, counter);
    rows.extend(scaling_rows);
    eprintln!("step-cost: ensemble throughput on 1 and 2 threads …");
    let ensemble = ensemble::measure(opts.quick);
    if let Ok(t) = &ensemble {
        write_csv(&opts.out.join("ensemble_throughput.csv"), &t.records)?;
    }
    let exponents = scaling::exponents(&rows);
    let compile = if opts.quick {
        Err("not measured in --quick (it builds two crates; see the full run)".to_string())
    } else {
        eprintln!("step-cost: compile times …");
        compile::compile_times()
    };
    let first_run = if opts.quick {
        Err("not measured in --quick (it builds a crate; see the full run)".to_string())
    } else {
        eprintln!("step-cost: the first answer on a new model, against heyoka …");
        first_run::measure()
    };
    let records: Vec<StepCostRecord> = rows.iter().map(Into::into).collect();
    write_csv(&opts.out.join("step_cost.csv"), &records)?;
    let svg = opts.out.join("step_cost_scaling.svg");
    style::register_font(&opts.out)?;
    let plotted = figures::plot_scaling(&svg, &rows).map_err(style::plot_err(&svg))?;
    let mut summary = Summary {
        rows,
        exponents,
        peaks,
        compile,
        first_run,
        memory,
        same_iterations,
        ensemble,
        elapsed: 0.0,
    };
    summary.elapsed = t0.elapsed().as_secs_f64();
    let md = section::markdown_section(
        &summary,
        opts.quick,
        plotted.then_some("step_cost_scaling.svg"),
    );
    readme::write_section(&opts.out, SECTION, &md)?;
    Ok(summary)
}
