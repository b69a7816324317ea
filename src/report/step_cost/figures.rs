//! The step-cost figure: time per step against n for the FPU chain and the membrane, dense and
//! sparse paths.

use std::path::Path;

use plotters::prelude::*;

use super::rows::Row;
use super::scaling::SCHEMES;
use crate::report::chart::{draw_chart, Axes, Curve};
use crate::report::style::{self, Look, Shape, GREY, PALETTE};

/// Time per step against n, log-log: one curve per scene, scheme and path (dashed: dense),
/// with an n^1.2 reference line from the sparse lobatto3 chain at n = 32.
pub fn plot_scaling(path: &Path, rows: &[Row]) -> Result<bool, String> {
    let mut curves = Vec::new();
    for (k, scene) in ["fpu_chain", "lattice_2d"].into_iter().enumerate() {
        for (j, method) in SCHEMES.into_iter().enumerate() {
            for p in ["sparse", "dense"] {
                let points: Vec<(f64, f64)> = rows
                    .iter()
                    .filter(|r| r.scene == scene && r.method == method && r.path == p)
                    .filter_map(|r| Some((r.n as f64, r.generated? * 1e-3)))
                    .collect();
                if points.is_empty() {
                    continue;
                }
                curves.push(Curve {
                    look: Look {
                        color: PALETTE[2 * k + j],
                        dashed: p == "dense",
                        shape: Some(if k == 0 { Shape::Dot } else { Shape::Triangle }),
                    },
                    label: format!("{scene}, {method}, {p}"),
                    points,
                    band: None,
                });
            }
        }
    }
    let all = curves.iter().flat_map(|c| c.points.iter().copied());
    let (ylo, yhi) = all.fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    if !(ylo.is_finite() && yhi > 0.0) {
        return Ok(false);
    }
    let anchor = rows.iter().find(|r| {
        r.scene == "fpu_chain" && r.method == "lobatto3" && r.path == "sparse" && r.n == 32
    });
    if let Some(t0) = anchor.and_then(|r| r.generated) {
        curves.push(Curve {
            look: Look {
                color: GREY,
                dashed: true,
                shape: None,
            },
            label: "target: n^1.2 from n = 32".into(),
            points: [32.0, 4096.0]
                .iter()
                .map(|&n: &f64| (n, t0 * 1e-3 * (n / 32.0).powf(1.2)))
                .collect(),
            band: None,
        });
    }
    let root = SVGBackend::new(path, (1000, 680)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let axes = Axes {
        title: "time per step against n (h = 0.01; dashed: dense path)",
        x_desc: "degrees of freedom n",
        y_desc: "µs per step (median)",
        x_range: (1.5f64..6000.0).log_scale(),
        x_fmt: &style::sci,
        y_range: (ylo / 3.0, yhi * 3.0),
    };
    draw_chart(&root, axes, &curves, Some(SeriesLabelPosition::UpperLeft))?;
    root.present().map_err(|e| e.to_string())?;
    Ok(true)
}
