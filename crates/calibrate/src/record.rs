//! The calibration record of a calibration on measurement files (`hapcal-contract`,
//! docs/design.md §5.6): what `hapcal calibrate --out` writes beside the calibrated URDF so
//! that the runtime, `predict` and `compensate` evaluate the model that was identified; the
//! files that carry it, and the runtime's robot (a haptic device's model) of them, which the
//! report's calibrated figures are evaluated with.

use hapcal_contract::{
    Calibration, Covariance, Frame, JointRange, ModelName, PointMass, Region, SCHEMA_VERSION,
    Torque, TorqueSource, ValueName,
};
use hapcal_problems::CalibratedModel;

use anyhow::{Context, Result, bail};
use hapcal_kinematics::{Isometry3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

use crate::report::{FrameReport, Outcome, ParamReport};

/// Standard gravity, m/s² (CGPM 1901): the acceleration of the link masses' loads.
const STANDARD_GRAVITY: f64 = 9.806_65;

/// What a calibration on measurement files found, as the record needs it.
pub(crate) struct MeasuredRecord<'a> {
    /// The rung identified.
    pub model: ModelName,
    /// The calibration's tip links, in marker order.
    pub tips: &'a [String],
    /// Tips after `tips` that carry loads only ([`crate::data::Robot::load_tips`]).
    pub load_tips: &'a [String],
    /// The joints' names, in the order of the readings.
    pub joint_names: &'a [String],
    /// Whether each joint is prismatic (its range in m).
    pub prismatic: &'a [bool],
    /// The calibrated model (its compliance's loads and equilibrium).
    pub calibrated: &'a CalibratedModel,
    /// The identified values with their σ, as the report lists them (frames excluded).
    pub parameters: &'a [ParamReport],
    /// The identification's covariance over its free parameters (frames included).
    pub covariance: &'a hapcal_identify::Covariance,
    /// The identified instrument and marker frames.
    pub frames: &'a [FrameReport],
    /// The frames' identified deviations from their nominal guesses (`instrument.x` …
    /// `marker<k>.rz`) with their σ: recorded so that a prediction in the instrument frame
    /// carries the frames' uncertainty.
    pub frame_values: &'a [ParamReport],
    /// The values the final identification held at its warm start rather than estimated
    /// ([`held_values`]): part of the model all the same.
    pub held: Vec<ParamReport>,
    /// Each joint's training range, rad or m (`training_ranges`).
    pub ranges: Vec<(f64, f64)>,
    /// Number of training rows.
    pub rows: usize,
}

/// The schema-1 record of a calibration on measurement files: the model, the tips, the
/// compliances' torque source with the point masses it used, the training region, the frames,
/// every value as identified (kinematic values are also applied to the written URDF's joint
/// origins; `.offset`s fold into them) and the covariance of those values.
pub(crate) fn measured_record(m: &MeasuredRecord<'_>) -> Calibration {
    let torque = m.calibrated.compliance.as_ref().map(|(g, _)| {
        let source = if g.masses.is_empty() {
            TorqueSource::LumpedUnitWeights
        } else if matches!(
            m.model,
            ModelName::MassCompliance
                | ModelName::ActuatorCompliance
                | ModelName::MassComplianceHarmonic
        ) {
            TorqueSource::PublishedMasses
        } else {
            TorqueSource::UrdfMasses
        };
        Torque {
            source,
            // `+ 0.0` writes −0 as 0.
            gravity_direction: [
                g.gravity_dir.x + 0.0,
                g.gravity_dir.y + 0.0,
                g.gravity_dir.z + 0.0,
            ],
            gravity_m_s2: STANDARD_GRAVITY,
            equilibrium: m.calibrated.equilibrium,
            tips: m.tips.iter().chain(m.load_tips).cloned().collect(),
            masses: (g.masses.iter())
                .map(|l| PointMass {
                    joint: m.joint_names[l.joint].clone(),
                    mass_kg: l.mass_kg,
                    com_m: l.com_m.into(),
                })
                .collect(),
            handle_mass_kg: None,
        }
    });
    let compliance_unit = torque.as_ref().map(|t| t.source.compliance_unit());
    let values: Vec<hapcal_contract::CalibratedValue> = (m.parameters.iter())
        .chain(m.frame_values)
        .map(|p| value_of(p, compliance_unit, p.std))
        .collect();
    // A value the final identification held rather than estimated (its warm start from an
    // earlier fit: a per-axis compliance at the isotropic rung's estimate, a value the torque
    // equilibrium's refits moved) is part of the model all the same: recorded with σ 0,
    // outside the covariance; so is a kinematic value held outside the identification.
    let mut values = values;
    for p in &m.held {
        if !values.iter().any(|v| v.name == p.name) {
            values.push(value_of(p, compliance_unit, 0.0));
        }
    }
    let chain = m.calibrated.tips.first().unwrap_or(&m.calibrated.chain);
    for (p, &x) in chain.params().iter().zip(&m.calibrated.x_kin) {
        let frame = crate::report::is_frame_param(&p.name);
        if x != 0.0 && !frame && !values.iter().any(|v| v.name == p.name) {
            values.push(hapcal_contract::CalibratedValue {
                name: p.name.clone(),
                value: x,
                std: 0.0,
                unit: p.unit.symbol().to_owned(),
            });
        }
    }
    let region = Region {
        rows: m.rows,
        joints: (m.joint_names.iter().zip(&m.ranges))
            .zip(m.prismatic)
            .map(|((name, &(min, max)), &prismatic)| JointRange {
                name: name.clone(),
                min,
                max,
                unit: if prismatic { "m" } else { "rad" }.to_owned(),
            })
            .collect(),
    };
    Calibration {
        schema_version: Some(SCHEMA_VERSION),
        model: Some(m.model),
        date: None,
        data_hash: None,
        notes: Some(format!("hapcal calibrate, model {}", m.model)),
        tips: m.tips.to_vec(),
        // Set when the record is written beside its URDF (`write_outputs`), as the nominal
        // origins.
        urdf_digest: None,
        nominal: std::collections::BTreeMap::new(),
        torque,
        region: Some(region),
        frames: (m.frames.iter())
            .map(|f| {
                (
                    f.name.clone(),
                    Frame {
                        xyz_m: f.xyz_m,
                        rpy_rad: f.rpy_rad,
                    },
                )
            })
            .collect(),
        covariance: covariance_of(m.covariance, &values),
        values,
    }
}

/// `record` bound to the calibrated URDF `urdf` it is written beside: with the URDF's digest
/// ([`hapcal_contract::digest`]) and the nominal origin (`device`'s placement, the URDF the
/// calibration started from) of every joint its values deviate, so that a reader refuses the
/// record beside another URDF and a value edited in one of the two files.
pub(crate) fn bound_record(
    record: &Calibration,
    urdf: &str,
    device: &hapcal_io::Device,
) -> Calibration {
    let mut nominal = std::collections::BTreeMap::new();
    for v in &record.values {
        if let Ok(hapcal_contract::ValueName::Element { element, .. }) =
            hapcal_contract::ValueName::parse(&v.name)
            && let Some(p) = device.all_placements().find(|p| p.name == element)
        {
            nominal.insert(
                element,
                Frame {
                    xyz_m: p.xyz_m,
                    rpy_rad: p.rpy_rad,
                },
            );
        }
    }
    Calibration {
        urdf_digest: Some(hapcal_contract::digest(urdf.as_bytes())),
        nominal,
        ..record.clone()
    }
}

/// The values of `id` that its rank decision pruned but that are not zero (their warm start
/// from an earlier fit, which the fit held), frames (`instrument.*`, `marker*`) excluded:
/// each with σ 0 and its unit's symbol.
pub(crate) fn held_values(id: &hapcal_identify::Identified) -> Vec<ParamReport> {
    (0..id.layout.len())
        .filter(|i| !id.covariance.free.contains(i))
        .filter(|&i| id.fit.x[i] != 0.0 && !crate::report::is_frame_param(id.layout.name(i)))
        .map(|i| ParamReport {
            name: id.layout.name(i).to_owned(),
            value: id.fit.x[i],
            std: 0.0,
            unit: id.layout.spec(i).unit.symbol(),
        })
        .collect()
}

/// The record's value of `p` with standard deviation `std`, in the unit of the torque source
/// `compliance_unit` for a compliance.
fn value_of(
    p: &ParamReport,
    compliance_unit: Option<&str>,
    std: f64,
) -> hapcal_contract::CalibratedValue {
    hapcal_contract::CalibratedValue {
        name: p.name.clone(),
        value: p.value,
        std,
        unit: match (compliance_unit, ValueName::parse(&p.name)) {
            (Some(unit), Ok(ValueName::Compliance { .. } | ValueName::Transversal { .. })) => {
                unit.to_owned()
            }
            _ => p.unit.to_string(),
        },
    }
}

/// The covariance block, in full, of the recorded `values` the identification estimated (its
/// free parameters); a value it held (σ 0) is exact to the model and stays outside. `None` when it estimated none of them.
fn covariance_of(
    cov: &hapcal_identify::Covariance,
    values: &[hapcal_contract::CalibratedValue],
) -> Option<Covariance> {
    let (names, index): (Vec<String>, Vec<usize>) = (values.iter())
        .filter_map(|v| {
            let i = cov.names.iter().position(|n| *n == v.name)?;
            Some((v.name.clone(), i))
        })
        .unzip();
    if index.is_empty() {
        return None;
    }
    let k = index.len();
    let mut matrix = vec![0.0; k * k];
    for (a, &i) in index.iter().enumerate() {
        for (b, &j) in index.iter().enumerate() {
            matrix[a * k + b] = cov.matrix[(i, j)];
        }
    }
    Some(Covariance::from_matrix(names, &matrix))
}

/// Sets the value `name` (a record's value name: `compliance.<joint>[+<joint>…]`,
/// `transversal.<joint>[.u|.v]`, `harmonic.<joint>.sin<h>|cos<h>`) of `model` to `value`
/// (rad/(N·m), rad/m or rad), with `joint_names` the model's joints in chain order. Returns
/// whether the model holds such a value. How a test exercises the runtime against the
/// library at values larger than the identified ones.
pub fn set_model_value(
    model: &mut CalibratedModel,
    joint_names: &[String],
    name: &str,
    value: f64,
) -> bool {
    use hapcal_contract::ValueName;
    let index = |joint: &str| joint_names.iter().position(|n| n == joint);
    match ValueName::parse(name) {
        Ok(ValueName::Compliance { joints }) => {
            let Some((_, k)) = model.compliance.as_mut() else {
                return false;
            };
            let mut found = false;
            for joint in &joints {
                if let Some(j) = index(joint) {
                    k[j] = value;
                    found = true;
                }
            }
            found
        }
        Ok(ValueName::Transversal { joint, axis }) => {
            let Some(j) = index(&joint) else {
                return false;
            };
            // Per-axis terms of a joint come in the order u, v.
            let wanted = match axis {
                None => None,
                Some('u') => Some(0),
                Some(_) => Some(1),
            };
            let mut seen = 0;
            for t in model.transversal.iter_mut().filter(|t| t.joint == j) {
                let hit = match (wanted, t.direction) {
                    (None, None) => true,
                    (Some(w), Some(_)) => {
                        seen += 1;
                        seen - 1 == w
                    }
                    _ => false,
                };
                if hit {
                    t.compliance = value;
                    return true;
                }
            }
            false
        }
        Ok(ValueName::Harmonic { joint, order, sine }) => {
            let Some(j) = index(&joint) else {
                return false;
            };
            let Some((h, coef)) = model.harmonics.as_mut() else {
                return false;
            };
            match (h.terms().iter()).position(|&t| t == (j, order, sine)) {
                Some(i) => {
                    coef[i] = value;
                    true
                }
                None => false,
            }
        }
        _ => false,
    }
}

/// `Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz)` of six deviations (m, rad), as the frames apply
/// them ([`Tree::with_frames`]).
pub(crate) fn deviation(d: &[f64]) -> Isometry3<f64> {
    let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), d[3])
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), d[4])
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d[5]);
    Isometry3::from_parts(Vector3::new(d[0], d[1], d[2]).into(), r)
}

/// The kinematic values of a measured calibration as a placement device applies them
/// ([`hapcal_io::Device::with_calibration`]): a joint's offset `{joint}.offset` (rotation about,
/// or translation along, its axis just before the joint's motion) is folded into that joint's
/// six deviations, `Δ' = Δ · Rot(axis, offset)` (or `· Trans(axis·offset)`), decomposed back
/// into `Tx·Ty·Tz·Rx·Ry·Rz`; the standard deviation of each rotation it changes becomes the
/// root sum of squares of the two. Values of D-H devices pass unchanged.
///
/// # Errors
/// An offset of a joint the device has no placement for.
pub fn fold_joint_offsets(
    device: &hapcal_io::Device,
    values: &[hapcal_io::CalibratedValue],
) -> Result<Vec<hapcal_io::CalibratedValue>> {
    use hapcal_io::CalibratedValue;
    let mut out: Vec<CalibratedValue> = values
        .iter()
        .filter(|v| !v.name.ends_with(".offset"))
        .cloned()
        .collect();
    for v in values.iter().filter(|v| v.name.ends_with(".offset")) {
        let joint = v.name.trim_end_matches(".offset");
        let Some(p) = device.all_placements().find(|p| p.name == joint) else {
            bail!(
                "{}: the device has no placement {joint:?} to fold it into",
                v.name
            );
        };
        let Some(axis) = p.axis else {
            bail!("{}: {joint:?} is a fixed joint", v.name);
        };
        let axis = nalgebra::Unit::new_normalize(Vector3::from(axis));
        let suffixes = ["x", "y", "z", "rx", "ry", "rz"];
        let get = |s: &str| {
            out.iter()
                .find(|w| w.name == format!("{joint}.{s}"))
                .map_or((0.0, 0.0), |w| (w.value, w.std))
        };
        let d: Vec<(f64, f64)> = suffixes.iter().map(|s| get(s)).collect();
        let delta = deviation(&d.iter().map(|(v, _)| *v).collect::<Vec<_>>());
        let motion = if p.prismatic {
            Isometry3::from_parts(
                (axis.into_inner() * v.value).into(),
                UnitQuaternion::identity(),
            )
        } else {
            Isometry3::from_parts(
                Vector3::zeros().into(),
                UnitQuaternion::from_axis_angle(&axis, v.value),
            )
        };
        let folded = delta * motion;
        let r = folded.rotation.to_rotation_matrix();
        let b = r[(0, 2)].clamp(-1.0, 1.0).asin();
        let a = (-r[(1, 2)]).atan2(r[(2, 2)]);
        let c = (-r[(0, 1)]).atan2(r[(0, 0)]);
        let t = folded.translation.vector;
        let new = [t.x, t.y, t.z, a, b, c];
        for (k, s) in suffixes.iter().enumerate() {
            let name = format!("{joint}.{s}");
            let changed = (new[k] - d[k].0).abs() > 0.0;
            let std = if changed { d[k].1.hypot(v.std) } else { d[k].1 };
            let unit = if k < 3 { "m" } else { "rad" };
            match out.iter_mut().find(|w| w.name == name) {
                Some(w) => {
                    w.value = new[k];
                    w.std = std;
                }
                None if new[k] != 0.0 => out.push(CalibratedValue {
                    name,
                    value: new[k],
                    std,
                    unit: unit.to_owned(),
                }),
                None => {}
            }
        }
    }
    Ok(out)
}

/// The files `--out out` writes for `outcome`, as path and text: the calibrated device (a
/// haptic device's file; for a `.urdf` path a copy of the source URDF with the calibrated
/// joint origins, then its record `<out>.calibration.toml`; otherwise a device file with the
/// record in `[calibration]`).
///
/// # Errors
/// A haptic device's output that is not `.toml`, a calibration without record, a `.urdf`
/// output for a device that did not come from a URDF, values the device cannot take, or an
/// unreadable source URDF.
pub(crate) fn output_files(outcome: &Outcome, out: &Path) -> Result<Vec<(PathBuf, String)>> {
    if let Some(calibrated) = &outcome.calibrated {
        if !out
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            bail!(
                "{}: the calibrated haptic device is written as a device file (.toml)",
                out.display()
            );
        }
        return Ok(vec![(
            out.to_path_buf(),
            hapcal_io::write_device(calibrated),
        )]);
    }
    // Every workflow but the haptic one (its device file, above) records its calibration.
    let Some(record) = &outcome.record else {
        bail!(
            "the calibration of {} holds no record (model, loads, region, values): nothing was \
             written",
            outcome.device_path.display()
        );
    };
    let device_tree = outcome.device.tree()?;
    let values: Vec<_> = (fold_joint_offsets(&outcome.device, &record.values)?.into_iter())
        .filter(|v| device_tree.params().iter().any(|p| p.name == v.name))
        .collect();
    let meta = hapcal_io::CalibrationMeta {
        date: None,
        data_hash: None,
        notes: Some(format!(
            "hapcal calibrate, model {}; {} kept parameters; compliance terms are not part of the kinematic description",
            outcome.report.model,
            outcome.report.parameters.len()
        )),
    };
    let mut calibrated = outcome
        .device
        .with_calibration(&values, meta)
        .context("applying the identified deviations to the device description")?;
    // A device file's `[calibration]` is the whole record (its kinematic values, offsets
    // folded, are those just applied to the rows and placements).
    calibrated.calibration = Some(record.clone());
    let urdf_output = is_urdf_path(out);
    let text = if urdf_output {
        let Some(source) = source_urdf(outcome) else {
            bail!(
                "{} is a URDF output, but the device {} did not come from a URDF",
                out.display(),
                outcome.device_path.display()
            );
        };
        let placements: Vec<_> = calibrated.all_placements().cloned().collect();
        hapcal_io::write_calibrated_urdf(&source, &placements).with_context(|| {
            format!(
                "writing the calibrated joint origins into a copy of {}",
                source.display()
            )
        })?
    } else {
        hapcal_io::write_device(&calibrated)
    };
    let mut files = vec![(out.to_path_buf(), text.clone())];
    // The record holds every value as identified (the runtime evaluates the transversal tilts
    // and the gravity loads from the kinematic ones), the model, its loads and its region, and
    // what binds it to the URDF written beside it (its digest and the nominal origins of the
    // joints its values deviate); a device file holds it in its `[calibration]` table.
    let sidecar_text =
        urdf_output.then(|| bound_record(record, &text, &outcome.device).to_sidecar_toml());
    if let Some(text) = sidecar_text {
        files.push((out.with_extension("calibration.toml"), text));
    }
    Ok(files)
}

/// The calibrated haptic device as `hapcal predict` evaluates it: the device file `hapcal
/// calibrate --out` writes for the calibrated device `calibrated` (`output_files`), made in
/// memory and loaded by the runtime ([`hapcal_runtime::Model::from_toml`]). What the report's
/// calibrated figures of a haptic device's logs are evaluated with.
///
/// # Errors
/// A device file the runtime refuses (its message names the line).
pub fn runtime_device(calibrated: &hapcal_io::Device) -> Result<hapcal_runtime::Model> {
    let path = "calibrated.toml";
    let text = hapcal_io::write_device(calibrated);
    hapcal_runtime::Model::from_toml(&text, path).with_context(|| {
        format!(
            "reading back {path} as the runtime reads it, before reporting or writing the \
             calibration"
        )
    })
}

/// The source URDF of `outcome`'s device: the device itself when it is a URDF, else the URDF
/// its device file names; `None` for a device of its own (D-H rows, placements).
pub(crate) fn source_urdf(outcome: &Outcome) -> Option<PathBuf> {
    if is_urdf_path(&outcome.device_path) {
        return Some(outcome.device_path.clone());
    }
    (outcome.device.urdf.as_ref()).map(|u| u.resolve(&outcome.device_path))
}

/// Whether `path` ends in `.urdf` (any case).
fn is_urdf_path(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
}

/// The calibrated robot as `hapcal predict` evaluates it: the files `hapcal calibrate --out`
/// writes for `outcome` (a calibrated URDF and its record for a URDF device, else the device
/// file with its `[calibration]`), made in memory (`output_files`) and loaded by the
/// runtime ([`runtime_robot_of`]). What the report's calibrated figures are evaluated with.
/// `None` as [`runtime_robot_of`], for a device file that names a URDF (its tips are not the
/// record's), and for a haptic device (its calibrated device file is a
/// `hapcal_runtime::Model`: [`runtime_device`]).
///
/// # Errors
/// As `output_files` and [`runtime_robot_of`].
pub fn runtime_robot(outcome: &Outcome) -> Result<Option<hapcal_runtime::Robot>> {
    if outcome.calibrated.is_some() || outcome.record.is_none() {
        return Ok(None);
    }
    let out = if is_urdf_path(&outcome.device_path) {
        "calibrated.urdf"
    } else if source_urdf(outcome).is_none() {
        "calibrated.toml"
    } else {
        return Ok(None);
    };
    runtime_robot_of(outcome, &output_files(outcome, Path::new(out))?)
}

/// The runtime's robot of `files`, the files a calibration writes (`output_files`: path
/// and text, the calibrated URDF or device file first, then the sidecar), loaded as `hapcal
/// predict` loads them: a URDF with its sidecar and the record's tips
/// ([`hapcal_runtime::Robot::from_urdf_str`]), a D-H robot's device file
/// ([`hapcal_runtime::Robot::from_device_str`]). `None` for what the runtime does not read
/// as a robot: a calibration without record or, on a URDF, without tips; a device file of a
/// device that came from a URDF or whose chain is made of placements.
///
/// # Errors
/// Files the runtime refuses.
pub fn runtime_robot_of(
    outcome: &Outcome,
    files: &[(PathBuf, String)],
) -> Result<Option<hapcal_runtime::Robot>> {
    let (Some((path, text)), Some(record)) = (files.first(), &outcome.record) else {
        return Ok(None);
    };
    let context = || {
        format!(
            "reading back {} as the runtime reads it, before reporting or writing the \
             calibration",
            path.display()
        )
    };
    if is_urdf_path(path) {
        let tips: Vec<&str> = record.tips.iter().map(String::as_str).collect();
        if tips.is_empty() {
            return Ok(None);
        }
        let sidecar_path = path.with_extension("calibration.toml");
        let sidecar_name = sidecar_path.display().to_string();
        let sidecar = (files.iter())
            .find(|(p, _)| *p == sidecar_path)
            .map(|(_, text)| (text.as_str(), sidecar_name.as_str()));
        let robot = (hapcal_runtime::Robot::from_urdf_str(
            text,
            &path.display().to_string(),
            sidecar,
            &tips,
        ))
        .with_context(context)?;
        return Ok(Some(robot));
    }
    let device = &outcome.device;
    if source_urdf(outcome).is_some() || device.dh.is_empty() || !device.placements.is_empty() {
        return Ok(None);
    }
    let robot = hapcal_runtime::Robot::from_device_str(text, &path.display().to_string())
        .with_context(context)?;
    Ok(Some(robot))
}
