#!/usr/bin/env python3
"""Lobatto nodes, weights and predictor growth to 60 digits, for the stage cap.

Usage: python3 scripts/lobatto_limits.py > forced-vi/data/lobatto_predictor.csv
Writes the exact nodes and weights to forced-vi/data/lobatto_exact.csv for
the Rust test that compares the f64 implementation with them, and prints the Lebesgue
constant of the extrapolating predictor, max_j sum_m |l_m(1 + d_j)|.
"""
import os
import mpmath as mp
from fractions import Fraction

mp.mp.dps = 60
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, '..', 'forced-vi', 'data', 'lobatto_exact.csv')


def nodes_weights(s):
    n = s - 1
    # Interior nodes: roots of P'_n on (-1, 1), from exact rational coefficients.
    p0, p1 = [Fraction(1)], [Fraction(0), Fraction(1)]
    for k in range(2, n + 1):
        p2 = [Fraction(0)] * (k + 1)
        for i, c in enumerate(p1):
            p2[i + 1] += Fraction(2 * k - 1, k) * c
        for i, c in enumerate(p0):
            p2[i] -= Fraction(k - 1, k) * c
        p0, p1 = p1, p2
    pn = p1 if n >= 1 else p0
    der = [i * c for i, c in enumerate(pn)][1:]
    coeffs = [mp.mpf(c.numerator) / c.denominator for c in reversed(der)]
    xs = [mp.re(r) for r in mp.polyroots(coeffs, maxsteps=400, extraprec=400)] if n > 1 else []
    xs = [mp.mpf(-1)] + sorted(xs) + [mp.mpf(1)]
    ws = [2 / (n * (n + 1) * mp.legendre(n, x) ** 2) for x in xs]
    return [(1 + x) / 2 for x in xs], [w / 2 for w in ws]


def lag(d, j, x):
    p = mp.mpf(1)
    for m, dm in enumerate(d):
        if m != j:
            p *= (x - dm) / (d[j] - dm)
    return p


with open(OUT, 'w') as f:
    f.write('s,k,node,weight\n')
    print('s,predictor_lebesgue')
    for s in range(2, 49):
        d, w = nodes_weights(s)
        for k in range(s):
            f.write(f'{s},{k},{mp.nstr(d[k], 25)},{mp.nstr(w[k], 25)}\n')
        leb = max(sum(abs(lag(d, m, 1 + dj)) for m in range(s)) for dj in d)
        print(f'{s},{mp.nstr(leb, 4)}', flush=True)
