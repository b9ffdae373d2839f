//! Loading a device file (TOML, docs/design.md §5.1), as `hapcal calibrate` writes it.

use hapcal_contract::device::{Convention, DeviceFile, JointRef, JointSpec};
use hapcal_contract::drives::{DriveFault, HapticDrives, JointDrive, haptic_drives};
use hapcal_contract::locate::TomlSpans;
use hapcal_contract::{ContractError, TorqueSource};
use std::fmt;
use std::path::{Path, PathBuf};

use crate::{DhConvention, DhRow, Drive, Error, Model};

/// Gravity of a haptic device's handle, m/s²: `hapcal_problems::GRAVITY_M_S2`, the value its
/// handle compliances (rad/(N·m)) were identified with, for a device file whose
/// `[calibration]` does not record it (written before the record had a `[torque]` table).
pub const HANDLE_GRAVITY_M_S2: f64 = 9.81;

/// Why a device file could not be loaded. Messages name the file (`origin`) and, for syntax
/// and type errors, the line and column.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum LoadError {
    /// The file cannot be read.
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// TOML syntax, a missing or unknown key, or a value of the wrong type.
    Parse {
        /// The file (or `<string>`).
        origin: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What the parser expected.
        message: String,
    },
    /// A well-formed file whose content the runtime cannot use: joints misnumbered, a
    /// capstan on a missing joint, a calibrated value with a wrong unit, a URDF-placement
    /// chain, an invalid value ([`Error`]), …
    Invalid {
        /// The file (or `<string>`).
        origin: String,
        /// What is wrong, naming the table or parameter.
        message: String,
    },
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::Io { path, message } => {
                write!(f, "{}: cannot read: {message}", path.display())
            }
            LoadError::Parse {
                origin,
                line,
                column,
                message,
            } => write!(f, "{origin}:{line}:{column}: {message}"),
            LoadError::Invalid { origin, message } => write!(f, "{origin}: {message}"),
        }
    }
}

impl std::error::Error for LoadError {}

impl Model {
    /// Loads a device file (`fixtures/reference-device/calibrated.toml`, or any device
    /// file with a `[[dh]]` chain) into a model: see [`Model::from_toml`].
    ///
    /// # Errors
    /// [`LoadError::Io`] if the file cannot be read; otherwise as [`Model::from_toml`],
    /// with the path as origin.
    pub fn load(path: &Path) -> Result<Model, LoadError> {
        let text = read_text(path)?;
        Model::from_toml(&text, &path.display().to_string())
    }

    /// The calibrated model of a device file's text (docs/design.md §5.1), the same model
    /// as `hapcal_force::ForceModel::calibrated_library` (hapcal-force evaluates it through
    /// this function):
    ///
    /// - the `[[dh]]` rows as written (`hapcal calibrate` adds the identified kinematic
    ///   deviations to them), standard or modified by `convention`;
    /// - each `[[capstan]]` joint a capstan drive with the eq.-1 parameters
    ///   `capstan{j}.c`, `.re`, `.r_o`, `.beta_o`, `.r_i`, `.beta_i` of
    ///   `[calibration.values]` (units `rad`, `1`, `m`, `rad`, `m`, `rad`; missing ones 0);
    /// - a joint with `joint{j}.cheb0 … joint{j}.cheb{n}` (rad) the polynomial drive on its
    ///   `[[joint]]` range, keeping its nominal ratio (the paper's joint-4 model);
    /// - every other joint direct;
    /// - each `joint_compliance.j{k}` (rad/(N·m)) the handle's gravity compliance of joint k
    ///   ([`Model::with_handle_compliance`]): the joint angle deflected by `k·τ_k`, τ the
    ///   torque of the handle's weight at the end point, with the mass, gravity and
    ///   direction of `[calibration.torque]` (`source = "handle-mass"`), or for a record
    ///   without it the `[handle]` mass, [`HANDLE_GRAVITY_M_S2`] and minus the axis of joint
    ///   1 (what `hapcal_problems::handle_gravity_torques_nm` takes);
    /// - `[calibration.region]`, the joints' training ranges, for [`Model::outside_region`].
    ///
    /// `[calibration]` is the file contract's record (`hapcal-contract`, docs/design.md
    /// §5.6), checked by `Calibration::check`: an unknown or mistyped value name, a wrong
    /// unit, a missing key of its schema or a newer schema is refused at its line. Kinematic
    /// names (`da1`, `dtheta3`, …) are skipped: the rows already hold them; the instrument's
    /// and markers' frames (`[calibration.frames]`) are the measurement rig's. A value the
    /// device model cannot evaluate (a robot's `compliance.*`, `transversal.*`,
    /// `harmonic.*`, a placement deviation) is refused: a serial robot's device file with
    /// such a record is a [`crate::Robot`] ([`crate::Robot::load_device`]). A file without
    /// `[calibration]` gives the nominal model (ideal capstans, rigid joints). `origin` names
    /// the text in messages.
    ///
    /// # Errors
    /// [`LoadError::Parse`] for TOML syntax, a missing or unknown key or a wrong type (an
    /// unknown `convention`, a `[[dh]]` joint that is neither a number ≥ 1 nor `"fixed"`), and
    /// for a `[calibration]` the contract refuses or a value naming a joint, row or
    /// coefficient the device does not have (or a capstan value on a joint without a
    /// capstan), at its line and column;
    /// [`LoadError::Invalid`] for a `[[placement]]` chain (not supported by the runtime),
    /// joints not numbered 1, 2, … in row order, a `[[joint]]` count that differs from the
    /// chain's, `lower_rad ≥ upper_rad`, a capstan on a missing joint or twice on one, a
    /// gap in the Chebyshev indices, a handle compliance without a known handle weight or
    /// under another torque source, or a model value [`Model::from_dh`], [`Drive`] or
    /// [`Model::with_handle_compliance`] refuses.
    pub fn from_toml(text: &str, origin: &str) -> Result<Model, LoadError> {
        let DhFile {
            file,
            convention,
            rows,
            n_joints,
        } = read_device_file(text, origin)?;
        let model_error = |what: &str, e: Error| invalid(origin, format!("{what}: {e}"));
        let record = file.calibration.unwrap_or_default();
        record
            .check(text, origin)
            .map_err(|e| contract_error(e, origin))?;
        let HapticDrives {
            drives,
            handle_compliance: compliance,
        } = haptic_drives(&file.capstans, n_joints, rows.len(), Some(&record))
            .map_err(|fault| drive_fault(fault, text, origin))?;
        let drives = drives_of(&drives, &file.joints, origin)?;
        let model =
            Model::from_dh(convention, &rows, &drives).map_err(|e| model_error("[[dh]]", e))?;
        let model = if compliance.iter().any(|&k| k != 0.0) {
            let (weight_n, direction) = match &record.torque {
                Some(t) => {
                    if t.source != TorqueSource::HandleMass || t.equilibrium {
                        return Err(invalid(
                            origin,
                            format!(
                                "[calibration.torque]: source = \"{}\", equilibrium = {}: the \
                             handle compliances joint_compliance.j<k> are evaluated under the \
                             handle's weight at the undeflected angles (source = \
                             \"handle-mass\", equilibrium = false)",
                                t.source, t.equilibrium
                            ),
                        ));
                    }
                    // The contract's check asks a handle mass of this source.
                    let mass_kg = t.handle_mass_kg.unwrap_or(0.0);
                    (mass_kg * t.gravity_m_s2, t.gravity_direction)
                }
                // An earlier hapcal's record: the handle of `[handle]`, gravity along minus
                // the axis of joint 1, as the calibration library takes them.
                None => {
                    let Some(handle) = &file.handle else {
                        return Err(invalid(
                            origin,
                            "[calibration.values] holds joint_compliance.j<k>, but the file has \
                             neither [calibration.torque] nor [handle]: the handle's weight is \
                             unknown"
                                .to_owned(),
                        ));
                    };
                    let z = model.joint1_axis();
                    (handle.mass_kg * HANDLE_GRAVITY_M_S2, [-z[0], -z[1], -z[2]])
                }
            };
            model
                .with_handle_compliance(&compliance, weight_n, direction)
                .map_err(|e| model_error("joint_compliance", e))?
        } else {
            model
        };
        match &record.region {
            Some(region) => {
                let ranges: Vec<(f64, f64)> =
                    region.joints.iter().map(|j| (j.min, j.max)).collect();
                model
                    .with_region(&ranges, hapcal_contract::REGION_SLACK_SHARE)
                    .map_err(|e| model_error("[calibration.region]", e))
            }
            None => Ok(model),
        }
    }
}

/// A fault of the file's capstans or record values as the runtime reports it: at the line
/// of the value's name in `text` when it names a value, else without a line.
fn drive_fault(fault: DriveFault, text: &str, origin: &str) -> LoadError {
    let at = (fault.value.as_deref()).and_then(|name| TomlSpans::parse(text).value_line(name));
    at_line(origin, at.unwrap_or((0, 0)), fault.to_string())
}

/// Each joint's drive built from the file's and record's `drives` ([`haptic_drives`]);
/// `joints` are the file's `[[joint]]` entries (their limits, rad, bound a polynomial).
///
/// # Errors
/// A drive the runtime cannot build (more coefficients than it holds, capstan values outside
/// eq. 1's domain).
fn drives_of(
    drives: &[JointDrive],
    joints: &[JointSpec],
    origin: &str,
) -> Result<Vec<Drive>, LoadError> {
    let refused = |what: &str, message: String| invalid(origin, format!("{what}: {message}"));
    let built = |(j, drive): (usize, &JointDrive)| match drive {
        JointDrive::Direct => Ok(Drive::DIRECT),
        JointDrive::Capstan {
            ratio,
            drum_distance_m,
            params,
        } => Drive::capstan(*ratio, *drum_distance_m, *params)
            .map_err(|e| refused(&format!("capstan{}", j + 1), e.to_string())),
        JointDrive::Polynomial { ratio, coeffs } => {
            let what = format!("joint{}.cheb*", j + 1);
            let limits = &joints[j];
            Drive::polynomial(*ratio, limits.lower_rad, limits.upper_rad, coeffs)
                .map_err(|e| refused(&what, e.to_string()))
        }
    };
    drives.iter().enumerate().map(built).collect()
}

/// The text of the file at `path`.
///
/// # Errors
/// [`LoadError::Io`] if it cannot be read.
pub(crate) fn read_text(path: &Path) -> Result<String, LoadError> {
    std::fs::read_to_string(path).map_err(|e| LoadError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// A device file's `[[dh]]` chain, read and checked: the tables, the convention, the rows
/// (as written) and the number of joints.
pub(crate) struct DhFile {
    /// The file's tables, as the one device-file reader (`hapcal-contract`) reads them.
    pub(crate) file: DeviceFile,
    /// Standard or modified D-H.
    pub(crate) convention: DhConvention,
    /// The `[[dh]]` rows as written.
    pub(crate) rows: Vec<DhRow>,
    /// Number of joint rows (= `[[joint]]` entries).
    pub(crate) n_joints: usize,
}

/// Reads a device file's text up to its chain: TOML syntax and keys, the convention, the
/// `[[dh]]` rows numbered 1, 2, … in row order, one `[[joint]]` per joint row with
/// `lower_rad < upper_rad`. `[[placement]]` (URDF) chains are refused.
///
/// # Errors
/// As [`Model::from_toml`] for these checks.
pub(crate) fn read_device_file(text: &str, origin: &str) -> Result<DhFile, LoadError> {
    // Both name a line (1 for a fault without a place): a `Parse` error.
    let file = DeviceFile::from_toml_str(text).map_err(|e| {
        let (line, column, message) = hapcal_contract::toml_error_at(text, &e);
        at_line(origin, (line, column), message)
    })?;
    hapcal_contract::device::check_numbers(text)
        .map_err(|bad| at_line(origin, (bad.line, bad.column), bad.to_string()))?;
    if !file.placements.is_empty() || !file.branches.is_empty() || file.urdf.is_some() {
        return Err(invalid(
            origin,
            "[[placement]] (URDF) chains are not supported by the runtime: use a [[dh]] \
                 chain"
                .to_owned(),
        ));
    }
    let convention = match file.convention {
        Convention::Standard => DhConvention::Standard,
        Convention::Modified => DhConvention::Modified,
    };
    let mut rows = Vec::with_capacity(file.dh.len());
    let mut n_joints = 0usize;
    for (i, entry) in file.dh.iter().enumerate() {
        let joint = match entry.joint {
            JointRef::Fixed => false,
            JointRef::Joint(j) if j == n_joints + 1 => true,
            other => {
                return Err(invalid(
                    origin,
                    format!(
                        "[[dh]] row {i}: joint = {other}, expected {} (joints numbered in row \
                         order) or \"fixed\"",
                        n_joints + 1
                    ),
                ));
            }
        };
        n_joints += usize::from(joint);
        rows.push(DhRow {
            a_m: entry.a_m,
            alpha_rad: entry.alpha_rad,
            d_m: entry.d_m,
            theta_rad: entry.theta_rad,
            beta_rad: entry.beta_rad,
            joint,
        });
    }
    if file.joints.len() != n_joints {
        return Err(invalid(
            origin,
            format!(
                "the chain has {n_joints} joints but {} [[joint]] entries",
                file.joints.len()
            ),
        ));
    }
    for j in &file.joints {
        if !j.lower_rad.is_finite() || !j.upper_rad.is_finite() || j.lower_rad >= j.upper_rad {
            return Err(invalid(
                origin,
                format!(
                    "[[joint]] {:?}: lower_rad = {} must be finite and below upper_rad = {}",
                    j.name, j.lower_rad, j.upper_rad
                ),
            ));
        }
    }
    Ok(DhFile {
        file,
        convention,
        rows,
        n_joints,
    })
}

/// A refusal of the content of `origin` ([`LoadError::Invalid`]).
pub(crate) fn invalid(origin: &str, message: String) -> LoadError {
    LoadError::Invalid {
        origin: origin.to_owned(),
        message,
    }
}

/// A refusal at `(line, column)` of `origin`; without a line (0), of the file.
pub(crate) fn at_line(origin: &str, (line, column): (usize, usize), message: String) -> LoadError {
    contract_error(
        ContractError {
            origin: origin.to_owned(),
            line,
            column,
            message,
        },
        origin,
    )
}

/// A contract's refusal as a load error: at its line and column when known.
pub(crate) fn contract_error(e: ContractError, origin: &str) -> LoadError {
    if e.line == 0 {
        invalid(origin, e.message)
    } else {
        LoadError::Parse {
            origin: origin.to_owned(),
            line: e.line,
            column: e.column,
            message: e.message,
        }
    }
}
