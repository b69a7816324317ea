//! The work-precision figures: error against h, error against run time, and the long run's
//! energy balance. Each is a function from the summary's rows to an SVG file.

use std::path::Path;

use plotters::prelude::*;

use super::external::HEYOKA_LABEL;
use super::rows::{LongRun, Mode, Summary};
use crate::report::chart::{draw_chart, legend_beside, Axes, Curve};
use crate::report::style::{self, log_range, plot_err, Look, FAMILY};
use crate::report::{Method, ReportError};
use crate::scenes::Scene;

/// Energy-balance errors below this (zero to round-off) are drawn at this value.
pub const BALANCE_FLOOR: f64 = 1e-16;

/// The file names of the plots that were written, relative to the report folder.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Figures {
    /// `(scene, file)` of the error-against-h plots.
    pub error_vs_h: Vec<(String, String)>,
    /// `(scene, file)` of the error-against-run-time plots.
    pub work_precision: Vec<(String, String)>,
    /// The energy-balance plot.
    pub energy_balance: Option<String>,
}

/// The curves of error `k` (q, p, energy) against h, one per variational method.
fn error_curves(scene: &dyn Scene, summary: &Summary, k: usize) -> Vec<Curve> {
    let ensemble = scene.members() > 1;
    let variational = summary.methods.iter().filter(|m| m.is_variational());
    variational
        .filter_map(|m| {
            let rows = summary.rows_of(scene.name(), m);
            let points: Vec<(f64, f64)> = rows
                .iter()
                .map(|r| (r.h_or_tol, r.err[k].mean))
                .filter(|p| p.1 > 0.0)
                .collect();
            let order = summary
                .orders
                .iter()
                .find(|o| o.scene == scene.name() && &o.method == m)
                .and_then(|o| o.observed[k].as_ref())
                .map_or(String::new(), |f| format!(", slope {:.2}", f.order));
            let band = ensemble.then(|| {
                rows.iter()
                    .filter(|r| r.err[k].min > 0.0)
                    .map(|r| (r.h_or_tol, r.err[k].min, r.err[k].max))
                    .collect()
            });
            (!points.is_empty()).then(|| Curve {
                look: Look::of(m, &summary.methods),
                label: format!("{m}{order}"),
                points,
                band,
            })
        })
        .collect()
}

/// Error in q, p and energy against h for the variational schemes of one scene.
fn error_vs_h(path: &Path, scene: &dyn Scene, summary: &Summary) -> Result<bool, String> {
    let names = ["q", "p", "energy"];
    let panels: Vec<Vec<Curve>> = (0..3).map(|k| error_curves(scene, summary, k)).collect();
    let all_x = panels
        .iter()
        .flatten()
        .flat_map(|c| c.points.iter().map(|p| p.0));
    let Some(xr) = log_range(all_x) else {
        return Ok(false);
    };
    let root = SVGBackend::new(path, (1500, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let band_note = if scene.members() > 1 {
        " (mean over members; band: min–max)"
    } else {
        ""
    };
    let title = format!(
        "{}: error at t = {} against step size{band_note}",
        scene.name(),
        scene.t_final()
    );
    let root = root
        .titled(&title, (FAMILY, 22))
        .map_err(|e| e.to_string())?;
    let areas = root.split_evenly((1, 3));
    for (k, (area, curves)) in areas.iter().zip(&panels).enumerate() {
        let ys = curves.iter().flat_map(|c| {
            let band = c.band.iter().flatten().flat_map(|b| [b.1, b.2]);
            c.points.iter().map(|p| p.1).chain(band)
        });
        let Some(y_range) = log_range(ys) else {
            continue;
        };
        let axes = Axes {
            title: &format!("error in {}", names[k]),
            x_desc: "step size h",
            y_desc: &format!("max-norm error in {}", names[k]),
            x_range: (xr.0..xr.1).log_scale(),
            x_fmt: &style::sci,
            y_range,
        };
        draw_chart(area, axes, curves, Some(SeriesLabelPosition::UpperLeft))?;
    }
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// The external baseline's curve on `scene`, if it was measured there: error in q against its
/// run time (JIT excluded), loosest tolerance first. None on an ensemble, where it ran member
/// 0 alone and the plot's times are those of the whole ensemble.
fn external_curve(scene: &dyn Scene, summary: &Summary) -> Option<Curve> {
    if scene.members() > 1 {
        return None;
    }
    let points: Vec<(f64, f64)> = summary
        .external
        .rows_of(scene.name())
        .iter()
        .map(|r| (r.run_seconds, r.error))
        .filter(|p| p.0 > 0.0 && p.1 > 0.0)
        .collect();
    (!points.is_empty()).then(|| Curve {
        look: Look::external(),
        label: HEYOKA_LABEL.to_string(),
        points,
        band: None,
    })
}

/// Error in q against wall time, all methods (fixed-step and adaptive), one scene, and the
/// external baseline as a series of its own.
fn work_precision(path: &Path, scene: &dyn Scene, summary: &Summary) -> Result<bool, String> {
    let mut curves: Vec<Curve> = summary
        .series()
        .iter()
        .filter_map(|(m, mode)| {
            // In sweep order (decreasing h or tolerance), so that timing noise shows as a
            // kink rather than reordering the line.
            let points: Vec<(f64, f64)> = summary
                .rows_in(scene.name(), m, *mode)
                .iter()
                .rev()
                .map(|r| (r.seconds, r.errors()[0]))
                .filter(|p| p.0 > 0.0 && p.1 > 0.0)
                .collect();
            let look = match mode {
                Mode::Fixed => Look::of(m, &summary.methods),
                Mode::Adaptive => Look::adaptive(m, &summary.methods),
            };
            (!points.is_empty()).then(|| Curve {
                look,
                label: mode.label(m),
                points,
                band: None,
            })
        })
        .collect();
    curves.extend(external_curve(scene, summary));
    let (Some(xr), Some(y_range)) = (
        log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0))),
        log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1))),
    ) else {
        return Ok(false);
    };
    let root = SVGBackend::new(path, (900, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let whole = if scene.members() > 1 {
        " (whole ensemble)"
    } else {
        ""
    };
    let axes = Axes {
        title: &format!("{}: error against run time{whole}", scene.name()),
        x_desc: "wall time per run [s] (median of repeats)",
        y_desc: "max-norm error in q at the final time",
        x_range: (xr.0..xr.1).log_scale(),
        x_fmt: &style::sci,
        y_range,
    };
    draw_chart(&root, axes, &curves, Some(SeriesLabelPosition::UpperRight))?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// |energy-balance error| against time for the long run.
fn energy_balance(path: &Path, lr: &LongRun, methods: &[Method]) -> Result<bool, String> {
    let curves: Vec<Curve> = lr
        .curves
        .iter()
        .map(|c| {
            let samples = c.series.t.iter().zip(&c.series.balance);
            let points = samples
                .filter(|(t, _)| **t > 0.0)
                .map(|(t, b)| (*t, b.abs().max(BALANCE_FLOOR)))
                .collect();
            let param = if c.method.is_variational() && c.mode == Mode::Fixed {
                format!("h = {:.3}", c.h_or_tol)
            } else {
                format!("tol = {:.0e}", c.h_or_tol)
            };
            let look = match c.mode {
                Mode::Fixed => Look::of(&c.method, methods),
                Mode::Adaptive => Look::adaptive(&c.method, methods),
            };
            Curve {
                look,
                label: format!("{} ({param}, {:.2} s)", c.mode.label(&c.method), c.seconds),
                points,
                band: None,
            }
        })
        .collect();
    let Some(yr) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1))) else {
        return Ok(false);
    };
    let root = SVGBackend::new(path, (1100, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (chart_area, legend_area) = root.split_horizontally(800);
    let axes = Axes {
        title: &format!("{}: energy-balance error at equal cost", lr.scene),
        x_desc: "time t",
        y_desc: "|E(t) − E(0) − W(t)|",
        x_range: 0.0..lr.t_final,
        x_fmt: &|t: &f64| format!("{t:.0}"),
        y_range: (BALANCE_FLOOR / 2.0, yr.1 * 10.0),
    };
    draw_chart(&chart_area, axes, &curves, None)?;
    // The legend sits beside the chart: the curves fill the plot area.
    legend_beside(&legend_area, &curves)?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// Draws every plot into `out` and returns the file names.
pub fn draw_all(
    out: &Path,
    scenes: &[&dyn Scene],
    summary: &Summary,
) -> Result<Figures, ReportError> {
    style::register_font(out)?;
    let mut figures = Figures::default();
    for scene in scenes {
        let file = format!("error_vs_h_{}.svg", scene.name());
        let path = out.join(&file);
        if error_vs_h(&path, *scene, summary).map_err(plot_err(&path))? {
            figures.error_vs_h.push((scene.name().to_string(), file));
        }
        let file = format!("work_precision_{}.svg", scene.name());
        let path = out.join(&file);
        if work_precision(&path, *scene, summary).map_err(plot_err(&path))? {
            let entry = (scene.name().to_string(), file);
            figures.work_precision.push(entry);
        }
    }
    if let Some(lr) = &summary.long_run {
        let file = "energy_balance.svg".to_string();
        let path = out.join(&file);
        if energy_balance(&path, lr, &summary.methods).map_err(plot_err(&path))? {
            figures.energy_balance = Some(file);
        }
    }
    Ok(figures)
}
