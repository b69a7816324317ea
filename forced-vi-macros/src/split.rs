//! Per-term differentiation (DESIGN §9): when the Lagrangian is a sum of local terms (index
//! sums `(a..b).map(|i| …).sum()`, `for` accumulations, terms with fixed indices, with signs
//! and constant factors) and every force entry reads a few coordinates, each term is
//! differentiated over a dual number of only the coordinates it reads, and the small blocks
//! are scattered into sparse node blocks (`SparseNode`).
//!
//! A term reads coordinates through *slots*: each distinct index expression `q[e]` (and the
//! scalar coordinates) becomes a scalar stand-in, which the ordinary lowering then treats like
//! a named coordinate. An index expression may use only the term's loop variable, integer
//! literals and const parameters, so its value is known before the term is evaluated; at a
//! loop value where it is out of range, the slot is absent (never read, never written).
//!
//! Anything else (a whole-array expression, an index the analysis cannot resolve, a sum used
//! nonlinearly) makes the whole model keep its dense kernels: the analysis returns `None`.

use std::collections::BTreeSet;

use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote, ToTokens};
use syn::visit::Visit;
use syn::visit_mut::VisitMut;
use syn::{BinOp, Expr, Ident, Stmt, UnOp};

use crate::check::Checked;
use crate::ctxt::Ctxt;
use crate::lower::{Env, Group, IntRange, Kind, Len, Lowered, Lowerer, TIME};

/// The most slots one term may read (its dual numbers are `K × K`).
const MAX_SLOTS: usize = 32;

/// A model split into local terms.
pub struct Split {
    pub terms: Vec<Local>,
    pub forces: Vec<Local>,
}

/// One term of `L`, or one force entry (then `row` is its component's index).
pub struct Local {
    /// `for var in iter` loops around the term, outermost first (none for a fixed term).
    pub loops: Vec<(Ident, TokenStream)>,
    /// The constant factor (sign included), an `f64` expression; `None` for 1.
    pub weight: Option<TokenStream>,
    /// For a force entry: its component, a `usize` expression.
    pub row: Option<TokenStream>,
    pub slots: Vec<Slot>,
    /// The term as a `__D` expression over the slots' stand-ins.
    pub body: TokenStream,
    pub uses_time: bool,
}

/// A coordinate or velocity that a term reads.
pub struct Slot {
    /// The stand-in's name in `body`.
    pub ident: Ident,
    /// Its index in `q` (or `v`), a `usize` expression (`ABSENT` when out of range).
    pub index: TokenStream,
    pub vel: bool,
}

/// A loop around a term: the variable, the iterator's tokens and the values it takes.
#[derive(Clone)]
struct Loop {
    var: Ident,
    iter: TokenStream,
    range: Option<IntRange>,
}

/// Splits the model, or `None` when some part of it cannot be split soundly.
pub fn split(c: &Checked) -> Option<Split> {
    let (_, l) = c.model.lagrangian.as_ref()?;
    let a = Analysis { env: &c.env };
    let mut terms = Vec::new();
    a.decompose(l, &[], &[], &mut terms)?;
    let mut forces = Vec::new();
    if let Some(force) = &c.force {
        for f in &force.fns {
            forces.push(a.force_entry(c, f)?);
        }
    }
    Some(Split { terms, forces })
}

struct Analysis<'a> {
    env: &'a Env,
}

impl Analysis<'_> {
    /// Splits `e`, scaled by the product of `weight`, into terms (an empty factor is `-1`),
    /// inside `loops`.
    fn decompose(
        &self,
        e: &Expr,
        loops: &[Loop],
        weight: &[TokenStream],
        out: &mut Vec<Local>,
    ) -> Option<()> {
        let with = |f: TokenStream| -> Vec<TokenStream> {
            let mut w = weight.to_vec();
            w.push(f);
            w
        };
        let within = |lp: Loop| -> Vec<Loop> {
            let mut l = loops.to_vec();
            l.push(lp);
            l
        };
        let neg = TokenStream::new;
        match e {
            Expr::Paren(p) => self.decompose(&p.expr, loops, weight, out),
            Expr::Group(g) => self.decompose(&g.expr, loops, weight, out),
            Expr::Unary(u) if matches!(u.op, UnOp::Neg(_)) => {
                self.decompose(&u.expr, loops, &with(neg()), out)
            }
            Expr::Binary(b) => match b.op {
                BinOp::Add(_) | BinOp::Sub(_) => {
                    let right = if matches!(b.op, BinOp::Sub(_)) {
                        with(neg())
                    } else {
                        weight.to_vec()
                    };
                    self.decompose(&b.left, loops, weight, out)?;
                    self.decompose(&b.right, loops, &right, out)
                }
                BinOp::Mul(_) => match (
                    self.constant(&b.left, loops),
                    self.constant(&b.right, loops),
                ) {
                    (Some(f), _) => self.decompose(&b.right, loops, &with(f), out),
                    (None, Some(f)) => self.decompose(&b.left, loops, &with(f), out),
                    _ => self.leaf(e, loops, weight, out),
                },
                BinOp::Div(_) => match self.constant(&b.right, loops) {
                    Some(f) => self.decompose(&b.left, loops, &with(quote!(1.0 / #f)), out),
                    None => self.leaf(e, loops, weight, out),
                },
                _ => self.leaf(e, loops, weight, out),
            },
            Expr::MethodCall(m) if m.method == "sum" && m.args.is_empty() => {
                match self.index_sum(m, loops) {
                    Some((lp, body)) => self.decompose(body, &within(lp), weight, out),
                    None => self.leaf(e, loops, weight, out),
                }
            }
            Expr::Block(b) if b.label.is_none() => match accumulation(&b.block) {
                Some(parts) => {
                    for (var_iter, body, negative) in parts {
                        let w = if negative {
                            with(neg())
                        } else {
                            weight.to_vec()
                        };
                        match var_iter {
                            Some((var, iter)) => {
                                let lp = self.iterator(var, iter, &body, loops)?;
                                self.decompose(&body, &within(lp), &w, out)?;
                            }
                            None => self.decompose(&body, loops, &w, out)?,
                        }
                    }
                    Some(())
                }
                None => self.leaf(e, loops, weight, out),
            },
            _ => self.leaf(e, loops, weight, out),
        }
    }

    /// An `f64` constant (literals, parameters and loop variables, no coordinate and no
    /// time) as tokens.
    fn constant(&self, e: &Expr, loops: &[Loop]) -> Option<TokenStream> {
        let l = quietly(self.env, loops, |lw| lw.expr(e))?;
        // Only parameters by name: not the time, nor a coordinate array (`q.len()`).
        let constant = matches!(l.kind, Kind::Real | Kind::Int)
            && l.uses.is_empty()
            && l.names
                .iter()
                .all(|n| self.env.params.iter().any(|p| p == n))
            && !mentions_coordinate(self.env, e);
        constant.then(|| l.as_real()).filter(|t| !t.is_empty())
    }

    /// `iter.map(|i| body).sum()`: the loop and the body.
    fn index_sum<'e>(
        &self,
        m: &'e syn::ExprMethodCall,
        loops: &[Loop],
    ) -> Option<(Loop, &'e Expr)> {
        if m.turbofish.is_some() {
            return None;
        }
        let Expr::MethodCall(map) = &*m.receiver else {
            return None;
        };
        if map.method != "map" || map.turbofish.is_some() || map.args.len() != 1 {
            return None;
        }
        let Some(Expr::Closure(closure)) = map.args.first() else {
            return None;
        };
        if closure.inputs.len() != 1 || closure.capture.is_some() {
            return None;
        }
        let var = pat_ident(closure.inputs.first()?)?;
        let body = &*closure.body;
        Some((self.iterator(var, &map.receiver, body, loops)?, body))
    }

    /// A loop over `iter`: integers that depend on nothing but constants, and of type
    /// `usize` in the dense code too (the per-term kernels take the loop variable as a
    /// `usize`).
    fn iterator(&self, var: &Ident, iter: &Expr, body: &Expr, loops: &[Loop]) -> Option<Loop> {
        if loops.iter().any(|l| l.var == *var) {
            return None;
        }
        if mentions_coordinate(self.env, iter) {
            return None;
        }
        let l = quietly(self.env, loops, |lw| lw.expr(iter))?;
        if l.kind != Kind::Iter(Box::new(Kind::Int)) || !l.uses.is_empty() || !l.names.is_empty() {
            return None;
        }
        let lp = Loop {
            var: var.clone(),
            iter: l.tokens,
            range: l.range,
        };
        let mut all = loops.to_vec();
        all.push(lp.clone());
        self.loop_var_is_usize(&all, iter, body).then_some(lp)
    }

    /// Whether the dense code's loop variable is certainly a `usize`: a bound of the range
    /// is a const parameter or a `usize` literal, or the body indexes a coordinate array with an
    /// expression of the variable that the dense lowering proves in range (a plain
    /// `q[...]`, whose index is a `usize`). Otherwise its type is Rust's inference's choice.
    fn loop_var_is_usize(&self, loops: &[Loop], iter: &Expr, body: &Expr) -> bool {
        let mut range = iter;
        let bounds = loop {
            match range {
                Expr::Paren(p) => range = &p.expr,
                Expr::MethodCall(m) => range = &m.receiver,
                Expr::Range(r) => break r,
                _ => return false,
            }
        };
        let by_const = [&bounds.start, &bounds.end]
            .into_iter()
            .flatten()
            .any(|b| self.env.const_params.iter().any(|p| mentions(b, p)) || usize_literal(b));
        if by_const {
            return true;
        }
        let Some(lp) = loops.last() else {
            return false;
        };
        let indexed = IndexedBy::find(body, &lp.var);
        let unproven = quietly(self.env, loops, |lw| {
            let _ = lw.expr(body);
            lw.checked_index.get()
        });
        indexed && unproven == Some(false)
    }

    /// One term `weight · body` (at every value of the loop, if any).
    fn leaf(
        &self,
        body: &Expr,
        loops: &[Loop],
        weight: &[TokenStream],
        out: &mut Vec<Local>,
    ) -> Option<()> {
        let local = self.local(body, loops, weight)?;
        // A term that reads no coordinate has no derivatives (its value is in `L` itself).
        if !local.slots.is_empty() {
            out.push(local);
        }
        Some(())
    }

    /// The slots and the lowered body of a term.
    fn local(&self, body: &Expr, loops: &[Loop], weight: &[TokenStream]) -> Option<Local> {
        let vars: Vec<Ident> = loops.iter().map(|l| l.var.clone()).collect();
        if !binders_ok(self.env, body, &vars) {
            return None;
        }
        let mut rw = Rewrite {
            env: self.env,
            vars,
            keys: Vec::new(),
            ok: true,
        };
        let mut body = body.clone();
        rw.visit_expr_mut(&mut body);
        if !rw.ok {
            return None;
        }
        let env = rw.synthetic_env();
        let lowered = quietly(&env, loops, |lw| {
            let index: Vec<Option<Lowered>> = rw
                .keys
                .iter()
                .map(|k| k.index.as_ref().map(|e| lw.expr(e)))
                .collect();
            (lw.expr(&body), index)
        })?;
        let (body, index) = lowered;
        let tokens = match body.kind {
            Kind::Dual => body.tokens.clone(),
            Kind::Real | Kind::Int => body.as_dual(Span::call_site()),
            _ => return None,
        };
        if body.uses.len() > MAX_SLOTS {
            return None;
        }
        let mut slots = Vec::new();
        for u in &body.uses {
            let key = rw.keys.get(u.group)?;
            let g = self.env.groups.get(key.group)?;
            let (offset, len) = (g.offset, &g.len);
            let index = match index.get(u.group)? {
                Some(ix) if ix.kind == Kind::Int => {
                    let t = &ix.tokens;
                    quote!(::forced_vi::__private::slot_index(#t, #offset, #len))
                }
                Some(_) => return None,
                None => quote!(#offset),
            };
            let ident = if u.vel {
                env.groups.get(u.group)?.velocity.clone()
            } else {
                env.groups.get(u.group)?.name.clone()
            };
            slots.push(Slot {
                ident,
                index,
                vel: u.vel,
            });
        }
        // An empty factor stands for `-1`.
        let negative = weight.iter().filter(|w| w.is_empty()).count() % 2 == 1;
        let factors: Vec<&TokenStream> = weight.iter().filter(|w| !w.is_empty()).collect();
        let product = factors
            .split_first()
            .map(|(first, rest)| quote!((#first) #(* (#rest))*));
        let weight = match (product, negative) {
            (Some(p), false) => Some(p),
            (Some(p), true) => Some(quote!(-(#p))),
            (None, true) => Some(quote!(-1.0)),
            (None, false) => None,
        };
        Some(Local {
            loops: loops
                .iter()
                .map(|l| (l.var.clone(), l.iter.clone()))
                .collect(),
            weight,
            row: None,
            slots,
            body: tokens,
            uses_time: body.names.contains(TIME),
        })
    }

    /// One force entry: its rows, as a loop over the index variable for `q[i] = …`.
    fn force_entry(&self, c: &Checked, f: &crate::check::ForceFn) -> Option<Local> {
        let force = c.model.force.as_ref()?;
        let entry = force.entries.iter().find(|e| e.target == f.target_name)?;
        let g = self.env.groups.get(f.group)?;
        let (offset, len) = (g.offset, &g.len);
        let value = match (&entry.value, f.element) {
            (Expr::Array(a), Some(k)) => a.elems.iter().nth(k)?,
            (e, None) => e,
            _ => return None,
        };
        let (loops, row) = match (&f.index, f.element) {
            (Some(i), _) => {
                let range = len.literal().and_then(|n| {
                    Some(IntRange {
                        lo: 0,
                        hi: i64::try_from(n).ok()? - 1,
                        exact: true,
                    })
                });
                let lp = Loop {
                    var: i.clone(),
                    iter: quote!(0usize..#len),
                    range,
                };
                (vec![lp], quote!(#offset + #i))
            }
            (None, Some(k)) => (Vec::new(), quote!(#offset + #k)),
            (None, None) => (Vec::new(), quote!(#offset)),
        };
        let mut local = self.local(value, &loops, &[])?;
        local.row = Some(row);
        Some(local)
    }
}

/// Lowers with errors discarded; `None` if the lowering reported any.
fn quietly<T>(env: &Env, loops: &[Loop], f: impl FnOnce(&mut Lowerer<'_>) -> T) -> Option<T> {
    let cx = Ctxt::default();
    let mut lw = Lowerer::new(&cx, env, "a term");
    for l in loops {
        lw.bind_index(&l.var, l.range);
    }
    let out = f(&mut lw);
    cx.check().ok().map(|()| out)
}

/// `{ let mut s = 0.0; for i in … { let …; s += e; } … s }`: per part, its loop (if any), its
/// summand and whether it is subtracted. `None` if the block has any other shape.
#[allow(clippy::type_complexity)]
fn accumulation(b: &syn::Block) -> Option<Vec<(Option<(&Ident, &Expr)>, Expr, bool)>> {
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
fn accumulate<'e>(s: &'e Stmt, acc: &Ident) -> Option<(&'e Expr, bool)> {
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
fn usize_literal(e: &Expr) -> bool {
    match e {
        Expr::Paren(p) => usize_literal(&p.expr),
        Expr::Lit(l) => matches!(&l.lit, syn::Lit::Int(i) if i.suffix() == "usize"),
        _ => false,
    }
}

/// Whether some coordinate index in an expression mentions a variable.
struct IndexedBy<'a> {
    var: &'a Ident,
    found: bool,
}

impl IndexedBy<'_> {
    fn find(e: &Expr, var: &Ident) -> bool {
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
fn mentions_coordinate(env: &Env, e: &Expr) -> bool {
    env.groups
        .iter()
        .any(|g| mentions(e, &g.name) || mentions(e, &g.velocity))
}

/// Whether `name` occurs anywhere in `t` as an identifier.
fn mentions(t: &impl ToTokens, name: &Ident) -> bool {
    fn walk(t: TokenStream, name: &str) -> bool {
        t.into_iter().any(|tt| match tt {
            proc_macro2::TokenTree::Ident(i) => i == name,
            proc_macro2::TokenTree::Group(g) => walk(g.stream(), name),
            _ => false,
        })
    }
    walk(t.to_token_stream(), &name.to_string())
}

fn pat_ident(p: &syn::Pat) -> Option<&Ident> {
    match p {
        syn::Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => Some(&pi.ident),
        syn::Pat::Type(pt) => pat_ident(&pt.pat),
        _ => None,
    }
}

/// Whether `body` binds none of the names the rewrite relies on: the loop variable, the
/// coordinates and velocities, the const parameters and `t`.
fn binders_ok(env: &Env, body: &Expr, vars: &[Ident]) -> bool {
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
struct Key {
    group: usize,
    text: String,
    index: Option<Expr>,
}

/// Replaces `q[e]`, `q_dot[e]` and scalar coordinates by slot stand-ins.
struct Rewrite<'a> {
    env: &'a Env,
    vars: Vec<Ident>,
    keys: Vec<Key>,
    ok: bool,
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
    fn synthetic_env(&self) -> Env {
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

#[cfg(test)]
mod tests {
    use proc_macro2::TokenStream;
    use quote::quote;

    fn expand(args: TokenStream) -> String {
        crate::entry(
            args,
            quote!(
                struct M<const N: usize> {
                    k: f64,
                    c: f64,
                }
            ),
        )
        .to_string()
    }

    fn splits(args: TokenStream) -> bool {
        let out = expand(args);
        assert!(!out.contains("compile_error"), "{out}");
        let has_impl = out.contains("SparseNode for M");
        assert_eq!(has_impl, out.contains("fn sparse_node"));
        has_impl
    }

    #[test]
    fn index_sums_split() {
        let kinetic_for_nested = quote!((0..N).map(|i| q_dot[i] * q_dot[i]).sum());
        // The spring chain of `src/models.rs`, with guarded neighbours.
        assert!(splits(quote!(
            coordinates(q: [f64; N]),
            lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
                - (0..=N).map(|i| {
                    let left = if i == 0 { 0.0 } else { q[i - 1] };
                    let right = if i == N { 0.0 } else { q[i] };
                    let d = right - left;
                    0.5 * k * d * d + 0.25 * c * d.powi(4)
                }).sum(),
            force(q[i] = -c * q_dot[i]),
        )));
        // Constant factors, division by a constant, negation, nesting of ±.
        assert!(splits(quote!(
            coordinates(q: [f64; N]),
            lagrangian = k * ((0..N).map(|i| q_dot[i] * q_dot[i]).sum() / 2.0
                - -(1..N).map(|i| (q[i] * q[i - 1]).cos()).sum()) - q[0],
        )));
        // Nested index sums: all pairs, the inner range starting at the outer variable.
        assert!(splits(quote!(
            coordinates(q: [f64; N]),
            lagrangian = #kinetic_for_nested
                - (0..N).map(|i| (i + 1..N).map(|j| k * (q[i] - q[j]).powi(2)).sum()).sum(),
        )));
        // `for` accumulations, with `let`s in the loop body and `-=`.
        assert!(splits(quote!(
            coordinates(q: [f64; N]),
            lagrangian = {
                let mut s = 0.0;
                for i in 0..N {
                    let w = 1.0 + q[i] * q[i];
                    s += w * q_dot[i] * q_dot[i];
                }
                for i in 1..N {
                    s -= (q[i] - q[i - 1]).sinh();
                }
                s
            },
        )));
    }

    #[test]
    fn non_local_models_do_not_split() {
        let kinetic = quote!((0..N).map(|i| q_dot[i] * q_dot[i]).sum());
        for l in [
            // A sum used nonlinearly.
            quote!(#kinetic - (0..N).map(|i| q[i]).sum().powi(2)),
            // A product of sums.
            quote!(#kinetic * (0..N).map(|i| q[i]).sum()),
            // An index through a local.
            quote!(#kinetic - (0..N).map(|i| { let j = i + 1; q[j % N] }).sum()),
            // A nested sum whose range depends on a coordinate.
            quote!(#kinetic - (0..N).map(|i| (0..N).map(|j| q[i] * q[j]).sum() * q[0]).sum()),
            // The whole array.
            quote!(#kinetic - (0..N).map(|i| q[i] * q.len() as f64).sum()),
            // A coordinate's name rebound in the term.
            quote!(#kinetic - (0..N).map(|i| { let q_dot = 2.0; q[i] * q_dot }).sum()),
            // The loop variable rebound.
            quote!(#kinetic - (0..N).map(|i| { let i = 0; q[i] }).sum()),
            // A range over the array's length.
            quote!(#kinetic - (0..q.len()).map(|i| q[i] * k).sum()),
            // A product over an index is not a sum.
            quote!(#kinetic - (0..N).map(|i| q[i] * k).product()),
        ] {
            assert!(
                !splits(quote!(coordinates(q: [f64; N]), lagrangian = #l)),
                "{l}"
            );
        }
        // A force entry that reads the whole array.
        assert!(!splits(quote!(
            coordinates(q: [f64; N]),
            lagrangian = #kinetic,
            force(q[i] = -c * (0..N).map(|j| q_dot[j]).sum()),
        )));
    }

    #[test]
    fn large_models_compute_dense_blocks_through_the_terms() {
        let out = expand(quote!(
            coordinates(q: [f64; N]),
            lagrangian = (0..N).map(|i| q_dot[i] * q_dot[i] * (1.0 + q[i].cos())).sum(),
            force(q[i] = -c * q_dot[i] * q[i]),
        ));
        // No whole-model dual numbers (`N × N` types) anywhere.
        assert!(out.contains("DenseAccum"), "{out}");
        assert!(!out.contains("term_hessian") && !out.contains("term_cross"));
        assert!(!out.contains("force_jacobian_q") && !out.contains("Dual2SVec64 < N >"));
        assert!(out.contains("split_stack_bytes"));
    }

    #[test]
    fn small_literal_models_keep_their_dense_kernels() {
        let out = crate::entry(
            quote!(
                coordinates(x, y),
                lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
                    - 0.5 * (x * x + y * y)
                    - k * (x - y).cos(),
                force(x = -c * x_dot, y = (c - y * y) * y_dot),
            ),
            quote!(
                struct P {
                    k: f64,
                    c: f64,
                }
            ),
        )
        .to_string();
        assert!(out.contains("SparseNode for P"), "{out}");
        assert!(!out.contains("DenseAccum") && out.contains("fn node_jacobian"));
    }

    #[test]
    fn a_large_literal_model_must_split() {
        let big = |l: TokenStream| {
            crate::entry(
                quote!(coordinates(q: [f64; 2048]), lagrangian = #l),
                quote!(
                    struct B {
                        k: f64,
                    }
                ),
            )
            .to_string()
        };
        let kinetic = quote!((0..2048).map(|i| q_dot[i] * q_dot[i]).sum());
        let out = big(quote!(#kinetic - k * (1..2048).map(|i| q[i] * q[i - 1]).sum()));
        assert!(!out.contains("compile_error") && out.contains("SparseNode for B"));
        let out = big(quote!(#kinetic - k * (0..2048).map(|i| q[i]).sum().powi(2)));
        assert!(out.contains("compile_error") && out.contains("does not split"));
    }
}
