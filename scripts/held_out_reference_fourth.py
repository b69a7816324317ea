"""References for the fourth held-out set of tests/held_out.rs (tests/held_out_models_fourth.rs):
the end states (q, p). Each model's Lagrangian and force are written again here in sympy, and
integrated as in held_out_reference_third.py (sympy's equations of motion, Gragg-Bulirsch-Stoer
extrapolation in numpy's long double over macro steps H and H/2, DOP853 at 1e-13 beside them).
Then, for each model, its amplification: the largest growth over the run, in (q, p), of a
perturbation of 1e-7 in one initial position or velocity (DOP853 at 1e-13, in f64).
Needs sympy, numpy and scipy; a few minutes. Run from the repository root:
`python3 scripts/held_out_reference_fourth.py`.
"""
import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from held_out_reference_third import equations, main

R = sp.Rational


def lj_wall():
    x, dx = sp.symbols("x dx")
    L = R(1, 2) * dx**2 - (1 / x**12 - 2 / x**6)
    return [x], [dx], L, [-R(1, 100) * dx]


def stiff_pair():
    a, b, da, db = sp.symbols("a b da db")
    L = R(1, 2) * (da**2 + db**2) - R(1, 2) * 10000 * (b - a) ** 2 - R(1, 2) * a**2
    return [a, b], [da, db], L, [R(1, 100) * (db - da), -R(1, 100) * (db - da)]


def slow():
    x, dx = sp.symbols("x dx")
    return [x], [dx], R(1, 2) * dx**2 - R(1, 2) * R(1, 10**6) * x**2, [-R(1, 10**5) * dx]


def quartic():
    x, dx = sp.symbols("x dx")
    return [x], [dx], R(1, 2) * dx**2 - x**4, [-R(5, 100) * dx]


def lj_dimer():
    x, y, dx, dy = sp.symbols("x y dx dy")
    r2 = x**2 + y**2
    L = R(1, 2) * (dx**2 + dy**2) - (1 / r2**6 - 2 / r2**3)
    return [x, y], [dx, dy], L, [-R(1, 100) * dx, -R(1, 100) * dy]


# (name, model, q0, v0, T, H), as in tests/held_out.rs: macro steps short against each
# model's fastest time scale (the pair's spring has a period of 0.044; the Lennard-Jones
# walls turn the motion within about 0.1).
MODELS = [
    ("lj_wall", lj_wall, ["1.5"], ["0"], 30, 0.005),
    ("stiff_pair", stiff_pair, ["1", "1.01"], ["0", "0"], 10, 0.004),
    ("slow", slow, ["1"], ["0"], 10000, 20),
    ("quartic", quartic, ["1"], ["0"], 30, 0.05),
    ("lj_dimer", lj_dimer, ["1.3", "0"], ["0", "0.5"], 30, 0.005),
]

def amplification(model, q0, v0, T):
    _, f64, p_f, n = equations(model)

    def end(y0):
        y = solve_ivp(f64, [0, T], y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
        return np.array(list(y[:n]) + [float(x) for x in p_f(T, *y)])

    y0 = [float(x) for x in q0 + v0]
    base, d, grow = end(y0), 1e-7, 0.0
    for k in range(2 * n):
        y = list(y0)
        y[k] += d
        grow = max(grow, float(np.abs(end(y) - base).max()) / d)
    return grow


if __name__ == "__main__":
    main(MODELS)
    for name, model, q0, v0, T, _ in MODELS:
        print(f"{name}: amplification {amplification(model, q0, v0, T):.1f}", flush=True)
