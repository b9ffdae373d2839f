//! Loading a device file (TOML, docs/design.md §5.1), as `hapcal calibrate` writes it.

use serde::Deserialize;
use serde::de::IgnoredAny;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::{CapstanParams, DhConvention, DhRow, Drive, Error, Model};

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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    #[expect(
        dead_code,
        reason = "read so that the key is known; the runtime needs no name"
    )]
    name: Option<String>,
    #[serde(default)]
    convention: Option<String>,
    #[serde(default)]
    dh: Vec<DhEntry>,
    #[serde(default)]
    urdf: Option<IgnoredAny>,
    #[serde(default)]
    placement: Vec<IgnoredAny>,
    #[serde(default)]
    branch: Vec<IgnoredAny>,
    #[serde(default)]
    joint: Vec<JointEntry>,
    #[serde(default)]
    capstan: Vec<CapstanEntry>,
    #[serde(default)]
    #[expect(
        dead_code,
        reason = "the calibrated joint 4 is a polynomial; nominal: a capstan"
    )]
    parallelogram: Option<IgnoredAny>,
    #[serde(default)]
    #[expect(
        dead_code,
        reason = "the measurement rig: not part of the evaluated model"
    )]
    cable_encoder: Option<IgnoredAny>,
    #[serde(default)]
    #[expect(dead_code, reason = "gravity is left out, as in the force study")]
    handle: Option<IgnoredAny>,
    #[serde(default)]
    calibration: Option<Calibration>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DhEntry {
    a_m: f64,
    alpha_rad: f64,
    d_m: f64,
    theta_rad: f64,
    #[serde(default)]
    beta_rad: Option<f64>,
    joint: toml::Value,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JointEntry {
    name: String,
    lower_rad: f64,
    upper_rad: f64,
    #[serde(default)]
    #[expect(
        dead_code,
        reason = "readings arrive in rad; the resolution is not needed"
    )]
    counts_per_rev: Option<u32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CapstanEntry {
    joint: usize,
    ratio: f64,
    drum_distance_m: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Calibration {
    #[serde(default)]
    #[expect(dead_code, reason = "metadata")]
    date: Option<String>,
    #[serde(default)]
    #[expect(dead_code, reason = "metadata")]
    data_hash: Option<String>,
    #[serde(default)]
    #[expect(dead_code, reason = "metadata")]
    notes: Option<String>,
    #[serde(default)]
    values: toml::Table,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Value {
    value: f64,
    std: f64,
    unit: String,
}

/// The drive of one joint while the calibration is read.
enum Pending {
    Direct,
    Capstan {
        ratio: f64,
        drum_distance_m: f64,
        params: CapstanParams,
    },
}

/// 1-based line and column of byte `offset` in `text`.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = text.get(..offset).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

impl Model {
    /// Loads a device file (`fixtures/reference-device/calibrated.toml`, or any device
    /// file with a `[[dh]]` chain) into a model: see [`Model::from_toml`].
    ///
    /// # Errors
    /// [`LoadError::Io`] if the file cannot be read; otherwise as [`Model::from_toml`],
    /// with the path as origin.
    pub fn load(path: &Path) -> Result<Model, LoadError> {
        let text = std::fs::read_to_string(path).map_err(|e| LoadError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
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
    /// - every other joint direct.
    ///
    /// Kinematic names (`da1`, `dtheta3`, …) are skipped: the rows already hold them. A file
    /// without `[calibration]` gives the nominal model (ideal capstans). `origin` names the
    /// text in messages.
    ///
    /// # Errors
    /// [`LoadError::Parse`] for TOML syntax, a missing or unknown key or a wrong type;
    /// [`LoadError::Invalid`] for a `[[placement]]` chain (not supported by the runtime),
    /// joints not numbered 1, 2, … in row order, a `[[joint]]` count that differs from the
    /// chain's, `lower_rad ≥ upper_rad`, a capstan on a missing joint or twice on one, a
    /// calibrated value with an unknown capstan field, a wrong unit, a joint without a
    /// capstan, a gap in the Chebyshev indices, or a model value [`Model::from_dh`] or
    /// [`Drive`] refuses.
    pub fn from_toml(text: &str, origin: &str) -> Result<Model, LoadError> {
        let file: File = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map_or((0, 0), |span| line_column(text, span.start));
            LoadError::Parse {
                origin: origin.to_owned(),
                line,
                column,
                message: e.message().trim_end().to_owned(),
            }
        })?;
        let invalid = |message: String| LoadError::Invalid {
            origin: origin.to_owned(),
            message,
        };
        let model_error = |what: &str, e: Error| invalid(format!("{what}: {e}"));

        if !file.placement.is_empty() || !file.branch.is_empty() || file.urdf.is_some() {
            return Err(invalid(
                "[[placement]] (URDF) chains are not supported by the runtime: use a [[dh]] \
                 chain"
                    .to_owned(),
            ));
        }
        let convention = match file.convention.as_deref() {
            None | Some("dh") => DhConvention::Standard,
            Some("mdh") => DhConvention::Modified,
            Some(other) => {
                return Err(invalid(format!(
                    "unknown convention {other:?}, expected \"dh\" (standard) or \"mdh\" \
                     (modified)"
                )));
            }
        };
        let mut rows = Vec::with_capacity(file.dh.len());
        let mut n_joints = 0usize;
        for (i, entry) in file.dh.iter().enumerate() {
            let joint = match &entry.joint {
                toml::Value::String(s) if s == "fixed" => false,
                toml::Value::Integer(j) if usize::try_from(*j).ok() == Some(n_joints + 1) => true,
                other => {
                    return Err(invalid(format!(
                        "[[dh]] row {i}: joint = {other}, expected {} (joints numbered in row \
                         order) or \"fixed\"",
                        n_joints + 1
                    )));
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
        if file.joint.len() != n_joints {
            return Err(invalid(format!(
                "the chain has {n_joints} joints but {} [[joint]] entries",
                file.joint.len()
            )));
        }
        for j in &file.joint {
            if !j.lower_rad.is_finite() || !j.upper_rad.is_finite() || j.lower_rad >= j.upper_rad {
                return Err(invalid(format!(
                    "[[joint]] {:?}: lower_rad = {} must be finite and below upper_rad = {}",
                    j.name, j.lower_rad, j.upper_rad
                )));
            }
        }
        let mut pending: Vec<Pending> = (0..n_joints).map(|_| Pending::Direct).collect();
        for c in &file.capstan {
            let slot = (c.joint.checked_sub(1))
                .and_then(|j| pending.get_mut(j))
                .ok_or_else(|| {
                    invalid(format!(
                        "[[capstan]] on joint {}: the device has joints 1..={n_joints}",
                        c.joint
                    ))
                })?;
            if matches!(slot, Pending::Capstan { .. }) {
                return Err(invalid(format!(
                    "two [[capstan]] entries on joint {}",
                    c.joint
                )));
            }
            *slot = Pending::Capstan {
                ratio: c.ratio,
                drum_distance_m: c.drum_distance_m,
                params: CapstanParams::default(),
            };
        }

        let mut cheb: Vec<Vec<Option<f64>>> = vec![Vec::new(); n_joints];
        let values = file.calibration.map(|c| c.values).unwrap_or_default();
        for (name, raw) in values {
            let bad = |message: String| invalid(format!("[calibration.values] {name}: {message}"));
            let v = Value::deserialize(raw).map_err(|e| bad(e.message().trim_end().to_owned()))?;
            if !v.value.is_finite() || !v.std.is_finite() || v.std < 0.0 {
                return Err(bad(format!(
                    "value {} with std {} must be finite, std ≥ 0",
                    v.value, v.std
                )));
            }
            let check_unit = |unit: &str| {
                if v.unit == unit {
                    Ok(())
                } else {
                    Err(bad(format!("unit is {:?}, expected {unit:?}", v.unit)))
                }
            };
            let Some((element, field)) = name.split_once('.') else {
                continue; // a kinematic deviation, already in the rows
            };
            let joint_of =
                |prefix: &str| (element.strip_prefix(prefix)).and_then(|d| d.parse::<usize>().ok());
            if let Some(joint) = joint_of("capstan") {
                let slot = (joint.checked_sub(1))
                    .and_then(|j| pending.get_mut(j))
                    .ok_or_else(|| bad(format!("the device has joints 1..={n_joints}")))?;
                let Pending::Capstan { params, .. } = slot else {
                    return Err(bad(format!("joint {joint} has no capstan")));
                };
                let (target, unit) = match field {
                    "c" => (&mut params.c_rad, "rad"),
                    "re" => (&mut params.re, "1"),
                    "r_o" => (&mut params.r_o_m, "m"),
                    "beta_o" => (&mut params.beta_o_rad, "rad"),
                    "r_i" => (&mut params.r_i_m, "m"),
                    "beta_i" => (&mut params.beta_i_rad, "rad"),
                    other => {
                        return Err(bad(format!(
                            "unknown capstan parameter {other:?}: expected c, re, r_o, beta_o, \
                             r_i or beta_i"
                        )));
                    }
                };
                check_unit(unit)?;
                *target = v.value;
            } else if let Some(joint) = joint_of("joint") {
                let Some(k) = (field.strip_prefix("cheb")).and_then(|d| d.parse::<usize>().ok())
                else {
                    return Err(bad("expected joint{j}.cheb{k}".to_owned()));
                };
                check_unit("rad")?;
                let coeffs = (joint.checked_sub(1))
                    .and_then(|j| cheb.get_mut(j))
                    .ok_or_else(|| bad(format!("the device has joints 1..={n_joints}")))?;
                if k >= crate::MAX_COEFFS {
                    return Err(bad(format!(
                        "the runtime holds at most {} coefficients",
                        crate::MAX_COEFFS
                    )));
                }
                if coeffs.len() <= k {
                    coeffs.resize(k + 1, None);
                }
                coeffs[k] = Some(v.value);
            }
        }

        let mut drives = Vec::with_capacity(n_joints);
        for (j, (p, coeffs)) in pending.iter().zip(&cheb).enumerate() {
            let joint = j + 1;
            let ratio = match p {
                Pending::Direct => 1.0,
                Pending::Capstan { ratio, .. } => *ratio,
            };
            let drive = if coeffs.is_empty() {
                match p {
                    Pending::Direct => Ok(Drive::DIRECT),
                    Pending::Capstan {
                        ratio,
                        drum_distance_m,
                        params,
                    } => Drive::capstan(*ratio, *drum_distance_m, *params),
                }
                .map_err(|e| model_error(&format!("capstan{joint}"), e))?
            } else {
                let mut dense = [0.0; crate::MAX_COEFFS];
                for (k, c) in coeffs.iter().enumerate() {
                    dense[k] = c.ok_or_else(|| {
                        invalid(format!(
                            "joint{joint}.cheb{k} is missing (coefficients 0..={})",
                            coeffs.len() - 1
                        ))
                    })?;
                }
                let limits = &file.joint[j];
                Drive::polynomial(
                    ratio,
                    limits.lower_rad,
                    limits.upper_rad,
                    &dense[..coeffs.len()],
                )
                .map_err(|e| model_error(&format!("joint{joint}.cheb*"), e))?
            };
            drives.push(drive);
        }
        Model::from_dh(convention, &rows, &drives).map_err(|e| model_error("[[dh]]", e))
    }
}
