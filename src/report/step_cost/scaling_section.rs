//! The Markdown of the scaling part of `step-cost` (issue 12): the table of both scenes on
//! both paths, the fitted exponents and the targets.

use std::fmt::Write as _;

use super::rows::Exponent;
use super::rows::{Row, Summary};
use crate::report::table::{col, markdown, met};

fn us(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{:.2}", v * 1e-3))
}

/// The scaling section.
pub fn markdown_section(s: &Summary, plot: Option<&str>) -> String {
    let mut md = String::from("\n### Scaling: large sparse models\n\n");
    md.push_str(
        "`fpu_chain`: n masses between fixed walls, bonds `kΔ²/2 + βΔ⁴/4` (k = 1, β = 1), \
         damping `−cv` (c = 0.01); `lattice_2d`: a W × W membrane (n = W²), each mass bonded \
         to its 4 neighbours by the same springs, fixed rim. Generated: `#[forced_lagrangian]` \
         models (`SpringChain::FPU`, `Membrane<W, N>`), whose Lagrangian the macro splits into \
         local terms, each differentiated over its own few coordinates (DESIGN §9); \
         hand-written: `forced_vi_scenes::large` (sparse kernels by hand). lobatto2 and \
         lobatto3 at h = 0.01, full diagnostics, medians of interleaved repeats, each run of \
         about 0.5 s timed from its first step's record to its last (the one-off setup of a \
         run, which a small model's thousands of steps amortise, is left out: the larger the \
         model, the fewer steps fit in a run). `dense`: N × N node blocks and a dense LU of the \
         (s−1)n unknowns; `sparse`: the node pattern recorded once, the step Jacobian \
         assembled on its pattern (coordinate-major) and factored by faer's sparse LU \
         (symbolic analysis once per run), the factors carried across steps while simplified \
         Newton contracts fast (README, large models).\n\n",
    );
    let scaling_rows = s.rows.iter().filter(|r| r.scene != "coupled_van_der_pol");
    md.push_str(&markdown(
        scaling_rows,
        &[
            col("scene", |r: &Row| r.scene.clone()),
            col("scheme", |r: &Row| r.method.clone()),
            col("path", |r: &Row| r.path.to_string()),
            col("n", |r: &Row| r.n.to_string()),
            col("generated µs/step", |r: &Row| us(r.generated)),
            col("hand-written µs/step", |r: &Row| us(r.handwritten)),
            col("ratio", |r: &Row| {
                r.ratio().map_or("–".into(), |x| format!("{x:.2}"))
            }),
            col("Newton iters/step", |r: &Row| {
                r.iters.map_or("–".into(), |x| format!("{x:.2}"))
            }),
            col("allocs/step", |r: &Row| {
                r.allocs.map_or("–".into(), |x| format!("{x}"))
            }),
            col("note", |r: &Row| r.note.clone()),
        ],
    ));
    exponents(&mut md, &s.exponents);
    targets(&mut md, s);
    if let Some(p) = plot {
        let _ = writeln!(md, "\n![time per step against n]({p})");
    }
    md
}

fn exponents(md: &mut String, exps: &[Exponent]) {
    md.push_str("\nFitted growth of the time per step for n ≥ 32 (least squares on log–log):\n\n");
    for e in exps {
        let sizes: Vec<String> = e.sizes.iter().map(|n| n.to_string()).collect();
        let _ = writeln!(
            *md,
            "- `{}` {} {}: n^{:.2} (n = {})",
            e.scene,
            e.method,
            e.path,
            e.exponent,
            sizes.join(", ")
        );
    }
}

fn find<'a>(s: &'a Summary, scene: &str, method: &str, path: &str, n: usize) -> Option<&'a Row> {
    s.rows
        .iter()
        .find(|r| r.scene == scene && r.method == method && r.path == path && r.n == n)
}

fn targets(md: &mut String, s: &Summary) {
    md.push_str("\n| target (issue 12) | goal | measured | verdict |\n|---|---|---|---|\n");
    for e in s.exponents.iter().filter(|e| e.path == "sparse") {
        let top = e.sizes.last().copied().unwrap_or(0);
        if e.scene == "fpu_chain" {
            let _ = writeln!(
                *md,
                "| fpu_chain {} sparse, n = 32 … {top} | ≤ n^1.2 | n^{:.2} | {} |",
                e.method,
                e.exponent,
                met(e.exponent <= 1.2 && top >= 4096)
            );
        } else {
            let _ = writeln!(
                *md,
                "| lattice_2d {} sparse, n = 32 … {top} | report (a direct factorisation of a 2-D pattern: about n^1.5) | n^{:.2} | reported |",
                e.method, e.exponent
            );
        }
    }
    if let Some(t) = find(s, "fpu_chain", "lobatto3", "sparse", 1024).and_then(|r| r.generated) {
        let ms = t * 1e-6;
        let _ = writeln!(
            *md,
            "| fpu_chain n = 1024, lobatto3 | ≤ 2 ms per step | {ms:.3} ms ({:.1}× the 0.5 ms physical limit) | {} |",
            ms / 0.5,
            met(ms <= 2.0)
        );
    }
    for p in &s.peaks {
        let _ = writeln!(
            *md,
            "| peak RSS, {} {} sparse, n = {} | O(n) | {:.1} MiB (VmHWM reset before the run) | reported |",
            p.scene,
            p.method,
            p.n,
            p.kib as f64 / 1024.0
        );
    }
}
