//! `forced-vi-report`: the workspace's front door (`cargo run --release`).
//!
//! Without a subcommand it runs the work-precision report and writes `report/`. Commands
//! share the options `--out`, `--quick`, `--scene` and `--method`, and each adds its own
//! section to `report/README.md` (see `forced_vi_scenes::report`). A new command is a new
//! variant of [`Command`] plus a match arm in `main`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use forced_vi_scenes::report::{self, Method, Options};
use forced_vi_scenes::scenes;

mod alloc_count;

/// Counts heap allocations for `step-cost` (allocations per step).
#[global_allocator]
static ALLOC: alloc_count::Counting = alloc_count::Counting;

/// Work-precision report for the forced variational integrators.
///
/// Runs every scene with the variational schemes (over step sizes) and with the baseline
/// ODE solvers (over tolerances), and writes CSV files, SVG plots and README.md into the
/// output folder.
#[derive(Debug, Parser)]
#[command(name = "forced-vi-report", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    common: CommonArgs,
}

/// Options every command understands.
#[derive(Debug, Args)]
struct CommonArgs {
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "report", global = true)]
    out: PathBuf,
    /// Reduced grids: finishes in under a minute on two cores (used by CI).
    #[arg(long, global = true)]
    quick: bool,
    /// Run only these scenes (repeat or comma-separate; see `list`).
    #[arg(long, value_name = "NAME", value_delimiter = ',', global = true)]
    scene: Vec<String>,
    /// Run only these methods: lobattoS (S >= 2), midpoint, trapezoid, alpha(A), dop853, tsit45,
    /// bdf, esdirk34 (repeat or comma-separate).
    #[arg(long, value_name = "NAME", value_delimiter = ',', global = true)]
    method: Vec<String>,
    /// Do not draw the progress bar.
    #[arg(long, global = true)]
    no_progress: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The work-precision report (what runs when no command is given).
    WorkPrecision,
    /// List the scenes and the default methods.
    List,
    /// Stiff and extreme cases: writes stability.csv and the stability section.
    Stability,
    /// Per-step cost: generated against hand-written kernels, chain scaling, allocations,
    /// compile time and peak RSS (writes step_cost.csv and its section).
    StepCost,
}

fn options(common: &CommonArgs) -> Result<Options, report::ReportError> {
    let methods = common
        .method
        .iter()
        .map(|m| m.parse::<Method>())
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Options {
        out: common.out.clone(),
        quick: common.quick,
        scenes: common.scene.clone(),
        methods,
        progress: !common.no_progress,
    })
}

fn list() -> Result<(), report::ReportError> {
    println!("scenes:");
    for s in scenes::all()? {
        println!(
            "  {:<30} {} (T = {}, {} member(s))",
            s.name(),
            s.summary(),
            s.t_final(),
            s.members()
        );
    }
    println!("default methods:");
    for m in Method::defaults() {
        println!("  {m}");
    }
    Ok(())
}

fn work_precision(common: &CommonArgs) -> Result<(), report::ReportError> {
    let opts = options(common)?;
    let summary = report::work_precision::run(&opts)?;
    if opts.scenes.is_empty() || opts.scenes.iter().any(|s| s == "driven_duffing") {
        let points = report::poincare::run(&opts)?;
        println!("Poincaré section: {points} points");
        report::readme::assemble(&opts.out)?;
    }
    println!(
        "wrote {} ({} runs, {} failed) in {:.1} s",
        opts.out.join("README.md").display(),
        summary.rows.len(),
        summary.failures.len(),
        summary.elapsed
    );
    Ok(())
}

fn step_cost(common: &CommonArgs) -> Result<(), report::ReportError> {
    let opts = options(common)?;
    let summary = report::step_cost::run(&opts, Some(alloc_count::allocations))?;
    println!(
        "wrote {} ({} rows) in {:.1} s",
        opts.out.join("step_cost.csv").display(),
        summary.rows.len(),
        summary.elapsed
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None | Some(Command::WorkPrecision) => work_precision(&cli.common),
        Some(Command::List) => list(),
        Some(Command::Stability) => options(&cli.common)
            .and_then(|o| report::stability::run(&o).map(|s| (o, s)))
            .map(|(o, s)| {
                let done = s
                    .rows
                    .iter()
                    .filter(|r| !r.outcome.to_string().starts_with("failed"))
                    .count();
                println!(
                    "wrote {} ({} runs, {} finished) in {:.1} s",
                    o.out.join("stability.csv").display(),
                    s.rows.len(),
                    done,
                    s.elapsed
                );
            }),
        Some(Command::StepCost) => step_cost(&cli.common),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
