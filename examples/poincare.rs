//! The Poincaré section of the chaotic driven Duffing oscillator: the state `(x, ẋ)` sampled
//! once per driving period over 10⁴ periods (`output::Samples`, the steps are not kept).
//! `cargo run --release --example poincare [OUT.svg]` (default `report/poincare_duffing.svg`).
use forced_vi::prelude::*;
use forced_vi_scenes::models::DrivenDuffing;
use forced_vi_scenes::report::style::{register_font, FAMILY};
use plotters::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or("report/poincare_duffing.svg".into());
    let model = DrivenDuffing::CHAOTIC;
    let period = 2.0 * std::f64::consts::PI / model.omega;
    let periods = 10_000;
    // 100 steps per driving period; the first 100 periods are transient and left out.
    let times: Vec<f64> = (100..=periods).map(|k| k as f64 * period).collect();
    let start = std::time::Instant::now();
    let samples = Integrator::new(&model, Scheme::lobatto(3)?, period / 100.0)?
        .solve(
            InitialState::from_velocity([1.0], [0.0]),
            periods as f64 * period,
            output::Samples(&times),
        )
        .map_err(|f| f.error)?;
    println!(
        "{} section points from {periods} periods in {:.2} s",
        samples.len(),
        start.elapsed().as_secs_f64()
    );
    let path = std::path::Path::new(&out);
    register_font(path.parent().unwrap_or(std::path::Path::new(".")))?;
    let root = SVGBackend::new(path, (640, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Driven Duffing, Poincaré section (δ=0.3, α=−1, β=1, γ=0.5, ω=1.2)",
            (FAMILY, 16),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-2.0f64..2.0, -1.0f64..1.5)?;
    chart
        .configure_mesh()
        .x_desc("x")
        .y_desc("dx/dt")
        .label_style((FAMILY, 12))
        .draw()?;
    chart.draw_series(
        samples
            .iter()
            .map(|s| Circle::new((s.q[0], s.v[0]), 1, RGBColor(31, 119, 180).filled())),
    )?;
    root.present()?;
    println!("wrote {out}");
    Ok(())
}
