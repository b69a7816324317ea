//! Reference solutions produced by `scripts/reference.py` and committed under
//! `data/reference/`, so that tests and reports need no Python.
//!
//! Each file has the header `member,t,q1..qn,v1..vn,p1..pn,energy`; the `t = 0` rows give the
//! initial values of each member.

use std::fmt;

/// One row of a reference file: the state of one member at one time.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferencePoint {
    /// Ensemble member (0 for single-trajectory scenes).
    pub member: usize,
    /// Time.
    pub t: f64,
    /// Positions.
    pub q: Vec<f64>,
    /// Velocities.
    pub v: Vec<f64>,
    /// Momenta.
    pub p: Vec<f64>,
    /// Energy.
    pub energy: f64,
}

/// A malformed reference file.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceError(String);

impl fmt::Display for ReferenceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "bad reference data: {}", self.0)
    }
}

impl std::error::Error for ReferenceError {}

/// A parsed reference file.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// Degrees of freedom.
    pub dim: usize,
    /// All rows, in file order.
    pub points: Vec<ReferencePoint>,
}

impl Reference {
    /// Parses the CSV text of a reference file.
    pub fn parse(text: &str) -> Result<Self, ReferenceError> {
        let mut lines = text
            .lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with('#'));
        let header = lines
            .next()
            .ok_or_else(|| ReferenceError("empty file".into()))?;
        let cols = header.split(',').count();
        if cols < 6 || (cols - 3) % 3 != 0 {
            return Err(ReferenceError(format!("unexpected header `{header}`")));
        }
        let n = (cols - 3) / 3;
        let mut points = Vec::new();
        for (i, line) in lines.enumerate() {
            let vals: Vec<f64> = line
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| ReferenceError(format!("row {}: {e}", i + 1)))?;
            if vals.len() != cols {
                return Err(ReferenceError(format!(
                    "row {} has {} columns",
                    i + 1,
                    vals.len()
                )));
            }
            points.push(ReferencePoint {
                member: vals[0] as usize,
                t: vals[1],
                q: vals[2..2 + n].to_vec(),
                v: vals[2 + n..2 + 2 * n].to_vec(),
                p: vals[2 + 2 * n..2 + 3 * n].to_vec(),
                energy: vals[2 + 3 * n],
            });
        }
        Ok(Reference { dim: n, points })
    }

    /// The row of `member` at time `t` (to within 1e-12), if present.
    pub fn at(&self, member: usize, t: f64) -> Option<&ReferencePoint> {
        self.points
            .iter()
            .find(|p| p.member == member && (p.t - t).abs() <= 1e-12 * t.abs().max(1.0))
    }

    /// The initial row (`t = 0`) of `member`.
    pub fn initial(&self, member: usize) -> Option<&ReferencePoint> {
        self.at(member, 0.0)
    }

    /// The number of members.
    pub fn members(&self) -> usize {
        self.points.iter().map(|p| p.member + 1).max().unwrap_or(0)
    }
}

/// The embedded reference files, by scene name.
pub fn embedded(scene: &str) -> Option<&'static str> {
    Some(match scene {
        "coupled_van_der_pol" => include_str!("../data/reference/coupled_van_der_pol.csv"),
        "coupled_van_der_pol_ensemble" => {
            include_str!("../data/reference/coupled_van_der_pol_ensemble.csv")
        }
        "damped_oscillator" => include_str!("../data/reference/damped_oscillator.csv"),
        "double_pendulum_friction" => {
            include_str!("../data/reference/double_pendulum_friction.csv")
        }
        "kepler_drag" => include_str!("../data/reference/kepler_drag.csv"),
        "overdamped_oscillator" => include_str!("../data/reference/overdamped_oscillator.csv"),
        "stiff_van_der_pol" => include_str!("../data/reference/stiff_van_der_pol.csv"),
        _ => return None,
    })
}
