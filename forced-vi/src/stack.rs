//! Deep stacks for the dual-number kernels of large models.

/// The stack below which [`with_stack`] runs on the caller's stack.
const SMALL_STACK: usize = 256 * 1024;

/// Runs `f` on a stack with `need` bytes to spare: the caller's own stack when it has them,
/// else a fresh one on the heap (`stacker`), so that no model size overflows a thread's
/// stack, whichever thread runs it.
#[inline]
pub(crate) fn with_stack<R>(need: usize, f: impl FnOnce() -> R) -> R {
    if need <= SMALL_STACK {
        f()
    } else {
        // `f` behind a call that is never inlined: inlined into the test of the stack left,
        // its frame would be the caller's, probed on entry before the test could move it
        // (an ensemble of 8192 coordinates overflowed a worker's 2 MiB that way).
        stacker::maybe_grow(need, need.saturating_mul(2), || on_this_stack(f))
    }
}

/// Calls `f` in a frame of its own.
#[inline(never)]
fn on_this_stack<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// The stack that a run of a model of `n` coordinates may take outside its kernels: its
/// set-up and its outputs hold copies of `[f64; n]` values (initial states, records, dense
/// states), about 80 of them on the deepest path (measured with n = 131072, whose frames
/// took 12.6 to 27 MB each on the caller's stack), here with 2.5 times that to spare. Below
/// 129 coordinates this is at most 256 KiB, and [`with_stack`] runs on the caller's stack.
#[inline]
pub(crate) const fn run_stack_bytes(n: usize) -> usize {
    n.saturating_mul(2048)
}

/// [`with_stack`] with [`run_stack_bytes`] for a model of `N` coordinates, decided at
/// compile time: below the threshold `f` runs here (and may be inlined); above it, `f`'s
/// frame is never part of the caller's. A need known only at run time leaves both calls in
/// the caller, and an optimiser that inlined `f` into it put `f`'s frame, megabytes at 8192
/// coordinates, on the caller's stack whichever branch ran (measured: a build of the whole
/// workspace overflowed a 2 MiB thread in `Integrator::solve` where a build of one package
/// did not).
#[inline]
pub(crate) fn with_run_stack<const N: usize, R>(f: impl FnOnce() -> R) -> R {
    if const { run_stack_bytes(N) <= SMALL_STACK } {
        f()
    } else {
        let need = run_stack_bytes(N);
        stacker::maybe_grow(need, need.saturating_mul(2), || on_this_stack(f))
    }
}
