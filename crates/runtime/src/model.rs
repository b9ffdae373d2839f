//! The calibrated device: a D-H chain folded into one constant transform per joint, and one
//! drive per joint.

use crate::error::{check_finite, check_len};
use crate::math::sin_cos;
use crate::pose::cross;
use crate::{Drive, Error, MAX_JOINTS, MAX_ROWS, Pose};

/// Which Denavit–Hartenberg convention the rows of a [`Model`] follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DhConvention {
    /// Standard (distal) D-H, paper eq. 3:
    /// `A_i = Rz(θ_i + q) · Tz(d_i) · Tx(a_i) · Rx(α_i) [· Ry(β_i)]`.
    Standard,
    /// Modified (proximal) D-H, Craig 1989, *Introduction to Robotics*, §3.4:
    /// `A_i = Rx(α_i) [· Ry(β_i)] · Tx(a_i) · Rz(θ_i + q) · Tz(d_i)`.
    Modified,
}

/// One D-H row of a calibrated chain (the identified deviations already added, as
/// `hapcal calibrate` writes them into the device file's `[[dh]]` rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhRow {
    /// Link length `a`, m.
    pub a_m: f64,
    /// Link twist `α`, rad.
    pub alpha_rad: f64,
    /// Link offset `d`, m.
    pub d_m: f64,
    /// Joint angle offset `θ`, rad (the joint angle q is added to it).
    pub theta_rad: f64,
    /// Hayati's `β` about y, rad (Hayati 1983), or `None`.
    pub beta_rad: Option<f64>,
    /// Whether the row carries a revolute joint; the joints are numbered in row order.
    /// `false`: a constant transform (e.g. row 0, rig → base).
    pub joint: bool,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Link {
    /// `θ_i` of the joint's row, rad.
    theta0_rad: f64,
    /// Everything from just after the joint's `Rz` to just before the next joint's `Rz`
    /// (the tip, for the last joint).
    after: Pose,
}

/// A calibrated serial device ready to evaluate: at most [`MAX_JOINTS`] revolute joints, each
/// with its [`Drive`]. Fixed-size storage: evaluating never allocates.
///
/// The chain is `T = B · Rz(θ_1 + q_1) · C_1 · Rz(θ_2 + q_2) · C_2 ⋯ Rz(θ_n + q_n) · C_n`
/// (paper eq. 4), with the constant transforms `B`, `C_k` folded from the D-H rows at
/// construction. Poses are of the tip frame (the last row's frame, whose origin is the end
/// point) in the base frame of row 0; wrenches and the body Jacobian are in the tip frame at
/// the end point, as in the force study (docs/design.md §3.10).
///
/// Inputs are either the **readings** θ the device reports (rad, motor angle / R), mapped
/// through the drives, or the **joint angles** q (rad) directly (`…_at_joints`).
///
/// A model may carry a haptic handle's **gravity compliance**
/// ([`Model::with_handle_compliance`], `joint_compliance.j{k}` of a device file): from the
/// readings, each joint angle is then deflected by the handle's weight,
/// `q_j = q̄_j + k_j·τ_j(q̄)`, `q̄` the drives' angles and `τ = J_vᵀ·F` the gravity torque
/// of the handle's weight F at the end point (N·m; `J_v` the linear rows of the spatial
/// Jacobian at `q̄`), without iterating to the deflected equilibrium: the model
/// `hapcal_problems::handle_gravity_torques_nm` and `hapcal calibrate --model compliance`
/// identify. The `…_at_joints` calls take the joint angles as given (no deflection).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Model {
    base: Pose,
    links: [Link; MAX_JOINTS],
    drives: [Drive; MAX_JOINTS],
    n_joints: usize,
    /// The handle compliance k_j of each joint, rad/(N·m) (0: rigid).
    compliance: [f64; MAX_JOINTS],
    /// The handle's weight, a force at the end point in the base frame, N.
    handle_force_n: [f64; 3],
    /// The training range of the first `n_region` joints' readings: (min, max, slack), rad.
    region: [(f64, f64, f64); MAX_JOINTS],
    /// How many joints the region judges (0: no region recorded).
    n_region: usize,
}

/// Everything [`Model::evaluate`] computes for one reading. Entries past `n_joints` are 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evaluation {
    /// Number of joints n; the arrays below hold n entries.
    pub n_joints: usize,
    /// Joint angles q, rad (deflected by the handle's weight, if the model has a compliance).
    pub q_rad: [f64; MAX_JOINTS],
    /// `dq/dθ` of each drive, rad/rad.
    pub dq_dtheta: [f64; MAX_JOINTS],
    /// Tip pose in the base frame.
    pub pose: Pose,
    /// Body Jacobian, one column per joint (see [`Model::body_jacobian`]).
    pub body_jacobian: [[f64; 6]; MAX_JOINTS],
    /// Motor torques for the wrench, N·m (see [`Model::motor_torques`]).
    pub motor_torques_nm: [f64; MAX_JOINTS],
}

impl Default for Evaluation {
    fn default() -> Evaluation {
        Evaluation {
            n_joints: 0,
            q_rad: [0.0; MAX_JOINTS],
            dq_dtheta: [0.0; MAX_JOINTS],
            pose: Pose::IDENTITY,
            body_jacobian: [[0.0; 6]; MAX_JOINTS],
            motor_torques_nm: [0.0; MAX_JOINTS],
        }
    }
}

/// Which Jacobian [`Model::kinematics`] writes.
#[derive(Clone, Copy)]
enum Frame {
    Body,
    Spatial,
}

impl Model {
    /// A model from a D-H table (row 0 first) and one drive per joint (joints in row order).
    ///
    /// # Errors
    /// [`Error::TooMany`] past [`MAX_ROWS`] rows or [`MAX_JOINTS`] joints;
    /// [`Error::Invalid`] named `joints` for a chain without a joint; [`Error::NotFinite`]
    /// naming the field and row; [`Error::Length`] if `drives` does not have one entry per
    /// joint.
    pub fn from_dh(
        convention: DhConvention,
        rows: &[DhRow],
        drives: &[Drive],
    ) -> Result<Model, Error> {
        if rows.len() > MAX_ROWS {
            return Err(Error::TooMany {
                what: "rows",
                found: rows.len(),
                max: MAX_ROWS,
            });
        }
        let n_joints = rows.iter().filter(|r| r.joint).count();
        if n_joints > MAX_JOINTS {
            return Err(Error::TooMany {
                what: "joints",
                found: n_joints,
                max: MAX_JOINTS,
            });
        }
        if n_joints == 0 {
            return Err(Error::Invalid {
                what: "joints",
                value: 0.0,
                expected: "a chain with at least one joint",
            });
        }
        check_len("drives", n_joints, drives.len())?;
        for (index, row) in rows.iter().enumerate() {
            let fields = [
                ("a_m", row.a_m),
                ("alpha_rad", row.alpha_rad),
                ("d_m", row.d_m),
                ("theta_rad", row.theta_rad),
                ("beta_rad", row.beta_rad.unwrap_or(0.0)),
            ];
            for (what, value) in fields {
                if !value.is_finite() {
                    return Err(Error::NotFinite { what, index, value });
                }
            }
        }
        let link = Link {
            theta0_rad: 0.0,
            after: Pose::IDENTITY,
        };
        let mut model = Model {
            base: Pose::IDENTITY,
            links: [link; MAX_JOINTS],
            drives: [Drive::DIRECT; MAX_JOINTS],
            n_joints,
            compliance: [0.0; MAX_JOINTS],
            handle_force_n: [0.0; 3],
            region: [(0.0, 0.0, 0.0); MAX_JOINTS],
            n_region: 0,
        };
        model.drives[..n_joints].copy_from_slice(drives);
        // `acc` collects the constant transforms since the last joint's Rz.
        let mut acc = Pose::IDENTITY;
        let mut joint = 0;
        for row in rows {
            let (pre, post) = dh_split(convention, row, sin_cos);
            acc = acc.compose(&pre);
            if row.joint {
                if joint == 0 {
                    model.base = acc;
                } else {
                    model.links[joint - 1].after = acc;
                }
                model.links[joint].theta0_rad = row.theta_rad;
                acc = post;
                joint += 1;
            } else {
                let (s, c) = sin_cos(row.theta_rad);
                acc = acc.compose(&Pose::rot_z(s, c)).compose(&post);
            }
        }
        model.links[n_joints - 1].after = acc;
        Ok(model)
    }

    /// The same model with a haptic handle's gravity compliance: `k` one compliance per
    /// joint (rad/(N·m); 0 for a rigid joint), `handle_weight_n` the handle's weight m·g (N,
    /// ≥ 0) and `gravity_direction` the unit direction of gravity in the base frame (for a
    /// haptic device, minus the axis of joint 1: [`Model::joint1_axis`]). From the readings
    /// each joint angle is then deflected by `k_j·τ_j` (see [`Model`]). Allocation-free and
    /// `no_std`.
    ///
    /// # Errors
    /// [`Error::Length`] unless `k` has n entries; [`Error::NotFinite`] for a NaN or infinite
    /// value (`compliances`, `handle_weight_n`, `gravity_direction`); [`Error::Invalid`] for
    /// a negative weight or a direction that is not a unit vector (within 1e-6).
    pub fn with_handle_compliance(
        &self,
        k: &[f64],
        handle_weight_n: f64,
        gravity_direction: [f64; 3],
    ) -> Result<Model, Error> {
        check_len("compliances", self.n_joints, k.len())?;
        check_finite("compliances", k)?;
        check_finite("handle_weight_n", &[handle_weight_n])?;
        check_finite("gravity_direction", &gravity_direction)?;
        if handle_weight_n < 0.0 {
            return Err(Error::Invalid {
                what: "handle_weight_n",
                value: handle_weight_n,
                expected: "a weight ≥ 0 N",
            });
        }
        let g = gravity_direction;
        let norm2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
        if (norm2 - 1.0).abs() > 2e-6 {
            return Err(Error::Invalid {
                what: "gravity_direction",
                value: norm2,
                expected: "a unit vector (squared norm 1)",
            });
        }
        let mut model = *self;
        model.compliance = [0.0; MAX_JOINTS];
        model.compliance[..self.n_joints].copy_from_slice(k);
        model.handle_force_n = [
            handle_weight_n * g[0],
            handle_weight_n * g[1],
            handle_weight_n * g[2],
        ];
        Ok(model)
    }

    /// The same model with the region its calibration was fitted on: `ranges[k] = (min,
    /// max)` the training range of joint k's readings (rad), for the first `ranges.len()`
    /// joints; a reading more than `slack_share` of its range past it lies outside
    /// ([`Model::outside_region`]; the record's share is `hapcal_contract::REGION_SLACK_SHARE`).
    ///
    /// # Errors
    /// [`Error::TooMany`] for more ranges than joints; [`Error::NotFinite`] for a NaN or
    /// infinite bound; [`Error::Invalid`] for `min > max` or a negative `slack_share`.
    pub fn with_region(&self, ranges: &[(f64, f64)], slack_share: f64) -> Result<Model, Error> {
        if ranges.len() > self.n_joints {
            return Err(Error::TooMany {
                what: "region ranges",
                found: ranges.len(),
                max: self.n_joints,
            });
        }
        check_finite("slack_share", &[slack_share])?;
        if slack_share < 0.0 {
            return Err(Error::Invalid {
                what: "slack_share",
                value: slack_share,
                expected: "a share ≥ 0",
            });
        }
        let mut model = *self;
        model.region = [(0.0, 0.0, 0.0); MAX_JOINTS];
        for (index, (&(min, max), slot)) in ranges.iter().zip(&mut model.region).enumerate() {
            for value in [min, max] {
                if !value.is_finite() {
                    return Err(Error::NotFinite {
                        what: "region",
                        index,
                        value,
                    });
                }
            }
            if min > max {
                return Err(Error::Invalid {
                    what: "region",
                    value: min,
                    expected: "min ≤ max",
                });
            }
            *slot = (min, max, slack_share * (max - min));
        }
        model.n_region = ranges.len();
        Ok(model)
    }

    /// Whether the readings `theta` (rad) lie outside the region the calibration was fitted
    /// on ([`Model::with_region`], a device file's `[calibration.region]`): the joint farthest
    /// past its range (by share of the range) and by how much (rad; positive above the
    /// range, negative below); `None` inside, or without a recorded region. Allocation-free.
    ///
    /// # Errors
    /// As [`Model::joint_angles`] for the readings.
    pub fn outside_region(&self, theta: &[f64]) -> Result<Option<(usize, f64)>, Error> {
        self.check_readings(theta)?;
        let region = self.region[..self.n_region].iter().zip(theta).enumerate();
        Ok(farthest_outside(region.map(
            |(j, (&(min, max, slack), &v))| (j, v, min, max, slack),
        )))
    }

    /// Whether the model has a recorded region ([`Model::with_region`]).
    pub fn has_region(&self) -> bool {
        self.n_region > 0
    }

    /// The handle compliance of each joint, rad/(N·m) (zeros for a rigid model).
    pub fn compliances(&self) -> &[f64] {
        &self.compliance[..self.n_joints]
    }

    /// The handle's weight as a force at the end point in the base frame, N (zero without
    /// a handle compliance).
    pub fn handle_force_n(&self) -> [f64; 3] {
        self.handle_force_n
    }

    /// The axis of joint 1 in the base frame (unit; constant, whatever the joint angles).
    pub fn joint1_axis(&self) -> [f64; 3] {
        let r = &self.base.rotation;
        [r[0][2], r[1][2], r[2][2]]
    }

    /// Number of joints n.
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// The drives, one per joint.
    pub fn drives(&self) -> &[Drive] {
        &self.drives[..self.n_joints]
    }

    /// Joint angles q (rad) and `dq/dθ` (rad/rad) for readings `theta` (rad, motor angle /
    /// R), through each joint's [`Drive`] (paper eq. 1; the joint-4 polynomial) and, for a
    /// model with a handle compliance, deflected by the handle's weight (see [`Model`]).
    /// `dq/dθ` is the drives' derivative: the deflection's own, `k_j·∂τ_j/∂q`, is left out
    /// (the motor torques pass through the drives only; the compliance carries the joint
    /// torque).
    ///
    /// # Errors
    /// [`Error::Length`] unless all three slices have n entries; [`Error::NotFinite`] for a
    /// NaN or infinite reading; [`Error::OutsideDomain`] for a reading past its transmission
    /// polynomial's domain by more than [`crate::DOMAIN_MARGIN`] of its width.
    pub fn joint_angles(
        &self,
        theta: &[f64],
        q_rad: &mut [f64],
        dq_dtheta: &mut [f64],
    ) -> Result<(), Error> {
        self.check_readings(theta)?;
        check_len("joint angles", self.n_joints, q_rad.len())?;
        check_len("joint angle derivatives", self.n_joints, dq_dtheta.len())?;
        let (q, dq) = self.angles(theta)?;
        q_rad.copy_from_slice(&q[..self.n_joints]);
        dq_dtheta.copy_from_slice(&dq[..self.n_joints]);
        Ok(())
    }

    /// Tip pose in the base frame at readings `theta` (rad); translation in m (paper eq. 4
    /// at the calibrated joint angles).
    ///
    /// # Errors
    /// As [`Model::joint_angles`].
    pub fn end_pose(&self, theta: &[f64]) -> Result<Pose, Error> {
        let (q, _) = self.angles(theta)?;
        Ok(self.kinematics(&q, None))
    }

    /// Tip pose in the base frame at joint angles `q_rad` (rad); translation in m.
    ///
    /// # Errors
    /// [`Error::Length`] unless `q_rad` has n entries; [`Error::NotFinite`] for a NaN or
    /// infinite angle.
    pub fn end_pose_at_joints(&self, q_rad: &[f64]) -> Result<Pose, Error> {
        let q = self.joint_array(q_rad)?;
        Ok(self.kinematics(&q, None))
    }

    /// Body Jacobian with respect to the joint angles at readings `theta`, and the tip pose.
    ///
    /// `jac` has one column per joint (n columns of 6): `J_b = diag(Rᵀ, Rᵀ)·J_s` with R the
    /// tip orientation and `J_s` the spatial Jacobian ([`Model::spatial_jacobian`]). Rows
    /// 0–2: end-point velocity in the tip frame, m/rad; rows 3–5: angular velocity in the
    /// tip frame, rad/rad (Siciliano et al., *Robotics*, 2009, §3.1). Per joint angle q, not
    /// per reading: multiply column k by `dq_k/dθ_k` for the Jacobian in the readings.
    ///
    /// # Errors
    /// As [`Model::joint_angles`], and [`Error::Length`] unless `jac` has n columns.
    pub fn body_jacobian(&self, theta: &[f64], jac: &mut [[f64; 6]]) -> Result<Pose, Error> {
        self.jacobian(self.angles(theta).map(|(q, _)| q), Frame::Body, jac)
    }

    /// Spatial Jacobian with respect to the joint angles at readings `theta`, and the tip
    /// pose: the geometric Jacobian of the end point in the base frame.
    ///
    /// Column k is `(z_k × (p − o_k), z_k)` with `z_k`, `o_k` joint k's axis and origin and
    /// `p` the end point, all in the base frame: rows 0–2 the end-point velocity (m/rad),
    /// rows 3–5 the angular velocity (rad/rad) (Siciliano et al., *Robotics*, 2009, §3.1.3).
    /// The twist's reference point is the end point, not the base origin of Murray, Li and
    /// Sastry's spatial velocity.
    ///
    /// # Errors
    /// As [`Model::body_jacobian`].
    pub fn spatial_jacobian(&self, theta: &[f64], jac: &mut [[f64; 6]]) -> Result<Pose, Error> {
        self.jacobian(self.angles(theta).map(|(q, _)| q), Frame::Spatial, jac)
    }

    /// [`Model::body_jacobian`] at joint angles `q_rad` (rad).
    ///
    /// # Errors
    /// As [`Model::end_pose_at_joints`], and [`Error::Length`] unless `jac` has n columns.
    pub fn body_jacobian_at_joints(
        &self,
        q_rad: &[f64],
        jac: &mut [[f64; 6]],
    ) -> Result<Pose, Error> {
        self.jacobian(self.joint_array(q_rad), Frame::Body, jac)
    }

    /// [`Model::spatial_jacobian`] at joint angles `q_rad` (rad).
    ///
    /// # Errors
    /// As [`Model::body_jacobian_at_joints`].
    pub fn spatial_jacobian_at_joints(
        &self,
        q_rad: &[f64],
        jac: &mut [[f64; 6]],
    ) -> Result<Pose, Error> {
        self.jacobian(self.joint_array(q_rad), Frame::Spatial, jac)
    }

    /// Motor torques (N·m, one per joint) that render the wrench `wrench` at readings
    /// `theta`: `τ_m = diag((dq/dθ)/R)·J_bᵀ·w` (the paper's force control, Fig. 11;
    /// docs/design.md §3.10), by virtual work through each drive.
    ///
    /// `wrench = (f, m)`: force (N) and moment about the end point (N·m), in the tip frame.
    ///
    /// # Errors
    /// As [`Model::evaluate`], and [`Error::Length`] unless `tau_m` has n entries.
    pub fn motor_torques(
        &self,
        theta: &[f64],
        wrench: &[f64; 6],
        tau_m: &mut [f64],
    ) -> Result<(), Error> {
        check_len("motor torques", self.n_joints, tau_m.len())?;
        let mut out = Evaluation::default();
        self.evaluate(theta, wrench, &mut out)?;
        tau_m.copy_from_slice(&out.motor_torques_nm[..self.n_joints]);
        Ok(())
    }

    /// Joint angles, their derivatives, tip pose, body Jacobian and motor torques for one
    /// reading and one wrench, in one pass (see [`Model::joint_angles`],
    /// [`Model::body_jacobian`], [`Model::motor_torques`]). Overwrites all of `out`.
    ///
    /// # Errors
    /// As [`Model::joint_angles`]; [`Error::NotFinite`] named `wrench` for a NaN or infinite
    /// force or moment (`out` is then left as it was).
    pub fn evaluate(
        &self,
        theta: &[f64],
        wrench: &[f64; 6],
        out: &mut Evaluation,
    ) -> Result<(), Error> {
        check_finite("wrench", wrench)?;
        let (q, dq) = self.angles(theta)?;
        *out = Evaluation::default();
        out.n_joints = self.n_joints;
        out.q_rad = q;
        out.dq_dtheta = dq;
        let n = self.n_joints;
        out.pose = self.kinematics(&q, Some((Frame::Body, &mut out.body_jacobian[..n])));
        let columns = out.body_jacobian.iter().zip(&dq).zip(&self.drives);
        for (tau, ((col, g), drive)) in out.motor_torques_nm[..n].iter_mut().zip(columns) {
            let mut tau_j = 0.0;
            for (j, w) in col.iter().zip(wrench) {
                tau_j += j * w;
            }
            *tau = tau_j * g / drive.ratio();
        }
        Ok(())
    }

    fn check_readings(&self, theta: &[f64]) -> Result<(), Error> {
        check_len("joint readings", self.n_joints, theta.len())?;
        check_finite("joint readings", theta)?;
        for (k, (drive, &t)) in self.drives.iter().zip(theta).enumerate() {
            drive.check_reading(k, t)?;
        }
        Ok(())
    }

    /// Joint angles (deflected by the handle's weight, if the model has a compliance) and
    /// the drives' derivatives for readings, in fixed arrays.
    fn angles(&self, theta: &[f64]) -> Result<([f64; MAX_JOINTS], [f64; MAX_JOINTS]), Error> {
        self.check_readings(theta)?;
        let (mut q, mut dq) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        for (k, (drive, &t)) in self.drives.iter().zip(theta).enumerate() {
            (q[k], dq[k]) = drive.angle_and_derivative(t);
        }
        self.deflect(&mut q);
        Ok((q, dq))
    }

    /// `q_j += k_j·τ_j(q)`, `τ_j = F·(z_j × (p − o_j))` the handle weight's torque about
    /// joint j at the undeflected angles (Siciliano et al., *Robotics*, 2009, §3.8.1: `τ =
    /// J_vᵀ·F`); nothing for a rigid model.
    fn deflect(&self, q: &mut [f64; MAX_JOINTS]) {
        let n = self.n_joints;
        if self.compliance[..n].iter().all(|&k| k == 0.0) {
            return;
        }
        let (pose, axes, origins) = self.frames(q);
        let p = pose.translation_m;
        let f = self.handle_force_n;
        for ((qj, &k), (z, o)) in q[..n]
            .iter_mut()
            .zip(&self.compliance)
            .zip(axes.iter().zip(&origins))
        {
            let lever = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
            let v = cross(z, &lever);
            let tau = v[0] * f[0] + v[1] * f[1] + v[2] * f[2];
            *qj += k * tau;
        }
    }

    fn joint_array(&self, q_rad: &[f64]) -> Result<[f64; MAX_JOINTS], Error> {
        check_len("joint angles", self.n_joints, q_rad.len())?;
        check_finite("joint angles", q_rad)?;
        let mut q = [0.0; MAX_JOINTS];
        q[..self.n_joints].copy_from_slice(q_rad);
        Ok(q)
    }

    /// Tip pose and the `frame` Jacobian in `jac` at joint angles `q` (the error of reading
    /// or checking them, if any, comes first).
    ///
    /// # Errors
    /// `q`'s error; [`Error::Length`] unless `jac` has n columns.
    #[inline]
    fn jacobian(
        &self,
        q: Result<[f64; MAX_JOINTS], Error>,
        frame: Frame,
        jac: &mut [[f64; 6]],
    ) -> Result<Pose, Error> {
        let q = q?;
        check_len("jacobian columns", self.n_joints, jac.len())?;
        Ok(self.kinematics(&q, Some((frame, jac))))
    }

    /// Tip pose at joint angles `q` (first n entries), and optionally a Jacobian in `jac`
    /// (exactly n columns).
    #[inline]
    fn kinematics(&self, q: &[f64; MAX_JOINTS], jac: Option<(Frame, &mut [[f64; 6]])>) -> Pose {
        let (pose, axes, origins) = self.frames(q);
        if let Some((frame, jac)) = jac {
            let p = pose.translation_m;
            for ((col, z), o) in jac.iter_mut().zip(&axes).zip(&origins) {
                let lever = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
                let (lin, ang) = match frame {
                    Frame::Spatial => (cross(z, &lever), *z),
                    Frame::Body => (
                        pose.inverse_rotate(&cross(z, &lever)),
                        pose.inverse_rotate(z),
                    ),
                };
                col[..3].copy_from_slice(&lin);
                col[3..].copy_from_slice(&ang);
            }
        }
        pose
    }

    /// Tip pose, and each joint's axis and origin in the base frame, at joint angles `q`
    /// (first n entries).
    #[inline]
    fn frames(
        &self,
        q: &[f64; MAX_JOINTS],
    ) -> (Pose, [[f64; 3]; MAX_JOINTS], [[f64; 3]; MAX_JOINTS]) {
        let n = self.n_joints;
        let mut axes = [[0.0; 3]; MAX_JOINTS];
        let mut origins = [[0.0; 3]; MAX_JOINTS];
        let mut pose = self.base;
        for k in 0..n {
            let link = &self.links[k];
            // Rz leaves the z axis and the origin in place: joint k turns about them.
            axes[k] = [
                pose.rotation[0][2],
                pose.rotation[1][2],
                pose.rotation[2][2],
            ];
            origins[k] = pose.translation_m;
            let (s, c) = sin_cos(link.theta0_rad + q[k]);
            pose.then_rot_z(s, c);
            pose = pose.compose(&link.after);
        }
        (pose, axes, origins)
    }
}

/// One D-H row's constant factors before and after its `Rz(θ + q)`, in the order
/// `hapcal_kinematics::Chain::from_dh` composes them, with the sines and cosines of
/// `sin_cos`. Standard: `I | Tz(d)·Tx(a)·Rx(α)·Ry(β)`; modified (Craig):
/// `Rx(α)·Ry(β)·Tx(a) | Tz(d)` (`Ry(β)` only for a row with β).
pub(crate) fn dh_split(
    convention: DhConvention,
    row: &DhRow,
    sin_cos: fn(f64) -> (f64, f64),
) -> (Pose, Pose) {
    let rot = |angle: f64, f: fn(f64, f64) -> Pose| {
        let (s, c) = sin_cos(angle);
        f(s, c)
    };
    let beta = row.beta_rad.map_or(Pose::IDENTITY, |b| rot(b, Pose::rot_y));
    let alpha = rot(row.alpha_rad, Pose::rot_x);
    let tx = Pose::translation([row.a_m, 0.0, 0.0]);
    let tz = Pose::translation([0.0, 0.0, row.d_m]);
    match convention {
        DhConvention::Standard => (
            Pose::IDENTITY,
            tz.compose(&tx).compose(&alpha).compose(&beta),
        ),
        DhConvention::Modified => (alpha.compose(&beta).compose(&tx), tz),
    }
}

/// Of `(joint, value, min, max, slack)` entries, the joint whose value lies past
/// `[min − slack, max + slack]` by the largest share of its range `max − min`, with how far
/// past its range it lies (positive above, negative below); `None` when every value is
/// within its slack.
pub(crate) fn farthest_outside(
    entries: impl Iterator<Item = (usize, f64, f64, f64, f64)>,
) -> Option<(usize, f64)> {
    let mut worst: Option<(usize, f64, f64)> = None;
    for (j, v, min, max, slack) in entries {
        let past = if v > max + slack {
            v - max
        } else if v < min - slack {
            v - min
        } else {
            continue;
        };
        let share = past.abs() / (max - min).max(f64::MIN_POSITIVE);
        if worst.is_none_or(|(_, _, s)| share > s) {
            worst = Some((j, past, share));
        }
    }
    worst.map(|(j, past, _)| (j, past))
}
