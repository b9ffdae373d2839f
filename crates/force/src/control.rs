//! Quasi-static closed-loop impedance control with the handle fixed (paper Fig. 11).

use nalgebra::{DMatrix, Matrix6, Vector3, Vector6};

use crate::{Error, ForceModel};

/// Joint readings of one pose, as the controller and as the device see them (rad, one per
/// joint).
///
/// `device` is the true motor angle divided by R (continuous); `controller` is what the
/// encoder reports, `device` rounded to the encoder resolution (or equal to it when
/// quantisation is off). The truth's joint angles follow `device`, the model's `controller`.
#[derive(Clone, Debug, PartialEq)]
pub struct Readings {
    /// What the controller reads, rad.
    pub controller: Vec<f64>,
    /// What the motors really are at (divided by R), rad.
    pub device: Vec<f64>,
}

impl Readings {
    /// Exact readings: the controller sees `theta` itself (no quantisation).
    pub fn exact(theta: &[f64]) -> Readings {
        Readings {
            controller: theta.to_vec(),
            device: theta.to_vec(),
        }
    }
}

/// The open-loop wrench map `M` at one pose (6 × 6, dimensionless in each block): column k is
/// the body-frame wrench the truth device applies to the fixed handle when the controller,
/// using `model`, commands the unit wrench `e_k`.
///
/// ```text
/// τ_m = diag((dq/dθ)_model / R) · J_b,model(θ_c)ᵀ · w_cmd          (controller, Fig. 11 J block)
/// τ_j = diag(R / (dq/dθ)_truth) · τ_m                               (truth drives)
/// J_b,truth,a(θ_d)ᵀ · w = τ_j,a      (statics of the fixed handle, unlocked joints a)
/// ⇒ w = M · w_cmd,  M = J_b,truth,aᵀ⁻¹ · diag(g_a) · J_b,model,aᵀ,
///   g = ((dq/dθ)_model / R_model) · (R_truth / (dq/dθ)_truth)
/// ```
///
/// The locked joint (`locked_joint`, 1-based; the paper locks the redundant joint 3 at
/// home) carries whatever torque the lock takes, so only the six unlocked joints enter. A
/// model equal to the truth gives `M = I`.
///
/// # Errors
/// [`Error::LockedJoint`] for a locked joint the device lacks; [`Error::ActiveJoints`] unless
/// six joints remain; [`Error::Singular`] if the truth's 6 × 6 Jacobian cannot be inverted;
/// and the errors of [`ForceModel::body_jacobian`].
pub fn wrench_map(
    model: &ForceModel,
    truth: &ForceModel,
    readings: &Readings,
    locked_joint: Option<usize>,
) -> Result<Matrix6<f64>, Error> {
    let n = truth.n_joints();
    if model.n_joints() != n {
        return Err(Error::Length {
            what: "model joints",
            expected: n,
            found: model.n_joints(),
        });
    }
    let active = active_joints(n, locked_joint)?;
    let jm = model.body_jacobian(&readings.controller)?;
    let jt = truth.body_jacobian(&readings.device)?;
    let dq_m = model.angle_derivatives(&readings.controller)?;
    let dq_t = truth.angle_derivatives(&readings.device)?;
    let (mut a_model, mut a_truth) = (Matrix6::zeros(), Matrix6::zeros());
    let (ratios_m, ratios_t) = (model.ratios(), truth.ratios());
    for (row, &j) in active.iter().enumerate() {
        // Rows of Jᵀ restricted to the unlocked joints, the model's scaled by the torque gain
        // g = (dq/dθ)_model/R_model · R_truth/(dq/dθ)_truth (R cancels when both use the
        // device file's nominal ratio).
        let g = dq_m[j] / ratios_m[j] * ratios_t[j] / dq_t[j];
        for k in 0..6 {
            a_model[(row, k)] = g * jm[(k, j)];
            a_truth[(row, k)] = jt[(k, j)];
        }
    }
    let lu = a_truth.lu();
    lu.solve(&a_model).ok_or(Error::Singular {
        which: "truth Jacobian",
    })
}

/// The unlocked joints (0-based) of an `n`-joint device with `locked_joint` (1-based) locked.
fn active_joints(n: usize, locked_joint: Option<usize>) -> Result<Vec<usize>, Error> {
    if let Some(l) = locked_joint
        && !(1..=n).contains(&l)
    {
        return Err(Error::LockedJoint {
            joint: l,
            n_joints: n,
        });
    }
    let active: Vec<usize> = (0..n).filter(|&j| Some(j + 1) != locked_joint).collect();
    if active.len() != 6 {
        return Err(Error::ActiveJoints {
            n_active: active.len(),
        });
    }
    Ok(active)
}

/// Condition number (2-norm) of the truth's 6 × 6 body Jacobian of the unlocked joints, with
/// its linear rows divided by `length_m` (m) so both blocks are in rad/rad: how strongly
/// the fixed-handle statics amplifies torque errors into wrench errors.
///
/// # Errors
/// As [`wrench_map`].
pub fn condition_number(
    truth: &ForceModel,
    theta: &[f64],
    locked_joint: Option<usize>,
    length_m: f64,
) -> Result<f64, Error> {
    let active = active_joints(truth.n_joints(), locked_joint)?;
    let jt = truth.body_jacobian(theta)?;
    let a = DMatrix::from_fn(6, 6, |r, c| {
        let v = jt[(r, active[c])];
        if r < 3 { v / length_m } else { v }
    });
    let s = a.singular_values();
    let (max, min) = (s.max(), s.min());
    Ok(if min > 0.0 { max / min } else { f64::INFINITY })
}

/// Closed-loop map of paper Fig. 11, quasi-static: with the handle fixed the loop is
/// algebraic. The controller adds proportional force feedback with gain G (dimensionless)
/// from the handle's force sensor, `w_cmd = w_d + G·(w_d − w_sens)`, and the device renders
/// `w = M·w_cmd` ([`wrench_map`]); with `w_sens = w` the equilibrium is
///
/// ```text
/// (I + G·M)·w = (1 + G)·M·w_d   ⇒   w = C·w_d,   C = (I + G·M)⁻¹ (1 + G) M
/// ```
///
/// For `M = I + E`, `w − w_d = (I + G M)⁻¹ E w_d ≈ E w_d/(1 + G)`: feedback divides the
/// open-loop error by about `1 + G`. `G = 0` is open-loop impedance control (`C = M`). The
/// sensor is rigid on the handle, so `w_sens` is in the true tip frame, while `w_d` is in the
/// frame the model believes: feedback also removes errors of the model's tip orientation.
/// This is the equilibrium a stable loop settles to; whether the loop is stable depends on the
/// device's dynamics (Z_h of Fig. 11), which a quasi-static model does not have.
///
/// # Errors
/// [`Error::InvalidConfig`] for a negative or non-finite `gain`; [`Error::Singular`] if
/// `I + G·M` is singular.
pub fn closed_loop(m: &Matrix6<f64>, gain: f64) -> Result<Matrix6<f64>, Error> {
    if !(gain.is_finite() && gain >= 0.0) {
        return Err(Error::InvalidConfig {
            name: "gain",
            value: gain,
            expected: "a finite number ≥ 0",
        });
    }
    let lhs = Matrix6::identity() + m * gain;
    lhs.lu().solve(&(m * (1.0 + gain))).ok_or(Error::Singular {
        which: "closed-loop",
    })
}

/// One of the six wrench directions of the body frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Force along tip x.
    Fx,
    /// Force along tip y.
    Fy,
    /// Force along tip z (the paper's wall direction).
    Fz,
    /// Moment about tip x.
    Mx,
    /// Moment about tip y.
    My,
    /// Moment about tip z.
    Mz,
}

impl Direction {
    /// All six, in wrench order.
    pub const ALL: [Direction; 6] = [
        Direction::Fx,
        Direction::Fy,
        Direction::Fz,
        Direction::Mx,
        Direction::My,
        Direction::Mz,
    ];

    /// Index into a wrench `(f, m)`.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Name for reports and files: `Fx`, …, `Mz`.
    pub fn name(self) -> &'static str {
        ["Fx", "Fy", "Fz", "Mx", "My", "Mz"][self.index()]
    }
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Direction {
    type Err = Error;

    /// Parses `Fx`, `Fy`, `Fz`, `Mx`, `My` or `Mz` (as [`Direction::name`] writes them).
    ///
    /// # Errors
    /// [`Error::UnknownDirection`] for anything else.
    fn from_str(s: &str) -> Result<Direction, Error> {
        (Direction::ALL.into_iter())
            .find(|d| d.name() == s)
            .ok_or_else(|| Error::UnknownDirection { name: s.to_owned() })
    }
}

/// Errors of a rendered wrench against the desired one along `direction`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrenchError {
    /// Angle between the rendered and the desired force (force directions) or moment (moment
    /// directions), degrees.
    pub direction_deg: f64,
    /// `(|rendered| − |desired|)/|desired|·100` of the same part, %.
    pub magnitude_pct: f64,
}

/// Direction and magnitude error of `rendered` against `desired` (body-frame wrenches, N and
/// N·m), comparing their force parts for a force direction and their moment parts for a
/// moment direction.
pub fn wrench_error(
    desired: &Vector6<f64>,
    rendered: &Vector6<f64>,
    direction: Direction,
) -> WrenchError {
    let part = |w: &Vector6<f64>| -> Vector3<f64> {
        let start = if direction.index() < 3 { 0 } else { 3 };
        w.fixed_rows::<3>(start).into_owned()
    };
    let (d, r) = (part(desired), part(rendered));
    WrenchError {
        direction_deg: r.cross(&d).norm().atan2(r.dot(&d)).to_degrees(),
        magnitude_pct: (r.norm() - d.norm()) / d.norm() * 100.0,
    }
}
