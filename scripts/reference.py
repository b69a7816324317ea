#!/usr/bin/env python3
"""High-accuracy reference solutions of forced Euler-Lagrange equations for forced-vi.

    d/dt (dL/dv) - dL/dq = F(q, v),   q(0) = q0, v(0) = v0.

Usage:  python3 scripts/reference.py            (from the workspace root)
Output: data/reference/<scene>.csv, one header line, then one row per (member, t):

    member,t,q1,..,qn,v1,..,vn,p1,..,pn,energy

with p = dL/dv, energy = v.p - L. Every member has a row at t = 0 holding its
initial values. Floats are written as '%.17e' (round-trip exact doubles).
Model parameters are the IEEE doubles (e.g. 0.02 means the double nearest 0.02),
converted exactly to mpmath, so the references solve exactly the f64 problem.

Primary reference: mpmath.odefun (Taylor series) at mp.dps = 30, except
damped_oscillator (exact, matrix exponential at dps 30), overdamped_oscillator
(closed form) and stiff_van_der_pol (scipy Radau, rtol = atol = 1e-13; explicit
Taylor series are far too slow for this stiff problem beyond t = 10, so its
reference is only good to ~1e-11). Cross-checks (printed): scipy DOP853 (rtol
1e-13, atol 1e-15), odefun at dps 40 (self-convergence), Radau/BDF/LSODA and
odefun on [0, 10] for the stiff case. The hand-derived accelerations are also
checked against the Lagrangian by numerical differentiation (mpmath.diff).
"""
import os, time
import numpy as np
import mpmath as mp
from scipy.integrate import solve_ivp

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'reference')
DPS = 30


# --- models ----------------------------------------------------------------
# Each model, built for a number type `num` (float or mp.mpf), gives
#   L(q, v), M(q) = d2L/dv2, G(q, v) = dL/dq - (d2L/dv dq) v, F(q, v),
# so that the equations of motion read  M(q) a = G(q, v) + F(q, v).

def lib(num):
    return mp if num is mp.mpf else np


def coupled_van_der_pol(num):
    eps, rho, lam = num(0.5), num(0.02), num(0.8)
    return dict(
        L=lambda q, v: (v[0]**2 + v[1]**2) / 2 - (q[0]**2 + (1 + rho) * q[1]**2) / 2 - lam * (q[0] - q[1])**2,
        M=lambda q: [[1, 0], [0, 1]],
        G=lambda q, v: [-q[0] - 2 * lam * (q[0] - q[1]), -(1 + rho) * q[1] + 2 * lam * (q[0] - q[1])],
        F=lambda q, v: [(eps - q[0]**2) * v[0], (eps - q[1]**2) * v[1]])


def damped_oscillator(num):
    M = [[num(2), num(0.5)], [num(0.5), num(1)]]
    K = [[num(3), num(-1)], [num(-1), num(2)]]
    D = [[num(0.1), num(0.02)], [num(0.02), num(0.05)]]
    mul = lambda A, x: [A[0][0] * x[0] + A[0][1] * x[1], A[1][0] * x[0] + A[1][1] * x[1]]
    dot = lambda x, y: x[0] * y[0] + x[1] * y[1]
    return dict(
        L=lambda q, v: dot(v, mul(M, v)) / 2 - dot(q, mul(K, q)) / 2,
        M=lambda q: M,
        G=lambda q, v: [-x for x in mul(K, q)],
        F=lambda q, v: [-x for x in mul(D, v)],
        matrices=(M, K, D))


def double_pendulum_friction(num):
    m1, m2, l1, l2, g, c = num(1), num(1), num(1), num(1), num(9.81), num(0.05)

    def trig(q):  # sin/cos of q1, q2 and q1 - q2; q may carry (s1, c1, s2, c2) after q1, q2
        s1, c1, s2, c2 = q[2:6] if len(q) > 2 else [f(x) for x in q[:2] for f in (lib(num).sin, lib(num).cos)]
        return s1, c1, s2, c2, s1 * c2 - c1 * s2, c1 * c2 + s1 * s2

    def M(q):
        k = m2 * l1 * l2 * trig(q)[5]
        return [[(m1 + m2) * l1**2, k], [k, m2 * l2**2]]

    def G(q, v):
        s1, _, s2, _, sd, _ = trig(q)
        s = m2 * l1 * l2 * sd
        return [-s * v[1]**2 - (m1 + m2) * g * l1 * s1, s * v[0]**2 - m2 * g * l2 * s2]

    def L(q, v):
        _, c1, _, c2, _, cd = trig(q)
        return ((m1 + m2) * l1**2 * v[0]**2 / 2 + m2 * l2**2 * v[1]**2 / 2 + m2 * l1 * l2 * v[0] * v[1] * cd
                + (m1 + m2) * g * l1 * c1 + m2 * g * l2 * c2)
    return dict(L=L, M=M, G=G, F=lambda q, v: [-c * v[0], -c * v[1]], lift=True)


def kepler_drag(num):
    mu, gamma, sqrt = num(1), num(0.01), lib(num).sqrt
    return dict(
        L=lambda q, v: (v[0]**2 + v[1]**2) / 2 + mu / sqrt(q[0]**2 + q[1]**2),
        M=lambda q: [[1, 0], [0, 1]],
        G=lambda q, v: [-mu * x / sqrt(q[0]**2 + q[1]**2)**3 for x in q],
        F=lambda q, v: [-gamma * v[0], -gamma * v[1]])


def stiff_van_der_pol(num):
    mu = num(1000)
    return dict(L=lambda q, v: (v[0]**2 - q[0]**2) / 2, M=lambda q: [[1]], G=lambda q, v: [-q[0]],
                F=lambda q, v: [mu * (1 - q[0]**2) * v[0]])


OMEGA, ZETA = 1.0, 100.0


def overdamped_oscillator(num):
    w, z = num(OMEGA), num(ZETA)
    return dict(L=lambda q, v: (v[0]**2 - w**2 * q[0]**2) / 2, M=lambda q: [[1]],
                G=lambda q, v: [-w**2 * q[0]], F=lambda q, v: [-2 * z * w * v[0]])


# --- generic machinery -------------------------------------------------------

def accel(m, q, v):
    M, b = m['M'](q), [g + f for g, f in zip(m['G'](q, v), m['F'](q, v))]
    if len(v) == 1:
        return [b[0] / M[0][0]]
    det = M[0][0] * M[1][1] - M[0][1] * M[1][0]
    return [(M[1][1] * b[0] - M[0][1] * b[1]) / det, (M[0][0] * b[1] - M[1][0] * b[0]) / det]


def rhs(m, n):
    """First-order system for y = (q, v), or for the lifted state
    y = (q, v, sin q1, cos q1, sin q2, cos q2), which makes the pendulum's right-hand
    side rational (odefun then runs ~3-4x faster, as it needs no trig at high precision)."""
    def f(t, y):
        q, v, sc = y[:n], y[n:2 * n], y[2 * n:]
        lifted = [[c * w, -s * w] for s, c, w in zip(sc[::2], sc[1::2], v)]
        return list(v) + accel(m, list(q) + list(sc), v) + [x for pair in lifted for x in pair]
    return f


def momentum_energy(m, q, v):
    M = m['M'](q)
    p = [sum(M[i][j] * v[j] for j in range(len(v))) for i in range(len(v))]
    return p, sum(a * b for a, b in zip(v, p)) - m['L'](q, v)


def check_lagrangian(model, n, rng):
    """max |accel(hand-coded) - accel(from L by mpmath.diff)| at random states."""
    m, worst = model(mp.mpf), 0
    with mp.workdps(DPS):
        for _ in range(3):
            y = [mp.mpf(x) for x in rng.uniform(-1.5, 1.5, 2 * n)]
            y[0] += 2  # keep away from the Kepler singularity at q = 0
            Lf = lambda *z: m['L'](z[:n], z[n:])
            d = lambda *k: mp.diff(Lf, y, [k.count(i) for i in range(2 * n)])
            Mn = [[d(n + i, n + j) for j in range(n)] for i in range(n)]
            b = [d(i) - sum(d(n + i, j) * y[n + j] for j in range(n)) + f
                 for i, f in enumerate(m['F'](y[:n], y[n:]))]
            a = mp.lu_solve(mp.matrix(Mn), mp.matrix(b))
            worst = max([worst] + [abs(a[i] - x) for i, x in enumerate(accel(m, y[:n], y[n:]))])
    return float(worst)


def solve_taylor(model, y0, times, dps=DPS):
    with mp.workdps(dps):
        m, n = model(mp.mpf), len(y0) // 2
        y0 = [mp.mpf(x) for x in y0]
        if m.get('lift'):
            y0 += [f(x) for x in y0[:n] for f in (mp.sin, mp.cos)]
        sol = mp.odefun(rhs(m, n), 0, y0)
        return [sol(mp.mpf(t))[:2 * n] for t in times]


def solve_scipy(model, y0, times, method, rtol, atol):
    f = rhs(model(float), len(y0) // 2)
    r = solve_ivp(lambda t, y: np.array(f(t, y), dtype=float), (0, times[-1]), np.array(y0, float),
                  method=method, rtol=rtol, atol=atol, t_eval=times)
    assert r.success, r.message
    return r.y.T


def exact_damped(y0, times):
    M, K, D = [mp.matrix(A) for A in damped_oscillator(mp.mpf)['matrices']]
    Mi = M**-1
    A = mp.matrix(4, 4)
    A[0, 2] = A[1, 3] = 1
    A[2:4, 0:2], A[2:4, 2:4] = -Mi * K, -Mi * D
    return [list(mp.expm(A * t) * mp.matrix([mp.mpf(x) for x in y0])) for t in times]


def exact_overdamped(y0, times):
    w, z, (q0, v0) = mp.mpf(OMEGA), mp.mpf(ZETA), [mp.mpf(x) for x in y0]
    r1, r2 = w * (-z + mp.sqrt(z**2 - 1)), w * (-z - mp.sqrt(z**2 - 1))
    A, B = (r2 * q0 - v0) / (r2 - r1), (v0 - r1 * q0) / (r2 - r1)
    return [[A * mp.exp(r1 * t) + B * mp.exp(r2 * t), A * r1 * mp.exp(r1 * t) + B * r2 * mp.exp(r2 * t)]
            for t in map(mp.mpf, times)]


def diff(a, b):
    """(max abs difference, max difference relative to max(1, |state|))."""
    with mp.workdps(50):  # exact for doubles, so differences far below 1e-16 stay visible
        d = [(abs(mp.mpf(x) - mp.mpf(y)), abs(mp.mpf(y))) for ra, rb in zip(a, b) for x, y in zip(ra, rb)]
        return float(max(e for e, _ in d)), float(max(e / max(1, s) for e, s in d))


def write_csv(name, model, n, members):
    """members: list of (times, states); states are mp or float lists [q.., v..]."""
    cols = [f'{s}{i + 1}' for s in 'qvp' for i in range(n)]
    with mp.workdps(DPS):
        m = model(mp.mpf)
        lines = [','.join(['member', 't'] + cols + ['energy'])]
        for k, (times, states) in enumerate(members):
            for t, y in zip(times, states):
                q, v = [mp.mpf(x) for x in y[:n]], [mp.mpf(x) for x in y[n:]]
                p, e = momentum_energy(m, q, v)
                lines.append(','.join([str(k)] + ['%.17e' % float(x) for x in [t] + q + v + p + [e]]))
    with open(os.path.join(OUT, name + '.csv'), 'w') as fh:
        fh.write('\n'.join(lines) + '\n')


# --- scenes --------------------------------------------------------------------

def main():
    os.makedirs(OUT, exist_ok=True)
    start, rng = time.time(), np.random.default_rng(7)
    dop = lambda model, y0, ts: solve_scipy(model, y0, ts, 'DOP853', 1e-13, 1e-15)
    report = lambda label, d: print(f'  {label:<34s} max abs {d[0]:.2e}  max rel {d[1]:.2e}', flush=True)

    for model, n in [(coupled_van_der_pol, 2), (damped_oscillator, 2), (double_pendulum_friction, 2),
                     (kepler_drag, 2), (stiff_van_der_pol, 1), (overdamped_oscillator, 1)]:
        print(f'{model.__name__}: accel vs mpmath.diff(L): {check_lagrangian(model, n, rng):.1e}')

    # Single-member scenes solved with Taylor series (odefun), + self- and DOP853 checks.
    single = [('coupled_van_der_pol', coupled_van_der_pol, [-0.5, -0.25, 0, 4], [0, 0.25, 0.5, 0.75, 1]),
              ('double_pendulum_friction', double_pendulum_friction, [1.0, 0.5, 0, 0], [0, 5]),
              ('kepler_drag', kepler_drag, [1, 0, 0, 1.2], [0, 20])]
    for name, model, y0, ts in single:
        t0 = time.time()
        ref = solve_taylor(model, y0, ts)
        print(f'{name} (odefun dps {DPS}, {time.time() - t0:.1f} s)')
        report('odefun dps 40 vs dps 30', diff(solve_taylor(model, y0, ts, 40), ref))
        report('DOP853 vs odefun', diff(dop(model, y0, ts), ref))
        write_csv(name, model, 2, [(ts, ref)])

    # Ensemble: 25 members, q0 uniform in [-4, 4]^2, v0 = (0, 4).
    t0, ts, members, worst = time.time(), [0, 1], [], (0, 0)
    for q0 in np.random.default_rng(2025).uniform(-4, 4, size=(25, 2)):
        y0 = [float(q0[0]), float(q0[1]), 0.0, 4.0]
        members.append((ts, solve_taylor(coupled_van_der_pol, y0, ts)))
        worst = np.maximum(worst, diff(dop(coupled_van_der_pol, y0, ts), members[-1][1]))
    print(f'coupled_van_der_pol_ensemble (odefun dps {DPS}, {time.time() - t0:.1f} s)')
    report('DOP853 vs odefun (25 members)', worst)
    write_csv('coupled_van_der_pol_ensemble', coupled_van_der_pol, 2, members)

    # Linear scenes: exact solutions (matrix exponential / closed form) at dps 30.
    for model, exact, y0, method in [(damped_oscillator, exact_damped, [1, 0, 0, 0.5], 'DOP853'),
                                     (overdamped_oscillator, exact_overdamped, [1, 0], 'Radau')]:
        with mp.workdps(DPS):
            ref = exact(y0, [0, 10])
        print(f'{model.__name__} (exact solution)')
        report(f'odefun dps {DPS} vs exact', diff(solve_taylor(model, y0, [0, 10]), ref))
        report(f'{method} 1e-13 vs exact', diff(solve_scipy(model, y0, [0, 10], method, 1e-13, 1e-15), ref))
        write_csv(model.__name__, model, len(y0) // 2, [([0, 10], ref)])

    # Stiff Van der Pol: implicit scipy solvers only (report their mutual agreement).
    y0, ts = [2, 0], [0, 1, 10, 100, 1000, 2000]
    t0 = time.time()
    ref = solve_scipy(stiff_van_der_pol, y0, ts, 'Radau', 1e-13, 1e-13)
    print(f'stiff_van_der_pol (Radau 1e-13, {time.time() - t0:.1f} s)')
    # BDF fails ("step size less than spacing") below tol ~1e-11; 3e-14 is scipy's smallest rtol.
    for method, tol in [('Radau', 1e-12), ('Radau', 3e-14), ('LSODA', 1e-13), ('BDF', 1e-10)]:
        report(f'{method} {tol:.0e} vs Radau 1e-13', diff(solve_scipy(stiff_van_der_pol, y0, ts, method, tol, tol), ref))
    report('odefun dps 30 (t <= 10) vs Radau', diff(solve_taylor(stiff_van_der_pol, y0, ts[:3]), ref[:3]))
    write_csv('stiff_van_der_pol', stiff_van_der_pol, 1, [(ts, ref)])

    print(f'total run time {time.time() - start:.0f} s')


if __name__ == '__main__':
    main()
