//! Plot styles, in one place: the bundled font, one colour and marker per method, axis labels.
//!
//! plotters runs with its default features off: the SVG backend and `ab_glyph` for text
//! metrics, fed with the bundled DejaVu Sans (`assets/DejaVuSans.ttf`, licence beside it), so no
//! system font library is needed. Each method keeps one colour and marker in every plot;
//! variational schemes are solid lines with filled circles (dashed for their adaptive runs),
//! baselines dashed lines with other markers, and the external baseline (heyoka, measured
//! outside the report) a black dashed line with hollow squares.

use std::path::Path;
use std::sync::OnceLock;

use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use plotters_backend::DrawingErrorKind;

use super::{Method, ReportError};
use crate::baselines::Baseline;

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// The font family every text uses (the bundled font).
pub const FAMILY: &str = "sans-serif";

/// Grid lines of every chart: light and bold.
pub const GRID: (RGBColor, RGBColor) = (RGBColor(235, 235, 235), RGBColor(200, 200, 200));

/// Grey for reference lines that are not a method.
pub const GREY: RGBColor = RGBColor(120, 120, 120);

/// Registers the bundled font once; `out` names the report folder in the error.
pub fn register_font(out: &Path) -> Result<(), ReportError> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
            .map_err(|_| "the bundled font is not a valid TrueType file".to_string())
    })
    .clone()
    .map_err(plot_err(&out.join("(font)")))
}

/// Turns a drawing error message into a [`ReportError::Plot`] for `path`.
pub fn plot_err(path: &Path) -> impl Fn(String) -> ReportError + '_ {
    move |message| ReportError::Plot {
        path: path.to_path_buf(),
        message,
    }
}

/// Tableau-10 colours, assigned to methods in default report order.
pub const PALETTE: [RGBColor; 10] = [
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

/// The marker shape of a curve's points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// A filled circle (variational schemes).
    Dot,
    /// A filled triangle.
    Triangle,
    /// A triangle outline.
    HollowTriangle,
    /// A diagonal cross.
    Cross,
    /// A circle outline.
    Ring,
    /// A square outline (the external baseline).
    HollowSquare,
}

/// How a curve is drawn: colour, solid or dashed, and its marker (none: a plain line).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Look {
    /// Line and marker colour.
    pub color: RGBColor,
    /// A dashed line.
    pub dashed: bool,
    /// The marker at each point, if any.
    pub shape: Option<Shape>,
}

impl Look {
    /// The look of `method`: its colour by position in [`Method::defaults`] (then in `methods`).
    pub fn of(method: &Method, methods: &[Method]) -> Look {
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
        let shape = match method {
            Method::Variational(_) => Shape::Dot,
            Method::Baseline(Baseline::Dop853) => Shape::Triangle,
            Method::Baseline(Baseline::Tsit45) => Shape::Cross,
            Method::Baseline(Baseline::Bdf) => Shape::Ring,
            Method::Baseline(Baseline::Esdirk34) => Shape::HollowTriangle,
        };
        Look {
            color: PALETTE[idx % PALETTE.len()],
            dashed: !method.is_variational(),
            shape: Some(shape),
        }
    }

    /// The look of `method`'s adaptive (tolerance-driven) runs: its colour and marker,
    /// dashed.
    pub fn adaptive(method: &Method, methods: &[Method]) -> Look {
        Look {
            dashed: true,
            ..Look::of(method, methods)
        }
    }

    /// The look of an external baseline, measured outside the report (heyoka): black,
    /// dashed, hollow squares, unlike every method of the report.
    pub fn external() -> Look {
        Look {
            color: BLACK,
            dashed: true,
            shape: Some(Shape::HollowSquare),
        }
    }

    /// The line style.
    pub fn line(&self) -> ShapeStyle {
        ShapeStyle::from(self.color).stroke_width(2)
    }
}

/// A marker drawn with backend primitives at one point (nothing for no shape).
pub struct Mark<C> {
    at: C,
    shape: Option<Shape>,
    color: RGBColor,
}

impl<C> Mark<C> {
    /// A marker of `shape` at `at`.
    pub fn new(at: C, shape: Option<Shape>, color: RGBColor) -> Self {
        Mark { at, shape, color }
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
        let (Some((x, y)), Some(shape)) = (points.next(), self.shape) else {
            return Ok(());
        };
        let solid = ShapeStyle::from(self.color).filled();
        let line = ShapeStyle::from(self.color).stroke_width(2);
        let tri = vec![(x, y - 6), (x - 6, y + 4), (x + 6, y + 4)];
        match shape {
            Shape::Dot => backend.draw_circle((x, y), 4, &solid, true),
            Shape::Ring => backend.draw_circle((x, y), 5, &line, false),
            Shape::Triangle => backend.fill_polygon(tri, &solid),
            Shape::HollowTriangle => {
                let mut path = tri.clone();
                path.push(tri[0]);
                backend.draw_path(path, &line)
            }
            Shape::HollowSquare => {
                let corners = [
                    (x - 5, y - 5),
                    (x + 5, y - 5),
                    (x + 5, y + 5),
                    (x - 5, y + 5),
                ];
                let mut path = corners.to_vec();
                path.push(corners[0]);
                backend.draw_path(path, &line)
            }
            Shape::Cross => {
                backend.draw_line((x - 5, y - 5), (x + 5, y + 5), &line)?;
                backend.draw_line((x - 5, y + 5), (x + 5, y - 5), &line)
            }
        }
    }
}

/// A log-scale range covering `values` (positive ones), padded by a factor of 2.
pub fn log_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    (hi > 0.0).then(|| (lo / 2.0, hi * 2.0))
}

/// A log-axis tick label: `1`, `1e-3`, or `5e-3` between decades.
pub fn sci(x: &f64) -> String {
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
