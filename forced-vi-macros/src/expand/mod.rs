//! The expand phase: generates the impl from a checked model. Nothing here validates.
//!
//! Generated items, all reaching the runtime through `::forced_vi::__private`:
//! - `impl ForcedLagrangian<N>`: `lagrangian`, `force` (only with a force), `STRUCTURE`,
//!   `coordinate_names`, `check_parameters`, and the specialised kernels `node_gradient`,
//!   `node_jacobian` and `mass_matrix`;
//! - for a driven model (one that names `t`): `lagrangian_at` and `force_at` instead, with
//!   `lagrangian`/`force` their values at `t = 0`, `STRUCTURE.uses_time`, and the
//!   specialised kernels at the node's time (`node_gradient_at`, `node_jacobian_at`,
//!   `mass_matrix_at`; the autonomous ones are those at `t = 0`);
//! - an inherent `doubled_lagrangian` and one hidden helper per non-polynomial term of `L`
//!   and per force entry.
//!
//! The kernels add up, per block, only what the model has: polynomial terms as `f64` code
//! derived at compile time (see `poly`), other terms with the smallest dual number over the
//! variables they use, and the force only where it acts; they are generated in `kernels`
//! (with `slots` for where they write).

use std::collections::BTreeSet;

use proc_macro2::{Literal, Span, TokenStream};
use quote::{format_ident, quote};
use syn::Ident;

use crate::check::{Checked, CheckedForce};
use crate::lower::{dual_ident, Env, Len, Lowered, TIME};
use crate::split::Split;

mod kernels;
mod slots;

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
    for (k, p) in env.params.iter().enumerate() {
        if !names.contains(&p.to_string()) {
            continue;
        }
        out.extend(if env.params_dual {
            let k = lit(k);
            quote!(let #p: #scalar = match __fvi_theta.get(#k) {
                ::core::option::Option::Some(__fvi_x) => *__fvi_x,
                ::core::option::Option::None => #scalar::from(self.#p),
            };)
        } else {
            quote!(let #p: f64 = self.#p;)
        });
    }
    out
}

/// All parameters as `f64` locals (for polynomial coefficients), allowed to go unused.
fn param_bindings(env: &Env) -> TokenStream {
    let ps = &env.params;
    quote!(#( #[allow(unused_variables)] let #ps: f64 = self.#ps; )*)
}

/// The generated code for a checked model and its `split` into local terms, if any;
/// `theta`, the same model checked with its parameters as duals, adds `lagrangian_with` and `force_with` (DESIGN §12).
pub fn generate(
    c: &Checked,
    split: Option<&Split>,
    theta: Option<(&Checked, Option<&Split>)>,
) -> TokenStream {
    let g = Gen::new(c);
    // A model that splits into local terms gets per-term kernels (DESIGN §9); a large one
    // also computes its dense blocks through them.
    let through = split.is_some() && crate::sparse::dense_through_split(c);
    let lagrangian = g.lagrangian();
    // Helpers: non-polynomial terms and force entries.
    let mut helpers = g.term_helpers(through);
    let force_method = match &c.force {
        Some(force) => g.force_items(force, &mut helpers),
        None => TokenStream::new(),
    };
    // Specialised kernels, at the node's time for a driven model; a model whose dense blocks
    // go through its per-term code keeps the runtime's general kernels.
    let fvi = &g.fvi;
    let kernels_and_stack = (!through).then(|| {
        let (kernels, stack) = kernels::kernels(c);
        let stack_bytes = stack
            .into_iter()
            .reduce(|a, b| quote!(#fvi::max_usize(#a, #b)));
        quote! {
            const KERNEL_STACK_BYTES: usize = #stack_bytes;
            #kernels
        }
    });
    let check_model = c.checked_index.then(|| g.check_model());
    // The parameters' per-term kernels, for a model with per-term kernels whose split with
    // its parameters as duals exists.
    let theta_split = theta
        .and_then(|(th, s)| Some((th, s?)))
        .filter(|_| split.is_some());
    if let Some((th, s)) = theta_split {
        helpers.extend(crate::sparse::parameter_helpers(th, s));
    }
    let (split_items, sparse_impl) = match split {
        Some(s) => {
            helpers.extend(crate::sparse::helpers(c, s));
            let params = theta_split.is_some();
            (
                crate::sparse::trait_items(c),
                crate::sparse::sparse_impl(c, params),
            )
        }
        None => (TokenStream::new(), TokenStream::new()),
    };
    let parameter_items = match theta {
        Some((th, _)) => Gen::new(th).parameter_items(&mut helpers),
        None => TokenStream::new(),
    };
    let constraint_items = g.constraint_items();
    let items = quote! {
        #lagrangian
        #force_method
        #parameter_items
        #constraint_items
    };
    let trait_impl = g.trait_impl(items, check_model, kernels_and_stack, split_items);
    let inherent_impl = g.inherent_impl(helpers);
    let item = &c.model.item;
    quote! {
        #item

        #trait_impl

        #sparse_impl

        #inherent_impl
    }
}

/// What the generated items of one model share: the model, the runtime's path and the
/// names of the scalar and of the arguments.
struct Gen<'c, 'm> {
    c: &'c Checked<'m>,
    fvi: TokenStream,
    /// The generic scalar `__D` and its bound.
    d: Ident,
    scalar_bound: TokenStream,
    /// The coordinates, velocities and time arguments.
    dq: Ident,
    dv: Ident,
    dt: Ident,
    /// `__fvi_t: __D,` in the parameters of a driven model's helpers, `__fvi_t,` in calls.
    time_param: Option<TokenStream>,
    time_arg: Option<TokenStream>,
}

impl<'c, 'm> Gen<'c, 'm> {
    fn new(c: &'c Checked<'m>) -> Self {
        let fvi = fvi();
        let d = dual_ident();
        let dt = format_ident!("__fvi_t");
        let timed = c.uses_time;
        Gen {
            c,
            scalar_bound: quote!(#fvi::Scalar),
            fvi,
            time_param: timed.then(|| quote!(#dt: #d,)),
            time_arg: timed.then(|| quote!(#dt,)),
            d,
            dq: format_ident!("__fvi_q"),
            dv: format_ident!("__fvi_v"),
            dt,
        }
    }

    /// In a driven model, `t` bound from the `__fvi_t` argument where an expression uses it.
    fn time_binding(&self, names: &BTreeSet<String>) -> TokenStream {
        let (d, dt) = (&self.d, &self.dt);
        let time = Ident::new(TIME, Span::call_site());
        if names.contains(TIME) {
            quote!(let #time: #d = #dt;)
        } else {
            quote!(let _ = #dt;)
        }
    }

    /// `let` bindings for the model names in `names`, from `__fvi_q`, `__fvi_v` and `self`.
    fn bindings(&self, names: &BTreeSet<String>) -> TokenStream {
        let d = &self.d;
        bindings(
            &self.c.env,
            &self.c.n,
            names,
            &self.dq,
            &self.dv,
            &quote!(#d),
        )
    }

    /// L(q, v), generic; for a driven model L(t, q, v), with `lagrangian` its value at t = 0.
    fn lagrangian(&self) -> TokenStream {
        let c = self.c;
        let (fvi, n, d, scalar_bound) = (&self.fvi, &c.n, &self.d, &self.scalar_bound);
        let (dq, dv, dt) = (&self.dq, &self.dv, &self.dt);
        let l_bind = self.bindings(&c.lagrangian.names);
        let l_body = lowered_dual(&c.lagrangian);
        if c.uses_time {
            let t_bind = self.time_binding(&c.lagrangian.names);
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
        }
    }

    /// One hidden helper per non-polynomial term of `L` (taking the time first for a driven
    /// model), unless `general`: kernels that go through the per-term code call none.
    fn term_helpers(&self, general: bool) -> TokenStream {
        let c = self.c;
        let (n, d, scalar_bound, dq, dv) = (&c.n, &self.d, &self.scalar_bound, &self.dq, &self.dv);
        let time_param = &self.time_param;
        let mut helpers = TokenStream::new();
        let dual_terms: &[crate::check::Term] = if general { &[] } else { &c.dual_terms };
        for (k, t) in dual_terms.iter().enumerate() {
            let name = format_ident!("__fvi_l{}", k);
            let bind = self.bindings(&t.lowered.names);
            let t_bind = c.uses_time.then(|| self.time_binding(&t.lowered.names));
            let body = lowered_dual(&t.lowered);
            helpers.extend(quote! {
                #[doc(hidden)]
                #[inline(always)]
                #[allow(unused_braces, unused_parens)]
                fn #name<#d: #scalar_bound>(&self, #time_param #dq: &[#d; #n], #dv: &[#d; #n]) -> #d {
                    #t_bind
                    #bind
                    #body
                }
            });
        }
        helpers
    }

    /// The force: one hidden helper per entry (added to `helpers`), and the `force` method
    /// (`force_at` and `force` for a driven model) that calls them.
    fn force_items(&self, force: &CheckedForce, helpers: &mut TokenStream) -> TokenStream {
        let c = self.c;
        let (fvi, n, d, scalar_bound) = (&self.fvi, &c.n, &self.d, &self.scalar_bound);
        let (dq, dv, dt, time_param) = (&self.dq, &self.dv, &self.dt, &self.time_param);
        for (k, f) in force.fns.iter().enumerate() {
            let name = format_ident!("__fvi_f{}", k);
            let bind = self.bindings(&f.lowered.names);
            let t_bind = c.uses_time.then(|| self.time_binding(&f.lowered.names));
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
        let body = self.force_body(force);
        if c.uses_time {
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
        }
    }

    /// The parameters for sensitivities (DESIGN §12), from a model checked with them as
    /// duals: their names and values, and `L` and `F` at given parameter values
    /// `__fvi_theta` (with a helper per force entry added to `helpers`).
    fn parameter_items(&self, helpers: &mut TokenStream) -> TokenStream {
        let c = self.c;
        let (n, d, scalar_bound) = (&c.n, &self.d, &self.scalar_bound);
        let (dq, dv, dt) = (&self.dq, &self.dv, &self.dt);
        let ps = &c.env.params;
        let names = ps.iter().map(|p| p.to_string());
        let time = |names: &BTreeSet<String>| {
            let t = Ident::new(TIME, Span::call_site());
            if names.contains(TIME) {
                quote!(let #t: #d = #dt;)
            } else {
                quote!(let _ = #dt;)
            }
        };
        let l_bind = self.bindings(&c.lagrangian.names);
        let l_time = time(&c.lagrangian.names);
        let l_body = lowered_dual(&c.lagrangian);
        let force = c.force.as_ref().map(|force| {
            for (k, f) in force.fns.iter().enumerate() {
                let name = format_ident!("__fvi_pf{}", k);
                let bind = self.bindings(&f.lowered.names);
                let t_bind = time(&f.lowered.names);
                let body = lowered_dual(&f.lowered);
                let index = f.index.as_ref().map(|i| quote!(, #i: usize));
                helpers.extend(quote! {
                    #[doc(hidden)]
                    #[inline(always)]
                    #[allow(unused_braces, unused_parens, unused_variables)]
                    fn #name<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], #dv: &[#d; #n], __fvi_theta: &[#d] #index) -> #d {
                        #t_bind
                        #bind
                        #body
                    }
                });
            }
            let body = match &c.n {
                Len::Lit(_) => {
                    let calls = force.rows.iter().map(|r| {
                        let name = format_ident!("__fvi_pf{}", r.func);
                        let index = r.index.map(|i| {
                            let i = lit(i);
                            quote!(, #i)
                        });
                        quote!(self.#name(#dt, #dq, #dv, __fvi_theta #index))
                    });
                    quote!([#(#calls),*])
                }
                Len::Param(_) => quote!(::core::array::from_fn(|__fvi_k| {
                    self.__fvi_pf0(#dt, #dq, #dv, __fvi_theta, __fvi_k)
                })),
            };
            quote! {
                #[inline]
                fn force_with<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], #dv: &[#d; #n], __fvi_theta: &[#d]) -> [#d; #n] {
                    #body
                }
            }
        });
        // The constraints at given parameter values, for the sensitivities of a constrained
        // model: a parameter may shape the constraint (a pendulum's length).
        let constraints = (!c.constraints.is_empty()).then(|| {
            let slots = self.constraint_slots();
            quote! {
                #[allow(unused_braces, unused_parens, unused_variables)]
                fn constraints_with<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], __fvi_theta: &[#d], __fvi_g: &mut [#d]) {
                    let #dv: &[#d; #n] = #dq;
                    let _ = #dv;
                    #(#slots)*
                }
            }
        });
        quote! {
            fn parameter_names(&self) -> &'static [&'static str] {
                &[#(#names),*]
            }
            fn parameter_values(&self) -> ::std::vec::Vec<f64> {
                ::std::vec![#(self.#ps),*]
            }
            #[inline]
            #[allow(unused_braces, unused_parens, unused_variables)]
            fn lagrangian_with<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], #dv: &[#d; #n], __fvi_theta: &[#d]) -> #d {
                #l_time
                #l_bind
                #l_body
            }
            #force
            #constraints
        }
    }

    /// Each `g_k` written to its slot of `__fvi_g`, with `t` and the coordinates (and, in a
    /// model checked with its parameters as duals, the parameters from `__fvi_theta`) bound
    /// as for the Lagrangian.
    fn constraint_slots(&self) -> Vec<TokenStream> {
        let (d, dt) = (&self.d, &self.dt);
        self.c
            .constraints
            .iter()
            .enumerate()
            .map(|(k, l)| {
                let bind = self.bindings(&l.names);
                let t_bind = if l.names.contains(TIME) {
                    let t = Ident::new(TIME, Span::call_site());
                    quote!(let #t: #d = #dt;)
                } else {
                    TokenStream::new()
                };
                let body = lowered_dual(l);
                let k = lit(k);
                quote! {
                    if let ::core::option::Option::Some(__fvi_slot) = __fvi_g.get_mut(#k) {
                        *__fvi_slot = { #t_bind #bind #body };
                    }
                }
            })
            .collect()
    }

    /// `constraint_count` and `constraints` for a model with `constraints(...)`
    /// (DESIGN §11): each `g_k` written to its slot of `g`, with `t` and the coordinates
    /// bound as for the Lagrangian.
    fn constraint_items(&self) -> TokenStream {
        let c = self.c;
        if c.constraints.is_empty() {
            // The promise that lets the runtime leave out a constrained step's code.
            return quote!(
                const CONSTRAINED: bool = false;
            );
        }
        let (n, d, scalar_bound) = (&c.n, &self.d, &self.scalar_bound);
        let (dq, dv, dt) = (&self.dq, &self.dv, &self.dt);
        let count = lit(c.constraints.len());
        let slots = self.constraint_slots();
        // No constraint names `t`, so none reads it (`t` is not even bound in their code): the
        // promise that lets the runtime leave out their rate `∂g/∂t`.
        let reads_time = c.constraints.iter().any(|l| l.names.contains(TIME));
        let read_time = (!reads_time).then(|| {
            quote!(
                const CONSTRAINTS_READ_TIME: bool = false;
            )
        });
        quote! {
            #read_time
            fn constraint_count(&self) -> usize {
                #count
            }
            #[allow(unused_braces, unused_parens, unused_variables)]
            fn constraints<#d: #scalar_bound>(&self, #dt: #d, #dq: &[#d; #n], __fvi_g: &mut [#d]) {
                // Velocities are refused in constraints; `__fvi_v` only keeps the bindings'
                // shape.
                let #dv: &[#d; #n] = #dq;
                let _ = #dv;
                #(#slots)*
            }
        }
    }

    /// The force as an array: one helper call per row, or `from_fn` over the one entry of a
    /// const-generic model.
    fn force_body(&self, force: &CheckedForce) -> TokenStream {
        let (dq, dv, time_arg) = (&self.dq, &self.dv, &self.time_arg);
        match &self.c.n {
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
        }
    }

    /// `check_model`, for a model with indices checked at run time.
    fn check_model(&self) -> TokenStream {
        let (fvi, n) = (&self.fvi, &self.c.n);
        let force = self.c.force.as_ref().map(|_| {
            quote!(let _ = <Self as #fvi::ForcedLagrangian<#n>>::force::<f64>(self, &__fvi_z, &__fvi_z);)
        });
        let constraints = (!self.c.constraints.is_empty()).then(|| {
            quote! {
                let mut __fvi_g = ::std::vec![0.0f64; <Self as #fvi::ForcedLagrangian<#n>>::constraint_count(self)];
                <Self as #fvi::ForcedLagrangian<#n>>::constraints::<f64>(self, 0.0, &__fvi_z, &mut __fvi_g);
            }
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
                #constraints
                match #fvi::take_index_fault() {
                    ::core::option::Option::Some(__fvi_what) => ::core::result::Result::Err(::std::format!(
                        "index `{}` is out of range: the model has {} coordinates",
                        __fvi_what, #n
                    )),
                    ::core::option::Option::None => ::core::result::Result::Ok(()),
                }
            }
        }
    }

    /// `impl ForcedLagrangian<N>`: the structure, the names, `items` (the Lagrangian and the
    /// force), the parameter check, then the optional items.
    fn trait_impl(
        &self,
        items: TokenStream,
        check_model: Option<TokenStream>,
        kernels_and_stack: Option<TokenStream>,
        split_items: TokenStream,
    ) -> TokenStream {
        let c = self.c;
        let (fvi, n) = (&self.fvi, &c.n);
        let item = &c.model.item;
        let ident = &item.ident;
        let (ig, tg, wc) = item.generics.split_for_impl();
        let has_force = c.force.is_some();
        let force_uses_velocity = c.force.as_ref().is_some_and(|f| f.uses_v);
        let constant_mass = c.constant_mass;
        let linear = c.linear;
        let timed = c.uses_time;
        let names = coordinate_names(c);
        let checks = c.env.params.iter().map(|p| {
            let s = p.to_string();
            quote!(if !self.#p.is_finite() { return ::core::result::Result::Err(#s); })
        });
        quote! {
            #[automatically_derived]
            impl #ig #fvi::ForcedLagrangian<#n> for #ident #tg #wc {
                const STRUCTURE: #fvi::Structure = #fvi::Structure {
                    has_force: #has_force,
                    force_uses_velocity: #force_uses_velocity,
                    constant_mass: #constant_mass,
                    linear: #linear,
                    uses_time: #timed,
                };
                fn coordinate_names(&self) -> [&'static str; #n] {
                    #names
                }
                #items
                fn check_parameters(&self) -> ::core::result::Result<(), &'static str> {
                    #(#checks)*
                    ::core::result::Result::Ok(())
                }
                #check_model
                #kernels_and_stack
                #split_items
            }
        }
    }

    /// The inherent impl: `doubled_lagrangian` and the hidden `helpers`.
    fn inherent_impl(&self, helpers: TokenStream) -> TokenStream {
        let (fvi, n, d, scalar_bound) = (&self.fvi, &self.c.n, &self.d, &self.scalar_bound);
        let item = &self.c.model.item;
        let ident = &item.ident;
        let (ig, tg, wc) = item.generics.split_for_impl();
        quote! {
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
