//! A chain of rigid links in the plane, in Cartesian coordinates (DESIGN §11), written by
//! hand with sparse node and constraint kernels: `n = N/2` point masses `m` at
//! `(x_i, y_i)` (coordinates `2i`, `2i + 1`), the first hung from a pin at the origin, each
//! joined to the one before by a massless rod of length `ℓ`; gravity `g` along `−y` and air
//! drag `F_i = −c v_i` on each mass. The constraints are
//! `g_i = ½(|r_i − r_{i−1}|² − ℓ²) = 0`, `r_{−1} = 0`, one per link.

use forced_vi::model::Structure;
use forced_vi::sparse::{Block, ConstraintSink, NodeSink, SparseNode};
use forced_vi::{ForcedLagrangian, InitialState, Scalar};

/// The chain of `N/2` rigid links (`N` even).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidChain<const N: usize> {
    /// The mass of each link's end.
    pub m: f64,
    /// The length of each link.
    pub l: f64,
    /// Gravity.
    pub g: f64,
    /// The drag coefficient of `F_i = −c v_i`.
    pub c: f64,
}

impl<const N: usize> Default for RigidChain<N> {
    /// Unit length and unit mass in all (`ℓ = m = 2/N`), `g = 9.81`, `c = 0.1 m`.
    fn default() -> Self {
        let n = (N / 2).max(1) as f64;
        RigidChain {
            m: 1.0 / n,
            l: 1.0 / n,
            g: 9.81,
            c: 0.1 / n,
        }
    }
}

impl<const N: usize> RigidChain<N> {
    /// The link angles from the downward vertical of the initial state:
    /// `θ_i = 0.6 + 0.3 sin(π (i + ½)/n)`.
    pub fn initial_angles() -> Vec<f64> {
        let n = N / 2;
        (0..n)
            .map(|i| 0.6 + 0.3 * (std::f64::consts::PI * (i as f64 + 0.5) / n as f64).sin())
            .collect()
    }

    /// The positions of the link angles `theta`, at rest: on the constraints to round-off.
    pub fn at_rest(&self, theta: &[f64]) -> InitialState<N> {
        let mut q = [0.0; N];
        let (mut x, mut y) = (0.0, 0.0);
        for (i, th) in theta.iter().enumerate().take(N / 2) {
            x += self.l * th.sin();
            y -= self.l * th.cos();
            q[2 * i] = x;
            q[2 * i + 1] = y;
        }
        InitialState::from_velocity(q, [0.0; N])
    }

    /// The initial state of the tests: [`Self::initial_angles`], at rest.
    pub fn initial(&self) -> InitialState<N> {
        self.at_rest(&Self::initial_angles())
    }

    /// The coordinates of the mass before mass `i` (`None`: the pin).
    fn before(i: usize) -> Option<usize> {
        i.checked_sub(1).map(|j| 2 * j)
    }
}

impl<const N: usize> ForcedLagrangian<N> for RigidChain<N> {
    const STRUCTURE: Structure = Structure {
        has_force: true,
        force_uses_velocity: true,
        constant_mass: true,
        linear: false,
        uses_time: false,
    };
    // Fixed links: no constraint reads `t` (so the sparse sensitivities take `∂(G v)/∂q`
    // from the kernels' second derivatives, not from `N` dual evaluations of `g`).
    const CONSTRAINTS_READ_TIME: bool = false;

    fn lagrangian<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> D {
        let zero = D::from(0.0);
        let kinetic = v.iter().fold(zero, |s, &vi| s + vi * vi * (0.5 * self.m));
        (0..N / 2).fold(kinetic, |s, i| s - q[2 * i + 1] * (self.m * self.g))
    }

    fn force<D: Scalar>(&self, _q: &[D; N], v: &[D; N]) -> [D; N] {
        v.map(|vi| vi * (-self.c))
    }

    fn constraint_count(&self) -> usize {
        N / 2
    }

    fn constraints<D: Scalar>(&self, _t: D, q: &[D; N], g: &mut [D]) {
        let zero = D::from(0.0);
        for (i, gi) in g.iter_mut().enumerate().take(N / 2) {
            let (px, py) = match Self::before(i) {
                Some(j) => (q[j], q[j + 1]),
                None => (zero, zero),
            };
            let (dx, dy) = (q[2 * i] - px, q[2 * i + 1] - py);
            *gi = (dx * dx + dy * dy - self.l * self.l) * 0.5;
        }
    }

    fn check_parameters(&self) -> Result<(), &'static str> {
        let fields = [("m", self.m), ("l", self.l), ("g", self.g), ("c", self.c)];
        match fields.iter().find(|(_, x)| !x.is_finite()) {
            Some((name, _)) => Err(name),
            None => Ok(()),
        }
    }

    fn check_model(&self) -> Result<(), String> {
        if N.is_multiple_of(2) {
            Ok(())
        } else {
            Err(format!(
                "a planar chain needs an even number of coordinates, not {N}"
            ))
        }
    }

    fn sparse_node(&self) -> Option<&dyn SparseNode> {
        Some(self)
    }
}

impl<const N: usize> SparseNode for RigidChain<N> {
    fn dof(&self) -> usize {
        N
    }

    fn eval(&self, _t: f64, _q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
        let blocks = sink.wants_blocks();
        for (a, &va) in v.iter().enumerate() {
            sink.add_lv(a, self.m * va);
            let gravity = if a % 2 == 1 { -self.m * self.g } else { 0.0 };
            sink.add_lq_f(a, gravity - self.c * va);
            if blocks {
                sink.add(Block::E, a, a, self.m);
                sink.add(Block::B, a, a, -self.c);
            }
        }
    }

    fn lagrangian_value(&self, _t: f64, q: &[f64], v: &[f64]) -> f64 {
        let kinetic: f64 = v.iter().map(|x| 0.5 * self.m * x * x).sum();
        let potential: f64 = q
            .iter()
            .skip(1)
            .step_by(2)
            .map(|y| self.m * self.g * y)
            .sum();
        kinetic - potential
    }

    fn sparse_constraint_count(&self) -> usize {
        N / 2
    }

    fn eval_constraints(&self, _t: f64, q: &[f64], sink: &mut ConstraintSink<'_>) {
        let at = |j: usize| q.get(j).copied().unwrap_or(f64::NAN);
        let derivatives = sink.wants_derivatives();
        for i in 0..N / 2 {
            let prev = Self::before(i);
            let (px, py) = prev.map_or((0.0, 0.0), |j| (at(j), at(j + 1)));
            let (dx, dy) = (at(2 * i) - px, at(2 * i + 1) - py);
            sink.add_value(i, 0.5 * (dx * dx + dy * dy - self.l * self.l));
            if !derivatives {
                continue;
            }
            for (axis, d) in [dx, dy].into_iter().enumerate() {
                let this = 2 * i + axis;
                sink.add_gradient(i, this, d);
                sink.add_curvature(i, this, this, 1.0);
                if let Some(j) = prev {
                    let that = j + axis;
                    sink.add_gradient(i, that, -d);
                    sink.add_curvature(i, that, that, 1.0);
                    sink.add_curvature(i, this, that, -1.0);
                    sink.add_curvature(i, that, this, -1.0);
                }
            }
        }
    }
}
