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

use std::cell::Cell;
use std::collections::{BTreeSet, HashMap};
use std::rc::Rc;

use proc_macro2::{Span, TokenStream};
use quote::{quote, quote_spanned, ToTokens};
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Ident, Lit, Pat, Stmt, UnOp};

use crate::ctxt::Ctxt;

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
    fn single(&self) -> Option<i64> {
        (self.lo == self.hi).then_some(self.lo)
    }
    fn hull(a: IntRange, b: IntRange) -> IntRange {
        IntRange {
            lo: a.lo.min(b.lo),
            hi: a.hi.max(b.hi),
            exact: false,
        }
    }
}

/// Joins two abstract ranges (either may be unknown).
fn join_range(a: Option<IntRange>, b: Option<IntRange>) -> Option<IntRange> {
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
    fn max(self, o: Degree) -> Degree {
        let m = |a: Deg, b: Deg| Some(a?.max(b?));
        Degree {
            q: m(self.q, o.q),
            v: m(self.v, o.v),
        }
    }
    fn add(self, o: Degree) -> Degree {
        let s = |a: Deg, b: Deg| a?.checked_add(b?);
        Degree {
            q: s(self.q, o.q),
            v: s(self.v, o.v),
        }
    }
    /// Not polynomial in whatever the operands depend on.
    fn opaque(self) -> Degree {
        let o = |a: Deg| if a == Some(0) { Some(0) } else { None };
        Degree {
            q: o(self.q),
            v: o(self.v),
        }
    }
    fn times(self, n: u32) -> Degree {
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
}

impl Lowered {
    fn new(tokens: TokenStream, kind: Kind) -> Lowered {
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
        }
    }
    /// The compile-time value of an integer, if it has a single one.
    pub fn int(&self) -> Option<i64> {
        self.range.and_then(|r| r.single())
    }
    fn absorb(&mut self, o: &Lowered) {
        self.uses.extend(o.uses.iter().copied());
        self.names.extend(o.names.iter().cloned());
    }
    /// The tokens, in parentheses unless atomic (a block or an `if` is parenthesised too: at
    /// the start of a statement it would end the expression).
    fn operand(&self) -> TokenStream {
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
    fn make_real(&mut self) {
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

#[derive(Clone, PartialEq)]
struct Local {
    kind: Kind,
    uses: BTreeSet<Var>,
    names: BTreeSet<String>,
    degree: Degree,
    range: Option<IntRange>,
}

impl Local {
    /// The least upper bound of two states of one local; with `widen`, a degree that grew
    /// becomes "not a polynomial" so that loops reach a fixpoint.
    fn join(&self, o: &Local, widen: bool) -> Local {
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
        }
    }
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

    fn unsupported(&self, tokens: impl ToTokens, what: &str) -> Lowered {
        self.cx
            .error_spanned_by(tokens, format!("{what} {UNSUPPORTED}"));
        Lowered::new(TokenStream::new(), Kind::Real)
    }

    /// Lowers an expression.
    pub fn expr(&mut self, e: &Expr) -> Lowered {
        let left = self.budget.get();
        if left == 0 {
            return Lowered::new(TokenStream::new(), Kind::Real);
        }
        self.budget.set(left - 1);
        if left == 1 {
            self.cx.error_spanned_by(
                e,
                "this model expression is too large to analyse (loops nested too deeply); simplify it",
            );
        }
        let mut out = self.expr_inner(e);
        out.stmt_like = matches!(e, Expr::Block(_) | Expr::If(_) | Expr::ForLoop(_));
        out
    }

    fn expr_inner(&mut self, e: &Expr) -> Lowered {
        match e {
            Expr::Lit(lit) => self.lit(&lit.lit),
            Expr::Path(p) => self.path(p),
            Expr::Paren(p) => {
                let inner = self.expr(&p.expr);
                let t = &inner.tokens;
                let mut out = inner.clone();
                out.tokens = quote_spanned!(p.paren_token.span.join()=> (#t));
                out.atomic = true;
                out
            }
            Expr::Group(g) => {
                let inner = self.expr(&g.expr);
                let mut out = inner.clone();
                out.tokens = inner.operand();
                out.atomic = true;
                out
            }
            Expr::Unary(u) => self.unary(u),
            Expr::Binary(b) => self.binary(b),
            Expr::Assign(a) => self.assign(&a.left, None, &a.right),
            Expr::MethodCall(m) => self.method(m),
            Expr::Call(c) => self.call(c),
            Expr::Index(i) => self.index(i),
            Expr::Cast(c) => self.cast(c),
            Expr::Block(b) => {
                if b.label.is_some() {
                    return self.unsupported(e, "a labelled block");
                }
                self.block(&b.block, false)
            }
            Expr::If(i) => self.if_expr(i),
            Expr::ForLoop(f) => self.for_loop(f),
            Expr::Range(r) => self.range(r),
            Expr::Closure(c) => self.unsupported(c, "a closure outside `.map(...)`"),
            Expr::Macro(m) => self.unsupported(m, "a macro call"),
            Expr::Return(r) => self.unsupported(r, "`return`"),
            other => self.unsupported(other, "this expression"),
        }
    }

    fn lit(&mut self, lit: &Lit) -> Lowered {
        match lit {
            Lit::Float(_) => Lowered::new(lit.to_token_stream(), Kind::Real),
            Lit::Int(i) => {
                let mut l = Lowered::new(lit.to_token_stream(), Kind::Int);
                if i.suffix() == "f64" || i.suffix() == "f32" {
                    l.kind = Kind::Real;
                } else {
                    l.range = i.base10_parse::<i64>().ok().map(IntRange::point);
                    if i.suffix().is_empty() {
                        l.lit_f64 = i
                            .base10_digits()
                            .parse::<f64>()
                            .ok()
                            .filter(|x| x.is_finite());
                    }
                }
                l
            }
            Lit::Bool(_) => Lowered::new(lit.to_token_stream(), Kind::Bool),
            other => self.unsupported(other, "this literal"),
        }
    }

    fn path(&mut self, p: &syn::ExprPath) -> Lowered {
        let tokens = p.to_token_stream();
        let Some(ident) = p.path.get_ident().filter(|_| p.qself.is_none()) else {
            // A path such as `std::f64::consts::PI` or `f64::EPSILON`: a constant.
            return Lowered::new(tokens, Kind::Real);
        };
        let name = ident.to_string();
        if let Some((_, local)) = self.lookup(&name) {
            let mut l = Lowered::new(tokens, local.kind.clone());
            l.uses = local.uses.clone();
            l.names = local.names.clone();
            l.degree = local.degree;
            l.range = local.range;
            return l;
        }
        for (g, group) in self.env.groups.iter().enumerate() {
            for (vel, gname) in [(false, &group.name), (true, &group.velocity)] {
                if *gname == name {
                    let mut l = if group.array {
                        Lowered::new(tokens.clone(), Kind::Array(g))
                    } else {
                        let mut l = Lowered::new(tokens.clone(), Kind::Dual);
                        l.uses.insert(Var {
                            vel,
                            group: g,
                            idx: Idx::At(0),
                        });
                        l.degree = var_degree(vel);
                        l
                    };
                    l.names.insert(name.clone());
                    return l;
                }
            }
        }
        if self.env.params.iter().any(|p| *p == name) {
            let mut l = Lowered::new(tokens, Kind::Real);
            l.names.insert(name);
            return l;
        }
        if self.env.const_params.iter().any(|p| *p == name) {
            return Lowered::new(tokens, Kind::Int);
        }
        if name == TIME {
            // The time: a `__D` value (so that `∂L/∂t` can be taken with a dual number)
            // that is constant in `q` and `v`, like a parameter, for the degree analysis.
            let mut l = Lowered::new(tokens, Kind::Dual);
            l.names.insert(name);
            return l;
        }
        let hint = if name == "self" {
            "; parameters are written by name, without `self.`".to_string()
        } else if name.len() > 1
            && name
                .chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
        {
            format!("; a constant from outside the model is written with its path, as in `self::{name}` or `crate::{name}`")
        } else if let Some(stem) = name.strip_suffix("_dot") {
            format!("; `{stem}` is not a coordinate")
        } else {
            String::new()
        };
        self.cx.error_spanned_by(
            ident,
            format!(
                "unknown name `{name}` in {}: not a coordinate, velocity or parameter of `{}`{hint}",
                self.place, self.env.model
            ),
        );
        Lowered::new(tokens, Kind::Real)
    }

    fn unary(&mut self, u: &syn::ExprUnary) -> Lowered {
        let inner = self.expr(&u.expr);
        let op = &u.op;
        let mut out = inner.clone();
        match u.op {
            UnOp::Neg(_) => {
                out.range = inner.range.and_then(|r| {
                    Some(IntRange {
                        lo: r.hi.checked_neg()?,
                        hi: r.lo.checked_neg()?,
                        exact: r.exact,
                    })
                });
                out.lit_f64 = inner.lit_f64.map(|x| -x);
            }
            UnOp::Not(_) => {
                out.kind = Kind::Bool;
                out.degree = inner.degree.opaque();
                out.range = None;
            }
            _ => return self.unsupported(u, "dereferencing"),
        }
        let t = inner.operand();
        out.tokens = quote!(#op #t);
        out.atomic = false;
        out
    }

    fn binary(&mut self, b: &syn::ExprBinary) -> Lowered {
        match b.op {
            BinOp::AddAssign(_)
            | BinOp::SubAssign(_)
            | BinOp::MulAssign(_)
            | BinOp::DivAssign(_) => return self.assign(&b.left, Some(&b.op), &b.right),
            BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_) | BinOp::Div(_) | BinOp::Rem(_) => {}
            BinOp::Eq(_)
            | BinOp::Lt(_)
            | BinOp::Le(_)
            | BinOp::Ne(_)
            | BinOp::Ge(_)
            | BinOp::Gt(_)
            | BinOp::And(_)
            | BinOp::Or(_) => return self.compare(b),
            _ => return self.unsupported(b.op, "this operator"),
        }
        let mut l = self.expr(&b.left);
        let mut r = self.expr(&b.right);
        let op = &b.op;
        let span = b.span();
        let mut out = Lowered::new(TokenStream::new(), Kind::Real);
        out.absorb(&l);
        out.absorb(&r);
        out.atomic = false;
        out.kind = match (&l.kind, &r.kind) {
            (Kind::Dual, _) | (_, Kind::Dual) => Kind::Dual,
            (Kind::Int, Kind::Int) => Kind::Int,
            _ => Kind::Real,
        };
        out.degree = match b.op {
            BinOp::Add(_) | BinOp::Sub(_) => l.degree.max(r.degree),
            BinOp::Mul(_) => l.degree.add(r.degree),
            BinOp::Div(_) => {
                if r.degree == Degree::CONST {
                    l.degree
                } else {
                    l.degree.max(r.degree).opaque()
                }
            }
            _ => l.degree.max(r.degree).opaque(),
        };
        if out.kind == Kind::Int {
            out.range = int_op(b.op, l.range, r.range);
            // Integer arithmetic wraps instead of panicking: an index that wraps is out of
            // range, which the checked access reports.
            let fvi = quote!(::forced_vi::__private);
            let f = match b.op {
                BinOp::Add(_) => quote!(int_add),
                BinOp::Sub(_) => quote!(int_sub),
                BinOp::Mul(_) => quote!(int_mul),
                BinOp::Div(_) => quote!(int_div),
                _ => quote!(int_rem),
            };
            let (lt, rt) = (&l.tokens, &r.tokens);
            out.tokens = quote_spanned!(span=> #fvi::#f(#lt, #rt));
            out.atomic = true;
            return out;
        }
        // A user writes integer literals (`2 * x`, `v * v / 2`): they are `f64` here.
        l.make_real();
        r.make_real();
        let (lt, rt) = (&l.tokens, &r.tokens);
        let real_left = l.kind == Kind::Real;
        out.tokens = if real_left && r.kind == Kind::Dual {
            // num-dual has `D ∘ f64` only: put the dual operand first.
            let (lo, ro) = (l.operand(), r.operand());
            match b.op {
                BinOp::Add(_) => quote!(#ro + #lo),
                BinOp::Mul(_) => quote!(#ro * #lo),
                BinOp::Sub(_) => quote_spanned!(span=> -#ro + #lo),
                _ => {
                    let ld = l.as_dual(span);
                    quote!(#ld #op #ro)
                }
            }
        } else {
            quote!(#lt #op #rt)
        };
        out
    }

    fn compare(&mut self, b: &syn::ExprBinary) -> Lowered {
        let mut l = self.expr(&b.left);
        let mut r = self.expr(&b.right);
        let op = &b.op;
        let mut out = Lowered::new(TokenStream::new(), Kind::Bool);
        out.absorb(&l);
        out.absorb(&r);
        out.degree = l.degree.max(r.degree).opaque();
        out.atomic = false;
        if l.kind != r.kind {
            l.make_real();
            r.make_real();
        }
        out.tokens = if l.kind == Kind::Dual || r.kind == Kind::Dual {
            let ld = l.as_dual(b.left.span());
            let rd = r.as_dual(b.right.span());
            let ld = if l.kind == Kind::Dual {
                l.operand()
            } else {
                ld
            };
            let rd = if r.kind == Kind::Dual {
                r.operand()
            } else {
                rd
            };
            quote!(#ld #op #rd)
        } else {
            let (lt, rt) = (&l.tokens, &r.tokens);
            quote!(#lt #op #rt)
        };
        out
    }

    /// `x = e`, `x += e`, ... on a local.
    fn assign(&mut self, left: &Expr, op: Option<&BinOp>, right: &Expr) -> Lowered {
        let Expr::Path(p) = left else {
            return self.unsupported(left, "assigning to anything but a local variable");
        };
        let Some(ident) = p.path.get_ident() else {
            return self.unsupported(left, "assigning to a path");
        };
        let mut r = self.expr(right);
        let name = ident.to_string();
        let Some((depth, _)) = self.lookup(&name) else {
            self.cx.error_spanned_by(
                ident,
                format!(
                    "`{name}` is not a local variable; only `let mut` variables can be assigned"
                ),
            );
            return Lowered::new(TokenStream::new(), Kind::Unit);
        };
        // The regions entered since the local was declared decide whether it is assigned.
        let ctrl: Vec<Ctrl> = self
            .ctrl
            .iter()
            .filter(|c| c.depth > depth)
            .cloned()
            .collect();
        let Some(local) = self.scopes.get_mut(depth).and_then(|s| s.get_mut(&name)) else {
            return Lowered::new(TokenStream::new(), Kind::Unit);
        };
        local.uses.extend(r.uses.iter().copied());
        local.names.extend(r.names.iter().cloned());
        local.range = None;
        local.degree = match op {
            None | Some(BinOp::AddAssign(_)) | Some(BinOp::SubAssign(_)) => {
                local.degree.max(r.degree)
            }
            Some(BinOp::DivAssign(_)) if r.degree == Degree::CONST => local.degree,
            _ => local.degree.max(r.degree).opaque(),
        };
        for c in &ctrl {
            local.uses.extend(c.uses.iter().copied());
            local.names.extend(c.names.iter().cloned());
            if c.degree != Degree::CONST {
                // A value chosen by a condition on coordinates is piecewise: no polynomial.
                local.degree = local.degree.max(c.degree).opaque();
            }
        }
        let lkind = local.kind.clone();
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&r);
        out.atomic = false;
        if lkind != Kind::Int {
            r.make_real();
        }
        let rt = if lkind == Kind::Dual {
            r.as_dual(right.span())
        } else {
            r.tokens.clone()
        };
        out.tokens = match op {
            Some(op) => quote!(#ident #op #rt),
            None => quote!(#ident = #rt),
        };
        out
    }

    fn method(&mut self, m: &syn::ExprMethodCall) -> Lowered {
        let recv = self.expr(&m.receiver);
        let name = m.method.to_string();
        let method = &m.method;
        if m.turbofish.is_some() {
            return self.unsupported(m, "a turbofish");
        }
        match &recv.kind {
            Kind::Array(g) => {
                if name == "len" && m.args.is_empty() {
                    let rt = recv.operand();
                    let mut out = Lowered::new(quote!(#rt.#method()), Kind::Int);
                    out.range = self.env.groups[*g]
                        .len
                        .literal()
                        .and_then(|n| i64::try_from(n).ok())
                        .map(IntRange::point);
                    return out;
                }
                self.unsupported(
                    m,
                    "a method on a coordinate array (index it instead, as in `q[i]`, or use `.len()`)",
                )
            }
            Kind::Iter(item) => self.iter_method(m, recv.clone(), (**item).clone()),
            Kind::Dual | Kind::Real | Kind::Int => self.scalar_method(m, recv),
            _ => self.unsupported(m, "this method call"),
        }
    }

    fn scalar_method(&mut self, m: &syn::ExprMethodCall, mut recv: Lowered) -> Lowered {
        let name = m.method.to_string();
        let mut method = m.method.clone();
        let mut out = recv.clone();
        out.atomic = true;
        out.range = None;
        out.lit_f64 = None;
        let mut args = Vec::new();
        let mut all_const = recv.degree == Degree::CONST;
        for a in &m.args {
            let la = self.expr(a);
            out.absorb(&la);
            all_const &= la.degree == Degree::CONST;
            out.degree = out.degree.max(la.degree);
            args.push(la);
        }
        let int_method = matches!(name.as_str(), "min" | "max" | "pow" | "abs" | "rem_euclid");
        let all_int = recv.kind == Kind::Int && args.iter().all(|a| a.kind == Kind::Int);
        if all_int && int_method {
            let rt = recv.operand();
            let at = args.iter().map(|a| &a.tokens);
            out.kind = Kind::Int;
            out.degree = Degree::CONST;
            out.tokens = quote!(#rt.#method(#(#at),*));
            return out;
        }
        // Everything else is real arithmetic: integer literals become `f64` (a receiver
        // suffixed, `2.0_f64.sqrt()`, so that its type is known).
        if let Some(x) = float_literal(&m.receiver) {
            let l = proc_macro2::Literal::f64_suffixed(x);
            recv.tokens = quote!(#l);
            recv.atomic = true;
        }
        if recv.kind == Kind::Int {
            if let Some(x) = recv.lit_f64.or_else(|| recv.int().map(|k| k as f64)) {
                if x.is_finite() {
                    let l = proc_macro2::Literal::f64_suffixed(x.abs());
                    recv.tokens = if x < 0.0 { quote!((-#l)) } else { quote!(#l) };
                    recv.kind = Kind::Real;
                    recv.atomic = true;
                }
            }
        }
        recv.make_real();
        if name != "powi" {
            for a in &mut args {
                a.make_real();
            }
        }
        let any_dual = recv.kind == Kind::Dual || args.iter().any(|a| a.kind == Kind::Dual);
        out.kind = if any_dual { Kind::Dual } else { Kind::Real };
        let powi = (name == "powi")
            .then(|| args.first().and_then(|a| a.int()))
            .flatten()
            .and_then(|n| u32::try_from(n).ok());
        out.degree = match powi {
            Some(n) if args.len() == 1 => recv.degree.times(n),
            _ if all_const => Degree::CONST,
            _ => out.degree.opaque(),
        };
        if !any_dual {
            let rt = recv.operand();
            let at = args.iter().map(|a| &a.tokens);
            out.tokens = quote!(#rt.#method(#(#at),*));
            return out;
        }
        let span = m.span();
        if matches!(name.as_str(), "max" | "min") && args.len() == 1 {
            // num-dual has no `max`/`min`: choose by comparing values.
            let a = recv.as_dual(m.receiver.span());
            let b = args.first().map(|x| x.as_dual(span)).unwrap_or_default();
            let cmp = if name == "max" {
                quote!(>=)
            } else {
                quote!(<=)
            };
            out.degree = out.degree.opaque();
            out.tokens = quote_spanned! {span=>
                {
                    let __fvi_a: __D = #a;
                    let __fvi_b: __D = #b;
                    if __fvi_a #cmp __fvi_b { __fvi_a } else { __fvi_b }
                }
            };
            return out;
        }
        if name == "powf" && args.first().is_some_and(|a| a.kind == Kind::Dual) {
            method = Ident::new("powd", m.method.span());
        }
        // Methods whose arguments are `Self` in DualNum.
        let method_name = method.to_string();
        if matches!(method_name.as_str(), "mul_add" | "powd" | "atan2") {
            for (a, orig) in args.iter_mut().zip(&m.args) {
                a.tokens = a.as_dual(orig.span());
                a.kind = Kind::Dual;
            }
        }
        let rt = if recv.kind == Kind::Dual {
            recv.operand()
        } else {
            recv.as_dual(m.receiver.span())
        };
        let at = args.iter().map(|a| &a.tokens);
        out.tokens = quote!(#rt.#method(#(#at),*));
        out
    }

    fn iter_method(&mut self, m: &syn::ExprMethodCall, recv: Lowered, item: Kind) -> Lowered {
        let name = m.method.to_string();
        let method = &m.method;
        let rt = recv.operand();
        let mut out = recv.clone();
        out.atomic = true;
        match name.as_str() {
            "map" => {
                let Some(Expr::Closure(c)) = m.args.first().filter(|_| m.args.len() == 1) else {
                    return self.unsupported(m, "`.map` without a one-argument closure");
                };
                let (Some(pat), 1) = (c.inputs.first(), c.inputs.len()) else {
                    return self.unsupported(c, "a closure with other than one argument");
                };
                let Some(ident) = pat_ident(pat) else {
                    return self.unsupported(pat, "this closure argument");
                };
                let param = Local {
                    kind: item,
                    uses: recv.uses.clone(),
                    names: BTreeSet::new(),
                    degree: Degree::CONST,
                    range: recv.range,
                };
                let body = self.repeated(&recv, ident, param, |l| l.expr(&c.body));
                out.absorb(&body);
                out.degree = out.degree.max(body.degree);
                out.kind = Kind::Iter(Box::new(body.kind.clone()));
                out.range = body.range;
                let bt = &body.tokens;
                let inputs = &c.inputs;
                out.tokens = quote!(#rt.#method(|#inputs| #bt));
            }
            "sum" | "product" if m.args.is_empty() => {
                let ty = match item {
                    Kind::Dual => quote!(__D),
                    Kind::Real => quote!(f64),
                    Kind::Int => quote!(usize),
                    _ => return self.unsupported(m, "this sum"),
                };
                if name == "product" {
                    out.degree = out.degree.opaque();
                }
                out.range = None;
                out.kind = item;
                out.tokens = quote!(#rt.#method::<#ty>());
            }
            "rev" | "step_by" | "skip" | "take" => {
                let mut args = Vec::new();
                for a in &m.args {
                    let la = self.expr(a);
                    out.absorb(&la);
                    args.push(la.tokens);
                }
                if name != "rev" {
                    // Some of the values, not necessarily the ends.
                    out.range = out.range.map(|r| IntRange { exact: false, ..r });
                }
                out.tokens = quote!(#rt.#method(#(#args),*));
            }
            _ => return self.unsupported(m, "this iterator method"),
        }
        out
    }

    fn call(&mut self, c: &syn::ExprCall) -> Lowered {
        let Expr::Path(func) = &*c.func else {
            return self.unsupported(&c.func, "calling this");
        };
        let mut out = Lowered::new(TokenStream::new(), Kind::Real);
        let mut args = Vec::new();
        let mut degree = Degree::CONST;
        for a in &c.args {
            let la = self.expr(a);
            out.absorb(&la);
            degree = degree.max(la.degree);
            if la.kind == Kind::Dual {
                out.kind = Kind::Dual;
            }
            args.push(la.tokens);
        }
        out.degree = degree.opaque();
        out.tokens = quote!(#func(#(#args),*));
        out
    }

    fn index(&mut self, i: &syn::ExprIndex) -> Lowered {
        let base = self.expr(&i.expr);
        let Kind::Array(g) = base.kind else {
            return self.unsupported(i, "indexing anything but a coordinate array");
        };
        let idx = self.expr(&i.index);
        let Some(group) = self.env.groups.get(g) else {
            return Lowered::new(TokenStream::new(), Kind::Real);
        };
        let velocity = group.velocity.to_string();
        let vel = base.names.contains(&velocity);
        let name = if vel { &group.velocity } else { &group.name };
        let len = group.len.literal();
        let in_range = |k: i64| len.is_some_and(|n| usize::try_from(k).is_ok_and(|k| k < n));
        let mut proven = false;
        let at = match (idx.range, len) {
            (Some(r), Some(_)) if in_range(r.lo) && in_range(r.hi) => {
                proven = true;
                match r.single().and_then(|k| usize::try_from(k).ok()) {
                    Some(k) => Idx::At(k),
                    None => Idx::All,
                }
            }
            (Some(r), Some(n)) if r.exact && self.dead == 0 => {
                let bad = if in_range(r.lo) { r.hi } else { r.lo };
                let index = &i.index;
                let shown = compact(&quote!(#index).to_string());
                let which = if r.single().is_some() {
                    format!("index {bad} is out of range")
                } else {
                    format!("index `{shown}` reaches {bad}, out of range")
                };
                self.cx.error_spanned_by(
                    &i.index,
                    format!(
                        "{which}: `{name}` has {n} entries (`{}: [f64; {n}]`)",
                        group.name
                    ),
                );
                Idx::All
            }
            (Some(r), None) => match r.single().and_then(|k| usize::try_from(k).ok()) {
                Some(k) => Idx::At(k),
                None => Idx::All,
            },
            _ => Idx::All,
        };
        let mut out = Lowered::new(TokenStream::new(), Kind::Dual);
        out.absorb(&base);
        out.absorb(&idx);
        out.uses.insert(Var {
            vel,
            group: g,
            idx: at,
        });
        out.degree = var_degree(vel);
        let (bt, it) = (&base.tokens, &idx.tokens);
        out.tokens = if proven {
            quote!(#bt[#it])
        } else {
            // Not proven in range: a checked access that yields NaN (and records the
            // index for `check_model`) instead of panicking.
            self.checked_index.set(true);
            let index = &i.index;
            let what = format!("{}[{}]", name, compact(&quote!(#index).to_string()));
            let span = i.span();
            quote_spanned!(span=> ::forced_vi::__private::at(&#bt[..], #it, #what))
        };
        out.atomic = true;
        out
    }

    fn cast(&mut self, c: &syn::ExprCast) -> Lowered {
        let inner = self.expr(&c.expr);
        let ty = &c.ty;
        let is_float = matches!(&*c.ty, syn::Type::Path(p) if p.path.is_ident("f64"));
        let mut out = inner.clone();
        out.kind = if is_float { Kind::Real } else { Kind::Int };
        out.lit_f64 = None;
        if is_float || inner.kind != Kind::Int {
            out.range = None;
        }
        let t = inner.operand();
        out.tokens = quote!(#t as #ty);
        out.atomic = false;
        out
    }

    /// A block; with `lift_tail`, its value is turned into a `__D` (or, with `real`, an
    /// integer value into an `f64`).
    fn block(&mut self, b: &syn::Block, lift_tail: bool) -> Lowered {
        let real = self.lift_real;
        self.lift_real = false;
        let mut out = self.block_inner(b, lift_tail, real);
        if real && lift_tail {
            out.kind = Kind::Real;
        }
        out
    }

    fn block_inner(&mut self, b: &syn::Block, lift_tail: bool, real: bool) -> Lowered {
        self.scopes.push(HashMap::new());
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        let mut stmts = TokenStream::new();
        let n = b.stmts.len();
        for (k, stmt) in b.stmts.iter().enumerate() {
            match stmt {
                Stmt::Local(local) => stmts.extend(self.local(local, &mut out)),
                Stmt::Expr(e, semi) => {
                    let le = self.expr(e);
                    out.absorb(&le);
                    if k + 1 == n && semi.is_none() {
                        out.kind = le.kind.clone();
                        out.degree = le.degree;
                        out.range = le.range;
                        out.lit_f64 = le.lit_f64;
                        let t = if lift_tail && real {
                            le.as_real()
                        } else if lift_tail {
                            out.kind = Kind::Dual;
                            le.as_dual(e.span())
                        } else {
                            le.tokens.clone()
                        };
                        stmts.extend(t);
                    } else {
                        let t = &le.tokens;
                        stmts.extend(quote!(#t #semi));
                    }
                }
                Stmt::Item(item) => {
                    self.unsupported(item, "an item");
                }
                Stmt::Macro(mac) => {
                    self.unsupported(mac, "a macro call");
                }
            }
        }
        self.scopes.pop();
        out.tokens = quote_spanned!(b.brace_token.span.join()=> { #stmts });
        out
    }

    fn local(&mut self, local: &syn::Local, out: &mut Lowered) -> TokenStream {
        let (pat, ty) = match &local.pat {
            Pat::Type(pt) => (&*pt.pat, Some(&pt.ty)),
            p => (p, None),
        };
        let Pat::Ident(pi) = pat else {
            self.unsupported(pat, "this pattern");
            return TokenStream::new();
        };
        if pi.by_ref.is_some() || pi.subpat.is_some() {
            self.unsupported(pat, "this pattern");
            return TokenStream::new();
        }
        let Some(init) = &local.init else {
            self.cx
                .error_spanned_by(local, "a `let` in a model expression needs a value");
            return TokenStream::new();
        };
        if init.diverge.is_some() {
            self.unsupported(local, "`let ... else`");
            return TokenStream::new();
        }
        let mut le = self.expr(&init.expr);
        out.absorb(&le);
        let ident = &pi.ident;
        let mutability = &pi.mutability;
        let is_f64 =
            ty.is_some_and(|t| matches!(&**t, syn::Type::Path(p) if p.path.is_ident("f64")));
        if is_f64 {
            le.make_real();
        }
        // An accumulator `let mut s = 0.0;` becomes a dual: it will collect dual terms.
        let promote = pi.mutability.is_some() && le.kind == Kind::Real && ty.is_none();
        let kind = if promote { Kind::Dual } else { le.kind.clone() };
        let value = if promote {
            le.as_dual(init.expr.span())
        } else {
            le.tokens.clone()
        };
        self.bind_user(
            ident,
            Local {
                kind,
                uses: le.uses.clone(),
                names: le.names.clone(),
                degree: le.degree,
                range: le.range,
            },
        );
        let ty = ty.map(|t| quote!(: #t));
        let let_token = &local.let_token;
        quote!(#let_token #mutability #ident #ty = #value;)
    }

    fn if_expr(&mut self, i: &syn::ExprIf) -> Lowered {
        let cond = self.expr(&i.cond);
        self.ctrl.push(Ctrl {
            depth: self.scopes.len(),
            uses: cond.uses.clone(),
            names: cond.names.clone(),
            degree: cond.degree,
        });
        let then_b = self.refined(&i.cond, true, |l| l.block(&i.then_branch, false));
        let else_b = i
            .else_branch
            .as_ref()
            .map(|(_, e)| self.refined(&i.cond, false, |l| l.expr(e)));
        self.ctrl.pop();
        let mut out = Lowered::new(TokenStream::new(), then_b.kind.clone());
        out.absorb(&cond);
        out.absorb(&then_b);
        out.atomic = false;
        let if_token = &i.if_token;
        let ct = &cond.tokens;
        let Some(else_b) = else_b else {
            out.kind = Kind::Unit;
            out.degree = Degree::CONST;
            let tt = &then_b.tokens;
            out.tokens = quote!(#if_token #ct #tt);
            return out;
        };
        out.absorb(&else_b);
        let mut degree = then_b.degree.max(else_b.degree);
        if cond.degree != Degree::CONST {
            degree = degree.max(cond.degree).opaque();
        }
        out.degree = degree;
        out.range = join_range(then_b.range, else_b.range);
        let real_like = |k: &Kind| matches!(k, Kind::Real | Kind::Int | Kind::Dual);
        let mixed =
            then_b.kind != else_b.kind && real_like(&then_b.kind) && real_like(&else_b.kind);
        let to_real = mixed && then_b.kind != Kind::Dual && else_b.kind != Kind::Dual;
        let (tt, et) = if to_real {
            // An integer branch beside an `f64` one: the integer is a number.
            out.kind = Kind::Real;
            out.range = None;
            let Some((_, else_expr)) = &i.else_branch else {
                return out;
            };
            let t = if then_b.kind == Kind::Int {
                self.silently(|l| {
                    l.lift_real = true;
                    l.block(&i.then_branch, true).tokens
                })
            } else {
                then_b.tokens.clone()
            };
            let e = if else_b.kind == Kind::Int {
                self.silently(|l| {
                    l.lift_real = true;
                    l.lift_branch(else_expr)
                })
            } else {
                else_b.tokens.clone()
            };
            (t, e)
        } else if mixed {
            out.kind = Kind::Dual;
            let Some((_, else_expr)) = &i.else_branch else {
                return out;
            };
            // Lift the `f64` branch so that both arms are `__D`.
            let t = if then_b.kind == Kind::Dual {
                then_b.tokens.clone()
            } else {
                self.silently(|l| l.block(&i.then_branch, true).tokens)
            };
            let e = if else_b.kind == Kind::Dual {
                else_b.tokens.clone()
            } else {
                self.silently(|l| l.lift_branch(else_expr))
            };
            (t, e)
        } else {
            (then_b.tokens.clone(), else_b.tokens.clone())
        };
        out.tokens = quote!(#if_token #ct #tt else #et);
        out
    }

    /// Runs `f` with the integer locals that `cond` compares narrowed to the values for
    /// which `cond == positive`; a branch that no value reaches is marked dead.
    fn refined<T>(&mut self, cond: &Expr, positive: bool, f: impl FnOnce(&mut Self) -> T) -> T {
        let mut facts = Vec::new();
        let understood = self.facts(cond, positive, &mut facts);
        let saved = self.scopes.clone();
        let mut dead = false;
        for (name, lo, hi) in &facts {
            let Some((depth, local)) = self.lookup(name) else {
                continue;
            };
            let Some(r) = local.range else {
                continue;
            };
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
        if dead {
            self.dead += 1;
        }
        let out = f(self);
        if dead {
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
    fn facts(&mut self, cond: &Expr, positive: bool, out: &mut Vec<(String, i64, i64)>) -> bool {
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
                // Normalise to `name OP k`.
                let op = match (b.op, flipped) {
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
                    _ => return false,
                };
                let op = if positive {
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

    /// Lowers a loop body or a `map` closure, which runs any number of times: the locals it
    /// assigns are analysed to a fixpoint (silently), then the body is lowered once more
    /// for real from that state.
    fn repeated(
        &mut self,
        iter: &Lowered,
        var: &Ident,
        param: Local,
        mut f: impl FnMut(&mut Lowerer<'_>) -> Lowered,
    ) -> Lowered {
        self.ctrl.push(Ctrl {
            depth: self.scopes.len(),
            uses: iter.uses.clone(),
            names: iter.names.clone(),
            degree: iter.degree,
        });
        let dead = iter.range.is_some_and(|r| r.lo > r.hi);
        let param = Local {
            range: param.range.filter(|r| r.lo <= r.hi),
            ..param
        };
        let mut converged = false;
        let mut last_uses = BTreeSet::new();
        for pass in 0..MAX_PASSES {
            let before = self.scopes.clone();
            let (after, uses) = self.silently(|l| {
                l.scopes.push(HashMap::new());
                l.bind(var, param.clone());
                let body = f(l);
                l.scopes.pop();
                (l.scopes.clone(), body.uses)
            });
            last_uses = uses;
            let joined = join_scopes(&before, &after, pass >= 1);
            let stable = joined == before;
            self.scopes = joined;
            if stable || self.budget.get() == 0 {
                converged = true;
                break;
            }
        }
        if !converged {
            // Widen what still changes: any polynomial degree, any use seen anywhere.
            let mut all: BTreeSet<Var> = last_uses;
            for scope in &self.scopes {
                for l in scope.values() {
                    all.extend(l.uses.iter().copied());
                }
            }
            for scope in &mut self.scopes {
                for l in scope.values_mut() {
                    l.uses.extend(all.iter().copied());
                    if l.degree != Degree::CONST {
                        l.degree = Degree { q: None, v: None };
                    }
                    l.range = None;
                }
            }
        }
        let state = self.scopes.clone();
        if dead {
            self.dead += 1;
        }
        self.scopes.push(HashMap::new());
        self.bind_user(var, param);
        let body = f(self);
        self.scopes.pop();
        if dead {
            self.dead -= 1;
        }
        self.scopes = state;
        self.ctrl.pop();
        body
    }

    /// An `else` branch whose value is lifted to `__D` (to `f64` with `lift_real`).
    fn lift_branch(&mut self, e: &Expr) -> TokenStream {
        let real = self.lift_real;
        match e {
            Expr::Block(b) => self.block(&b.block, true).tokens,
            Expr::If(i) => {
                let cond = self.expr(&i.cond);
                let ct = &cond.tokens;
                self.lift_real = real;
                let tt = self.block(&i.then_branch, true).tokens;
                self.lift_real = real;
                let if_token = &i.if_token;
                match &i.else_branch {
                    Some((_, e)) => {
                        let et = self.lift_branch(e);
                        quote!(#if_token #ct #tt else #et)
                    }
                    None => quote!(#if_token #ct #tt),
                }
            }
            other => {
                self.lift_real = false;
                let l = self.expr(other);
                if real {
                    l.as_real()
                } else {
                    l.as_dual(other.span())
                }
            }
        }
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
        };
        let out = f(&mut l);
        // The quiet context's errors are reported by the real pass.
        let _ = quiet.check();
        out
    }

    fn for_loop(&mut self, f: &syn::ExprForLoop) -> Lowered {
        if f.label.is_some() {
            return self.unsupported(f, "a labelled loop");
        }
        let iter = self.expr(&f.expr);
        let Kind::Iter(item) = iter.kind.clone() else {
            return self.unsupported(&f.expr, "looping over anything but a range");
        };
        let Some(ident) = pat_ident(&f.pat) else {
            return self.unsupported(&f.pat, "this loop pattern");
        };
        let param = Local {
            kind: *item,
            uses: iter.uses.clone(),
            names: BTreeSet::new(),
            degree: Degree::CONST,
            range: iter.range,
        };
        let body = self.repeated(&iter, ident, param, |l| l.block(&f.body, false));
        let mut out = Lowered::new(TokenStream::new(), Kind::Unit);
        out.absorb(&iter);
        out.absorb(&body);
        out.atomic = false;
        let (for_token, in_token, pat) = (&f.for_token, &f.in_token, &f.pat);
        let (it, bt) = (&iter.tokens, &body.tokens);
        out.tokens = quote!(#for_token #pat #in_token #it #bt);
        out
    }

    fn range(&mut self, r: &syn::ExprRange) -> Lowered {
        let mut out = Lowered::new(TokenStream::new(), Kind::Iter(Box::new(Kind::Int)));
        let (Some(start), Some(end)) = (&r.start, &r.end) else {
            return self.unsupported(r, "an open range");
        };
        let s = self.expr(start);
        let e = self.expr(end);
        out.absorb(&s);
        out.absorb(&e);
        out.atomic = false;
        let closed = matches!(r.limits, syn::RangeLimits::Closed(_));
        out.range = match (s.range, e.range) {
            (Some(a), Some(b)) => {
                let hi = if closed {
                    Some(b.hi)
                } else {
                    b.hi.checked_sub(1)
                };
                hi.map(|hi| IntRange {
                    lo: a.lo,
                    hi,
                    exact: a.single().is_some() && b.single().is_some() && a.exact && b.exact,
                })
            }
            _ => None,
        };
        let (st, et, limits) = (s.operand(), e.operand(), &r.limits);
        out.tokens = quote!(#st #limits #et);
        out
    }
}

/// An unsuffixed, finite float literal (through parentheses).
fn float_literal(e: &Expr) -> Option<f64> {
    match e {
        Expr::Paren(p) => float_literal(&p.expr),
        Expr::Lit(syn::ExprLit {
            lit: Lit::Float(f), ..
        }) if f.suffix().is_empty() => f.base10_parse::<f64>().ok().filter(|x| x.is_finite()),
        _ => None,
    }
}

fn var_degree(vel: bool) -> Degree {
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

/// The interval of `l OP r` for integers (`None`: unknown).
fn int_op(op: BinOp, l: Option<IntRange>, r: Option<IntRange>) -> Option<IntRange> {
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

fn join_scopes(a: &Scopes, b: &Scopes, widen: bool) -> Scopes {
    a.iter()
        .zip(b)
        .map(|(sa, sb)| {
            sa.iter()
                .map(|(k, la)| {
                    let l = match sb.get(k) {
                        Some(lb) => la.join(lb, widen),
                        None => la.clone(),
                    };
                    (k.clone(), l)
                })
                .collect()
        })
        .collect()
}

fn local_name(e: &Expr) -> Option<String> {
    match e {
        Expr::Path(p) if p.qself.is_none() => p.path.get_ident().map(|i| i.to_string()),
        Expr::Paren(p) => local_name(&p.expr),
        _ => None,
    }
}

fn mentions_int_local(l: &Lowerer<'_>, e: &Expr) -> bool {
    let mut names = Vec::new();
    idents_in(&e.to_token_stream(), &mut names);
    names
        .iter()
        .any(|n| l.lookup(n).is_some_and(|(_, x)| x.kind == Kind::Int))
}

fn idents_in(t: &TokenStream, out: &mut Vec<String>) {
    for tt in t.clone() {
        match tt {
            proc_macro2::TokenTree::Ident(i) => out.push(i.to_string()),
            proc_macro2::TokenTree::Group(g) => idents_in(&g.stream(), out),
            _ => {}
        }
    }
}

fn pat_ident(p: &Pat) -> Option<&Ident> {
    match p {
        Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => Some(&pi.ident),
        Pat::Type(pt) => pat_ident(&pt.pat),
        _ => None,
    }
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
