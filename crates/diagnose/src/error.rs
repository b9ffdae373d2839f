//! The crate's one error type.

/// What can stop a diagnosis (data-dependent outcomes, such as a `none` verdict, are
/// results, not errors).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A setting is out of range.
    #[error("invalid diagnosis setting: {message}")]
    Config {
        /// What is wrong.
        message: String,
    },
    /// The log does not fit the device or is too short.
    #[error("log: {message}")]
    Data {
        /// What is wrong.
        message: String,
    },
    /// The baseline model could not be built or fitted.
    #[error("baseline: {message}")]
    Baseline {
        /// What failed.
        message: String,
    },
    /// The blind-test generator failed to simulate a case.
    #[error("blind test: {message}")]
    Blind {
        /// What failed.
        message: String,
    },
}

/// The settings the rounds of either diagnosis share, checked: `folds` ≥ 2, 0 < `alpha` < 1,
/// `max_effects` ≥ 1.
///
/// # Errors
/// [`Error::Config`] naming the values given.
pub(crate) fn check_rounds(folds: usize, alpha: f64, max_effects: usize) -> Result<(), Error> {
    if folds < 2 || !(alpha > 0.0 && alpha < 1.0) || max_effects == 0 {
        return Err(Error::Config {
            message: format!(
                "need folds ≥ 2 (got {folds}), 0 < alpha < 1 (got {alpha}), max_effects ≥ 1"
            ),
        });
    }
    Ok(())
}
