//! The `#[forced_lagrangian]` attribute of [forced-vi](https://docs.rs/forced-vi): a model
//! written as a Lagrangian and a force over named coordinates becomes a checked,
//! specialised `ForcedLagrangian` impl. Use it through `forced_vi::forced_lagrangian`.
//!
//! The crate is split by phase: `ast` parses, `check` validates and analyses (with `lower`
//! for expressions and `poly` for symbolic polynomials), `expand` generates, and `fallback`
//! pairs the errors with a stub impl.
#![warn(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used)]

mod ast;
mod check;
mod ctxt;
mod expand;
mod fallback;
mod lower;
mod poly;
#[cfg(test)]
mod props;

use proc_macro::TokenStream;

/// Writes the `ForcedLagrangian` impl of a model; see the forced-vi README, "Writing a model".
#[proc_macro_attribute]
pub fn forced_lagrangian(args: TokenStream, item: TokenStream) -> TokenStream {
    entry(args.into(), item.into()).into()
}

fn entry(
    args: proc_macro2::TokenStream,
    item: proc_macro2::TokenStream,
) -> proc_macro2::TokenStream {
    let item: syn::Item = match syn::parse2(item) {
        Ok(item) => item,
        Err(e) => return e.into_compile_error(),
    };
    let cx = ctxt::Ctxt::default();
    let model = match ast::parse(&cx, args, item) {
        Ok(model) => model,
        Err(item) => {
            return match cx.check() {
                Err(e) => fallback::non_struct(&item, e),
                Ok(()) => quote::quote!(#item),
            }
        }
    };
    let checked = check::check(&cx, &model);
    match (cx.check(), checked) {
        (Ok(()), Some(checked)) => expand::generate(&checked),
        (Err(e), _) => fallback::expand(&model, e),
        (Ok(()), None) => fallback::expand(
            &model,
            syn::Error::new(
                proc_macro2::Span::call_site(),
                "#[forced_lagrangian] could not read this model",
            ),
        ),
    }
}

#[cfg(test)]
mod tests {
    use quote::quote;

    #[test]
    fn expands_the_paper_model() {
        let out = super::entry(
            quote!(
                coordinates(x, y),
                lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
                    - 0.5 * (x * x + (1.0 + rho) * y * y)
                    - lambda * (x - y) * (x - y),
                force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
            ),
            quote!(
                struct CoupledVanDerPol {
                    eps: f64,
                    rho: f64,
                    lambda: f64,
                }
            ),
        )
        .to_string();
        if std::env::var_os("FVI_SHOW_EXPANSION").is_some() {
            println!("{out}");
        }
        assert!(!out.contains("compile_error"));
        // All of the paper's model is polynomial: no dual numbers in its kernels.
        assert!(!out.contains("term_hessian"));
        assert!(!out.contains("force_row"));
    }
}
