//! Enums named by a fixed lower-case word on the command line, in parameter
//! files and in model files ([`Named`]), with their `Display` and `FromStr`
//! written once ([`impl_named!`](crate::impl_named)).

/// An enum whose values have fixed lower-case names.
pub trait Named: Copy + PartialEq + 'static {
    /// Every value, in the order names are listed in messages.
    const ALL: &'static [Self];
    /// What a value is called in messages ("model", "system kind", ...).
    const WHAT: &'static str;

    /// The lower-case name.
    fn name(self) -> &'static str;

    /// The value named `s` (surrounding space and case ignored).
    fn from_name(s: &str) -> Result<Self, UnknownName> {
        let t = s.trim().to_ascii_lowercase();
        Self::ALL
            .iter()
            .copied()
            .find(|v| v.name() == t)
            .ok_or_else(|| UnknownName {
                what: Self::WHAT,
                given: s.to_string(),
                expected: Self::ALL.iter().map(|v| v.name()).collect(),
            })
    }
}

/// A name that is none of an enum's: says what was given and lists the
/// valid names.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} {given:?}; expected one of {}", expected.join(", "))]
pub struct UnknownName {
    /// What was being named ("model", "system kind", ...).
    pub what: &'static str,
    /// The name given.
    pub given: String,
    /// The valid names.
    pub expected: Vec<&'static str>,
}

/// `Display` (the name) and `FromStr` ([`Named::from_name`]) of a [`Named`]
/// enum.
#[macro_export]
macro_rules! impl_named {
    ($t:ty) => {
        impl ::std::fmt::Display for $t {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str($crate::names::Named::name(*self))
            }
        }

        impl ::std::str::FromStr for $t {
            type Err = $crate::names::UnknownName;

            fn from_str(s: &str) -> ::std::result::Result<Self, Self::Err> {
                <$t as $crate::names::Named>::from_name(s)
            }
        }
    };
}
