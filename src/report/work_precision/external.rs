//! External baselines: runs measured outside the report and committed as CSV.
//!
//! `data/baselines/heyoka.csv` holds heyoka (an adaptive Taylor integrator, JIT-compiled by
//! LLVM) on the non-stiff scenes. `scripts/heyoka_baseline.py` writes it, on the machine
//! named in its first line, when the file is committed; the report embeds it with
//! `include_str!`, as it does the references, so it never runs Python. Its times come from
//! another process at another time, so the report labels them external and keeps them out of
//! its bold "cheapest method" marks (see `data/baselines/README.md`).

use serde::Deserialize;

/// The committed heyoka timings.
pub const HEYOKA_CSV: &str = include_str!("../../../data/baselines/heyoka.csv");

/// The file's path in the workspace, for messages and the report text.
pub const HEYOKA_PATH: &str = "data/baselines/heyoka.csv";

/// The label of the heyoka series in tables and plots.
pub const HEYOKA_LABEL: &str = "heyoka (external, measured at commit time, JIT excluded)";

/// One heyoka run: a scene (member 0) at one tolerance.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct ExternalRow {
    /// The report scene.
    pub scene: String,
    /// The ensemble member (always 0).
    pub member: usize,
    /// heyoka's tolerance.
    pub tol: f64,
    /// The Taylor order heyoka chose.
    pub order: usize,
    /// Steps to the final time.
    pub steps: usize,
    /// Max-norm error in q at the final time (the report's `err_q`).
    pub error: f64,
    /// Max-norm error in p.
    pub err_p: f64,
    /// Absolute energy error.
    pub err_energy: f64,
    /// Median wall time of the propagation, JIT excluded, seconds.
    pub run_seconds: f64,
    /// The time to build (JIT-compile) the integrator, seconds.
    pub jit_seconds: f64,
    /// The cost of the Python call alone (included in `run_seconds`), seconds.
    pub overhead_seconds: f64,
    /// Timed repeats.
    pub repeats: usize,
    /// The heyoka version.
    pub heyoka_version: String,
}

/// The embedded heyoka file: its provenance line (the first `#` comment) and its rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct External {
    /// Where and when the file was measured.
    pub provenance: String,
    /// Every row, in file order.
    pub rows: Vec<ExternalRow>,
}

impl External {
    /// Parses the text of a baseline file (`#` lines are comments).
    pub fn parse(text: &str) -> Result<External, String> {
        let provenance = text
            .lines()
            .find_map(|l| l.strip_prefix('#'))
            .map_or(String::new(), |l| l.trim().to_string());
        let mut reader = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let rows = reader
            .deserialize()
            .collect::<Result<Vec<ExternalRow>, _>>()
            .map_err(|e| format!("{HEYOKA_PATH}: {e}"))?;
        let bad = rows.iter().find(|r| {
            let values = [r.tol, r.error, r.run_seconds, r.jit_seconds];
            !values.iter().all(|x| x.is_finite() && *x >= 0.0)
        });
        match bad {
            Some(r) => Err(format!(
                "{HEYOKA_PATH}: a row of `{}` at tol {:e} has a negative or non-finite value",
                r.scene, r.tol
            )),
            None => Ok(External { provenance, rows }),
        }
    }

    /// The committed heyoka file.
    pub fn heyoka() -> Result<External, String> {
        External::parse(HEYOKA_CSV)
    }

    /// The rows of `scenes` only.
    pub fn of_scenes(self, scenes: &[&str]) -> External {
        External {
            rows: self
                .rows
                .into_iter()
                .filter(|r| scenes.contains(&r.scene.as_str()))
                .collect(),
            ..self
        }
    }

    /// The heyoka version(s) in the file, comma-separated.
    pub fn versions(&self) -> String {
        let mut v: Vec<&str> = self
            .rows
            .iter()
            .map(|r| r.heyoka_version.as_str())
            .collect();
        v.sort_unstable();
        v.dedup();
        v.join(", ")
    }
}

impl External {
    /// The rows of `scene`, loosest tolerance first (the order of a sweep).
    pub fn rows_of(&self, scene: &str) -> Vec<&ExternalRow> {
        let mut rows: Vec<&ExternalRow> = self.rows.iter().filter(|r| r.scene == scene).collect();
        rows.sort_by(|a, b| b.tol.total_cmp(&a.tol));
        rows
    }

    /// The fastest run on `scene` whose error in q is at most `target`.
    pub fn cheapest(&self, scene: &str, target: f64) -> Option<&ExternalRow> {
        self.rows_of(scene)
            .into_iter()
            .filter(|r| r.error <= target)
            .min_by(|a, b| a.run_seconds.total_cmp(&b.run_seconds))
    }
}
