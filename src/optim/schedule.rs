//! Learning-rate schedules: a factor in `[0, 1]` applied to every rate.

use std::str::FromStr;

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
        let t = if total <= 1 {
            0.0
        } else {
            (step.min(total - 1)) as f64 / (total - 1) as f64
        };
        match self {
            Schedule::Constant => 1.0,
            Schedule::Cosine => {
                FLOOR + (1.0 - FLOOR) * 0.5 * (1.0 + (std::f64::consts::PI * t).cos())
            }
            Schedule::Linear => 1.0 - (1.0 - FLOOR) * t,
        }
    }
}

impl FromStr for Schedule {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "constant" | "const" => Ok(Schedule::Constant),
            "cosine" | "cos" => Ok(Schedule::Cosine),
            "linear" => Ok(Schedule::Linear),
            _ => Err(format!(
                "unknown schedule {s:?} (expected constant, cosine or linear)"
            )),
        }
    }
}

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
        assert_eq!("cos".parse::<Schedule>(), Ok(Schedule::Cosine));
        assert!("step".parse::<Schedule>().is_err());
    }
}
