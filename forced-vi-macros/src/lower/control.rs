//! Control flow and blocks: blocks and `let`, `if` (with the lifting of its branches to a
//! common kind), loop bodies and `map` closures analysed to a fixpoint, `for` loops and
//! ranges.

use std::collections::{BTreeSet, HashMap};

use proc_macro2::TokenStream;
use quote::{quote, quote_spanned};
use syn::spanned::Spanned;
use syn::{Expr, Ident, Pat, Stmt};

use super::types::{join_range, Local};
use super::{Ctrl, Degree, IntRange, Kind, Lowered, Lowerer, Scopes, Var, MAX_PASSES};

impl Lowerer<'_> {
    /// A block; with `lift_tail`, its value is turned into a `__D` (or, with `real`, an
    /// integer value into an `f64`).
    pub(super) fn block(&mut self, b: &syn::Block, lift_tail: bool) -> Lowered {
        let real = self.lift_real;
        self.lift_real = false;
        let mut out = self.block_inner(b, lift_tail, real);
        if real && lift_tail {
            out.kind = Kind::Real;
        }
        out
    }

    pub(super) fn block_inner(&mut self, b: &syn::Block, lift_tail: bool, real: bool) -> Lowered {
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
                        out.range = le.range;
                        out.lit_f64 = le.lit_f64;
                        out.inexact = le.inexact.clone();
                        let t = if lift_tail && real {
                            le.as_real()
                        } else if lift_tail {
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

    pub(super) fn local(&mut self, local: &syn::Local, out: &mut Lowered) -> TokenStream {
        let (pat, ty) = match &local.pat {
            Pat::Type(pt) => (&*pt.pat, Some(&pt.ty)),
            p => (p, None),
        };
        let Pat::Ident(pi) = pat else {
            self.unsupported(pat, "this pattern");
            return TokenStream::new();
        };
        if pi.by_ref.is_some() || pi.subpat.is_some() {
            self.unsupported(pat, "this pattern");
            return TokenStream::new();
        }
        let Some(init) = &local.init else {
            self.cx
                .error_spanned_by(local, "a `let` in a model expression needs a value");
            return TokenStream::new();
        };
        if init.diverge.is_some() {
            self.unsupported(local, "`let ... else`");
            return TokenStream::new();
        }
        let mut le = self.expr(&init.expr);
        out.absorb(&le);
        let ident = &pi.ident;
        let mutability = &pi.mutability;
        let is_f64 =
            ty.is_some_and(|t| matches!(&**t, syn::Type::Path(p) if p.path.is_ident("f64")));
        if is_f64 {
            le.make_real();
        }
        if let Some(t) = ty.filter(|_| le.kind == Kind::Int) {
            // A typed integer (`let j: u8 = i;`) keeps its values only if all fit the type.
            let bounds = match &**t {
                syn::Type::Path(p) if p.qself.is_none() => p
                    .path
                    .get_ident()
                    .and_then(|t| super::int_type_bounds(&t.to_string())),
                _ => None,
            };
            le.range = bounds.and_then(|(lo, hi)| le.range.filter(|r| r.lo >= lo && r.hi <= hi));
        }
        // An accumulator `let mut s = 0.0;` becomes a dual: it will collect dual terms.
        let promote = pi.mutability.is_some() && le.kind == Kind::Real && ty.is_none();
        let kind = if promote { Kind::Dual } else { le.kind.clone() };
        let value = if promote {
            le.as_dual(init.expr.span())
        } else {
            le.tokens.clone()
        };
        self.bind_user(
            ident,
            Local {
                kind,
                uses: le.uses.clone(),
                names: le.names.clone(),
                degree: le.degree,
                range: le.range,
                inexact: le.inexact.clone(),
            },
        );
        // With the parameters as duals, a value the user typed `f64` may be one.
        let ty = ty
            .filter(|_| !(self.env.params_dual && le.kind == Kind::Dual))
            .map(|t| quote!(: #t));
        let let_token = &local.let_token;
        quote!(#let_token #mutability #ident #ty = #value;)
    }

    pub(super) fn if_expr(&mut self, i: &syn::ExprIf) -> Lowered {
        let cond = self.expr(&i.cond);
        self.ctrl.push(Ctrl {
            depth: self.scopes.len(),
            uses: cond.uses.clone(),
            names: cond.names.clone(),
            degree: cond.degree,
        });
        let then_b = self.refined(&i.cond, true, |l| l.block(&i.then_branch, false));
        let else_b = i
            .else_branch
            .as_ref()
            .map(|(_, e)| self.refined(&i.cond, false, |l| l.expr(e)));
        self.ctrl.pop();
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
        let array = |k: &Kind| matches!(k, Kind::Array(_));
        if array(&then_b.kind) || array(&else_b.kind) {
            // An array chosen by a condition: which coordinates it holds is not known here.
            let (a, b) = (self.array_of(&then_b), self.array_of(&else_b));
            if then_b.kind != else_b.kind || a.is_none() || a != b {
                self.unsupported(
                    i,
                    "an `if` that chooses between coordinate or velocity arrays (index them inside the branches instead)",
                );
                // Read on as the first array: one error, at the `if`.
                return then_b;
            }
        }
        let mut degree = then_b.degree.max(else_b.degree);
        if cond.degree != Degree::CONST {
            degree = degree.max(cond.degree).opaque();
        }
        out.degree = degree;
        out.range = join_range(then_b.range, else_b.range);
        let Some((tt, et)) = self.if_arms(i, &then_b, &else_b, &mut out) else {
            return out;
        };
        out.tokens = quote!(#if_token #ct #tt else #et);
        out
    }

    /// The tokens of the two arms of an `if` with an `else`, of one kind: an integer arm
    /// beside an `f64` one becomes an `f64`, an `f64` (or integer) arm beside a `__D` one
    /// becomes a `__D`. Sets the kind of `out` (and its range) to match; `None` if there is
    /// no `else` after all.
    fn if_arms(
        &mut self,
        i: &syn::ExprIf,
        then_b: &Lowered,
        else_b: &Lowered,
        out: &mut Lowered,
    ) -> Option<(TokenStream, TokenStream)> {
        let real_like = |k: &Kind| matches!(k, Kind::Real | Kind::Int | Kind::Dual);
        let mixed =
            then_b.kind != else_b.kind && real_like(&then_b.kind) && real_like(&else_b.kind);
        let to_real = mixed && then_b.kind != Kind::Dual && else_b.kind != Kind::Dual;
        if to_real {
            // An integer branch beside an `f64` one: the integer is a number.
            out.kind = Kind::Real;
            out.range = None;
            let (_, else_expr) = i.else_branch.as_ref()?;
            let t = if then_b.kind == Kind::Int {
                self.silently(|l| {
                    l.lift_real = true;
                    l.block(&i.then_branch, true).tokens
                })
            } else {
                then_b.tokens.clone()
            };
            let e = if else_b.kind == Kind::Int {
                self.silently(|l| {
                    l.lift_real = true;
                    l.lift_branch(else_expr)
                })
            } else {
                else_b.tokens.clone()
            };
            Some((t, e))
        } else if mixed {
            out.kind = Kind::Dual;
            let (_, else_expr) = i.else_branch.as_ref()?;
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
            Some((t, e))
        } else {
            Some((then_b.tokens.clone(), else_b.tokens.clone()))
        }
    }

    /// Lowers a loop body or a `map` closure, which runs any number of times: the locals it
    /// assigns are analysed to a fixpoint (silently), then the body is lowered once more
    /// for real from that state.
    pub(super) fn repeated(
        &mut self,
        iter: &Lowered,
        var: &Ident,
        param: Local,
        mut f: impl FnMut(&mut Lowerer<'_>) -> Lowered,
    ) -> Lowered {
        self.ctrl.push(Ctrl {
            depth: self.scopes.len(),
            uses: iter.uses.clone(),
            names: iter.names.clone(),
            degree: iter.degree,
        });
        // A body that may run for no value (an empty range, or one whose ends are not
        // known: `(0..i)` at `i = 0`) reports no out-of-range index either.
        let dead = !iter.range.is_some_and(|r| r.exact && r.lo <= r.hi);
        let param = Local {
            range: param.range.filter(|r| r.lo <= r.hi),
            ..param
        };
        let mut converged = false;
        let mut last_uses = BTreeSet::new();
        for pass in 0..MAX_PASSES {
            let before = self.scopes.clone();
            let (after, uses) = self.silently(|l| {
                l.scopes.push(HashMap::new());
                l.bind(var, param.clone());
                let body = f(l);
                l.scopes.pop();
                (l.scopes.clone(), body.uses)
            });
            last_uses = uses;
            let joined = join_scopes(&before, &after, pass >= 1);
            let stable = joined == before;
            self.scopes = joined;
            if stable || self.budget.get() == 0 {
                converged = true;
                break;
            }
        }
        if !converged {
            // Widen what still changes: any polynomial degree, any use seen anywhere.
            let mut all: BTreeSet<Var> = last_uses;
            for scope in &self.scopes {
                for l in scope.values() {
                    all.extend(l.uses.iter().copied());
                }
            }
            for scope in &mut self.scopes {
                for l in scope.values_mut() {
                    l.uses.extend(all.iter().copied());
                    if l.degree != Degree::CONST {
                        l.degree = Degree { q: None, v: None };
                    }
                    l.range = None;
                }
            }
        }
        let state = self.scopes.clone();
        if dead {
            self.dead += 1;
        }
        self.scopes.push(HashMap::new());
        self.bind_user(var, param);
        let body = f(self);
        self.scopes.pop();
        if dead {
            self.dead -= 1;
        }
        self.scopes = state;
        self.ctrl.pop();
        body
    }

    /// An `else` branch whose value is lifted to `__D` (to `f64` with `lift_real`).
    pub(super) fn lift_branch(&mut self, e: &Expr) -> TokenStream {
        let real = self.lift_real;
        match e {
            Expr::Block(b) => self.block(&b.block, true).tokens,
            Expr::If(i) => {
                let cond = self.expr(&i.cond);
                let ct = &cond.tokens;
                self.lift_real = real;
                let tt = self.block(&i.then_branch, true).tokens;
                self.lift_real = real;
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
                self.lift_real = false;
                let l = self.expr(other);
                if real {
                    l.as_real()
                } else {
                    l.as_dual(other.span())
                }
            }
        }
    }

    pub(super) fn for_loop(&mut self, f: &syn::ExprForLoop) -> Lowered {
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
        let param = Local {
            kind: *item,
            uses: iter.uses.clone(),
            names: BTreeSet::new(),
            degree: iter.degree.opaque(),
            range: iter.range,
            inexact: None,
        };
        let body = self.repeated(&iter, ident, param, |l| l.block(&f.body, false));
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&iter);
        out.absorb(&body);
        out.atomic = false;
        let (for_token, in_token, pat) = (&f.for_token, &f.in_token, &f.pat);
        let (it, bt) = (&iter.tokens, &body.tokens);
        out.tokens = quote!(#for_token #pat #in_token #it #bt);
        out
    }

    pub(super) fn range(&mut self, r: &syn::ExprRange) -> Lowered {
        let mut out = Lowered::new(TokenStream::new(), Kind::Iter(Box::new(Kind::Int)));
        let (Some(start), Some(end)) = (&r.start, &r.end) else {
            return self.unsupported(r, "an open range");
        };
        let s = self.expr(start);
        let e = self.expr(end);
        out.absorb(&s);
        out.absorb(&e);
        // Ends that depend on a coordinate or velocity: so does everything the range
        // reaches (its items, how many there are).
        out.degree = s.degree.max(e.degree).opaque();
        out.atomic = false;
        let closed = matches!(r.limits, syn::RangeLimits::Closed(_));
        out.range = match (s.range, e.range) {
            (Some(a), Some(b)) => {
                let hi = if closed {
                    Some(b.hi)
                } else {
                    b.hi.checked_sub(1)
                };
                hi.map(|hi| IntRange {
                    lo: a.lo,
                    hi,
                    exact: a.single().is_some() && b.single().is_some() && a.exact && b.exact,
                })
            }
            _ => None,
        };
        let (st, et, limits) = (s.operand(), e.operand(), &r.limits);
        out.tokens = quote!(#st #limits #et);
        out
    }
}

pub(super) fn join_scopes(a: &Scopes, b: &Scopes, widen: bool) -> Scopes {
    a.iter()
        .zip(b)
        .map(|(sa, sb)| {
            sa.iter()
                .map(|(k, la)| {
                    let l = match sb.get(k) {
                        Some(lb) => la.join(lb, widen),
                        None => la.clone(),
                    };
                    (k.clone(), l)
                })
                .collect()
        })
        .collect()
}

pub(super) fn pat_ident(p: &Pat) -> Option<&Ident> {
    match p {
        Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => Some(&pi.ident),
        Pat::Type(pt) => pat_ident(&pt.pat),
        _ => None,
    }
}
