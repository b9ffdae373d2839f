//! Loading a calibrated robot as `hapcal calibrate --out robot.urdf` writes it: the URDF with
//! calibrated joint origins and the sidecar `robot.calibration.toml` (identified frames and
//! compliances, what a URDF cannot hold).

use std::path::Path;

use serde::Deserialize;

use crate::robot::{PointMass, RobotJoint, RobotTip};
use crate::{GravityModel, LoadError, Pose, Robot};

/// The sidecar: `[frames.<name>]` and `[values]` (as `hapcal-calibrate`'s `sidecar_toml`).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Sidecar {
    #[serde(default)]
    frames: std::collections::BTreeMap<String, FrameEntry>,
    #[serde(default)]
    values: std::collections::BTreeMap<String, ValueEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameEntry {
    xyz_m: [f64; 3],
    rpy_rad: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ValueEntry {
    value: f64,
    #[serde(default)]
    #[expect(
        dead_code,
        reason = "the runtime evaluates the values, not their spread"
    )]
    std: Option<f64>,
    unit: String,
}

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

fn invalid(origin: &str, message: String) -> LoadError {
    LoadError::Invalid {
        origin: origin.to_owned(),
        message,
    }
}

fn joint_pose(joint: &urdf_rs::Joint) -> Pose {
    origin_pose(joint.origin.xyz.0, joint.origin.rpy.0)
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
    /// of the paths (a moving joint off the paths held at zero). From the sidecar: the frames
    /// ([`Robot::frame`]) and the compliances `compliance.<joint>` (or
    /// `compliance.<joint>+<joint>…` for a shared one), in rad/(N·m) with link masses and in
    /// rad/m without (the calibration's lumped unit weights; the tips must then be those of
    /// the calibration). Gravity is along −z of the root link (ROS REP 103).
    ///
    /// # Errors
    /// [`LoadError::Io`] for a file that cannot be read; [`LoadError::Parse`] (line, column)
    /// for a malformed sidecar; [`LoadError::Invalid`] for a URDF that urdf-rs cannot read, a
    /// tip that is not a link (listing them), a tip named twice, a floating or planar joint on
    /// a path, a joint without axis, a non-finite number, a negative mass, a sidecar value the
    /// runtime does not evaluate (transversal compliance, joint harmonics), a compliance of an
    /// unknown joint or in the wrong unit.
    pub fn load_urdf(urdf: &Path, tips: &[&str]) -> Result<Robot, LoadError> {
        let read = |path: &Path| {
            std::fs::read_to_string(path).map_err(|e| LoadError::Io {
                path: path.to_path_buf(),
                message: e.to_string(),
            })
        };
        let text = read(urdf)?;
        let sidecar_path = urdf.with_extension("calibration.toml");
        let sidecar = if sidecar_path.is_file() {
            Some((read(&sidecar_path)?, sidecar_path.display().to_string()))
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
        let robot = urdf_rs::read_from_string(urdf)
            .map_err(|e| invalid(origin, format!("not a valid URDF: {e}")))?;
        if tips.is_empty() {
            return Err(invalid(origin, "no tip link given".to_owned()));
        }
        let parent_joint = |link: &str| robot.joints.iter().find(|j| j.child.link == link);
        let mut joints: Vec<RobotJoint> = Vec::new();
        let mut joint_names: Vec<String> = Vec::new();
        let mut limits = Vec::new();
        let mut robot_tips = Vec::new();
        for (i, &tip) in tips.iter().enumerate() {
            if tips[..i].contains(&tip) {
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
            let mut path = Vec::new();
            let mut link = tip;
            while let Some(joint) = parent_joint(link) {
                if path.len() >= robot.joints.len() {
                    return Err(invalid(
                        origin,
                        format!("the joints above link {tip:?} form a loop"),
                    ));
                }
                path.push(joint);
                link = &joint.parent.link;
            }
            path.reverse();
            let mut parent: Option<usize> = None;
            let mut pending = Pose::IDENTITY;
            for joint in path {
                let name = &joint.name;
                let (xyz, rpy) = (joint.origin.xyz.0, joint.origin.rpy.0);
                if xyz.iter().chain(&rpy).any(|v| !v.is_finite()) {
                    return Err(invalid(
                        origin,
                        format!("joint {name:?}: origin xyz {xyz:?} rpy {rpy:?} is not finite"),
                    ));
                }
                let prismatic = match joint.joint_type {
                    urdf_rs::JointType::Fixed => {
                        pending = pending.compose(&joint_pose(joint));
                        continue;
                    }
                    urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => false,
                    urdf_rs::JointType::Prismatic => true,
                    ref other => {
                        return Err(invalid(
                            origin,
                            format!(
                                "joint {name:?} is {}: the runtime evaluates revolute, continuous, prismatic and fixed joints",
                                format!("{other:?}").to_lowercase()
                            ),
                        ));
                    }
                };
                if let Some(k) = joint_names.iter().position(|n| n == name) {
                    parent = Some(k);
                    pending = Pose::IDENTITY;
                    continue;
                }
                let axis = joint.axis.xyz.0;
                let norm = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
                if !norm.is_finite() || norm < 1e-12 {
                    return Err(invalid(
                        origin,
                        format!("joint {name:?}: axis {axis:?} has no direction"),
                    ));
                }
                let (lower, upper) = match joint.joint_type {
                    urdf_rs::JointType::Continuous => (f64::NEG_INFINITY, f64::INFINITY),
                    _ => (joint.limit.lower, joint.limit.upper),
                };
                if lower.is_nan() || upper.is_nan() || lower > upper {
                    return Err(invalid(
                        origin,
                        format!("joint {name:?}: limits [{lower}, {upper}] are not lower ≤ upper"),
                    ));
                }
                joints.push(RobotJoint {
                    parent,
                    origin: pending.compose(&joint_pose(joint)),
                    axis: [axis[0] / norm, axis[1] / norm, axis[2] / norm],
                    prismatic,
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
            });
        }
        if joints.is_empty() {
            return Err(invalid(
                origin,
                "no moving joint between the root link and the tips".to_owned(),
            ));
        }
        // Link masses, each in the frame of the nearest moving joint above it.
        let mut masses = Vec::new();
        for l in &robot.links {
            let mass_kg = l.inertial.mass.value;
            let xyz = l.inertial.origin.xyz.0;
            if !(mass_kg.is_finite() && mass_kg >= 0.0) || xyz.iter().any(|v| !v.is_finite()) {
                return Err(invalid(
                    origin,
                    format!(
                        "link {:?}: inertial mass {mass_kg} kg at {xyz:?} m is not a finite, non-negative mass at a finite point",
                        l.name
                    ),
                ));
            }
            if mass_kg == 0.0 {
                continue;
            }
            let mut frame = Pose::IDENTITY;
            let mut link = l.name.as_str();
            let mut above = None;
            for _ in 0..=robot.joints.len() {
                let Some(joint) = parent_joint(link) else {
                    break;
                };
                if let Some(j) = joint_names.iter().position(|n| *n == joint.name) {
                    above = Some(j);
                    break;
                }
                frame = joint_pose(joint).compose(&frame);
                link = &joint.parent.link;
            }
            if let Some(joint) = above {
                masses.push(PointMass {
                    joint,
                    mass_kg,
                    com_m: crate::robot::transform_point(&frame, &xyz),
                });
            }
        }
        let gravity = if masses.is_empty() {
            GravityModel::Lumped
        } else {
            GravityModel::Masses
        };
        let n = joints.len();
        let mut out = Robot {
            joints,
            joint_names,
            limits,
            tips: robot_tips,
            tip_names: tips.iter().map(|t| (*t).to_owned()).collect(),
            masses,
            compliance: vec![0.0; n],
            gravity,
            gravity_dir: [0.0, 0.0, -1.0],
            frames: Vec::new(),
            record: None,
            region: Vec::new(),
        };
        if let Some((text, sidecar_origin)) = sidecar {
            out.apply_sidecar(text, sidecar_origin)?;
        }
        Ok(out)
    }

    /// Reads the sidecar's frames and compliances into the robot.
    fn apply_sidecar(&mut self, text: &str, origin: &str) -> Result<(), LoadError> {
        let sidecar: Sidecar = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map_or((0, 0), |s| crate::load::line_column(text, s.start));
            LoadError::Parse {
                origin: origin.to_owned(),
                line,
                column,
                message: e.message().to_owned(),
            }
        })?;
        for (name, f) in &sidecar.frames {
            if f.xyz_m.iter().chain(&f.rpy_rad).any(|v| !v.is_finite()) {
                return Err(invalid(
                    origin,
                    format!("frames.{name}: a value is not finite"),
                ));
            }
            self.frames
                .push((name.clone(), origin_pose(f.xyz_m, f.rpy_rad)));
        }
        let unit = match self.gravity {
            GravityModel::Masses => "rad/(N·m)",
            GravityModel::Lumped => "rad/m",
        };
        for (name, v) in &sidecar.values {
            let Some(joints) = name.strip_prefix("compliance.") else {
                return Err(invalid(
                    origin,
                    format!(
                        "{name:?}: the runtime evaluates the compliances (compliance.<joint>) of a sidecar, not this value"
                    ),
                ));
            };
            if v.unit != unit {
                return Err(invalid(
                    origin,
                    format!(
                        "{name:?} is in {:?}, expected {unit:?} ({})",
                        v.unit,
                        match self.gravity {
                            GravityModel::Masses => "the URDF has link masses",
                            GravityModel::Lumped =>
                                "the URDF has no link masses: lumped unit weights",
                        }
                    ),
                ));
            }
            if !v.value.is_finite() {
                return Err(invalid(
                    origin,
                    format!("{name:?} = {} is not finite", v.value),
                ));
            }
            for joint in joints.split('+') {
                let Some(j) = self.joint_names.iter().position(|n| n == joint) else {
                    return Err(invalid(
                        origin,
                        format!(
                            "{name:?}: no moving joint {joint:?} on the paths to the tips; joints: {}",
                            self.joint_names.join(", ")
                        ),
                    ));
                };
                self.compliance[j] = v.value;
            }
        }
        Ok(())
    }
}

/// [`Robot::with_value`].
pub(crate) fn with_value(robot: &Robot, name: &str, value: f64) -> Result<Robot, crate::Error> {
    let _ = (robot, name, value);
    Err(crate::Error::Invalid {
        what: "value",
        value,
        expected: "a value the calibration record holds",
    })
}
