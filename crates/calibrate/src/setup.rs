//! The setup check: catches ordinary setup mistakes in a measurement-file calibration before
//! they become a confident, wrong calibration.
//!
//! For each hypothesis of a mistake (positions in millimetres read as metres, orientations in
//! degrees read as radians, quaternion components in another order, roll and yaw swapped, a
//! mirrored or swapped position axis (one hypothesis: a left-handed frame), joint columns in the wrong order, joint rows out of step
//! with the measurement rows, the tip link one or two moving joints up or down the chain, tips
//! given in the wrong order), the data are corrected as the hypothesis says, the frames only
//! are fitted (the nominal kinematics with the instrument and marker frames) and the
//! frames-only residual compared with that of the data as given. Every hypothesis is screened
//! with a closed-form fit ([`closed_form_residual`], microseconds per row); when something
//! looks wrong, the data as given and the three best hypotheses are refitted with the
//! calibration's own frames-only fit ([`measured::frames_only`]), whose residuals the findings
//! report. A joint column that never changes while the robot's description lets the joint
//! move is found from the data directly.
//!
//! A hypothesis without a free parameter lowers the residual of right data only by chance:
//! the frames-only residual of right data is the instrument's noise plus the robot's
//! manufacturing deviations, and relabelling, rescaling or shifting the rows scrambles both
//! without fitting anything new. A hypothesis that divides the residual by
//! [`OVERWHELMING_FACTOR`] and leaves a residual a real robot can have
//! ([`PLAUSIBLE_FRAMES_ONLY_RMS_M`], [`PLAUSIBLE_FRAMES_ONLY_RAD`]) is therefore a finding of
//! severity error: the caller stops unless the user accepts the data as they are
//! ([`SetupConfig::accept_setup`]). One that divides it by [`SUGGESTIVE_FACTOR`] is a
//! warning. Nothing is ever corrected silently: the findings name the flag or the edit that
//! applies, and the residual before and after it.

use crate::model::ModelName;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use hapcal_io::{AngleUnit, LengthUnit, MeasurementTable, Units};
use hapcal_kinematics::{UnitQuaternion, Vector3};
use hapcal_problems::{CalibratedModel, Weights};

use crate::measured::{self, MeasuredConfig, Robot};
use crate::noise::PLAUSIBLE_FRAMES_ONLY_RMS_M;
use crate::setup_change::{
    ChangeInput, PartFit, SampleResidual, change_hypotheses, residuals_jump,
};
use crate::setup_families::{
    ANGLE_UNITS, JointColumn, LENGTH_UNITS, Layout, LengthGroup, SetupData, Tier,
    fitted_hypotheses, general_hypotheses, residual_location, row_hypotheses, shift_readings,
};
pub use crate::setup_findings::{
    CHECK_SAMPLE_ROWS, ClosestHypothesis, FROZEN_SPREAD, Finding, MAX_CHECK_ROWS, MistakeClass,
    OVERWHELMING_FACTOR, PLAUSIBLE_FRAMES_ONLY_RAD, Residual, ResidualOf, SUGGESTIVE_FACTOR,
    SetupReport, Severity,
};
use crate::setup_findings::{
    Corrected, OPEN_LIMIT, ResidualFn, Scoring, frozen_columns, judge, mm, nearest_rotation,
    nearest_rotation_from, tip_candidates,
};

/// What the user accepts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SetupConfig {
    /// Use the data as they are even when a hypothesis explains them overwhelmingly better
    /// (`--accept-setup`): the findings become warnings.
    pub accept_setup: bool,
    /// How the user says so, as the messages name it: `--accept-setup` on the command line,
    /// `accept_setup=True` in Python.
    pub accept_option: &'static str,
}

/// What the check needs besides the robot and its tables: where they came from.
#[derive(Clone, Debug)]
pub struct SetupInput<'a> {
    /// The robot as given.
    pub robot: &'a Robot,
    /// Its training tables as read with `units`.
    pub tables: &'a [MeasurementTable],
    /// The URDF the robot came from (`None` for a device file): the tip hypotheses need it.
    pub urdf: Option<&'a Path>,
    /// The tip links given (marker k on tip k), for a URDF.
    pub tips: &'a [String],
    /// The units the tables were read with.
    pub units: Units,
}

/// Measurement data as a hypothesis corrects them: the tables, and the robot (another tip)
/// and the markers' tips where the hypothesis changes them.
#[derive(Clone)]
struct MeasuredData {
    robot: Option<Robot>,
    tables: Vec<MeasurementTable>,
    marker_tips: Option<Vec<usize>>,
}

impl MeasuredData {
    fn tables(tables: Vec<MeasurementTable>) -> Self {
        MeasuredData {
            robot: None,
            tables,
            marker_tips: None,
        }
    }
}

impl SetupData for MeasuredData {
    fn with_joints(&self, f: &(dyn Fn(&mut [f64]) + Sync)) -> Self {
        MeasuredData::tables(map_rows(&self.tables, &|row| {
            let mut q = row.q.to_vec();
            f(&mut q);
            row.q = q.into();
        }))
    }

    fn with_lengths(&self, group: Option<usize>, factor: f64) -> Self {
        MeasuredData::tables(map_rows(&self.tables, &|row| {
            for m in &mut row.markers {
                if group.is_none_or(|g| g == m.marker) {
                    m.position_m = m.position_m.map(|v| v * factor);
                }
            }
            if group.is_none() {
                row.distance_m = row.distance_m.map(|d| d * factor);
            }
        }))
    }

    fn with_shift(&self, shift: isize, from: Option<(usize, u64)>) -> Option<Self> {
        let tables = shifted(&self.tables, shift, from);
        let min_rows = tables.iter().map(|t| t.rows.len()).min().unwrap_or(0);
        (min_rows >= 6).then(|| MeasuredData::tables(tables))
    }
}

/// The weights of the frames-only fits: those `calibrate_measured` starts from.
fn check_weights() -> Weights {
    Weights {
        sigma_position_m: 1e-3,
        sigma_distance_m: 1e-3,
        sigma_orientation_rad: 1e-2,
        ..Weights::default()
    }
}

/// The frames-only residual of `tables` on `robot` with markers on `marker_tips`; `None`
/// when the fit fails.
pub fn frames_only_residual(
    robot: &Robot,
    tables: &[MeasurementTable],
    marker_tips: &[usize],
) -> Option<Residual> {
    let cfg = MeasuredConfig {
        rung: Some(ModelName::FramesOnly),
        folds: 2,
        marker_tips: marker_tips.to_vec(),
        ..MeasuredConfig::default()
    };
    let tables = thinned(tables);
    let fo = measured::frames_only(robot, &tables, &cfg, check_weights()).ok()?;
    Some(residual_of(&fo.model, &tables))
}

/// `tables` with at most [`MAX_CHECK_ROWS`] rows in all, evenly spaced in each file.
fn thinned(tables: &[MeasurementTable]) -> Vec<MeasurementTable> {
    let n: usize = tables.iter().map(|t| t.rows.len()).sum();
    let mut out = tables.to_vec();
    if n <= MAX_CHECK_ROWS {
        return out;
    }
    for t in &mut out {
        let keep = (t.rows.len() * MAX_CHECK_ROWS).div_ceil(n).max(1);
        let len = t.rows.len();
        let rows = std::mem::take(&mut t.rows);
        t.rows = (rows.into_iter().enumerate())
            .filter(|(i, _)| (i * keep) / len != ((i + 1) * keep) / len || len <= keep)
            .map(|(_, r)| r)
            .collect();
    }
    out
}

/// Weight of the orientation against the position residual in [`closed_form_residual`], m²
/// per unit of `‖R_model − R_measured‖²_F` (≈ 2θ²): the weights of the frames-only fit, σ = 1 mm
/// per axis and 0.01 rad, so that 0.01 rad counts as 1 mm.
const ORIENTATION_WEIGHT_M2: f64 = 0.5 * 1e-3 * 1e-3 / (1e-2 * 1e-2);

/// Block iterations of [`closed_form_residual`], at most, before its Levenberg–Marquardt
/// steps ([`Frames::polish`]): a start from which those steps converge (the Kabsch step of
/// the first is global).
const POLISHED_ITERATIONS: usize = 3;

/// The frames-only residual of marker data (no distance rows) by block coordinate descent on
/// the nominal tip poses: the instrument rotation `R₀` and translation `t` (Kabsch, with the
/// orientations' term), then each marker's offset `m_k` (the mean of the back-projected
/// measurements: `R₀·R_tip` is orthogonal) and rotation `R_k` (the nearest rotation to the sum
/// of `(R₀·R_tip)ᵀ·R_meas`), each step lowering `Σ|e_p|² + w·Σ‖ΔR‖²_F`. Microseconds per row:
/// the check screens every hypothesis with it and refits the suspicious ones with
/// [`frames_only_residual`]. `None` with distance rows or fewer than 3 samples.
pub fn closed_form_residual(
    robot: &Robot,
    tables: &[MeasurementTable],
    marker_tips: &[usize],
) -> Option<Residual> {
    closed_form_fit(robot, tables, marker_tips, None).map(|fit| fit.residual)
}

/// Closed-form fits, at most, to the rows that fit the last one (the per-row residuals that
/// find rows that do not belong): a tenth of a file's rows mixed up ruins the first fit to
/// every row, and the rows within 3 medians of it still hold some of them.
const ROBUST_REFITS: usize = 4;

/// The closed-form frames-only fit of [`closed_form_residual`]: its residual, and each row's.
struct ClosedForm {
    residual: Residual,
    /// Per row checked: its file (index into the tables), its line, and the root of its
    /// squared position errors plus the weighted orientation term, m.
    per_row: Vec<(usize, u64, f64)>,
    /// Per marker sample checked, in the rows' order: its position error under the frames
    /// fitted (the change-point probe's input).
    samples: Vec<SampleResidual>,
    /// The frames fitted.
    frames: Frames,
}

/// One marker sample of [`closed_form_fit`]: the nominal tip pose and the measurement.
#[derive(Clone, Copy)]
struct Sample {
    /// The marker's index.
    marker: usize,
    /// The tip's rotation and position in the robot's base frame (nominal model).
    r_tip: nalgebra::Matrix3<f64>,
    p_tip: Vector3<f64>,
    /// The measured position (m) and rotation, in the instrument's frame.
    measured: Vector3<f64>,
    rotation: Option<nalgebra::Matrix3<f64>>,
}

/// The frames of [`closed_form_fit`]: the instrument's rotation `R₀` and translation `t` (m),
/// and each marker's offset `m_k` (m) and rotation `R_k` on its tip.
struct Frames {
    r0: nalgebra::Matrix3<f64>,
    t: Vector3<f64>,
    offsets: Vec<Vector3<f64>>,
    marker_rot: Vec<nalgebra::Matrix3<f64>>,
}

/// Steps of [`Frames::polish`], at most: from the block iterations' start, data a hypothesis
/// explains converge in four or five (Gauss–Newton converges fast near a small residual:
/// 2.86 → 0.17 → 3.8·10⁻³ → 1.4·10⁻⁵ → 1.73·10⁻⁶ on the positioner); a wrong hypothesis,
/// far from any fit, is left with a residual above its minimum (every step lowers it), which
/// judges it no better than it is.
const POLISH_STEPS: usize = 8;

/// [`Frames::polish`] stops when a step lowers the cost by less than this share of it: the RMS
/// residual then moves by under 10⁻⁶ of itself, where the judge compares residuals by factors.
const POLISH_TOLERANCE: f64 = 1e-6;

impl Frames {
    /// The block coordinate descent of [`closed_form_residual`] from identity frames, at most
    /// [`POLISHED_ITERATIONS`], fewer when the frames stop moving. The first iteration's
    /// rotations by SVD (a global answer from any start), the next ones by ascent from the
    /// last (the frames move little from one iteration to the next).
    fn start(samples: &[Sample], n_markers: usize) -> Frames {
        use nalgebra::Matrix3;
        let mut offsets = vec![Vector3::zeros(); n_markers];
        let mut marker_rot = vec![Matrix3::identity(); n_markers];
        let (mut r0, mut t) = (Matrix3::identity(), Vector3::zeros());
        let mut first = true;
        let nearest = |m: &Matrix3<f64>, last: &Matrix3<f64>, first: bool| {
            if first {
                nearest_rotation(m)
            } else {
                nearest_rotation_from(m, last)
            }
        };
        for _ in 0..POLISHED_ITERATIONS {
            let (r0_before, t_before) = (r0, t);
            let (offsets_before, marker_rot_before) = (offsets.clone(), marker_rot.clone());
            // Instrument frame.
            let a: Vec<Vector3<f64>> = (samples.iter())
                .map(|s| s.r_tip * offsets[s.marker] + s.p_tip)
                .collect();
            let n = a.len() as f64;
            let ca = a.iter().sum::<Vector3<f64>>() / n;
            let cb = samples.iter().map(|s| s.measured).sum::<Vector3<f64>>() / n;
            let mut h = Matrix3::zeros();
            for (ai, s) in a.iter().zip(samples) {
                h += (s.measured - cb) * (ai - ca).transpose();
                if let Some(meas) = &s.rotation {
                    let model = s.r_tip * marker_rot[s.marker];
                    h += ORIENTATION_WEIGHT_M2 * meas * model.transpose();
                }
            }
            r0 = nearest(&h, &r0, first);
            t = cb - r0 * ca;
            // Marker frames.
            let mut sum_m = vec![(Vector3::zeros(), 0usize); n_markers];
            let mut sum_r = vec![Matrix3::zeros(); n_markers];
            for s in samples {
                let rt = r0 * s.r_tip;
                let back = rt.transpose() * (s.measured - t - r0 * s.p_tip);
                sum_m[s.marker].0 += back;
                sum_m[s.marker].1 += 1;
                if let Some(meas) = &s.rotation {
                    sum_r[s.marker] += rt.transpose() * meas;
                }
            }
            for k in 0..n_markers {
                if sum_m[k].1 > 0 {
                    offsets[k] = sum_m[k].0 / sum_m[k].1 as f64;
                }
                if sum_r[k] != Matrix3::zeros() {
                    marker_rot[k] = nearest(&sum_r[k], &marker_rot[k], first);
                }
            }
            first = false;
            // Converged: the frames no longer move (a picometre, 10⁻¹² rad).
            let moved = (r0 - r0_before).amax() + (t - t_before).amax();
            let moved_markers = (offsets.iter().zip(&offsets_before))
                .map(|(a, b)| (a - b).amax())
                .chain((marker_rot.iter().zip(&marker_rot_before)).map(|(a, b)| (a - b).amax()))
                .fold(0.0, f64::max);
            if moved + moved_markers < 1e-12 {
                break;
            }
        }
        Frames {
            r0,
            t,
            offsets,
            marker_rot,
        }
    }

    /// The position error of one sample, m: `R₀·(R_tip·m_k + p_tip) + t − p_meas`.
    fn position_error(&self, s: &Sample) -> Vector3<f64> {
        self.r0 * (s.r_tip * self.offsets[s.marker] + s.p_tip) + self.t - s.measured
    }

    /// Residual rows of one sample: the position error `R₀·(R_tip·m_k + p_tip) + t − p_meas`
    /// (m) and, with a measured rotation, `√(2w)·θ·n` for the rotation `θ` about `n` from the
    /// model to the measurement (the logarithm of `R_meas·R_modelᵀ`; w
    /// [`ORIENTATION_WEIGHT_M2`]: its square `2w·θ²` is the block iterations'
    /// `w·‖ΔR‖²_F = 4w·(1 − cos θ)` to second order in `θ`).
    fn residual(&self, s: &Sample) -> (Vector3<f64>, Option<Vector3<f64>>) {
        let e = self.position_error(s);
        let rot = s.rotation.map(|meas| {
            let model = self.r0 * s.r_tip * self.marker_rot[s.marker];
            (2.0 * ORIENTATION_WEIGHT_M2).sqrt()
                * nalgebra::Rotation3::from_matrix_unchecked(meas * model.transpose()).scaled_axis()
        });
        (e, rot)
    }

    /// The sum of the squared [`Frames::residual`] rows over `samples`, m²: the rotation's
    /// `2w·θ²` from its angle alone (`cos θ = (tr(R_meas·R_modelᵀ) − 1)/2`, the trace as the
    /// sum of the element-wise product), without its axis.
    fn cost(&self, samples: &[Sample]) -> f64 {
        (samples.iter())
            .map(|s| {
                let e = self.position_error(s);
                let turned = s.rotation.map_or(0.0, |meas| {
                    let model = self.r0 * s.r_tip * self.marker_rot[s.marker];
                    let cos = ((meas.component_mul(&model).sum() - 1.0) / 2.0).clamp(-1.0, 1.0);
                    2.0 * ORIENTATION_WEIGHT_M2 * cos.acos().powi(2)
                });
                e.norm_squared() + turned
            })
            .sum()
    }

    /// Levenberg–Marquardt on the frames from the block iterations' estimate: the block
    /// coordinate descent crawls along the valley a long lever between the instrument and the
    /// joints makes (the positioner's: 25 mm after 50 iterations where the frames fit to
    /// 0.45 mm), Gauss–Newton steps on all frames at once cross it. Parameters: `R₀` turned
    /// by `exp(δ₀)` on the left, `t`, each `m_k`, each `R_k` turned by `exp(δ_k)` on the
    /// right; normal equations of `6 + 6·markers` unknowns, damped by `λ·(diag + 1)`. Stops
    /// when a step lowers the cost by less than [`POLISH_TOLERANCE`] of it or after
    /// [`POLISH_STEPS`].
    fn polish(&mut self, samples: &[Sample]) {
        use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, Vector6};
        use std::ops::{AddAssign, SubAssign};
        let n_markers = self.offsets.len();
        let n = 6 + 6 * n_markers;
        let skew = |v: Vector3<f64>| v.cross_matrix();
        let mut cost = self.cost(samples);
        let mut lambda = 1e-4;
        for _ in 0..POLISH_STEPS {
            // The upper blocks of JᵀJ and Jᵀr: the instrument's (δ₀, t) with itself, with each
            // marker's (m_k, δ_k), and each marker's with itself.
            let mut a00 = Matrix6::<f64>::zeros();
            let mut g0 = Vector6::<f64>::zeros();
            let mut a0k = vec![Matrix6::<f64>::zeros(); n_markers];
            let mut akk = vec![Matrix6::<f64>::zeros(); n_markers];
            let mut gk = vec![Vector6::<f64>::zeros(); n_markers];
            let c2 = 2.0 * ORIENTATION_WEIGHT_M2;
            let c = c2.sqrt();
            for s in samples {
                let (e, rot) = self.residual(s);
                let k = s.marker;
                // Position rows: ∂/∂δ₀ = −[v]× (v = R₀·(R_tip·m_k + p_tip)), ∂/∂t = I,
                // ∂/∂m_k = B = R₀·R_tip, orthogonal (BᵀB = I).
                let v = self.r0 * (s.r_tip * self.offsets[k] + s.p_tip);
                let b = self.r0 * s.r_tip;
                let vx = skew(v);
                let id = Matrix3::<f64>::identity();
                a00.fixed_view_mut::<3, 3>(0, 0)
                    .add_assign(id * v.norm_squared() - v * v.transpose());
                a00.fixed_view_mut::<3, 3>(0, 3).add_assign(vx);
                a00.fixed_view_mut::<3, 3>(3, 3).add_assign(id);
                g0.fixed_rows_mut::<3>(0).add_assign(v.cross(&e));
                g0.fixed_rows_mut::<3>(3).add_assign(e);
                a0k[k].fixed_view_mut::<3, 3>(0, 0).add_assign(vx * b);
                a0k[k].fixed_view_mut::<3, 3>(3, 0).add_assign(b);
                akk[k].fixed_view_mut::<3, 3>(0, 0).add_assign(id);
                gk[k].fixed_rows_mut::<3>(0).add_assign(b.tr_mul(&e));
                if let Some(r) = rot {
                    // Rotation rows: ∂/∂δ₀ = −c·I, ∂/∂δ_k = −c·R_model.
                    let model = b * self.marker_rot[k];
                    a00.fixed_view_mut::<3, 3>(0, 0).add_assign(id * c2);
                    g0.fixed_rows_mut::<3>(0).sub_assign(c * r);
                    a0k[k].fixed_view_mut::<3, 3>(0, 3).add_assign(c2 * model);
                    akk[k].fixed_view_mut::<3, 3>(3, 3).add_assign(id * c2);
                    gk[k]
                        .fixed_rows_mut::<3>(3)
                        .sub_assign(c * model.tr_mul(&r));
                }
            }
            let mut jtj = DMatrix::<f64>::zeros(n, n);
            let mut jtr = DVector::<f64>::zeros(n);
            jtj.fixed_view_mut::<6, 6>(0, 0).copy_from(&a00);
            jtr.fixed_rows_mut::<6>(0).copy_from(&g0);
            for k in 0..n_markers {
                let at = 6 + 6 * k;
                jtj.fixed_view_mut::<6, 6>(0, at).copy_from(&a0k[k]);
                jtj.fixed_view_mut::<6, 6>(at, at).copy_from(&akk[k]);
                jtr.fixed_rows_mut::<6>(at).copy_from(&gk[k]);
            }
            jtj.fill_lower_triangle_with_upper_triangle();
            let mut accepted = false;
            while lambda < 1e6 {
                let mut a = jtj.clone();
                for i in 0..n {
                    a[(i, i)] += lambda * (jtj[(i, i)] + 1.0);
                }
                let Some(chol) = a.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let step = chol.solve(&(-&jtr));
                let v = |i: usize| Vector3::new(step[i], step[i + 1], step[i + 2]);
                let trial = Frames {
                    r0: Rotation3::new(v(0)).into_inner() * self.r0,
                    t: self.t + v(3),
                    offsets: (0..n_markers)
                        .map(|m| self.offsets[m] + v(6 + 6 * m))
                        .collect(),
                    marker_rot: (0..n_markers)
                        .map(|m| self.marker_rot[m] * Rotation3::new(v(9 + 6 * m)).into_inner())
                        .collect(),
                };
                let trial_cost = trial.cost(samples);
                if trial_cost <= cost {
                    let gained = cost - trial_cost;
                    *self = trial;
                    cost = trial_cost;
                    lambda = (lambda / 10.0).max(1e-12);
                    accepted = gained > POLISH_TOLERANCE * cost;
                    break;
                }
                if trial_cost - cost <= POLISH_TOLERANCE * cost {
                    // At the minimum: the step changes the cost by its rounding only.
                    break;
                }
                lambda *= 10.0;
            }
            if !accepted {
                break;
            }
        }
    }
}

/// [`closed_form_residual`] with the per-row residuals.
fn closed_form_fit(
    robot: &Robot,
    tables: &[MeasurementTable],
    marker_tips: &[usize],
    fit_rows: Option<&[bool]>,
) -> Option<ClosedForm> {
    if tables.iter().any(|t| t.has_distance) {
        return None;
    }
    let tables = thinned(tables);
    let chains = robot.tree.tips();
    let last = chains.len().checked_sub(1)?;
    let zero = vec![0.0; robot.tree.n_params()];
    // Per sample: marker, tip pose in the base frame, measured position and rotation; and its
    // row (index into `rows`).
    let mut samples = Vec::new();
    let mut sample_rows = Vec::new();
    let mut rows: Vec<(usize, u64)> = Vec::new();
    for (f, row) in
        (tables.iter().enumerate()).flat_map(|(f, t)| t.rows.iter().map(move |r| (f, r)))
    {
        rows.push((f, row.line));
        for m in &row.markers {
            sample_rows.push(rows.len() - 1);
            let tip = marker_tips.get(m.marker).copied().unwrap_or(last).min(last);
            let pose = chains.get(tip)?.end_pose(&zero, &row.q);
            let rotation = m.rotation.map(|[w, x, y, z]| {
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
                    .to_rotation_matrix()
                    .into_inner()
            });
            samples.push(Sample {
                marker: m.marker,
                r_tip: pose.rotation.to_rotation_matrix().into_inner(),
                p_tip: pose.translation.vector,
                measured: Vector3::from(m.position_m),
                rotation,
            });
        }
    }
    if samples.len() < 3 {
        return None;
    }
    let n_markers = samples.iter().map(|s| s.marker + 1).max().unwrap_or(0);
    // The frames from the rows `fit_rows` keeps (every row without it).
    let fitted: Vec<Sample> = (samples.iter().zip(&sample_rows))
        .filter(|(_, r)| fit_rows.is_none_or(|keep| keep.get(**r) == Some(&true)))
        .map(|(s, _)| *s)
        .collect();
    if fitted.len() < 3 {
        return None;
    }
    let mut frames = Frames::start(&fitted, n_markers);
    frames.polish(&fitted);
    let (mut len_sq, mut rot_sq, mut n_rot) = (0.0, 0.0, 0usize);
    let mut row_sq = vec![0.0; rows.len()];
    let mut residuals = Vec::with_capacity(samples.len());
    for (s, &r) in samples.iter().zip(&sample_rows) {
        let error = frames.position_error(s);
        residuals.push(SampleResidual {
            file: rows[r].0,
            marker: s.marker,
            error_m: error,
            in_tip_m: (frames.r0 * s.r_tip).tr_mul(&error),
            measured_m: s.measured,
        });
        let e = error.norm_squared();
        len_sq += e;
        row_sq[r] += e;
        if let Some(meas) = &s.rotation {
            let model = frames.r0 * s.r_tip * frames.marker_rot[s.marker];
            let rel = nalgebra::Rotation3::from_matrix_unchecked(model.transpose() * meas);
            let angle_sq = rel.angle().powi(2);
            rot_sq += angle_sq;
            n_rot += 1;
            // ‖ΔR‖²_F ≈ 2θ², weighted as the fit weighs it.
            row_sq[r] += 2.0 * ORIENTATION_WEIGHT_M2 * angle_sq;
        }
    }
    Some(ClosedForm {
        residual: frames_only_rms((len_sq, samples.len()), (rot_sq, n_rot), &tables),
        per_row: (rows.iter().zip(&row_sq))
            .map(|(&(f, line), sq)| (f, line, sq.sqrt()))
            .collect(),
        samples: residuals,
        frames,
    })
}

/// The residual of `tables` under `model` (a framed tree: tip k is marker k).
fn residual_of(model: &CalibratedModel, tables: &[MeasurementTable]) -> Residual {
    let (mut len_sq, mut n_len, mut rot_sq, mut n_rot) = (0.0, 0usize, 0.0, 0usize);
    let n_tips = model.tips.len().max(1);
    for row in tables.iter().flat_map(|t| &t.rows) {
        if let Some(d) = row.distance_m {
            let e = model.end_pose_of(0, &row.q).translation.vector.norm() - d;
            len_sq += e * e;
            n_len += 1;
        }
        let markers: Vec<_> = row.markers.iter().filter(|m| m.marker < n_tips).collect();
        let tips: Vec<usize> = markers.iter().map(|m| m.marker).collect();
        for (m, pose) in markers.iter().zip(model.end_poses_of(&tips, &row.q)) {
            len_sq += (pose.translation.vector - Vector3::from(m.position_m)).norm_squared();
            n_len += 1;
            if let Some([w, x, y, z]) = m.rotation {
                let meas = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                rot_sq += meas.angle_to(&pose.rotation).powi(2);
                n_rot += 1;
            }
        }
    }
    frames_only_rms((len_sq, n_len), (rot_sq, n_rot), tables)
}

/// The frames-only residual of `tables` from the sums of squared position (m²) and angle
/// (rad²) errors with their counts: RMS of each (`None` without a sample), and the spread.
fn frames_only_rms(
    (len_sq, n_len): (f64, usize),
    (rot_sq, n_rot): (f64, usize),
    tables: &[MeasurementTable],
) -> Residual {
    let rms = |sq: f64, n: usize| (n > 0).then(|| (sq / n as f64).sqrt());
    Residual {
        of: ResidualOf::FramesOnly,
        length_rms_m: rms(len_sq, n_len),
        orientation_rms_rad: rms(rot_sq, n_rot),
        spread_m: spread_of(tables),
    }
}

/// [`Residual::spread_m`] of `tables`.
fn spread_of(tables: &[MeasurementTable]) -> Option<f64> {
    let rows = || tables.iter().flat_map(|t| &t.rows);
    let mut sum: Vec<(Vector3<f64>, usize)> = Vec::new();
    let (mut d_sum, mut n_d) = (0.0, 0usize);
    for row in rows() {
        for m in &row.markers {
            if sum.len() <= m.marker {
                sum.resize(m.marker + 1, (Vector3::zeros(), 0));
            }
            if let Some(s) = sum.get_mut(m.marker) {
                s.0 += Vector3::from(m.position_m);
                s.1 += 1;
            }
        }
        if let Some(d) = row.distance_m {
            d_sum += d;
            n_d += 1;
        }
    }
    let centroid: Vec<Vector3<f64>> = sum.iter().map(|(s, n)| s / (*n).max(1) as f64).collect();
    let d_mean = d_sum / n_d.max(1) as f64;
    let (mut sq, mut n) = (0.0, 0usize);
    for row in rows() {
        for m in &row.markers {
            if let Some(c) = centroid.get(m.marker) {
                sq += (Vector3::from(m.position_m) - c).norm_squared();
                n += 1;
            }
        }
        if let Some(d) = row.distance_m {
            sq += (d - d_mean).powi(2);
            n += 1;
        }
    }
    (n > 0 && sq > 0.0).then(|| (sq / n as f64).sqrt())
}

/// `tables` with every marker position and distance mapped by `f`.
fn map_rows(
    tables: &[MeasurementTable],
    f: &dyn Fn(&mut hapcal_io::MeasuredRow),
) -> Vec<MeasurementTable> {
    let mut out = tables.to_vec();
    for row in out.iter_mut().flat_map(|t| &mut t.rows) {
        f(row);
    }
    out
}

/// `tables` with every marker's rotation mapped by `f` (`[w, x, y, z]` in, a rotation out).
fn map_rotations(
    tables: &[MeasurementTable],
    f: &(dyn Fn(UnitQuaternion<f64>) -> UnitQuaternion<f64> + Sync),
) -> Vec<MeasurementTable> {
    map_rows(tables, &|row| {
        for m in &mut row.markers {
            if let Some([w, x, y, z]) = m.rotation {
                let r = f(UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    w, x, y, z,
                )));
                m.rotation = Some([r.w, r.i, r.j, r.k]);
            }
        }
    })
}

/// `tables` with the marker positions and rotations seen through the reflection or
/// permutation `m` (its own inverse): `p → M·p`, `R → M·R·M`.
fn reflect(tables: &[MeasurementTable], m: &nalgebra::Matrix3<f64>) -> Vec<MeasurementTable> {
    map_rows(tables, &|row| {
        for s in &mut row.markers {
            s.position_m = (m * Vector3::from(s.position_m)).into();
            if let Some([w, x, y, z]) = s.rotation {
                let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                let mm = m * r.to_rotation_matrix().matrix() * m;
                let r = UnitQuaternion::from_matrix(&mm);
                s.rotation = Some([r.w, r.i, r.j, r.k]);
            }
        }
    })
}

/// `tables` with the joint readings of each row taken from the row `shift` further down the
/// file (rows without a partner dropped): joint readings `shift` rows late; with `from`, only
/// in that file (index) from that line on.
fn shifted(
    tables: &[MeasurementTable],
    shift: isize,
    from: Option<(usize, u64)>,
) -> Vec<MeasurementTable> {
    let mut out = tables.to_vec();
    for (f, t) in out.iter_mut().enumerate() {
        let from = match from {
            None => 0,
            Some((file, _)) if file != f => continue,
            Some((_, line)) => line,
        };
        t.rows = shift_readings(
            &t.rows,
            shift,
            from,
            |r| r.line,
            |r, p| r.q.clone_from(&p.q),
        );
    }
    out
}

/// The joint's name with its column number: `elbow_joint (q3)`.
fn joint_label(robot: &Robot, j: usize) -> String {
    format!(
        "{} (q{})",
        robot.joint_names.get(j).map_or("?", String::as_str),
        j + 1
    )
}

/// Whether every file's header has a column for each of `joints` (by name, or as `q{n}` past
/// the `n_joints` the robot has).
fn has_columns(headers: &[Vec<String>], joints: &[String], n_joints: usize) -> bool {
    headers.iter().all(|h| {
        joints
            .iter()
            .enumerate()
            .all(|(i, name)| h.contains(name) || h.contains(&format!("q{}", n_joints + i + 1)))
    })
}

/// The robot of a URDF for each set of tips in `tip_sets`, from one reading of the URDF (with
/// the union of the tips): the robot of [`measured::robot_from_urdf`] without link masses
/// (the frames-only fits do not use them); `None` for a set that does not build.
fn robots_for_tips(urdf: &Path, tip_sets: &[Vec<String>]) -> Vec<Option<Robot>> {
    let mut all: Vec<String> = Vec::new();
    for t in tip_sets.iter().flatten() {
        if !all.contains(t) {
            all.push(t.clone());
        }
    }
    let Ok(description) = hapcal_io::import_urdf_tips(urdf, &all) else {
        // One bad tip spoils the union: each set on its own.
        return (tip_sets.iter())
            .map(|set| measured::robot_from_urdf(urdf, set).ok())
            .collect();
    };
    tip_sets
        .iter()
        .map(|set| {
            let paths: Vec<_> = (set.iter())
                .map(|t| {
                    let i = all.iter().position(|a| a == t)?;
                    description.paths.get(i).cloned()
                })
                .collect::<Option<_>>()?;
            let tree = hapcal_kinematics::Tree::from_placement_paths(&paths).ok()?;
            let joint_names = tree.joint_names().to_vec();
            let limits = (joint_names.iter())
                .map(|n| {
                    let j = description.joints.iter().find(|j| &j.name == n)?;
                    Some((j.lower_rad, j.upper_rad))
                })
                .collect::<Option<Vec<_>>>()?;
            let prismatic = (hapcal_kinematics::joint_motions(tree.tips()).iter())
                .map(|m| *m == Some(hapcal_kinematics::Motion::Translation))
                .collect();
            Some(Robot {
                joint_names,
                prismatic,
                limits,
                masses: Vec::new(),
                held_joints: Vec::new(),
                load_tips: Vec::new(),
                gravity_dir: -hapcal_kinematics::Vector3::z(),
                tree,
            })
        })
        .collect()
}

/// How the files of `input` lay out their columns, for the general families.
fn layout_of(input: &SetupInput<'_>, headers: &[Vec<String>]) -> Layout {
    let robot = input.robot;
    let named =
        |name: &str| !headers.is_empty() && headers.iter().all(|h| h.iter().any(|c| c == name));
    let joints = (0..robot.joint_names.len())
        .map(|j| {
            let name = robot.joint_names.get(j).map_or("?", String::as_str);
            JointColumn {
                label: if named(name) {
                    name.to_owned()
                } else {
                    format!("q{}", j + 1)
                },
                words: joint_label(robot, j),
                revolute: robot.prismatic.get(j) != Some(&true),
            }
        })
        .collect();
    let n_markers = input.tables.iter().map(|t| t.n_markers).max().unwrap_or(0);
    let mut lengths: Vec<LengthGroup> = (0..n_markers)
        .map(|k| {
            let n = if named("x1") || !named("x") {
                (k + 1).to_string()
            } else {
                String::new()
            };
            let (x, y, z) = (format!("x{n}"), format!("y{n}"), format!("z{n}"));
            LengthGroup {
                label: format!("{x},{y},{z}"),
                words: format!("marker {}'s positions ({x}, {y}, {z})", k + 1),
            }
        })
        .collect();
    if lengths.is_empty() && input.tables.iter().any(|t| t.has_distance) {
        lengths.push(LengthGroup {
            label: "distance_m".to_owned(),
            words: "the distances".to_owned(),
        });
    }
    let unit_name = |units: &[(&'static str, &'static str, f64)], si: f64| {
        (units.iter())
            .find(|u| (u.2 - si).abs() <= 1e-12 * si)
            .map_or("?", |u| u.0)
    };
    // The joints each tip's chain moves that no other tip's does: one arm's columns.
    let moved: Vec<Vec<usize>> = (robot.tree.tips().iter())
        .map(|chain| {
            let mut js: Vec<usize> = (chain.factors().iter())
                .filter_map(|f| match f {
                    hapcal_kinematics::Factor::Screw { joint: Some(j), .. } => Some(*j),
                    _ => None,
                })
                .collect();
            js.sort_unstable();
            js.dedup();
            js
        })
        .collect();
    // The measured tips, then the links that only carry loads (the other arm's readings).
    let names: Vec<&String> = input.tips.iter().chain(&robot.load_tips).collect();
    let arms = if moved.len() >= 2 {
        (moved.iter().enumerate())
            .filter_map(|(t, js)| {
                let own: Vec<usize> = (js.iter().copied())
                    .filter(|j| {
                        moved
                            .iter()
                            .enumerate()
                            .all(|(u, o)| u == t || !o.contains(j))
                    })
                    .collect();
                Some(((*names.get(t)?).clone(), own))
            })
            .collect()
    } else {
        Vec::new()
    };
    Layout {
        joints,
        lengths,
        angle_unit: unit_name(&ANGLE_UNITS, input.units.angle.to_rad()),
        length_unit: unit_name(&LENGTH_UNITS, input.units.length.to_m()),
        arms,
        paired_rows: true,
    }
}

/// The hypotheses of the measurement files' own families (frames and conventions of pose
/// data, the angles of orientations, tips) for `input`; the files read again in the other
/// angle unit only when the data are `suspicious` (angles in the wrong unit turn every joint
/// by a factor of 57, or leave the robot all but still: no frames fit that to a residual right
/// data leave).
fn own_hypotheses(
    input: &SetupInput<'_>,
    headers: &[Vec<String>],
    suspicious: bool,
) -> Vec<Corrected<MeasuredData>> {
    let mut out = if suspicious {
        angle_rereads(input, headers)
    } else {
        Vec::new()
    };
    out.extend(orientation_conventions(input.tables, headers));
    out.extend(tip_hypotheses(input, headers));
    out
}

/// The files read again in the other angle unit (all angles, or only the orientation angles);
/// none without orientation angles (`phix, phiy, phiz`) or a revolute joint.
fn angle_rereads(input: &SetupInput<'_>, headers: &[Vec<String>]) -> Vec<Corrected<MeasuredData>> {
    let (robot, tables, units) = (input.robot, input.tables, &input.units);
    let has_rpy = headers.iter().flatten().any(|c| c.starts_with("phix"));
    if !has_rpy || robot.prismatic.iter().all(|p| *p) {
        return Vec::new();
    }
    let (other, unit_word, other_word, flag) = match units.angle {
        AngleUnit::Rad => (AngleUnit::Deg, "radians", "degrees", "--angle-unit deg"),
        AngleUnit::Deg => (AngleUnit::Rad, "degrees", "radians", "--angle-unit rad"),
        _ => (
            AngleUnit::Rad,
            "another unit",
            "radians",
            "--angle-unit rad",
        ),
    };
    let other_units = Units {
        angle: other,
        ..(*units).clone()
    };
    let paths: Vec<PathBuf> = tables.iter().map(|t| t.path.clone()).collect();
    let Ok(reread) = load_sample(&paths, robot, &other_units) else {
        return Vec::new();
    };
    if (reread.iter().zip(tables.iter())).any(|(a, b)| a.rows.len() != b.rows.len()) {
        return Vec::new();
    }
    // Every angle (joints and phix, phiy, phiz) in the other unit (the joints alone are a
    // general hypothesis), or only the orientation angles.
    let mut mixed = tables.to_vec();
    for (t, r) in mixed.iter_mut().zip(&reread) {
        for (row, rr) in t.rows.iter_mut().zip(&r.rows) {
            for (m, mr) in row.markers.iter_mut().zip(&rr.markers) {
                m.rotation = mr.rotation;
            }
        }
    }
    vec![
        corrected(
            MistakeClass::AngleUnit,
            format!("the angles are in {other_word}, read as {unit_word}"),
            flag,
            reread,
        ),
        corrected(
            MistakeClass::OrientationUnit,
            format!(
                "the orientation angles phix, phiy, phiz are in {other_word} while the joint \
                 readings are in {unit_word}"
            ),
            format!(
                "convert phix, phiy, phiz to {unit_word} in the file ({flag} would convert the \
                 joint readings too)"
            ),
            mixed,
        ),
    ]
}

/// The hypothesis of `class` (`what` the mistake is, its `fix`) whose data are `tables`.
fn corrected(
    class: MistakeClass,
    what: impl Into<String>,
    fix: impl Into<String>,
    tables: Vec<MeasurementTable>,
) -> Corrected<MeasuredData> {
    Corrected::new(class, what, fix, MeasuredData::tables(tables))
}

/// The conventions of the orientations (quaternion order and conjugate, Euler orders) and of
/// the instrument's axes (a left-handed frame).
fn orientation_conventions(
    tables: &[MeasurementTable],
    headers: &[Vec<String>],
) -> Vec<Corrected<MeasuredData>> {
    let mut out = Vec::new();
    let has_markers = tables.iter().any(|t| t.n_markers > 0);
    let has_orientation = tables.iter().any(|t| t.has_orientation);
    let has_rpy = headers.iter().flatten().any(|c| c.starts_with("phix"));
    let has_quaternion =
        has_orientation && (!has_rpy || headers.iter().flatten().any(|c| c.starts_with("qw")));
    // Orientations.
    if has_quaternion {
        out.push(corrected(
            MistakeClass::QuaternionOrder,
            "the quaternion columns qw, qx, qy, qz hold x, y, z, w (scalar last)",
            "rename the columns qw, qx, qy, qz to qx, qy, qz, qw (the scalar is the last \
             component)",
            map_rotations(tables, &|r| {
                let (w, x, y, z) = (r.w, r.i, r.j, r.k);
                // Read as (w, x, y, z) = (x', y', z', w').
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(z, w, x, y))
            }),
        ));
    }
    if has_orientation {
        out.push(corrected(
            MistakeClass::QuaternionInverse,
            "the orientations are inverted (the instrument in the marker's frame)",
            if has_rpy {
                "invert the orientations: negate phix, phiy, phiz and reverse their order of \
                 rotation, or export the marker in the instrument's frame"
            } else {
                "negate qx, qy, qz (the conjugate quaternion), or export the marker in the \
                 instrument's frame"
            },
            map_rotations(tables, &|r| r.inverse()),
        ));
    }
    if has_rpy {
        out.push(corrected(
            MistakeClass::EulerOrder,
            "roll and yaw are swapped: phix holds the yaw and phiz the roll",
            "swap the columns phix and phiz",
            map_rotations(tables, &|r| {
                let (roll, pitch, yaw) = r.euler_angles();
                UnitQuaternion::from_euler_angles(yaw, pitch, roll)
            }),
        ));
        // The angles composed in another order than R = Rz(phiz)·Ry(phiy)·Rx(phix).
        for order in ["XYZ", "XZY", "YXZ", "YZX", "ZXY"] {
            let product = order
                .chars()
                .map(|c| format!("R{}(phi{})", c.to_ascii_lowercase(), c.to_ascii_lowercase()))
                .collect::<Vec<_>>()
                .join("·");
            out.push(corrected(
                MistakeClass::EulerOrder,
                format!(
                    "the orientation angles compose as R = {product} ({order} Euler angles), read \
                     as R = Rz(phiz)·Ry(phiy)·Rx(phix)"
                ),
                format!(
                    "convert the orientations to R = Rz(phiz)·Ry(phiy)·Rx(phix), or export them \
                     as quaternions qw, qx, qy, qz (the export uses {order})"
                ),
                map_rotations(tables, &|r| {
                    let (x, y, z) = r.euler_angles();
                    let axis = |c: char| match c {
                        'X' => UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x),
                        'Y' => UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y),
                        _ => UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z),
                    };
                    order
                        .chars()
                        .fold(UnitQuaternion::identity(), |acc, c| acc * axis(c))
                }),
            ));
        }
    }

    // Position axes: a mirrored axis and two swapped axes are one hypothesis. Each
    // reflection is any other times a rotation (diag(−1, 1, 1) = Rz(π)·diag(1, −1, 1), a swap
    // of x and y = a rotation times diag(1, −1, 1)), and the fitted instrument frame takes up
    // the rotation, in the orientations too (M₁·R·M₁ = Q·M₂·R·M₂·Qᵀ, the Qᵀ taken up by the
    // marker frame): the data tell that the frame is left-handed, not which axis made it so.
    if has_markers {
        let mut m = nalgebra::Matrix3::identity();
        m[(2, 2)] = -1.0;
        out.push(corrected(
            MistakeClass::MirroredAxis,
            "the positions are in a left-handed frame: one axis mirrored or two axes swapped \
             (the fit cannot tell which: each is the other up to a rotation)",
            "find the axis the export mirrors (negate that column of the positions) or the two \
             axes it swaps (swap those columns), and mirror the orientations with them",
            reflect(tables, &m),
        ));
    }
    out
}

/// The tips: given in the wrong order, or one link off the one the markers sit on.
fn tip_hypotheses(input: &SetupInput<'_>, headers: &[Vec<String>]) -> Vec<Corrected<MeasuredData>> {
    let (robot, tables, units) = (input.robot, input.tables, &input.units);
    let mut out = Vec::new();
    let n = robot.joint_names.len();
    let paths: Vec<PathBuf> = tables.iter().map(|t| t.path.clone()).collect();
    // Tips in the wrong order.
    let n_tips = input.tips.len();
    for a in 0..n_tips {
        for b in a + 1..n_tips {
            let mut tips: Vec<usize> = (0..n_tips).collect();
            tips.swap(a, b);
            let mut order: Vec<String> = input.tips.to_vec();
            order.swap(a, b);
            out.push(Corrected::new(
                MistakeClass::SwappedTips,
                format!(
                    "the markers of {} and {} are swapped (the tips in the wrong order)",
                    input.tips[a], input.tips[b]
                ),
                format!(
                    "give the tips in the order of the markers: {} (or swap the marker columns \
                     x{}.. and x{}..)",
                    tip_flags(&order),
                    a + 1,
                    b + 1
                ),
                MeasuredData {
                    robot: None,
                    tables: tables.to_vec(),
                    marker_tips: Some(tips),
                },
            ));
        }
    }

    // The tip link: the candidates whose joints the files have columns for, their robots
    // from one reading of the URDF.
    if let Some(urdf) = input.urdf
        && let Ok(description) = hapcal_io::read_urdf(urdf)
    {
        let mut candidates = Vec::new();
        let mut named = Vec::new();
        for (t, tip) in input.tips.iter().enumerate() {
            for (link, steps, joints) in tip_candidates(&description, tip) {
                if input.tips.contains(&link) || !has_columns(headers, &joints, n) {
                    continue;
                }
                // Columns named for the joints between (not q8, q9 past the chain's count).
                named.push(
                    (joints.iter())
                        .filter(|j| headers.iter().all(|h| h.contains(j)))
                        .cloned()
                        .collect::<Vec<String>>(),
                );
                let mut tips = input.tips.to_vec();
                if let Some(slot) = tips.get_mut(t) {
                    slot.clone_from(&link);
                }
                candidates.push((tip.clone(), link, steps, tips));
            }
        }
        let sets: Vec<Vec<String>> = candidates.iter().map(|c| c.3.clone()).collect();
        for (((tip, link, steps, tips), other), ignored) in candidates
            .into_iter()
            .zip(robots_for_tips(urdf, &sets))
            .zip(named)
        {
            let Some(other) = other else { continue };
            let Ok(reread) = load_sample(&paths, &other, units) else {
                continue;
            };
            let k = steps.unsigned_abs();
            let joints = if k == 1 { "joint" } else { "joints" };
            let side = if steps > 0 { "below" } else { "above" };
            out.push(Corrected {
                class: MistakeClass::TipLink,
                what: format!(
                    "the markers sit on {link}, {k} moving {joints} {side} the tip {tip}"
                ),
                fix: format!("use {}", tip_flags(&tips)),
                data: MeasuredData {
                    robot: Some(other),
                    tables: reread,
                    marker_tips: None,
                },
                evidence: ignored,
            });
        }
    }
    out
}

/// Every hypothesis of a mistake for `input` (the data as given, `given`, residual
/// `as_given`): the files' own families and the general ones, the per-column and per-row
/// families too when the data are `suspicious` (the free scales and couplings fitted with
/// `screen`), the row families from the per-row residuals `per_row` (file, line, m) when there
/// are any. `whole` is the closed-form fit to every row, when it applies.
fn measurement_hypotheses(
    input: &SetupInput<'_>,
    (given, as_given): (&MeasuredData, &Residual),
    suspicious: Option<ResidualFn<'_, MeasuredData>>,
    whole: Option<&ClosedForm>,
    per_row: Option<&[(usize, u64, f64)]>,
) -> Vec<Corrected<MeasuredData>> {
    let headers: Vec<Vec<String>> = (input.tables.iter())
        .map(|t| crate::data::csv_columns(&t.path))
        .collect();
    let layout = layout_of(input, &headers);
    let names: Vec<String> = input.tables.iter().map(file_name).collect();
    let mut hypotheses = own_hypotheses(input, &headers, suspicious.is_some());
    hypotheses.extend(general_hypotheses(given, &layout, Tier::Always));
    // Frames that change from a row on: scanned when the data are suspicious or the per-row
    // residuals jump, else after a probe of a few splits (a move the frames of the whole file
    // absorb to a residual right data can leave).
    let jumps = suspicious.is_some() || per_row.is_some_and(residuals_jump);
    hypotheses.extend(change_point_hypotheses(input, &names, jumps, whole));
    if let Some(screen) = suspicious {
        hypotheses.extend(general_hypotheses(given, &layout, Tier::Suspicious));
        hypotheses.extend(fitted_hypotheses(given, &layout, as_given, screen));
        hypotheses.extend(position_reflections(input.tables));
        hypotheses.extend(part_unit_hypotheses(input.tables, input.units.length));
        if let Some(per_row) = per_row {
            hypotheses.extend(row_hypotheses(given, &layout, per_row, &names, |drop| {
                let mut tables = thinned(input.tables);
                for (f, t) in tables.iter_mut().enumerate() {
                    t.rows.retain(|r| !drop.contains(&(f, r.line)));
                }
                Some(MeasuredData::tables(tables))
            }));
        }
    }
    hypotheses
}

/// The name a finding gives a table's file: its file name (the table's name without a path).
fn file_name(t: &MeasurementTable) -> String {
    (t.path.file_name()).map_or_else(|| t.name.clone(), |f| f.to_string_lossy().into_owned())
}

/// The change-point hypotheses of `input` (files named `names`), with the closed-form fit
/// as the frames of each part; every file scanned when the data are `suspicious`, else the
/// files whose probe of `whole` (the closed-form fit to every row) finds a change.
fn change_point_hypotheses(
    input: &SetupInput<'_>,
    names: &[String],
    suspicious: bool,
    whole: Option<&ClosedForm>,
) -> Vec<Corrected<MeasuredData>> {
    let given_tips: Vec<usize> = (0..input.tips.len().max(1)).collect();
    let part = |fit: &ClosedForm, tables: &[MeasurementTable]| {
        let n_rows: usize = tables.iter().map(|t| t.rows.len()).sum();
        let sq: f64 = fit.per_row.iter().map(|r| r.2 * r.2).sum();
        PartFit {
            cost_m2: sq / fit.per_row.len().max(1) as f64 * n_rows as f64,
            instrument: (fit.frames.r0, fit.frames.t),
            marker_offsets_m: fit.frames.offsets.clone(),
            samples: fit.samples.clone(),
        }
    };
    let fit = |tables: &[MeasurementTable], tips: &[usize]| {
        Some(part(
            &closed_form_fit(input.robot, tables, tips, None)?,
            tables,
        ))
    };
    let whole = whole.map(|w| part(w, input.tables));
    let urdf = input.urdf.and_then(|p| hapcal_io::read_urdf(p).ok());
    let twins: Vec<Option<String>> = (input.tips.iter())
        .map(|tip| {
            let urdf = urdf.as_ref()?;
            crate::setup_change::fixed_twin(urdf, tip, input.tips)
        })
        .collect();
    change_hypotheses(
        &ChangeInput {
            tables: input.tables,
            file_names: names,
            marker_tips: &given_tips,
            tip_names: input.tips,
            twins: &twins,
            suspicious,
            whole: whole.as_ref(),
        },
        &fit,
        &|tables, tips| MeasuredData {
            robot: None,
            tables,
            marker_tips: Some(tips),
        },
    )
}

/// Least ratio between the position magnitudes of two consecutive rows, sorted by magnitude,
/// that splits a file into two parts in different length units ([`magnitude_split`]): a
/// millimetre part among metres is 1000× larger, an inch part 39×; the markers of one
/// recording, seen by one instrument, do not jump by 20× in their distance from it.
const PART_UNIT_RATIO: f64 = 20.0;

/// The rows of `table` (indices) whose positions lie [`PART_UNIT_RATIO`] or more times
/// farther from the instrument than the other rows', with the ratio of the two parts'
/// median distances; `None` when the rows form one part (or fewer than 4 have positions).
fn magnitude_split(table: &MeasurementTable) -> Option<(Vec<usize>, f64)> {
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut sizes: Vec<(usize, f64)> = (table.rows.iter().enumerate())
        .filter_map(|(i, r)| {
            let mut d: Vec<f64> = (r.markers.iter())
                .map(|m| Vector3::from(m.position_m).norm())
                .collect();
            if d.is_empty() {
                return None;
            }
            let d = median(&mut d);
            (d > 0.0 && d.is_finite()).then_some((i, d))
        })
        .collect();
    if sizes.len() < 4 {
        return None;
    }
    sizes.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (k, gap) = (1..sizes.len())
        .map(|k| (k, sizes[k].1 / sizes[k - 1].1))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    if gap < PART_UNIT_RATIO {
        return None;
    }
    let mut small: Vec<f64> = sizes[..k].iter().map(|s| s.1).collect();
    let mut large: Vec<f64> = sizes[k..].iter().map(|s| s.1).collect();
    let ratio = median(&mut large) / median(&mut small);
    let mut rows: Vec<usize> = sizes[k..].iter().map(|s| s.0).collect();
    rows.sort_unstable();
    Some((rows, ratio))
}

/// File lines as ranges: `19–24, 30`.
fn line_ranges(lines: &[u64]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let mut j = i;
        while j + 1 < lines.len() && lines[j + 1] == lines[j] + 1 {
            j += 1;
        }
        out.push(if j > i {
            format!("{}–{}", lines[i], lines[j])
        } else {
            lines[i].to_string()
        });
        i = j + 1;
    }
    out.join(", ")
}

/// "rows 19–24 of tail.csv": the rows `rows` (indices) of `table` by their file lines.
fn rows_of_file(table: &MeasurementTable, rows: &[usize]) -> String {
    let lines: Vec<u64> = rows.iter().map(|&i| table.rows[i].line).collect();
    format!("rows {} of {}", line_ranges(&lines), file_name(table))
}

/// The words of the unit of [`LENGTH_UNITS`] of `m` metres (`metres` for 1), if any.
fn part_unit_name(m: f64) -> Option<&'static str> {
    (LENGTH_UNITS.iter())
        .find(|(_, _, u)| (u / m - 1.0).abs() < 1e-9)
        .map(|&(_, words, _)| words)
}

/// Part of a file in another length unit ([`magnitude_split`]): for each table whose rows
/// split into two parts, the larger part's positions read in the unit (of [`LENGTH_UNITS`],
/// smaller than the file's `unit`) whose ratio to it lies nearest the parts' ratio. The
/// answer locates the rows: no flag reads part of a file, so the fix is the edit of those
/// rows.
fn part_unit_hypotheses(
    tables: &[MeasurementTable],
    unit: LengthUnit,
) -> Vec<Corrected<MeasuredData>> {
    let file_m = unit.to_m();
    let Some(file_name) = part_unit_name(file_m) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (t, table) in tables.iter().enumerate() {
        let Some((rows, ratio)) = magnitude_split(table) else {
            continue;
        };
        let off = |m: f64| ((file_m / m) / ratio).ln().abs();
        let Some(&(_, part_name, part_m)) = (LENGTH_UNITS.iter())
            .filter(|(_, _, m)| *m < file_m)
            .min_by(|a, b| off(a.2).total_cmp(&off(b.2)))
        else {
            continue;
        };
        let factor = part_m / file_m;
        let mut rescaled = tables.to_vec();
        for &i in &rows {
            for m in &mut rescaled[t].rows[i].markers {
                m.position_m = m.position_m.map(|v| v * factor);
            }
        }
        let where_ = rows_of_file(table, &rows);
        out.push(corrected(
            MistakeClass::LengthUnit,
            format!("{where_} look like {part_name} while the rest are in {file_name}"),
            format!(
                "no flag reads part of a file: convert the positions of {where_} to {file_name} \
                 (×{factor}) or record them again"
            ),
            rescaled,
        ));
    }
    out
}

/// With orientations, one position axis mirrored or two exchanged while the orientations are
/// not: the orientations pin the instrument frame's rotation, so here each reflection is a
/// hypothesis of its own (naming its columns). Empty without orientations.
fn position_reflections(tables: &[MeasurementTable]) -> Vec<Corrected<MeasuredData>> {
    if !tables.iter().any(|t| t.has_orientation) {
        return Vec::new();
    }
    let axes = ["x", "y", "z"];
    let reflected = |m: nalgebra::Matrix3<f64>, what: String, fix: String| {
        let positions = map_rows(tables, &|row| {
            for s in &mut row.markers {
                s.position_m = (m * Vector3::from(s.position_m)).into();
            }
        });
        corrected(MistakeClass::MirroredAxis, what, fix, positions)
    };
    let mirrored = axes.iter().enumerate().map(|(a, name)| {
        let mut m = nalgebra::Matrix3::identity();
        m[(a, a)] = -1.0;
        let what = format!("the positions' {name} axis is mirrored while the orientations are not");
        reflected(
            m,
            what,
            format!("negate the {name} columns of the positions"),
        )
    });
    let swapped = [(0, 1), (0, 2), (1, 2)].map(|(a, b)| {
        let mut m = nalgebra::Matrix3::identity();
        m.swap_rows(a, b);
        let (a, b) = (axes[a], axes[b]);
        let what =
            format!("the positions' {a} and {b} axes are exchanged while the orientations are not");
        reflected(
            m,
            what,
            format!("swap the {a} and {b} columns of the positions"),
        )
    });
    mirrored.chain(swapped).collect()
}

/// Joints whose readings never change (spread ≤ [`FROZEN_SPREAD`]) over two or more rows
/// while their limits let them move: `(joint, value)`.
pub fn frozen_joints(robot: &Robot, tables: &[MeasurementTable]) -> Vec<(usize, f64)> {
    let rows: Vec<&[f64]> = (tables.iter().flat_map(|t| &t.rows))
        .map(|r| &r.q[..])
        .collect();
    if rows.len() < 2 {
        return Vec::new();
    }
    frozen_columns(&rows, &robot.limits, robot.joint_names.len())
}

/// Checks the setup of a measurement-file calibration: the frames-only residual of the data as
/// given against each hypothesis of a mistake, and the joint columns that never change.
/// Findings, errors first; see the module docs for the decision.
///
/// # Errors
/// The frames-only fit of the data as given fails (no closed-form start, a failed
/// identification): the calibration would fail the same way.
pub fn check_setup(input: &SetupInput<'_>) -> Result<SetupReport> {
    let n_tips = input.tips.len().max(1);
    let given_tips: Vec<usize> = (0..n_tips).collect();
    fn robot_of<'r>(d: &'r MeasuredData, given: &'r Robot) -> &'r Robot {
        d.robot.as_ref().unwrap_or(given)
    }
    let tips_of = |d: &MeasuredData| d.marker_tips.clone().unwrap_or_else(|| given_tips.clone());
    // Screen with the closed form (the full fit for distance data), refit what looks
    // suspicious with the full frames-only fit.
    let screen = |d: &MeasuredData| {
        closed_form_residual(robot_of(d, input.robot), &d.tables, &tips_of(d))
            .or_else(|| frames_only_residual(robot_of(d, input.robot), &d.tables, &tips_of(d)))
    };
    let refine =
        |d: &MeasuredData| frames_only_residual(robot_of(d, input.robot), &d.tables, &tips_of(d));
    let given = MeasuredData::tables(input.tables.to_vec());
    let closed_form = closed_form_fit(input.robot, input.tables, &given_tips, None);
    let as_given = match &closed_form {
        Some(fit) => fit.residual,
        None => frames_only_residual(input.robot, input.tables, &given_tips)
            .context("the frames-only fit of the data as given failed")?,
    };
    let robust = robust_closed_form(input, &given_tips, closed_form.as_ref());
    let per_row = robust
        .as_ref()
        .or(closed_form.as_ref())
        .map(|fit| &fit.per_row[..]);
    // The closed form may stop short of the full fit (a long lever between the instrument and
    // the joints): the per-column families only when the full fit agrees the data are not
    // right data of a real robot.
    let full = (!as_given.is_clean())
        .then(|| frames_only_residual(input.robot, input.tables, &given_tips))
        .flatten();
    let suspicious = !as_given.is_clean() && full.is_none_or(|f| !f.is_clean());
    // Right data whose closed form stopped short are judged against the full fit (no
    // hypothesis then looks better than the data as given by the screen's shortfall).
    let as_given = match full {
        Some(f) if f.is_clean() => f,
        _ => as_given,
    };
    let hypotheses = measurement_hypotheses(
        input,
        (&given, &as_given),
        suspicious.then_some(&screen as ResidualFn<'_, MeasuredData>),
        closed_form.as_ref(),
        per_row,
    );
    let judged = judge(
        as_given,
        &given,
        &hypotheses,
        &Scoring {
            screen: &screen,
            refine: Some(&refine),
        },
    );
    let as_given = judged.as_given;
    let n_results = judged.n_scored;
    let mut findings: Vec<Finding> = judged.finding.into_iter().collect();
    let explained = findings.iter().any(|f| f.severity == Severity::Error);
    let frozen = frozen_joints(input.robot, input.tables);
    let n_rows: usize = input.tables.iter().map(|t| t.rows.len()).sum();
    findings.extend(frozen_findings(
        input,
        &frozen,
        !explained && !as_given.is_plausible(),
        as_given,
    ));
    // Another robot's lengths: a residual above what right data leave (a plausible one too,
    // when a free instrument frame absorbs much of the lengths' effect, as a UR5e's
    // description does of a UR10e's data) that a geometric calibration explains.
    let another = (!explained && frozen.is_empty() && !as_given.is_clean())
        .then(|| another_device(input.robot, input.tables, &given_tips, &as_given))
        .flatten();
    let explained = explained || another.is_some();
    findings.extend(another);
    if !explained && frozen.is_empty() && !as_given.is_plausible() {
        findings.push(no_hypothesis_finding(input, per_row, as_given, n_results));
    }
    findings.sort_by_key(|f| f.severity != Severity::Error);
    Ok(SetupReport {
        n_rows,
        as_given,
        n_hypotheses: n_results,
        closest: judged.closest,
        findings,
    })
}

/// Per-row residuals under frames fitted to the rows that fit (rows that do not belong pull
/// the frames of a fit to every row, and every row's residual with them): the rows within 3
/// medians of the last fit, refitted until the rows kept no longer change (at most
/// `ROBUST_REFITS` times). `None` when no refit was made.
fn robust_closed_form(
    input: &SetupInput<'_>,
    given_tips: &[usize],
    closed_form: Option<&ClosedForm>,
) -> Option<ClosedForm> {
    let mut robust: Option<ClosedForm> = None;
    let mut kept: Option<Vec<bool>> = None;
    for _ in 0..ROBUST_REFITS {
        let Some(fit) = robust.as_ref().or(closed_form) else {
            break;
        };
        let mut sorted: Vec<f64> = fit.per_row.iter().map(|r| r.2).collect();
        sorted.sort_by(f64::total_cmp);
        let Some(&median) = sorted.get(sorted.len() / 2) else {
            break;
        };
        let keep: Vec<bool> = fit.per_row.iter().map(|r| r.2 <= 3.0 * median).collect();
        // The rows kept last, or every row of the first fit: the fit would be the same.
        if kept
            .as_ref()
            .map_or(keep.iter().all(|k| *k), |kept| *kept == keep)
        {
            break;
        }
        let Some(next) = closed_form_fit(input.robot, input.tables, given_tips, Some(&keep)) else {
            break;
        };
        robust = Some(next);
        kept = Some(keep);
    }
    robust
}

/// One finding per joint that reads one value in every row (`frozen`: joint index and
/// value): an error when `moved` (the residual says the joint did move and nothing else
/// explains it), a warning otherwise.
fn frozen_findings(
    input: &SetupInput<'_>,
    frozen: &[(usize, f64)],
    moved: bool,
    as_given: Residual,
) -> Vec<Finding> {
    let n_rows: usize = input.tables.iter().map(|t| t.rows.len()).sum();
    let mut findings = Vec::new();
    for &(j, value) in frozen {
        let (lo, hi) = input.robot.limits.get(j).copied().unwrap_or((0.0, 0.0));
        let unit = if input.robot.prismatic.get(j) == Some(&true) {
            "m"
        } else {
            "rad"
        };
        let joint = joint_label(input.robot, j);
        let why = if moved {
            ", and the residual says the joint did move"
        } else {
            ", or the joint was held still (then its parameters cannot be identified)"
        };
        let message = format!(
            "joint {joint} reads {value} {unit} in every one of the {n_rows} rows while the \
             description lets it move over [{lo}, {hi}] {unit}: a frozen encoder or a copied \
             column{why}"
        );
        let fix = format!("check the export of the column of {joint}");
        let finding = Finding::new(MistakeClass::FrozenJoint, Severity::of(moved), message, fix);
        findings.push(finding.with_residuals(as_given, None));
    }
    findings
}

/// The finding of a residual no checked mistake explains: where it lies, in the user's files.
fn no_hypothesis_finding(
    input: &SetupInput<'_>,
    per_row: Option<&[(usize, u64, f64)]>,
    as_given: Residual,
    n_results: usize,
) -> Finding {
    // No cause is named: where the residual lies is.
    let names: Vec<String> = input.tables.iter().map(file_name).collect();
    let location = per_row
        .and_then(|rows| residual_location(rows, &names))
        .map_or_else(String::new, |w| format!("; {w}"));
    let message = format!(
        "the nominal model misses the measurements by {} RMS with the instrument and marker \
         frames fitted, more than manufacturing deviations of a real robot produce ({} mm, \
         {:.1}°), and none of the {n_results} checked mistakes explains it{location}: these data \
         do not come from this robot (or the setup is wrong in a way not checked)",
        as_given.text(),
        mm(PLAUSIBLE_FRAMES_ONLY_RMS_M),
        PLAUSIBLE_FRAMES_ONLY_RAD.to_degrees(),
    );
    let fix = "check --device, --tip, the units and the columns of the files";
    Finding::new(MistakeClass::NoHypothesis, Severity::Error, message, fix)
        .with_residuals(as_given, None)
}

/// The setup check of a `hapcal calibrate` or `hapcal diagnose` plan: measurement files
/// (marker positions, poses, distances) of a URDF or a D-H device, a haptic device's logs
/// ([`crate::setup_haptic::check_logs`]) and socket folders of a single tip
/// ([`crate::setup_sockets::check_socket_plan`]); `None` for other data.
///
/// # Errors
/// An unreadable device or file, and as [`check_setup`].
pub fn check_plan(plan: &crate::inputs::Plan) -> Result<Option<SetupReport>> {
    let device = crate::data::load_device(&plan.device, &plan.tip)?;
    if device.has_transmissions() {
        if plan.data.iter().all(|p| p.is_file()) {
            return crate::setup_haptic::check_logs(&device, &plan.data, &plan.units).map(Some);
        }
        return Ok(None);
    }
    if plan.tips.is_empty() && !plan.data.is_empty() && plan.data.iter().all(|p| p.is_dir()) {
        return crate::setup_sockets::check_socket_plan(plan, &device).map(Some);
    }
    let distances = device.cable_encoder.is_none();
    let files: Vec<PathBuf> = (plan.data.iter())
        .filter(|p| measured::is_marker_file(p, distances))
        .cloned()
        .collect();
    if files.is_empty() || plan.data.iter().any(|p| p.is_dir()) {
        return Ok(None);
    }
    let tips: Vec<String> = std::iter::once(plan.tip.clone())
        .chain(plan.tips.iter().cloned())
        .collect();
    let is_urdf = (plan.device.extension()).is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    // The robot the calibration builds: a URDF's read joints off the measured paths load it.
    let robot = crate::data::robot_of(plan, &device)?;
    let read = PlanFiles {
        robot: &robot,
        files: &files,
        tips: &tips,
        plan,
        is_urdf,
    };
    let tables = match load_sample(&files, &robot, &plan.units) {
        Ok(tables) => tables,
        Err(e) => {
            // A tip below the markers' link may need a joint the files have no column for; a
            // column read past its joint's limits is there (a tip above it would leave it out
            // and hide the mistake: a motor-side or counted reading).
            let past_limit = e.root_cause().to_string().contains("is outside");
            let report = (is_urdf && !past_limit)
                .then(|| tip_above(&plan.device, &tips, &files, plan.units.clone()))
                .flatten()
                // A reading past its joint's limits: read again without the limits, so that
                // the finding that put it there (degrees, swapped columns) is named with it.
                .or_else(|| read.past_limits(&e))
                // A length past the readers' ±1000 m: millimetres read as metres, in every
                // marker or in some.
                .or_else(|| read.past_length_range(&e));
            return report.map(Some).ok_or(e);
        }
    };
    check_setup(&read.input(&robot, &tables, plan.units.clone())).map(Some)
}

/// The rows of `files` the check judges, read for `robot` in `units`: every row of a
/// recording of up to [`CHECK_SAMPLE_ROWS`] rows; of a longer one, a sample spread over it,
/// every `s`-th row of each file from its first (the stride of
/// [`crate::fit::ladder_sample`]), read as the files stream, so the check's memory does not
/// grow with the rows. Every row is still read and checked; the rows kept keep their lines,
/// and the same files always give the same sample (the check's rereads in other units line
/// up row for row).
///
/// # Errors
/// As [`crate::data::load_tables`].
fn load_sample(
    files: &[PathBuf],
    robot: &Robot,
    units: &hapcal_io::Units,
) -> Result<Vec<MeasurementTable>> {
    let lengths: Vec<usize> = files.iter().map(|p| hapcal_io::count_log_rows(p)).collect();
    let stride =
        crate::fit::ladder_sample(&lengths, CHECK_SAMPLE_ROWS).map_or(1, |sample| sample.stride);
    Ok(crate::data::load_tables_every(files, robot, units, stride)?.0)
}

/// The measurement files of a plan (`files`, the plan's `tips`, on `robot`, a URDF's when
/// `is_urdf`), as the check reads them again when the reader refuses them.
struct PlanFiles<'a> {
    robot: &'a Robot,
    files: &'a [PathBuf],
    tips: &'a [String],
    plan: &'a crate::inputs::Plan,
    is_urdf: bool,
}

impl PlanFiles<'_> {
    /// The check's input of `tables` read for `robot` in `units`.
    fn input<'b>(
        &'b self,
        robot: &'b Robot,
        tables: &'b [MeasurementTable],
        units: Units,
    ) -> SetupInput<'b> {
        SetupInput {
            robot,
            tables,
            urdf: self.is_urdf.then_some(self.plan.device.as_path()),
            tips: self.tips,
            units,
        }
    }

    /// The setup check of files that the reader refused with `limit_error` (a reading past
    /// its joint's limits), read again with every range opened to ±[`OPEN_LIMIT`]: when the
    /// check finds an error (a mistake such as degrees or swapped columns, or data of another
    /// robot), the report with the reader's message (`file:line:column: joint … is outside …`)
    /// at the start of that finding; `None` when the files do not read either or nothing
    /// explains the reading (then the reader's error stands).
    fn past_limits(&self, limit_error: &anyhow::Error) -> Option<SetupReport> {
        let limit = limit_error.root_cause().to_string();
        if !limit.contains("is outside") {
            return None;
        }
        let mut open = self.robot.clone();
        for l in &mut open.limits {
            *l = (-OPEN_LIMIT, OPEN_LIMIT);
        }
        let tables = load_sample(self.files, &open, &self.plan.units).ok()?;
        let mut report = check_setup(&self.input(&open, &tables, self.plan.units.clone())).ok()?;
        let f = (report.findings.iter_mut()).find(|f| f.severity == Severity::Error)?;
        f.message = format!("{limit}: {}", f.message);
        Some(report)
    }

    /// The setup check of files that the reader refused with `range_error` (a length past the
    /// readers' ±1000 m), read again with the refused column's group (a marker's `x, y, z`, or
    /// the distance) in millimetres, group after group until they read: when the data then fit
    /// the robot, one finding names the groups in millimetres and the flag (`--length-unit mm`
    /// when every marker was); when the check of the data so read finds another error, that
    /// report; `None` when they do not read or nothing explains them (the reader's error
    /// stands).
    fn past_length_range(&self, range_error: &anyhow::Error) -> Option<SetupReport> {
        let first = range_error.root_cause().to_string();
        let mut message = first.clone();
        let mut groups: Vec<String> = Vec::new();
        let mut units = self.plan.units.clone();
        let tables = loop {
            if !message.contains("a length must lie within") || groups.len() >= 16 {
                return None;
            }
            // `file:line:column: x2 = 2.2e3 m is out of range: …`.
            let name = message
                .split(" = ")
                .next()?
                .rsplit(": ")
                .next()?
                .trim()
                .to_owned();
            let group = match name.split_at_checked(1) {
                Some(("x" | "y" | "z", k)) if k.chars().all(|c| c.is_ascii_digit()) => {
                    format!("x{k},y{k},z{k}")
                }
                _ => name,
            };
            if groups.contains(&group) {
                return None;
            }
            let edit = hapcal_io::ColumnEdit::parse_unit(&format!("{group}=mm")).ok()?;
            groups.push(group);
            units = units.with_columns([edit]);
            match load_sample(self.files, self.robot, &units) {
                Ok(tables) => break tables,
                Err(e) => message = e.root_cause().to_string(),
            }
        };
        if let Some(report) = self.part_in_millimetres(&tables, &first) {
            return Some(report);
        }
        let report = check_setup(&self.input(self.robot, &tables, units.clone())).ok()?;
        if let Some(f) = report.overwhelming() {
            let mut report = report.clone();
            if let Some(e) = report.findings.iter_mut().find(|x| x.message == f.message) {
                e.message = format!("{first}: {}", e.message);
            }
            return Some(report);
        }
        if !report.as_given.is_plausible() {
            return None;
        }
        let n_markers = tables.iter().map(|t| t.n_markers).max().unwrap_or(0);
        let every_marker =
            groups.len() >= n_markers.max(1) && groups.iter().all(|g| g.contains(','));
        let fix = if every_marker {
            "--length-unit mm".to_owned()
        } else {
            (groups.iter())
                .map(|g| format!("--column-unit {g}=mm"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let message = format!(
            "{first}: the columns {} are in millimetres, read as metres (read in millimetres, \
             the data fit this robot)",
            groups.join(" and ")
        );
        let finding = Finding::new(MistakeClass::LengthUnit, Severity::Error, message, fix);
        Some(SetupReport::of_unread(
            report.n_rows,
            finding,
            report.as_given,
        ))
    }

    /// Lengths past the reader's range in part of a file ([`PlanFiles::past_length_range`],
    /// whose `tables` read the columns out of range in millimetres; `first` the reader's
    /// message): when the rows split into two parts by the size of their positions
    /// ([`magnitude_split`]) and the smaller part read back in the file's unit makes the data
    /// fit the robot (no error finding, a plausible residual), the answer locates the rows in
    /// millimetres; `None` otherwise.
    fn part_in_millimetres(&self, tables: &[MeasurementTable], first: &str) -> Option<SetupReport> {
        let file_m = self.plan.units.length.to_m();
        let file_name = part_unit_name(file_m)?;
        let mut corrected = tables.to_vec();
        let mut located = Vec::new();
        for (t, table) in tables.iter().enumerate() {
            let Some((large, _)) = magnitude_split(table) else {
                continue;
            };
            let scale = file_m / 1e-3;
            for (i, row) in corrected[t].rows.iter_mut().enumerate() {
                if !large.contains(&i) {
                    for m in &mut row.markers {
                        m.position_m = m.position_m.map(|v| v * scale);
                    }
                }
            }
            located.push(rows_of_file(table, &large));
        }
        if located.is_empty() {
            return None;
        }
        let units = self.plan.units.clone();
        let report = check_setup(&self.input(self.robot, &corrected, units)).ok()?;
        if report.overwhelming().is_some() || !report.as_given.is_plausible() {
            return None;
        }
        let where_ = located.join(" and ");
        let message = format!(
            "{first}: {where_} look like millimetres while the rest are in {file_name} (read \
             so, the data fit this robot)"
        );
        let fix = format!(
            "no flag reads part of a file: convert the positions of {where_} to {file_name} \
             (×{}) or record them again",
            1e-3 / file_m
        );
        let finding = Finding::new(MistakeClass::LengthUnit, Severity::Error, message, fix);
        Some(SetupReport::of_unread(
            report.n_rows,
            finding,
            report.as_given,
        ))
    }
}

/// The `--tip` flags of `tips`, in their order: `--tip a --tip b`.
fn tip_flags(tips: &[String]) -> String {
    let flags: Vec<String> = tips.iter().map(|t| format!("--tip {t}")).collect();
    flags.join(" ")
}

/// When the files do not read with the tips given: the first tip one or two moving joints up
/// the chain with which they read and leave a plausible frames-only residual, as a report of
/// one finding (the tip too low: its joints have no column in the files).
fn tip_above(urdf: &Path, tips: &[String], files: &[PathBuf], units: Units) -> Option<SetupReport> {
    let description = hapcal_io::read_urdf(urdf).ok()?;
    for (t, tip) in tips.iter().enumerate() {
        for (link, steps, _) in tip_candidates(&description, tip) {
            if steps > 0 || tips.contains(&link) {
                continue;
            }
            let mut other_tips = tips.to_vec();
            if let Some(slot) = other_tips.get_mut(t) {
                slot.clone_from(&link);
            }
            let Ok(robot) = measured::robot_from_urdf(urdf, &other_tips) else {
                continue;
            };
            let Ok(tables) = load_sample(files, &robot, &units) else {
                continue;
            };
            let marker_tips: Vec<usize> = (0..other_tips.len()).collect();
            let Some(after) = frames_only_residual(&robot, &tables, &marker_tips) else {
                continue;
            };
            if !after.is_plausible() {
                continue;
            }
            let k = steps.unsigned_abs();
            let joints = if k == 1 { "joint" } else { "joints" };
            let message = format!(
                "the files have no column for the joints between {link} and the tip {tip}: the \
                 markers sit on {link}, {k} moving {joints} above the tip"
            );
            let fix = format!("use {}", tip_flags(&other_tips));
            let finding = Finding::new(MistakeClass::TipLink, Severity::Error, message, fix);
            let n_rows = tables.iter().map(|t| t.rows.len()).sum();
            return Some(SetupReport::of_unread(n_rows, finding, after));
        }
    }
    None
}

/// Largest identified length deviation (m) a real device or robot leaves: link lengths, joint
/// origins and prismatic joint offsets deviate from their drawing by fractions of a millimetre
/// to a few millimetres, up to about a centimetre: the bundled recordings' calibrations with
/// their own descriptions move lengths by at most 1.1 mm on the iiwa 14's sockets, 10.0 mm
/// on the Pandas' (panda_2/back_left alone), 2.6 mm on the simulated humanoid, and the
/// lengths they hold at nominal, fitted, by at most 7.6 mm (TIAGo's arm_5_joint.z); the
/// reference device's deviations are 1 to 2 mm. Variants of one
/// robot differ by more: the LBR iiwa 7 R800's upper arm is 20 mm shorter than the iiwa 14
/// R820's, which its description fitted to the iiwa 14's sockets moves by 20.6 mm
/// (`crates/calibrate/tests/wrong_robot.rs`); a UR5e's links are 18 to 188 mm shorter than
/// a UR10e's.
pub const MANUFACTURING_TOLERANCE_M: f64 = 0.015;

/// Standard deviation (m) within which an identified length is the geometry's own: socket
/// contacts determine the iiwa 14's to 0.43 mm. A length determined no better than this
/// absorbs what the instrument and the markers leave, and is judged against
/// [`ABSORBING_TOLERANCE_M`].
pub const PRECISE_LENGTH_SIGMA_M: f64 = 5e-4;

/// Largest deviation (m) of a length determined no better than [`PRECISE_LENGTH_SIGMA_M`]
/// that a right description leaves: with motion capture, TIAGo's own description moves
/// arm_6_joint.x by +16.2 ± 1.4 mm (11 σ), marker and instrument effects the length absorbs.
pub const ABSORBING_TOLERANCE_M: f64 = 0.025;

/// The tolerance of a length deviation determined to `std` (m): [`MANUFACTURING_TOLERANCE_M`]
/// within [`PRECISE_LENGTH_SIGMA_M`], else [`ABSORBING_TOLERANCE_M`].
pub fn length_tolerance_m(std: f64) -> f64 {
    if std <= PRECISE_LENGTH_SIGMA_M {
        MANUFACTURING_TOLERANCE_M
    } else {
        ABSORBING_TOLERANCE_M
    }
}

/// Standard deviations a length deviation must lie from zero to count after the fit: one
/// determined to a tenth of itself. A large deviation the data hardly determine is the
/// conditioning's (an unmodelled effect such as a latency pulled on a weak direction), not
/// evidence of another device.
pub const DETERMINED_SIGMAS: f64 = 10.0;

/// The another-device finding of data that no hypothesis of a mistake explains: when the
/// geometric calibration of `tables` (at most [`MAX_CHECK_ROWS`] of their rows, markers on
/// `marker_tips`) brings the residual `as_given` to one a real robot leaves, moving link lengths
/// by more than [`MANUFACTURING_TOLERANCE_M`] as [`after_fit`] judges them (identified, or
/// pruned and fitted), the data come from a robot of this structure with other dimensions;
/// `None` otherwise (the fit fails, stays implausible or moves no length that far).
fn another_device(
    robot: &Robot,
    tables: &[MeasurementTable],
    marker_tips: &[usize],
    as_given: &Residual,
) -> Option<Finding> {
    let cfg = MeasuredConfig {
        rung: Some(ModelName::Geometric),
        folds: 2,
        marker_tips: marker_tips.to_vec(),
        ..MeasuredConfig::default()
    };
    let tables = thinned(tables);
    let out = measured::calibrate_measured(robot, &tables, &[], &cfg).ok()?;
    let after = residual_of(&out.model, &tables);
    if !after.is_plausible() {
        return None;
    }
    let id = &out.fitted.identified;
    let parameters: Vec<crate::report::ParamReport> = (id.covariance.free.iter())
        .zip(id.covariance.std())
        .filter(|(i, _)| {
            id.layout.spec(**i).unit == hapcal_identify::Unit::Meter
                && !crate::report::is_frame_param(id.layout.name(**i))
        })
        .map(|(&i, std)| crate::report::ParamReport {
            name: id.layout.name(i).to_owned(),
            value: id.fit.x[i],
            std,
            unit: "m",
        })
        .collect();
    let beyond = lengths_beyond(&parameters, &out.refitted_lengths)?;
    let origins = crate::report::joint_origins(robot.tree.tips());
    let links = beyond.links(&parameters, &out.refitted_lengths, &origins);
    let conclusion = if links.is_empty() {
        "these data come from a robot of this structure with other dimensions, or the \
         description is not the one measured"
            .to_owned()
    } else {
        format!(
            "these data come from another robot or variant: {}",
            links.join("; ")
        )
    };
    let message = format!(
        "the nominal model misses the measurements by {} RMS with the instrument and marker \
         frames fitted, and no checked mistake explains it; the geometric calibration fits \
         them to {} RMS by moving {}: {conclusion}",
        as_given.text(),
        after.text(),
        beyond.words(),
    );
    let fix = "calibrate with the robot's own description (--device), and check --tip";
    let finding = Finding::new(MistakeClass::AnotherDevice, Severity::Error, message, fix);
    Some(finding.with_residuals(*as_given, Some(after)))
}

/// The setup check after a calibration: an identified length deviation beyond
/// [`MANUFACTURING_TOLERANCE_M`], determined to [`DETERMINED_SIGMAS`], a length the
/// calibration held at nominal (pruned as not identifiable) that a fit of the held lengths
/// moves that far, determined to [`HELD_DETERMINED_SIGMAS`]
/// ([`crate::report::CalibrationReport::refitted_lengths`]), or a training set the
/// calibrated model still misses by more than [`PLAUSIBLE_FRAMES_ONLY_RMS_M`], says the data
/// come from another device or robot (or a mistake the check before the fit could not tell),
/// an error finding; `None` otherwise. For a URDF the finding names the links that differ
/// at the joints whose origins end them, and by how much. An estimate no real robot can have
/// ([`crate::report::CalibrationReport::implausible`]) is an error finding too: an
/// unconverged fit before everything, negative compliances (named as a mounting when another
/// direction of gravity explains them) and a marker frame metres from its link after the
/// lengths of another robot (whose compliances absorb what the lengths leave). The size of
/// compliances, frames and angles is not judged otherwise: it depends on the setup.
///
/// `before` holds the classes of the findings the check before the fit warned of: after a
/// latency warning, lengths beyond tolerance are what a calibration that does not model the
/// lag makes of it (the lengths absorb it), a latency warning that says so.
pub fn after_fit(
    report: &crate::report::CalibrationReport,
    before: &[MistakeClass],
) -> Option<Finding> {
    use crate::report::ImplausibleKind;
    let implausible = |i: &crate::report::Implausible| {
        let class = match i.kind {
            ImplausibleKind::Mounting => MistakeClass::Mounting,
            _ => MistakeClass::ImplausibleEstimate,
        };
        Finding::new(class, Severity::Error, i.message.clone(), i.fix.clone())
    };
    // An unconverged estimate first (nothing else about it means anything), then lengths of
    // another robot (its compliances absorb what the lengths leave), then the rest.
    let unconverged = (report.implausible.iter()).find(|i| i.kind == ImplausibleKind::Unconverged);
    if let Some(i) = unconverged {
        return Some(implausible(i));
    }
    let Some(beyond) = lengths_beyond_tolerance(report) else {
        return (report.implausible.first().map(implausible))
            .or_else(|| misfit_after_calibration(report));
    };
    if before.contains(&MistakeClass::Latency) {
        if let Some(i) = report.implausible.first() {
            return Some(implausible(i));
        }
        let message = format!(
            "the calibration moves {}, as a lag between the joint readings and the instrument \
             makes a calibration that does not model it do (the latency warned above)",
            beyond.words()
        );
        let fix = "correct the lag before using the calibrated lengths (hapcal diagnose models \
                   latency)";
        return Some(Finding::new(
            MistakeClass::Latency,
            Severity::Warning,
            message,
            fix,
        ));
    }
    Some(lengths_finding(report, &beyond))
}

/// The another-device finding of the lengths `beyond` of `report` (the check after the fit's).
fn lengths_finding(
    report: &crate::report::CalibrationReport,
    beyond: &LengthsBeyond<'_>,
) -> Finding {
    let links = beyond.links(
        &report.parameters,
        &report.refitted_lengths,
        &report.origins,
    );
    let (message, fix) = if links.is_empty() {
        (
            format!(
                "the calibration moves {}: these data come from another device or robot, or the \
                 device file is not the one measured",
                beyond.words()
            ),
            "check --device (and --tip) against the device that recorded the data",
        )
    } else {
        (
            format!(
                "these data come from another robot or variant: {}; the calibration moves {}",
                links.join("; "),
                beyond.words()
            ),
            "calibrate with the robot's own URDF (--device), and check --tip",
        )
    };
    Finding::new(MistakeClass::AnotherDevice, Severity::Error, message, fix)
}

/// The training set the calibrated model misses by more than [`PLAUSIBLE_FRAMES_ONLY_RMS_M`]
/// RMS (the residual the nominal model of a real robot leaves with its frames fitted): the
/// calibration could not explain the data, an another-device finding (the identification
/// may have kept no parameter at all when the nominal model starts that far off); `None` when
/// every training set is fitted closer.
fn misfit_after_calibration(report: &crate::report::CalibrationReport) -> Option<Finding> {
    let (name, rms) = (report.placements.iter())
        .filter(|s| s.role == crate::report::SetRole::Train)
        .filter_map(|s| {
            let a = &s.after;
            let rms = [a.distance_rms_m, a.pose.map(|p| p.position_rms_m)]
                .into_iter()
                .flatten()
                .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))?;
            Some((s.name.as_str(), rms))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let message = format!(
        "the calibrated {} model still misses the training rows of {name} by {} mm RMS, more \
         than the nominal model of a real device leaves ({} mm): these data come from another \
         device or robot, or the setup is wrong in a way not checked",
        report.model,
        mm(rms),
        mm(PLAUSIBLE_FRAMES_ONLY_RMS_M)
    );
    let fix = "check --device (and --tip) against the device that recorded the data, and the \
               units and columns of the files";
    (rms > PLAUSIBLE_FRAMES_ONLY_RMS_M)
        .then(|| Finding::new(MistakeClass::AnotherDevice, Severity::Error, message, fix))
}

/// The length deviations of [`after_fit`] (none: `None`): the identified ones beyond
/// [`MANUFACTURING_TOLERANCE_M`] and determined to [`DETERMINED_SIGMAS`] or, when the
/// calibration held lengths at nominal (pruned, or not in its model) and a fit of them moves
/// one that far, determined to [`HELD_DETERMINED_SIGMAS`] in that fit, every length of the
/// fit that far ([`crate::report::CalibrationReport::refitted_lengths`]; not when the
/// calibrated model still misses the training rows, [`misfit_after_calibration`]).
fn lengths_beyond_tolerance(
    report: &crate::report::CalibrationReport,
) -> Option<LengthsBeyond<'_>> {
    // A model that still misses the training rows by more than a real robot's nominal one
    // leaves is too far from the data for one linear step: its refit means nothing.
    let refitted = if misfit_after_calibration(report).is_some() {
        &[][..]
    } else {
        &report.refitted_lengths[..]
    };
    lengths_beyond(&report.parameters, refitted)
}

/// [`lengths_beyond_tolerance`] of the identified deviations `parameters` and the lengths
/// `refitted` after a fit of those held at nominal.
fn lengths_beyond<'a>(
    parameters: &'a [crate::report::ParamReport],
    refitted: &'a [crate::report::ParamReport],
) -> Option<LengthsBeyond<'a>> {
    let beyond = |sigmas: f64| {
        move |p: &&crate::report::ParamReport| {
            p.unit == "m"
                && p.value.abs() > length_tolerance_m(p.std)
                && p.value.abs() > sigmas * p.std
        }
    };
    // A held length is determined to centimetres: it is beyond tolerance only when its whole
    // confidence interval is, |δ| − k·σ > tolerance (a right robot's length lies within
    // tolerance; k Bonferroni's, as for the distance from zero).
    let held_beyond = |p: &&crate::report::ParamReport| {
        p.unit == "m" && p.value.abs() - HELD_DETERMINED_SIGMAS * p.std > length_tolerance_m(p.std)
    };
    let is_held = |p: &crate::report::ParamReport| !parameters.iter().any(|q| q.name == p.name);
    let mut refit: Vec<&crate::report::ParamReport> =
        (refitted.iter()).filter(held_beyond).collect();
    // Only a held length beyond tolerance makes the refit the evidence.
    if !refit.iter().any(|p| is_held(p)) {
        refit.clear();
    }
    let refit_given = !refit.is_empty();
    let listed = if refit_given {
        refit
    } else {
        parameters
            .iter()
            .filter(beyond(DETERMINED_SIGMAS))
            .collect()
    };
    let worst = *(listed.iter()).max_by(|a, b| a.value.abs().total_cmp(&b.value.abs()))?;
    Some(LengthsBeyond {
        listed,
        refit: refit_given,
        worst,
    })
}

/// Standard deviations a length the calibration held at nominal must lie beyond the
/// manufacturing tolerance (its value less this many σ beyond [`length_tolerance_m`]) when the
/// held lengths are fitted ([`after_fit`]): a two-sided normal tail of
/// 6.3·10⁻⁵ per length, so that noise alone stops a right calibration holding 16 lengths once
/// in a thousand (Bonferroni). Held lengths are the ones the data determine worst, to
/// centimetres: the UR5e description of the UR10e recording moves the upper arm by
/// 189 ± 37 mm, 5.2 σ, where the right description's largest move is 20 ± 18 mm and its
/// largest in σ 1.9 σ. Systematic errors are no noise: over the bundled recordings' right
/// descriptions the held lengths lie up to 2.6 σ from zero, and TIAGo's arm_5_joint.z at
/// 7.6 ± 0.9 mm (8.6 σ; its frames-only model keeps no length), which only
/// [`MANUFACTURING_TOLERANCE_M`] tells from another robot. A recording thinned to a third of
/// TIAGo's (8 training rows) moves arm_6_joint.y by 50.3 ± 12.0 mm: 4.2 σ from zero, but its
/// interval reaches within tolerance, so it is no finding.
pub const HELD_DETERMINED_SIGMAS: f64 = 4.0;

/// Length deviations beyond manufacturing tolerance.
struct LengthsBeyond<'a> {
    /// The identified ones in the report's order or, after a fit of the held lengths, every
    /// length of that fit beyond tolerance, the held first (at least one).
    listed: Vec<&'a crate::report::ParamReport>,
    /// Whether `listed` comes from the fit of the held lengths.
    refit: bool,
    /// The largest in size.
    worst: &'a crate::report::ParamReport,
}

impl LengthsBeyond<'_> {
    /// "3 lengths by more than the 25 mm a real device's manufacturing leaves (d2 +58.1 mm,
    /// …; the largest, d2, 40 standard deviations from zero)"; after a fit of the held
    /// lengths, each with its σ and the words "once the lengths it held at nominal are fitted".
    fn words(&self) -> String {
        let (listed, worst) = (&self.listed, self.worst);
        let n = listed.len();
        let shown: Vec<String> = (listed.iter().take(4))
            .map(|p| {
                if self.refit {
                    format!("{} {:+.1} ± {:.1} mm", p.name, p.value * 1e3, p.std * 1e3)
                } else {
                    format!("{} {:+.1} mm", p.name, p.value * 1e3)
                }
            })
            .collect();
        let more = if n > 4 { ", …" } else { "" };
        format!(
            "{n} length{} by more than the {:.0} mm a real device's manufacturing leaves{} \
             ({}{more}; the largest, {}, {:.1} standard deviations from zero)",
            if n == 1 { "" } else { "s" },
            length_tolerance_m(worst.std) * 1e3,
            if self.refit {
                " once the lengths it held at nominal (pruned as not identifiable) are fitted"
            } else {
                ""
            },
            shown.join(", "),
            worst.name,
            (worst.value / worst.std.max(f64::MIN_POSITIVE)).abs()
        )
    }

    /// The links of the URDF joints whose lengths are beyond tolerance, in words ("the link
    /// after elbow_joint (the origin of wrist_1_joint) is about 183 mm longer"), the joints in
    /// the order of `origins` ([`crate::report::CalibrationReport::origins`]): the change of the origin's
    /// length under every length deviation of the joint (identified, or held and fitted), or
    /// how far the origin moves when the length hardly changes; `parameters` and `refitted`
    /// as [`lengths_beyond`] took them (the deviations of the fit the lengths were listed
    /// from). Empty without `origins` (a D-H device).
    fn links(
        &self,
        parameters: &[crate::report::ParamReport],
        refitted: &[crate::report::ParamReport],
        origins: &[crate::report::JointOrigin],
    ) -> Vec<String> {
        let values = if self.refit { refitted } else { parameters };
        let value = |name: &str| {
            (values.iter())
                .find(|p| p.name == name && p.unit == "m")
                .map_or(0.0, |p| p.value)
        };
        (origins.iter())
            .filter(|o| {
                (self.listed.iter())
                    .any(|p| p.name.rsplit_once('.').is_some_and(|(j, _)| j == o.joint))
            })
            .map(|o| {
                let nominal = Vector3::from(o.origin_m);
                let delta =
                    Vector3::from(["x", "y", "z"].map(|a| value(&format!("{}.{a}", o.joint))));
                let change = (nominal + delta).norm() - nominal.norm();
                let link = match &o.after {
                    Some(after) => format!("the link after {after} (the origin of {})", o.joint),
                    None => format!("the link from the root to {}", o.joint),
                };
                if change.abs() > 0.5 * delta.norm() {
                    format!(
                        "{link} is about {:.0} mm {} than the URDF says",
                        change.abs() * 1e3,
                        if change > 0.0 { "longer" } else { "shorter" }
                    )
                } else {
                    format!(
                        "{link} ends about {:.0} mm from where the URDF puts it",
                        delta.norm() * 1e3
                    )
                }
            })
            .collect()
    }
}

/// [`after_fit`] as the commands apply it (`before` as it takes it, [`Gated::classes`]): the
/// line to print, a warning or an error `cfg` accepts, or the error.
///
/// # Errors
/// A finding without [`SetupConfig::accept_setup`].
pub fn gate_after_fit(
    report: &crate::report::CalibrationReport,
    cfg: &SetupConfig,
    before: &[MistakeClass],
) -> Result<Option<String>> {
    let Some(f) = after_fit(report, before) else {
        return Ok(None);
    };
    if f.severity == Severity::Error && !cfg.accept_setup {
        anyhow::bail!(
            "{}; {} uses the calibration as it is",
            cfg.line(&f, false),
            cfg.accept_option
        );
    }
    Ok(Some(cfg.line(&f, true)))
}

impl SetupConfig {
    /// A finding as the commands print it, `setup check [class]: …`, with the words
    /// `(accepted with --accept-setup)` when `accepted` and it is an error.
    fn line(&self, f: &Finding, accepted: bool) -> String {
        let accepted = if accepted && f.severity == Severity::Error {
            format!(" (accepted with {})", self.accept_option)
        } else {
            String::new()
        };
        format!("setup check{accepted} [{}]: {}", f.class, f.text())
    }
}

/// What the setup check at the start of a calibration or diagnosis lets through.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gated {
    /// The findings as warnings to print, errors first.
    pub warnings: Vec<String>,
    /// The error finding the user accepted with [`SetupConfig::accept_setup`], if any, in the
    /// words of the notes (`setup check (accepted with --accept-setup) [class]: …`): a
    /// diagnosis then names no physical effect and says why.
    pub accepted: Option<String>,
    /// The classes of every finding, in the order of [`Gated::warnings`]: what the check after
    /// the fit ([`gate_after_fit`]) weighs its own finding against.
    pub classes: Vec<MistakeClass>,
}

/// The setup check at the start of a calibration or diagnosis: the warnings to print and the
/// error finding accepted, or an error naming the mistake, its fix and the residual before →
/// after when a finding is overwhelming and `cfg` does not accept the data (then they are
/// warnings too).
///
/// A check that cannot run (an unreadable file, a failed fit) says nothing: the calibration
/// reports the same problem in its own words.
///
/// # Errors
/// An overwhelming finding without [`SetupConfig::accept_setup`].
pub fn gate(plan: &crate::inputs::Plan, cfg: &SetupConfig) -> Result<Gated> {
    let Ok(Some(report)) = check_plan(plan) else {
        return Ok(Gated::default());
    };
    if let Some(f) = report.overwhelming()
        && !cfg.accept_setup
    {
        anyhow::bail!(
            "{}; {} uses the data as they are",
            cfg.line(f, false),
            cfg.accept_option
        );
    }
    Ok(Gated {
        warnings: (report.findings.iter())
            .map(|f| cfg.line(f, true))
            .collect(),
        accepted: report.overwhelming().map(|f| cfg.line(f, true)),
        classes: report.findings.iter().map(|f| f.class).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ur10() -> (Robot, Vec<MeasurementTable>) {
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let robot = measured::robot_from_urdf(
            &root.join("figaroh/ur10/ur10_robot.urdf"),
            &["wrist_3_link".to_owned()],
        )
        .expect("the UR10 URDF");
        let tables = load_sample(
            &[root.join("figaroh/ur10/calibration.csv")],
            &robot,
            &Units::default(),
        )
        .expect("the UR10 recording");
        (robot, tables)
    }

    #[test]
    fn a_description_with_shorter_links_is_another_device() {
        // The UR10's recording against its description with the upper arm and forearm 150 mm
        // shorter: no mistake of the data explains the residual (53 mm, 1.8° with the frames
        // fitted), a geometric calibration brings it to what a real robot leaves by moving
        // lengths far beyond the recording's own deviations of a few millimetres. (Its 23
        // configurations cannot tell which lengths: the ones named are those identifiable.)
        let (_, tables) = ur10();
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let text = std::fs::read_to_string(root.join("figaroh/ur10/ur10_robot.urdf"))
            .expect("the UR10 URDF");
        let shorter = text
            .replace("xyz=\"-0.6127 0 0\"", "xyz=\"-0.4627 0 0\"")
            .replace("xyz=\"-0.57155 0 0.17415\"", "xyz=\"-0.42155 0 0.17415\"");
        assert_ne!(shorter, text);
        let dir = std::env::temp_dir().join(format!("hapcal-shorter-ur10-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a scratch directory");
        let urdf = dir.join("ur10_shorter.urdf");
        std::fs::write(&urdf, shorter).expect("the shorter URDF");
        let tips = ["wrist_3_link".to_owned()];
        let robot = measured::robot_from_urdf(&urdf, &tips).expect("the shorter URDF");
        let report = check_setup(&SetupInput {
            robot: &robot,
            tables: &tables,
            urdf: Some(&urdf),
            tips: &tips,
            units: Units::default(),
        })
        .expect("the check runs");
        let _ = std::fs::remove_dir_all(&dir);
        let f = report.overwhelming().expect("an error finding");
        assert_eq!(f.class, MistakeClass::AnotherDevice, "{}", f.text());
        let after = f.after.expect("the geometric fit's residual");
        assert!(after.is_plausible(), "{}", f.text());
        assert!(
            after
                .length_rms_m
                .is_some_and(|a| a < 0.2 * f.before.length_rms_m.unwrap_or(0.0)),
            "{}",
            f.text()
        );
    }

    #[test]
    fn the_measurement_check_generates_every_family_of_its_kind() {
        let (robot, mut tables) = ur10();
        // The instrument turned by 0.2 rad and moved by 50 mm from the 13th row on: a step for
        // the change-point family.
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2);
        for m in tables[0]
            .rows
            .iter_mut()
            .skip(12)
            .flat_map(|r| &mut r.markers)
        {
            m.position_m = (turn * Vector3::from(m.position_m) + Vector3::x() * 0.05).into();
            if let Some([w, x, y, z]) = m.rotation {
                let r =
                    turn * UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                m.rotation = Some([r.w, r.i, r.j, r.k]);
            }
        }
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let urdf = root.join("figaroh/ur10/ur10_robot.urdf");
        let tips = ["wrist_3_link".to_owned()];
        let input = SetupInput {
            robot: &robot,
            tables: &tables,
            urdf: Some(&urdf),
            tips: &tips,
            units: Units::default(),
        };
        // Per-row residuals that jump after row 16, one row far off: both row families.
        let per_row: Vec<(usize, u64, f64)> = (tables[0].rows.iter().enumerate())
            .map(|(i, r)| {
                (
                    0,
                    r.line,
                    [1e-3, 1e-2, 1.0][usize::from(i >= 16) + usize::from(i == 22)],
                )
            })
            .collect();
        let given = MeasuredData::tables(tables.clone());
        let as_given = closed_form_residual(&robot, &tables, &[0]).expect("marker data");
        let screen = |d: &MeasuredData| closed_form_residual(&robot, &d.tables, &[0]);
        let hypotheses = measurement_hypotheses(
            &input,
            (&given, &as_given),
            Some(&screen),
            None,
            Some(&per_row),
        );
        crate::setup_families::assert_families(
            crate::setup_families::DataKind::MeasurementFiles,
            &hypotheses,
            &[
                MistakeClass::RowMismatch,
                MistakeClass::ColumnUnit,
                MistakeClass::ColumnZero,
                MistakeClass::ChangePoint,
                MistakeClass::ColumnScale,
            ],
        );
    }

    #[test]
    fn closed_form_screening_reaches_the_full_frames_only_fit() {
        // Both minimise Σ|e_p|²/σ_p² + θ²/σ_θ² over the frames at σ_p = 1 mm, σ_θ = 0.01 rad;
        // they differ by how far each converged, a fraction of a per cent.
        let (robot, tables) = ur10();
        let closed = closed_form_residual(&robot, &tables, &[0]).expect("marker data");
        let full = frames_only_residual(&robot, &tables, &[0]).expect("a fit");
        let (c, f) = (
            closed.length_rms_m.expect("positions"),
            full.length_rms_m.expect("positions"),
        );
        assert!((c - f).abs() <= 0.01 * f, "{c} vs {f}");
        let (c, f) = (
            closed.orientation_rms_rad.expect("poses"),
            full.orientation_rms_rad.expect("poses"),
        );
        assert!((c - f).abs() <= 0.01 * f, "{c} vs {f}");
    }

    #[test]
    fn every_reflection_of_the_positions_leaves_the_same_residual() {
        // diag(−1, 1, 1) and the swap of x and z differ by a rotation, which the instrument
        // and marker frames take up: the residuals agree to the fit's convergence.
        let (robot, tables) = ur10();
        let mut mirror = nalgebra::Matrix3::identity();
        mirror[(0, 0)] = -1.0;
        let mut swap = nalgebra::Matrix3::zeros();
        swap[(0, 2)] = 1.0;
        swap[(2, 0)] = 1.0;
        swap[(1, 1)] = 1.0;
        let a = closed_form_residual(&robot, &reflect(&tables, &mirror), &[0]).expect("a fit");
        let b = closed_form_residual(&robot, &reflect(&tables, &swap), &[0]).expect("a fit");
        let given = closed_form_residual(&robot, &tables, &[0]).expect("a fit");
        let (la, lb) = (a.length_rms_m.expect("m"), b.length_rms_m.expect("m"));
        assert!((la - lb).abs() <= 1e-3 * la, "{la} vs {lb}");
        // And a reflection is no rotation: far worse than the data as given.
        assert!(la > 3.0 * given.length_rms_m.expect("m"), "{la}");
    }

    #[test]
    fn thinning_keeps_evenly_spaced_rows_up_to_the_cap() {
        let (_, tables) = ur10();
        let mut long = tables.clone();
        let rows = long[0].rows.clone();
        while long[0].rows.len() < 3 * MAX_CHECK_ROWS {
            long[0].rows.extend(rows.iter().cloned());
        }
        let n = long[0].rows.len();
        let thin = thinned(&long);
        assert_eq!(thin[0].rows.len(), MAX_CHECK_ROWS.min(n));
        assert_eq!(thinned(&tables)[0].rows.len(), tables[0].rows.len());
    }
}
