use forced_vi::prelude::*;
struct Cvdp { eps: f64, rho: f64, lambda: f64 }
impl ForcedLagrangian<2> for Cvdp {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let [x, y] = *q;
        (v[0] * v[0] + v[1] * v[1]) * 0.5 - (x * x + y * y * (1.0 + self.rho)) * 0.5 - (x - y) * (x - y) * self.lambda
    }
    fn force<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [(-q[0] * q[0] + self.eps) * v[0], (-q[1] * q[1] + self.eps) * v[1]]
    }
}
fn main() {
    let m = Cvdp { eps: 0.5, rho: 0.02, lambda: 0.8 };
    for s in 2..=5 {
        let mut prev: Option<nalgebra::SVector<f64,2>> = None;
        for &h in &[0.1, 0.05, 0.025, 0.0125, 1e-3, 1e-4] {
            let t0 = std::time::Instant::now();
            let run = Integrator::new(&m, Scheme::lobatto(s).unwrap(), h).unwrap()
                .run(InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]), 1.0).unwrap();
            let e = run.last().unwrap();
            println!("s={s} h={h} q={:.16?} p={:.16?} eb={:.3e} iters/step={:.2} {:?}", e.q.as_slice(), e.p.as_slice(), e.energy_balance,
                run.stats.newton_iterations as f64 / run.stats.steps as f64, t0.elapsed());
            prev = Some(e.q);
        }
        let _ = prev;
    }
}
