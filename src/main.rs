//! `forced-vi-report`: the workspace's front door (`cargo run --release`).
//!
//! Without a subcommand it runs the work-precision report and writes `report/`. Commands
//! share the options `--out`, `--quick`, `--scene` and `--method`, and each adds its own
//! section to `report/README.md`. The commands are `forced_vi_scenes::report::COMMANDS`: a
//! new command is added there, not here.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, FromArgMatches};
use forced_vi_scenes::report::{self, Method, Options};
use forced_vi_scenes::scenes;

mod alloc_count;

/// Counts heap allocations for `step-cost` (allocations per step).
#[global_allocator]
static ALLOC: alloc_count::Counting = alloc_count::Counting;

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

/// The command line: the options of [`CommonArgs`], `list`, and one subcommand per entry of
/// [`report::COMMANDS`].
fn cli() -> clap::Command {
    let root = CommonArgs::augment_args(clap::Command::new("forced-vi-report"))
        .version(env!("CARGO_PKG_VERSION"))
        .about("Work-precision report for the forced variational integrators.")
        .long_about(
            "Work-precision report for the forced variational integrators.\n\n\
             Runs every scene with the variational schemes (over step sizes) and with the \
             baseline ODE solvers (over tolerances), and writes CSV files, SVG plots and \
             README.md into the output folder.",
        )
        .subcommand(clap::Command::new("list").about("List the scenes and the default methods."));
    report::COMMANDS.iter().fold(root, |cli, c| {
        cli.subcommand(clap::Command::new(c.name).about(c.about))
    })
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

fn main() -> ExitCode {
    let matches = cli().get_matches();
    let result = CommonArgs::from_arg_matches(&matches)
        .map_err(|e| e.exit())
        .and_then(|common| match matches.subcommand_name() {
            Some("list") => list(),
            name => {
                let command = name
                    .and_then(report::command::find)
                    .unwrap_or(&report::COMMANDS[0]);
                let hooks = report::Hooks {
                    allocations: Some(alloc_count::allocations),
                };
                options(&common)
                    .and_then(|opts| (command.run)(&opts, &hooks))
                    .map(|line| println!("{line}"))
            }
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
