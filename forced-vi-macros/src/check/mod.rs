//! The check phase: one function per rule, each recording its errors in the [`Ctxt`] and
//! going on, then the analysis that the expand phase consumes (kinds, uses, polynomials).
//!
//! The rules on the struct and its coordinates are in `rules`, the rule on the force and
//! the analysis of its rows in `force`; this module runs them and analyses the Lagrangian.

use std::collections::BTreeSet;

use quote::quote;
use syn::{Expr, Ident};

use crate::ast::Model;
use crate::ctxt::Ctxt;
use crate::lower::{Env, Idx, Kind, Len, Lowered, Lowerer, Var, TIME};
use crate::poly::{Atoms, Extractor, Monomial, Poly};

mod force;
mod rules;

use force::{check_force, checked_force};
pub use rules::check_dense_size;
use rules::{
    check_coordinates, check_fields, check_generics, check_lagrangian_uses_velocity, total_len,
};

/// A checked model, ready for code generation.
pub struct Checked<'a> {
    pub model: &'a Model,
    pub env: Env,
    /// The number of degrees of freedom.
    pub n: Len,
    /// The whole Lagrangian, lowered.
    pub lagrangian: Lowered,
    /// The terms of the Lagrangian that are not polynomials (differentiated with duals).
    pub dual_terms: Vec<Term>,
    /// The sum of the polynomial terms (differentiated symbolically).
    pub poly_l: Poly,
    /// The force, if any.
    pub force: Option<CheckedForce>,
    /// Opaque constants used by the polynomials.
    pub atoms: Atoms,
    pub constant_mass: bool,
    /// `L` is a polynomial of degree at most two and every force component one of degree
    /// at most one in the coordinates and velocities (a literal number of coordinates, no
    /// time): the node Jacobian blocks are constant.
    pub linear: bool,
    /// The Lagrangian or the force names the time `t`.
    pub uses_time: bool,
    /// Some index of the Lagrangian, the force or a constraint is checked at run time: generate
    /// `check_model`.
    pub checked_index: bool,
    /// The holonomic constraints `g_k(t, q)`, lowered (DESIGN §11).
    pub constraints: Vec<Lowered>,
}

/// The largest number of coordinates of a model with a literal length (a larger one is
/// refused at its length).
pub const MAX_COORDINATES: usize = 16384;

/// The largest literal number of coordinates of a model that does not split into local
/// terms: its dense kernels differentiate the whole model at once, with `N × N` blocks.
pub const MAX_DENSE_COORDINATES: usize = 1024;

/// A term of the Lagrangian with its sign applied.
pub struct Term {
    pub lowered: Lowered,
}

/// The force: the functions that compute its components, and per row what they use.
pub struct CheckedForce {
    pub fns: Vec<ForceFn>,
    /// One per coordinate for a literal number of coordinates; empty for a const-generic one.
    pub rows: Vec<Row>,
    pub uses_q: bool,
    pub uses_v: bool,
}

/// A generated function for one force entry: `x = ...`, `q[i] = ...` or an array element.
pub struct ForceFn {
    /// The coordinate group the entry is for.
    pub group: usize,
    /// `i` in `q[i] = ...`.
    pub index: Option<Ident>,
    /// For an element of `q = [...]`, its position.
    pub element: Option<usize>,
    pub lowered: Lowered,
    /// The coordinate's name.
    pub target_name: String,
    /// Some index in it is checked at run time.
    pub checked: bool,
}

/// One component of the force.
pub struct Row {
    pub row: usize,
    pub func: usize,
    /// The value of the index variable for this row.
    pub index: Option<usize>,
    pub uses: BTreeSet<Var>,
    pub poly: Option<Poly>,
}

/// Runs every rule; returns the analysis if no rule failed.
pub fn check<'a>(cx: &Ctxt, model: &'a Model) -> Option<Checked<'a>> {
    check_as(cx, model, false)
}

/// [`check`], with the parameters as `__D` values if `params_dual`. The split into local
/// terms ([`crate::split`]) and the rule that needs it ([`check_dense_size`]) come after.
pub fn check_as<'a>(cx: &Ctxt, model: &'a Model, params_dual: bool) -> Option<Checked<'a>> {
    check_fields(cx, model);
    let const_params = check_generics(cx, model);
    let groups = check_coordinates(cx, model, &const_params);
    let n = total_len(cx, model, &groups);
    let env = Env {
        groups,
        params: model.params.iter().map(|p| p.ident.clone()).collect(),
        const_params,
        model: model.item.ident.clone(),
        params_dual,
    };
    let (_, lagrangian) = model.lagrangian.as_ref()?;
    let before = cx.error_count();
    let mut lower_l = Lowerer::new(cx, &env, "the Lagrangian");
    let lowered = lower_l.expr(lagrangian);
    let l_checked = lower_l.checked_index.get();
    // Only on a Lagrangian lowered whole: an unsupported part records no names, and the
    // rule would then call a Lagrangian with a kinetic term in that part velocity-free.
    if cx.error_count() == before {
        check_lagrangian_uses_velocity(cx, &env, lagrangian, &lowered);
    }
    let force_fns = model.force.as_ref().map(|f| check_force(cx, &env, f));
    let (constraints, constraints_checked) = check_constraints(cx, &env, model, &n);
    let n = n?;
    if cx.has_errors() {
        return None;
    }
    let mut extractor = Extractor {
        env: &env,
        n: n.literal().unwrap_or(0),
        atoms: Atoms::default(),
        index: None,
    };
    let symbolic = n.literal().is_some();
    let (poly_l, dual_terms, constant_mass) =
        lagrangian_terms(&env, lagrangian, &mut extractor, symbolic);
    let force = force_fns.map(|fns| checked_force(model, &env, &n, fns, &mut extractor));
    let atoms = extractor.atoms;
    let linear = symbolic && is_linear(&poly_l, &dual_terms, force.as_ref(), extractor.n);
    let uses_time = lowered.names.contains(TIME)
        || force
            .as_ref()
            .is_some_and(|f| f.fns.iter().any(|func| func.lowered.names.contains(TIME)));
    let uses_time = uses_time || constraints.iter().any(|c| c.names.contains(TIME));
    let checked_index = l_checked
        || constraints_checked
        || force
            .as_ref()
            .is_some_and(|f| f.fns.iter().any(|func| func.checked));
    let checked = Checked {
        model,
        env,
        n,
        lagrangian: lowered,
        dual_terms,
        poly_l,
        force,
        atoms,
        constant_mass,
        linear,
        uses_time,
        checked_index,
        constraints,
    };
    Some(checked)
}

/// The `constraints(...)` argument: each expression lowered, reading no velocity (only
/// holonomic constraints are supported), fewer constraints than coordinates.
fn check_constraints(cx: &Ctxt, env: &Env, model: &Model, n: &Option<Len>) -> (Vec<Lowered>, bool) {
    let Some((key, exprs)) = model.constraints.as_ref() else {
        return (Vec::new(), false);
    };
    if let Some(n) = n.as_ref().and_then(|n| n.literal()) {
        if exprs.len() >= n {
            cx.error_spanned_by(
                key,
                format!(
                    "{} constraints for {n} coordinates: no coordinate is left free; a constrained model needs fewer constraints than coordinates",
                    exprs.len()
                ),
            );
        }
    }
    let velocities: Vec<String> = env.groups.iter().map(|g| g.velocity.to_string()).collect();
    let (mut out, mut checked) = (Vec::new(), false);
    for (k, e) in exprs.iter().enumerate() {
        let mut lw = Lowerer::new(cx, env, format!("constraint {}", k + 1));
        let l = lw.expr(e);
        checked |= lw.checked_index.get();
        if let Some(v) = velocities.iter().find(|v| l.names.contains(*v)) {
            // Point at the velocity itself where it is written.
            let at = velocity_token(e, v);
            let msg = format!(
                "constraint {} reads the velocity `{v}`: only holonomic constraints g(t, q) = 0 are supported (nonholonomic, velocity-dependent constraints are not)",
                k + 1
            );
            match at {
                Some(tok) => cx.error_spanned_by(tok, msg),
                None => cx.error_spanned_by(e, msg),
            }
        }
        out.push(l);
    }
    (out, checked)
}

/// The first token of `e` named `name`.
fn velocity_token(e: &Expr, name: &str) -> Option<proc_macro2::Ident> {
    fn find(ts: proc_macro2::TokenStream, name: &str) -> Option<proc_macro2::Ident> {
        for t in ts {
            match t {
                proc_macro2::TokenTree::Ident(i) if i == name => return Some(i),
                proc_macro2::TokenTree::Group(g) => {
                    if let Some(i) = find(g.stream(), name) {
                        return Some(i);
                    }
                }
                _ => {}
            }
        }
        None
    }
    find(quote::ToTokens::to_token_stream(e), name)
}

/// Splits `L` into terms: the sum of the polynomials (with `symbolic`, for a literal number
/// of coordinates), the other terms with their dual code, and whether the mass matrix is
/// constant.
fn lagrangian_terms(
    env: &Env,
    lagrangian: &Expr,
    extractor: &mut Extractor<'_>,
    symbolic: bool,
) -> (Poly, Vec<Term>, bool) {
    // Split L into terms; polynomials go to `poly_l`, the rest keep their dual code.
    let mut terms = Vec::new();
    split_terms(lagrangian, false, &mut terms);
    let mut poly_l = Poly::default();
    let mut dual_terms = Vec::new();
    let mut constant_mass = true;
    for (negative, e) in terms {
        let quiet = Ctxt::default();
        let mut l = Lowerer::new(&quiet, env, "the Lagrangian").expr(e);
        let _ = quiet.check();
        if l.kind != Kind::Dual || l.uses.is_empty() {
            continue;
        }
        // A term with a velocity and the time may make the mass matrix depend on `t`.
        if l.names.contains(TIME) && l.uses.iter().any(|u| u.vel) {
            constant_mass = false;
        }
        let poly = if symbolic { extractor.poly(e) } else { None };
        let poly = match (poly, negative) {
            (Some(p), true) => p.negated(),
            (p, _) => p,
        };
        // A polynomial term is differentiated at compile time only if the sum stays
        // representable and so do its first and second derivatives (an overflowing
        // coefficient would otherwise be lost); else it takes the dual-number path.
        if let Some(p) = poly.filter(|p| {
            let mut sum = poly_l.clone();
            sum.add(p).is_some() && sum.derivatives_ok(2)
        }) {
            let _ = poly_l.add(&p);
            continue;
        }
        let uses_q = l.uses.iter().any(|u| !u.vel);
        let uses_v = l.uses.iter().any(|u| u.vel);
        if uses_v && !(l.degree.q == Some(0) && l.degree.v.is_some_and(|d| d <= 2)) {
            constant_mass = false;
        }
        let _ = uses_q;
        if negative {
            let t = &l.tokens;
            l.tokens = if l.atomic { quote!(-#t) } else { quote!(-(#t)) };
        }
        dual_terms.push(Term { lowered: l });
    }
    constant_mass &= poly_mass_is_constant(&poly_l, extractor.n);
    (poly_l, dual_terms, constant_mass)
}

/// Whether the polynomial part of `L` (over `nn` coordinates) has a constant mass matrix:
/// no monomial with a velocity and a coordinate, or with more than two velocities.
fn poly_mass_is_constant(poly_l: &Poly, nn: usize) -> bool {
    let mut constant_mass = true;
    for m in poly_l.monomials() {
        let dq: u32 = m.iter().filter(|(s, _)| *s < nn).map(|(_, e)| e).sum();
        let dv: u32 = m.iter().filter(|(s, _)| *s >= nn).map(|(_, e)| e).sum();
        if dv > 0 && (dq > 0 || dv > 2) {
            constant_mass = false;
        }
    }
    constant_mass
}

/// Whether the model's step equations are linear with constant coefficients: every term of
/// `L` a polynomial (`poly_l`, no `dual_terms`) of degree at most two in the coordinates
/// and velocities, and every force component a polynomial of degree at most one (`nn`
/// coordinates). The time is not a polynomial variable: a term that names it is neither.
/// Coefficients are numbers and parameters, which do not change during a run.
fn is_linear(poly_l: &Poly, dual_terms: &[Term], force: Option<&CheckedForce>, nn: usize) -> bool {
    let degree =
        |m: &Monomial| -> u32 { m.iter().filter(|(s, _)| *s < 2 * nn).map(|(_, e)| e).sum() };
    // (Every slot is a coordinate or a velocity; one that were not would claim nothing.)
    let in_range = |m: &Monomial| m.iter().all(|(s, _)| *s < 2 * nn);
    let l_ok = dual_terms.is_empty() && poly_l.monomials().all(|m| in_range(m) && degree(m) <= 2);
    let f_ok = force.is_none_or(|f| {
        f.rows.iter().all(|r| {
            r.poly
                .as_ref()
                .is_some_and(|p| p.monomials().all(|m| in_range(m) && degree(m) <= 1))
        })
    });
    nn > 0 && l_ok && f_ok
}

/// Splits a sum at its top level (through parentheses and negation) into signed terms.
pub fn split_terms<'e>(e: &'e Expr, negative: bool, out: &mut Vec<(bool, &'e Expr)>) {
    match e {
        Expr::Binary(b) if matches!(b.op, syn::BinOp::Add(_)) => {
            split_terms(&b.left, negative, out);
            split_terms(&b.right, negative, out);
        }
        Expr::Binary(b) if matches!(b.op, syn::BinOp::Sub(_)) => {
            split_terms(&b.left, negative, out);
            split_terms(&b.right, !negative, out);
        }
        Expr::Paren(p) => split_terms(&p.expr, negative, out),
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => split_terms(&u.expr, !negative, out),
        other => out.push((negative, other)),
    }
}

/// What a set of uses means in slots, for a literal number of coordinates `n`:
/// `q[s]` is slot `s`, `v[s]` is slot `n + s`.
pub fn slots(env: &Env, n: usize, uses: &BTreeSet<Var>) -> Vec<usize> {
    let mut out = BTreeSet::new();
    for u in uses {
        let g = &env.groups[u.group];
        let base = g.offset + if u.vel { n } else { 0 };
        match u.idx {
            Idx::At(k) => {
                out.insert(base + k);
            }
            Idx::All => {
                for k in 0..g.len.literal().unwrap_or(0) {
                    out.insert(base + k);
                }
            }
        }
    }
    out.into_iter().collect()
}
