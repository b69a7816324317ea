#!/usr/bin/env python3
"""Reference for the rigid chain of `forced_vi_models::rigid_chain` (issue 25): n = 256 links.

The Rust model is in Cartesian coordinates with one constraint per link. Here the same chain
is written in its minimal coordinates, the link angles th_i from the downward vertical
(r_k = sum_{j<=k} l (sin th_j, -cos th_j)), with equal masses m at the links' ends:

    M(th) th'' + (W * sin(th_i - th_j)) th'^2 = -m g l (n - i) sin th_i - (c/m) M(th) th',
    M_ij = W_ij cos(th_i - th_j),  W_ij = m l^2 (n - max(i, j)),

where the drag F_k = -c v_k on every mass gives the generalised force -(c/m) M th'. It is
integrated by scipy's DOP853 at rtol = atol = 1e-13, cross-checked (printed) against
rtol = atol = 1e-11, with the parameters of `RigidChain::<512>::default()`:
m = l = 1/n, g = 9.81, c = 0.1/n, th_i(0) = 0.6 + 0.3 sin(pi (i + 1/2)/n), at rest.

Usage:  python3 scripts/rigid_chain_reference.py   (from the workspace root)
Output: data/reference/rigid_chain_256.csv: `t,q1..q512,v1..v512` (Cartesian, x_i and y_i
interleaved as in the Rust model) at t = 0.25 and 0.5; floats as %.17e.
"""
import os
import numpy as np
from scipy.integrate import solve_ivp

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')
n = 256
m = 1.0 / n
l = 1.0 / n
g = 9.81
c = 0.1 / n
TIMES = [0.25, 0.5]

idx = np.arange(n)
W = m * l * l * (n - np.maximum.outer(idx, idx))
GRAV = m * g * l * (n - idx)


def rhs(_t, y):
    th, w = y[:n], y[n:]
    s, co = np.sin(th), np.cos(th)
    cos_d = np.outer(co, co) + np.outer(s, s)
    sin_d = np.outer(s, co) - np.outer(co, s)
    mass = W * cos_d
    f = -(W * sin_d) @ (w * w) - GRAV * s
    acc = np.linalg.solve(mass, f) - (c / m) * w
    return np.concatenate([w, acc])


def cartesian(th, w):
    x = np.cumsum(l * np.sin(th))
    y = -np.cumsum(l * np.cos(th))
    vx = np.cumsum(l * np.cos(th) * w)
    vy = np.cumsum(l * np.sin(th) * w)
    q = np.empty(2 * n)
    v = np.empty(2 * n)
    q[0::2], q[1::2] = x, y
    v[0::2], v[1::2] = vx, vy
    return q, v


def solve(tol):
    th0 = 0.6 + 0.3 * np.sin(np.pi * (idx + 0.5) / n)
    y0 = np.concatenate([th0, np.zeros(n)])
    sol = solve_ivp(rhs, (0.0, TIMES[-1]), y0, method='DOP853', rtol=tol, atol=tol,
                    t_eval=TIMES)
    assert sol.success, sol.message
    return [cartesian(sol.y[:n, k], sol.y[n:, k]) for k in range(len(TIMES))]


def main():
    fine = solve(1e-13)
    coarse = solve(1e-11)
    for t, (qf, vf), (qc, vc) in zip(TIMES, fine, coarse):
        print(f"t = {t}: |dq| {np.abs(qf - qc).max():.2e}  |dv| {np.abs(vf - vc).max():.2e}")
    header = ['t'] + [f'q{i + 1}' for i in range(2 * n)] + [f'v{i + 1}' for i in range(2 * n)]
    with open(os.path.join(OUT, 'rigid_chain_256.csv'), 'w') as f:
        f.write(','.join(header) + '\n')
        for t, (q, v) in zip(TIMES, fine):
            f.write(','.join(f'{x:.17e}' for x in [t, *q, *v]) + '\n')


if __name__ == '__main__':
    main()
