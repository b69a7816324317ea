"""References for tests/held_out.rs (third set): the end states (q, p) of the third held-out set of
examples/tolerance_sweep.rs (tests/held_out_models_third.rs). Each model's Lagrangian and
force are written again here in sympy, not read through forced-vi; sympy forms the
Euler-Lagrange equations M(q, t) a = L_q + F - L_vq v - L_vt, solves them for the
accelerations a, and gives the momenta p = L_v. They are integrated by Gragg-Bulirsch-Stoer
extrapolation (modified midpoint rule, 8 columns, order 16 per macro step) in numpy's 80-bit
long double (machine epsilon 1.1e-19), over fixed macro steps H and again over H/2; the test
takes the H/2 values rounded to f64. The script prints how far the two runs, and scipy's DOP853
at rtol = atol = 1e-13, lie from them. (mpmath's `odefun` at 30 digits, as in
held_out_reference.py, did not finish the heavy top within five minutes.) Needs sympy, numpy
and scipy; about a minute.
"""
import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

t = sp.Symbol("t")


def heavy_top():
    th, ph, ps, dth, dph, dps = sp.symbols("th ph ps dth dph dps")
    L = (sp.Rational(1, 2) * (dth**2 + dph**2 * sp.sin(th) ** 2)
         + sp.Rational(1, 4) * (dps + dph * sp.cos(th)) ** 2 - sp.cos(th))
    F = [-sp.Rational(5, 100) * dth, 0, 0]
    return [th, ph, ps], [dth, dph, dps], L, F


def fpu_chain():
    q = sp.symbols("q0:8")
    v = sp.symbols("v0:8")
    L = sum(sp.Rational(1, 2) * x**2 for x in v)
    for i in range(9):
        left = 0 if i == 0 else q[i - 1]
        right = 0 if i == 8 else q[i]
        d = right - left
        L -= sp.Rational(1, 2) * d**2 + sp.Rational(1, 4) * d**4
    F = [0] * 7 + [-sp.Rational(2, 10) * v[7]]
    return list(q), list(v), L, F


def caldirola_kanai():
    x, dx = sp.symbols("x dx")
    L = sp.exp(sp.Rational(3, 10) * t) * (sp.Rational(1, 2) * dx**2 - sp.Rational(1, 2) * x**2)
    return [x], [dx], L, [0]


def dry_friction():
    x, dx = sp.symbols("x dx")
    L = sp.Rational(1, 2) * dx**2 - sp.Rational(1, 2) * x**2
    return [x], [dx], L, [-sp.Rational(3, 10) * sp.tanh(dx / sp.Rational(2, 100))]


def cart_pendulum():
    x, th, dx, dth = sp.symbols("x th dx dth")
    L = (dx**2 + sp.Rational(1, 2) * dx * dth * sp.cos(th) + sp.Rational(1, 8) * dth**2
         + sp.Rational(1, 2) * sp.Rational(981, 100) * sp.Rational(1, 2) * sp.cos(th))
    F = [-sp.Rational(1, 2) * dx + sp.Rational(8, 10) * sp.sin(sp.Rational(13, 10) * t), 0]
    return [x, th], [dx, dth], L, F


# (name, model, q0, v0, T, H): the sweep's initial states and run lengths, and the macro step
# (the dry friction's force turns over a velocity of 0.02: a shorter one).
MODELS = [
    ("heavy_top", heavy_top, ["0.6", "0", "0"], ["0", "0.5", "5"], 15, 0.05),
    ("fpu_chain", fpu_chain, ["0.8", "0", "0", "-0.4", "0", "0", "0", "0"], ["0"] * 8, 20, 0.05),
    ("caldirola_kanai", caldirola_kanai, ["1"], ["0"], 20, 0.05),
    ("dry_friction", dry_friction, ["2"], ["0"], 15, 0.005),
    ("cart_pendulum", cart_pendulum, ["0", "1"], ["0", "0"], 15, 0.05),
]

LD = np.longdouble


def equations(model):
    """The accelerations as f(t, y) with y = (q, v) in long double, the same in f64 for
    DOP853, and the momenta p(t, q, v)."""
    q, v, L, F = model()
    n = len(q)
    lv = [sp.diff(L, x) for x in v]
    mass = sp.Matrix(n, n, lambda a, b: sp.diff(lv[a], v[b]))
    rhs = sp.Matrix([sp.diff(L, q[a]) + F[a] - sum(sp.diff(lv[a], q[b]) * v[b] for b in range(n))
                     - sp.diff(lv[a], t) for a in range(n)])
    acc = mass.LUsolve(rhs)
    args = [t] + list(q) + list(v)
    a_f = sp.lambdify(args, list(acc), "numpy")
    p_f = sp.lambdify(args, lv, "numpy")

    def f(tt, y):
        return np.array(list(y[n:]) + [LD(x) for x in a_f(tt, *y)], dtype=LD)

    def f64(tt, y):
        return list(y[n:]) + [float(x) for x in a_f(tt, *y)]

    return f, f64, p_f, n


def gbs_step(f, t0, y0, H, k=8):
    """One macro step of Gragg-Bulirsch-Stoer: modified midpoint with 2, 4, ..., 2k
    substeps, extrapolated in the square of the substep (Aitken-Neville)."""
    table = []
    for j in range(1, k + 1):
        m = 2 * j
        h = H / m
        z0 = y0.copy()
        z1 = z0 + h * f(t0, z0)
        for i in range(1, m):
            z0, z1 = z1, z0 + 2 * h * f(t0 + i * h, z1)
        row = [(z1 + z0 + h * f(t0 + H, z1)) / 2]
        for i in range(1, j):
            r = (LD(j) / LD(j - i)) ** 2
            row.append(row[i - 1] + (row[i - 1] - table[j - 2][i - 1]) / (r - 1))
        table.append(row)
    return table[-1][-1]


def end_state(f, p_f, n, q0, v0, T, H):
    steps = int(round(T / H))
    H = LD(T) / steps
    y = np.array([LD(x) for x in q0 + v0], dtype=LD)
    for i in range(steps):
        y = gbs_step(f, i * H, y, H)
    p = p_f(LD(T), *y)
    return [float(x) for x in y[:n]] + [float(x) for x in p]


def main(models):
    for name, model, q0, v0, T, H in models:
        f, f64, p_f, n = equations(model)
        coarse = end_state(f, p_f, n, q0, v0, T, H)
        ref = end_state(f, p_f, n, q0, v0, T, H / 2)
        y0 = [float(x) for x in q0 + v0]
        dop = solve_ivp(f64, [0, T], y0, method="DOP853", rtol=1e-13, atol=1e-13)
        y = dop.y[:, -1]
        dop_end = list(y[:n]) + [float(x) for x in p_f(T, *y)]
        dh = max(abs(a - b) for a, b in zip(ref, coarse))
        ddop = max(abs(a - b) for a, b in zip(ref, dop_end))
        print(f"{name}: q = {ref[:n]!r}, p = {ref[n:]!r} (H = {H}: within {dh:.1e}; "
              f"DOP853 within {ddop:.1e})", flush=True)


if __name__ == "__main__":
    main(MODELS)
