//! The C ABI of calibrated URDF robots ([`hapcal_runtime::Robot`]): an opaque handle holding
//! the robot and its [`RobotWorkspace`], so evaluation calls do not allocate.
//!
//! Joint arrays have `n_joints` entries ([`hapcal_robot_n_joints`]), in the order of the
//! joint names ([`hapcal_robot_joint_name`]): rad, m for a prismatic joint. Poses are of tip
//! links in the URDF's root link frame. Jacobians are `6 · n_joints` doubles, column-major
//! (column k = joint k). A handle holds its workspace: calls that take it non-`const` may run
//! on one thread at a time per handle (one handle per thread for parallel use).

use std::ffi::{CStr, c_char};
use std::path::Path;

use hapcal_runtime::{
    Compensation, CompensationConfig, Deflection, Error, GravityModel, Pose, Robot, RobotWorkspace,
    Target, compensate,
};

use crate::{Failure, HapcalPose, HapcalStatus, guard, put, record, slice, slice_mut};

// `HapcalPose` and `hapcal_runtime::Pose` are both `#[repr(C)]` with the same fields: a caller's
// array of `HapcalPose` is written as an array of `Pose`.
const _: () = assert!(
    size_of::<HapcalPose>() == size_of::<Pose>() && align_of::<HapcalPose>() == align_of::<Pose>()
);

/// A loaded calibrated robot and its evaluation buffers, opaque to C: create with
/// [`hapcal_robot_load`], release with [`hapcal_robot_free`]. Calls that take it `const`
/// (counts, names, the region flag) may run from several threads at once; the others use the
/// handle's workspace and must not overlap on one handle.
pub struct HapcalRobot {
    robot: Robot,
    ws: RobotWorkspace,
    /// How many tips the caller gave: the robot's first tips. The runtime loads the tips
    /// whose paths carry the calibration's gravity loads after them (the other arm of a
    /// humanoid calibrated on one, read but not measured); they load the joints, and the
    /// ABI shows only the tips given.
    given: usize,
    /// Every tip's pose, the buffer of [`hapcal_robot_deflected_tip_poses`] (made once).
    poses: Vec<Pose>,
}

impl HapcalRobot {
    /// The robot the handle evaluates.
    pub(crate) fn robot(&self) -> &Robot {
        &self.robot
    }

    /// How many tips the caller gave ([`hapcal_robot_n_tips`]).
    pub(crate) fn given_tips(&self) -> usize {
        self.given
    }
}

/// [`HapcalTarget::kind`]: reach the target's position only (`pose.translation_m`; the
/// rotation is ignored), 3 equations.
pub const HAPCAL_TARGET_POSITION: u32 = 0;
/// [`HapcalTarget::kind`]: reach the target's full pose, 6 equations.
pub const HAPCAL_TARGET_POSE: u32 = 1;

/// The joint index [`hapcal_robot_outside_region`] writes for readings inside the region the
/// calibration was fitted on (or a robot without a recorded region): `SIZE_MAX`.
pub const HAPCAL_INSIDE_REGION: usize = usize::MAX;

/// Where a tip should go, in the robot's root link frame ([`hapcal_runtime::Target`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HapcalTarget {
    /// [`HAPCAL_TARGET_POSITION`] or [`HAPCAL_TARGET_POSE`].
    pub kind: u32,
    /// The target pose (m); only its translation for [`HAPCAL_TARGET_POSITION`].
    pub pose: HapcalPose,
}

/// Settings of [`hapcal_robot_compensate`] ([`hapcal_runtime::CompensationConfig`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HapcalCompensationConfig {
    /// A target is reached when the tip's origin is within this distance of it, m (> 0).
    pub tolerance_m: f64,
    /// … and, for a pose target, its orientation within this angle, rad (> 0).
    pub tolerance_rad: f64,
    /// Most damped least-squares steps (each one deflection and one Jacobian).
    pub max_iterations: usize,
    /// Initial damping λ of the step `Δq = Jᵀ(J·Jᵀ + λ²·I)⁻¹·e`, m (> 0; 1e-3 is typical).
    pub damping_m: f64,
    /// Length that weighs orientation against position, m (> 0): an orientation error of
    /// 1 rad counts as a position error of this length.
    pub orientation_scale_m: f64,
}

/// What the deflection under the robot's own weight did ([`hapcal_runtime::Deflection`]):
/// fixed-point iterations of `θ = q + k∘τ(θ)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HapcalDeflection {
    /// Iterations taken (0 for a robot without compliance).
    pub iterations: usize,
    /// Largest joint change of the last iteration, rad (m for a prismatic joint).
    pub final_step_rad: f64,
    /// Whether the last step was at most 1e-12 rad (true without compliance); false when the
    /// iterations hit their bound (20) first.
    pub converged: bool,
}

impl From<Deflection> for HapcalDeflection {
    fn from(d: Deflection) -> HapcalDeflection {
        HapcalDeflection {
            iterations: d.iterations,
            final_step_rad: d.final_step_rad,
            converged: d.converged,
        }
    }
}

/// The outcome of [`hapcal_robot_compensate`] ([`hapcal_runtime::Compensation`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HapcalCompensation {
    /// Whether the deflected tip is within the tolerances of the target at the command.
    pub reached: bool,
    /// Damped least-squares steps taken (accepted or not).
    pub iterations: usize,
    /// Distance from the deflected tip's origin to the target at the command, m.
    pub position_error_m: f64,
    /// Angle between the deflected tip's orientation and the target's, rad (0 for a position
    /// target).
    pub orientation_error_rad: f64,
    /// The deflection at the command.
    pub deflection: HapcalDeflection,
}

impl From<Compensation> for HapcalCompensation {
    fn from(c: Compensation) -> HapcalCompensation {
        HapcalCompensation {
            reached: c.reached,
            iterations: c.iterations,
            position_error_m: c.position_error_m,
            orientation_error_rad: c.orientation_error_rad,
            deflection: c.deflection.into(),
        }
    }
}

/// Checks that `n_joints` is the robot's.
pub(crate) fn check_n(robot: &Robot, n_joints: usize) -> Result<(), Failure> {
    check_count("n_joints", robot.n_joints(), n_joints)
}

/// `Length` naming `what` (a robot call's error) unless the caller's count `found` is
/// `expected`.
pub(crate) fn check_count(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), Failure> {
    if found == expected {
        Ok(())
    } else {
        Err(Failure::Robot(Error::Length {
            what,
            expected,
            found,
        }))
    }
}

/// The error of a tip index past the tips given (the runtime's words for a tip past the
/// last).
fn past_given(tip: usize) -> Error {
    Error::Invalid {
        what: "tip",
        value: tip as f64,
        expected: "a tip index below the number of tips",
    }
}

/// Runs `f` on a handle (`None`: a NULL pointer) under [`guard`], its workspace rebuilt after
/// a caught panic ([`crate::guard_handle`]). Before `f` runs: for a call on tip `tip`,
/// `InvalidArgument` for a tip past the tips the caller gave ([`hapcal_robot_n_tips`]); then
/// `Length` unless `n_joints` is the robot's ([`check_n`]).
fn with_robot(
    handle: Option<&mut HapcalRobot>,
    tip: Option<usize>,
    n_joints: usize,
    f: impl FnOnce(&Robot, &mut RobotWorkspace) -> Result<(), Failure>,
) -> HapcalStatus {
    if let (Some(h), Some(tip)) = (&handle, tip)
        && tip >= h.given
    {
        return guard(|| Err(Failure::Robot(past_given(tip))));
    }
    let rebuild = |h: &mut HapcalRobot| h.ws = h.robot.workspace();
    let checked = |h: &mut HapcalRobot| {
        check_n(&h.robot, n_joints)?;
        f(&h.robot, &mut h.ws)
    };
    crate::guard_handle(handle, "robot", checked, rebuild)
}

/// Loads the calibrated robot `urdf_path` (UTF-8, NUL-terminated) with the links `tips[0 ..
/// n_tips]` as its tips, and the sidecar `<urdf stem>.calibration.toml` beside it if there is
/// one (as `hapcal calibrate --out robot.urdf` writes them: identified frames and joint
/// compliances), and stores a new handle in `*out` ([`hapcal_runtime::Robot::load_urdf`]).
///
/// The joints are the moving joints on the paths from the root link to the tips; gravity is
/// along −z of the root link; torques use the URDF's link masses (N·m, compliances in
/// rad/(N·m)), or without any, the calibration's lumped unit weights (m, rad/m).
///
/// Returns `Ok`, `NullPointer`, `InvalidUtf8`, `Io`, `Parse` (a malformed sidecar, or one
/// that does not belong here: written beside another URDF, for other tips, with a region
/// joint the robot lacks or a value that disagrees with the URDF; with line and column) or
/// `InvalidModel` (a URDF the runtime cannot use, an unknown tip link, a sidecar value it
/// does not evaluate, no tip); `*out` is written only on success. The robot has the `n_tips`
/// tips given ([`hapcal_robot_n_tips`]).
///
/// # Safety
/// `urdf_path` is NULL or a NUL-terminated string; `tips` is NULL or valid for `n_tips`
/// reads, each NULL or a NUL-terminated string; `out` is NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_load(
    urdf_path: *const c_char,
    tips: *const *const c_char,
    n_tips: usize,
    out: *mut *mut HapcalRobot,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        let (path, tip_ptrs) = unsafe {
            (
                crate::str_arg(urdf_path, "urdf_path")?,
                if n_tips == 0 {
                    &[][..]
                } else {
                    slice(tips, n_tips, "tips")?
                },
            )
        };
        let mut names = Vec::with_capacity(n_tips);
        for (i, &tip) in tip_ptrs.iter().enumerate() {
            if tip.is_null() {
                return Err(Failure::Message(
                    HapcalStatus::NullPointer,
                    format!("tips[{i}] is NULL"),
                ));
            }
            // SAFETY: non-null and NUL-terminated by the caller's contract.
            let name = unsafe { CStr::from_ptr(tip) }.to_str().map_err(|_| {
                Failure::Message(HapcalStatus::InvalidUtf8, format!("tips[{i}] is not UTF-8"))
            })?;
            names.push(name);
        }
        if out.is_null() {
            return Err(Failure::Null("out"));
        }
        let robot = Robot::load_urdf(Path::new(path), &names).map_err(Failure::Load)?;
        // SAFETY: `out` is non-null and valid for a write by the caller's contract.
        unsafe { store_robot(out, robot, names.len()) };
        Ok(())
    })
}

/// Releases a robot handle; NULL is ignored.
///
/// # Safety
/// `robot` is NULL or a handle from [`hapcal_robot_load`] not yet freed; it must not be used
/// afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_free(robot: *mut HapcalRobot) {
    // SAFETY: the caller's contract.
    unsafe { crate::free(robot) }
}

/// Number of moving joints n of the robot (0 for NULL).
///
/// # Safety
/// `robot` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_n_joints(robot: *const HapcalRobot) -> usize {
    // SAFETY: the caller's contract.
    unsafe { robot.as_ref() }.map_or(0, |r| r.robot.n_joints())
}

/// Number of tips of the robot: the `n_tips` given to [`hapcal_robot_load`] (0 for NULL).
/// The tips whose paths carry the calibration's loads and that were not given (the other
/// arm of a humanoid calibrated on one) are loaded after them, to load the joints, but not
/// counted, named or written.
///
/// # Safety
/// `robot` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_n_tips(robot: *const HapcalRobot) -> usize {
    // SAFETY: the caller's contract.
    unsafe { robot.as_ref() }.map_or(0, |r| r.given)
}

/// Whether the robot's gravity torques come from the URDF's link masses (N·m; compliances in
/// rad/(N·m)); false: the lumped unit weights of a URDF without masses (m; rad/m), or NULL.
///
/// # Safety
/// `robot` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_has_link_masses(robot: *const HapcalRobot) -> bool {
    // SAFETY: the caller's contract.
    unsafe { robot.as_ref() }.is_some_and(|r| r.robot.gravity_model() == GravityModel::Masses)
}

/// Which name list a name query reads.
#[derive(Clone, Copy)]
enum NameKind {
    Joint,
    Tip,
}

/// # Safety
/// As [`hapcal_robot_joint_name`].
unsafe fn name(
    robot: *const HapcalRobot,
    index: usize,
    buf: *mut c_char,
    buf_len: usize,
    len_out: *mut usize,
    kind: NameKind,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let handle = unsafe { crate::get(robot, "robot") }?;
        let robot = &handle.robot;
        let (names, what, label) = match kind {
            NameKind::Joint => (robot.joint_names(), "joint", "joint name"),
            NameKind::Tip => (&robot.tip_names()[..handle.given], "tip", "tip name"),
        };
        let Some(name) = names.get(index) else {
            return Err(Failure::Message(
                HapcalStatus::InvalidArgument,
                format!(
                    "{what} index {index} is past the last {what}: the robot has {}",
                    names.len()
                ),
            ));
        };
        // SAFETY: forwarded contract.
        unsafe { copy_text(name, label, buf, buf_len, len_out) }
    })
}

/// Writes `text` with its NUL into `buf[0 .. buf_len]` and its length in bytes without the
/// NUL into `*len_out` unless `len_out` is NULL; with `buf` NULL and `buf_len` 0 only the
/// length. `Length` (naming `what`) when the buffer is too small; `*len_out` is still written.
///
/// # Safety
/// `buf` NULL or valid for `buf_len` writes; `len_out` NULL or valid for one write.
pub(crate) unsafe fn copy_text(
    text: &str,
    what: &str,
    buf: *mut c_char,
    buf_len: usize,
    len_out: *mut usize,
) -> Result<(), Failure> {
    let bytes = text.as_bytes();
    // SAFETY: the caller's contract: NULL or valid for one write.
    unsafe { put(len_out, bytes.len()) };
    if buf.is_null() && buf_len == 0 {
        return Ok(());
    }
    // SAFETY: the caller's contract: NULL or valid for `buf_len` writes.
    let buf = unsafe { slice_mut(buf.cast::<u8>(), buf_len, "buf") }?;
    if buf.len() <= bytes.len() {
        return Err(Failure::Message(
            HapcalStatus::Length,
            format!(
                "buf: {} bytes cannot hold the {what} {text:?} ({} bytes with its NUL)",
                buf.len(),
                bytes.len() + 1
            ),
        ));
    }
    buf[..bytes.len()].copy_from_slice(bytes);
    buf[bytes.len()] = 0;
    Ok(())
}

/// Writes the name of joint `joint` (the URDF's `<joint name>`, UTF-8) with its NUL into
/// `buf[0 .. buf_len]`, and its length in bytes without the NUL into `*len_out` unless
/// `len_out` is NULL. With `buf` NULL and `buf_len` 0 only the length is written (to size a
/// buffer).
///
/// Returns `Ok`, `NullPointer`, `InvalidArgument` (joint index past the last) or `Length`
/// (`buf_len` ≤ the name's length; `*len_out` is still written, `buf` is not).
///
/// # Safety
/// `robot` is NULL or a live handle; `buf` NULL or valid for `buf_len` writes; `len_out`
/// NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_joint_name(
    robot: *const HapcalRobot,
    joint: usize,
    buf: *mut c_char,
    buf_len: usize,
    len_out: *mut usize,
) -> HapcalStatus {
    // SAFETY: forwarded contract.
    unsafe { name(robot, joint, buf, buf_len, len_out, NameKind::Joint) }
}

/// Writes the name of tip `tip` (its link's name, as given to [`hapcal_robot_load`]); as
/// [`hapcal_robot_joint_name`].
///
/// # Safety
/// As [`hapcal_robot_joint_name`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_tip_name(
    robot: *const HapcalRobot,
    tip: usize,
    buf: *mut c_char,
    buf_len: usize,
    len_out: *mut usize,
) -> HapcalStatus {
    // SAFETY: forwarded contract.
    unsafe { name(robot, tip, buf, buf_len, len_out, NameKind::Tip) }
}

/// Pose of tip `tip` of the rigid robot (no deflection) at joint angles `q` (rad, m for a
/// prismatic joint), in the root link frame ([`hapcal_runtime::Robot::tip_pose`]).
///
/// Returns `Ok`, `NullPointer`, `Length`, `NotFinite` or `InvalidArgument` (tip index past
/// the last).
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `pose_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_tip_pose(
    robot: *mut HapcalRobot,
    tip: usize,
    q: *const f64,
    n_joints: usize,
    pose_out: *mut HapcalPose,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { robot.as_mut() };
    with_robot(handle, Some(tip), n_joints, |robot, ws| {
        // SAFETY: the caller's contract, for every pointer.
        let q = unsafe { slice(q, n_joints, "q") }?;
        if pose_out.is_null() {
            return Err(Failure::Null("pose_out"));
        }
        let pose = robot.tip_pose(tip, q, ws).map_err(Failure::Robot)?;
        // SAFETY: non-null, valid for one write by the caller's contract.
        unsafe { *pose_out = pose.into() };
        Ok(())
    })
}

/// Poses of every tip given (`poses_out[n_tips]`, in the order of the tip names) of the robot
/// deflected under its own weight when commanded `q` (rad, m for a prismatic joint): the
/// calibrated model's prediction, compliance included ([`hapcal_runtime::Robot::deflected_tip_poses`]:
/// the fixed point `θ = q + k∘τ(θ)`), and what the deflection did into `*deflection_out`
/// unless it is NULL.
///
/// Returns `Ok`, `NullPointer`, `Length` (`n_joints` or `n_tips` not the robot's) or
/// `NotFinite`.
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `poses_out` NULL or valid for `n_tips` writes; `deflection_out` NULL or
/// valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_deflected_tip_poses(
    robot: *mut HapcalRobot,
    q: *const f64,
    n_joints: usize,
    poses_out: *mut HapcalPose,
    n_tips: usize,
    deflection_out: *mut HapcalDeflection,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let Some(handle) = (unsafe { robot.as_mut() }) else {
        return record(HapcalStatus::NullPointer, "robot is NULL".to_owned());
    };
    let given = handle.given;
    let mut all = core::mem::take(&mut handle.poses);
    let status = with_robot(Some(&mut *handle), None, n_joints, |robot, ws| {
        check_count("n_tips", given, n_tips)?;
        // SAFETY: the caller's contract, for every pointer; `HapcalPose` has `Pose`'s
        // layout (checked above).
        let (q, poses) = unsafe {
            (
                slice(q, n_joints, "q")?,
                slice_mut(poses_out.cast::<Pose>(), n_tips, "poses_out")?,
            )
        };
        let deflection = (robot.deflected_tip_poses(q, ws, &mut all)).map_err(Failure::Robot)?;
        poses.copy_from_slice(&all[..given]);
        // SAFETY: the caller's contract: NULL or valid for one write.
        unsafe { put(deflection_out, deflection) };
        Ok(())
    });
    handle.poses = all;
    status
}

/// Which Jacobian a call wants: the deflected one also writes what the deflection did to its
/// pointer unless it is NULL.
#[derive(Clone, Copy)]
enum JacobianKind {
    Spatial,
    Body,
    DeflectedSpatial(*mut HapcalDeflection),
}

/// # Safety
/// As [`hapcal_robot_deflected_spatial_jacobian`], with `kind`'s pointer for
/// `deflection_out`.
unsafe fn jacobian(
    robot: *mut HapcalRobot,
    tip: usize,
    q: *const f64,
    n_joints: usize,
    jac_out: *mut f64,
    pose_out: *mut HapcalPose,
    kind: JacobianKind,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { robot.as_mut() };
    with_robot(handle, Some(tip), n_joints, |robot, ws| {
        // SAFETY: the caller's contract, for every pointer; `[f64; 6]` has the layout of
        // six consecutive doubles, so 6·n doubles are n columns.
        let (q, jac) = unsafe {
            (
                slice(q, n_joints, "q")?,
                slice_mut(jac_out.cast::<[f64; 6]>(), n_joints, "jac_out")?,
            )
        };
        let pose = match kind {
            JacobianKind::Spatial => robot.spatial_jacobian(tip, q, ws, jac),
            JacobianKind::Body => robot.body_jacobian(tip, q, ws, jac),
            JacobianKind::DeflectedSpatial(deflection_out) => {
                let deflected = robot.deflected_spatial_jacobian(tip, q, ws, jac);
                deflected.map(|(pose, deflection)| {
                    // SAFETY: the caller's contract: NULL or valid for one write.
                    unsafe { put(deflection_out, deflection) };
                    pose
                })
            }
        }
        .map_err(Failure::Robot)?;
        // SAFETY: the caller's contract: NULL or valid for one write.
        unsafe { put(pose_out, pose) };
        Ok(())
    })
}

/// Spatial Jacobian of tip `tip` of the rigid robot at joint angles `q` (6 × `n_joints`,
/// column-major into `jac_out[6·n_joints]`; column k: `(w_k × (p − o_k), w_k)` for a revolute
/// joint, `(w_k, 0)` for a prismatic one, zero for a joint not on the tip's path, in the root
/// link frame; rows 0–2 m/rad, rows 3–5 rad/rad), and the tip pose in `*pose_out` unless it is
/// NULL ([`hapcal_runtime::Robot::spatial_jacobian`]).
///
/// Returns `Ok`, `NullPointer`, `Length`, `NotFinite` or `InvalidArgument` (tip index past
/// the last).
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `jac_out` NULL or valid for `6·n_joints` writes; `pose_out` NULL or
/// valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_spatial_jacobian(
    robot: *mut HapcalRobot,
    tip: usize,
    q: *const f64,
    n_joints: usize,
    jac_out: *mut f64,
    pose_out: *mut HapcalPose,
) -> HapcalStatus {
    let kind = JacobianKind::Spatial;
    // SAFETY: forwarded contract.
    unsafe { jacobian(robot, tip, q, n_joints, jac_out, pose_out, kind) }
}

/// Body Jacobian of tip `tip` of the rigid robot at joint angles `q`: the spatial Jacobian's
/// columns in the tip frame, `diag(Rᵀ, Rᵀ)·J_s` ([`hapcal_runtime::Robot::body_jacobian`]);
/// as [`hapcal_robot_spatial_jacobian`].
///
/// # Safety
/// As [`hapcal_robot_spatial_jacobian`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_body_jacobian(
    robot: *mut HapcalRobot,
    tip: usize,
    q: *const f64,
    n_joints: usize,
    jac_out: *mut f64,
    pose_out: *mut HapcalPose,
) -> HapcalStatus {
    let kind = JacobianKind::Body;
    // SAFETY: forwarded contract.
    unsafe { jacobian(robot, tip, q, n_joints, jac_out, pose_out, kind) }
}

/// Gravity torque of every joint at joint angles `q` (no deflection), into
/// `tau_out[n_joints]`: N·m from the link masses, m with lumped unit weights
/// ([`hapcal_robot_has_link_masses`]); 0 for a prismatic joint
/// ([`hapcal_runtime::Robot::gravity_torques`]).
///
/// Returns `Ok`, `NullPointer`, `Length` or `NotFinite`.
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` and `tau_out` NULL or
/// valid for `n_joints` values.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_gravity_torques(
    robot: *mut HapcalRobot,
    q: *const f64,
    n_joints: usize,
    tau_out: *mut f64,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { robot.as_mut() };
    with_robot(handle, None, n_joints, |robot, ws| {
        // SAFETY: the caller's contract, for every pointer.
        let (q, tau) = unsafe {
            (
                slice(q, n_joints, "q")?,
                slice_mut(tau_out, n_joints, "tau_out")?,
            )
        };
        robot.gravity_torques(q, ws, tau).map_err(Failure::Robot)
    })
}

/// The first non-finite value of `values`, as a `NotFinite` failure naming `what`.
fn check_finite(what: &'static str, values: &[f64]) -> Result<(), Failure> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(Failure::Robot(Error::NotFinite {
            what,
            index,
            value: values[index],
        })),
    }
}

/// The runtime's target and settings from C's, every number checked finite.
fn target_and_config(
    target: &HapcalTarget,
    cfg: &HapcalCompensationConfig,
) -> Result<(Target, CompensationConfig), Failure> {
    let p = &target.pose;
    let target = match target.kind {
        HAPCAL_TARGET_POSITION => {
            check_finite("target translation_m", &p.translation_m)?;
            Target::Position(p.translation_m)
        }
        HAPCAL_TARGET_POSE => {
            check_finite("target translation_m", &p.translation_m)?;
            check_finite("target rotation", p.rotation.as_flattened())?;
            Target::Pose(Pose {
                rotation: p.rotation,
                translation_m: p.translation_m,
            })
        }
        other => {
            return Err(Failure::Message(
                HapcalStatus::InvalidArgument,
                format!(
                    "target kind {other} is invalid: expected {HAPCAL_TARGET_POSITION} (position) or {HAPCAL_TARGET_POSE} (pose)"
                ),
            ));
        }
    };
    let settings = [
        cfg.tolerance_m,
        cfg.tolerance_rad,
        cfg.damping_m,
        cfg.orientation_scale_m,
    ];
    check_finite(
        "config (tolerance_m, tolerance_rad, damping_m, orientation_scale_m)",
        &settings,
    )?;
    let cfg = CompensationConfig {
        tolerance_m: cfg.tolerance_m,
        tolerance_rad: cfg.tolerance_rad,
        max_iterations: cfg.max_iterations,
        damping_m: cfg.damping_m,
        orientation_scale_m: cfg.orientation_scale_m,
    };
    Ok((target, cfg))
}

/// The joint command `q_out[n_joints]` (rad, m for a prismatic joint) at which tip `tip`,
/// deflected under the robot's own weight, reaches `*target` (root link frame): damped least
/// squares from `q_start` (the nominal inverse kinematics' solution, or the previous command
/// along a path), commands clamped to the joint limits ([`hapcal_runtime::compensate`]).
/// The outcome goes to `*result_out` unless it is NULL.
///
/// Not reaching the target is a result (`reached` false, the errors left; `q_out` the best
/// command found), not a failure status.
///
/// Returns `Ok`, `NullPointer`, `Length`, `NotFinite` (a start angle, target value or
/// setting) or `InvalidArgument` (tip index past the last, unknown target kind, a target
/// rotation that is not a rotation matrix to 1e-9, a setting not positive).
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `target` and `config` NULL
/// or valid for one read; `q_start` and `q_out` NULL or valid for `n_joints` values;
/// `result_out` NULL or valid for one write.
#[unsafe(no_mangle)]
#[allow(
    clippy::too_many_arguments,
    reason = "a C function: its arguments are its interface"
)]
pub unsafe extern "C" fn hapcal_robot_compensate(
    robot: *mut HapcalRobot,
    tip: usize,
    target: *const HapcalTarget,
    q_start: *const f64,
    n_joints: usize,
    config: *const HapcalCompensationConfig,
    q_out: *mut f64,
    result_out: *mut HapcalCompensation,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { robot.as_mut() };
    with_robot(handle, Some(tip), n_joints, |robot, ws| {
        // SAFETY: the caller's contract, for every pointer.
        let (target, q_start, cfg, q_out) = unsafe {
            (
                crate::get(target, "target")?,
                slice(q_start, n_joints, "q_start")?,
                crate::get(config, "config")?,
                slice_mut(q_out, n_joints, "q_out")?,
            )
        };
        let (target, cfg) = target_and_config(target, cfg)?;
        let c =
            compensate(robot, tip, &target, q_start, &cfg, ws, q_out).map_err(Failure::Robot)?;
        // SAFETY: the caller's contract: NULL or valid for one write.
        unsafe { put(result_out, c) };
        Ok(())
    })
}

/// Whether joint angles `q` (rad, m for a prismatic joint) lie outside the region the
/// calibration was fitted on (the sidecar's recorded training range of each joint, with
/// 5 % of the range as slack; [`hapcal_runtime::Robot::outside_region`]). Outside:
/// `*joint_out` is the joint farthest past its range (by share of the range) and
/// `*distance_out` how far past it (rad or m; positive above the range, negative below).
/// Inside, or for a robot without a recorded region: `*joint_out` is
/// [`HAPCAL_INSIDE_REGION`] and `*distance_out` 0.
///
/// Returns `Ok` (inside or outside: read `*joint_out`), `NullPointer`, `Length` or
/// `NotFinite`; the out-params are written only on `Ok`.
///
/// # Safety
/// `robot` is NULL or a live handle; `q` NULL or valid for `n_joints` values; `joint_out`
/// and `distance_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_outside_region(
    robot: *const HapcalRobot,
    q: *const f64,
    n_joints: usize,
    joint_out: *mut usize,
    distance_out: *mut f64,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        unsafe {
            let robot = &crate::get(robot, "robot")?.robot;
            outside_region(robot, q, n_joints, joint_out, distance_out)
        }
    })
}

/// [`hapcal_robot_outside_region`] on `robot`, for the robot's and the predictor's calls.
///
/// # Safety
/// As [`hapcal_robot_outside_region`], for `q`, `joint_out` and `distance_out`.
pub(crate) unsafe fn outside_region(
    robot: &Robot,
    q: *const f64,
    n_joints: usize,
    joint_out: *mut usize,
    distance_out: *mut f64,
) -> Result<(), Failure> {
    check_n(robot, n_joints)?;
    // SAFETY: the caller's contract, for every pointer.
    let (q, joint, distance) = unsafe {
        (
            slice(q, n_joints, "q")?,
            joint_out.as_mut().ok_or(Failure::Null("joint_out"))?,
            distance_out.as_mut().ok_or(Failure::Null("distance_out"))?,
        )
    };
    let flag = robot.outside_region(q).map_err(Failure::Robot)?;
    (*joint, *distance) = flag.unwrap_or((HAPCAL_INSIDE_REGION, 0.0));
    Ok(())
}

/// Stores a new handle holding `robot` (and a workspace made for it), of which the caller
/// gave the first `given` tips, in `*out`.
///
/// # Safety
/// `out` is valid for one write.
unsafe fn store_robot(out: *mut *mut HapcalRobot, robot: Robot, given: usize) {
    let ws = robot.workspace();
    let poses = vec![Pose::IDENTITY; robot.tip_names().len()];
    let handle = HapcalRobot {
        robot,
        ws,
        given,
        poses,
    };
    // SAFETY: the caller's contract.
    unsafe { crate::store(out, handle) };
}

/// The pattern of the `hapcal_robot_with_*` functions: the robot behind `robot`, the
/// arguments `args` reads for it, `out` checked, then the robot `make` derives from it (given
/// how many tips the caller gave) stored in a new handle with as many tips given; the first
/// failure in that order is returned.
///
/// # Safety
/// `robot` is NULL or a live handle; `out` NULL or valid for one write; `args` may
/// dereference only pointers valid by the caller's contract.
unsafe fn derive<A>(
    robot: *const HapcalRobot,
    out: *mut *mut HapcalRobot,
    args: impl FnOnce(&Robot) -> Result<A, Failure>,
    make: impl FnOnce(&Robot, usize, A) -> Result<Robot, Failure>,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let handle = unsafe { crate::get(robot, "robot") }?;
        let (robot, given) = (&handle.robot, handle.given);
        let args = args(robot)?;
        if out.is_null() {
            return Err(Failure::Null("out"));
        }
        let derived = make(robot, given, args)?;
        // SAFETY: `out` is non-null and valid for a write by the caller's contract.
        unsafe { store_robot(out, derived, given) };
        Ok(())
    })
}

/// Joint limits of the robot, into `lower_out[n_joints]` and `upper_out[n_joints]` (rad, m for
/// a prismatic joint; `-INFINITY` and `INFINITY` for a continuous joint), in the order of the
/// joint names ([`hapcal_runtime::Robot::limits`]).
///
/// Returns `Ok`, `NullPointer` or `Length`.
///
/// # Safety
/// `robot` is NULL or a live handle; `lower_out` and `upper_out` NULL or valid for `n_joints`
/// writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_limits(
    robot: *const HapcalRobot,
    lower_out: *mut f64,
    upper_out: *mut f64,
    n_joints: usize,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        let (robot, lower, upper) = unsafe {
            let robot = &crate::get(robot, "robot")?.robot;
            check_n(robot, n_joints)?;
            (
                robot,
                slice_mut(lower_out, n_joints, "lower_out")?,
                slice_mut(upper_out, n_joints, "upper_out")?,
            )
        };
        for ((lo, hi), &(l, h)) in lower.iter_mut().zip(upper.iter_mut()).zip(robot.limits()) {
            (*lo, *hi) = (l, h);
        }
        Ok(())
    })
}

/// Whether joint `joint` is prismatic (its angle in m, not rad); false for NULL or a joint
/// index past the last ([`hapcal_runtime::Robot::is_prismatic`]).
///
/// # Safety
/// `robot` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_is_prismatic(
    robot: *const HapcalRobot,
    joint: usize,
) -> bool {
    // SAFETY: the caller's contract.
    unsafe { robot.as_ref() }
        .is_some_and(|r| joint < r.robot.n_joints() && r.robot.is_prismatic(joint))
}

/// The compliance of each joint (0: rigid), into `k_out[n_joints]`: rad/(N·m) with link
/// masses, rad/m with lumped unit weights ([`hapcal_robot_has_link_masses`];
/// [`hapcal_runtime::Robot::compliances`]).
///
/// Returns `Ok`, `NullPointer` or `Length`.
///
/// # Safety
/// `robot` is NULL or a live handle; `k_out` NULL or valid for `n_joints` writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_compliances(
    robot: *const HapcalRobot,
    k_out: *mut f64,
    n_joints: usize,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        let (robot, k) = unsafe {
            let robot = &crate::get(robot, "robot")?.robot;
            check_n(robot, n_joints)?;
            (robot, slice_mut(k_out, n_joints, "k_out")?)
        };
        k.copy_from_slice(robot.compliances());
        Ok(())
    })
}

/// An identified frame of the calibration by name (UTF-8, NUL-terminated): `instrument`
/// (the robot's root link frame in the instrument's frame) or `marker1`, `marker2`, … (a
/// marker's frame in its tip link's frame), as the sidecar holds them
/// ([`hapcal_runtime::Robot::frame`]). `*found_out` says whether the calibration identified
/// a frame of that name; only then is `*pose_out` written.
///
/// Returns `Ok` (found or not: read `*found_out`), `NullPointer` or `InvalidUtf8`.
///
/// # Safety
/// `robot` is NULL or a live handle; `name` NULL or a NUL-terminated string; `pose_out` and
/// `found_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_frame(
    robot: *const HapcalRobot,
    name: *const c_char,
    pose_out: *mut HapcalPose,
    found_out: *mut bool,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        let (robot, name, pose, found) = unsafe {
            (
                &crate::get(robot, "robot")?.robot,
                crate::str_arg(name, "name")?,
                pose_out.as_mut().ok_or(Failure::Null("pose_out"))?,
                found_out.as_mut().ok_or(Failure::Null("found_out"))?,
            )
        };
        *found = false;
        if let Some(frame) = robot.frame(name) {
            *pose = frame.into();
            *found = true;
        }
        Ok(())
    })
}

/// A new handle in `*out`: the robot with the frame `*marker` on tip `tip`'s link (in the
/// link's frame, e.g. the calibration's `marker1` from [`hapcal_robot_frame`]); its poses and
/// Jacobians of that tip are then of the marker frame, the gravity loads unchanged
/// ([`hapcal_runtime::Robot::with_marker`]). `robot` itself is unchanged; free both.
///
/// Returns `Ok`, `NullPointer`, `NotFinite` (a pose entry) or `InvalidArgument` (tip index
/// past the last); `*out` is written only on success.
///
/// # Safety
/// `robot` is NULL or a live handle; `marker` NULL or valid for one read; `out` NULL or valid
/// for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_with_marker(
    robot: *const HapcalRobot,
    tip: usize,
    marker: *const HapcalPose,
    out: *mut *mut HapcalRobot,
) -> HapcalStatus {
    // SAFETY: the caller's contract, for every pointer.
    unsafe {
        derive(
            robot,
            out,
            |_| crate::get(marker, "marker"),
            |robot, given, marker| {
                let marker = Pose {
                    rotation: marker.rotation,
                    translation_m: marker.translation_m,
                };
                if tip >= given {
                    return Err(Failure::Robot(past_given(tip)));
                }
                robot.with_marker(tip, &marker).map_err(Failure::Robot)
            },
        )
    }
}

/// A new handle in `*out`: the robot with the joint compliances `k[n_joints]` (rad/(N·m)
/// with link masses, rad/m with lumped unit weights), e.g. a rigid copy with zeros
/// ([`hapcal_runtime::Robot::with_compliances`]). `robot` itself is unchanged; free both.
///
/// Returns `Ok`, `NullPointer`, `Length` or `NotFinite`; `*out` is written only on success.
///
/// # Safety
/// `robot` is NULL or a live handle; `k` NULL or valid for `n_joints` reads; `out` NULL or
/// valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_with_compliances(
    robot: *const HapcalRobot,
    k: *const f64,
    n_joints: usize,
    out: *mut *mut HapcalRobot,
) -> HapcalStatus {
    // SAFETY: the caller's contract, for every pointer.
    unsafe {
        derive(
            robot,
            out,
            |robot| {
                check_n(robot, n_joints)?;
                slice(k, n_joints, "k")
            },
            |robot, _, k| robot.with_compliances(k).map_err(Failure::Robot),
        )
    }
}

/// A new handle in `*out`: the robot with the calibration record's value `name` (UTF-8,
/// NUL-terminated; a name of the sidecar's `[values]`, e.g. `compliance.joint_a2`) set to
/// `value` (in the record's unit): a kinematic value moves its joint's origin, a compliance or
/// harmonic changes the deflection ([`hapcal_runtime::Robot::with_value`]). `robot` itself is
/// unchanged; free both.
///
/// Returns `Ok`, `NullPointer`, `InvalidUtf8`, `NotFinite` or `InvalidArgument` (a name the
/// record does not hold); `*out` is written only on success.
///
/// # Safety
/// `robot` is NULL or a live handle; `name` NULL or a NUL-terminated string; `out` NULL or
/// valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_with_value(
    robot: *const HapcalRobot,
    name: *const c_char,
    value: f64,
    out: *mut *mut HapcalRobot,
) -> HapcalStatus {
    // SAFETY: the caller's contract, for every pointer.
    unsafe {
        derive(
            robot,
            out,
            |_| crate::str_arg(name, "name"),
            |robot, _, name| {
                robot.with_value(name, value).map_err(|e| match e {
                    Error::Invalid { .. } => {
                        Failure::Message(HapcalStatus::InvalidArgument, format!("{name:?}: {e}"))
                    }
                    e => Failure::Robot(e),
                })
            },
        )
    }
}

/// The joint angles θ the calibrated robot takes when commanded `q` (rad, m for a prismatic
/// joint), into `theta_out[n_joints]`: `θ = q + k∘τ + h(q)`, the gravity torques τ on the
/// nominal geometry at the readings, or at the torque equilibrium `θ = q + k∘τ(θ)` when the
/// calibration solved it, and the joint harmonics h (Judd & Knasinski 1990;
/// [`hapcal_runtime::Robot::deflect`]); `theta_out` = `q` without compliance or harmonics.
/// What the deflection did goes to `*deflection_out` unless it is NULL.
///
/// Returns `Ok`, `NullPointer`, `Length` or `NotFinite`.
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` and `theta_out` NULL or
/// valid for `n_joints` values; `deflection_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_deflect(
    robot: *mut HapcalRobot,
    q: *const f64,
    n_joints: usize,
    theta_out: *mut f64,
    deflection_out: *mut HapcalDeflection,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { robot.as_mut() };
    with_robot(handle, None, n_joints, |robot, ws| {
        // SAFETY: the caller's contract, for every pointer.
        let (q, theta) = unsafe {
            (
                slice(q, n_joints, "q")?,
                slice_mut(theta_out, n_joints, "theta_out")?,
            )
        };
        let deflection = robot.deflect(q, ws, theta).map_err(Failure::Robot)?;
        // SAFETY: the caller's contract: NULL or valid for one write.
        unsafe { put(deflection_out, deflection) };
        Ok(())
    })
}

/// The calibrated pose of tip `tip` when commanded `q` (deflected under the robot's own
/// weight, with the calibration's harmonics: as [`hapcal_robot_deflected_tip_poses`]) into
/// `*pose_out` unless it is NULL, and its spatial Jacobian at the deflected angles θ into
/// `jac_out[6·n_joints]` (as [`hapcal_robot_spatial_jacobian`] at θ; the compliance's own
/// `∂θ/∂q`, a relative change of about `k·∂τ/∂θ`, left out), from one deflection: what a
/// controller needs per cycle ([`hapcal_runtime::Robot::deflected_spatial_jacobian`]). What
/// the deflection did goes to `*deflection_out` unless it is NULL.
///
/// Returns `Ok`, `NullPointer`, `Length`, `NotFinite` or `InvalidArgument` (tip index past
/// the last).
///
/// # Safety
/// `robot` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `jac_out` NULL or valid for `6·n_joints` writes; `pose_out` and
/// `deflection_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_robot_deflected_spatial_jacobian(
    robot: *mut HapcalRobot,
    tip: usize,
    q: *const f64,
    n_joints: usize,
    jac_out: *mut f64,
    pose_out: *mut HapcalPose,
    deflection_out: *mut HapcalDeflection,
) -> HapcalStatus {
    let kind = JacobianKind::DeflectedSpatial(deflection_out);
    // SAFETY: forwarded contract.
    unsafe { jacobian(robot, tip, q, n_joints, jac_out, pose_out, kind) }
}
