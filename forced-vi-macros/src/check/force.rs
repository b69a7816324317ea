//! The force: the rule on its entries ([`check_force`]) and the analysis of its rows.

use std::collections::HashMap;

use syn::{Expr, Ident};

use super::{CheckedForce, ForceFn, Row};
use crate::ast::{Force, ForceEntry, Model};
use crate::ctxt::Ctxt;
use crate::lower::{reserved, reserved_message, Env, Group, IntRange, Len, Lowerer};
use crate::poly::Extractor;

/// Rule: a force names each coordinate once and only coordinates: `x = ...` for a scalar,
/// `q[i] = ...` or `q = [...]` (with exactly `LEN` entries) for an array. Every coordinate
/// needs an entry once a force is given (write `x = 0.0` for none).
pub(super) fn check_force(cx: &Ctxt, env: &Env, force: &Force) -> Vec<ForceFn> {
    let mut fns = Vec::new();
    let mut seen: HashMap<String, &Ident> = HashMap::new();
    for entry in &force.entries {
        let name = entry.target.to_string();
        let Some((g, group)) = env.groups.iter().enumerate().find(|(_, g)| g.name == name) else {
            unknown_target(cx, env, entry, &name);
            continue;
        };
        if seen.insert(name.clone(), &entry.target).is_some() {
            cx.error_spanned_by(&entry.target, format!("duplicate force entry for `{name}`"));
            continue;
        }
        force_entry(cx, env, entry, (g, group), name, &mut fns);
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

/// The error for a force entry whose target `name` is not a coordinate.
fn unknown_target(cx: &Ctxt, env: &Env, entry: &ForceEntry, name: &str) {
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
        format!(
            "force on `{name}`, which is not a coordinate (the coordinates are {coords}){hint}"
        ),
    );
}

/// One force entry on the coordinate group `g` (named `name`): its functions, added to `fns`.
fn force_entry(
    cx: &Ctxt,
    env: &Env,
    entry: &ForceEntry,
    (g, group): (usize, &Group),
    name: String,
    fns: &mut Vec<ForceFn>,
) {
    let place = format!("the force on `{name}`");
    match (&entry.index, group.array, &entry.value) {
        (Some(i), false, _) => {
            cx.error_spanned_by(
                i,
                format!("`{name}` is a scalar coordinate: write `{name} = ...` without an index"),
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
        (None, true, Expr::Array(arr)) => array_entry(cx, env, arr, (g, group), name, fns),
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

/// A force entry `q = [...]` on the array group `g`: one function per element.
fn array_entry(
    cx: &Ctxt,
    env: &Env,
    arr: &syn::ExprArray,
    (g, group): (usize, &Group),
    name: String,
    fns: &mut Vec<ForceFn>,
) {
    let place = format!("the force on `{name}`");
    let Some(len) = group.len.literal() else {
        cx.error_spanned_by(
            arr,
            format!("`{name}` has a const-parameter length: give its force as `{name}[i] = ...`"),
        );
        return;
    };
    if arr.elems.len() != len {
        cx.error_spanned_by(
            arr,
            format!(
                "the force on `{name}` has {} entries, but `{name}: [f64; {len}]` has {len} coordinates",
                arr.elems.len()
            ),
        );
        return;
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

/// The analysis of a checked force: for a literal number of coordinates `n`, one row per
/// coordinate (what it uses, its polynomial if it is one); what the whole force uses.
pub(super) fn checked_force(
    model: &Model,
    env: &Env,
    n: &Len,
    fns: Vec<ForceFn>,
    extractor: &mut Extractor<'_>,
) -> CheckedForce {
    let mut rows = Vec::new();
    if let Some(total) = n.literal() {
        for (f, func) in fns.iter().enumerate() {
            rows.extend(entry_rows(model, env, f, func, extractor));
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
}

/// The rows of the force function `func` (number `f`): one per value of its index
/// variable, or the one element or coordinate it is for.
fn entry_rows(
    model: &Model,
    env: &Env,
    f: usize,
    func: &ForceFn,
    extractor: &mut Extractor<'_>,
) -> Vec<Row> {
    let mut rows = Vec::new();
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
        let mut lw = Lowerer::new(&quiet, env, "the force");
        if let (Some(i), Some(value)) = (&func.index, index) {
            lw.bind_index(i, i64::try_from(value).ok().map(IntRange::point));
        }
        let lowered = match entry {
            Some(e) => lw.expr(e),
            None => func.lowered.clone(),
        };
        let _ = quiet.check();
        extractor.index = match (&func.index, index) {
            (Some(i), Some(value)) => i64::try_from(value).ok().map(|v| (i.to_string(), v)),
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
    rows
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
