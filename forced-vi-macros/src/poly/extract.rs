//! The extraction of polynomials from the model's expressions: numbers, coordinates and
//! velocities (scalar, or array entries at a compile-time index), parameters and other
//! constants (as opaque atoms), `+ - *`, division by a constant and `powi`.

use proc_macro2::TokenStream;
use quote::quote;
use syn::{BinOp, Expr, Lit, UnOp};

use super::{Atoms, Coef, Poly, MAX_DEGREE};
use crate::lower::Env;

/// Extracts polynomials from expressions of one model (literal number of coordinates).
pub struct Extractor<'a> {
    pub env: &'a Env,
    /// Total number of coordinates.
    pub n: usize,
    pub atoms: Atoms,
    /// The index variable of `force(q[i] = ...)` and its value.
    pub index: Option<(String, i64)>,
}

impl Extractor<'_> {
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
            Expr::Path(p) => self.path(p),
            Expr::Paren(p) => self.poly(&p.expr),
            Expr::Group(g) => self.poly(&g.expr),
            Expr::Unary(u) => match u.op {
                UnOp::Neg(_) => self.poly(&u.expr)?.neg(),
                _ => None,
            },
            Expr::Binary(b) => self.binary(e, b),
            Expr::MethodCall(m) => self.method(m),
            Expr::Index(i) => self.index(i),
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

    /// A name: a scalar coordinate or velocity, or a parameter (an atom); a path such as
    /// `std::f64::consts::PI` is an atom too.
    fn path(&mut self, p: &syn::ExprPath) -> Option<Poly> {
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

    /// `l + r`, `l - r`, `l * r` and `l / c` (`e` is the whole expression).
    fn binary(&mut self, e: &Expr, b: &syn::ExprBinary) -> Option<Poly> {
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
            BinOp::Mul(_) => {
                if cancels(&l, &r) {
                    return None;
                }
                l.mul(&r)
            }
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

    /// `p.powi(n)` with a compile-time `n`, or a method of constants (an atom).
    fn method(&mut self, m: &syn::ExprMethodCall) -> Option<Poly> {
        let recv = self.poly(&m.receiver)?;
        if m.method == "powi" && m.args.len() == 1 {
            let n = self.int(m.args.first()?)?;
            let n = u32::try_from(n).ok().filter(|&n| n <= MAX_DEGREE)?;
            let mut out = Poly::constant(Coef::number(1.0)?);
            for _ in 0..n {
                if cancels(&out, &recv) {
                    return None;
                }
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

    /// `q[k]` (or `q_dot[k]`) at a compile-time index `k` in range.
    fn index(&mut self, i: &syn::ExprIndex) -> Option<Poly> {
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
        self.int_typed(e).map(|(v, _)| v)
    }

    /// An integer expression's value, and whether it involves a `usize` (a suffixed literal,
    /// or a force entry's index). A `usize` expression whose value, or a part's, would be
    /// negative wraps in the model's own code (`1usize - 3` is 2⁶⁴ − 2 there): it is left
    /// to the general kernels, which evaluate that code, rather than taken as −2.
    fn int_typed(&self, e: &Expr) -> Option<(i64, bool)> {
        match e {
            Expr::Lit(l) => match &l.lit {
                Lit::Int(i)
                    if i.suffix().is_empty() || i.suffix() == "usize" || i.suffix() == "i32" =>
                {
                    // An unsuffixed literal is an `i32` (its default type) in the model's
                    // own code: arithmetic is folded at that type, or not at all.
                    let v: i64 = i.base10_parse().ok()?;
                    let unsigned = i.suffix() == "usize";
                    fits(v, unsigned).then_some((v, unsigned))
                }
                _ => None,
            },
            Expr::Path(p) => {
                let (name, value) = self.index.as_ref()?;
                p.path.is_ident(name).then_some((*value, true))
            }
            Expr::Paren(p) => self.int_typed(&p.expr),
            Expr::Binary(b) => {
                let ((l, lu), (r, ru)) = (self.int_typed(&b.left)?, self.int_typed(&b.right)?);
                let v = match b.op {
                    BinOp::Add(_) => l.checked_add(r),
                    BinOp::Sub(_) => l.checked_sub(r),
                    BinOp::Mul(_) => l.checked_mul(r),
                    BinOp::Div(_) => l.checked_div(r),
                    BinOp::Rem(_) => l.checked_rem(r),
                    _ => None,
                }?;
                let unsigned = lu || ru;
                fits(v, unsigned).then_some((v, unsigned))
            }
            _ => None,
        }
    }
}

/// Whether the expanded product `a * b` may cancel catastrophically: a sum (or difference)
/// multiplied into a product of degree 3 or more, as `(x - c).powi(4)` or
/// `x * (x - c).powi(2)`, whose monomials are large where the value (and its derivatives)
/// are small (at `x ≈ c`).
/// Such a product is left to the dual-number kernels, which evaluate the user's form.
/// (Up to degree 2 the derivatives of the expansion, linear or constant, are as accurate as
/// the user's form.)
fn cancels(a: &Poly, b: &Poly) -> bool {
    let deg = |p: &Poly| p.monomials().map(super::degree).max().unwrap_or(0);
    let sum = |p: &Poly| p.0.len() >= 2;
    if deg(a) + deg(b) < 3 {
        return false;
    }
    // Two sums (`(x - c) * (y - d) * (z - e)`), or a sum times a factor in its own
    // variables (a power). A sum times a monomial in other variables (`(eps - x * x) *
    // x_dot`) only distributes: its derivatives are the user's form.
    let shared = !a.slots().is_disjoint(&b.slots());
    (sum(a) && sum(b)) || ((sum(a) || sum(b)) && shared)
}

/// Whether `v` is a value of the type the model's code computes it in: `usize` (no wrap
/// below zero), else `i32` (the default of unsuffixed literals; a value beyond it wraps
/// there, so it is not folded here).
fn fits(v: i64, unsigned: bool) -> bool {
    if unsigned {
        v >= 0
    } else {
        i32::try_from(v).is_ok()
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
