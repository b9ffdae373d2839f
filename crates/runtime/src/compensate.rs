//! Compensation: the joint command that brings a tip of the calibrated robot, deflection
//! included, to a target position or pose (damped least squares).

use crate::error::{check_finite_parts, check_len};
use crate::robot::{Deflection, Robot, RobotWorkspace};
use crate::{Error, Pose};

/// Where a tip should go, in the robot's root link frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// The tip frame's origin at this point, m (3 equations; the orientation is free).
    Position([f64; 3]),
    /// The tip frame at this pose (6 equations).
    Pose(Pose),
}

/// Settings of [`compensate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompensationConfig {
    /// A target is reached when the tip's origin is within this distance of it, m.
    pub tolerance_m: f64,
    /// … and, for a [`Target::Pose`], its orientation within this angle, rad.
    pub tolerance_rad: f64,
    /// Most damped least-squares steps (each one deflection and one Jacobian).
    pub max_iterations: usize,
    /// Initial damping λ of the step `Δq = Jᵀ(J·Jᵀ + λ²·I)⁻¹·e`, m (Wampler 1986; Nakamura &
    /// Hanafusa 1986): divided by 10 after a step that lowers the error, multiplied by 10
    /// after one that does not (Levenberg–Marquardt's rule).
    pub damping_m: f64,
    /// Length that weighs orientation against position in the step, m: an orientation error
    /// of 1 rad counts as a position error of this length.
    pub orientation_scale_m: f64,
}

impl Default for CompensationConfig {
    /// 1 µm and 1 µrad, at most 50 steps, an initial damping of 1 mm, orientation weighed at
    /// 0.1 m per rad: a tip on its target to the encoders' resolution within a few steps.
    fn default() -> Self {
        CompensationConfig {
            tolerance_m: 1e-6,
            tolerance_rad: 1e-6,
            max_iterations: 50,
            damping_m: 1e-3,
            orientation_scale_m: 0.1,
        }
    }
}

/// The outcome of [`compensate`] for one target.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Compensation {
    /// Whether the tip is within [`CompensationConfig::tolerance_m`] (and
    /// [`CompensationConfig::tolerance_rad`]) of the target at the command written.
    pub reached: bool,
    /// Damped least-squares steps taken (accepted or not).
    pub iterations: usize,
    /// Distance from the deflected tip's origin to the target at the command, m.
    pub position_error_m: f64,
    /// Angle between the deflected tip's orientation and the target's, rad (0 for a
    /// [`Target::Position`]).
    pub orientation_error_rad: f64,
    /// The deflection at the command.
    pub deflection: Deflection,
}

/// The rotation vector (axis · angle, rad) of `r`: `log(r)` (Murray, Li & Sastry, *A
/// Mathematical Introduction to Robotic Manipulation*, 1994, §2.2).
fn rotation_vector(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let v = [
        0.5 * (r[2][1] - r[1][2]),
        0.5 * (r[0][2] - r[2][0]),
        0.5 * (r[1][0] - r[0][1]),
    ];
    let cos = (0.5 * (r[0][0] + r[1][1] + r[2][2] - 1.0)).clamp(-1.0, 1.0);
    let sin = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let angle = sin.atan2(cos);
    if sin > 1e-6 {
        let s = angle / sin;
        return [v[0] * s, v[1] * s, v[2] * s];
    }
    if cos > 0.0 {
        // Small angle: log(R) ≈ v (angle/sin → 1).
        return v;
    }
    // Angle near π: the axis from the diagonal of (R + I)/2 = a·aᵀ.
    let d = [r[0][0], r[1][1], r[2][2]];
    let k = if d[0] >= d[1] && d[0] >= d[2] {
        0
    } else if d[1] >= d[2] {
        1
    } else {
        2
    };
    let mut axis = [0.0; 3];
    let ak = (0.5 * (d[k] + 1.0)).max(0.0).sqrt();
    for (i, a) in axis.iter_mut().enumerate() {
        *a = if i == k {
            ak
        } else if ak > 0.0 {
            0.5 * (r[i][k] + r[k][i]) / (2.0 * ak)
        } else {
            0.0
        };
    }
    [axis[0] * angle, axis[1] * angle, axis[2] * angle]
}

/// The error (target − current) of `pose`: rows 0–2 position (m), 3–5 the rotation vector of
/// `R_target·Rᵀ` (rad, root frame); the number of rows used; distance and angle.
fn error(target: &Target, pose: &Pose) -> ([f64; 6], usize, f64, f64) {
    let p = pose.translation_m;
    let (goal, rotation) = match target {
        Target::Position(x) => (*x, None),
        Target::Pose(t) => (t.translation_m, Some(&t.rotation)),
    };
    let mut e = [0.0; 6];
    for i in 0..3 {
        e[i] = goal[i] - p[i];
    }
    let distance = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    let Some(rt) = rotation else {
        return (e, 3, distance, 0.0);
    };
    let w = rotation_vector(&crate::predict::relative(rt, &pose.rotation));
    e[3..].copy_from_slice(&w);
    let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    (e, 6, distance, angle)
}

/// Largest departure of a rotation matrix from orthonormality and from determinant 1 that
/// [`compensate`] accepts in a target: a rotation written to 16 digits is within 1e-15.
pub const ROTATION_TOLERANCE: f64 = 1e-9;

/// `Ok` for a rotation matrix: `RᵀR = I` entry by entry and `det R = 1`, each to
/// [`ROTATION_TOLERANCE`]; else [`Error::Invalid`] with the largest entry of `|RᵀR − I|` (a
/// scaled or sheared matrix) or the determinant (a reflection).
fn check_rotation(r: &[[f64; 3]; 3]) -> Result<(), Error> {
    let mut worst = 0.0_f64;
    for i in 0..3 {
        for j in 0..3 {
            let dot = r[0][i] * r[0][j] + r[1][i] * r[1][j] + r[2][i] * r[2][j];
            let identity = if i == j { 1.0 } else { 0.0 };
            worst = worst.max((dot - identity).abs());
        }
    }
    if worst > ROTATION_TOLERANCE {
        return Err(Error::Invalid {
            what: "the target rotation's largest entry of |RᵀR − I|",
            value: worst,
            expected: "at most 1e-9: a rotation matrix is orthonormal (a scaled or sheared \
                       matrix is no orientation)",
        });
    }
    let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
        - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
    if (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(Error::Invalid {
            what: "the target rotation's determinant",
            value: det,
            expected: "1 within 1e-9: a rotation, not a reflection",
        });
    }
    Ok(())
}

/// Weighted squared error `|e_p|² + L²·|e_r|²`, m².
fn cost(e: &[f64; 6], rows: usize, scale_m: f64) -> f64 {
    (0..rows)
        .map(|i| {
            let w = if i < 3 { 1.0 } else { scale_m };
            (w * e[i]) * (w * e[i])
        })
        .sum()
}

/// Solves `(J_w·J_wᵀ + λ²·I)·y = e_w` (Cholesky, `R` = 3 or 6 rows) and writes `q + J_wᵀ·y`,
/// clamped to the joint limits, into `trial`. Rows 3–5 of `J` and `e` are weighted by
/// `scale_m`.
#[allow(
    clippy::too_many_arguments,
    clippy::needless_range_loop,
    reason = "a 6 × 6 Cholesky solve reads best with the textbook's indices"
)]
fn step<const R: usize>(
    jac: &[[f64; 6]],
    e: &[f64; 6],
    scale_m: f64,
    lambda: f64,
    q: &[f64],
    limits: &[(f64, f64)],
    trial: &mut [f64],
) {
    let w = |i: usize| if i < 3 { 1.0 } else { scale_m };
    // M = J_w·J_wᵀ + λ²·I, row by row (a row's sums stay in registers over the columns).
    let mut m = [[0.0; R]; R];
    for (a, row) in m.iter_mut().enumerate() {
        let mut sum = [0.0; R];
        for col in jac {
            let ca = col[a];
            for (s, cb) in sum.iter_mut().zip(col) {
                *s += ca * cb;
            }
        }
        for (b, (x, s)) in row.iter_mut().zip(sum).enumerate() {
            *x = w(a) * w(b) * s;
        }
        row[a] += lambda * lambda;
    }
    // Cholesky M = L·Lᵀ in place (lower triangle); M is positive definite (λ > 0).
    for j in 0..R {
        let mut d = m[j][j];
        for k in 0..j {
            d -= m[j][k] * m[j][k];
        }
        let d = d.max(f64::MIN_POSITIVE).sqrt();
        m[j][j] = d;
        let inv = 1.0 / d;
        for i in j + 1..R {
            let mut s = m[i][j];
            for k in 0..j {
                s -= m[i][k] * m[j][k];
            }
            m[i][j] = s * inv;
        }
    }
    let mut y = [0.0; R];
    for i in 0..R {
        let mut s = w(i) * e[i];
        for k in 0..i {
            s -= m[i][k] * y[k];
        }
        y[i] = s / m[i][i];
    }
    for i in (0..R).rev() {
        let mut s = y[i];
        for k in i + 1..R {
            s -= m[k][i] * y[k];
        }
        y[i] = s / m[i][i];
    }
    for (((t, q), col), (lo, hi)) in trial.iter_mut().zip(q).zip(jac).zip(limits) {
        let mut dq = 0.0;
        for i in 0..R {
            dq += w(i) * col[i] * y[i];
        }
        *t = (q + dq).clamp(*lo, *hi);
    }
}

/// The joint command `q_out` (rad, m for a prismatic joint) at which tip `tip` of `robot`,
/// deflected under its own weight ([`Robot::deflect`]), reaches `target` (root link frame):
/// damped least squares `Δq = Jᵀ(J·Jᵀ + λ²·I)⁻¹·e` (Wampler 1986, "Manipulator inverse
/// kinematic solutions based on vector formulations and damped least-squares methods";
/// Levenberg–Marquardt's adaptive λ) from `q_start` (the nominal inverse kinematics'
/// solution, or the previous command along a path), with `J` the spatial Jacobian at the
/// deflected angles ([`Robot::spatial_jacobian`]) and commands clamped to the joint limits.
///
/// Not reaching the target is a result (`reached == false`, with the error left), not an
/// `Err`; `q_out` then holds the best command found. No allocation.
///
/// # Errors
/// [`Error::Length`] unless `q_start` and `q_out` have n entries; [`Error::NotFinite`] for a
/// NaN or infinite start angle or target value; [`Error::Invalid`] named `tip` for a tip
/// index past the last tip, for a target rotation that is not a rotation matrix (orthonormal
/// with determinant 1, to [`ROTATION_TOLERANCE`]), or naming a setting of `cfg` that is not
/// finite and positive.
///
/// # Panics
/// If `ws` was made for another robot.
#[track_caller]
pub fn compensate(
    robot: &Robot,
    tip: usize,
    target: &Target,
    q_start: &[f64],
    cfg: &CompensationConfig,
    ws: &mut RobotWorkspace,
    q_out: &mut [f64],
) -> Result<Compensation, Error> {
    let n = robot.n_joints();
    robot.check_workspace(ws);
    robot.check_tip(tip)?;
    robot.check_joints("joint angles", q_start)?;
    check_len("joint command", n, q_out.len())?;
    // Every number of the target: the position, or the rotation's 9 entries then the
    // translation's 3 (the index the error names).
    let parts: [&[f64]; 2] = match target {
        Target::Position(p) => [p, &[]],
        Target::Pose(p) => [p.rotation.as_flattened(), &p.translation_m],
    };
    check_finite_parts("target", &parts)?;
    if let Target::Pose(p) = target {
        check_rotation(&p.rotation)?;
    }
    for (what, value) in [
        ("tolerance_m", cfg.tolerance_m),
        ("tolerance_rad", cfg.tolerance_rad),
        ("damping_m", cfg.damping_m),
        ("orientation_scale_m", cfg.orientation_scale_m),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(Error::Invalid {
                what,
                value,
                expected: "a finite, positive value",
            });
        }
    }
    let limits = robot.limits();
    let mut q = core::mem::take(&mut ws.command);
    let mut trial = core::mem::take(&mut ws.trial);
    for ((c, s), (lo, hi)) in q.iter_mut().zip(q_start).zip(limits) {
        *c = s.clamp(*lo, *hi);
    }
    let scale = cfg.orientation_scale_m;
    let mut deflection = robot.deflect_frames(&q, ws);
    let mut pose = robot.tip_from(tip, &ws.frames);
    let (mut e, rows, mut distance, mut angle) = error(target, &pose);
    let mut current = cost(&e, rows, scale);
    let mut lambda = cfg.damping_m;
    let mut iterations = 0;
    // Whether `ws.jac` holds the Jacobian at `q`: made from the frames of the deflection
    // at `q` only when a step needs it (not for the command that ends the iterations), and
    // kept when a trial is refused.
    let mut jacobian_at_q = false;
    let within = |d: f64, a: f64| d <= cfg.tolerance_m && a <= cfg.tolerance_rad;
    while !within(distance, angle) && iterations < cfg.max_iterations {
        if !jacobian_at_q {
            robot.columns_from(tip, &ws.frames, &pose, &mut ws.jac, false);
            jacobian_at_q = true;
        }
        iterations += 1;
        if rows == 3 {
            step::<3>(&ws.jac, &e, scale, lambda, &q, limits, &mut trial);
        } else {
            step::<6>(&ws.jac, &e, scale, lambda, &q, limits, &mut trial);
        }
        let deflection_t = robot.deflect_frames(&trial, ws);
        let pose_t = robot.tip_from(tip, &ws.frames);
        let (e_t, _, distance_t, angle_t) = error(target, &pose_t);
        let cost_t = cost(&e_t, rows, scale);
        if cost_t < current {
            q.copy_from_slice(&trial);
            (pose, e, distance, angle, current, deflection) =
                (pose_t, e_t, distance_t, angle_t, cost_t, deflection_t);
            jacobian_at_q = false;
            lambda = (lambda * 0.1).max(1e-12);
        } else {
            // The Jacobian at q again, with more damping.
            lambda *= 10.0;
            if lambda > 1e6 {
                break;
            }
        }
    }
    q_out.copy_from_slice(&q);
    ws.command = q;
    ws.trial = trial;
    Ok(Compensation {
        reached: within(distance, angle),
        iterations,
        position_error_m: distance,
        orientation_error_rad: angle,
        deflection,
    })
}

#[cfg(test)]
mod tests {
    use super::rotation_vector;

    /// `Rot(axis, angle)` by Rodrigues' formula, independent of the code under test.
    fn rotation(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let [x, y, z] = axis.map(|a| a / n);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        [
            [c + t * x * x, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, c + t * y * y, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, c + t * z * z],
        ]
    }

    #[test]
    fn rotation_vector_inverts_axis_angle_from_tiny_to_near_half_turn() {
        let axis = [0.3, -0.5, 0.8];
        let n = (0.3f64 * 0.3 + 0.25 + 0.64).sqrt();
        for angle in [1e-9, 1e-4, 0.3, 2.0, 3.1, std::f64::consts::PI - 1e-7] {
            let w = rotation_vector(&rotation(axis, angle));
            for (wi, ai) in w.iter().zip(axis) {
                let expected = ai / n * angle;
                // Near a half turn the axis comes from the diagonal: √ of a difference of
                // order 1e-7 loses half the digits.
                let tol = if angle > 3.0 { 1e-6 } else { 1e-12 };
                assert!((wi - expected).abs() <= tol, "{angle}: {w:?}");
            }
        }
    }
}
