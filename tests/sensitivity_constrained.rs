//! Sensitivities of constrained models (DESIGN §11, §12): the tangent of the constrained
//! step, its multipliers and its end projection, against central differences of whole
//! fixed-step runs from initial data on the constraints (and parameters, the constraints'
//! own among them), and against the same pendulum in its angle, an independent
//! discretisation. `cargo test --release --test models_suite sensitivity_constrained::`.

use forced_vi::output;
use forced_vi::{
    forced_lagrangian, ForcedLagrangian, InitialState, Integrator, LinearPath, Scheme,
};
use forced_vi_models::models::CartesianPendulum;
use forced_vi_models::rigid_chain::RigidChain;
use nalgebra::DVector;

/// A pendulum in its angle: `L = ½ m l² θ̇² + m g l cos θ`, drag `−c l² θ̇` (the Cartesian
/// pendulum's drag `−c v` in the angle).
#[forced_lagrangian(
    coordinates(th),
    lagrangian = 0.5 * m * l * l * th_dot * th_dot + m * g * l * th.cos(),
    force(th = -c * l * l * th_dot),
)]
#[derive(Clone, Copy, Debug)]
struct AnglePendulum {
    m: f64,
    g: f64,
    l: f64,
    c: f64,
}

/// A pendulum whose pivot swings along `x` as `a sin(w t)`: a constraint that reads the time
/// and two parameters.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 9.81 * y,
    force(x = -c * x_dot, y = -c * y_dot),
    constraints(0.5 * ((x - a * (w * t).sin()) * (x - a * (w * t).sin()) + y * y - r * r)),
)]
#[derive(Clone, Copy, Debug)]
struct SwingingPivot {
    a: f64,
    w: f64,
    r: f64,
    c: f64,
}

/// A double pendulum in Cartesian coordinates: two constraints, masses and lengths as
/// parameters.
#[forced_lagrangian(
    coordinates(x1, y1, x2, y2),
    lagrangian = 0.5 * m1 * (x1_dot * x1_dot + y1_dot * y1_dot)
        + 0.5 * m2 * (x2_dot * x2_dot + y2_dot * y2_dot)
        - 9.81 * (m1 * y1 + m2 * y2),
    force(x1 = -c * x1_dot, y1 = -c * y1_dot, x2 = -c * x2_dot, y2 = -c * y2_dot),
    constraints(
        0.5 * (x1 * x1 + y1 * y1 - l1 * l1),
        0.5 * ((x2 - x1) * (x2 - x1) + (y2 - y1) * (y2 - y1) - l2 * l2),
    ),
)]
#[derive(Clone, Copy, Debug)]
struct CartesianDouble {
    m1: f64,
    m2: f64,
    l1: f64,
    l2: f64,
    c: f64,
}

/// A model with its initial positions and velocities.
type Start<M, const N: usize> = (M, [f64; N], [f64; N]);

/// A case: a model, its initial data on the constraints and its parameters, all from one
/// vector `x` (the model's parameters first, in the order of its `parameter_names`, then
/// those of the initial data).
struct Case<M, const N: usize> {
    name: &'static str,
    build: fn(&[f64]) -> Start<M, N>,
    x: Vec<f64>,
    params: usize,
}

/// The final `(q, v)` of a fixed-step run from the case at `x`, and (with `tangents`) the
/// derivative of it in `x` from the carried tangent: `wrt_initial · ∂(q₀, v₀)/∂x` (by
/// central differences of the initial data alone, which are closed forms) plus the
/// parameters' columns.
fn end_state<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    x: &[f64],
    (scheme, h, t_final): (&Scheme, f64, f64),
) -> DVector<f64> {
    end_state_on(case, x, (scheme, h, t_final), LinearPath::Auto)
}

/// [`end_state`] on the backend of `path`.
fn end_state_on<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    x: &[f64],
    (scheme, h, t_final): (&Scheme, f64, f64),
    path: LinearPath,
) -> DVector<f64> {
    let (model, q0, v0) = (case.build)(x);
    let integ = Integrator::new(&model, scheme.clone(), h)
        .expect("an integrator")
        .linear_path(path);
    let end = integ
        .final_state(InitialState::from_velocity(q0, v0), t_final)
        .expect("a run from data on the constraints");
    DVector::from_iterator(2 * N, end.q.iter().chain(end.v.iter()).copied())
}

/// The derivative of the final `(q, v)` along each entry of `x` from the carried tangent
/// of a run: `wrt_initial · ∂(q₀, v₀)/∂x_i` plus, for a parameter, its column. The initial
/// data's derivatives are central differences of their closed forms (exact to round-off at
/// this step). Only such directions, which keep the initial data on the constraints, are
/// the flow's: the tangent maps others too, as the discrete map's extension off the
/// constraints, which depends on the step.
fn along_x<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    sens: &forced_vi::Sensitivities<N>,
) -> nalgebra::DMatrix<f64> {
    let mut out = nalgebra::DMatrix::zeros(2 * N, case.x.len());
    for i in 0..case.x.len() {
        let d = 1e-6 * case.x[i].abs().max(1.0);
        let at = |sign: f64| {
            let mut x = case.x.clone();
            x[i] += sign * d;
            (case.build)(&x)
        };
        let ((_, qp, vp), (_, qm, vm)) = (at(1.0), at(-1.0));
        let dy0 = DVector::from_iterator(
            2 * N,
            (0..N)
                .map(|a| (qp[a] - qm[a]) / (2.0 * d))
                .chain((0..N).map(|a| (vp[a] - vm[a]) / (2.0 * d))),
        );
        let mut col = &sens.wrt_initial * dy0;
        if i < case.params {
            col += sens.wrt_parameters.column(i);
        }
        out.set_column(i, &col);
    }
    out
}

/// A sensitivity run of the case at its `x`: fixed steps of `h`, or (`adaptive`) at
/// `rtol = atol = h`.
fn tangents<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    scheme: &Scheme,
    (h, adaptive): (f64, bool),
    t_final: f64,
) -> forced_vi::Sensitivities<N> {
    tangents_on(case, scheme, (h, adaptive), t_final, LinearPath::Auto)
}

/// [`tangents`] on the backend of `path`.
fn tangents_on<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    scheme: &Scheme,
    (h, adaptive): (f64, bool),
    t_final: f64,
    path: LinearPath,
) -> forced_vi::Sensitivities<N> {
    let (model, q0, v0) = (case.build)(&case.x);
    let integ = if adaptive {
        Integrator::adaptive(&model, scheme.clone(), h, h)
    } else {
        Integrator::new(&model, scheme.clone(), h)
    };
    let sens = integ
        .expect("an integrator")
        .linear_path(path)
        .solve(
            InitialState::from_velocity(q0, v0),
            t_final,
            output::Tangents,
        )
        .expect("a sensitivity run");
    assert_eq!(sens.wrt_parameters.ncols(), case.params, "{}", case.name);
    sens
}

/// `max |tangent − differences| / max |differences|` over the directions of `x`, for a
/// scheme with fixed steps.
fn tangent_error<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    (scheme, h, t_final): (&Scheme, f64, f64),
    path: LinearPath,
) -> f64 {
    let run = (scheme, h, t_final);
    let sens = tangents_on(case, scheme, (h, false), t_final, path);
    let tangent = along_x(case, &sens);
    let (mut worst, mut size) = (0.0f64, 0.0f64);
    for i in 0..case.x.len() {
        let d = 1e-6 * case.x[i].abs().max(1.0);
        let at = |sign: f64| {
            let mut x = case.x.clone();
            x[i] += sign * d;
            x
        };
        let diff = (end_state_on(case, &at(1.0), run, path)
            - end_state_on(case, &at(-1.0), run, path))
            / (2.0 * d);
        worst = worst.max((tangent.column(i) - &diff).amax());
        size = size.max(diff.amax());
    }
    worst / size
}

fn pendulum_case() -> Case<CartesianPendulum, 2> {
    Case {
        name: "cartesian_pendulum",
        build: |x| {
            let model = CartesianPendulum {
                m: x[0],
                g: x[1],
                l: x[2],
                c: x[3],
            };
            let (l, th, om) = (x[2], x[4], x[5]);
            let q0 = [l * th.sin(), -l * th.cos()];
            let v0 = [l * om * th.cos(), l * om * th.sin()];
            (model, q0, v0)
        },
        x: vec![1.3, 9.81, 0.8, 0.3, 0.7, 0.4],
        params: 4,
    }
}

fn swinging_case() -> Case<SwingingPivot, 2> {
    Case {
        name: "swinging_pivot",
        build: |x| {
            let model = SwingingPivot {
                a: x[0],
                w: x[1],
                r: x[2],
                c: x[3],
            };
            let (aw, r, th, om) = (x[0] * x[1], x[2], x[4], x[5]);
            // The pivot at 0 and moving at `a w` at t = 0.
            let q0 = [r * th.sin(), -r * th.cos()];
            let v0 = [aw + r * om * th.cos(), r * om * th.sin()];
            (model, q0, v0)
        },
        x: vec![0.2, 3.0, 1.1, 0.1, 0.5, -0.3],
        params: 4,
    }
}

fn double_case() -> Case<CartesianDouble, 4> {
    Case {
        name: "cartesian_double",
        build: |x| {
            let model = CartesianDouble {
                m1: x[0],
                m2: x[1],
                l1: x[2],
                l2: x[3],
                c: x[4],
            };
            let (l1, l2, a, b, wa, wb) = (x[2], x[3], x[5], x[6], x[7], x[8]);
            let (x1, y1) = (l1 * a.sin(), -l1 * a.cos());
            let (u1, w1) = (l1 * wa * a.cos(), l1 * wa * a.sin());
            let q0 = [x1, y1, x1 + l2 * b.sin(), y1 - l2 * b.cos()];
            let v0 = [u1, w1, u1 + l2 * wb * b.cos(), w1 + l2 * wb * b.sin()];
            (model, q0, v0)
        },
        x: vec![1.0, 0.7, 1.0, 0.8, 0.05, 0.9, -0.4, 0.2, 0.5],
        params: 5,
    }
}

#[test]
fn the_parameter_names_follow_the_fields() {
    let m = CartesianPendulum::DEFAULT;
    assert_eq!(m.parameter_names(), ["m", "g", "l", "c"]);
    let s = SwingingPivot {
        a: 0.0,
        w: 0.0,
        r: 1.0,
        c: 0.0,
    };
    assert_eq!(s.parameter_names(), ["a", "w", "r", "c"]);
}

#[test]
fn constrained_tangents_match_central_differences() {
    // On both backends: the sparse one takes its terms from its own kernels (the
    // constraints' `G` and curvature, the end's blocks and saddle-point factors).
    for path in [LinearPath::Dense, LinearPath::Sparse] {
        for s in 2..=5 {
            let scheme = Scheme::lobatto(s).unwrap();
            let run = (&scheme, 0.02, 1.5);
            let e1 = tangent_error(&pendulum_case(), run, path);
            let e2 = tangent_error(&swinging_case(), run, path);
            let e3 = tangent_error(&double_case(), (&scheme, 0.02, 1.0), path);
            println!(
                "{path:?} lobatto{s}: pendulum {e1:.2e}, swinging pivot {e2:.2e}, double {e3:.2e}"
            );
            // Measured: 1e-11 to 1.5e-10, the differences' own round-off (`ε |x| / δ`).
            // With the step polynomial's end slope in place of the projected velocity,
            // 3e-6 (lobatto4) to 8.6e-3 (lobatto2).
            for (name, e) in [("pendulum", e1), ("swinging", e2), ("double", e3)] {
                assert!(e < 1e-8, "{path:?} lobatto{s} {name}: {e:.2e}");
            }
        }
    }
}

/// The Cartesian pendulum's tangent, mapped to its angle (`dθ = (x dy − y dx)/l²`), against
/// the pendulum written in its angle: two discretisations, equal to their own errors.
#[test]
fn constrained_tangent_matches_the_angle_pendulum() {
    let (m, g, l, c) = (1.3, 9.81, 0.8, 0.3);
    let (th, om) = (0.7f64, 0.4f64);
    let (h, t_final) = (0.01, 2.0);
    let scheme = Scheme::lobatto(4).unwrap();
    let cart = CartesianPendulum { m, g, l, c };
    let q0 = [l * th.sin(), -l * th.cos()];
    let v0 = [l * om * th.cos(), l * om * th.sin()];
    let sc = Integrator::new(&cart, scheme.clone(), h)
        .unwrap()
        .solve(
            InitialState::from_velocity(q0, v0),
            t_final,
            output::Tangents,
        )
        .unwrap();
    let angle = AnglePendulum { m, g, l, c };
    let sa = Integrator::new(&angle, scheme, h)
        .unwrap()
        .solve(
            InitialState::from_velocity([th], [om]),
            t_final,
            output::Tangents,
        )
        .unwrap();
    // Directions of (θ₀, ω₀) in Cartesian initial data.
    let dth = DVector::from_vec(vec![
        l * th.cos(),
        l * th.sin(),
        -l * om * th.sin(),
        l * om * th.cos(),
    ]);
    let dom = DVector::from_vec(vec![0.0, 0.0, l * th.cos(), l * th.sin()]);
    let (x, y) = (sc.q[0], sc.q[1]);
    let (xd, yd) = (sc.v[0], sc.v[1]);
    let mut worst = 0.0f64;
    for (col, d) in [(0, dth), (1, dom)] {
        let t = &sc.wrt_initial * d;
        // θ = atan2(x, −y), ω = (x ẏ − y ẋ)/l².
        let dtheta = (-y * t[0] + x * t[1]) / (l * l);
        let domega = (t[0] * yd + x * t[3] - t[1] * xd - y * t[2]) / (l * l);
        worst = worst.max((dtheta - sa.wrt_initial[(0, col)]).abs());
        worst = worst.max((domega - sa.wrt_initial[(1, col)]).abs());
    }
    // Parameters: g, m, c enter both alike (l too, with the initial data fixed in θ).
    for name in ["m", "g", "c"] {
        let kc = cart
            .parameter_names()
            .iter()
            .position(|n| *n == name)
            .unwrap();
        let ka = angle
            .parameter_names()
            .iter()
            .position(|n| *n == name)
            .unwrap();
        let t = sc.wrt_parameters.column(kc);
        let dtheta = (-y * t[0] + x * t[1]) / (l * l);
        let domega = (t[0] * yd + x * t[3] - t[1] * xd - y * t[2]) / (l * l);
        worst = worst.max((dtheta - sa.wrt_parameters[(0, ka)]).abs());
        worst = worst.max((domega - sa.wrt_parameters[(1, ka)]).abs());
    }
    println!("Cartesian against angle: {worst:.2e}");
    assert!(worst < 1e-10, "{worst:.2e}");
}

/// With tolerances the step sequence is held fixed; the tangent of an adaptive run is that of
/// its steps, and so close to a fine fixed-step run's along the constraints.
#[test]
fn adaptive_constrained_tangents_follow_fixed_ones() {
    let case = double_case();
    let scheme = Scheme::lobatto(4).unwrap();
    let fine = along_x(&case, &tangents(&case, &scheme, (1e-3, false), 1.0));
    for tol in [1e-6, 1e-9] {
        let sens = tangents(&case, &scheme, (tol, true), 1.0);
        let e = (along_x(&case, &sens) - &fine).amax() / fine.amax();
        println!("tol {tol:.0e}: {} steps, {e:.2e}", sens.stats.steps);
        assert!(e < 10.0 * tol, "tol {tol:.0e}: {e:.2e}");
    }
}

/// The backward pass of a constrained model (`output::adjoint`) is the transpose of its
/// forward tangent: `wrt_initialᵀ g` and `wrt_parametersᵀ g` to round-off, on both backends,
/// lobatto2..5, for the three cases (parameters in the constraints, a constraint that reads
/// `t`, two constraints), fixed and adaptive steps.
fn transposed_tangent_error<M: ForcedLagrangian<N>, const N: usize>(
    case: &Case<M, N>,
    scheme: &Scheme,
    (h, adaptive): (f64, bool),
    path: LinearPath,
) -> f64 {
    let t_final = 1.0;
    let sens = tangents_on(case, scheme, (h, adaptive), t_final, path);
    let (model, q0, v0) = (case.build)(&case.x);
    let integ = if adaptive {
        Integrator::adaptive(&model, scheme.clone(), h, h)
    } else {
        Integrator::new(&model, scheme.clone(), h)
    };
    // ℓ with ∂ℓ/∂q_T = q_T, ∂ℓ/∂v_T = (1, 2, …).
    let gv = nalgebra::SVector::<f64, N>::from_fn(|i, _| 1.0 + i as f64);
    let grad = integ
        .unwrap()
        .linear_path(path)
        .solve(
            InitialState::from_velocity(q0, v0),
            t_final,
            output::adjoint(|e| (e.q, gv)),
        )
        .expect("a constrained adjoint");
    assert!(grad.tape_bytes > 0);
    let g = DVector::from_iterator(2 * N, grad.q.iter().chain(gv.iter()).copied());
    let (fwd, fwd_p) = (sens.wrt_initial.tr_mul(&g), sens.wrt_parameters.tr_mul(&g));
    let scale = fwd.amax().max(fwd_p.amax());
    let e = (&grad.wrt_initial - fwd)
        .amax()
        .max((&grad.wrt_parameters - fwd_p).amax());
    e / scale
}

#[test]
fn constrained_adjoint_is_the_transposed_tangent() {
    for path in [LinearPath::Dense, LinearPath::Sparse] {
        for s in 2..=5 {
            let scheme = Scheme::lobatto(s).unwrap();
            let e1 = transposed_tangent_error(&pendulum_case(), &scheme, (0.02, false), path);
            let e2 = transposed_tangent_error(&swinging_case(), &scheme, (0.02, false), path);
            let e3 = transposed_tangent_error(&double_case(), &scheme, (0.02, false), path);
            let e4 = transposed_tangent_error(&double_case(), &scheme, (1e-8, true), path);
            println!("{path:?} lobatto{s}: {e1:.2e} {e2:.2e} {e3:.2e}, adaptive {e4:.2e}");
            for e in [e1, e2, e3, e4] {
                assert!(e < 1e-11, "{path:?} lobatto{s}: {e:.2e}");
            }
        }
    }
}

/// The gradient of a loss of the final state (`output::adjoint`, a backward pass) against
/// central differences of the loss along each direction of the case.
#[test]
fn constrained_adjoint_matches_central_differences() {
    let case = swinging_case();
    let scheme = Scheme::lobatto(3).unwrap();
    let (h, t_final) = (0.02, 1.5);
    // ℓ = ½ |q_T|² + v_T,x.
    let loss = |y: &DVector<f64>| 0.5 * (y[0] * y[0] + y[1] * y[1]) + y[2];
    let (model, q0, v0) = (case.build)(&case.x);
    let grad = Integrator::new(&model, scheme.clone(), h)
        .unwrap()
        .solve(
            InitialState::from_velocity(q0, v0),
            t_final,
            output::adjoint(|e| (e.q, nalgebra::SVector::from([1.0, 0.0]))),
        )
        .expect("a constrained adjoint");
    let mut worst = 0.0f64;
    for i in 0..case.x.len() {
        let d = 1e-6 * case.x[i].abs().max(1.0);
        let at = |sign: f64| {
            let mut x = case.x.clone();
            x[i] += sign * d;
            x
        };
        let ((_, qp, vp), (_, qm, vm)) = ((case.build)(&at(1.0)), (case.build)(&at(-1.0)));
        let dy0: Vec<f64> = (0..2)
            .map(|a| (qp[a] - qm[a]) / (2.0 * d))
            .chain((0..2).map(|a| (vp[a] - vm[a]) / (2.0 * d)))
            .collect();
        let mut mine: f64 = grad.wrt_initial.iter().zip(&dy0).map(|(g, y)| g * y).sum();
        if i < case.params {
            mine += grad.wrt_parameters[i];
        }
        let run = (&scheme, h, t_final);
        let diff = (loss(&end_state(&case, &at(1.0), run))
            - loss(&end_state(&case, &at(-1.0), run)))
            / (2.0 * d);
        worst = worst.max((mine - diff).abs() / diff.abs().max(1.0));
    }
    println!("adjoint against differences: {worst:.2e}");
    assert!(worst < 1e-8, "{worst:.2e}");
}

/// The rigid chain's hand-written sparse kernels (`G`, the curvature, the node blocks) on
/// the sparse backend against the dense backend's dual numbers over all coordinates: the
/// tangent and the loss gradient to round-off, lobatto2..5. A chain of 256 links (512
/// coordinates), beyond what the dense tangent can take, runs too.
#[test]
fn constrained_tangents_on_the_sparse_backend_match_the_dense_backend() {
    let chain = RigidChain::<16>::default();
    let init = chain.initial();
    for s in 2..=5 {
        let integ = Integrator::new(&chain, Scheme::lobatto(s).unwrap(), 2e-3).unwrap();
        assert_eq!(integ.path_for(&init), Ok(LinearPath::Sparse));
        let sparse = integ.solve(init, 0.1, output::Tangents).unwrap();
        let dense = integ
            .clone()
            .linear_path(LinearPath::Dense)
            .solve(init, 0.1, output::Tangents)
            .unwrap();
        let off = (&sparse.wrt_initial - &dense.wrt_initial).amax() / dense.wrt_initial.amax();
        println!("lobatto{s}: sparse against dense {off:.2e}");
        // Measured: 7.9e-14 to 2e-13.
        assert!(off < 1e-11, "lobatto{s}: {off:.2e}");
        let loss = |end: &forced_vi::FinalState<16>| (end.q, nalgebra::SVector::zeros());
        let grad = integ.solve(init, 0.1, output::adjoint(loss)).unwrap();
        let g = DVector::from_fn(32, |i, _| if i < 16 { sparse.q[i] } else { 0.0 });
        let mine = (sparse.wrt_initial.transpose() * g - &grad.wrt_initial).amax();
        assert!(mine < 1e-12 * grad.wrt_initial.amax(), "{mine:.2e}");
    }
    let big = RigidChain::<512>::default();
    let integ = Integrator::new(&big, Scheme::lobatto(3).unwrap(), 1e-3).unwrap();
    let sens = integ.solve(big.initial(), 3e-3, output::Tangents).unwrap();
    assert_eq!(sens.wrt_initial.shape(), (1024, 1024));
    assert!(sens.wrt_initial.iter().all(|x| x.is_finite()));
}

/// Without forces the constrained Lobatto map is symplectic on the constraints (RATTLE and
/// its higher-order kin): for two directions `u, w` tangent to them in `(q, p)`,
/// `ω(M u, M w) = ω(u, w)`. With drag the form contracts instead, so the check can fail.
#[test]
fn unforced_constrained_map_is_symplectic_on_the_constraints() {
    let (m, g, l) = (1.3, 9.81, 0.8);
    let (th, om) = (0.7f64, 0.4f64);
    let q0 = [l * th.sin(), -l * th.cos()];
    let v0 = [l * om * th.cos(), l * om * th.sin()];
    // (dq, dp) along θ and along ω; p = m v.
    let u = [
        l * th.cos(),
        l * th.sin(),
        -m * l * om * th.sin(),
        m * l * om * th.cos(),
    ];
    let w = [0.0, 0.0, m * l * th.cos(), m * l * th.sin()];
    let form = |a: &[f64], b: &[f64]| a[0] * b[2] + a[1] * b[3] - a[2] * b[0] - a[3] * b[1];
    let before = form(&u, &w);
    for (c, s) in [(0.0, 2), (0.0, 3), (0.0, 4), (0.0, 5), (0.3, 3)] {
        let model = CartesianPendulum { m, g, l, c };
        let sens = Integrator::new(&model, Scheme::lobatto(s).unwrap(), 0.01)
            .unwrap()
            .solve(InitialState::from_velocity(q0, v0), 5.0, output::Tangents)
            .unwrap();
        // The map in (q, p): dv₀ = dp₀/m in, dp_T = m dv_T out.
        let map = |x: &[f64; 4]| {
            let d = DVector::from_vec(vec![x[0], x[1], x[2] / m, x[3] / m]);
            let y = &sens.wrt_initial * d;
            [y[0], y[1], m * y[2], m * y[3]]
        };
        let after = form(&map(&u), &map(&w));
        let change = (after - before).abs() / before.abs();
        println!("c = {c}, lobatto{s}: ω changed by {change:.2e}");
        if c == 0.0 {
            assert!(change < 1e-11, "lobatto{s}: {change:.2e}");
        } else {
            assert!(change > 0.1, "drag: {change:.2e}");
        }
    }
}

/// A Newton solve whose iterate is at the residual's round-off floor is not "diverged":
/// with factors kept from the first iteration, an iterate whose estimated error is a hair
/// above the increments' round-off took corrections of noise, its residual rose three times
/// far below the floor (2e-17 to 7e-17, the floor 1.4e-14), and the run ended in
/// `NewtonFailed` (diverged, residual 6e-15) at step 19. Measured on 400 starts of the
/// double pendulum near `double_case`'s (half of them within 1e-5 of it, the rest
/// within 15 %; 4800 runs of lobatto2–7 at h = 0.01, 0.02 and 0.04 on both backends): two
/// such failures before the fix, none after. This runs the 134 starts at h = 0.02, lobatto5,
/// on both backends.
#[test]
fn trust_newton_noise_below_the_floor_is_not_divergence() {
    let mut seed = 12345u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let base = double_case().x;
    let scheme = Scheme::lobatto(5).unwrap();
    let mut runs = 0;
    for trial in 0..400 {
        let spread = if trial % 2 == 0 { 0.3 } else { 1e-5 };
        let x: Vec<f64> = base
            .iter()
            .map(|v| v * (1.0 + spread * (rnd() - 0.5)))
            .collect();
        if (trial / 2) % 3 != 1 {
            continue;
        }
        let (model, q0, v0) = (double_case().build)(&x);
        for path in [LinearPath::Dense, LinearPath::Sparse] {
            let integ = Integrator::new(&model, scheme.clone(), 0.02)
                .unwrap()
                .linear_path(path);
            let end = integ.final_state(InitialState::from_velocity(q0, v0), 1.0);
            assert!(
                end.is_ok(),
                "trial {trial}, {path:?}: {}",
                end.unwrap_err().error
            );
            runs += 1;
        }
    }
    assert_eq!(runs, 268);
}
