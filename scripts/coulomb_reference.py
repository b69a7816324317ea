"""Reference for tests/trust_runtime.rs: a unit oscillator with regularised Coulomb friction,
x'' = -x - mu tanh(x' / eps), mu = 1, x(0) = 3.3, x'(0) = 0, at T = 10.

Two independent solvers of scipy at rtol 1e-13 (Radau, implicit, and DOP853, explicit); the
test takes Radau's value and the two agree to about 2e-14. Needs numpy and scipy.
"""
import numpy as np
from scipy.integrate import solve_ivp

for eps in [1e-2, 1e-3, 1e-4]:
    f = lambda t, y: [y[1], -y[0] - np.tanh(y[1] / eps)]
    radau = solve_ivp(f, [0, 10], [3.3, 0.0], method="Radau", rtol=1e-13, atol=1e-15)
    dop = solve_ivp(f, [0, 10], [3.3, 0.0], method="DOP853", rtol=1e-13, atol=1e-15)
    print(f"eps {eps:.0e}: x(10) = {radau.y[0, -1]!r} (DOP853 {dop.y[0, -1]!r})")
