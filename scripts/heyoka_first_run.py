#!/usr/bin/env python3
"""The first answer on a new large model: heyoka's JIT build plus its run (issue 28, item 5).

What: a damped sine-Gordon chain of n = 256 coordinates with fixed ends,

    L = sum_i v_i^2 / 2 - sum_{j=0..n} k (q_j - q_{j-1})^2 / 2 - sum_i w (1 - cos q_i),
    F_i = -c v_i,            q_{-1} = q_n = 0,   k = 1, w = 1, c = 0.01,

from q_i(0) = 1.5 exp(-((i - 127.5) / 12)^2), v(0) = 0, to T = 10. The same model is
`first_run`'s in src/report/step_cost/first_run.rs, which `forced-vi-report step-cost` builds
as a new crate and runs; the report puts the two side by side (it runs no Python).

How: the reference final state is scipy's DOP853 at rtol = 2.5e-14 (its floor) and
atol = 1e-14, checked against
heyoka at tol 1e-15 (compact mode): their difference is written in the CSV's note. For each tolerance (1e-6 and
1e-9) and each of heyoka's two code-generation modes (the default, one function unrolled
over the whole system, and `compact_mode`, loops over the terms, which heyoka's docs
recommend for large systems), the integrator is built once with heyoka's code caches out
of the way (its disk cache disabled, its memory cache cleared): jit_seconds. Then
propagate_until(T) is timed from the initial state, reset before each of 5 repeats (run_seconds: the median). error is the max-norm error in q at T.

Writes data/baselines/heyoka_first_run.csv and data/reference/sine_gordon_chain_256.csv.

Usage (from the workspace root; a few minutes, most of it the default mode's JIT):
    pip install -r scripts/requirements.txt heyoka
    python3 scripts/heyoka_first_run.py
"""
import csv
import datetime
import os
import platform
import statistics
import time

import heyoka as hy
import numpy as np
from scipy.integrate import solve_ivp

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
OUT = os.path.join(ROOT, 'data', 'baselines', 'heyoka_first_run.csv')
REF = os.path.join(ROOT, 'data', 'reference', 'sine_gordon_chain_256.csv')
N, K, W, C, T = 256, 1.0, 1.0, 0.01, 10.0
TOLERANCES = [1e-6, 1e-9]
REPEATS = 5


def initial():
    i = np.arange(N)
    return 1.5 * np.exp(-(((i - 127.5) / 12.0) ** 2)), np.zeros(N)


def rhs(_t, y):
    q, v = y[:N], y[N:]
    left = np.concatenate(([0.0], q[:-1]))
    right = np.concatenate((q[1:], [0.0]))
    return np.concatenate((v, K * (right - 2.0 * q + left) - W * np.sin(q) - C * v))


def reference(sys):
    q0, v0 = initial()
    y0 = np.concatenate((q0, v0))
    fine = solve_ivp(rhs, (0.0, T), y0, method='DOP853', rtol=2.5e-14, atol=1e-14)
    ta = hy.taylor_adaptive(sys, y0.copy(), tol=1e-15, compact_mode=True)
    ta.propagate_until(T)
    q = fine.y[:N, -1]
    return q, float(np.max(np.abs(q - ta.state[:N])))


def heyoka_system():
    qs = hy.make_vars(*[f'q{i}' for i in range(N)])
    vs = hy.make_vars(*[f'v{i}' for i in range(N)])
    sys = [(qs[i], vs[i]) for i in range(N)]
    for i in range(N):
        left = qs[i - 1] if i > 0 else 0.0
        right = qs[i + 1] if i < N - 1 else 0.0
        acc = K * (right - 2.0 * qs[i] + left) - W * hy.sin(qs[i]) - C * vs[i]
        sys.append((vs[i], acc))
    return sys


def main():
    hy.llvm_state.set_diskcache_enabled(False)  # every build below compiles from scratch
    sys = heyoka_system()
    q_ref, ref_check = reference(sys)
    with open(REF, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['i', 'q_final'])
        for i, x in enumerate(q_ref):
            w.writerow([i, f'{x:.17e}'])
    q0, v0 = initial()
    state = np.concatenate((q0, v0))
    rows = []
    for tol in TOLERANCES:
        for compact in (False, True):
            hy.llvm_state.clear_memcache()
            t0 = time.perf_counter()
            ta = hy.taylor_adaptive(sys, state.copy(), tol=tol, compact_mode=compact)
            jit = time.perf_counter() - t0
            runs = []
            for _ in range(REPEATS):
                ta.state[:] = state
                ta.time = 0.0
                t0 = time.perf_counter()
                out = ta.propagate_until(T)
                runs.append(time.perf_counter() - t0)
            err = float(np.max(np.abs(ta.state[:N] - q_ref)))
            rows.append([tol, 'compact' if compact else 'default', f'{jit:.4f}',
                         f'{statistics.median(runs):.6e}', f'{err:.3e}', out[3],
                         ta.order, REPEATS])
            print(rows[-1], flush=True)
    note = (f'measured at commit time by scripts/heyoka_first_run.py, not by the report: '
            f'{datetime.date.today()}, {platform.processor() or platform.machine()}, '
            f'load average {os.getloadavg()[0]:.2f} at the start, heyoka {hy.__version__}, '
            f'Python {platform.python_version()}; reference scipy DOP853 at 2.5e-14, '
            f'{ref_check:.1e} from heyoka at tol 1e-15')
    with open(OUT, 'w', newline='') as f:
        f.write(f'# {note}\n')
        w = csv.writer(f)
        w.writerow(['tol', 'mode', 'jit_seconds', 'run_seconds', 'error', 'steps', 'order',
                    'repeats'])
        w.writerows(rows)


if __name__ == '__main__':
    main()
