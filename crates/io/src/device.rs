//! The device file (TOML, docs/design.md §5): kinematic chain, joint limits, transmissions,
//! measurement rig and, once calibrated, the identified values.

use std::path::Path;

use hapcal_contract::device::{BranchEntry, Convention, DeviceFile, PlacementEntry};
use hapcal_kinematics::{Chain, DhConvention, DhRow, Isometry3, Placement, Vector3};
use serde::{Deserialize, Serialize};

use crate::Error;

mod serde_helpers;
mod validate;
mod write;

#[cfg(test)]
mod tests;

pub use write::write_device;

// The tables the one device-file reader (`hapcal-contract`) reads, as this crate's device
// holds them.
pub use hapcal_contract::device::{
    CableEncoder, Capstan, DhEntry, Handle, JointRef, JointSpec, Parallelogram, UrdfSource,
};

/// A device as described by its TOML file (docs/design.md §5), lengths in m, angles in rad.
///
/// The kinematic chain is either a D-H table (`[[dh]]` rows) or URDF-style joint placements
/// (`[[placement]]` rows, usually imported with [`import_urdf`](crate::import_urdf), with
/// `[urdf]` remembering the source for [`write_calibrated_urdf`](crate::write_calibrated_urdf)).
/// A value returned by [`read_device`] has passed every check listed there; a value built
/// by hand is checked when [`Device::chain`] compiles it.
///
/// The file is read by the one device-file reader, `hapcal_contract::device::DeviceFile`
/// (unknown keys refused: a misspelt `[parallelogam]` must not vanish silently), whose tables
/// this type holds with the placements and the convention as kinematics types.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "DeviceFile")]
pub struct Device {
    /// Free-form device name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// D-H convention of the `[[dh]]` rows: `"dh"` (standard, the default) or `"mdh"`
    /// (modified). Ignored for placement chains.
    #[serde(serialize_with = "serde_helpers::serialize_convention")]
    pub convention: DhConvention,
    /// D-H rows, row 0 first (`[[dh]]`); empty for a placement chain.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dh: Vec<DhEntry>,
    /// The URDF the placements came from (`[urdf]`), for writing the calibration back.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub urdf: Option<UrdfSource>,
    /// URDF joint placements, root to tip (`[[placement]]`); empty for a D-H chain.
    #[serde(
        rename = "placement",
        serialize_with = "serde_helpers::serialize_placements",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub placements: Vec<Placement>,
    /// Further branches of a placement tree (`[[branch]]`), one per further tip: a robot with
    /// several tips (two arms on one torso). `placements` is then the path to the first tip.
    #[serde(rename = "branch", skip_serializing_if = "Vec::is_empty")]
    pub branches: Vec<Branch>,
    /// One entry per joint of the chain, in joint order (`[[joint]]`); for a tree, the joints
    /// of `placements` first, then those of each branch in order.
    #[serde(rename = "joint")]
    pub joints: Vec<JointSpec>,
    /// Capstan drives (`[[capstan]]`).
    #[serde(rename = "capstan", skip_serializing_if = "Vec::is_empty")]
    pub capstans: Vec<Capstan>,
    /// Parallelogram (four-bar) transmission (`[parallelogram]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parallelogram: Option<Parallelogram>,
    /// The cable encoder of the measurement rig (`[cable_encoder]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cable_encoder: Option<CableEncoder>,
    /// The handle, the one link not statically balanced (`[handle]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub handle: Option<Handle>,
    /// Identified values of a calibrated device (`[calibration]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Calibration>,
}

impl From<DeviceFile> for Device {
    /// The file's tables, the placements and the convention as kinematics types.
    fn from(file: DeviceFile) -> Device {
        Device {
            name: file.name,
            convention: match file.convention {
                Convention::Standard => DhConvention::Standard,
                Convention::Modified => DhConvention::Modified,
            },
            dh: file.dh,
            urdf: file.urdf,
            placements: placements_of(file.placements),
            branches: file.branches.into_iter().map(Branch::from).collect(),
            joints: file.joints,
            capstans: file.capstans,
            parallelogram: file.parallelogram,
            cable_encoder: file.cable_encoder,
            handle: file.handle,
            calibration: file.calibration,
        }
    }
}

/// The `[[placement]]` rows as kinematics placements.
fn placements_of(rows: Vec<PlacementEntry>) -> Vec<Placement> {
    (rows.into_iter())
        .map(|r| Placement {
            name: r.name,
            xyz_m: r.xyz_m,
            rpy_rad: r.rpy_rad,
            axis: r.axis,
            prismatic: r.prismatic,
        })
        .collect()
}

/// One branch of a placement tree (`[[branch]]`): the placements below the placement `from`
/// down to a further tip. Its path from the root is the path to `from` (on the main chain or
/// an earlier branch) followed by `placements`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "BranchEntry")]
pub struct Branch {
    /// The placement the branch hangs below; absent: the branch starts at the root link.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<String>,
    /// The branch's placements, root side first (`[[branch.placement]]`, as `[[placement]]`).
    #[serde(
        rename = "placement",
        serialize_with = "serde_helpers::serialize_placements",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub placements: Vec<Placement>,
}

impl From<BranchEntry> for Branch {
    /// The branch's rows, the placements as kinematics placements.
    fn from(entry: BranchEntry) -> Branch {
        Branch {
            from: entry.from,
            placements: placements_of(entry.placements),
        }
    }
}

/// The calibration record of a calibrated device (`[calibration]`): the contract's record
/// (`hapcal-contract`, docs/design.md §5.6), the same keys as a URDF's sidecar under the
/// table `[calibration]` (`[calibration.values]`, `[calibration.region]`, …).
///
/// In the file the values form the table `[calibration.values]`, one inline table per
/// parameter in identification order: `dtheta3 = { value = 1.2e-3, std = 4e-5, unit = "rad" }`.
/// A record with `schema_version` is checked by [`Calibration::check`] when the file is read;
/// one without (an earlier hapcal's: date, data hash, notes and values) is read as before.
pub use hapcal_contract::Calibration;

/// One identified value with its standard deviation, in SI units: the calibration record's
/// type (`hapcal-contract`), shared by the writer and every reader.
pub use hapcal_contract::CalibratedValue;

/// What [`Device::with_calibration`] records beside the values (a record without a schema
/// version: [`Device::with_record`] writes a full one).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CalibrationMeta {
    /// Date of the calibration.
    pub date: Option<String>,
    /// Hash of the measurement data.
    pub data_hash: Option<String>,
    /// Free text.
    pub notes: Option<String>,
}

/// Reads and checks a device file.
///
/// Checks, beyond the TOML syntax and the types: every number is finite, every length (a key
/// ending in `_m`, a value in m) and angle (`_rad`, a value in rad) within ±1000 m or rad
/// (`hapcal_contract::device::check_numbers`, the runtime's check too); the chain is
/// given by exactly one of `[[dh]]` or `[[placement]]` (`[urdf]` needs placements); D-H
/// joints are numbered 1, 2, … in row order; placement names are unique and axes non-zero;
/// the chain has at least one joint and exactly as many `[[joint]]` rows, with unique names
/// and `lower_rad < upper_rad`; capstans name existing joints (once each) with positive
/// ratio and drum distance; lengths, radii and counts are positive, the handle mass is not
/// negative; calibrated values are finite with `std ≥ 0`.
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::Toml`] for a syntax error, a missing
/// or unknown key or a value of the wrong type; [`Error::NotFinite`] for a NaN or infinite
/// number; [`Error::LengthOutOfRange`] for a length past ±[`MAX_LENGTH_M`](crate::MAX_LENGTH_M);
/// [`Error::JointCount`] if `[[joint]]` and the chain disagree on the number of
/// joints; [`Error::InvalidDevice`] for any other failed check. All name the file, line and
/// column.
pub fn read_device(path: &Path) -> Result<Device, Error> {
    let text = Error::read_text(path, toml_error(path))?;
    parse_device(&text, path)
}

/// [`Error::Toml`] in `path` at a 1-based line and column, with what the parser said.
fn toml_error(path: &Path) -> impl FnOnce(u64, u64, String) -> Error + '_ {
    move |line, column, message| Error::Toml {
        path: path.to_path_buf(),
        line,
        column,
        message,
    }
}

/// Parses and checks device-file text; `path` is only used in messages. See [`read_device`].
///
/// # Errors
///
/// As [`read_device`], except [`Error::Io`].
pub fn parse_device(text: &str, path: &Path) -> Result<Device, Error> {
    let device: Device = DeviceFile::from_toml_str(text)
        .map(Device::from)
        .map_err(|e| {
            let (line, column, message) = crate::toml_error_at(text, &e);
            toml_error(path)(line, column, message)
        })?;
    validate::validate(&device, &validate::Locator::new(path, text))?;
    Ok(device)
}

impl Device {
    /// Whether the device has transmissions between its motors and joints: capstan drives
    /// (`[[capstan]]`) or a parallelogram (`[parallelogram]`), as a haptic device of the
    /// paper's kind has (its joint angles then come from the motor encoders through them, and
    /// a haptic log's external encoders identify them).
    pub fn has_transmissions(&self) -> bool {
        !self.capstans.is_empty() || self.parallelogram.is_some()
    }

    /// The number of joints of the chain (non-fixed `[[dh]]` rows, or placements with an axis,
    /// branches included).
    pub fn n_joints(&self) -> usize {
        if self.dh.is_empty() {
            self.all_placements().filter(|p| p.axis.is_some()).count()
        } else {
            (self.dh.iter())
                .filter(|r| matches!(r.joint, JointRef::Joint(_)))
                .count()
        }
    }

    /// `(lower, upper)` limits of each `[[joint]]`, in joint order: rad, m for a prismatic
    /// joint.
    pub fn joint_limits(&self) -> Vec<(f64, f64)> {
        (self.joints.iter())
            .map(|j| (j.lower_rad, j.upper_rad))
            .collect()
    }

    /// Whether each joint of the chain, in joint order, is prismatic (a placement with an
    /// axis and `prismatic = true`; a D-H joint is revolute).
    pub fn prismatic_joints(&self) -> Vec<bool> {
        if self.dh.is_empty() {
            (self.all_placements())
                .filter(|p| p.axis.is_some())
                .map(|p| p.prismatic)
                .collect()
        } else {
            vec![false; self.n_joints()]
        }
    }

    /// The `[[dh]]` rows as [`hapcal_kinematics::DhRow`]s (with the device's convention and
    /// 0-based joint indices); empty for a placement chain.
    pub fn dh_rows(&self) -> Vec<DhRow> {
        (self.dh.iter())
            .map(|r| DhRow {
                convention: self.convention,
                a_m: r.a_m,
                alpha_rad: r.alpha_rad,
                d_m: r.d_m,
                theta_rad: r.theta_rad,
                beta_rad: r.beta_rad,
                joint: match r.joint {
                    // Joint 0 becomes an out-of-range index that `Chain::from_dh` rejects.
                    JointRef::Joint(j) => Some(j.wrapping_sub(1)),
                    JointRef::Fixed => None,
                },
            })
            .collect()
    }

    /// Every placement: those of the main chain, then those of each branch in order.
    pub fn all_placements(&self) -> impl Iterator<Item = &Placement> {
        (self.placements.iter()).chain(self.branches.iter().flat_map(|b| &b.placements))
    }

    /// The root-to-tip placement paths, one per tip: `placements`, then for each branch the
    /// path down to its `from` placement followed by its own placements (the shape
    /// [`hapcal_kinematics::Tree::from_placement_paths`] takes).
    ///
    /// # Errors
    ///
    /// [`Error::Parameter`] (named after the branch's `from`) if no placement of the main
    /// chain or of an earlier branch has that name.
    pub fn placement_paths(&self) -> Result<Vec<Vec<Placement>>, Error> {
        let mut paths = vec![self.placements.clone()];
        for branch in &self.branches {
            let mut path = match &branch.from {
                None => Vec::new(),
                Some(from) => {
                    let prefix = paths.iter().find_map(|p| {
                        let i = p.iter().position(|q| &q.name == from)?;
                        p.get(..=i)
                    });
                    let Some(prefix) = prefix else {
                        return Err(Error::Parameter {
                            name: from.clone(),
                            message: "a [[branch]] hangs from it, but no placement above the branch has that name".into(),
                        });
                    };
                    prefix.to_vec()
                }
            };
            path.extend(branch.placements.iter().cloned());
            paths.push(path);
        }
        Ok(paths)
    }

    /// The kinematic tree of a device: one tip per path of [`Device::placement_paths`] (a
    /// D-H device or a placement chain without branches: the tree of [`Device::chain`]).
    ///
    /// # Errors
    ///
    /// As [`Device::chain`] and [`Device::placement_paths`].
    pub fn tree(&self) -> Result<hapcal_kinematics::Tree, Error> {
        if self.branches.is_empty() {
            return Ok(hapcal_kinematics::Tree::single(self.chain()?));
        }
        hapcal_kinematics::Tree::from_placement_paths(&self.placement_paths()?)
            .map_err(|source| Error::Chain { source })
    }

    /// Compiles the kinematic chain: [`Chain::from_dh`] of the D-H rows, or
    /// [`Chain::from_placements`] of the placements.
    ///
    /// # Errors
    ///
    /// [`Error::Chain`] if the kinematics crate rejects the description (cannot happen for a
    /// device returned by [`read_device`] or [`import_urdf`](crate::import_urdf)).
    pub fn chain(&self) -> Result<Chain, Error> {
        let chain = if self.dh.is_empty() {
            Chain::from_placements(&self.placements)
        } else {
            Chain::from_dh(&self.dh_rows())
        };
        chain.map_err(|source| Error::Chain { source })
    }

    /// A calibrated copy: the kinematic deviations among `values` applied to the nominal
    /// rows, and `[calibration]` set to `values` and `meta` (replacing any earlier one).
    ///
    /// Kinematic names are those of [`Chain`]'s parameters. For a D-H chain, `da{i}`,
    /// `dd{i}` (unit `m`) and `dalpha{i}`, `dtheta{i}`, `dbeta{i}` (unit `rad`) add to
    /// `a_m`, `d_m`, `alpha_rad`, `theta_rad`, `beta_rad` of row `i` (a missing `beta_rad`
    /// counts as 0). For a placement chain, the deviation
    /// `Δ = Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz)` of `{name}.x` … `{name}.rz` (units `m`
    /// and `rad`) is composed onto that placement's origin: new origin = origin · Δ, written
    /// back as `xyz`/`rpy`. This holds for a revolute placement (whose Δ follows its
    /// origin) and for the tip element named after the last placement of a path (whose Δ
    /// follows the trailing fixed origins, i.e. the last one), branches included. Every other name (transmission
    /// parameters, …) is only recorded.
    ///
    /// # Errors
    ///
    /// [`Error::Parameter`] if a name appears twice, a value or std is not finite (or std
    /// is negative), a kinematic name refers to a row or placement the chain has no such
    /// parameter for (`da9` on an 8-row table, `{fixed joint}.x`), or its unit is not the
    /// parameter's.
    pub fn with_calibration(
        &self,
        values: &[CalibratedValue],
        meta: CalibrationMeta,
    ) -> Result<Device, Error> {
        let mut device = self.with_deviations(values)?;
        device.calibration = Some(Calibration {
            date: meta.date,
            data_hash: meta.data_hash,
            notes: meta.notes,
            values: values.to_vec(),
            ..Calibration::default()
        });
        Ok(device)
    }

    /// A calibrated copy carrying the whole calibration record `record` as `[calibration]`
    /// (replacing any earlier one): its kinematic values applied to the nominal rows or
    /// placements as [`Device::with_calibration`] applies them, and the record (model name,
    /// torque source, region, values, covariance, …) stored as it is, for
    /// [`write_device`] to write and [`read_device`] to check.
    ///
    /// # Errors
    /// [`Error::Contract`] if the record fails [`Calibration::check`] (an unknown value name,
    /// a wrong unit, a missing key of its schema, …); then as [`Device::with_calibration`].
    pub fn with_record(&self, record: Calibration) -> Result<Device, Error> {
        record
            .check("", "calibration record")
            .map_err(|source| Error::Contract { source })?;
        let mut device = self.with_deviations(&record.values)?;
        device.calibration = Some(record);
        Ok(device)
    }

    /// A copy with the kinematic deviations among `values` applied (see
    /// [`Device::with_calibration`]); `[calibration]` is left as it was.
    fn with_deviations(&self, values: &[CalibratedValue]) -> Result<Device, Error> {
        let mut device = self.clone();
        // Every placement, flattened as `all_placements`, with whether it carries deviations:
        // a moving joint, or the last placement of its path (a tip element).
        let mut eligible: Vec<(String, bool)> = Vec::new();
        for path in
            std::iter::once(&device.placements).chain(device.branches.iter().map(|b| &b.placements))
        {
            let n = path.len();
            for (i, p) in path.iter().enumerate() {
                eligible.push((p.name.clone(), p.axis.is_some() || i + 1 == n));
            }
        }
        let mut pending: Vec<[f64; 6]> = vec![[0.0; 6]; eligible.len()];
        for (k, v) in values.iter().enumerate() {
            let err = |message: String| Error::Parameter {
                name: v.name.clone(),
                message,
            };
            if values.iter().take(k).any(|w| w.name == v.name) {
                return Err(err("appears twice".into()));
            }
            v.check_numbers().map_err(err)?;
            let check_unit = |unit: &str| {
                if v.unit == unit {
                    Ok(())
                } else {
                    Err(err(format!("unit is {:?}, expected {unit:?}", v.unit)))
                }
            };
            if device.dh.is_empty() {
                let Some((name, kind)) = parse_placement_param(&v.name) else {
                    continue;
                };
                let index = (eligible.iter()).position(|(n, ok)| n == name && *ok);
                let Some(index) = index else {
                    return Err(err(format!(
                        "no revolute or tip placement named {name:?} carries it"
                    )));
                };
                check_unit(if kind < 3 { "m" } else { "rad" })?;
                if let Some(slot) = pending.get_mut(index).and_then(|d| d.get_mut(kind)) {
                    *slot += v.value;
                }
            } else {
                let Some((field, row)) = parse_dh_param(&v.name) else {
                    continue;
                };
                let n_rows = device.dh.len();
                let Some(entry) = device.dh.get_mut(row) else {
                    return Err(err(format!("the D-H table has rows 0..{n_rows}")));
                };
                check_unit(match field {
                    DhField::A | DhField::D => "m",
                    _ => "rad",
                })?;
                match field {
                    DhField::A => entry.a_m += v.value,
                    DhField::Alpha => entry.alpha_rad += v.value,
                    DhField::D => entry.d_m += v.value,
                    DhField::Theta => entry.theta_rad += v.value,
                    DhField::Beta => entry.beta_rad = Some(entry.beta_rad.unwrap_or(0.0) + v.value),
                }
            }
        }
        let all = (device.placements.iter_mut()).chain(
            device
                .branches
                .iter_mut()
                .flat_map(|b| b.placements.iter_mut()),
        );
        for (placement, delta) in all.zip(&pending) {
            if delta.iter().any(|d| *d != 0.0) {
                compose_deviation(placement, delta);
            }
        }
        Ok(device)
    }
}

#[derive(Clone, Copy)]
enum DhField {
    A,
    Alpha,
    D,
    Theta,
    Beta,
}

/// `dalpha3` → (Alpha, 3); names that are not D-H parameters → `None`.
fn parse_dh_param(name: &str) -> Option<(DhField, usize)> {
    // Longest prefixes first: `dalpha3` also starts with `da`.
    let prefixes = [
        ("dalpha", DhField::Alpha),
        ("dtheta", DhField::Theta),
        ("dbeta", DhField::Beta),
        ("da", DhField::A),
        ("dd", DhField::D),
    ];
    prefixes.into_iter().find_map(|(prefix, field)| {
        let digits = name.strip_prefix(prefix)?;
        let canonical = !digits.is_empty()
            && digits.bytes().all(|b| b.is_ascii_digit())
            && (digits == "0" || !digits.starts_with('0'));
        if !canonical {
            return None;
        }
        digits.parse().ok().map(|i| (field, i))
    })
}

/// `joint_a2.rx` → ("joint_a2", 3): index into `[x, y, z, rx, ry, rz]`.
fn parse_placement_param(name: &str) -> Option<(&str, usize)> {
    let (placement, suffix) = name.rsplit_once('.')?;
    let kind = ["x", "y", "z", "rx", "ry", "rz"]
        .iter()
        .position(|s| *s == suffix)?;
    Some((placement, kind))
}

/// origin ← origin · Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz), `delta = [x, y, z, rx, ry, rz]`.
fn compose_deviation(placement: &mut Placement, delta: &[f64; 6]) {
    let [x, y, z, rx, ry, rz] = *delta;
    let translation = Isometry3::translation(x, y, z);
    let rotation = Isometry3::rotation(Vector3::x() * rx)
        * Isometry3::rotation(Vector3::y() * ry)
        * Isometry3::rotation(Vector3::z() * rz);
    let origin = placement.origin() * translation * rotation;
    let t = origin.translation.vector;
    placement.xyz_m = [t.x + 0.0, t.y + 0.0, t.z + 0.0];
    if [rx, ry, rz].iter().any(|d| *d != 0.0) {
        let (roll, pitch, yaw) = origin.rotation.euler_angles();
        // `+ 0.0` turns −0 into +0, which reads better in the files.
        placement.rpy_rad = [roll + 0.0, pitch + 0.0, yaw + 0.0];
    }
}
