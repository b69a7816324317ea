//! A four-bar linkage driven by a motor torque (issue 25): a closed loop, three constraints on
//! four Cartesian coordinates, against an independent reference, the index-1 form of the
//! same equations (`[[M, Gᵀ], [G, 0]] (a, λ) = (F, −vᵀ∇²g v)`) integrated by ode_solvers'
//! DOP853 at rtol = atol = 10⁻¹³ (its final-time nodes fixed as in `src/baselines.rs`:
//! the system is autonomous, so the c₁₂ = c₁₃ = 0 defect does not apply).
//! `cargo test --workspace --release --test models_suite constraint_fourbar::`.

use forced_vi::prelude::*;
use nalgebra::{DMatrix, DVector};

const D: f64 = 2.5;

/// Crank A–B (A at the origin, length `a`), coupler B–C (length `b`), rocker C–D (D at
/// `(d, 0)`, length `c`); point masses at B and C, gravity, a motor torque `tau` on the
/// crank and a linear drag `k` on both masses.
#[forced_lagrangian(
    coordinates(x1, y1, x2, y2),
    lagrangian = 0.5 * m1 * (x1_dot * x1_dot + y1_dot * y1_dot)
        + 0.5 * m2 * (x2_dot * x2_dot + y2_dot * y2_dot)
        - g * (m1 * y1 + m2 * y2),
    force(
        x1 = -tau * y1 / (a * a) - k * x1_dot,
        y1 = tau * x1 / (a * a) - k * y1_dot,
        x2 = -k * x2_dot,
        y2 = -k * y2_dot,
    ),
    constraints(
        0.5 * (x1 * x1 + y1 * y1 - a * a),
        0.5 * ((x2 - x1) * (x2 - x1) + (y2 - y1) * (y2 - y1) - b * b),
        0.5 * ((x2 - d) * (x2 - d) + y2 * y2 - c * c),
    ),
)]
struct FourBar {
    m1: f64,
    m2: f64,
    a: f64,
    b: f64,
    c: f64,
    d: f64,
    g: f64,
    tau: f64,
    k: f64,
}

const MODEL: FourBar = FourBar {
    m1: 1.0,
    m2: 0.5,
    a: 1.0,
    b: 2.5,
    c: 2.0,
    d: D,
    g: 9.81,
    tau: 4.0,
    k: 0.1,
};

/// The index-1 right-hand side: `y = (q, v)`.
struct IndexOne;

impl ode_solvers::System<f64, ode_solvers::DVector<f64>> for IndexOne {
    fn system(&self, _t: f64, y: &ode_solvers::DVector<f64>, dy: &mut ode_solvers::DVector<f64>) {
        let m = &MODEL;
        let (q, v) = (&y.as_slice()[..4], &y.as_slice()[4..]);
        let (x1, y1, x2, y2) = (q[0], q[1], q[2], q[3]);
        let mass = [m.m1, m.m1, m.m2, m.m2];
        let f = [
            -m.tau * y1 / (m.a * m.a) - m.k * v[0],
            m.tau * x1 / (m.a * m.a) - m.k * v[1] - m.g * m.m1,
            -m.k * v[2],
            -m.k * v[3] - m.g * m.m2,
        ];
        let gq = [
            [x1, y1, 0.0, 0.0],
            [-(x2 - x1), -(y2 - y1), x2 - x1, y2 - y1],
            [0.0, 0.0, x2 - m.d, y2],
        ];
        let w = [
            v[0] * v[0] + v[1] * v[1],
            (v[2] - v[0]).powi(2) + (v[3] - v[1]).powi(2),
            v[2] * v[2] + v[3] * v[3],
        ];
        let mut k = DMatrix::<f64>::zeros(7, 7);
        let mut rhs = DVector::<f64>::zeros(7);
        for i in 0..4 {
            k[(i, i)] = mass[i];
            rhs[i] = f[i];
            for r in 0..3 {
                k[(i, 4 + r)] = gq[r][i];
                k[(4 + r, i)] = gq[r][i];
            }
        }
        for r in 0..3 {
            rhs[4 + r] = -w[r];
        }
        let sol = k.lu().solve(&rhs).expect("a regular linkage");
        for i in 0..4 {
            dy[i] = v[i];
            dy[4 + i] = sol[i];
        }
    }
}

/// A consistent start: the crank at 90°, turning at 1 rad/s.
fn start() -> InitialState<4> {
    let m = &MODEL;
    let (x1, y1) = (0.0, m.a);
    // C on the circles of radius b about B and c about D (the upper intersection).
    let (dx, dy) = (m.d - x1, 0.0 - y1);
    let dist = (dx * dx + dy * dy).sqrt();
    let along = (m.b * m.b - m.c * m.c + dist * dist) / (2.0 * dist);
    let h = (m.b * m.b - along * along).sqrt();
    let (ex, ey) = (dx / dist, dy / dist);
    let (x2, y2) = (x1 + along * ex - h * ey, y1 + along * ey + h * ex);
    let guess = [-m.a, 0.0, 0.0, 0.0];
    InitialState::projected(m, [x1, y1, x2, y2], guess).expect("a consistent start")
}

#[test]
fn constraint_four_bar_linkage_matches_the_index_one_reference() {
    let init = start();
    let (q0, v0) = match init {
        InitialState::Velocity { q, v } => (q, v),
        InitialState::Momentum { .. } => unreachable!(),
    };
    let t_final = 2.0;
    let y0: Vec<f64> = q0.iter().chain(&v0).copied().collect();
    let mut ode = ode_solvers::Dop853::from_param(
        IndexOne,
        0.0,
        t_final,
        t_final,
        ode_solvers::DVector::from_vec(y0),
        1e-13,
        1e-13,
        0.9,
        0.0,
        0.333,
        6.0,
        t_final,
        0.0,
        u32::MAX,
        1000,
        ode_solvers::OutputType::Sparse,
    );
    ode.integrate().expect("reference");
    let (_, ys) = ode.results().get();
    let y_ref = ys.last().expect("a final state").clone();
    let mut pts = Vec::new();
    for h in [0.02, 0.01, 0.005] {
        let end = Integrator::new(&MODEL, Scheme::lobatto(4).expect("s"), h)
            .expect("integrator")
            .final_state(init, t_final)
            .expect("constrained run");
        let eq = (0..4)
            .map(|a| (end.q[a] - y_ref[a]).abs())
            .fold(0.0, f64::max);
        let ev = (0..4)
            .map(|a| (end.v[a] - y_ref[4 + a]).abs())
            .fold(0.0, f64::max);
        eprintln!("lobatto4 h = {h}: |q − q_ref| = {eq:.1e}, |v − v_ref| = {ev:.1e}");
        pts.push((h, eq.max(ev)));
    }
    let order = (pts[0].1 / pts[2].1).ln() / (pts[0].0 / pts[2].0).ln();
    eprintln!("lobatto4: order {order:.2} against the index-1 reference");
    assert!((order - 6.0).abs() < 0.5, "order {order:.2}");
    assert!(pts[2].1 < 1e-10, "{pts:?}");
    // The crank turned: the motor drives the loop.
    let end = Integrator::new(&MODEL, Scheme::lobatto(4).expect("s"), 0.01)
        .expect("integrator")
        .final_state(init, t_final)
        .expect("run");
    assert!((end.q[0] - q0[0]).abs() + (end.q[1] - q0[1]).abs() > 0.1);
}
