//! The check phase: one function per rule, each recording its errors in the [`Ctxt`] and
//! going on, then the analysis that the expand phase consumes (kinds, uses, polynomials).

use std::collections::{BTreeSet, HashMap};

use quote::quote;
use syn::ext::IdentExt;
use syn::{Expr, Ident, Type};

use crate::ast::{Coord, Force, Model};
use crate::ctxt::Ctxt;
use crate::lower::{
    compact, reserved, reserved_message, time_message, Env, Group, Idx, IntRange, Kind, Len,
    Lowered, Lowerer, Var, TIME,
};
use crate::poly::{Atoms, Extractor, Poly};

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
    /// The Lagrangian or the force names the time `t`.
    pub uses_time: bool,
    /// Some index of the Lagrangian or the force is checked at run time: generate
    /// `check_model`.
    pub checked_index: bool,
    /// The model as local terms, if it splits (DESIGN §9).
    pub split: Option<crate::split::Split>,
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
    check_fields(cx, model);
    let const_params = check_generics(cx, model);
    let groups = check_coordinates(cx, model, &const_params);
    let n = total_len(cx, model, &groups);
    let env = Env {
        groups,
        params: model.params.iter().map(|p| p.ident.clone()).collect(),
        const_params,
        model: model.item.ident.clone(),
    };
    let (_, lagrangian) = model.lagrangian.as_ref()?;
    let mut lower_l = Lowerer::new(cx, &env, "the Lagrangian");
    let lowered = lower_l.expr(lagrangian);
    let l_checked = lower_l.checked_index.get();
    check_lagrangian_uses_velocity(cx, &env, lagrangian, &lowered);
    let force_fns = model.force.as_ref().map(|f| check_force(cx, &env, f));
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

    // Split L into terms; polynomials go to `poly_l`, the rest keep their dual code.
    let mut terms = Vec::new();
    split_terms(lagrangian, false, &mut terms);
    let mut poly_l = Poly::default();
    let mut dual_terms = Vec::new();
    let mut constant_mass = true;
    for (negative, e) in terms {
        let quiet = Ctxt::default();
        let mut l = Lowerer::new(&quiet, &env, "the Lagrangian").expr(e);
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
    let nn = extractor.n;
    for m in poly_l.monomials() {
        let dq: u32 = m.iter().filter(|(s, _)| *s < nn).map(|(_, e)| e).sum();
        let dv: u32 = m.iter().filter(|(s, _)| *s >= nn).map(|(_, e)| e).sum();
        if dv > 0 && (dq > 0 || dv > 2) {
            constant_mass = false;
        }
    }

    let force = force_fns.map(|fns| {
        let mut rows = Vec::new();
        if let Some(total) = n.literal() {
            for (f, func) in fns.iter().enumerate() {
                let group = &env.groups[func.group];
                let len = group.len.literal().unwrap_or(1);
                let elems: Vec<(usize, Option<usize>)> = match (&func.index, func.element) {
                    (Some(_), _) => (0..len).map(|k| (k, Some(k))).collect(),
                    (None, Some(k)) => vec![(k, None)],
                    (None, None) => vec![(0, None)],
                };
                for (k, index) in elems {
                    let entry = entry_expr(model, func);
                    let quiet = Ctxt::default();
                    let mut lw = Lowerer::new(&quiet, &env, "the force");
                    if let (Some(i), Some(value)) = (&func.index, index) {
                        lw.bind_index(i, i64::try_from(value).ok().map(IntRange::point));
                    }
                    let lowered = match entry {
                        Some(e) => lw.expr(e),
                        None => func.lowered.clone(),
                    };
                    let _ = quiet.check();
                    extractor.index = match (&func.index, index) {
                        (Some(i), Some(value)) => {
                            i64::try_from(value).ok().map(|v| (i.to_string(), v))
                        }
                        _ => None,
                    };
                    let poly = entry
                        .and_then(|e| extractor.poly(e))
                        .filter(|p| p.derivatives_ok(1));
                    extractor.index = None;
                    rows.push(Row {
                        row: group.offset + k,
                        func: f,
                        index,
                        uses: lowered.uses,
                        poly,
                    });
                }
            }
            rows.sort_by_key(|r| r.row);
            let _ = total;
        }
        let uses_q = fns.iter().any(|f| f.lowered.uses.iter().any(|u| !u.vel));
        let uses_v = fns.iter().any(|f| f.lowered.uses.iter().any(|u| u.vel));
        CheckedForce {
            fns,
            rows,
            uses_q,
            uses_v,
        }
    });
    let atoms = extractor.atoms;
    let uses_time = lowered.names.contains(TIME)
        || force
            .as_ref()
            .is_some_and(|f| f.fns.iter().any(|func| func.lowered.names.contains(TIME)));
    let checked_index = l_checked
        || force
            .as_ref()
            .is_some_and(|f| f.fns.iter().any(|func| func.checked));
    let mut checked = Checked {
        model,
        env,
        n,
        lagrangian: lowered,
        dual_terms,
        poly_l,
        force,
        atoms,
        constant_mass,
        uses_time,
        checked_index,
        split: None,
    };
    checked.split = crate::split::split(&checked);
    check_dense_size(cx, &checked);
    Some(checked)
}

/// Rule: a model with more than [`MAX_DENSE_COORDINATES`] coordinates (a literal length)
/// splits into local terms; whole-model kernels at that size would need `N × N` dual
/// numbers.
fn check_dense_size(cx: &Ctxt, c: &Checked) {
    let Some(n) = c.n.literal() else { return };
    if n <= MAX_DENSE_COORDINATES || c.split.is_some() {
        return;
    }
    let Some((key, _)) = &c.model.coordinates else {
        return;
    };
    cx.error_spanned_by(
        key,
        format!(
            "too many coordinates for a model that does not split into local terms: {n} > {MAX_DENSE_COORDINATES}; write the Lagrangian as a sum of index sums such as `(0..N).map(|i| ...).sum()` whose terms read `q[i]`, `q[i + 1]`, ... (no whole-array expression), and each force entry likewise"
        ),
    );
}

/// The expression of one force entry (an array element for `q = [...]`).
fn entry_expr<'m>(model: &'m Model, func: &ForceFn) -> Option<&'m Expr> {
    let force = model.force.as_ref()?;
    let group_entries = force.entries.iter();
    for entry in group_entries {
        if entry.target != func.target_name {
            continue;
        }
        return match (&entry.value, func.element) {
            (Expr::Array(a), Some(k)) => a.elems.iter().nth(k),
            (e, None) => Some(e),
            _ => None,
        };
    }
    None
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

/// Rule: the parameters of a model are its named fields, and each is an `f64`. The code
/// differentiates with respect to coordinates only, so parameters enter as plain numbers.
/// Names starting with `__fvi` (and `__D`) are the generated code's own, so a field with
/// such a name is refused rather than silently shadowed.
fn check_fields(cx: &Ctxt, model: &Model) {
    for p in &model.params {
        let name = p.ident.to_string();
        if reserved(&name) {
            cx.error_spanned_by(&p.ident, reserved_message(&name));
        }
        if name == TIME {
            cx.error_spanned_by(&p.ident, time_message("parameter"));
        }
        if !is_f64(&p.ty) {
            let ty = &p.ty;
            cx.error_spanned_by(
                ty,
                format!(
                    "parameter `{}` has type `{}`: the parameters of a model are `f64` fields",
                    p.ident,
                    compact(&quote!(#ty).to_string())
                ),
            );
        }
    }
}

fn is_f64(ty: &Type) -> bool {
    matches!(ty, Type::Path(p) if p.qself.is_none() && p.path.is_ident("f64"))
}

/// Rule: the struct may have const parameters of type `usize` (for an array length), and no
/// type or lifetime parameters: the model's scalar is chosen by the runtime.
fn check_generics(cx: &Ctxt, model: &Model) -> Vec<Ident> {
    let mut out = Vec::new();
    for param in &model.item.generics.params {
        match param {
            syn::GenericParam::Const(c) => {
                let name = c.ident.to_string();
                if reserved(&name) {
                    cx.error_spanned_by(&c.ident, reserved_message(&name));
                }
                if name == TIME {
                    cx.error_spanned_by(&c.ident, time_message("const parameter"));
                }
                if matches!(&c.ty, Type::Path(p) if p.path.is_ident("usize")) {
                    out.push(c.ident.clone());
                } else {
                    cx.error_spanned_by(&c.ty, "a const parameter of a model is a `usize` length");
                }
            }
            other => cx.error_spanned_by(
                other,
                "a model may only have const parameters such as `const N: usize`",
            ),
        }
    }
    if let Some(w) = &model.item.generics.where_clause {
        cx.error_spanned_by(w, "a model takes no `where` clause");
    }
    out
}

/// Rule: coordinates have distinct names, none of which is the velocity of another
/// (`x_dot` is the velocity of `x`) or a parameter; an array coordinate is `q: [f64; LEN]`
/// with `LEN` an integer literal or a const parameter of the struct, and a const-parameter
/// length needs the array to be the only coordinate.
fn check_coordinates(cx: &Ctxt, model: &Model, const_params: &[Ident]) -> Vec<Group> {
    let Some((key, coords)) = &model.coordinates else {
        return Vec::new();
    };
    if coords.is_empty() {
        cx.error_spanned_by(
            key,
            "`coordinates()` is empty: name at least one coordinate",
        );
    }
    let mut seen: BTreeSet<String> = BTreeSet::new();
    let mut groups = Vec::new();
    let mut offset: usize = 0;
    for c in coords {
        let unraw;
        let c = if c.name.to_string().starts_with("r#") {
            cx.error_spanned_by(
                &c.name,
                format!(
                    "a coordinate cannot be a raw identifier (`{}`): its velocity is named by appending `_dot`; choose a plain name",
                    c.name
                ),
            );
            // Registered under its plain name, so that uses of `x` and `x_dot` resolve and
            // the refusal is the only error (a keyword such as `r#fn` has no plain name).
            let plain = c.name.unraw().to_string();
            if syn::parse_str::<Ident>(&plain).is_err() {
                continue;
            }
            unraw = Coord {
                name: Ident::new(&plain, c.name.span()),
                velocity: c.velocity.clone(),
                ty: c.ty.clone(),
            };
            &unraw
        } else {
            c
        };
        let name = c.name.to_string();
        if reserved(&name) {
            cx.error_spanned_by(&c.name, reserved_message(&name));
            continue;
        }
        if name == TIME {
            // Still declared, so that `t_dot` resolves: one error, at this token.
            cx.error_spanned_by(&c.name, time_message("coordinate"));
        }
        if seen.contains(&name) {
            cx.error_spanned_by(&c.name, format!("duplicate coordinate `{name}`"));
            continue;
        }
        if let Some(owner) = coords.iter().find(|o| o.velocity == name) {
            cx.error_spanned_by(
                &c.name,
                format!(
                    "`{name}` is the velocity of `{}`: declare only the coordinate `{}`, its velocity `{name}` comes with it",
                    owner.name, owner.name
                ),
            );
            continue;
        }
        if model.params.iter().any(|p| p.ident == name) {
            cx.error_spanned_by(
                &c.name,
                format!("`{name}` is both a coordinate and a parameter (a field of the struct)"),
            );
        }
        if let Some(p) = model.params.iter().find(|p| p.ident == c.velocity) {
            cx.error_spanned_by(
                &p.ident,
                format!(
                    "the field `{}` has the name of the velocity of `{name}`",
                    p.ident
                ),
            );
        }
        seen.insert(name);
        let (len, array) = match &c.ty {
            None => (Some(Len::Lit(1)), false),
            Some(ty) => (array_len(cx, c, ty, const_params), true),
        };
        // An invalid length has its error; the group still resolves its names.
        let len =
            len.unwrap_or_else(|| Len::Param(Ident::new("__fvi_invalid_length", c.name.span())));
        if let Len::Param(p) = &len {
            if coords.len() != 1 && const_params.contains(p) {
                cx.error_spanned_by(
                    p,
                    format!(
                        "an array whose length is the const parameter `{p}` must be the only coordinate; use a literal length to combine it with others"
                    ),
                );
            }
        }
        groups.push(Group {
            name: c.name.clone(),
            velocity: c.velocity.clone(),
            offset,
            len: len.clone(),
            array,
        });
        match offset
            .checked_add(len.literal().unwrap_or(0))
            .filter(|&n| n <= MAX_COORDINATES)
        {
            Some(n) => offset = n,
            None => {
                cx.error_spanned_by(
                    c.ty.as_ref().map_or_else(
                        || {
                            let name = &c.name;
                            quote!(#name)
                        },
                        |t| quote!(#t),
                    ),
                    format!("too many coordinates: a model has at most {MAX_COORDINATES}"),
                );
                break;
            }
        }
    }
    groups
}

fn array_len(cx: &Ctxt, c: &Coord, ty: &Type, const_params: &[Ident]) -> Option<Len> {
    let Type::Array(arr) = ty else {
        cx.error_spanned_by(
            ty,
            format!(
                "an array coordinate is declared as `{}: [f64; LEN]`",
                c.name
            ),
        );
        return None;
    };
    if !is_f64(&arr.elem) {
        cx.error_spanned_by(&arr.elem, "the entries of an array coordinate are `f64`");
    }
    match &arr.len {
        Expr::Lit(syn::ExprLit {
            lit: syn::Lit::Int(i),
            ..
        }) => match i.base10_parse::<usize>() {
            Ok(0) | Err(_) => {
                cx.error_spanned_by(i, "an array coordinate has at least one entry");
                None
            }
            Ok(n) if n > MAX_COORDINATES => {
                cx.error_spanned_by(
                    i,
                    format!(
                        "array length {n} is too large: a model has at most {MAX_COORDINATES} coordinates"
                    ),
                );
                None
            }
            Ok(n) => Some(Len::Lit(n)),
        },
        Expr::Path(p) if p.path.get_ident().is_some_and(|i| const_params.contains(i)) => {
            p.path.get_ident().map(|i| Len::Param(i.clone()))
        }
        other => {
            cx.error_spanned_by(
                other,
                "the length of an array coordinate is an integer literal or a const parameter of the struct (`struct Chain<const N: usize>`)",
            );
            None
        }
    }
}

fn total_len(cx: &Ctxt, model: &Model, groups: &[Group]) -> Option<Len> {
    if let [g] = groups {
        if let Len::Param(p) = &g.len {
            return Some(Len::Param(p.clone()));
        }
    }
    let _ = (cx, model);
    if groups.is_empty() {
        return None;
    }
    let mut n: usize = 0;
    for g in groups {
        n = n.checked_add(g.len.literal()?)?;
    }
    (n <= MAX_COORDINATES).then_some(Len::Lit(n))
}

/// Rule: a regular Lagrangian depends on the velocities; one that names none of them gives
/// a singular mass matrix, so it is refused at the expression.
fn check_lagrangian_uses_velocity(cx: &Ctxt, env: &Env, expr: &Expr, lowered: &Lowered) {
    if env.groups.is_empty() {
        return;
    }
    let velocities: Vec<String> = env.groups.iter().map(|g| g.velocity.to_string()).collect();
    if !velocities.iter().any(|v| lowered.names.contains(v)) {
        let list = velocities
            .iter()
            .map(|v| format!("`{v}`"))
            .collect::<Vec<_>>()
            .join(", ");
        cx.error_spanned_by(
            expr,
            format!(
                "the Lagrangian uses no velocity ({list}), so its mass matrix is singular; add a kinetic term such as `0.5 * {} * {}`",
                velocities[0], velocities[0]
            ),
        );
    }
}

/// Rule: a force names each coordinate once and only coordinates: `x = ...` for a scalar,
/// `q[i] = ...` or `q = [...]` (with exactly `LEN` entries) for an array. Every coordinate
/// needs an entry once a force is given (write `x = 0.0` for none).
fn check_force(cx: &Ctxt, env: &Env, force: &Force) -> Vec<ForceFn> {
    let mut fns = Vec::new();
    let mut seen: HashMap<String, &Ident> = HashMap::new();
    for entry in &force.entries {
        let name = entry.target.to_string();
        let Some((g, group)) = env.groups.iter().enumerate().find(|(_, g)| g.name == name) else {
            let coords = env
                .groups
                .iter()
                .map(|g| format!("`{}`", g.name))
                .collect::<Vec<_>>()
                .join(", ");
            let hint = match env.groups.iter().find(|g| g.velocity == name) {
                Some(g) => format!("; `{name}` is the velocity of `{}`", g.name),
                None => String::new(),
            };
            cx.error_spanned_by(
                &entry.target,
                format!("force on `{name}`, which is not a coordinate (the coordinates are {coords}){hint}"),
            );
            continue;
        };
        if seen.insert(name.clone(), &entry.target).is_some() {
            cx.error_spanned_by(&entry.target, format!("duplicate force entry for `{name}`"));
            continue;
        }
        let place = format!("the force on `{name}`");
        match (&entry.index, group.array, &entry.value) {
            (Some(i), false, _) => {
                cx.error_spanned_by(
                    i,
                    format!(
                        "`{name}` is a scalar coordinate: write `{name} = ...` without an index"
                    ),
                );
            }
            (None, false, value) => {
                let mut lw = Lowerer::new(cx, env, place);
                let lowered = lw.expr(value);
                fns.push(ForceFn {
                    group: g,
                    index: None,
                    element: None,
                    lowered,
                    target_name: name,
                    checked: lw.checked_index.get(),
                });
            }
            (Some(i), true, value) => {
                let iname = i.to_string();
                if reserved(&iname) {
                    cx.error_spanned_by(i, reserved_message(&iname));
                }
                let mut lw = Lowerer::new(cx, env, place);
                // `i` takes every value `0..LEN` (unknown for a const-parameter length).
                let range = group
                    .len
                    .literal()
                    .and_then(|n| i64::try_from(n).ok())
                    .map(|n| IntRange {
                        lo: 0,
                        hi: n - 1,
                        exact: true,
                    });
                lw.bind_index(i, range);
                let lowered = lw.expr(value);
                fns.push(ForceFn {
                    group: g,
                    index: Some(i.clone()),
                    element: None,
                    lowered,
                    target_name: name,
                    checked: lw.checked_index.get(),
                });
            }
            (None, true, Expr::Array(arr)) => {
                let Some(len) = group.len.literal() else {
                    cx.error_spanned_by(
                        arr,
                        format!(
                            "`{name}` has a const-parameter length: give its force as `{name}[i] = ...`"
                        ),
                    );
                    continue;
                };
                if arr.elems.len() != len {
                    cx.error_spanned_by(
                        arr,
                        format!(
                            "the force on `{name}` has {} entries, but `{name}: [f64; {len}]` has {len} coordinates",
                            arr.elems.len()
                        ),
                    );
                    continue;
                }
                for (k, elem) in arr.elems.iter().enumerate() {
                    let mut lw = Lowerer::new(cx, env, place.clone());
                    let lowered = lw.expr(elem);
                    fns.push(ForceFn {
                        group: g,
                        index: None,
                        element: Some(k),
                        lowered,
                        target_name: name.clone(),
                        checked: lw.checked_index.get(),
                    });
                }
            }
            (None, true, value) => {
                cx.error_spanned_by(
                    value,
                    format!(
                        "`{name}` is an array coordinate: write `{name}[i] = ...` (with an index variable) or `{name} = [..., ...]`"
                    ),
                );
            }
        }
    }
    for group in &env.groups {
        if !seen.contains_key(&group.name.to_string()) {
            let name = &group.name;
            let example = if group.array {
                format!("`{name}[i] = 0.0`")
            } else {
                format!("`{name} = 0.0`")
            };
            cx.error_spanned_by(
                &force.key,
                format!(
                    "missing force entry for `{name}`: a force gives every coordinate an entry (write {example} for none)"
                ),
            );
        }
    }
    fns
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
