//! Which models split, and what the expansion then holds.
use proc_macro2::TokenStream;
use quote::quote;

fn expand(args: TokenStream) -> String {
    crate::entry(
        args,
        quote!(
            struct M<const N: usize> {
                k: f64,
                c: f64,
            }
        ),
    )
    .to_string()
}

fn splits(args: TokenStream) -> bool {
    let out = expand(args);
    assert!(!out.contains("compile_error"), "{out}");
    let has_impl = out.contains("SparseNode for M");
    assert_eq!(has_impl, out.contains("fn sparse_node"));
    has_impl
}

#[test]
fn index_sums_split() {
    let kinetic_for_nested = quote!((0..N).map(|i| q_dot[i] * q_dot[i]).sum());
    // The spring chain of `models/src/models.rs`, with guarded neighbours.
    assert!(splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
            - (0..=N).map(|i| {
                let left = if i == 0 { 0.0 } else { q[i - 1] };
                let right = if i == N { 0.0 } else { q[i] };
                let d = right - left;
                0.5 * k * d * d + 0.25 * c * d.powi(4)
            }).sum(),
        force(q[i] = -c * q_dot[i]),
    )));
    // Constant factors, division by a constant, negation, nesting of ±.
    assert!(splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = k * ((0..N).map(|i| q_dot[i] * q_dot[i]).sum() / 2.0
            - -(1..N).map(|i| (q[i] * q[i - 1]).cos()).sum()) - q[0],
    )));
    // Nested index sums: all pairs, the inner range starting at the outer variable.
    assert!(splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = #kinetic_for_nested
            - (0..N).map(|i| (i + 1..N).map(|j| k * (q[i] - q[j]).powi(2)).sum()).sum(),
    )));
    // `for` accumulations, with `let`s in the loop body and `-=`.
    assert!(splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = {
            let mut s = 0.0;
            for i in 0..N {
                let w = 1.0 + q[i] * q[i];
                s += w * q_dot[i] * q_dot[i];
            }
            for i in 1..N {
                s -= (q[i] - q[i - 1]).sinh();
            }
            s
        },
    )));
}

#[test]
fn non_local_models_do_not_split() {
    let kinetic = quote!((0..N).map(|i| q_dot[i] * q_dot[i]).sum());
    for l in [
        // A sum used nonlinearly.
        quote!(#kinetic - (0..N).map(|i| q[i]).sum().powi(2)),
        // A product of sums.
        quote!(#kinetic * (0..N).map(|i| q[i]).sum()),
        // An index through a local.
        quote!(#kinetic - (0..N).map(|i| { let j = i + 1; q[j % N] }).sum()),
        // A nested sum whose range depends on a coordinate.
        quote!(#kinetic - (0..N).map(|i| (0..N).map(|j| q[i] * q[j]).sum() * q[0]).sum()),
        // The whole array.
        quote!(#kinetic - (0..N).map(|i| q[i] * q.len() as f64).sum()),
        // A coordinate's name rebound in the term.
        quote!(#kinetic - (0..N).map(|i| { let q_dot = 2.0; q[i] * q_dot }).sum()),
        // The loop variable rebound.
        quote!(#kinetic - (0..N).map(|i| { let i = 0; q[i] }).sum()),
        // A range over the array's length.
        quote!(#kinetic - (0..q.len()).map(|i| q[i] * k).sum()),
        // A product over an index is not a sum.
        quote!(#kinetic - (0..N).map(|i| q[i] * k).product()),
    ] {
        assert!(
            !splits(quote!(coordinates(q: [f64; N]), lagrangian = #l)),
            "{l}"
        );
    }
    // A force entry that reads the whole array.
    assert!(!splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = #kinetic,
        force(q[i] = -c * (0..N).map(|j| q_dot[j]).sum()),
    )));
}

#[test]
fn large_models_compute_dense_blocks_through_the_terms() {
    let out = expand(quote!(
        coordinates(q: [f64; N]),
        lagrangian = (0..N).map(|i| q_dot[i] * q_dot[i] * (1.0 + q[i].cos())).sum(),
        force(q[i] = -c * q_dot[i] * q[i]),
    ));
    // No whole-model dual numbers (`N × N` types) anywhere.
    assert!(out.contains("DenseAccum"), "{out}");
    assert!(!out.contains("term_hessian") && !out.contains("term_cross"));
    assert!(!out.contains("force_jacobian_q") && !out.contains("Dual2SVec64 < N >"));
    assert!(out.contains("split_stack_bytes"));
}

#[test]
fn small_literal_models_keep_their_dense_kernels() {
    let out = crate::entry(
        quote!(
            coordinates(x, y),
            lagrangian =
                0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y) - k * (x - y).cos(),
            force(x = -c * x_dot, y = (c - y * y) * y_dot),
        ),
        quote!(
            struct P {
                k: f64,
                c: f64,
            }
        ),
    )
    .to_string();
    assert!(out.contains("SparseNode for P"), "{out}");
    assert!(!out.contains("DenseAccum") && out.contains("fn node_jacobian"));
}

#[test]
fn a_large_literal_model_must_split() {
    let big = |l: TokenStream| {
        crate::entry(
            quote!(coordinates(q: [f64; 2048]), lagrangian = #l),
            quote!(
                struct B {
                    k: f64,
                }
            ),
        )
        .to_string()
    };
    let kinetic = quote!((0..2048).map(|i| q_dot[i] * q_dot[i]).sum());
    let out = big(quote!(#kinetic - k * (1..2048).map(|i| q[i] * q[i - 1]).sum()));
    assert!(!out.contains("compile_error") && out.contains("SparseNode for B"));
    let out = big(quote!(#kinetic - k * (0..2048).map(|i| q[i]).sum().powi(2)));
    assert!(out.contains("compile_error") && out.contains("does not split"));
}

#[test]
fn a_block_around_a_nested_sum_splits() {
    // rustfmt writes the outer closure's body as a block holding only the inner sum.
    assert!(splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = (0..N).map(|s| 0.5 * q_dot[s] * q_dot[s]).sum()
            - (0..N)
                .map(|r| {
                    (0..=N)
                        .map(|j| {
                            let left = if j == 0 { 0.0 } else { q[r * N + j - 1] };
                            let right = if j == N { 0.0 } else { q[r * N + j] };
                            0.5 * k * (right - left) * (right - left)
                        })
                        .sum()
                })
                .sum(),
        force(q[i] = -c * q_dot[i]),
    )));
    // A block with a statement before the sum is not a bare sum.
    assert!(!splits(quote!(
        coordinates(q: [f64; N]),
        lagrangian = (0..N).map(|s| 0.5 * q_dot[s] * q_dot[s]).sum()
            - (0..N).map(|r| { let x = q[r]; x.sin() }).sum().sin(),
        force(q[i] = -c * q_dot[i]),
    )));
}
