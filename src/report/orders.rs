//! Observed orders of convergence: slopes of `log err` against `log h`.
//!
//! # The rule
//!
//! The observed order of a method on a scene is the least-squares slope of `log err` against
//! `log h` over the asymptotic range of its sweep, which sits just above the round-off floor:
//!
//! 1. **Candidates.** Points with `FLOOR · s ≤ err ≤ CEILING · s` are kept, where
//!    `s = max(1, |x|∞)` is the size of the reference value (the positions `q`, the momenta `p`
//!    or the energy). Below [`FLOOR`] `= 10⁻¹³` round-off bends the curve (the schemes' floors
//!    measure 10⁻¹⁶–10⁻¹⁵ `s`); above [`CEILING`] `= 10⁻³` the leading error term need not
//!    dominate.
//!    Before that, a point counts only while the curve still falls below it: every point at a
//!    smaller `h` has an error at most [`FALL`] `= 1/1.5` of it. A sweep that reaches its
//!    round-off floor scatters there (a chaotic scene amplifies round-off to 10⁻¹³ and
//!    more, above [`FLOOR`]); the first point of the scatter, and every smaller `h`, drop
//!    out. (Eight steps per decade shrink an order-2 error by 1.78 per point.) The rule
//!    looks only at errors within [`FLOOR_BAND`] `= 10³` of the sweep's smallest, where a
//!    floor can be, and only at points whose every smaller `h` is within that band too (the
//!    floor is the tail of the sweep); a bump at larger `h` is pre-asymptotic and left to
//!    step 3. Where such a tail drops out, the points above it count only from
//!    [`FLOOR_MARGIN`] `= 10` times its median error up: the scatter measures the floor's
//!    noise, which is added to every error near it, and its median is not moved by a
//!    pre-asymptotic wiggle that falls into the tail (the largest error was: on the double
//!    pendulum lobatto7 it dropped the asymptotic points). The quick report's driven_duffing
//!    lobatto5 sweep ends at 4.4e-14 and 4.6e-14; its next point, 1.3e-13, or 2.4e-13 after
//!    a change of the Jacobian's round-off, fitted 7.91 or 7.19 with it and 7.97 without.
//!    Below 10 times the noise, a point's error may be off by a tenth, which moves the slope
//!    of three points `0.29` apart in `log h` by about 0.2.
//! 2. **Seed.** The [`MIN_POINTS`] `= 3` candidates with the smallest `h` start the fit.
//! 3. **Grow.** The next larger `h` joins while the slope of the segment from it to the fit's
//!    largest-`h` point is within [`TRIM`] `= 0.3` of the seed's slope; the first point that
//!    breaks this ends the asymptotic range (larger steps are pre-asymptotic). Comparing with
//!    the seed, not the running fit, keeps a slowly bending curve from dragging the fit along.
//!
//! With fewer than [`MIN_POINTS`] candidates there is no observed order (an empty CSV field).
//!
//! # When a fit settles the order
//!
//! A fit is published only where its own points pin the slope down ([`Fit::unsettled`]):
//!
//! 4. **Confidence.** The 95 % confidence half-width of the least-squares slope (Student's
//!    `t` with `n − 2` degrees of freedom, times the slope's standard error from the
//!    residuals) is at most [`SETTLED`] `= 0.3`, the tolerance the orders are checked to. A
//!    fit of three points has one degree of freedom (`t = 12.7`): its points must lie on a
//!    line almost exactly.
//! 5. **Span.** Its errors fall by at least [`MIN_FALL`] `= 10` from its largest `h` to its
//!    smallest. The residuals measure the scatter about the line only where there is a fall
//!    to scatter about: three points of a wiggling curve can line up by chance. The full
//!    report's driven_duffing lobatto6 (order 10) fitted 11.76 ± 0.10 over three points
//!    whose errors fell by a factor 4.2, while the segments around them ranged from 9.1 to
//!    21.4.
//!
//! High orders fail these on most scenes: their errors cross from the ceiling to the floor
//! within a few tenths of a decade of `h`, where pre-asymptotic wiggles, the cancellation of
//! the leading error term at some step size (Kepler's lobatto7 near h = 0.25), and the
//! scenes' whole-number grids (`T / n`) leave a few points. A row without a settled order
//! says so and gives the unsettled fit.

/// Errors below `FLOOR · max(1, |reference|)` count as round-off.
pub const FLOOR: f64 = 1e-13;
/// Errors above `CEILING · max(1, |reference|)` count as pre-asymptotic.
pub const CEILING: f64 = 1e-3;
/// A point counts only if every error at a smaller `h` is at most this fraction of its own.
pub const FALL: f64 = 1.0 / 1.5;
/// The falling rule applies to errors within this factor of the sweep's smallest.
pub const FLOOR_BAND: f64 = 1e3;
/// Above a scattered tail, a point counts only from this multiple of the tail's median error.
pub const FLOOR_MARGIN: f64 = 10.0;
/// Fewest points a fit uses.
pub const MIN_POINTS: usize = 3;
/// A point whose segment slope is further than this from the fit ends the range.
pub const TRIM: f64 = 0.3;
/// The largest 95 % confidence half-width of a published slope.
pub const SETTLED: f64 = 0.3;
/// The least factor by which a published fit's errors fall across it.
pub const MIN_FALL: f64 = 10.0;

/// Two-sided 95 % quantiles of Student's `t` for 1 to 20 degrees of freedom.
const T95: [f64; 20] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
    2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
];

/// Why a fit does not settle the order ([`Fit::unsettled`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Unsettled {
    /// The slope's 95 % confidence half-width is above [`SETTLED`].
    Wide {
        /// The half-width.
        half_width: f64,
    },
    /// The errors fall by less than [`MIN_FALL`] across the fit.
    Short {
        /// The factor they fall by.
        fall: f64,
    },
}

impl std::fmt::Display for Unsettled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unsettled::Wide { half_width } => {
                write!(f, "a 95 % half-width of {half_width:.2}, above {SETTLED}")
            }
            Unsettled::Short { fall } => write!(
                f,
                "errors that fall by a factor {fall:.1} across it, less than {MIN_FALL}"
            ),
        }
    }
}

/// A fitted order and the points it used.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// The slope.
    pub order: f64,
    /// The `(h, err)` points in the fit, largest `h` first.
    pub used: Vec<(f64, f64)>,
}

impl Fit {
    /// The 95 % confidence half-width of the slope (infinite for two points or fewer).
    pub fn half_width(&self) -> f64 {
        let n = self.used.len();
        if n < 3 {
            return f64::INFINITY;
        }
        let pts: Vec<(f64, f64)> = self.used.iter().map(|&(h, e)| (h.ln(), e.ln())).collect();
        let nf = n as f64;
        let mx = pts.iter().map(|p| p.0).sum::<f64>() / nf;
        let my = pts.iter().map(|p| p.1).sum::<f64>() / nf;
        let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
        let rss: f64 = pts
            .iter()
            .map(|p| {
                let r = p.1 - my - self.order * (p.0 - mx);
                r * r
            })
            .sum();
        let t = T95.get(n - 3).copied().unwrap_or(T95[T95.len() - 1]);
        t * (rss / (nf - 2.0) / sxx).sqrt()
    }

    /// The factor by which the errors fall from the fit's largest `h` to its smallest.
    pub fn fall(&self) -> f64 {
        match (self.used.first(), self.used.last()) {
            (Some(big), Some(small)) => big.1 / small.1,
            _ => 1.0,
        }
    }

    /// Why the fit does not settle the order (rules 4 and 5 of the module docs); `None`
    /// when it does.
    pub fn unsettled(&self) -> Option<Unsettled> {
        let half_width = self.half_width();
        let fall = self.fall();
        if half_width.is_nan() || half_width > SETTLED {
            Some(Unsettled::Wide { half_width })
        } else if fall.is_nan() || fall < MIN_FALL {
            Some(Unsettled::Short { fall })
        } else {
            None
        }
    }
}

/// Least-squares slope of `log y` against `log x`; `None` for fewer than two distinct `x`.
pub fn slope(points: &[(f64, f64)]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = points.iter().map(|&(x, y)| (x.ln(), y.ln())).collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// Whether an error is at the round-off floor for a reference of size `scale`.
pub fn at_floor(err: f64, scale: f64) -> bool {
    err < FLOOR * scale.max(1.0)
}

/// The observed order of `(h, err)` points by the rule in the module docs; `scale` is
/// `|reference|∞`.
pub fn observed_order(points: &[(f64, f64)], scale: f64) -> Option<Fit> {
    let s = scale.max(1.0);
    let mut pts: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|&(h, e)| h > 0.0 && e.is_finite())
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The curve must still fall below a point: the largest error at smaller `h` (a running
    // maximum from the smallest `h` up) is at most `FALL` of it.
    // Only near the sweep's smallest error: a bump at large `h` is pre-asymptotic, which
    // the growth rule below handles.
    let least = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let mut below = 0.0f64;
    let mut falling = vec![false; pts.len()];
    for (i, &(_, e)) in pts.iter().enumerate() {
        // The scatter is the floor's only if every smaller `h` is near the floor too: a
        // wiggle above an asymptotic range that reaches the floor (high orders cross the fit's
        // window within a few tenths of a decade of `h`) is pre-asymptotic, not round-off.
        let tail_near_floor = below <= FLOOR_BAND * least;
        falling[i] = below <= FALL * e || e > FLOOR_BAND * least || !tail_near_floor;
        below = below.max(e);
    }
    let first = falling.iter().rposition(|&f| !f).map_or(0, |i| i + 1);
    // The noise of the tail that dropped out (zero without one): its median, which a
    // pre-asymptotic wiggle that falls into the tail does not move.
    let mut tail: Vec<f64> = pts[..first].iter().map(|p| p.1).collect();
    tail.sort_by(f64::total_cmp);
    let noise = tail.get(tail.len() / 2).copied().unwrap_or(0.0);
    let pts: Vec<(f64, f64)> = pts[first..]
        .iter()
        .copied()
        .filter(|&(_, e)| e >= FLOOR * s && e >= FLOOR_MARGIN * noise && e <= CEILING * s)
        .collect();
    if pts.len() < MIN_POINTS {
        return None;
    }
    let mut n = MIN_POINTS;
    let seed = slope(&pts[..n])?;
    let mut fit = seed;
    while n < pts.len() {
        let segment = slope(&pts[n - 1..=n]).unwrap_or(f64::INFINITY);
        if (segment - seed).abs() > TRIM {
            break;
        }
        n += 1;
        fit = slope(&pts[..n])?;
    }
    let mut used = pts[..n].to_vec();
    used.reverse();
    Some(Fit { order: fit, used })
}
