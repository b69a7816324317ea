//! Ensemble throughput (issue 14): the paper's 25-member ensemble through
//! [`Integrator::ensemble` with `output::Final`] on rayon pools of 1 and 2 threads.

use serde::{Deserialize, Serialize};

use forced_vi::prelude::*;

use crate::models::CoupledVanDerPol;
use crate::report::table::sci;
use crate::report::timing::interleaved;
use crate::scenes::{self, Scene};

/// The final time of every member.
pub const ENSEMBLE_T: f64 = 20.0;

/// The thread counts measured.
pub const THREADS: [usize; 2] = [1, 2];

/// One line of `ensemble_throughput.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ThroughputRecord {
    /// Worker threads of the rayon pool.
    pub threads: usize,
    /// Ensemble members.
    pub members: usize,
    /// Steps of all members divided by the wall time (median over repeats).
    #[serde(with = "sci")]
    pub member_steps_per_second: f64,
}

/// The measurement: the records, the scheme and the final time, or why there is none.
#[derive(Clone, Debug, PartialEq)]
pub struct Throughput {
    /// One record per thread count.
    pub records: Vec<ThroughputRecord>,
    /// The scheme of the run.
    pub method: &'static str,
    /// The final time of every member.
    pub t_final: f64,
    /// Members that ended in an error (their steps are not counted).
    pub failed: usize,
}

impl Throughput {
    /// Throughput on 2 threads ÷ throughput on 1.
    pub fn speedup(&self) -> Option<f64> {
        let at = |t| {
            self.records
                .iter()
                .find(|r| r.threads == t)
                .map(|r| r.member_steps_per_second)
        };
        Some(at(2)? / at(1)?)
    }
}

/// The paper's ensemble as initial states and its final time.
fn paper_members() -> Result<(Vec<InitialState<2>>, f64), String> {
    let all = scenes::all().map_err(|e| e.to_string())?;
    let scene: &dyn Scene = all
        .iter()
        .find(|s| s.name() == "coupled_van_der_pol_ensemble")
        .ok_or("no scene coupled_van_der_pol_ensemble")?
        .as_ref();
    let members = (0..scene.members())
        .filter_map(|m| scene.initial(m))
        .filter_map(|(q, v)| {
            Some(InitialState::from_velocity(
                q.try_into().ok()?,
                v.try_into().ok()?,
            ))
        })
        .collect::<Vec<_>>();
    Ok((members, scene.t_final()))
}

/// Runs the ensemble on each pool size; the two sizes alternate over the repeats.
pub fn measure(quick: bool) -> Result<Throughput, String> {
    let method = "lobatto3";
    let (members, _paper_t) = paper_members()?;
    // The paper's T = 1 makes a whole ensemble about 1 ms of work, of which waking the
    // pool's threads would be a visible part; T = 20 (2000 steps per member) measures the
    // throughput itself.
    let t_final = ENSEMBLE_T;
    let model = CoupledVanDerPol::PAPER;
    let integ = Integrator::new(&model, Scheme::lobatto(3).map_err(|e| e.to_string())?, 0.01)
        .map_err(|e| e.to_string())?;
    let pools = THREADS
        .iter()
        .map(|&t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .map_err(|e| e.to_string())
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut failed = 0;
    let mut rate = |pool: &rayon::ThreadPool| -> Result<f64, String> {
        let t0 = std::time::Instant::now();
        let ends = pool.install(|| integ.ensemble(&members, t_final, output::Final));
        let secs = t0.elapsed().as_secs_f64();
        failed = ends.iter().filter(|e| e.is_err()).count();
        let steps: usize = ends.iter().flatten().map(|e| e.stats.steps).sum();
        Ok(steps as f64 / secs)
    };
    rate(&pools[0])?; // warm-up
    let repeats = if quick { 3 } else { 7 };
    let (one, two) = {
        let rate = std::cell::RefCell::new(&mut rate);
        interleaved(
            repeats,
            || (rate.borrow_mut())(&pools[0]),
            || (rate.borrow_mut())(&pools[1]),
        )?
    };
    let records = [one, two]
        .into_iter()
        .zip(THREADS)
        .map(|(r, threads)| ThroughputRecord {
            threads,
            members: members.len(),
            member_steps_per_second: r,
        })
        .collect();
    Ok(Throughput {
        records,
        method,
        t_final,
        failed,
    })
}
