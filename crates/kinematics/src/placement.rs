//! URDF-style joint placements (`<origin xyz rpy>` + `<axis>`).

use hapcal_contract::{ElementField as F, ValueName};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::{Chain, Error, Factor, Motion, ParamInfo, ParamUnit};

/// One URDF joint: its origin in the parent link frame and, for a moving joint, its axis
/// (ROS URDF specification, `<joint>`: `<origin xyz rpy>`, `<axis xyz>`, `type`).
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Joint name; becomes the joint / element name and the parameter prefix.
    pub name: String,
    /// Origin translation `xyz`, m, in the parent frame.
    pub xyz_m: [f64; 3],
    /// Origin rotation `rpy` = (roll, pitch, yaw), rad, fixed axes:
    /// `R = Rz(yaw) · Ry(pitch) · Rx(roll)`.
    pub rpy_rad: [f64; 3],
    /// Joint axis in the joint frame (any non-zero length; normalised); `None` = fixed joint.
    pub axis: Option<[f64; 3]>,
    /// True for a prismatic joint (translation along `axis` by `q`, m); false for a revolute
    /// or continuous one (rotation about `axis` by `q`, rad). Ignored for a fixed joint.
    pub prismatic: bool,
}

impl Placement {
    /// The origin transform `Trans(xyz) · Rz(yaw) · Ry(pitch) · Rx(roll)` (parent frame →
    /// joint frame at q = 0), translation in m.
    pub fn origin(&self) -> Isometry3<f64> {
        let [x, y, z] = self.xyz_m;
        let [roll, pitch, yaw] = self.rpy_rad;
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(roll, pitch, yaw),
        )
    }
}

/// Pushes the six deviation factors `Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz)` of `name`.
pub(crate) fn push_deviation(
    factors: &mut Vec<Factor>,
    params: &mut Vec<ParamInfo>,
    name: &str,
    element: usize,
) {
    let axes = [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()];
    for (motion, unit, names) in [
        (Motion::Translation, ParamUnit::Meter, [F::X, F::Y, F::Z]),
        (Motion::Rotation, ParamUnit::Radian, [F::Rx, F::Ry, F::Rz]),
    ] {
        for (axis, field) in axes.into_iter().zip(names) {
            factors.push(Factor::Screw {
                motion,
                axis,
                nominal: 0.0,
                param: Some(params.len()),
                joint: None,
            });
            params.push(ParamInfo {
                name: ValueName::Element {
                    element: name.to_owned(),
                    field,
                }
                .to_string(),
                unit,
                element,
            });
        }
    }
}

impl Chain {
    /// A chain from URDF joint placements, root to tip (revolute, continuous, prismatic and
    /// fixed joints).
    ///
    /// A revolute joint's transform is `Trans(xyz) · Rz(yaw)Ry(pitch)Rx(roll) · Δ ·
    /// Rot(axis, q)` (a prismatic joint's ends in `Trans(axis · q)`, q in m) with the deviation `Δ = Tx(x)·Ty(y)·Tz(z)·Rx(rx)·Ry(ry)·Rz(rz)` and
    /// parameters `{name}.x`, `{name}.y`, `{name}.z` (m), `{name}.rx`, `{name}.ry`,
    /// `{name}.rz` (rad). Fixed placements are folded into the next revolute joint's
    /// origin (no parameters of their own). Trailing fixed placements after the last
    /// revolute joint fold into one *tip* element named after the last placement, with
    /// its own six parameters; without them the tip is the last joint frame's origin.
    /// Joints and elements are named after their placements.
    ///
    /// # Errors
    ///
    /// [`Error::EmptyChain`] if `placements` is empty; [`Error::NotFinite`] for a NaN or
    /// infinite value; [`Error::ZeroAxis`] for an axis shorter than 1e-12;
    /// [`Error::DuplicateName`] if two joints or elements share a name.
    pub fn from_placements(placements: &[Placement]) -> Result<Chain, Error> {
        let Some(last) = placements.last() else {
            return Err(Error::EmptyChain);
        };
        for p in placements {
            let axis = p.axis.unwrap_or([0.0; 3]);
            let fields = (p.xyz_m.iter().map(|v| ("xyz_m", *v)))
                .chain(p.rpy_rad.iter().map(|v| ("rpy_rad", *v)))
                .chain(axis.iter().map(|v| ("axis", *v)));
            for (k, (field, value)) in fields.enumerate() {
                if !value.is_finite() {
                    return Err(Error::NotFinite {
                        element: p.name.clone(),
                        field: format!("{field}[{}]", k % 3),
                        value,
                    });
                }
            }
            if p.axis.is_some() && Vector3::from(axis).norm() < 1e-12 {
                return Err(Error::ZeroAxis {
                    element: p.name.clone(),
                    axis,
                });
            }
        }

        let mut factors = Vec::new();
        let mut params = Vec::new();
        let mut joint_names = Vec::new();
        let mut element_names = Vec::new();
        let mut pending = Isometry3::identity();
        let mut n_trailing_fixed = 0;
        for p in placements {
            let origin = pending * p.origin();
            let Some(axis) = p.axis else {
                pending = origin;
                n_trailing_fixed += 1;
                continue;
            };
            factors.push(Factor::Fixed(origin));
            push_deviation(&mut factors, &mut params, &p.name, element_names.len());
            factors.push(Factor::Screw {
                motion: if p.prismatic {
                    Motion::Translation
                } else {
                    Motion::Rotation
                },
                axis: Unit::new_normalize(Vector3::from(axis)),
                nominal: 0.0,
                param: None,
                joint: Some(joint_names.len()),
            });
            joint_names.push(p.name.clone());
            element_names.push(p.name.clone());
            pending = Isometry3::identity();
            n_trailing_fixed = 0;
        }
        if n_trailing_fixed > 0 {
            factors.push(Factor::Fixed(pending));
            push_deviation(&mut factors, &mut params, &last.name, element_names.len());
            element_names.push(last.name.clone());
        }
        Chain::from_factors(factors, params, joint_names, element_names)
    }
}
