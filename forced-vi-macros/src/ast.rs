//! The parse phase: the attribute's arguments and the struct, as a typed IR whose nodes keep
//! the user's tokens (for spans). Nothing here judges meaning; `check` does.
//!
//! ```text
//! #[forced_lagrangian(
//!     coordinates(x, y),                  // or coordinates(q: [f64; 8]) / [f64; N]
//!     lagrangian = <expr>,
//!     force(x = <expr>, y = <expr>),      // optional; q[i] = <expr> or q = [<expr>, …]
//!     constraints(<expr>, <expr>),        // optional: holonomic g(t, q) = 0
//! )]
//! struct Model { /* f64 parameters */ }
//! ```

use proc_macro2::{Delimiter, Span, TokenStream, TokenTree};
use syn::parse::{Parse, ParseStream, Parser};
use syn::punctuated::Punctuated;
use syn::{Expr, Ident, Token, Type};

use crate::ctxt::Ctxt;

/// Everything the user wrote: the struct and the attribute's arguments.
pub struct Model {
    /// The struct, re-emitted unchanged.
    pub item: syn::ItemStruct,
    /// The named fields, in order.
    pub params: Vec<Param>,
    /// The `coordinates(...)` argument: its keyword and its entries.
    pub coordinates: Option<(Ident, Vec<Coord>)>,
    /// The `lagrangian = ...` argument: its keyword and expression.
    pub lagrangian: Option<(Ident, Expr)>,
    /// The optional `force(...)` argument.
    pub force: Option<Force>,
    /// The optional `constraints(...)` argument: its keyword and the expressions `g_k` that
    /// must vanish.
    pub constraints: Option<(Ident, Vec<Expr>)>,
}

/// A named field of the struct: a parameter of the model.
pub struct Param {
    pub ident: Ident,
    pub ty: Type,
}

/// A coordinate declaration, `x` or `q: [f64; 8]`.
pub struct Coord {
    pub name: Ident,
    /// The velocity's name, `<name>_dot`, with the name's span.
    pub velocity: Ident,
    /// `None` for a scalar, else the declared type (checked to be `[f64; LEN]`).
    pub ty: Option<Type>,
}

/// The `force(...)` argument.
pub struct Force {
    pub key: Ident,
    pub entries: Vec<ForceEntry>,
}

/// One entry of `force(...)`.
pub struct ForceEntry {
    /// The coordinate the force acts on.
    pub target: Ident,
    /// `i` in `q[i] = ...`.
    pub index: Option<Ident>,
    pub value: Expr,
}

impl Coord {
    fn new(name: Ident, ty: Option<Type>) -> Coord {
        let velocity = velocity_name(&name);
        Coord { name, velocity, ty }
    }
}

/// The velocity of coordinate `x` is `x_dot` (a raw `r#x` is refused by `check`; its
/// velocity is still a valid name here, `x_dot`).
pub fn velocity_name(name: &Ident) -> Ident {
    use syn::ext::IdentExt;
    Ident::new(&format!("{}_dot", name.unraw()), name.span())
}

/// Parses the item and the attribute's arguments. A malformed argument is recorded in `cx`
/// and skipped, so that the others are still checked. `Err` only when the item is not a
/// struct (then there is nothing to attach an impl to).
pub fn parse(cx: &Ctxt, args: TokenStream, item: syn::Item) -> Result<Model, Box<syn::Item>> {
    let item = match item {
        syn::Item::Struct(s) => s,
        other => {
            cx.error_spanned_by(
                item_keyword(&other),
                "#[forced_lagrangian] goes on a struct whose named fields are the model's `f64` parameters",
            );
            return Err(Box::new(other));
        }
    };
    let params = match &item.fields {
        syn::Fields::Named(named) => named
            .named
            .iter()
            .filter_map(|f| {
                f.ident.clone().map(|ident| Param {
                    ident,
                    ty: f.ty.clone(),
                })
            })
            .collect(),
        syn::Fields::Unnamed(unnamed) => {
            cx.error_spanned_by(
                unnamed,
                "the parameters of a model are named fields: write `struct Name { k: f64 }`",
            );
            Vec::new()
        }
        syn::Fields::Unit => Vec::new(),
    };
    let mut model = Model {
        item,
        params,
        coordinates: None,
        lagrangian: None,
        force: None,
        constraints: None,
    };
    let mut seen = Vec::new();
    for chunk in split_top_level_commas(args) {
        if let Some(TokenTree::Ident(key)) = chunk.clone().into_iter().next() {
            seen.push(key.to_string());
        }
        parse_argument(cx, &mut model, chunk);
    }
    // A malformed argument has its own error; do not also call it missing.
    let seen = |key: &str| seen.iter().any(|s| s == key);
    if model.coordinates.is_none() && !seen("coordinates") {
        cx.error_at(
            Span::call_site(),
            "missing `coordinates(...)`: name the coordinates, for example `coordinates(x, y)`",
        );
    }
    if model.lagrangian.is_none() && !seen("lagrangian") {
        cx.error_at(
            Span::call_site(),
            "missing `lagrangian = ...`: give the Lagrangian as an expression",
        );
    }
    Ok(model)
}

/// The token that names the kind of a non-struct item, for the error's span.
fn item_keyword(item: &syn::Item) -> TokenStream {
    use quote::ToTokens;
    match item {
        syn::Item::Enum(e) => e.enum_token.to_token_stream(),
        syn::Item::Fn(f) => f.sig.fn_token.to_token_stream(),
        syn::Item::Union(u) => u.union_token.to_token_stream(),
        syn::Item::Trait(t) => t.trait_token.to_token_stream(),
        syn::Item::Impl(i) => i.impl_token.to_token_stream(),
        syn::Item::Mod(m) => m.mod_token.to_token_stream(),
        syn::Item::Type(t) => t.type_token.to_token_stream(),
        syn::Item::Const(c) => c.const_token.to_token_stream(),
        syn::Item::Static(s) => s.static_token.to_token_stream(),
        other => other.to_token_stream(),
    }
}

/// Splits the arguments at the commas that are not inside a delimiter.
fn split_top_level_commas(args: TokenStream) -> Vec<TokenStream> {
    let mut chunks = Vec::new();
    let mut current = Vec::new();
    for tt in args {
        match &tt {
            TokenTree::Punct(p) if p.as_char() == ',' => {
                chunks.push(current.drain(..).collect());
            }
            _ => current.push(tt),
        }
    }
    if !current.is_empty() {
        chunks.push(current.into_iter().collect());
    }
    chunks
}

fn parse_argument(cx: &Ctxt, model: &mut Model, chunk: TokenStream) {
    let mut tokens = chunk.clone().into_iter();
    let Some(first) = tokens.next() else {
        return;
    };
    let key = match &first {
        TokenTree::Ident(ident) => ident.clone(),
        other => {
            cx.error_spanned_by(
                other,
                "expected `coordinates(...)`, `lagrangian = ...`, `force(...)` or `constraints(...)`",
            );
            return;
        }
    };
    let rest: TokenStream = tokens.collect();
    let duplicate = |what: &str| {
        cx.error_spanned_by(&key, format!("duplicate `{what}` argument"));
    };
    match key.to_string().as_str() {
        "coordinates" => match parenthesised(&key, rest)
            .and_then(|body| Punctuated::<CoordDecl, Token![,]>::parse_terminated.parse2(body))
        {
            Ok(list) => {
                if model.coordinates.is_some() {
                    duplicate("coordinates");
                } else {
                    let coords = list.into_iter().map(|d| Coord::new(d.name, d.ty)).collect();
                    model.coordinates = Some((key, coords));
                }
            }
            Err(e) => cx.syn_error(e),
        },
        "lagrangian" => match (|input: ParseStream| {
            input.parse::<Token![=]>()?;
            input.parse::<Expr>()
        })
        .parse2(rest)
        {
            Ok(expr) => {
                if model.lagrangian.is_some() {
                    duplicate("lagrangian");
                } else {
                    model.lagrangian = Some((key, expr));
                }
            }
            Err(e) => cx.syn_error(e),
        },
        "force" => match parenthesised(&key, rest).and_then(|body| {
            Punctuated::<ForceEntry, Token![,]>::parse_terminated.parse2(body)
        }) {
            Ok(list) => {
                if model.force.is_some() {
                    duplicate("force");
                } else {
                    model.force = Some(Force {
                        key,
                        entries: list.into_iter().collect(),
                    });
                }
            }
            Err(e) => cx.syn_error(e),
        },
        "constraints" => match parenthesised(&key, rest)
            .and_then(|body| Punctuated::<Expr, Token![,]>::parse_terminated.parse2(body))
        {
            Ok(list) => {
                if model.constraints.is_some() {
                    duplicate("constraints");
                } else if list.is_empty() {
                    cx.error_spanned_by(&key, "`constraints()` is empty: list the expressions that must vanish, or leave the argument out");
                } else {
                    model.constraints = Some((key, list.into_iter().collect()));
                }
            }
            Err(e) => cx.syn_error(e),
        },
        other => cx.error_spanned_by(
            &key,
            format!(
                "unknown argument `{other}`: expected `coordinates(...)`, `lagrangian = ...`, `force(...)` or `constraints(...)`"
            ),
        ),
    }
}

/// The contents of `( ... )` right after `key`, which must be all that follows it.
fn parenthesised(key: &Ident, rest: TokenStream) -> syn::Result<TokenStream> {
    let mut tokens = rest.into_iter();
    match (tokens.next(), tokens.next()) {
        (Some(TokenTree::Group(g)), None) if g.delimiter() == Delimiter::Parenthesis => {
            Ok(g.stream())
        }
        (_, Some(extra)) => Err(syn::Error::new_spanned(
            extra,
            format!("unexpected tokens after `{key}(...)`"),
        )),
        (Some(other), None) => Err(syn::Error::new_spanned(
            other,
            format!("expected parentheses: `{key}(...)`"),
        )),
        (None, None) => Err(syn::Error::new_spanned(
            key,
            format!("expected parentheses: `{key}(...)`"),
        )),
    }
}

struct CoordDecl {
    name: Ident,
    ty: Option<Type>,
}

impl Parse for CoordDecl {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let name: Ident = input.parse()?;
        let ty = if input.peek(Token![:]) {
            input.parse::<Token![:]>()?;
            Some(input.parse::<Type>()?)
        } else {
            None
        };
        Ok(CoordDecl { name, ty })
    }
}

impl Parse for ForceEntry {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let target: Ident = input.parse()?;
        let index = if input.peek(syn::token::Bracket) {
            let inner;
            syn::bracketed!(inner in input);
            let index: Ident = inner.parse()?;
            if !inner.is_empty() {
                return Err(inner.error("expected one index variable, as in `q[i] = ...`"));
            }
            Some(index)
        } else {
            None
        };
        input.parse::<Token![=]>()?;
        let value: Expr = input.parse()?;
        Ok(ForceEntry {
            target,
            index,
            value,
        })
    }
}
