//! The velocity solve `L_v(q, v) = p` on sparse storage (DESIGN §3, "Initial data"): Newton
//! on the mass matrix `E`, factored by faer's sparse LU on the node pattern.

use crate::error::Error;
use crate::model::{NodeBlocks, NodePattern, NodeSink, SparseNode};
use crate::sparse::lu::SparseLu;
use crate::sparse::pattern::transpose;

/// Buffers of the velocity solve, made once per run.
pub(crate) struct VelocitySolver {
    lu: SparseLu,
    /// Where each node-pattern entry sits in `lu`'s values.
    csc_of: Vec<usize>,
    blocks: NodeBlocks,
    lq_f: Vec<f64>,
    lv: Vec<f64>,
    r: Vec<f64>,
    r_trial: Vec<f64>,
    dv: Vec<f64>,
    trial: Vec<f64>,
    /// Each row's terms, `|p_a| + Σ_b |E_ab| |v_b|`, at the current `v`.
    size: Vec<f64>,
    /// A constant mass matrix is factored once.
    constant_mass: bool,
    factored: bool,
}

fn max_norm(x: &[f64]) -> f64 {
    x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// `max_a |r_a| / (k size_a + 4 MIN_POSITIVE)`: each row against its own terms (NaN if a
/// row is).
fn weighed(r: &[f64], size: &[f64], k: f64) -> f64 {
    r.iter().zip(size).fold(0.0f64, |m, (r, s)| {
        let x = r.abs() / (k * s + 4.0 * f64::MIN_POSITIVE);
        if x > m || x.is_nan() { x } else { m }
    })
}

/// `L_v(q, v) − p` into `out` (with `lq_f`, `lv` as scratch); `false` if not finite or
/// written outside `n`.
fn residual(
    node: &dyn SparseNode,
    (t, q, v, p): (f64, &[f64], &[f64], &[f64]),
    (lq_f, lv): (&mut [f64], &mut [f64]),
    out: &mut [f64],
) -> bool {
    let mut sink = NodeSink::gradient(lq_f, lv);
    node.eval(t, q, v, &mut sink);
    if sink.outside() {
        return false;
    }
    for ((r, lv), p) in out.iter_mut().zip(lv.iter()).zip(p) {
        *r = lv - p;
    }
    out.iter().all(|x| x.is_finite())
}

impl VelocitySolver {
    /// Buffers on `pattern`. With `constant_mass` (the model's promise), `E` is factored once.
    pub(crate) fn new(pattern: &NodePattern, constant_mass: bool) -> Result<Self, Error> {
        let n = pattern.n();
        let tr = transpose(pattern);
        let lu = SparseLu::new(n, tr.col_ptr, tr.row_idx).map_err(|_| Error::InvalidModel {
            message: "the sparse node pattern cannot be analysed".into(),
        })?;
        Ok(VelocitySolver {
            lu,
            csc_of: tr.csc_of,
            blocks: NodeBlocks::zeros(pattern.nnz()),
            lq_f: vec![0.0; n],
            lv: vec![0.0; n],
            r: vec![0.0; n],
            r_trial: vec![0.0; n],
            dv: vec![0.0; n],
            trial: vec![0.0; n],
            size: vec![0.0; n],
            constant_mass,
            factored: false,
        })
    }

    /// Evaluates and factors `E` at `(t, q, v)`; returns its largest entry.
    fn factor_mass(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        at: (f64, &[f64], &[f64]),
        step: usize,
    ) -> Result<f64, Error> {
        let (t, q, v) = at;
        if self.constant_mass && self.factored {
            return Ok(self.lu.max_abs());
        }
        let mut sink = NodeSink::values(&mut self.lq_f, &mut self.lv, pattern, &mut self.blocks);
        node.eval(t, q, v, &mut sink);
        if sink.outside() {
            return Err(Error::outside_pattern());
        }
        for (k, &e) in self.blocks.e.iter().enumerate() {
            self.lu.values[self.csc_of[k]] = e;
        }
        if self.lu.values.iter().any(|x| !x.is_finite()) {
            return Err(Error::NonFiniteModel { step, t });
        }
        self.lu.factor().map_err(|_| Error::SingularMassMatrix {
            step,
            t,
            rcond: 0.0,
        })?;
        self.factored = true;
        Ok(self.lu.max_abs())
    }

    /// The node blocks at `(t, q, v)` into `self.blocks`, checked.
    fn eval_blocks(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        (t, q, v): (f64, &[f64], &[f64]),
    ) -> Result<(), Error> {
        let mut sink = NodeSink::values(&mut self.lq_f, &mut self.lv, pattern, &mut self.blocks);
        node.eval(t, q, v, &mut sink);
        if sink.outside() {
            return Err(Error::outside_pattern());
        }
        let finite = |x: &[f64]| x.iter().all(|c| c.is_finite());
        if !(finite(&self.blocks.c) && finite(&self.blocks.e)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        Ok(())
    }

    /// The tangent of `p = L_v(t, q, v)`: `dp = C dq + E dv` (DESIGN §12).
    pub(crate) fn momentum_tangent(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        at: (f64, &[f64], &[f64]),
        (dq, dv): (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error> {
        self.eval_blocks(node, pattern, at)?;
        dp.fill(0.0);
        for (k, (r, c)) in pattern.entries().enumerate() {
            dp[r] += self.blocks.c[k] * dq[c] + self.blocks.e[k] * dv[c];
        }
        Ok(())
    }

    /// The transposed tangent of `p = L_v(t, q, v)`: `cq = Cᵀ y`, `ev = Eᵀ y`.
    pub(crate) fn momentum_cotangent(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        at: (f64, &[f64], &[f64]),
        y: &[f64],
        (cq, ev): (&mut [f64], &mut [f64]),
    ) -> Result<(), Error> {
        self.eval_blocks(node, pattern, at)?;
        cq.fill(0.0);
        ev.fill(0.0);
        for (k, (r, c)) in pattern.entries().enumerate() {
            cq[c] += self.blocks.c[k] * y[r];
            ev[c] += self.blocks.e[k] * y[r];
        }
        Ok(())
    }

    /// The tangent of the velocity solve: `E dv = dp − C dq` (DESIGN §12).
    pub(crate) fn velocity_tangent(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        at: (f64, &[f64], &[f64]),
        (dq, dp): (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error> {
        self.eval_blocks(node, pattern, at)?;
        dv.copy_from_slice(dp);
        for (k, (r, c)) in pattern.entries().enumerate() {
            dv[r] -= self.blocks.c[k] * dq[c];
        }
        self.factor_mass(node, pattern, at, 0)?;
        self.lu.solve_in_place(dv);
        if dv.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            let size = dq.iter().chain(dp).fold(0.0f64, |m, x| m.max(x.abs()));
            Err(crate::stepper::non_finite(size, 0, at.0, "tangent"))
        }
    }

    /// Checks (and factors) the mass matrix at `(t, q, v)` for the initial data.
    pub(crate) fn check_mass(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        at: (f64, &[f64], &[f64]),
    ) -> Result<(), Error> {
        self.factor_mass(node, pattern, at, 0).map(|_| ())
    }

    /// Solves `L_v(q, v) = p` for `v`, starting from the `v` given. One Newton step for a
    /// constant mass matrix; otherwise damped Newton until each row meets
    /// `|L_v − p|_a ≤ 1e-13 (|p_a| + Σ_b |E_ab| |v_b|)` (or its round-off floor) within 60
    /// iterations, as the dense solve does.
    pub(crate) fn solve(
        &mut self,
        node: &dyn SparseNode,
        pattern: &NodePattern,
        (t, q, p): (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error> {
        let non_finite = Error::NonFiniteModel { step, t };
        let scratch = (&mut self.lq_f[..], &mut self.lv[..]);
        if !residual(node, (t, q, v, p), scratch, &mut self.r) {
            return Err(non_finite);
        }
        for _ in 0..60 {
            self.factor_mass(node, pattern, (t, q, v), step)?;
            let rnorm = max_norm(&self.r);
            for (s, p) in self.size.iter_mut().zip(p) {
                *s = p.abs();
            }
            for ((a, b), e) in pattern.entries().zip(&self.blocks.e) {
                self.size[a] += e.abs() * v[b].abs();
            }
            let wnorm = weighed(&self.r, &self.size, 1e-13);
            if !self.constant_mass && wnorm <= 1.0 {
                return Ok(());
            }
            self.dv.copy_from_slice(&self.r);
            self.lu.solve_in_place(&mut self.dv);
            if self.constant_mass {
                v.iter_mut().zip(&self.dv).for_each(|(x, d)| *x -= d);
                return if v.iter().all(|x| x.is_finite()) {
                    Ok(())
                } else {
                    Err(non_finite)
                };
            }
            let mut lambda = 1.0;
            loop {
                for ((x, v), d) in self.trial.iter_mut().zip(v.iter()).zip(&self.dv) {
                    *x = v - lambda * d;
                }
                let scratch = (&mut self.lq_f[..], &mut self.lv[..]);
                let ok = residual(node, (t, q, &self.trial, p), scratch, &mut self.r_trial);
                if ok && weighed(&self.r_trial, &self.size, 1e-13) < wnorm * (1.0 - 1e-4 * lambda) {
                    std::mem::swap(&mut self.r, &mut self.r_trial);
                    v.copy_from_slice(&self.trial);
                    break;
                }
                lambda *= 0.5;
                if lambda < 1e-10 {
                    return if weighed(&self.r, &self.size, 64.0 * f64::EPSILON) <= 1.0 {
                        Ok(())
                    } else {
                        Err(Error::VelocitySolveFailed {
                            step,
                            t,
                            residual: rnorm,
                        })
                    };
                }
            }
        }
        Err(Error::VelocitySolveFailed {
            step,
            t,
            residual: max_norm(&self.r),
        })
    }
}
