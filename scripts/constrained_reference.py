#!/usr/bin/env python3
"""Reference for the constrained scene `cartesian_pendulum` (issue 25).

The scene integrates a pendulum in Cartesian coordinates (x, y) with the constraint
x^2 + y^2 = l^2 and linear air drag F = -c v. Its reference comes from the minimal form, the
angle th from the downward vertical:

    m l^2 th'' = -m g l sin(th) - c l^2 th',   x = l sin th,  y = -l cos th,

by mpmath.odefun (Taylor series) at mp.dps = 25, with the parameters and initial values taken
as the IEEE doubles the Rust scene uses; cross-checked (printed) with scipy DOP853 at
rtol 1e-13. (m, g, l, c) = (1, 9.81, 1.5, 0.3), th(0) = 1.2, th'(0) = 0.4, T = 10.

Usage:  python3 scripts/constrained_reference.py   (from the workspace root)
Output: data/reference/cartesian_pendulum.csv (member,t,q1,q2,v1,v2,p1,p2,energy), with
p = m v and energy = m|v|^2/2 + m g y (= v.p - L).
"""
import os
import mpmath as mp
from scipy.integrate import solve_ivp

mp.mp.dps = 25
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')
M = mp.mpf
m, g, l, c = 1.0, 9.81, 1.5, 0.3
th0, w0, T = 1.2, 0.4, 10.0


def row(lib, t, th, w):
    mm, gg, ll = (M(m), M(g), M(l)) if lib is mp else (m, g, l)
    x, y = ll * lib.sin(th), -ll * lib.cos(th)
    vx, vy = ll * lib.cos(th) * w, ll * lib.sin(th) * w
    energy = mm * (vx * vx + vy * vy) / 2 + mm * gg * y
    return [t, x, y, vx, vy, mm * vx, mm * vy, energy]


def main():
    mm, gg, ll, cc = map(M, (m, g, l, c))
    f = mp.odefun(lambda t, y: [y[1], -gg / ll * mp.sin(y[0]) - cc / mm * y[1]], 0, [M(th0), M(w0)])
    th, w = f(M(T))
    ref = row(mp, M(T), th, w)
    sol = solve_ivp(lambda t, y: [y[1], -g / l * __import__('math').sin(y[0]) - c / m * y[1]],
                    (0, T), [th0, w0], method='DOP853', rtol=1e-13, atol=1e-15)
    check = row(__import__('math'), T, sol.y[0, -1], sol.y[1, -1])
    print('DOP853 - mpmath:', max(abs(float(a) - b) for a, b in zip(ref[1:], check[1:])))
    rows = [row(mp, M(0), M(th0), M(w0)), ref]
    with open(os.path.join(OUT, 'cartesian_pendulum.csv'), 'w') as out:
        out.write('member,t,q1,q2,v1,v2,p1,p2,energy\n')
        for r in rows:
            out.write('0,' + ','.join('%.17e' % float(v) for v in r) + '\n')


if __name__ == '__main__':
    main()
