//! The timing loop: wall times of repeated runs and their median.
//!
//! Every command times the same way: run once, decide from that first time how many repeats
//! fit the budget, and report the median. Where two variants are compared (`step-cost`), the
//! repeats alternate which goes first, so that drifts in machine load hit both alike.

use std::time::Instant;

/// The median of `xs` (NaN for none).
pub fn median(xs: &mut [f64]) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        xs[n / 2]
    } else {
        0.5 * (xs[n / 2 - 1] + xs[n / 2])
    }
}

/// Runs `f` and returns its result with the wall time in seconds.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let out = f();
    (out, start.elapsed().as_secs_f64())
}

/// A run timed over repeats.
#[derive(Clone, Debug, PartialEq)]
pub struct Timing<T> {
    /// The result of the first run.
    pub first: T,
    /// The wall time of the first run, seconds.
    pub first_seconds: f64,
    /// The median wall time over all runs, seconds.
    pub median: f64,
}

/// Runs `f` once, then `repeats(first time) − 1` more times, stopping at the first error.
pub fn repeated<T, E>(
    repeats: impl FnOnce(f64) -> usize,
    mut f: impl FnMut() -> Result<T, E>,
) -> Result<Timing<T>, E> {
    let (first, first_seconds) = timed(&mut f);
    let first = first?;
    let mut times = vec![first_seconds];
    for _ in 1..repeats(first_seconds) {
        let (r, t) = timed(&mut f);
        r?;
        times.push(t);
    }
    Ok(Timing {
        first,
        first_seconds,
        median: median(&mut times),
    })
}

/// Medians of two measurements `a` and `b` over `repeats` rounds, alternating which runs
/// first. Each call returns one sample (for instance nanoseconds per step).
pub fn interleaved<E>(
    repeats: usize,
    mut a: impl FnMut() -> Result<f64, E>,
    mut b: impl FnMut() -> Result<f64, E>,
) -> Result<(f64, f64), E> {
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for k in 0..repeats {
        if k % 2 == 0 {
            ta.push(a()?);
            tb.push(b()?);
        } else {
            tb.push(b()?);
            ta.push(a()?);
        }
    }
    Ok((median(&mut ta), median(&mut tb)))
}

/// Medians of several measurements over `repeats` rounds, each round running all of them
/// and starting one further along (round `k` starts with `fs[k mod n]`), so that drifts in
/// machine load and the cost of going first hit each alike. Each call returns one sample.
pub fn rotated<E>(
    repeats: usize,
    fs: &mut [&mut dyn FnMut() -> Result<f64, E>],
) -> Result<Vec<f64>, E> {
    let n = fs.len();
    let mut samples = vec![Vec::with_capacity(repeats); n];
    for k in 0..repeats {
        for j in 0..n {
            let i = (k + j) % n;
            samples[i].push(fs[i]()?);
        }
    }
    Ok(samples.iter_mut().map(|s| median(s)).collect())
}
