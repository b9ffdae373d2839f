//! The crate's error type: transmission inputs that the models cannot accept.

/// Input that a transmission model or identification problem cannot accept.
///
/// Messages are lower case, without a trailing period; angles in rad, lengths in m.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A quantity that must be strictly positive (ratio, length, noise level) is not.
    #[error("{name} must be positive, found {value}")]
    NonPositive {
        /// Which quantity, e.g. `ratio`, `l2_m`, `sigma_rad`.
        name: &'static str,
        /// The offending value (in its unit).
        value: f64,
    },
    /// The four-bar loop cannot close at this crank angle (or is at a dead centre, where the
    /// output is not differentiable): the diagonal is longer than coupler + rocker, shorter than
    /// their difference, or zero.
    #[error("the four-bar loop cannot close at crank angle {phi} rad")]
    NoClosure {
        /// Crank angle φ, rad.
        phi: f64,
    },
    /// A drum eccentricity `|r| ≥ D`: eq. 1 is undefined (the drum would cross the other drum's
    /// centre).
    #[error("{name} = {value} m is not below the drum distance {drum_distance_m} m")]
    EccentricityTooLarge {
        /// `r_o_m` or `r_i_m`.
        name: &'static str,
        /// The eccentricity, m.
        value: f64,
        /// Drum centre distance D, m.
        drum_distance_m: f64,
    },
    /// Two sequences that must pair up (readings and measurements) differ in length.
    #[error("{name} has {found} entries, expected {expected}")]
    LengthMismatch {
        /// The sequence with the unexpected length, e.g. `ext`.
        name: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A sequence that must not be empty (readings, Chebyshev coefficients) is.
    #[error("{name} is empty")]
    Empty {
        /// The empty sequence, e.g. `theta` or `coeffs`.
        name: &'static str,
    },
    /// A value is NaN or infinite.
    #[error("{name} = {value} is not finite")]
    NotFinite {
        /// Which value, with its index for sequences, e.g. `ext[17]`.
        name: String,
        /// The offending value.
        value: f64,
    },
    /// A polynomial domain `[lo, hi]` that is not finite with `lo < hi`.
    #[error("the domain [{lo}, {hi}] rad is not a finite interval with lo < hi")]
    Domain {
        /// Lower end, rad.
        lo: f64,
        /// Upper end, rad.
        hi: f64,
    },
}

/// `Ok(value)` if finite and `> 0`, else [`Error::NotFinite`] or [`Error::NonPositive`]
/// naming `name`: the check of every positive model value (a ratio, a drum distance, a link
/// length in m, a noise σ), here and in the identification problems of `hapcal-problems`.
///
/// # Errors
/// [`Error::NotFinite`] for a NaN or infinite value, [`Error::NonPositive`] for `value ≤ 0`.
pub fn positive(name: &'static str, value: f64) -> Result<f64, Error> {
    if !value.is_finite() {
        return Err(Error::NotFinite {
            name: name.to_owned(),
            value,
        });
    }
    if value <= 0.0 {
        return Err(Error::NonPositive { name, value });
    }
    Ok(value)
}

/// `Ok(())` if every entry of `values` is finite, else [`Error::NotFinite`] naming `name[i]`
/// (any length, any unit).
///
/// # Errors
/// [`Error::NotFinite`] for the first NaN or infinite entry.
pub fn all_finite(name: &'static str, values: &[f64]) -> Result<(), Error> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(Error::NotFinite {
            name: format!("{name}[{i}]"),
            value: values[i],
        }),
        None => Ok(()),
    }
}
