//! Update rules: Adam and RMSProp over one scalar slot, generic over `f32` and `f64`.

use num_traits::Float;

/// How one slot moves given its gradient: the rule and its constants.
///
/// Both rules keep a second moment `v` (running mean of `g²`); Adam also keeps a first
/// moment `m` (running mean of `g`). Both divide by the running RMS of the gradient, so a
/// step of rate `lr` moves a slot by an amount of the order of `lr` in the slot's own
/// units, whatever the gradient's scale (Adam's first step is exactly `lr·sign(g)`,
/// RMSProp's `lr/√(1 − β)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rule<T> {
    /// Adam with bias correction: `m ← β₁·m + (1 − β₁)·g`, `v ← β₂·v + (1 − β₂)·g²`,
    /// `x ← x − lr·(m / (1 − β₁ᵗ)) / (√(v / (1 − β₂ᵗ)) + ε)` at step `t` (1-based).
    Adam {
        /// Decay of the first moment, in `[0, 1)`.
        beta1: T,
        /// Decay of the second moment, in `[0, 1)`.
        beta2: T,
        /// Added to `√v̂` to keep steps finite, `> 0`.
        eps: T,
    },
    /// RMSProp without momentum (Plenoxels' choice): `v ← β·v + (1 − β)·g²`,
    /// `x ← x − lr·g / (√v + ε)`. Keeps no first moment.
    RmsProp {
        /// Decay of the squared-gradient average, in `[0, 1)`.
        beta: T,
        /// Added to `√v`, `> 0`.
        eps: T,
    },
}

impl<T: Float> Rule<T> {
    /// Whether the rule keeps a first moment (Adam does, RMSProp does not).
    pub fn has_first_moment(&self) -> bool {
        matches!(self, Rule::Adam { .. })
    }

    /// Whether the constants are usable: betas in `[0, 1)` and `eps > 0`.
    pub fn is_valid(&self) -> bool {
        let beta = |b: T| b >= T::zero() && b < T::one();
        match *self {
            Rule::Adam { beta1, beta2, eps } => beta(beta1) && beta(beta2) && eps > T::zero(),
            Rule::RmsProp { beta: b, eps } => beta(b) && eps > T::zero(),
        }
    }

    /// The constants of step `t` (1 for the first step; Adam's bias corrections depend on
    /// it, RMSProp ignores it). Compute once per step, then [`Update::apply`] per slot.
    pub fn at(&self, t: i32) -> Update<T> {
        let one = T::one();
        match *self {
            Rule::Adam { beta1, beta2, eps } => Update {
                adam: true,
                b1: beta1,
                b2: beta2,
                eps,
                c1: one - beta1.powi(t),
                c2: one - beta2.powi(t),
            },
            Rule::RmsProp { beta, eps } => Update {
                adam: false,
                b1: T::zero(),
                b2: beta,
                eps,
                c1: one,
                c2: one,
            },
        }
    }
}

/// One step's constants of a [`Rule`] (from [`Rule::at`]): small and `Copy`, meant to be
/// computed once per step and applied to every slot that moves, from any thread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Update<T> {
    adam: bool,
    b1: T,
    b2: T,
    eps: T,
    /// Adam's bias corrections `1 − β₁ᵗ`, `1 − β₂ᵗ` (1 for RMSProp).
    c1: T,
    c2: T,
}

impl<T: Float> Update<T> {
    /// Folds gradient `g` into the moments `m` (ignored, and may be `None`, for
    /// RMSProp) and `v`.
    ///
    /// # Panics
    /// When the rule is Adam and `m` is `None`.
    #[inline(always)]
    pub fn accumulate(&self, m: Option<&mut T>, v: &mut T, g: T) {
        *v = self.b2 * *v + (T::one() - self.b2) * g * g;
        if self.adam {
            let m = m.expect("Adam keeps first moments");
            *m = self.b1 * *m + (T::one() - self.b1) * g;
        }
    }

    /// How far a slot with (already updated) moments `m`, `v` and gradient `g` moves down
    /// at rate `lr`: `lr·m̂ / (√v̂ + ε)` for Adam (`m` unused by RMSProp, which uses `g`).
    #[inline(always)]
    pub fn delta(&self, m: T, v: T, g: T, lr: T) -> T {
        if self.adam {
            lr * (m / self.c1) / ((v / self.c2).sqrt() + self.eps)
        } else {
            lr * g / (v.sqrt() + self.eps)
        }
    }

    /// One slot's whole update: [`accumulate`](Self::accumulate), then
    /// `x ← x − `[`delta`](Self::delta). No check of `g` or `lr`: a non-finite gradient
    /// poisons the slot, and a rate of 0 still updates the moments (and `x` by `−0·…`).
    ///
    /// # Panics
    /// When the rule is Adam and `m` is `None`.
    #[inline(always)]
    pub fn apply(&self, x: &mut T, m: Option<&mut T>, v: &mut T, g: T, lr: T) {
        *v = self.b2 * *v + (T::one() - self.b2) * g * g;
        if self.adam {
            let m = m.expect("Adam keeps first moments");
            *m = self.b1 * *m + (T::one() - self.b1) * g;
            *x = *x - lr * (*m / self.c1) / ((*v / self.c2).sqrt() + self.eps);
        } else {
            *x = *x - lr * g / (v.sqrt() + self.eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ADAM: Rule<f64> = Rule::Adam {
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-8,
    };

    #[test]
    fn apply_is_accumulate_then_delta() {
        for rule in [
            ADAM,
            Rule::RmsProp {
                beta: 0.95,
                eps: 1e-8,
            },
        ] {
            let (mut x, mut m, mut v) = (1.0, 0.0, 0.0);
            let (mut y, mut n, mut w) = (1.0, 0.0, 0.0);
            for t in 1..20 {
                let u = rule.at(t);
                let g = (t as f64 * 0.7).sin();
                u.apply(&mut x, Some(&mut m), &mut v, g, 0.1);
                u.accumulate(Some(&mut n), &mut w, g);
                y -= u.delta(n, w, g, 0.1);
                assert_eq!((x.to_bits(), m.to_bits()), (y.to_bits(), n.to_bits()));
                assert_eq!(v.to_bits(), w.to_bits());
            }
        }
    }

    #[test]
    fn rmsprop_needs_no_first_moment_and_f32_works() {
        let rule = Rule::RmsProp {
            beta: 0.5f32,
            eps: 0.0,
        };
        assert!(!rule.has_first_moment());
        let (mut x, mut v) = (0.0f32, 0.0f32);
        rule.at(1).apply(&mut x, None, &mut v, 2.0, 1.0);
        // v = 0.5·4 = 2, step = 2 / √2.
        assert_eq!(v, 2.0);
        assert!((x + std::f32::consts::SQRT_2).abs() < 1e-6);
    }

    #[test]
    fn validity() {
        assert!(ADAM.is_valid());
        let bad = Rule::Adam {
            beta1: 1.0,
            beta2: 0.5,
            eps: 1e-8,
        };
        assert!(!bad.is_valid());
        assert!(
            !Rule::RmsProp {
                beta: 0.5,
                eps: 0.0
            }
            .is_valid()
        );
        assert!(
            !Rule::RmsProp {
                beta: f32::NAN,
                eps: 1.0
            }
            .is_valid()
        );
    }
}
