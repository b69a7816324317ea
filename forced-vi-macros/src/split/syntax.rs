//! The syntax side of the split: the shapes it recognises (`for` accumulations), the names
//! a term may not rebind, and the rewrite of coordinate reads into slot stand-ins.

use std::collections::BTreeSet;

use proc_macro2::TokenStream;
use quote::{format_ident, ToTokens};
use syn::visit::Visit;
use syn::visit_mut::VisitMut;
use syn::{BinOp, Expr, Ident, Stmt};

use crate::lower::{Env, Group, Len, TIME};

/// `{ let mut s = 0.0; for i in … { let …; s += e; } … s }`: per part, its loop (if any), its
/// summand and whether it is subtracted. `None` if the block has any other shape.
#[allow(clippy::type_complexity)]
pub(super) fn accumulation(b: &syn::Block) -> Option<Vec<(Option<(&Ident, &Expr)>, Expr, bool)>> {
    let (first, rest) = b.stmts.split_first()?;
    let (last, middle) = rest.split_last()?;
    let Stmt::Local(init) = first else {
        return None;
    };
    let syn::Pat::Ident(acc) = &init.pat else {
        return None;
    };
    if acc.mutability.is_none() || acc.by_ref.is_some() || acc.subpat.is_some() {
        return None;
    }
    let acc = &acc.ident;
    let init_ok = init.init.as_ref().is_some_and(|i| {
        i.diverge.is_none() && matches!(&*i.expr, Expr::Lit(_)) && !mentions(&i.expr, acc)
    });
    if !init_ok || !matches!(last, Stmt::Expr(Expr::Path(p), None) if p.path.is_ident(acc)) {
        return None;
    }
    let mut parts = Vec::new();
    for stmt in middle {
        let Stmt::Expr(e, _) = stmt else {
            return None;
        };
        match e {
            Expr::ForLoop(f) if f.label.is_none() => {
                let var = pat_ident(&f.pat)?;
                let (tail, lets) = f.body.stmts.split_last()?;
                let (summand, negative) = accumulate(tail, acc)?;
                if !lets.iter().all(|s| matches!(s, Stmt::Local(_)))
                    || lets.iter().any(|s| mentions(s, acc))
                    || mentions(&f.expr, acc)
                    || var == acc
                {
                    return None;
                }
                let mut stmts = lets.to_vec();
                stmts.push(Stmt::Expr(summand.clone(), None));
                let body = Expr::Block(syn::ExprBlock {
                    attrs: Vec::new(),
                    label: None,
                    block: syn::Block {
                        brace_token: f.body.brace_token,
                        stmts,
                    },
                });
                parts.push((Some((var, &*f.expr)), body, negative));
            }
            _ => {
                let (summand, negative) = accumulate(stmt, acc)?;
                parts.push((None, summand.clone(), negative));
            }
        }
    }
    Some(parts)
}

/// `acc += e` or `acc -= e` (with or without `;`), where `e` does not read `acc`.
pub(super) fn accumulate<'e>(s: &'e Stmt, acc: &Ident) -> Option<(&'e Expr, bool)> {
    let Stmt::Expr(Expr::Binary(b), _) = s else {
        return None;
    };
    let negative = match b.op {
        BinOp::AddAssign(_) => false,
        BinOp::SubAssign(_) => true,
        _ => return None,
    };
    let is_acc = matches!(&*b.left, Expr::Path(p) if p.path.is_ident(acc));
    (is_acc && !mentions(&b.right, acc)).then_some((&*b.right, negative))
}

/// A `usize`-suffixed integer literal (through parentheses).
pub(super) fn usize_literal(e: &Expr) -> bool {
    match e {
        Expr::Paren(p) => usize_literal(&p.expr),
        Expr::Lit(l) => matches!(&l.lit, syn::Lit::Int(i) if i.suffix() == "usize"),
        _ => false,
    }
}

/// Whether some coordinate index in an expression mentions a variable.
pub(super) struct IndexedBy<'a> {
    var: &'a Ident,
    found: bool,
}

impl IndexedBy<'_> {
    pub(super) fn find(e: &Expr, var: &Ident) -> bool {
        let mut v = IndexedBy { var, found: false };
        v.visit_expr(e);
        v.found
    }
}

impl<'ast> Visit<'ast> for IndexedBy<'_> {
    fn visit_expr_index(&mut self, i: &'ast syn::ExprIndex) {
        self.found |= mentions(&i.index, self.var);
        syn::visit::visit_expr_index(self, i);
    }
}

/// Whether a coordinate or velocity is named in `e` (even where the lowering forgets it,
/// as in `q.len()`).
pub(super) fn mentions_coordinate(env: &Env, e: &Expr) -> bool {
    env.groups
        .iter()
        .any(|g| mentions(e, &g.name) || mentions(e, &g.velocity))
}

/// Whether `name` occurs anywhere in `t` as an identifier.
pub(super) fn mentions(t: &impl ToTokens, name: &Ident) -> bool {
    fn walk(t: TokenStream, name: &str) -> bool {
        t.into_iter().any(|tt| match tt {
            proc_macro2::TokenTree::Ident(i) => i == name,
            proc_macro2::TokenTree::Group(g) => walk(g.stream(), name),
            _ => false,
        })
    }
    walk(t.to_token_stream(), &name.to_string())
}

pub(super) fn pat_ident(p: &syn::Pat) -> Option<&Ident> {
    match p {
        syn::Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => Some(&pi.ident),
        syn::Pat::Type(pt) => pat_ident(&pt.pat),
        _ => None,
    }
}

/// Whether `body` binds none of the names the rewrite relies on: the loop variable, the
/// coordinates and velocities, the const parameters and `t`.
pub(super) fn binders_ok(env: &Env, body: &Expr, vars: &[Ident]) -> bool {
    struct Binders(BTreeSet<String>);
    impl<'ast> Visit<'ast> for Binders {
        fn visit_pat_ident(&mut self, p: &'ast syn::PatIdent) {
            self.0.insert(p.ident.to_string());
            syn::visit::visit_pat_ident(self, p);
        }
    }
    let mut b = Binders(BTreeSet::new());
    b.visit_expr(body);
    let mut reserved: Vec<String> = env
        .groups
        .iter()
        .flat_map(|g| [g.name.to_string(), g.velocity.to_string()])
        .chain(env.const_params.iter().map(|p| p.to_string()))
        .chain([TIME.to_string()])
        .collect();
    reserved.extend(vars.iter().map(|v| v.to_string()));
    !reserved.iter().any(|r| b.0.contains(r))
}

/// A distinct coordinate read: its group and index expression (`None` for a scalar).
pub(super) struct Key {
    pub(super) group: usize,
    pub(super) text: String,
    pub(super) index: Option<Expr>,
}

/// Replaces `q[e]`, `q_dot[e]` and scalar coordinates by slot stand-ins.
pub(super) struct Rewrite<'a> {
    pub(super) env: &'a Env,
    pub(super) vars: Vec<Ident>,
    pub(super) keys: Vec<Key>,
    pub(super) ok: bool,
}

impl Rewrite<'_> {
    fn stand_in(&mut self, group: usize, index: Option<&Expr>, vel: bool) -> Expr {
        let text = index.map_or_else(String::new, |e| e.to_token_stream().to_string());
        let k = match self
            .keys
            .iter()
            .position(|k| k.group == group && k.text == text)
        {
            Some(k) => k,
            None => {
                self.keys.push(Key {
                    group,
                    text,
                    index: index.cloned(),
                });
                self.keys.len() - 1
            }
        };
        let name = if vel {
            format_ident!("__fvi_x{}_dot", k)
        } else {
            format_ident!("__fvi_x{}", k)
        };
        syn::parse_quote!(#name)
    }

    /// The coordinate group (and whether it is the velocity) that a path names.
    fn group_of(&self, e: &Expr) -> Option<(usize, bool, bool)> {
        let Expr::Path(p) = e else { return None };
        let ident = p.path.get_ident().filter(|_| p.qself.is_none())?;
        self.env.groups.iter().enumerate().find_map(|(k, g)| {
            (g.name == *ident)
                .then_some((k, false, g.array))
                .or_else(|| (g.velocity == *ident).then_some((k, true, g.array)))
        })
    }

    /// An index the rewrite can evaluate before the term: integer literals, const
    /// parameters and the loop variable, with `+ - * / %`.
    fn simple_index(&self, e: &Expr) -> bool {
        match e {
            Expr::Lit(l) => {
                matches!(&l.lit, syn::Lit::Int(i) if matches!(i.suffix(), "" | "usize"))
            }
            Expr::Path(p) => p.path.get_ident().is_some_and(|i| {
                p.qself.is_none() && (self.vars.contains(i) || self.env.const_params.contains(i))
            }),
            Expr::Paren(p) => self.simple_index(&p.expr),
            Expr::Group(g) => self.simple_index(&g.expr),
            Expr::Binary(b) => {
                matches!(
                    b.op,
                    BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_) | BinOp::Div(_) | BinOp::Rem(_)
                ) && self.simple_index(&b.left)
                    && self.simple_index(&b.right)
            }
            _ => false,
        }
    }

    /// The environment in which every key is a scalar coordinate.
    pub(super) fn synthetic_env(&self) -> Env {
        let groups = (0..self.keys.len())
            .map(|k| Group {
                name: format_ident!("__fvi_x{}", k),
                velocity: format_ident!("__fvi_x{}_dot", k),
                offset: k,
                len: Len::Lit(1),
                array: false,
            })
            .collect();
        Env {
            groups,
            params: self.env.params.clone(),
            const_params: self.env.const_params.clone(),
            model: self.env.model.clone(),
            params_dual: self.env.params_dual,
        }
    }
}

impl VisitMut for Rewrite<'_> {
    fn visit_expr_mut(&mut self, e: &mut Expr) {
        if let Expr::Index(ix) = e {
            if let Some((g, vel, true)) = self.group_of(&ix.expr) {
                if self.simple_index(&ix.index) {
                    *e = self.stand_in(g, Some(&ix.index), vel);
                } else {
                    self.ok = false;
                }
                return;
            }
        }
        if let Some((g, vel, array)) = self.group_of(e) {
            if array {
                // A whole array (not indexed): not local.
                self.ok = false;
            } else {
                *e = self.stand_in(g, None, vel);
            }
            return;
        }
        syn::visit_mut::visit_expr_mut(self, e);
    }
}
