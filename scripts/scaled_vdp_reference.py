#!/usr/bin/env python3
"""Reference for the stability report's `van_der_pol_scaled_1e6` scene.

    eps x'' - (1 - x^2) x' + x = 0,  eps = 1e-12 (mu = 1e6),  x(0) = 2, x'(0) = 0,  tau in [0, 2]

solved in this scaled form by scipy's Radau with its analytic Jacobian, and written in the
unscaled model's time t = mu tau (the report runs L = v^2/2 - q^2/2, F = mu (1 - q^2) v),
where v = x'(tau) / mu, p = v and energy = (v^2 + q^2) / 2.

Usage:  python3 scripts/scaled_vdp_reference.py   (from the workspace root)
Output: data/reference/van_der_pol_scaled_1e6.csv (rows at t = 0 and t = 2e6).

Radau at rtol = atol = 3e-11 is the reference. Below that scipy's Radau stops (at 1e-11 and
1e-12 it ends early, status -1), as does its BDF from 1e-10 down; the differences from
Radau at 1e-9 and 1e-10 and from LSODA at 1e-11 are printed.
"""
import os
from scipy.integrate import solve_ivp

EPS, MU = 1e-12, 1e6
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')


def f(_, y):
    return [y[1], ((1 - y[0] ** 2) * y[1] - y[0]) / EPS]


def jac(_, y):
    return [[0, 1], [(-2 * y[0] * y[1] - 1) / EPS, (1 - y[0] ** 2) / EPS]]


def solve(method, tol):
    s = solve_ivp(f, (0, 2), [2.0, 0.0], method=method, rtol=tol, atol=tol, jac=jac)
    if s.status != 0:
        raise RuntimeError(f'{method} at {tol:g} ended early: {s.message}')
    return s.y[0, -1], s.y[1, -1], s.t.size


def main():
    x, xd, steps = solve('Radau', 3e-11)
    print(f'Radau 3e-11: x(2) = {x!r} ({steps} steps)')
    for method, tol in [('Radau', 1e-9), ('Radau', 1e-10), ('LSODA', 1e-11)]:
        print(f'  {method} {tol:.0e}: differs by {abs(solve(method, tol)[0] - x):.1e}')
    v = xd / MU
    rows = [(0.0, 2.0, 0.0), (2 * MU, x, v)]
    lines = ['member,t,q1,v1,p1,energy']
    for t, q, v in rows:
        lines.append(','.join('%.17e' % a for a in [t, q, v, v, (v * v + q * q) / 2]))
        lines[-1] = '0,' + lines[-1]
    with open(os.path.join(OUT, 'van_der_pol_scaled_1e6.csv'), 'w') as fh:
        fh.write('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
