#!/usr/bin/env python3
"""Writes tests/generated_models.rs: random `#[forced_lagrangian]` models (sums, products,
`powi`, `sin`, `if` with and without `else`, `let`, `for` loops, `.map().sum()`, integer
literals) from a fixed seed, and a property test that compares each model's STRUCTURE
claims and specialised kernels with the general dual-number path (issue 10).

Run `python3 scripts/gen_models.py` from the workspace root; the output is committed."""

import random

SEED = 20240610
MODELS = 40


class Gen:
    def __init__(self, rng, scalars, arrays, params):
        self.r = rng
        self.scalars = scalars  # names of scalar coordinates
        self.arrays = arrays  # (name, len)
        self.params = params
        self.ints = []  # integer locals in scope: (name, lo, hi)
        self.fresh = 0

    def name(self, stem):
        self.fresh += 1
        return f"{stem}{self.fresh}"

    def var(self, vel=None):
        r = self.r
        opts = []
        for s in self.scalars:
            opts.append(s + ("_dot" if vel or (vel is None and r.random() < 0.5) else ""))
        for (a, n) in self.arrays:
            v = "_dot" if vel or (vel is None and r.random() < 0.5) else ""
            ints = [i for i in self.ints if i[1] >= 0 and i[2] < n]
            if ints and r.random() < 0.6:
                idx = r.choice(ints)[0]
            else:
                idx = str(r.randrange(n))
            opts.append(f"{a}{v}[{idx}]")
        return r.choice(opts)

    def lit(self):
        r = self.r
        if r.random() < 0.3:
            return str(r.randint(1, 3))
        return f"{r.choice([0.25, 0.5, 0.75, 1.5, 2.0, 0.1])}"

    def flit(self):
        return f"{self.r.choice([0.25, 0.5, 0.75, 1.5, 2.0, 0.1])}"

    def leaf(self):
        r = self.r.random()
        if r < 0.55:
            return self.var()
        if r < 0.7 and self.params:
            return self.r.choice(self.params)
        return self.lit()

    def expr(self, d):
        r = self.r
        if d <= 0:
            return self.leaf()
        k = r.randrange(14)
        e = lambda: self.expr(d - 1)
        if k <= 2:
            return f"({e()} + {e()})"
        if k == 3:
            return f"({e()} - {e()})"
        if k <= 5:
            return f"({e()} * {e()})"
        if k == 6:
            return f"({e()} * {self.var()}).powi({r.randint(0, 4)})"
        if k == 7:
            return f"({e()} + {self.var()}).{r.choice(['sin', 'cos', 'tanh'])}()"
        if k == 8:
            return f"(1.0 + {self.var()} * {self.var()} * {e()} * {e()}).{r.choice(['ln', 'sqrt'])}()"
        if k == 9:
            return f"(if {e()} > {self.lit()} {{ {e()} }} else {{ {e()} }})"
        if k == 10:
            t = self.name("t")
            return f"{{ let {t} = {e()}; {t} * {e()} }}"
        if k == 11:
            m = self.name("m")
            return f"{{ let mut {m} = {self.flit()}; if {e()} > 0.0 {{ {m} = {e()}; }} {m} * {e()} }}"
        if k == 12:
            s = self.name("s")
            kk = self.name("k")
            n = r.randint(0, 4)
            op = r.choice([f"{s} = {s} * {e()} + {self.lit()};", f"{s} += {e()} * {e()};",
                           f"{s} = {s} * {s} - {e()};"])
            return f"{{ let mut {s} = {self.flit()}; for _{kk} in 0..{n} {{ {op} }} {s} }}"
        # a loop over an index
        i = self.name("i")
        n = self.r.randint(1, 3)
        self.ints.append((i, 0, n - 1))
        body = e()
        self.ints.pop()
        if r.random() < 0.5:
            return f"(0..{n}).map(|{i}| {body} * ({i} as f64 + 1.0)).sum::<f64>()".replace(".sum::<f64>()", ".sum()")
        s = self.name("s")
        return f"{{ let mut {s} = 0.0; for {i} in 0..{n} {{ {s} += {body}; }} {s} }}"


def model(rng, k):
    shape = rng.randrange(3)
    if shape == 0:
        scalars, arrays = ["x", "y"], []
        coords = "x, y"
        n = 2
        kinetic = "0.5 * (x_dot * x_dot + y_dot * y_dot)"
    elif shape == 1:
        scalars, arrays = [], [("q", 3)]
        coords = "q: [f64; 3]"
        n = 3
        kinetic = "(0..3).map(|j| 0.5 * q_dot[j] * q_dot[j]).sum()"
    else:
        scalars, arrays = ["x"], [("q", 2)]
        coords = "x, q: [f64; 2]"
        n = 3
        kinetic = "0.5 * x_dot * x_dot + q_dot[0] * q_dot[0] / 2 + 0.5 * q_dot[1] * q_dot[1]"
    params = ["a", "b"]
    g = Gen(rng, scalars, arrays, params)
    terms = [kinetic]
    for _ in range(rng.randint(1, 3)):
        c = rng.choice(["0.1", "0.2", "0.05", "1", "0.3"])
        terms.append(f"{rng.choice(['+', '-'])} {c} * {g.expr(rng.randint(1, 3))}")
    lag = " ".join(terms)
    force = ""
    fk = rng.randrange(3)
    if fk == 1:
        entries = []
        for s in scalars:
            entries.append(f"{s} = {g.expr(rng.randint(0, 2))}")
        for (a, ln) in arrays:
            if rng.random() < 0.5:
                i = "i"
                g.ints.append((i, 0, ln - 1))
                entries.append(f"{a}[{i}] = {g.expr(rng.randint(0, 2))}")
                g.ints.pop()
            else:
                entries.append(f"{a} = [{', '.join(g.expr(rng.randint(0, 2)) for _ in range(ln))}]")
        force = f",\n    force({', '.join(entries)})"
    elif fk == 2:
        entries = [f"{s} = -0.1 * {s}" for s in scalars]
        entries += [f"{a}[i] = -0.1 * {a}[i] * {a}[i]" for (a, _) in arrays]
        force = f",\n    force({', '.join(entries)})"
    name = f"Gen{k:02}"
    src = f"""#[forced_lagrangian(
    coordinates({coords}),
    lagrangian = {lag}{force},
)]
struct {name} {{
    a: f64,
    b: f64,
}}
"""
    return name, n, src


HEADER = '''//! Generated by `scripts/gen_models.py` (seed {seed}); do not edit by hand. Random models
//! (sums, products, `powi`, `sin`, `if` with and without `else`, `let`, `for` loops,
//! `.map().sum()`, integer literals) whose `STRUCTURE` claims and specialised kernels are
//! compared with the general dual-number path at random points (issue 10).
#![allow(clippy::all, unused_parens, unused_braces, unused_variables)]

use forced_vi::model::general;
use forced_vi::prelude::*;
use nalgebra::SVector;
use proptest::prelude::*;

fn close(a: f64, b: f64) -> bool {{
    (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-10 * (1.0 + a.abs().max(b.abs()))
}}

/// Checks the claims and kernels of one model at `(q, v)` and at a second point `(q2, v2)`.
/// Returns which claims were made: (no force, force without velocity, constant mass).
fn check<M: ForcedLagrangian<N>, const N: usize>(
    name: &str,
    m: &M,
    q: [f64; N],
    v: [f64; N],
    q2: [f64; N],
    v2: [f64; N],
) -> [bool; 3] {{
    let s = M::STRUCTURE;
    let (qs, vs) = (SVector::from(q), SVector::from(v));
    let (qs2, vs2) = (SVector::from(q2), SVector::from(v2));
    // The code with the parameters as duals (for sensitivities) is the model's own at
    // theta = its fields.
    let theta = m.parameter_values();
    let lw = m.lagrangian_with::<f64>(0.0, &q, &v, &theta);
    assert!(close(lw, m.lagrangian::<f64>(&q, &v)), "{{name}}: lagrangian_with");
    let (fw, f) = (m.force_with::<f64>(0.0, &q, &v, &theta), m.force::<f64>(&q, &v));
    assert!(fw.iter().zip(&f).all(|(a, b)| close(*a, *b)), "{{name}}: force_with");
    let k = m.node_jacobian(&qs, &vs);
    let g = general::node_jacobian(m, &qs, &vs);
    let blocks = |j: &forced_vi::NodeJacobian<N>| -> Vec<f64> {{
        j.grad.fq.iter().chain(j.grad.lv.iter()).chain(j.a.iter()).chain(j.b.iter())
            .chain(j.c.iter()).chain(j.e.iter()).copied().collect()
    }};
    if blocks(&g).iter().any(|x| !x.is_finite()) {{
        // Outside the model's domain (`sqrt`/`ln` of a negative number): the kernels must
        // not report a finite result either; entries of terms that do not use the
        // offending variable may stay finite, so compare only that something is not.
        assert!(blocks(&k).iter().any(|x| !x.is_finite()), "{{name}}: general path non-finite, kernels finite at q = {{q:?}}, v = {{v:?}}");
        return [!s.has_force, !s.force_uses_velocity, s.constant_mass];
    }}
    let pairs = [
        ("fq", k.grad.fq.as_slice(), g.grad.fq.as_slice()),
        ("lv", k.grad.lv.as_slice(), g.grad.lv.as_slice()),
        ("a", k.a.as_slice(), g.a.as_slice()),
        ("b", k.b.as_slice(), g.b.as_slice()),
        ("c", k.c.as_slice(), g.c.as_slice()),
        ("e", k.e.as_slice(), g.e.as_slice()),
    ];
    for (block, x, y) in pairs {{
        for (i, (a, b)) in x.iter().zip(y).enumerate() {{
            assert!(close(*a, *b), "{{name}}: node_jacobian {{block}}[{{i}}] = {{a:e}}, general {{b:e}} at q = {{q:?}}, v = {{v:?}}");
        }}
    }}
    let kg = m.node_gradient(&qs, &vs);
    let gg = general::node_gradient(m, &qs, &vs);
    for i in 0..N {{
        assert!(close(kg.fq[i], gg.fq[i]) && close(kg.lv[i], gg.lv[i]), "{{name}}: node_gradient[{{i}}]");
    }}
    let mass = m.mass_matrix(&qs, &vs);
    for (a, b) in mass.iter().zip(g.e.iter()) {{
        assert!(close(*a, *b), "{{name}}: mass_matrix {{a:e}} vs {{b:e}}");
    }}
    let f1: [f64; N] = m.force::<f64>(&q, &v);
    let f2: [f64; N] = m.force::<f64>(&q, &v2);
    if !s.has_force {{
        assert!(f1.iter().all(|x| *x == 0.0), "{{name}}: has_force = false but F = {{f1:?}}");
    }}
    if !s.force_uses_velocity {{
        assert_eq!(f1, f2, "{{name}}: force_uses_velocity = false but F changes with v");
    }}
    if s.constant_mass {{
        let g2 = general::node_jacobian(m, &qs2, &vs2);
        for (a, b) in g.e.iter().zip(g2.e.iter()) {{
            assert!(close(*a, *b), "{{name}}: constant_mass = true but E changes: {{a:e}} vs {{b:e}}");
        }}
        for c in g.c.iter().chain(g2.c.iter()) {{
            assert!(c.abs() <= 1e-12, "{{name}}: constant_mass = true but C = {{c:e}}");
        }}
    }}
    [!s.has_force, !s.force_uses_velocity, s.constant_mass]
}}

'''


def main():
    rng = random.Random(SEED)
    out = [HEADER.format(seed=SEED)]
    models = []
    for k in range(MODELS):
        name, n, src = model(rng, k)
        models.append((name, n))
        out.append(src + "\n")
    calls = []
    for name, n in models:
        calls.append(
            f"    let m = {name} {{ a: pa, b: pb }};\n"
            f"    claims.push(check(\"{name}\", &m, pick(&p, 0), pick(&p, 1), pick(&p, 2), pick(&p, 3)));\n"
        )
    out.append(
        """/// Four points of `N` coordinates from a flat list of numbers.
fn pick<const N: usize>(p: &[f64], which: usize) -> [f64; N] {
    std::array::from_fn(|i| p[(which * 3 + i) % p.len()])
}

fn check_all(p: &[f64], pa: f64, pb: f64) -> Vec<[bool; 3]> {
    let mut claims = Vec::new();
"""
        + "".join(calls)
        + """    claims
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn trust_generated_models_match_the_general_path(
        p in proptest::collection::vec(-1.0f64..1.0, 12),
        pa in 0.5f64..1.5,
        pb in -1.0f64..1.0,
    ) {
        let _ = check_all(&p, pa, pb);
    }
}

/// The generated set exercises every claim both ways (otherwise the comparison above
/// would test nothing).
#[test]
fn trust_generated_models_make_claims_both_ways() {
    let p: Vec<f64> = (0..12).map(|i| 0.1 * i as f64 - 0.55).collect();
    let claims = check_all(&p, 1.0, 0.3);
    for k in 0..3 {
        assert!(claims.iter().any(|c| c[k]) && claims.iter().any(|c| !c[k]), "claim {k}");
    }
}
"""
    )
    with open("tests/generated_models.rs", "w") as f:
        f.write("".join(out))


if __name__ == "__main__":
    main()
