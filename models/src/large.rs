//! Large sparse models, written by hand (DESIGN §9): an FPU-β chain and a 2-D membrane, with
//! the generic [`ForcedLagrangian`] (for the dense path) and [`SparseNode`] kernels that
//! differentiate each local term with a small num-dual number and scatter its blocks.
//!
//! Both share the spring law `V(d) = ½k d² + ¼β d⁴` on the bonds between neighbours, fixed
//! (zero) boundaries, masses `m` and the damping force `F_i = −c v_i`:
//! `L = Σ ½ m v_i² − Σ_bonds V(q_right − q_left)`.

use forced_vi::model::Structure;
use forced_vi::sparse::{Block, NodeSink, SparseNode};
use forced_vi::{ForcedLagrangian, InitialState, Scalar};
use nalgebra::{SMatrix, SVector};
use num_dual::{gradient, hessian, Dual2SVec64, DualSVec64};

/// The parameters shared by the scenes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringLaw {
    /// Mass of each site.
    pub m: f64,
    /// Linear spring constant.
    pub k: f64,
    /// Quartic (FPU-β) coefficient.
    pub beta: f64,
    /// Damping coefficient of `F_i = −c v_i`.
    pub c: f64,
}

impl SpringLaw {
    /// The scenes' defaults: `m = 1, k = 1, β = 1, c = 0.01`.
    pub const DEFAULT: SpringLaw = SpringLaw {
        m: 1.0,
        k: 1.0,
        beta: 1.0,
        c: 0.01,
    };

    fn potential<D: Scalar>(&self, d: D) -> D {
        let d2 = d * d;
        d2 * (0.5 * self.k) + d2 * d2 * (0.25 * self.beta)
    }

    fn check(&self) -> Result<(), &'static str> {
        let fields = [
            ("m", self.m),
            ("k", self.k),
            ("beta", self.beta),
            ("c", self.c),
        ];
        match fields.iter().find(|(_, x)| !x.is_finite()) {
            Some((name, _)) => Err(name),
            None => Ok(()),
        }
    }
}

/// A bond: the sites at its two ends (`None` is the fixed wall).
type Bond = (Option<usize>, Option<usize>);

/// The FPU-β chain of `N` masses between two fixed walls: bonds `d_i = q_i − q_{i−1}` for
/// `i = 0 … N`, with `q_{−1} = q_N = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FpuChain<const N: usize> {
    /// The spring law and damping.
    pub law: SpringLaw,
}

impl<const N: usize> Default for FpuChain<N> {
    fn default() -> Self {
        FpuChain {
            law: SpringLaw::DEFAULT,
        }
    }
}

impl<const N: usize> FpuChain<N> {
    fn bonds(&self) -> impl Iterator<Item = Bond> {
        (0..=N).map(|i| (i.checked_sub(1), (i < N).then_some(i)))
    }

    /// A smooth initial state: the two lowest modes, `q_i = 0.5 sin(π x) + 0.1 sin(3π x)` at
    /// `x = (i + 1)/(N + 1)`, at rest.
    pub fn initial() -> InitialState<N> {
        let x = |i: usize| std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64;
        let q = std::array::from_fn(|i| 0.5 * x(i).sin() + 0.1 * (3.0 * x(i)).sin());
        InitialState::from_velocity(q, [0.0; N])
    }
}

/// A `W × W` membrane (`N = W²` sites, row-major), each site bonded to its 4 neighbours,
/// with a fixed rim.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice2d<const W: usize, const N: usize> {
    /// The spring law and damping.
    pub law: SpringLaw,
}

impl<const W: usize, const N: usize> Default for Lattice2d<W, N> {
    fn default() -> Self {
        Lattice2d {
            law: SpringLaw::DEFAULT,
        }
    }
}

impl<const W: usize, const N: usize> Lattice2d<W, N> {
    fn bonds(&self) -> impl Iterator<Item = Bond> {
        let site = |r: usize, c: usize| r * W + c;
        let rows = (0..W).flat_map(move |r| {
            (0..=W).map(move |c| {
                (
                    c.checked_sub(1).map(|c| site(r, c)),
                    (c < W).then(|| site(r, c)),
                )
            })
        });
        let cols = (0..W).flat_map(move |c| {
            (0..=W).map(move |r| {
                (
                    r.checked_sub(1).map(|r| site(r, c)),
                    (r < W).then(|| site(r, c)),
                )
            })
        });
        rows.chain(cols)
    }

    /// A smooth initial state: `q = 0.5 sin(π x) sin(π y) + 0.1 sin(3π x) sin(2π y)`, at rest.
    pub fn initial() -> InitialState<N> {
        let x = |i: usize| std::f64::consts::PI * (i + 1) as f64 / (W + 1) as f64;
        let q = std::array::from_fn(|s| {
            let (r, c) = (s / W.max(1), s % W.max(1));
            0.5 * x(r).sin() * x(c).sin() + 0.1 * (3.0 * x(r)).sin() * (2.0 * x(c)).sin()
        });
        InitialState::from_velocity(q, [0.0; N])
    }
}

/// `L` over any scalar, from the bonds.
fn lagrangian<D: Scalar, const N: usize>(
    law: &SpringLaw,
    bonds: impl Iterator<Item = Bond>,
    q: &[D; N],
    v: &[D; N],
) -> D {
    let zero = D::from(0.0);
    let kinetic = v.iter().fold(zero, |s, &vi| s + vi * vi * (0.5 * law.m));
    let get = |i: Option<usize>| i.map_or(zero, |i| q[i]);
    bonds.fold(kinetic, |s, (l, r)| s - law.potential(get(r) - get(l)))
}

/// The sparse node kernels from the bonds: each bond's `−V` is differentiated with a
/// second-order dual number over its two ends, each kinetic term over its velocity.
fn eval(
    law: &SpringLaw,
    bonds: impl Iterator<Item = Bond>,
    q: &[f64],
    v: &[f64],
    sink: &mut NodeSink<'_>,
) {
    let blocks = sink.wants_blocks();
    let get = |i: Option<usize>| i.map_or(0.0, |i| q.get(i).copied().unwrap_or(f64::NAN));
    // The second derivatives only where the blocks are asked for: a residual needs the
    // gradient alone (first-order duals, about half the work of the Hessian's).
    let bond = |x: SVector<f64, 2>| -> (SVector<f64, 2>, Option<SMatrix<f64, 2, 2>>) {
        if blocks {
            let (_, g, hs) = hessian(
                |x: SVector<Dual2SVec64<2>, 2>| -law.potential(x[1] - x[0]),
                &x,
            );
            (g, Some(hs))
        } else {
            let (_, g) = gradient(
                |x: SVector<DualSVec64<2>, 2>| -law.potential(x[1] - x[0]),
                &x,
            );
            (g, None)
        }
    };
    for (l, r) in bonds {
        let (g, hs) = bond(SVector::from([get(l), get(r)]));
        let ends = [l, r];
        for (a, ia) in ends.iter().enumerate() {
            let Some(ia) = *ia else { continue };
            sink.add_lq_f(ia, g[a]);
            if let Some(hs) = &hs {
                for (b, ib) in ends.iter().enumerate() {
                    if let Some(ib) = *ib {
                        sink.add(Block::A, ia, ib, hs[(a, b)]);
                    }
                }
            }
        }
    }
    let kinetic = |x: SVector<f64, 1>| -> (f64, Option<f64>) {
        if blocks {
            let (_, g, hs) = hessian(
                |x: SVector<Dual2SVec64<1>, 1>| x[0] * x[0] * (0.5 * law.m),
                &x,
            );
            (g[0], Some(hs[(0, 0)]))
        } else {
            let (_, g) = gradient(
                |x: SVector<DualSVec64<1>, 1>| x[0] * x[0] * (0.5 * law.m),
                &x,
            );
            (g[0], None)
        }
    };
    for (i, &vi) in v.iter().enumerate() {
        let (lv, e) = kinetic(SVector::from([vi]));
        sink.add_lv(i, lv);
        // The force −c v is linear: its value and its ∂F/∂v = −c are exact as written.
        sink.add_lq_f(i, -law.c * vi);
        if let Some(e) = e {
            sink.add(Block::E, i, i, e);
            sink.add(Block::B, i, i, -law.c);
        }
    }
}

fn lagrangian_value(
    law: &SpringLaw,
    bonds: impl Iterator<Item = Bond>,
    q: &[f64],
    v: &[f64],
) -> f64 {
    let get = |i: Option<usize>| i.map_or(0.0, |i| q.get(i).copied().unwrap_or(f64::NAN));
    let kinetic: f64 = v.iter().map(|vi| 0.5 * law.m * vi * vi).sum();
    kinetic
        - bonds
            .map(|(l, r)| law.potential(get(r) - get(l)))
            .sum::<f64>()
}

/// The structure both scenes promise: a velocity-dependent force, constant mass.
const STRUCTURE: Structure = Structure {
    has_force: true,
    force_uses_velocity: true,
    constant_mass: true,
    linear: false,
    uses_time: false,
};

impl<const N: usize> ForcedLagrangian<N> for FpuChain<N> {
    // No constraints: the runtime leaves their code out.
    const CONSTRAINED: bool = false;
    const STRUCTURE: Structure = STRUCTURE;
    fn lagrangian<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> D {
        lagrangian(&self.law, self.bonds(), q, v)
    }
    fn force<D: Scalar>(&self, _q: &[D; N], v: &[D; N]) -> [D; N] {
        v.map(|vi| vi * (-self.law.c))
    }
    fn check_parameters(&self) -> Result<(), &'static str> {
        self.law.check()
    }
    fn sparse_node(&self) -> Option<&dyn SparseNode> {
        Some(self)
    }
}

impl<const N: usize> SparseNode for FpuChain<N> {
    fn dof(&self) -> usize {
        N
    }
    fn eval(&self, _t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
        eval(&self.law, self.bonds(), q, v, sink)
    }
    fn lagrangian_value(&self, _t: f64, q: &[f64], v: &[f64]) -> f64 {
        lagrangian_value(&self.law, self.bonds(), q, v)
    }
}

impl<const W: usize, const N: usize> ForcedLagrangian<N> for Lattice2d<W, N> {
    // No constraints: the runtime leaves their code out.
    const CONSTRAINED: bool = false;
    const STRUCTURE: Structure = STRUCTURE;
    fn lagrangian<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> D {
        lagrangian(&self.law, self.bonds(), q, v)
    }
    fn force<D: Scalar>(&self, _q: &[D; N], v: &[D; N]) -> [D; N] {
        v.map(|vi| vi * (-self.law.c))
    }
    fn check_parameters(&self) -> Result<(), &'static str> {
        self.law.check()
    }
    fn check_model(&self) -> Result<(), String> {
        if W * W == N {
            Ok(())
        } else {
            Err(format!(
                "a {W} × {W} lattice has {} sites, not N = {N}",
                W * W
            ))
        }
    }
    fn sparse_node(&self) -> Option<&dyn SparseNode> {
        Some(self)
    }
}

impl<const W: usize, const N: usize> SparseNode for Lattice2d<W, N> {
    fn dof(&self) -> usize {
        N
    }
    fn eval(&self, _t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
        eval(&self.law, self.bonds(), q, v, sink)
    }
    fn lagrangian_value(&self, _t: f64, q: &[f64], v: &[f64]) -> f64 {
        lagrangian_value(&self.law, self.bonds(), q, v)
    }
}
