//! The linear algebra of a step, behind one trait (DESIGN §10).
//!
//! What differs between a 2-coordinate model and a 4096-coordinate lattice is how a step's
//! equations are stored, assembled, factored and solved, not the step. A [`StepBackend`]
//! owns that: the step equations of DESIGN §3 on its own storage, the Newton iteration with
//! its linear solver, and the velocity solve `L_v(q, v) = p`, with every buffer made once
//! per run. The one [`Stepper`](crate::Stepper) (predictor, subdivision, error control,
//! diagnostics, records and checks) sits above it and sees only slices.
//!
//! | backend | storage | module |
//! |---|---|---|
//! | [`DenseBackend`] | `N × N` node blocks from [`ForcedLagrangian::node_jacobian_at`], a dense step Jacobian, LU with partial pivoting | `dense` |
//! | [`SparseBackend`] | node blocks on the model's [`SparseNode`](crate::model::SparseNode) pattern, faer's sparse LU with its symbolic analysis made once | `sparse` |
//!
//! The runtime dispatches on [`Backend`], an enum of the two, so that the public
//! [`Stepper`](crate::Stepper) has one type for every model size.

mod dense;
#[cfg(feature = "sparse")]
mod sparse;

pub(crate) use dense::DenseBackend;
#[cfg(feature = "sparse")]
pub(crate) use sparse::{ConstraintRate, SparseBackend};

use crate::error::{Error, NewtonFailure};
use crate::model::ForcedLagrangian;
use crate::newton::NewtonReport;
use crate::scheme::Scheme;

/// Where the unknowns of a step live: the increment `Z_m = x_m − q_k` of control point
/// `m = 1 … s − 1`, coordinate `a`, is entry [`Layout::at`]`(m, a)` of the backend's vector.
///
/// The stages of one coordinate together (the sparse backend's banded order) or the
/// coordinates of one stage together (the dense one's): either way, strides.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// The distance between two coordinates of one stage.
    coordinate: usize,
    /// The distance between two stages of one coordinate.
    stage: usize,
    /// A constrained model: where the multipliers `ŵ_j = h² λ_j` (`j = 0 … s − 2`) start,
    /// after the increments, and their strides in the constraint and in `j`.
    multipliers: usize,
    constraint: usize,
    point: usize,
}

impl Layout {
    /// The layout of `n` coordinates, `m` constraints and `s1` stages, the stages of a
    /// coordinate (or a constraint) together (`coordinate_major`) or the coordinates of a
    /// stage.
    pub(crate) fn new(n: usize, m: usize, s1: usize, coordinate_major: bool) -> Self {
        let multipliers = n * s1;
        if coordinate_major {
            Layout {
                coordinate: s1,
                stage: 1,
                multipliers,
                constraint: s1,
                point: 1,
            }
        } else {
            Layout {
                coordinate: 1,
                stage: n,
                multipliers,
                constraint: 1,
                point: m,
            }
        }
    }

    /// The index of the multiplier `ŵ_{j, k}` (control point `j = 0 … s − 2`, constraint
    /// `k`).
    #[inline(always)]
    pub(crate) fn multiplier(&self, j: usize, k: usize) -> usize {
        self.multipliers + k * self.constraint + j * self.point
    }

    /// The number of increments `(m, a)`: they come first, in `0 … increments()`, in
    /// either order.
    #[inline(always)]
    pub(crate) fn increments(&self) -> usize {
        self.multipliers
    }

    /// The index of unknown `(m, a)`.
    #[inline(always)]
    pub(crate) fn at(&self, m: usize, a: usize) -> usize {
        a * self.coordinate + (m - 1) * self.stage
    }

    /// The strides of [`Self::at`] in `a` and in `m`.
    #[inline(always)]
    pub(crate) fn strides(&self) -> (usize, usize) {
        (self.coordinate, self.stage)
    }
}

/// Why one attempt at a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum StepFailure {
    /// The Newton solve of the step equations failed.
    Newton(NewtonFailure),
    /// The step ended at a singular mass matrix or across one.
    SingularMass { rcond: f64 },
    /// A sparse kernel wrote outside the pattern recorded at the first evaluation.
    #[cfg_attr(not(feature = "sparse"), allow(dead_code))]
    OutsidePattern,
    /// What a run keeps per step (an adjoint's tape) no longer fits in memory.
    Memory { records: usize },
    /// The tangent of a sensitivity run left the range of `f64` over the step (a flow that
    /// stretches perturbations without bound, as a chaotic one does over a long run).
    TangentOverflow,
}

impl StepFailure {
    /// A failure that a smaller step would not avoid: the run ends at once.
    pub(crate) fn is_fatal(self) -> bool {
        matches!(
            self,
            StepFailure::OutsidePattern | StepFailure::Memory { .. } | StepFailure::TangentOverflow
        )
    }
}

/// The directions the forward sensitivities carry through a step at once, where the
/// backend takes them so ([`StepBackend::tangent_blocks`]).
pub(crate) const TANGENT_BLOCK: usize = 8;

/// The linear algebra of a step. Slices of positions, velocities and momenta have the
/// model's `N` entries.
pub(crate) trait StepBackend {
    /// The layout of the unknowns.
    fn layout(&self) -> Layout;
    /// The scheme whose step equations this backend solves.
    fn scheme(&self) -> &Scheme;
    /// The unknowns: the predictor is written here, the solution read from here.
    fn z(&self) -> &[f64];
    /// The unknowns, to write.
    fn z_mut(&mut self) -> &mut [f64];
    /// Solves the step equations of a step of size `h` from `(t0, q0, p0)`, starting from
    /// the guess in [`Self::z`]; `scale = (global, force)` sets the residual's units: the
    /// momentum scale of the whole step, and per coordinate the size of `L_q + F` at the
    /// last step's nodes, from which each coordinate's rows get their own (see
    /// [`coordinate_scales`]). On success, the node values ([`Self::node_fq`], …) belong to
    /// the solution.
    fn solve(
        &mut self,
        h: f64,
        t0: f64,
        start: (&[f64], &[f64]),
        scale: (f64, &[f64]),
    ) -> Result<NewtonReport, StepFailure>;
    /// Linear solves of the last [`Self::solve`], converged or not.
    fn last_iterations(&self) -> usize;
    /// The error estimate's backend: lets the next [`Self::solve`], of a step of size `h`,
    /// start from the factors of the last one (see `crate::newton`'s iteration); returns
    /// whether it will. Without it, every solve of the estimate makes fresh factors. The
    /// carried factors' second correction is left out where it is at most `negligible`.
    fn carry_factors(&mut self, h: f64, negligible: f64) -> bool;
    /// Lets the next [`Self::solve`] (only) stop once its iterate's estimated error is at
    /// most `bound` (max-norm, in the unknowns), not at round-off: an adaptive step, whose
    /// error estimate measures the step as solved. Ignored on a constrained model, whose
    /// constraint rows are solved to round-off.
    fn solve_within(&mut self, bound: f64);
    /// After a solve with carried factors: a bound (max-norm) on the error they left in
    /// [`Self::z`]; zero after any other solve.
    fn carried_error(&self) -> f64;
    /// Refuses the last solve's carried factors: the next solves make fresh ones.
    fn reject_carry(&mut self);
    /// The size (max-norm, in the unknowns) of the Newton correction that would follow the
    /// last solve's iterate, with its factors, of its last correction, and whether its
    /// residual was at its round-off floor (see `crate::newton`'s iteration).
    fn next_correction(&mut self) -> (f64, f64, bool);
    /// Marks the model's factors as costly: after carried factors fail, the next solve
    /// carries again (see the `crate::newton` iteration's `set_costly_factors`).
    fn set_costly_factors(&mut self, costly: bool);
    /// Lets a solve start from the factors of the last one where the step size is the same
    /// (simplified Newton across steps; see the dense backend's `solve`). The sparse
    /// backend always does, its LU being most of a step's cost.
    fn factors_across_steps(&mut self, on: bool);
    /// Whether [`Self::apply_node_block`] and [`Self::solve_linearized_block`] take
    /// [`TANGENT_BLOCK`] directions at once (the sparse backend); otherwise the tangent goes
    /// column by column.
    fn tangent_blocks(&self) -> bool {
        false
    }
    /// [`Self::apply_node`] for [`TANGENT_BLOCK`] directions, interleaved: entry `a` of
    /// direction `b` at `a * TANGENT_BLOCK + b`, in every slice. The same results as one
    /// call each.
    fn apply_node_block(&self, i: usize, d: (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        let (dx, dv) = d;
        let n = dfq.len() / TANGENT_BLOCK;
        let mut one = [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for b in 0..TANGENT_BLOCK {
            let [x, v, f, l] = &mut one;
            let lane = |from: &[f64], to: &mut [f64]| {
                for (t, y) in to
                    .iter_mut()
                    .zip(from.iter().skip(b).step_by(TANGENT_BLOCK))
                {
                    *t = *y;
                }
            };
            lane(dx, x);
            lane(dv, v);
            self.apply_node(i, (x, v), f, l);
            for (out, from) in [(&mut *dfq, &*f), (&mut *dlv, &*l)] {
                for (t, y) in out.iter_mut().skip(b).step_by(TANGENT_BLOCK).zip(from) {
                    *t = *y;
                }
            }
        }
    }
    /// [`Self::solve_linearized`] for [`TANGENT_BLOCK`] right-hand sides, interleaved as in
    /// [`Self::apply_node_block`].
    fn solve_linearized_block(&mut self, x: &mut [f64]) {
        let n = x.len() / TANGENT_BLOCK;
        let mut one = vec![0.0; n];
        for b in 0..TANGENT_BLOCK {
            for (t, y) in one.iter_mut().zip(x.iter().skip(b).step_by(TANGENT_BLOCK)) {
                *t = *y;
            }
            self.solve_linearized(&mut one);
            for (t, y) in x.iter_mut().skip(b).step_by(TANGENT_BLOCK).zip(&one) {
                *t = *y;
            }
        }
    }
    /// `L_q + F` at quadrature node `i` of the last residual evaluation.
    fn node_fq(&self, i: usize) -> &[f64];
    /// The position at quadrature node `i`.
    fn node_x(&self, i: usize) -> &[f64];
    /// The velocity at quadrature node `i`.
    fn node_v(&self, i: usize) -> &[f64];
    /// `(L_q + F, L_v)` at `(t, q, v)` into `fq` and `lv`.
    fn gradient(
        &mut self,
        at: (f64, &[f64], &[f64]),
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> Result<(), Error>;
    /// Solves `L_v(q, v) = p` for `v` from the guess in `v`.
    fn velocity(
        &mut self,
        at: (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error>;
    /// Checks the mass matrix of the initial data; returns the sign of its determinant.
    fn mass_sign(&mut self, at: (f64, &[f64], &[f64])) -> Result<f64, Error>;
    /// Checks the mass matrix at a step's end: regular, with the determinant's sign
    /// `sign` of the start (a change means a singular mass was crossed).
    fn mass_at_end(&mut self, at: (f64, &[f64], &[f64]), sign: f64) -> Result<(), StepFailure>;
    /// Evaluates the node blocks at the solution in [`Self::z`] of the last
    /// [`Self::solve`] and factors the step Jacobian there: the exact linearisation of the
    /// step for its tangent (DESIGN §12).
    fn linearize(&mut self) -> Result<(), StepFailure>;
    /// With the blocks of quadrature node `i` from [`Self::linearize`]:
    /// `dfq = A dx + B dv` and `dlv = C dx + E dv`, `dxv = (dx, dv)`.
    fn apply_node(&self, i: usize, dxv: (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]);
    /// Solves `J y = b` in place (the layout of [`Self::z`]) with the factors of
    /// [`Self::linearize`].
    fn solve_linearized(&mut self, b: &mut [f64]);
    /// The tangent of `p = L_v(t, q, v)`: `dp = C dq + E dv` at `at = (t, q, v)`.
    fn momentum_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        dqv: (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error>;
    /// The tangent of the velocity solve: `E dv = dp − C dq` at `at = (t, q, v)`.
    fn velocity_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        dqp: (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error>;
    /// A constrained model: the momentum `h Σ_j b_j G(x_j)ᵀ λ_j` of the constraint forces
    /// over the last solved step (DESIGN §11); `None` without constraints.
    fn constraint_impulse(&self) -> Option<&[f64]>;
    /// A constrained model: `[|g|, |G v + ∂g/∂t|, |G| |v| + |∂g/∂t|, |G|]` (max-norms: the
    /// position and velocity residuals, the size of the latter's terms, and the scale of
    /// the constraints' gradients) at `at = (t, q, v)`; zeros without constraints.
    fn constraint_residuals(&mut self, at: (f64, &[f64], &[f64])) -> Result<[f64; 4], Error>;
    /// A constrained model: the multipliers at the end of the last solved step, as
    /// `h² λ_{s−1}` (the units of those of its earlier control points, which follow the
    /// increments in [`Self::z`]).
    fn end_multipliers(&self) -> &[f64];
    /// The step of the last [`Self::solve`] (or [`Self::restore`]): `(h, t0, q0, p0)`.
    fn step_data(&self) -> (f64, f64, &[f64], &[f64]);
    /// `max |A| · max |x| + max |B| · max |v|` at the nodes of the last Jacobian
    /// (`A = ∂(L_q + F)/∂q`, `B = ∂(L_q + F)/∂v`): times ε, the round-off of the forces
    /// there, which the rounding of their positions and velocities carries.
    fn force_round_off_rate(&self) -> f64;
    /// `h |A| + |B|` over the nodes of the last Jacobian, in row sums (an upper bound):
    /// how much an error `δ` in every increment of a step of size `h` moves a node's
    /// `L_q + F` (the positions by `δ`, the velocities by about `δ / h`), and so the
    /// momentum update `h Σ_i b_i (L_q + F)_i`, per unit of `δ` (see `crate::control`,
    /// "Newton's stop").
    fn force_gain(&self, h: f64) -> f64;
    /// Sets a step `(h, t0, (q0, p0))` and its solution `z` without solving, for the
    /// backward pass of an adjoint.
    fn restore(&mut self, h: f64, t0: f64, start: (&[f64], &[f64]), z: &[f64]);
    /// Evaluates the node blocks at the solution in [`Self::z`] and factors the transposed
    /// step Jacobian `Jᵀ` there.
    fn linearize_transposed(&mut self) -> Result<(), StepFailure>;
    /// Solves `Jᵀ y = b` in place with the factors of [`Self::linearize_transposed`].
    fn solve_transposed(&mut self, b: &mut [f64]);
    /// With the blocks of quadrature node `i`: `ux = Aᵀ mf + Cᵀ ml`, `uv = Bᵀ mf + Eᵀ ml`,
    /// `m = (mf, ml)`.
    fn apply_node_transposed(&self, i: usize, m: (&[f64], &[f64]), ux: &mut [f64], uv: &mut [f64]);
    /// At `at = (t, q, v)`: `cq = Cᵀ y` and `ev = Eᵀ y`, the transposed tangent of
    /// `p = L_v(t, q, v)`.
    fn momentum_cotangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        y: &[f64],
        out: (&mut [f64], &mut [f64]),
    ) -> Result<(), Error>;
    /// Whether the node kernels of this backend need a deep stack (see
    /// [`crate::stepper`]'s stack guard).
    fn deep_stack(&self) -> bool;
    /// The constraint terms of the tangent of the constrained step just solved and
    /// linearised, on the backend's sparse patterns, with the end projection's matrix
    /// factored for [`Self::solve_end_projection`] (see `crate::stepper`'s
    /// `tangent_constrained`); `None` where the stepper makes them from the model's dense
    /// kernels (the dense backend).
    fn sparse_constraint_terms(&mut self) -> Result<Option<SparseConstraintTerms>, StepFailure>;
    /// Solves `[[E₁, G₁ᵀ], [G₁, 0]] x = rhs` in place with the factors of the last
    /// [`Self::sparse_constraint_terms`]; false without them.
    fn solve_end_projection(&mut self, rhs: &mut [f64]) -> bool;
    /// A constrained step's projected end velocity where the backend keeps it (the sparse
    /// one), for the adjoint's tape.
    fn end_velocity(&self) -> Option<&[f64]>;
    /// Puts back a constrained step's end multipliers ([`Self::end_multipliers`]) and
    /// projected end velocity, after [`Self::restore`].
    fn restore_end(&mut self, mu: &[f64], v1: &[f64]);
}

/// A constrained step's terms for its tangent on sparse patterns (see
/// [`StepBackend::sparse_constraint_terms`]): `G(x_j)` at the `s` control points, the
/// curvatures `K_j = Σ_r ŵ_{j,r} ∂²g_r(x_j)` at the first `s − 1`, and at the projected end
/// `(q₁, v₁)` with the impulse `μ̂`: `C₁ + K_μ` and `K_μ = Σ_r μ̂_r ∂²g_r(q₁)`.
pub(crate) struct SparseConstraintTerms {
    /// The entries `(k, a)` of `G` (`m × N`).
    pub(crate) g_entries: Vec<(usize, usize)>,
    /// `G(x_j)`'s values, per control point.
    pub(crate) g: Vec<Vec<f64>>,
    /// The entries `(r, c)` of the node pattern, on which the curvatures and `C` live.
    pub(crate) node_entries: Vec<(usize, usize)>,
    /// `K_j`'s values, `j = 0 … s − 2`.
    pub(crate) k: Vec<Vec<f64>>,
    /// `C₁ + K_μ` and `K_μ`.
    pub(crate) c1k: Vec<f64>,
    pub(crate) kmu: Vec<f64>,
    /// The projected end velocity `v₁`.
    pub(crate) v1: Vec<f64>,
    /// `H = ∂(G v₁)/∂q` at the end by its entries `(k, a, value)` (equal `(k, a)` add up),
    /// from the kernels' second derivatives, where the constraints do not read `t`.
    pub(crate) rate: Option<Vec<(usize, usize, f64)>>,
}

impl SparseConstraintTerms {
    /// `out = M x` for a matrix on `entries` with `values`.
    pub(crate) fn times(entries: &[(usize, usize)], values: &[f64], x: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for (&(r, c), v) in entries.iter().zip(values) {
            out[r] += v * x[c];
        }
    }

    /// `out = Mᵀ y` for a matrix on `entries` with `values`.
    pub(crate) fn times_transposed(
        entries: &[(usize, usize)],
        values: &[f64],
        y: &[f64],
        out: &mut [f64],
    ) {
        out.fill(0.0);
        for (&(r, c), v) in entries.iter().zip(values) {
            out[c] += v * y[r];
        }
    }
}

/// The backend of a run: dense or sparse.
// The sparse backend is boxed: inline, it made every `Backend` (and so the stepper, which
// holds two) about 4.5 KiB, moved several times at the start of each run, which was the
// largest single cost of a short run on a small model; a sparse step takes far longer
// than the indirection. The dense one stays inline: it is the small models' hot path.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Backend<'a, M, const N: usize> {
    /// `N × N` node blocks.
    Dense(Box<DenseBackend<'a, M, N>>),
    /// Node blocks on the model's sparse pattern.
    #[cfg(feature = "sparse")]
    Sparse(Box<SparseBackend<'a>>),
}

/// Whether an `N × N` block takes more than 64 KiB: a dense backend's call may then hold
/// several on its frame.
const fn dense_frame_is_large<const N: usize>() -> bool {
    N.saturating_mul(N)
        .saturating_mul(std::mem::size_of::<f64>())
        > 64 * 1024
}

/// Each coordinate's momentum scale for a step of size `h` from momenta `p0`, with `force`
/// the size of its `L_q + F` at the last step's nodes: `max(|p0_a|, h |F_a|)` into `out`
/// (its gradient rows' [`crate::NonlinearSystem::row_scales`]). A coordinate's rows are
/// then tested against their own terms, not the largest coordinate's: a Duffing oscillator
/// beside a mass of 1e9 moving at unit speed (fixed lobatto4, h = 0.1) ended 5.9e-11 off
/// the oscillator alone with the one scale `max_a |p0_a|`, and the sparse path 3.5e-7.
/// Where `force` is shorter than `p0` (not yet measured), the momenta alone.
pub(crate) fn coordinate_scales(h: f64, (p0, force): (&[f64], &[f64]), out: &mut [f64]) {
    for (a, (o, p)) in out.iter_mut().zip(p0).enumerate() {
        let f = force.get(a).map_or(0.0, |f| h * f);
        *o = if f > p.abs() { f } else { p.abs() };
    }
}

/// Runs `f` in a frame of its own. A dense call of a large model (its mass matrix, its node
/// blocks: megabytes at `N` = 1024) inlined into the code shared with the sparse backend
/// would put those blocks on that code's frame, which the sparse path's stack budget
/// (`crate::stepper::step_stack_bytes`) does not count; whether LLVM inlines it changes
/// with unrelated code (measured: a 1024-coordinate constrained chain on the sparse backend
/// overflowed its stack in `initial_state` after an edit elsewhere in the stepper, an
/// adaptive step-size rule).
#[inline(never)]
fn out_of_line<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// Forwards a call to the backend in use; for a large model, the dense backend's out of
/// line ([`out_of_line`]).
macro_rules! forward {
    ($self:ident, $b:ident => $e:expr) => {
        match $self {
            Backend::Dense($b) => {
                if dense_frame_is_large::<N>() {
                    out_of_line(move || $e)
                } else {
                    $e
                }
            }
            #[cfg(feature = "sparse")]
            Backend::Sparse($b) => $e,
        }
    };
}

/// A backend's last step as the stepper's code that is not generic over the model reads
/// it: the scheme, the layout of the unknowns and the unknowns, in one call.
#[derive(Clone, Copy)]
pub(crate) struct StepView<'a> {
    pub(crate) scheme: &'a Scheme,
    pub(crate) layout: Layout,
    pub(crate) z: &'a [f64],
}

impl<M: ForcedLagrangian<N>, const N: usize> Backend<'_, M, N> {
    /// The scheme, the layout and the unknowns ([`StepView`]).
    #[inline(always)]
    pub(crate) fn view(&self) -> StepView<'_> {
        forward!(self, b => StepView {
            scheme: b.scheme(),
            layout: b.layout(),
            z: b.z(),
        })
    }

    /// Whether [`Backend::restart`] keeps this backend for a new run: the dense one. The
    /// sparse one's pattern is recorded at a run's initial state, so a new run makes its own.
    pub(crate) fn can_restart(&self) -> bool {
        matches!(self, Backend::Dense(_))
    }

    /// Back to the state a new backend starts a run in, keeping the buffers (the dense
    /// backend: [`DenseBackend::restart`]); nothing for the sparse one, see
    /// [`Backend::can_restart`].
    pub(crate) fn restart(&mut self) {
        match self {
            Backend::Dense(b) => b.restart(),
            #[cfg(feature = "sparse")]
            Backend::Sparse(_) => {}
        }
    }

    /// Gives the next [`StepBackend::solve`] node blocks interpolated from those of `from`'s
    /// last Jacobian (see [`DenseBackend::seed_node_blocks`]); false, and nothing given, where
    /// the backend evaluates its own (the sparse one).
    pub(crate) fn seed_node_blocks(&mut self, from: &Self, weights: &[f64]) -> bool {
        match (self, from) {
            (Backend::Dense(to), Backend::Dense(from)) => to.seed_node_blocks(from, weights),
            #[cfg(feature = "sparse")]
            _ => false,
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> StepBackend for Backend<'_, M, N> {
    #[inline(always)]
    fn layout(&self) -> Layout {
        forward!(self, b => b.layout())
    }
    #[inline(always)]
    fn scheme(&self) -> &Scheme {
        forward!(self, b => b.scheme())
    }
    #[inline(always)]
    fn z(&self) -> &[f64] {
        forward!(self, b => b.z())
    }
    #[inline(always)]
    fn z_mut(&mut self) -> &mut [f64] {
        forward!(self, b => b.z_mut())
    }
    #[inline(always)]
    fn solve(
        &mut self,
        h: f64,
        t0: f64,
        start: (&[f64], &[f64]),
        scale: (f64, &[f64]),
    ) -> Result<NewtonReport, StepFailure> {
        forward!(self, b => b.solve(h, t0, start, scale))
    }
    #[inline(always)]
    fn last_iterations(&self) -> usize {
        forward!(self, b => b.last_iterations())
    }
    #[inline(always)]
    fn carry_factors(&mut self, h: f64, negligible: f64) -> bool {
        forward!(self, b => b.carry_factors(h, negligible))
    }
    #[inline(always)]
    fn solve_within(&mut self, bound: f64) {
        forward!(self, b => b.solve_within(bound))
    }
    #[inline(always)]
    fn carried_error(&self) -> f64 {
        forward!(self, b => b.carried_error())
    }
    #[inline(always)]
    fn reject_carry(&mut self) {
        forward!(self, b => b.reject_carry())
    }
    fn next_correction(&mut self) -> (f64, f64, bool) {
        forward!(self, b => b.next_correction())
    }
    fn set_costly_factors(&mut self, costly: bool) {
        forward!(self, b => b.set_costly_factors(costly))
    }
    fn factors_across_steps(&mut self, on: bool) {
        forward!(self, b => b.factors_across_steps(on))
    }
    #[inline(always)]
    fn node_fq(&self, i: usize) -> &[f64] {
        forward!(self, b => b.node_fq(i))
    }
    #[inline(always)]
    fn node_x(&self, i: usize) -> &[f64] {
        forward!(self, b => b.node_x(i))
    }
    #[inline(always)]
    fn node_v(&self, i: usize) -> &[f64] {
        forward!(self, b => b.node_v(i))
    }
    #[inline(always)]
    fn gradient(
        &mut self,
        at: (f64, &[f64], &[f64]),
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> Result<(), Error> {
        forward!(self, b => b.gradient(at, fq, lv))
    }
    #[inline(always)]
    fn velocity(
        &mut self,
        at: (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error> {
        forward!(self, b => b.velocity(at, v, step))
    }
    #[inline(always)]
    fn mass_sign(&mut self, at: (f64, &[f64], &[f64])) -> Result<f64, Error> {
        forward!(self, b => b.mass_sign(at))
    }
    #[inline(always)]
    fn mass_at_end(&mut self, at: (f64, &[f64], &[f64]), sign: f64) -> Result<(), StepFailure> {
        forward!(self, b => b.mass_at_end(at, sign))
    }
    fn linearize(&mut self) -> Result<(), StepFailure> {
        forward!(self, b => b.linearize())
    }
    #[inline(always)]
    fn apply_node(&self, i: usize, d: (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        forward!(self, b => b.apply_node(i, d, dfq, dlv))
    }
    fn tangent_blocks(&self) -> bool {
        forward!(self, b => b.tangent_blocks())
    }
    fn apply_node_block(&self, i: usize, d: (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        forward!(self, b => b.apply_node_block(i, d, dfq, dlv))
    }
    fn solve_linearized_block(&mut self, x: &mut [f64]) {
        forward!(self, b => b.solve_linearized_block(x))
    }
    #[inline(always)]
    fn solve_linearized(&mut self, x: &mut [f64]) {
        forward!(self, b => b.solve_linearized(x))
    }
    fn momentum_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        d: (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error> {
        forward!(self, b => b.momentum_tangent(at, d, dp))
    }
    fn velocity_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        d: (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error> {
        forward!(self, b => b.velocity_tangent(at, d, dv))
    }
    #[inline(always)]
    fn constraint_impulse(&self) -> Option<&[f64]> {
        forward!(self, b => b.constraint_impulse())
    }
    fn end_multipliers(&self) -> &[f64] {
        forward!(self, b => b.end_multipliers())
    }
    fn constraint_residuals(&mut self, at: (f64, &[f64], &[f64])) -> Result<[f64; 4], Error> {
        forward!(self, b => b.constraint_residuals(at))
    }
    fn step_data(&self) -> (f64, f64, &[f64], &[f64]) {
        forward!(self, b => b.step_data())
    }
    fn force_round_off_rate(&self) -> f64 {
        forward!(self, b => b.force_round_off_rate())
    }
    fn force_gain(&self, h: f64) -> f64 {
        forward!(self, b => b.force_gain(h))
    }
    fn restore(&mut self, h: f64, t0: f64, start: (&[f64], &[f64]), z: &[f64]) {
        forward!(self, b => b.restore(h, t0, start, z))
    }
    fn linearize_transposed(&mut self) -> Result<(), StepFailure> {
        forward!(self, b => b.linearize_transposed())
    }
    fn solve_transposed(&mut self, x: &mut [f64]) {
        forward!(self, b => b.solve_transposed(x))
    }
    #[inline(always)]
    fn apply_node_transposed(&self, i: usize, m: (&[f64], &[f64]), ux: &mut [f64], uv: &mut [f64]) {
        forward!(self, b => b.apply_node_transposed(i, m, ux, uv))
    }
    fn momentum_cotangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        y: &[f64],
        out: (&mut [f64], &mut [f64]),
    ) -> Result<(), Error> {
        forward!(self, b => b.momentum_cotangent(at, y, out))
    }
    #[inline(always)]
    fn deep_stack(&self) -> bool {
        forward!(self, b => b.deep_stack())
    }
    fn sparse_constraint_terms(&mut self) -> Result<Option<SparseConstraintTerms>, StepFailure> {
        forward!(self, b => b.sparse_constraint_terms())
    }
    fn solve_end_projection(&mut self, rhs: &mut [f64]) -> bool {
        forward!(self, b => b.solve_end_projection(rhs))
    }
    fn end_velocity(&self) -> Option<&[f64]> {
        forward!(self, b => b.end_velocity())
    }
    fn restore_end(&mut self, mu: &[f64], v1: &[f64]) {
        forward!(self, b => b.restore_end(mu, v1))
    }
}
