//! The step-cost figure: time per step against n for the spring chain.

use std::path::Path;

use plotters::prelude::*;

use super::rows::Row;
use crate::report::chart::{draw_chart, Axes, Curve};
use crate::report::style::{self, Look, Shape, GREY, PALETTE};

/// Time per step against n, log-log, with the fitted slope and an n^1.2 reference line.
pub fn plot_scaling(path: &Path, rows: &[Row], exponent: Option<f64>) -> Result<bool, String> {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.scene == "spring_chain")
        .filter_map(|r| Some((r.n as f64, r.generated? * 1e-3)))
        .collect();
    if pts.len() < 2 {
        return Ok(false);
    }
    let (ylo, yhi) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    let label = match exponent {
        Some(e) => format!("generated kernels, dense LU (slope {e:.2} for n ≥ 32)"),
        None => "generated kernels, dense LU".to_string(),
    };
    let mut curves = vec![Curve {
        look: Look {
            color: PALETTE[0],
            dashed: false,
            shape: Some(Shape::Dot),
        },
        label,
        points: pts.clone(),
        band: None,
    }];
    if let Some(&(n0, t0)) = pts.iter().find(|p| p.0 >= 32.0) {
        curves.push(Curve {
            look: Look {
                color: GREY,
                dashed: true,
                shape: None,
            },
            label: "target: n^1.2 from n = 32".into(),
            points: [n0, 2048.0]
                .iter()
                .map(|&n| (n, t0 * (n / n0).powf(1.2)))
                .collect(),
            band: None,
        });
    }
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let axes = Axes {
        title: "spring_chain (lobatto2, h = 0.01): time per step against n",
        x_desc: "degrees of freedom n",
        y_desc: "µs per step (median)",
        x_range: (1.5f64..3000.0).log_scale(),
        x_fmt: &style::sci,
        y_range: (ylo / 3.0, yhi * 3.0),
    };
    draw_chart(&root, axes, &curves, Some(SeriesLabelPosition::UpperLeft))?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}
