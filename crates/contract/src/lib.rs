//! The file contract of a calibrated model: the calibration record that `hapcal calibrate
//! --out` writes (a URDF's sidecar `robot.calibration.toml`, or the `[calibration]` table of
//! a device file) and that every reader shares: `hapcal-io`, the runtime, its C ABI and the
//! Python package (docs/design.md §5.6).
//!
//! *One set of types, in the lowest crate: the writer and every reader parse and check the
//! record here, so they cannot disagree on a name or a unit.*
//!
//! The robot description's readers live here too, once, for the same reason: [`urdf`] parses
//! a URDF and walks its tree, [`device`] reads a device file's tables, for `hapcal-io` and the
//! runtime alike.
//!
//! A record ([`Calibration`]) carries the model's name, every identified value with its unit
//! and standard deviation, the parameter covariance (for the prediction's uncertainty at a
//! configuration), each compliance's torque source ([`Torque`]), the calibration's tips, the
//! instrument and marker frames, and the region the model was fitted on ([`Region`]). Value
//! names are typed by [`ValueName::parse`]; [`Calibration::check`] refuses an unknown name, a
//! wrong unit, a missing key or a newer schema at file:line:column ([`ContractError`]).
//!
//! ```
//! use hapcal_contract::{Calibration, ModelName};
//!
//! let text = r#"
//! schema_version = 1
//! model = "compliance"
//! tips = ["ball_link"]
//!
//! [torque]
//! source = "lumped-unit-weights"
//! gravity_direction = [0.0, 0.0, -1.0]
//! gravity_m_s2 = 9.80665
//! tips = ["ball_link"]
//!
//! [region]
//! rows = 120
//! joint = [{ name = "joint_a2", min = -0.5, max = 1.1, unit = "rad" }]
//!
//! [values]
//! "compliance.joint_a2" = { value = 1.5e-4, std = 2e-6, unit = "rad/m" }
//! "#;
//! let record = Calibration::from_sidecar_str(text, "robot.calibration.toml")?;
//! assert_eq!(record.model, Some(ModelName::Compliance));
//! assert_eq!(record.values[0].unit, "rad/m");
//! // Read back what it writes.
//! let again = Calibration::from_sidecar_str(&record.to_sidecar_toml(), "again")?;
//! assert_eq!(again, record);
//! # Ok::<(), hapcal_contract::ContractError>(())
//! ```

pub mod device;
pub mod drives;
mod effect;
pub mod locate;
mod names;
pub mod urdf;
mod write;

pub use effect::{Effect, ModelFor, SeparatingMeasurement};

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use locate::{Step, TomlSpans, key_line};
pub use locate::{line_column, toml_error_at};
pub use names::{CapstanField, DhField, ElementField, ValueName};

/// The schema version this crate writes and the newest it reads. Version 1 is the first
/// record with a model name, torque source, region and covariance; a record without
/// `schema_version` was written by an earlier hapcal (frames and values only,
/// [`Calibration::is_legacy`]): read in a device file's `[calibration]`, refused as a sidecar.
pub const SCHEMA_VERSION: u32 = 1;

/// The model a calibration identified: the rung of `hapcal calibrate`'s ladder, by the name
/// its `--model` option takes (`transversal-compliance`, …).
///
/// Ordered simplest first within the ladder (`FramesOnly < JointOffsets < Geometric <
/// Compliance …`), the order of [`ModelName::ALL`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelName {
    /// The nominal kinematics; only the instrument's and markers' frames.
    FramesOnly,
    /// The frames plus one offset per joint.
    JointOffsets,
    /// Every kinematic parameter the data determine.
    Geometric,
    /// Geometric plus one gravity compliance per joint (URDF masses, lumped unit weights, or a
    /// haptic device's handle mass).
    Compliance,
    /// Compliance with the robot's published link masses.
    MassCompliance,
    /// Mass-compliance with one compliance per actuator size.
    ActuatorCompliance,
    /// Compliance plus one transversal compliance per revolute joint, alike in every direction.
    TransversalCompliance,
    /// Compliance plus two transversal compliances per revolute joint, one per axis.
    TransversalAxes,
    /// Geometric plus once-per-revolution joint harmonics.
    Harmonic,
    /// Geometric plus first- and second-order joint harmonics.
    Harmonic2,
    /// Mass-compliance plus harmonic.
    MassComplianceHarmonic,
    /// Compliance plus harmonic.
    ComplianceHarmonic,
    /// A haptic device's transmissions (capstans, the parallelogram's polynomial) and
    /// kinematic deviations.
    Transmissions,
}

impl ModelName {
    /// Every model, in ladder order.
    pub const ALL: [ModelName; 13] = [
        ModelName::FramesOnly,
        ModelName::JointOffsets,
        ModelName::Geometric,
        ModelName::Compliance,
        ModelName::MassCompliance,
        ModelName::ActuatorCompliance,
        ModelName::TransversalCompliance,
        ModelName::TransversalAxes,
        ModelName::Harmonic,
        ModelName::Harmonic2,
        ModelName::MassComplianceHarmonic,
        ModelName::ComplianceHarmonic,
        ModelName::Transmissions,
    ];

    /// The name as files and `--model` write it (`transversal-compliance`).
    pub const fn name(self) -> &'static str {
        match self {
            ModelName::FramesOnly => "frames-only",
            ModelName::JointOffsets => "joint-offsets",
            ModelName::Geometric => "geometric",
            ModelName::Compliance => "compliance",
            ModelName::MassCompliance => "mass-compliance",
            ModelName::ActuatorCompliance => "actuator-compliance",
            ModelName::TransversalCompliance => "transversal-compliance",
            ModelName::TransversalAxes => "transversal-axes",
            ModelName::Harmonic => "harmonic",
            ModelName::Harmonic2 => "harmonic2",
            ModelName::MassComplianceHarmonic => "mass-compliance-harmonic",
            ModelName::ComplianceHarmonic => "compliance-harmonic",
            ModelName::Transmissions => "transmissions",
        }
    }

    /// The model whose name is `name` (`-` or `_` between words, any case), if any.
    pub fn from_name(name: &str) -> Option<ModelName> {
        let wanted = name.trim().to_ascii_lowercase().replace('_', "-");
        ModelName::ALL.into_iter().find(|m| m.name() == wanted)
    }
}

impl fmt::Display for ModelName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// Where a compliance's load comes from, which fixes its unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TorqueSource {
    /// The link masses of the URDF's `<inertial>` elements: torques in N·m, compliances in
    /// rad/(N·m). The masses are written into the record ([`Torque::masses`]).
    UrdfMasses,
    /// A robot's published link masses (Franka Panda, KUKA LBR iiwa 14): N·m, rad/(N·m); the
    /// masses are written into the record.
    PublishedMasses,
    /// Without masses: a unit weight at the origin of every joint below and at every tip of
    /// [`Torque::tips`] below ("torques" in m, compliances in rad/m).
    LumpedUnitWeights,
    /// A haptic device's handle, a point mass at the end point ([`Torque::handle_mass_kg`]):
    /// N·m, rad/(N·m).
    HandleMass,
}

impl TorqueSource {
    /// The name as the record writes it (`urdf-masses`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            TorqueSource::UrdfMasses => "urdf-masses",
            TorqueSource::PublishedMasses => "published-masses",
            TorqueSource::LumpedUnitWeights => "lumped-unit-weights",
            TorqueSource::HandleMass => "handle-mass",
        }
    }

    /// The unit of a compliance under this load: `rad/m` for the lumped unit weights,
    /// `rad/(N·m)` otherwise.
    pub fn compliance_unit(self) -> &'static str {
        match self {
            TorqueSource::LumpedUnitWeights => "rad/m",
            _ => "rad/(N·m)",
        }
    }
}

impl fmt::Display for TorqueSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.as_str())
    }
}

/// A link's point mass, in the frame of the joint that moves it (after the joint's motion).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMass {
    /// The moving joint (URDF name) whose child link carries the mass.
    pub joint: String,
    /// Mass, kg (≥ 0).
    pub mass_kg: f64,
    /// Centre of mass in that joint's frame after its motion, m.
    pub com_m: [f64; 3],
}

/// The gravity load the compliances were identified under (`[torque]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Torque {
    /// Where the load comes from.
    pub source: TorqueSource,
    /// Unit vector of gravity in the robot's root frame (the base of the chain).
    pub gravity_direction: [f64; 3],
    /// Gravitational acceleration, m/s² (9.80665 for link masses; 9.81 for the haptic
    /// handle, as the simulator).
    pub gravity_m_s2: f64,
    /// Whether the loads are those of the deflected robot (the torque equilibrium
    /// `θ = q + k∘τ(θ)`, solved by fixed-point iteration) rather than those of the robot at
    /// its readings.
    #[serde(default)]
    pub equilibrium: bool,
    /// The tips whose paths carry the load (the calibration's tips): the lumped unit weights
    /// sit at every joint origin and tip of these paths.
    #[serde(default)]
    pub tips: Vec<String>,
    /// The point masses (URDF or published masses); empty otherwise.
    #[serde(default, rename = "mass", skip_serializing_if = "Vec::is_empty")]
    pub masses: Vec<PointMass>,
    /// The handle's mass, kg (handle mass only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub handle_mass_kg: Option<f64>,
}

/// A frame identified with the kinematics (`[frames.<name>]`): the instrument's frame in the
/// robot's root frame, or a marker's frame on its tip link; a URDF `<origin>`, `R =
/// Rz(yaw)·Ry(pitch)·Rx(roll)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Frame {
    /// Translation, m.
    pub xyz_m: [f64; 3],
    /// Roll, pitch, yaw, rad.
    pub rpy_rad: [f64; 3],
}

/// One joint's range over the training rows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointRange {
    /// Joint name (URDF name, or `q<k>` for a D-H device's joint k).
    pub name: String,
    /// Least reading, rad (m for a prismatic joint).
    pub min: f64,
    /// Greatest reading, rad (m).
    pub max: f64,
    /// `rad` or `m`.
    pub unit: String,
}

/// The region the model was fitted on (`[region]`): where its predictions are backed by data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Number of training rows.
    pub rows: usize,
    /// Every joint's training range, in the order of the joint readings.
    #[serde(default, rename = "joint")]
    pub joints: Vec<JointRange>,
}

/// Share of a joint's training range a reading may lie past it and still count as inside
/// the region (random readings fall a fraction of a percent past the training extremes).
pub const REGION_SLACK_SHARE: f64 = 0.05;

/// A configuration's place against a [`Region`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Outside {
    /// Joints past their training range by more than [`REGION_SLACK_SHARE`] of it: (index
    /// in the region's joints, signed distance past the nearer end, rad or m).
    pub joints: Vec<(usize, f64)>,
}

impl Outside {
    /// Whether the configuration lies inside the region.
    pub fn is_inside(&self) -> bool {
        self.joints.is_empty()
    }
}

impl Region {
    /// Where the readings `q` (rad or m, in the region's joint order) lie against the
    /// training ranges: the joints past their range by more than [`REGION_SLACK_SHARE`] of
    /// it, with how far (positive above the range, negative below). Readings beyond the
    /// region's joints are not judged.
    pub fn outside(&self, q: &[f64]) -> Outside {
        let mut out = Outside::default();
        for (j, (r, &v)) in self.joints.iter().zip(q).enumerate() {
            let slack = REGION_SLACK_SHARE * (r.max - r.min).max(0.0);
            if v > r.max + slack {
                out.joints.push((j, v - r.max));
            } else if v < r.min - slack {
                out.joints.push((j, v - r.min));
            }
        }
        out
    }
}

/// A compliance estimate below zero by more than this many standard deviations, at the least,
/// is no physical value: calibrate stops on it: a joint does not bend against its load.
/// Within it, the estimate is zero within its uncertainty. Among `n` estimates the bound grows
/// to keep the chance that a right calibration is stopped at [`NEGATIVE_COMPLIANCE_FAMILY_RISK`]
/// ([`negative_compliance_sigmas`]).
pub const NEGATIVE_COMPLIANCE_SIGMAS: f64 = 2.0;

/// Chance that some compliance of a right calibration lies below zero by more than
/// [`negative_compliance_sigmas`] by noise alone (Bonferroni over the estimates): at 2σ each,
/// one of 12 compliances of the real UR10 recording's per-axis transversal model lies at
/// −2.3σ, and half of the right calibrations with 33 compliances would be stopped.
pub const NEGATIVE_COMPLIANCE_FAMILY_RISK: f64 = 0.05;

/// The bound, in standard deviations, below zero beyond which one of `n` compliance estimates
/// is a finding: the one-sided normal quantile of [`NEGATIVE_COMPLIANCE_FAMILY_RISK`]/`n`
/// (Bonferroni), at least [`NEGATIVE_COMPLIANCE_SIGMAS`]: 2.0 for one estimate, 2.64 for 12,
/// 2.97 for 33.
pub fn negative_compliance_sigmas(n: usize) -> f64 {
    let p = NEGATIVE_COMPLIANCE_FAMILY_RISK / n.max(1) as f64;
    // Upper tail of the standard normal, Q(z) = erfc(z/√2)/2, with erfc from Abramowitz &
    // Stegun 7.1.26 (error below 1.5·10⁻⁷), inverted by bisection on [0, 10].
    let q = |z: f64| {
        let x = z / std::f64::consts::SQRT_2;
        let t = 1.0 / (1.0 + 0.327_591_1 * x);
        let poly = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        0.5 * poly * (-x * x).exp()
    };
    let (mut lo, mut hi) = (0.0_f64, 10.0_f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if q(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).max(NEGATIVE_COMPLIANCE_SIGMAS)
}

/// The covariance of the identified values (`[covariance]`): the symmetric matrix `Σ` over
/// [`Covariance::names`], its lower triangle row by row (`Σ₀₀, Σ₁₀, Σ₁₁, Σ₂₀, …`,
/// `n(n+1)/2` entries), in the values' units (m², rad², m·rad, …).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Covariance {
    /// The values the rows and columns stand for (names of [`Calibration::values`]).
    pub names: Vec<String>,
    /// Lower triangle, row-major.
    pub lower: Vec<f64>,
}

impl Covariance {
    /// The covariance of the `n × n` matrix `matrix` (row-major, symmetric; its lower triangle
    /// is kept) over `names`.
    ///
    /// # Panics
    /// If `matrix` does not have `names.len()²` entries.
    #[track_caller]
    pub fn from_matrix(names: Vec<String>, matrix: &[f64]) -> Covariance {
        let n = names.len();
        assert_eq!(matrix.len(), n * n, "a covariance needs n² entries");
        let lower = (0..n)
            .flat_map(|i| (0..=i).map(move |j| matrix[i * n + j]))
            .collect();
        Covariance { names, lower }
    }

    /// Entry `Σ_ij`.
    ///
    /// # Panics
    /// If `i` or `j` is not below `names.len()`.
    #[track_caller]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let n = self.names.len();
        assert!(i < n && j < n, "covariance entry ({i}, {j}) of {n}");
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        self.lower[i * (i + 1) / 2 + j]
    }
}

/// One identified value with its standard deviation, in SI units (`[values]`: `"name" = {
/// value, std, unit }`).
#[derive(Clone, Debug, PartialEq)]
pub struct CalibratedValue {
    /// Parameter name ([`ValueName`]: `dtheta3`, `joint_a2.rx`, `compliance.joint_a4`, …).
    pub name: String,
    /// Identified value, in `unit` (a deviation from nominal for kinematic values).
    pub value: f64,
    /// Its standard deviation, in `unit` (≥ 0).
    pub std: f64,
    /// Unit symbol: `m`, `rad`, `1`, `rad/(N·m)` or `rad/m`.
    pub unit: String,
}

impl CalibratedValue {
    /// Checks that the value and its standard deviation are finite and the deviation is not
    /// negative: the one check of a value's numbers, for [`Calibration::check`] and for a
    /// reader applying values without a record.
    ///
    /// # Errors
    /// What is wrong and what was expected: `value … with std …: expected finite numbers,
    /// std ≥ 0` (without the value's name, which the caller gives).
    pub fn check_numbers(&self) -> Result<(), String> {
        if self.value.is_finite() && self.std.is_finite() && self.std >= 0.0 {
            Ok(())
        } else {
            Err(format!(
                "value {} with std {}: expected finite numbers, std ≥ 0",
                self.value, self.std
            ))
        }
    }
}

/// A calibration record: the sidecar of a calibrated URDF, or a device file's
/// `[calibration]` table.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// The schema it was written in ([`SCHEMA_VERSION`]); `None`: an earlier hapcal's record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schema_version: Option<u32>,
    /// The model identified (required from schema 1 on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelName>,
    /// Date of the calibration, free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub date: Option<String>,
    /// Hash of the measurement data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_hash: Option<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
    /// The calibration's tip links, in the order of the measurement's markers (URDF robots).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tips: Vec<String>,
    /// The digest ([`digest`]) of the robot description the record was written beside: the
    /// calibrated URDF's bytes (`fnv1a64:` and 16 hex digits). Readers refuse the record
    /// beside another file ([`Calibration::check_urdf`]); `None`: written before hapcal
    /// recorded it (nothing binds the record to its robot), or a device file's record (the
    /// same file holds both).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub urdf_digest: Option<String>,
    /// The compliances' gravity load (required when the record holds a compliance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torque: Option<Torque>,
    /// The region the model was fitted on (required from schema 1 on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<Region>,
    /// The identified frames (`instrument`, `marker1`, …).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub frames: BTreeMap<String, Frame>,
    /// The nominal `<origin>` of every URDF joint whose placement the record's values
    /// deviate (`[nominal.<joint>]`), as the URDF the calibration started from holds it: the
    /// calibrated URDF's origin of that joint is this origin composed with the values'
    /// deviation, so a reader checks that the values and the URDF beside them agree (a value
    /// is held in one place: edited in one file only, it is refused, not ignored). Empty:
    /// written before hapcal recorded it, or a D-H robot's record.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub nominal: BTreeMap<String, Frame>,
    /// Identified values, in identification order.
    #[serde(default, with = "values_table")]
    pub values: Vec<CalibratedValue>,
    /// Their covariance (absent: the prediction's uncertainty is unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance: Option<Covariance>,
}

/// Why a record was refused: the file, and where known the line and column, and what was
/// expected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ContractError {
    /// The file (or another name for the text).
    pub origin: String,
    /// 1-based line, 0 when unknown.
    pub line: usize,
    /// 1-based column, 0 when unknown.
    pub column: usize,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for ContractError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.origin, self.message)
        } else {
            write!(
                f,
                "{}:{}:{}: {}",
                self.origin, self.line, self.column, self.message
            )
        }
    }
}

impl std::error::Error for ContractError {}

/// The digest a record keeps of the robot description it was written beside
/// ([`Calibration::urdf_digest`]): `fnv1a64:` and the 64-bit FNV-1a hash of `bytes` in 16
/// lowercase hex digits (Fowler, Noll & Vo; offset basis 0xcbf29ce484222325, prime
/// 0x100000001b3).
///
/// FNV-1a rather than a cryptographic hash: it guards against a record read beside the wrong
/// file (another robot, a variant, an edited copy), where a chance collision has odds of 2⁻⁶⁴;
/// it does not guard against a forged file, which nothing in a calibration record could.
pub fn digest(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

impl Calibration {
    /// A sidecar's text (`robot.calibration.toml`, as [`Self::to_sidecar_toml`] writes it),
    /// parsed and checked ([`Self::check`]); `origin` names it in errors.
    ///
    /// # Errors
    /// TOML syntax, a missing or unknown key or a wrong type at its line and column; as
    /// [`Self::check`]; a sidecar without `schema_version` (an earlier hapcal's,
    /// [`Self::is_legacy`]).
    pub fn from_sidecar_str(text: &str, origin: &str) -> Result<Calibration, ContractError> {
        let record: Calibration = toml::from_str(text).map_err(|e| {
            let (line, column, message) = locate::toml_error_at(text, &e);
            ContractError {
                origin: origin.to_owned(),
                line,
                column,
                message,
            }
        })?;
        record.check(text, origin)?;
        if record.is_legacy() {
            // A device file's `[calibration]` may still be an earlier hapcal's values; a
            // sidecar is written by `Calibration::to_sidecar_toml` only.
            return Err(ContractError {
                origin: origin.to_owned(),
                line: 1,
                column: 1,
                message: format!(
                    "missing key schema_version: a calibration record begins with \
                     schema_version = {SCHEMA_VERSION}; a sidecar without it (frames and values \
                     only) was written by an earlier hapcal, whose sidecars this one does not \
                     read: calibrate again"
                ),
            });
        }
        if record.model == Some(ModelName::Transmissions) {
            let (line, column) = TomlSpans::parse(text)
                .record_line(&[Step::Key("model")])
                .unwrap_or((0, 0));
            return Err(ContractError {
                origin: origin.to_owned(),
                line,
                column,
                message: "model = \"transmissions\" is a haptic device's model (capstans and \
                          polynomial drives), whose record lives in its device file's \
                          [calibration]; a URDF's sidecar holds a serial robot's model"
                    .to_owned(),
            });
        }
        Ok(record)
    }

    /// Checks that the record belongs to the robot description beside it: `urdf` (the
    /// file's bytes, named `urdf_origin`) must have the digest the record holds
    /// ([`Calibration::urdf_digest`], [`digest`]). `text` is the record's text, named
    /// `origin`. Returns a note for a record without a digest (written before hapcal recorded
    /// one: nothing checks that it belongs to this file), `None` when the digests agree.
    ///
    /// # Errors
    /// Another digest: which file, the digest recorded (at its line), the one found and what
    /// to do.
    pub fn check_urdf(
        &self,
        text: &str,
        origin: &str,
        urdf: &[u8],
        urdf_origin: &str,
    ) -> Result<Option<String>, ContractError> {
        let Some(recorded) = &self.urdf_digest else {
            return Ok(Some(format!(
                "note: {origin} holds no digest of the URDF it was written beside (an earlier \
                 hapcal wrote it): nothing checks that it belongs to {urdf_origin}"
            )));
        };
        let found = digest(urdf);
        if *recorded == found {
            return Ok(None);
        }
        let (line, column) = TomlSpans::parse(text)
            .record_line(&[Step::Key("urdf_digest")])
            .unwrap_or((0, 0));
        Err(ContractError {
            origin: origin.to_owned(),
            line,
            column,
            message: format!(
                "urdf_digest = \"{recorded}\" is the digest of the URDF this record was written \
                 beside, but {urdf_origin} has {found}: the record belongs to another robot \
                 description (another robot or variant, or a URDF edited after the calibration). \
                 Load it beside the URDF hapcal calibrate wrote with it, or calibrate \
                 {urdf_origin} again"
            ),
        })
    }

    /// Whether an earlier hapcal wrote the record (no `schema_version`): frames and values
    /// only, no model, torque source, region or covariance.
    pub fn is_legacy(&self) -> bool {
        self.schema_version.is_none()
    }

    /// The value named `name`, if any.
    pub fn value(&self, name: &str) -> Option<&CalibratedValue> {
        self.values.iter().find(|v| v.name == name)
    }

    /// Checks what the types cannot: the schema version (a newer one is refused in words),
    /// the keys schema 1 requires (`model`, `region`, `torque` when a compliance is
    /// recorded), every value's name ([`ValueName::parse`]) and unit ([`ValueName::units`]),
    /// finite numbers, standard deviations ≥ 0, a covariance over recorded values with
    /// `n(n+1)/2` finite entries and a non-negative diagonal, training ranges with `min ≤
    /// max`, a unit gravity direction, finite non-negative masses. `text` is the record's
    /// text (the whole file), searched for the line of the key at fault; `origin` names it.
    ///
    /// # Errors
    /// The first fault, at the line of its key where it can be found.
    pub fn check(&self, text: &str, origin: &str) -> Result<(), ContractError> {
        let at = RecordText { text, origin };
        self.check_schema(&at)?;
        self.check_torque(&at)?;
        self.check_region(&at)?;
        self.check_frames(&at)?;
        self.check_values(&at)?;
        self.check_covariance(&at)
    }

    /// The schema's keys: a record of schema 1 begins with `schema_version` and names its model
    /// and region; a key of schema 1 without the version is a record whose first line was lost.
    fn check_schema(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        if self.schema_version.is_none() {
            // An earlier hapcal's record holds frames and values only: a key of schema 1
            // without the version is a record whose first line was lost or edited away.
            let present = [
                ("model", self.model.is_some()),
                ("tips", !self.tips.is_empty()),
                ("urdf_digest", self.urdf_digest.is_some()),
                ("torque", self.torque.is_some()),
                ("region", self.region.is_some()),
                ("nominal", !self.nominal.is_empty()),
                ("covariance", self.covariance.is_some()),
            ];
            if let Some((key, _)) = present.iter().find(|(_, p)| *p) {
                return at.fail(
                    key,
                    format!(
                        "missing key schema_version: `{key}` is a key of calibration records \
                     of schema 1, which begin with schema_version = {SCHEMA_VERSION}; add \
                     that line (a record without it is read as an earlier hapcal's: frames \
                     and values only)"
                    ),
                );
            }
        }
        if let Some(v) = self.schema_version {
            if v > SCHEMA_VERSION {
                return at.fail(
                    "schema_version",
                    format!(
                        "schema_version = {v}: written by a newer hapcal; this one reads \
                     calibration records up to version {SCHEMA_VERSION}"
                    ),
                );
            }
            if v == 0 {
                return at.fail(
                    "schema_version",
                    "schema_version = 0: expected 1 (or no schema_version for a record written \
                 before versions were recorded)"
                        .to_owned(),
                );
            }
            if self.model.is_none() {
                return at.fail(
                    "schema_version",
                    format!(
                        "missing key model: expected the identified model's name, one of {}",
                        ModelName::ALL.map(ModelName::name).join(", ")
                    ),
                );
            }
            if self.region.is_none() {
                return at.fail(
                    "schema_version",
                    "missing table [region]: expected rows and each joint's training range"
                        .to_owned(),
                );
            }
        }
        Ok(())
    }

    /// The `[torque]` table: a unit gravity direction, a positive acceleration, finite non-
    /// negative masses at finite points, the masses its source needs.
    fn check_torque(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        if let Some(t) = &self.torque {
            let g = t.gravity_direction;
            let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if !norm.is_finite() || (norm - 1.0).abs() > 1e-6 {
                return at.fail_at(
                    &[Step::Key("torque"), Step::Key("gravity_direction")],
                    "gravity_direction",
                    format!("torque.gravity_direction = {g:?}: expected a unit vector"),
                );
            }
            if !(t.gravity_m_s2.is_finite() && t.gravity_m_s2 > 0.0) {
                return at.fail_at(
                    &[Step::Key("torque"), Step::Key("gravity_m_s2")],
                    "gravity_m_s2",
                    format!(
                        "torque.gravity_m_s2 = {}: expected a positive acceleration, m/s²",
                        t.gravity_m_s2
                    ),
                );
            }
            for (i, m) in t.masses.iter().enumerate() {
                if !(m.mass_kg.is_finite() && m.mass_kg >= 0.0)
                    || m.com_m.iter().any(|c| !c.is_finite())
                {
                    let field = if m.mass_kg.is_finite() && m.mass_kg >= 0.0 {
                        "com_m"
                    } else {
                        "mass_kg"
                    };
                    return at.fail_at(
                        &[
                            Step::Key("torque"),
                            Step::Key("mass"),
                            Step::Index(i),
                            Step::Key(field),
                        ],
                        "torque",
                        format!(
                            "torque mass on joint {:?}: {} kg at {:?} m is not a finite, \
                         non-negative mass at a finite point",
                            m.joint, m.mass_kg, m.com_m
                        ),
                    );
                }
            }
            let needs_masses = matches!(
                t.source,
                TorqueSource::UrdfMasses | TorqueSource::PublishedMasses
            );
            if needs_masses && t.masses.is_empty() {
                return at.fail_at(
                    &[Step::Key("torque"), Step::Key("source")],
                    "torque",
                    format!(
                        "torque.source = \"{}\" without [[torque.mass]]: expected the link masses",
                        t.source
                    ),
                );
            }
            if t.source == TorqueSource::HandleMass
                && !t.handle_mass_kg.is_some_and(|m| m.is_finite() && m > 0.0)
            {
                return at.fail_at(
                    &[Step::Key("torque"), Step::Key("source")],
                    "torque",
                    "torque.source = \"handle-mass\": expected handle_mass_kg > 0".to_owned(),
                );
            }
        }
        Ok(())
    }

    /// The `[region]` table: each joint's finite range, min ≤ max, in rad or m.
    fn check_region(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        if let Some(r) = &self.region {
            for (k, j) in r.joints.iter().enumerate() {
                let entry = |field| {
                    [
                        Step::Key("region"),
                        Step::Key("joint"),
                        Step::Index(k),
                        Step::Key(field),
                    ]
                };
                if !(j.min.is_finite() && j.max.is_finite() && j.min <= j.max) {
                    return at.fail_at(
                        &entry(if j.min.is_finite() { "max" } else { "min" }),
                        "region",
                        format!(
                            "region joint {:?}: min = {}, max = {}: expected finite min ≤ max",
                            j.name, j.min, j.max
                        ),
                    );
                }
                if j.unit != "rad" && j.unit != "m" {
                    return at.fail_at(
                        &entry("unit"),
                        "region",
                        format!(
                            "region joint {:?}: unit {:?}, expected \"rad\" or \"m\"",
                            j.name, j.unit
                        ),
                    );
                }
            }
        }
        Ok(())
    }

    /// The `[frames]` and `[nominal]` tables: finite values.
    fn check_frames(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        for (table, frames) in [("frames", &self.frames), ("nominal", &self.nominal)] {
            for (name, f) in frames {
                if f.xyz_m.iter().chain(&f.rpy_rad).any(|v| !v.is_finite()) {
                    return at.fail_at(
                        &[Step::Key(table), Step::Key(name)],
                        &format!("{table}.{name}"),
                        format!("{table}.{name}: a value is not finite"),
                    );
                }
            }
        }
        Ok(())
    }

    /// The `[values]`: names the contract parses, finite values and σ ≥ 0, compliances only
    /// under a `[torque]` table, units their kind allows, only values the record's model holds.
    fn check_values(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        for v in &self.values {
            let at_value = |message: String| {
                at.fail_at(&[Step::Key("values"), Step::Key(&v.name)], &v.name, message)
            };
            let parsed = match ValueName::parse(&v.name) {
                Ok(p) => p,
                Err(message) => return at_value(format!("{:?}: {message}", v.name)),
            };
            if let Err(message) = v.check_numbers() {
                return at_value(format!("{:?}: {message}", v.name));
            }
            if parsed.is_compliance() && self.torque.is_none() && !self.is_legacy() {
                return at_value(format!(
                    "{:?} is a compliance, but the record has no [torque] table: expected \
                     the load it was identified under",
                    v.name
                ));
            }
            let torque = self.torque.as_ref().map(|t| t.source);
            if let Some(expected) = parsed.unexpected_unit(&v.unit, torque) {
                return at_value(format!(
                    "{:?} is in {:?}, expected {expected}",
                    v.name, v.unit
                ));
            }
            if let Some(model) = self.model
                && let Err(why) = model_holds(model, &parsed)
            {
                return at_value(format!(
                    "{:?}: model = \"{model}\" {why}; expected only the values of that model",
                    v.name
                ));
            }
        }
        Ok(())
    }

    /// The `[covariance]`: n(n+1)/2 entries for n names, each name a recorded value, finite
    /// entries and a non-negative diagonal.
    fn check_covariance(&self, at: &RecordText<'_>) -> Result<(), ContractError> {
        if let Some(c) = &self.covariance {
            let n = c.names.len();
            if c.lower.len() != n * (n + 1) / 2 {
                return at.fail_at(
                    &[Step::Key("covariance"), Step::Key("lower")],
                    "lower",
                    format!(
                        "covariance.lower has {} entries; {n} names need n(n+1)/2 = {}",
                        c.lower.len(),
                        n * (n + 1) / 2
                    ),
                );
            }
            for name in &c.names {
                if self.value(name).is_none() {
                    // A value renamed by hand: point at the value, not at the covariance.
                    let likeness = |v: &&CalibratedValue| {
                        let a = v.name.as_bytes();
                        let b = name.as_bytes();
                        let front = a.iter().zip(b).take_while(|(x, y)| x == y).count();
                        let back = (a.iter().rev().zip(b.iter().rev()))
                            .take_while(|(x, y)| x == y)
                            .count();
                        front + back
                    };
                    if let Some(v) = (self.values.iter())
                        .filter(|v| !c.names.contains(&v.name))
                        .max_by_key(likeness)
                    {
                        return at.fail_at(
                            &[Step::Key("values"), Step::Key(&v.name)],
                            &v.name,
                            format!(
                                "{:?} is not among the covariance's names, which name {name:?} \
                             instead: a misnamed value (expected the name the calibration \
                             recorded, {name:?})",
                                v.name
                            ),
                        );
                    }
                    return at.fail_at(
                        &[Step::Key("covariance"), Step::Key("names")],
                        "names",
                        format!("covariance names {name:?}, which is not a recorded value"),
                    );
                }
            }
            if c.lower.iter().any(|x| !x.is_finite()) || (0..n).any(|i| c.get(i, i) < 0.0) {
                return at.fail_at(
                    &[Step::Key("covariance"), Step::Key("lower")],
                    "lower",
                    "covariance.lower: expected finite entries and a non-negative diagonal"
                        .to_owned(),
                );
            }
        }
        Ok(())
    }
}

/// A record's text and where it came from, for the errors of [`Calibration::check`].
struct RecordText<'a> {
    /// The record's TOML text.
    text: &'a str,
    /// Where the text came from (a file name), for the error.
    origin: &'a str,
}

impl RecordText<'_> {
    /// An error at the value `path` names (the record's own line for it), else at the first
    /// line naming `key`.
    fn fail_at(&self, path: &[Step<'_>], key: &str, message: String) -> Result<(), ContractError> {
        let (line, column) = TomlSpans::parse(self.text)
            .record_line(path)
            .or_else(|| key_line(self.text, key))
            .unwrap_or((0, 0));
        Err(ContractError {
            origin: self.origin.to_owned(),
            line,
            column,
            message,
        })
    }

    /// An error at the top-level key `key`.
    fn fail(&self, key: &str, message: String) -> Result<(), ContractError> {
        self.fail_at(&[Step::Key(key)], key, message)
    }
}

/// Whether a record of `model` may hold the value `name`: a compliance only in a model with
/// compliances (or a haptic device's `transmissions`, its handle compliances), a transversal
/// compliance only in the transversal models, no joint harmonic in the kinematic models
/// (`frames-only`, `joint-offsets`, `geometric`) nor in `transmissions`, and only first-order
/// ones in `harmonic`; a capstan or polynomial drive only in a haptic device's
/// `transmissions` or `compliance` record; kinematic and D-H deviations in any. `Err` says
/// what the model does not hold.
fn model_holds(model: ModelName, name: &ValueName) -> Result<(), &'static str> {
    use ModelName as M;
    let compliance = matches!(
        model,
        M::Compliance
            | M::MassCompliance
            | M::ActuatorCompliance
            | M::TransversalCompliance
            | M::TransversalAxes
            | M::MassComplianceHarmonic
            | M::ComplianceHarmonic
    );
    match name {
        ValueName::Compliance { .. } if !compliance => Err("identifies no compliance"),
        ValueName::HandleCompliance { .. } if !(compliance || model == M::Transmissions) => {
            Err("identifies no compliance")
        }
        ValueName::Transversal { .. }
            if !matches!(model, M::TransversalCompliance | M::TransversalAxes) =>
        {
            Err("identifies no transversal compliance")
        }
        ValueName::Harmonic { order, .. } => match model {
            M::Harmonic if *order > 1 => Err("identifies first-order harmonics only"),
            M::FramesOnly | M::JointOffsets | M::Geometric | M::Transmissions => {
                Err("identifies no joint harmonic")
            }
            _ => Ok(()),
        },
        ValueName::Capstan { .. } | ValueName::Chebyshev { .. }
            if !matches!(model, M::Transmissions | M::Compliance) =>
        {
            Err("identifies no transmission (a haptic device's capstans and polynomial drives)")
        }
        _ => Ok(()),
    }
}

/// `[values]` as a table of `"name" = { value, std, unit }`, in file order: the serde
/// `with` module of every table of calibrated values (this record's, a device file's).
pub mod values_table {
    use std::fmt;

    use serde::de::{MapAccess, Visitor};
    use serde::ser::SerializeMap;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::CalibratedValue;

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Body {
        value: f64,
        std: f64,
        unit: String,
    }

    /// Writes the values as a table, in order.
    pub fn serialize<S: Serializer>(values: &[CalibratedValue], s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(values.len()))?;
        for v in values {
            let body = Body {
                value: v.value,
                std: v.std,
                unit: v.unit.clone(),
            };
            map.serialize_entry(&v.name, &body)?;
        }
        map.end()
    }

    /// Reads the table, in file order.
    ///
    /// # Errors
    /// An entry that is not `{ value, std, unit }`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<CalibratedValue>, D::Error> {
        struct ValuesVisitor;
        impl<'de> Visitor<'de> for ValuesVisitor {
            type Value = Vec<CalibratedValue>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a table of name = { value, std, unit }")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut values = Vec::new();
                while let Some((name, body)) = map.next_entry::<String, Body>()? {
                    values.push(CalibratedValue {
                        name,
                        value: body.value,
                        std: body.std,
                        unit: body.unit,
                    });
                }
                Ok(values)
            }
        }
        d.deserialize_map(ValuesVisitor)
    }
}
