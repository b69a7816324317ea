//! Symbolic polynomials in the model's variables, with coefficients built from the
//! parameters. A term of the Lagrangian or a force component that is a (small) polynomial is
//! differentiated here, at compile time, and the kernels get plain `f64` code for its
//! derivatives: a quadratic term has a constant Hessian, a linear force a constant Jacobian
//! (DESIGN §2, "Specialise"). Anything else falls back to dual numbers.
//!
//! Variables are numbered by slot: `q[s]` is slot `s`, `v[s]` is slot `n + s`.
//!
//! This module has the algebra ([`Poly`], its coefficients and atoms); `extract` reads
//! polynomials from expressions ([`Extractor`]).

use std::collections::{BTreeMap, HashMap};

use proc_macro2::{Literal, TokenStream};
use quote::{quote, ToTokens};

mod extract;
pub use extract::Extractor;

/// Limits that keep generated code small; beyond them, dual numbers are used.
const MAX_DEGREE: u32 = 8;
const MAX_MONOMIALS: usize = 48;
const MAX_COEF_TERMS: usize = 32;

/// `Π atoms × number`, summed.
#[derive(Clone, Debug, PartialEq)]
pub struct Coef(BTreeMap<Vec<usize>, f64>);

/// Slot → exponent, sorted by slot.
pub type Monomial = Vec<(usize, u32)>;

/// A polynomial: monomial → coefficient.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Poly(pub BTreeMap<Monomial, Coef>);

/// Opaque constant sub-expressions (parameters, `rho.sqrt()`, `PI`), by their tokens.
#[derive(Default)]
pub struct Atoms {
    tokens: Vec<TokenStream>,
    ids: HashMap<String, usize>,
}

impl Atoms {
    fn intern(&mut self, t: TokenStream) -> usize {
        let key = t.to_string();
        if let Some(&id) = self.ids.get(&key) {
            return id;
        }
        self.tokens.push(t);
        self.ids.insert(key, self.tokens.len() - 1);
        self.tokens.len() - 1
    }
}

impl Coef {
    /// A number; `None` unless finite (an infinite coefficient cannot be written out).
    fn number(x: f64) -> Option<Coef> {
        if !x.is_finite() {
            return None;
        }
        let mut m = BTreeMap::new();
        if x != 0.0 {
            m.insert(Vec::new(), x);
        }
        Some(Coef(m))
    }
    fn zero() -> Coef {
        Coef(BTreeMap::new())
    }
    fn atom(id: usize) -> Coef {
        Coef(BTreeMap::from([(vec![id], 1.0)]))
    }
    fn is_zero(&self) -> bool {
        self.0.is_empty()
    }
    /// The numeric value, if the coefficient has no atoms.
    fn as_number(&self) -> Option<f64> {
        match self.0.len() {
            0 => Some(0.0),
            1 => self.0.get(&Vec::new()).copied(),
            _ => None,
        }
    }
    fn add(&mut self, o: &Coef) -> Option<()> {
        for (k, x) in &o.0 {
            let e = self.0.entry(k.clone()).or_insert(0.0);
            *e += x;
            if !e.is_finite() {
                return None;
            }
            if *e == 0.0 {
                self.0.remove(k);
            }
        }
        (self.0.len() <= MAX_COEF_TERMS).then_some(())
    }
    /// The product; `None` if a coefficient overflows or underflows (a product of nonzero
    /// numbers that is not a normal `f64` would lose the term or its precision).
    fn mul(&self, o: &Coef) -> Option<Coef> {
        let mut out = Coef::zero();
        for (ka, xa) in &self.0 {
            for (kb, xb) in &o.0 {
                let mut k: Vec<usize> = ka.iter().chain(kb).copied().collect();
                k.sort_unstable();
                let x = xa * xb;
                if !x.is_normal() {
                    return None;
                }
                out.add(&Coef(BTreeMap::from([(k, x)])))?;
            }
        }
        Some(out)
    }
    fn scale(&self, x: f64) -> Option<Coef> {
        self.mul(&Coef::number(x)?)
    }

    /// The coefficient as an `f64` expression (atoms by their tokens).
    pub fn tokens(&self, atoms: &Atoms) -> TokenStream {
        let mut out = TokenStream::new();
        for (k, (ids, x)) in self.0.iter().enumerate() {
            let neg = *x < 0.0;
            let mag = x.abs();
            let mut factors: Vec<TokenStream> =
                ids.iter().map(|&i| atoms.tokens[i].clone()).collect();
            if mag != 1.0 || factors.is_empty() {
                // Coefficients are finite by construction (`Coef::number`, `Coef::mul`).
                let mag = if mag.is_finite() { mag } else { f64::NAN };
                factors.insert(0, f64_literal(mag));
            }
            let mut it = factors.into_iter();
            let mut term = it.next().unwrap_or_else(|| quote!(1.0));
            for f in it {
                term = quote!(#term * #f);
            }
            match (k, neg) {
                (0, false) => out.extend(term),
                (0, true) => out.extend(quote!(-#term)),
                (_, false) => out.extend(quote!(+ #term)),
                (_, true) => out.extend(quote!(- #term)),
            }
        }
        if self.0.is_empty() {
            out.extend(quote!(0.0));
        }
        out
    }

    /// Whether [`Coef::tokens`] needs parentheses as a factor.
    fn compound(&self) -> bool {
        self.0.len() > 1 || self.0.values().any(|x| *x < 0.0)
    }
}

impl Poly {
    fn constant(c: Coef) -> Poly {
        let mut m = BTreeMap::new();
        if !c.is_zero() {
            m.insert(Vec::new(), c);
        }
        Poly(m)
    }
    fn var(slot: usize) -> Poly {
        Poly(BTreeMap::from([(
            vec![(slot, 1)],
            Coef(BTreeMap::from([(Vec::new(), 1.0)])),
        )]))
    }
    /// The coefficient, if the polynomial is constant.
    fn as_constant(&self) -> Option<Coef> {
        match self.0.len() {
            0 => Some(Coef::zero()),
            1 => self.0.get(&Vec::new()).cloned(),
            _ => None,
        }
    }
    pub fn is_zero(&self) -> bool {
        self.0.is_empty()
    }
    pub fn add(&mut self, o: &Poly) -> Option<()> {
        for (m, c) in &o.0 {
            let e = self.0.entry(m.clone()).or_insert_with(Coef::zero);
            e.add(c)?;
            if e.is_zero() {
                self.0.remove(m);
            }
        }
        (self.0.len() <= MAX_MONOMIALS).then_some(())
    }
    /// `−p`.
    pub fn negated(&self) -> Option<Poly> {
        self.neg()
    }
    fn neg(&self) -> Option<Poly> {
        self.scale(&Coef::number(-1.0)?)
    }
    fn scale(&self, c: &Coef) -> Option<Poly> {
        let mut out = Poly::default();
        for (m, x) in &self.0 {
            out.add(&Poly(BTreeMap::from([(m.clone(), x.mul(c)?)])))?;
        }
        Some(out)
    }
    fn mul(&self, o: &Poly) -> Option<Poly> {
        let mut out = Poly::default();
        for (ma, ca) in &self.0 {
            for (mb, cb) in &o.0 {
                let m = mul_monomials(ma, mb);
                if degree(&m) > MAX_DEGREE {
                    return None;
                }
                out.add(&Poly(BTreeMap::from([(m, ca.mul(cb)?)])))?;
            }
        }
        Some(out)
    }
    /// `∂/∂(slot)`; `None` if a coefficient of the derivative overflows.
    pub fn diff(&self, slot: usize) -> Option<Poly> {
        let mut out = Poly::default();
        for (m, c) in &self.0 {
            let Some(pos) = m.iter().position(|&(s, _)| s == slot) else {
                continue;
            };
            let mut dm = m.clone();
            let e = dm.get(pos)?.1;
            if e == 1 {
                dm.remove(pos);
            } else if let Some(entry) = dm.get_mut(pos) {
                entry.1 = e - 1;
            }
            let dc = c.scale(f64::from(e))?;
            out.add(&Poly(BTreeMap::from([(dm, dc)])))?;
        }
        Some(out)
    }
    /// The variables (slots) that occur.
    pub fn slots(&self) -> std::collections::BTreeSet<usize> {
        self.0
            .keys()
            .flat_map(|m| m.iter().map(|&(s, _)| s))
            .collect()
    }
    /// Whether every derivative up to `order` has representable coefficients, so that the
    /// compile-time derivatives lose nothing.
    pub fn derivatives_ok(&self, order: u32) -> bool {
        if order == 0 {
            return true;
        }
        self.slots().into_iter().all(|s| match self.diff(s) {
            Some(d) => d.derivatives_ok(order - 1),
            None => false,
        })
    }
    /// The monomials.
    pub fn monomials(&self) -> impl Iterator<Item = &Monomial> {
        self.0.keys()
    }

    /// The polynomial as an `f64` expression; `var(slot)` gives a variable's tokens.
    pub fn tokens(&self, atoms: &Atoms, var: &dyn Fn(usize) -> TokenStream) -> TokenStream {
        let mut out = TokenStream::new();
        for (k, (m, c)) in self.0.iter().enumerate() {
            let mut factors: Vec<TokenStream> = Vec::new();
            for &(s, e) in m {
                for _ in 0..e {
                    factors.push(var(s));
                }
            }
            let (neg, c) = match c.as_number() {
                Some(x) if x < 0.0 => (true, Coef::number(-x).unwrap_or_else(Coef::zero)),
                _ => (false, c.clone()),
            };
            let is_one = c.as_number() == Some(1.0);
            if !is_one || factors.is_empty() {
                let ct = c.tokens(atoms);
                factors.insert(0, if c.compound() { quote!((#ct)) } else { ct });
            }
            let mut it = factors.into_iter();
            let mut term = it.next().unwrap_or_else(|| quote!(0.0));
            for f in it {
                term = quote!(#term * #f);
            }
            match (k, neg) {
                (0, false) => out.extend(term),
                (0, true) => out.extend(quote!(-#term)),
                (_, false) => out.extend(quote!(+ #term)),
                (_, true) => out.extend(quote!(- #term)),
            }
        }
        if self.0.is_empty() {
            out.extend(quote!(0.0));
        }
        out
    }
}

fn mul_monomials(a: &Monomial, b: &Monomial) -> Monomial {
    let mut m: BTreeMap<usize, u32> = a.iter().copied().collect();
    for &(s, e) in b {
        *m.entry(s).or_insert(0) += e;
    }
    m.into_iter().collect()
}

/// Total degree of a monomial.
pub fn degree(m: &Monomial) -> u32 {
    m.iter().map(|&(_, e)| e).sum()
}

/// A finite `f64` as an unsuffixed literal (`NaN` stays a valid token).
fn f64_literal(x: f64) -> TokenStream {
    if x.is_finite() {
        Literal::f64_unsuffixed(x).into_token_stream()
    } else {
        quote!(::core::primitive::f64::NAN)
    }
}
