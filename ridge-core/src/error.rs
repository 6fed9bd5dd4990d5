//! The one error type of the crate.

use core::fmt;

/// Why an identification step could not produce a trustworthy result.
///
/// Every fallible function of the crate returns this; nothing in the crate panics on
/// bad data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// A sample, scale factor or hyper-parameter was NaN or ±∞.
    NonFinite,
    /// An accumulator would overflow (integer statistics), or a value left the range
    /// of the floating-point type. The statistics are left as they were before the call.
    Overflow,
    /// The record has fewer samples than the structure needs.
    TooShort {
        /// Samples needed (seed samples plus one per parameter, plus one).
        needed: u32,
        /// Samples available.
        have: u32,
    },
    /// A structure or search range outside the compile-time maxima
    /// ([`crate::P_MAX`], [`crate::Q_MAX`], [`crate::D_MAX`]), or with `p = 0` / `q = 0`.
    InvalidStructure,
    /// A hyper-parameter outside its documented range (e.g. `gamma < 0`, `beta ∉ [0, 1)`,
    /// `lambda ∉ (0, 1]`).
    InvalidParameter,
    /// The input or output has no variation (e.g. constant input, zero output): the
    /// record does not excite the plant.
    NotExcited,
    /// A normal-equation matrix is not (numerically) positive definite: its columns are
    /// linearly dependent on this record (insufficient excitation for this structure).
    NotPositiveDefinite,
    /// No candidate of the search grid could be fitted.
    NoCandidate,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::NonFinite => f.write_str("a value is NaN or infinite"),
            Error::Overflow => f.write_str("statistics overflow"),
            Error::TooShort { needed, have } => {
                write!(f, "record too short: {have} samples, {needed} needed")
            }
            Error::InvalidStructure => f.write_str("structure outside the supported range"),
            Error::InvalidParameter => f.write_str("hyper-parameter out of range"),
            Error::NotExcited => f.write_str("input or output is not excited (no variation)"),
            Error::NotPositiveDefinite => {
                f.write_str("normal equations not positive definite (insufficient excitation)")
            }
            Error::NoCandidate => f.write_str("no candidate structure could be fitted"),
        }
    }
}

/// A name that no variant of an enum carries: the error of `FromStr` for [`crate::Criterion`],
/// [`crate::Offset`] and [`crate::MethodKind`]. Each of those enums has one name table, its
/// `name()`; `FromStr` reads exactly those names and this error lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownName {
    /// What was being named (`"criterion"`, `"offset"`, `"method"`).
    pub what: &'static str,
    /// The accepted names, in the enum's order.
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown {} (expected ", self.what)?;
        let n = self.expected.len();
        for (i, name) in self.expected.iter().enumerate() {
            let sep = match (i, n - i) {
                (0, _) => "",
                (_, 1) => " or ",
                _ => ", ",
            };
            write!(f, "{sep}{name}")?;
        }
        f.write_str(")")
    }
}

impl core::error::Error for UnknownName {}

/// Parses `s` as the variant of `all` whose `name` it is (exactly, case-sensitive).
pub(crate) fn parse_name<T: Copy>(
    s: &str,
    all: &[T],
    name: fn(T) -> &'static str,
    what: &'static str,
    expected: &'static [&'static str],
) -> core::result::Result<T, UnknownName> {
    all.iter()
        .copied()
        .find(|v| name(*v) == s)
        .ok_or(UnknownName { what, expected })
}

impl fmt::Display for crate::Criterion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Display for crate::Offset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Display for crate::MethodKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Result alias of the crate.
pub type Result<T> = core::result::Result<T, Error>;
