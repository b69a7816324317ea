//! Expressions and operators: the dispatch over expression forms, literals, names (paths),
//! unary and binary operators, comparisons and assignments to locals.

use proc_macro2::TokenStream;
use quote::{quote, quote_spanned, ToTokens};
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Lit, UnOp};

use super::refine::int_op;
use super::types::var_degree;
use super::{Ctrl, Degree, Idx, Inexact, IntRange, Kind, Lowered, Lowerer, Var, TIME};

impl Lowerer<'_> {
    /// Lowers an expression.
    pub fn expr(&mut self, e: &Expr) -> Lowered {
        let left = self.budget.get();
        if left == 0 {
            return Lowered::new(TokenStream::new(), Kind::Real);
        }
        self.budget.set(left - 1);
        if self.wrap.is_none() {
            self.wrap = Some(super::wrap_bounds(&e.to_token_stream()));
        }
        if left == 1 {
            self.cx.error_spanned_by(
                e,
                "this model expression is too large to analyse (loops nested too deeply); simplify it",
            );
        }
        let mut out = self.expr_inner(e);
        out.stmt_like = matches!(e, Expr::Block(_) | Expr::If(_) | Expr::ForLoop(_));
        out
    }

    pub(super) fn expr_inner(&mut self, e: &Expr) -> Lowered {
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
            Expr::Assign(a) => self.assign(&a.left, None, &a.right),
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

    pub(super) fn lit(&mut self, lit: &Lit) -> Lowered {
        match lit {
            Lit::Float(_) => Lowered::new(lit.to_token_stream(), Kind::Real),
            Lit::Int(i) => {
                let mut l = Lowered::new(lit.to_token_stream(), Kind::Int);
                if i.suffix() == "f64" || i.suffix() == "f32" {
                    l.kind = Kind::Real;
                } else {
                    l.range = i.base10_parse::<i64>().ok().map(IntRange::point);
                    if i.suffix().is_empty() {
                        l.lit_f64 = i
                            .base10_digits()
                            .parse::<f64>()
                            .ok()
                            .filter(|x| x.is_finite());
                    }
                }
                l
            }
            Lit::Bool(_) => Lowered::new(lit.to_token_stream(), Kind::Bool),
            other => self.unsupported(other, "this literal"),
        }
    }

    pub(super) fn path(&mut self, p: &syn::ExprPath) -> Lowered {
        let tokens = p.to_token_stream();
        let Some(ident) = p.path.get_ident().filter(|_| p.qself.is_none()) else {
            // A path such as `std::f64::consts::PI` or `f64::EPSILON`: a constant.
            return Lowered::new(tokens, Kind::Real);
        };
        let name = ident.to_string();
        if let Some((_, local)) = self.lookup(&name) {
            let mut l = Lowered::new(tokens, local.kind.clone());
            l.uses = local.uses.clone();
            l.names = local.names.clone();
            l.degree = local.degree;
            l.range = local.range;
            l.inexact = local.inexact.clone();
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
                        l.degree = var_degree(vel);
                        l
                    };
                    l.names.insert(name.clone());
                    return l;
                }
            }
        }
        if self.env.params.iter().any(|p| *p == name) {
            let kind = if self.env.params_dual {
                Kind::Dual
            } else {
                Kind::Real
            };
            let mut l = Lowered::new(tokens, kind);
            l.names.insert(name);
            return l;
        }
        if self.env.const_params.iter().any(|p| *p == name) {
            return Lowered::new(tokens, Kind::Int);
        }
        if name == TIME {
            // The time: a `__D` value (so that `∂L/∂t` can be taken with a dual number)
            // that is constant in `q` and `v`, like a parameter, for the degree analysis.
            let mut l = Lowered::new(tokens, Kind::Dual);
            l.names.insert(name);
            return l;
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

    pub(super) fn unary(&mut self, u: &syn::ExprUnary) -> Lowered {
        let inner = self.expr(&u.expr);
        let op = &u.op;
        let mut out = inner.clone();
        match u.op {
            UnOp::Neg(_) => {
                out.range = inner.range.and_then(|r| {
                    Some(IntRange {
                        lo: r.hi.checked_neg()?,
                        hi: r.lo.checked_neg()?,
                        exact: r.exact,
                    })
                });
                out.lit_f64 = inner.lit_f64.map(|x| -x);
            }
            UnOp::Not(_) => {
                out.kind = Kind::Bool;
                out.degree = inner.degree.opaque();
                out.range = None;
            }
            _ => return self.unsupported(u, "dereferencing"),
        }
        let t = inner.operand();
        // Spanned at the user's tokens: rustc's own error (`-` on a `usize` index) then
        // points there, not at the whole attribute.
        let span = syn::spanned::Spanned::span(u);
        out.tokens = quote::quote_spanned!(span=> #op #t);
        out.atomic = false;
        out
    }

    pub(super) fn binary(&mut self, b: &syn::ExprBinary) -> Lowered {
        match b.op {
            BinOp::AddAssign(_)
            | BinOp::SubAssign(_)
            | BinOp::MulAssign(_)
            | BinOp::DivAssign(_) => self.assign(&b.left, Some(&b.op), &b.right),
            BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_) | BinOp::Div(_) | BinOp::Rem(_) => {
                self.arithmetic(b)
            }
            BinOp::Eq(_)
            | BinOp::Lt(_)
            | BinOp::Le(_)
            | BinOp::Ne(_)
            | BinOp::Ge(_)
            | BinOp::Gt(_)
            | BinOp::And(_)
            | BinOp::Or(_) => self.compare(b),
            _ => self.unsupported(b.op, "this operator"),
        }
    }

    /// `l + r`, `l - r`, `l * r`, `l / r` and `l % r`: integer arithmetic (wrapping) between
    /// integers, real or dual arithmetic otherwise.
    fn arithmetic(&mut self, b: &syn::ExprBinary) -> Lowered {
        let mut l = self.expr(&b.left);
        let mut r = self.expr(&b.right);
        let op = &b.op;
        let span = first_span(&b.left);
        let mut out = Lowered::new(TokenStream::new(), Kind::Real);
        out.absorb(&l);
        out.absorb(&r);
        out.atomic = false;
        out.kind = match (&l.kind, &r.kind) {
            (Kind::Dual, _) | (_, Kind::Dual) => Kind::Dual,
            (Kind::Int, Kind::Int) => Kind::Int,
            _ => Kind::Real,
        };
        out.degree = arithmetic_degree(b.op, l.degree, r.degree);
        if out.kind == Kind::Int {
            // Ranges are computed in i64: a result (or an operand) beyond what the model's
            // integer type holds wraps at run time, so it is unknown here.
            out.range = self.unwrapped(int_op(
                b.op,
                self.unwrapped(l.range),
                self.unwrapped(r.range),
            ));
            if matches!(b.op, BinOp::Div(_) | BinOp::Rem(_))
                && r.range.and_then(|r| r.single()) == Some(0)
            {
                self.cx.error_spanned_by(
                    b,
                    format!(
                        "`{}` divides by zero",
                        super::compact(&b.to_token_stream().to_string())
                    ),
                );
            }
            out.inexact = l.inexact.clone().or_else(|| r.inexact.clone());
            if out.inexact.is_none() {
                // Overflow as the default `i32` arithmetic of unsuffixed literals.
                let i32_range = int_op(b.op, l.range, r.range)
                    .filter(|x| x.lo >= i64::from(i32::MIN) && x.hi <= i64::from(i32::MAX));
                out.inexact = inexact(b, l.range, r.range, i32_range);
            }
            // Integer arithmetic wraps instead of panicking: an index that wraps is out of
            // range, which the checked access reports.
            let fvi = quote!(::forced_vi::__private);
            let f = match b.op {
                BinOp::Add(_) => quote!(int_add),
                BinOp::Sub(_) => quote!(int_sub),
                BinOp::Mul(_) => quote!(int_mul),
                BinOp::Div(_) => quote!(int_div),
                _ => quote!(int_rem),
            };
            let (lt, rt) = (&l.tokens, &r.tokens);
            out.tokens = quote_spanned!(span=> #fvi::#f(#lt, #rt));
            out.atomic = true;
            return out;
        }
        // A user writes integer literals (`2 * x`, `v * v / 2`): they are `f64` here.
        l.make_real();
        r.make_real();
        let (lt, rt) = (&l.tokens, &r.tokens);
        let real_left = l.kind == Kind::Real;
        out.tokens = if real_left && r.kind == Kind::Dual {
            // num-dual has `D ∘ f64` only: put the dual operand first.
            let (lo, ro) = (l.operand(), r.operand());
            match b.op {
                BinOp::Add(_) => quote!(#ro + #lo),
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
        out
    }

    pub(super) fn compare(&mut self, b: &syn::ExprBinary) -> Lowered {
        let mut l = self.expr(&b.left);
        let mut r = self.expr(&b.right);
        let op = &b.op;
        let mut out = Lowered::new(TokenStream::new(), Kind::Bool);
        out.absorb(&l);
        out.absorb(&r);
        out.degree = l.degree.max(r.degree).opaque();
        out.atomic = false;
        if l.kind != r.kind {
            l.make_real();
            r.make_real();
        }
        out.tokens = if l.kind == Kind::Dual || r.kind == Kind::Dual {
            let ld = l.as_dual(b.left.span());
            let rd = r.as_dual(b.right.span());
            let ld = if l.kind == Kind::Dual {
                l.operand()
            } else {
                ld
            };
            let rd = if r.kind == Kind::Dual {
                r.operand()
            } else {
                rd
            };
            quote!(#ld #op #rd)
        } else {
            let (lt, rt) = (&l.tokens, &r.tokens);
            quote!(#lt #op #rt)
        };
        out
    }

    /// `x = e`, `x += e`, ... on a local.
    pub(super) fn assign(&mut self, left: &Expr, op: Option<&BinOp>, right: &Expr) -> Lowered {
        let Expr::Path(p) = left else {
            return self.unsupported(left, "assigning to anything but a local variable");
        };
        let Some(ident) = p.path.get_ident() else {
            return self.unsupported(left, "assigning to a path");
        };
        let mut r = self.expr(right);
        let name = ident.to_string();
        let Some((depth, _)) = self.lookup(&name) else {
            self.cx.error_spanned_by(
                ident,
                format!(
                    "`{name}` is not a local variable; only `let mut` variables can be assigned"
                ),
            );
            return Lowered::new(TokenStream::new(), Kind::Unit);
        };
        let array = |k: &Kind| matches!(k, Kind::Array(_));
        if array(&r.kind) || self.lookup(&name).is_some_and(|(_, l)| array(&l.kind)) {
            // Which coordinates the local holds would depend on where it was assigned.
            return self.unsupported(left, "assigning a coordinate or velocity array");
        }
        // The regions entered since the local was declared decide whether it is assigned.
        let ctrl: Vec<Ctrl> = self
            .ctrl
            .iter()
            .filter(|c| c.depth > depth)
            .cloned()
            .collect();
        let Some(local) = self.scopes.get_mut(depth).and_then(|s| s.get_mut(&name)) else {
            return Lowered::new(TokenStream::new(), Kind::Unit);
        };
        local.uses.extend(r.uses.iter().copied());
        local.names.extend(r.names.iter().cloned());
        local.range = None;
        if lkind_is_int(&local.kind) {
            let divides = matches!(op, Some(BinOp::DivAssign(_))).then(|| {
                Inexact::at(
                    right,
                    format!(
                        "`{name} /= ...` divides integers, which truncates as in Rust (`3 / 2` is 1); if `{name}` is used as a real number, make it one (`let mut {name} = 1.0;`)"
                    ),
                )
            });
            local.inexact = local.inexact.take().or(r.inexact.clone()).or(divides);
        }
        local.degree = match op {
            None | Some(BinOp::AddAssign(_)) | Some(BinOp::SubAssign(_)) => {
                local.degree.max(r.degree)
            }
            Some(BinOp::DivAssign(_)) if r.degree == Degree::CONST => local.degree,
            _ => local.degree.max(r.degree).opaque(),
        };
        for c in &ctrl {
            local.uses.extend(c.uses.iter().copied());
            local.names.extend(c.names.iter().cloned());
            if c.degree != Degree::CONST {
                // A value chosen by a condition on coordinates is piecewise: no polynomial.
                local.degree = local.degree.max(c.degree).opaque();
            }
        }
        let lkind = local.kind.clone();
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&r);
        out.atomic = false;
        if lkind != Kind::Int {
            r.make_real();
        }
        let rt = if lkind == Kind::Dual {
            r.as_dual(right.span())
        } else {
            r.tokens.clone()
        };
        out.tokens = match op {
            Some(op) => quote!(#ident #op #rt),
            None => quote!(#ident = #rt),
        };
        out
    }
}

/// The polynomial degree of `l OP r` for an arithmetic operator.
fn arithmetic_degree(op: BinOp, l: Degree, r: Degree) -> Degree {
    match op {
        BinOp::Add(_) | BinOp::Sub(_) => l.max(r),
        BinOp::Mul(_) => l.add(r),
        BinOp::Div(_) => {
            if r == Degree::CONST {
                l
            } else {
                l.max(r).opaque()
            }
        }
        _ => l.max(r).opaque(),
    }
}

/// Whether the integer arithmetic `b`, of operands in `l` and `r` with a result in `out`,
/// may give a value that the same arithmetic on reals would not: a division that may
/// truncate (or divide by zero), or a sum or product that overflows.
fn inexact(
    b: &syn::ExprBinary,
    l: Option<IntRange>,
    r: Option<IntRange>,
    out: Option<IntRange>,
) -> Option<Inexact> {
    let text = || super::compact(&b.to_token_stream().to_string());
    let message = match b.op {
        BinOp::Div(_) => {
            let exact = matches!(
                (l.and_then(|l| l.single()), r.and_then(|r| r.single())),
                (Some(a), Some(d)) if d != 0 && a.checked_rem(d) == Some(0)
            );
            if exact {
                return None;
            }
            let text = text();
            format!(
                "`{text}` divides integers, which truncates as in Rust (`3 / 2` is 1), and its value is used here as a real number; write the numbers as reals (`3.0 / 2.0`), or convert explicitly with `({text}) as f64`"
            )
        }
        BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_)
            if l.is_some() && r.is_some() && out.is_none() =>
        {
            let text = text();
            format!(
                "`{text}` overflows integer arithmetic, and its value is used here as a real number; write the numbers as reals (`2147483647.0`)"
            )
        }
        _ => return None,
    };
    Some(Inexact::at(b, message))
}

fn lkind_is_int(k: &Kind) -> bool {
    *k == Kind::Int
}

/// The span of the first token of `e`, as `e.span()` gives it on stable Rust (which cannot
/// join spans), without printing `e` to tokens: that costs the size of `e`, and at every
/// operator of a long sum it made the expansion quadratic in the number of terms (800 terms
/// took 3 s, 3000 took 47 s).
fn first_span(e: &Expr) -> proc_macro2::Span {
    let mut e = e;
    loop {
        e = match e {
            Expr::Binary(b) => &b.left,
            Expr::MethodCall(m) => &m.receiver,
            Expr::Index(i) => &i.expr,
            Expr::Cast(c) => &c.expr,
            Expr::Field(f) => &f.base,
            Expr::Call(c) => &c.func,
            Expr::Range(syn::ExprRange { start: Some(s), .. }) => s,
            Expr::Paren(p) if p.attrs.is_empty() => return p.paren_token.span.open(),
            Expr::Lit(l) if l.attrs.is_empty() => return l.lit.span(),
            Expr::Path(p) if p.attrs.is_empty() && p.qself.is_none() => {
                if let Some(s) = p.path.segments.first() {
                    return s.ident.span();
                }
                return e.span();
            }
            other => return other.span(),
        };
    }
}
