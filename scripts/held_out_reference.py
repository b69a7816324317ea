"""References for tests/held_out.rs: the end states (q, p) of the second held-out set of
examples/tolerance_sweep.rs, and of two constrained models written in Cartesian coordinates
(a spherical pendulum, a bead on the parabola y = x²), from equations of motion written out by
hand (not from the Lagrangians through forced-vi; the constrained ones in their free
coordinates: the pendulum's two angles, the bead's x).

mpmath's Taylor-series solver (`odefun`) at 25 and at 30 digits; the test takes the
30-digit values rounded to f64. The script prints how far the 25-digit run and scipy's DOP853
at rtol = atol = 1e-13 lie from them. Needs mpmath, numpy and scipy; about a minute.
"""
import mpmath as mp
import numpy as np
from scipy.integrate import solve_ivp


def parametric(t, y, m):
    th, w = y
    return [w, -(1 + m.mpf("0.3") * m.cos(2 * t)) * m.sin(th) - m.mpf("0.05") * w]


def two_mass(t, y, m):
    x, yy, vx, vy = y
    d, dv = yy - x, vy - vx
    spring = d + m.mpf("0.4") * d**3
    return [vx, vy, (-x + spring + m.mpf("0.02") * dv) / 2, (-spring - m.mpf("0.02") * dv) * 2]


def lorentz(t, y, m):
    x, yy, vx, vy = y
    s = m.sqrt(vx * vx + vy * vy)
    c = m.mpf("0.1")
    return [vx, vy, m.mpf("1.5") * vy - c * vx * s + m.mpf("0.3") * m.cos(t),
            -m.mpf("1.5") * vx - c * vy * s]


def relativistic(t, y, m):
    x, v = y
    g = 1 / m.sqrt(1 - v * v)
    return [v, (-x - m.mpf("0.05") * v) / g**3]


def soft_kepler(t, y, m):
    x, yy, vx, vy = y
    r3 = (x * x + yy * yy + m.mpf("0.1")) ** m.mpf("1.5")
    return [vx, vy, -x / r3 - m.mpf("0.02") * vx, -yy / r3 - m.mpf("0.02") * vy]


def spherical(t, y, m):
    th, ph, w, u = y
    s, c = m.sin(th), m.cos(th)
    d = m.mpf("0.2")
    return [w, u, s * c * u * u - m.mpf("9.81") * s - d * w, -2 * c / s * w * u - d * u]


def spherical_cartesian(y, m):
    """(x, y, z) and their velocities (the momenta: unit mass) from the angles."""
    th, ph, w, u = y
    s, c, sp, cp = m.sin(th), m.cos(th), m.sin(ph), m.cos(ph)
    return [s * cp, s * sp, -c], [c * w * cp - s * sp * u, c * w * sp + s * cp * u, s * w]


def bead(t, y, m):
    x, v = y
    k = 1 + 4 * x * x
    return [v, (-4 * x * v * v - 2 * m.mpf("9.81") * x - m.mpf("0.1") * k * v) / k]


# (name, right-hand side, q0, v0, T, momenta from (q, v))
MODELS = [
    ("parametric", parametric, ["0.6"], ["0"], 15, lambda q, v, m: [v[0]]),
    ("two_mass", two_mass, ["1", "-0.5"], ["0", "0"], 15, lambda q, v, m: [2 * v[0], v[1] / 2]),
    ("lorentz", lorentz, ["0", "0"], ["1", "0"], 15,
     lambda q, v, m: [v[0] - m.mpf("0.75") * q[1], v[1] + m.mpf("0.75") * q[0]]),
    ("relativistic", relativistic, ["0.5"], ["0.5"], 15,
     lambda q, v, m: [v[0] / m.sqrt(1 - v[0] ** 2)]),
    ("soft_kepler", soft_kepler, ["1", "0"], ["0", "0.8"], 15, lambda q, v, m: list(v)),
]


class Float:
    """numpy in place of mpmath, for DOP853."""
    mpf = staticmethod(float)
    cos, sin, sqrt = np.cos, np.sin, np.sqrt


def end_state(f, q0, v0, T, momenta, dps):
    mp.mp.dps = dps
    n = len(q0)
    sol = mp.odefun(lambda t, y: f(t, y, mp), 0, [mp.mpf(x) for x in q0 + v0])
    y = sol(T)
    return [float(x) for x in list(y[:n]) + momenta(y[:n], y[n:], mp)]


mp.mp.dps = 30
sol = mp.odefun(lambda t, y: spherical(t, y, mp), 0, [mp.mpf(1), mp.mpf(0), mp.mpf(0), mp.mpf(2)])
q, p = spherical_cartesian(sol(10), mp)
print(f"spherical_cartesian: q = {[float(x) for x in q]!r}, p = {[float(x) for x in p]!r}")
x, v = mp.odefun(lambda t, y: bead(t, y, mp), 0, [mp.mpf(1), mp.mpf(0)])(10)
print(f"bead_on_parabola: q = {[float(x), float(x * x)]!r}, p = {[float(v), float(2 * x * v)]!r}")

for name, f, q0, v0, T, momenta in MODELS:
    n = len(q0)
    ref = end_state(f, q0, v0, T, momenta, 30)
    low = end_state(f, q0, v0, T, momenta, 25)
    y0 = [float(x) for x in q0 + v0]
    dop = solve_ivp(lambda t, y: f(t, y, Float), [0, T], y0, method="DOP853", rtol=1e-13, atol=1e-13)
    y = dop.y[:, -1]
    dop_end = list(y[:n]) + [float(x) for x in momenta(y[:n], y[n:], Float)]
    d25 = max(abs(a - b) for a, b in zip(ref, low))
    ddop = max(abs(a - b) for a, b in zip(ref, dop_end))
    print(f"{name}: q = {ref[:n]!r}, p = {ref[n:]!r} (25 digits within {d25:.1e}, DOP853 within {ddop:.1e})")
