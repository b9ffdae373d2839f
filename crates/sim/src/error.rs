//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong reading a truth file or simulating a log.
///
/// Errors about a truth file name the file, the 1-based line and the 1-based character
/// column within the line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The truth file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A TOML syntax or type error in a truth file (missing or unknown key, wrong type).
    #[error("{path}:{line}:{column}: {message}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// What the TOML parser expected.
        message: String,
    },
    /// A truth file is well-formed TOML but holds an impossible value (a NaN, a malformed
    /// parameter name, a capstan joint numbered 0 or given twice, …).
    #[error("{path}:{line}:{column}: {message}")]
    InvalidTruth {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// What is wrong.
        message: String,
    },
    /// The nominal device could not be read, or its chain could not be built.
    #[error("device: {source}")]
    Device {
        /// What `hapcal-io` said.
        source: hapcal_io::Error,
    },
    /// A `[deviations]` name is not a parameter of the device's chain (e.g. `da9` on an
    /// 8-row D-H table).
    #[error("deviation {name:?} is not a parameter of the chain; the chain has {available}")]
    UnknownParameter {
        /// The name in the truth.
        name: String,
        /// The chain's parameter names, comma separated.
        available: String,
    },
    /// The device has a capstan drive on a joint for which the truth gives no `[[capstan]]`.
    #[error("the device has a capstan on joint {joint} but the truth has no [[capstan]] for it")]
    MissingCapstan {
        /// The joint, 1-based.
        joint: usize,
    },
    /// The truth gives a `[[capstan]]` for a joint on which the device has no capstan drive.
    #[error("the truth has a [[capstan]] for joint {joint} but the device has no capstan there")]
    UnexpectedCapstan {
        /// The joint, 1-based.
        joint: usize,
    },
    /// The device has a parallelogram but no capstan on its joint, or the truth has no
    /// `[parallelogram]` for it.
    #[error("parallelogram on joint {joint}: {message}")]
    Parallelogram {
        /// The joint the parallelogram drives, 1-based.
        joint: usize,
        /// What is missing.
        message: String,
    },
    /// The transmission model rejected the truth values of a joint (eccentricity at least
    /// the drum distance, four-bar lengths that cannot close at this crank angle, …).
    #[error("transmission of joint {joint}: {source}")]
    Transmission {
        /// The joint, 1-based.
        joint: usize,
        /// What `hapcal-transmission` said.
        source: hapcal_transmission::Error,
    },
    /// A vector of joint readings has another length than the device has joints.
    #[error("expected {expected} joint readings (as the device has joints), found {found}")]
    JointCount {
        /// The device's number of joints.
        expected: usize,
        /// The number of readings given.
        found: usize,
    },
    /// A noise standard deviation is negative, NaN or infinite.
    #[error("noise {name} = {value} is not a finite, non-negative standard deviation")]
    InvalidNoise {
        /// `sigma_e_rad` or `sigma_m_m`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// An unmodelled effect is malformed or does not fit the device (`--effect` syntax:
    /// `name:key=value,…`, see [`crate::injectable`]).
    #[error("effect {spec}: {message}")]
    Effect {
        /// The effect as given.
        spec: String,
        /// What is wrong.
        message: String,
    },
}
