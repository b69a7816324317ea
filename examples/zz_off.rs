use forced_vi::prelude::*;
#[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * (x - x0) * (x - x0), force(x = -c * x_dot))]
struct Off {
    k: f64,
    x0: f64,
    c: f64,
}
#[forced_lagrangian(coordinates(x, y), lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - a * (-((x - 0.5) * (x - 0.5) + (y - 0.1) * (y - 0.1)) / (w * w)).exp())]
struct Well2 {
    a: f64,
    w: f64,
}
fn main() {
    // damped oscillator about x0: x = x0 + e^{-ct/2}(A cos wd t + B sin wd t)
    let (mut wrong, mut ok, mut typed) = (0, 0, 0);
    for (k, x0) in [(1e4, 1e3), (1e6, 1.0), (1e2, 1e6), (1.0, 1e8)] {
        let c = 0.1;
        let m = Off { k, x0, c };
        let wd = (k - c * c / 4.0f64).sqrt();
        let t: f64 = 2.0;
        let (a0, b0) = (1.0, c / 2.0 / wd);
        let exact = x0 + (-c * t / 2.0).exp() * (a0 * (wd * t).cos() + b0 * (wd * t).sin());
        for s in [2usize, 3, 5] {
            for tol in [1e-6, 1e-9, 1e-11, 1e-12, 1e-13] {
                let r = Integrator::adaptive(&m, Scheme::lobatto(s).unwrap(), tol, tol)
                    .unwrap()
                    .max_steps(20_000_000)
                    .final_state(InitialState::from_velocity([x0 + 1.0], [0.0]), t);
                match r {
                    Ok(e) => {
                        let err = (e.q[0] - exact).abs();
                        let sc = tol * (1.0 + exact.abs());
                        if err > 10.0 * sc {
                            wrong += 1;
                            println!("WRONG k {k:e} x0 {x0:e} lobatto{s} tol {tol:e}: err {err:.2e} = {:.1} tol-scale, {} steps", err / sc, e.stats.steps);
                        } else {
                            ok += 1;
                        }
                    }
                    Err(e) => {
                        typed += 1;
                        println!(
                            "typed k {k:e} x0 {x0:e} lobatto{s} tol {tol:e}: {} after {} steps",
                            e.error, e.stats.steps
                        );
                    }
                }
            }
        }
    }
    println!("ok {ok} typed {typed} wrong {wrong}");
    // 2-D narrow well: compare tight runs with each other
    let m = Well2 { a: 0.3, w: 2e-3 };
    let init = InitialState::from_velocity([0.0, 0.1], [1.0, 0.0]);
    let r = Integrator::adaptive(&m, Scheme::lobatto(7).unwrap(), 1e-13, 1e-13)
        .unwrap()
        .final_state(init, 2.0);
    match &r {
        Ok(e) => println!("ref {:?}", e.q.as_slice()),
        Err(e) => println!("ref err {}", e.error),
    }
    for s in [3usize, 5] {
        for tol in [1e-8, 1e-10, 1e-12] {
            match Integrator::adaptive(&m, Scheme::lobatto(s).unwrap(), tol, tol)
                .unwrap()
                .final_state(init, 2.0)
            {
                Ok(e) => println!(
                    "well lobatto{s} tol {tol:e}: {:?} diff {:.2e} steps {}",
                    e.q.as_slice(),
                    r.as_ref()
                        .map(|r| (r.q - e.q).abs().max())
                        .unwrap_or(f64::NAN),
                    e.stats.steps
                ),
                Err(e) => println!("well lobatto{s} tol {tol:e}: {}", e.error),
            }
        }
    }
}
