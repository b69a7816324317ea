//! Symbolic polynomials in the model's variables, with coefficients built from the
//! parameters. A term of the Lagrangian or a force component that is a (small) polynomial is
//! differentiated here, at compile time, and the kernels get plain `f64` code for its
//! derivatives: a quadratic term has a constant Hessian, a linear force a constant Jacobian
//! (DESIGN §2, "Specialise"). Anything else falls back to dual numbers.
//!
//! Variables are numbered by slot: `q[s]` is slot `s`, `v[s]` is slot `n + s`.

use std::collections::{BTreeMap, HashMap};

use proc_macro2::{Literal, TokenStream};
use quote::{quote, ToTokens};
use syn::{BinOp, Expr, Lit, UnOp};

use crate::lower::Env;

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

/// Extracts polynomials from expressions of one model (literal number of coordinates).
pub struct Extractor<'a> {
    pub env: &'a Env,
    /// Total number of coordinates.
    pub n: usize,
    pub atoms: Atoms,
    /// The index variable of `force(q[i] = ...)` and its value.
    pub index: Option<(String, i64)>,
}

impl<'a> Extractor<'a> {
    /// The polynomial of `e`, or `None` if it is not one (or too large).
    pub fn poly(&mut self, e: &Expr) -> Option<Poly> {
        match e {
            Expr::Lit(l) => match &l.lit {
                Lit::Float(f) if f.suffix().is_empty() || f.suffix() == "f64" => {
                    Some(Poly::constant(Coef::number(f.base10_parse().ok()?)?))
                }
                Lit::Int(i) if i.suffix().is_empty() || i.suffix() == "f64" => {
                    let x: f64 = i.base10_digits().parse().ok()?;
                    Some(Poly::constant(Coef::number(x)?))
                }
                _ => None,
            },
            Expr::Path(p) => {
                let Some(ident) = p.path.get_ident().filter(|_| p.qself.is_none()) else {
                    let id = self.atoms.intern(quote!(#p));
                    return Some(Poly::constant(Coef::atom(id)));
                };
                let name = ident.to_string();
                if self.index.as_ref().is_some_and(|(i, _)| *i == name) {
                    return None;
                }
                for g in &self.env.groups {
                    if g.array {
                        continue;
                    }
                    if g.name == name {
                        return Some(Poly::var(g.offset));
                    }
                    if g.velocity == name {
                        return Some(Poly::var(self.n + g.offset));
                    }
                }
                if self.env.params.iter().any(|p| *p == name) {
                    let id = self.atoms.intern(quote!(#ident));
                    return Some(Poly::constant(Coef::atom(id)));
                }
                None
            }
            Expr::Paren(p) => self.poly(&p.expr),
            Expr::Group(g) => self.poly(&g.expr),
            Expr::Unary(u) => match u.op {
                UnOp::Neg(_) => self.poly(&u.expr)?.neg(),
                _ => None,
            },
            Expr::Binary(b) => {
                // Integer arithmetic (`3 / 2` is 1) is evaluated as the generated code does.
                if let Some(k) = self.int(e) {
                    return Some(Poly::constant(Coef::number(k as f64)?));
                }
                if self.int(&b.left).is_some() && self.int(&b.right).is_some() {
                    // Integer overflow or division by zero: leave it to the generated code.
                    return None;
                }
                let l = self.poly(&b.left)?;
                let r = self.poly(&b.right)?;
                match b.op {
                    BinOp::Add(_) => {
                        let mut out = l;
                        out.add(&r)?;
                        Some(out)
                    }
                    BinOp::Sub(_) => {
                        let mut out = l;
                        out.add(&r.neg()?)?;
                        Some(out)
                    }
                    BinOp::Mul(_) => l.mul(&r),
                    BinOp::Div(_) => {
                        let c = r.as_constant()?;
                        let inv = match c.as_number() {
                            Some(x) if x != 0.0 && (1.0 / x).is_normal() => Coef::number(1.0 / x)?,
                            Some(_) => return None,
                            None => {
                                let right = &b.right;
                                self.opaque(quote!((1.0 / (#right))))?
                            }
                        };
                        l.scale(&inv)
                    }
                    _ => None,
                }
            }
            Expr::MethodCall(m) => {
                let recv = self.poly(&m.receiver)?;
                if m.method == "powi" && m.args.len() == 1 {
                    let n = self.int(m.args.first()?)?;
                    let n = u32::try_from(n).ok().filter(|&n| n <= MAX_DEGREE)?;
                    let mut out = Poly::constant(Coef::number(1.0)?);
                    for _ in 0..n {
                        out = out.mul(&recv)?;
                    }
                    return Some(out);
                }
                recv.as_constant()?;
                for a in &m.args {
                    if !matches!(a, Expr::Lit(_)) {
                        self.poly(a)?.as_constant()?;
                    }
                }
                Some(Poly::constant(self.opaque(quote!(#m))?))
            }
            Expr::Index(i) => {
                let Expr::Path(p) = &*i.expr else {
                    return None;
                };
                let ident = p.path.get_ident()?;
                let k = usize::try_from(self.int(&i.index)?).ok()?;
                for g in &self.env.groups {
                    let len = g.len.literal()?;
                    if !g.array || k >= len {
                        continue;
                    }
                    if g.name == *ident {
                        return Some(Poly::var(g.offset + k));
                    }
                    if g.velocity == *ident {
                        return Some(Poly::var(self.n + g.offset + k));
                    }
                }
                None
            }
            Expr::Cast(c) => {
                let is_float = matches!(&*c.ty, syn::Type::Path(p) if p.path.is_ident("f64"));
                if !is_float {
                    return None;
                }
                let k = self.int(&c.expr)?;
                Some(Poly::constant(Coef::number(k as f64)?))
            }
            _ => None,
        }
    }

    /// An opaque constant; `None` if it mentions the index variable (not bound in kernels).
    fn opaque(&mut self, t: TokenStream) -> Option<Coef> {
        if let Some((i, _)) = &self.index {
            if mentions(&t, i) {
                return None;
            }
        }
        // The user's tokens are emitted as `f64` code: an integer literal there (other
        // than a `powi` exponent) would not type-check; the dual path converts it.
        if has_bare_int(&t) {
            return None;
        }
        Some(Coef::atom(self.atoms.intern(t)))
    }

    /// A compile-time integer: literals, the index variable, `+ - *`.
    fn int(&self, e: &Expr) -> Option<i64> {
        match e {
            Expr::Lit(l) => match &l.lit {
                Lit::Int(i)
                    if i.suffix().is_empty() || i.suffix() == "usize" || i.suffix() == "i32" =>
                {
                    i.base10_parse().ok()
                }
                _ => None,
            },
            Expr::Path(p) => {
                let (name, value) = self.index.as_ref()?;
                p.path.is_ident(name).then_some(*value)
            }
            Expr::Paren(p) => self.int(&p.expr),
            Expr::Binary(b) => {
                let (l, r) = (self.int(&b.left)?, self.int(&b.right)?);
                match b.op {
                    BinOp::Add(_) => l.checked_add(r),
                    BinOp::Sub(_) => l.checked_sub(r),
                    BinOp::Mul(_) => l.checked_mul(r),
                    BinOp::Div(_) => l.checked_div(r),
                    BinOp::Rem(_) => l.checked_rem(r),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

/// A finite `f64` as an unsuffixed literal (`NaN` stays a valid token).
fn f64_literal(x: f64) -> TokenStream {
    if x.is_finite() {
        Literal::f64_unsuffixed(x).into_token_stream()
    } else {
        quote!(::core::primitive::f64::NAN)
    }
}

/// Whether `t` has an integer literal other than the argument of `powi(...)`.
fn has_bare_int(t: &TokenStream) -> bool {
    let mut prev_powi = false;
    for tt in t.clone() {
        let this_powi = matches!(&tt, proc_macro2::TokenTree::Ident(i) if i == "powi");
        match &tt {
            proc_macro2::TokenTree::Literal(l) => {
                let s = l.to_string();
                let float = s.contains('.')
                    || s.ends_with("f64")
                    || ((s.contains('e') || s.contains('E')) && !s.starts_with("0x"));
                if !float {
                    return true;
                }
            }
            proc_macro2::TokenTree::Group(g) => {
                let is_exponent =
                    prev_powi && g.delimiter() == proc_macro2::Delimiter::Parenthesis && {
                        let inner: Vec<_> = g.stream().into_iter().collect();
                        inner.len() == 1
                            && matches!(inner.first(), Some(proc_macro2::TokenTree::Literal(_)))
                    };
                if !is_exponent && has_bare_int(&g.stream()) {
                    return true;
                }
            }
            _ => {}
        }
        prev_powi = this_powi;
    }
    false
}

fn mentions(t: &TokenStream, name: &str) -> bool {
    t.clone().into_iter().any(|tt| match tt {
        proc_macro2::TokenTree::Ident(i) => i == name,
        proc_macro2::TokenTree::Group(g) => mentions(&g.stream(), name),
        _ => false,
    })
}
