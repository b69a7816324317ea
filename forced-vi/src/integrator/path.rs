//! The choice of the dense or the sparse step for a run: [`LinearPath`] and the pattern
//! recorded for the sparse one.

use super::Integrator;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
#[cfg(feature = "sparse")]
use crate::sparse::{record_node_pattern, NodePattern, SparseNode, SparseStepper};

/// Which linear algebra a run uses: the dense step with `N × N` node blocks, or the sparse
/// step of DESIGN §9 on the model's [`SparseNode`] kernels.
///
/// [`LinearPath::Auto`] (the default) takes the sparse path when the model has sparse
/// kernels ([`ForcedLagrangian::sparse_node`]), at least [`LinearPath::SPARSE_MIN_DOF`]
/// coordinates, and a node pattern (the union of the blocks `A, B, C, E`, recorded at the
/// initial state) with at most [`LinearPath::SPARSE_MAX_DENSITY`] `· N²` entries; otherwise
/// the dense one. The sparse path steps with a fixed `h` only: an adaptive run that would
/// take it fails with [`Error::SparsePathUnavailable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum LinearPath {
    /// By size and density (see above).
    #[default]
    Auto,
    /// Always the dense step.
    Dense,
    /// Always the sparse step; a model without sparse kernels is an error.
    Sparse,
}

impl LinearPath {
    /// The fewest coordinates for which [`LinearPath::Auto`] takes the sparse path.
    ///
    /// Measured on the hand-written FPU chain (3 entries per row, lobatto3, release, medians;
    /// `examples/large_chain.rs --crossover`): dense 15.5, 46.5, 256 and 1941 µs per step at
    /// n = 4, 8, 16 and 32, sparse 4.0, 6.0, 10.2 and 21.8 µs. The sparse step wins from
    /// n = 4 against general dense kernels; the macro's specialised dense kernels of small
    /// models take a few µs, so below n = 8 the dense path is kept.
    pub const SPARSE_MIN_DOF: usize = 8;
    /// The densest node pattern, as a fraction of `N²`, for which [`LinearPath::Auto`] takes
    /// the sparse path.
    pub const SPARSE_MAX_DENSITY: f64 = 0.25;
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> Integrator<'m, M, N> {
    /// The path a run from `init` takes ([`LinearPath::Dense`] or [`LinearPath::Sparse`]),
    /// or why it cannot run.
    pub fn path_for(&self, init: &InitialState<N>) -> Result<LinearPath, Error> {
        Ok(match self.choose(init)? {
            Some(_) => LinearPath::Sparse,
            None => LinearPath::Dense,
        })
    }

    /// The sparse kernels and their pattern if the run takes the sparse path.
    #[cfg(feature = "sparse")]
    pub(super) fn choose(
        &self,
        init: &InitialState<N>,
    ) -> Result<Option<(&'m dyn SparseNode, NodePattern)>, Error> {
        let node = self.model.sparse_node();
        let node = match (self.linear_path, node) {
            (LinearPath::Dense, _) => return Ok(None),
            (LinearPath::Sparse, None) => {
                return Err(Error::SparsePathUnavailable {
                    reason: "the model has no sparse node kernels",
                })
            }
            (LinearPath::Auto, Some(_)) if N < LinearPath::SPARSE_MIN_DOF => return Ok(None),
            (LinearPath::Auto, None) => return Ok(None),
            (_, Some(node)) => node,
        };
        let pattern = self.record_pattern(node, init)?;
        let dense_enough = pattern.nnz() as f64 > LinearPath::SPARSE_MAX_DENSITY * (N * N) as f64;
        if self.linear_path == LinearPath::Auto && dense_enough {
            return Ok(None);
        }
        Ok(Some((node, pattern)))
    }

    /// Without the `sparse` feature every run takes the dense path.
    #[cfg(not(feature = "sparse"))]
    pub(super) fn choose(
        &self,
        _init: &InitialState<N>,
    ) -> Result<Option<std::convert::Infallible>, Error> {
        match self.linear_path {
            LinearPath::Sparse => Err(Error::SparsePathUnavailable {
                reason: "forced-vi was built without its `sparse` feature",
            }),
            LinearPath::Auto | LinearPath::Dense => Ok(None),
        }
    }

    /// Records the node pattern at the initial state (at `v = 0` for initial momenta).
    #[cfg(feature = "sparse")]
    pub(super) fn record_pattern(
        &self,
        node: &dyn SparseNode,
        init: &InitialState<N>,
    ) -> Result<NodePattern, Error> {
        if self.tolerance.is_some() {
            return Err(Error::SparsePathUnavailable {
                reason: "adaptive step control is not implemented on the sparse path",
            });
        }
        match init {
            InitialState::Velocity { q, v } => record_node_pattern(node, 0.0, q, v),
            InitialState::Momentum { q, .. } => record_node_pattern(node, 0.0, q, &vec![0.0; N]),
        }
    }

    /// The sparse stepper of a run on the recorded `pattern`.
    #[cfg(feature = "sparse")]
    pub(super) fn open_sparse(
        &self,
        node: &'m dyn SparseNode,
        pattern: NodePattern,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<SparseStepper<'_, M, N>, Error> {
        SparseStepper::new(self, node, pattern, init, t_final)
    }
}
