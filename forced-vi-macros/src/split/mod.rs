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

use proc_macro2::{Span, TokenStream};
use quote::quote;
use syn::visit_mut::VisitMut;
use syn::{BinOp, Expr, Ident, UnOp};

use crate::check::Checked;
use crate::ctxt::Ctxt;
use crate::lower::{Env, IntRange, Kind, Lowered, Lowerer, TIME};

mod syntax;
use syntax::{
    accumulation, binders_ok, mentions, mentions_coordinate, pat_ident, usize_literal, IndexedBy,
    Rewrite,
};

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
    /// The constant factor (sign included), an `f64` expression (a `__D` one in a model
    /// read with its parameters as duals, where it may hold parameters); `None` for 1.
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
        match e {
            Expr::Paren(p) => self.decompose(&p.expr, loops, weight, out),
            Expr::Group(g) => self.decompose(&g.expr, loops, weight, out),
            Expr::Unary(u) if matches!(u.op, UnOp::Neg(_)) => {
                self.decompose(&u.expr, loops, &with(weight, negative()), out)
            }
            Expr::Binary(b) => self.decompose_binary(e, b, loops, weight, out),
            Expr::MethodCall(m) if m.method == "sum" && m.args.is_empty() => {
                match self.index_sum(m, loops) {
                    Some((lp, body)) => self.decompose(body, &within(loops, lp), weight, out),
                    None => self.leaf(e, loops, weight, out),
                }
            }
            // `{ e }` is `e` (rustfmt writes a nested sum's closure body this way).
            Expr::Block(b) if b.label.is_none() && tail_only(&b.block).is_some() => {
                match tail_only(&b.block) {
                    Some(inner) => self.decompose(inner, loops, weight, out),
                    None => self.leaf(e, loops, weight, out),
                }
            }
            Expr::Block(b) if b.label.is_none() => match accumulation(&b.block) {
                Some(parts) => self.decompose_accumulation(parts, loops, weight, out),
                None => self.leaf(e, loops, weight, out),
            },
            _ => self.leaf(e, loops, weight, out),
        }
    }

    /// A sum or difference (split into its operands), or a product or quotient with a
    /// constant factor (which joins the weight); anything else is one term (`e`).
    fn decompose_binary(
        &self,
        e: &Expr,
        b: &syn::ExprBinary,
        loops: &[Loop],
        weight: &[TokenStream],
        out: &mut Vec<Local>,
    ) -> Option<()> {
        match b.op {
            BinOp::Add(_) | BinOp::Sub(_) => {
                let right = if matches!(b.op, BinOp::Sub(_)) {
                    with(weight, negative())
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
                (Some(f), _) => self.decompose(&b.right, loops, &with(weight, f), out),
                (None, Some(f)) => self.decompose(&b.left, loops, &with(weight, f), out),
                _ => self.leaf(e, loops, weight, out),
            },
            BinOp::Div(_) => match self.constant(&b.right, loops) {
                Some(f) => self.decompose(&b.left, loops, &with(weight, self.reciprocal(f)), out),
                None => self.leaf(e, loops, weight, out),
            },
            _ => self.leaf(e, loops, weight, out),
        }
    }

    /// The parts of an accumulation block (see `syntax::accumulation`): each `for` loop's
    /// body inside its loop, each other part as it is, with its sign.
    #[allow(clippy::type_complexity)]
    fn decompose_accumulation(
        &self,
        parts: Vec<(Option<(&Ident, &Expr)>, Expr, bool)>,
        loops: &[Loop],
        weight: &[TokenStream],
        out: &mut Vec<Local>,
    ) -> Option<()> {
        for (var_iter, body, negative_part) in parts {
            let w = if negative_part {
                with(weight, negative())
            } else {
                weight.to_vec()
            };
            match var_iter {
                Some((var, iter)) => {
                    let lp = self.iterator(var, iter, &body, loops)?;
                    self.decompose(&body, &within(loops, lp), &w, out)?;
                }
                None => self.decompose(&body, loops, &w, out)?,
            }
        }
        Some(())
    }

    /// A constant factor (literals, parameters and loop variables, no coordinate and no
    /// time) as tokens: an `f64` expression, or, in a model read with its parameters as
    /// duals (`params_dual`), a `__D` one (each factor, so that their product is one too).
    fn constant(&self, e: &Expr, loops: &[Loop]) -> Option<TokenStream> {
        let l = quietly(self.env, loops, |lw| lw.expr(e))?;
        // Only parameters by name: not the time, nor a coordinate array (`q.len()`).
        let constant = l.uses.is_empty()
            && l.names
                .iter()
                .all(|n| self.env.params.iter().any(|p| p == n))
            && !mentions_coordinate(self.env, e);
        let tokens = match l.kind {
            Kind::Real | Kind::Int if constant => Some(l.as_real()),
            Kind::Dual if constant && self.env.params_dual => Some(l.as_real()),
            _ => None,
        }
        .filter(|t| !t.is_empty())?;
        Some(match (self.env.params_dual, l.kind) {
            (true, Kind::Real | Kind::Int) => quote!(__D::from(#tokens)),
            _ => tokens,
        })
    }

    /// The reciprocal `1 / f` of a constant factor `f` (see [`Self::constant`]).
    fn reciprocal(&self, f: TokenStream) -> TokenStream {
        if self.env.params_dual {
            quote!(__D::from(1.0) / (#f))
        } else {
            quote!(1.0 / #f)
        }
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
        let input = closure.inputs.first()?;
        // The per-term kernels take the variable as a `usize`: no other declared type.
        if let syn::Pat::Type(t) = input {
            if !matches!(&*t.ty, syn::Type::Path(p) if p.path.is_ident("usize")) {
                return None;
            }
        }
        let var = pat_ident(input)?;
        let body = &*closure.body;
        Some((self.iterator(var, &map.receiver, body, loops)?, body))
    }

    /// Whether a loop variable's name is free for a term's kernel: not a coordinate's or its
    /// velocity's (the rewrite reads a bare scalar coordinate's name as that coordinate: a
    /// loop `|x|` beside a coordinate `x` ran on the coordinate), not a const parameter's or
    /// `t` (which the kernel binds), nor one of the generated code's. A parameter's name is
    /// free: the kernel leaves that parameter unbound (see `sparse::term_fn`). Otherwise
    /// the model keeps its dense kernels.
    fn free_name(&self, var: &Ident) -> bool {
        let name = var.to_string();
        let env = self.env;
        !(name == TIME
            || name.starts_with("__fvi")
            || env.const_params.iter().any(|p| *p == name)
            || env
                .groups
                .iter()
                .any(|g| g.name == name || g.velocity == name))
    }

    /// A loop over `iter`: integers that depend on nothing but constants, and of type
    /// `usize` in the dense code too (the per-term kernels take the loop variable as a
    /// `usize`).
    fn iterator(&self, var: &Ident, iter: &Expr, body: &Expr, loops: &[Loop]) -> Option<Loop> {
        if loops.iter().any(|l| l.var == *var) || !self.free_name(var) {
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
        let weight = weight_tokens(weight);
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
            (Some(i), _) if !self.free_name(i) => return None,
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

/// The factor `-1` of a weight (an empty factor).
fn negative() -> TokenStream {
    TokenStream::new()
}

/// `weight` with one more factor.
fn with(weight: &[TokenStream], f: TokenStream) -> Vec<TokenStream> {
    let mut w = weight.to_vec();
    w.push(f);
    w
}

/// `loops` with one more loop inside.
fn within(loops: &[Loop], lp: Loop) -> Vec<Loop> {
    let mut l = loops.to_vec();
    l.push(lp);
    l
}

/// The product of the factors (an empty one is `-1`); `None` for 1.
fn weight_tokens(weight: &[TokenStream]) -> Option<TokenStream> {
    // An empty factor stands for `-1`.
    let negative = weight.iter().filter(|w| w.is_empty()).count() % 2 == 1;
    let factors: Vec<&TokenStream> = weight.iter().filter(|w| !w.is_empty()).collect();
    let product = factors
        .split_first()
        .map(|(first, rest)| quote!((#first) #(* (#rest))*));
    match (product, negative) {
        (Some(p), false) => Some(p),
        (Some(p), true) => Some(quote!(-(#p))),
        (None, true) => Some(quote!(-1.0)),
        (None, false) => None,
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

/// The expression of a block that holds nothing else (`{ e }`).
fn tail_only(block: &syn::Block) -> Option<&Expr> {
    match block.stmts.as_slice() {
        [syn::Stmt::Expr(e, None)] => Some(e),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
