//! The stiff and extreme scenes of the stability study and their grids. A new scene is one
//! function here, its name in [`SCENES`] and a line in [`plan`].

use forced_vi::SchemeId;

use super::problem::{fine_reference, q_error, reference_end, Case, Problem};
use crate::baselines::Baseline;
use crate::models::{CoupledVanDerPol, OverdampedOscillator, SpringChain, StiffVanDerPol};
use crate::report::ReportError;

/// The over-damped oscillator of `data/reference/overdamped_oscillator.csv`: `ω = 1`,
/// `ζ = 100` (the model's `DEFAULT` has `ζ = 5`).
pub const OVERDAMPED_ZETA_100: OverdampedOscillator = OverdampedOscillator {
    omega: 1.0,
    zeta: 100.0,
};

/// Masses in the stiff spring chain.
pub const CHAIN_DOF: usize = 4;

/// Scene names, in report order.
pub const SCENES: [&str; 5] = [
    "stiff_van_der_pol",
    "van_der_pol_scaled_1e6",
    "stiff_spring_chain",
    "overdamped_oscillator",
    "coupled_van_der_pol_x100",
];

/// The step sizes, methods and baseline tolerances of one scene.
pub struct Grid {
    /// Step sizes, in the scene's time unit.
    pub hs: Vec<f64>,
    /// The variational schemes.
    pub methods: Vec<SchemeId>,
    /// Tolerances of the stiff baselines.
    pub tols: Vec<f64>,
    /// Tolerances `rtol = atol` of the adaptive variational runs.
    pub adaptive_tols: Vec<f64>,
    /// The schemes run adaptively: `methods` and lobatto5–8 (`--quick`: `lobatto3` only;
    /// second-order schemes need millions of steps on the stiff scenes).
    pub adaptive_methods: Vec<SchemeId>,
}

/// A scene with its grid.
pub type Planned = (Box<dyn Case>, Grid);

/// The grids shared by the scenes, full or `--quick`.
struct Common {
    quick: bool,
    methods: Vec<SchemeId>,
    tols: Vec<f64>,
    wide: Vec<f64>,
}

impl Common {
    fn new(quick: bool) -> Self {
        use SchemeId::{Lobatto, Midpoint};
        let pick = |q: Vec<f64>, full: Vec<f64>| if quick { q } else { full };
        Common {
            quick,
            methods: if quick {
                vec![Lobatto(3), Midpoint]
            } else {
                vec![Lobatto(2), Lobatto(3), Lobatto(4), Midpoint]
            },
            tols: pick(
                vec![1e-4, 1e-7],
                // From 1e-1: loose tolerances for the baselines too, as the adaptive
                // variational runs get them (below); BDF fails at 1e-1 on the stiff scenes.
                vec![1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10],
            ),
            wide: pick(
                vec![1.0, 1e-2, 5e-5],
                vec![1.0, 0.5, 0.2, 0.1, 1e-2, 1e-3, 1e-4, 5e-5],
            ),
        }
    }

    fn grid(&self, hs: Vec<f64>) -> Grid {
        Grid {
            hs,
            methods: self.methods.clone(),
            tols: self.tols.clone(),
            adaptive_tols: if self.quick {
                vec![1e-3, 1e-5]
            } else {
                // From tol 1: with error control per unit step a stiff run ends orders of
                // magnitude more accurate than its tolerance (the report's stiff-cost
                // paragraph gives this run's errors at tol 1e-1), and the errors of 1e-3 to
                // 1e-5 the stiff cost table asks about take looser tolerances.
                [1.0, 0.3]
                    .into_iter()
                    .chain((1..=8).map(|k| 10f64.powi(-k)))
                    .collect()
            },
            adaptive_methods: if self.quick {
                vec![SchemeId::Lobatto(3)]
            } else {
                // The higher orders too: the adaptive runs are cheap, lobatto6 and lobatto8
                // are what `Integrator::auto` takes on a small model, and only the higher
                // orders finish the van der Pol at μ = 10⁶ at tight tolerances.
                let higher = [5, 6, 7, 8].map(SchemeId::Lobatto);
                self.methods.iter().copied().chain(higher).collect()
            },
        }
    }
}

/// Builds the scenes (and their references) and the grids, in [`SCENES`] order.
pub fn plan(quick: bool) -> Result<Vec<Planned>, ReportError> {
    let c = Common::new(quick);
    Ok(vec![
        stiff_van_der_pol(&c)?,
        scaled_van_der_pol(&c)?,
        stiff_chain(&c),
        overdamped(&c)?,
        large_amplitude(&c),
    ])
}

/// Stiff van der Pol, μ = 10³, over T = 2μ = 2000 (the relaxation jump near t ≈ 807).
fn stiff_van_der_pol(c: &Common) -> Result<Planned, ReportError> {
    let (t_end, q_ref) = reference_end(include_str!(
        "../../../data/reference/stiff_van_der_pol.csv"
    ))?;
    let vdp = Problem {
        name: SCENES[0],
        description: format!(
            "x'' − μ(1 − x²)x' + x = 0, μ = 10³, x(0) = 2, x'(0) = 0, T = {t_end} \
             (relaxation jumps near t ≈ 807 and 1614)"
        ),
        model: StiffVanDerPol::DEFAULT,
        q0: [2.0],
        v0: [0.0],
        t_final: t_end,
        time_scale: 1.0,
        reference: q_ref,
        reference_note: "data/reference/stiff_van_der_pol.csv (scipy Radau)".into(),
        reference_accuracy: 1e-11,
    };
    let hs = if c.quick {
        vec![1.0, 0.1, 0.01]
    } else {
        // 2e-3 is 10⁶ steps, 1e-4 is 2·10⁷ steps: the long runs.
        vec![
            1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4,
        ]
    };
    Ok((Box::new(vdp), c.grid(hs)))
}

/// Hairer's scaled form ε x'' − (1 − x²)x' + x = 0, ε = μ⁻² with μ = 10⁶, over τ ∈ [0, 2].
/// It is the unscaled model with t = μτ: both discrete actions differ by the factor μ, so the
/// variational schemes give the same positions at h_t = μ h_τ.
fn scaled_van_der_pol(c: &Common) -> Result<Planned, ReportError> {
    let mu = StiffVanDerPol::VERY_STIFF.mu;
    let (t_end, q_ref) = reference_end(include_str!(
        "../../../data/reference/van_der_pol_scaled_1e6.csv"
    ))?;
    let scaled = Problem {
        name: SCENES[1],
        description: "Hairer's scaled van der Pol ε x'' − (1 − x²)x' + x = 0, ε = 10⁻¹² \
                      (μ = 10⁶), x(0) = 2, x'(0) = 0, τ ∈ [0, 2]; h is in τ. Run as the \
                      unscaled model with t = μτ."
            .into(),
        model: StiffVanDerPol::VERY_STIFF,
        q0: [2.0],
        v0: [0.0],
        t_final: t_end,
        time_scale: mu,
        reference: q_ref,
        // Radau at 1e-9 and 1e-10 differ from it by 7.2e-13 and 2.5e-14 (the script prints
        // them); 1e-12 leaves a margin.
        reference_note: "data/reference/van_der_pol_scaled_1e6.csv (scipy Radau at 3e-11, \
                         scripts/scaled_vdp_reference.py)"
            .into(),
        reference_accuracy: 1e-12,
    };
    let hs = if c.quick {
        vec![0.1, 1e-3]
    } else {
        vec![
            1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5,
        ]
    };
    Ok((Box::new(scaled), c.grid(hs)))
}

/// The highest frequency of the stiff chain, `ω_max = 2 √(k/m) sin(nπ / (2(n + 1)))`.
pub fn chain_omega_max() -> f64 {
    let chain_model = SpringChain::<CHAIN_DOF>::STIFF;
    let n = CHAIN_DOF as f64;
    2.0 * (chain_model.k / chain_model.m).sqrt()
        * (n * std::f64::consts::PI / (2.0 * (n + 1.0))).sin()
}

/// A damped chain of stiff springs, hω_max from 0.1 to 10³, T = 5.
fn stiff_chain(c: &Common) -> Planned {
    let chain_model = SpringChain::<CHAIN_DOF>::STIFF;
    let omega_max = chain_omega_max();
    let t_chain = 5.0;
    let mut chain = Problem {
        name: SCENES[2],
        description: format!(
            "{CHAIN_DOF} masses, SpringChain::STIFF (k = 10⁴, β = 1, c = 1, m = 1), \
             ω_max = {omega_max:.1}, q(0) = (0.01, −0.02, 0.015, 0), v(0) = 0, T = {t_chain}; \
             h = T/n with n = round(T ω_max / (hω))"
        ),
        model: chain_model,
        q0: [0.01, -0.02, 0.015, 0.0],
        v0: [0.0; CHAIN_DOF],
        t_final: t_chain,
        time_scale: 1.0,
        reference: Vec::new(),
        reference_note: String::new(),
        reference_accuracy: f64::NAN,
    };
    (
        chain.reference,
        chain.reference_note,
        chain.reference_accuracy,
    ) = fine_reference(&chain, t_chain / 50_000.0);
    let hw: Vec<f64> = if c.quick {
        vec![0.1, 10.0, 1000.0]
    } else {
        vec![0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0]
    };
    let hs = hw
        .iter()
        .map(|r| t_chain / (t_chain * omega_max / r).round().max(1.0))
        .collect();
    (Box::new(chain), c.grid(hs))
}

/// The over-damped oscillator of the reference file (ζ = 100).
fn overdamped(c: &Common) -> Result<Planned, ReportError> {
    let (t_end, q_ref) = reference_end(include_str!(
        "../../../data/reference/overdamped_oscillator.csv"
    ))?;
    let od = Problem {
        name: SCENES[3],
        description: format!(
            "x'' + 2ζωx' + ω²x = 0, ζ = 100, ω = 1, x(0) = 1, x'(0) = 0, T = {t_end} \
             (eigenvalues ≈ −0.005 and −200)"
        ),
        model: OVERDAMPED_ZETA_100,
        q0: [1.0],
        v0: [0.0],
        t_final: t_end,
        time_scale: 1.0,
        reference: q_ref,
        reference_note: "data/reference/overdamped_oscillator.csv (closed form)".into(),
        reference_accuracy: 1e-15,
    };
    Ok((Box::new(od), c.grid(c.wide.clone())))
}

/// Large amplitudes: the paper's coupled van der Pol with q(0) × 100.
fn large_amplitude(c: &Common) -> Planned {
    let mut big = Problem {
        name: SCENES[4],
        description: "the paper's coupled van der Pol (ε, ρ, λ) = (0.5, 0.02, 0.8) with \
                      q(0) = 100 · (−0.5, −0.25), v(0) = (0, 4), T = 10 (damping up to \
                      q² ≈ 2500)"
            .into(),
        model: CoupledVanDerPol::PAPER,
        q0: [-50.0, -25.0],
        v0: [0.0, 4.0],
        t_final: 10.0,
        time_scale: 1.0,
        reference: Vec::new(),
        reference_note: String::new(),
        reference_accuracy: f64::NAN,
    };
    // DOP853 stops on this problem (its stiffness detection), so the reference is a fine
    // lobatto5 run, checked against BDF.
    (big.reference, big.reference_note, big.reference_accuracy) = fine_reference(&big, 1e-4);
    if let Ok((b, _)) = big.baseline_q(Baseline::Bdf, 1e-10) {
        let d = q_error(&b, &big.reference);
        big.reference_note
            .push_str(&format!("; bdf at tol 1e-10 differs by {d:.1e}"));
    }
    (Box::new(big), c.grid(c.wide.clone()))
}
