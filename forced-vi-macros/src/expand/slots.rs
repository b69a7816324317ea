//! Where the kernels write: the block entries of a slot ([`Slots`]) and the slots that a
//! term reads ([`SlotSet`]), as specific slots or, for a const-generic model, whole halves.

use std::collections::BTreeSet;

use proc_macro2::TokenStream;
use quote::quote;
use syn::Ident;

use super::{fvi, lit};
use crate::check::Checked;
use crate::lower::{Idx, Len, Var};

/// The block that a slot belongs to, as an accumulator path.
pub(super) struct Slots<'a> {
    pub(super) n: usize,
    pub(super) j: &'a Ident,
}

impl Slots<'_> {
    /// `j.grad.fq[s]` or `j.grad.lv[s − n]` (with a `grad` prefix or not).
    pub(super) fn grad(&self, s: usize, prefix: &TokenStream) -> TokenStream {
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
    pub(super) fn hess(&self, s: usize, t: usize) -> TokenStream {
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
pub(super) struct SlotSet {
    pub(super) q: SlotPart,
    pub(super) v: SlotPart,
}

pub(super) enum SlotPart {
    None,
    Some(Vec<TokenStream>),
    All,
}

pub(super) fn slot_set(c: &Checked, uses: &BTreeSet<Var>) -> SlotSet {
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

pub(super) fn part_tokens(part: &SlotPart, n: &Len, vel: bool) -> Option<TokenStream> {
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
