//! When a check fails: the user's struct, the compile errors, and a stub impl, so that code
//! using the model (`Integrator::new(&model, …)`) reports no follow-on errors.

use proc_macro2::TokenStream;
use quote::quote;

use crate::ast::Model;

/// The struct, the errors and (when the number of coordinates is known) a stub impl.
pub fn expand(model: &Model, errors: syn::Error) -> TokenStream {
    let item = &model.item;
    let errors = errors.into_compile_error();
    let stub = stub_len(model).map(|n| {
        let ident = &item.ident;
        let (ig, tg, wc) = item.generics.split_for_impl();
        quote! {
            #[automatically_derived]
            impl #ig ::forced_vi::__private::ForcedLagrangian<#n> for #ident #tg #wc {
                fn lagrangian<__D: ::forced_vi::__private::Scalar>(
                    &self,
                    _: &[__D; #n],
                    _: &[__D; #n],
                ) -> __D {
                    ::core::unimplemented!()
                }
            }
        }
    });
    quote! {
        #item
        #errors
        #stub
    }
}

/// An item that is not a struct: itself and the errors.
pub fn non_struct(item: &syn::Item, errors: syn::Error) -> TokenStream {
    let errors = errors.into_compile_error();
    quote!(#item #errors)
}

/// The number of coordinates, if it can be read off the declaration.
fn stub_len(model: &Model) -> Option<TokenStream> {
    let generics_ok = model
        .item
        .generics
        .params
        .iter()
        .all(|p| matches!(p, syn::GenericParam::Const(_)));
    if !generics_ok || model.item.generics.where_clause.is_some() {
        return None;
    }
    let (_, coords) = model.coordinates.as_ref()?;
    if coords.is_empty() {
        return None;
    }
    let mut total = 0usize;
    let mut seen = std::collections::HashSet::new();
    for c in coords {
        if !seen.insert(c.name.to_string()) || coords.iter().any(|o| o.velocity == c.name) {
            continue;
        }
        match &c.ty {
            None => total = total.checked_add(1)?,
            Some(syn::Type::Array(a)) => {
                match &a.len {
                    syn::Expr::Lit(syn::ExprLit {
                        lit: syn::Lit::Int(i),
                        ..
                    }) => {
                        total = total
                            .checked_add(i.base10_parse::<usize>().ok()?)
                            .filter(|&t| t <= crate::check::MAX_COORDINATES)?;
                    }
                    syn::Expr::Path(p) if coords.len() == 1 => {
                        let ident = p.path.get_ident()?;
                        let is_param =
                            model.item.generics.params.iter().any(
                                |g| matches!(g, syn::GenericParam::Const(c) if c.ident == *ident),
                            );
                        return is_param.then(|| quote!(#ident));
                    }
                    _ => return None,
                }
            }
            Some(_) => return None,
        }
    }
    let n = proc_macro2::Literal::usize_unsuffixed(total);
    Some(quote!(#n))
}
