"""Reference for `trust_a_steep_force_at_a_tight_tolerance_ends_ok` (tests/trust_runtime.rs).

A unit mass from x = 0 at speed 1 crosses the potential
V(x) = a exp(-((x - xc) / w)^2) + k x^2 (a = 0.4, xc = 0.5, w = 1e-3, k = 0.001).
Energy is conserved (E = 1/2, V(0) below 1e-100), so the time to reach X is
t(X) = integral_0^X dx / sqrt(1 - 2 V(x)); the script solves t(X) = T for X at T = 3 and
T = 1 with 40-digit quadrature (split around the bump) and prints X to 17 digits.
Run: python3 scripts/bump_reference.py
"""
from mpmath import mp, mpf, exp, sqrt, quad, findroot

mp.dps = 40
a, xc, w, k = mpf("0.4"), mpf("0.5"), mpf("1e-3"), mpf("0.001")


def potential(x):
    return a * exp(-(((x - xc) / w) ** 2)) + k * x * x


def time_to(x_end):
    inv = lambda x: 1 / sqrt(1 - 2 * potential(x))
    cuts = [mpf(0), xc - 12 * w, xc - 3 * w, xc, xc + 3 * w, xc + 12 * w]
    pts = [c for c in cuts if c < x_end] + [x_end]
    return quad(inv, pts)


for t_final in ["1", "3"]:
    x = findroot(lambda x: time_to(x) - mpf(t_final), mpf(t_final) - mpf("0.01"))
    print(f"T = {t_final}: x = {mp.nstr(x, 20)}")
