//! Loading a calibrated robot as `hapcal calibrate --out` writes it: the URDF with calibrated
//! joint origins and the sidecar `robot.calibration.toml` (identified frames and compliances,
//! what a URDF cannot hold), or a serial robot's device file (`[[dh]]` rows with the
//! identified deviations added, the record in `[calibration]`).

use std::path::Path;

use hapcal_contract::locate::{Step, TomlSpans};
use hapcal_contract::urdf;
use hapcal_contract::{Calibration, ElementField, Region, Torque, TorqueSource, ValueName};

use crate::dh_table::{DhTable, add_dh, dh_frames};
use crate::load::{at_line, contract_error, invalid, read_text};
use crate::robot::{HarmonicTerm, PointMass, RobotJoint, RobotTip, TransversalJoint};
use crate::robot::{deviation_pose, joint_motion};
use crate::{GravityModel, LoadError, Pose, Robot};

/// The rotation `Rz(yaw)·Ry(pitch)·Rx(roll)` and translation `xyz` of a URDF `<origin>`.
pub(crate) fn origin_pose(xyz: [f64; 3], rpy: [f64; 3]) -> Pose {
    let [roll, pitch, yaw] = rpy;
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    Pose {
        rotation: [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ],
        translation_m: xyz,
    }
}

fn joint_pose(joint: &urdf::Joint) -> Pose {
    origin_pose(joint.origin.xyz.0, joint.origin.rpy.0)
}

impl Robot {
    /// A robot of `joints` (named `joint_names`, limits `limits` in rad or m) and `tips`
    /// (named `tip_names`) as a file describes it before any calibration record: rigid (zero
    /// compliance), gravity lumped at the tips at standard gravity along −z, loads at
    /// equilibrium, nominal frames, no frames, region, transversal terms or harmonics, no
    /// tip element names (one `None` per tip) and no D-H table.
    fn rigid(
        joints: Vec<RobotJoint>,
        joint_names: Vec<String>,
        limits: Vec<(f64, f64)>,
        tips: Vec<RobotTip>,
        tip_names: Vec<String>,
    ) -> Robot {
        let (n, n_tips) = (joints.len(), tips.len());
        Robot {
            joints,
            joint_names,
            limits,
            tips,
            tip_names,
            masses: Vec::new(),
            compliance: vec![0.0; n],
            gravity: GravityModel::Lumped,
            gravity_dir: [0.0, 0.0, -1.0],
            frames: Vec::new(),
            record: None,
            region: Vec::new(),
            gravity_m_s2: crate::STANDARD_GRAVITY,
            equilibrium: true,
            nominal_differs: false,
            transversal: Vec::new(),
            harmonics: Vec::new(),
            tip_elements: vec![None; n_tips],
            dh: None,
        }
    }
}

impl Robot {
    /// Loads the calibrated robot `urdf` with the links `tips` as tips, and its sidecar
    /// `<urdf stem>.calibration.toml` beside it if there is one (as `hapcal calibrate --out
    /// robot.urdf` writes them).
    ///
    /// From the URDF: the moving joints (revolute, continuous, prismatic) on the paths from
    /// the root link to each tip, their `<origin>`s (fixed joints folded into the next moving
    /// joint's origin or the tip's offset), `<axis>` and `<limit>` (infinite for a continuous
    /// joint), and the `<inertial>` mass and centre of mass of every link below a moving joint
    /// of the paths (a moving joint off the paths held at zero). From the sidecar, the
    /// calibration record (`hapcal-contract`, docs/design.md §5.6): the frames
    /// ([`Robot::frame`]); the compliances' torque source, gravity, point masses (replacing the
    /// URDF's), equilibrium and load tips (a load tip not among `tips` is loaded as a further tip
    /// after them: the calibration read its joints to load the tree); every value: the
    /// kinematic deviations (which the URDF's origins already hold; they give the nominal
    /// geometry the gravity loads are evaluated on, as the calibration evaluated them, and the
    /// base of the transversal tilts), the compliances `compliance.<joint>[+<joint>…]`, the
    /// transversal compliances `transversal.<joint>[.u|.v]` and the joint harmonics
    /// `harmonic.<joint>.sin<h>|cos<h>`; the region ([`Robot::outside_region`]). A sidecar of
    /// an earlier hapcal (no `schema_version`) is refused. Gravity is along −z of the root
    /// link (ROS REP 103) unless the record says otherwise.
    ///
    /// A record binds to its robot: it is refused beside another URDF than the one it was
    /// written beside (its `urdf_digest`), for tips it was not made for (its `tips` and load
    /// tips), with a region joint the URDF lacks, and with values that, from the record's
    /// nominal origins, do not give the URDF's joint origins (a value edited by hand in one
    /// of the two files); a record without digest or nominal origins is not bound to one
    /// URDF.
    ///
    /// # Errors
    /// [`LoadError::Io`] for a file that cannot be read; [`LoadError::Parse`] (line, column)
    /// for a malformed sidecar, an unknown value name, a wrong unit, a missing key or a newer
    /// schema, and for a record that does not bind to this URDF and these tips (above);
    /// [`LoadError::Invalid`] for a URDF that urdf-rs cannot read, a tip that is not a
    /// link (listing them), a tip named twice, a link on a path with two parent joints or
    /// joints above a tip that form a loop, a floating or planar joint on a path, a joint
    /// without axis, `<limit>` bounds that are not finite with lower < upper (a continuous
    /// joint's are infinite), a non-finite number, a negative mass, a value of a joint or element not
    /// on the paths to the tips, a haptic device's value, lumped loads whose tips are not all
    /// loaded.
    pub fn load_urdf(urdf: &Path, tips: &[&str]) -> Result<Robot, LoadError> {
        let text = read_text(urdf)?;
        let sidecar_path = urdf.with_extension("calibration.toml");
        let sidecar = if sidecar_path.is_file() {
            Some((
                read_text(&sidecar_path)?,
                sidecar_path.display().to_string(),
            ))
        } else {
            None
        };
        let sidecar = sidecar.as_ref().map(|(t, o)| (t.as_str(), o.as_str()));
        Robot::from_urdf_str(&text, &urdf.display().to_string(), sidecar, tips)
    }

    /// [`Robot::load_urdf`] from text: the URDF (`origin` names it in errors) and, if any, the
    /// sidecar's text with its name.
    ///
    /// # Errors
    /// As [`Robot::load_urdf`], without [`LoadError::Io`].
    pub fn from_urdf_str(
        urdf: &str,
        origin: &str,
        sidecar: Option<(&str, &str)>,
        tips: &[&str],
    ) -> Result<Robot, LoadError> {
        let robot = urdf::parse(urdf).map_err(|e| invalid(origin, e.to_string()))?;
        if tips.is_empty() {
            return Err(invalid(origin, "no tip link given".to_owned()));
        }
        // The tips whose paths carry the record's loads and that the caller did not give
        // (the other arm, read but not measured): further tips after the given ones, so that
        // their joints' readings load the tree as the calibration loaded it.
        // Parsed once; a malformed sidecar is reported after the URDF's own checks.
        let parsed = sidecar.map(|(t, o)| (Calibration::from_sidecar_str(t, o), t, o));
        if let Some((Ok(record), text, sidecar_origin)) = &parsed {
            // The record binds to the URDF it was written beside, and to its tips.
            record
                .check_urdf(text, sidecar_origin, urdf.as_bytes(), origin)
                .map_err(|e| contract_error(e, sidecar_origin))?;
            check_tips(record, text, sidecar_origin, tips)?;
        }
        let load_tips: Vec<String> = (parsed.as_ref())
            .and_then(|(record, _, _)| record.as_ref().ok())
            .and_then(|record| record.torque.as_ref())
            .map(|torque| torque.tips.clone())
            .unwrap_or_default();
        let all_tips: Vec<&str> = (tips.iter().copied())
            .chain((load_tips.iter().map(String::as_str)).filter(|t| !tips.contains(t)))
            .collect();
        let tips = all_tips.as_slice();
        let mut joints: Vec<RobotJoint> = Vec::new();
        let mut joint_names: Vec<String> = Vec::new();
        let mut limits = Vec::new();
        let mut robot_tips = Vec::new();
        // The name of each tip's element: the last fixed joint of its path, if the path ends
        // in fixed joints (the calibration's tip element carries that name).
        let mut tip_elements: Vec<Option<String>> = Vec::new();
        for (i, &tip) in tips.iter().enumerate() {
            check_tip(&robot, &tips[..i], tip, origin)?;
            // The contract's URDF walk: a link with two parent joints, or a loop, is refused.
            let path = urdf::path_to(&robot, tip).map_err(|e| invalid(origin, e.to_string()))?;
            let mut parent: Option<usize> = None;
            let mut pending = Pose::IDENTITY;
            let mut last_fixed: Option<String> = None;
            for joint in path {
                let name = &joint.name;
                urdf::origin(joint).map_err(|m| invalid(origin, m))?;
                let prismatic = match joint.joint_type {
                    urdf::JointType::Fixed => {
                        pending = pending.compose(&joint_pose(joint));
                        last_fixed = Some(name.clone());
                        continue;
                    }
                    urdf::JointType::Revolute | urdf::JointType::Continuous => false,
                    urdf::JointType::Prismatic => true,
                    ref other => {
                        return Err(invalid(
                            origin,
                            format!(
                                "joint {name:?} is {}: the runtime evaluates revolute, continuous, prismatic and fixed joints",
                                urdf::joint_type_name(other)
                            ),
                        ));
                    }
                };
                last_fixed = None;
                if let Some(k) = joint_names.iter().position(|n| n == name) {
                    parent = Some(k);
                    pending = Pose::IDENTITY;
                    continue;
                }
                // The contract's URDF reader checks the axis and the limits (a continuous
                // joint's are infinite).
                let axis = urdf::axis(joint).map_err(|m| invalid(origin, m))?;
                let norm = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
                let (lower, upper) = urdf::limits(joint, (f64::NEG_INFINITY, f64::INFINITY))
                    .map_err(|m| invalid(origin, m))?;
                let origin = pending.compose(&joint_pose(joint));
                joints.push(RobotJoint {
                    parent,
                    origin,
                    axis: axis.map(|a| a / norm),
                    prismatic,
                    nominal: origin,
                    deviation: [0.0; 7],
                    weight: true,
                });
                joint_names.push(name.clone());
                limits.push((lower, upper));
                parent = Some(joints.len() - 1);
                pending = Pose::IDENTITY;
            }
            robot_tips.push(RobotTip {
                parent,
                offset: pending,
                marker: Pose::IDENTITY,
                nominal_offset: pending,
                weight: true,
            });
            tip_elements.push(last_fixed);
        }
        if joints.is_empty() {
            return Err(invalid(
                origin,
                "no moving joint between the root link and the tips".to_owned(),
            ));
        }
        let masses = link_masses(&robot, &joint_names, origin)?;
        let gravity = if masses.is_empty() {
            GravityModel::Lumped
        } else {
            GravityModel::Masses
        };
        let tip_names = tips.iter().map(|t| (*t).to_owned()).collect();
        let mut out = Robot {
            masses,
            gravity,
            tip_elements: tip_elements.clone(),
            ..Robot::rigid(joints, joint_names, limits, robot_tips, tip_names)
        };
        if let Some((record, text, sidecar_origin)) = parsed {
            let urdf_joints: Vec<(&str, Pose)> = (robot.joints.iter())
                .map(|j| (j.name.as_str(), joint_pose(j)))
                .collect();
            let record = record.map_err(|e| contract_error(e, sidecar_origin))?;
            out.apply_record(record, text, sidecar_origin, &tip_elements, &urdf_joints)?;
        }
        Ok(out)
    }
}

impl Robot {
    /// Loads a serial robot's device file as `hapcal calibrate --out robot.toml` writes it
    /// (docs/design.md §5.1): see [`Robot::from_device_str`].
    ///
    /// # Errors
    /// [`LoadError::Io`] for a file that cannot be read; otherwise as
    /// [`Robot::from_device_str`], with the path as origin.
    pub fn load_device(path: &Path) -> Result<Robot, LoadError> {
        let text = read_text(path)?;
        Robot::from_device_str(&text, &path.display().to_string())
    }

    /// The robot of a device file's text (`origin` names it in errors) whose chain is a
    /// `[[dh]]` table (standard or modified by `convention`, fixed rows allowed): one revolute
    /// joint per joint row, about the z axis of the frame just after its row's `Rz(θ)`
    /// (standard D-H: `Rz(θ + q)·Tz(d)·Tx(a)·Rx(α)·Ry(β)`; modified:
    /// `Rx(α)·Ry(β)·Tx(a)·Rz(θ + q)·Tz(d)`), as `hapcal_kinematics::Chain::from_dh` builds
    /// the chain the calibration identified; the tip at the end of the last row. The joints
    /// are named `q1 … qn` (the calibration's names: the columns of the measurement files and
    /// the record's), with the `[[joint]]` limits. The tip is named after the record's first
    /// tip (`tip` without a record).
    ///
    /// The rows as written hold the identified D-H deviations (`da<i>`, `dalpha<i>`, `dd<i>`,
    /// `dtheta<i>`, `dbeta<i>`, row i counted from 0); the nominal rows, without them, carry
    /// the gravity loads, as the calibration evaluated them. The rest of the record
    /// (`[calibration]`, `hapcal-contract`, docs/design.md §5.6) reads as
    /// [`Robot::load_urdf`] reads a sidecar's: frames, the compliances' torque source (lumped
    /// unit weights at the joints' origins and the tip, the calibration library's
    /// `GravityCompliance` without link masses), gravity and equilibrium, the compliances
    /// `compliance.q<j>`, the harmonics `harmonic.q<j>.sin<h>|cos<h>`, the region. Every
    /// [`Robot`] feature (deflection, prediction, compensation) then works for it.
    ///
    /// # Errors
    /// [`LoadError::Parse`] for TOML syntax, a missing or unknown key, a wrong type, a number
    /// that is not finite, a `[calibration]` the contract refuses, or a D-H deviation of a row
    /// the table does not have, at its line; [`LoadError::Invalid`] for a `[[placement]]`
    /// chain, joints not numbered 1, 2, … in row order, a `[[joint]]` count that differs from
    /// the chain's, bad limits, a chain without a joint, a haptic device (capstans or
    /// a parallelogram: its model is a [`crate::Model`], [`crate::Model::load`]), and the
    /// record values a D-H robot cannot hold (placement deviations, transversal compliances,
    /// a haptic device's values) or that name no joint `q<j>` of the chain.
    pub fn from_device_str(text: &str, origin: &str) -> Result<Robot, LoadError> {
        let crate::load::DhFile {
            file,
            convention,
            rows,
            n_joints,
        } = crate::load::read_device_file(text, origin)?;
        if !file.capstans.is_empty() || file.parallelogram.is_some() {
            return Err(invalid(
                origin,
                "a haptic device (its file has [[capstan]] or [parallelogram] tables): its \
                 calibrated model is a hapcal_runtime::Model (Model::load), not a Robot"
                    .to_owned(),
            ));
        }
        if n_joints == 0 {
            return Err(invalid(
                origin,
                "the [[dh]] table has no joint row (joint = 1, 2, …)".to_owned(),
            ));
        }
        let record = file.calibration;
        let mut nominal = rows.clone();
        if let Some(record) = &record {
            record
                .check(text, origin)
                .map_err(|e| contract_error(e, origin))?;
            for v in &record.values {
                if let Ok(ValueName::Dh { field, row }) = ValueName::parse(&v.name) {
                    let Some(r) = nominal.get_mut(row) else {
                        let at = TomlSpans::parse(text).value_line(&v.name);
                        let message = format!(
                            "[calibration.values] {}: the [[dh]] table has rows 0..{}",
                            v.name,
                            rows.len()
                        );
                        return Err(at_line(origin, at.unwrap_or((0, 0)), message));
                    };
                    add_dh(r, field, -v.value);
                }
            }
        }
        let (origins, offset) = dh_frames(convention, &rows);
        let (nominal_origins, nominal_offset) = dh_frames(convention, &nominal);
        let joints: Vec<RobotJoint> = (origins.iter().zip(&nominal_origins).enumerate())
            .map(|(j, (&origin, &nominal))| RobotJoint {
                parent: j.checked_sub(1),
                origin,
                axis: [0.0, 0.0, 1.0],
                prismatic: false,
                nominal,
                deviation: [0.0; 7],
                weight: true,
            })
            .collect();
        let tip = RobotTip {
            parent: Some(n_joints - 1),
            offset,
            marker: Pose::IDENTITY,
            nominal_offset,
            weight: true,
        };
        let tip_name = (record.as_ref())
            .and_then(|r| r.tips.first().cloned())
            .unwrap_or_else(|| "tip".to_owned());
        let joint_names = (1..=n_joints).map(|j| format!("q{j}")).collect();
        let limits = (file.joints.iter())
            .map(|j| (j.lower_rad, j.upper_rad))
            .collect();
        let mut out = Robot {
            nominal_differs: nominal != rows,
            dh: Some(DhTable {
                convention,
                nominal,
            }),
            ..Robot::rigid(joints, joint_names, limits, vec![tip], vec![tip_name])
        };
        if let Some(record) = record {
            // Every marker of a device file's calibration sits on its one tip, which carries
            // the loads of every tip the record names.
            let mut one_tip = record.clone();
            if let Some(t) = &mut one_tip.torque {
                t.tips.truncate(1);
            }
            let names = out.joint_names.clone();
            let joints: Vec<(&str, Pose)> = (names.iter())
                .map(|n| (n.as_str(), Pose::IDENTITY))
                .collect();
            out.apply_record(one_tip, text, origin, &[None], &joints)?;
            out.record = Some(record);
        }
        Ok(out)
    }
}

impl Robot {
    /// The same robot with the recorded value `name` (a name of the record's `[values]`, in
    /// its unit) set to `value`: a kinematic value moves its joint's origin, a compliance,
    /// transversal compliance or harmonic changes the deflection. How `hapcal predict`
    /// propagates the covariance to a prediction's uncertainty.
    ///
    /// # Errors
    /// [`Error::Invalid`](crate::Error::Invalid) for a name the record does not hold;
    /// [`Error::NotFinite`](crate::Error::NotFinite) for a NaN or infinite value.
    pub fn with_value(&self, name: &str, value: f64) -> Result<Robot, crate::Error> {
        let robot = self;
        let unknown = crate::Error::Invalid {
            what: "value",
            value,
            expected: "the name of a value the calibration record holds",
        };
        if !value.is_finite() {
            return Err(crate::Error::NotFinite {
                what: "value",
                index: 0,
                value,
            });
        }
        let mut out = robot.clone();
        let Some(record) = out.record.as_mut() else {
            return Err(unknown);
        };
        let Some(recorded) = record.values.iter_mut().find(|v| v.name == name) else {
            return Err(unknown);
        };
        recorded.value = value;
        let Ok(parsed) = ValueName::parse(name) else {
            return Err(unknown);
        };
        match parsed {
            ValueName::Element { element, field } => {
                let k = field_index(field);
                if let Some(f) = out.frames.iter().position(|(n, _)| *n == element) {
                    // A frame holds `nominal · Δ(d)`: it becomes `frame · Δ(d)⁻¹ · Δ(d')`.
                    let before = element_deviation(robot.record.as_ref(), &element);
                    let after = element_deviation(out.record.as_ref(), &element);
                    let frame = &mut out.frames[f].1;
                    *frame = frame
                        .compose(&deviation_pose(&before).inverse())
                        .compose(&deviation_pose(&after));
                } else if let Some(j) = out.joint_names.iter().position(|n| *n == element) {
                    let joint = &mut out.joints[j];
                    joint.deviation[k] = value;
                    let [x, y, z, rx, ry, rz, _] = joint.deviation;
                    joint.origin = crate::robot::origin_at(joint, &[x, y, z, rx, ry, rz]);
                } else {
                    let d = element_deviation(out.record.as_ref(), &element);
                    for (tip, e) in out.tips.iter_mut().zip(&out.tip_elements) {
                        if e.as_deref() != Some(element.as_str()) {
                            continue;
                        }
                        tip.offset = tip.nominal_offset.compose(&deviation_pose(&d));
                    }
                }
                out.nominal_differs = true;
            }
            ValueName::Compliance { joints } => {
                for joint in &joints {
                    if let Some(j) = out.joint_names.iter().position(|n| n == joint) {
                        out.compliance[j] = value;
                    }
                }
            }
            ValueName::Transversal { joint, axis } => {
                let Some(j) = out.joint_names.iter().position(|n| *n == joint) else {
                    return Err(unknown);
                };
                let direction = transversal_direction(&out.joints[j].axis, axis);
                for t in &mut out.transversal {
                    if t.joint == j && t.direction == direction {
                        t.compliance = value;
                    }
                }
            }
            ValueName::Harmonic { joint, order, sine } => {
                let Some(j) = out.joint_names.iter().position(|n| *n == joint) else {
                    return Err(unknown);
                };
                for h in &mut out.harmonics {
                    if h.joint == j && h.order == order && h.sine == sine {
                        h.coef = value;
                    }
                }
            }
            ValueName::Dh { .. } => {
                // The rows at the nominal geometry plus the record's deviations, this one moved.
                let Some(table) = &out.dh else {
                    return Err(unknown);
                };
                let rows = table.calibrated_rows(out.record.as_ref());
                let (origins, offset) = dh_frames(table.convention, &rows);
                for (joint, origin) in out.joints.iter_mut().zip(origins) {
                    joint.origin = origin;
                }
                if let Some(tip) = out.tips.first_mut() {
                    tip.offset = offset;
                }
                out.nominal_differs = true;
            }
            _ => return Err(unknown),
        }
        Ok(out)
    }
}

/// The suffixes of a placement deviation's values `<element>.x` … `<element>.rz`, in the
/// order of [`deviation_pose`]'s `d`.
const DEVIATION_FIELDS: [&str; 6] = ["x", "y", "z", "rx", "ry", "rz"];

/// The deviation `[x, y, z, rx, ry, rz]` (m, rad) the record's values `<element>.x` …
/// `<element>.rz` give an element (a joint, a tip element or a frame); 0 for a value it lacks.
fn element_deviation(record: Option<&Calibration>, element: &str) -> [f64; 6] {
    let value = |suffix: &str| {
        record?
            .value(&format!("{element}.{suffix}"))
            .map(|v| v.value)
    };
    DEVIATION_FIELDS.map(|suffix| value(suffix).unwrap_or(0.0))
}

/// The index of a placement deviation's field in a joint's `deviation`.
fn field_index(field: ElementField) -> usize {
    match field {
        ElementField::X => 0,
        ElementField::Y => 1,
        ElementField::Z => 2,
        ElementField::Rx => 3,
        ElementField::Ry => 4,
        ElementField::Rz => 5,
        ElementField::Offset => 6,
    }
}

impl Robot {
    /// Reads a calibration record (schema 1 on) into the robot: its frames; its torque source,
    /// point masses, gravity, equilibrium and load tips; every value (kinematic deviations,
    /// which the URDF's joint origins already hold, give the nominal geometry the loads are
    /// evaluated on and the transversal tilts' base; compliances, transversal compliances,
    /// harmonics); its region, whose joints must be among `known_joints` (the URDF's joints
    /// with their own `<origin>`s, or a D-H robot's joints); its nominal origins, which with
    /// the values must give those `<origin>`s ([`check_nominal`]). `text` is the record's text
    /// (refusals at their line).
    fn apply_record(
        &mut self,
        record: Calibration,
        text: &str,
        origin: &str,
        tip_elements: &[Option<String>],
        known_joints: &[(&str, Pose)],
    ) -> Result<(), LoadError> {
        for (name, f) in &record.frames {
            self.frames
                .push((name.clone(), origin_pose(f.xyz_m, f.rpy_rad)));
        }
        let at = RecordAt { text, origin };
        if let Some(torque) = &record.torque {
            self.apply_torque(torque, &at)?;
        }
        let tip_deviation = self.apply_values(&record, &at, tip_elements)?;
        if (self.has_compliance() || !self.transversal.is_empty()) && record.torque.is_none() {
            return Err(invalid(
                origin,
                "the record holds compliances but no [torque] table (their gravity load)"
                    .to_owned(),
            ));
        }
        self.check_nominal(&record, text, origin, known_joints)?;
        self.apply_nominal(&tip_deviation);
        if let Some(region) = &record.region {
            self.apply_region(region, &at, known_joints)?;
        }
        self.record = Some(record);
        Ok(())
    }

    /// The index of the moving joint `joint`, for the value `what` of the record at `at`.
    ///
    /// # Errors
    /// No moving joint of that name on the paths to the tips, at the value's line.
    fn joint_index_at(
        &self,
        at: &RecordAt<'_>,
        what: &str,
        joint: &str,
    ) -> Result<usize, LoadError> {
        self.joint_names
            .iter()
            .position(|n| n == joint)
            .ok_or_else(|| {
                at.value(
                    what,
                    format!(
                        "{what}: no moving joint {joint:?} on the paths to the tips; joints: {}",
                        self.joint_names.join(", ")
                    ),
                )
            })
    }

    /// The record's `[torque]` table: the gravity direction and acceleration, the load model
    /// (lumped weights at the tips, or the link masses) and which tips and joints carry it.
    ///
    /// # Errors
    /// A gravity direction of zero length, a haptic device's load, a mass on a joint the robot
    /// does not have, lumped weights at tips the robot was not loaded with.
    fn apply_torque(&mut self, torque: &Torque, at: &RecordAt<'_>) -> Result<(), LoadError> {
        let origin = at.origin;
        let g = torque.gravity_direction;
        let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        if !(norm > 1e-12 && norm.is_finite()) {
            return Err(invalid(
                origin,
                format!("torque.gravity_direction {g:?} has no direction"),
            ));
        }
        self.gravity_dir = [g[0] / norm, g[1] / norm, g[2] / norm];
        self.gravity_m_s2 = torque.gravity_m_s2;
        self.equilibrium = torque.equilibrium;
        match torque.source {
            TorqueSource::HandleMass => {
                return Err(invalid(
                    origin,
                    "torque.source = \"handle-mass\" is a haptic device's load, not a URDF robot's"
                        .to_owned(),
                ));
            }
            TorqueSource::LumpedUnitWeights => {
                self.gravity = GravityModel::Lumped;
                self.masses.clear();
            }
            TorqueSource::UrdfMasses | TorqueSource::PublishedMasses => {
                self.gravity = GravityModel::Masses;
                if !torque.masses.is_empty() {
                    let mut masses = Vec::with_capacity(torque.masses.len());
                    for m in &torque.masses {
                        masses.push(PointMass {
                            joint: self.joint_index_at(at, "torque.mass", &m.joint)?,
                            mass_kg: m.mass_kg,
                            com_m: m.com_m,
                        });
                    }
                    self.masses = masses;
                }
            }
        }
        // The lumped weights hang at the calibration's tips and the joints on their paths.
        let missing: Vec<&str> = (torque.tips.iter())
            .filter(|t| !self.tip_names.contains(t))
            .map(String::as_str)
            .collect();
        if self.gravity == GravityModel::Lumped && !missing.is_empty() {
            return Err(invalid(
                origin,
                format!(
                    "the calibration's gravity loads hang at the tips {}: load the robot with {} as tips too",
                    torque.tips.join(", "),
                    missing.join(", ")
                ),
            ));
        }
        if !torque.tips.is_empty() {
            for joint in &mut self.joints {
                joint.weight = false;
            }
            for k in 0..self.tips.len() {
                let carries = torque.tips.contains(&self.tip_names[k]);
                self.tips[k].weight = carries;
                let mut at = if carries { self.tips[k].parent } else { None };
                while let Some(j) = at {
                    self.joints[j].weight = true;
                    at = self.joints[j].parent;
                }
            }
        }
        Ok(())
    }

    /// The record's `[values]`: each joint's placement deviation, compliances, transversal
    /// compliances and joint harmonics set on the robot; returns each tip's deviation (tips
    /// sharing an element share it; `tip_elements` names each tip's element).
    ///
    /// # Errors
    /// A value name the contract does not parse, a value of another kind of robot (D-H on a
    /// URDF robot, placement on a D-H one, a haptic device's), a joint or element the robot
    /// does not have, a transversal compliance on a prismatic joint or a D-H row.
    fn apply_values(
        &mut self,
        record: &Calibration,
        at: &RecordAt<'_>,
        tip_elements: &[Option<String>],
    ) -> Result<Vec<[f64; 6]>, LoadError> {
        let mut tip_deviation = vec![[0.0; 6]; self.tips.len()];
        for v in &record.values {
            let name = ValueName::parse(&v.name).map_err(|e| at.value(&v.name, e))?;
            match name {
                ValueName::Element { element, field } => {
                    let k = field_index(field);
                    let joint = self.joint_names.iter().position(|n| *n == element);
                    if let (Some(_), Some(_)) = (joint, &self.dh) {
                        return Err(at.value(
                            &v.name,
                            format!(
                                "{:?} is a placement deviation: a D-H robot's record holds D-H deviations (da<i>, dalpha<i>, dd<i>, dtheta<i>, dbeta<i>)",
                                v.name
                            ),
                        ));
                    }
                    if let Some(j) = joint {
                        self.joints[j].deviation[k] = v.value;
                    } else if record.frames.contains_key(&element) && k < 6 {
                        // An identified frame's deviation from its nominal guess: the frame
                        // itself is in [frames]; the value and its σ serve the prediction's
                        // uncertainty ([`Robot::with_value`]).
                    } else if k < 6
                        && (tip_elements.iter()).any(|e| e.as_deref() == Some(element.as_str()))
                    {
                        // Tips sharing the element share its deviation.
                        for (d, e) in tip_deviation.iter_mut().zip(tip_elements) {
                            if e.as_deref() == Some(element.as_str()) {
                                d[k] = v.value;
                            }
                        }
                    } else {
                        return Err(at.value(
                            &v.name,
                            format!(
                                "{:?}: no moving joint or tip element {element:?} of this name on the paths to the tips; joints: {}",
                                v.name,
                                self.joint_names.join(", ")
                            ),
                        ));
                    }
                }
                ValueName::Compliance { joints } => {
                    for joint in &joints {
                        let j = self.joint_index_at(at, &v.name, joint)?;
                        self.compliance[j] = v.value;
                    }
                }
                ValueName::Transversal { joint, axis } => {
                    let j = self.joint_index_at(at, &v.name, &joint)?;
                    if self.dh.is_some() {
                        return Err(at.value(
                            &v.name,
                            format!(
                                "{:?}: a transversal compliance tilts a joint's placement, which a D-H row does not have",
                                v.name
                            ),
                        ));
                    }
                    if self.joints[j].prismatic {
                        return Err(at.value(
                            &v.name,
                            format!("{:?}: joint {joint:?} is prismatic", v.name),
                        ));
                    }
                    self.transversal.push(TransversalJoint {
                        joint: j,
                        compliance: v.value,
                        direction: transversal_direction(&self.joints[j].axis, axis),
                    });
                }
                ValueName::Harmonic { joint, order, sine } => {
                    let j = self.joint_index_at(at, &v.name, &joint)?;
                    self.harmonics.push(HarmonicTerm {
                        joint: j,
                        order,
                        sine,
                        coef: v.value,
                    });
                }
                // A D-H robot's rows already hold it (its nominal rows were read without it).
                ValueName::Dh { .. } if self.dh.is_some() => {}
                ValueName::Dh { .. } => {
                    return Err(at.value(
                        &v.name,
                        format!(
                            "{:?} is a D-H deviation: a calibrated URDF's record holds placement deviations (<joint>.x … .rz, .offset)",
                            v.name
                        ),
                    ));
                }
                ValueName::HandleCompliance { .. }
                | ValueName::Capstan { .. }
                | ValueName::Chebyshev { .. } => {
                    return Err(at.value(
                        &v.name,
                        format!(
                            "{:?} is a haptic device's value, not a URDF robot's",
                            v.name
                        ),
                    ));
                }
            }
        }
        Ok(tip_deviation)
    }

    /// The nominal geometry of the deviated joints and tips: the URDF's origins hold
    /// `nominal · Δ · motion(offset)`.
    fn apply_nominal(&mut self, tip_deviation: &[[f64; 6]]) {
        for joint in &mut self.joints {
            if joint.deviation == [0.0; 7] {
                continue;
            }
            let [x, y, z, rx, ry, rz, offset] = joint.deviation;
            let delta = deviation_pose(&[x, y, z, rx, ry, rz]);
            let undo = delta.compose(&joint_motion(joint, offset)).inverse();
            joint.nominal = joint.origin.compose(&undo);
            self.nominal_differs = true;
        }
        for (tip, d) in self.tips.iter_mut().zip(tip_deviation) {
            if *d != [0.0; 6] {
                tip.nominal_offset = tip.offset.compose(&deviation_pose(d).inverse());
                self.nominal_differs = true;
            }
        }
    }

    /// The record's `[region]`: each joint's training range with its slack.
    ///
    /// # Errors
    /// A joint the robot does not have (the record was written for another robot).
    fn apply_region(
        &mut self,
        region: &Region,
        at: &RecordAt<'_>,
        known_joints: &[(&str, Pose)],
    ) -> Result<(), LoadError> {
        let (text, origin) = (at.text, at.origin);
        for (k, r) in region.joints.iter().enumerate() {
            if !known_joints.iter().any(|(n, _)| *n == r.name) {
                let entry = [
                    Step::Key("region"),
                    Step::Key("joint"),
                    Step::Index(k),
                    Step::Key("name"),
                ];
                return Err(at_line(
                    origin,
                    TomlSpans::parse(text).record_line(&entry).unwrap_or((1, 1)),
                    format!(
                        "[region] joint {:?}: the robot has no joint of this name ({}): the \
                         record was written for another robot",
                        r.name,
                        (known_joints.iter())
                            .map(|(n, _)| *n)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            // A joint off the paths to the tips given has no reading to judge.
            let Some(j) = self.joint_names.iter().position(|n| *n == r.name) else {
                continue;
            };
            let slack = hapcal_contract::REGION_SLACK_SHARE * (r.max - r.min).max(0.0);
            self.region.push((j, r.min, r.max, slack));
        }
        Ok(())
    }
}

/// A calibration record's text and where it came from, for errors at a value's line.
struct RecordAt<'a> {
    /// The record's TOML text.
    text: &'a str,
    /// Where it came from (a file name).
    origin: &'a str,
}

impl RecordAt<'_> {
    /// A refusal of the value `name` at its line.
    fn value(&self, name: &str, message: String) -> LoadError {
        let at = TomlSpans::parse(self.text).value_line(name);
        at_line(self.origin, at.unwrap_or((0, 0)), message)
    }
}

/// Checks that `tip` is a link of `robot` and not among the tips `before` it.
///
/// # Errors
/// A tip given twice, or no link of that name (the links are listed).
fn check_tip(
    robot: &urdf::Robot,
    before: &[&str],
    tip: &str,
    origin: &str,
) -> Result<(), LoadError> {
    if before.contains(&tip) {
        return Err(invalid(origin, format!("tip link {tip:?} is given twice")));
    }
    if !robot.links.iter().any(|l| l.name == tip) {
        let names: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
        return Err(invalid(
            origin,
            format!(
                "no link {tip:?} to use as a tip; links: {}",
                names.join(", ")
            ),
        ));
    }
    Ok(())
}

/// The links' masses, each in the frame of the nearest moving joint above it (`joint_names`,
/// the robot's moving joints); massless links and links above every moving joint left out.
///
/// # Errors
/// A mass that is not finite and non-negative, or at a point that is not finite.
fn link_masses(
    robot: &urdf::Robot,
    joint_names: &[String],
    origin: &str,
) -> Result<Vec<PointMass>, LoadError> {
    let mut masses = Vec::new();
    for l in &robot.links {
        let (mass_kg, xyz) = urdf::inertial(l).map_err(|m| invalid(origin, m))?;
        if mass_kg == 0.0 {
            continue;
        }
        let walk = urdf::walk_up(robot, &l.name, |joint| joint_names.contains(&joint.name));
        let above = (walk.stop).and_then(|stop| joint_names.iter().position(|n| *n == stop.name));
        if let Some(joint) = above {
            let frame = (walk.passed.iter()).fold(Pose::IDENTITY, |frame, joint| {
                joint_pose(joint).compose(&frame)
            });
            masses.push(PointMass {
                joint,
                mass_kg,
                com_m: crate::robot::transform_point(&frame, &xyz),
            });
        }
    }
    Ok(masses)
}

/// The axis in its frame that a transversal compliance of a revolute joint of unit `axis`
/// bends about: `None` for an isotropic term; for a per-axis term `which` = `u` or `v`, one of
/// the two axes normal to `axis`: `u = axis × e` with `e` the frame axis least aligned with the
/// joint axis, normalised, and `v = axis × u` (`hapcal_problems`'s rule).
fn transversal_direction(axis: &[f64; 3], which: Option<char>) -> Option<[f64; 3]> {
    let which = which?;
    let mut k = 0;
    for i in 1..3 {
        if axis[i].abs() < axis[k].abs() {
            k = i;
        }
    }
    let mut e = [0.0; 3];
    e[k] = 1.0;
    let u = crate::pose::cross(axis, &e);
    let n = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = [u[0] / n, u[1] / n, u[2] / n];
    Some(if which == 'u' {
        u
    } else {
        crate::pose::cross(axis, &u)
    })
}

/// Refuses tips the calibration was not made for: every tip given must be one of the
/// record's tips or its load tips (a record of schema 1 that names them; an earlier hapcal's
/// names none).
fn check_tips(
    record: &Calibration,
    text: &str,
    origin: &str,
    tips: &[&str],
) -> Result<(), LoadError> {
    if record.tips.is_empty() {
        return Ok(());
    }
    let load: &[String] = record.torque.as_ref().map_or(&[], |t| &t.tips);
    let Some(stranger) = (tips.iter()).find(|t| !record.tips.iter().chain(load).any(|r| r == *t))
    else {
        return Ok(());
    };
    let (line, column) = TomlSpans::parse(text)
        .record_line(&[Step::Key("tips")])
        .unwrap_or((0, 0));
    Err(at_line(
        origin,
        (line, column),
        format!(
            "tips = [{}]: the calibration was made for these tips, not for the tip {stranger:?} \
             given; load the robot with {} as tips (--tip {}), or calibrate for {stranger:?}",
            (record.tips.iter())
                .map(|t| format!("{t:?}"))
                .collect::<Vec<_>>()
                .join(", "),
            record.tips.join(", "),
            record.tips.join(" --tip ")
        ),
    ))
}

/// Largest difference between a URDF joint's `<origin>` and the record's nominal origin with
/// its values' deviation that [`Robot::check_nominal`] accepts, m and rad (entries of the
/// rotation matrices): the writer puts both in the files in full precision, so they agree to
/// rounding.
const NOMINAL_TOLERANCE: f64 = 1e-9;

/// The angles `[a, b, c]` (rad) of `R = Rx(a)·Ry(b)·Rz(c)`, the rotation of a placement
/// deviation ([`deviation_pose`]).
fn xyz_angles(r: &[[f64; 3]; 3]) -> [f64; 3] {
    [
        (-r[1][2]).atan2(r[2][2]),
        r[0][2].clamp(-1.0, 1.0).asin(),
        (-r[0][1]).atan2(r[0][0]),
    ]
}

impl Robot {
    /// Checks that the record's values and the URDF beside it hold one geometry: for every
    /// joint of the record's `[nominal]`, the URDF's `<origin>` of it (`urdf_joints`) must be
    /// the nominal origin composed with the values' deviation `Δ(x, y, z, rx, ry, rz)` and
    /// the joint's motion by its `.offset`, to [`NOMINAL_TOLERANCE`].
    ///
    /// # Errors
    /// A joint the URDF lacks; a value (or the URDF) edited by hand: each value that disagrees,
    /// at its line, with the number recorded and the number the URDF's origin holds.
    fn check_nominal(
        &self,
        record: &Calibration,
        text: &str,
        origin: &str,
        urdf_joints: &[(&str, Pose)],
    ) -> Result<(), LoadError> {
        for (element, nominal) in &record.nominal {
            let Some((_, own)) = urdf_joints.iter().find(|(n, _)| *n == element) else {
                return Err(at_line(
                    origin,
                    nominal_line(text, element),
                    format!(
                        "[nominal.{element}]: the URDF has no joint {element:?}: the record was \
                         written for another robot"
                    ),
                ));
            };
            let d = element_deviation(Some(record), element);
            let offset = (record.value(&format!("{element}.offset"))).map_or(0.0, |v| v.value);
            let motion = match self.joint_names.iter().position(|n| n == element) {
                Some(j) => joint_motion(&self.joints[j], offset),
                // A joint off the paths to the tips: its offset cannot be judged here.
                None if offset != 0.0 => continue,
                None => Pose::IDENTITY,
            };
            let nominal = origin_pose(nominal.xyz_m, nominal.rpy_rad);
            let expected = nominal.compose(&deviation_pose(&d)).compose(&motion);
            let worst = (0..3)
                .flat_map(|i| {
                    let t = (expected.translation_m[i] - own.translation_m[i]).abs();
                    (0..3)
                        .map(move |k| (expected.rotation[i][k] - own.rotation[i][k]).abs())
                        .chain(core::iter::once(t))
                })
                .fold(0.0_f64, f64::max);
            if worst <= NOMINAL_TOLERANCE {
                continue;
            }
            // What the URDF's origin holds: Δ = nominal⁻¹ · origin · motion⁻¹.
            let held = nominal.inverse().compose(own).compose(&motion.inverse());
            let angles = xyz_angles(&held.rotation);
            let implied: Vec<f64> = held.translation_m.iter().chain(&angles).copied().collect();
            let mut words = Vec::new();
            for (k, field) in DEVIATION_FIELDS.iter().enumerate() {
                if (d[k] - implied[k]).abs() <= NOMINAL_TOLERANCE {
                    continue;
                }
                let name = format!("{element}.{field}");
                let unit = if k < 3 { "m" } else { "rad" };
                let line = TomlSpans::parse(text)
                    .value_line(&name)
                    .map_or(0, |(l, _)| l);
                let at = if line > 0 {
                    format!(" (line {line})")
                } else {
                    " (not recorded)".to_owned()
                };
                words.push(format!(
                    "{name} = {} {unit}{at}, where the URDF's origin of {element} holds {} {unit}",
                    d[k], implied[k]
                ));
            }
            let first = (DEVIATION_FIELDS.iter())
                .map(|f| format!("{element}.{f}"))
                .chain(core::iter::once(format!("{element}.offset")))
                .find_map(|name| TomlSpans::parse(text).value_line(&name))
                .unwrap_or_else(|| nominal_line(text, element));
            return Err(at_line(
                origin,
                first,
                format!(
                    "the record's values of joint {element:?} and the URDF beside it disagree \
                     (by {worst:.3e} m or rad): {}. A value is held in one place: the URDF's \
                     origins hold the calibrated geometry, the record its uncertainty; a value \
                     edited in one of them is not applied. Restore the number hapcal calibrate \
                     wrote, or calibrate again",
                    if words.is_empty() {
                        format!("{element}.offset")
                    } else {
                        words.join("; ")
                    }
                ),
            ));
        }
        Ok(())
    }
}

/// 1-based line and column of the record's `[nominal.<element>]` table in `text`; (0, 0) if
/// none.
fn nominal_line(text: &str, element: &str) -> (usize, usize) {
    TomlSpans::parse(text)
        .record_line(&[Step::Key("nominal"), Step::Key(element)])
        .unwrap_or((0, 0))
}
