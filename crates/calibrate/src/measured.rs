//! Calibration from what users measure: marker positions (laser tracker, motion capture) and
//! marker poses (a camera seeing a target), in the instrument's own frame, of one or more
//! markers on one or more tips of a URDF tree or a D-H chain.
//!
//! The instrument-to-base transform and each marker's frame on its link are unknown and
//! identified with the kinematics ([`Tree::with_frames`]). The model is chosen on a ladder, as
//! published calibrations report it (Nubiola & Bonev 2013, "Absolute calibration of an ABB IRB
//! 1600 robot using a laser tracker", RCIM 29(1); figaroh's `calib_level`):
//!
//! 1. **frames only**: the nominal kinematics, only the instrument and marker frames fitted;
//! 2. **joint offsets**: plus one offset per joint;
//! 3. **geometric**: every kinematic parameter the data determine (identifiability pruning);
//! 4. **compliance**: plus a gravity compliance per joint (torques from the URDF's
//!    `<inertial>` masses when it has them, lumped weights otherwise; for a robot with
//!    published link masses, mass-compliance and actuator-compliance as alternatives);
//! 5. **transversal compliance**: plus the bending of each revolute joint's frame.
//!
//! Blocked cross-validation on the training rows (contiguous blocks in file order, the
//! blocked standard error of the socket workflow) scores each rung by its held-out weighted
//! squared error, `|e_p|²/σ_p² + θ²/σ_θ²` per marker (the fit's own objective, so that pose
//! data are judged on orientation too), and climbs the ladder only while a rung beats the one
//! chosen so far by [`crate::model::LADDER_SIGNIFICANCE_Z`] standard errors of the held-out difference; a
//! calibration that does not beat frames only on held-out rows keeps the nominal kinematics,
//! and the report says so.

use crate::model::ModelName;
use anyhow::{Context, Result, bail};
use faer::{Col, Mat, MatRef};
use hapcal_contract::ValueName;
use hapcal_identify::{Identified, Problem, Subset, identify};
use hapcal_io::{MeasuredRow, MeasurementTable};
use hapcal_kinematics::{FrameSpec, Isometry3, Point3, Tree, UnitQuaternion, Vector3};
use hapcal_problems::{
    CalibratedModel, CalibrationProblem, ModelTerms, Observations, Row, RowKind, Weights,
};
use std::sync::Arc;

pub use crate::data::{
    Robot, is_marker_file, load_tables, robot_from_device, robot_from_urdf,
    workspace_configurations,
};
use crate::fit::{CV_REPEATS, Fold, HeldOut, REFIT_MAX_ENTRIES, blocked_difference};
use crate::model::{DataKind, ModelRules};
pub use crate::noise::{CALIBRATED_SIGMA_RATIO, PLAUSIBLE_FRAMES_ONLY_RMS_M};
use crate::record::deviation;
use crate::report::SetRole;
use crate::report::UNCONVERGED_RUNG_NOTE;
pub use crate::report::{
    Beyond, Coverage, CoverageSide, Downweighted, FrameReport, PoseFigures, RangeFold, RangeStop,
    RungReport, SampleErrors,
};

/// The instrument frame and the markers' frames with their tips.
type Frames = (FrameSpec, Vec<(usize, FrameSpec)>);

/// Settings of [`calibrate_measured`].
#[derive(Clone, Debug)]
pub struct MeasuredConfig {
    /// The rung to fit, or `None` to choose by cross-validation.
    pub rung: Option<ModelName>,
    /// Cross-validation folds (contiguous blocks of rows in file order).
    pub folds: usize,
    /// Position noise σ, m, if known; else estimated from the frames-only residuals.
    pub sigma_m: Option<f64>,
    /// Orientation noise σ, rad, if known; else estimated from the frames-only residuals.
    pub sigma_rad: Option<f64>,
    /// Tip (index into the tree's tips) of each marker; markers past its end sit on the last
    /// tip.
    pub marker_tips: Vec<usize>,
    /// Joint configurations where the calibration will be used (rad, m for a prismatic
    /// joint; each of the robot's joint count), besides the test rows: the ladder judges
    /// extrapolation on the joint-range folds on whose side of the training range they lie.
    pub workspace: Vec<Vec<f64>>,
    /// Most residual evaluations of each rung's least-squares fit on every training row
    /// (`None`: the solver's default, [`hapcal_identify::LmConfig::default`]). A fit that
    /// reaches it did not converge: `--model auto` leaves its rung out of the ladder, and a
    /// rung given is a finding ([`MeasuredOutcome::implausible`]).
    pub max_evaluations: Option<usize>,
}

impl Default for MeasuredConfig {
    /// Choose the rung by [`crate::fit::DEFAULT_FOLDS`]-fold cross-validation, σ estimated from the
    /// frames-only residuals, every marker on the first tip, no workspace besides the test
    /// rows, the solver's own evaluation limit.
    fn default() -> Self {
        Self {
            rung: None,
            folds: crate::fit::DEFAULT_FOLDS,
            sigma_m: None,
            sigma_rad: None,
            marker_tips: Vec::new(),
            workspace: Vec::new(),
            max_evaluations: None,
        }
    }
}

/// Everything the measured workflow found.
#[derive(Clone, Debug)]
pub struct MeasuredOutcome {
    /// The chosen rung.
    pub rung: ModelName,
    /// Cross-validation scores, simplest rung first (empty when the rung was given).
    pub ladder: Vec<RungReport>,
    /// The training rows the ladder judged, when it judged a sample spread over more than
    /// [`crate::fit::LADDER_ROWS`] of them ([`crate::fit::ladder_sample`]); `None` when it
    /// judged every row or the rung was given.
    pub cross_validated_rows: Option<usize>,
    /// Final identification of the chosen rung on all training rows.
    pub fitted: Fitted,
    /// The frames-only identification on all training rows (the reference of every figure).
    pub frames_only: Fitted,
    /// The calibrated model (tree with frames, compliance if chosen).
    pub model: CalibratedModel,
    /// Identified frames.
    pub frames: Vec<FrameReport>,
    /// The tree the problems are built on: the robot with joint offsets, behind the instrument
    /// frame, with a marker frame on each tip ([`Tree::with_frames`]); `fitted.x` is in its
    /// layout.
    pub tree: Tree,
    /// Per data set (training first): name, role, rows, frames-only and calibrated figures.
    pub sets: Vec<(String, SetRole, usize, PoseFigures, PoseFigures)>,
    /// Per data set (the order of `sets`), the errors of every sample.
    pub sample_errors: Vec<SampleErrors>,
    /// Position σ (m) and orientation σ (rad) that weight the rows.
    pub weights: Weights,
    /// The joint-range folds the ladder judged extrapolation by: the sides of the joints'
    /// training ranges that test or workspace configurations lie beyond (empty when none does
    /// or the rung was given).
    pub range_folds: Vec<RangeFold>,
    /// Each joint's training range (rad, m for a prismatic joint), chain order.
    pub training_ranges: Vec<(f64, f64)>,
    /// With workspace configurations or test rows: where they lie beyond the training
    /// ranges, and what the model choice did about it.
    pub coverage: Option<Coverage>,
    /// Training samples the Huber loss bounded, file order.
    pub downweighted: Vec<Downweighted>,
    /// With compliance: how far one more fixed-point step of the torque equilibrium would
    /// move the tips, at most over the training rows, m
    /// ([`CalibratedModel::equilibrium_step_m`]).
    pub equilibrium_step_m: Option<f64>,
    /// Refits with the loads at the torque equilibrium (docs/engine.md); 0 when the loads of
    /// the undeflected robot were close enough.
    pub equilibrium_refits: usize,
    /// Plain-language warnings.
    pub warnings: Vec<String>,
    /// Estimates no real robot can have, each with its cause and fix (checked after the fit):
    /// never a result (`hapcal calibrate` stops on the first).
    pub implausible: Vec<crate::report::Implausible>,
    /// The robot's lengths after a least-squares fit, at the estimate, of those the chosen
    /// rung held at their nominal values (pruned, or not free in it): deviation from nominal
    /// (m) and σ (m) in that fit, the held lengths first
    /// ([`crate::report::CalibrationReport::refitted_lengths`]).
    pub refitted_lengths: Vec<crate::report::ParamReport>,
}

/// The rigid transform `T` minimising `Σ |T·a_i − b_i|²` (Kabsch 1976; Horn 1987, "Closed-form
/// solution of absolute orientation using unit quaternions", JOSA A 4(4)), by the SVD of the
/// cross-covariance; identity for fewer than 3 points.
pub fn kabsch(a: &[Point3<f64>], b: &[Point3<f64>]) -> Isometry3<f64> {
    let n = a.len().min(b.len());
    if n < 3 {
        return Isometry3::identity();
    }
    let ca = a.iter().take(n).fold(Vector3::zeros(), |s, p| s + p.coords) / n as f64;
    let cb = b.iter().take(n).fold(Vector3::zeros(), |s, p| s + p.coords) / n as f64;
    let mut h = nalgebra::Matrix3::zeros();
    for (p, q) in a.iter().zip(b).take(n) {
        h += (p.coords - ca) * (q.coords - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Isometry3::identity();
    };
    let mut d = nalgebra::Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = v_t.transpose() * d * u.transpose();
    let rotation = UnitQuaternion::from_matrix(&r);
    let t = cb - rotation * ca;
    Isometry3::from_parts(t.into(), rotation)
}

/// The tip of marker `k`.
fn tip_of(cfg: &MeasuredConfig, tree: &Tree, k: usize) -> usize {
    let last = tree.tips().len().saturating_sub(1);
    cfg.marker_tips.get(k).copied().unwrap_or(last).min(last)
}

/// Number of markers over the tables.
fn n_markers(tables: &[MeasurementTable]) -> usize {
    let distances = tables.iter().any(|t| t.has_distance);
    (tables.iter().map(|t| t.n_markers).max().unwrap_or(0)).max(usize::from(distances))
}

/// The anchor of the distance rows in the robot's base frame, m, by linear multilateration on
/// the nominal tip origins: `|p_i − a|² = d_i²` is linear in `(a, |a|²)` (Manolakis 1996,
/// "Efficient solution and performance analysis of 3-D position estimation by
/// trilateration", IEEE T-AES 32(4)). `None` with fewer than 5 distances or tip origins that
/// do not span the space.
fn anchor(robot: &Robot, tables: &[MeasurementTable]) -> Option<Vector3<f64>> {
    let zero = vec![0.0; robot.tree.n_params()];
    let rows: Vec<(Vector3<f64>, f64)> = (tables.iter().flat_map(|t| &t.rows))
        .filter_map(|r| {
            let d = r.distance_m?;
            Some((
                robot.tree.tips()[0]
                    .end_pose(&zero, &r.q)
                    .translation
                    .vector,
                d,
            ))
        })
        .collect();
    if rows.len() < 5 {
        return None;
    }
    let mut a = nalgebra::DMatrix::<f64>::zeros(rows.len(), 4);
    let mut b = nalgebra::DVector::<f64>::zeros(rows.len());
    for (i, (p, d)) in rows.iter().enumerate() {
        for k in 0..3 {
            a[(i, k)] = 2.0 * p[k];
        }
        a[(i, 3)] = -1.0;
        b[i] = p.norm_squared() - d * d;
    }
    let ata = a.tr_mul(&a);
    let eig = ata.clone().symmetric_eigen();
    let (emin, emax) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    if emax.is_nan() || emax <= 0.0 || emin < 1e-12 * emax {
        return None;
    }
    let x = ata.cholesky()?.solve(&a.tr_mul(&b));
    let anchor = Vector3::new(x[0], x[1], x[2]);
    anchor.iter().all(|v| v.is_finite()).then_some(anchor)
}

/// One marker sample with the nominal pose of its tip in the robot's base frame.
struct Sample {
    marker: usize,
    tip: Isometry3<f64>,
    measured: Point3<f64>,
    rotation: Option<UnitQuaternion<f64>>,
}

/// Marker samples in `tables`: one per marker seen in each row.
fn n_marker_samples(tables: &[MeasurementTable]) -> usize {
    (tables.iter().flat_map(|t| &t.rows))
        .map(|row| row.markers.len())
        .sum()
}

/// The samples of `tables` at the nominal kinematics.
fn samples(robot: &Robot, tables: &[MeasurementTable], cfg: &MeasuredConfig) -> Vec<Sample> {
    let zero = vec![0.0; robot.tree.n_params()];
    let mut out = Vec::with_capacity(n_marker_samples(tables));
    for t in tables {
        for row in &t.rows {
            for m in &row.markers {
                let tip = tip_of(cfg, &robot.tree, m.marker);
                out.push(Sample {
                    marker: m.marker,
                    tip: robot.tree.tips()[tip].end_pose(&zero, &row.q),
                    measured: Point3::from(m.position_m),
                    rotation: m.rotation.map(|[w, x, y, z]| {
                        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
                    }),
                });
            }
        }
    }
    out
}

/// The instrument rotation, translation and marker offsets (m, in the tip frames) in closed
/// form from marker positions at the nominal kinematics: `p_meas = R·(p_tip + R_tip·m_k) + t` is
/// linear in `R` (9 entries, unconstrained), `t` and the 9 products `R[:, j]·m_k[l]` per marker;
/// its least-squares solution's `R` is projected onto SO(3) (the nearest rotation, by SVD),
/// then `t` and the `m_k` solved again with that `R` (the linear relaxation of the hand-eye and
/// robot-world problem, Zhuang, Roth & Sudhakar 1994, "Simultaneous robot/world and tool/flange
/// calibration by solving homogeneous transformation equations of the form AX = YB", IEEE
/// T-RA 10(4)). `None` when the samples do not determine it (too few, or too little rotation
/// of the tips).
fn linear_frames(
    samples: &[Sample],
    n_markers: usize,
) -> Option<(Isometry3<f64>, Vec<Vector3<f64>>)> {
    let n_unknowns = 12 + 27 * n_markers;
    if samples.len() * 3 < n_unknowns + 3 {
        return None;
    }
    // The normal equations, summed over blocks of samples: the system is small (12 + 27 per
    // marker unknowns) and tall, and its rows never all held (a million samples would take
    // gigabytes); an initial guess needs no better than their precision.
    let (ata, atb) = normal_equations(samples, n_unknowns, |s, a, b| {
        let p = s.tip.translation.vector;
        let rt = s.tip.rotation.to_rotation_matrix();
        for r in 0..3 {
            // R[r, c]·p[c]: unknown R stored row-major at 0..9.
            for c in 0..3 {
                a[(r, 3 * r + c)] = p[c];
            }
            a[(r, 9 + r)] = 1.0;
            // Σ_{j,l} R_tip[j, l]·N_{k,j,l}[r], N_{k,j,l} = R[:, j]·m_k[l].
            for j in 0..3 {
                for l in 0..3 {
                    a[(r, 12 + 27 * s.marker + 9 * j + 3 * l + r)] = rt[(j, l)];
                }
            }
            b[r] = s.measured[r];
        }
    });
    // Singular values of A are the square roots of AᵀA's eigenvalues; a ratio below 1e-6 means
    // the samples do not determine the unknowns.
    let eig = ata.clone().symmetric_eigen();
    let (emin, emax) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    if emax.is_nan() || emax <= 0.0 || emin < 1e-12 * emax {
        return None;
    }
    let x = ata.cholesky()?.solve(&atb);
    let r_free = nalgebra::Matrix3::from_row_slice(&x.as_slice()[0..9]);
    let rsvd = r_free.svd(true, true);
    let (u, v_t) = (rsvd.u?, rsvd.v_t?);
    let mut d = nalgebra::Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = nalgebra::Rotation3::from_matrix_unchecked(u * d * v_t);
    // With R fixed: p_meas − R·p_tip = t + R·R_tip·m_k, linear in t and the m_k.
    let (ata2, atb2) = normal_equations(samples, 3 + 3 * n_markers, |s, a, b| {
        let rr = rotation.matrix() * s.tip.rotation.to_rotation_matrix().matrix();
        let rhs = s.measured.coords - rotation * s.tip.translation.vector;
        for r in 0..3 {
            a[(r, r)] = 1.0;
            for c in 0..3 {
                a[(r, 3 + 3 * s.marker + c)] = rr[(r, c)];
            }
            b[r] = rhs[r];
        }
    });
    let y = ata2.cholesky()?.solve(&atb2);
    let t = Vector3::new(y[0], y[1], y[2]);
    let offsets: Vec<Vector3<f64>> = (0..n_markers)
        .map(|k| Vector3::new(y[3 + 3 * k], y[4 + 3 * k], y[5 + 3 * k]))
        .collect();
    let base = Isometry3::from_parts(t.into(), UnitQuaternion::from_rotation_matrix(&rotation));
    offsets_finite(&base, &offsets).then_some((base, offsets))
}

/// Samples per block of [`normal_equations`]: the bundled recordings' few hundred fit in one.
const NORMAL_EQUATION_BLOCK: usize = 20_000;

/// `(AᵀA, Aᵀb)` of the linear system whose three rows per sample `row` writes (into a zeroed
/// `3 × n_unknowns` block of `A` and 3 entries of `b`), summed over blocks of
/// [`NORMAL_EQUATION_BLOCK`] samples: never more than a block's rows held.
fn normal_equations(
    samples: &[Sample],
    n_unknowns: usize,
    row: impl Fn(
        &Sample,
        &mut nalgebra::DMatrixViewMut<'_, f64>,
        &mut nalgebra::DVectorViewMut<'_, f64>,
    ),
) -> (nalgebra::DMatrix<f64>, nalgebra::DVector<f64>) {
    let mut ata = nalgebra::DMatrix::<f64>::zeros(n_unknowns, n_unknowns);
    let mut atb = nalgebra::DVector::<f64>::zeros(n_unknowns);
    for block in samples.chunks(NORMAL_EQUATION_BLOCK) {
        let mut a = nalgebra::DMatrix::<f64>::zeros(3 * block.len(), n_unknowns);
        let mut b = nalgebra::DVector::<f64>::zeros(3 * block.len());
        for (i, s) in block.iter().enumerate() {
            row(s, &mut a.rows_mut(3 * i, 3), &mut b.rows_mut(3 * i, 3));
        }
        ata += a.tr_mul(&a);
        atb += a.tr_mul(&b);
    }
    (ata, atb)
}

/// Whether a closed-form solution is finite (a degenerate system can yield NaN).
fn offsets_finite(base: &Isometry3<f64>, offsets: &[Vector3<f64>]) -> bool {
    base.translation.vector.iter().all(|v| v.is_finite())
        && base.rotation.coords.iter().all(|v| v.is_finite())
        && offsets.iter().all(|o| o.iter().all(|v| v.is_finite()))
}

/// The instrument frame and the marker's frame on its tip in closed form from pose samples of
/// one marker, `M_i = B · T_i · X`: the rotation of `B` aligns the rotation vectors of the
/// relative motions `T_i T_jᵀ` with those of `M_i M_jᵀ` (`A = R_B · B · R_Bᵀ`, Park & Martin
/// 1994, "Robot sensor calibration: solving AX = XB on the Euclidean group", IEEE T-RA 10(5)),
/// the rotation of `X` is the chordal mean of `R_Tᵢᵀ R_Bᵀ R_Mᵢ`, and both translations are
/// linear least squares. `None` without pose samples or without rotation between them.
fn pose_frames(samples: &[Sample], marker: usize) -> Option<(Isometry3<f64>, Isometry3<f64>)> {
    let poses: Vec<(&Sample, UnitQuaternion<f64>)> = samples
        .iter()
        .filter(|s| s.marker == marker)
        .filter_map(|s| s.rotation.map(|r| (s, r)))
        .collect();
    let n = poses.len();
    if n < 3 {
        return None;
    }
    let stride = n.div_ceil(200).max(1);
    let (mut from, mut to) = (Vec::new(), Vec::new());
    for i in (0..n).step_by(stride) {
        for j in (i + 1..n).step_by(stride) {
            let a = poses[i].1 * poses[j].1.inverse();
            let b = poses[i].0.tip.rotation * poses[j].0.tip.rotation.inverse();
            if a.angle() < 1e-3 || b.angle() < 1e-3 {
                continue;
            }
            // Each vector and its negative: a centred set, so Kabsch finds a pure rotation.
            for sign in [1.0, -1.0] {
                from.push(Point3::from(sign * b.scaled_axis()));
                to.push(Point3::from(sign * a.scaled_axis()));
            }
        }
    }
    if from.len() < 4 {
        return None;
    }
    let r_b = kabsch(&from, &to).rotation;
    let mut sum = nalgebra::Vector4::zeros();
    let mut reference: Option<UnitQuaternion<f64>> = None;
    for (s, m) in &poses {
        let rel = (r_b * s.tip.rotation).inverse() * m;
        let r = *reference.get_or_insert(rel);
        sum += if rel.coords.dot(&r.coords) < 0.0 {
            -rel.coords
        } else {
            rel.coords
        };
    }
    let r_x = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum.normalize()));
    // p_M = R_B·(p_T + R_T·t_X) + t_B, linear in (t_B, t_X).
    let mut a = nalgebra::DMatrix::<f64>::zeros(3 * n, 6);
    let mut rhs = nalgebra::DVector::<f64>::zeros(3 * n);
    for (i, (s, _)) in poses.iter().enumerate() {
        let rr = r_b.to_rotation_matrix().matrix() * s.tip.rotation.to_rotation_matrix().matrix();
        let b = s.measured.coords - r_b * s.tip.translation.vector;
        for r in 0..3 {
            a[(3 * i + r, r)] = 1.0;
            for c in 0..3 {
                a[(3 * i + r, 3 + c)] = rr[(r, c)];
            }
            rhs[3 * i + r] = b[r];
        }
    }
    let t = a.svd(true, true).solve(&rhs, 1e-12).ok()?;
    let base = Isometry3::from_parts(Vector3::new(t[0], t[1], t[2]).into(), r_b);
    let frame = Isometry3::from_parts(Vector3::new(t[3], t[4], t[5]).into(), r_x);
    offsets_finite(&base, &[frame.translation.vector]).then_some((base, frame))
}

/// Candidate initial frames: the instrument frame and marker offsets in closed form
/// ([`linear_frames`]) when the samples determine it, and the instrument frame by Kabsch from
/// the nominal tip origins to the measured positions (markers at their tips' origins); each
/// with each marker's rotation by the chordal mean of its measured orientations relative to the
/// nominal tip (pose data). With few rows the closed form follows the noise far from the
/// optimum; [`calibrate_measured`] fits the start with the smallest residual.
fn initial_frames(
    robot: &Robot,
    tables: &[MeasurementTable],
    samples: &[Sample],
    n: usize,
    cfg: &MeasuredConfig,
) -> Vec<Frames> {
    let a: Vec<Point3<f64>> = samples
        .iter()
        .map(|s| Point3::from(s.tip.translation.vector))
        .collect();
    let b: Vec<Point3<f64>> = samples.iter().map(|s| s.measured).collect();
    let mut starts = Vec::new();
    if let Some(linear) = linear_frames(samples, n) {
        starts.push(linear);
    }
    starts.push((kabsch(&a, &b), vec![Vector3::zeros(); n]));
    // Distances alone: the instrument frame's origin at the multilaterated anchor.
    if samples.is_empty()
        && let Some(anchor) = anchor(robot, tables)
    {
        starts.push((
            Isometry3::translation(-anchor.x, -anchor.y, -anchor.z),
            vec![Vector3::zeros(); n],
        ));
    }
    // Pose data: the instrument frame from the first marker's poses, every marker's frame from
    // its own poses seen through it.
    let mut rotations: Vec<Option<UnitQuaternion<f64>>> = vec![None; n];
    if let Some((base, _)) = pose_frames(samples, 0) {
        let offsets = (0..n)
            .map(|k| {
                let frame = pose_frames(samples, k).map(|(_, f)| f);
                rotations[k] = frame.map(|f| f.rotation);
                frame.map_or_else(Vector3::zeros, |f| f.translation.vector)
            })
            .collect();
        starts.push((base, offsets));
    }
    let n_starts = starts.len();
    starts
        .into_iter()
        .enumerate()
        .map(|(i, (base, offsets))| {
            let markers = (0..n)
                .map(|k| {
                    let rotation = rotations[k]
                        .filter(|_| i + 1 == n_starts)
                        .unwrap_or_else(|| mean_marker_rotation(samples, k, &base));
                    (
                        tip_of(cfg, &robot.tree, k),
                        FrameSpec {
                            name: format!("marker{}", k + 1),
                            nominal: Isometry3::from_parts(offsets[k].into(), rotation),
                        },
                    )
                })
                .collect();
            let instrument = FrameSpec {
                name: "instrument".into(),
                nominal: base,
            };
            (instrument, markers)
        })
        .collect()
}

/// Marker `k`'s rotation on its tip: the chordal mean of its measured orientations relative to
/// the nominal tip seen through `base` (identity without orientation data).
fn mean_marker_rotation(
    samples: &[Sample],
    k: usize,
    base: &Isometry3<f64>,
) -> UnitQuaternion<f64> {
    let mut sum = nalgebra::Vector4::zeros();
    let mut reference: Option<UnitQuaternion<f64>> = None;
    for s in samples.iter().filter(|s| s.marker == k) {
        let Some(meas) = s.rotation else { continue };
        let rel = (base.rotation * s.tip.rotation).inverse() * meas;
        // Sign-align quaternions before averaging (q and −q are one rotation).
        let r = *reference.get_or_insert(rel);
        let c = rel.coords;
        sum += if c.dot(&r.coords) < 0.0 { -c } else { c };
    }
    if sum.norm() > 0.0 {
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum / sum.norm()))
    } else {
        UnitQuaternion::identity()
    }
}

/// A marker sample the Huber loss bounded ([`winsorize`]): where it lies in the training
/// tables and the position every fit after the Huber pass sees instead of the measured one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct BoundedSample {
    /// Table, row of the table and sample of the row (index into its `markers`), 0-based.
    pub(crate) at: (usize, usize, usize),
    /// The bounded position in the instrument frame, m.
    pub(crate) position_m: [f64; 3],
}

/// Training tables as the fits see them: the tables as measured, with the marker samples the
/// Huber loss bounded at their bounded positions. Nothing is copied: a row holding a bounded
/// sample is rebuilt when it is read ([`Training::row`]), the others are borrowed.
#[derive(Clone, Copy)]
pub(crate) struct Training<'a> {
    /// The tables as measured.
    pub(crate) tables: &'a [MeasurementTable],
    /// The bounded samples, sorted by place.
    bounded: &'a [BoundedSample],
}

impl<'a> Training<'a> {
    /// `tables` as measured, nothing bounded.
    pub(crate) fn measured(tables: &'a [MeasurementTable]) -> Self {
        Training {
            tables,
            bounded: &[],
        }
    }

    /// `tables` with the samples `bounded` (sorted by place) at their bounded positions.
    fn with_bounded(tables: &'a [MeasurementTable], bounded: &'a [BoundedSample]) -> Self {
        debug_assert!(bounded.is_sorted_by_key(|b| b.at));
        Training { tables, bounded }
    }

    /// Row `ri` of table `ti`, its bounded samples at their bounded positions: borrowed from
    /// the table when none of its samples was bounded.
    pub(crate) fn row(&self, ti: usize, ri: usize) -> std::borrow::Cow<'a, MeasuredRow> {
        let row = &self.tables[ti].rows[ri];
        let first = (self.bounded).partition_point(|b| (b.at.0, b.at.1) < (ti, ri));
        let mut out = std::borrow::Cow::Borrowed(row);
        for b in self.bounded[first..].iter() {
            if (b.at.0, b.at.1) != (ti, ri) {
                break;
            }
            out.to_mut().markers[b.at.2].position_m = b.position_m;
        }
        out
    }

    /// The rows of table `ti` in file order ([`Training::row`]).
    fn rows(&self, ti: usize) -> impl Iterator<Item = std::borrow::Cow<'a, MeasuredRow>> + '_ {
        (0..self.tables[ti].rows.len()).map(move |ri| self.row(ti, ri))
    }
}

/// Observations of the rows of `tables` for which `keep(table, row)` holds: per row its
/// distance (if any), then each marker sample (bounded ones at their bounded positions), in
/// file order.
pub(crate) fn observations(
    tables: Training<'_>,
    keep: &dyn Fn(usize, usize) -> bool,
) -> Observations {
    let kept = || {
        (tables.tables.iter().enumerate())
            .flat_map(|(ti, t)| (0..t.rows.len()).map(move |ri| (ti, ri)))
            .filter(|&(ti, ri)| keep(ti, ri))
    };
    // Counted first: a million rows pushed into a growing vector reserve up to twice their
    // size.
    let n_rows = kept()
        .map(|(ti, ri)| observation_rows(&tables.tables[ti].rows[ri]))
        .sum();
    let mut obs = Observations {
        rows: Vec::with_capacity(n_rows),
        ..Observations::default()
    };
    for (ti, ri) in kept() {
        let row = tables.row(ti, ri);
        if let Some(distance_m) = row.distance_m {
            // From the instrument origin (the anchor) to marker 1's frame.
            obs.rows.push(Row {
                q: row.q.clone(),
                kind: RowKind::Distance { distance_m },
            });
        }
        for m in &row.markers {
            // Tip k of the framed tree is marker k.
            let kind = match m.rotation {
                Some(rotation) => RowKind::Pose {
                    tip: m.marker,
                    position_m: m.position_m,
                    rotation,
                },
                None => RowKind::Marker {
                    tip: m.marker,
                    position_m: m.position_m,
                },
            };
            obs.rows.push(Row {
                q: row.q.clone(),
                kind,
            });
        }
    }
    obs
}

/// The problem's model terms for `rung` ([`crate::model::terms`] with the robot's link masses),
/// the gravity loads taken on every tip of the tree, gravity along the robot's mounting
/// ([`Robot::gravity_dir`]).
///
/// # Errors
/// A published-mass model on a robot without published masses.
pub(crate) fn terms(rung: ModelName, robot: &Robot) -> Result<ModelTerms> {
    let mut terms = crate::model::terms(rung, &robot.joint_names, &robot.masses)?;
    if let Some(c) = terms.compliance.as_mut() {
        c.gravity_dir = robot.gravity_dir;
    }
    Ok(ModelTerms {
        torque_tips: Some(robot.tree.tips().to_vec()),
        ..terms
    })
}

/// The rungs of the measurement files' ladder `robot` carries, simplest first, with each
/// one's level ([`crate::model::ladder_for`]).
fn ladder_of(robot: &Robot) -> (Vec<ModelName>, Vec<usize>) {
    crate::model::ladder_for(
        DataKind::Measurements,
        &robot.joint_names,
        robot.tree.tips(),
    )
}

/// Free parameters of `rung` in the layout of a problem on `framed` (the tree with joint
/// offsets and frames; `offsets` its joint-offset parameters; `n_robot` the robot's own
/// parameter count, after the 6 of the instrument frame); `orientation`: whether marker
/// rotations are observed.
fn free_of(
    rung: ModelName,
    framed: &Tree,
    offsets: &[Option<usize>],
    n_robot: usize,
    orientation: bool,
    n_layout: usize,
) -> Vec<usize> {
    let n_kin = framed.n_params();
    let mut free: Vec<usize> = (0..6).collect();
    // Marker frames: 6 each after the robot's parameters; rotations only with orientation data.
    let mut k = 6 + n_robot;
    while k + 6 <= n_kin {
        free.extend(k..k + 3);
        if orientation {
            free.extend(k + 3..k + 6);
        }
        k += 6;
    }
    let families = rung.families();
    if families.geometric {
        free.extend(6..6 + n_robot);
    } else if families.joint_offsets {
        free.extend(offsets.iter().flatten().map(|&i| i + 6));
    }
    // Compliance (and any other model term) after the kinematic parameters.
    free.extend(n_kin..n_layout);
    free.sort_unstable();
    free.dedup();
    free
}

/// Where every fit starts: the framed tree and a parameter vector in its layout (the frames-only
/// estimate; entries past it, such as compliance, at the problem's initial guess).
struct Start<'a> {
    tree: &'a Tree,
    x: &'a Col<f64>,
    /// The estimate of a rung this one nests ([`nested_in`]): its parameters, by name, replace
    /// `x`'s (a per-axis transversal compliance starts at the isotropic one's value).
    nested: Option<&'a Fitted>,
    /// Most residual evaluations of the fit ([`MeasuredConfig::max_evaluations`]; `None`:
    /// the solver's default).
    max_evaluations: Option<usize>,
}

/// The rung whose model `rung` nests (its parameters a subset of `rung`'s, by name, up to the
/// per-axis transversal compliances, which start at their joint's isotropic one), if the
/// ladder fits `rung` from its estimate: per-axis transversal compliance from the isotropic
/// one (from the frames-only estimate it takes three pruning rounds and twice the
/// iterations on the simulated humanoid). Not `harmonic2` from `harmonic`: that start moves
/// its cross-validated error on the UR10 and TIAGo recordings by 4 to 6 % (another estimate).
fn nested_in(rung: ModelName) -> Option<ModelName> {
    match rung {
        ModelName::TransversalAxes => Some(ModelName::TransversalCompliance),
        _ => None,
    }
}

/// Per rung of `rungs`, the index of the rung it starts from ([`nested_in`]), if the ladder
/// holds it.
fn rung_parents(rungs: &[ModelName]) -> Vec<Option<usize>> {
    (rungs.iter())
        .map(|&r| nested_in(r).and_then(|p| rungs.iter().position(|&q| q == p)))
        .collect()
}

/// The ladder's rungs in chains of nesting ([`nested_in`]; `parent[i]` the rung rung `i` starts
/// from): each chain a rung that nests none, then the rungs that nest it, each after its
/// parent; the longest chains first (their nested fits are the ladder's critical path), ties
/// in ladder order.
fn rung_chains(parent: &[Option<usize>]) -> Vec<Vec<usize>> {
    let mut chains: Vec<Vec<usize>> = Vec::new();
    for root in (0..parent.len()).filter(|&i| parent[i].is_none()) {
        let mut chain = vec![root];
        let mut k = 0;
        while k < chain.len() {
            let at = chain[k];
            chain.extend((0..parent.len()).filter(|&i| parent[i] == Some(at)));
            k += 1;
        }
        chains.push(chain);
    }
    // A stable sort keeps the ladder order among chains of one length.
    chains.sort_by_key(|c| std::cmp::Reverse(c.len()));
    chains
}

/// The rung that heads the ladder's longest chain of nested rungs ([`rung_chains`]), when a
/// rung nests it: its fit on every row starts the ladder's critical path (the per-axis
/// transversal compliance from the isotropic one); `None` when no rung nests another.
fn ladder_head(rungs: &[ModelName]) -> Option<ModelName> {
    let chains = rung_chains(&rung_parents(rungs));
    (chains.first())
        .filter(|c| c.len() > 1)
        .map(|c| rungs[c[0]])
}

/// Fits on every training row done before the ladder, by rung, each the fit the ladder would
/// make itself (the same rows, weights and start): the Huber pass's rung when it bounded
/// nothing, and the rung fitted beside it ([`on_bounded_training`]).
type DoneFits = Vec<(ModelName, (CalibratedModel, Fitted))>;

/// What was worked out before the ladder, each what the ladder would work out itself: fits
/// on every training row ([`DoneFits`]), and whole chains of the ladder's runs ([`Run`]), by
/// rung index ([`on_bounded_training`]).
#[derive(Default)]
struct Done {
    fits: DoneFits,
    runs: Vec<(usize, Run)>,
}

/// The torque equilibrium of the ladder head's fit ([`equilibrate_fit`]) worked out beside
/// the ladder: the rung, the estimate it started from and the result. [`settle`] takes it
/// when the ladder chooses that very fit.
type EarlyEquilibrium = (
    ModelName,
    Col<f64>,
    Result<(CalibratedModel, Fitted, usize)>,
);

/// Fits `rung` on the rows `keep` selects: the problem and its identification (estimates
/// mapped back to the full layout).
fn fit(
    rung: ModelName,
    robot: &Robot,
    start: &Start<'_>,
    offsets: &[Option<usize>],
    tables: Training<'_>,
    weights: Weights,
    keep: &dyn Fn(usize, usize) -> bool,
) -> Result<(CalibratedModel, Fitted)> {
    let obs = observations(tables, keep);
    fit_terms(
        rung,
        terms(rung, robot)?,
        robot,
        start,
        offsets,
        obs,
        weights,
        &|| repeat_std_scale(tables, keep),
    )
}

/// `√(rows / distinct rows)` over the rows of `tables` that `keep` selects, a copy being a
/// row that repeats an earlier row of its table by the reader's repeat key (as
/// [`table_originals`] finds them for the folds): a copy adds residuals but no information,
/// while the least-squares covariance counts it. It scales the identification's σ before
/// the test of whether a compliance is significantly below zero
/// ([`crate::fit::hold_compliances_at_zero`]), so that a recording appended to itself holds
/// the compliances the recording holds. 1 without copies.
fn repeat_std_scale(tables: Training<'_>, keep: &dyn Fn(usize, usize) -> bool) -> f64 {
    let (mut n_rows, mut n_copies) = (0, 0);
    for ti in 0..tables.tables.len() {
        let originals = row_originals(tables, ti, keep);
        n_rows += originals.len();
        n_copies += crate::fit::n_copies(&originals);
    }
    (n_rows as f64 / (n_rows - n_copies).max(1) as f64).sqrt()
}

/// [`fit`] of the observations `obs` with the model terms `terms` (the rung's, with the
/// loads at a torque equilibrium, say); `std_scale` gives [`repeat_std_scale`] of the rows
/// `obs` holds, asked for only when a compliance falls below zero.
#[allow(clippy::too_many_arguments)]
fn fit_terms(
    rung: ModelName,
    terms: ModelTerms,
    robot: &Robot,
    start: &Start<'_>,
    offsets: &[Option<usize>],
    obs: Observations,
    weights: Weights,
    std_scale: &dyn Fn() -> f64,
) -> Result<(CalibratedModel, Fitted)> {
    let framed = start.tree;
    let n_rows = obs.rows.len();
    let orientation = (obs.rows.iter()).any(|r| matches!(r.kind, RowKind::Pose { .. }));
    let problem = CalibrationProblem::on_tree(framed.clone(), obs, weights, terms)
        .context("building the calibration problem")?;
    let n_layout = problem.layout().len();
    let free = free_of(
        rung,
        framed,
        offsets,
        robot.tree.n_params(),
        orientation,
        n_layout,
    );
    let mut x_full = problem.initial_guess();
    for i in 0..start.x.nrows().min(x_full.nrows()) {
        x_full[i] = start.x[i];
    }
    if let Some(nested) = start.nested {
        let index: std::collections::HashMap<&str, usize> = (nested.names.iter())
            .enumerate()
            .map(|(i, n)| (n.as_str(), i))
            .collect();
        for i in 0..n_layout {
            let name = problem.layout().name(i);
            // `transversal.{joint}.u` and `.v` start at `transversal.{joint}`.
            let isotropic = match ValueName::parse(name) {
                Ok(ValueName::Transversal {
                    joint,
                    axis: Some(_),
                }) => Some(ValueName::Transversal { joint, axis: None }.to_string()),
                _ => None,
            };
            let found = (index.get(name)).or_else(|| isotropic.and_then(|n| index.get(n.as_str())));
            if let Some(&k) = found {
                x_full[i] = nested.x[k];
            }
        }
    }
    let subset = Subset::new(&problem, free, x_full);
    let x0 = subset.initial_free();
    let mut config = crate::fit::identify_config(None);
    config.lm = crate::fit::full_fit_lm(config.lm, problem.n_residuals());
    if let Some(n) = start.max_evaluations {
        config.lm.max_evaluations = n;
    }
    let context = || format!("identifying the {rung} model from {n_rows} marker samples");
    let free_fit = identify(&subset, x0, &config).with_context(context)?;
    let id = crate::fit::hold_compliances_at_zero(&subset, &config, free_fit, std_scale)
        .with_context(context)?;
    let x = subset.full_x(id.fit.x.as_ref());
    let model = problem.model(x.as_ref());
    let names: Vec<String> = (0..problem.layout().len())
        .map(|i| problem.layout().name(i).to_owned())
        .collect();
    Ok((
        model,
        Fitted {
            x,
            identified: id,
            names,
        },
    ))
}

/// One identification of a rung: the full parameter vector, the identification over the free
/// parameters, and the full layout's names.
#[derive(Clone, Debug)]
pub struct Fitted {
    /// Every parameter of the problem (fixed ones at their nominal values).
    pub x: Col<f64>,
    /// The identification over the rung's free parameters (its layout names them).
    pub identified: Identified,
    /// Names of the full layout.
    pub names: Vec<String>,
}

/// Errors of one table under one model.
#[derive(Default)]
struct Errors {
    /// Per row, the squared errors summed over its markers and distance, m².
    per_row: Vec<f64>,
    /// Per marker sample, the 3-D position error, m.
    position: Vec<f64>,
    /// Per pose sample, the orientation error (angle of the relative rotation), rad.
    orientation: Vec<f64>,
    /// Per distance row, the distance error (model − measured), m.
    distance: Vec<f64>,
    /// Per row, the weighted squared error `Σ |e_p|²/σ_p² + θ²/σ_θ² + e_d²/σ_d²` (the fit's
    /// own objective; zeros without weights).
    score: Vec<f64>,
}

/// The errors of table `table` under `model`; scores with `weights`.
fn errors(
    model: &CalibratedModel,
    tables: Training<'_>,
    table: usize,
    weights: Option<&Weights>,
) -> Errors {
    let mut out = Errors::default();
    for row in tables.rows(table) {
        push_row_errors(model, &row, weights, &mut out);
    }
    out
}

/// Pushes the errors of one row under `model` onto `out` ([`push_errors`]).
fn push_row_errors(
    model: &CalibratedModel,
    row: &MeasuredRow,
    weights: Option<&Weights>,
    out: &mut Errors,
) {
    let tips: Vec<usize> = row.markers.iter().map(|m| m.marker).collect();
    let marker1 = row.distance_m.map(|_| model.end_pose_of(0, &row.q));
    let poses = model.end_poses_of(&tips, &row.q);
    push_errors(row, &poses, marker1.as_ref(), weights, out);
}

/// Pushes the errors of one row onto `out` from the predicted pose of each of its marker
/// samples (`poses`, in the order of `row.markers`, m, in the instrument frame) and, for a
/// distance row, of marker 1 (`marker1`): its distance and each marker sample's position and
/// orientation errors, its squared error and its score with `weights` (0 without).
fn push_errors(
    row: &MeasuredRow,
    poses: &[Isometry3<f64>],
    marker1: Option<&Isometry3<f64>>,
    weights: Option<&Weights>,
    out: &mut Errors,
) {
    let (mut sq, mut score) = (0.0, 0.0);
    if let (Some(d), Some(marker1)) = (row.distance_m, marker1) {
        let e = marker1.translation.vector.norm() - d;
        sq += e * e;
        out.distance.push(e);
        if let Some(w) = weights {
            score += (e / w.sigma_distance_m).powi(2);
        }
    }
    for (m, pose) in row.markers.iter().zip(poses) {
        let e = (pose.translation.vector - Vector3::from(m.position_m)).norm();
        sq += e * e;
        out.position.push(e);
        if let Some(w) = weights {
            score += (e / w.sigma_position_m).powi(2);
        }
        if let Some([w, xq, y, z]) = m.rotation {
            let meas = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, xq, y, z));
            let theta = meas.angle_to(&pose.rotation);
            out.orientation.push(theta);
            if let Some(w) = weights {
                score += (theta / w.sigma_orientation_rad).powi(2);
            }
        }
    }
    out.per_row.push(sq);
    out.score.push(score);
}

/// Mean, RMS and maximum of `v` (zeros when empty).
fn stats(v: &[f64]) -> (f64, f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0, 0.0);
    }
    let n = v.len() as f64;
    (
        v.iter().sum::<f64>() / n,
        (v.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        v.iter().copied().fold(0.0, f64::max),
    )
}

/// Mean, RMS and largest position, orientation (pose samples) and distance (distance rows)
/// errors of `e`.
fn pose_figures(e: &Errors) -> PoseFigures {
    let (pm, pr, px) = stats(&e.position);
    let (om, or, ox) = stats(&e.orientation);
    let abs: Vec<f64> = e.distance.iter().map(|d| d.abs()).collect();
    let (dm, dr, dx) = stats(&abs);
    let has_rot = !e.orientation.is_empty();
    let has_dist = !e.distance.is_empty();
    PoseFigures {
        position_mean_m: pm,
        position_rms_m: pr,
        position_max_m: px,
        orientation_mean_rad: has_rot.then_some(om),
        orientation_rms_rad: has_rot.then_some(or),
        orientation_max_rad: has_rot.then_some(ox),
        distance_mean_m: has_dist.then_some(dm),
        distance_rms_m: has_dist.then_some(dr),
        distance_max_m: has_dist.then_some(dx),
    }
}

/// A rung fitted on every training row: where its cross-validation folds start.
struct Warm {
    /// Every parameter of the problem at the full-data estimate.
    x: Col<f64>,
    /// The parameters that identification kept (frames included), in the full layout.
    free: Vec<usize>,
}

impl Warm {
    fn of(fitted: &Fitted) -> Warm {
        let id = &fitted.identified;
        let index: std::collections::HashMap<&str, usize> = (fitted.names.iter())
            .enumerate()
            .map(|(i, n)| (n.as_str(), i))
            .collect();
        let free = (id.identifiability.kept.iter())
            .filter_map(|&k| index.get(id.layout.name(k)).copied())
            .collect();
        Warm {
            x: fitted.x.clone(),
            free,
        }
    }
}

/// The residuals and the Jacobian of a rung's problem on every training row at its full-data
/// estimate [`Warm::x`]: what every fold's refit starts from (its training rows' entries).
struct AtWarm {
    /// The problem on every training row, whose rows each fold's problem takes
    /// ([`CalibrationProblem::with_rows`]).
    problem: CalibrationProblem,
    /// `r(x)`, length `m` (every training row's residuals, tables and rows in file order).
    r: Col<f64>,
    /// `∂r/∂x`, `m × n` (`n` the problem's layout).
    jac: Mat<f64>,
    /// Per table, per row, the index of its first residual in `r` ([`row_residuals`] each).
    first: Vec<Vec<usize>>,
}

impl AtWarm {
    /// The problem of `rung` on every row of `tables` evaluated at `warm.x`; `None` where it
    /// cannot be evaluated (each fold then evaluates its own start).
    fn new(
        rung: ModelName,
        robot: &Robot,
        tree: &Tree,
        tables: Training<'_>,
        weights: Weights,
        warm: &Warm,
    ) -> Option<AtWarm> {
        let obs = observations(tables, &|_, _| true);
        let terms = terms(rung, robot).ok()?;
        let problem = CalibrationProblem::on_tree(tree.clone(), obs, weights, terms).ok()?;
        let (m, n) = (problem.n_residuals(), problem.layout().len());
        let mut first = Vec::with_capacity(tables.tables.len());
        let mut at = 0;
        for t in tables.tables {
            let mut offsets = Vec::with_capacity(t.rows.len());
            for row in &t.rows {
                offsets.push(at);
                at += row_residuals(row);
            }
            first.push(offsets);
        }
        // Past the dense back end's bound each fold streams its Jacobian in row blocks
        // ([`refit`]): no Jacobian of every row is held for the folds to copy from.
        if at != m || warm.x.nrows() != n || m.saturating_mul(n) > REFIT_MAX_ENTRIES {
            return None;
        }
        let mut r = Col::zeros(m);
        let mut jac = Mat::zeros(m, n);
        (problem
            .residuals_and_jacobian(warm.x.as_ref(), r.as_mut(), jac.as_mut())
            .ok())?;
        Some(AtWarm {
            problem,
            r,
            jac,
            first,
        })
    }

    /// The indices in [`Self::r`] of the residuals of the rows `keep` selects, in table and
    /// row order.
    fn entries(
        &self,
        tables: &[MeasurementTable],
        keep: &dyn Fn(usize, usize) -> bool,
    ) -> Vec<usize> {
        let mut idx = Vec::new();
        for (ti, t) in tables.iter().enumerate() {
            for (ri, row) in t.rows.iter().enumerate() {
                if keep(ti, ri) {
                    let start = self.first[ti][ri];
                    idx.extend(start..start + row_residuals(row));
                }
            }
        }
        idx
    }

    /// The residuals of the rows `keep` selects, in table and row order.
    fn residuals_of(
        &self,
        tables: &[MeasurementTable],
        keep: &dyn Fn(usize, usize) -> bool,
    ) -> Col<f64> {
        let idx = self.entries(tables, keep);
        Col::from_fn(idx.len(), |i| self.r[idx[i]])
    }

    /// The problem on the rows `keep` selects: [`Self::problem`]'s rows of them (a table row
    /// gives its distance and each marker sample, as [`observations`] orders them).
    ///
    /// # Errors
    /// As [`CalibrationProblem::with_rows`].
    fn problem_on(
        &self,
        tables: &[MeasurementTable],
        keep: &dyn Fn(usize, usize) -> bool,
    ) -> Result<CalibrationProblem> {
        let mut rows = Vec::with_capacity(self.problem.observations().rows.len());
        for (ti, t) in tables.iter().enumerate() {
            for (ri, row) in t.rows.iter().enumerate() {
                rows.extend(std::iter::repeat_n(keep(ti, ri), observation_rows(row)));
            }
        }
        Ok(self.problem.with_rows(&rows)?)
    }

    /// The entries of the rows `keep` selects (in table and row order, as [`observations`]
    /// orders them): their residuals and Jacobian rows, `m_keep` and `m_keep × n`.
    fn rows(
        &self,
        tables: &[MeasurementTable],
        keep: &dyn Fn(usize, usize) -> bool,
    ) -> (Col<f64>, Mat<f64>) {
        let idx = self.entries(tables, keep);
        let m = idx.len();
        let r = Col::from_fn(m, |i| self.r[idx[i]]);
        // Column by column, through the columns' slices: indexing the matrix entry by entry
        // took about 4 % of the humanoid's ladder.
        let mut jac = Mat::zeros(m, self.jac.ncols());
        for (j, dst) in jac.col_iter_mut().enumerate() {
            match (
                self.jac.col(j).try_as_col_major(),
                dst.try_as_col_major_mut(),
            ) {
                (Some(src), Some(dst)) => {
                    let src = src.as_slice();
                    for (d, &i) in dst.as_slice_mut().iter_mut().zip(&idx) {
                        *d = src[i];
                    }
                }
                _ => unreachable!("the columns of an owned matrix are contiguous"),
            }
        }
        (r, jac)
    }
}

/// Where each blocked fold's refit starts, at a rung's full-data estimate: the R factor of
/// `[J_f r]` over the fold's training rows (`J_f` the refit's free columns).
/// The blocked folds come repeat by repeat, each repeat's held-out blocks a partition of the
/// training rows ([`crate::fit::blocked_folds`]), so a fold trains on the other blocks of its
/// repeat: each block's rows are reduced to their triangle once
/// ([`hapcal_identify::rows_r_factor`]), and a fold's start is the triangles of the blocks
/// before it and after it stacked ([`hapcal_identify::stacked_r_factor`], prefixes and
/// suffixes of the repeat reused): `3(k − 2)` merges of two triangles a repeat, where the
/// folds' own Jacobians would fold `k(k − 1)` blocks of rows (their rows never copied).
struct FoldStarts(Vec<Mat<f64>>);

impl FoldStarts {
    /// The starts of the folds of `blocked` (`k` folds a repeat) over the rows of `tables`
    /// that `at` evaluated, columns `free`; `None` when a repeat's held-out blocks do not
    /// partition the rows.
    fn new(
        at: &AtWarm,
        tables: &[MeasurementTable],
        blocked: &[Fold],
        k: usize,
        free: &[usize],
    ) -> Option<Self> {
        use rayon::prelude::*;
        if k < 2 || !blocked.len().is_multiple_of(k) {
            return None;
        }
        for repeat in blocked.chunks(k) {
            for (ti, t) in tables.iter().enumerate() {
                for ri in 0..t.rows.len() {
                    if repeat.iter().filter(|fold| fold[ti][ri]).count() != 1 {
                        return None;
                    }
                }
            }
        }
        let blocks: Vec<Mat<f64>> = (blocked.par_iter())
            .map(|fold| {
                let rows = at.entries(tables, &|ti, ri| fold[ti][ri]);
                hapcal_identify::rows_r_factor(at.jac.as_ref(), at.r.as_ref(), &rows, free)
            })
            .collect();
        let starts = (blocks.par_chunks(k))
            .flat_map_iter(Self::of_repeat)
            .collect();
        Some(Self(starts))
    }

    /// The starts of one repeat's folds from its blocks' triangles (fold `b` holds out block
    /// `b`): the blocks before `b` stacked with those after it.
    fn of_repeat(blocks: &[Mat<f64>]) -> Vec<Mat<f64>> {
        let k = blocks.len();
        let stack = |a: &Mat<f64>, b: &Mat<f64>| {
            hapcal_identify::stacked_r_factor(&[a.as_ref(), b.as_ref()])
        };
        // prefix[b]: blocks 0..b stacked (b ≥ 1); suffix[b]: blocks b+1..k stacked (b < k−1).
        let mut prefix: Vec<Option<Mat<f64>>> = vec![None; k];
        let mut suffix: Vec<Option<Mat<f64>>> = vec![None; k];
        for b in 1..k {
            prefix[b] = Some(match &prefix[b - 1] {
                Some(p) => stack(p, &blocks[b - 1]),
                None => blocks[b - 1].clone(),
            });
        }
        for b in (0..k - 1).rev() {
            suffix[b] = Some(match &suffix[b + 1] {
                Some(s) => stack(&blocks[b + 1], s),
                None => blocks[b + 1].clone(),
            });
        }
        (prefix.into_iter().zip(suffix))
            .filter_map(|ends| match ends {
                (Some(p), Some(s)) => Some(stack(&p, &s)),
                (Some(t), None) | (None, Some(t)) => Some(t),
                (None, None) => None,
            })
            .collect()
    }

    /// The start of blocked fold `f`; `None` past the blocked folds (a joint-range fold).
    fn start_of(&self, f: usize) -> Option<MatRef<'_, f64>> {
        self.0.get(f).map(Mat::as_ref)
    }
}

/// `rung` refitted on the rows `keep` selects, from `warm` and over its kept parameters
/// (the identifiability decided on all training rows): Levenberg–Marquardt alone, a few
/// iterations from a nearby start, from the residuals and Jacobian at `warm` that `at_warm`
/// holds for every training row (the same values the fold's problem evaluates there), when
/// given; the fold's problem is then that problem's on the fold's rows, its gravity loads not
/// evaluated again ([`AtWarm::problem_on`]). With `reduced`, the R factor of `[J_f r]` over
/// the fold's training rows at `warm` ([`FoldStarts`]), it starts from that triangle
/// ([`hapcal_identify::levenberg_marquardt_from_triangle`]): the fold's Jacobian rows are
/// neither copied nor folded again. A fold whose Jacobian has more than [`REFIT_MAX_ENTRIES`] entries is fitted on the
/// streaming back end ([`hapcal_identify::levenberg_marquardt_streaming`]): its Jacobian
/// passes in row blocks and is never held whole.
#[allow(clippy::too_many_arguments)]
fn refit(
    rung: ModelName,
    robot: &Robot,
    tree: &Tree,
    tables: Training<'_>,
    weights: Weights,
    keep: &dyn Fn(usize, usize) -> bool,
    warm: &Warm,
    at_warm: Option<&AtWarm>,
    reduced: Option<MatRef<'_, f64>>,
) -> Result<CalibratedModel> {
    let problem = match at_warm {
        Some(at) => at.problem_on(tables.tables, keep),
        None => CalibrationProblem::on_tree(
            tree.clone(),
            observations(tables, keep),
            weights,
            terms(rung, robot)?,
        )
        .map_err(Into::into),
    }
    .context("building the calibration problem")?;
    // A fold's estimate is judged by its held-out error: a relative cost reduction of 10⁻⁶
    // changes that error by about 10⁻⁶ of itself, far below the blocked standard errors the
    // ladder compares (a few per cent of the error); the full fits keep the default 10⁻¹². On
    // the bundled recordings, 10⁻⁶ instead of 10⁻⁸ moves the ladder's figures in the fourth
    // digit at most (docs/results/real-data.md) and saves 7 % of the humanoid ladder's time.
    // A first Gauss–Newton step that its linearisation predicted ends the refit
    // (crate::fit::FOLD_STEP_CHI2).
    let lm = crate::fit::fold_step_lm(
        crate::fit::identify_config(None).lm,
        problem.n_residuals(),
        warm.free.len(),
    );
    let fit = match (reduced, at_warm) {
        (Some(r_free), Some(at)) => hapcal_identify::levenberg_marquardt_from_triangle(
            &problem,
            warm.x.clone(),
            &warm.free,
            &lm,
            at.residuals_of(tables.tables, keep),
            r_free,
        ),
        _ => {
            let start = (at_warm.map(|a| a.rows(tables.tables, keep))).filter(|(r, jac)| {
                r.nrows() == problem.n_residuals() && jac.ncols() == problem.layout().len()
            });
            lm_alone(
                &problem,
                warm.x.clone(),
                &warm.free,
                &lm,
                start,
                REFIT_MAX_ENTRIES,
            )
        }
    }
    .with_context(|| format!("refitting the {rung} model on a fold"))?;
    Ok(problem.model(fit.x.as_ref()))
}

/// Levenberg–Marquardt alone on `problem` from `x0` over the parameters `free` (a fold's
/// refit, a torque-equilibrium refit): from the residuals and Jacobian `start` already
/// evaluated at `x0` when given; on the streaming back end
/// ([`hapcal_identify::levenberg_marquardt_streaming`], the Jacobian in row blocks, never held
/// whole) when the Jacobian has more than `max_entries` entries and the problem has row
/// blocks; dense otherwise. The three take the same steps up to rounding.
///
/// # Errors
/// As [`hapcal_identify::levenberg_marquardt`].
fn lm_alone<P: Problem + Sync>(
    problem: &P,
    x0: Col<f64>,
    free: &[usize],
    lm: &hapcal_identify::LmConfig,
    start: Option<(Col<f64>, Mat<f64>)>,
    max_entries: usize,
) -> std::result::Result<hapcal_identify::Fit, hapcal_identify::Error> {
    let entries = (problem.n_residuals()).saturating_mul(problem.layout().len());
    match start {
        Some((r0, jac0)) => {
            hapcal_identify::levenberg_marquardt_from(problem, x0, free, lm, r0, jac0)
        }
        None if problem.row_blocks().is_some() && entries > max_entries => {
            hapcal_identify::levenberg_marquardt_streaming(problem, x0, free, lm)
        }
        None => hapcal_identify::levenberg_marquardt(problem, x0, free, lm),
    }
}

/// The original of every row of every table ([`crate::fit::originals`] by the reader's
/// repeat key): a row that repeats an earlier row of its table is held out with it.
fn table_originals(tables: Training<'_>) -> Vec<Vec<usize>> {
    (0..tables.tables.len())
        .map(|ti| row_originals(tables, ti, &|_, _| true))
        .collect()
}

/// The original of every row of table `ti` that `keep` selects, numbered in that order: what
/// [`crate::fit::originals`] gives by the reader's repeat key ([`MeasuredRow::repeat_key`]),
/// found by the reader's 64-bit hash of the same values ([`MeasuredRow::repeat_hash`]) so
/// that the map holds 16 bytes a row rather than every value of every row (272 bytes a row
/// of two markers). A row whose hash an earlier row holds is compared with it by their keys,
/// and rows that share a hash without being copies are told apart by their keys, so a
/// collision changes nothing.
fn row_originals(
    tables: Training<'_>,
    ti: usize,
    keep: &dyn Fn(usize, usize) -> bool,
) -> Vec<usize> {
    use std::collections::{HashMap, hash_map::Entry};
    let kept: Vec<usize> = (0..tables.tables[ti].rows.len())
        .filter(|&ri| keep(ti, ri))
        .collect();
    let mut first = HashMap::with_capacity(kept.len());
    let mut collided = HashMap::new();
    (kept.iter().enumerate())
        .map(|(i, &ri)| {
            let row = tables.row(ti, ri);
            match first.entry(row.repeat_hash()) {
                Entry::Vacant(slot) => *slot.insert(i),
                Entry::Occupied(earlier) => {
                    let p = *earlier.get();
                    let key = row.repeat_key();
                    if tables.row(ti, kept[p]).repeat_key() == key {
                        p
                    } else {
                        *collided.entry(key).or_insert(i)
                    }
                }
            }
        })
        .collect()
}

/// Training rows of `tables` that repeat an earlier row of their table.
fn n_table_copies(tables: Training<'_>) -> usize {
    table_originals(tables)
        .iter()
        .map(|o| crate::fit::n_copies(o))
        .sum()
}

/// A rung of the ladder the training rows cannot fit, and the numbers that say so.
#[derive(Clone, Debug)]
struct Untried {
    rung: ModelName,
    /// Residuals of the fit that cannot have this rung: all training rows', or the fewest a
    /// cross-validation fold trains on.
    n_residuals: usize,
    /// Parameters the rung keeps.
    n_params: usize,
    /// Training rows of that fold; `None` for all training rows.
    fold_rows: Option<usize>,
}

impl Untried {
    /// Why, in the user's words: `38 parameters; a cross-validation fold's 6 training rows
    /// give 36 residuals`.
    fn reason(&self) -> String {
        match self.fold_rows {
            Some(rows) => format!(
                "{} parameters; a cross-validation fold's {rows} training rows give {} residuals",
                self.n_params, self.n_residuals
            ),
            None => format!(
                "{} parameters; the training rows give {} residuals",
                self.n_params, self.n_residuals
            ),
        }
    }
}

/// The note of a ladder that left rungs out because the rows cannot fit them: which rung it
/// stopped at (the last of `ladder`, the rungs tried) and, per rung left out, its parameters
/// and the residuals; `None` when every rung was tried.
fn untried_note(ladder: &[RungReport], untried: &[Untried]) -> Option<String> {
    let top = ladder.last()?.rung;
    if untried.is_empty() {
        return None;
    }
    let list: Vec<String> = (untried.iter())
        .map(|u| format!("{} ({})", u.rung, u.reason()))
        .collect();
    Some(format!(
        "{}{top}: every cross-validation fold must fit a rung's parameters from its training \
         rows, and too few rows were measured for {}; measure more configurations to try them",
        crate::report::UNTRIED_RUNGS_NOTE,
        list.join(", ")
    ))
}

/// The residual counts of an identification that had fewer residuals than parameters, from
/// its error: `(residuals, parameters)`.
fn too_few_residuals(e: &anyhow::Error) -> Option<(usize, usize)> {
    e.chain()
        .find_map(|c| match c.downcast_ref::<hapcal_identify::Error>()? {
            hapcal_identify::Error::TooFewResiduals {
                n_residuals,
                n_free,
            }
            | hapcal_identify::Error::NoDegreesOfFreedom {
                n_residuals,
                n_free,
            } => Some((*n_residuals, *n_free)),
            _ => None,
        })
}

/// The rows a table row gives [`observations`]: its distance, if any, then one per marker
/// sample.
fn observation_rows(row: &MeasuredRow) -> usize {
    usize::from(row.distance_m.is_some()) + row.markers.len()
}

/// Residuals of one measured row: 1 for a distance, 3 per marker position, 6 per pose.
fn row_residuals(row: &MeasuredRow) -> usize {
    usize::from(row.distance_m.is_some())
        + (row.markers.iter())
            .map(|m| if m.rotation.is_some() { 6 } else { 3 })
            .sum::<usize>()
}

/// The fewest residuals the training rows of a blocked cross-validation fold of `tables`
/// give, and that fold's training rows.
fn fewest_fold_residuals(tables: Training<'_>, k: usize) -> (usize, usize) {
    (crate::fit::blocked_folds(&table_originals(tables), k).iter())
        .map(|fold| {
            let mut residuals = 0;
            let mut rows = 0;
            for (t, held) in tables.tables.iter().zip(fold) {
                for (row, _) in t.rows.iter().zip(held).filter(|(_, h)| !**h) {
                    residuals += row_residuals(row);
                    rows += 1;
                }
            }
            (residuals, rows)
        })
        .min()
        .unwrap_or((0, 0))
}

/// How far past a joint's training range, as a share of the range, a test or workspace
/// reading counts as outside it (an extrapolation worth judging and reporting; random test
/// rows of a random design fall a fraction of a percent past the training extremes).
pub const OUTSIDE_SHARE: f64 = 0.05;

/// Which side of the training range `(lo, hi)` reading `q` lies past by more than
/// [`OUTSIDE_SHARE`] of the range: `Some(true)` above, `Some(false)` below, `None` within.
fn past_range(q: f64, (lo, hi): (f64, f64)) -> Option<bool> {
    let slack = OUTSIDE_SHARE * (hi - lo).max(0.0);
    if q > hi + slack {
        Some(true)
    } else if q < lo - slack {
        Some(false)
    } else {
        None
    }
}

/// Share of the training rows a joint-range fold holds out at least, from one end of the
/// joint's range: on evenly spread readings it emulates an extrapolation of a quarter of the
/// range it is fitted on (0.2 / 0.8).
pub const RANGE_FOLD_SHARE: f64 = 0.2;

/// Share of the training rows a joint-range fold holds out at most: on evenly spread readings
/// it emulates an extrapolation of the whole range it is fitted on (0.5 / 0.5); a fold that
/// held out more would be fitted on fewer rows than it is judged on.
pub const MAX_RANGE_FOLD_SHARE: f64 = 0.5;

/// Blocks of a joint-range fold's held-out rows, contiguous along the joint's reading, that
/// the standard error of a difference between rungs is taken over (a rung's extrapolation
/// error is smooth in the reading, so neighbouring rows are correlated).
pub const RANGE_BLOCKS: usize = 5;

/// The training range of every joint, rad or m: (min, max) over the training rows.
pub fn training_ranges(tables: &[MeasurementTable], n_joints: usize) -> Vec<(f64, f64)> {
    reading_ranges(
        tables.iter().flat_map(|t| &t.rows).map(|r| &r.q[..]),
        n_joints,
    )
}

/// The range of every joint over `readings` (one slice of joint readings per row, rad or
/// m): (min, max); (+∞, −∞) for a joint no row reads.
pub fn reading_ranges<'a>(
    readings: impl IntoIterator<Item = &'a [f64]>,
    n_joints: usize,
) -> Vec<(f64, f64)> {
    let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); n_joints];
    for q in readings {
        for (r, q) in range.iter_mut().zip(q) {
            *r = (r.0.min(*q), r.1.max(*q));
        }
    }
    range
}

/// How far reading `q` lies beyond side `upper` of the training range `(lo, hi)`, as a share
/// of the range; 0 when it does not lie past it by more than [`OUTSIDE_SHARE`] ([`past_range`]).
fn beyond_share(q: f64, (lo, hi): (f64, f64), upper: bool) -> f64 {
    match past_range(q, (lo, hi)) {
        Some(u) if u == upper && hi > lo => (if upper { q - hi } else { lo - q }) / (hi - lo),
        _ => 0.0,
    }
}

/// A joint-range fold: its report, its joint (chain order) and the rows it holds out.
struct RangeSplit {
    report: RangeFold,
    joint: usize,
    fold: Fold,
    /// The reading nearest the held-out end among the rows the fold is fitted on, and the
    /// width of their range (rad or m): a held-out reading `q` lies `|q − edge| / width`
    /// beyond them.
    edge: f64,
    width: f64,
}

/// The joint-range folds where the calibration will be used beyond its training range: for
/// each side of each joint's range that a configuration of `beyond` (test rows, workspace)
/// lies past by more than [`OUTSIDE_SHARE`] of the range, the rows at that end of the joint's
/// training readings held out. The fold holds out the fewest rows, from
/// [`RANGE_FOLD_SHARE`] up to [`MAX_RANGE_FOLD_SHARE`] of them, whose readings reach as far
/// beyond the readings it is fitted on, relative to their range, as the farthest
/// configuration lies beyond the training range (docs/engine.md, "Extrapolation"). A side is
/// skipped when ties would hold out more than half the rows or fewer than 3.
fn range_folds(robot: &Robot, tables: &[MeasurementTable], beyond: &[&[f64]]) -> Vec<RangeSplit> {
    let n_joints = robot.joint_names.len();
    let ranges = training_ranges(tables, n_joints);
    let n_rows: usize = tables.iter().map(|t| t.rows.len()).sum();
    let mut out = Vec::new();
    for (j, &(lo, hi)) in ranges.iter().enumerate() {
        if (hi - lo).is_nan() || hi - lo <= 1e-9 {
            continue;
        }
        let mut values: Vec<f64> = (tables.iter().flat_map(|t| &t.rows))
            .map(|r| r.q[j])
            .collect();
        values.sort_by(f64::total_cmp);
        let k_min = ((RANGE_FOLD_SHARE * n_rows as f64).ceil() as usize).clamp(1, n_rows);
        let k_max = ((MAX_RANGE_FOLD_SHARE * n_rows as f64).floor() as usize).max(k_min);
        for upper in [false, true] {
            let needed = (beyond.iter())
                .map(|q| beyond_share(q[j], (lo, hi), upper))
                .fold(0.0, f64::max);
            if needed <= 0.0 {
                continue;
            }
            // Holding out the k most extreme readings (and their ties): the rows held out and
            // the extrapolation the fold emulates.
            let split = |k: usize| {
                let (count, edge) = if upper {
                    let cut = values[n_rows - k];
                    let first = values.partition_point(|&v| v < cut);
                    (n_rows - first, values[..first].last().copied())
                } else {
                    let cut = values[k - 1];
                    let past = values.partition_point(|&v| v <= cut);
                    (past, values[past..].first().copied())
                };
                let edge = edge.unwrap_or(if upper { lo } else { hi });
                let fitted = if upper { edge - lo } else { hi - edge };
                let reach = if upper { hi - edge } else { edge - lo };
                let emulated = if fitted > 0.0 {
                    reach / fitted
                } else {
                    f64::INFINITY
                };
                (count, emulated, edge, fitted)
            };
            let mut chosen = None;
            for k in k_min..=k_max.min(n_rows) {
                let (count, emulated, edge, width) = split(k);
                if count < 3 || 2 * count > n_rows {
                    continue;
                }
                chosen = Some((k, count, emulated, edge, width));
                if emulated >= needed {
                    break;
                }
            }
            let Some((k, count, emulated, edge, width)) = chosen else {
                continue;
            };
            let held = |q: f64| {
                if upper {
                    q >= values[n_rows - k]
                } else {
                    q <= values[k - 1]
                }
            };
            let fold: Fold = (tables.iter())
                .map(|t| t.rows.iter().map(|r| held(r.q[j])).collect())
                .collect();
            out.push(RangeSplit {
                report: RangeFold {
                    joint: robot.joint_names[j].clone(),
                    upper,
                    relevant: true,
                    held_out_share: count as f64 / n_rows as f64,
                    emulated_share: emulated,
                    needed_share: needed,
                },
                joint: j,
                fold,
                edge,
                width,
            });
        }
    }
    out
}

/// What the joint-range folds say of one rung against another where the calibration will be
/// used beyond its training range, averaged over the folds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeVerdict {
    /// The difference of the weighted squared errors per row (the first rung's minus the
    /// second's, dimensionless) predicted at the extrapolation needed, and its standard error.
    pub predicted: (f64, f64),
    /// How that difference changes per unit of extrapolation share across the folds' rows
    /// (dimensionless; positive: the first rung's advantage shrinks the farther it
    /// extrapolates).
    pub growth: f64,
    /// Whether every fold could fit both rungs (`false`: a fold leaves fewer rows than a
    /// rung's parameters need; the folds cannot judge it, and it is not taken).
    pub judged: bool,
}

impl RangeVerdict {
    /// Whether the folds let the first rung be taken over the second (the one chosen below
    /// it): better at the extrapolation needed by [`crate::model::LADDER_SIGNIFICANCE_Z`]
    /// standard errors, the margin of the blocked folds, and with an advantage that does not
    /// shrink as the folds extrapolate farther (docs/engine.md, "Extrapolation").
    pub fn allows(&self) -> bool {
        let (d, se) = self.predicted;
        self.judged && d + crate::model::LADDER_SIGNIFICANCE_Z * se < 0.0 && self.growth <= 0.0
    }
}

/// The joint-range folds' held-out rows of every rung, with the blocks their differences are
/// judged over.
struct RangeEvidence {
    /// Per fold, per rung, the weighted squared error of every held-out row (`None`: the
    /// fold's remaining rows could not determine the rung's parameters).
    score: Vec<Vec<Option<Vec<f64>>>>,
    /// Per rung, the squared position error of every held-out row of every fold, m².
    squared: Vec<Vec<f64>>,
    /// Per fold, the block of every held-out row: its rank in extrapolation share cut into
    /// [`RANGE_BLOCKS`] equal parts (0 nearest the rows the fold is fitted on).
    block: Vec<Vec<usize>>,
    /// Per fold, the mean extrapolation share of each block's rows (how far beyond the
    /// readings the fold is fitted on, as a share of their range).
    reach: Vec<Vec<f64>>,
    /// Per fold, the extrapolation share needed on its side.
    need: Vec<f64>,
}

impl RangeEvidence {
    /// The evidence of the folds `ranges` on `tables` from each rung's `scores`.
    fn new(ranges: &[RangeSplit], tables: &[MeasurementTable], scores: &[Scores]) -> Self {
        let (mut block, mut reach) = (Vec::new(), Vec::new());
        for split in ranges {
            // The held-out rows' extrapolation shares, in the order cross_validate pushes them.
            let e: Vec<f64> = (tables.iter().enumerate())
                .flat_map(|(ti, t)| {
                    (t.rows.iter().enumerate())
                        .filter(move |&(r, _)| split.fold[ti][r])
                        .map(move |(_, row)| {
                            let q = row.q[split.joint];
                            let d = if split.report.upper {
                                q - split.edge
                            } else {
                                split.edge - q
                            };
                            d.max(0.0) / split.width.max(f64::MIN_POSITIVE)
                        })
                })
                .collect();
            let mut order: Vec<usize> = (0..e.len()).collect();
            order.sort_by(|&a, &b| e[a].total_cmp(&e[b]));
            let mut bin = vec![0; e.len()];
            for (rank, &i) in order.iter().enumerate() {
                bin[i] = rank * RANGE_BLOCKS / e.len().max(1);
            }
            reach.push(block_means(&e, &bin));
            block.push(bin);
        }
        RangeEvidence {
            score: (0..ranges.len())
                .map(|f| {
                    (scores.iter())
                        .map(|s| {
                            (s.range_rows[f].as_ref()).map(|r| r.iter().map(|e| e.0).collect())
                        })
                        .collect()
                })
                .collect(),
            squared: (scores.iter())
                .map(|s| {
                    s.range_rows
                        .iter()
                        .flatten()
                        .flatten()
                        .map(|e| e.1)
                        .collect()
                })
                .collect(),
            block,
            reach,
            need: ranges.iter().map(|r| r.report.needed_share).collect(),
        }
    }

    /// Whether no fold was made.
    fn is_empty(&self) -> bool {
        self.block.is_empty()
    }

    /// Rung `a` against rung `b` where the calibration will be used beyond its training
    /// range: on each fold, the straight line through its blocks' mean differences of the
    /// weighted squared error (`a`'s minus `b`'s) against their mean extrapolation share
    /// ([`Line`]), evaluated at the share needed on its side (within the blocks' reach when
    /// the fold emulates the need, beyond it when it does not), and its slope; averaged over
    /// the folds. A fold whose held-out readings do not spread gives its blocked mean
    /// difference and no slope. Zero without folds; not judged when a fold could not fit
    /// either rung.
    fn judge(&self, a: usize, b: usize) -> RangeVerdict {
        let (mut d, mut var, mut growth) = (0.0, 0.0, 0.0);
        for f in 0..self.block.len() {
            let (Some(sa), Some(sb)) = (&self.score[f][a], &self.score[f][b]) else {
                return RangeVerdict {
                    predicted: (0.0, 0.0),
                    growth: 0.0,
                    judged: false,
                };
            };
            let diff: Vec<f64> = sa.iter().zip(sb).map(|(x, y)| x - y).collect();
            let (fd, fse, slope) =
                match Line::fit(&self.reach[f], &block_means(&diff, &self.block[f])) {
                    Some(line) => {
                        let (v, se) = line.at(self.need[f]);
                        (v, se, line.slope)
                    }
                    None => {
                        let (v, se, _) =
                            crate::fit::blocked_mean_difference(sa, sb, &self.block[f]);
                        (v, se, 0.0)
                    }
                };
            d += fd;
            var += fse * fse;
            growth += slope;
        }
        let n = self.block.len().max(1) as f64;
        RangeVerdict {
            predicted: (d / n, var.sqrt() / n),
            growth: growth / n,
            judged: true,
        }
    }

    /// Mean over the held-out rows of every fold that fitted both rungs of rung `a`'s
    /// weighted squared error minus rung `b`'s; 0 without such folds.
    fn mean_difference(&self, a: usize, b: usize) -> f64 {
        let (sa, sb): (Vec<f64>, Vec<f64>) = (self.score.iter())
            .filter_map(|f| Some(f[a].as_ref()?.iter().zip(f[b].as_ref()?)))
            .flatten()
            .unzip();
        sa.iter().zip(&sb).map(|(x, y)| x - y).sum::<f64>() / sa.len().max(1) as f64
    }

    /// Held-out position RMS of rung `i` over the folds' rows, m; `None` without folds.
    fn rms_m(&self, i: usize) -> Option<f64> {
        let sq = &self.squared[i];
        (!sq.is_empty()).then(|| (sq.iter().sum::<f64>() / sq.len() as f64).sqrt())
    }
}

/// The mean of `values` over each non-empty block of `block` (`block[i] < RANGE_BLOCKS`), in
/// block order.
fn block_means(values: &[f64], block: &[usize]) -> Vec<f64> {
    let mut sum = [(0.0, 0usize); RANGE_BLOCKS];
    for (&v, &b) in values.iter().zip(block) {
        sum[b] = (sum[b].0 + v, sum[b].1 + 1);
    }
    (sum.iter().filter(|s| s.1 > 0))
        .map(|s| s.0 / s.1 as f64)
        .collect()
}

/// A least-squares straight line `y = ȳ + slope·(x − x̄)` through points `(x, y)`, with what
/// the standard error of a prediction needs (Draper & Smith, "Applied Regression Analysis",
/// 3rd ed., 1998, §1.4 and §3.1).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Line {
    n: usize,
    mean_x: f64,
    mean_y: f64,
    slope: f64,
    /// Residual variance, `Σ (y − ŷ)² / (n − 2)`.
    s2: f64,
    /// `Σ (x − x̄)²`.
    sxx: f64,
}

impl Line {
    /// The line through the first `min(x.len(), y.len())` points; `None` with fewer than 3
    /// points or no spread in `x` (beyond rounding).
    fn fit(x: &[f64], y: &[f64]) -> Option<Line> {
        let n = x.len().min(y.len());
        let (x, y) = (&x[..n], &y[..n]);
        if n < 3 {
            return None;
        }
        let nf = n as f64;
        let (mean_x, mean_y) = (x.iter().sum::<f64>() / nf, y.iter().sum::<f64>() / nf);
        let sxx: f64 = x.iter().map(|v| (v - mean_x).powi(2)).sum();
        // No spread: every x equal, up to rounding.
        if sxx <= f64::EPSILON * x.iter().map(|v| v * v).sum::<f64>() || !sxx.is_finite() {
            return None;
        }
        let sxy: f64 = (x.iter().zip(y))
            .map(|(a, b)| (a - mean_x) * (b - mean_y))
            .sum();
        let slope = sxy / sxx;
        let s2 = (x.iter().zip(y))
            .map(|(a, b)| (b - mean_y - slope * (a - mean_x)).powi(2))
            .sum::<f64>()
            / (nf - 2.0);
        Some(Line {
            n,
            mean_x,
            mean_y,
            slope,
            s2,
            sxx,
        })
    }

    /// The line's value at `x` and the standard error of that mean prediction,
    /// `√(s²·(1/n + (x − x̄)²/Sxx))`: it grows with the distance from the points' centre.
    fn at(&self, x: f64) -> (f64, f64) {
        let dx = x - self.mean_x;
        (
            self.mean_y + self.slope * dx,
            (self.s2 * (1.0 / self.n as f64 + dx * dx / self.sxx)).sqrt(),
        )
    }
}

/// Cross-validation scores of one rung.
struct Scores {
    /// Blocked folds: the held-out squared position error per row, averaged over the
    /// repeats.
    squared: HeldOut,
    /// Blocked folds: the held-out weighted squared error per row (the fit's objective).
    score: HeldOut,
    /// Joint-range folds: per fold, the held-out weighted squared error and squared position
    /// error (m²) of each held-out row, rows in table and file order.
    range_rows: Vec<Option<Vec<(f64, f64)>>>,
}

/// `rung` cross-validated on the training tables: the blocked folds (repeated, rows
/// contiguous in file order within each table) and the joint-range folds, each refitted from
/// the rung's full-data estimate `warm`, the folds in parallel.
#[allow(clippy::too_many_arguments)]
fn cross_validate(
    rung: ModelName,
    robot: &Robot,
    tree: &Tree,
    warm: &Warm,
    tables: Training<'_>,
    cfg: &MeasuredConfig,
    weights: Weights,
    ranges: &[RangeSplit],
) -> Result<Scores> {
    use rayon::prelude::*;
    let originals = table_originals(tables);
    let blocked = crate::fit::blocked_folds(&originals, cfg.folds);
    let folds: Vec<&Fold> = blocked
        .iter()
        .chain(ranges.iter().map(|r| &r.fold))
        .collect();
    // A joint-range fold that leaves too few rows for the rung's parameters (it holds out up
    // to half of them) cannot judge the rung: `None`, and the rung is not taken where the
    // calibration extrapolates. A blocked fold that cannot is an error, as before.
    // Per fold, per held-out row: table, row, squared error (m²), weighted squared error.
    type Held = Option<Vec<(usize, usize, f64, f64)>>;
    let at_warm = AtWarm::new(rung, robot, tree, tables, weights, warm);
    let starts = (at_warm.as_ref())
        .and_then(|a| FoldStarts::new(a, tables.tables, &blocked, cfg.folds, &warm.free));
    let held: Vec<Held> = (folds.par_iter().enumerate())
        .map(|(f, fold)| {
            let fitted = refit(
                rung,
                robot,
                tree,
                tables,
                weights,
                &|ti, r| !fold[ti][r],
                warm,
                at_warm.as_ref(),
                starts.as_ref().and_then(|s| s.start_of(f)),
            );
            let model = match fitted {
                Ok(model) => model,
                Err(_) if f >= blocked.len() => return Ok(None),
                Err(e) => return Err(e),
            };
            let mut out = Vec::new();
            for (ti, t) in tables.tables.iter().enumerate() {
                for r in 0..t.rows.len() {
                    if fold[ti][r] {
                        let (sq, score) = row_error(&model, &tables.row(ti, r), &weights);
                        out.push((ti, r, sq, score));
                    }
                }
            }
            Ok(Some(out))
        })
        .collect::<Result<_>>()?;
    let k = cfg.folds;
    let offsets: Vec<usize> = (tables.tables.iter())
        .scan(0, |acc, t| {
            let start = *acc;
            *acc += t.rows.len();
            Some(start)
        })
        .collect();
    let n_rows: usize = tables.tables.iter().map(|t| t.rows.len()).sum();
    let (mut sq, mut score) = (vec![0.0; n_rows], vec![0.0; n_rows]);
    let block = crate::fit::first_repeat_blocks(&originals, k);
    for fold in held[..blocked.len()].iter().flatten() {
        for &(ti, r, e2, s) in fold {
            sq[offsets[ti] + r] += e2 / CV_REPEATS as f64;
            score[offsets[ti] + r] += s / CV_REPEATS as f64;
        }
    }
    let range_rows = (held[blocked.len()..].iter())
        .map(|fold| (fold.as_ref()).map(|rows| rows.iter().map(|e| (e.3, e.2)).collect()))
        .collect();
    Ok(Scores {
        squared: HeldOut {
            sq_errors: sq,
            block: block.clone(),
        },
        score: HeldOut {
            sq_errors: score,
            block,
        },
        range_rows,
    })
}

/// Squared error (m², every marker and the distance of the row) and weighted squared error
/// (the fit's objective) of one row under `model`.
fn row_error(model: &CalibratedModel, row: &MeasuredRow, w: &Weights) -> (f64, f64) {
    let mut e = Errors::default();
    push_row_errors(model, row, Some(w), &mut e);
    (e.per_row[0], e.score[0])
}

/// Calibrates `robot` from marker tables: frames fitted, the rung chosen on the ladder (or
/// given), figures of every training and test table for frames only and the chosen rung.
///
/// # Errors
/// No training row, fewer rows than the kept parameters, or a failed identification.
pub fn calibrate_measured(
    robot: &Robot,
    train: &[MeasurementTable],
    test: &[MeasurementTable],
    cfg: &MeasuredConfig,
) -> Result<MeasuredOutcome> {
    on_bounded_training(robot, train, cfg, cfg.rung.is_none().then_some(test), |p| {
        let Prepared {
            n_rows,
            frames,
            fits,
            bounded,
            done,
            equilibrium,
            ladder_rungs,
        } = p;
        let (frames_model, frames_only) = &bounded.frames;
        let frames_fit = (frames_model, frames_only);
        // The ladder's head fitted before the ladder (isotropic transversal compliance) is
        // the rung a compliant tree most often settles on: its torque equilibrium is worked
        // out beside the ladder (before it, when its nested rungs' runs were), and taken when
        // the ladder chooses that very fit.
        let head = (cfg.rung.is_none() && equilibrium.is_none())
            .then(|| ladder_head(&ladder_rungs.0))
            .flatten()
            .and_then(|h| done.fits.iter().find(|(r, _)| *r == h).cloned());
        let (choice, early) = rayon::join(
            || choose_rung(&fits, cfg, test, frames_fit, done, &ladder_rungs),
            || {
                equilibrium.or_else(|| {
                    head.map(|(r, (model, fitted))| {
                        (
                            r,
                            fitted.x.clone(),
                            equilibrate_fit(&fits, r, model, fitted),
                        )
                    })
                })
            },
        );
        let Choice {
            rung,
            chosen,
            mut ladder,
        } = choice?;
        let early = early
            .filter(|(r, x, _)| *r == rung && *x == chosen.1.x)
            .map(|(_, _, settled)| settled);
        let settled = settle(&fits, rung, chosen, early, &mut ladder.reports)?;
        let review = Review {
            cfg,
            fits: &fits,
            rung,
            settled: &settled,
            frames_model,
            bounded,
            train,
            test,
            n_rows,
        };
        let markers = (&frames.base, frames.markers.as_slice());
        // Both read the settled fit only: side by side.
        let (reviewed, mut found) = rayon::join(
            || review_fit(&review, &ladder),
            || findings(&review, markers),
        );
        found
            .implausible
            .extend(reviewed.equilibrium.no_equilibrium);
        Ok(MeasuredOutcome {
            refitted_lengths: found.refitted_lengths,
            rung,
            cross_validated_rows: ladder.judged_rows,
            ladder: ladder.reports,
            fitted: settled.fitted,
            frames_only: frames_only.clone(),
            model: settled.model,
            frames: found.frames,
            tree: frames.framed.clone(),
            sets: reviewed.figures.sets,
            sample_errors: reviewed.figures.sample_errors,
            weights: fits.weights,
            coverage: reviewed.coverage,
            range_folds: ladder.range_folds,
            training_ranges: reviewed.ranges,
            downweighted: bounded.downweighted.clone(),
            equilibrium_step_m: reviewed.equilibrium.step_m,
            equilibrium_refits: settled.equilibrium_refits,
            warnings: reviewed.warnings,
            implausible: found.implausible,
        })
    })
}

/// The cross-validated held-out error of each of `rungs` on the training rows, as the ladder
/// of [`calibrate_measured`] with `cfg.rung` `None` reports it (the same frames-only start,
/// Huber pass judged with the whole ladder's richest rung, folds and fits, so the same
/// figures), without fitting or cross-validating the ladder's other rungs nor settling and
/// reviewing the rung it would choose. Reports in ladder order; a rung the robot does not
/// carry, or the rows cannot fit, has none. The geometric baseline of a diagnosis reports its
/// kinematic rungs' errors so (`baseline.rs`).
///
/// # Errors
/// As [`calibrate_measured`]: too few training rows, a failed identification or
/// cross-validation of one of `rungs`.
pub fn ladder_heldout(
    robot: &Robot,
    train: &[MeasurementTable],
    test: &[MeasurementTable],
    cfg: &MeasuredConfig,
    rungs: &[ModelName],
) -> Result<Vec<RungReport>> {
    let cfg = &MeasuredConfig {
        rung: None,
        ..cfg.clone()
    };
    on_bounded_training(robot, train, cfg, None, |p| {
        let (all, levels) = &p.ladder_rungs;
        let (some, some_levels): (Vec<ModelName>, Vec<usize>) = (all.iter().zip(levels))
            .filter(|(r, _)| rungs.contains(r))
            .map(|(&r, &l)| (r, l))
            .unzip();
        if some.is_empty() {
            return Ok(Vec::new());
        }
        let (frames_model, frames_only) = &p.bounded.frames;
        let choice = climb(
            &p.fits,
            cfg,
            test,
            (frames_model, frames_only),
            p.done,
            &(some, some_levels),
            false,
        )?;
        Ok(choice.ladder.reports)
    })
}

/// What every fit after the frames-only one starts from ([`on_bounded_training`]).
struct Prepared<'a> {
    /// Training rows.
    n_rows: usize,
    /// The frames-only fit of the training rows as measured.
    frames: &'a FramesOnly,
    /// The fits on the training tables as the Huber loss sees them.
    fits: Fits<'a>,
    /// Those tables, the samples the loss bounded and the frames-only fit on them.
    bounded: &'a Bounded,
    /// The fits on every training row and the ladder's runs done beside the Huber pass
    /// ([`Done`]).
    done: Done,
    /// The torque equilibrium of the ladder head's fit, when it was worked out beside the
    /// Huber pass.
    equilibrium: Option<EarlyEquilibrium>,
    /// The rungs of the robot's ladder and their levels ([`ladder_of`]).
    ladder_rungs: (Vec<ModelName>, Vec<usize>),
}

/// `then` of the training rows `train` prepared for the ladder: checked, the weights and
/// frames-only fit ([`weighted_frames_only`]), the gross errors bounded by the Huber loss with
/// the richest rung `cfg` may fit ([`bounded_training`]). With `ladder_test` (the ladder of
/// every rung will be climbed on every training row, judged where the calibration is used
/// on those test tables), the head of its longest chain of nested rungs ([`ladder_head`]) is
/// fitted on every training row beside the Huber pass, on the rows as measured: when the
/// pass bounds nothing, the ladder's own fit of that rung would be the same fit (the same
/// rows, weights and start), and it is handed to the ladder ([`Done`]); else it is dropped
/// and the ladder fits the bounded rows. The Huber pass runs alone otherwise, with one core
/// of two idle at times (its row blocks are evaluated in parallel, its QR folds are not),
/// while that fit starts the ladder's critical path.
///
/// Once the pass is known to bound nothing, the ladder's runs need not wait for it
/// ([`EarlyLadder`]): the pass goes on to the runs of the chains the head does not start,
/// and the head's fit, when it ends after the pass, to the runs of its own chain (the
/// nested rungs' fits from its estimate, then the cross-validations) beside its torque
/// equilibrium. Each is what the ladder would work out itself, so the results are the same
/// whichever ends first; the core that idled while the head's fit ran now climbs the rest
/// of the ladder.
///
/// # Errors
/// As [`check_training_rows`], [`weighted_frames_only`], [`bounded_training`], or `then`'s.
fn on_bounded_training<T>(
    robot: &Robot,
    train: &[MeasurementTable],
    cfg: &MeasuredConfig,
    ladder_test: Option<&[MeasurementTable]>,
    then: impl FnOnce(Prepared<'_>) -> Result<T>,
) -> Result<T> {
    let n_rows = check_training_rows(train, cfg)?;
    let (frames, weights) = weighted_frames_only(robot, train, cfg, n_rows)?;
    let start_x = frames.fitted.x.clone();
    let start = Start {
        tree: &frames.framed,
        x: &start_x,
        nested: None,
        max_evaluations: cfg.max_evaluations,
    };
    let measured = Fits {
        robot: &frames.robot,
        start: &start,
        offsets: &frames.offsets,
        train: Training::measured(train),
        weights,
    };
    let ladder_rungs = ladder_of(&frames.robot);
    let richest = richest_rung(cfg, &ladder_rungs);
    let frames_fit = (frames.model.clone(), frames.fitted.clone());
    let lengths: Vec<usize> = train.iter().map(|t| t.rows.len()).collect();
    let beside = (ladder_test.is_some()
        && crate::fit::ladder_sample(&lengths, crate::fit::LADDER_ROWS).is_none())
    .then(|| ladder_head(&ladder_rungs.0))
    .flatten()
    .filter(|&r| r != richest);
    // With a rung fitted beside, the longest chain is the one it heads ([`ladder_head`]). The
    // Huber pass's fit is the ladder's fit of its rung and ends on the pass's core: nothing
    // starts early when a rung of the head's chain (which the head's core runs) is that rung.
    let chains = rung_chains(&rung_parents(&ladder_rungs.0));
    let pass_in_head_chain =
        (chains.first()).is_some_and(|c| c.iter().any(|&i| ladder_rungs.0[i] == richest));
    let early = (beside.zip(ladder_test))
        .filter(|_| !pass_in_head_chain)
        .map(|(_, test)| EarlyLadder {
            measured: &measured,
            cfg,
            rungs: &ladder_rungs.0,
            plan: FoldPlan::new(&measured, cfg, test),
            chains,
        });
    // Whether the Huber pass bounded nothing, once it is known.
    let nothing_bounded = std::sync::OnceLock::new();
    let ((bounded, runs), beside_fit) = rayon::join(
        || {
            let mut bounded = bounded_training(richest, &measured, train, frames_fit);
            let clean = matches!(&bounded, Ok(b) if b.samples.is_empty());
            let _ = nothing_bounded.set(clean);
            let runs = match (&mut bounded, &early) {
                (Ok(b), Some(early)) if clean => {
                    let done: DoneFits = b.richest_fit.take().into_iter().collect();
                    early.runs((&b.frames.0, &b.frames.1), false, done)
                }
                _ => Vec::new(),
            };
            (bounded, runs)
        },
        || {
            beside.map(|r| {
                let fit = measured.fit(r);
                let more = match (&fit, &early) {
                    (Ok((model, fitted)), Some(early)) if nothing_bounded.get() == Some(&true) => {
                        Some(rayon::join(
                            || {
                                let done = vec![(r, (model.clone(), fitted.clone()))];
                                early.runs((&frames.model, &frames.fitted), true, done)
                            },
                            || {
                                let settled =
                                    equilibrate_fit(&measured, r, model.clone(), fitted.clone());
                                (r, fitted.x.clone(), settled)
                            },
                        ))
                    }
                    _ => None,
                };
                (r, fit, more)
            })
        },
    );
    let mut bounded = bounded?;
    let mut done = Done {
        fits: bounded.richest_fit.take().into_iter().collect(),
        runs,
    };
    let mut equilibrium = None;
    // A failed fit is the ladder's to report, as it would be without this one.
    if let Some((r, Ok(f), more)) = beside_fit
        && bounded.samples.is_empty()
    {
        done.fits.push((r, f));
        if let Some((runs, settled)) = more {
            done.runs.extend(runs);
            equilibrium = Some(settled);
        }
    }
    then(Prepared {
        n_rows,
        frames: &frames,
        fits: Fits {
            train: Training::with_bounded(train, &bounded.samples),
            ..measured
        },
        bounded: &bounded,
        done,
        equilibrium,
        ladder_rungs,
    })
}

/// The ladder's runs on the training rows as measured, worked out before the Huber pass's
/// judgement is taken ([`on_bounded_training`]): what the ladder would work out itself when
/// the pass bounds nothing (the same rows, weights, starts and folds).
struct EarlyLadder<'a> {
    /// The fits on the training rows as measured.
    measured: &'a Fits<'a>,
    cfg: &'a MeasuredConfig,
    /// The ladder's rungs ([`ladder_of`]).
    rungs: &'a [ModelName],
    /// Where the rungs are judged, on the test tables.
    plan: FoldPlan,
    /// The ladder's chains ([`rung_chains`]), the one the rung fitted beside the Huber pass
    /// heads first ([`ladder_head`]).
    chains: Vec<Vec<usize>>,
}

impl EarlyLadder<'_> {
    /// With `of_head`, the runs of the chain the head starts, else those of every other
    /// chain; from the frames-only fit `frames` and the fits `done`.
    fn runs(
        &self,
        frames: (&CalibratedModel, &Fitted),
        of_head: bool,
        done: DoneFits,
    ) -> Vec<(usize, Run)> {
        let runs = LadderRuns::new(
            self.measured,
            self.cfg,
            self.rungs,
            &self.plan,
            frames,
            done,
        );
        let (head, others) = self.chains.split_at(1.min(self.chains.len()));
        chain_runs(&runs, if of_head { head } else { others })
    }
}

/// The training rows of `train`, when they are enough for `cfg.folds`-fold cross-validation.
///
/// # Errors
/// No training row, a single one, or fewer rows than folds (or fewer than 2 folds).
fn check_training_rows(train: &[MeasurementTable], cfg: &MeasuredConfig) -> Result<usize> {
    let n_rows: usize = train.iter().map(|t| t.rows.len()).sum();
    if n_rows == 0 {
        bail!("the training files have no row");
    }
    if n_rows < 2 {
        bail!(
            "the training files have 1 row: cross-validation needs at least 2 (with --test-last, \
             hold out a smaller share)"
        );
    }
    if cfg.folds < 2 || cfg.folds > n_rows {
        // The row count is the problem as often as the flag (the default is 5 folds).
        let files: Vec<String> = (train.iter())
            .map(|t| format!("{}: {} rows", t.name, t.rows.len()))
            .collect();
        bail!(
            "{n_rows} training rows ({}) are too few for {k}-fold cross-validation (--folds {k}): \
             it holds out one block of rows per fold and needs at least {k} training rows; \
             measure at least {k} configurations, or give --folds between 2 and {n_rows}",
            files.join(", "),
            k = cfg.folds
        );
    }
    Ok(n_rows)
}

/// The frames-only fit of `train` ([`frames_only`]) at the weights every later fit uses: the
/// σ given, or the RMS of each residual group after a frames-only fit at unit weights, the
/// fit redone at them when they changed. `n_rows`: the training rows.
///
/// # Errors
/// As [`frames_only`]; too few distinct configurations for the frames.
fn weighted_frames_only(
    robot: &Robot,
    train: &[MeasurementTable],
    cfg: &MeasuredConfig,
    n_rows: usize,
) -> Result<(FramesOnly, Weights)> {
    // Weights: given, or the RMS of each residual group after a frames-only fit at unit weights.
    let initial_weights = Weights {
        sigma_position_m: cfg.sigma_m.unwrap_or(1e-3),
        sigma_distance_m: cfg.sigma_m.unwrap_or(1e-3),
        sigma_orientation_rad: cfg.sigma_rad.unwrap_or(1e-2),
        ..Weights::default()
    };
    let unweighted = frames_only(robot, train, cfg, initial_weights)?;
    check_distinct_configurations(train, n_rows, &unweighted.fitted)?;
    let (weights, reweighted) = estimated_weights(cfg, &unweighted.model, train, initial_weights);
    // Weights move a frames-only estimate only when they balance residuals of two kinds, but
    // they always scale its σ and covariance: the fit at the unit weights is redone at the
    // estimated ones whenever they changed (position-only data printed σ²/1 mm before).
    let weights_changed = weights != initial_weights;
    if !(reweighted || weights_changed) {
        return Ok((unweighted, weights));
    }
    let (model, fitted) = fit(
        ModelName::FramesOnly,
        &unweighted.robot,
        &Start {
            tree: &unweighted.framed,
            x: &unweighted.fitted.x,
            nested: None,
            max_evaluations: None,
        },
        &unweighted.offsets,
        Training::measured(train),
        weights,
        &|_, _| true,
    )?;
    Ok((
        FramesOnly {
            model,
            fitted,
            ..unweighted
        },
        weights,
    ))
}

/// Repeated configurations add residuals but no information: the distinct ones of `train`
/// must determine the frames of `frames_only` (its fit) with some redundancy, or σ (and every
/// standard deviation) is zero.
///
/// # Errors
/// Too few distinct configurations.
fn check_distinct_configurations(
    train: &[MeasurementTable],
    n_rows: usize,
    frames_only: &Fitted,
) -> Result<()> {
    let n_residuals = frames_only.identified.n_residuals;
    let per_configuration = n_residuals as f64 / n_rows as f64;
    let n_kept = frames_only.identified.identifiability.kept.len();
    let enough = |n_distinct: usize| (n_distinct as f64) * per_configuration > n_kept as f64;
    // Counted until there are enough: each row is compared with the few distinct ones before
    // it, so a file of a million rows costs a million short scans, not a million squared.
    let mut distinct: Vec<&[f64]> = Vec::new();
    for row in train.iter().flat_map(|t| &t.rows) {
        if enough(distinct.len()) {
            return Ok(());
        }
        if !distinct.contains(&&row.q[..]) {
            distinct.push(&row.q);
        }
    }
    if !enough(distinct.len()) {
        bail!(
            "the training data hold {} distinct joint configurations ({n_rows} rows), about {:.0} \
             independent residuals, not more than the {n_kept} frame parameters: record the \
             markers in more configurations",
            distinct.len(),
            distinct.len() as f64 * per_configuration
        );
    }
    Ok(())
}

/// The weights of `cfg`'s σ, each missing one the RMS of its residual group under the
/// frames-only model `m0` (`weights` otherwise), and whether they balance residuals of two
/// kinds (so that they move a frames-only estimate).
fn estimated_weights(
    cfg: &MeasuredConfig,
    m0: &CalibratedModel,
    train: &[MeasurementTable],
    mut weights: Weights,
) -> (Weights, bool) {
    if cfg.sigma_m.is_some() && cfg.sigma_rad.is_some() {
        return (weights, false);
    }
    let (mut pos, mut rot, mut dist) = (Vec::new(), Vec::new(), Vec::new());
    for ti in 0..train.len() {
        let e = errors(m0, Training::measured(train), ti, None);
        pos.extend(e.position);
        rot.extend(e.orientation);
        dist.extend(e.distance);
    }
    // Per axis: a 3-D error of RMS e has about e/√3 per axis.
    let (_, pos_rms, _) = stats(&pos);
    let (_, rot_rms, _) = stats(&rot);
    let (_, dist_rms, _) = stats(&dist);
    if cfg.sigma_m.is_none() && pos_rms > 0.0 {
        weights.sigma_position_m = pos_rms / 3f64.sqrt();
    }
    if cfg.sigma_m.is_none() && dist_rms > 0.0 {
        weights.sigma_distance_m = dist_rms;
    }
    if cfg.sigma_rad.is_none() && rot_rms > 0.0 {
        weights.sigma_orientation_rad = rot_rms / 3f64.sqrt();
    }
    // Weights move a frames-only estimate only when they balance residuals of two kinds.
    let kinds =
        [&pos, &dist].iter().filter(|v| !v.is_empty()).count() + usize::from(!rot.is_empty());
    (weights, kinds > 1)
}

/// What every fit after the frames-only one shares: the robot with joint offsets, where the
/// fits start, its joint-offset parameters, the training tables it fits and the weights.
#[derive(Clone, Copy)]
struct Fits<'a> {
    robot: &'a Robot,
    start: &'a Start<'a>,
    offsets: &'a [Option<usize>],
    train: Training<'a>,
    weights: Weights,
}

impl Fits<'_> {
    /// `rung` fitted on every training row from `start` ([`fit`]).
    fn fit_from(&self, rung: ModelName, start: &Start<'_>) -> Result<(CalibratedModel, Fitted)> {
        let all = |_: usize, _: usize| true;
        fit(
            rung,
            self.robot,
            start,
            self.offsets,
            self.train,
            self.weights,
            &all,
        )
    }

    /// `rung` fitted on every training row from the shared start.
    fn fit(&self, rung: ModelName) -> Result<(CalibratedModel, Fitted)> {
        self.fit_from(rung, self.start)
    }

    /// What a refit of `rung` needs ([`mounting_test`], [`plausibility`]).
    fn refit(&self, rung: ModelName) -> Refit<'_> {
        Refit {
            rung,
            robot: self.robot,
            start: self.start,
            offsets: self.offsets,
            train: self.train,
            weights: self.weights,
        }
    }
}

/// The richest rung: the one given, or the first alternative of the ladder's top level
/// (`ladder`: rungs and levels, [`ladder_of`]).
fn richest_rung(cfg: &MeasuredConfig, ladder: &(Vec<ModelName>, Vec<usize>)) -> ModelName {
    let (ladder_rungs, ladder_levels) = ladder;
    let top = ladder_levels.iter().copied().max().unwrap_or(0);
    cfg.rung.unwrap_or_else(|| {
        (ladder_rungs.iter().zip(ladder_levels))
            .find(|&(_, &l)| l == top)
            .map_or(ModelName::Geometric, |(&r, _)| r)
    })
}

/// The samples the Huber loss bounded in the training tables ([`bounded_training`]), with the
/// frames-only fit on the tables as it sees them.
struct Bounded {
    /// The bounded samples at their bounded positions, sorted by place (none when nothing
    /// was bounded): the training tables are read through them ([`Training`]), not copied.
    samples: Vec<BoundedSample>,
    /// The samples the Huber loss bounded, file order.
    downweighted: Vec<Downweighted>,
    /// The rung the Huber loss was evaluated with and its fit, when it bounded nothing.
    richest_fit: Option<(ModelName, (CalibratedModel, Fitted))>,
    /// The rung the Huber loss was evaluated with.
    judge: ModelName,
    /// The frames-only model and identification on the training tables with `samples`
    /// bounded.
    frames: (CalibratedModel, Fitted),
}

/// Gross errors bounded by the Huber loss ([`winsorize`], evaluated with `richest`): every fit
/// after it sees the winsorized samples; the figures are of the data as measured. The
/// frames-only fit `frames` is redone on the winsorized tables when a sample was bounded.
/// `train`: the training tables of `measured`, as measured.
///
/// # Errors
/// A failed identification.
fn bounded_training(
    richest: ModelName,
    measured: &Fits<'_>,
    train: &[MeasurementTable],
    frames: (CalibratedModel, Fitted),
) -> Result<Bounded> {
    let (samples, downweighted, richest_fit, judge) = winsorize(
        richest,
        measured.robot,
        measured.start,
        measured.offsets,
        train,
        measured.weights,
    )?;
    let frames = if downweighted.is_empty() {
        frames
    } else {
        Fits {
            train: Training::with_bounded(train, &samples),
            ..*measured
        }
        .fit(ModelName::FramesOnly)?
    };
    Ok(Bounded {
        samples,
        downweighted,
        richest_fit,
        judge,
        frames,
    })
}

/// What the ladder left out, and why ([`ladder_warnings`]).
#[derive(Default)]
struct LeftOut {
    /// Rungs the training rows cannot fit.
    untried: Vec<Untried>,
    /// Rungs of the ladder whose fit on every training row did not converge, with that fit.
    unconverged: Vec<(ModelName, hapcal_identify::Fit)>,
    /// Why the ladder left out the rung that predicted best.
    notes: Vec<String>,
}

/// The ladder that chose a rung (empty when the rung was given).
#[derive(Default)]
struct LadderOutcome {
    /// Cross-validation scores, simplest rung first.
    reports: Vec<RungReport>,
    /// The joint-range folds the ladder judged extrapolation by.
    range_folds: Vec<RangeFold>,
    /// The rungs the joint-range folds stopped.
    range_stops: Vec<RangeStop>,
    left_out: LeftOut,
    /// The training rows judged, when a sample of them was ([`crate::fit::ladder_sample`]).
    judged_rows: Option<usize>,
}

/// The rung chosen (or given), its fit on every training row, and the ladder that chose it.
struct Choice {
    rung: ModelName,
    /// The chosen rung's model and identification.
    chosen: (CalibratedModel, Fitted),
    ladder: LadderOutcome,
}

/// The rung given in `cfg` fitted on every training row (its fit in `done` when there is
/// one, `frames` for frames only), or the rung chosen on the ladder ([`climb_ladder`]).
///
/// # Errors
/// A failed identification.
fn choose_rung(
    fits: &Fits<'_>,
    cfg: &MeasuredConfig,
    test: &[MeasurementTable],
    frames: (&CalibratedModel, &Fitted),
    done: Done,
    ladder: &(Vec<ModelName>, Vec<usize>),
) -> Result<Choice> {
    let Some(rung) = cfg.rung else {
        return climb(fits, cfg, test, frames, done, ladder, true);
    };
    Ok(Choice {
        rung,
        chosen: fit_on_every_row(fits, rung, frames, done.fits)?,
        ladder: LadderOutcome::default(),
    })
}

/// The rung chosen on the ladder `ladder` ([`climb_ladder`]), judged on a sample of the
/// training rows of a long recording ([`climb_sample`]); `refit_sampled`: the rung chosen on
/// a sample then fitted on every training row (its fit in `done` when there is one), else
/// its fit on the sample is returned.
///
/// # Errors
/// As [`climb_ladder`]; a failed identification on every row.
fn climb(
    fits: &Fits<'_>,
    cfg: &MeasuredConfig,
    test: &[MeasurementTable],
    frames: (&CalibratedModel, &Fitted),
    done: Done,
    ladder: &(Vec<ModelName>, Vec<usize>),
    refit_sampled: bool,
) -> Result<Choice> {
    let lengths: Vec<usize> = fits.train.tables.iter().map(|t| t.rows.len()).collect();
    let Some(sample) = crate::fit::ladder_sample(&lengths, crate::fit::LADDER_ROWS) else {
        return climb_ladder(fits, cfg, test, frames, done, ladder);
    };
    let mut choice = climb_sample(fits, cfg, test, ladder, &sample)?;
    if refit_sampled {
        choice.chosen = fit_on_every_row(fits, choice.rung, frames, done.fits)?;
    }
    Ok(choice)
}

/// `rung` fitted on every training row: `frames` for frames only, its fit in `done` when
/// there is one, else a new fit.
///
/// # Errors
/// A failed identification.
fn fit_on_every_row(
    fits: &Fits<'_>,
    rung: ModelName,
    frames: (&CalibratedModel, &Fitted),
    mut done: DoneFits,
) -> Result<(CalibratedModel, Fitted)> {
    if rung == ModelName::FramesOnly {
        return Ok((frames.0.clone(), frames.1.clone()));
    }
    match done.iter().position(|(used, _)| *used == rung) {
        Some(k) => Ok(done.swap_remove(k).1),
        None => fits.fit(rung),
    }
}

/// The rung chosen on the ladder of a long recording: the ladder ([`climb_ladder`]) judged on
/// the training rows `sample` keeps (every `s`-th row of each table, their frames-only fit
/// the sample's own), with the chosen rung's fit on the sample ([`climb`] fits it on every
/// training row). The choice needs far fewer rows than the parameters' precision
/// (docs/engine.md, "Long logs"); the ladder's reports are those of the sample.
///
/// # Errors
/// As [`climb_ladder`].
fn climb_sample(
    fits: &Fits<'_>,
    cfg: &MeasuredConfig,
    test: &[MeasurementTable],
    ladder: &(Vec<ModelName>, Vec<usize>),
    sample: &crate::fit::LadderSample,
) -> Result<Choice> {
    let sampled: Vec<MeasurementTable> = (fits.train.tables.iter().enumerate())
        .map(|(ti, t)| MeasurementTable {
            name: t.name.clone(),
            path: t.path.clone(),
            rows: (fits.train.rows(ti))
                .step_by(sample.stride)
                .map(std::borrow::Cow::into_owned)
                .collect(),
            warnings: Vec::new(),
            n_markers: t.n_markers,
            has_orientation: t.has_orientation,
            has_distance: t.has_distance,
            ignored_columns: Vec::new(),
        })
        .collect();
    let on_sample = Fits {
        train: Training::measured(&sampled),
        ..*fits
    };
    let (sample_model, sample_frames) = on_sample.fit(ModelName::FramesOnly)?;
    let mut choice = climb_ladder(
        &on_sample,
        cfg,
        test,
        (&sample_model, &sample_frames),
        Done::default(),
        ladder,
    )?;
    drop(sampled);
    choice.ladder.judged_rows = Some(sample.rows.len());
    Ok(choice)
}

/// The rung chosen on the ladder (`ladder`: rungs and levels): each rung fitted and
/// cross-validated ([`ladder_runs`]), the rungs the rows cannot fit left out, and the ladder
/// climbed ([`climb_tried`]).
///
/// # Errors
/// A failed identification or cross-validation; rows that cannot fit frames only.
fn climb_ladder(
    fits: &Fits<'_>,
    cfg: &MeasuredConfig,
    test: &[MeasurementTable],
    frames: (&CalibratedModel, &Fitted),
    done: Done,
    (rungs, levels): &(Vec<ModelName>, Vec<usize>),
) -> Result<Choice> {
    let plan = FoldPlan::new(fits, cfg, test);
    let runs = ladder_runs(
        &LadderRuns::new(fits, cfg, rungs, &plan, frames, done.fits),
        done.runs,
    );
    let ranges = plan.ranges;
    let mut left_out = LeftOut::default();
    let tried = sort_runs(runs, rungs, &mut left_out)?;
    let tried_rungs: Vec<ModelName> = tried.index.iter().map(|&i| rungs[i]).collect();
    let tried_levels: Vec<usize> = tried.index.iter().map(|&i| levels[i]).collect();
    let evidence = RangeEvidence::new(&ranges, fits.train.tables, &tried.scores);
    let judge = LadderJudge {
        rungs: &tried_rungs,
        levels: &tried_levels,
        scores: &tried.scores,
        evidence: &evidence,
        stops: std::cell::RefCell::new(Vec::new()),
    };
    let mut ladder = ladder_reports(&judge);
    let (chosen, negative) = climb_tried(&judge, fits, &tried.fits);
    for (i, words) in &negative {
        left_out.notes.push(format!(
            "the {} model predicted the held-out rows best but was left out: its \
             compliances are negative ({words}) and no mounting explains them (it \
             absorbs an effect it lacks); the ladder keeps the {} model",
            tried_rungs[*i], tried_rungs[chosen]
        ));
    }
    for (i, report) in ladder.iter_mut().enumerate() {
        report.nested = (0..tried_rungs.len()).find_map(|j| {
            let (difference, beats) = judge.nested_difference(i, j)?;
            Some(crate::report::NestedComparison {
                contains: tried_rungs[j],
                difference,
                beats,
            })
        });
    }
    let mut fits_tried = tried.fits;
    Ok(Choice {
        rung: tried_rungs[chosen],
        chosen: fits_tried.swap_remove(chosen),
        ladder: LadderOutcome {
            reports: ladder,
            range_folds: ranges.into_iter().map(|r| r.report).collect(),
            range_stops: judge.stops.into_inner(),
            left_out,
            judged_rows: None,
        },
    })
}

/// A rung of the ladder fitted on every training row, or why it was not tried: a rung whose
/// fit on every training row has fewer residuals than parameters, or whose refit on some
/// fold's training rows would, is not tried (`Err`); its fit on every row, if any, still
/// starts the rungs that nest it.
type Tried = std::result::Result<(CalibratedModel, Fitted), (Untried, Option<Fitted>)>;

/// Per rung: its fit (or why it was not tried) and, when tried, its cross-validation.
type Run = (Result<Tried>, Option<Result<Scores>>);

/// The folds besides the blocked ones and what the blocked ones allow: the joint-range folds
/// on the sides where the calibration will be used beyond its training range (the test rows
/// and the workspace given), and the fewest residuals a blocked fold trains on (a rung
/// keeping more parameters on every row cannot be refitted on that fold), with its rows.
struct FoldPlan {
    ranges: Vec<RangeSplit>,
    fold_residuals: usize,
    fold_rows: usize,
}

impl FoldPlan {
    /// The plan of the training rows of `fits`, `cfg.folds` blocked folds, used on `test`
    /// and `cfg.workspace`.
    fn new(fits: &Fits<'_>, cfg: &MeasuredConfig, test: &[MeasurementTable]) -> Self {
        let beyond: Vec<&[f64]> = (test.iter().flat_map(|t| &t.rows))
            .map(|r| &r.q[..])
            .chain(cfg.workspace.iter().map(Vec::as_slice))
            .collect();
        let ranges = range_folds(fits.robot, fits.train.tables, &beyond);
        let (fold_residuals, fold_rows) = fewest_fold_residuals(fits.train, cfg.folds);
        FoldPlan {
            ranges,
            fold_residuals,
            fold_rows,
        }
    }
}

/// What fitting and cross-validating the ladder's rungs share ([`ladder_runs`]).
struct LadderRuns<'a> {
    fits: &'a Fits<'a>,
    cfg: &'a MeasuredConfig,
    rungs: &'a [ModelName],
    /// Per rung, the rung it starts from ([`nested_in`]), by index.
    parent: Vec<Option<usize>>,
    /// The joint-range folds the rungs are cross-validated on too.
    ranges: &'a [RangeSplit],
    /// The frames-only model and identification (the ladder's foot, fitted already).
    frames: (&'a CalibratedModel, &'a Fitted),
    /// The fits done before the ladder ([`DoneFits`]), each taken by its rung.
    cached: std::sync::Mutex<DoneFits>,
    /// The fewest residuals a blocked fold trains on, and its training rows.
    fold_residuals: usize,
    fold_rows: usize,
}

impl<'a> LadderRuns<'a> {
    /// The runs of `rungs` on the training rows of `fits`, judged by `plan`, from the
    /// frames-only fit `frames` and the fits `done` already.
    fn new(
        fits: &'a Fits<'a>,
        cfg: &'a MeasuredConfig,
        rungs: &'a [ModelName],
        plan: &'a FoldPlan,
        frames: (&'a CalibratedModel, &'a Fitted),
        done: DoneFits,
    ) -> Self {
        LadderRuns {
            fits,
            cfg,
            rungs,
            parent: rung_parents(rungs),
            ranges: &plan.ranges,
            frames,
            cached: std::sync::Mutex::new(done),
            fold_residuals: plan.fold_residuals,
            fold_rows: plan.fold_rows,
        }
    }

    /// Rung `r` fitted on every training row (from the estimate of the rung it nests, if
    /// any): frames only and the rungs of [`DoneFits`] are fitted already.
    fn full_fit(&self, r: ModelName, nested: Option<&Fitted>) -> Result<(CalibratedModel, Fitted)> {
        let f = if r == ModelName::FramesOnly {
            (self.frames.0.clone(), self.frames.1.clone())
        } else if let Some((_, f)) = (self.cached.lock().ok()).and_then(|mut c| {
            let k = c.iter().position(|(used, _)| *used == r)?;
            Some(c.swap_remove(k))
        }) {
            f
        } else {
            let start = Start {
                nested,
                ..*self.fits.start
            };
            self.fits.fit_from(r, &start)?
        };
        Ok(f)
    }

    /// Rung `i` fitted on every training row, or why it is not tried ([`Tried`]).
    fn try_rung(&self, i: usize, nested: Option<&Fitted>) -> Result<Tried> {
        let (model, fitted) = match self.full_fit(self.rungs[i], nested) {
            Ok(f) => f,
            Err(e) => {
                let Some((n_residuals, n_params)) = too_few_residuals(&e) else {
                    return Err(e);
                };
                let untried = Untried {
                    rung: self.rungs[i],
                    n_residuals,
                    n_params,
                    fold_rows: None,
                };
                return Ok(Err((untried, None)));
            }
        };
        let n_params = fitted.identified.identifiability.kept.len();
        if self.fold_residuals < n_params {
            let untried = Untried {
                rung: self.rungs[i],
                n_residuals: self.fold_residuals,
                n_params,
                fold_rows: Some(self.fold_rows),
            };
            return Ok(Err((untried, Some(fitted))));
        }
        Ok(Ok((model, fitted)))
    }

    /// The runs of one chain of nested rungs ([`rung_chains`]), in chain order: fits in
    /// nesting order (a rung whose parent has no fit starts from the frames-only estimate),
    /// each rung's cross-validation offered to an idle core beside the fits after it (they
    /// start from its estimate, not its folds'); a core that finds none idle runs it after
    /// them, the last fitted first (the nested rungs are the slowest).
    fn run_chain(&self, chain: &[usize]) -> Vec<(usize, Run)> {
        self.run_rest(chain, &[])
    }

    /// The runs of `chain` after the rungs fitted already, `before` (rung index and fit).
    fn run_rest(&self, chain: &[usize], before: &[(usize, &Fitted)]) -> Vec<(usize, Run)> {
        let Some((&i, rest)) = chain.split_first() else {
            return Vec::new();
        };
        let nested = (self.parent[i])
            .and_then(|p| before.iter().find(|(k, _)| *k == p))
            .map(|(_, f)| *f);
        let tried = self.try_rung(i, nested);
        let mut fitted = before.to_vec();
        if let Ok(Ok((_, f)) | Err((_, Some(f)))) = &tried {
            fitted.push((i, f));
        }
        let (mut out, scores) = rayon::join(
            || self.run_rest(rest, &fitted),
            || match &tried {
                Ok(Ok((_, f))) => Some(cross_validate(
                    self.rungs[i],
                    self.fits.robot,
                    self.fits.start.tree,
                    &Warm::of(f),
                    self.fits.train,
                    self.cfg,
                    self.fits.weights,
                    self.ranges,
                )),
                _ => None,
            },
        );
        drop(fitted);
        out.insert(0, (i, (tried, scores)));
        out
    }
}

/// Each rung fitted on every training row (the one the Huber pass fitted already was, when
/// it bounded nothing), then cross-validated from its estimate; per rung of the ladder, its
/// run. A rung that nests another ([`nested_in`]) starts from its estimate, the others from
/// the frames-only one: each chain of nested rungs is one task (its fits in order, then its
/// cross-validations, the nested rung's first), the chains in parallel, the longest first.
/// The fits of one rung do not wait for another chain's, so no core idles while a nested
/// rung is fitted (on two cores the per-axis transversal compliance fit, the ladder's
/// slowest, ran alone before).
/// The chains of `done` were run before the ladder ([`Done`]): they are taken as they are.
fn ladder_runs(runs: &LadderRuns<'_>, done: Vec<(usize, Run)>) -> Vec<Option<Run>> {
    let mut out: Vec<Option<Run>> = (0..runs.rungs.len()).map(|_| None).collect();
    for (i, run) in done {
        out[i] = Some(run);
    }
    let chains: Vec<Vec<usize>> = (rung_chains(&runs.parent).into_iter())
        .filter(|c| c.iter().any(|&i| out[i].is_none()))
        .collect();
    for (i, run) in chain_runs(runs, &chains) {
        out[i] = Some(run);
    }
    out
}

/// The runs of the ladder's chains `chains` ([`LadderRuns::run_chain`]), the chains in
/// parallel, by rung index.
fn chain_runs(runs: &LadderRuns<'_>, chains: &[Vec<usize>]) -> Vec<(usize, Run)> {
    use rayon::prelude::*;
    (chains.par_iter())
        .map(|c| runs.run_chain(c))
        .flatten()
        .collect()
}

/// The rungs of the ladder tried, in ladder order: their indices, fits on every training row
/// and cross-validation scores.
struct TriedRungs {
    index: Vec<usize>,
    fits: Vec<(CalibratedModel, Fitted)>,
    scores: Vec<Scores>,
}

/// The rungs of `runs` tried, the others in `left_out` (not tried, or unconverged).
///
/// # Errors
/// A failed fit first (in ladder order), then the ladder's foot not tried, then a failed
/// cross-validation.
fn sort_runs(
    runs: Vec<Option<Run>>,
    rungs: &[ModelName],
    left_out: &mut LeftOut,
) -> Result<TriedRungs> {
    let mut tried = Vec::new();
    let mut tried_fits = Vec::new();
    let mut tried_scores = Vec::new();
    for (i, (fit, scores)) in
        (runs.into_iter().enumerate()).filter_map(|(i, run)| run.map(|run| (i, run)))
    {
        match fit? {
            // An unconverged fit is never a result: the rung is left out (frames only,
            // the ladder's foot, stays; an unconverged final fit is a finding).
            Ok((_, f)) if i > 0 && !f.identified.fit.termination.is_success() => {
                left_out
                    .unconverged
                    .push((rungs[i], f.identified.fit.clone()));
            }
            Ok(f) => {
                tried.push(i);
                tried_fits.push(f);
                tried_scores.push(scores);
            }
            Err((u, _)) => left_out.untried.push(u),
        }
    }
    // Frames only is the ladder's foot: without it nothing can be compared.
    if tried.first() != Some(&0) {
        let reason = (left_out.untried.first()).map_or_else(String::new, Untried::reason);
        bail!(
            "the training rows cannot determine even the {} model ({reason}): record \
             more configurations",
            ModelName::FramesOnly
        );
    }
    let scores: Vec<Scores> = (tried_scores.into_iter())
        .map(|s| s.unwrap_or_else(|| bail!("a tried rung was not cross-validated")))
        .collect::<Result<_>>()?;
    Ok(TriedRungs {
        index: tried,
        fits: tried_fits,
        scores,
    })
}

/// Held-out RMS position error of `h`, m.
fn heldout_rms(h: &HeldOut) -> f64 {
    (h.sq_errors.iter().sum::<f64>() / h.sq_errors.len().max(1) as f64).sqrt()
}

/// The comparisons of the tried rungs ([`climb_tried`]): their cross-validation scores and
/// joint-range evidence, with the rungs the joint-range folds stopped.
struct LadderJudge<'a> {
    rungs: &'a [ModelName],
    levels: &'a [usize],
    scores: &'a [Scores],
    evidence: &'a RangeEvidence,
    /// Each rung the joint-range folds stopped in the last climb.
    stops: std::cell::RefCell<Vec<RangeStop>>,
}

impl LadderJudge<'_> {
    /// The one rule of every workflow (crate::model::climb): rung `i` must beat rung `j`
    /// (the one chosen so far) by LADDER_SIGNIFICANCE_Z blocked standard errors and, where
    /// the calibration will be used beyond its training range, pass the joint-range folds
    /// (RangeVerdict::allows). Each rung the folds stop is recorded.
    fn beats(&self, i: usize, j: usize) -> bool {
        let scores = self.scores;
        let (d, se) = blocked_difference(&scores[i].score, &scores[j].score);
        if i == j || d + crate::model::LADDER_SIGNIFICANCE_Z * se >= 0.0 {
            return false;
        }
        let verdict = self.evidence.judge(i, j);
        let allowed = self.evidence.is_empty() || verdict.allows();
        if !allowed {
            self.stops.borrow_mut().push(RangeStop {
                rung: self.rungs[i],
                compared_with: self.rungs[j],
                range_difference: verdict.predicted,
                range_growth: verdict.growth,
                judged: verdict.judged,
            });
        }
        allowed
    }

    /// Parsimony within a level: whether rung `i` contains another alternative `j` of its
    /// level (per-axis transversal compliance holds the isotropic one), which it must beat
    /// too, on the blocked folds (crate::model::climb).
    fn contains(&self, i: usize, j: usize) -> bool {
        i != j && self.levels[i] == self.levels[j] && self.rungs[i].contains(self.rungs[j])
    }

    /// When rung `i` contains rung `j`: their blocked difference and whether `i` beats `j`.
    fn nested_difference(&self, i: usize, j: usize) -> Option<((f64, f64), bool)> {
        self.contains(i, j).then(|| {
            let (d, se) = blocked_difference(&self.scores[i].score, &self.scores[j].score);
            ((d, se), d + crate::model::LADDER_SIGNIFICANCE_Z * se < 0.0)
        })
    }
}

/// The ladder's report of each tried rung (`nested` and `n_kept` filled later).
fn ladder_reports(judge: &LadderJudge<'_>) -> Vec<RungReport> {
    let (scores, evidence) = (judge.scores, judge.evidence);
    let mut ladder = Vec::new();
    for (i, r) in judge.rungs.iter().enumerate() {
        let to_frames = blocked_difference(&scores[i].score, &scores[0].score);
        ladder.push(RungReport {
            rung: *r,
            heldout_rms_m: heldout_rms(&scores[i].squared),
            score_difference_to_frames: if i == 0 { (0.0, 0.0) } else { to_frames },
            range_rms_m: evidence.rms_m(i),
            range_difference_to_frames: evidence.mean_difference(i, 0),
            range_predicted_to_frames: evidence.judge(i, 0).predicted,
            nested: None,
            n_kept: 0,
        });
    }
    ladder
}

/// The tried rung the ladder climbs to ([`crate::model::climb`]), with the rungs left out
/// on the way and the words of their compliances. A chosen rung whose compliances no real
/// robot has (below zero beyond the bound) and no other mounting explains is never the
/// result: the ladder keeps the best of the others, and says why. Negative compliances
/// another mounting explains stay, for the check after the fit to name the mounting.
fn climb_tried(
    judge: &LadderJudge<'_>,
    fits: &Fits<'_>,
    tried_fits: &[(CalibratedModel, Fitted)],
) -> (usize, Vec<(usize, String)>) {
    let unit = compliance_unit_of(fits.robot);
    let mut left_out: Vec<(usize, String)> = Vec::new();
    let chosen = loop {
        judge.stops.borrow_mut().clear();
        let allowed =
            |i: usize, j: usize| left_out.iter().all(|(k, _)| *k != i) && judge.beats(i, j);
        // A contained rung left out (negative compliances) no longer holds the richer
        // one back.
        let beats_contained = |i: usize, j: usize| {
            if left_out.iter().any(|(k, _)| *k == j) {
                return None;
            }
            judge.nested_difference(i, j).map(|(_, b)| b)
        };
        let chosen = crate::model::climb(
            judge.levels,
            &allowed,
            &|i| heldout_rms(&judge.scores[i].squared),
            &beats_contained,
        );
        let (chosen_model, chosen_fit) = &tried_fits[chosen];
        let (negative, n_compliances) =
            crate::fit::negative_compliances(&chosen_fit.identified, 1.0);
        if chosen == 0 || negative.is_empty() {
            break chosen;
        }
        let refit = fits.refit(judge.rungs[chosen]);
        let (_, given_rms, _) = stats(&training_position_errors(chosen_model, fits.train));
        if negative.len() >= 2 && mounting_test(&refit, given_rms).is_some() {
            break chosen;
        }
        left_out.push((
            chosen,
            crate::fit::negative_compliance_words(&negative, n_compliances, unit),
        ));
    };
    (chosen, left_out)
}

/// [`equilibrate`] of `rung`'s fit `(model, fitted)` on the training rows of `fits`.
///
/// # Errors
/// As [`equilibrate`].
fn equilibrate_fit(
    fits: &Fits<'_>,
    rung: ModelName,
    model: CalibratedModel,
    fitted: Fitted,
) -> Result<(CalibratedModel, Fitted, usize)> {
    equilibrate(
        rung,
        fits.robot,
        fits.start.tree,
        fits.offsets,
        fits.train,
        fits.weights,
        model,
        fitted,
    )
}

/// The chosen rung at its torque equilibrium ([`settle`]).
struct Settled {
    model: CalibratedModel,
    fitted: Fitted,
    /// Refits [`equilibrate`] made.
    equilibrium_refits: usize,
    /// Kinematic parameters kept (not the frames').
    n_kept: usize,
}

/// The torque equilibrium of the chosen rung ([`equilibrate`]): where the deflection changes
/// the loads by more than the noise can show, the loads are re-evaluated at the deflected
/// robot and the rung refitted; `early`, that equilibrium of the same fit worked out already
/// (beside the ladder), is taken as it is. Its kinematic parameters kept go into its `ladder`
/// report.
///
/// # Errors
/// A failed identification.
fn settle(
    fits: &Fits<'_>,
    rung: ModelName,
    (model, fitted): (CalibratedModel, Fitted),
    early: Option<Result<(CalibratedModel, Fitted, usize)>>,
    ladder: &mut [RungReport],
) -> Result<Settled> {
    let (model, fitted, equilibrium_refits) =
        early.unwrap_or_else(|| equilibrate_fit(fits, rung, model, fitted))?;
    let n_kept = (fitted.identified.identifiability.kept.iter())
        .filter(|&&i| !crate::report::is_frame_param(fitted.identified.layout.name(i)))
        .count();
    if let Some(r) = ladder.iter_mut().find(|r| r.rung == rung) {
        r.n_kept = n_kept;
    }
    Ok(Settled {
        model,
        fitted,
        equilibrium_refits,
        n_kept,
    })
}

/// Warnings of the model choice of `rung` on `ladder`: copied tables, rungs left out, and
/// frames only kept.
fn ladder_warnings(
    cfg: &MeasuredConfig,
    fits: &Fits<'_>,
    rung: ModelName,
    ladder: &LadderOutcome,
) -> Vec<String> {
    let (left_out, range_stops) = (&ladder.left_out, &ladder.range_stops);
    let mut warnings = Vec::new();
    if cfg.rung.is_none() {
        warnings.extend(crate::fit::copies_warning(n_table_copies(fits.train)));
    }
    warnings.extend(untried_note(&ladder.reports, &left_out.untried));
    warnings.extend(left_out.notes.iter().cloned());
    for (r, f) in &left_out.unconverged {
        warnings.push(format!(
            "{UNCONVERGED_RUNG_NOTE}{r} model: its least-squares fit stopped after {} evaluations, \
             {}, so its estimate is the last iterate, not a minimum; the ladder keeps {rung}",
            f.n_evaluations,
            crate::fit::termination_text(&f.termination)
        ));
    }
    if cfg.rung.is_none() && rung == ModelName::FramesOnly && range_stops.is_empty() {
        warnings.push(
            "no calibrated model beat frames only on held-out training rows: the nominal \
             kinematics are kept (only the instrument and marker frames are fitted)"
                .to_owned(),
        );
    } else if cfg.rung.is_none() && rung == ModelName::FramesOnly {
        warnings.push(
            "the joint-range folds stopped every model that beat frames only on held-out \
             training rows: where the calibration is used beyond its training range they are \
             not shown to do better; the nominal kinematics are kept (only the instrument and \
             marker frames are fitted)"
                .to_owned(),
        );
    }
    warnings
}

/// Warnings of the final fit `fitted` of `rung` (`n_kept` kinematic parameters kept): none
/// determined, too few residuals per parameter, not converged.
fn fit_warnings(rung: ModelName, n_kept: usize, fitted: &Fitted) -> Vec<String> {
    let mut warnings = Vec::new();
    if rung != ModelName::FramesOnly && n_kept == 0 {
        warnings.push(format!(
            "the data determine none of the {} model's kinematic parameters: only the \
             instrument and marker frames are fitted; move every joint over its range",
            rung
        ));
    }
    let n_samples: usize = fitted.identified.n_residuals;
    let n_free = fitted.identified.identifiability.kept.len();
    if 3 * n_free > n_samples {
        warnings.push(format!(
            "{n_free} parameters are kept from {n_samples} residuals: fewer than 3 residuals per \
             parameter; the estimate follows the noise (record more configurations)"
        ));
    }
    let termination = &fitted.identified.fit.termination;
    if !termination.is_success() {
        warnings.push(format!(
            "the least-squares fit did not converge ({} after {} evaluations): the \
             estimate is the last iterate, not a minimum (a --sigma-m far below the residual keeps \
             parameters the data do not determine)",
            crate::fit::termination_text(termination),
            fitted.identified.fit.n_evaluations
        ));
    }
    warnings
}

/// Warnings of the residuals, on two scales, each where it means something: the frames-only
/// residual (`frames_model`) against what a real robot's manufacturing deviations produce
/// (an uncalibrated robot is no mistake; a file in the wrong units or with the wrong joint
/// order is), the calibrated residual (`fitted`, of `rung`) against the instrument's stated
/// σ (far above it: an effect the model lacks).
fn residual_warnings(
    cfg: &MeasuredConfig,
    fits: &Fits<'_>,
    frames_model: &CalibratedModel,
    rung: ModelName,
    fitted: &Fitted,
) -> Vec<String> {
    let mut warnings = Vec::new();
    let train = fits.train;
    let frames_rms = {
        let e = training_position_errors(frames_model, train);
        (e.iter().map(|e| e * e).sum::<f64>() / e.len().max(1) as f64).sqrt()
    };
    if frames_rms > PLAUSIBLE_FRAMES_ONLY_RMS_M {
        warnings.push(format!(
            "the nominal model misses the measurements by {:.1} mm RMS with the instrument and \
             marker frames fitted, more than manufacturing deviations of a real robot produce \
             ({:.0} mm): the setup is likely wrong (units, joint order, tip link, marker on \
             the wrong link, another robot's description)",
            frames_rms * 1e3,
            PLAUSIBLE_FRAMES_ONLY_RMS_M * 1e3
        ));
    }
    // The stated σ, or the default of the instrument class that writes such files
    // (crate::noise).
    let (sigma, default_of) = match cfg.sigma_m {
        Some(stated) => (stated, None),
        None => {
            let poses = train.tables.iter().any(|t| t.has_orientation);
            let positions = train.tables.iter().any(|t| t.n_markers > 0);
            let (sigma, class) = crate::noise::default_sigma_m(poses, positions);
            (sigma, Some(class))
        }
    };
    let calibrated = fits.weights.sigma_position_m * fitted.identified.sigma;
    let ratio = if default_of.is_some() {
        crate::noise::DEFAULT_SIGMA_RATIO
    } else {
        CALIBRATED_SIGMA_RATIO
    };
    warnings.extend(crate::noise::residual_warning(
        &rung.to_string(),
        calibrated,
        sigma,
        default_of,
        ratio,
    ));
    warnings
}

/// The final fit and what it is judged by ([`review_fit`], [`findings`]).
struct Review<'a> {
    cfg: &'a MeasuredConfig,
    /// The fits of the ladder (on the training tables as the Huber loss sees them).
    fits: &'a Fits<'a>,
    rung: ModelName,
    settled: &'a Settled,
    /// The frames-only model.
    frames_model: &'a CalibratedModel,
    /// The samples the Huber loss bounded, and the frames-only fit after it.
    bounded: &'a Bounded,
    /// The training tables as measured.
    train: &'a [MeasurementTable],
    test: &'a [MeasurementTable],
    /// Training rows.
    n_rows: usize,
}

/// The warnings, figures and coverage of the final fit ([`review_fit`]).
struct Reviewed {
    warnings: Vec<String>,
    figures: SetFigures,
    /// Each joint's training range (rad, m for a prismatic joint), chain order.
    ranges: Vec<(f64, f64)>,
    coverage: Option<Coverage>,
    equilibrium: EquilibriumCheck,
}

/// The final fit judged: the warnings of the model choice (`ladder`), of the fit and its
/// residuals, the figures of every data set, extrapolation, bounded samples, the torque
/// equilibrium and coverage, in that order (a test set made worse first of all).
fn review_fit(review: &Review<'_>, ladder: &LadderOutcome) -> Reviewed {
    let (cfg, fits, rung, settled) = (review.cfg, review.fits, review.rung, review.settled);
    let robot = fits.robot;
    let mut warnings = ladder_warnings(cfg, fits, rung, ladder);
    warnings.extend(fit_warnings(rung, settled.n_kept, &settled.fitted));
    let frames_model = review.frames_model;
    warnings.extend(residual_warnings(
        cfg,
        fits,
        frames_model,
        rung,
        &settled.fitted,
    ));
    let (train, test) = (review.train, review.test);
    // Each evaluates the settled model on every row: side by side.
    let (mut figures, mut equilibrium) = rayon::join(
        || set_figures(robot, rung, frames_model, &settled.model, train, test),
        || equilibrium_check(rung, settled, fits.weights, train),
    );
    for w in std::mem::take(&mut figures.test_warnings) {
        warnings.insert(0, w);
    }
    let ranges = training_ranges(fits.train.tables, robot.joint_names.len());
    let sets = Extrapolation {
        train,
        test,
        ranges: &ranges,
        n_rows: review.n_rows,
    };
    warnings.extend(extrapolation_warnings(fits, rung, &settled.fitted, &sets));
    warnings.extend(crate::robust::bounded_warning(
        &review.bounded.downweighted,
        "training samples",
        &review.bounded.judge.to_string(),
    ));
    warnings.extend(equilibrium.warning.take());
    let coverage = coverage(
        robot,
        &ranges,
        &cfg.workspace,
        test,
        cfg.rung.is_none(),
        &ladder.range_folds,
        ladder.range_stops.clone(),
    );
    warnings.extend(coverage.iter().flat_map(unvalidated_warnings));
    Reviewed {
        warnings,
        figures,
        ranges,
        coverage,
        equilibrium,
    }
}

/// What the check after the fit found ([`findings`]).
struct Findings {
    /// Identified frames.
    frames: Vec<FrameReport>,
    /// Estimates no real robot can have.
    implausible: Vec<crate::report::Implausible>,
    /// The lengths the chosen rung held, refitted at the estimate.
    refitted_lengths: Vec<crate::report::ParamReport>,
}

/// The identified frames (`markers`: the nominal instrument frame and marker frames), the
/// estimates no real robot can have ([`plausibility`]; the review's torque-equilibrium
/// finding, [`equilibrium_check`], follows them), and the held lengths refitted
/// ([`refit_held_lengths`]) when the Huber loss bounded no sample.
fn findings(review: &Review<'_>, (base, markers): (&FrameSpec, &[(usize, FrameSpec)])) -> Findings {
    let (fits, rung, settled) = (review.fits, review.rung, review.settled);
    let framed = fits.start.tree;
    let frames = frame_reports(base, markers, &settled.fitted.x, framed.params());
    let implausible = plausibility(
        &fits.refit(rung),
        &settled.model,
        &settled.fitted,
        &frames,
        review.cfg.rung.is_some(),
    );
    // Not after the Huber loss bounded samples: a bounded sample's leftover residual, far from
    // the others' configurations, pulls the weak directions the held lengths lie along.
    let refitted_lengths = if review.bounded.downweighted.is_empty() {
        let (robot, train, weights) = (fits.robot, fits.train, fits.weights);
        refit_held_lengths(rung, robot, framed, &settled.fitted, train, weights)
    } else {
        Vec::new()
    };
    Findings {
        frames,
        implausible,
        refitted_lengths,
    }
}

/// Figures of every data set for frames only and the chosen rung ([`set_figures`]).
struct SetFigures {
    /// Per data set (training first): name, role, rows, frames-only and calibrated figures.
    sets: Vec<(String, SetRole, usize, PoseFigures, PoseFigures)>,
    /// Per data set, the errors of every sample.
    sample_errors: Vec<SampleErrors>,
    /// Per test set where the calibration is worse than frames only, in the order they were
    /// found (each goes to the front of the warnings).
    test_warnings: Vec<String>,
}

/// The figures and sample errors of every training table as measured (`train`) and test
/// table under `frames_model` and `model` (of `rung`), with a warning for each test set the
/// calibration makes worse.
fn set_figures(
    robot: &Robot,
    rung: ModelName,
    frames_model: &CalibratedModel,
    model: &CalibratedModel,
    train: &[MeasurementTable],
    test: &[MeasurementTable],
) -> SetFigures {
    let mut sets = Vec::new();
    let mut sample_errors = Vec::new();
    let mut test_warnings = Vec::new();
    for (role, tables) in [(SetRole::Train, train), (SetRole::Test, test)] {
        for ti in 0..tables.len() {
            let (e0, e1) = (
                errors(frames_model, Training::measured(tables), ti, None),
                errors(model, Training::measured(tables), ti, None),
            );
            let (before, after) = (pose_figures(&e0), pose_figures(&e1));
            sample_errors.push(SampleErrors {
                position_before_m: e0.position,
                position_after_m: e1.position,
                distance_before_m: e0.distance,
                distance_after_m: e1.distance,
                rows: crate::report::sample_rows(&tables[ti]),
                joints: crate::report::joint_units(&robot.joint_names, &robot.prismatic),
            });
            if role == SetRole::Test {
                test_warnings.extend(worse_warnings(rung, &tables[ti], &before, &after));
            }
            sets.push((
                tables[ti].name.clone(),
                role,
                tables[ti].rows.len(),
                before,
                after,
            ));
        }
    }
    SetFigures {
        sets,
        sample_errors,
        test_warnings,
    }
}

/// Warnings of a test `table` on which the `rung` model's figures `after` are worse than
/// frames only's `before`: position first, then distance.
fn worse_warnings(
    rung: ModelName,
    table: &MeasurementTable,
    before: &PoseFigures,
    after: &PoseFigures,
) -> Vec<String> {
    let worse = |kind: &str, b: f64, a: f64| {
        format!(
            "test set {}: the {rung} model is worse than frames only ({kind} RMS {:.3} → \
             {:.3} mm): do not use this calibration there",
            table.name,
            b * 1e3,
            a * 1e3
        )
    };
    let mut out = Vec::new();
    if after.position_rms_m > before.position_rms_m {
        out.push(worse(
            "position",
            before.position_rms_m,
            after.position_rms_m,
        ));
    }
    if let (Some(b), Some(a)) = (before.distance_rms_m, after.distance_rms_m)
        && a > b
    {
        out.push(worse("distance", b, a));
    }
    out
}

/// The data sets an extrapolation is judged on ([`extrapolation_warnings`]).
struct Extrapolation<'a> {
    /// The training tables as measured.
    train: &'a [MeasurementTable],
    test: &'a [MeasurementTable],
    /// Each joint's training range (rad, m for a prismatic joint), chain order.
    ranges: &'a [(f64, f64)],
    /// Training rows.
    n_rows: usize,
}

/// The model's own uncertainty where a test set extrapolates, beside its value on (up to
/// 100 evenly spaced) training rows ([`outside_warnings`]); nothing when no test row lies
/// beyond the training ranges.
fn extrapolation_warnings(
    fits: &Fits<'_>,
    rung: ModelName,
    fitted: &Fitted,
    sets: &Extrapolation<'_>,
) -> Vec<String> {
    let (robot, framed, weights) = (fits.robot, fits.start.tree, fits.weights);
    let ranges = sets.ranges;
    let outside_any = |t: &MeasurementTable| {
        (t.rows.iter())
            .any(|r| (r.q.iter().zip(ranges)).any(|(&q, &range)| past_range(q, range).is_some()))
    };
    let mut warnings = Vec::new();
    if !sets.test.iter().any(outside_any) {
        return warnings;
    }
    let rms = |v: &[f64]| (v.iter().map(|s| s * s).sum::<f64>() / v.len().max(1) as f64).sqrt();
    // Built field by field: `..t.clone()` would copy every row of the table first.
    let sample: Vec<MeasurementTable> = (sets.train.iter())
        .map(|t| MeasurementTable {
            name: t.name.clone(),
            path: t.path.clone(),
            rows: (t.rows.iter())
                .step_by((sets.n_rows / 100).max(1))
                .cloned()
                .collect(),
            warnings: t.warnings.clone(),
            n_markers: t.n_markers,
            has_orientation: t.has_orientation,
            has_distance: t.has_distance,
            ignored_columns: t.ignored_columns.clone(),
        })
        .collect();
    let reference: Vec<f64> = prediction_sigmas(rung, robot, framed, fitted, &sample, weights)
        .into_iter()
        .flatten()
        .collect();
    for t in sets.test.iter().filter(|t| outside_any(t)) {
        let sigmas = prediction_sigmas(
            rung,
            robot,
            framed,
            fitted,
            std::slice::from_ref(t),
            weights,
        );
        let sigmas = sigmas.first().map_or(&[][..], Vec::as_slice);
        warnings.extend(outside_warnings(t, robot, ranges, sigmas, rms(&reference)));
    }
    warnings
}

/// How far the chosen model is from its torque equilibrium ([`equilibrium_check`]).
struct EquilibriumCheck {
    /// With compliance: one more fixed-point step's largest tip motion over the training
    /// rows, m.
    step_m: Option<f64>,
    /// The finding of a fixed point iterated and still not reached.
    no_equilibrium: Option<crate::report::Implausible>,
    /// The warning of loads evaluated at the undeflected robot that the deflection changes.
    warning: Option<String>,
}

/// One more fixed-point step of the torque equilibrium of the `settled` model (of `rung`)
/// over the training rows as measured (`train`), against [`EQUILIBRIUM_SHARE`] of the noise
/// (`weights`, scaled by the fit's σ): a finding when the model iterated the equilibrium, a
/// warning when it evaluates the loads of the undeflected robot.
fn equilibrium_check(
    rung: ModelName,
    settled: &Settled,
    weights: Weights,
    train: &[MeasurementTable],
) -> EquilibriumCheck {
    let model = &settled.model;
    let equilibrium_step_m = model.compliance.is_some().then(|| {
        (train.iter().flat_map(|t| &t.rows))
            .map(|r| model.equilibrium_step_m(&r.q))
            .fold(0.0, f64::max)
    });
    let noise = weights.sigma_position_m * settled.fitted.identified.sigma;
    let mut check = EquilibriumCheck {
        step_m: equilibrium_step_m,
        no_equilibrium: None,
        warning: None,
    };
    if let Some(step) = equilibrium_step_m
        && step > EQUILIBRIUM_SHARE * noise
        && model.equilibrium
    {
        // The fixed point was iterated and is still not reached: the iteration does not
        // contract, and its prediction is where a fixed number of steps happens to stop.
        check.no_equilibrium = Some(crate::report::Implausible {
            kind: crate::report::ImplausibleKind::NoEquilibrium,
            message: format!(
                "the compliances of the {rung} model are so large that the robot's weight has \
                 no equilibrium its deflection reaches: after {} fixed-point steps of θ = q + \
                 k∘τ(θ), one more still moves the tips by up to {:.3} mm, more than \
                 {EQUILIBRIUM_SHARE} of the noise ({:.3} mm per axis); no real robot bends that \
                 far under its own weight, and the fit's predictions are where a fixed number \
                 of steps happens to stop; the model absorbs an effect it lacks or a setup \
                 mistake",
                hapcal_problems::EQUILIBRIUM_ITERATIONS,
                step * 1e3,
                noise * 1e3
            ),
            fix: "give a model with fewer compliances (--model compliance, or geometric), or \
                  check the link masses and the mounting (--gravity) of the description"
                .to_owned(),
        });
    } else if let Some(step) = equilibrium_step_m
        && step > EQUILIBRIUM_SHARE * noise
    {
        check.warning = Some(format!(
            "the deflection changes the gravity loads: one more fixed-point step of the torque \
             equilibrium moves the tips by up to {:.3} mm, more than {EQUILIBRIUM_SHARE} of the \
             noise ({:.3} mm per axis), and the model evaluates the loads of the undeflected \
             robot",
            step * 1e3,
            noise * 1e3
        ));
    }
    check
}

pub use hapcal_contract::{
    NEGATIVE_COMPLIANCE_FAMILY_RISK, NEGATIVE_COMPLIANCE_SIGMAS, negative_compliance_sigmas,
};

/// Longest distance of a marker's frame from the origin of its link's frame, m, that a
/// mounting can have (checked after the fit): a marker, a target or a tool flange sits within a
/// metre of the link it is fixed to; a frame metres away absorbs another mistake.
pub const MARKER_OFFSET_MAX_M: f64 = 1.0;

/// Largest training residual, as a multiple of the residual under the gravity given, at
/// which another mounting still explains the data ([`mounting_test`]): flipping gravity
/// flips every load, so a mounting upside down fits exactly as well with the compliances'
/// signs flipped, up to the equilibrium refits (a per cent).
const MOUNTING_RESIDUAL_RATIO: f64 = 1.01;

/// What a refit of the chosen rung needs ([`mounting_test`]).
struct Refit<'a> {
    rung: ModelName,
    robot: &'a Robot,
    start: &'a Start<'a>,
    offsets: &'a [Option<usize>],
    train: Training<'a>,
    weights: Weights,
}

/// `g` as `--gravity` reads it (`-z`, or three numbers).
fn gravity_text(g: &Vector3<f64>) -> String {
    crate::inputs::gravity_words([g.x + 0.0, g.y + 0.0, g.z + 0.0])
}

/// The mounting a direction of gravity in the root frame stands for, in words.
fn mounting_words(g: &Vector3<f64>) -> &'static str {
    if g.z > 0.5 {
        "mounted upside down (hanging from a ceiling)"
    } else if g.z < -0.5 {
        "mounted upright (on a floor)"
    } else {
        "mounted on a wall"
    }
}

/// Another mounting that explains negative compliances: the chosen rung refitted with gravity
/// along each other axis of the root frame (±x, ±y, ±z), in parallel; of those whose
/// compliances are none below zero by [`negative_compliance_sigmas`] σ and whose training
/// position residual is within [`MOUNTING_RESIDUAL_RATIO`] of `given_rms_m` (or below), the
/// one with the smallest residual: its gravity direction and residual, m. `None` when no axis
/// does.
fn mounting_test(r: &Refit<'_>, given_rms_m: f64) -> Option<(Vector3<f64>, f64)> {
    use rayon::prelude::*;
    let axes: Vec<Vector3<f64>> = (0..3)
        .flat_map(|k| {
            let e = Vector3::ith(k, 1.0);
            [e, -e]
        })
        .filter(|g| (g - r.robot.gravity_dir).norm() > 1e-9)
        .collect();
    let all = |_: usize, _: usize| true;
    let trials: Vec<(Vector3<f64>, f64)> = (axes.par_iter())
        .filter_map(|g| {
            let robot = Robot {
                gravity_dir: *g,
                ..r.robot.clone()
            };
            let start = Start {
                nested: None,
                ..*r.start
            };
            let (model, fitted) =
                fit(r.rung, &robot, &start, r.offsets, r.train, r.weights, &all).ok()?;
            if !fitted.identified.fit.termination.is_success()
                || !crate::fit::negative_compliances(&fitted.identified, 1.0)
                    .0
                    .is_empty()
            {
                return None;
            }
            let (_, rms, _) = stats(&training_position_errors(&model, r.train));
            Some((*g, rms))
        })
        .collect();
    (trials.into_iter())
        .filter(|(_, rms)| *rms <= MOUNTING_RESIDUAL_RATIO * given_rms_m)
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// What no real robot can have in the estimate of the chosen rung, each with its cause and
/// fix, the most basic first:
///
/// - a final fit that did not converge: its estimate is no minimum (`given`: the rung was
///   given by `--model`; with `--model auto` the ladder already left out the rungs whose fit
///   did not converge);
/// - compliances below zero by more than [`negative_compliance_sigmas`] σ: two or more (a
///   pattern) named as the mounting when gravity along another axis of the root frame makes
///   them non-negative at no larger residual ([`mounting_test`]), else as what they are;
/// - a marker frame farther than [`MARKER_OFFSET_MAX_M`] from its link's origin.
///
/// Empty when the estimate is plausible.
fn plausibility(
    r: &Refit<'_>,
    model: &CalibratedModel,
    fitted: &Fitted,
    frames: &[FrameReport],
    given: bool,
) -> Vec<crate::report::Implausible> {
    use crate::report::{Implausible, ImplausibleKind};
    let mut out: Vec<Implausible> = crate::fit::unconverged(&fitted.identified, r.rung, given)
        .into_iter()
        .collect();
    let (negative, n_compliances) = crate::fit::negative_compliances(&fitted.identified, 1.0);
    if !negative.is_empty() {
        let unit = compliance_unit_of(r.robot);
        let given_g = gravity_text(&r.robot.gravity_dir);
        let counted = crate::fit::negative_compliance_words(&negative, n_compliances, unit);
        let (_, given_rms, _) = stats(&training_position_errors(model, r.train));
        // A pattern is tested against the mounting; one estimate alone is what it is.
        let mounting = (negative.len() >= 2)
            .then(|| mounting_test(r, given_rms))
            .flatten();
        out.push(match mounting {
            Some((g, rms)) => Implausible {
                kind: ImplausibleKind::Mounting,
                message: format!(
                    "the compliances of the {} model are negative with gravity along {given_g} of \
                     the robot's root link ({counted}); with gravity along {} none is, and \
                     the training residual is {:.3} mm RMS against {:.3} mm: the robot is {}",
                    r.rung,
                    gravity_text(&g),
                    rms * 1e3,
                    given_rms * 1e3,
                    mounting_words(&g)
                ),
                fix: format!("--gravity {}", gravity_text(&g)),
            },
            None => Implausible {
                kind: ImplausibleKind::NegativeCompliance,
                message: format!(
                    "the compliances of the {} model are negative with gravity along {given_g} of \
                     the robot's root link ({counted}), and gravity along no other axis of the \
                     root frame makes them non-negative: a joint does not bend against its load; \
                     the model absorbs an effect it lacks or a setup mistake",
                    r.rung
                ),
                fix: "check the link masses and the mounting (--gravity) of the description, or \
                      give a model without compliance (--model geometric)"
                    .to_owned(),
            },
        });
    }
    for f in frames.iter().filter(|f| f.name.starts_with("marker")) {
        let d = Vector3::from(f.xyz_m).norm();
        if d > MARKER_OFFSET_MAX_M {
            out.push(Implausible {
                kind: ImplausibleKind::Frame,
                message: format!(
                    "the identified {} frame lies {d:.2} m from its link's origin, farther than \
                     any marker mounting ({MARKER_OFFSET_MAX_M} m): the frame absorbs another \
                     mistake (the tip link, the units, another robot's description)",
                    f.name
                ),
                fix: "check --tip and --device against the robot and the markers measured"
                    .to_owned(),
            });
        }
    }
    out
}

/// Most refits of [`equilibrate`].
const EQUILIBRIUM_REFITS: usize = 6;

/// The torque equilibrium of a compliance rung: while one more fixed-point step would move a
/// training tip by more than [`EQUILIBRIUM_SHARE`] of the noise
/// ([`CalibratedModel::equilibrium_step_m`]), the loads are evaluated at the current
/// estimate's equilibrium ([`CalibratedModel::load_angles`]) and the rung refitted from the
/// estimate, until the load angles move by less than 10⁻⁵ rad (at most
/// [`EQUILIBRIUM_REFITS`] refits). The model returned solves the equilibrium when a refit
/// was made; with the refits made.
#[allow(clippy::too_many_arguments)]
fn equilibrate(
    rung: ModelName,
    robot: &Robot,
    tree: &Tree,
    offsets: &[Option<usize>],
    train: Training<'_>,
    weights: Weights,
    model: CalibratedModel,
    fitted: Fitted,
) -> Result<(CalibratedModel, Fitted, usize)> {
    if model.compliance.is_none() {
        return Ok((model, fitted, 0));
    }
    let rows = || train.tables.iter().flat_map(|t| &t.rows);
    let noise = weights.sigma_position_m * fitted.identified.sigma;
    let step = rows()
        .map(|r| model.equilibrium_step_m(&r.q))
        .fold(0.0, f64::max);
    if step <= EQUILIBRIUM_SHARE * noise {
        return Ok((model, fitted, 0));
    }
    // Levenberg–Marquardt alone over the kept parameters while the loads move; one full
    // identification (pruning, covariance) at the converged loads.
    let warm = Warm::of(&fitted);
    let mut x = fitted.x.clone();
    let mut model = model;
    let mut previous: Option<Arc<[f64]>> = None;
    // The observations of the pass that found the loads converged, for the final fit.
    let mut converged = None;
    let mut refits = 0;
    // The observations are built for each problem rather than copied from one held beside
    // it: one copy of every row at a time.
    let all = |_: usize, _: usize| true;
    let lm = crate::fit::identify_config(None).lm;
    while refits < EQUILIBRIUM_REFITS {
        let solving = CalibratedModel {
            equilibrium: true,
            ..model.clone()
        };
        let obs = observations(train, &all);
        if let Some(p) = &previous {
            let change = equilibrium_change(&solving, &obs, p);
            // Ten microradians move a tip a metre out by ten micrometres: below the noise of
            // a tracker or motion capture. Each refit shrinks the change about twentyfold on
            // the simulated humanoid (0.75 mrad, 34 µrad, 1.6 µrad).
            if change < 1e-5 {
                converged = Some(obs);
                break;
            }
        }
        // The last refit's angles are judged: dropped before the new ones are collected, so
        // one set of angles is held at a time (the new ones are evaluated twice, once for the
        // test above and once here, rather than held beside the old).
        drop(previous.take());
        let at = equilibrium_angles(&solving, &obs);
        let terms = ModelTerms {
            load_angles: Some(Arc::clone(&at)),
            ..terms(rung, robot)?
        };
        let problem = CalibrationProblem::on_tree(tree.clone(), obs, weights, terms)
            .context("building the calibration problem")?;
        // Past the dense back end's bound, in row blocks: the Jacobian of every training row
        // is never held.
        let fit = lm_alone(
            &problem,
            x.clone(),
            &warm.free,
            &crate::fit::full_fit_lm(lm.clone(), problem.n_residuals()),
            None,
            REFIT_MAX_ENTRIES,
        )
        .context("refitting at the torque equilibrium")?;
        model = problem.model(fit.x.as_ref());
        x = fit.x;
        previous = Some(at);
        refits += 1;
    }
    let Some(at) = previous else {
        return Ok((model, fitted, 0));
    };
    let terms = ModelTerms {
        load_angles: Some(at),
        ..terms(rung, robot)?
    };
    let (model, fitted) = fit_terms(
        rung,
        terms,
        robot,
        &Start {
            tree,
            x: &x,
            nested: None,
            max_evaluations: None,
        },
        offsets,
        converged.unwrap_or_else(|| observations(train, &all)),
        weights,
        &|| repeat_std_scale(train, &all),
    )?;
    Ok((model, fitted, refits))
}

/// The torque-equilibrium joint angles of `solving` ([`CalibratedModel::load_angles`]) at
/// each configuration of `obs` ([`Observations::configurations`]), one configuration's
/// `n_joints` angles (rad, m for a prismatic joint) after another. The configurations are
/// solved in parallel (each on its own, so the angles do not depend on the threads), straight
/// into the shared slice: one allocation of the angles.
fn equilibrium_angles(solving: &CalibratedModel, obs: &Observations) -> Arc<[f64]> {
    use rayon::prelude::*;
    let starts: Vec<usize> = obs.configurations().map(|rows| rows.start).collect();
    let n_joints = obs.rows.first().map_or(0, |r| r.q.len());
    let mut at: Arc<[f64]> = std::iter::repeat_n(0.0, starts.len() * n_joints).collect();
    let Some(slots) = Arc::get_mut(&mut at) else {
        unreachable!("a slice just collected has no other owner")
    };
    (slots.par_chunks_mut(n_joints.max(1)).zip(&starts))
        .for_each(|(slot, &s)| slot.copy_from_slice(&solving.load_angles(&obs.rows[s].q).0));
    at
}

/// The largest change, rad (m for a prismatic joint), of the torque-equilibrium joint angles of
/// `solving` at the configurations of `obs` from `previous` (ordered as
/// [`equilibrium_angles`] gives them), without holding the new angles: the configurations in
/// parallel, each compared as it is solved.
fn equilibrium_change(solving: &CalibratedModel, obs: &Observations, previous: &[f64]) -> f64 {
    use rayon::prelude::*;
    let starts: Vec<usize> = obs.configurations().map(|rows| rows.start).collect();
    let n_joints = obs.rows.first().map_or(0, |r| r.q.len());
    (previous.par_chunks(n_joints.max(1)).zip(&starts))
        .map(|(p, &s)| {
            (p.iter().zip(solving.load_angles(&obs.rows[s].q).0))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

/// Share of the position noise σ below which the gravity loads of the undeflected robot are
/// close enough to the equilibrium's: one more fixed-point step moves the tips by less than
/// this, and the model's single step is reported as enough.
pub const EQUILIBRIUM_SHARE: f64 = 0.3;

/// The robot's lengths (`m` parameters of `robot`'s own, not the instrument's nor the
/// markers') after a fit, at the estimate `fitted` of `rung` on `tables`, of those it held at
/// their nominal values ([`crate::fit::refitted_lengths`]): the held ones first, then the
/// identified ones as the step moves them; `tree` is the framed tree the problems are built
/// on. Empty when nothing was held or the problem cannot be rebuilt.
fn refit_held_lengths(
    rung: ModelName,
    robot: &Robot,
    tree: &Tree,
    fitted: &Fitted,
    tables: Training<'_>,
    weights: Weights,
) -> Vec<crate::report::ParamReport> {
    let obs = observations(tables, &|_, _| true);
    let Ok(problem) = terms(rung, robot)
        .and_then(|t| Ok(CalibrationProblem::on_tree(tree.clone(), obs, weights, t)?))
    else {
        return Vec::new();
    };
    let layout = problem.layout();
    let id = &fitted.identified;
    let kept: Vec<usize> = (id.identifiability.kept.iter())
        .filter_map(|&i| layout.index_of(id.layout.name(i)))
        .collect();
    let lengths: Vec<usize> = (6..6 + robot.tree.n_params())
        .filter(|&i| i < layout.len() && layout.spec(i).unit == hapcal_identify::Unit::Meter)
        .collect();
    let held: Vec<usize> = (lengths.iter().copied())
        .filter(|i| !kept.contains(i))
        .collect();
    crate::fit::refitted_lengths(
        &problem,
        fitted.x.as_ref(),
        id.sigma,
        &kept,
        &held,
        &lengths,
    )
}

/// Covariance-propagated 3-D position uncertainty of the calibrated model (m) at every marker
/// sample of `tables`, per table in file order: `√trace(J·C·Jᵀ)` with `J` the position's
/// Jacobian with respect to the identified parameters at the estimate and `C` their
/// covariance (docs/engine.md, "Identification"). It is the spread the estimate's own noise
/// gives a prediction there, not the model's error: where the rows extrapolate, it says how
/// much less the data pin the model down. Empty for a table whose Jacobian cannot be
/// evaluated.
#[allow(clippy::too_many_arguments)]
fn prediction_sigmas(
    rung: ModelName,
    robot: &Robot,
    tree: &Tree,
    fitted: &Fitted,
    tables: &[MeasurementTable],
    weights: Weights,
) -> Vec<Vec<f64>> {
    let cov = &fitted.identified.covariance;
    let columns: Vec<Option<usize>> = (cov.names.iter())
        .map(|n| fitted.names.iter().position(|m| m == n))
        .collect();
    (0..tables.len())
        .map(|ti| {
            let mut obs = observations(Training::measured(tables), &|t, _| t == ti);
            // Positions only: one 3-row block per marker sample, in the rows' order.
            obs.rows
                .retain(|r| matches!(r.kind, RowKind::Marker { .. } | RowKind::Pose { .. }));
            for r in &mut obs.rows {
                if let RowKind::Pose {
                    tip, position_m, ..
                } = r.kind
                {
                    r.kind = RowKind::Marker { tip, position_m };
                }
            }
            let n_samples = obs.rows.len();
            let Ok(problem) = terms(rung, robot)
                .and_then(|t| Ok(CalibrationProblem::on_tree(tree.clone(), obs, weights, t)?))
            else {
                return Vec::new();
            };
            let n = problem.layout().len();
            let s = weights.sigma_position_m;
            // σ of sample `i` from its three Jacobian rows `jac` (3 × n).
            let sigma = |jac: faer::MatRef<'_, f64>| {
                let mut trace = 0.0;
                for k in 0..3 {
                    let g: Vec<f64> = (columns.iter())
                        .map(|c| c.map_or(0.0, |c| s * jac[(k, c)]))
                        .collect();
                    for (a, ga) in g.iter().enumerate() {
                        if *ga == 0.0 {
                            continue;
                        }
                        for (b, gb) in g.iter().enumerate() {
                            trace += ga * cov.matrix[(a, b)] * gb;
                        }
                    }
                }
                f64::max(trace, 0.0).sqrt()
            };
            // Block by block where the problem has row blocks (of whole samples, 3 rows
            // each): the memory of one block, not of the table's Jacobian.
            let mut out = Vec::with_capacity(n_samples);
            match problem.row_blocks() {
                Some(blocks) => {
                    for b in 0..blocks.n_blocks() {
                        let len = blocks.block_rows(b).len();
                        let mut r = Col::<f64>::zeros(len);
                        let mut jac = Mat::<f64>::zeros(len, n);
                        let x = fitted.x.as_ref();
                        if len % 3 != 0
                            || (blocks.block_jacobian(x, b, r.as_mut(), jac.as_mut())).is_err()
                        {
                            return Vec::new();
                        }
                        out.extend((0..len / 3).map(|i| sigma(jac.as_ref().subrows(3 * i, 3))));
                    }
                }
                None => {
                    let mut jac = Mat::<f64>::zeros(problem.n_residuals(), n);
                    if problem.jacobian(fitted.x.as_ref(), jac.as_mut()).is_err() {
                        return Vec::new();
                    }
                    out.extend((0..n_samples).map(|i| sigma(jac.as_ref().subrows(3 * i, 3))));
                }
            }
            if out.len() != n_samples {
                return Vec::new();
            }
            out
        })
        .collect()
}

/// Where `workspace` and the `test` rows lie against the training ranges `ranges` of
/// `robot`'s joints: every side of a joint's range that one of them lies past by more than
/// [`OUTSIDE_SHARE`] of the range, with the joint-range fold of `folds` that judged it and
/// the rungs the folds `stops`ped (`chosen`: the model was chosen on the ladder). `None`
/// without workspace configurations and test rows.
fn coverage(
    robot: &Robot,
    ranges: &[(f64, f64)],
    workspace: &[Vec<f64>],
    test: &[MeasurementTable],
    chosen: bool,
    folds: &[RangeFold],
    stops: Vec<RangeStop>,
) -> Option<Coverage> {
    let test_q: Vec<&[f64]> = (test.iter().flat_map(|t| &t.rows))
        .map(|r| &r.q[..])
        .collect();
    let workspace_q: Vec<&[f64]> = workspace.iter().map(Vec::as_slice).collect();
    if test_q.is_empty() && workspace_q.is_empty() {
        return None;
    }
    let reach = |set: &[&[f64]], j: usize, upper: bool| -> Option<Beyond> {
        if set.is_empty() {
            return None;
        }
        let shares: Vec<f64> = (set.iter())
            .map(|q| beyond_share(q[j], ranges[j], upper))
            .filter(|&s| s > 0.0)
            .collect();
        let farthest_share = shares.iter().copied().fold(0.0, f64::max);
        Some(Beyond {
            n_beyond: shares.len(),
            n: set.len(),
            farthest: farthest_share * (ranges[j].1 - ranges[j].0),
            farthest_share,
        })
    };
    let mut sides = Vec::new();
    for (j, &range) in ranges.iter().enumerate() {
        for upper in [false, true] {
            let (w, t) = (reach(&workspace_q, j, upper), reach(&test_q, j, upper));
            if [w, t].iter().flatten().all(|b| b.n_beyond == 0) {
                continue;
            }
            let joint = robot.joint_names[j].clone();
            sides.push(CoverageSide {
                fold: (folds.iter())
                    .find(|f| f.joint == joint && f.upper == upper)
                    .cloned(),
                joint,
                upper,
                unit: if robot.prismatic.get(j).copied().unwrap_or(false) {
                    "m"
                } else {
                    "rad"
                },
                training_range: range,
                workspace: w,
                test: t,
            });
        }
    }
    let mut stopped: Vec<RangeStop> = Vec::new();
    for s in stops {
        if !stopped.contains(&s) {
            stopped.push(s);
        }
    }
    Some(Coverage {
        n_workspace: workspace.len(),
        n_test: test_q.len(),
        sides,
        chosen,
        stopped,
        workspace_q: workspace.to_vec(),
    })
}

/// One warning per side of a joint's training range that the workspace or the test rows lie
/// beyond farther than its joint-range fold emulates: the model choice extrapolated the
/// folds' evidence there, and the calibration is not validated that far.
fn unvalidated_warnings(coverage: &Coverage) -> Vec<String> {
    (coverage.sides.iter())
        .filter_map(|side| {
            let fold = side.fold.as_ref().filter(|f| !f.emulates())?;
            let (lo, hi) = side.training_range;
            let far = [side.workspace, side.test]
                .into_iter()
                .flatten()
                .max_by(|a, b| a.farthest.total_cmp(&b.farthest))?;
            Some(format!(
                "{} is used up to {:.3} {unit} {} its training range {lo:.3}..{hi:.3} {unit} \
                 ({:.0} % of the range), farther than a joint-range fold emulates ({:.0} %, \
                 holding out {:.0} % of the rows): the model choice extrapolates the folds' \
                 evidence there, and the calibration is not validated that far",
                side.joint,
                far.farthest,
                if side.upper { "above" } else { "below" },
                fold.needed_share * 100.0,
                fold.emulated_share * 100.0,
                fold.held_out_share * 100.0,
                unit = side.unit,
            ))
        })
        .collect()
}

/// One warning per joint of `robot` that rows of `table` read outside its training range
/// `ranges` (by more than [`OUTSIDE_SHARE`] of the range): the calibration extrapolates
/// there.
/// `sigmas` are the calibrated model's covariance-propagated position uncertainties at the
/// table's marker samples ([`prediction_sigmas`]), `train_sigma` their RMS over the training
/// samples: each warning gives their RMS over the samples of the rows outside.
fn outside_warnings(
    table: &MeasurementTable,
    robot: &Robot,
    ranges: &[(f64, f64)],
    sigmas: &[f64],
    train_sigma: f64,
) -> Vec<String> {
    // The first sample of each row among `sigmas`.
    let first: Vec<usize> = (table.rows.iter())
        .scan(0, |n, r| {
            let start = *n;
            *n += r.markers.len();
            Some(start)
        })
        .collect();
    let mut out = Vec::new();
    for (j, &(lo, hi)) in ranges.iter().enumerate() {
        let outside_rows: Vec<usize> = (0..table.rows.len())
            .filter(|&r| past_range(table.rows[r].q[j], (lo, hi)).is_some())
            .collect();
        let outside: Vec<f64> = outside_rows.iter().map(|&r| table.rows[r].q[j]).collect();
        let there: Vec<f64> = (outside_rows.iter())
            .flat_map(|&r| first[r]..first[r] + table.rows[r].markers.len())
            .filter_map(|i| sigmas.get(i).copied())
            .collect();
        if outside.is_empty() {
            continue;
        }
        let unit = if robot.prismatic.get(j).copied().unwrap_or(false) {
            "m"
        } else {
            "rad"
        };
        let (min, max) = outside
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &q| {
                (a.min(q), b.max(q))
            });
        let uncertainty = if there.is_empty() {
            String::new()
        } else {
            let rms = (there.iter().map(|s| s * s).sum::<f64>() / there.len() as f64).sqrt();
            format!(
                " (the model's own position uncertainty there {:.3} mm RMS, {:.3} mm on the \
                 training rows)",
                rms * 1e3,
                train_sigma * 1e3
            )
        };
        out.push(format!(
            "test set {}: {} of {} rows read {} outside its training range {lo:.3}..{hi:.3} {unit} \
             ({min:.3}..{max:.3} {unit}): the calibration extrapolates there{uncertainty}",
            table.name,
            outside.len(),
            table.rows.len(),
            robot.joint_names[j],
        ));
    }
    out
}

/// The samples the Huber loss bounded at their bounded positions (sorted by place; the
/// training tables are read through them, [`Training`]), the same samples as the report lists
/// them, the rung it was evaluated with and its fit when it bounded none, and that rung.
type Winsorized = (
    Vec<BoundedSample>,
    Vec<Downweighted>,
    Option<(ModelName, (CalibratedModel, Fitted))>,
    ModelName,
);

/// The unit of `robot`'s compliances: rad/(N·m) with masses (loads are torques), rad/m
/// without (loads are lever arms).
fn compliance_unit_of(robot: &Robot) -> &'static str {
    if robot.masses.is_empty() {
        "rad/m"
    } else {
        "rad/(N·m)"
    }
}

pub use crate::robust::HUBER_CORNER;

/// The training tables as the Huber loss sees them ([`crate::robust::bound_gross_errors`]):
/// `rung` is fitted (the richest rung of the ladder, or the rung given) and every marker
/// sample whose 3-D residual `e` exceeds the corner replaced by `model + e·c/|e|`, until the
/// set of bounded samples no longer changes. No sample bounded or listed when nothing
/// exceeds the corner, with fewer than 20 samples, or when the rung cannot be fitted.
/// A rung with fewer than [`crate::robust::MIN_REDUNDANCY`] residuals per kept parameter
/// gives way to the geometric rung. With nothing bounded, the rung used and its fit on the
/// tables as measured are returned too. The tables are never copied: each fit reads them
/// through the bounded samples ([`Training`]), and only each sample's residual norm is kept
/// between rounds.
fn winsorize(
    rung: ModelName,
    robot: &Robot,
    start: &Start<'_>,
    offsets: &[Option<usize>],
    train: &[MeasurementTable],
    weights: Weights,
) -> Result<Winsorized> {
    use crate::robust::{Dim, Round, bound_gross_errors, redundancy};
    let all = |_: usize, _: usize| true;
    let n_samples = n_marker_samples(train);
    let mut first = None;
    let mut first_redundancy = 1.0;
    let mut rung = rung;
    // The model of the last fit, whose residuals the next bounds are set from.
    let mut last: Option<CalibratedModel> = None;
    let bounds = bound_gross_errors(n_samples, Dim::Three, |bounds| {
        let samples = match &last {
            Some(model) => bounded_samples(model, train, bounds),
            None => Vec::new(),
        };
        let tables = Training::with_bounded(train, &samples);
        let (model, fitted, redundancy) = loop {
            let (model, fitted) = fit(rung, robot, start, offsets, tables, weights, &all).ok()?;
            let n_residuals = fitted.identified.n_residuals;
            let n_kept = fitted.identified.identifiability.kept.len();
            match redundancy(n_residuals, n_kept) {
                Some(r) => break (model, fitted, r),
                // A later round's fit of the same rung and samples: the first round's
                // redundancy.
                None if first.is_some() => break (model, fitted, first_redundancy),
                // A rung with too few residuals per parameter fits the noise itself, and a
                // gross error hides in it: the geometric rung judges instead.
                None if first.is_none() && rung > ModelName::Geometric => {
                    rung = ModelName::Geometric;
                }
                None => return None,
            }
        };
        // Each sample's residual from the measured position, file order.
        let mut norms = Vec::with_capacity(n_samples);
        for row in train.iter().flat_map(|t| &t.rows) {
            let tips: Vec<usize> = row.markers.iter().map(|m| m.marker).collect();
            let poses = model.end_poses_of(&tips, &row.q);
            for (m, pose) in row.markers.iter().zip(poses) {
                norms.push((Vector3::from(m.position_m) - pose.translation.vector).norm());
            }
        }
        last = Some(model.clone());
        if first.is_none() {
            first = Some((rung, (model, fitted)));
            first_redundancy = redundancy;
        }
        Some(Round { norms, redundancy })
    });
    let (Some(model), false) = (&last, bounds.is_empty()) else {
        return Ok((Vec::new(), Vec::new(), first, rung));
    };
    let samples = bounded_samples(model, train, &bounds);
    let downweighted = (bounds.iter().zip(&samples))
        .map(|(b, s)| {
            let (ti, ri, mi) = s.at;
            Downweighted {
                file: train[ti].path.display().to_string(),
                line: train[ti].rows[ri].line,
                marker: Some(train[ti].rows[ri].markers[mi].marker + 1),
                residual_m: b.norm,
                bound_m: b.corner,
            }
        })
        .collect();
    Ok((samples, downweighted, None, rung))
}

/// The marker samples `bounds` (by index among the samples of `train`, file order, sorted)
/// at their bounded positions under `model`, the fit whose residuals bounded them:
/// `p + e·c/|e|` with `p` the model's position, `e` the measured position minus `p` and `c`
/// the corner, m; sorted by place.
fn bounded_samples(
    model: &CalibratedModel,
    train: &[MeasurementTable],
    bounds: &[crate::robust::Bound],
) -> Vec<BoundedSample> {
    debug_assert!(bounds.is_sorted_by_key(|b| b.sample));
    let mut out = Vec::with_capacity(bounds.len());
    let mut next = bounds.iter().peekable();
    let mut first_sample = 0;
    for (ti, t) in train.iter().enumerate() {
        for (ri, row) in t.rows.iter().enumerate() {
            if next.peek().is_none() {
                return out;
            }
            let end = first_sample + row.markers.len();
            let mut poses = None;
            while let Some(b) = next.next_if(|b| b.sample < end) {
                let mi = b.sample - first_sample;
                let poses = poses.get_or_insert_with(|| {
                    let tips: Vec<usize> = row.markers.iter().map(|m| m.marker).collect();
                    model.end_poses_of(&tips, &row.q)
                });
                let p = poses[mi].translation.vector;
                let e = Vector3::from(row.markers[mi].position_m) - p;
                out.push(BoundedSample {
                    at: (ti, ri, mi),
                    position_m: (p + e * (b.corner / b.norm)).into(),
                });
            }
            first_sample = end;
        }
    }
    out
}

/// The frames-only fit of the training tables ([`frames_only`]).
pub struct FramesOnly {
    /// The robot with joint offsets (every rung's tree before the frames).
    pub robot: Robot,
    /// The joint-offset parameter of each joint, if it has one.
    pub offsets: Vec<Option<usize>>,
    /// Nominal instrument frame (the closed-form start).
    pub base: FrameSpec,
    /// Nominal marker frames with their tips.
    pub markers: Vec<(usize, FrameSpec)>,
    /// The robot behind the instrument frame with a marker frame on each tip.
    pub framed: Tree,
    /// The fitted frames-only model.
    pub model: CalibratedModel,
    /// Its identification.
    pub fitted: Fitted,
}

/// The nominal kinematics with the instrument and marker frames fitted to `tables` at
/// `weights`: of the closed-form starts (docs/engine.md, "Trees, instruments and markers"),
/// the one whose residual is smallest, refined by Levenberg–Marquardt over the frames.
/// Cheap (a few milliseconds for hundreds of rows): the setup check fits it under each
/// hypothesis of a mistake.
///
/// # Errors
/// No closed-form start, or a failed identification.
pub fn frames_only(
    robot: &Robot,
    tables: &[MeasurementTable],
    cfg: &MeasuredConfig,
    weights: Weights,
) -> Result<FramesOnly> {
    let with_offsets = robot.tree.with_joint_offsets();
    let offsets = with_offsets.joint_offset_params();
    let robot = Robot {
        tree: with_offsets.clone(),
        ..robot.clone()
    };
    let samples = samples(&robot, tables, cfg);
    let distances: Vec<(Isometry3<f64>, f64)> = {
        let zero = vec![0.0; robot.tree.n_params()];
        let tip = &robot.tree.tips()[tip_of(cfg, &robot.tree, 0)];
        (tables.iter().flat_map(|t| &t.rows))
            .filter_map(|r| Some((tip.end_pose(&zero, &r.q), r.distance_m?)))
            .collect()
    };
    let mut best: Option<(f64, Frames)> = None;
    for (base, markers) in initial_frames(&robot, tables, &samples, n_markers(tables), cfg) {
        let cost = start_cost(&samples, &distances, &base, &markers, &weights);
        if best.as_ref().is_none_or(|(c, _)| cost < *c) {
            best = Some((cost, (base, markers)));
        }
    }
    let Some((_, (base, markers))) = best else {
        bail!("no initial guess of the instrument frame");
    };
    // The samples at the nominal kinematics (128 bytes each) are not held through the fit,
    // whose problem has a row per sample of its own.
    drop((samples, distances));
    let framed = with_offsets
        .with_frames(&base, &markers)
        .context("attaching the instrument and marker frames")?;
    let nominal = Col::<f64>::zeros(framed.n_params());
    let (model, fitted) = fit(
        ModelName::FramesOnly,
        &robot,
        &Start {
            tree: &framed,
            x: &nominal,
            nested: None,
            max_evaluations: None,
        },
        &offsets,
        Training::measured(tables),
        weights,
        &|_, _| true,
    )?;
    Ok(FramesOnly {
        robot,
        offsets,
        base,
        markers,
        framed,
        model,
        fitted,
    })
}

/// 3-D position error (m) of every marker sample of `tables` under `model`, file order.
pub fn position_errors(model: &CalibratedModel, tables: &[MeasurementTable]) -> Vec<f64> {
    training_position_errors(model, Training::measured(tables))
}

/// [`position_errors`] of the training tables as the fits see them (bounded samples at their
/// bounded positions).
fn training_position_errors(model: &CalibratedModel, tables: Training<'_>) -> Vec<f64> {
    (0..tables.tables.len())
        .flat_map(|t| errors(model, tables, t, None).position)
        .collect()
}

/// Half the weighted squared residual of the samples and of the `distances` (nominal pose of
/// marker 1's tip, measured distance) seen through the frames `base` and `markers`: the cost a
/// frames-only fit would start from.
fn start_cost(
    samples: &[Sample],
    distances: &[(Isometry3<f64>, f64)],
    base: &FrameSpec,
    markers: &[(usize, FrameSpec)],
    weights: &Weights,
) -> f64 {
    let mut cost = 0.0;
    if let Some((_, marker)) = markers.first() {
        for (tip, d) in distances {
            let p = base.nominal * tip * marker.nominal;
            cost += ((p.translation.vector.norm() - d) / weights.sigma_distance_m).powi(2);
        }
    }
    for s in samples {
        let Some((_, marker)) = markers.get(s.marker) else {
            continue;
        };
        let pose = base.nominal * s.tip * marker.nominal;
        let e = (pose.translation.vector - s.measured.coords).norm() / weights.sigma_position_m;
        cost += e * e;
        if let Some(r) = s.rotation {
            let theta = r.angle_to(&pose.rotation) / weights.sigma_orientation_rad;
            cost += theta * theta;
        }
    }
    if cost.is_finite() {
        0.5 * cost
    } else {
        f64::INFINITY
    }
}

/// The identified instrument and marker frames: each nominal frame times its deviation,
/// found by name among the framed tree's parameters (`instrument.x` … `marker<k>.rz`; `x`
/// holds them first, in that order, whatever the model's other terms).
fn frame_reports(
    base: &FrameSpec,
    markers: &[(usize, FrameSpec)],
    x: &Col<f64>,
    names: &[hapcal_kinematics::ParamInfo],
) -> Vec<FrameReport> {
    let at = |name: &str| -> Vec<f64> {
        ["x", "y", "z", "rx", "ry", "rz"]
            .iter()
            .map(|s| {
                let key = format!("{name}.{s}");
                (names.iter())
                    .position(|p| p.name == key)
                    .map_or(0.0, |i| x[i])
            })
            .collect()
    };
    let report = |name: &str, pose: Isometry3<f64>| {
        let (roll, pitch, yaw) = pose.rotation.euler_angles();
        FrameReport {
            name: name.to_owned(),
            xyz_m: pose.translation.vector.into(),
            rpy_rad: [roll, pitch, yaw],
        }
    };
    let mut out = vec![report(
        &base.name,
        base.nominal * deviation(&at(&base.name)),
    )];
    for (_, m) in markers {
        out.push(report(&m.name, m.nominal * deviation(&at(&m.name))));
    }
    out
}

/// `hapcal calibrate` on measurement tables ([`calibrate_measured`] with the plan's settings,
/// as a [`crate::report::Outcome`]), read by [`crate::data::load`] or
/// [`hapcal_io::read_measurement_file`], or built from arrays, for `robot`; `plan.data` and
/// `plan.test` are not read, `plan.test_last` splits `train`.
///
/// # Errors
/// As [`calibrate_measured`]; a `--test-last` share that leaves no training row.
pub fn run_tables(
    plan: &crate::inputs::Plan,
    device: &hapcal_io::Device,
    robot: &Robot,
    mut train: Vec<MeasurementTable>,
    mut test: Vec<MeasurementTable>,
    start: std::time::Instant,
) -> Result<crate::report::Outcome> {
    let tips: Vec<String> = std::iter::once(plan.tip.clone())
        .chain(plan.tips.iter().cloned())
        .collect();
    split_test_last(&mut train, &mut test, plan.test_last)?;
    let mut warnings = table_warnings(robot, &train, &test);
    let cfg = plan_config(plan, robot, tips.len())?;
    let robot = &Robot {
        gravity_dir: Vector3::from(plan.gravity),
        ..robot.clone()
    };
    let out = calibrate_measured(robot, &train, &test, &cfg)?;
    warnings.extend(out.warnings.iter().cloned());
    let report = calibration_report(plan, robot, &out, warnings, start);
    let record = calibration_record(robot, &out, &report, &tips, &train);
    let mut outcome = crate::report::Outcome {
        report,
        device: device.clone(),
        device_path: plan.device.clone(),
        model: out.model,
        calibrated: None,
        record: Some(record),
    };
    runtime_figures(&mut outcome, &train, &test)?;
    Ok(outcome)
}

/// The warnings of the tables as read: the columns they ignored (with a hint for the joints
/// off the measured paths of `robot`), then each table's own warnings, once each.
fn table_warnings(
    robot: &Robot,
    train: &[MeasurementTable],
    test: &[MeasurementTable],
) -> Vec<String> {
    let mut warnings: Vec<String> = Vec::new();
    let mut ignored: Vec<String> = (train.iter().chain(test))
        .flat_map(|t| t.ignored_columns.iter().cloned())
        .collect();
    ignored.sort();
    ignored.dedup();
    if !ignored.is_empty() {
        let held: Vec<&str> = (ignored.iter())
            .filter(|c| robot.held_joints.contains(c))
            .map(String::as_str)
            .collect();
        let hint = if held.is_empty() {
            String::new()
        } else {
            format!(
                " ({} off the measured paths, held at zero in the gravity torques; \
                 give a link below {} as a further --tip to use {} readings)",
                held.join(", "),
                if held.len() == 1 { "it" } else { "them" },
                if held.len() == 1 { "its" } else { "their" },
            )
        };
        warnings.push(format!("columns ignored: {}{hint}", ignored.join(", ")));
    }
    for w in (train.iter().chain(test)).flat_map(|t| &t.warnings) {
        if !warnings.contains(w) {
            warnings.push(w.clone());
        }
    }
    warnings
}

/// The settings of [`calibrate_measured`] from `plan`, with marker `k` on tip `k` of the
/// `n_tips` tips.
///
/// # Errors
/// A model measurement files cannot fit; an unreadable workspace file.
fn plan_config(plan: &crate::inputs::Plan, robot: &Robot, n_tips: usize) -> Result<MeasuredConfig> {
    Ok(MeasuredConfig {
        rung: {
            plan.model.check_fits(DataKind::Measurements)?;
            plan.model.model()
        },
        folds: plan.folds,
        sigma_m: plan.sigma_m,
        sigma_rad: plan.sigma_rad,
        marker_tips: (0..n_tips).collect(),
        workspace: match &plan.workspace {
            Some(path) => workspace_configurations(path, robot, &plan.units)?,
            None => Vec::new(),
        },
        max_evaluations: None,
    })
}

/// The identified values of `id` with their σ (frames excluded, or only the frames with
/// `frames`), each in its layout unit (a compliance's rad/(N·m) or rad/m).
fn identified_values(id: &Identified, frames: bool) -> Vec<crate::report::ParamReport> {
    (id.covariance.free.iter())
        .zip(id.covariance.std())
        .filter(|(i, _)| crate::report::is_frame_param(id.layout.name(**i)) == frames)
        .map(|(&i, std)| crate::report::ParamReport {
            name: id.layout.name(i).to_owned(),
            value: id.fit.x[i],
            std,
            unit: id.layout.spec(i).unit.symbol(),
        })
        .collect()
}

/// The kinematic parameters of `id` the data did not determine (frames excluded).
fn pruned_kinematics(id: &Identified) -> Vec<crate::report::PrunedReport> {
    crate::fit::pruned_report(id)
        .into_iter()
        .filter(|p| !crate::report::is_frame_param(&p.name))
        .collect()
}

/// The pairs of kinematic parameters of `id` correlated beyond 0.95, with their correlation
/// (frames excluded).
fn correlated_kinematics(id: &Identified) -> Vec<(String, String, f64)> {
    (id.covariance.correlated_pairs(0.95).into_iter())
        .map(|(a, b, c)| {
            (
                id.layout.name(a).to_owned(),
                id.layout.name(b).to_owned(),
                c,
            )
        })
        .filter(|(a, b, _)| !crate::report::is_frame_param(a) && !crate::report::is_frame_param(b))
        .collect()
}

/// The report of each data set of `out`: its frames-only and calibrated figures and the
/// errors of every sample.
fn set_reports(out: &MeasuredOutcome) -> Vec<crate::report::SetReport> {
    use crate::report::{Figures, SetReport};
    (out.sets.iter().zip(&out.sample_errors))
        .map(|((name, role, n_rows, before, after), errors)| {
            let f = |p: &PoseFigures| Figures {
                mean_absolute_error_m: None,
                distance_error_m: None,
                distance_rms_m: None,
                pose: Some(*p),
            };
            SetReport {
                name: name.clone(),
                role: *role,
                n_rows: *n_rows,
                before: f(before),
                after: f(after),
                errors: Some(errors.clone()),
            }
        })
        .collect()
}

/// Sets the calibrated figures and sample errors of every data set of `outcome`'s report (the
/// training tables `train`, then the test tables `test`, as [`set_reports`] lists them) to
/// the runtime's evaluation of the files the calibration writes
/// ([`crate::record::runtime_robot`], [`crate::predict::MarkerPoses`]): what `hapcal
/// predict` gives on them. Left as the library's model gives them where the runtime reads no
/// robot from the files (a device whose chain is made of placements).
///
/// # Errors
/// Files the runtime refuses, or a reading it refuses (file:line).
fn runtime_figures(
    outcome: &mut crate::report::Outcome,
    train: &[MeasurementTable],
    test: &[MeasurementTable],
) -> Result<()> {
    let Some(robot) = crate::record::runtime_robot(outcome)? else {
        return Ok(());
    };
    let mut markers = crate::predict::MarkerPoses::new(&robot)?;
    let sets = outcome.report.placements.iter_mut();
    for (set, table) in sets.zip(train.iter().chain(test)) {
        let mut e = Errors::default();
        for row in &table.rows {
            // Each marker sample's marker, then marker 1 for the distance.
            let mut wanted: Vec<usize> = row.markers.iter().map(|m| m.marker).collect();
            wanted.extend(row.distance_m.map(|_| 0));
            let mut poses = (markers.at(&row.q, &wanted))
                .with_context(|| format!("{}:{}", table.path.display(), row.line))?;
            let marker1 = row.distance_m.and_then(|_| poses.pop());
            push_errors(row, &poses, marker1.as_ref(), None, &mut e);
        }
        set.after.pose = Some(pose_figures(&e));
        if let Some(errors) = &mut set.errors {
            errors.position_after_m = e.position;
            errors.distance_after_m = e.distance;
        }
    }
    Ok(())
}

/// The report of the measured calibration `out` of `robot` with `plan`'s settings:
/// `warnings` the tables' and the calibration's, `start` when the command began.
fn calibration_report(
    plan: &crate::inputs::Plan,
    robot: &Robot,
    out: &MeasuredOutcome,
    warnings: Vec<String>,
    start: std::time::Instant,
) -> crate::report::CalibrationReport {
    let id = &out.fitted.identified;
    crate::report::CalibrationReport {
        device: plan.device.display().to_string(),
        model: out.rung,
        folds: plan.folds,
        cross_validation: Vec::new(),
        cross_validated_rows: out.cross_validated_rows,
        ladder: out.ladder.clone(),
        frames: out.frames.clone(),
        sigma_m: out.weights.sigma_position_m * id.sigma,
        sigma_source: id.sigma_source.name(),
        parameters: identified_values(id, false),
        pruned: pruned_kinematics(id),
        correlated: correlated_kinematics(id),
        observability: None,
        warnings,
        termination: id.fit.termination.clone(),
        backend: crate::fit::backend_of(id),
        n_evaluations: id.fit.n_evaluations,
        n_jacobians: id.fit.n_jacobians,
        rounds: id.rounds,
        placements: set_reports(out),
        elapsed_s: start.elapsed().as_secs_f64(),
        downweighted: out.downweighted.clone(),
        range_folds: out.range_folds.clone(),
        coverage: out.coverage.clone(),
        equilibrium_step_m: out.equilibrium_step_m,
        equilibrium_refits: out.equilibrium_refits,
        implausible: out.implausible.clone(),
        refitted_lengths: out.refitted_lengths.clone(),
        origins: crate::report::joint_origins(robot.tree.tips()),
    }
}

/// The calibration record of `out` ([`crate::record::measured_record`]): `report` its report,
/// `tips` the calibration's tip links in marker order, `train` the training tables (the
/// joints' training ranges and rows).
fn calibration_record(
    robot: &Robot,
    out: &MeasuredOutcome,
    report: &crate::report::CalibrationReport,
    tips: &[String],
    train: &[MeasurementTable],
) -> hapcal_contract::Calibration {
    let id = &out.fitted.identified;
    let frame_values = identified_values(id, true);
    crate::record::measured_record(&crate::record::MeasuredRecord {
        model: out.rung,
        tips,
        load_tips: &robot.load_tips,
        joint_names: &robot.joint_names,
        prismatic: &robot.prismatic,
        calibrated: &out.model,
        parameters: &report.parameters,
        covariance: &id.covariance,
        frames: &report.frames,
        frame_values: &frame_values,
        held: crate::record::held_values(id),
        ranges: training_ranges(train, robot.joint_names.len()),
        rows: train.iter().map(|t| t.rows.len()).sum(),
    })
}

/// Holds out the last fraction `test_last` of each training table's rows (file order) as a
/// test table (`round((1 − f)·n)` rows stay to train); nothing without a fraction.
///
/// # Errors
/// A fraction outside (0, 1), or one that leaves a table no training or no test row.
pub(crate) fn split_test_last(
    train: &mut [MeasurementTable],
    test: &mut Vec<MeasurementTable>,
    test_last: Option<f64>,
) -> Result<()> {
    let Some(f) = test_last else {
        return Ok(());
    };
    if !(f > 0.0 && f < 1.0) {
        bail!("--test-last must be a fraction in (0, 1), got {f}");
    }
    for t in train {
        let n = t.rows.len();
        let k = ((1.0 - f) * n as f64).round() as usize;
        if k == 0 || k == n {
            bail!(
                "{}: --test-last {f} leaves {k} of {n} rows to train on",
                t.path.display()
            );
        }
        // Field by field: a clone of the table would copy every row first. The file's
        // warnings are said once, with its training part.
        let held = MeasurementTable {
            name: format!("{} (last {})", t.name, n - k),
            path: t.path.clone(),
            rows: t.rows.split_off(k),
            warnings: Vec::new(),
            n_markers: t.n_markers,
            has_orientation: t.has_orientation,
            has_distance: t.has_distance,
            ignored_columns: t.ignored_columns.clone(),
        };
        t.name = format!("{} (first {k})", t.name);
        test.push(held);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{
        Arc, CalibrationProblem, Line, ModelName, RangeVerdict, Vector3, lm_alone,
        negative_compliance_sigmas, rung_chains,
    };
    use faer::{Col, ColMut, ColRef, MatMut};
    use hapcal_identify::{EvalError, ParamLayout, ParamSpec, Problem, Role, RowBlocks, Unit};

    /// `y_i = a + b·t_i + c·t_i²`, in row blocks of 7.
    struct Quadratic {
        layout: ParamLayout,
        t: Vec<f64>,
        y: Vec<f64>,
    }

    impl Quadratic {
        fn new(n: usize) -> Quadratic {
            let spec = |name: &str| ParamSpec {
                name: name.into(),
                unit: Unit::Meter,
                role: Role::Model,
            };
            let t: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
            // Noise of ±1e-3 so that the fit has a residual to settle.
            let y = (t.iter().enumerate())
                .map(|(i, &t)| 0.3 - 0.2 * t + 0.5 * t * t + 1e-3 * ((i * 7 % 5) as f64 - 2.0))
                .collect();
            Quadratic {
                layout: ParamLayout::new(vec![spec("a"), spec("b"), spec("c")]),
                t,
                y,
            }
        }
        fn row(&self, x: ColRef<'_, f64>, i: usize) -> (f64, [f64; 3]) {
            let t = self.t[i];
            (x[0] + x[1] * t + x[2] * t * t - self.y[i], [1.0, t, t * t])
        }
    }

    impl Problem for Quadratic {
        fn layout(&self) -> &ParamLayout {
            &self.layout
        }
        fn n_residuals(&self) -> usize {
            self.t.len()
        }
        fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
            for i in 0..self.t.len() {
                out[i] = self.row(x, i).0;
            }
            Ok(())
        }
        fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
            for i in 0..self.t.len() {
                for (j, d) in self.row(x, i).1.into_iter().enumerate() {
                    jac[(i, j)] = d;
                }
            }
            Ok(())
        }
        fn row_blocks(&self) -> Option<&dyn RowBlocks> {
            Some(self)
        }
    }

    impl RowBlocks for Quadratic {
        fn n_blocks(&self) -> usize {
            self.t.len().div_ceil(7)
        }
        fn block_rows(&self, block: usize) -> std::ops::Range<usize> {
            7 * block..(7 * block + 7).min(self.t.len())
        }
        fn block_residuals(
            &self,
            x: ColRef<'_, f64>,
            block: usize,
            mut out: ColMut<'_, f64>,
        ) -> Result<(), EvalError> {
            for (k, i) in self.block_rows(block).enumerate() {
                out[k] = self.row(x, i).0;
            }
            Ok(())
        }
        fn block_jacobian(
            &self,
            x: ColRef<'_, f64>,
            block: usize,
            mut r_out: ColMut<'_, f64>,
            mut jac: MatMut<'_, f64>,
        ) -> Result<(), EvalError> {
            for (k, i) in self.block_rows(block).enumerate() {
                let (r, d) = self.row(x, i);
                r_out[k] = r;
                for (j, d) in d.into_iter().enumerate() {
                    jac[(k, j)] = d;
                }
            }
            Ok(())
        }
    }

    #[test]
    fn a_refit_past_the_entry_bound_streams_and_finds_the_dense_estimate() {
        let problem = Quadratic::new(100);
        let x0 = || Col::from_fn(3, |i| [0.25, -0.1, 0.4][i]);
        let free = [0, 1, 2];
        let lm = crate::fit::identify_config(None).lm;
        // 300 entries: under a bound of 300 the fit is dense, under 299 it streams (the
        // streaming back end keeps no residuals).
        let dense = lm_alone(&problem, x0(), &free, &lm, None, 300).expect("a well-posed fit");
        let streamed = lm_alone(&problem, x0(), &free, &lm, None, 299).expect("a well-posed fit");
        assert_eq!(dense.residuals.nrows(), 100);
        assert_eq!(streamed.residuals.nrows(), 0);
        // The same steps up to rounding: the estimates agree far below their scatter (the
        // noise of 1e-3 over 100 rows moves them by about 1e-4).
        for k in 0..3 {
            assert!(
                (dense.x[k] - streamed.x[k]).abs() < 1e-10,
                "parameter {k}: dense {} streamed {}",
                dense.x[k],
                streamed.x[k]
            );
        }
        assert!((dense.x[2] - 0.5).abs() < 1e-2, "c = {}", dense.x[2]);
    }

    #[test]
    fn the_negative_compliance_bound_is_the_bonferroni_normal_quantile() {
        // One estimate: the floor of 2σ (Φ⁻¹(0.95) = 1.645 is below it). 12 and 33 estimates:
        // Φ⁻¹(1 − 0.05/n) = 2.638 and 2.965 (normal tables).
        assert_eq!(negative_compliance_sigmas(1), 2.0);
        assert!((negative_compliance_sigmas(12) - 2.638).abs() < 2e-3);
        assert!((negative_compliance_sigmas(33) - 2.965).abs() < 2e-3);
    }

    #[test]
    fn a_line_through_exact_points_predicts_them_with_no_error() {
        let x = [0.1, 0.3, 0.5, 0.7, 0.9];
        let y: Vec<f64> = x.iter().map(|v| 2.0 - 3.0 * v).collect();
        let line = Line::fit(&x, &y).expect("five spread points");
        assert!((line.slope + 3.0).abs() < 1e-12);
        let (at, se) = line.at(1.5);
        assert!(
            (at - (2.0 - 4.5)).abs() < 1e-12 && se < 1e-12,
            "{at} ± {se}"
        );
        assert_eq!(Line::fit(&[0.2, 0.2, 0.2], &[1.0, 2.0, 3.0]), None);
        assert_eq!(Line::fit(&[0.1, 0.2], &[1.0, 2.0]), None);
    }

    #[test]
    fn a_prediction_beyond_the_points_is_less_certain() {
        // Residuals ±0.1 about y = x: s² = 4·0.01/3; at the centre se = s/√5, at x̄ + 1 it
        // grows by √(1 + 5/Sxx) with Sxx = 0.4.
        let x = [0.1, 0.3, 0.5, 0.7, 0.9];
        let y = [0.2, 0.2, 0.5, 0.8, 0.8];
        let line = Line::fit(&x, &y).expect("five spread points");
        let (_, near) = line.at(0.5);
        let (_, far) = line.at(1.5);
        let s = (line.s2).sqrt();
        assert!((near - s / 5f64.sqrt()).abs() < 1e-12);
        assert!(
            (far / near - (1.0f64 + 5.0 / 0.4).sqrt()).abs() < 1e-9,
            "{near} {far}"
        );
    }

    #[test]
    fn nested_rungs_are_fitted_in_the_chain_of_the_rung_they_start_from() {
        // 0 frames only, 1 geometric, 2 isotropic, 3 per axis (from 2), 4 harmonic.
        let parent = [None, None, None, Some(2), None];
        assert_eq!(
            rung_chains(&parent),
            vec![vec![2, 3], vec![0], vec![1], vec![4]]
        );
        // Every rung exactly once, after its parent.
        let parent = [None, Some(0), Some(1), Some(0), None];
        let chains = rung_chains(&parent);
        assert_eq!(chains, vec![vec![0, 1, 3, 2], vec![4]]);
        let mut all: Vec<usize> = chains.concat();
        all.sort_unstable();
        assert_eq!(all, [0, 1, 2, 3, 4]);
    }

    #[test]
    fn a_rung_is_taken_only_when_better_by_the_margin_and_not_fading() {
        let verdict = |d: f64, se: f64, growth: f64| RangeVerdict {
            predicted: (d, se),
            growth,
            judged: true,
        };
        assert!(verdict(-3.0, 1.0, -0.5).allows());
        // Better, but not by two standard errors.
        assert!(!verdict(-1.5, 1.0, -0.5).allows());
        // Better by the margin, but the advantage shrinks with the extrapolation.
        assert!(!verdict(-3.0, 1.0, 0.2).allows());
        // A fold that could not fit it judges nothing.
        let unfit = RangeVerdict {
            judged: false,
            ..verdict(-3.0, 1.0, -0.5)
        };
        assert!(!unfit.allows());
    }

    /// A marker sample at `position_m`, no orientation.
    fn marker_sample(marker: usize, position_m: [f64; 3]) -> hapcal_io::MarkerSample {
        hapcal_io::MarkerSample {
            marker,
            position_m,
            rotation: None,
        }
    }

    #[test]
    fn training_rows_show_their_bounded_samples_and_borrow_the_others() {
        use super::{BoundedSample, Training};
        let row = |line: u64| hapcal_io::MeasuredRow {
            line,
            q: vec![0.1 * line as f64; 3].into(),
            t_s: None,
            markers: vec![
                marker_sample(0, [line as f64, 0.0, 0.0]),
                marker_sample(1, [0.0, line as f64, 0.0]),
            ],
            distance_m: None,
        };
        let table = |first: u64| {
            let rows = (first..first + 3).map(row).collect();
            hapcal_io::MeasurementTable::positions("t", "t.csv", 2, rows)
        };
        let tables = [table(2), table(10)];
        let bounded = [
            BoundedSample {
                at: (0, 1, 1),
                position_m: [7.0, 8.0, 9.0],
            },
            BoundedSample {
                at: (1, 0, 0),
                position_m: [4.0, 5.0, 6.0],
            },
            BoundedSample {
                at: (1, 0, 1),
                position_m: [1.0, 2.0, 3.0],
            },
        ];
        let seen = Training::with_bounded(&tables, &bounded);
        // The same rows as a copy of the tables with the bounded positions written in.
        let mut copy = tables.to_vec();
        for b in &bounded {
            let (ti, ri, mi) = b.at;
            copy[ti].rows[ri].markers[mi].position_m = b.position_m;
        }
        for (ti, t) in copy.iter().enumerate() {
            for (ri, expected) in t.rows.iter().enumerate() {
                let row = seen.row(ti, ri);
                assert_eq!(*row, *expected, "table {ti}, row {ri}");
                let has_bounded = bounded.iter().any(|b| (b.at.0, b.at.1) == (ti, ri));
                assert_eq!(
                    matches!(row, std::borrow::Cow::Owned(_)),
                    has_bounded,
                    "table {ti}, row {ri}: only a row with a bounded sample is rebuilt"
                );
            }
        }
        let all = |_: usize, _: usize| true;
        assert_eq!(
            super::observations(seen, &all),
            super::observations(Training::measured(&copy), &all)
        );
        assert_ne!(
            super::observations(Training::measured(&tables), &all),
            super::observations(seen, &all)
        );
    }

    /// The iiwa of fixtures/mukca with its `ball_link` tip, and a tracker table of `n` rows,
    /// each `row(i, q, p, rng)` at joint readings `q` drawn uniform in 80 % of the joint limits
    /// (seed `seed`, the same generator `rng` the row may draw from next) where the nominal
    /// robot puts the tip at `p` (m).
    fn iiwa_tracker(
        seed: u64,
        n: usize,
        mut row: impl FnMut(
            usize,
            Vec<f64>,
            super::Point3<f64>,
            &mut rand_chacha::ChaCha8Rng,
        ) -> hapcal_io::MeasuredRow,
    ) -> (super::Robot, hapcal_io::MeasurementTable) {
        use rand::{Rng, SeedableRng};
        let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/mukca/urdf/iiwa14.urdf");
        let robot = super::robot_from_urdf(&urdf, &["ball_link".to_owned()]).expect("the iiwa");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let nominal = vec![0.0; robot.tree.n_params()];
        let rows = (0..n)
            .map(|i| {
                let q: Vec<f64> = (robot.limits.iter())
                    .map(|(lo, hi)| rng.random_range(0.8 * lo..0.8 * hi))
                    .collect();
                let p = robot.tree.tips()[0].end_point(&nominal, &q);
                row(i, q, p, &mut rng)
            })
            .collect();
        let table = hapcal_io::MeasurementTable::positions("tracker", "tracker.csv", 1, rows);
        (robot, table)
    }

    #[test]
    fn the_huber_pass_bounds_a_gross_error_where_the_fits_read_it() {
        use super::{Start, Training, observations, weighted_frames_only, winsorize};
        use rand::Rng;
        // 120 rows of the nominal robot, noise of ±0.1 mm per axis; row 37 20 mm off along y
        // (two hundred times the noise).
        let (robot, table) = iiwa_tracker(3, 120, |i, q, p, rng| {
            let mut position_m: [f64; 3] =
                std::array::from_fn(|a| p[a] + rng.random_range(-1e-4..1e-4));
            if i == 37 {
                position_m[1] += 0.02;
            }
            hapcal_io::MeasuredRow {
                line: i as u64 + 2,
                q: q.into(),
                t_s: None,
                markers: vec![marker_sample(0, position_m)],
                distance_m: None,
            }
        });
        let tables = [table];
        let cfg = super::MeasuredConfig::default();
        let (frames, weights) = weighted_frames_only(&robot, &tables, &cfg, 120).expect("frames");
        let start = Start {
            tree: &frames.framed,
            x: &frames.fitted.x,
            nested: None,
            max_evaluations: None,
        };
        let (samples, downweighted, _, _) = winsorize(
            ModelName::JointOffsets,
            &frames.robot,
            &start,
            &frames.offsets,
            &tables,
            weights,
        )
        .expect("the Huber pass");
        assert_eq!(samples.len(), 1, "{samples:?}");
        assert_eq!(samples[0].at, (0, 37, 0));
        assert_eq!(downweighted.len(), 1);
        assert_eq!(downweighted[0].line, 39);
        // The bounded position is `p + e·c/|e|`: the measured one moved toward the model by
        // the residual beyond the corner (rounding of a few ulps of the 1 m positions).
        let measured = Vector3::from(tables[0].rows[37].markers[0].position_m);
        let moved = (measured - Vector3::from(samples[0].position_m)).norm();
        let beyond = downweighted[0].residual_m - downweighted[0].bound_m;
        assert!(beyond > 0.01, "{downweighted:?}");
        assert!(
            (moved - beyond).abs() < 1e-12,
            "{moved} m against {beyond} m"
        );
        // What every fit after the pass reads: the tables with the bounded position written
        // in.
        let mut copy = tables.to_vec();
        copy[0].rows[37].markers[0].position_m = samples[0].position_m;
        let all = |_: usize, _: usize| true;
        assert_eq!(
            observations(Training::with_bounded(&tables, &samples), &all),
            observations(Training::measured(&copy), &all)
        );
    }

    /// Rows that repeat an earlier row of their table scale σ by √(rows / distinct rows):
    /// a table appended to itself by √2, over the rows selected only; the same row in another
    /// table, or with another reading (−0 is +0), is no copy.
    #[test]
    fn rows_that_repeat_others_scale_the_compliance_test_sigma() {
        use super::{Training, repeat_std_scale};
        let row = |q0: f64| hapcal_io::MeasuredRow {
            line: 2,
            q: vec![q0, 0.5].into(),
            t_s: None,
            markers: vec![marker_sample(0, [1.0, 2.0, 3.0])],
            distance_m: None,
        };
        let table = |q: &[f64]| {
            hapcal_io::MeasurementTable::positions(
                "t",
                "t.csv",
                1,
                q.iter().map(|&q| row(q)).collect(),
            )
        };
        let all = |_: usize, _: usize| true;
        let once = [table(&[0.1, 0.2, 0.3])];
        assert_eq!(repeat_std_scale(Training::measured(&once), &all), 1.0);
        let twice = [table(&[0.1, 0.2, 0.3, 0.1, 0.2, 0.3])];
        let scale = repeat_std_scale(Training::measured(&twice), &all);
        assert!((scale - 2f64.sqrt()).abs() < 1e-15, "{scale}");
        let first_half = |_: usize, ri: usize| ri < 3;
        assert_eq!(
            repeat_std_scale(Training::measured(&twice), &first_half),
            1.0
        );
        let signed = [table(&[0.0, -0.0, 1e-300])];
        let scale = repeat_std_scale(Training::measured(&signed), &all);
        assert!((scale - 1.5f64.sqrt()).abs() < 1e-15, "{scale}");
        let apart = [table(&[0.1]), table(&[0.1])];
        assert_eq!(repeat_std_scale(Training::measured(&apart), &all), 1.0);
    }

    #[test]
    fn observation_rows_share_their_file_rows_readings_and_give_the_same_residuals() {
        use super::{Observations, Problem, Row, Training, observations, weighted_frames_only};
        // 40 rows of the nominal robot, each a marker and a distance: two observation rows of
        // one configuration.
        let (robot, table) = iiwa_tracker(5, 40, |i, q, p, _| hapcal_io::MeasuredRow {
            line: i as u64 + 2,
            q: q.into(),
            t_s: None,
            markers: vec![marker_sample(0, [p[0], p[1], p[2]])],
            distance_m: Some(p.coords.norm()),
        });
        let mut tables = [table];
        let cfg = super::MeasuredConfig::default();
        let (frames, weights) = weighted_frames_only(&robot, &tables, &cfg, 40).expect("frames");
        tables[0].has_distance = true;
        let all = |_: usize, _: usize| true;
        let shared = observations(Training::measured(&tables), &all);
        assert_eq!(shared.rows.len(), 80);
        for (k, row) in tables[0].rows.iter().enumerate() {
            for r in &shared.rows[2 * k..2 * k + 2] {
                assert!(
                    Arc::ptr_eq(&r.q, &row.q),
                    "row {k}: its observation rows hold a copy of its readings"
                );
            }
        }
        // The same observations, each row with its own copy of the readings.
        let copied = Observations {
            rows: (shared.rows.iter())
                .map(|r| Row::new(r.q.to_vec(), r.kind.clone()))
                .collect(),
            ..shared.clone()
        };
        assert!(!Arc::ptr_eq(&copied.rows[0].q, &copied.rows[1].q));
        assert_eq!(shared.configurations().count(), 40);
        assert_eq!(copied.configurations().count(), 40);
        let problem = |obs: Observations| {
            let terms = super::terms(ModelName::TransversalCompliance, &frames.robot)
                .expect("the rung's terms");
            CalibrationProblem::on_tree(frames.framed.clone(), obs, weights, terms)
                .expect("the problem")
        };
        let (shared, copied) = (problem(shared), problem(copied));
        let n = shared.layout().len();
        assert_eq!(copied.layout().len(), n);
        // Every deviation and compliance a little off zero, so that every term moves the
        // residuals.
        let x = Col::from_fn(n, |i| 1e-3 * ((i * 7 % 5) as f64 - 2.0));
        let m = shared.n_residuals();
        let (mut r_shared, mut r_copied) = (Col::zeros(m), Col::zeros(m));
        shared
            .residuals(x.as_ref(), r_shared.as_mut())
            .expect("residuals");
        copied
            .residuals(x.as_ref(), r_copied.as_mut())
            .expect("residuals");
        let (mut j_shared, mut j_copied) = (faer::Mat::zeros(m, n), faer::Mat::zeros(m, n));
        shared
            .jacobian(x.as_ref(), j_shared.as_mut())
            .expect("Jacobian");
        copied
            .jacobian(x.as_ref(), j_copied.as_mut())
            .expect("Jacobian");
        for i in 0..m {
            assert_eq!(r_shared[i].to_bits(), r_copied[i].to_bits(), "residual {i}");
            for j in 0..n {
                assert_eq!(
                    j_shared[(i, j)].to_bits(),
                    j_copied[(i, j)].to_bits(),
                    "Jacobian entry ({i}, {j})"
                );
            }
        }
        assert!(r_shared.norm_l2() > 0.0);
    }
}
