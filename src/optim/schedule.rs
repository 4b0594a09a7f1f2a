//! Learning-rate schedules: how rates change over a run.
//!
//! * [`Schedule`]: a factor in `[0, 1]` applied to every rate (the 2D fitter's
//!   `--schedule`).
//! * [`exponential`]: a rate going from a start to an end value geometrically (the voxel
//!   trainer's, one `[start, end]` pair per parameter group).
//!
//! Both take the run's progress, [`progress`]: 0 at the first step, 1 at the last.

use num_traits::Float;

/// How learning rates change over a run of `total` steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Schedule {
    /// The same rate throughout.
    #[default]
    Constant,
    /// Half a cosine from 1 down to 0.05 at the last step.
    Cosine,
    /// Straight line from 1 down to 0.05 at the last step.
    Linear,
}

/// Where the decaying schedules end, as a fraction of the initial rate.
const FLOOR: f64 = 0.05;

impl Schedule {
    /// The factor for step `step` (0-based) of `total`.
    pub fn factor(self, step: usize, total: usize) -> f64 {
        let t: f64 = progress(step, total);
        match self {
            Schedule::Constant => 1.0,
            Schedule::Cosine => {
                FLOOR + (1.0 - FLOOR) * 0.5 * (1.0 + (std::f64::consts::PI * t).cos())
            }
            Schedule::Linear => 1.0 - (1.0 - FLOOR) * t,
        }
    }
}

/// The fraction of a run of `total` steps done at step `step` (0-based):
/// `step / (total − 1)`, clamped to 1 past the last step, and 0 for runs of at most one
/// step.
pub fn progress<T: Float>(step: usize, total: usize) -> T {
    if total <= 1 {
        T::zero()
    } else {
        let at = T::from(step.min(total - 1)).expect("a count converts to a float");
        at / T::from(total - 1).expect("a count converts to a float")
    }
}

/// The rate at progress `frac` (in `[0, 1]`) of a run going from `start` to `end`
/// geometrically: `start·(end / start)^frac`, so it falls by the same factor every step.
/// When either end is not positive (a rate of 0 at the end, say) it goes in a straight line
/// instead, `start + (end − start)·frac`. Rates are in whatever units the caller uses.
pub fn exponential<T: Float>([start, end]: [T; 2], frac: T) -> T {
    if start > T::zero() && end > T::zero() {
        start * (end / start).powf(frac)
    } else {
        start + (end - start) * frac
    }
}

impl crate::choice::Choice for Schedule {
    const WHAT: &'static str = "schedule";
    const ALL: &'static [Self] = &[Self::Constant, Self::Cosine, Self::Linear];
    fn name(self) -> &'static str {
        match self {
            Self::Constant => "constant",
            Self::Cosine => "cosine",
            Self::Linear => "linear",
        }
    }
    fn aliases(self) -> &'static [&'static str] {
        match self {
            Self::Constant => &["const"],
            Self::Cosine => &["cos"],
            Self::Linear => &[],
        }
    }
}

crate::choice::from_str_by_name!(Schedule);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_and_monotonicity() {
        for s in [Schedule::Cosine, Schedule::Linear] {
            assert_eq!(s.factor(0, 100), 1.0);
            assert!((s.factor(99, 100) - FLOOR).abs() < 1e-12);
            let f: Vec<f64> = (0..100).map(|i| s.factor(i, 100)).collect();
            assert!(f.windows(2).all(|w| w[1] <= w[0]));
        }
        assert_eq!(Schedule::Constant.factor(50, 100), 1.0);
        assert_eq!(Schedule::Cosine.factor(0, 1), 1.0);
    }

    #[test]
    fn learning_rates_decay_exponentially() {
        assert_eq!(exponential([1.0f32, 0.01], 0.0), 1.0);
        assert!((exponential([1.0f32, 0.01], 0.5) - 0.1).abs() < 1e-6);
        assert!((exponential([1.0f32, 0.01], 1.0) - 0.01).abs() < 1e-7);
        assert_eq!(exponential([0.0f32, 1.0], 0.25), 0.25);
        assert!((exponential([2.0f64, 0.02], 0.5) - 0.2).abs() < 1e-12);
    }

    #[test]
    fn progress_runs_from_0_to_1() {
        assert_eq!(progress::<f32>(0, 1), 0.0);
        assert_eq!(progress::<f32>(3, 0), 0.0);
        assert_eq!(progress::<f64>(0, 5), 0.0);
        assert_eq!(progress::<f64>(2, 5), 0.5);
        assert_eq!(progress::<f32>(4, 5), 1.0);
        assert_eq!(progress::<f32>(9, 5), 1.0);
    }

    #[test]
    fn schedule_names_round_trip() {
        crate::choice::tests::round_trip::<Schedule>();
    }
}
