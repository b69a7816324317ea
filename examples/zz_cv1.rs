use forced_vi::prelude::*;
use forced_vi_models::models::{CoupledVanDerPol, KeplerDrag};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let s: usize = a[2].parse().unwrap();
    let n: usize = a[3].parse().unwrap();
    let reps: usize = a[4].parse().unwrap();
    let mut acc = 0.0;
    let t0 = std::time::Instant::now();
    let mut st = (0, 0);
    for _ in 0..reps {
        let e = if a[1] == "cvdp" {
            let m = CoupledVanDerPol::PAPER;
            let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
            Integrator::new(&m, Scheme::lobatto(s).unwrap(), 1.0 / n as f64)
                .unwrap()
                .final_state(init, 1.0)
                .unwrap()
        } else {
            let m = KeplerDrag::DEFAULT;
            let init = InitialState::from_velocity([1.0, 0.0], [0.0, 1.2]);
            Integrator::new(&m, Scheme::lobatto(s).unwrap(), 20.0 / n as f64)
                .unwrap()
                .final_state(init, 20.0)
                .unwrap()
        };
        acc += e.q[0];
        st = (e.stats.steps, e.stats.newton_iterations);
    }
    println!(
        "{acc:.16e} {st:?} {:.2} us",
        t0.elapsed().as_secs_f64() * 1e6 / reps as f64
    );
}
