//! Errors of building and evaluating a model: plain values, no allocation.

use core::fmt;

/// What went wrong building or evaluating a [`Model`](crate::Model).
///
/// `Copy` and allocation-free, so an evaluation call can return it from a control loop.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// A slice has the wrong length (`what` names it: `"joint readings"`, `"motor torques"`, …).
    Length {
        /// The slice.
        what: &'static str,
        /// Length the model needs.
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// A number is NaN or infinite: an input (`"joint readings"`, index = joint, 0-based) or
    /// a model value at construction (`"a_m"`, index = D-H row; `"coeffs"`, index = k; …).
    NotFinite {
        /// The quantity.
        what: &'static str,
        /// Its index (row, joint or coefficient; 0 for a scalar).
        index: usize,
        /// The value.
        value: f64,
    },
    /// More joints, D-H rows or polynomial coefficients than the fixed-size model holds.
    TooMany {
        /// `"joints"`, `"rows"` or `"coefficients"`.
        what: &'static str,
        /// How many were given.
        found: usize,
        /// The capacity ([`MAX_JOINTS`](crate::MAX_JOINTS), [`MAX_ROWS`](crate::MAX_ROWS),
        /// [`MAX_COEFFS`](crate::MAX_COEFFS)).
        max: usize,
    },
    /// An input outside the range the model holds on: a joint reading past its transmission
    /// polynomial's domain by more than [`DOMAIN_MARGIN`](crate::DOMAIN_MARGIN) of its width
    /// (the Chebyshev series is fitted there; beyond it the correction and its derivative grow
    /// without bound, and the motor torques can change sign).
    OutsideDomain {
        /// The quantity (`"joint readings"`).
        what: &'static str,
        /// Its index (joint, 0-based).
        index: usize,
        /// The value (rad).
        value: f64,
        /// The domain's lower end (rad).
        lo: f64,
        /// The domain's upper end (rad).
        hi: f64,
    },
    /// A model value outside its domain, e.g. a capstan with `|r_o| ≥ D` where paper eq. 1 is
    /// undefined, a non-positive ratio, a polynomial domain with `lo ≥ hi`, a chain without
    /// joints.
    Invalid {
        /// The quantity (`"ratio"`, `"r_o_m"`, `"ratio + re"`, `"domain"`, `"joints"`, …).
        what: &'static str,
        /// Its value (the lower end for a domain; the count for `"joints"`).
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Length {
                what,
                expected,
                found,
            } => write!(f, "{what}: expected {expected} values, found {found}"),
            Error::NotFinite { what, index, value } => {
                write!(f, "{what}[{index}] = {value} is not finite")
            }
            Error::OutsideDomain {
                what,
                index,
                value,
                lo,
                hi,
            } => write!(
                f,
                "{what}[{index}] = {value} rad lies outside the transmission polynomial's domain \
                 [{lo}, {hi}] rad (the range it was fitted on, with a margin of 5 % of its width \
                 each side)"
            ),
            Error::TooMany { what, found, max } => {
                write!(f, "{found} {what}, the runtime model holds at most {max}")
            }
            Error::Invalid {
                what,
                value,
                expected,
            } => write!(f, "{what} = {value} is invalid: expected {expected}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for Error {}

/// `Ok` when a slice `what` has the `expected` length, else [`Error::Length`].
pub(crate) fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), Error> {
    if expected == found {
        Ok(())
    } else {
        Err(Error::Length {
            what,
            expected,
            found,
        })
    }
}

/// `Ok` when every entry of `values` (named `what`) is finite, else [`Error::NotFinite`] for
/// the first that is not.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<(), Error> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(Error::NotFinite {
            what,
            index,
            value: values[index],
        }),
    }
}

/// [`check_finite`] of the entries of `parts` one after the other (a pose's rotation, then
/// its translation), indexed across them.
#[cfg(feature = "std")]
pub(crate) fn check_finite_parts(what: &'static str, parts: &[&[f64]]) -> Result<(), Error> {
    let values = parts.iter().flat_map(|part| part.iter());
    match values.enumerate().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some((index, &value)) => Err(Error::NotFinite { what, index, value }),
    }
}
