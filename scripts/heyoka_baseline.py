#!/usr/bin/env python3
"""heyoka as an external baseline for the work-precision report (issue 28, item 4).

What: times heyoka's adaptive Taylor integrator (`taylor_adaptive`) on the report's non-stiff
scenes and writes data/baselines/heyoka.csv, which the report embeds and shows as an external
series (it never runs Python itself). Left out: cartesian_pendulum (a constrained model),
stiff_van_der_pol (stiff; an explicit Taylor method is the wrong tool) and the large models.

How: each scene's first-order ODE in (q, v) is written by hand from the forced Euler-Lagrange
equations d/dt(dL/dv) - dL/dq = F with the parameters of models/src/models.rs; the hand-derived
acceleration and momentum are checked at random points against L and F differentiated by
central differences in numpy (`check`). Initial data, final time and the reference final state
come from data/reference/<scene>.csv as the Rust scene reads them: the t = 0 row gives (q0, v0),
the last row the final time and state (ensembles: member 0 only). For each tolerance of the
ladder (rtol = atol = tol, half decades from 1e-3 to 1e-14, the report's baseline ladder
extended) the integrator is built once (its JIT compilation timed on its own, as jit_seconds)
(caches cleared) and propagate_until(T) is timed from the initial state, state and time reset before each
repeat: run_seconds is the median of the repeats (at least 5, about 0.2 s of timing, at most
51). It includes the Python-to-C++ call, whose own cost (a propagate_until that takes no step)
is overhead_seconds. Errors are computed as the report computes them: error is the max-norm
error in q at the final time (the report's err_q), err_p the same in p = dL/dv, err_energy the
absolute error of v.p - L.

Usage (from the workspace root):
    pip install -r scripts/requirements.txt heyoka
    python3 scripts/heyoka_baseline.py              # checks, then measures; ~1 min
    python3 scripts/heyoka_baseline.py --check      # only the right-hand-side checks
Run it on a quiet machine: the times are wall times.
"""
import argparse
import csv
import datetime
import os
import platform
import statistics
import time

import heyoka as hy
import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
OUT = os.path.join(ROOT, 'data', 'baselines', 'heyoka.csv')
TOLERANCES = [10.0 ** (-3 - 0.5 * k) for k in range(23)]
BUDGET, MIN_REPEATS, MAX_REPEATS = 0.2, 5, 51


class Math:
    """The functions the models use, for numpy floats or for heyoka expressions."""

    def __init__(self, lib):
        self.sin, self.cos = lib.sin, lib.cos


NP, HY = Math(np), Math(hy)


# --- scenes ------------------------------------------------------------------------------
# Each scene: n, accel(m, t, q, v) (the acceleration from the Euler-Lagrange equations, for
# floats or expressions), momentum(m, t, q, v), and the numpy L(t, q, v) and F(t, q, v) the
# check differentiates and the energy needs. Parameters as in models/src/models.rs.

def coupled_van_der_pol():
    eps, rho, lam = 0.5, 0.02, 0.8
    return dict(
        n=2,
        accel=lambda m, t, q, v: [
            -q[0] - 2 * lam * (q[0] - q[1]) + (eps - q[0] * q[0]) * v[0],
            -(1 + rho) * q[1] + 2 * lam * (q[0] - q[1]) + (eps - q[1] * q[1]) * v[1]],
        momentum=lambda m, t, q, v: list(v),
        L=lambda t, q, v: (0.5 * (v[0] ** 2 + v[1] ** 2) - 0.5 * (q[0] ** 2 + (1 + rho) * q[1] ** 2)
                           - lam * (q[0] - q[1]) ** 2),
        F=lambda t, q, v: [(eps - q[0] ** 2) * v[0], (eps - q[1] ** 2) * v[1]])


def damped_oscillator():
    mass = np.array([[2.0, 0.5], [0.5, 1.0]])
    stiff = np.array([[3.0, -1.0], [-1.0, 2.0]])
    damp = np.array([[0.1, 0.02], [0.02, 0.05]])
    # M a = -K q - D v with a constant M: a = -(M^-1 K) q - (M^-1 D) v.
    a_q, a_v = -np.linalg.solve(mass, stiff), -np.linalg.solve(mass, damp)
    return dict(
        n=2,
        accel=lambda m, t, q, v: [sum(float(a_q[i, j]) * q[j] + float(a_v[i, j]) * v[j] for j in range(2))
                                  for i in range(2)],
        momentum=lambda m, t, q, v: [mass[i, 0] * v[0] + mass[i, 1] * v[1] for i in range(2)],
        L=lambda t, q, v: 0.5 * v @ mass @ v - 0.5 * q @ stiff @ q,
        F=lambda t, q, v: -damp @ v)


def double_pendulum_friction():
    m1, m2, l1, l2, g, c = 1.0, 1.0, 1.0, 1.0, 9.81, 0.05
    k = m2 * l1 * l2

    def accel(m, t, q, v):
        # E(q) a = L_q + F - (dE/dt) v, E = [[(m1+m2) l1^2, k cos d], [k cos d, m2 l2^2]], d = q1 - q2.
        s, cd = m.sin(q[0] - q[1]), m.cos(q[0] - q[1])
        b1 = -k * s * v[1] * v[1] - (m1 + m2) * g * l1 * m.sin(q[0]) - c * v[0]
        b2 = k * s * v[0] * v[0] - m2 * g * l2 * m.sin(q[1]) - c * v[1]
        e11, e12, e22 = (m1 + m2) * l1 * l1, k * cd, m2 * l2 * l2
        det = e11 * e22 - e12 * e12
        return [(e22 * b1 - e12 * b2) / det, (e11 * b2 - e12 * b1) / det]

    def momentum(m, t, q, v):
        e12 = k * m.cos(q[0] - q[1])
        return [(m1 + m2) * l1 * l1 * v[0] + e12 * v[1], e12 * v[0] + m2 * l2 * l2 * v[1]]

    return dict(
        n=2, accel=accel, momentum=momentum,
        L=lambda t, q, v: (0.5 * (m1 + m2) * l1 ** 2 * v[0] ** 2 + 0.5 * m2 * l2 ** 2 * v[1] ** 2
                           + k * v[0] * v[1] * np.cos(q[0] - q[1]) + (m1 + m2) * g * l1 * np.cos(q[0])
                           + m2 * g * l2 * np.cos(q[1])),
        F=lambda t, q, v: [-c * v[0], -c * v[1]])


def kepler_drag():
    mu, gamma = 1.0, 0.01

    def accel(m, t, q, v):
        r3_inv = (q[0] * q[0] + q[1] * q[1]) ** -1.5
        return [-mu * q[0] * r3_inv - gamma * v[0], -mu * q[1] * r3_inv - gamma * v[1]]

    return dict(
        n=2, accel=accel, momentum=lambda m, t, q, v: list(v),
        L=lambda t, q, v: 0.5 * (v[0] ** 2 + v[1] ** 2) + mu / np.sqrt(q[0] ** 2 + q[1] ** 2),
        F=lambda t, q, v: [-gamma * v[0], -gamma * v[1]])


def driven_duffing():
    delta, alpha, beta, gamma, omega = 0.3, -1.0, 1.0, 0.5, 1.2
    return dict(
        n=1,
        accel=lambda m, t, q, v: [-delta * v[0] - alpha * q[0] - beta * q[0] ** 3 + gamma * m.cos(omega * t)],
        momentum=lambda m, t, q, v: list(v),
        L=lambda t, q, v: 0.5 * v[0] ** 2 - 0.5 * alpha * q[0] ** 2 - 0.25 * beta * q[0] ** 4,
        F=lambda t, q, v: [-delta * v[0] + gamma * np.cos(omega * t)])


def kapitza_pendulum():
    mass, l, g, a, om, c = 1.0, 1.0, 9.81, 0.1, 50.0, 0.1

    def accel(m, t, q, v):
        # Pivot y_s = a cos(om t): m l^2 th'' + m l sin(th) (g + y_s'') = -c th'.
        ys_dd = -a * om * om * m.cos(om * t)
        return [-(g + ys_dd) * m.sin(q[0]) / l - c * v[0] / (mass * l * l)]

    def momentum(m, t, q, v):
        ys_d = -a * om * m.sin(om * t)
        return [mass * (l * l * v[0] + l * m.sin(q[0]) * ys_d)]

    def lagrangian(t, q, v):
        ys, ys_d = a * np.cos(om * t), -a * om * np.sin(om * t)
        return (0.5 * mass * (l * l * v[0] ** 2 + 2 * l * np.sin(q[0]) * v[0] * ys_d + ys_d ** 2)
                - mass * g * (ys - l * np.cos(q[0])))

    return dict(n=1, accel=accel, momentum=momentum, L=lagrangian, F=lambda t, q, v: [-c * v[0]])


SCENES = {
    'coupled_van_der_pol': coupled_van_der_pol,
    'coupled_van_der_pol_ensemble': coupled_van_der_pol,
    'damped_oscillator': damped_oscillator,
    'double_pendulum_friction': double_pendulum_friction,
    'kepler_drag': kepler_drag,
    'driven_duffing': driven_duffing,
    'kapitza_pendulum': kapitza_pendulum,
}


# --- reference data, system, checks ------------------------------------------------------

def reference(name, n, member=0):
    """(q0, v0, T, q_T, p_T, E_T) of a member, as src/scenes.rs reads them."""
    with open(os.path.join(ROOT, 'data', 'reference', name + '.csv')) as f:
        rows = [[float(x) for x in r] for r in csv.reader(line for line in f if not line.startswith('#'))
                if r and r[0] != 'member']
    rows = [r for r in rows if int(r[0]) == member]
    start = next(r for r in rows if r[1] == 0.0)
    end = max(rows, key=lambda r: r[1])
    return (start[2:2 + n], start[2 + n:2 + 2 * n], end[1], np.array(end[2:2 + n]),
            np.array(end[2 + 2 * n:2 + 3 * n]), end[2 + 3 * n])


def system(model):
    """The variables and the heyoka system y' = (v, a(t, q, v))."""
    n = model['n']
    q = list(hy.make_vars(*[f'q{i}' for i in range(n)])) if n > 1 else [hy.make_vars('q0')]
    v = list(hy.make_vars(*[f'v{i}' for i in range(n)])) if n > 1 else [hy.make_vars('v0')]
    a = model['accel'](HY, hy.time, q, v)
    return q + v, list(zip(q, v)) + list(zip(v, a))


def fd_accel_momentum(model, t, q, v, h=1e-4):
    """Acceleration and momentum from L and F alone, by central differences of step h:
    E a = L_q + F - C v - L_vt with E = L_vv, C = L_vq."""
    n, L = model['n'], model['L']
    unit = np.eye(n) * h

    def lv(t, q, v):
        return np.array([(L(t, q, v + unit[i]) - L(t, q, v - unit[i])) / (2 * h) for i in range(n)])

    lq = np.array([(L(t, q + unit[i], v) - L(t, q - unit[i], v)) / (2 * h) for i in range(n)])
    e = np.column_stack([(lv(t, q, v + unit[j]) - lv(t, q, v - unit[j])) / (2 * h) for j in range(n)])
    c = np.column_stack([(lv(t, q + unit[j], v) - lv(t, q - unit[j], v)) / (2 * h) for j in range(n)])
    lvt = (lv(t + h, q, v) - lv(t - h, q, v)) / (2 * h)
    rhs = lq + np.asarray(model['F'](t, q, v)) - c @ v - lvt
    return np.linalg.solve(e, rhs), lv(t, q, v)


def check(name, model, points=5, seed=28):
    """The compiled right-hand side against L and F by finite differences; raises if off."""
    n = model['n']
    variables, sys = system(model)
    rhs = hy.cfunc([f for _, f in sys], variables)
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(points):
        t, q, v = rng.uniform(0, 10), rng.uniform(-2, 2, n), rng.uniform(-2, 2, n)
        got = rhs(np.concatenate([q, v]), time=t)
        # Richardson's extrapolation of steps h and h/2 (the pivot of kapitza_pendulum is fast).
        (a1, p1), (a2, p2) = (fd_accel_momentum(model, t, q, v, h) for h in (2e-4, 1e-4))
        a, p = (4 * a2 - a1) / 3, (4 * p2 - p1) / 3
        scale = max(1.0, np.max(np.abs(a)), np.max(np.abs(p)))
        off = max(np.max(np.abs(got[:n] - v)), np.max(np.abs(got[n:] - a)),
                  np.max(np.abs(np.array(model['momentum'](NP, t, q, v)) - p))) / scale
        worst = max(worst, off)
    if worst > 1e-6:
        raise SystemExit(f'{name}: the right-hand side disagrees with L and F ({worst:.1e})')
    print(f'{name}: right-hand side and momentum agree with L, F by finite differences ({worst:.1e})')


# --- measurement -------------------------------------------------------------------------

def timed(f):
    start = time.perf_counter()
    out = f()
    return out, time.perf_counter() - start


def measure(name, model, tol):
    n = model['n']
    q0, v0, t_final, q_ref, p_ref, e_ref = reference(name, n)
    y0 = np.array(q0 + v0)
    _, sys = system(model)
    # A cold build: heyoka keeps compiled code in memory (and on disk, switched off in main), and
    # tolerances with the same Taylor order, or the ensemble after coupled_van_der_pol, would
    # otherwise reuse it.
    hy.llvm_state.clear_memcache()
    ta, jit = timed(lambda: hy.taylor_adaptive(sys, y0, tol=tol))

    def run():
        ta.time = 0.0
        ta.state[:] = y0
        return timed(lambda: ta.propagate_until(t_final))

    (outcome, _, _, steps, _, _), first = run()
    if outcome != hy.taylor_outcome.time_limit:
        raise SystemExit(f'{name} at tol {tol:.1e}: {outcome}')
    y, t_end = ta.state.copy(), ta.time
    times = [first] + [run()[1] for _ in range(max(MIN_REPEATS, min(MAX_REPEATS, int(BUDGET / first))) - 1)]
    # The cost of the call alone: a propagate_until to the time already reached takes no step.
    overhead = statistics.median(timed(lambda: ta.propagate_until(t_final))[1] for _ in range(21))
    q, v = y[:n], y[n:]
    p = np.array(model['momentum'](NP, t_end, q, v))
    energy = v @ p - model['L'](t_end, q, v)
    return dict(scene=name, member=0, tol=f'{tol:.3e}', order=ta.order, steps=steps,
                error=f'{np.max(np.abs(q - q_ref)):.6e}', err_p=f'{np.max(np.abs(p - p_ref)):.6e}',
                err_energy=f'{abs(energy - e_ref):.6e}', run_seconds=f'{statistics.median(times):.6e}',
                jit_seconds=f'{jit:.6e}', overhead_seconds=f'{overhead:.6e}', repeats=len(times),
                heyoka_version=hy.__version__)


def cpu():
    try:
        with open('/proc/cpuinfo') as f:
            return next(line.split(':', 1)[1].strip() for line in f if line.startswith('model name'))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--check', action='store_true', help='only check the right-hand sides')
    ap.add_argument('--out', default=OUT, help='the CSV file (default data/baselines/heyoka.csv)')
    args = ap.parse_args()
    hy.llvm_state.set_diskcache_enabled(False)  # every build below compiles from scratch
    for name, make in SCENES.items():
        check(name, make())
    if args.check:
        return
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    rows = []
    for name, make in SCENES.items():
        model = make()
        for tol in TOLERANCES:
            rows.append(measure(name, model, tol))
            r = rows[-1]
            print(f"{name:30} tol {r['tol']}  err_q {r['error']}  run {float(r['run_seconds']) * 1e6:9.1f} us"
                  f"  jit {float(r['jit_seconds']) * 1e3:7.1f} ms  steps {r['steps']}")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, 'w', newline='') as f:
        f.write(f'# measured at commit time by scripts/heyoka_baseline.py, not by the report: '
                f'{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d}, {cpu()}, {os.cpu_count()} '
                f'hardware threads shared with other work (load average {load:.2f} at the start), '
                f'heyoka {hy.__version__}, Python {platform.python_version()}\n')
        w = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator='\n')
        w.writeheader()
        w.writerows(rows)
    print(f'wrote {os.path.relpath(args.out)} ({len(rows)} rows)')


if __name__ == '__main__':
    main()
