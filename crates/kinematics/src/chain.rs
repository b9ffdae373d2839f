//! The factor chain, its evaluation and its Jacobians.

use std::collections::HashSet;

use nalgebra::{Isometry3, Matrix3xX, Matrix6xX, Point3, Unit, UnitQuaternion, Vector3};

use crate::Error;

/// Kind of motion of a [`Factor::Screw`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// Rotation about the axis (value in rad).
    Rotation,
    /// Translation along the axis (value in m).
    Translation,
}

/// Unit of a kinematic parameter deviation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamUnit {
    /// Metre (lengths: `da*`, `dd*`, `{joint}.x`, …).
    Meter,
    /// Radian (angles: `dalpha*`, `dtheta*`, `dbeta*`, `{joint}.rx`, …).
    Radian,
}

impl ParamUnit {
    /// SI symbol for reports: `"m"` or `"rad"`.
    pub fn symbol(self) -> &'static str {
        match self {
            ParamUnit::Meter => "m",
            ParamUnit::Radian => "rad",
        }
    }
}

/// Name, unit and owner of one entry of the deviation vector `x`.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamInfo {
    /// Stable name used in files and reports, e.g. `dtheta3` or `ball_joint.rx`.
    pub name: String,
    /// Unit of the deviation (m or rad).
    pub unit: ParamUnit,
    /// Index into [`Chain::element_names`] of the element (D-H row or URDF joint) it
    /// belongs to.
    pub element: usize,
}

/// One elementary transform of a serial chain.
#[derive(Clone, Debug, PartialEq)]
pub enum Factor {
    /// A constant transform (rigid, m for the translation).
    Fixed(Isometry3<f64>),
    /// Rotation about / translation along a unit axis of the current frame by
    /// `nominal + x[param] + q[joint]` (rad or m); `param` and `joint` are optional.
    Screw {
        /// Rotation or translation.
        motion: Motion,
        /// Unit axis, expressed in the frame just before this factor.
        axis: Unit<Vector3<f64>>,
        /// Nominal angle (rad) or displacement (m).
        nominal: f64,
        /// Index into `x` of the deviation added to `nominal`, if any.
        param: Option<usize>,
        /// Index into `q` of the joint angle added to `nominal`, if any.
        joint: Option<usize>,
    },
}

impl Factor {
    /// The factor's transform for deviations `x` and joint angles `q` (the frame just
    /// after the factor, expressed in the frame just before it).
    ///
    /// # Panics
    ///
    /// If `param` or `joint` index past the end of `x` or `q`.
    #[track_caller]
    pub fn transform(&self, x: &[f64], q: &[f64]) -> Isometry3<f64> {
        let mut pose = Isometry3::identity();
        apply(&mut pose, self, x, q);
        pose
    }
}

/// Right-multiplies `pose` by the factor's transform, in place.
#[inline]
fn apply(pose: &mut Isometry3<f64>, factor: &Factor, x: &[f64], q: &[f64]) {
    match factor {
        Factor::Fixed(t) => *pose *= t,
        Factor::Screw {
            motion,
            axis,
            nominal,
            param,
            joint,
        } => {
            let value = nominal + param.map_or(0.0, |j| x[j]) + joint.map_or(0.0, |j| q[j]);
            // A zero screw is the identity: most deviation parameters are zero or pruned, and
            // skipping them halves the cost of a URDF-placement chain (6 screws per joint).
            if value == 0.0 {
                return;
            }
            match motion {
                Motion::Rotation => pose.rotation *= UnitQuaternion::from_axis_angle(axis, value),
                Motion::Translation => {
                    pose.translation.vector += pose.rotation * (axis.into_inner() * value);
                }
            }
        }
    }
}

/// The motion of each joint of `chains` (the tips of one tree, all with the same joints):
/// rotation or translation of the screw that carries it, `None` for a joint no chain moves.
/// Length: the first chain's joint count (0 without a chain).
pub fn joint_motions(chains: &[Chain]) -> Vec<Option<Motion>> {
    let n = chains.first().map_or(0, Chain::n_joints);
    let mut motions = vec![None; n];
    for chain in chains {
        for factor in chain.factors() {
            if let Factor::Screw {
                motion,
                joint: Some(j),
                ..
            } = factor
                && let Some(m) = motions.get_mut(*j)
            {
                *m = Some(*motion);
            }
        }
    }
    motions
}

/// A serial kinematic chain: a sequence of [`Factor`]s from the base frame to the tip
/// frame, with named parameters, joints and elements.
///
/// Valid by construction (see [`Chain::from_factors`]). Built with [`Chain::from_dh`]
/// (Denavit–Hartenberg 1955 / Craig 1989 / Hayati 1983), [`Chain::from_placements`] (ROS
/// URDF joint origins) or [`Chain::from_factors`]. The tip (end point) is the origin of
/// the frame after the last factor.
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    pub(crate) factors: Vec<Factor>,
    pub(crate) params: Vec<ParamInfo>,
    pub(crate) joint_names: Vec<String>,
    pub(crate) element_names: Vec<String>,
}

/// Reusable buffers for [`Chain::point_and_jacobian_in`], so the hot path allocates
/// nothing per call (the model/data split of Pinocchio, `doc/a-features/b-model-data.md`).
///
/// One workspace may serve several chains; it grows to the largest.
#[derive(Clone, Debug)]
pub struct FkWorkspace {
    /// World pose after each factor.
    poses: Vec<Isometry3<f64>>,
    /// World frame (rotation columns, translation) at the start of each constant run of a
    /// [`FrozenChain`](crate::FrozenChain).
    pub(crate) starts: Vec<[Vector3<f64>; 4]>,
}

impl FkWorkspace {
    /// A workspace sized for `chain`.
    pub fn new(chain: &Chain) -> FkWorkspace {
        FkWorkspace {
            poses: Vec::with_capacity(chain.factors.len()),
            starts: Vec::with_capacity(chain.joint_names.len() + 1),
        }
    }
}

fn check_unique<'a>(kind: &'static str, names: impl Iterator<Item = &'a str>) -> Result<(), Error> {
    let mut seen = HashSet::new();
    for name in names {
        if !seen.insert(name) {
            return Err(Error::DuplicateName {
                kind,
                name: name.to_owned(),
            });
        }
    }
    Ok(())
}

impl Chain {
    /// A chain from explicit factors.
    ///
    /// `params` names the entries of `x` (factor `param` indices point into it),
    /// `joint_names` the entries of `q`, `element_names` the owners of parameters
    /// ([`ParamInfo::element`] indexes it). A joint or parameter used by no factor is
    /// allowed (its Jacobian column is zero).
    ///
    /// # Errors
    ///
    /// [`Error::EmptyChain`] if `factors` is empty; [`Error::NotFinite`] for a NaN or
    /// infinite transform or nominal value; [`Error::AxisNotUnit`] if a screw axis is not
    /// unit length within 1e-9; [`Error::ParamOutOfRange`], [`Error::JointOutOfRange`],
    /// [`Error::ElementOutOfRange`] for indices out of range; [`Error::DuplicateName`] if
    /// two parameters, joints or elements share a name.
    pub fn from_factors(
        factors: Vec<Factor>,
        params: Vec<ParamInfo>,
        joint_names: Vec<String>,
        element_names: Vec<String>,
    ) -> Result<Chain, Error> {
        if factors.is_empty() {
            return Err(Error::EmptyChain);
        }
        let not_finite = |factor: usize, field: &str, value: f64| Error::NotFinite {
            element: format!("factor{factor}"),
            field: field.to_owned(),
            value,
        };
        for (k, factor) in factors.iter().enumerate() {
            match factor {
                Factor::Fixed(t) => {
                    let values = t.translation.vector.iter().chain(t.rotation.coords.iter());
                    if let Some(&v) = values.clone().find(|v| !v.is_finite()) {
                        return Err(not_finite(k, "transform", v));
                    }
                }
                Factor::Screw {
                    axis,
                    nominal,
                    param,
                    joint,
                    ..
                } => {
                    if !nominal.is_finite() {
                        return Err(not_finite(k, "nominal", *nominal));
                    }
                    let norm = axis.norm();
                    if !norm.is_finite() || (norm - 1.0).abs() > 1e-9 {
                        return Err(Error::AxisNotUnit { factor: k, norm });
                    }
                    if let Some(index) = *param
                        && index >= params.len()
                    {
                        return Err(Error::ParamOutOfRange {
                            factor: k,
                            index,
                            n_params: params.len(),
                        });
                    }
                    if let Some(index) = *joint
                        && index >= joint_names.len()
                    {
                        return Err(Error::JointOutOfRange {
                            factor: k,
                            index,
                            n_joints: joint_names.len(),
                        });
                    }
                }
            }
        }
        if let Some(p) = params.iter().find(|p| p.element >= element_names.len()) {
            return Err(Error::ElementOutOfRange {
                param: p.name.clone(),
                index: p.element,
                n_elements: element_names.len(),
            });
        }
        check_unique("parameter", params.iter().map(|p| p.name.as_str()))?;
        check_unique("joint", joint_names.iter().map(String::as_str))?;
        check_unique("element", element_names.iter().map(String::as_str))?;
        Ok(Chain {
            factors,
            params,
            joint_names,
            element_names,
        })
    }

    /// Number of parameter deviations, the length of `x`.
    pub fn n_params(&self) -> usize {
        self.params.len()
    }

    /// Number of joints, the length of `q`.
    pub fn n_joints(&self) -> usize {
        self.joint_names.len()
    }

    /// Name, unit and element of each entry of `x` (length [`Chain::n_params`]).
    pub fn params(&self) -> &[ParamInfo] {
        &self.params
    }

    /// Name of each entry of `q` (length [`Chain::n_joints`]), e.g. `q1` for D-H chains.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// Name of each element (D-H row `row{i}`, URDF joint or tip placement).
    pub fn element_names(&self) -> &[String] {
        &self.element_names
    }

    /// The factors, base to tip.
    pub fn factors(&self) -> &[Factor] {
        &self.factors
    }

    /// Index into `x` of the parameter called `name`, if any.
    pub fn param_index(&self, name: &str) -> Option<usize> {
        self.params.iter().position(|p| p.name == name)
    }

    /// Panics unless `x` has one entry per parameter.
    #[track_caller]
    pub(crate) fn check_params_len(&self, x: &[f64]) {
        assert_eq!(
            x.len(),
            self.n_params(),
            "x has length {}, but the chain has {} parameters",
            x.len(),
            self.n_params()
        );
    }

    #[track_caller]
    fn check_shapes(&self, x: &[f64], q: &[f64]) {
        self.check_params_len(x);
        assert_eq!(
            q.len(),
            self.n_joints(),
            "q has length {}, but the chain has {} joints",
            q.len(),
            self.n_joints()
        );
    }

    /// Fills `poses` with the world pose after each factor.
    fn fill_poses(&self, x: &[f64], q: &[f64], poses: &mut Vec<Isometry3<f64>>) {
        poses.clear();
        let mut pose = Isometry3::identity();
        for factor in &self.factors {
            apply(&mut pose, factor, x, q);
            poses.push(pose);
        }
    }

    /// World pose (base frame) after each factor, length `factors().len()`; the last one
    /// is [`Chain::end_pose`]. Translations in m.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn frame_poses(&self, x: &[f64], q: &[f64]) -> Vec<Isometry3<f64>> {
        self.check_shapes(x, q);
        let mut poses = Vec::with_capacity(self.factors.len());
        self.fill_poses(x, q, &mut poses);
        poses
    }

    /// Pose of the tip frame in the base frame, `base_T_tip` (the product of all factors;
    /// paper eq. 4 for D-H chains). Translation in m.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn end_pose(&self, x: &[f64], q: &[f64]) -> Isometry3<f64> {
        self.check_shapes(x, q);
        let mut pose = Isometry3::identity();
        for factor in &self.factors {
            apply(&mut pose, factor, x, q);
        }
        pose
    }

    /// End point (tip origin) in the base frame, m (`P` of paper eq. 5).
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn end_point(&self, x: &[f64], q: &[f64]) -> Point3<f64> {
        Point3::from(self.end_pose(x, q).translation.vector)
    }

    /// End point (m, base frame) and its Jacobian with respect to `x`, without
    /// allocating once `ws` has grown to the chain.
    ///
    /// `jac_out` has length `3 · n_params()`, column-major 3 × `n_params()`:
    /// `jac_out[3*j + k] = ∂p_k/∂x_j`, m/m for lengths and m/rad for angles. For a screw
    /// with world frame F (pose just after it) and world axis `w = R_F · axis`, a rotation
    /// contributes `w × (p − o_F)` and a translation `w`; a parameter used by several
    /// factors sums their contributions.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()`, `q.len() != n_joints()` or
    /// `jac_out.len() != 3 * n_params()`.
    #[track_caller]
    pub fn point_and_jacobian_in(
        &self,
        x: &[f64],
        q: &[f64],
        ws: &mut FkWorkspace,
        jac_out: &mut [f64],
    ) -> Point3<f64> {
        let end = self.jacobian_rows_in(x, q, ws, jac_out, 3);
        Point3::from(end.translation.vector)
    }

    /// Tip pose (base frame, m) and its Jacobian with respect to `x`, without allocating
    /// once `ws` has grown to the chain.
    ///
    /// `jac_out` has length `6 · n_params()`, column-major 6 × `n_params()`: rows 0–2 are
    /// `∂p/∂x_j` as in [`Chain::point_and_jacobian_in`], rows 3–5 the rotation vector `ω`
    /// with `δR = [ω]× R` per unit parameter (base frame), as in
    /// [`Chain::pose_jacobian_wrt_params`].
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()`, `q.len() != n_joints()` or
    /// `jac_out.len() != 6 * n_params()`.
    #[track_caller]
    pub fn pose_and_jacobian_in(
        &self,
        x: &[f64],
        q: &[f64],
        ws: &mut FkWorkspace,
        jac_out: &mut [f64],
    ) -> Isometry3<f64> {
        self.jacobian_rows_in(x, q, ws, jac_out, 6)
    }

    /// Tip pose and the first `rows` rows of its Jacobian with respect to `x` into `jac_out`
    /// (column-major `rows × n_params()`): 3, the end point's
    /// ([`Chain::point_and_jacobian_in`]); 6, with the rotation vector's
    /// ([`Chain::pose_and_jacobian_in`]).
    #[track_caller]
    fn jacobian_rows_in(
        &self,
        x: &[f64],
        q: &[f64],
        ws: &mut FkWorkspace,
        jac_out: &mut [f64],
        rows: usize,
    ) -> Isometry3<f64> {
        self.check_shapes(x, q);
        assert_eq!(
            jac_out.len(),
            rows * self.n_params(),
            "jac_out has length {}, expected {rows} × {} parameters",
            jac_out.len(),
            self.n_params()
        );
        self.fill_poses(x, q, &mut ws.poses);
        let end = ws.poses.last().copied().unwrap_or_else(Isometry3::identity);
        let tip = end.translation.vector;
        jac_out.fill(0.0);
        for (factor, pose) in self.factors.iter().zip(&ws.poses) {
            if let Factor::Screw {
                motion,
                axis,
                param: Some(j),
                ..
            } = factor
            {
                let w = pose.rotation * axis.into_inner();
                let (linear, angular) = match motion {
                    Motion::Rotation => (w.cross(&(tip - pose.translation.vector)), w),
                    Motion::Translation => (w, Vector3::zeros()),
                };
                let col = &mut jac_out[rows * j..rows * (j + 1)];
                for k in 0..3 {
                    col[k] += linear[k];
                }
                if rows == 6 {
                    for k in 0..3 {
                        col[3 + k] += angular[k];
                    }
                }
            }
        }
        end
    }

    /// Jacobian of the end point with respect to `x`: 3 × `n_params()`, base frame,
    /// m/m for lengths and m/rad for angles (see [`Chain::point_and_jacobian_in`]).
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn point_jacobian_wrt_params(&self, x: &[f64], q: &[f64]) -> Matrix3xX<f64> {
        let mut jac = Matrix3xX::zeros(self.n_params());
        let mut ws = FkWorkspace::new(self);
        self.point_and_jacobian_in(x, q, &mut ws, jac.as_mut_slice());
        jac
    }

    /// Pose Jacobian of the tip with respect to `x`: 6 × `n_params()`, base frame.
    ///
    /// Rows 0–2: ∂p/∂x as in [`Chain::point_jacobian_wrt_params`] (m/m, m/rad). Rows 3–5:
    /// the angular part, the rotation vector ω with `δR = [ω]× R` per unit parameter
    /// (rad/rad for angles, rad/m = 0 for lengths): `w` for a rotation, 0 for a translation.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn pose_jacobian_wrt_params(&self, x: &[f64], q: &[f64]) -> Matrix6xX<f64> {
        self.twist_jacobian(x, q, self.n_params(), |f| match f {
            Factor::Screw { param, .. } => *param,
            Factor::Fixed(_) => None,
        })
    }

    /// Geometric Jacobian with respect to the joints: 6 × `n_joints()`, base frame, per
    /// unit joint rate (rad/s). Rows 0–2: linear velocity of the end point (m/rad);
    /// rows 3–5: angular velocity of the tip frame (rad/rad). Siciliano et al., *Robotics:
    /// Modelling, Planning and Control*, 2009, §3.1.
    ///
    /// # Panics
    ///
    /// If `x.len() != n_params()` or `q.len() != n_joints()`.
    #[track_caller]
    pub fn geometric_jacobian(&self, x: &[f64], q: &[f64]) -> Matrix6xX<f64> {
        self.twist_jacobian(x, q, self.n_joints(), |f| match f {
            Factor::Screw { joint, .. } => *joint,
            Factor::Fixed(_) => None,
        })
    }

    /// The 6 × `n_columns` Jacobian at `x`, `q` that adds each screw's twist (linear part at
    /// the tip, angular part) to the column that `column_of` assigns it.
    #[track_caller]
    fn twist_jacobian(
        &self,
        x: &[f64],
        q: &[f64],
        n_columns: usize,
        column_of: impl Fn(&Factor) -> Option<usize>,
    ) -> Matrix6xX<f64> {
        let poses = self.frame_poses(x, q);
        let mut jac = Matrix6xX::zeros(n_columns);
        let tip = poses
            .last()
            .map_or(Vector3::zeros(), |t| t.translation.vector);
        for (factor, pose) in self.factors.iter().zip(&poses) {
            let (Factor::Screw { motion, axis, .. }, Some(j)) = (factor, column_of(factor)) else {
                continue;
            };
            let w = pose.rotation * axis.into_inner();
            let (linear, angular) = match motion {
                Motion::Rotation => (w.cross(&(tip - pose.translation.vector)), w),
                Motion::Translation => (w, Vector3::zeros()),
            };
            let mut lin_rows = jac.fixed_view_mut::<3, 1>(0, j);
            lin_rows += linear;
            let mut ang_rows = jac.fixed_view_mut::<3, 1>(3, j);
            ang_rows += angular;
        }
        jac
    }
}
