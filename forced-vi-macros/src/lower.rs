//! Walks a user expression (the Lagrangian, a term of it, or a force component) once and
//! returns three things together:
//!
//! - the *kind* of every sub-expression: an `f64` constant (parameters and literals), a
//!   dual-valued quantity (anything that depends on a coordinate or velocity), an integer
//!   (indices), and so on;
//! - the expression rewritten for the generic scalar `__D`: num-dual implements `D ∘ f64` but
//!   not `f64 ∘ D`, so `c * x` becomes `x * c`, `c - x` becomes `-x + c`, `c / x` becomes
//!   `__D::from(c) / x`, and `let mut s = 0.0` (an accumulator) becomes a `__D`;
//! - what the expression *uses* (which coordinate and velocity slots, which names) and its
//!   polynomial *degree* in `q` and in `v`, which drive the specialisation.
//!
//! Names are resolved here too, so an unknown identifier is reported at its own token.
//!
//! Room for time-dependent forcing `F(t, q, v)`: time would be one more resolvable name
//! (a dual-valued variable with its own [`Var`] flavour and degree), bound from a `t`
//! argument of the generated force helpers; the uses/degree analysis and the kernels' slot
//! machinery need no other change, and a force that does not name `t` keeps today's code.

use std::collections::{BTreeSet, HashMap};

use proc_macro2::{Span, TokenStream};
use quote::{quote, quote_spanned, ToTokens};
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Ident, Lit, Pat, Stmt, UnOp};

use crate::ctxt::Ctxt;

/// The number of coordinates of an array group (or of the model).
#[derive(Clone)]
pub enum Len {
    /// An integer literal.
    Lit(usize),
    /// A const parameter of the struct.
    Param(Ident),
}

impl Len {
    pub fn literal(&self) -> Option<usize> {
        match self {
            Len::Lit(n) => Some(*n),
            Len::Param(_) => None,
        }
    }
}

impl ToTokens for Len {
    fn to_tokens(&self, tokens: &mut TokenStream) {
        match self {
            Len::Lit(n) => proc_macro2::Literal::usize_unsuffixed(*n).to_tokens(tokens),
            Len::Param(p) => p.to_tokens(tokens),
        }
    }
}

/// A checked coordinate declaration: `x` (scalar) or `q: [f64; L]` (array).
pub struct Group {
    pub name: Ident,
    pub velocity: Ident,
    /// Index of the group's first coordinate in `q`.
    pub offset: usize,
    pub len: Len,
    pub array: bool,
}

/// What expressions may refer to.
pub struct Env {
    pub groups: Vec<Group>,
    pub params: Vec<Ident>,
    /// Const parameters of the struct (usable as integers, e.g. as an array length).
    pub const_params: Vec<Ident>,
    /// The struct's name, for messages.
    pub model: Ident,
}

/// Which coordinates of a group a use touches.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub enum Idx {
    At(usize),
    All,
}

/// A use of a coordinate (`vel == false`) or a velocity.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub struct Var {
    pub vel: bool,
    pub group: usize,
    pub idx: Idx,
}

/// Polynomial degree in one set of variables; `None` is "not a polynomial".
pub type Deg = Option<u32>;

/// Degrees in `q` and in `v`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Degree {
    pub q: Deg,
    pub v: Deg,
}

impl Degree {
    pub const CONST: Degree = Degree {
        q: Some(0),
        v: Some(0),
    };
    fn max(self, o: Degree) -> Degree {
        let m = |a: Deg, b: Deg| Some(a?.max(b?));
        Degree {
            q: m(self.q, o.q),
            v: m(self.v, o.v),
        }
    }
    fn add(self, o: Degree) -> Degree {
        let s = |a: Deg, b: Deg| Some(a? + b?);
        Degree {
            q: s(self.q, o.q),
            v: s(self.v, o.v),
        }
    }
    /// Not polynomial in whatever the operands depend on.
    fn opaque(self) -> Degree {
        let o = |a: Deg| if a == Some(0) { Some(0) } else { None };
        Degree {
            q: o(self.q),
            v: o(self.v),
        }
    }
    fn times(self, n: u32) -> Degree {
        Degree {
            q: self.q.map(|d| d * n),
            v: self.v.map(|d| d * n),
        }
    }
}

/// The kind of a sub-expression in generated code.
#[derive(Clone, PartialEq, Debug)]
pub enum Kind {
    /// `f64`: literals, parameters, and anything built from them.
    Real,
    /// The generic scalar `__D`.
    Dual,
    /// An integer (index, length, loop variable).
    Int,
    Bool,
    /// An array coordinate or velocity (group index).
    Array(usize),
    /// An iterator over items of the kind.
    Iter(Box<Kind>),
    Unit,
}

/// The result of lowering one expression.
#[derive(Clone)]
pub struct Lowered {
    pub tokens: TokenStream,
    pub kind: Kind,
    pub uses: BTreeSet<Var>,
    /// The model names (coordinates, velocities, parameters) referred to.
    pub names: BTreeSet<String>,
    pub degree: Degree,
    /// A compile-time integer value, if known.
    pub int: Option<i64>,
    /// Needs no parentheses as an operand.
    pub atomic: bool,
}

impl Lowered {
    fn new(tokens: TokenStream, kind: Kind) -> Lowered {
        Lowered {
            tokens,
            kind,
            uses: BTreeSet::new(),
            names: BTreeSet::new(),
            degree: Degree::CONST,
            int: None,
            atomic: true,
        }
    }
    fn absorb(&mut self, o: &Lowered) {
        self.uses.extend(o.uses.iter().copied());
        self.names.extend(o.names.iter().cloned());
    }
    /// The tokens, in parentheses unless atomic.
    fn operand(&self) -> TokenStream {
        let t = &self.tokens;
        if self.atomic {
            t.clone()
        } else {
            quote!((#t))
        }
    }
    /// The tokens as a `__D` (wrapping an `f64`).
    pub fn as_dual(&self, span: Span) -> TokenStream {
        let t = &self.tokens;
        match self.kind {
            Kind::Dual => t.clone(),
            _ => quote_spanned!(span=> __D::from(#t)),
        }
    }
}

#[derive(Clone)]
struct Local {
    kind: Kind,
    uses: BTreeSet<Var>,
    names: BTreeSet<String>,
    degree: Degree,
    int: Option<i64>,
}

/// The name of the generic scalar in generated code.
pub fn dual_ident() -> Ident {
    Ident::new("__D", Span::call_site())
}

/// Lowers expressions against an [`Env`].
pub struct Lowerer<'a> {
    cx: &'a Ctxt,
    env: &'a Env,
    scopes: Vec<HashMap<String, Local>>,
    /// Where the expression is, for messages: "the Lagrangian", "the force on `x`".
    place: String,
}

const UNSUPPORTED: &str = "is not supported in a model expression; use arithmetic, method calls such as `sin()` or `powi(2)`, `let`, `if`, `for` loops over ranges, and `(a..b).map(|i| ...).sum()`";

impl<'a> Lowerer<'a> {
    pub fn new(cx: &'a Ctxt, env: &'a Env, place: impl Into<String>) -> Lowerer<'a> {
        Lowerer {
            cx,
            env,
            scopes: vec![HashMap::new()],
            place: place.into(),
        }
    }

    /// Binds an integer (the index variable `i` of `force(q[i] = ...)`), with a known value
    /// or not.
    pub fn bind_index(&mut self, name: &Ident, value: Option<i64>) {
        self.bind(
            name,
            Local {
                kind: Kind::Int,
                uses: BTreeSet::new(),
                names: BTreeSet::new(),
                degree: Degree::CONST,
                int: value,
            },
        );
    }

    fn bind(&mut self, name: &Ident, local: Local) {
        if let Some(scope) = self.scopes.last_mut() {
            scope.insert(name.to_string(), local);
        }
    }

    fn lookup_mut(&mut self, name: &str) -> Option<&mut Local> {
        self.scopes.iter_mut().rev().find_map(|s| s.get_mut(name))
    }

    fn unsupported(&self, tokens: impl ToTokens, what: &str) -> Lowered {
        self.cx
            .error_spanned_by(tokens, format!("{what} {UNSUPPORTED}"));
        Lowered::new(TokenStream::new(), Kind::Real)
    }

    /// Lowers an expression.
    pub fn expr(&mut self, e: &Expr) -> Lowered {
        match e {
            Expr::Lit(lit) => self.lit(&lit.lit),
            Expr::Path(p) => self.path(p),
            Expr::Paren(p) => {
                let inner = self.expr(&p.expr);
                let t = &inner.tokens;
                let mut out = inner.clone();
                out.tokens = quote_spanned!(p.paren_token.span.join()=> (#t));
                out.atomic = true;
                out
            }
            Expr::Group(g) => {
                let inner = self.expr(&g.expr);
                let mut out = inner.clone();
                out.tokens = inner.operand();
                out.atomic = true;
                out
            }
            Expr::Unary(u) => self.unary(u),
            Expr::Binary(b) => self.binary(b),
            Expr::Assign(a) => self.assign(&a.left, None, &a.right, e),
            Expr::MethodCall(m) => self.method(m),
            Expr::Call(c) => self.call(c),
            Expr::Index(i) => self.index(i),
            Expr::Cast(c) => self.cast(c),
            Expr::Block(b) => {
                if b.label.is_some() {
                    return self.unsupported(e, "a labelled block");
                }
                self.block(&b.block, false)
            }
            Expr::If(i) => self.if_expr(i),
            Expr::ForLoop(f) => self.for_loop(f),
            Expr::Range(r) => self.range(r),
            Expr::Closure(c) => self.unsupported(c, "a closure outside `.map(...)`"),
            Expr::Macro(m) => self.unsupported(m, "a macro call"),
            Expr::Return(r) => self.unsupported(r, "`return`"),
            other => self.unsupported(other, "this expression"),
        }
    }

    fn lit(&mut self, lit: &Lit) -> Lowered {
        match lit {
            Lit::Float(_) => Lowered::new(lit.to_token_stream(), Kind::Real),
            Lit::Int(i) => {
                let mut l = Lowered::new(lit.to_token_stream(), Kind::Int);
                if i.suffix() == "f64" || i.suffix() == "f32" {
                    l.kind = Kind::Real;
                } else {
                    l.int = i.base10_parse::<i64>().ok();
                }
                l
            }
            Lit::Bool(_) => Lowered::new(lit.to_token_stream(), Kind::Bool),
            other => self.unsupported(other, "this literal"),
        }
    }

    fn path(&mut self, p: &syn::ExprPath) -> Lowered {
        let tokens = p.to_token_stream();
        let Some(ident) = p.path.get_ident().filter(|_| p.qself.is_none()) else {
            // A path such as `std::f64::consts::PI` or `f64::EPSILON`: a constant.
            return Lowered::new(tokens, Kind::Real);
        };
        let name = ident.to_string();
        if let Some(local) = self.scopes.iter().rev().find_map(|s| s.get(&name)) {
            let mut l = Lowered::new(tokens, local.kind.clone());
            l.uses = local.uses.clone();
            l.names = local.names.clone();
            l.degree = local.degree;
            l.int = local.int;
            return l;
        }
        for (g, group) in self.env.groups.iter().enumerate() {
            for (vel, gname) in [(false, &group.name), (true, &group.velocity)] {
                if *gname == name {
                    let mut l = if group.array {
                        Lowered::new(tokens.clone(), Kind::Array(g))
                    } else {
                        let mut l = Lowered::new(tokens.clone(), Kind::Dual);
                        l.uses.insert(Var {
                            vel,
                            group: g,
                            idx: Idx::At(0),
                        });
                        l.degree = if vel {
                            Degree {
                                q: Some(0),
                                v: Some(1),
                            }
                        } else {
                            Degree {
                                q: Some(1),
                                v: Some(0),
                            }
                        };
                        l
                    };
                    l.names.insert(name.clone());
                    return l;
                }
            }
        }
        if self.env.params.iter().any(|p| *p == name) {
            let mut l = Lowered::new(tokens, Kind::Real);
            l.names.insert(name);
            return l;
        }
        if self.env.const_params.iter().any(|p| *p == name) {
            return Lowered::new(tokens, Kind::Int);
        }
        let hint = if name == "self" {
            "; parameters are written by name, without `self.`".to_string()
        } else if name.len() > 1
            && name
                .chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
        {
            format!("; a constant from outside the model is written with its path, as in `self::{name}` or `crate::{name}`")
        } else if let Some(stem) = name.strip_suffix("_dot") {
            format!("; `{stem}` is not a coordinate")
        } else {
            String::new()
        };
        self.cx.error_spanned_by(
            ident,
            format!(
                "unknown name `{name}` in {}: not a coordinate, velocity or parameter of `{}`{hint}",
                self.place, self.env.model
            ),
        );
        Lowered::new(tokens, Kind::Real)
    }

    fn unary(&mut self, u: &syn::ExprUnary) -> Lowered {
        let inner = self.expr(&u.expr);
        let op = &u.op;
        let mut out = inner.clone();
        match u.op {
            UnOp::Neg(_) => {
                out.int = inner.int.map(|i| -i);
            }
            UnOp::Not(_) => {
                out.kind = Kind::Bool;
                out.degree = inner.degree.opaque();
            }
            _ => return self.unsupported(u, "dereferencing"),
        }
        let t = inner.operand();
        out.tokens = quote!(#op #t);
        out.atomic = false;
        out
    }

    fn binary(&mut self, b: &syn::ExprBinary) -> Lowered {
        match b.op {
            BinOp::AddAssign(_)
            | BinOp::SubAssign(_)
            | BinOp::MulAssign(_)
            | BinOp::DivAssign(_) => {
                return self.assign(&b.left, Some(&b.op), &b.right, &Expr::Binary(b.clone()))
            }
            BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_) | BinOp::Div(_) | BinOp::Rem(_) => {}
            BinOp::Eq(_)
            | BinOp::Lt(_)
            | BinOp::Le(_)
            | BinOp::Ne(_)
            | BinOp::Ge(_)
            | BinOp::Gt(_)
            | BinOp::And(_)
            | BinOp::Or(_) => return self.compare(b),
            _ => return self.unsupported(b.op, "this operator"),
        }
        let l = self.expr(&b.left);
        let r = self.expr(&b.right);
        let op = &b.op;
        let span = b.span();
        let mut out = Lowered::new(TokenStream::new(), Kind::Real);
        out.absorb(&l);
        out.absorb(&r);
        out.atomic = false;
        out.kind = match (&l.kind, &r.kind) {
            (Kind::Dual, _) | (_, Kind::Dual) => Kind::Dual,
            (Kind::Int, Kind::Int) => Kind::Int,
            _ => Kind::Real,
        };
        out.degree = match b.op {
            BinOp::Add(_) | BinOp::Sub(_) => l.degree.max(r.degree),
            BinOp::Mul(_) => l.degree.add(r.degree),
            BinOp::Div(_) => {
                if r.degree == Degree::CONST {
                    l.degree
                } else {
                    l.degree.max(r.degree).opaque()
                }
            }
            _ => l.degree.max(r.degree).opaque(),
        };
        if out.kind == Kind::Int {
            out.int = match (l.int, r.int, b.op) {
                (Some(x), Some(y), BinOp::Add(_)) => x.checked_add(y),
                (Some(x), Some(y), BinOp::Sub(_)) => x.checked_sub(y),
                (Some(x), Some(y), BinOp::Mul(_)) => x.checked_mul(y),
                (Some(x), Some(y), BinOp::Div(_)) => x.checked_div(y),
                (Some(x), Some(y), BinOp::Rem(_)) => x.checked_rem(y),
                _ => None,
            };
        }
        let (lt, rt) = (&l.tokens, &r.tokens);
        let real_left = l.kind == Kind::Real || l.kind == Kind::Int;
        out.tokens = if real_left && r.kind == Kind::Dual {
            // num-dual has `D ∘ f64` only: put the dual operand first.
            let (lo, ro) = (l.operand(), r.operand());
            match b.op {
                BinOp::Add(_) => quote!(#rt + #lo),
                BinOp::Mul(_) => quote!(#ro * #lo),
                BinOp::Sub(_) => quote_spanned!(span=> -#ro + #lo),
                _ => {
                    let ld = l.as_dual(span);
                    quote!(#ld #op #ro)
                }
            }
        } else {
            quote!(#lt #op #rt)
        };
        // Keep operator precedence: the swapped forms above parenthesise their operands,
        // and the direct form keeps the user's own parentheses.
        out
    }

    fn compare(&mut self, b: &syn::ExprBinary) -> Lowered {
        let l = self.expr(&b.left);
        let r = self.expr(&b.right);
        let op = &b.op;
        let mut out = Lowered::new(TokenStream::new(), Kind::Bool);
        out.absorb(&l);
        out.absorb(&r);
        out.degree = l.degree.max(r.degree).opaque();
        out.atomic = false;
        let rt = &r.tokens;
        out.tokens = if (l.kind == Kind::Real) && r.kind == Kind::Dual {
            let ld = l.as_dual(b.left.span());
            quote!(#ld #op #rt)
        } else {
            let lt = &l.tokens;
            quote!(#lt #op #rt)
        };
        out
    }

    /// `x = e`, `x += e`, ... on a local.
    fn assign(&mut self, left: &Expr, op: Option<&BinOp>, right: &Expr, whole: &Expr) -> Lowered {
        let Expr::Path(p) = left else {
            return self.unsupported(left, "assigning to anything but a local variable");
        };
        let Some(ident) = p.path.get_ident() else {
            return self.unsupported(left, "assigning to a path");
        };
        let r = self.expr(right);
        let name = ident.to_string();
        let Some(local) = self.lookup_mut(&name) else {
            self.cx.error_spanned_by(
                ident,
                format!(
                    "`{name}` is not a local variable; only `let mut` variables can be assigned"
                ),
            );
            return Lowered::new(TokenStream::new(), Kind::Unit);
        };
        local.uses.extend(r.uses.iter().copied());
        local.names.extend(r.names.iter().cloned());
        local.int = None;
        local.degree = match op {
            None | Some(BinOp::AddAssign(_)) | Some(BinOp::SubAssign(_)) => {
                local.degree.max(r.degree)
            }
            Some(BinOp::DivAssign(_)) if r.degree == Degree::CONST => local.degree,
            _ => local.degree.max(r.degree).opaque(),
        };
        let lkind = local.kind.clone();
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&r);
        out.atomic = false;
        let rt = if lkind == Kind::Dual && op.is_none() {
            r.as_dual(right.span())
        } else {
            r.tokens.clone()
        };
        let _ = whole;
        out.tokens = match op {
            Some(op) => quote!(#ident #op #rt),
            None => quote!(#ident = #rt),
        };
        out
    }

    fn method(&mut self, m: &syn::ExprMethodCall) -> Lowered {
        let recv = self.expr(&m.receiver);
        let name = m.method.to_string();
        let method = &m.method;
        let rt = recv.operand();
        if m.turbofish.is_some() {
            return self.unsupported(m, "a turbofish");
        }
        match &recv.kind {
            Kind::Array(g) => {
                if name == "len" && m.args.is_empty() {
                    let mut out = Lowered::new(quote!(#rt.#method()), Kind::Int);
                    out.int = self.env.groups[*g]
                        .len
                        .literal()
                        .and_then(|n| i64::try_from(n).ok());
                    return out;
                }
                self.unsupported(
                    m,
                    "a method on a coordinate array (index it instead, as in `q[i]`, or use `.len()`)",
                )
            }
            Kind::Iter(item) => self.iter_method(m, recv.clone(), (**item).clone()),
            Kind::Dual | Kind::Real | Kind::Int => {
                let mut out = recv.clone();
                out.atomic = true;
                let mut args = Vec::new();
                let mut all_const = recv.degree == Degree::CONST;
                let mut method = method.clone();
                for a in &m.args {
                    let la = self.expr(a);
                    out.absorb(&la);
                    all_const &= la.degree == Degree::CONST;
                    out.degree = out.degree.max(la.degree);
                    args.push(la);
                }
                if recv.kind == Kind::Dual {
                    match name.as_str() {
                        "re" => out.kind = Kind::Real,
                        "powf" if args.first().is_some_and(|a| a.kind == Kind::Dual) => {
                            method = Ident::new("powd", m.method.span());
                        }
                        _ => {}
                    }
                    // Methods whose arguments are `Self` in DualNum.
                    if matches!(name.as_str(), "mul_add" | "powd" | "atan2") {
                        for (a, orig) in args.iter_mut().zip(&m.args) {
                            a.tokens = a.as_dual(orig.span());
                            a.kind = Kind::Dual;
                        }
                    }
                } else if args.iter().any(|a| a.kind == Kind::Dual) && recv.kind == Kind::Real {
                    // `c.powf(x)` with a dual `x`, `c.max(x)` ...: lift the receiver.
                    out.kind = Kind::Dual;
                }
                let powi = (name == "powi")
                    .then(|| args.first().and_then(|a| a.int))
                    .flatten()
                    .and_then(|n| u32::try_from(n).ok());
                out.degree = match powi {
                    Some(n) if args.len() == 1 => recv.degree.times(n),
                    _ if all_const => Degree::CONST,
                    _ => out.degree.opaque(),
                };
                if out.kind == Kind::Dual && recv.kind == Kind::Real {
                    let rd = recv.as_dual(m.receiver.span());
                    let at = args.iter().map(|a| &a.tokens);
                    out.tokens = quote!(#rd.#method(#(#at),*));
                } else {
                    let at = args.iter().map(|a| &a.tokens);
                    out.tokens = quote!(#rt.#method(#(#at),*));
                }
                out.int = None;
                out
            }
            _ => self.unsupported(m, "this method call"),
        }
    }

    fn iter_method(&mut self, m: &syn::ExprMethodCall, recv: Lowered, item: Kind) -> Lowered {
        let name = m.method.to_string();
        let method = &m.method;
        let rt = recv.operand();
        let mut out = recv.clone();
        out.atomic = true;
        out.int = None;
        match name.as_str() {
            "map" => {
                let Some(Expr::Closure(c)) = m.args.first().filter(|_| m.args.len() == 1) else {
                    return self.unsupported(m, "`.map` without a one-argument closure");
                };
                let (Some(pat), 1) = (c.inputs.first(), c.inputs.len()) else {
                    return self.unsupported(c, "a closure with other than one argument");
                };
                let Some(ident) = pat_ident(pat) else {
                    return self.unsupported(pat, "this closure argument");
                };
                self.scopes.push(HashMap::new());
                self.bind(
                    ident,
                    Local {
                        kind: item,
                        uses: recv.uses.clone(),
                        names: BTreeSet::new(),
                        degree: Degree::CONST,
                        int: None,
                    },
                );
                let body = self.expr(&c.body);
                self.scopes.pop();
                out.absorb(&body);
                out.degree = out.degree.max(body.degree);
                out.kind = Kind::Iter(Box::new(body.kind.clone()));
                let bt = &body.tokens;
                let inputs = &c.inputs;
                out.tokens = quote!(#rt.#method(|#inputs| #bt));
            }
            "sum" | "product" if m.args.is_empty() => {
                let ty = match item {
                    Kind::Dual => quote!(__D),
                    Kind::Real => quote!(f64),
                    Kind::Int => quote!(usize),
                    _ => return self.unsupported(m, "this sum"),
                };
                if name == "product" {
                    out.degree = out.degree.opaque();
                }
                out.kind = item;
                out.tokens = quote!(#rt.#method::<#ty>());
            }
            "rev" | "step_by" | "skip" | "take" => {
                let mut args = Vec::new();
                for a in &m.args {
                    let la = self.expr(a);
                    out.absorb(&la);
                    args.push(la.tokens);
                }
                out.tokens = quote!(#rt.#method(#(#args),*));
            }
            _ => return self.unsupported(m, "this iterator method"),
        }
        out
    }

    fn call(&mut self, c: &syn::ExprCall) -> Lowered {
        let Expr::Path(func) = &*c.func else {
            return self.unsupported(&c.func, "calling this");
        };
        let mut out = Lowered::new(TokenStream::new(), Kind::Real);
        let mut args = Vec::new();
        let mut degree = Degree::CONST;
        for a in &c.args {
            let la = self.expr(a);
            out.absorb(&la);
            degree = degree.max(la.degree);
            if la.kind == Kind::Dual {
                out.kind = Kind::Dual;
            }
            args.push(la.tokens);
        }
        out.degree = degree.opaque();
        out.tokens = quote!(#func(#(#args),*));
        out
    }

    fn index(&mut self, i: &syn::ExprIndex) -> Lowered {
        let base = self.expr(&i.expr);
        let Kind::Array(g) = base.kind else {
            return self.unsupported(i, "indexing anything but a coordinate array");
        };
        let idx = self.expr(&i.index);
        let group = &self.env.groups[g];
        let velocity = group.velocity.to_string();
        let vel = base.names.contains(&velocity);
        let at = match (idx.int, group.len.literal()) {
            (Some(k), Some(len)) => match usize::try_from(k).ok().filter(|&k| k < len) {
                Some(k) => Idx::At(k),
                None => {
                    let name = if vel { &group.velocity } else { &group.name };
                    self.cx.error_spanned_by(
                        &i.index,
                        format!(
                            "index {k} is out of range: `{name}` has {len} entries (`{}: [f64; {len}]`)",
                            group.name
                        ),
                    );
                    Idx::All
                }
            },
            (Some(k), None) => usize::try_from(k).map(Idx::At).unwrap_or(Idx::All),
            (None, _) => Idx::All,
        };
        let mut out = Lowered::new(TokenStream::new(), Kind::Dual);
        out.absorb(&base);
        out.absorb(&idx);
        out.uses.insert(Var {
            vel,
            group: g,
            idx: at,
        });
        out.degree = if vel {
            Degree {
                q: Some(0),
                v: Some(1),
            }
        } else {
            Degree {
                q: Some(1),
                v: Some(0),
            }
        };
        let (bt, it) = (&base.tokens, &idx.tokens);
        out.tokens = quote!(#bt[#it]);
        out
    }

    fn cast(&mut self, c: &syn::ExprCast) -> Lowered {
        let inner = self.expr(&c.expr);
        let ty = &c.ty;
        let is_float = matches!(&*c.ty, syn::Type::Path(p) if p.path.is_ident("f64"));
        let mut out = inner.clone();
        out.kind = if is_float { Kind::Real } else { Kind::Int };
        if !is_float {
            out.int = inner.int;
        }
        let t = inner.operand();
        out.tokens = quote!(#t as #ty);
        out.atomic = false;
        out
    }

    /// A block; with `lift_tail`, its value is turned into a `__D`.
    fn block(&mut self, b: &syn::Block, lift_tail: bool) -> Lowered {
        self.scopes.push(HashMap::new());
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        let mut stmts = TokenStream::new();
        let n = b.stmts.len();
        for (k, stmt) in b.stmts.iter().enumerate() {
            match stmt {
                Stmt::Local(local) => stmts.extend(self.local(local, &mut out)),
                Stmt::Expr(e, semi) => {
                    let le = self.expr(e);
                    out.absorb(&le);
                    if k + 1 == n && semi.is_none() {
                        out.kind = le.kind.clone();
                        out.degree = le.degree;
                        out.int = le.int;
                        let t = if lift_tail {
                            out.kind = Kind::Dual;
                            le.as_dual(e.span())
                        } else {
                            le.tokens.clone()
                        };
                        stmts.extend(t);
                    } else {
                        let t = &le.tokens;
                        stmts.extend(quote!(#t #semi));
                    }
                }
                Stmt::Item(item) => {
                    self.unsupported(item, "an item");
                }
                Stmt::Macro(mac) => {
                    self.unsupported(mac, "a macro call");
                }
            }
        }
        self.scopes.pop();
        out.tokens = quote_spanned!(b.brace_token.span.join()=> { #stmts });
        out
    }

    fn local(&mut self, local: &syn::Local, out: &mut Lowered) -> TokenStream {
        let (pat, ty) = match &local.pat {
            Pat::Type(pt) => (&*pt.pat, Some(&pt.ty)),
            p => (p, None),
        };
        let Pat::Ident(pi) = pat else {
            self.unsupported(pat, "this pattern");
            return TokenStream::new();
        };
        let Some(init) = &local.init else {
            self.cx
                .error_spanned_by(local, "a `let` in a model expression needs a value");
            return TokenStream::new();
        };
        if init.diverge.is_some() {
            self.unsupported(local, "`let ... else`");
            return TokenStream::new();
        }
        let le = self.expr(&init.expr);
        out.absorb(&le);
        let ident = &pi.ident;
        let mutability = &pi.mutability;
        // An accumulator `let mut s = 0.0;` becomes a dual: it will collect dual terms.
        let promote = pi.mutability.is_some() && le.kind == Kind::Real && ty.is_none();
        let kind = if promote { Kind::Dual } else { le.kind.clone() };
        let value = if promote {
            le.as_dual(init.expr.span())
        } else {
            le.tokens.clone()
        };
        self.bind(
            ident,
            Local {
                kind,
                uses: le.uses.clone(),
                names: le.names.clone(),
                degree: le.degree,
                int: if pi.mutability.is_some() {
                    None
                } else {
                    le.int
                },
            },
        );
        let ty = ty.map(|t| quote!(: #t));
        let let_token = &local.let_token;
        quote!(#let_token #mutability #ident #ty = #value;)
    }

    fn if_expr(&mut self, i: &syn::ExprIf) -> Lowered {
        let cond = self.expr(&i.cond);
        let then_b = self.block(&i.then_branch, false);
        let else_b = i.else_branch.as_ref().map(|(_, e)| self.expr(e));
        let mut out = Lowered::new(TokenStream::new(), then_b.kind.clone());
        out.absorb(&cond);
        out.absorb(&then_b);
        out.atomic = false;
        let if_token = &i.if_token;
        let ct = &cond.tokens;
        let Some(else_b) = else_b else {
            out.kind = Kind::Unit;
            out.degree = Degree::CONST;
            let tt = &then_b.tokens;
            out.tokens = quote!(#if_token #ct #tt);
            return out;
        };
        out.absorb(&else_b);
        let mut degree = then_b.degree.max(else_b.degree);
        if cond.degree != Degree::CONST {
            degree = degree.max(cond.degree).opaque();
        }
        out.degree = degree;
        let mixed =
            (then_b.kind == Kind::Dual) != (else_b.kind == Kind::Dual) && then_b.kind != Kind::Unit;
        let (tt, et) = if mixed {
            out.kind = Kind::Dual;
            let Some((_, else_expr)) = &i.else_branch else {
                return out;
            };
            // Lift the `f64` branch so that both arms are `__D`.
            let t = if then_b.kind == Kind::Dual {
                then_b.tokens.clone()
            } else {
                self.silently(|l| l.block(&i.then_branch, true).tokens)
            };
            let e = if else_b.kind == Kind::Dual {
                else_b.tokens.clone()
            } else {
                self.silently(|l| l.lift_branch(else_expr))
            };
            (t, e)
        } else {
            (then_b.tokens.clone(), else_b.tokens.clone())
        };
        out.tokens = quote!(#if_token #ct #tt else #et);
        out
    }

    /// An `else` branch whose value is lifted to `__D`.
    fn lift_branch(&mut self, e: &Expr) -> TokenStream {
        match e {
            Expr::Block(b) => self.block(&b.block, true).tokens,
            Expr::If(i) => {
                let cond = self.expr(&i.cond);
                let ct = &cond.tokens;
                let tt = self.block(&i.then_branch, true).tokens;
                let if_token = &i.if_token;
                match &i.else_branch {
                    Some((_, e)) => {
                        let et = self.lift_branch(e);
                        quote!(#if_token #ct #tt else #et)
                    }
                    None => quote!(#if_token #ct #tt),
                }
            }
            other => {
                let l = self.expr(other);
                l.as_dual(other.span())
            }
        }
    }

    /// Runs `f` with errors discarded (for a second pass over an already checked expression).
    fn silently<T>(&mut self, f: impl FnOnce(&mut Lowerer<'_>) -> T) -> T {
        let quiet = Ctxt::default();
        let mut l = Lowerer {
            cx: &quiet,
            env: self.env,
            scopes: self.scopes.clone(),
            place: self.place.clone(),
        };
        let out = f(&mut l);
        // The quiet context's errors were already reported by the first pass.
        let _ = quiet.check();
        out
    }

    fn for_loop(&mut self, f: &syn::ExprForLoop) -> Lowered {
        if f.label.is_some() {
            return self.unsupported(f, "a labelled loop");
        }
        let iter = self.expr(&f.expr);
        let Kind::Iter(item) = iter.kind.clone() else {
            return self.unsupported(&f.expr, "looping over anything but a range");
        };
        let Some(ident) = pat_ident(&f.pat) else {
            return self.unsupported(&f.pat, "this loop pattern");
        };
        self.scopes.push(HashMap::new());
        self.bind(
            ident,
            Local {
                kind: *item,
                uses: iter.uses.clone(),
                names: BTreeSet::new(),
                degree: Degree::CONST,
                int: None,
            },
        );
        let body = self.block(&f.body, false);
        self.scopes.pop();
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&iter);
        out.absorb(&body);
        out.atomic = false;
        let (for_token, in_token, pat) = (&f.for_token, &f.in_token, &f.pat);
        let (it, bt) = (&iter.tokens, &body.tokens);
        out.tokens = quote!(#for_token #pat #in_token #it #bt);
        out
    }

    fn range(&mut self, r: &syn::ExprRange) -> Lowered {
        let mut out = Lowered::new(TokenStream::new(), Kind::Iter(Box::new(Kind::Int)));
        let (Some(start), Some(end)) = (&r.start, &r.end) else {
            return self.unsupported(r, "an open range");
        };
        let s = self.expr(start);
        let e = self.expr(end);
        out.absorb(&s);
        out.absorb(&e);
        out.atomic = false;
        let (st, et, limits) = (s.operand(), e.operand(), &r.limits);
        out.tokens = quote!(#st #limits #et);
        out
    }
}

fn pat_ident(p: &Pat) -> Option<&Ident> {
    match p {
        Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => Some(&pi.ident),
        Pat::Type(pt) => pat_ident(&pt.pat),
        _ => None,
    }
}
