//! The calibration record of a calibration on measurement files (`hapcal-contract`,
//! docs/design.md §5.6): what `hapcal calibrate --out` writes beside the calibrated URDF so
//! that the runtime, `predict` and `compensate` evaluate the model that was identified.

use hapcal_contract::{
    Calibration, Covariance, Frame, JointRange, ModelName, PointMass, Region, SCHEMA_VERSION,
    Torque, TorqueSource,
};
use hapcal_problems::CalibratedModel;

use crate::report::{FrameReport, ParamReport};

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
        unit: match compliance_unit {
            Some(unit)
                if p.name.starts_with("compliance.") || p.name.starts_with("transversal.") =>
            {
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
