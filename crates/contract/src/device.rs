//! The device file's reader every crate shares (TOML, docs/design.md §5.1): its tables as
//! written ([`DeviceFile`]), parsed once ([`DeviceFile::from_toml_str`]) for `hapcal-io` (which
//! checks them and builds the kinematic chain) and the runtime (which builds its evaluated
//! model). Lengths in m, angles in rad.
//!
//! Unknown keys are refused (a misspelt `[parallelogam]` must not vanish silently).

use std::fmt;
use std::path::{Path, PathBuf};

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::Calibration;
use crate::locate::{Step, TomlSpans, dotted_name};

/// A device file's tables as written: the kinematic chain (a D-H table or URDF-style joint
/// placements), joint limits, transmissions, measurement rig and, once calibrated, the
/// calibration record. Only the types are checked here; the meaning (joints numbered in row
/// order, positive lengths, …) is the reader's.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceFile {
    /// Free-form device name.
    #[serde(default)]
    pub name: Option<String>,
    /// D-H convention of the `[[dh]]` rows (`convention = "dh" | "mdh"`; standard when absent).
    #[serde(default)]
    pub convention: Convention,
    /// D-H rows, row 0 first (`[[dh]]`).
    #[serde(default)]
    pub dh: Vec<DhEntry>,
    /// The URDF the placements came from (`[urdf]`).
    #[serde(default)]
    pub urdf: Option<UrdfSource>,
    /// URDF joint placements, root to tip (`[[placement]]`).
    #[serde(default, rename = "placement")]
    pub placements: Vec<PlacementEntry>,
    /// Further branches of a placement tree (`[[branch]]`).
    #[serde(default, rename = "branch")]
    pub branches: Vec<BranchEntry>,
    /// One entry per joint, in joint order (`[[joint]]`).
    #[serde(default, rename = "joint")]
    pub joints: Vec<JointSpec>,
    /// Capstan drives (`[[capstan]]`).
    #[serde(default, rename = "capstan")]
    pub capstans: Vec<Capstan>,
    /// Parallelogram transmission (`[parallelogram]`).
    #[serde(default)]
    pub parallelogram: Option<Parallelogram>,
    /// The cable encoder of the measurement rig (`[cable_encoder]`).
    #[serde(default)]
    pub cable_encoder: Option<CableEncoder>,
    /// The handle (`[handle]`).
    #[serde(default)]
    pub handle: Option<Handle>,
    /// The calibration record of a calibrated device (`[calibration]`, not yet checked:
    /// [`Calibration::check`]).
    #[serde(default)]
    pub calibration: Option<Calibration>,
}

impl DeviceFile {
    /// Parses a device file's text: TOML syntax, keys and types.
    ///
    /// # Errors
    /// TOML's error: syntax, a missing or unknown key, a value of the wrong type, an unknown
    /// convention or a `[[dh]]` joint that is neither a number ≥ 1 nor `"fixed"`; its span
    /// locates it in `text`.
    pub fn from_toml_str(text: &str) -> Result<DeviceFile, toml::de::Error> {
        toml::from_str(text)
    }
}

/// Largest magnitude of a length (m) or an angle (rad) that a device file may hold: a key
/// ending in `_m` or `_rad`, or the `value` of a calibrated value whose unit is `m` or `rad`.
/// 1 km or 1000 rad (about 159 turns) is a typo or a unit mistake (micrometres read as
/// metres) on any device, and such numbers reach the kinematics as squares that overflow.
pub const MAX_MAGNITUDE: f64 = 1e3;

/// A number of a device file that no reader accepts ([`check_numbers`]): not finite, or a
/// length or an angle past ±[`MAX_MAGNITUDE`]. Displayed as what was expected and found,
/// without the file's place (the reader's error gives it).
#[derive(Clone, Debug, PartialEq)]
pub struct BadNumber {
    /// Dotted name of its key (`dh[1].d_m`, `calibration.values.da0.value`).
    pub name: String,
    /// 1-based line of the value.
    pub line: usize,
    /// 1-based column of the value.
    pub column: usize,
    /// The value as read.
    pub value: f64,
    /// `Some("m")` or `Some("rad")` for a finite length or angle past ±[`MAX_MAGNITUDE`];
    /// `None` for a number that is not finite.
    pub past_bound: Option<&'static str>,
}

impl fmt::Display for BadNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (name, value) = (&self.name, self.value);
        match self.past_bound {
            None => write!(f, "expected a finite number in {name:?}, found {value}"),
            Some(unit) => {
                let kind = if unit == "m" { "a length" } else { "an angle" };
                write!(
                    f,
                    "{name} = {value:e} {unit} is out of range: {kind} must lie within \
                     ±{MAX_MAGNITUDE} {unit}"
                )
            }
        }
    }
}

/// Checks every number of a device file's text: each float finite, each length or angle (a
/// key ending in `_m` or `_rad`; a calibrated value's `value` in `m` or `rad`) within
/// ±[`MAX_MAGNITUDE`]. The one check of a device file's numbers, for `hapcal-io` and the
/// runtime; text that is not TOML passes (the typed reader reports its syntax).
///
/// # Errors
/// The first [`BadNumber`] in file order, at its line and column.
pub fn check_numbers(text: &str) -> Result<(), BadNumber> {
    let Ok(root) = toml::from_str::<toml::Table>(text) else {
        return Ok(());
    };
    let mut path = Vec::new();
    let Some((path, value, past_bound)) = first_bad_in_table(&root, &mut path) else {
        return Ok(());
    };
    let (line, column) = TomlSpans::parse(text).line_column(&path).unwrap_or((1, 1));
    Err(BadNumber {
        name: dotted_name(&path),
        line,
        column,
        value,
        past_bound,
    })
}

/// A refused number of [`check_numbers`] in `table`: its key path, value and bound's unit.
type Found<'a> = (Vec<Step<'a>>, f64, Option<&'static str>);

/// The first number of `table` (at `path`) that [`check_numbers`] refuses.
fn first_bad_in_table<'a>(table: &'a toml::Table, path: &mut Vec<Step<'a>>) -> Option<Found<'a>> {
    let unit = match table.get("unit").and_then(toml::Value::as_str) {
        Some("m") => Some("m"),
        Some("rad") => Some("rad"),
        _ => None,
    };
    for (key, value) in table {
        path.push(Step::Key(key));
        let bound = if key.ends_with("_m") {
            Some("m")
        } else if key.ends_with("_rad") {
            Some("rad")
        } else if key == "value" {
            unit
        } else {
            None
        };
        if let Some(found) = first_bad_in_value(value, bound, path) {
            return Some(found);
        }
        path.pop();
    }
    None
}

/// The first number of `value` (at `path`, bounded in `bound`'s unit if any) that
/// [`check_numbers`] refuses.
fn first_bad_in_value<'a>(
    value: &'a toml::Value,
    bound: Option<&'static str>,
    path: &mut Vec<Step<'a>>,
) -> Option<Found<'a>> {
    match value {
        toml::Value::Float(v) if !v.is_finite() => Some((path.clone(), *v, None)),
        toml::Value::Float(v) if bound.is_some() && v.abs() > MAX_MAGNITUDE => {
            Some((path.clone(), *v, bound))
        }
        // A length written without a decimal point (`a_m = 5000`) is read as a number too.
        toml::Value::Integer(i) if bound.is_some() && i.unsigned_abs() as f64 > MAX_MAGNITUDE => {
            Some((path.clone(), *i as f64, bound))
        }
        toml::Value::Table(t) => first_bad_in_table(t, path),
        toml::Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.push(Step::Index(i));
                if let Some(found) = first_bad_in_value(item, bound, path) {
                    return Some(found);
                }
                path.pop();
            }
            None
        }
        _ => None,
    }
}

/// The D-H convention of a device file's `[[dh]]` rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Convention {
    /// Standard D-H (`"dh"`, the default): `Rz(θ + q)·Tz(d)·Tx(a)·Rx(α)·Ry(β)`.
    #[default]
    Standard,
    /// Modified D-H (`"mdh"`, Craig): `Rx(α)·Ry(β)·Tx(a)·Rz(θ + q)·Tz(d)`.
    Modified,
}

impl Convention {
    /// The name as the file writes it: `dh` or `mdh`.
    pub fn name(self) -> &'static str {
        match self {
            Convention::Standard => "dh",
            Convention::Modified => "mdh",
        }
    }
}

impl Serialize for Convention {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Convention {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Convention, D::Error> {
        let text = String::deserialize(d)?;
        match text.as_str() {
            "dh" => Ok(Convention::Standard),
            "mdh" => Ok(Convention::Modified),
            other => Err(de::Error::custom(format!(
                "unknown convention {other:?}, expected \"dh\" (standard) or \"mdh\" (modified)"
            ))),
        }
    }
}

/// One `[[dh]]` row as written in the device file (docs/design.md §2, paper eq. 3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DhEntry {
    /// Link length `a`, m.
    pub a_m: f64,
    /// Link twist `alpha`, rad.
    pub alpha_rad: f64,
    /// Link offset `d`, m.
    pub d_m: f64,
    /// Joint angle offset `theta`, rad (the joint reading is added to it).
    pub theta_rad: f64,
    /// Hayati `beta`, rad, for near-parallel consecutive axes; absent = no beta.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beta_rad: Option<f64>,
    /// The row's joint: a 1-based joint number or `"fixed"`.
    pub joint: JointRef,
}

/// Which joint a `[[dh]]` row carries: `joint = 3` or `joint = "fixed"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointRef {
    /// Revolute joint number, 1-based (`q1` is joint 1); 0 is invalid.
    Joint(usize),
    /// No joint: a constant transform (e.g. row 0, rig → base).
    Fixed,
}

impl fmt::Display for JointRef {
    /// As the file writes it: `3` or `"fixed"`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            JointRef::Joint(j) => write!(f, "{j}"),
            JointRef::Fixed => f.write_str("\"fixed\""),
        }
    }
}

impl Serialize for JointRef {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            JointRef::Joint(j) => s.serialize_u64(*j as u64),
            JointRef::Fixed => s.serialize_str("fixed"),
        }
    }
}

impl<'de> Deserialize<'de> for JointRef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct JointVisitor;
        impl Visitor<'_> for JointVisitor {
            type Value = JointRef;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a joint number 1, 2, … or \"fixed\"")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<JointRef, E> {
                match usize::try_from(v) {
                    Ok(j) if j >= 1 => Ok(JointRef::Joint(j)),
                    _ => Err(E::custom(format!(
                        "joint number {v} is invalid, expected 1, 2, … or \"fixed\""
                    ))),
                }
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<JointRef, E> {
                match usize::try_from(v) {
                    Ok(j) if j >= 1 => Ok(JointRef::Joint(j)),
                    _ => Err(E::custom(format!(
                        "joint number {v} is invalid, expected 1, 2, … or \"fixed\""
                    ))),
                }
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<JointRef, E> {
                if v == "fixed" {
                    Ok(JointRef::Fixed)
                } else {
                    Err(E::custom(format!(
                        "joint {v:?} is invalid, expected a joint number 1, 2, … or \"fixed\""
                    )))
                }
            }
        }
        d.deserialize_any(JointVisitor)
    }
}

/// Where a placement chain came from (`[urdf]`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrdfSource {
    /// The URDF file, relative to the device file's folder (or absolute).
    pub path: PathBuf,
    /// The link whose origin is the chain's tip.
    pub tip: String,
}

impl UrdfSource {
    /// The URDF's path for a device read from `device_file`: `path` itself if absolute,
    /// else `path` relative to `device_file`'s folder.
    pub fn resolve(&self, device_file: &Path) -> PathBuf {
        if self.path.is_absolute() {
            return self.path.clone();
        }
        match device_file.parent() {
            Some(dir) => dir.join(&self.path),
            None => self.path.clone(),
        }
    }
}

/// One `[[placement]]` row: a URDF joint's `<origin>` and, for a moving joint, its axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacementEntry {
    /// The joint's name.
    pub name: String,
    /// Translation of the origin, m.
    pub xyz_m: [f64; 3],
    /// Roll, pitch, yaw of the origin, rad (`R = Rz(yaw)·Ry(pitch)·Rx(roll)`).
    pub rpy_rad: [f64; 3],
    /// The joint's axis in its frame; absent for a fixed joint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<[f64; 3]>,
    /// Whether the joint slides along its axis (m) instead of turning about it (rad).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub prismatic: bool,
}

/// One `[[branch]]`: the placements below the placement `from` down to a further tip.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BranchEntry {
    /// The placement the branch hangs below; absent: the branch starts at the root link.
    #[serde(default)]
    pub from: Option<String>,
    /// The branch's placements, root side first (`[[branch.placement]]`).
    #[serde(default, rename = "placement")]
    pub placements: Vec<PlacementEntry>,
}

/// One `[[joint]]`: name, limits and encoder of a joint, in joint order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Joint name (`q1`, `joint_a1`, …), used in messages.
    pub name: String,
    /// Lower joint limit, rad; m for a prismatic joint, whose file keys are `lower_m` and
    /// `upper_m`.
    #[serde(alias = "lower_m")]
    pub lower_rad: f64,
    /// Upper joint limit, rad; m for a prismatic joint (> `lower_rad`).
    #[serde(alias = "upper_m")]
    pub upper_rad: f64,
    /// Encoder counts per revolution of the encoder shaft (the motor, for a capstan joint:
    /// docs/design.md §2), if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub counts_per_rev: Option<u32>,
}

/// One capstan drive (`[[capstan]]`, paper eq. 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Capstan {
    /// The driven joint, 1-based.
    pub joint: usize,
    /// Transmission ratio `R` (motor angle / joint angle), > 0.
    pub ratio: f64,
    /// Distance `D` between the drum centres, m, > 0.
    pub drum_distance_m: f64,
}

/// The parallelogram (four-bar) driving joint 4 (`[parallelogram]`, paper eq. 2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Parallelogram {
    /// Crank length `L1`, m.
    pub l1_m: f64,
    /// Coupler length `L2`, m.
    pub l2_m: f64,
    /// Rocker length `L3`, m.
    pub l3_m: f64,
    /// Ground length `L4`, m.
    pub l4_m: f64,
}

/// The cable encoder measuring the distance to the end point (`[cable_encoder]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CableEncoder {
    /// Drum radius `R_d`, m.
    pub drum_radius_m: f64,
    /// Encoder counts per drum revolution.
    pub counts_per_rev: u32,
}

/// The handle (`[handle]`): a point mass at the end point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Handle {
    /// Mass, kg (≥ 0).
    pub mass_kg: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dh_file_reads_its_tables() -> Result<(), Box<dyn std::error::Error>> {
        let file = DeviceFile::from_toml_str(
            "convention = \"mdh\"\n\
             [[dh]]\na_m = 0.1\nalpha_rad = 0.0\nd_m = 0.2\ntheta_rad = 0.0\njoint = \"fixed\"\n\
             [[dh]]\na_m = 0.0\nalpha_rad = 1.5\nd_m = 0.0\ntheta_rad = 0.0\njoint = 1\n\
             [[joint]]\nname = \"q1\"\nlower_rad = -1.0\nupper_rad = 2.0\n",
        )?;
        assert_eq!(file.convention, Convention::Modified);
        assert_eq!(file.dh[0].joint, JointRef::Fixed);
        assert_eq!(file.dh[1].joint, JointRef::Joint(1));
        assert_eq!(
            (file.joints[0].lower_rad, file.joints[0].upper_rad),
            (-1.0, 2.0)
        );
        assert_eq!(
            DeviceFile::from_toml_str("")?.convention,
            Convention::Standard
        );
        Ok(())
    }

    #[test]
    fn every_number_is_finite_and_lengths_and_angles_are_bounded() {
        let fault = |text: &str| check_numbers(text).err().map(|e| e.to_string());
        assert_eq!(fault("[[dh]]\na_m = 0.5\ntheta_rad = -3.0\n"), None);
        assert_eq!(
            fault("[[dh]]\na_m = 0.5\n\n[[dh]]\nd_m = nan\n"),
            Some("expected a finite number in \"dh[1].d_m\", found NaN".to_owned())
        );
        let e = check_numbers("x = 1\n[[joint]]\nname = \"q1\"\nupper_rad = 1e308\n").err();
        assert_eq!(e.as_ref().map(|e| (e.line, e.column)), Some((4, 13)));
        assert_eq!(
            e.map(|e| e.to_string()),
            Some("joint[0].upper_rad = 1e308 rad is out of range: an angle must lie within ±1000 rad".to_owned())
        );
        // A calibrated value is bounded by its unit; a count is not a length.
        let value = |unit: &str| {
            format!("[calibration.values]\nda0 = {{ value = 2e3, std = 0.0, unit = \"{unit}\" }}\n")
        };
        assert!(
            fault(&value("m"))
                .is_some_and(|m| m.starts_with("calibration.values.da0.value = 2e3 m"))
        );
        assert_eq!(fault(&value("1")), None);
        assert_eq!(fault("counts_per_rev = 4096\nratio = 1e9\n"), None);
        assert!(fault("[[dh]]\na_m = 5000\n").is_some_and(|m| m.starts_with("dh[0].a_m = 5e3 m")));
        assert_eq!(fault("a = ["), None);
    }

    #[test]
    fn a_bad_convention_or_joint_is_refused_by_name() {
        let message = |text: &str| {
            DeviceFile::from_toml_str(text)
                .map_or_else(|e| e.message().to_owned(), |_| String::new())
        };
        assert!(message("convention = \"craig\"").starts_with("unknown convention \"craig\""));
        assert!(
            message("[[dh]]\na_m = 0.0\nalpha_rad = 0.0\nd_m = 0.0\ntheta_rad = 0.0\njoint = 0\n")
                .starts_with("joint number 0 is invalid")
        );
        assert!(message("[parallelogam]\n").starts_with("unknown field `parallelogam`"));
    }
}
