//! The choice of a run's backend: [`LinearPath`], and the node pattern recorded for the
//! sparse one.

use super::Integrator;
use crate::MAX_KERNEL_STACK;
use crate::backend::{Backend, DenseBackend};
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::newton::NewtonOptions;
use crate::scheme::Scheme;
#[cfg(feature = "sparse")]
use crate::{
    backend::{ConstraintRate, SparseBackend},
    model::{DualConstraints, NodePattern},
    sparse::equations::NodeRef,
    sparse::{record_constraint_patterns, record_node_pattern},
};

/// Which linear algebra a run uses: the dense backend with `N × N` node blocks, or the
/// sparse backend of DESIGN §9 on the model's [`SparseNode`](crate::model::SparseNode)
/// kernels. Both run the same [`Stepper`](crate::Stepper), with fixed or adaptive steps,
/// and every run method.
///
/// [`LinearPath::Auto`] (the default) takes the sparse backend when the model has sparse
/// kernels ([`ForcedLagrangian::sparse_node`]), at least [`LinearPath::SPARSE_MIN_DOF`]
/// coordinates, and a node pattern (the union of the blocks `A, B, C, E`, recorded at the
/// initial state) with at most [`LinearPath::SPARSE_MAX_DENSITY`] `· N²` entries; otherwise
/// the dense one. The dense backend takes at most [`LinearPath::DENSE_MAX_DOF`]
/// coordinates: a larger model without sparse kernels is [`Error::ModelTooLarge`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[non_exhaustive]
pub enum LinearPath {
    /// By size and density (see above).
    #[default]
    Auto,
    /// Always the dense backend.
    Dense,
    /// Always the sparse backend; a model without sparse kernels is
    /// [`Error::NoSparseKernels`], one whose pattern is denser than
    /// [`LinearPath::SPARSE_FORCED_MAX_DENSITY`] is [`Error::PatternTooDense`].
    Sparse,
}

impl LinearPath {
    /// The fewest coordinates for which [`LinearPath::Auto`] takes the sparse backend.
    ///
    /// Measured on the hand-written FPU chain (3 entries per row, lobatto3, release, medians;
    /// `examples/large_chain.rs --crossover`): dense 15.5, 46.5, 256 and 1941 µs per step at
    /// n = 4, 8, 16 and 32, sparse 4.0, 6.0, 10.2 and 21.8 µs. The sparse step wins from
    /// n = 4 against general dense kernels; the macro's specialised dense kernels of small
    /// models take a few µs, so below n = 8 the dense backend is kept.
    pub const SPARSE_MIN_DOF: usize = 8;
    /// The densest node pattern, as a fraction of `N²`, for which [`LinearPath::Auto`] takes
    /// the sparse backend.
    pub const SPARSE_MAX_DENSITY: f64 = 0.25;
    /// The densest node pattern, as a fraction of `N²`, that [`LinearPath::Sparse`] accepts
    /// from [`LinearPath::SPARSE_MIN_DOF`] coordinates on (smaller models are accepted
    /// whatever their pattern). Denser, sparse storage costs more than the dense backend.
    pub const SPARSE_FORCED_MAX_DENSITY: f64 = 0.5;
    /// The most coordinates the dense backend takes. Its step matrix has `((s − 1) N)²`
    /// entries and its LU `O(((s − 1) N)³)` operations, and its node kernels return four
    /// `N × N` blocks by value (8 MiB at `N = 512`), which the stepper runs on a stack sized
    /// for them. Measured (`step-cost`, lattice_2d, lobatto3): 52 ms per dense step at
    /// n = 256 against 0.9 ms sparse, and about 3 s predicted at n = 1024; the dense
    /// backend's every run method at `N = 512` is `tests/trust_dense_stack.rs`.
    pub const DENSE_MAX_DOF: usize = 512;
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> Integrator<'m, M, N> {
    /// The backend a run from `init` takes ([`LinearPath::Dense`] or
    /// [`LinearPath::Sparse`]), or why it cannot run.
    pub fn path_for(&self, init: &InitialState<N>) -> Result<LinearPath, Error> {
        Ok(
            match self.backend(init, &self.scheme, self.options.newton)? {
                Backend::Dense(_) => LinearPath::Dense,
                #[cfg(feature = "sparse")]
                Backend::Sparse(_) => LinearPath::Sparse,
            },
        )
    }

    /// Whether every run takes the dense backend whatever its initial state, so that a
    /// stepper can be restarted from any other (see [`Integrator::runs`]): the sparse
    /// backend's pattern, and with [`LinearPath::Auto`] the choice of backend itself, depend
    /// on the initial state.
    pub(super) fn dense_for_every_start(&self) -> bool {
        match self.linear_path {
            LinearPath::Dense => true,
            LinearPath::Sparse => false,
            LinearPath::Auto => {
                self.model.sparse_node().is_none() || N < LinearPath::SPARSE_MIN_DOF
            }
        }
    }

    /// The backend of a run from `init` with `scheme`, with its buffers.
    pub(super) fn backend<'s>(
        &'s self,
        init: &InitialState<N>,
        scheme: &'s Scheme,
        newton: NewtonOptions,
    ) -> Result<Backend<'s, M, N>, Error> {
        if self.model.constraint_count() > 0 {
            check_constrained(self.model, scheme)?;
        }
        #[cfg(feature = "sparse")]
        if let Some(backend) = self.sparse_backend(init, scheme, newton)? {
            return Ok(Backend::Sparse(Box::new(backend)));
        }
        #[cfg(not(feature = "sparse"))]
        if self.linear_path == LinearPath::Sparse {
            let _ = init;
            return Err(Error::NoSparseKernels {
                reason: "forced-vi was built without its `sparse` feature",
            });
        }
        check_dense::<M, N>()?;
        if self.model.constraint_count() > 0 {
            let stack = crate::model::general::constraint_stack_bytes::<N>();
            if stack > MAX_KERNEL_STACK {
                return Err(Error::ModelTooLarge {
                    dof: N,
                    max_dof: LinearPath::DENSE_MAX_DOF,
                    stack_bytes: stack,
                    max: MAX_KERNEL_STACK,
                });
            }
        }
        Ok(Backend::Dense(Box::new(DenseBackend::new(
            self.model, scheme, newton,
        ))))
    }

    /// The sparse backend if the run takes it.
    #[cfg(feature = "sparse")]
    fn sparse_backend<'s>(
        &'s self,
        init: &InitialState<N>,
        scheme: &'s Scheme,
        newton: NewtonOptions,
    ) -> Result<Option<SparseBackend<'s>>, Error> {
        let node = match (self.linear_path, self.model.sparse_node()) {
            (LinearPath::Dense, _) => return Ok(None),
            (LinearPath::Sparse, None) => {
                return Err(Error::NoSparseKernels {
                    reason: "the model has no sparse node kernels",
                });
            }
            (LinearPath::Auto, Some(_)) if N < LinearPath::SPARSE_MIN_DOF => return Ok(None),
            (LinearPath::Auto, None) => return Ok(None),
            (_, Some(node)) => node,
        };
        // A constrained model whose node kernels do not evaluate its constraints gets them
        // from its generic `constraints` with dual numbers (`DualConstraints`).
        let cons = self.model.constraint_count();
        // `M::CONSTRAINED` first, alone: a model that promises no constraints compiles none
        // of their code (see `ForcedLagrangian::CONSTRAINED`).
        let node = if M::CONSTRAINED && cons > 0 && node.sparse_constraint_count() != cons {
            if node.sparse_constraint_count() != 0 {
                return Err(Error::InvalidModel {
                    message: format!(
                        "the sparse kernels evaluate {} constraints, the model declares {cons}",
                        node.sparse_constraint_count()
                    ),
                });
            }
            NodeRef::Owned(Box::new(DualConstraints {
                model: self.model,
                node,
            }))
        } else {
            NodeRef::Borrowed(node)
        };
        let constant_mass = M::STRUCTURE.constant_mass;
        let path = (self.linear_path, constant_mass);
        let model = self.model;
        let reads_time = M::CONSTRAINED && M::CONSTRAINTS_READ_TIME && cons > 0;
        let rate: Option<ConstraintRate<'_>> = reads_time.then(|| {
            Box::new(move |t: f64, q: &[f64], out: &mut [f64]| {
                crate::model::general::constraint_rate_at(model, t, q, out)
            }) as ConstraintRate<'_>
        });
        sparse_backend_on(node, init.as_slices(), (cons, rate), scheme, newton, path)
    }
}

/// The sparse backend on the node kernels `node` if the run takes it: the pattern at the
/// initial state `(q, v)` (`v = None` for initial momenta: the pattern at `v = 0`), with
/// `cons` constraints, against the density limits of `path = (linear path, constant mass)`.
/// Not generic over the model: one copy serves every model.
#[cfg(feature = "sparse")]
fn sparse_backend_on<'s>(
    node: NodeRef<'s>,
    (q, v): (&[f64], Option<&[f64]>),
    (cons, rate): (usize, Option<ConstraintRate<'s>>),
    scheme: &'s Scheme,
    newton: NewtonOptions,
    (linear_path, constant_mass): (LinearPath, bool),
) -> Result<Option<SparseBackend<'s>>, Error> {
    let n = q.len();
    let mut pattern = match v {
        Some(v) => record_node_pattern(node.get(), 0.0, q, v)?,
        None => record_node_pattern(node.get(), 0.0, q, &vec![0.0; n])?,
    };
    // The constraints' curvature adds to the diagonal node blocks: its entries join the
    // node pattern.
    let g_pattern = if cons > 0 {
        let (g, curvature) = record_constraint_patterns(node.get(), 0.0, q)?;
        let pairs = pattern.entries().chain(curvature).collect();
        pattern = NodePattern::from_pairs(n, pairs);
        Some(g)
    } else {
        None
    };
    let fill = pattern.nnz() as f64 / (n as f64 * n as f64);
    match linear_path {
        LinearPath::Auto if fill > LinearPath::SPARSE_MAX_DENSITY => return Ok(None),
        LinearPath::Sparse
            if n >= LinearPath::SPARSE_MIN_DOF && fill > LinearPath::SPARSE_FORCED_MAX_DENSITY =>
        {
            return Err(Error::PatternTooDense {
                nnz: pattern.nnz(),
                n,
                fill,
                max: LinearPath::SPARSE_FORCED_MAX_DENSITY,
            });
        }
        _ => {}
    }
    SparseBackend::new(
        node,
        scheme,
        (pattern, g_pattern),
        newton,
        constant_mass,
        rate,
    )
    .map(Some)
}

/// Refuses a model too large for the dense backend: more than
/// [`LinearPath::DENSE_MAX_DOF`] coordinates, or kernels that need more stack than
/// [`MAX_KERNEL_STACK`].
/// A constrained model needs fewer constraints than coordinates and a Lobatto scheme (its
/// multipliers live at the control points, DESIGN §11).
fn check_constrained<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    scheme: &Scheme,
) -> Result<(), Error> {
    if model.constraint_count() >= N {
        return Err(Error::UnsupportedConstraints {
            message: "as many constraints as coordinates or more: no coordinate is left free",
        });
    }
    if !matches!(scheme.id(), crate::SchemeId::Lobatto(_)) {
        return Err(Error::UnsupportedConstraints {
            message: "constrained models need a Lobatto scheme (lobatto2 is RATTLE)",
        });
    }
    Ok(())
}

pub(super) fn check_dense<M: ForcedLagrangian<N>, const N: usize>() -> Result<(), Error> {
    if N > LinearPath::DENSE_MAX_DOF || M::KERNEL_STACK_BYTES > MAX_KERNEL_STACK {
        return Err(Error::ModelTooLarge {
            dof: N,
            max_dof: LinearPath::DENSE_MAX_DOF,
            stack_bytes: M::KERNEL_STACK_BYTES,
            max: MAX_KERNEL_STACK,
        });
    }
    Ok(())
}
