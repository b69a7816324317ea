//! The reference of [`#[forced_lagrangian]`](crate::forced_lagrangian), and what a run
//! promises.
//!
//! Every form that the attribute accepts is shown below by an example that runs as a
//! doctest, and every example asserts what it shows. Sections:
//!
//! - [Writing a model](#writing-a-model): the attribute, parameters, coordinates;
//! - [Scalar coordinates](#scalar-coordinates);
//! - [Arrays of literal length](#arrays-of-literal-length), mixed with scalars;
//! - [Arrays of length `N`](#arrays-of-length-n), `N` a const parameter;
//! - [Expressions](#expressions): `let`, `if`, `for`, `(a..b).map(..).sum()`, methods;
//! - [Forces](#forces): none, `x = ..`, `q[i] = ..`, `q = [..]`;
//! - [Time](#time-driven-models): `t` in the Lagrangian and the force;
//! - [Constraints](#constraints): `constraints(g1, g2, ...)`, holonomic `g(t, q) = 0`;
//! - [Parameters and sensitivities](#parameters-and-sensitivities): derivatives of the
//!   flow in the initial data and the struct's fields, forward and adjoint;
//! - [`STRUCTURE`](#structure): what the generated flags mean;
//! - [The sparse backend](#the-sparse-backend): when [`LinearPath::Auto`] takes it;
//! - [What an `Ok` promises](#what-an-ok-promises);
//! - [Bad input](#bad-input): the errors a new user meets first, with their messages;
//! - [Compile errors](#compile-errors): the mistakes the attribute rejects;
//! - [Export](#export): trajectories to JSON or CSV with the `serde` feature.
//!
//! # Writing a model
//!
//! `#[forced_lagrangian(...)]` goes on a struct and writes its [`ForcedLagrangian`] impl.
//! Its arguments, in this order:
//!
//! - `coordinates(...)`: the generalised coordinates, scalars (`x`) and arrays
//!   (`q: [f64; 4]`, `q: [f64; N]`). Each coordinate `x` comes with its velocity `x_dot`
//!   (`q_dot[i]` for an array).
//! - `lagrangian = <expr>`: the Lagrangian `L(q, v)`, an ordinary Rust expression over the
//!   coordinates, velocities, parameters and the time `t`.
//! - `force(...)`, optional: the non-conservative generalised force `F(q, v)`, one entry per
//!   coordinate.
//! - `constraints(...)`, optional: holonomic constraints, expressions of the coordinates
//!   (and `t`) that must vanish ([Constraints](#constraints)).
//!
//! The struct's fields are the model's parameters; each is an `f64` and is read by name in
//! the expressions (`k`, not `self.k`). The struct may be generic over one const parameter,
//! the length of its array coordinate. The macro checks the model at compile time, with the
//! error at your own tokens ([Compile errors](#compile-errors)), differentiates polynomial
//! terms at compile time and the others with dual numbers (num-dual), and fills in
//! [`ForcedLagrangian::STRUCTURE`] from the expressions.
//!
//! The model then runs through an [`Integrator`]: a scheme ([`Scheme`]), a step size (or
//! tolerances), an initial state ([`InitialState`]) and a final time.
//!
//! # Scalar coordinates
//!
//! A damped oscillator: one coordinate `x`, its velocity `x_dot`, three parameters. The
//! generated impl is an ordinary [`ForcedLagrangian<1>`](ForcedLagrangian), and the run
//! matches the exact solution.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// m ẍ + c ẋ + k x = 0.
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = 0.5 * m * x_dot * x_dot - 0.5 * k * x * x,
//!     force(x = -c * x_dot),
//! )]
//! struct Damped { m: f64, k: f64, c: f64 }
//!
//! let model = Damped { m: 1.0, k: 4.0, c: 0.1 };
//! assert_eq!(model.coordinate_names(), ["x"]);
//! assert_eq!(model.lagrangian::<f64>(&[1.0], &[3.0]), 4.5 - 2.0);
//! assert_eq!(model.force::<f64>(&[1.0], &[3.0]), [-0.1 * 3.0]);
//!
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(InitialState::from_velocity([1.0], [0.0]), 10.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! let end = run.last().expect("a run keeps its initial record");
//! // x(t) = e^{-ct/2} (cos ωt + c/(2ω) sin ωt), ω² = k − c²/4.
//! let w = (4.0f64 - 0.0025).sqrt();
//! let exact = (-0.5f64).exp() * ((10.0 * w).cos() + 0.05 / w * (10.0 * w).sin());
//! assert!((end.q[0] - exact).abs() < 1e-7);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! Several scalars are listed in order, `coordinates(x, y)`: the paper's coupled van der
//! Pol oscillators in the [crate docs](crate) and the README are an example.
//!
//! # Arrays of literal length
//!
//! `q: [f64; 4]` is four coordinates `q[0] .. q[3]` with velocities `q_dot[0] ..`; arrays and
//! scalars mix, and are laid out in the order written (here `N = 4 + 1 + 2 = 7`). An index
//! that can leave a literal length is a compile error. The force shows its three forms:
//! one entry per array element `q[i] = ..` (`i` runs over the array), a scalar `s = ..`, and
//! a whole array `p = [.., ..]`.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(q: [f64; 4], s, p: [f64; 2]),
//!     lagrangian = (0..4).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
//!         + 0.5 * (s_dot * s_dot + p_dot[0] * p_dot[0] + p_dot[1] * p_dot[1])
//!         - {
//!             let mut v = 0.0;
//!             for i in 0..3 {
//!                 let d = q[i + 1] - q[i];
//!                 v += 0.5 * k * d * d;
//!             }
//!             v
//!         }
//!         - 0.5 * (s * s + p[0] * p[0] + p[1] * p[1]),
//!     force(q[i] = -c * q_dot[i], s = 0.0, p = [-c * p_dot[0], -c * p_dot[1]]),
//! )]
//! struct Mixed { k: f64, c: f64 }
//!
//! let model = Mixed { k: 2.0, c: 0.1 };
//! assert_eq!(
//!     model.coordinate_names(),
//!     ["q[0]", "q[1]", "q[2]", "q[3]", "s", "p[0]", "p[1]"]
//! );
//! let v = [1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0];
//! assert_eq!(model.force::<f64>(&[0.0; 7], &v), [-0.1, 0.0, 0.0, 0.0, 0.0, -0.1, 0.0]);
//!
//! // `s` is a free, undamped oscillator: s(t) = sin t.
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(InitialState::from_velocity([0.0; 7], v), 2.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! let end = run.last().expect("a run keeps its initial record");
//! assert!((end.q[4] - 2f64.sin()).abs() < 1e-9);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # Arrays of length `N`
//!
//! A struct generic over `const N: usize` may have one coordinate, `q: [f64; N]`; each
//! `Chain::<N>` is then a model with `N` coordinates. Indices are checked against `N` by
//! [`Integrator::new`] ([`Error::InvalidModel`]) rather than by the compiler; an index reached
//! only for some values of the coordinates reads NaN (an [`Error::NonFiniteModel`]), never
//! a panic. The Lagrangian below is a sum of local terms, so the model also gets sparse
//! node kernels ([The sparse backend](#the-sparse-backend)).
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// N masses between two walls: nonlinear springs (FPU-β), linear damping.
//! #[forced_lagrangian(
//!     coordinates(q: [f64; N]),
//!     lagrangian = (0..N).map(|i| 0.5 * m * q_dot[i] * q_dot[i]).sum()
//!         - (0..=N)
//!             .map(|i| {
//!                 let left = if i == 0 { 0.0 } else { q[i - 1] };
//!                 let right = if i == N { 0.0 } else { q[i] };
//!                 let d = right - left;
//!                 0.5 * k * d * d + 0.25 * beta * d.powi(4)
//!             })
//!             .sum(),
//!     force(q[i] = -c * q_dot[i]),
//! )]
//! struct Chain<const N: usize> { m: f64, k: f64, beta: f64, c: f64 }
//!
//! let chain = Chain::<32> { m: 1.0, k: 1.0, beta: 1.0, c: 0.01 };
//! assert_eq!(chain.coordinate_names()[31], "q"); // names are `&'static str`: no index for `N`
//! let q0: [f64; 32] = std::array::from_fn(|i| (std::f64::consts::PI * (i + 1) as f64 / 33.0).sin());
//! let run = Integrator::new(&chain, Scheme::lobatto(3)?, 0.05)?
//!     .solve(InitialState::from_velocity(q0, [0.0; 32]), 5.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! let (start, end) = (&run.records[0], run.last().expect("a run keeps its initial record"));
//! assert!(end.energy < start.energy); // damping takes energy out...
//! assert!(end.energy_balance.abs() < 1e-6); // ...and E − E0 − W stays near zero
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # Expressions
//!
//! `lagrangian = ..` and the force entries are Rust expressions over `f64` values:
//!
//! - arithmetic, with parameters and literals written as plain numbers (`0.5 * x`,
//!   `x_dot * x_dot / 2`, `2 * x`: an integer literal is an `f64` where a number is meant,
//!   but arithmetic between integers is integer arithmetic, and a truncating `3 / 2` used as
//!   a number is a compile error, see [Compile errors](#compile-errors));
//! - the methods of num-dual's `DualNum`: `sin`, `cos`, `exp`, `ln`, `sqrt`, `powi`,
//!   `powf`, `tanh`, `abs`, `mul_add`, ..., and `x.max(y)`, `x.min(y)`, `k.powf(x)`;
//! - blocks with `let` (and `let mut`), `if`/`else` (on coordinates, parameters or `t`),
//!   `for` loops over integer ranges, and index sums `(a..b).map(|i| ..).sum()`.
//!
//! `tanh` is taken in a form whose derivatives stay finite at any argument (num-dual's own,
//! `sinh / cosh`, is NaN from `|x| ≈ 355`), so a regularised Coulomb friction
//! `−mu * (x_dot / eps).tanh()` runs at any speed; and `powf` with a real exponent in one
//! that is exact at a zero or tiny base (num-dual's is NaN at `0.0` and infinite at
//! `1e-160.powf(0.5)`), so `x.powf(2.5)` runs from `x = 0`. A force that jumps (`signum`, or an `if`
//! on a velocity) is accepted, but a run across the jump ends in a typed error there (see
//! [`control`](crate::control), "Forces that jump"): regularise it.
//!
//! Names starting with `__fvi`, and `__D`, are reserved; `t` is the time.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// A pendulum on a spring that only pulls: a slack spring (r < 0) exerts no force.
//! #[forced_lagrangian(
//!     coordinates(theta, r),
//!     lagrangian = {
//!         let len = l0 + r;
//!         let stretch = if r > 0.0 { 0.5 * k * r * r } else { 0.0 };
//!         0.5 * m * (r_dot * r_dot + len * len * theta_dot * theta_dot)
//!             + m * g * len * theta.cos()
//!             - stretch
//!     },
//!     force(theta = -mu * theta_dot, r = 0),
//! )]
//! struct SpringPendulum { m: f64, g: f64, l0: f64, k: f64, mu: f64 }
//!
//! let model = SpringPendulum { m: 2.0, g: 9.81, l0: 1.0, k: 50.0, mu: 0.1 };
//! let (q, v) = ([0.3, 0.1], [0.5, -0.2]);
//! let len = 1.1;
//! let by_hand = 0.5 * 2.0 * (0.04 + len * len * 0.25) + 2.0 * 9.81 * len * 0.3f64.cos()
//!     - 0.5 * 50.0 * 0.01;
//! assert!((model.lagrangian::<f64>(&q, &v) - by_hand).abs() < 1e-12);
//! // The `if` takes the other branch for a slack spring.
//! let slack = model.lagrangian::<f64>(&[0.0, -0.1], &[0.0, 0.0]);
//! assert!((slack - 2.0 * 9.81 * 0.9).abs() < 1e-12);
//!
//! // Index sums and `for` loops over a range, with methods and integer literals.
//! #[forced_lagrangian(
//!     coordinates(q: [f64; 3]),
//!     lagrangian = (0..3).map(|i| q_dot[i] * q_dot[i] / 2).sum() - {
//!         let mut v = 0.0;
//!         for i in 0..3 {
//!             v += a.powf(q[i]) + q[i].max(0.0) - 2 * q[i].min(0.0).powi(2);
//!         }
//!         v
//!     },
//! )]
//! struct Terms { a: f64 }
//!
//! let model = Terms { a: 2.0 };
//! let l = model.lagrangian::<f64>(&[1.0, -1.0, 0.0], &[1.0, 0.0, 2.0]);
//! // T = (1 + 4) / 2; V = (2 + 1) + (0.5 + 0 − 2) + (1 + 0 − 0)
//! assert!((l - (2.5 - 2.5)).abs() < 1e-12);
//! ```
//!
//! # Forces
//!
//! `force(...)` is optional: without it the model is conservative, `STRUCTURE.has_force`
//! is `false`, and the energy error of the run stays bounded (a variational integrator
//! conserves a nearby energy: `E` oscillates by `O(h^order)` and does not drift). With it, every coordinate has exactly one entry:
//!
//! | form | for | example |
//! |---|---|---|
//! | `x = <expr>` | a scalar coordinate `x` | `x = -c * x_dot` |
//! | `q[i] = <expr>` | every element of an array `q`, `i` running over its indices | `q[i] = -c * q_dot[i]` |
//! | `q = [<expr>, ...]` | an array of literal length, element by element | `p = [-c * p_dot[0], 0.0]` |
//!
//! A coordinate without a force still needs its entry (`y = 0.0`). The `q[i] = ..` and
//! `q = [..]` forms are in [Arrays of literal length](#arrays-of-literal-length); a
//! conservative model:
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(theta),
//!     lagrangian = 0.5 * len * len * theta_dot * theta_dot + g * len * theta.cos(),
//! )]
//! struct Pendulum { g: f64, len: f64 }
//!
//! let model = Pendulum { g: 9.81, len: 1.0 };
//! assert!(!<Pendulum as ForcedLagrangian<1>>::STRUCTURE.has_force);
//! assert_eq!(model.force::<f64>(&[0.3], &[0.1]), [0.0]);
//! let run = Integrator::new(&model, Scheme::lobatto(4)?, 0.05)?
//!     .solve(InitialState::from_velocity([2.5], [0.0]), 20.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! // No force: E − E0 is the whole energy balance. Order 6 at h = 0.05: below 1e-7 over
//! // the 400 steps, with no drift (the second half is no worse than the first).
//! let worst = |rs: &[StepRecord<1>]| rs.iter().map(|r| r.energy_balance.abs()).fold(0.0, f64::max);
//! let (first, second) = run.records.split_at(200);
//! assert!(worst(first) < 1e-7 && worst(second) < 2.0 * worst(first));
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # Time: driven models
//!
//! The Lagrangian and the force may use `t`, the time, so no coordinate or parameter may be
//! called `t`. Such a model gets [`ForcedLagrangian::lagrangian_at`] and
//! [`ForcedLagrangian::force_at`] (its `lagrangian` and `force` are the values at `t = 0`)
//! and `STRUCTURE.uses_time`; the energy balance becomes `E − E0 − W + ∫ ∂L/∂t`. Its
//! specialised kernels take the node's time ([`ForcedLagrangian::node_gradient_at`],
//! [`ForcedLagrangian::node_jacobian_at`]). A model without `t` pays nothing for the
//! feature.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// ẍ + δẋ + αx + βx³ = γ cos ωt.
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = x_dot * x_dot / 2 - alpha * x * x / 2 - beta * x.powi(4) / 4,
//!     force(x = -delta * x_dot + gamma * (omega * t).cos()),
//! )]
//! struct DrivenDuffing { delta: f64, alpha: f64, beta: f64, gamma: f64, omega: f64 }
//!
//! let model = DrivenDuffing { delta: 0.3, alpha: -1.0, beta: 1.0, gamma: 0.5, omega: 1.2 };
//! assert!(<DrivenDuffing as ForcedLagrangian<1>>::STRUCTURE.uses_time);
//! let t = std::f64::consts::PI / 1.2; // cos(ωt) = −1
//! assert!((model.force_at::<f64>(t, &[0.0], &[0.0])[0] + 0.5).abs() < 1e-15);
//!
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(InitialState::from_velocity([1.0], [0.0]), 10.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! assert!(run.records.iter().all(|r| r.energy_balance.abs() < 1e-6));
//!
//! /// A time-dependent mass: `STRUCTURE.constant_mass` is then `false`.
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = 0.5 * (1.0 + eps * (w * t).sin()) * x_dot * x_dot - 0.5 * x * x,
//! )]
//! struct Breathing { eps: f64, w: f64 }
//! let s = <Breathing as ForcedLagrangian<1>>::STRUCTURE;
//! assert!(s.uses_time && !s.constant_mass);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! A model written by hand (without the attribute) overrides `lagrangian_at`/`force_at`
//! and sets `uses_time` in its `STRUCTURE` ([`Structure::GENERAL_DRIVEN`]); the integrator
//! checks the flag on the first step. It takes the general dual-number kernels of
//! [`crate::model::general`].
//!
//! # Constraints
//!
//! `constraints(g1, g2, ...)` lists expressions of the coordinates, the parameters and `t`
//! that must vanish on the motion (DESIGN §11). The step then carries multipliers at its
//! control points (the constrained Lobatto IIIA–IIIB pair; RATTLE for `lobatto2`), keeps
//! `g = 0` and `G v + ∂g/∂t = 0` to round-off at every step, and reports the mean
//! constraint force `−Gᵀλ` of each step in [`StepRecord::constraint_force`](crate::StepRecord)
//! and `max(|g|, |G v + ∂g/∂t|)` in `constraint_residual`. A constraint that reads `t` (a
//! moving support, a driven linkage) moves the velocity-level constraint by its rate
//! `∂g/∂t`, which the runtime takes from `constraints` with a dual number in `t`, and its
//! forces do the work `∫ λᵀ ∂g/∂t dt`, which the energy ledger adds. When no constraint
//! names `t`, the attribute promises fixed constraints
//! ([`ForcedLagrangian::CONSTRAINTS_READ_TIME`] `= false`) and neither is computed. Fixed and adaptive steps, dense output and
//! ensembles work, and so do sensitivities ([`output::Tangents`](crate::output::Tangents))
//! on the dense backend: the multipliers join the step's unknowns, the end projection is
//! differentiated too, and parameters that shape the constraints (a length) get their
//! columns from [`ForcedLagrangian::constraints_with`]. Only directions that keep the
//! initial data on the constraints are the flow's; the tangent maps others as the discrete
//! map's extension, which depends on the step. A loss gradient
//! ([`output::adjoint`](crate::output::adjoint)) of a constrained model is a backward pass
//! through the same terms, on either backend. Non-Lobatto schemes are
//! [`Error::UnsupportedConstraints`]. A large model runs on the sparse backend when its
//! hand-written [`SparseNode`](crate::model::SparseNode) kernels evaluate the constraints
//! too ([`SparseNode::sparse_constraint_count`](crate::model::SparseNode::sparse_constraint_count),
//! [`SparseNode::eval_constraints`](crate::model::SparseNode::eval_constraints)); for a model
//! written with the attribute, whose sparse kernels leave the constraints out, the runtime
//! differentiates `constraints` with dual numbers (`N` evaluations of `g` per node: meant for
//! a few constraints on a large model). Initial data must lie on the constraints
//! ([`Error::InconsistentInitialState`]); [`InitialState::projected`] puts it there.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! /// A spherical pendulum: three Cartesian coordinates, one rod.
//! #[forced_lagrangian(
//!     coordinates(x, y, z),
//!     lagrangian = 0.5 * m * (x_dot * x_dot + y_dot * y_dot + z_dot * z_dot) - m * g * z,
//!     constraints(0.5 * (x * x + y * y + z * z - l * l)),
//! )]
//! struct Spherical { m: f64, g: f64, l: f64 }
//!
//! let model = Spherical { m: 1.0, g: 9.81, l: 1.0 };
//! assert_eq!(model.constraint_count(), 1);
//! // Off the sphere, and a velocity across it: `projected` makes both consistent.
//! let init = InitialState::projected(&model, [0.6, 0.0, -0.9], [0.0, 1.0, 0.2])?;
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(init, 5.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! // Rotations about the vertical are a symmetry: L_z = m (x ẏ − y ẋ) is kept.
//! let lz = |r: &forced_vi::StepRecord<3>| r.q[0] * r.p[1] - r.q[1] * r.p[0];
//! let lz0 = lz(&run.records[0]);
//! assert!(run.records.iter().all(|r| (lz(r) - lz0).abs() < 1e-12));
//! assert!(run.records.iter().all(|r| r.constraint_residual < 1e-13));
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! A constraint may not read a velocity (nonholonomic constraints are not supported), and
//! a model needs fewer constraints than coordinates:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(
//!     coordinates(x, y),
//!     lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot),
//!     constraints(x * x_dot + y * y_dot), // error: reads the velocity `x_dot`
//! )]
//! struct Rolling {}
//! ```
//!
//! A model written by hand declares constraints by overriding
//! [`ForcedLagrangian::constraint_count`] and [`ForcedLagrangian::constraints`].
//!
//! Sensitivities of a constrained model carry its multipliers; only directions that keep
//! the initial data on the constraints are the flow's, such as a turn about the vertical:
//!
//! ```
//! use forced_vi::prelude::*;
//! # #[forced_lagrangian(
//! #     coordinates(x, y, z),
//! #     lagrangian = 0.5 * m * (x_dot * x_dot + y_dot * y_dot + z_dot * z_dot) - m * g * z,
//! #     constraints(0.5 * (x * x + y * y + z * z - l * l)),
//! # )]
//! # struct Spherical { m: f64, g: f64, l: f64 }
//! let model = Spherical { m: 1.0, g: 9.81, l: 1.0 };
//! let (q0, v0) = ([0.6, 0.0, -0.8], [0.0, 1.0, 0.0]);
//! let end = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(InitialState::from_velocity(q0, v0), 2.0, output::Tangents)
//!     .map_err(|failure| failure.error)?;
//! // The turn about the vertical of (q, v), applied to the start, comes out turned.
//! let turn = |q: &[f64], v: &[f64]| {
//!     nalgebra::DVector::from_vec(vec![-q[1], q[0], 0.0, -v[1], v[0], 0.0])
//! };
//! let moved = &end.wrt_initial * turn(&q0, &v0);
//! assert!((moved - turn(end.q.as_slice(), end.v.as_slice())).amax() < 1e-10);
//! // The mass scales the Lagrangian alone: the motion does not depend on it.
//! assert!(end.wrt_parameters.column(0).amax() < 1e-10);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # Parameters and sensitivities
//!
//! [`output::Tangents`](crate::output::Tangents) returns, with the final state, `∂(q_T, v_T)/∂(q_0, v_0)`
//! and `∂(q_T, v_T)/∂θ` for the struct's fields `θ`, in field order; for a scalar loss of
//! the final state, [`output::adjoint`](crate::output::adjoint) gives its gradient by the discrete
//! adjoint at the cost of about one more run (DESIGN §12). Both are exact derivatives of
//! the discrete flow (the factored step Jacobian, no finite differences). The forward
//! sensitivities carry a `2N × (2N + P)` matrix and are refused past
//! [`MAX_TANGENT_BYTES`](crate::MAX_TANGENT_BYTES) with [`Error::TangentTooLarge`]; the
//! adjoint runs at every size. The attribute
//! generates [`ForcedLagrangian::lagrangian_with`] and [`ForcedLagrangian::force_with`],
//! the model with its fields as dual numbers; a model written by hand declares no
//! parameters unless it overrides them and [`ForcedLagrangian::parameter_names`].
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * x * x,
//!     force(x = -c * x_dot),
//! )]
//! struct Damped { k: f64, c: f64 }
//!
//! let model = Damped { k: 1.0, c: 0.0 };
//! assert_eq!(model.parameter_names(), ["k", "c"]);
//! let integ = Integrator::new(&model, Scheme::lobatto(4)?, 0.01)?;
//! let init = InitialState::from_velocity([1.0], [0.0]);
//! let s = integ.solve(init, 1.0, output::Tangents)?;
//! // x(T) = cos(√k T): ∂x_T/∂x_0 = cos 1, ∂x_T/∂k = −(T/2) sin 1 at k = 1.
//! assert!((s.wrt_initial[(0, 0)] - 1f64.cos()).abs() < 1e-9);
//! assert!((s.wrt_parameters[(0, 0)] + 0.5 * 1f64.sin()).abs() < 1e-9);
//! // The adjoint gradient of ℓ = x_T agrees.
//! let g = integ.solve(init, 1.0, output::adjoint( |end| {
//!     (nalgebra::SVector::from([1.0]), nalgebra::SVector::zeros())
//! }))?;
//! assert!((g.wrt_parameters[0] - s.wrt_parameters[(0, 0)]).abs() < 1e-12);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # `STRUCTURE`
//!
//! [`ForcedLagrangian::STRUCTURE`] is a [`Structure`]: five flags that tell the integrator
//! what it may leave out. Each `false` (and `constant_mass: true`) is a promise about the
//! model for *every* state:
//!
//! | flag | means | the integrator then |
//! |---|---|---|
//! | `has_force: false` | `F ≡ 0` | skips the force and the work `W` |
//! | `force_uses_velocity: false` | `∂F/∂v ≡ 0` | leaves `∂F/∂v` out of the general kernels |
//! | `constant_mass: true` | `E = ∂²L/∂v²` constant and `C = ∂²L/∂v∂q ≡ 0` | builds the `E` part of the step Jacobian once per step size, skips `C`, solves for velocities in one linear step and skips the mass check at step ends |
//! | `linear: true` | `L` of degree at most two and `F` of degree at most one in `(q, v)`, with constant coefficients (no `t`): `A, B, C, E` constant | keeps one factorisation through fixed steps of one size, at any number of unknowns, and accepts the first Newton correction made with it as it would a fresh one's |
//! | `uses_time: true` | `L` or `F` depends on `t` | evaluates each node at its time and adds `∫ ∂L/∂t` to the balance |
//!
//! The attribute proves each claim from the expressions and claims nothing it cannot prove:
//! a value that depends on a condition on the coordinates, or changes in a loop, counts as
//! varying. A hand-written model starts from [`Structure::GENERAL`], which promises nothing;
//! a wrong promise gives wrong results, so claim only what holds. The integrator's first
//! step checks each promise at the initial state and beside it, and refuses a broken one
//! with [`Error::InvalidModel`]: `uses_time: false` under an `L` or `F` that changes with
//! `t`, `has_force: false` under a force that is not zero, `force_uses_velocity: false`
//! under a force that changes with `v`, `constant_mass: true` under a mass that changes
//! or an `L` that mixes `q` and `v` (along one direction: a check, not a proof), and
//! `linear: true` under second derivatives of `L` or first derivatives of `F` that change
//! with the state or the time (along three directions, likewise). Broken, the
//! last two left the positions unchanged but the sensitivities wrong by orders of magnitude
//! (measured on a one-coordinate model with the mass `1 + q²`).
//!
//! Beside `STRUCTURE`, [`ForcedLagrangian::CONSTRAINED`] is `false` for every model without
//! `constraints(...)`: the integrator then compiles none of a constrained step's code for it
//! (a smaller build). A hand-written model keeps the default `true` unless it has no
//! constraints; a model that declares constraints under `false` is refused with
//! [`Error::InvalidModel`].
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(x, y),
//!     lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * k * (x * x + y * y),
//!     force(x = -a * x.powi(3), y = -a * y.powi(3)),
//! )]
//! struct PositionForce { k: f64, a: f64 }
//! let s = <PositionForce as ForcedLagrangian<2>>::STRUCTURE;
//! assert!(s.has_force && !s.force_uses_velocity && s.constant_mass && !s.uses_time);
//!
//! /// A bead on a rotating parabola: the mass depends on x.
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = 0.5 * (1.0 + 4.0 * a * a * x * x) * x_dot * x_dot - g * a * x * x,
//!     force(x = -c * x_dot),
//! )]
//! struct Bead { a: f64, g: f64, c: f64 }
//! let s = <Bead as ForcedLagrangian<1>>::STRUCTURE;
//! assert!(s.has_force && s.force_uses_velocity && !s.constant_mass);
//! ```
//!
//! # The sparse backend
//!
//! Every run takes one of two backends for the linear algebra of its steps: dense (an
//! `sN × sN` LU of the step Jacobian) or sparse (faer's sparse LU on the Jacobian's pattern,
//! with the cargo feature `sparse`, on by default). [`LinearPath::Auto`], the default, takes
//! the sparse backend when all of these hold:
//!
//! 1. the model has sparse node kernels ([`ForcedLagrangian::sparse_node`] is `Some`): the
//!    attribute writes them when the Lagrangian is a sum of local terms (index sums
//!    `(0..N).map(|i| ..).sum()`, nested ones for 2-D indices such as `q[r * W + j]`, `for`
//!    accumulations, terms with fixed indices, with signs and constant factors) and each
//!    force entry reads a few coordinates. A whole-array expression, a sum used nonlinearly,
//!    or an index it cannot resolve keeps the model dense;
//! 2. the model has at least [`LinearPath::SPARSE_MIN_DOF`] coordinates (the measured
//!    crossover);
//! 3. the node pattern, recorded at the initial state, fills at most
//!    [`LinearPath::SPARSE_MAX_DENSITY`] of `N × N`.
//!
//! Otherwise it takes the dense backend, which holds at most [`LinearPath::DENSE_MAX_DOF`]
//! coordinates ([`Error::ModelTooLarge`] above that). [`Integrator::path_for`] tells which
//! one a run will take, and [`Integrator::linear_path`] overrides the choice. Both backends
//! run the same stepper and give the same steps (to round-off).
//!
//! ```
//! use forced_vi::{prelude::*, LinearPath};
//!
//! #[forced_lagrangian(
//!     coordinates(q: [f64; N]),
//!     lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
//!         - (0..N - 1).map(|i| 0.5 * k * (q[i + 1] - q[i]).powi(2)).sum()
//!         - 0.5 * k * (q[0] * q[0] + q[N - 1] * q[N - 1]),
//!     force(q[i] = -c * q_dot[i]),
//! )]
//! struct Springs<const N: usize> { k: f64, c: f64 }
//!
//! let long = Springs::<64> { k: 1.0, c: 0.1 };
//! assert!(long.sparse_node().is_some());
//! let init = InitialState::from_velocity(std::array::from_fn(|i| (i as f64 / 10.0).sin()), [0.0; 64]);
//! let integrator = Integrator::new(&long, Scheme::lobatto(3)?, 0.01)?;
//! let expected = if cfg!(feature = "sparse") { LinearPath::Sparse } else { LinearPath::Dense };
//! assert_eq!(integrator.path_for(&init)?, expected);
//! // Overridden: the same run on the dense backend.
//! let dense = Integrator::new(&long, Scheme::lobatto(3)?, 0.01)?.linear_path(LinearPath::Dense);
//! assert_eq!(dense.path_for(&init)?, LinearPath::Dense);
//! let a = integrator.final_state(init, 0.5).map_err(|f| f.error)?;
//! let b = dense.final_state(init, 0.5).map_err(|f| f.error)?;
//! assert!((a.q - b.q).amax() < 1e-12);
//!
//! // Below SPARSE_MIN_DOF coordinates, the dense backend is faster: Auto takes it.
//! let short = Springs::<4> { k: 1.0, c: 0.1 };
//! let integrator = Integrator::new(&short, Scheme::lobatto(3)?, 0.01)?;
//! assert_eq!(integrator.path_for(&InitialState::from_velocity([0.1; 4], [0.0; 4]))?, LinearPath::Dense);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # What an `Ok` promises
//!
//! A run that returns `Ok`, and every record that a stream hands out, guarantees:
//!
//! - **each step solves its discrete Euler–Lagrange equations**: Newton stops only when the
//!   residual meets its bound ([`NewtonOptions`]: a relative residual tolerance, or the
//!   round-off floor of the terms that cancel in it) and the estimated error of the iterate
//!   is within `rtol · |z| + atol`; [`StepRecord::residual`] is the residual it stopped at.
//!   With tolerances, an unconstrained model's step may instead stop once the iterate's
//!   estimated error is a hundredth of the last accepted step's error estimate: the
//!   estimate measures the step as solved, Newton's error included (see
//!   [`crate::control`], "Newton's stop");
//! - **the velocities solve `L_v(q, v) = p`** to `1e-13 (|p| + |E| |v|)` or to round-off;
//! - **no step ends at, or crosses, a singular mass matrix**: every step end has a
//!   well-conditioned mass matrix whose determinant keeps the sign it had at the start;
//! - **every reported number is finite**: `q`, `p`, `v`, the energy, the energy balance and
//!   the residual.
//!
//! With tolerances ([`Integrator::tolerances`], [`Integrator::adaptive`],
//! [`Integrator::auto`], which picks the Lobatto scheme from the tolerance too), every step's
//! estimated local error per unit step is within them, so the error follows the tolerance
//! (measured, not proved: an estimate can be fooled). A step and its estimate see the
//! forces at their nodes only: a force that acts only between them (a pulse shorter than
//! the steps, a narrow well crossed fast) can be missed by both, with an `Ok` (measured on
//! a pulse of width 10⁻³: lobatto5 at tol 1e-8 took 6 steps to t = 3, error 1.06). Bound
//! the steps below such a feature's width with [`Integrator::max_step`], or put an output
//! time of [`output::Samples`](crate::output::Samples) on a feature at a known time: a
//! step then ends on it.
//!
//! A fixed-step run does **not** promise that `h` is small enough for the accuracy you
//! want: the error is `O(h^order)` and `h` is your choice. Watch
//! [`StepRecord::energy_balance`], `E − E0 − W`, which shrinks at the scheme's order.
//!
//! Anything else is a typed [`Error`], inside a [`RunFailure`] that keeps what the run
//! computed before it; the library does not panic on user input.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(x, y),
//!     lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
//!         - 0.5 * (x * x + (1.0 + rho) * y * y)
//!         - lambda * (x - y) * (x - y),
//!     force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
//! )]
//! struct CoupledVanDerPol { eps: f64, rho: f64, lambda: f64 }
//!
//! let model = CoupledVanDerPol { eps: 0.5, rho: 0.02, lambda: 0.8 };
//! let run = Integrator::new(&model, Scheme::lobatto(3)?, 0.01)?
//!     .solve(InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]), 5.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! for r in &run.records {
//!     let numbers = r.q.iter().chain(&r.p).chain(&r.v).chain([&r.energy, &r.energy_balance]);
//!     assert!(numbers.copied().all(f64::is_finite));
//!     assert!(r.residual < 1e-10);
//! }
//! // The energy balance shrinks as h⁴ (lobatto3 has order 4): here it is about 1e-8.
//! assert!(run.records.iter().all(|r| r.energy_balance.abs() < 1e-6));
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! # Bad input
//!
//! The errors a new user meets first, and the message each one prints. A run method returns
//! a [`RunFailure`]; its field `error` is the [`Error`], and `?` converts it.
//!
//! **A step size that is zero, negative or not finite**, refused by [`Integrator::new`]:
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x)]
//! struct Oscillator {}
//!
//! let err = Integrator::new(&Oscillator {}, Scheme::lobatto(3)?, 0.0).err().expect("h = 0");
//! assert_eq!(
//!     err.to_string(),
//!     "step size h = 0.0 must be positive and finite (and at least 1.0e-292)"
//! );
//! assert!(matches!(err, forced_vi::Error::InvalidStepSize { .. }));
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! **A tolerance that is negative, not finite, or zero with its partner**, refused by
//! [`Integrator::tolerances`] (and [`Integrator::adaptive`], [`Tolerance::scalar`]):
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x)]
//! struct Oscillator {}
//!
//! let integrator = Integrator::new(&Oscillator {}, Scheme::lobatto(3)?, 0.1)?;
//! let err = integrator.tolerances(-0.001, 0.0).err().expect("a negative rtol");
//! assert_eq!(
//!     err.to_string(),
//!     "tolerance of coordinate 0 is invalid (rtol = -0.001, atol = 0): \
//!      both must be finite and non-negative, not both zero"
//! );
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! **A singular mass matrix** `∂²L/∂v²`: a Lagrangian that cannot be solved for the
//! velocities, here because both coordinates move only together. The run fails at step 0,
//! before any step:
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(
//!     coordinates(x, y),
//!     lagrangian = 0.5 * (x_dot + y_dot) * (x_dot + y_dot) - 0.5 * (x * x + y * y),
//! )]
//! struct Degenerate {}
//!
//! let failure = Integrator::new(&Degenerate {}, Scheme::lobatto(3)?, 0.1)?
//!     .solve(InitialState::from_velocity([0.1, 0.2], [0.0, 0.0]), 1.0, output::Records)
//!     .expect_err("the mass matrix [[1, 1], [1, 1]] is singular");
//! let message = failure.error.to_string();
//! assert!(
//!     message.starts_with("mass matrix is singular or nearly so at step 0, t = 0"),
//!     "{message}"
//! );
//! assert_eq!(failure.stats.steps, 0);
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! **An initial state the model cannot start from**: a NaN or infinite entry, or a momentum
//! that no velocity gives (`p = L_v(q, v)` has no solution):
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(coordinates(x, y), lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot))]
//! struct Free {}
//!
//! let integrator = Integrator::new(&Free {}, Scheme::lobatto(3)?, 0.1)?;
//! let failure = integrator
//!     .solve(InitialState::from_velocity([0.0, f64::NAN], [1.0, 0.0]), 1.0, output::Records)
//!     .expect_err("q[1] is NaN");
//! assert_eq!(failure.error.to_string(), "initial q[1] is not finite");
//!
//! /// A particle whose momentum `p = v / √(1 + v²)` stays within (−1, 1).
//! #[forced_lagrangian(coordinates(x), lagrangian = (1.0 + x_dot * x_dot).sqrt())]
//! struct Bounded {}
//!
//! let integrator = Integrator::new(&Bounded {}, Scheme::lobatto(3)?, 0.1)?;
//! let failure = integrator
//!     .solve(InitialState::from_momentum([0.0], [2.0]), 1.0, output::Records)
//!     .expect_err("no velocity has p = 2");
//! let message = failure.error.to_string();
//! assert!(
//!     message.starts_with("velocity solve L_v(q, v) = p failed at step 0, t = 0"),
//!     "{message}"
//! );
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! The other input errors: [`Error::InvalidFinalTime`], [`Error::NonFiniteParameter`],
//! [`Error::InvalidStepBounds`], [`Error::InvalidNewtonOptions`], [`Error::TooManySteps`],
//! [`Error::UnorderedTimes`], [`Error::InvalidOutputTime`], [`Error::NonFiniteLossGradient`]
//! and the scheme errors ([`SchemeError`](crate::SchemeError)).
//!
//! # Compile errors
//!
//! The attribute checks the model before it writes anything, and reports each mistake at
//! the tokens that make it (all of them at once). The common ones:
//!
//! A name that is not a coordinate, velocity or parameter:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * x * xx)]
//! struct Oscillator { k: f64 }
//! ```
//!
//! A force for a coordinate that does not exist, or a coordinate without its force entry:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(
//!     coordinates(x, y),
//!     lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y),
//!     force(x = -c * x_dot, z = 0.0),
//! )]
//! struct Damped { c: f64 }
//! ```
//!
//! A Lagrangian without velocities (its mass matrix is zero):
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(coordinates(x), lagrangian = -0.5 * k * x * x)]
//! struct Potential { k: f64 }
//! ```
//!
//! A parameter that is not an `f64`:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * x * x)]
//! struct Oscillator { k: f64, steps: usize }
//! ```
//!
//! An index outside an array of literal length:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(
//!     coordinates(q: [f64; 2]),
//!     lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1]) - (q[2] - q[0]).powi(2),
//! )]
//! struct Pair {}
//! ```
//!
//! A parameter (or a coordinate) named `t`, which is the time:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(
//!     coordinates(x),
//!     lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
//!     force(x = (omega * t).cos()),
//! )]
//! struct Driven { omega: f64, t: f64 }
//! ```
//!
//! Integer arithmetic whose value a real number would not reproduce, used as a real number:
//! arithmetic between integers stays integer arithmetic, as in Rust, so `3 / 2` is 1 where
//! `3.0 / 2.0` is 1.5 (an overflow, such as `2147483647 * 2147483647 * 4`, is the same
//! mistake). Write the numbers as reals, or `(3 / 2) as f64` for Rust's quotient; exact
//! integer arithmetic (`4 / 2`, `7 % 4`, `2.pow(3)`) and indices (`q[i / 2]`) are fine:
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(coordinates(x), lagrangian = x_dot * x_dot * (3 / 2) - x)]
//! struct Truncated {}
//! ```
//!
//! An expression outside the supported forms (a macro call, a closure that is not an index
//! sum, a method of another type, ...):
//!
//! ```compile_fail
//! use forced_vi::prelude::*;
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - println!("{}", 1))]
//! struct Loud {}
//! ```
//!
//! The workspace's `tests/ui/` holds one case per error, with the exact message.
//!
//! # Export
//!
//! With the cargo feature `serde`, [`Trajectory`], [`StepRecord`], [`RunStats`],
//! [`FinalState`], [`DenseState`], [`InitialState`], [`Tolerance`], [`SchemeId`],
//! [`LinearPath`] and [`NewtonOptions`] implement `Serialize` and `Deserialize`, and the
//! errors ([`Error`], [`RunFailure`]) and [`Structure`] implement `Serialize`. Vectors are
//! sequences, `[f64; N]` of any length included. A trajectory to JSON and back:
//!
//! ```
//! # #[cfg(feature = "serde")] {
//! use forced_vi::prelude::*;
//!
//! #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x)]
//! struct Oscillator {}
//!
//! let run = Integrator::new(&Oscillator {}, Scheme::lobatto(3)?, 0.1)?
//!     .solve(InitialState::from_velocity([1.0], [0.0]), 1.0, output::Records)
//!     .map_err(|failure| failure.error)?;
//! let json = serde_json::to_string(&run).expect("a trajectory serialises");
//! let back: Trajectory<1> = serde_json::from_str(&json).expect("and reads back");
//! assert_eq!(back, run);
//! # }
//! # Ok::<(), forced_vi::Error>(())
//! ```
//!
//! The workspace's `examples/export.rs` writes a trajectory to CSV (with the `csv` crate)
//! and to JSON.

#[allow(unused_imports)] // for the intra-doc links above
use crate::{
    DenseState, Error, FinalState, ForcedLagrangian, InitialState, Integrator, LinearPath,
    NewtonOptions, RunFailure, RunStats, Scheme, SchemeId, StepRecord, Structure, Tolerance,
    Trajectory,
};
