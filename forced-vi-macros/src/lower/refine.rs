//! Integer ranges: the narrowing of integer locals by the condition of an `if` (and the
//! marking of branches that no value reaches), and the interval arithmetic of integer
//! operators.

use proc_macro2::TokenStream;
use quote::ToTokens;
use syn::{BinOp, Expr, UnOp};

use super::{IntRange, Kind, Lowerer};

impl Lowerer<'_> {
    /// Runs `f` with the integer locals that `cond` compares narrowed to the values for
    /// which `cond == positive`; a branch that no value reaches is marked dead.
    pub(super) fn refined<T>(
        &mut self,
        cond: &Expr,
        positive: bool,
        f: impl FnOnce(&mut Self) -> T,
    ) -> T {
        let mut facts = Vec::new();
        let understood = self.facts(cond, positive, &mut facts);
        let saved = self.scopes.clone();
        let mut dead = false;
        let mut unsure = false;
        for (name, lo, hi) in &facts {
            let Some((depth, local)) = self.lookup(name) else {
                continue;
            };
            let Some(r) = local.range else {
                continue;
            };
            if r.lo < 0 {
                // A negative value may be an unsigned one that wrapped (`i - 1` at `i = 0`
                // is `usize::MAX`): the comparison is not about these values. The local
                // keeps its range, as not all of it reached here.
                if let Some(l) = self.scopes.get_mut(depth).and_then(|s| s.get_mut(name)) {
                    l.range = Some(IntRange { exact: false, ..r });
                }
                unsure = true;
                continue;
            }
            let nr = IntRange {
                lo: r.lo.max(*lo),
                hi: r.hi.min(*hi),
                exact: r.exact,
            };
            if nr.lo > nr.hi {
                dead = true;
            }
            if let Some(l) = self.scopes.get_mut(depth).and_then(|s| s.get_mut(name)) {
                l.range = Some(nr);
            }
        }
        if !understood {
            // A condition the analysis cannot read: the integers it mentions may have any
            // subset of their values in this branch.
            let mut names = Vec::new();
            idents_in(&cond.to_token_stream(), &mut names);
            for name in names {
                if let Some((depth, _)) = self.lookup(&name) {
                    if let Some(l) = self.scopes.get_mut(depth).and_then(|s| s.get_mut(&name)) {
                        l.range = l.range.map(|r| IntRange { exact: false, ..r });
                    }
                }
            }
        }
        // A branch that may be unreachable reports no out-of-range index either.
        let quiet = dead || unsure;
        if quiet {
            self.dead += 1;
        }
        let out = f(self);
        if quiet {
            self.dead -= 1;
        }
        // Restore the ranges narrowed for the branch; keep what the branch assigned.
        for (k, scope) in saved.into_iter().enumerate() {
            if let Some(cur) = self.scopes.get_mut(k) {
                for (name, before) in scope {
                    if let Some(l) = cur.get_mut(&name) {
                        if l.kind == Kind::Int && l.range.is_some() {
                            l.range = before.range;
                        }
                    }
                }
            }
        }
        out
    }

    /// Facts `name ∈ [lo, hi]` implied by `cond == positive`; `false` if some part of the
    /// condition was not understood.
    pub(super) fn facts(
        &mut self,
        cond: &Expr,
        positive: bool,
        out: &mut Vec<(String, i64, i64)>,
    ) -> bool {
        match cond {
            Expr::Paren(p) => self.facts(&p.expr, positive, out),
            Expr::Unary(u) if matches!(u.op, UnOp::Not(_)) => self.facts(&u.expr, !positive, out),
            Expr::Binary(b) => {
                match (b.op, positive) {
                    (BinOp::And(_), true) | (BinOp::Or(_), false) => {
                        let l = self.facts(&b.left, positive, out);
                        let r = self.facts(&b.right, positive, out);
                        return l && r;
                    }
                    (BinOp::And(_), false) | (BinOp::Or(_), true) => return false,
                    _ => {}
                }
                let (name, other, flipped) = match (local_name(&b.left), local_name(&b.right)) {
                    (Some(n), _) => (n, &b.right, false),
                    (None, Some(n)) => (n, &b.left, true),
                    _ => return !mentions_int_local(self, cond),
                };
                let is_int = self.lookup(&name).is_some_and(|(_, l)| l.kind == Kind::Int);
                if !is_int {
                    return !mentions_int_local(self, cond);
                }
                let Some(k) = self.silently(|l| l.expr(other).int()) else {
                    return false;
                };
                let Some(op) = normalised(b.op, flipped, positive) else {
                    return false;
                };
                let (lo, hi) = match op {
                    "lt" => (i64::MIN, k.saturating_sub(1)),
                    "le" => (i64::MIN, k),
                    "gt" => (k.saturating_add(1), i64::MAX),
                    "ge" => (k, i64::MAX),
                    "eq" => (k, k),
                    _ => {
                        // `!=`: only an end of the range can be removed.
                        if let Some(r) = self.lookup(&name).and_then(|(_, l)| l.range) {
                            if r.lo == k {
                                out.push((name, k.saturating_add(1), i64::MAX));
                            } else if r.hi == k {
                                out.push((name, i64::MIN, k.saturating_sub(1)));
                            }
                        }
                        return true;
                    }
                };
                out.push((name, lo, hi));
                true
            }
            _ => !mentions_int_local(self, cond),
        }
    }
}

/// The comparison `op` (between `name` and `k`, or with `flipped` between `k` and `name`)
/// as `name OP k` where it holds (`positive`) or where it does not: `"lt"`, `"le"`, `"gt"`,
/// `"ge"`, `"eq"` or `"ne"`; `None` for an operator that is no comparison.
fn normalised(op: BinOp, flipped: bool, positive: bool) -> Option<&'static str> {
    // Normalise to `name OP k`.
    let op = match (op, flipped) {
        (BinOp::Lt(_), true) => "gt",
        (BinOp::Le(_), true) => "ge",
        (BinOp::Gt(_), true) => "lt",
        (BinOp::Ge(_), true) => "le",
        (BinOp::Lt(_), false) => "lt",
        (BinOp::Le(_), false) => "le",
        (BinOp::Gt(_), false) => "gt",
        (BinOp::Ge(_), false) => "ge",
        (BinOp::Eq(_), _) => "eq",
        (BinOp::Ne(_), _) => "ne",
        _ => return None,
    };
    Some(if positive {
        op
    } else {
        match op {
            "lt" => "ge",
            "le" => "gt",
            "gt" => "le",
            "ge" => "lt",
            "eq" => "ne",
            _ => "eq",
        }
    })
}

/// The interval of `l OP r` for integers (`None`: unknown).
pub(super) fn int_op(op: BinOp, l: Option<IntRange>, r: Option<IntRange>) -> Option<IntRange> {
    let (l, r) = (l?, r?);
    let exact = l.exact && r.exact && (l.single().is_some() || r.single().is_some());
    let corners = |f: fn(i64, i64) -> Option<i64>| -> Option<IntRange> {
        let c = [
            f(l.lo, r.lo)?,
            f(l.lo, r.hi)?,
            f(l.hi, r.lo)?,
            f(l.hi, r.hi)?,
        ];
        Some(IntRange {
            lo: c.iter().copied().min()?,
            hi: c.iter().copied().max()?,
            exact,
        })
    };
    match op {
        BinOp::Add(_) => corners(i64::checked_add),
        BinOp::Sub(_) => corners(i64::checked_sub),
        BinOp::Mul(_) => corners(i64::checked_mul),
        BinOp::Div(_) => {
            let k = r.single().filter(|&k| k > 0)?;
            if l.lo < 0 {
                // A negative dividend may be an unsigned integer that wrapped.
                return None;
            }
            Some(IntRange {
                lo: l.lo.checked_div(k)?,
                hi: l.hi.checked_div(k)?,
                exact: l.exact,
            })
        }
        BinOp::Rem(_) => {
            let k = r.single().filter(|&k| k > 0)?;
            if l.lo >= 0 && l.hi < k {
                Some(l)
            } else if l.lo >= 0 {
                Some(IntRange {
                    lo: 0,
                    hi: k - 1,
                    exact: false,
                })
            } else {
                None
            }
        }
        _ => None,
    }
}

pub(super) fn local_name(e: &Expr) -> Option<String> {
    match e {
        Expr::Path(p) if p.qself.is_none() => p.path.get_ident().map(|i| i.to_string()),
        Expr::Paren(p) => local_name(&p.expr),
        _ => None,
    }
}

pub(super) fn mentions_int_local(l: &Lowerer<'_>, e: &Expr) -> bool {
    let mut names = Vec::new();
    idents_in(&e.to_token_stream(), &mut names);
    names
        .iter()
        .any(|n| l.lookup(n).is_some_and(|(_, x)| x.kind == Kind::Int))
}

pub(super) fn idents_in(t: &TokenStream, out: &mut Vec<String>) {
    for tt in t.clone() {
        match tt {
            proc_macro2::TokenTree::Ident(i) => out.push(i.to_string()),
            proc_macro2::TokenTree::Group(g) => idents_in(&g.stream(), out),
            _ => {}
        }
    }
}
