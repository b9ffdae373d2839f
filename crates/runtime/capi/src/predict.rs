//! The C ABI of the calibrated model's predictions with their uncertainty
//! ([`hapcal_runtime::Predictor`]): an opaque handle holding the predictor and its
//! [`PredictionWorkspace`], so a prediction does not allocate.
//!
//! A prediction is the pose of every tip of the robot deflected under its own weight, in the
//! robot's root link frame or in the calibration's instrument frame (markers on the tips), with
//! the 1σ of its position (m) and orientation (rad) propagated to first order from the
//! calibration record's covariance (GUM, JCGM 100:2008, §5.1.2), as `hapcal predict` prints it.

use std::ffi::c_char;

use hapcal_runtime::{
    PredictionFrame, PredictionWorkspace, Predictor, TipPrediction, UncertaintyBasis,
};

use crate::robot::{HapcalRobot, copy_text};
use crate::{Failure, HapcalPose, HapcalStatus, guard, slice, slice_mut};

/// [`hapcal_predictor_new`]'s `frame`: poses of the tip links in the robot's root link frame.
pub const HAPCAL_FRAME_ROOT: u32 = 0;
/// [`hapcal_predictor_new`]'s `frame`: poses in the calibration's instrument frame, and on
/// tip k (0-based) of marker k + 1 (`marker1`, …; the tip link where the calibration
/// identified no such marker): what the instrument measured.
pub const HAPCAL_FRAME_INSTRUMENT: u32 = 1;

/// What a prediction's σ rests on ([`hapcal_runtime::UncertaintyBasis`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HapcalUncertaintyBasis {
    /// The calibration record's covariance of the values.
    Covariance = 0,
    /// The record holds no covariance: the values' standard deviations as a diagonal
    /// covariance (their correlations ignored).
    StdsOnly = 1,
    /// The robot has no calibration record: no σ.
    NoRecord = 2,
    /// The record holds no identified value (only the instrument and marker frames): no σ.
    NoValues = 3,
}

impl From<UncertaintyBasis> for HapcalUncertaintyBasis {
    fn from(b: UncertaintyBasis) -> HapcalUncertaintyBasis {
        match b {
            UncertaintyBasis::Covariance => HapcalUncertaintyBasis::Covariance,
            UncertaintyBasis::StdsOnly => HapcalUncertaintyBasis::StdsOnly,
            UncertaintyBasis::NoRecord => HapcalUncertaintyBasis::NoRecord,
            UncertaintyBasis::NoValues => HapcalUncertaintyBasis::NoValues,
        }
    }
}

/// One tip's prediction ([`hapcal_runtime::TipPrediction`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HapcalTipPrediction {
    /// The predicted pose (tip link or marker frame) in the predictor's frame, m.
    pub pose: HapcalPose,
    /// 1σ of the predicted position, m: `√trace(G·Σ·Gᵀ)`, `G` the position's derivative with
    /// respect to the recorded values, `Σ` their covariance; NaN without σ.
    pub sigma_m: f64,
    /// 1σ of the predicted orientation, rad (the same with `G` the rotation vector's
    /// derivative); NaN without σ.
    pub sigma_rad: f64,
    /// Whether `sigma_m` and `sigma_rad` hold a σ ([`hapcal_predictor_has_uncertainty`]).
    pub has_sigma: bool,
}

impl From<&TipPrediction> for HapcalTipPrediction {
    fn from(t: &TipPrediction) -> HapcalTipPrediction {
        HapcalTipPrediction {
            pose: t.pose.into(),
            sigma_m: t.sigma_m.unwrap_or(f64::NAN),
            sigma_rad: t.sigma_rad.unwrap_or(f64::NAN),
            has_sigma: t.sigma_m.is_some(),
        }
    }
}

/// A predictor and its buffers, opaque to C: create with [`hapcal_predictor_new`], release
/// with [`hapcal_predictor_free`]. Calls that take it `const` may run from several threads at
/// once; the others use its workspace and must not overlap on one handle.
pub struct HapcalPredictor {
    predictor: Predictor,
    ws: PredictionWorkspace,
    /// One prediction per tip, the runtime's form of the caller's array.
    tips: Vec<TipPrediction>,
    /// How many tips the robot's caller gave ([`crate::hapcal_robot_n_tips`]): the first of
    /// `tips`, those written.
    given: usize,
}

/// Runs `f` on a handle (`None`: a NULL pointer) under [`guard`], once `n_joints` is checked
/// to be the robot's (`Length`); after a caught panic the workspace is rebuilt. `f` gets the predictor, its workspace, every tip's buffer and how
/// many tips were given (the first ones, those written).
fn with_predictor(
    handle: Option<&mut HapcalPredictor>,
    n_joints: usize,
    f: impl FnOnce(
        &Predictor,
        &mut PredictionWorkspace,
        &mut [TipPrediction],
        usize,
    ) -> Result<(), Failure>,
) -> HapcalStatus {
    let rebuild = |h: &mut HapcalPredictor| h.ws = h.predictor.workspace();
    let run = |h: &mut HapcalPredictor| {
        crate::robot::check_n(h.predictor.robot(), n_joints)?;
        f(&h.predictor, &mut h.ws, &mut h.tips, h.given)
    };
    crate::guard_handle(handle, "predictor", run, rebuild)
}

/// Makes the predictor of `robot` in `frame` ([`HAPCAL_FRAME_ROOT`] or
/// [`HAPCAL_FRAME_INSTRUMENT`]) and stores a new handle in `*out`
/// ([`hapcal_runtime::Predictor::new`]): for each recorded value of nonzero variance, the
/// robot with that value a step (10⁻³ of its σ) above and below its record, so a prediction
/// evaluates `2m + 1` deflected robots. The handle holds its own copy of the robot: `robot`
/// may be freed afterwards.
///
/// Returns `Ok`, `NullPointer` or `InvalidArgument` (an unknown `frame`, or
/// [`HAPCAL_FRAME_INSTRUMENT`] for a robot whose calibration identified no instrument frame);
/// `*out` is written only on success.
///
/// # Safety
/// `robot` is NULL or a live handle; `out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_new(
    robot: *const HapcalRobot,
    frame: u32,
    out: *mut *mut HapcalPredictor,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let handle = unsafe { crate::get(robot, "robot") }?;
        let (robot, given) = (handle.robot(), handle.given_tips());
        if out.is_null() {
            return Err(Failure::Null("out"));
        }
        let frame = match frame {
            HAPCAL_FRAME_ROOT => PredictionFrame::Root,
            HAPCAL_FRAME_INSTRUMENT => PredictionFrame::Instrument,
            other => {
                return Err(Failure::Message(
                    HapcalStatus::InvalidArgument,
                    format!(
                        "frame {other} is invalid: expected {HAPCAL_FRAME_ROOT} (root link) or \
                         {HAPCAL_FRAME_INSTRUMENT} (instrument)"
                    ),
                ));
            }
        };
        let predictor = Predictor::new(robot, frame).map_err(Failure::Robot)?;
        let ws = predictor.workspace();
        let tips = vec![TipPrediction::default(); robot.tip_names().len()];
        let handle = HapcalPredictor {
            predictor,
            ws,
            tips,
            given,
        };
        // SAFETY: `out` is non-null and valid for a write by the caller's contract.
        unsafe { crate::store(out, handle) };
        Ok(())
    })
}

/// Releases a predictor handle; NULL is ignored.
///
/// # Safety
/// `predictor` is NULL or a handle from [`hapcal_predictor_new`] not yet freed; it must not
/// be used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_free(predictor: *mut HapcalPredictor) {
    // SAFETY: the caller's contract.
    unsafe { crate::free(predictor) }
}

/// What the predictions' σ rests on; `NoRecord` for NULL.
///
/// # Safety
/// `predictor` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_basis(
    predictor: *const HapcalPredictor,
) -> HapcalUncertaintyBasis {
    // SAFETY: the caller's contract.
    unsafe { predictor.as_ref() }.map_or(HapcalUncertaintyBasis::NoRecord, |p| {
        p.predictor.basis().into()
    })
}

/// Whether the predictions carry a σ (a record whose values the runtime could all vary);
/// false for NULL ([`hapcal_runtime::Predictor::has_uncertainty`]).
///
/// # Safety
/// `predictor` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_has_uncertainty(
    predictor: *const HapcalPredictor,
) -> bool {
    // SAFETY: the caller's contract.
    unsafe { predictor.as_ref() }.is_some_and(|p| p.predictor.has_uncertainty())
}

/// Number of recorded values the σ propagates (those of nonzero variance); 0 for NULL.
///
/// # Safety
/// `predictor` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_n_values(predictor: *const HapcalPredictor) -> usize {
    // SAFETY: the caller's contract.
    unsafe { predictor.as_ref() }.map_or(0, |p| p.predictor.n_values())
}

/// Writes what the σ rests on in words when it is not the record's covariance (the note
/// `hapcal predict` prints; [`hapcal_runtime::Predictor::uncertainty_note`]), UTF-8 with its
/// NUL, into `buf[0 .. buf_len]`, and its length in bytes without the NUL into `*len_out`
/// unless `len_out` is NULL; the empty string with a covariance. With `buf` NULL and
/// `buf_len` 0 only the length is written.
///
/// Returns `Ok`, `NullPointer` or `Length` (`buf_len` ≤ the note's length; `*len_out` is
/// still written, `buf` is not).
///
/// # Safety
/// `predictor` is NULL or a live handle; `buf` NULL or valid for `buf_len` writes; `len_out`
/// NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_uncertainty_note(
    predictor: *const HapcalPredictor,
    buf: *mut c_char,
    buf_len: usize,
    len_out: *mut usize,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let predictor = &unsafe { crate::get(predictor, "predictor") }?.predictor;
        let note = predictor.uncertainty_note().unwrap_or_default();
        // SAFETY: forwarded contract.
        unsafe { copy_text(&note, "uncertainty note", buf, buf_len, len_out) }
    })
}

/// The predicted poses of every tip at the joint readings `q` (rad, m for a prismatic joint;
/// in the order of the joint names) with their σ, into `out[n_tips]` (in the order of the
/// tip names): the robot deflected under its own weight in the predictor's frame
/// ([`hapcal_runtime::Predictor::predict`]). No allocation.
///
/// Returns `Ok`, `NullPointer`, `Length` (`n_joints` or `n_tips` not the robot's) or
/// `NotFinite`.
///
/// # Safety
/// `predictor` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `out` NULL or valid for `n_tips` writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_predict(
    predictor: *mut HapcalPredictor,
    q: *const f64,
    n_joints: usize,
    out: *mut HapcalTipPrediction,
    n_tips: usize,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { predictor.as_mut() };
    with_predictor(handle, n_joints, |predictor, ws, tips, given| {
        crate::robot::check_count("n_tips", given, n_tips)?;
        // SAFETY: the caller's contract, for every pointer.
        let (q, out) = unsafe { (slice(q, n_joints, "q")?, slice_mut(out, n_tips, "out")?) };
        predictor.predict(q, ws, tips).map_err(Failure::Robot)?;
        for (o, t) in out.iter_mut().zip(tips.iter()) {
            *o = t.into();
        }
        Ok(())
    })
}

/// The predicted poses of the markers 0 .. `n_markers` (1-based in files: `x1, y1, z1` is
/// marker 0) at `q`, into `poses_out[n_markers]`, in the instrument frame whatever the
/// predictor's frame: marker k + 1's frame on tip `min(k, last)`, the root frame or the tip
/// link where the calibration identified none ([`hapcal_runtime::Predictor::marker_poses_into`]):
/// what a measured row is compared with. No allocation.
///
/// Returns `Ok`, `NullPointer`, `Length` or `NotFinite`.
///
/// # Safety
/// `predictor` is NULL or a live handle not in use by another call; `q` NULL or valid for
/// `n_joints` values; `poses_out` NULL or valid for `n_markers` writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_marker_poses(
    predictor: *mut HapcalPredictor,
    q: *const f64,
    n_joints: usize,
    poses_out: *mut HapcalPose,
    n_markers: usize,
) -> HapcalStatus {
    // SAFETY: the caller's contract.
    let handle = unsafe { predictor.as_mut() };
    with_predictor(handle, n_joints, |predictor, ws, _, _| {
        // SAFETY: the caller's contract, for every pointer; `HapcalPose` has `Pose`'s layout
        // (checked in robot.rs).
        let (q, poses) = unsafe {
            (
                slice(q, n_joints, "q")?,
                slice_mut(
                    poses_out.cast::<hapcal_runtime::Pose>(),
                    n_markers,
                    "poses_out",
                )?,
            )
        };
        (predictor.marker_poses_into(q, ws, poses)).map_err(Failure::Robot)
    })
}

/// Whether the readings `q` lie outside the region the calibration was fitted on, as
/// [`crate::hapcal_robot_outside_region`] on the predictor's robot: `*joint_out` the joint
/// farthest past its range or [`crate::HAPCAL_INSIDE_REGION`], `*distance_out` how far (rad or m).
///
/// Returns `Ok`, `NullPointer`, `Length` or `NotFinite`; the out-params are written only on
/// `Ok`.
///
/// # Safety
/// `predictor` is NULL or a live handle; `q` NULL or valid for `n_joints` values; `joint_out`
/// and `distance_out` NULL or valid for one write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hapcal_predictor_outside_region(
    predictor: *const HapcalPredictor,
    q: *const f64,
    n_joints: usize,
    joint_out: *mut usize,
    distance_out: *mut f64,
) -> HapcalStatus {
    guard(|| {
        // SAFETY: the caller's contract, for every pointer.
        unsafe {
            let robot = crate::get(predictor, "predictor")?.predictor.robot();
            crate::robot::outside_region(robot, q, n_joints, joint_out, distance_out)
        }
    })
}
