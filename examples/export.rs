//! A trajectory written out with serde, no formatting by hand: one CSV row per step (the
//! `csv` crate) and the whole `Trajectory` as JSON (`serde_json`). Needs the `serde` feature
//! of `forced-vi`, which this workspace turns on.
//!
//! `cargo run --release --example export [OUT_DIR]` (default `target/export`).
use std::error::Error;
use std::fs::File;
use std::path::PathBuf;

use forced_vi::prelude::*;
use serde::Serialize;

/// Two coupled van der Pol oscillators (the paper's numerical test).
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + (1.0 + rho) * y * y)
        - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
)]
struct CoupledVanDerPol {
    eps: f64,
    rho: f64,
    lambda: f64,
}

/// One CSV row: a flat record, so that the header names every column.
#[derive(Serialize)]
struct Row {
    step: usize,
    t: f64,
    x: f64,
    y: f64,
    x_dot: f64,
    y_dot: f64,
    energy: f64,
    energy_balance: f64,
}

impl From<&StepRecord<2>> for Row {
    fn from(r: &StepRecord<2>) -> Self {
        Row {
            step: r.step,
            t: r.t,
            x: r.q[0],
            y: r.q[1],
            x_dot: r.v[0],
            y_dot: r.v[1],
            energy: r.energy,
            energy_balance: r.energy_balance,
        }
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let out: PathBuf = std::env::args_os()
        .nth(1)
        .map_or_else(|| PathBuf::from("target/export"), PathBuf::from);
    std::fs::create_dir_all(&out)?;

    let model = CoupledVanDerPol {
        eps: 0.5,
        rho: 0.02,
        lambda: 0.8,
    };
    let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
        .solve(
            InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
            10.0,
            output::Records,
        )
        .map_err(|failure| failure.error)?;

    let csv_path = out.join("trajectory.csv");
    let mut csv = csv::Writer::from_path(&csv_path)?;
    for r in &run.records {
        csv.serialize(Row::from(r))?;
    }
    csv.flush()?;

    let json_path = out.join("trajectory.json");
    serde_json::to_writer_pretty(File::create(&json_path)?, &run)?;

    // The JSON reads back to the same trajectory, bit for bit.
    let back: Trajectory<2> = serde_json::from_reader(File::open(&json_path)?)?;
    assert_eq!(back, run);

    println!(
        "{} records to {} and {}",
        run.records.len(),
        csv_path.display(),
        json_path.display()
    );
    Ok(())
}
