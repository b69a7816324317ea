//! Scheme names: [`SchemeId`], shown and parsed as `midpoint`, `trapezoid`, `alpha(<value>)`
//! and `lobatto<s>`.

use std::fmt;
use std::str::FromStr;

use super::check_stages;
use crate::error::SchemeError;

/// The name of a scheme, as used on the command line and in reports.
///
/// Ids: `midpoint`, `trapezoid`, `alpha(<value>)`, `lobatto<s>` for `s ≥ 2`.
///
/// ```
/// use forced_vi::SchemeId;
/// let id: SchemeId = "alpha(0.25)".parse().unwrap();
/// assert_eq!(id, SchemeId::Alpha(0.25));
/// assert_eq!("lobatto3".parse::<SchemeId>().unwrap().to_string(), "lobatto3");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum SchemeId {
    /// `L_d = h L((q₀ + q₁)/2, (q₁ − q₀)/h)`: order 2.
    Midpoint,
    /// Linear path, trapezoidal quadrature: order 2.
    Trapezoid,
    /// `L_d = h L((1 − α)q₀ + αq₁, (q₁ − q₀)/h)`: order 2 at `α = ½`, else 1.
    Alpha(f64),
    /// Galerkin with `s` Lobatto control points and Lobatto quadrature: order `2s − 2`.
    Lobatto(usize),
}

impl fmt::Display for SchemeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SchemeId::Midpoint => write!(f, "midpoint"),
            SchemeId::Trapezoid => write!(f, "trapezoid"),
            SchemeId::Alpha(a) => write!(f, "alpha({a})"),
            SchemeId::Lobatto(s) => write!(f, "lobatto{s}"),
        }
    }
}

impl FromStr for SchemeId {
    type Err = SchemeError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let t = text.trim();
        let unknown = || SchemeError::Unknown(t.to_string());
        match t {
            "midpoint" => return Ok(SchemeId::Midpoint),
            "trapezoid" => return Ok(SchemeId::Trapezoid),
            _ => {}
        }
        if let Some(rest) = t.strip_prefix("lobatto") {
            // Plain decimal digits only: no sign, no leading zero, no whitespace.
            if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) || rest.starts_with('0')
            {
                return Err(unknown());
            }
            let s: usize = rest.parse().unwrap_or(usize::MAX);
            return check_stages(s).map(SchemeId::Lobatto);
        }
        if let Some(inner) = t.strip_prefix("alpha(").and_then(|r| r.strip_suffix(')')) {
            let a: f64 = inner.trim().parse().map_err(|_| unknown())?;
            return if a.is_finite() && (0.0..=1.0).contains(&a) {
                Ok(SchemeId::Alpha(a))
            } else {
                Err(SchemeError::AlphaOutOfRange(a))
            };
        }
        Err(unknown())
    }
}
