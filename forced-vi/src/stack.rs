//! Deep stacks for the dual-number kernels of large models.

/// Runs `f` on a stack with `need` bytes to spare: the caller's own stack when it has them,
/// else a fresh one on the heap (`stacker`), so that no model size overflows a thread's
/// stack, whichever thread runs it.
#[inline]
pub(crate) fn with_stack<R>(need: usize, f: impl FnOnce() -> R) -> R {
    if need <= 256 * 1024 {
        f()
    } else {
        stacker::maybe_grow(need, need.saturating_mul(2), f)
    }
}
