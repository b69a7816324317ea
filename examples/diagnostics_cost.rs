//! Cost per step with full diagnostics (`output::each_step`: records, velocity solve, energy,
//! work) against the final state alone (`final_state`), coupled van der Pol, h = 0.01,
//! T = 100: `cargo run --release --example diagnostics_cost`. Medians of 9 interleaved runs.
use forced_vi::prelude::*;
use forced_vi_scenes::models::CoupledVanDerPol;

fn main() {
    let m = CoupledVanDerPol::PAPER;
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    println!("scheme,full_ns_per_step,final_state_ns_per_step,ratio");
    for id in ["midpoint", "lobatto2", "lobatto3", "lobatto4", "lobatto5"] {
        let integ = Integrator::new(&m, Scheme::new(id.parse().unwrap()).unwrap(), 0.01).unwrap();
        let (mut full, mut lean) = (vec![], vec![]);
        for _ in 0..9 {
            let t0 = std::time::Instant::now();
            let st = integ.solve(init, 100.0, output::each_step(|_| {})).unwrap();
            full.push(t0.elapsed().as_secs_f64() / st.steps as f64);
            let t0 = std::time::Instant::now();
            let end = integ.final_state(init, 100.0).unwrap();
            lean.push(t0.elapsed().as_secs_f64() / end.stats.steps as f64);
        }
        full.sort_by(f64::total_cmp);
        lean.sort_by(f64::total_cmp);
        let (f, l) = (full[4] * 1e9, lean[4] * 1e9);
        println!("{id},{f:.0},{l:.0},{:.2}", f / l);
    }
}
