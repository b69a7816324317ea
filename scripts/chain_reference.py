"""Reference for the order test of the large-model path (issue 12): the damped FPU-beta chain
with fixed ends, n = 64, solved as a first-order ODE by scipy (DOP853 and Radau at tight
tolerances, which must agree). Independent of forced-vi: the equations are written out here.

    L = sum_i m v_i^2 / 2 - sum_{i=0..n} (k d_i^2 / 2 + beta d_i^4 / 4),  d_i = q_i - q_{i-1},
    q_{-1} = q_n = 0,  F_i = -c v_i,  so  m a_i = -phi'(d_i) + phi'(d_{i+1}) - c v_i,
    phi'(d) = k d + beta d^3.

Initial state (modes 8 and 20, springs stretched into the quartic range, |d| up to about 1):
q_i = 0.3 sin(8 x_i), v_i = 0.8 cos(20 x_i), x_i = pi (i+1)/(n+1). T = 8.
Writes data/reference/fpu_chain_64.csv: one line per coordinate, i,q0,v0,q_T,p_T.

    pip install -r scripts/requirements.txt && python3 scripts/chain_reference.py
"""
import numpy as np
from scipy.integrate import solve_ivp

N, M, K, BETA, C, T = 64, 1.0, 1.0, 1.0, 0.01, 8.0


def rhs(_t, y):
    q, v = y[:N], y[N:]
    ext = np.concatenate(([0.0], q, [0.0]))
    d = np.diff(ext)  # d_0 .. d_N
    dphi = K * d + BETA * d**3
    a = (-dphi[:-1] + dphi[1:] - C * v) / M
    return np.concatenate((v, a))


def main():
    x = np.pi * np.arange(1, N + 1) / (N + 1)
    q0 = 0.3 * np.sin(8 * x)
    v0 = 0.8 * np.cos(20 * x)
    y0 = np.concatenate((q0, v0))
    runs = {}
    for method, tol in (("DOP853", 3e-14), ("Radau", 1e-13)):
        sol = solve_ivp(rhs, (0.0, T), y0, method=method, rtol=tol, atol=tol * 1e-2)
        assert sol.success, sol.message
        runs[method] = sol.y[:, -1]
    gap = np.max(np.abs(runs["DOP853"] - runs["Radau"]))
    print(f"DOP853 against Radau: max difference {gap:.2e}")
    assert gap < 1e-10, gap
    y = runs["DOP853"]
    with open("data/reference/fpu_chain_64.csv", "w") as f:
        f.write(f"# scripts/chain_reference.py: n={N} m={M} k={K} beta={BETA} c={C} T={T}; "
                f"DOP853 rtol 3e-14, Radau agrees to {gap:.1e}\n")
        f.write("i,q0,v0,q_T,p_T\n")
        for i in range(N):
            f.write(f"{i},{float(q0[i])!r},{float(v0[i])!r},{float(y[i])!r},{float(M * y[N + i])!r}\n")


if __name__ == "__main__":
    main()
