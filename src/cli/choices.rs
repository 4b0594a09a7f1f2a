//! The command line's fixed choices as clap value enums (so `--help` lists them and a bad
//! value is refused before anything runs), each mapped onto the library's own type. The
//! library stays free of clap; these are the only places the spellings live.

use clap::ValueEnum;

use diffsvg::fit::vectorize::Mode;
use diffsvg::loss::Loss;
use diffsvg::optim::Schedule;
use diffsvg::scene::ParamGroup;

/// `--loss`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum LossArg {
    /// Mean squared error.
    #[default]
    #[value(alias = "l2")]
    Mse,
    /// Mean absolute error.
    #[value(alias = "mae")]
    L1,
}

impl From<LossArg> for Loss {
    fn from(l: LossArg) -> Loss {
        match l {
            LossArg::Mse => Loss::Mse,
            LossArg::L1 => Loss::L1,
        }
    }
}

/// `--schedule`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum ScheduleArg {
    /// The same rate throughout.
    #[default]
    #[value(alias = "const")]
    Constant,
    /// Half a cosine down to 5% of the rate at the last step.
    #[value(alias = "cos")]
    Cosine,
    /// A straight line down to 5% of the rate at the last step.
    Linear,
}

impl From<ScheduleArg> for Schedule {
    fn from(s: ScheduleArg) -> Schedule {
        match s {
            ScheduleArg::Constant => Schedule::Constant,
            ScheduleArg::Cosine => Schedule::Cosine,
            ScheduleArg::Linear => Schedule::Linear,
        }
    }
}

/// `vectorize --mode`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Add paths where the error is largest, prune the useless ones.
    #[default]
    Adaptive,
    /// DiffVG's random closed blobs, all at once.
    #[value(alias = "blobs")]
    Fixed,
    /// DiffVG's random open strokes with widths.
    #[value(alias = "strokes")]
    Painterly,
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Mode {
        match m {
            ModeArg::Adaptive => Mode::Adaptive,
            ModeArg::Fixed => Mode::Fixed,
            ModeArg::Painterly => Mode::Painterly,
        }
    }
}

/// `vectorize --init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// vtracer's photo preset, pruned to the path budget, then refined.
    Trace,
}

/// `--freeze`: a parameter group held fixed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum GroupArg {
    /// Control points.
    #[value(alias = "point")]
    Points,
    /// Solid and stop colors.
    #[value(alias = "color")]
    Colors,
    /// Fill, stroke, stop and group opacities.
    #[value(alias = "opacity")]
    Opacities,
    /// Stroke widths.
    #[value(alias = "width")]
    Widths,
    /// Gradient geometry (end points, centers, radii).
    Paint,
    /// Gradient stop offsets.
    #[value(alias = "stop")]
    Stops,
}

impl From<GroupArg> for ParamGroup {
    fn from(g: GroupArg) -> ParamGroup {
        match g {
            GroupArg::Points => ParamGroup::Points,
            GroupArg::Colors => ParamGroup::Color,
            GroupArg::Opacities => ParamGroup::Opacity,
            GroupArg::Widths => ParamGroup::StrokeWidth,
            GroupArg::Paint => ParamGroup::PaintGeometry,
            GroupArg::Stops => ParamGroup::StopOffset,
        }
    }
}

/// `view --split`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum SplitArg {
    /// The held-out views.
    #[default]
    Test,
    /// The training views.
    Train,
}

impl SplitArg {
    /// The name as typed.
    pub fn name(self) -> &'static str {
        match self {
            SplitArg::Test => "test",
            SplitArg::Train => "train",
        }
    }
}

/// `fit --background`/`vectorize --background`: `auto` or a color.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Background {
    /// White for an opaque target, transparent otherwise.
    Auto,
    /// This straight RGBA color (`none`: transparent).
    Color([f32; 4]),
}

/// Parses `--background` for `fit` and `vectorize`.
pub fn parse_background(s: &str) -> Result<Background, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(Background::Auto);
    }
    super::util::parse_color(s)
        .map(Background::Color)
        .map_err(|e| format!("{e}, or auto"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aliases_and_case() {
        assert_eq!(LossArg::from_str("L2", true), Ok(LossArg::Mse));
        assert_eq!(LossArg::from_str("mae", true), Ok(LossArg::L1));
        assert_eq!(ScheduleArg::from_str("cos", true), Ok(ScheduleArg::Cosine));
        assert!(ScheduleArg::from_str("step", true).is_err());
        assert_eq!(parse_background("AUTO"), Ok(Background::Auto));
        assert_eq!(parse_background("none"), Ok(Background::Color([0.0; 4])));
        assert!(parse_background("bluish").is_err());
        // Every group has a spelling, and the spelling is the group's own name.
        for g in GroupArg::value_variants() {
            let name = g.to_possible_value().unwrap().get_name().to_string();
            assert_eq!(ParamGroup::from(*g).name(), name);
        }
    }
}
