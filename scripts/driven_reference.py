#!/usr/bin/env python3
"""References for the driven scenes (issue 13): scipy DOP853 at rtol 1e-13, atol 1e-15,
cross-checked with Radau at the same tolerances and with DOP853 at rtol 3e-14.

Usage:  python3 scripts/driven_reference.py   (from the workspace root)
Output: data/reference/driven_duffing.csv, data/reference/kapitza_pendulum.csv in the format
of data/reference/README.md (member,t,q..,v..,p..,energy), energy = v.p - L(t, q, v).

driven_duffing:   x'' + delta x' + alpha x + beta x^3 = gamma cos(omega t)
                  L = x'^2/2 - alpha x^2/2 - beta x^4/4, F = -delta x' + gamma cos(omega t)
                  (delta, alpha, beta, gamma, omega) = (0.3, -1, 1, 0.5, 1.2), x(0) = 1, x'(0) = 0,
                  T = 5 driving periods.
kapitza_pendulum: pivot at height y_s(t) = a cos(Omega t); angle th from the downward vertical.
                  L = m/2 (l^2 th'^2 + 2 l sin(th) th' y_s' + y_s'^2) - m g (y_s - l cos th),
                  F = -c th'; (m, l, g, a, Omega, c) = (1, 1, 9.81, 0.1, 50, 0.1),
                  th(0) = pi - 0.3, th'(0) = 0, T = 10.
"""
import os
import numpy as np
from scipy.integrate import solve_ivp

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')

DUF = dict(delta=0.3, alpha=-1.0, beta=1.0, gamma=0.5, omega=1.2)
KAP = dict(m=1.0, l=1.0, g=9.81, a=0.1, Omega=50.0, c=0.1)


def duffing_rhs(t, y):
    x, v = y
    d = DUF
    return [v, -d['delta'] * v - d['alpha'] * x - d['beta'] * x**3 + d['gamma'] * np.cos(d['omega'] * t)]


def duffing_pe(t, x, v):
    d = DUF
    lag = 0.5 * v * v - 0.5 * d['alpha'] * x * x - 0.25 * d['beta'] * x**4
    return v, v * v - lag


def kapitza_rhs(t, y):
    th, w = y
    k = KAP
    ydd = -k['a'] * k['Omega']**2 * np.cos(k['Omega'] * t)
    return [w, -(k['g'] + ydd) * np.sin(th) / k['l'] - k['c'] * w / (k['m'] * k['l']**2)]


def kapitza_pe(t, th, w):
    k = KAP
    ys = k['a'] * np.cos(k['Omega'] * t)
    yd = -k['a'] * k['Omega'] * np.sin(k['Omega'] * t)
    m, l, g = k['m'], k['l'], k['g']
    lag = 0.5 * m * (l * l * w * w + 2 * l * np.sin(th) * w * yd + yd * yd) - m * g * (ys - l * np.cos(th))
    p = m * (l * l * w + l * np.sin(th) * yd)
    return p, w * p - lag


def solve(rhs, y0, times, method, rtol):
    sol = solve_ivp(rhs, (0.0, times[-1]), y0, method=method, t_eval=times, rtol=rtol, atol=1e-15,
                    dense_output=False)
    assert sol.success, sol.message
    return sol.y


def write(name, rhs, pe, y0, times):
    y = solve(rhs, y0, times, 'DOP853', 1e-13)
    for method, rtol in [('Radau', 1e-13), ('DOP853', 3e-14)]:
        other = solve(rhs, y0, times, method, rtol)
        print(f'{name}: {method} rtol {rtol:g} differs by {np.max(np.abs(other - y)):.2e} (q, v)')
    with open(os.path.join(OUT, name + '.csv'), 'w') as f:
        f.write('member,t,q1,v1,p1,energy\n')
        for k, t in enumerate(times):
            q, v = y[0, k], y[1, k]
            p, e = pe(t, q, v)
            f.write('0,' + ','.join('%.17e' % x for x in (t, q, v, p, e)) + '\n')


if __name__ == '__main__':
    T = 2 * np.pi / DUF['omega'] * 5
    write('driven_duffing', duffing_rhs, duffing_pe, [1.0, 0.0], np.linspace(0.0, T, 6))
    write('kapitza_pendulum', kapitza_rhs, kapitza_pe, [np.pi - 0.3, 0.0], np.linspace(0.0, 10.0, 11))
