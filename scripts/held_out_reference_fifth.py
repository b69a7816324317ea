"""References for the fifth held-out set of tests/held_out.rs (tests/held_out_models_fifth.rs):
the end states (q, p). Each model's Lagrangian and force are written again here in sympy, and
integrated as in held_out_reference_third.py (sympy's equations of motion, Gragg-Bulirsch-Stoer
extrapolation in numpy's long double over macro steps H and H/2, DOP853 at 1e-13 beside them).
Needs sympy, numpy and scipy; about a minute. Run from the repository root:
`python3 scripts/held_out_reference_fifth.py`.
"""
import sympy as sp

from held_out_reference_third import main, t  # noqa: F401  (t: the time symbol)

R = sp.Rational


def swinging_atwood():
    r, th, dr, dth = sp.symbols("r th dr dth")
    L = 2 * dr**2 + R(1, 2) * r**2 * dth**2 - R(981, 100) * r * (3 - sp.cos(th))
    return [r, th], [dr, dth], L, [-R(5, 100) * dr, 0]


def triple_pendulum():
    a, b, c, da, db, dc = sp.symbols("a b c da db dc")
    L = (R(1, 2) * (3 * da**2 + 2 * db**2 + dc**2 + 4 * da * db * sp.cos(a - b)
                    + 2 * da * dc * sp.cos(a - c) + 2 * db * dc * sp.cos(b - c))
         + R(981, 100) * (3 * sp.cos(a) + 2 * sp.cos(b) + sp.cos(c)))
    return [a, b, c], [da, db, dc], L, [-R(1, 10) * da, -R(1, 10) * db, -R(1, 10) * dc]


def penning_trap():
    x, y, z, dx, dy, dz = sp.symbols("x y z dx dy dz")
    L = (R(1, 2) * (dx**2 + dy**2 + dz**2) + 4 * (x * dy - y * dx)
         - R(1, 2) * (z**2 - R(1, 2) * (x**2 + y**2)))
    return [x, y, z], [dx, dy, dz], L, [-R(2, 100) * dx, -R(2, 100) * dy, -R(2, 100) * dz]


def washboard():
    x, dx = sp.symbols("x dx")
    return [x], [dx], R(1, 2) * dx**2 + R(1, 2) * sp.cos(x), [-R(1, 10) * (dx - 20)]


def far_oscillator():
    x, dx = sp.symbols("x dx")
    return [x], [dx], R(1, 2) * dx**2 - R(1, 2) * (x - 10000) ** 2, [-R(1, 10) * dx]


# (name, model, q0, v0, T, H), as in tests/held_out.rs; the Atwood machine whirls fast where
# its cord is short, and the trap's cyclotron period is 0.8: shorter macro steps there.
MODELS = [
    ("swinging_atwood", swinging_atwood, ["1", "1"], ["0", "0"], 10, 0.01),
    ("triple_pendulum", triple_pendulum, ["0.3", "-0.2", "0.4"], ["0"] * 3, 10, 0.05),
    ("penning_trap", penning_trap, ["1", "0", "0.5"], ["0", "0.3", "0"], 15, 0.02),
    ("washboard", washboard, ["0"], ["20"], 15, 0.02),
    ("far_oscillator", far_oscillator, ["10001"], ["0"], 15, 0.05),
]

if __name__ == "__main__":
    main(MODELS)
