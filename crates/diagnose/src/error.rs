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
