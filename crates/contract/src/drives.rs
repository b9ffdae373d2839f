//! A haptic device's drives as its file and record give them: each joint's capstan
//! (`[[capstan]]`, paper eq. 1) with the record's calibrated `capstan{j}.*` values, or the
//! record's polynomial `joint{j}.cheb{k}` in its place, and the handle compliances
//! `joint_compliance.j{k}`. The one reading of those values: the runtime's device model, the
//! calibration library's log state and the force study's library model build their drives
//! from [`haptic_drives`].

use std::fmt;

use hapcal_transmission::CapstanParams;

use crate::device::Capstan;
use crate::{Calibration, CapstanField, ValueName};

/// One joint's drive as the device file and its record give it.
#[derive(Clone, Debug, PartialEq)]
pub enum JointDrive {
    /// No transmission model: the reading is the joint angle (ratio 1).
    Direct,
    /// A capstan of nominal ratio `ratio` and drum distance `drum_distance_m` (m) with the
    /// record's eq.-1 parameters (0 where the record names none).
    Capstan {
        /// Nominal ratio `R`, motor angle per joint angle.
        ratio: f64,
        /// Drum centre distance `D`, m.
        drum_distance_m: f64,
        /// The calibrated parameters of eq. 1.
        params: CapstanParams,
    },
    /// The record's polynomial `q = θ + Σ_k coeffs[k]·T_k(u)` on the joint's range (rad,
    /// Chebyshev basis; docs/design.md §3.3), in place of the joint's capstan model.
    Polynomial {
        /// Nominal ratio of the joint's `[[capstan]]` (1 without one).
        ratio: f64,
        /// Coefficients 0..n, rad, every one present in the record.
        coeffs: Vec<f64>,
    },
}

/// The drives of a haptic device: per joint (index `j − 1` for joint `j`), and the handle
/// compliance about each joint, rad/(N·m) (0 where the record names none).
#[derive(Clone, Debug, PartialEq)]
pub struct HapticDrives {
    /// Each joint's drive.
    pub drives: Vec<JointDrive>,
    /// Each joint's `joint_compliance.j{k}`, rad/(N·m).
    pub handle_compliance: Vec<f64>,
}

/// Why the file's capstans or the record's values do not make a haptic device's drives.
#[derive(Clone, Debug, PartialEq)]
pub struct DriveFault {
    /// The record value at fault (its name in `[calibration.values]`), `None` for a
    /// `[[capstan]]` entry.
    pub value: Option<String>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for DriveFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.value {
            Some(name) => write!(f, "[calibration.values] {name}: {}", self.message),
            None => f.write_str(&self.message),
        }
    }
}

impl std::error::Error for DriveFault {}

/// The slot of `field` in `p`: `c` → `c_rad`, `re` → `re`, `r_o` → `r_o_m`, and so on.
pub fn capstan_field(p: &mut CapstanParams, field: CapstanField) -> &mut f64 {
    match field {
        CapstanField::C => &mut p.c_rad,
        CapstanField::Re => &mut p.re,
        CapstanField::ROut => &mut p.r_o_m,
        CapstanField::BetaOut => &mut p.beta_o_rad,
        CapstanField::RIn => &mut p.r_i_m,
        CapstanField::BetaIn => &mut p.beta_i_rad,
    }
}

/// The drives of a haptic device with `n_joints` joints and `n_rows` D-H rows, its
/// `[[capstan]]` entries `capstans` and its record (none: ideal capstans, no polynomial, no
/// compliance). D-H deviations are skipped (the rows already hold them), and so are the
/// record's rig frames.
///
/// # Errors
/// A capstan on a joint the device does not have or twice on one joint; a value on a joint
/// or D-H row the device does not have, a capstan value on a joint without `[[capstan]]`, a
/// gap in a joint's Chebyshev coefficients, a value in a unit its kind does not take
/// ([`ValueName::unexpected_unit`]), or a robot's value (compliance, transversal,
/// harmonic, element deviation), which a haptic device's model does not hold.
pub fn haptic_drives(
    capstans: &[Capstan],
    n_joints: usize,
    n_rows: usize,
    record: Option<&Calibration>,
) -> Result<HapticDrives, DriveFault> {
    let fault = |value: Option<&str>, message: String| DriveFault {
        value: value.map(str::to_owned),
        message,
    };
    let mut drives = vec![JointDrive::Direct; n_joints];
    for c in capstans {
        let slot = (c.joint.checked_sub(1)).and_then(|j| drives.get_mut(j));
        let Some(slot) = slot else {
            let message = format!(
                "[[capstan]] on joint {}: the device has joints 1..={n_joints}",
                c.joint
            );
            return Err(fault(None, message));
        };
        if *slot != JointDrive::Direct {
            let message = format!("two [[capstan]] entries on joint {}", c.joint);
            return Err(fault(None, message));
        }
        *slot = JointDrive::Capstan {
            ratio: c.ratio,
            drum_distance_m: c.drum_distance_m,
            params: CapstanParams::default(),
        };
    }
    let mut handle_compliance = vec![0.0; n_joints];
    let mut cheb: Vec<Vec<Option<f64>>> = vec![Vec::new(); n_joints];
    let values = record.map_or(&[][..], |r| &r.values[..]);
    let torque = record.and_then(|r| r.torque.as_ref()).map(|t| t.source);
    for v in values {
        let name = v.name.as_str();
        let joint_index = |joint: usize| {
            (1..=n_joints)
                .contains(&joint)
                .then_some(joint - 1)
                .ok_or_else(|| fault(Some(name), format!("the device has joints 1..={n_joints}")))
        };
        let parsed = ValueName::parse(name).map_err(|message| fault(Some(name), message))?;
        if let Some(expected) = parsed.unexpected_unit(&v.unit, torque) {
            let message = format!("unit is {:?}, expected {expected}", v.unit);
            return Err(fault(Some(name), message));
        }
        match parsed {
            ValueName::Dh { row, .. } if row >= n_rows => {
                let message = format!("the [[dh]] table has rows 0..{n_rows}");
                return Err(fault(Some(name), message));
            }
            ValueName::Dh { .. } => {}
            ValueName::Capstan { joint, field } => {
                let JointDrive::Capstan { params, .. } = &mut drives[joint_index(joint)?] else {
                    let message = format!("joint {joint} has no [[capstan]]");
                    return Err(fault(Some(name), message));
                };
                *capstan_field(params, field) = v.value;
            }
            ValueName::Chebyshev { joint, index } => {
                let coeffs = &mut cheb[joint_index(joint)?];
                if coeffs.len() <= index {
                    coeffs.resize(index + 1, None);
                }
                coeffs[index] = Some(v.value);
            }
            ValueName::HandleCompliance { joint } => {
                handle_compliance[joint_index(joint)?] = v.value;
            }
            // A frame of the measurement rig, not part of the device's model.
            ValueName::Element { element, .. }
                if record.is_some_and(|r| r.frames.contains_key(&element)) => {}
            ValueName::Element { .. }
            | ValueName::Compliance { .. }
            | ValueName::Transversal { .. }
            | ValueName::Harmonic { .. } => {
                let message = "a robot's value, which a haptic device's model does not hold: \
                               its record holds capstans (capstan<j>.*), joint polynomials \
                               (joint<j>.cheb<k>), the handle's compliance \
                               (joint_compliance.j<k>) and D-H deviations; a robot's record \
                               belongs with its URDF or D-H robot file"
                    .to_owned();
                return Err(fault(Some(name), message));
            }
        }
    }
    for (j, coeffs) in cheb.into_iter().enumerate() {
        if coeffs.is_empty() {
            continue;
        }
        let n = coeffs.len();
        let coeffs = (coeffs.into_iter().enumerate())
            .map(|(k, c)| {
                let missing = || {
                    format!(
                        "joint{}.cheb{k} is missing (coefficients 0..={})",
                        j + 1,
                        n - 1
                    )
                };
                c.ok_or_else(|| fault(None, missing()))
            })
            .collect::<Result<Vec<f64>, DriveFault>>()?;
        let ratio = match drives[j] {
            JointDrive::Capstan { ratio, .. } => ratio,
            _ => 1.0,
        };
        drives[j] = JointDrive::Polynomial { ratio, coeffs };
    }
    Ok(HapticDrives {
        drives,
        handle_compliance,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CalibratedValue;

    fn record(values: &[(&str, f64)]) -> Calibration {
        let value = |&(name, value): &(&str, f64)| CalibratedValue {
            name: name.to_owned(),
            value,
            std: 0.0,
            unit: ValueName::parse(name)
                .map_or("", |n| n.units(None)[0])
                .to_owned(),
        };
        Calibration {
            values: values.iter().map(value).collect(),
            ..Calibration::default()
        }
    }

    fn capstan(joint: usize, ratio: f64) -> Capstan {
        Capstan {
            joint,
            ratio,
            drum_distance_m: 0.05,
        }
    }

    /// Each of the six capstan names a record writes reaches its own field of eq. 1.
    #[test]
    fn each_capstan_name_reaches_its_field() {
        let names = ["c", "re", "r_o", "beta_o", "r_i", "beta_i"];
        let mut p = CapstanParams::default();
        for (i, name) in names.into_iter().enumerate() {
            let field = CapstanField::parse(name).expect("a capstan field");
            *capstan_field(&mut p, field) = i as f64 + 1.0;
        }
        let expected = CapstanParams {
            c_rad: 1.0,
            re: 2.0,
            r_o_m: 3.0,
            beta_o_rad: 4.0,
            r_i_m: 5.0,
            beta_i_rad: 6.0,
        };
        assert_eq!(p, expected);
        assert!(CapstanField::parse("ratio").is_none());
    }

    /// Capstan values land on their joint, a polynomial replaces its joint's capstan with the
    /// capstan's ratio, a handle compliance lands on its joint; faults name the value.
    #[test]
    fn the_record_s_values_make_each_joint_s_drive() {
        let capstans = [capstan(1, 10.0), capstan(2, 12.0)];
        let values = [
            ("capstan1.re", 0.25),
            ("capstan1.beta_i", -0.5),
            ("joint2.cheb1", 2e-3),
            ("joint2.cheb0", 1e-3),
            ("joint_compliance.j3", 4e-4),
            ("da2", 1e-4),
        ];
        let read = haptic_drives(&capstans, 3, 4, Some(&record(&values))).expect("drives");
        let params = CapstanParams {
            re: 0.25,
            beta_i_rad: -0.5,
            ..CapstanParams::default()
        };
        let capstan1 = JointDrive::Capstan {
            ratio: 10.0,
            drum_distance_m: 0.05,
            params,
        };
        let poly2 = JointDrive::Polynomial {
            ratio: 12.0,
            coeffs: vec![1e-3, 2e-3],
        };
        assert_eq!(read.drives, [capstan1, poly2, JointDrive::Direct]);
        assert_eq!(read.handle_compliance, [0.0, 0.0, 4e-4]);

        let fault = |capstans: &[Capstan], values: &[(&str, f64)]| {
            haptic_drives(capstans, 3, 4, Some(&record(values)))
                .expect_err("a fault")
                .to_string()
        };
        let no_capstan = fault(&capstans, &[("capstan3.re", 0.1)]);
        assert_eq!(
            no_capstan,
            "[calibration.values] capstan3.re: joint 3 has no [[capstan]]"
        );
        let gap = fault(&capstans, &[("joint1.cheb2", 0.1)]);
        assert_eq!(gap, "joint1.cheb0 is missing (coefficients 0..=2)");
        assert!(fault(&capstans, &[("dd4", 0.1)]).contains("rows 0..4"));
        assert!(fault(&capstans, &[("compliance.j2", 0.1)]).contains("a robot's value"));
        let mut metres = record(&[("capstan1.beta_o", 0.1)]);
        metres.values[0].unit = "m".into();
        let unit = haptic_drives(&capstans, 3, 4, Some(&metres)).expect_err("a wrong unit");
        let expected = "[calibration.values] capstan1.beta_o: unit is \"m\", expected \"rad\"";
        assert_eq!(unit.to_string(), expected);
        assert!(fault(&[capstan(4, 1.0)], &[]).contains("joints 1..=3"));
        assert!(fault(&[capstan(1, 1.0), capstan(1, 2.0)], &[]).contains("two [[capstan]]"));
    }
}
