//! The crate's error type.

/// Why a force model could not be built or a force could not be computed.
///
/// Messages name the device element at fault; callers that read files add the file name
/// (the `hapcal` binary does, with `anyhow` context).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The device description could not be compiled into a chain.
    #[error("device: {source}")]
    Device {
        /// The io crate's error.
        source: hapcal_io::Error,
    },
    /// The truth file does not fit the device (unknown parameter, missing capstan, …).
    #[error("truth: {source}")]
    Truth {
        /// The sim crate's error.
        source: hapcal_sim::Error,
    },
    /// A transmission model rejected its parameters or a reading (e.g. the four-bar cannot
    /// close).
    #[error("joint {joint}: {source}")]
    Transmission {
        /// The joint, 1-based.
        joint: usize,
        /// The transmission crate's error.
        source: hapcal_transmission::Error,
    },
    /// A `[calibration.values]` entry that names a transmission parameter is malformed.
    #[error("calibration value {name:?}: {message}")]
    Calibration {
        /// The entry's name, e.g. `capstan2.re`.
        name: String,
        /// What is wrong with it.
        message: String,
    },
    /// The runtime ([`hapcal_runtime::Model`]) refused the device file: a placement (URDF)
    /// chain, a malformed `[calibration.values]` entry, an invalid transmission value, …
    #[error("runtime model: {source}")]
    Runtime {
        /// The runtime's error, naming the file element.
        source: hapcal_runtime::LoadError,
    },
    /// The runtime refused an input while evaluating (a NaN or infinite reading).
    #[error("runtime evaluation: {source}")]
    Evaluate {
        /// The runtime's error.
        source: hapcal_runtime::Error,
    },
    /// A slice has the wrong number of entries.
    #[error("{what}: expected {expected} entries, found {found}")]
    Length {
        /// Which slice.
        what: &'static str,
        /// Entries expected.
        expected: usize,
        /// Entries found.
        found: usize,
    },
    /// The static problem with the handle fixed needs exactly six unlocked joints (a
    /// 6 × 6 Jacobian); any other number leaves the wrench undetermined or over-determined.
    #[error("{n_active} unlocked joints: the fixed-handle statics needs exactly 6")]
    ActiveJoints {
        /// Unlocked joints.
        n_active: usize,
    },
    /// The locked joint is not a joint of the device.
    #[error("locked joint {joint} is not one of the device's joints 1..={n_joints}")]
    LockedJoint {
        /// The requested joint, 1-based.
        joint: usize,
        /// The device's number of joints.
        n_joints: usize,
    },
    /// A matrix of the static problem is singular (or numerically so) at this pose.
    #[error("the {which} is singular at this pose")]
    Singular {
        /// Which matrix: `truth Jacobian` or `closed-loop matrix I + G·M`.
        which: &'static str,
    },
    /// A wrench direction name that is not `Fx`, `Fy`, `Fz`, `Mx`, `My` or `Mz`.
    #[error("unknown wrench direction {name:?}: expected Fx, Fy, Fz, Mx, My or Mz")]
    UnknownDirection {
        /// The name given.
        name: String,
    },
    /// A configuration value is out of its range.
    #[error("{name} = {value} is invalid: expected {expected}")]
    InvalidConfig {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The accepted range.
        expected: &'static str,
    },
    /// Too many random poses were rejected as near-singular.
    #[error("only {accepted} of {drawn} random poses have a condition number ≤ {max_condition}")]
    TooFewPoses {
        /// Poses accepted.
        accepted: usize,
        /// Poses drawn.
        drawn: usize,
        /// The limit.
        max_condition: f64,
    },
}
