#!/usr/bin/env python3
"""References for the driven scenes (issue 13).

Primary: mpmath.odefun (Taylor series) at mp.dps = 25, with the model parameters, initial
values and output times taken as the IEEE doubles the Rust scenes use. Cross-checks
(printed): scipy DOP853 and Radau at rtol 1e-13, atol 1e-15.

Usage:  python3 scripts/driven_reference.py   (from the workspace root, ~2 min)
Output: data/reference/driven_duffing.csv, data/reference/kapitza_pendulum.csv in the format
of data/reference/README.md (member,t,q1,v1,p1,energy), energy = v.p - L(t, q, v).

driven_duffing:   x'' + delta x' + alpha x + beta x^3 = gamma cos(omega t)
                  L = x'^2/2 - alpha x^2/2 - beta x^4/4, F = -delta x' + gamma cos(omega t)
                  (delta, alpha, beta, gamma, omega) = (0.3, -1, 1, 0.5, 1.2), x(0) = 1,
                  x'(0) = 0, T = 5 driving periods.
kapitza_pendulum: pivot at height y_s(t) = a cos(Omega t); angle th from the downward vertical.
                  L = m/2 (l^2 th'^2 + 2 l sin(th) th' y_s' + y_s'^2) - m g (y_s - l cos th),
                  F = -c th'; (m, l, g, a, Omega, c) = (1, 1, 9.81, 0.1, 50, 0.1),
                  th(0) = pi - 0.3 (as a double), th'(0) = 0, T = 10.
"""
import os
import mpmath as mp
import numpy as np
from scipy.integrate import solve_ivp

mp.mp.dps = 25
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')
M = mp.mpf  # exact conversion of a double


def duffing(lib):
    d, a, b, g, w = 0.3, -1.0, 1.0, 0.5, 1.2
    if lib is mp:
        d, a, b, g, w = map(M, (d, a, b, g, w))

    def rhs(t, y):
        return [y[1], -d * y[1] - a * y[0] - b * y[0]**3 + g * lib.cos(w * t)]

    def p_energy(t, x, v):
        lag = v * v / 2 - a * x * x / 2 - b * x**4 / 4
        return v, v * v - lag
    return rhs, p_energy


def kapitza(lib):
    m, l, g, a, om, c = 1.0, 1.0, 9.81, 0.1, 50.0, 0.1
    if lib is mp:
        m, l, g, a, om, c = map(M, (m, l, g, a, om, c))

    def rhs(t, y):
        ydd = -a * om**2 * lib.cos(om * t)
        return [y[1], -(g + ydd) * lib.sin(y[0]) / l - c * y[1] / (m * l * l)]

    def p_energy(t, th, w):
        ys, yd = a * lib.cos(om * t), -a * om * lib.sin(om * t)
        lag = m / 2 * (l * l * w * w + 2 * l * lib.sin(th) * w * yd + yd * yd) - m * g * (ys - l * lib.cos(th))
        p = m * (l * l * w + l * lib.sin(th) * yd)
        return p, w * p - lag
    return rhs, p_energy


def write(name, model, y0, times):
    rhs, pe = model(mp)
    sol = mp.odefun(rhs, 0, [M(y) for y in y0])
    rows = []
    for t in times:
        y = sol(M(t))
        p, e = pe(M(t), y[0], y[1])
        rows.append([t] + [float(x) for x in (y[0], y[1], p, e)])
    ref = np.array([[r[1], r[2]] for r in rows])
    frhs, _ = model(np)
    for method in ('DOP853', 'Radau'):
        s = solve_ivp(frhs, (0.0, times[-1]), y0, method=method, t_eval=times, rtol=1e-13, atol=1e-15)
        print(f'{name}: {method} differs by {np.max(np.abs(s.y.T - ref)):.2e} (q, v)')
    with open(os.path.join(OUT, name + '.csv'), 'w') as f:
        f.write('member,t,q1,v1,p1,energy\n')
        for r in rows:
            f.write('0,' + ','.join('%.17e' % x for x in r) + '\n')


if __name__ == '__main__':
    T = 2 * np.pi / 1.2 * 5
    write('driven_duffing', duffing, [1.0, 0.0], list(np.linspace(0.0, T, 6)))
    write('kapitza_pendulum', kapitza, [np.pi - 0.3, 0.0], list(np.linspace(0.0, 10.0, 11)))
