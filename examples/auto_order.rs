//! The order chosen from the tolerance (`Integrator::auto`, `Scheme::for_tolerance`) against
//! every fixed choice: `cargo run --release --example auto_order`.
//!
//! On three of the report's models and three models the rule was not tuned on, each adaptive
//! Lobatto scheme (s = 3 … 8) and `auto` run at `rtol = atol = tol` for tol = 1e-4, 1e-7 and
//! 1e-10. Each run is timed (the median of 9 rounds that run the seven of a tolerance one after
//! the other, each round starting one further along) and its final `(q, p)` compared with a reference
//! (fixed-step lobatto5 at `T/40000`, below 1e-13 on these models). The last column is the
//! time of `auto` over the cheapest scheme whose error is within 10·tol: 1.00 means the rule
//! picked the cheapest one.
//!
//! A second table runs the same schemes on Hairer's scaled van der Pol at μ = 10⁶ (the
//! stability report's `van_der_pol_scaled_1e6`, to τ = 2), capped at 2·10⁶ steps: the
//! stiff case that decides why the rule takes an even number of stages, and a slowly driven
//! over-damped oscillator, stiff too and held out. A last one runs a
//! large model on the sparse backend: an over-damped spring chain (32 masses, k = 10⁴,
//! c = 10⁵), stiff, against which the sparse rule was checked.
use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi_scenes::models::{
    CoupledVanDerPol, DoublePendulumFriction, KeplerDrag, SpringChain, StiffVanDerPol,
};
use forced_vi_scenes::report::timing::rotated;

/// Hénon–Heiles with linear drag (held out).
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y)
        - (x * x * y - y * y * y / 3.0),
    force(x = -c * x_dot, y = -c * y_dot),
)]
struct HenonHeiles {
    c: f64,
}

/// An elastic pendulum in polar coordinates with drag on both (held out).
#[forced_lagrangian(
    coordinates(r, th),
    lagrangian = 0.5 * (r_dot * r_dot + r * r * th_dot * th_dot) + g * r * th.cos()
        - 0.5 * k * (r - 1.0) * (r - 1.0),
    force(r = -c * r_dot, th = -c * r * r * th_dot),
)]
struct ElasticPendulum {
    g: f64,
    k: f64,
    c: f64,
}

/// A damped pendulum driven by a periodic torque (held out; non-autonomous).
#[forced_lagrangian(
    coordinates(th),
    lagrangian = 0.5 * th_dot * th_dot + th.cos(),
    force(th = -c * th_dot + a * (w * t).cos()),
)]
struct DrivenPendulum {
    c: f64,
    a: f64,
    w: f64,
}

/// A slowly driven, heavily damped oscillator (held out, stiff): `x'' = −x − λx' + a cos ωt`
/// with λ = 10⁶, whose velocity relaxes in 10⁻⁶ to a slow manifold.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = -lam * x_dot + a * (w * t).cos()),
)]
struct DrivenOverdamped {
    lam: f64,
    a: f64,
    w: f64,
}

const TOLS: [f64; 3] = [1e-4, 1e-7, 1e-10];

/// The rounds of [`measure`]'s timing.
const ROUNDS: usize = 9;

fn measure<M: ForcedLagrangian<N> + Sync, const N: usize>(
    name: &str,
    model: &M,
    init: InitialState<N>,
    t_final: f64,
) -> Result<Vec<f64>, forced_vi::Error> {
    let reference = Integrator::new(model, Scheme::lobatto(5)?, t_final / 40000.0)?
        .final_state(init, t_final)
        .map_err(|f| f.error)?;
    let err = |q: &[f64], p: &[f64]| {
        let dq = q.iter().zip(reference.q.iter()).map(|(a, b)| (a - b).abs());
        let dp = p.iter().zip(reference.p.iter()).map(|(a, b)| (a - b).abs());
        dq.chain(dp).fold(0.0, f64::max)
    };
    let mut ratios = Vec::new();
    for tol in TOLS {
        // Lobatto s = 3 … 8, then `auto`: their errors, then their times, in rounds that
        // run all seven one after the other, each round starting one further along (the
        // machine's speed drifts between moments; a ratio of two times taken apart carries
        // that drift).
        let mut integs = Vec::new();
        for s in 3..=8 {
            integs.push(Integrator::adaptive(model, Scheme::lobatto(s)?, tol, tol)?);
        }
        integs.push(Integrator::auto(model, tol, tol)?);
        let mut errs = Vec::new();
        for integ in &integs {
            let end = integ.final_state(init, t_final).map_err(|f| f.error)?;
            errs.push(err(end.q.as_slice(), end.p.as_slice()));
        }
        let mut runs: Vec<Box<dyn FnMut() -> Result<f64, forced_vi::Error> + '_>> = integs
            .iter()
            .map(|integ| {
                Box::new(move || {
                    let t0 = Instant::now();
                    let _ = std::hint::black_box(integ.final_state(init, t_final));
                    Ok(t0.elapsed().as_secs_f64())
                }) as Box<dyn FnMut() -> Result<f64, forced_vi::Error> + '_>
            })
            .collect();
        let mut fs: Vec<&mut dyn FnMut() -> Result<f64, forced_vi::Error>> =
            runs.iter_mut().map(|f| &mut **f as _).collect();
        let secs = rotated(ROUNDS, &mut fs)?;
        let mut best = f64::INFINITY;
        let mut cells = Vec::new();
        for (t, e) in secs.iter().zip(&errs).take(6) {
            if *e <= 10.0 * tol {
                best = best.min(*t);
            }
            cells.push(format!("{:>8.0} {:7.1e}", t * 1e6, e));
        }
        let (secs, e) = (secs[6], errs[6]);
        let ratio = secs / best;
        ratios.push(ratio);
        println!(
            "{name:<18} {tol:7.0e} | {} | {:>8} {:>8.0} {e:7.1e} | {ratio:5.2}",
            cells.join(" |"),
            integs[6].scheme().id().to_string(),
            secs * 1e6,
        );
    }
    Ok(ratios)
}

fn main() -> Result<(), forced_vi::Error> {
    println!(
        "{:<18} {:>7} | {} | {:>8} {:>8} {:>7} | auto/cheapest",
        "model",
        "tol",
        (3..=8)
            .map(|s| format!("lobatto{s}: µs     err"))
            .collect::<Vec<_>>()
            .join(" |"),
        "auto",
        "µs",
        "err"
    );
    let mut all = Vec::new();
    all.extend(measure(
        "coupled_van_der_pol",
        &CoupledVanDerPol::PAPER,
        InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
        10.0,
    )?);
    all.extend(measure(
        "kepler_drag",
        &KeplerDrag::DEFAULT,
        InitialState::from_velocity([1.0, 0.0], [0.0, 1.2]),
        20.0,
    )?);
    all.extend(measure(
        "double_pendulum",
        &DoublePendulumFriction::DEFAULT,
        InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]),
        10.0,
    )?);
    all.extend(measure(
        "henon_heiles*",
        &HenonHeiles { c: 0.05 },
        InitialState::from_velocity([0.3, 0.0], [0.0, 0.3]),
        20.0,
    )?);
    all.extend(measure(
        "elastic_pendulum*",
        &ElasticPendulum {
            g: 9.81,
            k: 40.0,
            c: 0.05,
        },
        InitialState::from_velocity([1.2, 0.8], [0.0, 0.0]),
        10.0,
    )?);
    all.extend(measure(
        "driven_pendulum*",
        &DrivenPendulum {
            c: 0.1,
            a: 0.8,
            w: 0.7,
        },
        InitialState::from_velocity([0.5], [0.0]),
        20.0,
    )?);
    all.sort_by(f64::total_cmp);
    println!(
        "auto / cheapest: median {:.2}, worst {:.2} over {} cases (* = held out)",
        all[all.len() / 2],
        all[all.len() - 1],
        all.len()
    );
    stiff()?;
    driven_overdamped()?;
    stiff_chain()?;
    Ok(())
}

/// Steps and outcome of each scheme and of `auto` on the scaled van der Pol at μ = 10⁶, with
/// the error in `x(2)` against the stability report's reference
/// (`data/reference/van_der_pol_scaled_1e6.csv`, scipy Radau at 3e-11).
fn stiff() -> Result<(), forced_vi::Error> {
    const X_REF: f64 = 1.705_546_217_535_202_5;
    const CAP: usize = 2_000_000;
    let model = StiffVanDerPol::VERY_STIFF;
    let init = InitialState::from_velocity([2.0], [0.0]);
    println!("\nvan der Pol, mu = 1e6, to tau = 2 (steps, error in x, or the typed error; cap {CAP} steps)");
    let run = |integ: Integrator<'_, StiffVanDerPol, 1>| -> String {
        match integ.max_steps(CAP).final_state(init, 2.0e6) {
            Ok(end) => format!("{:>8} {:7.1e}", end.stats.steps, (end.q[0] - X_REF).abs()),
            Err(f) => {
                let kind = match f.error {
                    forced_vi::Error::MaxStepsReached { .. } => "step cap",
                    forced_vi::Error::StepSizeTooSmall { .. } => "h too small",
                    forced_vi::Error::ToleranceBelowRoundOff { .. } => "round-off",
                    _ => "other error",
                };
                format!("{kind:>16}")
            }
        }
    };
    for tol in [1e-3, 1e-5, 1e-6, 1e-7, 1e-9] {
        let mut cells = Vec::new();
        for s in 5..=8 {
            cells.push(run(Integrator::adaptive(
                &model,
                Scheme::lobatto(s)?,
                tol,
                tol,
            )?));
        }
        let auto = Integrator::auto(&model, tol, tol)?;
        let name = auto.scheme().id().to_string();
        println!(
            "{tol:7.0e} | lobatto5–8: {} | auto ({name}): {}",
            cells.join(" |"),
            run(auto)
        );
    }
    Ok(())
}

/// Steps and time of lobatto3–5 and `auto` on an over-damped spring chain of 32 masses
/// (the sparse backend): velocities relax at a rate of about c = 10⁵, the chain's shape at
/// rates k/c·(mode)² from 10⁻³ to 0.4.
fn stiff_chain() -> Result<(), forced_vi::Error> {
    const N: usize = 32;
    let model = SpringChain::<N> {
        m: 1.0,
        k: 1e4,
        beta: 1.0,
        c: 1e5,
    };
    let q0: [f64; N] = std::array::from_fn(|i| {
        let bump = if i == N / 2 { 0.05 } else { 0.0 };
        0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64).sin() + bump
    });
    let init = InitialState::from_velocity(q0, [0.0; N]);
    println!("\nover-damped spring chain, 32 masses (sparse backend), to T = 200 (steps, ms)");
    let run = |integ: &Integrator<'_, SpringChain<N>, N>| -> Result<String, forced_vi::Error> {
        let t0 = Instant::now();
        let end = integ.final_state(init, 200.0).map_err(|f| f.error)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(format!("{:>8} {:8.1}", end.stats.steps, ms))
    };
    for tol in [1e-3, 1e-5] {
        let mut cells = Vec::new();
        for s in 3..=5 {
            cells.push(run(&Integrator::adaptive(
                &model,
                Scheme::lobatto(s)?,
                tol,
                tol,
            )?)?);
        }
        let auto = Integrator::auto(&model, tol, tol)?;
        println!(
            "{tol:7.0e} | lobatto3–5: {} | auto ({}): {}",
            cells.join(" |"),
            auto.scheme().id(),
            run(&auto)?
        );
    }
    Ok(())
}

/// Steps of lobatto5–8 and `auto` on the driven over-damped oscillator (held out) to
/// T = 200, with `x(T)` (the runs agree to the digits shown) or the typed error.
fn driven_overdamped() -> Result<(), forced_vi::Error> {
    const CAP: usize = 2_000_000;
    let model = DrivenOverdamped {
        lam: 1e6,
        a: 1e6,
        w: 0.1,
    };
    let init = InitialState::from_velocity([0.0], [0.0]);
    println!(
        "\ndriven over-damped oscillator, lambda = 1e6, to T = 200 (steps, x(T); cap {CAP} steps)"
    );
    let run = |integ: Integrator<'_, DrivenOverdamped, 1>| -> String {
        match integ.max_steps(CAP).final_state(init, 200.0) {
            Ok(end) => format!("{:>8} {:.9}", end.stats.steps, end.q[0]),
            Err(f) => format!(
                "{:>20}",
                format!("{:?}", f.error)
                    .split([' ', '{'])
                    .next()
                    .unwrap_or("error")
                    .to_string()
            ),
        }
    };
    for tol in [1e-3, 1e-5, 1e-7] {
        let mut cells = Vec::new();
        for s in 5..=8 {
            cells.push(run(Integrator::adaptive(
                &model,
                Scheme::lobatto(s)?,
                tol,
                tol,
            )?));
        }
        let auto = Integrator::auto(&model, tol, tol)?;
        let name = auto.scheme().id().to_string();
        println!(
            "{tol:7.0e} | lobatto5–8: {} | auto ({name}): {}",
            cells.join(" |"),
            run(auto)
        );
    }
    Ok(())
}
