//! The expand phase: generates the impl from a checked model. Nothing here validates.
//!
//! Generated items, all reaching the runtime through `::forced_vi::__private`:
//! - `impl ForcedLagrangian<N>`: `lagrangian`, `force` (only with a force), `STRUCTURE`,
//!   `coordinate_names`, `check_parameters`, and the specialised kernels `node_gradient`,
//!   `node_jacobian` and `mass_matrix`;
//! - for a driven model (one that names `t`): `lagrangian_at` and `force_at` instead, with
//!   `lagrangian`/`force` their values at `t = 0`, `STRUCTURE.uses_time`, and no
//!   specialised kernels (the runtime's general ones take the time);
//! - an inherent `doubled_lagrangian` and one hidden helper per non-polynomial term of `L`
//!   and per force entry.
//!
//! The kernels add up, per block, only what the model has: polynomial terms as `f64` code
//! derived at compile time (see `poly`), other terms with the smallest dual number over the
//! variables they use, and the force only where it acts.

use std::collections::{BTreeMap, BTreeSet};

use proc_macro2::{Literal, Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};
use syn::Ident;

use crate::check::{slots, Checked};
use crate::lower::{dual_ident, Env, Idx, Len, Lowered, Var, TIME};
use crate::poly::Poly;

fn fvi() -> TokenStream {
    quote!(::forced_vi::__private)
}

fn lit(n: usize) -> Literal {
    Literal::usize_unsuffixed(n)
}

/// `let` bindings for the model names an expression uses: coordinates and velocities from
/// the arrays `q` and `v`, parameters from `self`.
pub fn bindings(
    env: &Env,
    n: &Len,
    names: &BTreeSet<String>,
    q: &Ident,
    v: &Ident,
    scalar: &TokenStream,
) -> TokenStream {
    let mut out = TokenStream::new();
    for g in &env.groups {
        for (name, arr) in [(&g.name, q), (&g.velocity, v)] {
            if !names.contains(&name.to_string()) {
                continue;
            }
            let offset = lit(g.offset);
            let len = &g.len;
            out.extend(if !g.array {
                quote!(let #name: #scalar = #arr[#offset];)
            } else if env.groups.len() == 1 {
                quote!(let #name: &[#scalar; #n] = #arr;)
            } else {
                quote!(let #name: [#scalar; #len] = ::core::array::from_fn(|__fvi_k| #arr[#offset + __fvi_k]);)
            });
        }
    }
    for p in &env.params {
        if names.contains(&p.to_string()) {
            out.extend(quote!(let #p: f64 = self.#p;));
        }
    }
    out
}

/// All parameters as `f64` locals (for polynomial coefficients), allowed to go unused.
fn param_bindings(env: &Env) -> TokenStream {
    let ps = &env.params;
    quote!(#( #[allow(unused_variables)] let #ps: f64 = self.#ps; )*)
}

/// The generated code for a checked model.
pub fn generate(c: &Checked) -> TokenStream {
    let fvi = fvi();
    let model = c.model;
    let item = &model.item;
    let ident = &item.ident;
    let (ig, tg, wc) = item.generics.split_for_impl();
    let n = &c.n;
    let d = dual_ident();
    let scalar_bound = quote!(#fvi::Scalar);
    let dq = format_ident!("__fvi_q");
    let dv = format_ident!("__fvi_v");
    let d_ty = quote!(#d);
    let timed = c.uses_time;
    let dt = format_ident!("__fvi_t");
    let time = Ident::new(TIME, Span::call_site());
    // In a driven model, `t` bound from the `__fvi_t` argument where an expression uses it.
    let time_binding = |names: &BTreeSet<String>| -> TokenStream {
        if names.contains(TIME) {
            quote!(let #time: #d = #dt;)
        } else {
            quote!(let _ = #dt;)
        }
    };
    let time_param = timed.then(|| quote!(#dt: #d,));
    let time_arg = timed.then(|| quote!(#dt,));
    // A model that splits into local terms gets per-term kernels (DESIGN §9); a large one
    // also computes its dense blocks through them.
    let split = c.split.as_ref();
    let through = split.is_some() && crate::sparse::dense_through_split(c);

    // L(q, v), generic; for a driven model L(t, q, v), with `lagrangian` its value at t = 0.
    let l_bind = bindings(&c.env, n, &c.lagrangian.names, &dq, &dv, &d_ty);
    let l_body = lowered_dual(&c.lagrangian);
    let lagrangian = if timed {
        let t_bind = time_binding(&c.lagrangian.names);
        quote! {
            #[inline]
            #[allow(unused_braces, unused_parens)]
            fn lagrangian_at<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], #dv: &[#d; #n]) -> #d {
                #t_bind
                #l_bind
                #l_body
            }
            #[inline]
            fn lagrangian<#d: #scalar_bound>(&self, #dq: &[#d; #n], #dv: &[#d; #n]) -> #d {
                <Self as #fvi::ForcedLagrangian<#n>>::lagrangian_at(self, #d::from(0.0), #dq, #dv)
            }
        }
    } else {
        quote! {
            #[inline]
            #[allow(unused_braces, unused_parens)]
            fn lagrangian<#d: #scalar_bound>(&self, #dq: &[#d; #n], #dv: &[#d; #n]) -> #d {
                #l_bind
                #l_body
            }
        }
    };

    // Helpers: non-polynomial terms and force entries.
    let mut helpers = TokenStream::new();
    // A driven model uses the runtime's general kernels, which call no term helper; nor do
    // kernels that go through the per-term code.
    let dual_terms: &[crate::check::Term] = if timed || through { &[] } else { &c.dual_terms };
    for (k, t) in dual_terms.iter().enumerate() {
        let name = format_ident!("__fvi_l{}", k);
        let bind = bindings(&c.env, n, &t.lowered.names, &dq, &dv, &d_ty);
        let body = lowered_dual(&t.lowered);
        helpers.extend(quote! {
            #[doc(hidden)]
            #[inline(always)]
            #[allow(unused_braces, unused_parens)]
            fn #name<#d: #scalar_bound>(&self, #dq: &[#d; #n], #dv: &[#d; #n]) -> #d {
                #bind
                #body
            }
        });
    }
    let mut force_method = TokenStream::new();
    if let Some(force) = &c.force {
        for (k, f) in force.fns.iter().enumerate() {
            let name = format_ident!("__fvi_f{}", k);
            let bind = bindings(&c.env, n, &f.lowered.names, &dq, &dv, &d_ty);
            let t_bind = timed.then(|| time_binding(&f.lowered.names));
            let body = lowered_dual(&f.lowered);
            let index = f.index.as_ref().map(|i| quote!(, #i: usize));
            helpers.extend(quote! {
                #[doc(hidden)]
                #[inline(always)]
                #[allow(unused_braces, unused_parens)]
                fn #name<#d: #scalar_bound>(&self, #time_param #dq: &[#d; #n], #dv: &[#d; #n] #index) -> #d {
                    #t_bind
                    #bind
                    #body
                }
            });
        }
        let body = match n {
            Len::Lit(_) => {
                let calls = force.rows.iter().map(|r| {
                    let name = format_ident!("__fvi_f{}", r.func);
                    let index = r.index.map(|i| {
                        let i = lit(i);
                        quote!(, #i)
                    });
                    quote!(self.#name(#time_arg #dq, #dv #index))
                });
                quote!([#(#calls),*])
            }
            Len::Param(_) => {
                quote!(::core::array::from_fn(|__fvi_k| self.__fvi_f0(#time_arg #dq, #dv, __fvi_k)))
            }
        };
        force_method = if timed {
            quote! {
                #[inline]
                #[allow(unused_braces, unused_parens)]
                fn force_at<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], #dv: &[#d; #n]) -> [#d; #n] {
                    #body
                }
                #[inline]
                fn force<#d: #scalar_bound>(&self, #dq: &[#d; #n], #dv: &[#d; #n]) -> [#d; #n] {
                    <Self as #fvi::ForcedLagrangian<#n>>::force_at(self, #d::from(0.0), #dq, #dv)
                }
            }
        } else {
            quote! {
                #[inline]
                #[allow(unused_braces, unused_parens)]
                fn force<#d: #scalar_bound>(&self, #dq: &[#d; #n], #dv: &[#d; #n]) -> [#d; #n] {
                    #body
                }
            }
        };
    }

    let has_force = c.force.is_some();
    let force_uses_velocity = c.force.as_ref().is_some_and(|f| f.uses_v);
    let constant_mass = c.constant_mass;
    let names = coordinate_names(c);
    let checks = c.env.params.iter().map(|p| {
        let s = p.to_string();
        quote!(if !self.#p.is_finite() { return ::core::result::Result::Err(#s); })
    });
    // A driven model keeps the runtime's general kernels (they take `t`), and their stack
    // bound; an autonomous one gets the specialised kernels.
    let kernels_and_stack = (!timed && !through).then(|| {
        let (kernels, stack) = kernels(c);
        let stack_bytes = stack
            .into_iter()
            .reduce(|a, b| quote!(#fvi::max_usize(#a, #b)));
        quote! {
            const KERNEL_STACK_BYTES: usize = #stack_bytes;
            #kernels
        }
    });
    let check_model = c.checked_index.then(|| {
        let force = c.force.as_ref().map(|_| {
            quote!(let _ = <Self as #fvi::ForcedLagrangian<#n>>::force::<f64>(self, &__fvi_z, &__fvi_z);)
        });
        quote! {
            fn check_model(&self) -> ::core::result::Result<(), ::std::string::String> {
                // Indices that the macro could not prove in range are checked accesses;
                // one evaluation runs every loop iteration and reports the first that
                // falls outside.
                let _ = #fvi::take_index_fault();
                let __fvi_z = [0.0f64; #n];
                let _ = <Self as #fvi::ForcedLagrangian<#n>>::lagrangian::<f64>(self, &__fvi_z, &__fvi_z);
                #force
                match #fvi::take_index_fault() {
                    ::core::option::Option::Some(__fvi_what) => ::core::result::Result::Err(::std::format!(
                        "index `{}` is out of range: the model has {} coordinates",
                        __fvi_what, #n
                    )),
                    ::core::option::Option::None => ::core::result::Result::Ok(()),
                }
            }
        }
    });

    let (split_items, sparse_impl) = match split {
        Some(s) => {
            helpers.extend(crate::sparse::helpers(c, s));
            (crate::sparse::trait_items(c), crate::sparse::sparse_impl(c))
        }
        None => (TokenStream::new(), TokenStream::new()),
    };

    quote! {
        #item

        #[automatically_derived]
        impl #ig #fvi::ForcedLagrangian<#n> for #ident #tg #wc {
            const STRUCTURE: #fvi::Structure = #fvi::Structure {
                has_force: #has_force,
                force_uses_velocity: #force_uses_velocity,
                constant_mass: #constant_mass,
                uses_time: #timed,
            };
            fn coordinate_names(&self) -> [&'static str; #n] {
                #names
            }
            #lagrangian
            #force_method
            fn check_parameters(&self) -> ::core::result::Result<(), &'static str> {
                #(#checks)*
                ::core::result::Result::Ok(())
            }
            #check_model
            #kernels_and_stack
            #split_items
        }

        #sparse_impl

        #[automatically_derived]
        impl #ig #ident #tg #wc {
            /// Galley's doubled Lagrangian `Λ(t, q, v, Q, V) = L(t, Q, V) − L(t, q, v)
            /// + ½ (F(t, q, v) + F(t, Q, V)) · (Q − q)` of this model (`t` is ignored by an
            /// autonomous model).
            #[allow(dead_code)]
            pub fn doubled_lagrangian<#d: #scalar_bound>(
                &self,
                t: #d,
                q: &[#d; #n],
                v: &[#d; #n],
                big_q: &[#d; #n],
                big_v: &[#d; #n],
            ) -> #d {
                #fvi::doubled::doubled_lagrangian_at(self, t, q, v, big_q, big_v)
            }
            #helpers
        }
    }
}

/// The lowered tokens as a `__D` value, spanned at the user's expression.
/// In expression position (`identity(...)`), so that a body starting with a block or an
/// `if` is not read as a statement.
fn lowered_dual(l: &Lowered) -> TokenStream {
    let span = l
        .tokens
        .clone()
        .into_iter()
        .next()
        .map_or_else(Span::call_site, |t| t.span());
    let t = l.as_dual(span);
    let starts_like_statement = match t.clone().into_iter().next() {
        Some(proc_macro2::TokenTree::Group(g)) => g.delimiter() == proc_macro2::Delimiter::Brace,
        Some(proc_macro2::TokenTree::Ident(i)) => i == "if" || i == "for",
        _ => false,
    };
    if starts_like_statement && !(l.stmt_like && l.kind == crate::lower::Kind::Dual) {
        quote!(::core::convert::identity::<__D>(#t))
    } else {
        t
    }
}

fn coordinate_names(c: &Checked) -> TokenStream {
    match &c.n {
        Len::Lit(_) => {
            let mut names = Vec::new();
            for g in &c.env.groups {
                match g.len.literal() {
                    Some(len) if g.array => {
                        for k in 0..len {
                            names.push(format!("{}[{k}]", g.name));
                        }
                    }
                    _ => names.push(g.name.to_string()),
                }
            }
            quote!([#(#names),*])
        }
        Len::Param(p) => {
            let name = c.env.groups.first().map(|g| g.name.to_string());
            quote!([#name; #p])
        }
    }
}

/// The block that a slot belongs to, as an accumulator path.
struct Slots<'a> {
    n: usize,
    j: &'a Ident,
}

impl Slots<'_> {
    /// `j.grad.fq[s]` or `j.grad.lv[s − n]` (with a `grad` prefix or not).
    fn grad(&self, s: usize, prefix: &TokenStream) -> TokenStream {
        let j = self.j;
        if s < self.n {
            let s = lit(s);
            quote!(#j #prefix .fq[#s])
        } else {
            let s = lit(s - self.n);
            quote!(#j #prefix .lv[#s])
        }
    }
    /// The second-derivative block entry `∂²/∂(s)∂(t)`.
    fn hess(&self, s: usize, t: usize) -> TokenStream {
        let j = self.j;
        let (block, i, k) = match (s < self.n, t < self.n) {
            (true, true) => (quote!(a), s, t),
            (true, false) => (quote!(b), s, t - self.n),
            (false, true) => (quote!(c), s - self.n, t),
            (false, false) => (quote!(e), s - self.n, t - self.n),
        };
        let (i, k) = (lit(i), lit(k));
        quote!(#j.#block[(#i, #k)])
    }
}

/// Slot expressions for a use set: specific slots, or `All` halves for a const-generic `N`.
struct SlotSet {
    q: SlotPart,
    v: SlotPart,
}

enum SlotPart {
    None,
    Some(Vec<TokenStream>),
    All,
}

fn slot_set(c: &Checked, uses: &BTreeSet<Var>) -> SlotSet {
    let n = &c.n;
    let mut q = SlotPart::None;
    let mut v = SlotPart::None;
    for u in uses {
        let part = if u.vel { &mut v } else { &mut q };
        match (u.idx, &mut *part) {
            (_, SlotPart::All) => {}
            (Idx::All, p) => *p = SlotPart::All,
            (Idx::At(k), p) => {
                let k = lit(k);
                let tok = if u.vel { quote!(#n + #k) } else { quote!(#k) };
                match p {
                    SlotPart::None => *p = SlotPart::Some(vec![tok]),
                    SlotPart::Some(list) => list.push(tok),
                    SlotPart::All => {}
                }
            }
        }
    }
    SlotSet { q, v }
}

/// Token trees in a stream (an upper bound on the temporaries its code makes).
fn token_count(t: &TokenStream) -> usize {
    t.clone()
        .into_iter()
        .map(|tt| match tt {
            proc_macro2::TokenTree::Group(g) => token_count(&g.stream()).saturating_add(1),
            _ => 1,
        })
        .fold(0usize, usize::saturating_add)
}

/// The kernels, and the stack bound of each helper they call (`kernel_stack_bytes` of the
/// dual number it uses).
fn kernels(c: &Checked) -> (TokenStream, Vec<TokenStream>) {
    let fvi = fvi();
    let n = &c.n;
    let nd = quote!(#fvi::num_dual);
    let mut stack: Vec<TokenStream> = Vec::new();
    let base_values = token_count(&c.lagrangian.tokens)
        .saturating_add(c.force.as_ref().map_or(0, |f| {
            f.fns.iter().map(|x| token_count(&x.lowered.tokens)).sum()
        }))
        .saturating_mul(4)
        .saturating_add(64);
    let base_values = lit(base_values);
    stack.push(quote!(#fvi::kernel_stack_bytes::<f64, #n>(#base_values)));
    let qs = format_ident!("__fvi_qs");
    let vs = format_ident!("__fvi_vs");
    let q = format_ident!("__fvi_q");
    let v = format_ident!("__fvi_v");
    let g = format_ident!("__fvi_g");
    let j = format_ident!("__fvi_j");
    let params = param_bindings(&c.env);
    let sig_args = quote!(&self, #qs: &#fvi::SVector<f64, #n>, #vs: &#fvi::SVector<f64, #n>);
    let prologue = quote! {
        let #q: [f64; #n] = ::core::convert::Into::into(*#qs);
        let #v: [f64; #n] = ::core::convert::Into::into(*#vs);
    };

    let mut grad_code = TokenStream::new();
    let mut jac_code = TokenStream::new();
    let mut mass_code = TokenStream::new();

    // Polynomial part of L: derivatives written out at compile time.
    if let Len::Lit(nn) = *n {
        let var = |s: usize| -> TokenStream {
            if s < nn {
                let s = lit(s);
                quote!(#q[#s])
            } else {
                let s = lit(s - nn);
                quote!(#v[#s])
            }
        };
        let used: BTreeSet<usize> = c
            .poly_l
            .monomials()
            .flat_map(|m| m.iter().map(|&(s, _)| s))
            .collect();
        let mut g_lines = TokenStream::new();
        let mut j_lines = TokenStream::new();
        let mut m_lines = TokenStream::new();
        let gs = Slots { n: nn, j: &g };
        let js = Slots { n: nn, j: &j };
        let grad_prefix = quote!(.grad);
        let mut first_derivs: BTreeMap<usize, Poly> = BTreeMap::new();
        for &s in &used {
            // `check` kept only polynomials whose derivatives are representable.
            let Some(ds) = c.poly_l.diff(s).filter(|d| !d.is_zero()) else {
                continue;
            };
            let code = ds.tokens(&c.atoms, &var);
            let target = gs.grad(s, &TokenStream::new());
            g_lines.extend(quote!(#target = #code;));
            let target = js.grad(s, &grad_prefix);
            j_lines.extend(quote!(#target = #code;));
            first_derivs.insert(s, ds);
        }
        for (&s, ds) in &first_derivs {
            for &t in &used {
                let Some(h) = ds.diff(t).filter(|h| !h.is_zero()) else {
                    continue;
                };
                let code = h.tokens(&c.atoms, &var);
                let target = js.hess(s, t);
                j_lines.extend(quote!(#target = #code;));
                if s >= nn && t >= nn {
                    m_lines.extend(quote!(#target = #code;));
                }
            }
        }
        if !g_lines.is_empty() {
            grad_code.extend(quote!({ #params #g_lines }));
            jac_code.extend(quote!({ #params #j_lines }));
        }
        if !m_lines.is_empty() {
            mass_code.extend(quote!({ #params #m_lines }));
        }
    }

    // Non-polynomial terms of L: dual numbers over the variables each one uses.
    for (k, t) in c.dual_terms.iter().enumerate() {
        let name = format_ident!("__fvi_l{}", k);
        let call = quote!(|__fvi_a, __fvi_b| self.#name(__fvi_a, __fvi_b));
        let set = slot_set(c, &t.lowered.uses);
        let values = lit(token_count(&t.lowered.tokens)
            .saturating_mul(4)
            .saturating_add(64));
        match (&set.q, &set.v, n) {
            (SlotPart::All, _, Len::Param(_)) | (_, SlotPart::All, Len::Param(_)) => {
                let q_slots = part_tokens(&set.q, n, false);
                let v_slots = part_tokens(&set.v, n, true);
                stack.push(quote!(#fvi::kernel_stack_bytes::<#nd::Dual2SVec64<#n>, #n>(#values)));
                for slots in [&q_slots, &v_slots].into_iter().flatten() {
                    grad_code
                        .extend(quote!(#fvi::term_gradient(&#q, &#v, &#slots, #call, &mut #g);));
                    jac_code.extend(quote!(#fvi::term_hessian(&#q, &#v, &#slots, #call, &mut #j);));
                }
                if let Some(slots) = &v_slots {
                    mass_code
                        .extend(quote!(#fvi::term_hessian(&#q, &#v, &#slots, #call, &mut #j);));
                }
                if q_slots.is_some() && v_slots.is_some() {
                    stack.push(quote!(#fvi::kernel_stack_bytes::<#nd::HyperDualSVec64<#n, #n>, #n>(#values)));
                    jac_code.extend(quote!(#fvi::term_cross(&#q, &#v, #call, &mut #j);));
                }
            }
            _ => {
                let all = match n {
                    Len::Lit(nn) => slots(&c.env, *nn, &t.lowered.uses)
                        .into_iter()
                        .map(|s| {
                            let s = lit(s);
                            quote!(#s)
                        })
                        .collect::<Vec<_>>(),
                    Len::Param(_) => {
                        let mut all = Vec::new();
                        for part in [&set.q, &set.v] {
                            if let SlotPart::Some(list) = part {
                                all.extend(list.iter().cloned());
                            }
                        }
                        all
                    }
                };
                let kk = lit(all.len());
                stack.push(quote!(#fvi::kernel_stack_bytes::<#nd::Dual2SVec64<#kk>, #n>(#values)));
                grad_code
                    .extend(quote!(#fvi::term_gradient(&#q, &#v, &[#(#all),*], #call, &mut #g);));
                jac_code
                    .extend(quote!(#fvi::term_hessian(&#q, &#v, &[#(#all),*], #call, &mut #j);));
                let v_only: Vec<TokenStream> = match n {
                    Len::Lit(nn) => slots(&c.env, *nn, &t.lowered.uses)
                        .into_iter()
                        .filter(|&s| s >= *nn)
                        .map(|s| {
                            let s = lit(s);
                            quote!(#s)
                        })
                        .collect(),
                    Len::Param(_) => match &set.v {
                        SlotPart::Some(list) => list.clone(),
                        _ => Vec::new(),
                    },
                };
                if !v_only.is_empty() {
                    mass_code.extend(
                        quote!(#fvi::term_hessian(&#q, &#v, &[#(#v_only),*], #call, &mut #j);),
                    );
                }
            }
        }
    }

    // The force.
    if let Some(force) = &c.force {
        grad_code.extend(quote! {
            let __fvi_f: [f64; #n] = <Self as #fvi::ForcedLagrangian<#n>>::force::<f64>(self, &#q, &#v);
            for __fvi_k in 0..#n {
                #g.fq[__fvi_k] += __fvi_f[__fvi_k];
            }
        });
        match n {
            Len::Lit(nn) => {
                let var = |s: usize| -> TokenStream {
                    if s < *nn {
                        let s = lit(s);
                        quote!(#q[#s])
                    } else {
                        let s = lit(s - *nn);
                        quote!(#v[#s])
                    }
                };
                let js = Slots { n: *nn, j: &j };
                let mut poly_lines = TokenStream::new();
                for r in &force.rows {
                    let name = format_ident!("__fvi_f{}", r.func);
                    let index = r.index.map(|i| {
                        let i = lit(i);
                        quote!(, #i)
                    });
                    let row = lit(r.row);
                    if let Some(p) = &r.poly {
                        if p.is_zero() {
                            continue;
                        }
                        jac_code.extend(
                            quote!(#j.grad.fq[#row] += self.#name::<f64>(&#q, &#v #index);),
                        );
                        let used: BTreeSet<usize> = p
                            .monomials()
                            .flat_map(|m| m.iter().map(|&(s, _)| s))
                            .collect();
                        for s in used {
                            let Some(ds) = p.diff(s).filter(|d| !d.is_zero()) else {
                                continue;
                            };
                            let code = ds.tokens(&c.atoms, &var);
                            let target = js.hess(r.row, s);
                            poly_lines.extend(quote!(#target += #code;));
                        }
                        continue;
                    }
                    let sl: Vec<Literal> =
                        slots(&c.env, *nn, &r.uses).into_iter().map(lit).collect();
                    if sl.is_empty() {
                        jac_code.extend(
                            quote!(#j.grad.fq[#row] += self.#name::<f64>(&#q, &#v #index);),
                        );
                    } else {
                        let kk = lit(sl.len());
                        let values = lit(token_count(
                            &force
                                .fns
                                .get(r.func)
                                .map(|f| f.lowered.tokens.clone())
                                .unwrap_or_default(),
                        )
                        .saturating_mul(4)
                        .saturating_add(64));
                        stack.push(
                            quote!(#fvi::kernel_stack_bytes::<#nd::DualSVec64<#kk>, #n>(#values)),
                        );
                        jac_code.extend(quote! {
                            #fvi::force_row(&#q, &#v, &[#(#sl),*], #row,
                                |__fvi_a, __fvi_b| self.#name(__fvi_a, __fvi_b #index), &mut #j);
                        });
                    }
                }
                if !poly_lines.is_empty() {
                    jac_code.extend(quote!({ #params #poly_lines }));
                }
            }
            Len::Param(_) => {
                let values = lit(force
                    .fns
                    .iter()
                    .map(|f| token_count(&f.lowered.tokens))
                    .fold(0usize, usize::saturating_add)
                    .saturating_mul(4)
                    .saturating_add(64));
                stack.push(quote!(#fvi::kernel_stack_bytes::<#nd::DualSVec64<#n>, #n>(#values)));
                let call = quote!(|__fvi_a, __fvi_b| <Self as #fvi::ForcedLagrangian<#n>>::force(self, __fvi_a, __fvi_b));
                if force.uses_q {
                    jac_code
                        .extend(quote!(#fvi::force_jacobian_q(&#q, &#v, true, #call, &mut #j);));
                }
                if force.uses_v {
                    let add = !force.uses_q;
                    jac_code
                        .extend(quote!(#fvi::force_jacobian_v(&#q, &#v, #add, #call, &mut #j);));
                }
                if !force.uses_q && !force.uses_v {
                    jac_code.extend(quote! {
                        let __fvi_f: [f64; #n] = <Self as #fvi::ForcedLagrangian<#n>>::force::<f64>(self, &#q, &#v);
                        for __fvi_k in 0..#n {
                            #j.grad.fq[__fvi_k] += __fvi_f[__fvi_k];
                        }
                    });
                }
            }
        }
    }

    let uses_args = |code: &TokenStream| -> TokenStream {
        if code.is_empty() {
            quote!(let _ = (&#q, &#v);)
        } else {
            TokenStream::new()
        }
    };
    let g_unused = uses_args(&grad_code);
    let j_unused = uses_args(&jac_code);
    let m_unused = uses_args(&mass_code);
    let mut_g = if grad_code.is_empty() {
        quote!()
    } else {
        quote!(mut)
    };
    let mut_j = if jac_code.is_empty() {
        quote!()
    } else {
        quote!(mut)
    };
    let mut_m = if mass_code.is_empty() {
        quote!()
    } else {
        quote!(mut)
    };
    let code = quote_spanned! {Span::call_site()=>
        #[inline]
        fn node_gradient(#sig_args) -> #fvi::NodeGradient<#n> {
            #prologue
            let #mut_g #g = #fvi::zero_gradient::<#n>();
            #g_unused
            #grad_code
            #g
        }
        #[inline]
        fn node_jacobian(#sig_args) -> #fvi::NodeJacobian<#n> {
            #prologue
            let #mut_j #j = #fvi::zero_jacobian::<#n>();
            #j_unused
            #jac_code
            #j
        }
        #[inline]
        fn mass_matrix(#sig_args) -> #fvi::SMatrix<f64, #n, #n> {
            #prologue
            let #mut_m #j = #fvi::zero_jacobian::<#n>();
            #m_unused
            #mass_code
            #j.e
        }
    };
    (code, stack)
}

fn part_tokens(part: &SlotPart, n: &Len, vel: bool) -> Option<TokenStream> {
    let fvi = fvi();
    match part {
        SlotPart::None => None,
        SlotPart::Some(list) => Some(quote!([#(#list),*])),
        SlotPart::All => Some(if vel {
            quote!(#fvi::slot_range::<#n>(#n))
        } else {
            quote!(#fvi::slot_range::<#n>(0))
        }),
    }
}
