use forced_vi::prelude::*;
use forced_vi::NewtonOptions;
use forced_vi_scenes::models::CoupledVanDerPol;
fn main() {
    let m = CoupledVanDerPol::PAPER;
    for simp in [false, true] {
        for id in ["midpoint", "lobatto2", "lobatto3", "lobatto4", "lobatto5"] {
            let integ = Integrator::new(&m, Scheme::new(id.parse().unwrap()).unwrap(), 0.01)
                .unwrap()
                .newton(NewtonOptions::default().simplified(simp));
            let mut times = vec![];
            let mut it = 0;
            for _ in 0..9 {
                let t0 = std::time::Instant::now();
                let st = integ
                    .solve(
                        InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
                        100.0,
                        output::each_step(|_| {}),
                    )
                    .unwrap();
                times.push(t0.elapsed().as_secs_f64() / st.steps as f64);
                it = st.newton_iterations;
            }
            times.sort_by(f64::total_cmp);
            println!(
                "{id} simplified={simp}: median {:.0} ns/step min {:.0}, {:.2} iters/step",
                times[4] * 1e9,
                times[0] * 1e9,
                it as f64 / 10000.0
            );
        }
    }
}
