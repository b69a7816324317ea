//! The scalar bound that all model code is generic over.

use num_dual::DualNum;

/// A real number or a dual number built on `f64`.
///
/// Model code (the Lagrangian and the force) is written once, generic over `D: Scalar`, and
/// evaluated with `f64` for values and with num-dual's dual numbers for exact derivatives.
/// This is a trait alias for `DualNum<Primitive = f64> + Copy` with a blanket impl.
pub trait Scalar: DualNum<Primitive = f64> + Copy {}

impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

/// Lifts an `f64` array into any scalar type (with zero derivative parts).
#[inline]
pub fn lift<D: Scalar, const N: usize>(x: &[f64; N]) -> [D; N] {
    std::array::from_fn(|i| D::from(x[i]))
}

/// Whether every entry of a small matrix is finite.
pub(crate) fn all_finite<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f64, R, C>) -> bool {
    m.iter().all(|x| x.is_finite())
}
