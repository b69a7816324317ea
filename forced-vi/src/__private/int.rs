//! Indexing and integer arithmetic for model code: an index out of range reads NaN and is
//! recorded, integer arithmetic wraps; neither panics.

use core::cell::Cell;

use crate::scalar::Scalar;

std::thread_local! {
    static INDEX_FAULT: Cell<Option<&'static str>> = const { Cell::new(None) };
}

/// `a[i]`, or NaN when `i` is out of range (never a panic); the first such index expression
/// `what` is recorded for [`take_index_fault`]. Generated code uses it for every index that the macro
/// could not prove in range.
#[inline(always)]
pub fn at<D: Scalar, I: Int>(a: &[D], i: I, what: &'static str) -> D {
    match i.to_index().and_then(|k| a.get(k)) {
        Some(x) => *x,
        None => {
            INDEX_FAULT.with(|f| {
                if f.get().is_none() {
                    f.set(Some(what));
                }
            });
            D::from(f64::NAN)
        }
    }
}

/// The index expression of the last out-of-range [`at`] on this thread, cleared.
pub fn take_index_fault() -> Option<&'static str> {
    INDEX_FAULT.with(|f| f.take())
}

/// The integers of model code: arithmetic wraps (an index that wraps is out of range, and
/// [`at`] reports it) instead of panicking.
pub trait Int: Copy {
    /// Wrapping `+`.
    fn wrapping_add_(self, o: Self) -> Self;
    /// Wrapping `-`.
    fn wrapping_sub_(self, o: Self) -> Self;
    /// Wrapping `*`.
    fn wrapping_mul_(self, o: Self) -> Self;
    /// `/`, with the type's maximum for a division by zero.
    fn div_(self, o: Self) -> Self;
    /// `%`, with the type's maximum for a division by zero.
    fn rem_(self, o: Self) -> Self;
    /// The value as an index, if it is one.
    fn to_index(self) -> Option<usize>;
}

macro_rules! impl_int {
    ($($t:ty),*) => {$(
        impl Int for $t {
            #[inline(always)]
            fn wrapping_add_(self, o: Self) -> Self { self.wrapping_add(o) }
            #[inline(always)]
            fn wrapping_sub_(self, o: Self) -> Self { self.wrapping_sub(o) }
            #[inline(always)]
            fn wrapping_mul_(self, o: Self) -> Self { self.wrapping_mul(o) }
            #[inline(always)]
            fn div_(self, o: Self) -> Self { self.checked_div(o).unwrap_or(<$t>::MAX) }
            #[inline(always)]
            fn rem_(self, o: Self) -> Self { self.checked_rem(o).unwrap_or(<$t>::MAX) }
            #[inline(always)]
            fn to_index(self) -> Option<usize> { usize::try_from(self).ok() }
        }
    )*};
}
impl_int!(
    u8, u16, u32, u64, u128, usize, i8, i16, i32, i64, i128, isize
);

/// `a + b` in model code.
#[inline(always)]
pub fn int_add<I: Int>(a: I, b: I) -> I {
    a.wrapping_add_(b)
}
/// `a - b` in model code.
#[inline(always)]
pub fn int_sub<I: Int>(a: I, b: I) -> I {
    a.wrapping_sub_(b)
}
/// `a * b` in model code.
#[inline(always)]
pub fn int_mul<I: Int>(a: I, b: I) -> I {
    a.wrapping_mul_(b)
}
/// `a / b` in model code.
#[inline(always)]
pub fn int_div<I: Int>(a: I, b: I) -> I {
    a.div_(b)
}
/// `a % b` in model code.
#[inline(always)]
pub fn int_rem<I: Int>(a: I, b: I) -> I {
    a.rem_(b)
}
