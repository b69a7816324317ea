"""Reference for tests/trust_runtime.rs: a unit mass in the potential x^(5/2) from the
bottom, x'' = -(5/2) x^(3/2), x(0) = 0, x'(0) = 1, at T = 0.5 (x > 0 after the start).

scipy's DOP853 and Radau at rtol 1e-13 agree to the digits printed. Needs numpy and scipy.
"""
from scipy.integrate import solve_ivp

f = lambda t, y: [y[1], -2.5 * max(y[0], 0.0) ** 1.5]
for method in ["DOP853", "Radau"]:
    r = solve_ivp(f, [0, 0.5], [0.0, 1.0], method=method, rtol=1e-13, atol=1e-15)
    print(f"{method}: x(0.5) = {r.y[0, -1]!r}, v(0.5) = {r.y[1, -1]!r}")
