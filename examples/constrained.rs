//! Measurements of the constrained schemes (issue 25) on a pendulum with air drag written in
//! Cartesian coordinates with one constraint, against its angle form:
//! - the constraint residuals `|g|` and `|G v|` over a run of 10⁶ steps, in its first and
//!   last tenth (growth);
//! - the cost per step against the same model in its angle (minimal) coordinate, median of 5
//!   runs;
//! - the order of the multipliers: each record's mean constraint force over its step
//!   against the exact mean of the rod's force `−T q/l` (tension
//!   `T = m l θ̇² + m g cos θ`) over the same step, from the angle form's dense output and
//!   a 5-point Gauss rule, fitted over four step sizes.
//!
//! `cargo run --release --example constrained`

use forced_vi::prelude::*;

const M: f64 = 1.0;
const G: f64 = 9.81;
const L: f64 = 1.5;
const C: f64 = 0.3;

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * m * (x_dot * x_dot + y_dot * y_dot) - m * g * y,
    force(x = -c * x_dot, y = -c * y_dot),
    constraints(0.5 * (x * x + y * y - l * l)),
)]
struct Cartesian {
    m: f64,
    g: f64,
    l: f64,
    c: f64,
}

#[forced_lagrangian(
    coordinates(theta),
    lagrangian = 0.5 * m * l * l * theta_dot * theta_dot + m * g * l * theta.cos(),
    force(theta = -c * l * l * theta_dot),
)]
struct Angle {
    m: f64,
    g: f64,
    l: f64,
    c: f64,
}

const THETA0: f64 = 1.2;
const OMEGA0: f64 = 0.4;

fn cartesian_start() -> InitialState<2> {
    let (s, c) = THETA0.sin_cos();
    InitialState::from_velocity([L * s, -L * c], [L * c * OMEGA0, L * s * OMEGA0])
}

fn median_ns(mut f: impl FnMut() -> usize) -> f64 {
    let mut xs: Vec<f64> = (0..5)
        .map(|_| {
            let t0 = std::time::Instant::now();
            let steps = f();
            t0.elapsed().as_secs_f64() * 1e9 / steps as f64
        })
        .collect();
    xs.sort_by(f64::total_cmp);
    xs[2]
}

fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0.ln()).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1.ln()).sum::<f64>() / n;
    let num: f64 = pts.iter().map(|p| (p.0.ln() - mx) * (p.1.ln() - my)).sum();
    let den: f64 = pts.iter().map(|p| (p.0.ln() - mx).powi(2)).sum();
    num / den
}

fn main() -> Result<(), forced_vi::Error> {
    let cart = Cartesian {
        m: M,
        g: G,
        l: L,
        c: C,
    };
    let angle = Angle {
        m: M,
        g: G,
        l: L,
        c: C,
    };

    // 10⁶ steps: the residuals in the first and the last tenth.
    let steps = 1_000_000usize;
    let h = 1e-3;
    let integ = Integrator::new(&cart, Scheme::lobatto(2)?, h)?;
    let (mut first, mut last) = (0.0f64, 0.0f64);
    integ
        .solve(
            cartesian_start(),
            steps as f64 * h,
            output::each_step(|r| {
                if r.step < steps / 10 {
                    first = first.max(r.constraint_residual);
                } else if r.step >= steps - steps / 10 {
                    last = last.max(r.constraint_residual);
                }
            }),
        )
        .map_err(|f| f.error)?;
    println!(
        "lobatto2, h = {h}, {steps} steps: max(|g|, |G v|) = {first:.1e} in the first tenth, {last:.1e} in the last (l² = {:.2})",
        L * L
    );

    // Cost per step against the angle form.
    for s in 2..=5 {
        let t_final = 20.0;
        let h = 0.01;
        let c = Integrator::new(&cart, Scheme::lobatto(s)?, h)?;
        let a = Integrator::new(&angle, Scheme::lobatto(s)?, h)?;
        let tc = median_ns(|| {
            c.final_state(cartesian_start(), t_final)
                .expect("cartesian")
                .stats
                .steps
        });
        let ta = median_ns(|| {
            a.final_state(InitialState::from_velocity([THETA0], [OMEGA0]), t_final)
                .expect("angle")
                .stats
                .steps
        });
        println!(
            "lobatto{s}: {tc:.0} ns per constrained step (2 coordinates, 1 constraint), {ta:.0} ns in the angle (1 coordinate): {:.1}x",
            tc / ta
        );
    }

    // The multipliers' order: the mean constraint force per step against the exact one.
    let t_final = 2.0;
    let fine = Integrator::new(&angle, Scheme::lobatto(5)?, 1e-3)?;
    let gauss = [
        (-0.906_179_845_938_664, 0.236_926_885_056_189),
        (-0.538_469_310_105_683, 0.478_628_670_499_366),
        (0.0, 0.568_888_888_888_889),
        (0.538_469_310_105_683, 0.478_628_670_499_366),
        (0.906_179_845_938_664, 0.236_926_885_056_189),
    ];
    for s in 2..=5 {
        let mut pts = Vec::new();
        let h0 = [0.1, 0.1, 0.2, 0.4][s - 2];
        for k in 0..4 {
            let h = h0 / 2f64.powi(k);
            let run = Integrator::new(&cart, Scheme::lobatto(s)?, h)?
                .solve(cartesian_start(), t_final, output::Records)
                .map_err(|f| f.error)?;
            // Exact mean force over each step, from the angle form's dense output.
            let mut times = Vec::new();
            for r in run.records.iter().skip(1) {
                let t0 = r.t - h;
                for &(x, _) in &gauss {
                    times.push(t0 + 0.5 * h * (1.0 + x));
                }
            }
            let states = fine
                .solve(
                    InitialState::from_velocity([THETA0], [OMEGA0]),
                    t_final,
                    output::Samples(&times),
                )
                .map_err(|f| f.error)?;
            let mut worst = 0.0f64;
            for (r, chunk) in run.records.iter().skip(1).zip(states.chunks(gauss.len())) {
                let mut mean = [0.0; 2];
                for (st, &(_, w)) in chunk.iter().zip(&gauss) {
                    let (th, om) = (st.q[0], st.v[0]);
                    let tension = M * L * om * om + M * G * th.cos();
                    let (sn, cs) = th.sin_cos();
                    // −T q/l with q/l = (sin θ, −cos θ).
                    mean[0] += 0.5 * w * (-tension * sn);
                    mean[1] += 0.5 * w * (tension * cs);
                }
                for (f, m) in r.constraint_force.iter().zip(mean) {
                    worst = worst.max((f - m).abs());
                }
            }
            pts.push((h, worst));
        }
        let shown: Vec<String> = pts
            .iter()
            .map(|(h, e)| format!("h = {h}: {e:.1e}"))
            .collect();
        println!(
            "lobatto{s}: mean constraint force per step, max error {}; fitted order {:.2}",
            shown.join(", "),
            slope(&pts)
        );
    }
    Ok(())
}
