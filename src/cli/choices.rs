//! The command line's fixed choices as clap value enums (so `--help` lists them and a bad
//! value is refused before anything runs), each mapped onto the library's own type. The
//! library stays free of clap; these are the only places the spellings live.

use clap::ValueEnum;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

use diffsvg::choice::{Choice, parse_among};

/// A flag's parser over the library's names of `values` (a [`Choice`]): `--help` lists
/// them, aliases are accepted, case is ignored where the flag says `ignore_case`. The
/// spellings live in the library, beside each type.
pub fn among<T: Choice + Clone + Send + Sync>(
    values: &'static [T],
) -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(
        values
            .iter()
            .map(|v| PossibleValue::new(v.name()).aliases(v.aliases().iter().copied())),
    )
    .map(move |s| parse_among(&s, values).expect("clap matched one of these names"))
}

/// [`among`] every value of `T`.
pub fn choice<T: Choice + Clone + Send + Sync>() -> impl TypedValueParser<Value = T> {
    among(T::ALL)
}

/// `vectorize --init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// vtracer's photo preset, pruned to the path budget, then refined.
    Trace,
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
        use clap::Parser;
        use diffsvg::loss::Loss;
        use diffsvg::scene::ParamGroup;
        #[derive(Parser, Debug)]
        struct T {
            #[arg(long, ignore_case = true, value_parser = choice::<Loss>())]
            loss: Loss,
            #[arg(long, ignore_case = true, value_parser = choice::<ParamGroup>(), value_delimiter = ',')]
            freeze: Vec<ParamGroup>,
        }
        let t = T::try_parse_from(["t", "--loss", "L2", "--freeze", "point,Colors"]).unwrap();
        assert_eq!(t.loss, Loss::Mse);
        assert_eq!(t.freeze, [ParamGroup::Points, ParamGroup::Color]);
        let e = T::try_parse_from(["t", "--loss", "huber"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("possible values: mse, l1"), "{e}");
        assert_eq!(parse_background("AUTO"), Ok(Background::Auto));
        assert_eq!(parse_background("none"), Ok(Background::Color([0.0; 4])));
        assert!(parse_background("bluish").is_err());
    }
}
