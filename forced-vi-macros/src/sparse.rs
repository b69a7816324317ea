//! Generates the per-term kernels of a model that [`split`](crate::split) into local terms
//! (DESIGN §9): one generic function per term of `L` and per force entry, over only the
//! slots it reads; the hidden kernel `__fvi_sparse`, which loops over the terms and
//! scatters each term's small gradient and Hessian through an `Accum`; `impl SparseNode`;
//! for large models, the dense kernels through the same code; and, where the model read
//! with its parameters as duals splits too, the parameters' per-term kernels
//! (`__fvi_sparse_theta`, behind `SparseNode::eval_parameter`).
//!
//! The term functions are generic over `__D: Scalar` like the rest of the generated code,
//! so a type error in the user's expression is reported once, not once per dual type.

use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use syn::Ident;

use crate::check::Checked;
use crate::lower::{Len, TIME};
use crate::split::{Local, Split};

fn fvi() -> TokenStream {
    quote!(::forced_vi::__private)
}

/// Up to this many coordinates, a model with a literal length keeps its dense kernels
/// (symbolic polynomials and small dual numbers, the fastest for small models).
const DENSE_LITERAL_MAX: usize = 32;

/// Whether the dense kernels go through the per-term code too: for a const-generic or a
/// large length, where the whole-model dual numbers would be `N × N` (or larger) types.
pub fn dense_through_split(c: &Checked) -> bool {
    match c.n {
        Len::Param(_) => true,
        Len::Lit(n) => n > DENSE_LITERAL_MAX,
    }
}

/// The inherent items: one generic function per term and force entry, and `__fvi_sparse`.
pub fn helpers(c: &Checked, s: &Split) -> TokenStream {
    let fvi = fvi();
    let mut out = TokenStream::new();
    let mut calls = TokenStream::new();
    for (k, t) in s.terms.iter().enumerate() {
        let name = format_ident!("__fvi_s{}", k);
        out.extend(term_fn(c, t, &name));
        calls.extend(term_call(t, &name));
    }
    for (k, f) in s.forces.iter().enumerate() {
        let name = format_ident!("__fvi_sf{}", k);
        out.extend(term_fn(c, f, &name));
        calls.extend(force_call(f, &name));
    }
    out.extend(quote! {
        #[doc(hidden)]
        #[inline]
        #[allow(unused_variables, unused_parens, unused_braces)]
        fn __fvi_sparse<__A: #fvi::Accum>(
            &self,
            __fvi_time: f64,
            __fvi_qa: &[f64],
            __fvi_va: &[f64],
            __fvi_acc: &mut __A,
        ) {
            let __fvi_blocks = #fvi::Accum::wants_blocks(__fvi_acc);
            #calls
        }
    });
    out
}

/// `fn name<__D>(&self, t, [i,] z) -> __D`: the term (times its weight) at the slots `z`.
fn term_fn(c: &Checked, l: &Local, name: &Ident) -> TokenStream {
    let fvi = fvi();
    let k = l.slots.len();
    // A loop variable named like a parameter is the variable in the term, as in the dense
    // code (where the closure's or the loop's binding shadows the field): that parameter is
    // not bound over it (a loop `|i|` in a model with a field `i` ran on the field's value,
    // and ended `Ok` with every oscillator at the field's stiffness).
    let params: Vec<&Ident> = c
        .env
        .params
        .iter()
        .filter(|p| !l.loops.iter().any(|(v, _)| v == *p))
        .collect();
    let var = l.loops.iter().map(|(v, _)| quote!(#v: usize,));
    let binds = l.slots.iter().enumerate().map(|(j, s)| {
        let id = &s.ident;
        quote!(let #id: __D = __fvi_z[#j];)
    });
    let time = Ident::new(TIME, Span::call_site());
    let t_bind = l
        .uses_time
        .then(|| quote!(let #time: __D = __D::from(__fvi_time);));
    let body = &l.body;
    let weighted = match &l.weight {
        Some(w) => quote!(__fvi_val * (#w)),
        None => quote!(__fvi_val),
    };
    quote! {
        #[doc(hidden)]
        #[inline(always)]
        #[allow(unused_variables, unused_braces, unused_parens, non_snake_case)]
        fn #name<__D: #fvi::Scalar>(&self, __fvi_time: f64, #(#var)* __fvi_z: &[__D; #k]) -> __D {
            #( let #params: f64 = self.#params; )*
            #(#binds)*
            #t_bind
            let __fvi_val: __D = #body;
            #weighted
        }
    }
}

/// The slot arrays and values of a term.
fn prelude(l: &Local) -> TokenStream {
    let fvi = fvi();
    let k = l.slots.len();
    let index = l.slots.iter().map(|s| &s.index);
    let vel = l.slots.iter().map(|s| s.vel);
    quote! {
        let __fvi_s: [usize; #k] = [#(#index),*];
        let __fvi_vel: [bool; #k] = [#(#vel),*];
        let __fvi_x = #fvi::slot_values(__fvi_qa, __fvi_va, &__fvi_s, &__fvi_vel);
    }
}

fn looped(l: &Local, inner: TokenStream) -> TokenStream {
    l.loops.iter().rev().fold(
        quote!({ #inner }),
        |body, (var, iter)| quote!({ for #var in #iter #body }),
    )
}

/// The call of `name` at the slots `z` for the dual type `ty`.
fn call(l: &Local, name: &Ident, ty: TokenStream) -> TokenStream {
    let var = l.loops.iter().map(|(v, _)| v);
    quote!(self.#name::<#ty>(__fvi_time, #(#var,)* &::core::convert::Into::into(__fvi_z)))
}

fn term_call(l: &Local, name: &Ident) -> TokenStream {
    let fvi = fvi();
    let nd = quote!(#fvi::num_dual);
    let k = l.slots.len();
    let prelude = prelude(l);
    let hess = call(l, name, quote!(#nd::Dual2SVec64<#k>));
    let grad = call(l, name, quote!(#nd::DualSVec64<#k>));
    looped(
        l,
        quote! {
            #prelude
            if __fvi_blocks {
                let (_, __fvi_g, __fvi_h) = #nd::hessian(
                    |__fvi_z: #fvi::SVector<#nd::Dual2SVec64<#k>, #k>| #hess,
                    &__fvi_x,
                );
                #fvi::add_term(__fvi_acc, &__fvi_s, &__fvi_vel, &__fvi_g, ::core::option::Option::Some(&__fvi_h));
            } else {
                let (_, __fvi_g) = #nd::gradient(
                    |__fvi_z: #fvi::SVector<#nd::DualSVec64<#k>, #k>| #grad,
                    &__fvi_x,
                );
                #fvi::add_term(__fvi_acc, &__fvi_s, &__fvi_vel, &__fvi_g, ::core::option::Option::None);
            }
        },
    )
}

fn force_call(l: &Local, name: &Ident) -> TokenStream {
    let fvi = fvi();
    let nd = quote!(#fvi::num_dual);
    let k = l.slots.len();
    let prelude = prelude(l);
    let row = &l.row;
    let grad = call(l, name, quote!(#nd::DualSVec64<#k>));
    let value = call(l, name, quote!(f64));
    let blocks = (k > 0).then(|| {
        quote! {
            if __fvi_blocks {
                let (__fvi_f, __fvi_g) = #nd::gradient(
                    |__fvi_z: #fvi::SVector<#nd::DualSVec64<#k>, #k>| #grad,
                    &__fvi_x,
                );
                #fvi::add_force(__fvi_acc, __fvi_row, &__fvi_s, &__fvi_vel, __fvi_f, ::core::option::Option::Some(&__fvi_g));
                continue;
            }
        }
    });
    let inner = quote! {
        let __fvi_row: usize = #row;
        #prelude
        #blocks
        let __fvi_z = __fvi_x;
        let __fvi_f: f64 = #value;
        #fvi::add_force(__fvi_acc, __fvi_row, &__fvi_s, &__fvi_vel, __fvi_f, ::core::option::Option::None);
    };
    // One pass of a loop, so that `continue` leaves a force entry without an index too.
    if l.loops.is_empty() {
        quote!(for _ in 0..1 { #inner })
    } else {
        looped(l, inner)
    }
}

/// The parameters' per-term kernels (DESIGN §12 with §9), from the model checked with its
/// parameters as duals (`c`) and its own split (`s`): one generic function per term and
/// force entry, with the parameters read from `__fvi_theta`, and the hidden kernel
/// `__fvi_sparse_theta`, which adds each term's mixed derivatives `∂²T/∂z∂θ_k` over its own
/// slots, and each force entry's `∂F/∂θ_k`, through an `Accum`.
pub fn parameter_helpers(c: &Checked, s: &Split) -> TokenStream {
    let fvi = fvi();
    let nd = quote!(#fvi::num_dual);
    let mut out = TokenStream::new();
    let mut calls = TokenStream::new();
    for (k, t) in s.terms.iter().enumerate() {
        let name = format_ident!("__fvi_ps{}", k);
        out.extend(theta_term_fn(c, t, &name));
        let prelude = prelude(t);
        let var = t.loops.iter().map(|(v, _)| v);
        let k = t.slots.len();
        let term = looped(
            t,
            quote! {
                #prelude
                let __fvi_g = #fvi::term_theta_gradient(&__fvi_x, |__fvi_z| {
                    self.#name::<#nd::HyperDualSVec64<#k, 1>>(__fvi_time, #(#var,)* __fvi_z, &__fvi_th)
                });
                #fvi::add_term(__fvi_acc, &__fvi_s, &__fvi_vel, &__fvi_g, ::core::option::Option::None);
            },
        );
        // The parameters as this term's numbers, once for all its loop's values.
        calls.extend(quote! {{
            let __fvi_th = #fvi::theta_hyper::<#k>(__fvi_theta, __fvi_k);
            #term
        }});
    }
    for (k, f) in s.forces.iter().enumerate() {
        let name = format_ident!("__fvi_psf{}", k);
        out.extend(theta_term_fn(c, f, &name));
        let prelude = prelude(f);
        let row = &f.row;
        let var = f.loops.iter().map(|(v, _)| v);
        let inner = quote! {
            let __fvi_row: usize = #row;
            #prelude
            let __fvi_z = #fvi::dual_constants(&__fvi_x);
            let __fvi_f: f64 = #fvi::dual_part(&self.#name::<#nd::DualSVec64<1>>(__fvi_time, #(#var,)* &__fvi_z, &__fvi_thd));
            #fvi::add_force(__fvi_acc, __fvi_row, &__fvi_s, &__fvi_vel, __fvi_f, ::core::option::Option::None);
        };
        calls.extend(if f.loops.is_empty() {
            quote!({ #inner })
        } else {
            looped(f, inner)
        });
    }
    out.extend(quote! {
        #[doc(hidden)]
        #[inline]
        #[allow(unused_variables, unused_parens, unused_braces)]
        fn __fvi_sparse_theta<__A: #fvi::Accum>(
            &self,
            __fvi_time: f64,
            __fvi_qa: &[f64],
            __fvi_va: &[f64],
            __fvi_theta: &[f64],
            __fvi_k: usize,
            __fvi_acc: &mut __A,
        ) {
            let __fvi_thd = #fvi::theta_dual(__fvi_theta, __fvi_k);
            #calls
        }
    });
    out
}

/// `fn name<__D>(&self, t, [i,] z, theta) -> __D`: a term of the model checked with its
/// parameters as duals, the parameters read from `theta` (as `lagrangian_with` does).
fn theta_term_fn(c: &Checked, l: &Local, name: &Ident) -> TokenStream {
    let fvi = fvi();
    let k = l.slots.len();
    let params = c
        .env
        .params
        .iter()
        .enumerate()
        .filter(|(_, p)| !l.loops.iter().any(|(v, _)| v == *p));
    let param_binds = params.map(|(i, p)| {
        quote! {
            let #p: __D = match __fvi_theta.get(#i) {
                ::core::option::Option::Some(__fvi_p) => *__fvi_p,
                ::core::option::Option::None => __D::from(self.#p),
            };
        }
    });
    let var = l.loops.iter().map(|(v, _)| quote!(#v: usize,));
    let binds = l.slots.iter().enumerate().map(|(j, s)| {
        let id = &s.ident;
        quote!(let #id: __D = __fvi_z[#j];)
    });
    let time = Ident::new(TIME, Span::call_site());
    let t_bind = l
        .uses_time
        .then(|| quote!(let #time: __D = __D::from(__fvi_time);));
    let body = &l.body;
    let weighted = match &l.weight {
        Some(w) => quote!(__fvi_val * (#w)),
        None => quote!(__fvi_val),
    };
    quote! {
        #[doc(hidden)]
        #[inline(always)]
        #[allow(unused_variables, unused_braces, unused_parens, non_snake_case)]
        fn #name<__D: #fvi::Scalar>(&self, __fvi_time: f64, #(#var)* __fvi_z: &[__D; #k], __fvi_theta: &[__D]) -> __D {
            #( #param_binds )*
            #(#binds)*
            #t_bind
            let __fvi_val: __D = #body;
            #weighted
        }
    }
}

/// `impl SparseNode` for the model.
pub fn sparse_impl(c: &Checked, params: bool) -> TokenStream {
    let fvi = fvi();
    let item = &c.model.item;
    let ident = &item.ident;
    let (ig, tg, wc) = item.generics.split_for_impl();
    let n = &c.n;
    // With the parameters' per-term kernels (see `parameter_helpers`).
    let parameter_methods = params.then(|| {
        quote! {
            fn has_parameter_kernels(&self) -> bool {
                true
            }
            fn eval_parameter(
                &self,
                __fvi_t: f64,
                __fvi_q: &[f64],
                __fvi_v: &[f64],
                __fvi_theta: &[f64],
                __fvi_k: usize,
                __fvi_fq: &mut [f64],
                __fvi_lv: &mut [f64],
            ) -> bool {
                let mut __fvi_acc = #fvi::ThetaAccum { fq: __fvi_fq, lv: __fvi_lv };
                self.__fvi_sparse_theta(__fvi_t, __fvi_q, __fvi_v, __fvi_theta, __fvi_k, &mut __fvi_acc);
                true
            }
        }
    });
    quote! {
        #[automatically_derived]
        impl #ig #fvi::SparseNode for #ident #tg #wc {
            fn dof(&self) -> usize {
                #n
            }
            fn eval(&self, __fvi_t: f64, __fvi_q: &[f64], __fvi_v: &[f64], __fvi_sink: &mut #fvi::NodeSink<'_>) {
                self.__fvi_sparse(__fvi_t, __fvi_q, __fvi_v, __fvi_sink);
            }
            fn lagrangian_value(&self, __fvi_t: f64, __fvi_q: &[f64], __fvi_v: &[f64]) -> f64 {
                match (
                    <&[f64; #n] as ::core::convert::TryFrom<&[f64]>>::try_from(__fvi_q),
                    <&[f64; #n] as ::core::convert::TryFrom<&[f64]>>::try_from(__fvi_v),
                ) {
                    (::core::result::Result::Ok(__fvi_q), ::core::result::Result::Ok(__fvi_v)) => {
                        <Self as #fvi::ForcedLagrangian<#n>>::lagrangian_at::<f64>(self, __fvi_t, __fvi_q, __fvi_v)
                    }
                    _ => f64::NAN,
                }
            }
            #parameter_methods
        }
    }
}

/// Items of the `ForcedLagrangian` impl: `sparse_node`, and with [`dense_through_split`] the
/// dense kernels (through the per-term code) with their stack bound.
pub fn trait_items(c: &Checked) -> TokenStream {
    let fvi = fvi();
    let n = &c.n;
    let mut out = quote! {
        fn sparse_node(&self) -> ::core::option::Option<&dyn #fvi::SparseNode> {
            ::core::option::Option::Some(self)
        }
    };
    if dense_through_split(c) {
        out.extend(quote!(const KERNEL_STACK_BYTES: usize = #fvi::split_stack_bytes::<#n>();));
        out.extend(dense_kernels(c, "", false));
        if c.uses_time {
            out.extend(dense_kernels(c, "_at", true));
        }
    }
    out
}

/// `node_gradient`, `node_jacobian` and `mass_matrix` (with `_at` and a time argument when
/// `timed`) through the per-term code and dense blocks.
fn dense_kernels(c: &Checked, suffix: &str, timed: bool) -> TokenStream {
    let fvi = fvi();
    let n = &c.n;
    let g = format_ident!("node_gradient{}", suffix);
    let j = format_ident!("node_jacobian{}", suffix);
    let m = format_ident!("mass_matrix{}", suffix);
    let (t_param, t_arg, t) = if timed {
        (quote!(__fvi_t: f64,), quote!(__fvi_t,), quote!(__fvi_t))
    } else {
        (TokenStream::new(), TokenStream::new(), quote!(0.0))
    };
    let sig = quote!(&self, #t_param __fvi_qs: &#fvi::SVector<f64, #n>, __fvi_vs: &#fvi::SVector<f64, #n>);
    let args = quote!(#t, __fvi_qs.as_slice(), __fvi_vs.as_slice());
    quote! {
        #[inline]
        fn #g(#sig) -> #fvi::NodeGradient<#n> {
            let mut __fvi_g = #fvi::zero_gradient::<#n>();
            self.__fvi_sparse(#args, &mut #fvi::DenseAccum::gradient(&mut __fvi_g));
            __fvi_g
        }
        #[inline]
        fn #j(#sig) -> #fvi::NodeJacobian<#n> {
            let mut __fvi_j = #fvi::zero_jacobian::<#n>();
            self.__fvi_sparse(#args, &mut #fvi::DenseAccum::jacobian(&mut __fvi_j));
            __fvi_j
        }
        #[inline]
        fn #m(#sig) -> #fvi::SMatrix<f64, #n, #n> {
            <Self as #fvi::ForcedLagrangian<#n>>::#j(self, #t_arg __fvi_qs, __fvi_vs).e
        }
    }
}
