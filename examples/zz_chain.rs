use forced_vi::prelude::*;
use forced_vi_models::models::SpringChain;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let s: usize = a[1].parse().unwrap();
    let tol: f64 = a[2].parse().unwrap();
    let c: f64 = a[3].parse().unwrap();
    let t: f64 = a[4].parse().unwrap();
    const N: usize = 32;
    let m = SpringChain::<N> {
        k: 1e4,
        beta: 1.0,
        c,
        m: 1.0,
    };
    let q0: [f64; N] = std::array::from_fn(|i| {
        (std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64).sin() * 0.1
            + if i == N / 2 { 0.05 } else { 0.0 }
    });
    let init = InitialState::from_velocity(q0, [0.0; N]);
    let t0 = std::time::Instant::now();
    let r = Integrator::adaptive(&m, Scheme::lobatto(s).unwrap(), tol, tol)
        .unwrap()
        .linear_path(if std::env::var_os("ZZS").is_some() {
            forced_vi::LinearPath::Sparse
        } else {
            forced_vi::LinearPath::Dense
        })
        .max_steps(3_000_000)
        .final_state(init, t);
    match r {
        Ok(e) => println!(
            "s={s} tol={tol:e}: q16={:.12e} {:?} {:.2}s",
            e.q[N / 2],
            e.stats,
            t0.elapsed().as_secs_f64()
        ),
        Err(f) => println!(
            "s={s} tol={tol:e}: ERR {} {:.2}s",
            f.error,
            t0.elapsed().as_secs_f64()
        ),
    }
}
