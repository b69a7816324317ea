//! The specialised kernels of an autonomous model, `node_gradient`, `node_jacobian` and
//! `mass_matrix`: per block, the polynomial part of `L` as `f64` code derived at compile
//! time (see `poly`), each other term of `L` with the smallest dual number over the variables
//! it uses, and the force only where it acts.

use std::collections::{BTreeMap, BTreeSet};

use proc_macro2::{Literal, Span, TokenStream};
use quote::{format_ident, quote, quote_spanned};
use syn::Ident;

use super::slots::{part_tokens, slot_set, SlotPart, SlotSet, Slots};
use super::{fvi, lit, param_bindings};
use crate::check::{slots, Checked, CheckedForce, Row, Term};
use crate::lower::Len;
use crate::poly::Poly;

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
pub(super) fn kernels(c: &Checked) -> (TokenStream, Vec<TokenStream>) {
    let fvi = fvi();
    let n = &c.n;
    let mut stack: Vec<TokenStream> = Vec::new();
    let base_values = token_count(&c.lagrangian.tokens)
        .saturating_add(c.force.as_ref().map_or(0, |f| {
            f.fns.iter().map(|x| token_count(&x.lowered.tokens)).sum()
        }))
        .saturating_mul(4)
        .saturating_add(64);
    let base_values = lit(base_values);
    stack.push(quote!(#fvi::kernel_stack_bytes::<f64, #n>(#base_values)));
    let mut k = Kernels {
        c,
        nd: quote!(#fvi::num_dual),
        fvi,
        q: format_ident!("__fvi_q"),
        v: format_ident!("__fvi_v"),
        g: format_ident!("__fvi_g"),
        j: format_ident!("__fvi_j"),
        params: param_bindings(&c.env),
        time_f64: if c.uses_time {
            quote!(__fvi_t,)
        } else {
            TokenStream::new()
        },
        time_dual: if c.uses_time {
            quote!(::core::convert::From::from(__fvi_t),)
        } else {
            TokenStream::new()
        },
        stack,
        grad_code: TokenStream::new(),
        jac_code: TokenStream::new(),
        mass_code: TokenStream::new(),
    };
    // Polynomial part of L: derivatives written out at compile time.
    if let Len::Lit(nn) = *n {
        k.poly_lagrangian(nn);
    }
    // Non-polynomial terms of L: dual numbers over the variables each one uses.
    for (i, t) in c.dual_terms.iter().enumerate() {
        k.dual_term(i, t);
    }
    // The force.
    if let Some(force) = &c.force {
        k.force(force);
    }
    k.finish()
}

/// The kernels being generated: the names of their locals, the code of each so far, and
/// the stack bounds of the helpers they call.
struct Kernels<'c, 'm> {
    c: &'c Checked<'m>,
    fvi: TokenStream,
    /// `num_dual` in the runtime.
    nd: TokenStream,
    /// The coordinates and velocities as arrays.
    q: Ident,
    v: Ident,
    /// The gradient and the Jacobian (or mass matrix) accumulators.
    g: Ident,
    j: Ident,
    /// The parameters as `f64` locals.
    params: TokenStream,
    /// A driven model's time argument, leading the arguments of a call of its helpers and
    /// its `force_at`: as the kernels' `f64` (`time_f64`) and as the dual number of the
    /// call (`time_dual`); both empty for an autonomous model.
    time_f64: TokenStream,
    time_dual: TokenStream,
    stack: Vec<TokenStream>,
    grad_code: TokenStream,
    jac_code: TokenStream,
    mass_code: TokenStream,
}

impl Kernels<'_, '_> {
    /// Slot `s` of `nn` coordinates as a variable: `q[s]` or `v[s − nn]`.
    fn var(&self, nn: usize) -> impl Fn(usize) -> TokenStream {
        let (q, v) = (self.q.clone(), self.v.clone());
        move |s: usize| -> TokenStream {
            if s < nn {
                let s = lit(s);
                quote!(#q[#s])
            } else {
                let s = lit(s - nn);
                quote!(#v[#s])
            }
        }
    }

    /// The polynomial part of `L` (over `nn` coordinates): its first and second derivatives
    /// written out.
    fn poly_lagrangian(&mut self, nn: usize) {
        let c = self.c;
        let var = self.var(nn);
        let params = &self.params;
        let used: BTreeSet<usize> = c
            .poly_l
            .monomials()
            .flat_map(|m| m.iter().map(|&(s, _)| s))
            .collect();
        let mut g_lines = TokenStream::new();
        let mut j_lines = TokenStream::new();
        let mut m_lines = TokenStream::new();
        let gs = Slots { n: nn, j: &self.g };
        let js = Slots { n: nn, j: &self.j };
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
            self.grad_code.extend(quote!({ #params #g_lines }));
            self.jac_code.extend(quote!({ #params #j_lines }));
        }
        if !m_lines.is_empty() {
            self.mass_code.extend(quote!({ #params #m_lines }));
        }
    }

    /// The non-polynomial term `t` of `L` (helper `__fvi_l{k}`).
    fn dual_term(&mut self, k: usize, t: &Term) {
        let name = format_ident!("__fvi_l{}", k);
        let time = &self.time_dual;
        let call = quote!(|__fvi_a, __fvi_b| self.#name(#time __fvi_a, __fvi_b));
        let set = slot_set(self.c, &t.lowered.uses);
        let values = lit(token_count(&t.lowered.tokens)
            .saturating_mul(4)
            .saturating_add(64));
        match (&set.q, &set.v, &self.c.n) {
            (SlotPart::All, _, Len::Param(_)) | (_, SlotPart::All, Len::Param(_)) => {
                self.dual_term_ranges(&set, &call, &values);
            }
            _ => self.dual_term_slots(t, &set, &call, &values),
        }
    }

    /// A term that reads a whole array of a const-generic model: over slot ranges.
    fn dual_term_ranges(&mut self, set: &SlotSet, call: &TokenStream, values: &Literal) {
        let (fvi, nd, n) = (&self.fvi, &self.nd, &self.c.n);
        let (q, v, g, j) = (&self.q, &self.v, &self.g, &self.j);
        let q_slots = part_tokens(&set.q, n, false);
        let v_slots = part_tokens(&set.v, n, true);
        self.stack
            .push(quote!(#fvi::kernel_stack_bytes::<#nd::Dual2SVec64<#n>, #n>(#values)));
        for slots in [&q_slots, &v_slots].into_iter().flatten() {
            self.grad_code
                .extend(quote!(#fvi::term_gradient(&#q, &#v, &#slots, #call, &mut #g);));
            self.jac_code
                .extend(quote!(#fvi::term_hessian(&#q, &#v, &#slots, #call, &mut #j);));
        }
        if let Some(slots) = &v_slots {
            self.mass_code
                .extend(quote!(#fvi::term_hessian(&#q, &#v, &#slots, #call, &mut #j);));
        }
        if q_slots.is_some() && v_slots.is_some() {
            self.stack.push(
                quote!(#fvi::kernel_stack_bytes::<#nd::HyperDualSVec64<#n, #n>, #n>(#values)),
            );
            self.jac_code
                .extend(quote!(#fvi::term_cross(&#q, &#v, #call, &mut #j);));
        }
    }

    /// A term over the slots it reads.
    fn dual_term_slots(&mut self, t: &Term, set: &SlotSet, call: &TokenStream, values: &Literal) {
        let c = self.c;
        let (fvi, nd, n) = (&self.fvi, &self.nd, &c.n);
        let (q, v, g, j) = (&self.q, &self.v, &self.g, &self.j);
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
        self.stack
            .push(quote!(#fvi::kernel_stack_bytes::<#nd::Dual2SVec64<#kk>, #n>(#values)));
        self.grad_code
            .extend(quote!(#fvi::term_gradient(&#q, &#v, &[#(#all),*], #call, &mut #g);));
        self.jac_code
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
            self.mass_code
                .extend(quote!(#fvi::term_hessian(&#q, &#v, &[#(#v_only),*], #call, &mut #j);));
        }
    }

    /// The force: its value in the gradient, its derivatives in the Jacobian.
    fn force(&mut self, force: &CheckedForce) {
        let (n, g) = (&self.c.n, &self.g);
        let value = self.force_value();
        self.grad_code.extend(quote! {
            let __fvi_f: [f64; #n] = #value;
            for __fvi_k in 0..#n {
                #g.fq[__fvi_k] += __fvi_f[__fvi_k];
            }
        });
        match *n {
            Len::Lit(nn) => {
                let mut poly_lines = TokenStream::new();
                for r in &force.rows {
                    self.force_row(force, r, nn, &mut poly_lines);
                }
                if !poly_lines.is_empty() {
                    let params = &self.params;
                    self.jac_code.extend(quote!({ #params #poly_lines }));
                }
            }
            Len::Param(_) => self.force_whole(force),
        }
    }

    /// The force's value at the node as `[f64; N]` (at the kernel's time for a driven
    /// model).
    fn force_value(&self) -> TokenStream {
        let (fvi, n, q, v) = (&self.fvi, &self.c.n, &self.q, &self.v);
        if self.c.uses_time {
            quote!(<Self as #fvi::ForcedLagrangian<#n>>::force_at::<f64>(self, __fvi_t, &#q, &#v))
        } else {
            quote!(<Self as #fvi::ForcedLagrangian<#n>>::force::<f64>(self, &#q, &#v))
        }
    }

    /// One row of the force (of `nn` coordinates): a polynomial's derivatives (added to
    /// `poly_lines`), or a dual number over the slots it reads.
    fn force_row(
        &mut self,
        force: &CheckedForce,
        r: &Row,
        nn: usize,
        poly_lines: &mut TokenStream,
    ) {
        let c = self.c;
        let var = self.var(nn);
        let (fvi, nd, n) = (&self.fvi, &self.nd, &c.n);
        let (q, v, j) = (&self.q, &self.v, &self.j);
        let js = Slots { n: nn, j };
        let name = format_ident!("__fvi_f{}", r.func);
        let index = r.index.map(|i| {
            let i = lit(i);
            quote!(, #i)
        });
        let row = lit(r.row);
        let (tf, td) = (&self.time_f64, &self.time_dual);
        if let Some(p) = &r.poly {
            if p.is_zero() {
                return;
            }
            self.jac_code
                .extend(quote!(#j.grad.fq[#row] += self.#name::<f64>(#tf &#q, &#v #index);));
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
            return;
        }
        let sl: Vec<Literal> = slots(&c.env, nn, &r.uses).into_iter().map(lit).collect();
        if sl.is_empty() {
            self.jac_code
                .extend(quote!(#j.grad.fq[#row] += self.#name::<f64>(#tf &#q, &#v #index);));
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
            self.stack
                .push(quote!(#fvi::kernel_stack_bytes::<#nd::DualSVec64<#kk>, #n>(#values)));
            self.jac_code.extend(quote! {
                #fvi::force_row(&#q, &#v, &[#(#sl),*], #row,
                    |__fvi_a, __fvi_b| self.#name(#td __fvi_a, __fvi_b #index), &mut #j);
            });
        }
    }

    /// The force of a const-generic model: its Jacobians through the whole `force`.
    fn force_whole(&mut self, force: &CheckedForce) {
        let (fvi, nd, n) = (&self.fvi, &self.nd, &self.c.n);
        let (q, v, j) = (&self.q, &self.v, &self.j);
        let values = lit(force
            .fns
            .iter()
            .map(|f| token_count(&f.lowered.tokens))
            .fold(0usize, usize::saturating_add)
            .saturating_mul(4)
            .saturating_add(64));
        self.stack
            .push(quote!(#fvi::kernel_stack_bytes::<#nd::DualSVec64<#n>, #n>(#values)));
        let call = if self.c.uses_time {
            quote!(|__fvi_a, __fvi_b| <Self as #fvi::ForcedLagrangian<#n>>::force_at(self, ::core::convert::From::from(__fvi_t), __fvi_a, __fvi_b))
        } else {
            quote!(|__fvi_a, __fvi_b| <Self as #fvi::ForcedLagrangian<#n>>::force(self, __fvi_a, __fvi_b))
        };
        let value = self.force_value();
        if force.uses_q {
            self.jac_code
                .extend(quote!(#fvi::force_jacobian_q(&#q, &#v, true, #call, &mut #j);));
        }
        if force.uses_v {
            let add = !force.uses_q;
            self.jac_code
                .extend(quote!(#fvi::force_jacobian_v(&#q, &#v, #add, #call, &mut #j);));
        }
        if !force.uses_q && !force.uses_v {
            self.jac_code.extend(quote! {
                let __fvi_f: [f64; #n] = #value;
                for __fvi_k in 0..#n {
                    #j.grad.fq[__fvi_k] += __fvi_f[__fvi_k];
                }
            });
        }
    }

    /// The three kernels from the code gathered, and the stack bounds.
    fn finish(self) -> (TokenStream, Vec<TokenStream>) {
        let (fvi, n) = (&self.fvi, &self.c.n);
        let (q, v, g, j) = (&self.q, &self.v, &self.g, &self.j);
        let (grad_code, jac_code, mass_code) = (&self.grad_code, &self.jac_code, &self.mass_code);
        let qs = format_ident!("__fvi_qs");
        let vs = format_ident!("__fvi_vs");
        let sig_args = quote!(&self, #qs: &#fvi::SVector<f64, #n>, #vs: &#fvi::SVector<f64, #n>);
        let prologue = quote! {
            let #q: [f64; #n] = ::core::convert::Into::into(*#qs);
            let #v: [f64; #n] = ::core::convert::Into::into(*#vs);
        };
        let uses_args = |code: &TokenStream| -> TokenStream {
            if code.is_empty() {
                quote!(let _ = (&#q, &#v);)
            } else {
                TokenStream::new()
            }
        };
        let g_unused = uses_args(grad_code);
        let j_unused = uses_args(jac_code);
        let m_unused = uses_args(mass_code);
        let mutable = |code: &TokenStream| {
            if code.is_empty() {
                quote!()
            } else {
                quote!(mut)
            }
        };
        let (mut_g, mut_j, mut_m) = (mutable(grad_code), mutable(jac_code), mutable(mass_code));
        let grad_body = quote! {
            #prologue
            let #mut_g #g = #fvi::zero_gradient::<#n>();
            #g_unused
            #grad_code
            #g
        };
        let jac_body = quote! {
            #prologue
            let #mut_j #j = #fvi::zero_jacobian::<#n>();
            #j_unused
            #jac_code
            #j
        };
        let mass_body = quote! {
            #prologue
            let #mut_m #j = #fvi::zero_jacobian::<#n>();
            #m_unused
            #mass_code
            #j.e
        };
        let code = if self.c.uses_time {
            // A driven model: the kernels at the time `t` (`_at`), and the autonomous ones
            // at `t = 0`, as its `lagrangian` and `force` are.
            let sig_at = quote!(&self, __fvi_t: f64, #qs: &#fvi::SVector<f64, #n>, #vs: &#fvi::SVector<f64, #n>);
            let at = |name: &str| {
                let f = format_ident!("{}_at", name);
                quote!(<Self as #fvi::ForcedLagrangian<#n>>::#f(self, 0.0, #qs, #vs))
            };
            let (g0, j0, m0) = (at("node_gradient"), at("node_jacobian"), at("mass_matrix"));
            quote_spanned! {Span::call_site()=>
                #[inline]
                fn node_gradient_at(#sig_at) -> #fvi::NodeGradient<#n> {
                    let _ = __fvi_t;
                    #grad_body
                }
                #[inline]
                fn node_jacobian_at(#sig_at) -> #fvi::NodeJacobian<#n> {
                    let _ = __fvi_t;
                    #jac_body
                }
                #[inline]
                fn mass_matrix_at(#sig_at) -> #fvi::SMatrix<f64, #n, #n> {
                    let _ = __fvi_t;
                    #mass_body
                }
                #[inline]
                fn node_gradient(#sig_args) -> #fvi::NodeGradient<#n> { #g0 }
                #[inline]
                fn node_jacobian(#sig_args) -> #fvi::NodeJacobian<#n> { #j0 }
                #[inline]
                fn mass_matrix(#sig_args) -> #fvi::SMatrix<f64, #n, #n> { #m0 }
            }
        } else {
            quote_spanned! {Span::call_site()=>
                #[inline]
                fn node_gradient(#sig_args) -> #fvi::NodeGradient<#n> { #grad_body }
                #[inline]
                fn node_jacobian(#sig_args) -> #fvi::NodeJacobian<#n> { #jac_body }
                #[inline]
                fn mass_matrix(#sig_args) -> #fvi::SMatrix<f64, #n, #n> { #mass_body }
            }
        };
        (code, self.stack)
    }
}
