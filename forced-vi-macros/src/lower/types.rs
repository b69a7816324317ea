//! The values of the lowering: integer ranges, lengths, the environment (coordinate groups
//! and parameters), uses, polynomial degrees, kinds, the [`Lowered`] result and the state of
//! a local variable.

use std::collections::BTreeSet;

use proc_macro2::{Span, TokenStream};
use quote::{quote, quote_spanned, ToTokens};
use syn::Ident;

use super::f64_tokens;

/// The set of values an integer sub-expression can take, as an interval. `exact` says that
/// both ends are values that some evaluation really takes (so an end out of range is a real
/// out-of-range access, not an artefact of the analysis).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct IntRange {
    pub lo: i64,
    pub hi: i64,
    pub exact: bool,
}

impl IntRange {
    pub fn point(k: i64) -> IntRange {
        IntRange {
            lo: k,
            hi: k,
            exact: true,
        }
    }
    pub(super) fn single(&self) -> Option<i64> {
        (self.lo == self.hi).then_some(self.lo)
    }
    pub(super) fn hull(a: IntRange, b: IntRange) -> IntRange {
        IntRange {
            lo: a.lo.min(b.lo),
            hi: a.hi.max(b.hi),
            exact: false,
        }
    }
}

/// Joins two abstract ranges (either may be unknown).
pub(super) fn join_range(a: Option<IntRange>, b: Option<IntRange>) -> Option<IntRange> {
    match (a, b) {
        (Some(a), Some(b)) if a == b => Some(a),
        (Some(a), Some(b)) => Some(IntRange::hull(a, b)),
        _ => None,
    }
}

/// The number of coordinates of an array group (or of the model).
#[derive(Clone)]
pub enum Len {
    /// An integer literal.
    Lit(usize),
    /// A const parameter of the struct.
    Param(Ident),
}

impl Len {
    pub fn literal(&self) -> Option<usize> {
        match self {
            Len::Lit(n) => Some(*n),
            Len::Param(_) => None,
        }
    }
}

impl ToTokens for Len {
    fn to_tokens(&self, tokens: &mut TokenStream) {
        match self {
            Len::Lit(n) => proc_macro2::Literal::usize_unsuffixed(*n).to_tokens(tokens),
            Len::Param(p) => p.to_tokens(tokens),
        }
    }
}

/// A checked coordinate declaration: `x` (scalar) or `q: [f64; L]` (array).
pub struct Group {
    pub name: Ident,
    pub velocity: Ident,
    /// Index of the group's first coordinate in `q`.
    pub offset: usize,
    pub len: Len,
    pub array: bool,
}

/// What expressions may refer to.
pub struct Env {
    pub groups: Vec<Group>,
    pub params: Vec<Ident>,
    /// Const parameters of the struct (usable as integers, e.g. as an array length).
    pub const_params: Vec<Ident>,
    /// The struct's name, for messages.
    pub model: Ident,
    /// The parameters are `__D` values rather than `f64` (the code of `lagrangian_with` and
    /// `force_with`, which differentiate in them).
    pub params_dual: bool,
}

/// Which coordinates of a group a use touches.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub enum Idx {
    At(usize),
    All,
}

/// A use of a coordinate (`vel == false`) or a velocity.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub struct Var {
    pub vel: bool,
    pub group: usize,
    pub idx: Idx,
}

/// Polynomial degree in one set of variables; `None` is "not a polynomial".
pub type Deg = Option<u32>;

/// Degrees in `q` and in `v`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Degree {
    pub q: Deg,
    pub v: Deg,
}

impl Degree {
    pub const CONST: Degree = Degree {
        q: Some(0),
        v: Some(0),
    };
    pub(super) fn max(self, o: Degree) -> Degree {
        let m = |a: Deg, b: Deg| Some(a?.max(b?));
        Degree {
            q: m(self.q, o.q),
            v: m(self.v, o.v),
        }
    }
    pub(super) fn add(self, o: Degree) -> Degree {
        let s = |a: Deg, b: Deg| a?.checked_add(b?);
        Degree {
            q: s(self.q, o.q),
            v: s(self.v, o.v),
        }
    }
    /// Not polynomial in whatever the operands depend on.
    pub(super) fn opaque(self) -> Degree {
        let o = |a: Deg| if a == Some(0) { Some(0) } else { None };
        Degree {
            q: o(self.q),
            v: o(self.v),
        }
    }
    pub(super) fn times(self, n: u32) -> Degree {
        Degree {
            q: self.q.and_then(|d| d.checked_mul(n)),
            v: self.v.and_then(|d| d.checked_mul(n)),
        }
    }
}

/// The kind of a sub-expression in generated code.
#[derive(Clone, PartialEq, Debug)]
pub enum Kind {
    /// `f64`: literals, parameters, and anything built from them.
    Real,
    /// The generic scalar `__D`.
    Dual,
    /// An integer (index, length, loop variable).
    Int,
    Bool,
    /// An array coordinate or velocity (group index).
    Array(usize),
    /// An iterator over items of the kind.
    Iter(Box<Kind>),
    Unit,
}

/// The result of lowering one expression.
#[derive(Clone)]
pub struct Lowered {
    pub tokens: TokenStream,
    pub kind: Kind,
    pub uses: BTreeSet<Var>,
    /// The model names (coordinates, velocities, parameters) referred to.
    pub names: BTreeSet<String>,
    pub degree: Degree,
    /// The values an integer can take (for an iterator: the values of its items), if known.
    pub range: Option<IntRange>,
    /// An integer literal's value as an `f64`, for its use as a real number.
    pub lit_f64: Option<f64>,
    /// Needs no parentheses as an operand.
    pub atomic: bool,
    /// The expression is itself a block, `if` or `for` (whole, so it can stand as a body).
    pub stmt_like: bool,
    /// Integer arithmetic whose value differs from the same arithmetic on reals (a
    /// truncating division, an overflow): an error if the integer is used as a real number.
    pub inexact: Option<Inexact>,
}

/// Integer arithmetic that a real number would not reproduce, and where the user wrote it.
///
/// The macro reads an integer literal in real arithmetic as an `f64` (`v * v / 2`), but
/// arithmetic between integers stays integer arithmetic, as in Rust (it indexes arrays):
/// `3 / 2` is 1. Used as a real number, such a value would silently differ from what the
/// same expression means next to a real, so [`Lowered::as_real`] makes it a compile error
/// at these tokens instead; an explicit `as f64` keeps Rust's meaning.
#[derive(Clone, Debug)]
pub struct Inexact {
    message: String,
    /// The `compile_error!` spanned over the user's tokens.
    error: TokenStream,
}

impl Inexact {
    pub(super) fn at(tokens: impl ToTokens, message: String) -> Inexact {
        let error = syn::Error::new_spanned(tokens, &message).to_compile_error();
        Inexact { message, error }
    }
}

impl PartialEq for Inexact {
    fn eq(&self, o: &Inexact) -> bool {
        self.message == o.message
    }
}

impl Lowered {
    pub(super) fn new(tokens: TokenStream, kind: Kind) -> Lowered {
        Lowered {
            tokens,
            kind,
            uses: BTreeSet::new(),
            names: BTreeSet::new(),
            degree: Degree::CONST,
            range: None,
            lit_f64: None,
            atomic: true,
            stmt_like: false,
            inexact: None,
        }
    }
    /// The compile-time value of an integer, if it has a single one.
    pub fn int(&self) -> Option<i64> {
        self.range.and_then(|r| r.single())
    }
    pub(super) fn absorb(&mut self, o: &Lowered) {
        self.uses.extend(o.uses.iter().copied());
        self.names.extend(o.names.iter().cloned());
    }
    /// The tokens, in parentheses unless atomic (a block or an `if` is parenthesised too: at
    /// the start of a statement it would end the expression).
    pub(super) fn operand(&self) -> TokenStream {
        let t = &self.tokens;
        if self.atomic && !self.stmt_like {
            t.clone()
        } else {
            quote!((#t))
        }
    }
    /// An integer as an `f64` expression (`2` → `2.0`, `i` → `(i as f64)`); other kinds as
    /// they are.
    pub fn as_real(&self) -> TokenStream {
        if self.kind != Kind::Int {
            return self.operand();
        }
        if let Some(x) = &self.inexact {
            return x.error.clone();
        }
        if let Some(t) = self
            .lit_f64
            .or_else(|| self.int().map(|k| k as f64))
            .and_then(f64_tokens)
        {
            return t;
        }
        let t = self.operand();
        quote!((#t as f64))
    }
    /// Turns an integer into a real number in place.
    pub(super) fn make_real(&mut self) {
        if self.kind == Kind::Int {
            self.tokens = self.as_real();
            self.kind = Kind::Real;
            self.atomic = true;
            self.range = None;
        }
    }
    /// The tokens as a `__D` (wrapping an `f64`).
    pub fn as_dual(&self, span: Span) -> TokenStream {
        match self.kind {
            Kind::Dual => self.tokens.clone(),
            Kind::Int => {
                let t = self.as_real();
                quote_spanned!(span=> __D::from(#t))
            }
            _ => {
                let t = &self.tokens;
                quote_spanned!(span=> __D::from(#t))
            }
        }
    }
}

/// What the analysis knows of a local variable (a `let`, loop or closure variable, or the
/// index variable of a force entry) at one point.
#[derive(Clone, PartialEq)]
pub(super) struct Local {
    pub(super) kind: Kind,
    pub(super) uses: BTreeSet<Var>,
    pub(super) names: BTreeSet<String>,
    pub(super) degree: Degree,
    pub(super) range: Option<IntRange>,
    pub(super) inexact: Option<Inexact>,
}

impl Local {
    /// The least upper bound of two states of one local; with `widen`, a degree that grew
    /// becomes "not a polynomial" so that loops reach a fixpoint.
    pub(super) fn join(&self, o: &Local, widen: bool) -> Local {
        let grow = |a: Deg, b: Deg| -> Deg {
            let m = Some(a?.max(b?));
            if widen && m != a {
                None
            } else {
                m
            }
        };
        Local {
            kind: self.kind.clone(),
            uses: self.uses.union(&o.uses).copied().collect(),
            names: self.names.union(&o.names).cloned().collect(),
            degree: Degree {
                q: grow(self.degree.q, o.degree.q),
                v: grow(self.degree.v, o.degree.v),
            },
            range: join_range(self.range, o.range),
            inexact: self.inexact.clone().or_else(|| o.inexact.clone()),
        }
    }
}

pub(super) fn var_degree(vel: bool) -> Degree {
    if vel {
        Degree {
            q: Some(0),
            v: Some(1),
        }
    } else {
        Degree {
            q: Some(1),
            v: Some(0),
        }
    }
}
