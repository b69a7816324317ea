//! One chart: curves of `(x, y)` points on a log y axis, drawn with the shared styles.
//!
//! Figures of every command are made of [`Curve`]s drawn by [`draw_chart`]; the colours,
//! markers, fonts and grid come from [`super::style`].

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::style::{self, Look, Mark, FAMILY, GRID};

/// Curves with more points than this are drawn without markers.
const MAX_MARKED: usize = 80;

/// One series of `(x, y)` points, plus an optional min–max band `(x, lo, hi)`.
pub struct Curve {
    /// How it is drawn.
    pub look: Look,
    /// Its legend label.
    pub label: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// A shaded band.
    pub band: Option<Vec<(f64, f64, f64)>>,
}

/// The axes of a chart.
pub struct Axes<'a, X> {
    /// The caption above the chart.
    pub title: &'a str,
    /// The x-axis label.
    pub x_desc: &'a str,
    /// The y-axis label.
    pub y_desc: &'a str,
    /// The x range (`(a..b).log_scale()` or `a..b`).
    pub x_range: X,
    /// The x tick labels.
    pub x_fmt: &'a dyn Fn(&f64) -> String,
    /// The y range, drawn on a log scale.
    pub y_range: (f64, f64),
}

/// Where the legend goes; `None` draws no legend inside the chart.
pub type Legend = Option<SeriesLabelPosition>;

type Area<'b> = DrawingArea<SVGBackend<'b>, plotters::coord::Shift>;

/// Draws `curves` into `area`.
pub fn draw_chart<X>(
    area: &Area<'_>,
    axes: Axes<'_, X>,
    curves: &[Curve],
    legend: Legend,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let (y0, y1) = axes.y_range;
    let mut chart = ChartBuilder::on(area)
        .caption(axes.title, (FAMILY, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(axes.x_range, (y0..y1).log_scale())
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(axes.x_desc)
        .y_desc(axes.y_desc)
        .x_label_formatter(axes.x_fmt)
        .y_label_formatter(&style::sci)
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .light_line_style(GRID.0)
        .bold_line_style(GRID.1)
        .draw()
        .map_err(|e| e.to_string())?;
    for c in curves {
        let look = c.look;
        if let Some(band) = &c.band {
            let mut poly: Vec<(f64, f64)> = band.iter().map(|&(x, lo, _)| (x, lo)).collect();
            poly.extend(band.iter().rev().map(|&(x, _, hi)| (x, hi)));
            let fill = look.color.mix(0.15).filled();
            chart
                .draw_series(std::iter::once(Polygon::new(poly, fill)))
                .map_err(|e| e.to_string())?;
        }
        let points = c.points.iter().copied();
        let anno = if look.dashed {
            chart.draw_series(DashedLineSeries::new(points, 8, 5, look.line()))
        } else {
            chart.draw_series(LineSeries::new(points, look.line()))
        }
        .map_err(|e| e.to_string())?;
        anno.label(c.label.clone()).legend(move |(x, y)| {
            let line = PathElement::new(vec![(-12, 0), (12, 0)], look.line());
            EmptyElement::at((x + 12, y)) + line + Mark::new((0, 0), look.shape, look.color)
        });
        if look.shape.is_some() && c.points.len() <= MAX_MARKED {
            chart
                .draw_series(
                    c.points
                        .iter()
                        .map(|&p| Mark::new(p, look.shape, look.color)),
                )
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

/// A legend drawn beside a chart, one line per curve, from the top of `area`.
pub fn legend_beside(area: &Area<'_>, curves: &[Curve]) -> Result<(), String> {
    let mut y = 60;
    for c in curves {
        let style = c.look.line();
        let drawn = if c.look.dashed {
            area.draw(&DashedPathElement::new(vec![(10, y), (40, y)], 8, 5, style))
        } else {
            area.draw(&PathElement::new(vec![(10, y), (40, y)], style))
        };
        drawn.map_err(|e| e.to_string())?;
        area.draw(&Text::new(c.label.clone(), (50, y - 8), (FAMILY, 15)))
            .map_err(|e| e.to_string())?;
        y += 28;
    }
    Ok(())
}
