//! The diagnosis's view of the measurement model of a distance log,
//! [`hapcal_problems::DistanceLogModel`] (transmissions, kinematic deviations and the terms of
//! candidate effects): built from the device's encoder specification, linearised with the
//! residuals in the diagnosis's sign, measured − model.

use hapcal_io::{Device, LogRow, N_EXT};
use hapcal_kinematics::{Chain, Vector3};
use hapcal_problems::{DistanceLogLinearisation, DistanceLogModel, Error as ProblemError};
use nalgebra::{DMatrix, DVector};

pub(crate) use hapcal_problems::{
    DistanceLog as Data, DistanceLogState as State, EffectTerm as Term, EffectTermKind as TermKind,
    LogTransmission as Trans,
};

use crate::Error;

/// Relative tolerance below which a scaled column counts as dependent on the others.
pub(crate) const RANK_TOL: f64 = 1e-6;

/// Degree of the joint-4 polynomial (paper: tenth order).
pub(crate) const POLY_DEGREE: usize = 10;

/// The log's rows as the model's [`Data`].
///
/// # Errors
/// [`Error::Data`] for rows that do not form a log (readings of different lengths, values that
/// are not finite, times on some rows only).
pub(crate) fn log_data(rows: &[LogRow]) -> Result<Data, Error> {
    Data::new(
        rows.iter().map(|r| r.q.clone()).collect(),
        rows.iter().map(|r| r.t_s).collect(),
        rows.iter().map(|r| r.distance_m).collect(),
        rows.iter().map(|r| r.ext.clone()).collect(),
    )
    .map_err(|e| {
        // The problem counts rows from 0; the user reads the file's lines.
        let line = |row: usize| rows.get(row).map_or(0, |r| r.line);
        let message = match e {
            ProblemError::NotFinite { row } => {
                format!("line {}: a reading that is not a finite number", line(row))
            }
            ProblemError::JointCount {
                row,
                expected,
                found,
            } => format!(
                "line {}: {found} joint readings where the device has {expected} joints",
                line(row)
            ),
            e => e.to_string(),
        };
        Error::Data { message }
    })
}

/// The model linearised at a state: weighted residuals and Jacobian.
pub(crate) struct Linear {
    /// Weighted residuals (measured − model)/σ: the `n` distance rows, then the external
    /// encoder rows (joint by joint, `n` each).
    pub r: DVector<f64>,
    /// Weighted Jacobian of the model, one column per parameter of `names`.
    pub j: DMatrix<f64>,
    pub names: Vec<String>,
    /// σ of each row (m or rad).
    pub sigma: Vec<f64>,
    /// Sample of each row.
    pub sample: Vec<usize>,
    /// Per sample: end point in the rig frame, m.
    pub p: Vec<Vector3<f64>>,
}

impl From<DistanceLogLinearisation> for Linear {
    fn from(lin: DistanceLogLinearisation) -> Linear {
        Linear {
            r: -lin.residuals,
            j: lin.jacobian,
            names: lin.names,
            sigma: lin.sigma,
            sample: lin.sample,
            p: lin.points,
        }
    }
}

/// The model of one log.
pub(crate) struct Setup {
    model: DistanceLogModel,
}

impl Setup {
    /// The model of `data` on `chain` with the device's encoder specification (the paper's
    /// noise model, docs/design.md §3) and handle mass, the quantisation on.
    ///
    /// # Errors
    /// [`Error::Baseline`] for a device whose encoder specification or handle mass the model
    /// refuses, or a log that does not fit its chain.
    pub(crate) fn new(device: &Device, chain: Chain, data: Data) -> Result<Setup, Error> {
        let noise = hapcal_sim::distance_log_noise(device);
        let handle_mass_kg = device
            .handle
            .map_or(hapcal_sim::DEFAULT_HANDLE_MASS_KG, |h| h.mass_kg);
        let model = DistanceLogModel::new(chain, data, noise, handle_mass_kg).map_err(|e| {
            Error::Baseline {
                message: format!("the device's model of the log: {e}"),
            }
        })?;
        Ok(Setup { model })
    }

    /// Cable-encoder σ_m, m.
    pub(crate) fn sigma_m_m(&self) -> f64 {
        self.model.noise().sigma_m_m
    }

    /// External-encoder σ_e, rad.
    pub(crate) fn sigma_e_rad(&self) -> f64 {
        self.model.noise().sigma_e_rad
    }

    /// Whether the reading quantisation enters the floor.
    pub(crate) fn set_quantisation(&mut self, on: bool) {
        self.model.quantisation = on;
    }

    /// Makes the external encoders of `joints` (0-based) rows of the fit.
    ///
    /// # Errors
    /// [`Error::Baseline`] for a joint without readings.
    pub(crate) fn set_ext_joints(&mut self, joints: Vec<usize>) -> Result<(), Error> {
        self.model
            .set_ext_joints(joints)
            .map_err(|e| Error::Baseline {
                message: e.to_string(),
            })
    }

    /// The state with `trans`, zero deviations and no terms.
    pub(crate) fn initial_state(&self, trans: Vec<Trans>) -> State {
        self.model.initial_state(trans)
    }

    /// Linearises the model at `s`.
    pub(crate) fn linearise(&self, s: &State) -> Result<Linear, hapcal_problems::Error> {
        self.model.linearise(s).map(Linear::from)
    }
}

/// Whether the log has every external encoder the device's transmissions need.
pub(crate) fn ext_available(rows: &[LogRow], joints: &[usize]) -> bool {
    !rows.is_empty()
        && joints.iter().all(|&j| {
            j < N_EXT
                && rows
                    .iter()
                    .all(|r| r.ext.get(j).copied().flatten().is_some())
        })
}
