//! Fixed choices spelled by name — losses, schedules, vectorization modes, parameter
//! groups — written once here and read by every front end: command-line flags, batch
//! files and Python keywords all accept the same names and aliases, case-insensitively.
//!
//! ```
//! use diffsvg::choice::Choice;
//! use diffsvg::loss::Loss;
//! assert_eq!("L2".parse::<Loss>(), Ok(Loss::Mse));
//! assert_eq!(Loss::L1.name(), "l1");
//! assert_eq!(
//!     "huber".parse::<Loss>().unwrap_err(),
//!     "loss \"huber\": expected one of mse, l1"
//! );
//! ```

/// A fixed set of values, each with a name and other accepted spellings.
pub trait Choice: Sized + Copy + PartialEq + 'static {
    /// What the choice is, in messages (`"loss"`).
    const WHAT: &'static str;
    /// Every value, in the order they are listed.
    const ALL: &'static [Self];
    /// The value's name, as written and as listed.
    fn name(self) -> &'static str;
    /// Other spellings accepted on input.
    fn aliases(self) -> &'static [&'static str] {
        &[]
    }
}

/// The value named `s` (its name or an alias, any case) among `among`; otherwise a message
/// naming what was expected.
pub fn parse_among<T: Choice>(s: &str, among: &[T]) -> Result<T, String> {
    among
        .iter()
        .copied()
        .find(|v| {
            v.name().eq_ignore_ascii_case(s)
                || v.aliases().iter().any(|a| a.eq_ignore_ascii_case(s))
        })
        .ok_or_else(|| {
            let names: Vec<&str> = among.iter().map(|v| v.name()).collect();
            format!("{} {s:?}: expected one of {}", T::WHAT, names.join(", "))
        })
}

/// Implements [`std::str::FromStr`] by [`parse`] (name or alias, any case) for choices.
macro_rules! from_str_by_name {
    ($($t:ty),*) => {$(
        impl std::str::FromStr for $t {
            type Err = String;
            /// By name or alias, any case ([`crate::choice::parse`]).
            fn from_str(s: &str) -> Result<Self, String> {
                $crate::choice::parse(s)
            }
        }
    )*};
}
pub(crate) use from_str_by_name;

/// [`parse_among`] over every value.
pub fn parse<T: Choice>(s: &str) -> Result<T, String> {
    parse_among(s, T::ALL)
}

/// Checks of a [`Choice`] implementation, for the tests beside each one.
#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Every name and alias parses back to its value, in any case; names are unique.
    pub(crate) fn round_trip<T: Choice + std::fmt::Debug>() {
        let mut seen = std::collections::HashSet::new();
        for &v in T::ALL {
            for s in std::iter::once(v.name()).chain(v.aliases().iter().copied()) {
                assert!(seen.insert(s), "{s} spelled twice");
                assert_eq!(parse::<T>(s), Ok(v));
                assert_eq!(parse::<T>(&s.to_uppercase()), Ok(v));
            }
        }
        assert!(
            parse::<T>("no-such-thing")
                .unwrap_err()
                .contains(T::ALL[0].name())
        );
    }
}
