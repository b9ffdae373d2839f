//! Calibration problems: measurement residuals with analytic Jacobians, on a kinematic chain
//! and on the transmissions that drive it. Every [`hapcal_identify::Problem`] of hapcal lives
//! here, one measurement model:
//! - [`CalibrationProblem`]: the kinematic residuals of one chain (the measurement types below),
//!   optionally with gravity compliance and joint harmonics;
//! - [`FleetProblem`]: the cable distances of a fleet of devices, each with its own deviations,
//!   sharing the rig's cable-encoder offset and cable-angle coefficient;
//! - [`CapstanProblem`]: step 1 of the paper's procedure (Fig. 6) for a capstan drive, eq. 1
//!   from external-encoder data;
//! - [`PolynomialProblem`]: step 1 for the parallelogram joint, its transmission error as a
//!   Chebyshev polynomial of the reading;
//! - [`JointProblem`]: both steps at once, the transmissions' external-encoder residuals and
//!   the cable distances of the corrected chain sharing the transmission parameters;
//! - [`DistanceLogModel`]: the model of a haptic device's time-ordered distance log that the
//!   diagnosis linearises: [`JointProblem`]'s transmissions and kinematics plus the terms of
//!   unmodelled effects, with per-row σ from the encoder specification.
//!
//! Architecture invariant: *`problems` turns a chain, transmissions and observations into
//! residuals and their Jacobian — an [`hapcal_identify::Problem`], or for the diagnosis's
//! candidate search the linearisation of [`DistanceLogModel`], which the diagnosis hands to
//! `hapcal-identify` — it never reads files and never solves.*
//!
//! Measurement types (each a residual with its analytic Jacobian):
//! - [`RowKind::Distance`]: distance from the rig origin (the chain's base) to the end point,
//!   the paper's cable encoder (eq. 5): `r = (|P| − δ)/σ`;
//! - [`RowKind::Position`]: end point in the rig frame (a tracker): `r = (P − P_meas)/σ`;
//! - [`RowKind::Point`]: the end point sits at unknown point `k` (a socket): `r = (P − s_k)/σ`,
//!   with `s_k` a nuisance parameter;
//! - [`PointDistance`]: a known distance between two unknown points: `r = (|s_a − s_b| − D)/σ`.
//!
//! Optionally a [`GravityCompliance`] term adds one parameter per joint (non-geometric
//! calibration, Judd & Knasinski 1990; Zhou et al. 2014): each joint deflects by `k_j·τ̂_j(q)`.
//!
//! ```
//! use hapcal_kinematics::{Chain, DhConvention, DhRow};
//! use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};
//! use hapcal_identify::Problem;
//!
//! let row = |a_m: f64, joint: usize| DhRow { convention: DhConvention::Standard, a_m,
//!     alpha_rad: 0.0, d_m: 0.0, theta_rad: 0.0, beta_rad: None, joint: Some(joint) };
//! let chain = Chain::from_dh(&[row(0.3, 0), row(0.2, 1)])?;
//! let obs = Observations {
//!     rows: vec![Row::new(vec![0.1, 0.2], RowKind::Distance { distance_m: 0.49 })],
//!     ..Observations::default()
//! };
//! let problem = CalibrationProblem::new(chain, obs, Weights::default(), None)?;
//! assert_eq!(problem.n_residuals(), 1);
//! assert_eq!(problem.layout().len(), 8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod compliance;
mod distance_log;
mod fleet;
mod harmonics;
mod joint;
mod log_problem;
mod model;
mod problem;
mod transmission;

pub use compliance::{
    GRAVITY_M_S2, GravityCompliance, JointLoad, LinkMass, handle_gravity_torques_nm,
};
pub use distance_log::{
    DistanceLog, DistanceLogLinearisation, DistanceLogModel, DistanceLogNoise, DistanceLogState,
    DistanceRow, EffectTerm, EffectTermKind, LogTransmission, distance_row,
};
pub use fleet::{FleetDevice, FleetProblem, cable_angle, fleet_initial_guess};
pub use harmonics::JointHarmonics;
pub use joint::{JointData, JointProblem, JointTransmissions};
pub use log_problem::{DistanceLogProblem, HANDLE_COMPLIANCE_UNIT, SAMPLES_PER_BLOCK};
pub use model::{CalibratedModel, EQUILIBRIUM_ITERATIONS};
pub use problem::{
    CalibrationProblem, ModelTerms, Observations, PointDistance, Row, RowKind, Transversal,
    TransversalTerm, Weights,
};
pub use transmission::{CapstanProblem, PolynomialProblem};

/// Errors of problem construction: inconsistent observations.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A configuration has a different number of joint angles than the chain.
    #[error("observation {row} has {found} joint angles, the chain has {expected} joints")]
    JointCount {
        /// Index of the observation.
        row: usize,
        /// Joints of the chain.
        expected: usize,
        /// Angles in the observation.
        found: usize,
    },
    /// An observation names an unknown point that does not exist.
    #[error("observation {row} refers to point {point}, but there are only {n_points} points")]
    NoSuchPoint {
        /// Index of the observation (or of the point distance).
        row: usize,
        /// The point index.
        point: usize,
        /// Number of unknown points.
        n_points: usize,
    },
    /// A weight is not a positive finite number.
    #[error("measurement standard deviation {name} = {value} must be positive and finite")]
    BadSigma {
        /// Which sigma.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A device parameter index is not a parameter of the chain.
    #[error("parameter index {index} is out of range for a chain of {n_params} parameters")]
    NoSuchParam {
        /// The offending index.
        index: usize,
        /// Number of chain parameters.
        n_params: usize,
    },
    /// Transversal compliance asked for where it cannot be modelled.
    #[error("transversal compliance cannot be modelled: {reason}")]
    NoTransversal {
        /// Why, in the user's words.
        reason: &'static str,
    },
    /// A value in an observation is NaN or infinite.
    #[error("observation {row} holds a value that is not finite")]
    NotFinite {
        /// Index of the observation.
        row: usize,
    },
    /// A transmission sits on a joint the chain does not have.
    #[error("joint {joint} (1-based) is not a joint of a chain of {n_joints} joints")]
    NoSuchJoint {
        /// The joint, 1-based.
        joint: usize,
        /// Joints of the chain.
        n_joints: usize,
    },
    /// Sequences that must pair up (measurement columns, rows) differ in length.
    #[error("{name} has {found} entries, expected {expected}")]
    LengthMismatch {
        /// The sequence with the unexpected length, e.g. `ext` (number of columns).
        name: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A model setting is outside its range.
    #[error("{name} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range, in words.
        expected: &'static str,
    },
    /// A term of the model needs the log's sample times, which the log does not have.
    #[error("{term} needs the sample times of the log, which has none")]
    NoSampleTimes {
        /// The term's name.
        term: String,
    },
    /// A row lacks a reading the model uses.
    #[error("row {row} has no external-encoder reading of joint {joint}")]
    MissingReading {
        /// Index of the row.
        row: usize,
        /// The joint, 1-based.
        joint: usize,
    },
    /// A transmission model rejects its input (e.g. a polynomial domain that is not a finite
    /// interval).
    #[error(transparent)]
    Transmission(#[from] hapcal_transmission::Error),
}

impl Error {
    /// `Ok(())` when observation `row` holds the `expected` joint angles (it holds `found`),
    /// else [`Error::JointCount`].
    pub(crate) fn check_joint_count(
        row: usize,
        expected: usize,
        found: usize,
    ) -> Result<(), Error> {
        if found != expected {
            return Err(Error::JointCount {
                row,
                expected,
                found,
            });
        }
        Ok(())
    }
}
