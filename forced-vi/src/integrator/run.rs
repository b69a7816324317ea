//! The run methods of an [`Integrator`]: every record collected, streamed, sampled at given
//! times, or the final state alone; on either path, through one stepper interface.

use super::Integrator;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
#[cfg(feature = "sparse")]
use crate::sparse::SparseStepper;
use crate::stepper::Stepper;
use crate::trajectory::{
    hermite, DenseState, FinalState, RunFailure, RunStats, SampleFailure, StepRecord,
    StreamFailure, Trajectory,
};

impl<M: ForcedLagrangian<N>, const N: usize> Integrator<'_, M, N> {
    /// Opens the run's stepper on the chosen path and hands it to `visit`.
    fn open<R>(
        &self,
        init: InitialState<N>,
        t_final: f64,
        visit: impl FnOnce(&mut dyn Steps<N>) -> R,
    ) -> Result<R, Error> {
        match self.choose(&init)? {
            #[cfg(feature = "sparse")]
            Some((node, pattern)) => {
                let mut s = self.open_sparse(node, pattern, init, t_final)?;
                Ok(visit(&mut s))
            }
            #[cfg(not(feature = "sparse"))]
            Some(never) => match never {},
            None => {
                let mut s = self.stepper(init, t_final)?;
                Ok(visit(&mut s))
            }
        }
    }

    /// Streams every record to `f` and returns the totals. Memory use does not grow with
    /// the number of steps. On failure the totals up to it come back with the error.
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        mut f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, StreamFailure> {
        let streamed = self.open(init, t_final, |stepper| {
            while let Some(rec) = Iterator::next(stepper) {
                match rec {
                    Ok(r) => f(&r),
                    Err(error) => {
                        return Err(StreamFailure {
                            error,
                            stats: stepper.stats(),
                        })
                    }
                }
            }
            Ok(stepper.stats())
        });
        streamed.unwrap_or_else(|error| {
            Err(StreamFailure {
                error,
                stats: RunStats::default(),
            })
        })
    }

    /// Runs to `t_final` and returns the final state alone: the cheapest run. No record is
    /// kept, and the per-step diagnostics are left out (the velocity solve, the energy and
    /// the work of the force); the final velocity and energy are computed once, at the end.
    /// Each step is solved and checked as in [`Self::run`].
    pub fn final_state(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<FinalState<N>, StreamFailure> {
        let fail = |error, stats| StreamFailure { error, stats };
        let finished = self.open(init, t_final, |stepper| {
            stepper.set_lean(true);
            while let Some(rec) = Iterator::next(stepper) {
                if let Err(e) = rec {
                    return Err(fail(e, stepper.stats()));
                }
            }
            let stats = stepper.stats();
            let end = stepper.finish().map_err(|e| fail(e, stats))?;
            Ok(FinalState {
                t: end.t,
                q: end.q,
                p: end.p,
                v: end.v,
                energy: end.energy,
                stats,
            })
        });
        finished.unwrap_or_else(|e| Err(fail(e, RunStats::default())))
    }

    /// Runs to the last of `times` and returns the dense output at each of them (see
    /// [`DenseState`]), so that the step grid, fixed or adaptive, is free of the output grid.
    /// Only the last step is held, so memory grows with the samples, not the steps. The
    /// times must be finite, non-negative and non-decreasing.
    pub fn sample(
        &self,
        init: InitialState<N>,
        times: &[f64],
    ) -> Result<Vec<DenseState<N>>, SampleFailure<N>> {
        let fail = |error, samples| SampleFailure { error, samples };
        let ordered = times.windows(2).all(|w| w[0] <= w[1]);
        if let Some(&t) = times.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
            return Err(fail(Error::InvalidFinalTime { t_final: t }, Vec::new()));
        }
        if !ordered {
            return Err(fail(Error::UnorderedTimes, Vec::new()));
        }
        let t_final = times.last().copied().unwrap_or(0.0);
        let sampled = self.open(init, t_final, |stepper| {
            let mut out = Vec::with_capacity(times.len());
            let mut prev: Option<StepRecord<N>> = None;
            while let Some(rec) = Iterator::next(stepper) {
                let rec = match rec {
                    Ok(r) => r,
                    Err(e) => return Err(fail(e, out)),
                };
                while let Some(&t) = times.get(out.len()).filter(|&&t| t <= rec.t) {
                    out.push(match &prev {
                        Some(a) => hermite(a, &rec, t),
                        None => hermite(&rec, &rec, t),
                    });
                }
                prev = Some(rec);
            }
            Ok(out)
        });
        sampled.unwrap_or_else(|e| Err(fail(e, Vec::new())))
    }

    /// Runs to `t_final` and collects every record. On failure the records computed so far
    /// come back with the error.
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        let adaptive = self.tolerance.is_some();
        let collected = self.open(init, t_final, |stepper| collect(stepper, adaptive));
        collected.unwrap_or_else(|error| {
            Err(RunFailure {
                error,
                trajectory: Trajectory::default(),
            })
        })
    }
}

/// Collects a run's records. A fixed-step run reserves all its records up front, so that a
/// run that cannot hold them fails before its first step rather than aborting in the
/// middle; an adaptive one grows its storage fallibly.
fn collect<const N: usize>(
    stepper: &mut dyn Steps<N>,
    adaptive: bool,
) -> Result<Trajectory<N>, RunFailure<N>> {
    let mut traj = Trajectory::default();
    let records = stepper.total_steps().saturating_add(1);
    let reserve = if adaptive { records.min(1024) } else { records };
    if traj.records.try_reserve_exact(reserve).is_err() {
        return Err(RunFailure {
            error: Error::TooManyRecords { records },
            trajectory: traj,
        });
    }
    while let Some(rec) = Iterator::next(stepper) {
        match rec {
            Ok(r) => {
                if traj.records.len() == traj.records.capacity()
                    && traj.records.try_reserve(traj.records.len()).is_err()
                {
                    traj.stats = stepper.stats();
                    let records = traj.records.len() * 2;
                    return Err(RunFailure {
                        error: Error::TooManyRecords { records },
                        trajectory: traj,
                    });
                }
                traj.records.push(r)
            }
            Err(error) => {
                traj.stats = stepper.stats();
                return Err(RunFailure {
                    error,
                    trajectory: traj,
                });
            }
        }
    }
    traj.stats = stepper.stats();
    Ok(traj)
}

/// A run's stepper on either path, as the run methods drive it.
trait Steps<const N: usize>: Iterator<Item = Result<StepRecord<N>, Error>> {
    fn stats(&self) -> RunStats;
    fn total_steps(&self) -> usize;
    fn set_lean(&mut self, lean: bool);
    fn finish(&mut self) -> Result<StepRecord<N>, Error>;
}

impl<M: ForcedLagrangian<N>, const N: usize> Steps<N> for Stepper<'_, M, N> {
    fn stats(&self) -> RunStats {
        Stepper::stats(self)
    }
    fn total_steps(&self) -> usize {
        Stepper::total_steps(self)
    }
    fn set_lean(&mut self, lean: bool) {
        Stepper::set_lean(self, lean)
    }
    fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        Stepper::finish(self)
    }
}

#[cfg(feature = "sparse")]
impl<M: ForcedLagrangian<N>, const N: usize> Steps<N> for SparseStepper<'_, M, N> {
    fn stats(&self) -> RunStats {
        SparseStepper::stats(self)
    }
    fn total_steps(&self) -> usize {
        SparseStepper::total_steps(self)
    }
    fn set_lean(&mut self, lean: bool) {
        SparseStepper::set_lean(self, lean)
    }
    fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        SparseStepper::finish(self)
    }
}
