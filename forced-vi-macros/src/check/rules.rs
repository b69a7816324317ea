//! The rules on the struct (its fields and generics), on the coordinates (names, array
//! lengths, their number) and on the Lagrangian's use of the velocities.

use std::collections::BTreeSet;

use quote::quote;
use syn::ext::IdentExt;
use syn::{Expr, Ident, Type};

use super::{Checked, MAX_COORDINATES, MAX_DENSE_COORDINATES};
use crate::ast::{Coord, Model};
use crate::ctxt::Ctxt;
use crate::lower::{
    compact, reserved, reserved_message, time_message, Env, Group, Len, Lowered, TIME,
};

/// Rule: a model with more than [`MAX_DENSE_COORDINATES`] coordinates (a literal length)
/// splits into local terms (`splits`: [`crate::split::split`] found them); whole-model
/// kernels at that size would need `N × N` dual numbers.
pub fn check_dense_size(cx: &Ctxt, c: &Checked, splits: bool) {
    let Some(n) = c.n.literal() else { return };
    if n <= MAX_DENSE_COORDINATES || splits {
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

/// Rule: the parameters of a model are its named fields, and each is an `f64`. The code
/// differentiates with respect to coordinates only, so parameters enter as plain numbers.
/// Names starting with `__fvi` (and `__D`) are the generated code's own, so a field with
/// such a name is refused rather than silently shadowed.
pub(super) fn check_fields(cx: &Ctxt, model: &Model) {
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
pub(super) fn check_generics(cx: &Ctxt, model: &Model) -> Vec<Ident> {
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
pub(super) fn check_coordinates(cx: &Ctxt, model: &Model, const_params: &[Ident]) -> Vec<Group> {
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
            let Some(plain) = unraw_coordinate(cx, c) else {
                continue;
            };
            unraw = plain;
            &unraw
        } else {
            c
        };
        let name = c.name.to_string();
        if !coordinate_name_ok(cx, model, coords, c, &seen) {
            continue;
        }
        seen.insert(name);
        let (len, array) = coordinate_len(cx, coords, c, const_params);
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

/// A raw identifier `r#x` as a coordinate: refused, then registered under its plain name
/// (`None` for a keyword such as `r#fn`, which has none).
fn unraw_coordinate(cx: &Ctxt, c: &Coord) -> Option<Coord> {
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
        return None;
    }
    Some(Coord {
        name: Ident::new(&plain, c.name.span()),
        velocity: c.velocity.clone(),
        ty: c.ty.clone(),
    })
}

/// The rules on a coordinate's name; `false` if the coordinate is left out (reserved,
/// duplicate, or the velocity of another).
fn coordinate_name_ok(
    cx: &Ctxt,
    model: &Model,
    coords: &[Coord],
    c: &Coord,
    seen: &BTreeSet<String>,
) -> bool {
    let name = c.name.to_string();
    if reserved(&name) {
        cx.error_spanned_by(&c.name, reserved_message(&name));
        return false;
    }
    if name == TIME {
        // Still declared, so that `t_dot` resolves: one error, at this token.
        cx.error_spanned_by(&c.name, time_message("coordinate"));
    }
    if seen.contains(&name) {
        cx.error_spanned_by(&c.name, format!("duplicate coordinate `{name}`"));
        return false;
    }
    if let Some(owner) = coords.iter().find(|o| o.velocity == name) {
        cx.error_spanned_by(
            &c.name,
            format!(
                "`{name}` is the velocity of `{}`: declare only the coordinate `{}`, its velocity `{name}` comes with it",
                owner.name, owner.name
            ),
        );
        return false;
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
    true
}

/// The length of a coordinate group (1 for a scalar) and whether it is an array. An invalid
/// length has its error, and the group still resolves its names.
fn coordinate_len(cx: &Ctxt, coords: &[Coord], c: &Coord, const_params: &[Ident]) -> (Len, bool) {
    let (len, array) = match &c.ty {
        None => (Some(Len::Lit(1)), false),
        Some(ty) => (array_len(cx, c, ty, const_params), true),
    };
    // An invalid length has its error; the group still resolves its names.
    let len = len.unwrap_or_else(|| Len::Param(Ident::new("__fvi_invalid_length", c.name.span())));
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
    (len, array)
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

pub(super) fn total_len(cx: &Ctxt, model: &Model, groups: &[Group]) -> Option<Len> {
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
pub(super) fn check_lagrangian_uses_velocity(cx: &Ctxt, env: &Env, expr: &Expr, lowered: &Lowered) {
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
