//! SVG plots of the report, drawn with plotters.
//!
//! plotters runs with its default features off: the SVG backend and `ab_glyph` for text
//! metrics, fed with the bundled DejaVu Sans (`assets/DejaVuSans.ttf`, licence beside it), so no
//! system font library is needed. Each method keeps one colour and marker in every plot;
//! variational schemes are solid lines with filled circles, baselines dashed lines with
//! other markers.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::element::{DashedPathElement, Drawable, PointCollection};
use plotters::prelude::*;
use plotters_backend::DrawingErrorKind;

use super::work_precision::{LongRun, Row, Summary};
use super::{Method, ReportError};
use crate::baselines::Baseline;
use crate::scenes::Scene;

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

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

fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
            .map_err(|_| "the bundled font is not a valid TrueType file".to_string())
    })
    .clone()
}

/// Tableau-10 colours, assigned to methods in default report order.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

fn color_of(method: &Method, methods: &[Method]) -> RGBColor {
    let defaults = Method::defaults();
    let idx = defaults
        .iter()
        .position(|m| m == method)
        .or_else(|| {
            methods
                .iter()
                .position(|m| m == method)
                .map(|i| defaults.len() + i)
        })
        .unwrap_or(0);
    PALETTE[idx % PALETTE.len()]
}

/// The marker shape of a method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shape {
    Dot,
    Triangle,
    HollowTriangle,
    Cross,
    Ring,
}

fn shape_of(method: &Method) -> Shape {
    match method {
        Method::Variational(_) => Shape::Dot,
        Method::Baseline(Baseline::Dop853) => Shape::Triangle,
        Method::Baseline(Baseline::Tsit45) => Shape::Cross,
        Method::Baseline(Baseline::Bdf) => Shape::Ring,
        Method::Baseline(Baseline::Esdirk34) => Shape::HollowTriangle,
    }
}

/// A marker drawn with backend primitives at one point.
struct Mark<C> {
    at: C,
    shape: Shape,
    color: RGBColor,
}

impl<C> Mark<C> {
    fn new(at: C, method: &Method, color: RGBColor) -> Self {
        Mark {
            at,
            shape: shape_of(method),
            color,
        }
    }
}

impl<'a, C> PointCollection<'a, C> for &'a Mark<C> {
    type Point = &'a C;
    type IntoIter = std::iter::Once<&'a C>;
    fn point_iter(self) -> Self::IntoIter {
        std::iter::once(&self.at)
    }
}

impl<C, DB: DrawingBackend> Drawable<DB> for Mark<C> {
    fn draw<I: Iterator<Item = (i32, i32)>>(
        &self,
        mut points: I,
        backend: &mut DB,
        _: (u32, u32),
    ) -> Result<(), DrawingErrorKind<DB::ErrorType>> {
        let Some((x, y)) = points.next() else {
            return Ok(());
        };
        let solid = ShapeStyle::from(self.color).filled();
        let line = ShapeStyle::from(self.color).stroke_width(2);
        let tri = vec![(x, y - 6), (x - 6, y + 4), (x + 6, y + 4)];
        match self.shape {
            Shape::Dot => backend.draw_circle((x, y), 4, &solid, true),
            Shape::Ring => backend.draw_circle((x, y), 5, &line, false),
            Shape::Triangle => backend.fill_polygon(tri, &solid),
            Shape::HollowTriangle => {
                let mut path = tri.clone();
                path.push(tri[0]);
                backend.draw_path(path, &line)
            }
            Shape::Cross => {
                backend.draw_line((x - 5, y - 5), (x + 5, y + 5), &line)?;
                backend.draw_line((x - 5, y + 5), (x + 5, y - 5), &line)
            }
        }
    }
}

fn plot_err(path: &Path) -> impl Fn(String) -> ReportError + '_ {
    move |message| ReportError::Plot {
        path: path.to_path_buf(),
        message,
    }
}

/// A log-scale range covering `values` (positive ones), padded by a factor of 2.
fn log_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    (hi > 0.0).then(|| (lo / 2.0, hi * 2.0))
}

fn sci(x: &f64) -> String {
    let e = x.log10().round();
    if (x / 10f64.powf(e) - 1.0).abs() < 1e-6 {
        match e as i32 {
            0 => "1".to_string(),
            e => format!("1e{e}"),
        }
    } else {
        format!("{x:.0e}")
    }
}

/// One series of `(x, y)` points of a method, plus an optional min–max band.
struct Curve {
    method: Method,
    label: String,
    points: Vec<(f64, f64)>,
    band: Option<Vec<(f64, f64, f64)>>,
}

/// Draws curves into one log-log (or lin-log) chart.
#[allow(clippy::too_many_arguments)]
fn draw_chart<X>(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    x_range: X,
    x_fmt: &dyn Fn(&f64) -> String,
    y_range: (f64, f64),
    curves: &[Curve],
    methods: &[Method],
    legend: Option<SeriesLabelPosition>,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x_range, (y_range.0..y_range.1).log_scale())
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(x_fmt)
        .y_label_formatter(&sci)
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(|e| e.to_string())?;
    for c in curves {
        let color = color_of(&c.method, methods);
        if let Some(band) = &c.band {
            let mut poly: Vec<(f64, f64)> = band.iter().map(|&(x, lo, _)| (x, lo)).collect();
            poly.extend(band.iter().rev().map(|&(x, _, hi)| (x, hi)));
            chart
                .draw_series(std::iter::once(Polygon::new(
                    poly,
                    color.mix(0.15).filled(),
                )))
                .map_err(|e| e.to_string())?;
        }
        let style = ShapeStyle::from(color).stroke_width(2);
        let anno = if c.method.is_variational() {
            chart
                .draw_series(LineSeries::new(c.points.iter().copied(), style))
                .map_err(|e| e.to_string())?
        } else {
            chart
                .draw_series(DashedLineSeries::new(c.points.iter().copied(), 8, 5, style))
                .map_err(|e| e.to_string())?
        };
        let method = c.method;
        anno.label(c.label.clone()).legend(move |(x, y)| {
            EmptyElement::at((x + 12, y))
                + PathElement::new(vec![(-12, 0), (12, 0)], style)
                + Mark::new((0, 0), &method, color)
        });
        if c.points.len() <= 80 {
            chart
                .draw_series(c.points.iter().map(|&p| Mark::new(p, &c.method, color)))
                .map_err(|e| e.to_string())?;
        }
    }
    if let Some(pos) = legend {
        chart
            .configure_series_labels()
            .position(pos)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .label_font((FAMILY, 14))
            .margin(8)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn rows_of<'a>(summary: &'a Summary, scene: &str, method: &Method) -> Vec<&'a Row> {
    let mut rows: Vec<&Row> = summary
        .rows
        .iter()
        .filter(|r| r.scene == scene && &r.method == method)
        .collect();
    rows.sort_by(|a, b| a.h_or_tol.total_cmp(&b.h_or_tol));
    rows
}

/// Error in q, p and energy against h for the variational schemes of one scene.
fn error_vs_h(path: &Path, scene: &dyn Scene, summary: &Summary) -> Result<bool, String> {
    let methods: Vec<Method> = summary
        .methods
        .iter()
        .copied()
        .filter(Method::is_variational)
        .collect();
    let ensemble = scene.members() > 1;
    let names = ["q", "p", "energy"];
    let mut panels = Vec::new();
    for k in 0..names.len() {
        let curves: Vec<Curve> = methods
            .iter()
            .filter_map(|m| {
                let rows = rows_of(summary, scene.name(), m);
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
                    method: *m,
                    label: format!("{m}{order}"),
                    points,
                    band,
                })
            })
            .collect();
        panels.push(curves);
    }
    let all_x = panels
        .iter()
        .flatten()
        .flat_map(|c| c.points.iter().map(|p| p.0));
    let Some(xr) = log_range(all_x) else {
        return Ok(false);
    };
    let root = SVGBackend::new(path, (1500, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let title = format!(
        "{}: error at t = {} against step size{}",
        scene.name(),
        scene.t_final(),
        if ensemble {
            " (mean over members; band: min–max)"
        } else {
            ""
        }
    );
    let root = root
        .titled(&title, (FAMILY, 22))
        .map_err(|e| e.to_string())?;
    let areas = root.split_evenly((1, 3));
    for (k, (area, curves)) in areas.iter().zip(&panels).enumerate() {
        let ys = curves.iter().flat_map(|c| {
            c.points.iter().map(|p| p.1).chain(
                c.band
                    .iter()
                    .flatten()
                    .flat_map(|b| [b.1, b.2])
                    .collect::<Vec<_>>(),
            )
        });
        let Some(yr) = log_range(ys) else { continue };
        draw_chart(
            area,
            &format!("error in {}", names[k]),
            "step size h",
            &format!("max-norm error in {}", names[k]),
            (xr.0..xr.1).log_scale(),
            &sci,
            yr,
            curves,
            &summary.methods,
            Some(SeriesLabelPosition::UpperLeft),
        )?;
    }
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// Error in q against wall time, all methods, one scene.
fn work_precision(path: &Path, scene: &dyn Scene, summary: &Summary) -> Result<bool, String> {
    let curves: Vec<Curve> = summary
        .methods
        .iter()
        .filter_map(|m| {
            // In sweep order (decreasing h or tolerance), so that timing noise shows as a
            // kink rather than reordering the line.
            let points: Vec<(f64, f64)> = rows_of(summary, scene.name(), m)
                .iter()
                .rev()
                .map(|r| (r.seconds, r.errors()[0]))
                .filter(|p| p.0 > 0.0 && p.1 > 0.0)
                .collect();
            (!points.is_empty()).then(|| Curve {
                method: *m,
                label: m.to_string(),
                points,
                band: None,
            })
        })
        .collect();
    let (Some(xr), Some(yr)) = (
        log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0))),
        log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1))),
    ) else {
        return Ok(false);
    };
    let root = SVGBackend::new(path, (900, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    draw_chart(
        &root,
        &format!(
            "{}: error against run time{}",
            scene.name(),
            if scene.members() > 1 {
                " (whole ensemble)"
            } else {
                ""
            }
        ),
        "wall time per run [s] (median of repeats)",
        "max-norm error in q at the final time",
        (xr.0..xr.1).log_scale(),
        &sci,
        yr,
        &curves,
        &summary.methods,
        Some(SeriesLabelPosition::UpperRight),
    )?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// |energy-balance error| against time for the long run.
fn energy_balance(path: &Path, lr: &LongRun, methods: &[Method]) -> Result<bool, String> {
    let curves: Vec<Curve> = lr
        .curves
        .iter()
        .map(|c| {
            let points = c
                .series
                .t
                .iter()
                .zip(&c.series.balance)
                .filter(|(t, _)| **t > 0.0)
                .map(|(t, b)| (*t, b.abs().max(BALANCE_FLOOR)))
                .collect();
            let param = if c.method.is_variational() {
                format!("h = {:.3}", c.h_or_tol)
            } else {
                format!("tol = {:.0e}", c.h_or_tol)
            };
            Curve {
                method: c.method,
                label: format!("{} ({param}, {:.2} s)", c.method, c.seconds),
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
    draw_chart(
        &chart_area,
        &format!("{}: energy-balance error at equal cost", lr.scene),
        "time t",
        "|E(t) − E(0) − W(t)|",
        0.0..lr.t_final,
        &|t: &f64| format!("{t:.0}"),
        (BALANCE_FLOOR / 2.0, yr.1 * 10.0),
        &curves,
        methods,
        None,
    )?;
    // The legend sits beside the chart: the curves fill the plot area.
    let mut y = 60;
    for c in &curves {
        let color = color_of(&c.method, methods);
        let style = ShapeStyle::from(color).stroke_width(2);
        let drawn = if c.method.is_variational() {
            legend_area.draw(&PathElement::new(vec![(10, y), (40, y)], style))
        } else {
            legend_area.draw(&DashedPathElement::new(vec![(10, y), (40, y)], 8, 5, style))
        };
        drawn.map_err(|e| e.to_string())?;
        legend_area
            .draw(&Text::new(c.label.clone(), (50, y - 8), (FAMILY, 15)))
            .map_err(|e| e.to_string())?;
        y += 28;
    }
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}

/// Draws every plot into `out` and returns the file names.
pub fn draw_all(
    out: &Path,
    scenes: &[&dyn Scene],
    summary: &Summary,
) -> Result<Figures, ReportError> {
    let font_path = out.join("(font)");
    register_font().map_err(plot_err(&font_path))?;
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
            figures
                .work_precision
                .push((scene.name().to_string(), file));
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
