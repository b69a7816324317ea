//! The grids the report sweeps: step sizes, tolerances, repeats and early stops.
//!
//! Step sizes are `h = T/n` with whole `n`, so every run lands exactly on the final time;
//! `n` runs over a log-spaced range between `h = min(1, T)` and `h = 5·10⁻⁵` (the paper's
//! range). A sweep goes from large to small `h` and stops early when more points cannot change
//! the picture: after [`Plan::floor_points`] consecutive points at the round-off floor
//! (see [`crate::report::orders::FLOOR`]), when one run takes longer than
//! [`Plan::max_run_seconds`], or before a variational run predicted to take longer than
//! [`PREDICTED_RUN_FACTOR`] times that (from the previous point's time: the work goes as `1/h`
//! with fixed steps, as `tol^(−1/p)` with adaptive steps of order `p`). The paper's own scene, `coupled_van_der_pol`, is always swept to
//! the end of the range in the full report, to show the flat round-off tails.
//!
//! Tolerances for the baselines are `rtol = atol = 10^(−3 − k/2)` (full) or `10^(−3 − 2k)`
//! (quick) down to `10⁻¹³`, stopping in the same ways.
//!
//! The adaptive runs of the variational schemes sweep `rtol = atol` over
//! [`Plan::adaptive_tolerances`]: `10⁻³ … 10⁻¹²` by decades (full), `10⁻⁴, 10⁻⁷, 10⁻¹⁰`
//! (quick). Second-order schemes stop at [`ORDER2_TOL_FLOOR`]: at `10⁻¹²` they need about
//! `10⁷` steps.

/// The sweep settings of one report run.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Log-spaced step-count points per decade of `h`.
    pub per_decade: f64,
    /// The smallest step size.
    pub h_min: f64,
    /// Stop a sweep after this many consecutive points at the round-off floor.
    pub floor_points: usize,
    /// Sweep the paper's scene over the whole `h` range regardless of the floor.
    pub full_paper_tail: bool,
    /// Stop a sweep after a run that took longer than this (seconds, one repeat).
    pub max_run_seconds: f64,
    /// Tolerances for the baselines, loosest first.
    pub tolerances: Vec<f64>,
    /// Aim for this much timing per point (seconds over all repeats).
    pub timing_budget: f64,
    /// At most this many repeats per point.
    pub max_repeats: usize,
    /// Tolerances of the adaptive variational runs, loosest first.
    pub adaptive_tolerances: Vec<f64>,
    /// Final time of the energy-balance long run.
    pub long_run_t: f64,
    /// Samples per curve in the energy-balance plot.
    pub long_run_samples: usize,
    /// The flow's amplification ([`crate::scenes::Scene::amplification`]): the times `t`
    /// at which it samples `Φ(T, t)`.
    pub amplification_points: usize,
    /// The flow's amplification: the steps of each of its tangent runs over `[0, T]`.
    pub amplification_steps: usize,
}

/// Points per decade of `h`, per unit of order, for schemes above order 8.
pub const HIGH_ORDER_POINTS: f64 = 4.0;

/// Schemes of order 2 (`lobatto2`, `midpoint`) are run adaptively down to this tolerance only.
pub const ORDER2_TOL_FLOOR: f64 = 1e-9;

/// A sweep of a variational scheme stops before a point predicted to take this many times
/// [`Plan::max_run_seconds`].
pub const PREDICTED_RUN_FACTOR: f64 = 4.0;

/// The scene of the energy-balance long run.
pub const LONG_RUN_SCENE: &str = "coupled_van_der_pol";

/// The scene swept to the end of the `h` range in the full report (the paper's figure).
pub const PAPER_SCENE: &str = "coupled_van_der_pol";

impl Plan {
    /// The full report.
    pub fn full() -> Self {
        Plan {
            per_decade: 8.0,
            h_min: 5e-5,
            floor_points: 4,
            full_paper_tail: true,
            max_run_seconds: 4.0,
            tolerances: (0..=20)
                .map(|k| 10f64.powf(-3.0 - 0.5 * k as f64))
                .collect(),
            adaptive_tolerances: (3..=12).map(|k| 10f64.powi(-k)).collect(),
            timing_budget: 0.1,
            max_repeats: 21,
            long_run_t: 1000.0,
            long_run_samples: 400,
            amplification_points: 16,
            amplification_steps: 4000,
        }
    }

    /// `--quick`: coarser grids and early stops, under a minute on two cores.
    pub fn quick() -> Self {
        Plan {
            per_decade: 5.0,
            h_min: 1e-3,
            floor_points: 2,
            full_paper_tail: false,
            max_run_seconds: 0.25,
            tolerances: (0..=5).map(|k| 10f64.powi(-3 - 2 * k)).collect(),
            adaptive_tolerances: vec![1e-4, 1e-7, 1e-10],
            timing_budget: 0.01,
            max_repeats: 5,
            long_run_t: 1000.0,
            long_run_samples: 200,
            // A sample of the full report's 16 tangent runs of 4000 steps (about 9 s of
            // its under-a-minute budget at 16 × 4000, 0.6 s at 4 × 1000).
            amplification_points: 4,
            amplification_steps: 1000,
        }
    }

    /// The plan for `quick` or full runs.
    pub fn new(quick: bool) -> Self {
        if quick {
            Plan::quick()
        } else {
            Plan::full()
        }
    }

    /// Step sizes `T/n`, largest first, from `h = min(1, T)` down to [`h_min`](Self::h_min),
    /// for a scheme of order `order`.
    ///
    /// Above order 8 the grid is [`HIGH_ORDER_POINTS`] `· order` points per decade: an
    /// order-`p` error crosses the fit's window (`10⁻¹³ … 10⁻³`, ten decades) within about
    /// `10/p` decades of `h`, where [`Plan::per_decade`] would leave too few points to fit
    /// (the sweep stops at the round-off floor, so the denser grid costs little).
    pub fn step_sizes(&self, t_final: f64, order: usize) -> Vec<f64> {
        let per_decade = if order > 8 {
            self.per_decade.max(HIGH_ORDER_POINTS * order as f64)
        } else {
            self.per_decade
        };
        let n_min = (t_final / 1.0).ceil().max(1.0);
        let n_max = (t_final / self.h_min).floor().max(n_min);
        let decades = (n_max / n_min).log10();
        let points = (decades * per_decade).round() as usize;
        let mut ns: Vec<u64> = (0..=points)
            .map(|k| {
                let x = n_min * 10f64.powf(k as f64 / per_decade);
                x.round().clamp(n_min, n_max) as u64
            })
            .collect();
        ns.push(n_max as u64);
        ns.sort_unstable();
        ns.dedup();
        ns.into_iter().map(|n| t_final / n as f64).collect()
    }

    /// How many times to repeat a run whose first repeat took `first` seconds.
    pub fn repeats(&self, first: f64) -> usize {
        if first <= 0.0 {
            return self.max_repeats;
        }
        let wanted = (self.timing_budget / first).floor() as usize;
        wanted.clamp(1, self.max_repeats)
    }
}
