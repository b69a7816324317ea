"""Reference for `trust_a_force_steep_in_time_late_in_a_run_ends_ok` (tests/trust_runtime.rs).

A unit oscillator x'' + x = a tanh((t - tc) / w), x(0) = 1, x'(0) = 0 (a = 1, tc = 1000.5,
w = 1e-3), at T = 1001.5, by Duhamel's integral
x(T) = cos T + a ∫_0^T sin(T - s) tanh((s - tc) / w) ds (and its derivative for x'):
tanh is sign(s - tc), integrated in closed form, plus a correction that a 40-digit
quadrature takes over tc ± 40 w (beyond it the correction is below e^-80).
Run: python3 scripts/kick_reference.py   (prints x(T) and x'(T) to 25 digits)
"""
from mpmath import mp, mpf, sin, cos, tanh, quad, sign

mp.dps = 40
a, tc, w, T = mpf(1), mpf("1000.5"), mpf("1e-3"), mpf("1001.5")
assert tc + 40 * w < T


def sign_part(f):
    """∫_0^T f(T - s) sign(s - tc) ds for f = sin or cos, in closed form."""
    # An antiderivative in s of sin(T - s) is cos(T - s); of cos(T - s), -sin(T - s).
    g = (lambda s: cos(T - s)) if f is sin else (lambda s: -sin(T - s))
    return -(g(tc) - g(0)) + (g(T) - g(tc))


def correction(f):
    band = [tc - 40 * w, tc, tc + 40 * w]
    return quad(lambda s: f(T - s) * (tanh((s - tc) / w) - sign(s - tc)), band)


x = cos(T) + a * (sign_part(sin) + correction(sin))
v = -sin(T) + a * (sign_part(cos) + correction(cos))
print(mp.nstr(x, 25), mp.nstr(v, 25))
