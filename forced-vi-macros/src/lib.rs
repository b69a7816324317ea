//! The `#[forced_lagrangian]` attribute of [forced-vi](https://docs.rs/forced-vi): a model
//! written as a Lagrangian and a force over named coordinates becomes a checked,
//! specialised `ForcedLagrangian` impl. Use it through `forced_vi::forced_lagrangian`.
//!
//! The crate is split by phase: `ast` parses, `check` validates and analyses (with `lower`
//! for expressions, `poly` for symbolic polynomials and `split` for local terms), `expand`
//! generates (with `sparse` for the per-term kernels), and `fallback` pairs the errors with
//! a stub impl.
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
mod sparse;
mod split;

use proc_macro::TokenStream;

/// Writes the `ForcedLagrangian` impl of a model from its Lagrangian and its force.
///
/// ```text
/// #[forced_lagrangian(
///     coordinates(<coordinate>, ...),
///     lagrangian = <expr>,
///     force(<entry>, ...),            // optional: without it, a conservative model
/// )]
/// struct Model { <parameter>: f64, ... }      // or struct Model<const N: usize> { ... }
///
/// <coordinate> = x                 a scalar; its velocity is `x_dot`
///              | q: [f64; 4]       an array of literal length; `q[i]`, `q_dot[i]`
///              | q: [f64; N]       `N` the struct's const parameter (the only coordinate)
/// <entry>      = x = <expr>        the force on a scalar
///              | q[i] = <expr>     on every element of an array, `i` its index
///              | q = [<expr>, ...] on each element of an array of literal length
/// <expr>       = arithmetic on coordinates, velocities, parameters (by name), number
///                literals and the time `t`; methods (`sin`, `cos`, `exp`, `ln`, `sqrt`,
///                `powi`, `powf`, `max`, `min`, ...); blocks with `let`, `if`/`else`,
///                `for i in a..b`; index sums `(a..b).map(|i| ...).sum()`
/// ```
///
/// Every coordinate has one force entry; parameters are `f64` fields; `t` and names starting
/// with `__fvi` are reserved. Mistakes are compile errors at the user's tokens. The
/// generated impl sets `STRUCTURE` from what it proves about the expressions, and a
/// Lagrangian made of local terms also gets sparse node kernels.
///
/// The reference, every form with an example that runs and the compile errors, is the
/// module `forced_vi::guide`
/// ([docs.rs](https://docs.rs/forced-vi/latest/forced_vi/guide/index.html)). Use the
/// attribute through `forced_vi::forced_lagrangian` or `forced_vi::prelude`: the generated
/// code names `forced_vi`'s paths.
#[proc_macro_attribute]
pub fn forced_lagrangian(args: TokenStream, item: TokenStream) -> TokenStream {
    expand_on_own_stack(args.into(), item.into()).into()
}

/// [`entry`] on a stack of [`EXPANSION_STACK`] bytes.
fn expand_on_own_stack(
    args: proc_macro2::TokenStream,
    item: proc_macro2::TokenStream,
) -> proc_macro2::TokenStream {
    stacker::grow(EXPANSION_STACK, || entry(args, item))
}

/// The stack the expansion runs on. Parsing, checking and lowering recurse over the
/// expression tree, and a Lagrangian of a few thousand terms (`a + b + c + ...`, as a
/// computer algebra system writes one) is a tree a few thousand levels deep: 2000 terms
/// overflowed the compiler's own stack (rustc aborts with SIGSEGV), where plain Rust compiles
/// the same sum. The memory is reserved, not used: the pages a shallow model never reaches
/// are never touched.
const EXPANSION_STACK: usize = 1 << 30;

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
    // The model as local terms, if it splits (DESIGN §9).
    let split = checked.as_ref().and_then(split::split);
    if let Some(c) = &checked {
        check::check_dense_size(&cx, c, split.is_some());
    }
    match (cx.check(), checked) {
        (Ok(()), Some(checked)) => {
            // The same model with its parameters as duals, for their derivatives; a model
            // that does not read that way declares no parameters. Such a model is not
            // split, so a large one declares none.
            let quiet = ctxt::Ctxt::default();
            let theta = check::check_as(&quiet, &model, true);
            if let Some(t) = &theta {
                check::check_dense_size(&quiet, t, false);
            }
            let read = quiet.check().is_ok();
            let theta = theta.filter(|_| read);
            // A model with per-term kernels gets its parameter derivatives term by term too,
            // where the Lagrangian read with its parameters as duals still splits (its own
            // split: a parameter is no longer a constant factor there).
            // None for a model without parameters: nothing would call them.
            let theta_split = theta
                .as_ref()
                .filter(|t| split.is_some() && !t.env.params.is_empty())
                .and_then(split::split);
            expand::generate(
                &checked,
                split.as_ref(),
                theta.as_ref().map(|t| (t, theta_split.as_ref())),
            )
        }
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
        let out = super::expand_on_own_stack(
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

    /// A sum of 800 terms is a tree 800 levels deep: on the 2 MiB stack of a test thread
    /// (rustc's own was overflowed by 2000 terms), the expansion needs the stack it makes.
    #[test]
    fn a_lagrangian_of_hundreds_of_terms_expands() {
        let terms = (0..800).map(|k| {
            let k = k as f64;
            quote!(+ #k * x * y)
        });
        let out = super::expand_on_own_stack(
            quote!(coordinates(x, y), lagrangian = x_dot * x_dot + y_dot * y_dot #(#terms)*),
            quote!(
                struct Long {}
            ),
        )
        .to_string();
        assert!(!out.contains("compile_error"));
    }

    fn expand(args: proc_macro2::TokenStream) -> String {
        super::entry(
            args,
            quote!(
                struct M {
                    k: f64,
                    w: f64,
                }
            ),
        )
        .to_string()
    }

    #[test]
    fn a_model_that_names_t_is_driven() {
        // `t` in the force: `_at` methods, `uses_time`, specialised kernels at the time.
        let out = expand(quote!(
            coordinates(x),
            lagrangian = x_dot * x_dot / 2 - k * x * x / 2,
            force(x = (w * t).cos()),
        ));
        assert!(!out.contains("compile_error"), "{out}");
        assert!(out.contains("uses_time : true"));
        assert!(out.contains("fn force_at") && out.contains("fn lagrangian_at"));
        assert!(out.contains("fn node_gradient_at") && out.contains("fn node_jacobian_at"));
        assert!(out.contains("fn mass_matrix_at") && out.contains("KERNEL_STACK_BYTES"));
        // The mass matrix stays constant when only the potential depends on t.
        assert!(out.contains("constant_mass : true"));
        // Without t: today's code.
        let out = expand(quote!(
            coordinates(x),
            lagrangian = x_dot * x_dot / 2 - k * x * x / 2,
            force(x = -w * x_dot),
        ));
        assert!(out.contains("uses_time : false") && out.contains("fn node_gradient"));
        assert!(!out.contains("fn force_at") && !out.contains("fn lagrangian_at"));
    }

    #[test]
    fn only_constraints_that_name_t_read_the_time() {
        let promise = "const CONSTRAINTS_READ_TIME : bool = false";
        let fixed = expand(quote!(
            coordinates(x, y),
            lagrangian = (x_dot * x_dot + y_dot * y_dot) / 2,
            constraints(x * x + y * y - k),
        ));
        assert!(
            !fixed.contains("compile_error") && fixed.contains(promise),
            "{fixed}"
        );
        for g in [
            quote!(x * x + y * y - k * (w * t).cos()),
            quote!(x * y - k * t),
            quote!({
                let s = (w * t).sin();
                x - s
            }),
        ] {
            let out = expand(quote!(
                coordinates(x, y),
                lagrangian = (x_dot * x_dot + y_dot * y_dot) / 2,
                constraints(#g),
            ));
            assert!(!out.contains("compile_error"), "{out}");
            assert!(!out.contains(promise), "{g}");
        }
    }

    #[test]
    fn only_polynomials_of_degree_two_and_one_are_linear() {
        let linear = [
            quote!(
                coordinates(x, y),
                lagrangian =
                    (w * x_dot * x_dot + y_dot * y_dot) / 2 - k * (x - y) * (x - y) / 2 + w * x,
                force(x = -k * x_dot + 0.5, y = -(k * 2.0) * y_dot - x / 4.0),
            ),
            quote!(coordinates(x), lagrangian = x_dot * x_dot / 2 - x * x / 2),
            quote!(
                coordinates(q: [f64; 3]),
                lagrangian = q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1] + q_dot[2] * q_dot[2] - q[0] * q[1],
                force(q[i] = -k * q_dot[i]),
            ),
        ];
        for m in linear {
            let out = expand(m.clone());
            assert!(!out.contains("compile_error"), "{out}");
            assert!(out.contains("linear : true"), "{m}");
        }
        let not_linear = [
            // A cubic potential, a velocity-dependent mass, a cubic force, a sine.
            quote!(coordinates(x), lagrangian = x_dot * x_dot / 2 - x * x * x),
            quote!(
                coordinates(x),
                lagrangian = x * x_dot * x_dot / 2 - x * x / 2
            ),
            quote!(
                coordinates(x),
                lagrangian = x_dot * x_dot / 2,
                force(x = -x * x * x_dot)
            ),
            quote!(coordinates(x), lagrangian = x_dot * x_dot / 2 + x.cos()),
            // The time, even in an additive forcing, and a condition on the coordinates.
            quote!(
                coordinates(x),
                lagrangian = x_dot * x_dot / 2,
                force(x = (w * t).cos())
            ),
            quote!(
                coordinates(x),
                lagrangian = x_dot * x_dot / 2,
                force(x = if x > 0.0 { -x } else { x })
            ),
            // A constant-generic length: no polynomial is read.
        ];
        for m in not_linear {
            let out = expand(m.clone());
            assert!(!out.contains("compile_error"), "{out}");
            assert!(out.contains("linear : false"), "{m}");
        }
    }

    #[test]
    fn a_mass_that_depends_on_t_is_not_constant() {
        for l in [
            quote!(lagrangian = (1.0 + k * t) * x_dot * x_dot / 2 - x * x / 2),
            quote!(
                lagrangian = {
                    let m = 1.0 + (w * t).sin() / 2;
                    m * x_dot * x_dot
                }
            ),
            quote!(
                lagrangian = if t > 1.0 {
                    x_dot * x_dot
                } else {
                    2 * x_dot * x_dot
                }
            ),
            quote!(lagrangian = x_dot * x_dot / 2 + t * x_dot * x_dot),
        ] {
            let out = expand(quote!(coordinates(x), #l));
            assert!(!out.contains("compile_error"), "{out}");
            assert!(out.contains("uses_time : true"), "{l}");
            assert!(out.contains("constant_mass : false"), "{l}");
        }
    }
}
