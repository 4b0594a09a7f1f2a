//! The optimizer state of one parameter group: its rule, moments and step count, updated
//! densely (every slot) or lazily (only the slots that got a gradient).

use num_traits::Float;

use super::rule::{Rule, Update};

/// Optimizer state of one parameter group of `len` slots: the [`Rule`], one second
/// moment per slot, one first moment per slot when the rule keeps them (none for
/// RMSProp), and the number of steps taken (Adam's bias correction counts from it).
///
/// Steps are either dense ([`step`](Self::step): every slot, over flat slices) or lazy
/// ([`lazy_step`](Self::lazy_step): the caller updates only the slots that got a
/// gradient; the others keep their values and moments). Both count as one step.
#[derive(Clone, Debug, PartialEq)]
pub struct Moments<T> {
    rule: Rule<T>,
    /// First moments; empty when the rule keeps none.
    m: Vec<T>,
    v: Vec<T>,
    t: i32,
}

impl<T: Float> Moments<T> {
    /// Fresh state (zero moments, no step taken) for `len` slots.
    pub fn new(rule: Rule<T>, len: usize) -> Self {
        Moments {
            rule,
            m: if rule.has_first_moment() {
                vec![T::zero(); len]
            } else {
                Vec::new()
            },
            v: vec![T::zero(); len],
            t: 0,
        }
    }

    /// The update rule.
    pub fn rule(&self) -> Rule<T> {
        self.rule
    }

    /// Slots.
    pub fn len(&self) -> usize {
        self.v.len()
    }

    /// Whether there are no slots.
    pub fn is_empty(&self) -> bool {
        self.v.is_empty()
    }

    /// Steps taken so far.
    pub fn steps(&self) -> i32 {
        self.t
    }

    /// One dense step over all slots: `params[i] −= delta` with rate `lr[i]·scale` (the
    /// schedule's factor multiplies every rate). A non-finite gradient entry counts as 0,
    /// so one bad value cannot poison the state; a slot whose rate is 0 does not move (its
    /// moments still do). Returns how many gradient entries were not finite.
    ///
    /// # Panics
    /// When `params`, `grads` or `lr` do not have [`len`](Self::len) entries.
    pub fn step(&mut self, params: &mut [T], grads: &[T], lr: &[T], scale: T) -> usize {
        assert_eq!(params.len(), self.v.len(), "parameter count changed");
        assert_eq!(grads.len(), params.len(), "gradient length mismatch");
        assert_eq!(lr.len(), params.len(), "learning-rate length mismatch");
        self.t += 1;
        let u = self.rule.at(self.t);
        let mut bad = 0;
        for i in 0..params.len() {
            let g = if grads[i].is_finite() {
                grads[i]
            } else {
                bad += 1;
                T::zero()
            };
            u.accumulate(self.m.get_mut(i), &mut self.v[i], g);
            let rate = lr[i] * scale;
            if rate != T::zero() {
                let m = self.m.get(i).copied().unwrap_or_else(T::zero);
                params[i] = params[i] - u.delta(m, self.v[i], g, rate);
            }
        }
        bad
    }

    /// Starts one lazy step: counts it and returns the step's constants over all slots,
    /// for the caller to [`LazyStep::apply`] to the slots that got a gradient (or to split
    /// into [`blocks`](LazyStep::blocks) for parallel updates).
    pub fn lazy_step(&mut self) -> LazyStep<'_, T> {
        self.t += 1;
        LazyStep {
            update: self.rule.at(self.t),
            m: &mut self.m,
            v: &mut self.v,
        }
    }

    /// Keeps the moments of the slots flagged in `keep`, in order, each slot being
    /// `stride` consecutive entries (`keep.len()·stride` must be [`len`](Self::len)); the
    /// step count carries on. For pruning: compact the parameters the same way. Cloning
    /// slots is [`extend`](Self::extend) with fresh moments.
    ///
    /// # Panics
    /// When `keep.len()·stride` is not [`len`](Self::len).
    pub fn retain(&mut self, keep: &[bool], stride: usize) {
        assert_eq!(
            keep.len() * stride,
            self.v.len(),
            "retain mask length mismatch"
        );
        compact(&mut self.m, keep, stride);
        compact(&mut self.v, keep, stride);
    }

    /// Sets every moment to zero (as after a reset of the parameters); the step count
    /// carries on.
    pub fn clear(&mut self) {
        self.m.fill(T::zero());
        self.v.fill(T::zero());
    }

    /// Sets the moments of entries `range` to zero (a parameter moved or replaced
    /// starts afresh); the step count carries on.
    ///
    /// # Panics
    /// If `range` reaches past [`len`](Self::len).
    pub fn clear_range(&mut self, range: std::ops::Range<usize>) {
        if !self.m.is_empty() {
            self.m[range.clone()].fill(T::zero());
        }
        self.v[range].fill(T::zero());
    }

    /// Appends `n` slots with zero moments (new or cloned parameters start afresh); the
    /// step count carries on.
    pub fn extend(&mut self, n: usize) {
        if self.rule.has_first_moment() {
            self.m.resize(self.m.len() + n, T::zero());
        }
        self.v.resize(self.v.len() + n, T::zero());
    }
}

/// Moves the `stride`-long runs of `v` flagged in `keep` to the front, in order, and
/// truncates. An empty `v` stays empty.
fn compact<T: Copy>(v: &mut Vec<T>, keep: &[bool], stride: usize) {
    if v.is_empty() {
        return;
    }
    let mut out = 0;
    for (s, &k) in keep.iter().enumerate() {
        if k {
            v.copy_within(s * stride..(s + 1) * stride, out * stride);
            out += 1;
        }
    }
    v.truncate(out * stride);
}

/// One lazy step of a [`Moments`] over a range of its slots (all of them, or one block):
/// the step's [`Update`] constants and that range's moments, indexed from 0.
#[derive(Debug)]
pub struct LazyStep<'a, T> {
    update: Update<T>,
    /// Empty when the rule keeps no first moments.
    m: &'a mut [T],
    v: &'a mut [T],
}

impl<'a, T: Float> LazyStep<'a, T> {
    /// Slots in this range.
    pub fn len(&self) -> usize {
        self.v.len()
    }

    /// Whether the range is empty.
    pub fn is_empty(&self) -> bool {
        self.v.is_empty()
    }

    /// The step's constants.
    pub fn update(&self) -> Update<T> {
        self.update
    }

    /// Updates slot `i` of this range, whose value is `x`, with gradient `g` at rate `lr`
    /// ([`Update::apply`]: no check of `g`; call it only for slots that got a gradient).
    ///
    /// # Panics
    /// When `i` is out of range.
    #[inline(always)]
    pub fn apply(&mut self, i: usize, x: &mut T, g: T, lr: T) {
        self.update
            .apply(x, self.m.get_mut(i), &mut self.v[i], g, lr);
    }

    /// Splits the range into consecutive blocks of `len` slots (the last may be shorter),
    /// each with the same constants, to update in parallel.
    ///
    /// # Panics
    /// When `len` is 0.
    pub fn blocks(self, len: usize) -> impl Iterator<Item = LazyStep<'a, T>> {
        let update = self.update;
        let mut m = self.m.chunks_mut(len);
        self.v.chunks_mut(len).map(move |v| LazyStep {
            update,
            m: m.next().unwrap_or_default(),
            v,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ADAM: Rule<f32> = Rule::Adam {
        beta1: 0.9,
        beta2: 0.99,
        eps: 1e-8,
    };
    const RMS: Rule<f32> = Rule::RmsProp {
        beta: 0.95,
        eps: 1e-8,
    };

    /// A lazy step applied to every slot, whole or in blocks, equals a dense step with
    /// finite gradients and nonzero rates, bit for bit.
    #[test]
    fn lazy_over_all_slots_equals_dense() {
        for rule in [ADAM, RMS] {
            let n = 10;
            let (mut dense, mut whole, mut blocked) = (
                Moments::new(rule, n),
                Moments::new(rule, n),
                Moments::new(rule, n),
            );
            let mut p = vec![0.5f32; n];
            let (mut q, mut r) = (p.clone(), p.clone());
            for t in 0..5 {
                let g: Vec<f32> = (0..n).map(|i| ((i * 7 + t) as f32).cos()).collect();
                dense.step(&mut p, &g, &vec![0.1; n], 1.0);
                let mut s = whole.lazy_step();
                for i in 0..n {
                    s.apply(i, &mut q[i], g[i], 0.1);
                }
                for (b, block) in blocked.lazy_step().blocks(3).enumerate() {
                    let mut block = block;
                    for i in 0..block.len() {
                        block.apply(i, &mut r[3 * b + i], g[3 * b + i], 0.1);
                    }
                }
            }
            assert_eq!(p, q);
            assert_eq!(p, r);
            assert_eq!(dense, whole);
            assert_eq!(dense, blocked);
            assert_eq!(dense.steps(), 5);
        }
    }

    #[test]
    fn untouched_slots_keep_values_and_moments() {
        let mut s = Moments::new(ADAM, 3);
        let mut p = [1.0f32; 3];
        let mut l = s.lazy_step();
        l.apply(1, &mut p[1], 2.0, 0.1);
        assert_eq!(p[0], 1.0);
        assert_eq!(p[2], 1.0);
        assert!((p[1] - 0.9).abs() < 1e-6);
        assert_eq!(s.v[0], 0.0);
        assert!(s.v[1] > 0.0);
        assert_eq!(s.m.len(), 3);
        assert!(Moments::new(RMS, 3).m.is_empty());
    }

    #[test]
    fn retain_compacts_strided_slots_and_extend_appends() {
        let mut s = Moments::new(ADAM, 8);
        s.lazy_step();
        for (i, (m, v)) in s.m.iter_mut().zip(&mut s.v).enumerate() {
            *m = i as f32;
            *v = 10.0 + i as f32;
        }
        // Four slots of two entries; keep the second and the fourth.
        s.retain(&[false, true, false, true], 2);
        assert_eq!(s.m, [2.0, 3.0, 6.0, 7.0]);
        assert_eq!(s.v, [12.0, 13.0, 16.0, 17.0]);
        assert_eq!(s.steps(), 1);
        s.extend(2);
        assert_eq!(s.m, [2.0, 3.0, 6.0, 7.0, 0.0, 0.0]);
        assert_eq!(s.len(), 6);
        let mut r = Moments::new(RMS, 3);
        r.retain(&[true, false, true], 1);
        r.extend(1);
        assert_eq!((r.m.len(), r.v.len()), (0, 3));
    }

    #[test]
    fn dense_step_ignores_non_finite_and_freezes_rate_0() {
        let mut s = Moments::new(RMS, 3);
        let mut p = [0.0f32; 3];
        let bad = s.step(&mut p, &[f32::NAN, 1.0, 1.0], &[1.0, 1.0, 0.0], 1.0);
        assert_eq!(bad, 1);
        assert_eq!(p[0], 0.0);
        assert!(p[1] < 0.0);
        assert_eq!(p[2], 0.0);
        assert!(s.v[2] > 0.0);
    }
}
