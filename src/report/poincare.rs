//! The Poincaré section of the chaotic driven Duffing oscillator (issue 13): the state
//! `(x, ẋ)` once per driving period, from `output::Samples` (the steps are not kept).
//!
//! ```text
//! poincare_duffing.svg    the section (10⁴ periods; 10³ under --quick)
//! sections/poincare.md    its README section
//! ```

use std::path::Path;

use forced_vi::prelude::*;
use plotters::prelude::*;

use super::style::{plot_err, register_font, FAMILY, PALETTE};
use super::{readme, Options, ReportError};
use crate::models::DrivenDuffing;
use crate::scenes::SceneError;

/// The section name (`sections/poincare.md`).
pub const SECTION: &str = "poincare";
/// The scene whose Poincaré section this draws; the work-precision command draws it when the
/// scene is selected.
pub const SCENE: &str = "driven_duffing";

/// Steps per driving period (lobatto3: order 4).
const STEPS_PER_PERIOD: f64 = 100.0;

/// Computes the section, draws it and writes its README section; returns the points.
pub fn run(opts: &Options) -> Result<usize, ReportError> {
    let model = DrivenDuffing::CHAOTIC;
    let period = 2.0 * std::f64::consts::PI / model.omega;
    let periods: usize = if opts.quick { 1_000 } else { 10_000 };
    // The first 100 periods are the transient onto the attractor.
    let times: Vec<f64> = (100..=periods).map(|k| k as f64 * period).collect();
    let started = std::time::Instant::now();
    let vi = |e: forced_vi::Error| ReportError::from(SceneError::from(e));
    let scheme = Scheme::lobatto(3).map_err(|e| vi(e.into()))?;
    let samples = Integrator::new(&model, scheme, period / STEPS_PER_PERIOD)
        .map_err(vi)?
        .solve(
            InitialState::from_velocity([1.0], [0.0]),
            periods as f64 * period,
            output::Samples(&times),
        )
        .map_err(|f| vi(f.error))?;
    let seconds = started.elapsed().as_secs_f64();
    let path = opts.out.join("poincare_duffing.svg");
    draw(&path, &samples)?;
    let markdown = format!(
        "## Poincaré section of the driven Duffing oscillator\n\n\
         The chaotic Duffing oscillator `ẍ + 0.3ẋ − x + x³ = 0.5 cos 1.2t` (scene \
         `driven_duffing`, a force `F(t, x, ẋ)`), sampled once per driving period over {periods} \
         periods from `(x, ẋ) = (1, 0)`, leaving out the first 100: {} points. `lobatto3` with \
         {STEPS_PER_PERIOD} steps per period, {} steps in {seconds:.1} s, through \
         `output::Samples`, which keeps only the samples.\n\n\
         ![Poincaré section](poincare_duffing.svg)\n",
        samples.len(),
        periods as f64 * STEPS_PER_PERIOD,
    );
    readme::write_section(&opts.out, SECTION, &markdown)?;
    Ok(samples.len())
}

fn draw(path: &Path, samples: &[forced_vi::DenseState<1>]) -> Result<(), ReportError> {
    register_font(path.parent().unwrap_or(Path::new(".")))?;
    let err = plot_err(path);
    let root = SVGBackend::new(path, (640, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let mut chart = ChartBuilder::on(&root)
        .caption("Driven Duffing: Poincaré section", (FAMILY, 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-2.0f64..2.0, -1.0f64..1.5)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("x")
        .y_desc("dx/dt")
        .label_style((FAMILY, 12))
        .draw()
        .map_err(|e| err(e.to_string()))?;
    let dot = PALETTE[0].filled();
    chart
        .draw_series(
            samples
                .iter()
                .map(|s| Circle::new((s.q[0], s.v[0]), 1, dot)),
        )
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))
}
