//! Walks a user expression (the Lagrangian, a term of it, or a force component) once and
//! returns three things together:
//!
//! - the *kind* of every sub-expression: an `f64` constant (parameters and literals), a
//!   dual-valued quantity (anything that depends on a coordinate or velocity), an integer
//!   (indices), and so on;
//! - the expression rewritten for the generic scalar `__D`: num-dual implements `D ∘ f64` but
//!   not `f64 ∘ D`, so `c * x` becomes `x * c`, `c - x` becomes `-x + c`, `c / x` becomes
//!   `__D::from(c) / x`, and `let mut s = 0.0` (an accumulator) becomes a `__D`;
//! - what the expression *uses* (which coordinate and velocity slots, which names) and its
//!   polynomial *degree* in `q` and in `v`, which drive the specialisation.
//!
//! Names are resolved here too, so an unknown identifier is reported at its own token.
//!
//! The time `t` is one more resolvable name: a `__D` value with no uses and degree 0 in `q`
//! and `v` (like a parameter), recorded in `names` so that `check` knows the model is
//! driven. A model that never names `t` keeps today's code.

//!
//! The module is split by concern: `types` holds the values ([`IntRange`], [`Len`],
//! [`Degree`], [`Kind`], [`Lowered`], the state of a local), `expr` the expression forms and
//! operators, `call` method and function calls, indexing and casts, `control` blocks, `if`,
//! loops and ranges, and `refine` the integer-range analysis of conditions and operators.
//! Each adds its methods to the one [`Lowerer`].

use std::cell::Cell;
use std::collections::{BTreeSet, HashMap};
use std::rc::Rc;

use proc_macro2::{Span, TokenStream};
use quote::{quote, ToTokens};
use syn::Ident;

use crate::ctxt::Ctxt;

mod call;
mod control;
mod expr;
mod refine;
mod types;

use types::Local;
pub use types::{Degree, Env, Group, Idx, Inexact, IntRange, Kind, Len, Lowered, Var};

/// The name of the time in model expressions.
pub const TIME: &str = "t";

/// The message for a model name (coordinate, parameter, const parameter) that is `t`.
pub fn time_message(what: &str) -> String {
    format!("`t` is the time in model expressions and cannot name a {what}; rename it")
}

/// Whether a name is reserved for generated code (`__fvi…` locals and the scalar `__D`).
pub fn reserved(name: &str) -> bool {
    name.starts_with("__fvi") || name == "__D"
}

/// The message for a reserved name.
pub fn reserved_message(name: &str) -> String {
    format!("`{name}` is reserved: names starting with `__fvi` and the name `__D` belong to the code that `#[forced_lagrangian]` generates; rename it")
}

/// An `f64` literal as tokens (negative values in parentheses). `None` if not finite.
pub fn f64_tokens(x: f64) -> Option<TokenStream> {
    if !x.is_finite() {
        return None;
    }
    let lit = proc_macro2::Literal::f64_unsuffixed(x.abs());
    Some(if x < 0.0 || (x == 0.0 && x.is_sign_negative()) {
        quote!((-#lit))
    } else {
        quote!(#lit)
    })
}

type Scopes = Vec<HashMap<String, Local>>;

/// A region whose execution depends on a value: the branches of an `if` (on its
/// condition) and the body of a loop (on its iterator). A local declared outside it and
/// assigned inside depends on that value too.
#[derive(Clone)]
struct Ctrl {
    /// The number of scopes when the region was entered.
    depth: usize,
    uses: BTreeSet<Var>,
    names: BTreeSet<String>,
    degree: Degree,
}

/// The name of the generic scalar in generated code.
pub fn dual_ident() -> Ident {
    Ident::new("__D", Span::call_site())
}

/// How many expression nodes one macro call may lower (loops are analysed to a fixpoint,
/// nested ones multiply); beyond it the model is refused rather than analysed unsoundly.
const BUDGET: u64 = 2_000_000;
/// Passes over a loop body before its changing locals are widened to "anything".
const MAX_PASSES: usize = 8;

/// Lowers expressions against an [`Env`].
pub struct Lowerer<'a> {
    cx: &'a Ctxt,
    env: &'a Env,
    scopes: Scopes,
    ctrl: Vec<Ctrl>,
    /// Nodes left in the analysis budget, shared with nested silent passes.
    budget: Rc<Cell<u64>>,
    /// Set when an index needs a run-time check (`__private::at`).
    pub checked_index: Rc<Cell<bool>>,
    /// Inside a branch that no evaluation reaches (its condition is false for every value).
    dead: usize,
    /// The next `block`/`lift_branch` lifts an integer value to `f64` rather than `__D`.
    lift_real: bool,
    /// Where the expression is, for messages: "the Lagrangian", "the force on `x`".
    place: String,
    /// The values that integer arithmetic is trusted to reach without wrapping: the
    /// narrowest integer type the expression may compute in (`i32` by default, `u8` if it
    /// names one...). A result outside is unknown. Set at the first expression lowered.
    wrap: Option<(i64, i64)>,
}

const UNSUPPORTED: &str = "is not supported in a model expression; use arithmetic, method calls such as `sin()` or `powi(2)`, `let`, `if`, `for` loops over ranges, and `(a..b).map(|i| ...).sum()`";

impl<'a> Lowerer<'a> {
    pub fn new(cx: &'a Ctxt, env: &'a Env, place: impl Into<String>) -> Lowerer<'a> {
        Lowerer {
            cx,
            env,
            scopes: vec![HashMap::new()],
            ctrl: Vec::new(),
            budget: Rc::new(Cell::new(BUDGET)),
            checked_index: Rc::new(Cell::new(false)),
            dead: 0,
            lift_real: false,
            place: place.into(),
            wrap: None,
        }
    }

    /// Binds an integer (the index variable `i` of `force(q[i] = ...)`) with the values it
    /// takes, if known.
    pub fn bind_index(&mut self, name: &Ident, range: Option<IntRange>) {
        self.bind(
            name,
            Local {
                kind: Kind::Int,
                uses: BTreeSet::new(),
                names: BTreeSet::new(),
                degree: Degree::CONST,
                range,
                inexact: None,
            },
        );
    }

    fn bind(&mut self, name: &Ident, local: Local) {
        if let Some(scope) = self.scopes.last_mut() {
            scope.insert(name.to_string(), local);
        }
    }

    /// Binds a local that the user names (`let`, loop or closure variable).
    fn bind_user(&mut self, name: &Ident, local: Local) {
        let s = name.to_string();
        if reserved(&s) {
            self.cx.error_spanned_by(name, reserved_message(&s));
        }
        self.bind(name, local);
    }

    fn lookup(&self, name: &str) -> Option<(usize, &Local)> {
        self.scopes
            .iter()
            .enumerate()
            .rev()
            .find_map(|(k, s)| s.get(name).map(|l| (k, l)))
    }

    /// The range `r` if integer arithmetic reaches it without wrapping (see `wrap`).
    fn unwrapped(&self, r: Option<IntRange>) -> Option<IntRange> {
        let (lo, hi) = self
            .wrap
            .unwrap_or((i64::from(i32::MIN), i64::from(i32::MAX)));
        r.filter(|r| r.lo >= lo && r.hi <= hi)
    }

    fn unsupported(&self, tokens: impl ToTokens, what: &str) -> Lowered {
        self.cx
            .error_spanned_by(tokens, format!("{what} {UNSUPPORTED}"));
        Lowered::new(TokenStream::new(), Kind::Real)
    }

    /// Runs `f` with errors discarded (for a second pass over an already checked expression,
    /// or for the passes of a loop analysis). The scopes are its own copy.
    fn silently<T>(&mut self, f: impl FnOnce(&mut Lowerer<'_>) -> T) -> T {
        let quiet = Ctxt::default();
        let mut l = Lowerer {
            cx: &quiet,
            env: self.env,
            scopes: self.scopes.clone(),
            ctrl: self.ctrl.clone(),
            budget: Rc::clone(&self.budget),
            checked_index: Rc::new(Cell::new(false)),
            dead: self.dead,
            lift_real: false,
            place: self.place.clone(),
            wrap: self.wrap,
        };
        let out = f(&mut l);
        // The quiet context's errors are reported by the real pass.
        let _ = quiet.check();
        out
    }
}

/// The value bounds of a primitive integer type named `name`.
pub(crate) fn int_type_bounds(name: &str) -> Option<(i64, i64)> {
    Some(match name {
        "i8" => (i8::MIN.into(), i8::MAX.into()),
        "u8" => (0, u8::MAX.into()),
        "i16" => (i16::MIN.into(), i16::MAX.into()),
        "u16" => (0, u16::MAX.into()),
        "i32" => (i32::MIN.into(), i32::MAX.into()),
        "u32" => (0, u32::MAX.into()),
        "i64" | "isize" | "i128" => (i64::MIN, i64::MAX),
        "u64" | "usize" | "u128" => (0, i64::MAX),
        _ => return None,
    })
}

/// The values integer arithmetic in `t` can reach without wrapping in any of the integer
/// types it may compute in: `i32` (the default of an unsuffixed literal) narrowed by every
/// 8- or 16-bit type that `t` names (as a cast, a `let` type or a literal suffix), since
/// Rust's inference may give that type to any integer of the expression.
fn wrap_bounds(t: &TokenStream) -> (i64, i64) {
    let mut b = (i64::from(i32::MIN), i64::from(i32::MAX));
    let mut narrow = |name: &str| {
        if matches!(name, "i8" | "u8" | "i16" | "u16") {
            if let Some((lo, hi)) = int_type_bounds(name) {
                b = (b.0.max(lo), b.1.min(hi));
            }
        }
    };
    fn walk(t: &TokenStream, f: &mut dyn FnMut(&str)) {
        for tt in t.clone() {
            match tt {
                proc_macro2::TokenTree::Ident(i) => f(&i.to_string()),
                proc_macro2::TokenTree::Literal(l) => {
                    let s = l.to_string();
                    for suffix in ["i8", "u8", "i16", "u16"] {
                        if s.ends_with(suffix) && !s.starts_with('"') {
                            f(suffix);
                        }
                    }
                }
                proc_macro2::TokenTree::Group(g) => walk(&g.stream(), f),
                proc_macro2::TokenTree::Punct(_) => {}
            }
        }
    }
    walk(t, &mut narrow);
    b
}

/// Token text without the spaces that `TokenStream::to_string` puts between punctuation:
/// `& 'a f64` → `&'a f64`, `q [i + 1]` → `q[i + 1]`.
pub fn compact(s: &str) -> String {
    let chars: Vec<char> = s.chars().collect();
    let word = |c: char| c.is_alphanumeric() || c == '_' || c == '\'';
    let mut out = String::new();
    for (k, &c) in chars.iter().enumerate() {
        if c == ' ' {
            let prev = k.checked_sub(1).and_then(|p| chars.get(p)).copied();
            let next = chars.get(k + 1).copied();
            let keep = match (prev, next) {
                (Some(p), Some(n)) => {
                    (word(p) && word(n))
                        || matches!(p, ',' | ';' | '+' | '-' | '*' | '/' | '=')
                        || matches!(n, '+' | '-' | '*' | '/' | '=')
                }
                _ => false,
            };
            if !keep || prev == Some(' ') {
                continue;
            }
        }
        out.push(c);
    }
    out
}
