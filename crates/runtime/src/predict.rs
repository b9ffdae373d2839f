//! The calibrated model's prediction at new joint readings, with its 1σ uncertainty from the
//! calibration record's covariance and whether the readings lie outside the region the model
//! was fitted on: what `hapcal predict` prints.
//!
//! The uncertainty is first-order propagation (GUM, JCGM 100:2008, §5.1.2; the law of
//! propagation of uncertainty): for a predicted position `p(v)` of the recorded values `v`
//! with covariance `Σ`, `Cov(p) = G·Σ·Gᵀ` with `G = ∂p/∂v` (3 × m), and the reported σ is
//! `√trace(G·Σ·Gᵀ)`, the RMS length of the 3-D position error (m). Each column of `G` is a
//! central difference through [`Robot::with_value`], so the derivative is of the model the
//! runtime evaluates (rigid geometry and every deflection term) whatever the value's kind.

use crate::{Error, Pose, Robot, RobotWorkspace};

/// Step of the central differences, as a share of each value's standard deviation: small
/// enough that the model is linear over it (the truncation error is of order share² of the
/// σ), large enough that rounding stays far below it.
pub const STEP_SHARE_OF_STD: f64 = 1e-3;

/// Least step of the central differences, in the value's unit (m, rad, rad/(N·m), …): a
/// value whose standard deviation is below `STEP_FLOOR / STEP_SHARE_OF_STD` is still
/// differenced over a step rounding cannot swamp.
pub const STEP_FLOOR: f64 = 1e-12;

/// The frame the predictions are expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PredictionFrame {
    /// The robot's root link frame, and each tip link's own frame.
    Root,
    /// The calibration's instrument frame ([`Robot::frame`] `"instrument"`), and on tip `k`
    /// (0-based) the frame of marker `k + 1` (`"marker1"`, …; the tip link's frame where the
    /// calibration identified no such marker): what the instrument measured.
    Instrument,
}

/// What a prediction's uncertainty rests on ([`UncertaintyBasis::name`] in files).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UncertaintyBasis {
    /// The calibration record's covariance of the values.
    Covariance,
    /// The record holds no covariance: the values' standard deviations as a diagonal
    /// covariance (their correlations are ignored, so σ can be too large or too small).
    StdsOnly,
    /// The robot has no calibration record: no uncertainty.
    NoRecord,
    /// The record holds no identified value (a frames-only calibration: only the instrument
    /// and marker frames, whose uncertainty it does not hold): no uncertainty.
    NoValues,
}

/// One tip's prediction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipPrediction {
    /// The predicted pose (tip link or marker frame) in the [`PredictionFrame`], m.
    pub pose: Pose,
    /// 1σ of the predicted position, m: `√trace(G·Σ·Gᵀ)` (see the module docs); `None`
    /// when there is no uncertainty to propagate ([`Predictor::uncertainty_unavailable`]).
    pub sigma_m: Option<f64>,
    /// 1σ of each coordinate `x, y, z` of the predicted position in the prediction's frame,
    /// m: the square roots of the diagonal of `G·Σ·Gᵀ` (their root sum of squares is
    /// [`Self::sigma_m`]); `None` likewise.
    pub sigma_axes_m: Option<[f64; 3]>,
    /// 1σ of the predicted orientation, rad: the same with `G` the derivative of the
    /// rotation vector; `None` likewise.
    pub sigma_rad: Option<f64>,
}

impl UncertaintyBasis {
    /// The name files and JSON write: `covariance`, `stds-only`, `none`, `frames-only`.
    pub fn name(self) -> &'static str {
        match self {
            UncertaintyBasis::Covariance => "covariance",
            UncertaintyBasis::StdsOnly => "stds-only",
            UncertaintyBasis::NoRecord => "none",
            UncertaintyBasis::NoValues => hapcal_contract::ModelName::FramesOnly.name(),
        }
    }
}

impl Default for TipPrediction {
    fn default() -> Self {
        TipPrediction {
            pose: Pose::IDENTITY,
            sigma_m: None,
            sigma_axes_m: None,
            sigma_rad: None,
        }
    }
}

/// A robot with the identified frames its predictions go through.
#[derive(Clone, Debug)]
struct Framed {
    robot: Robot,
    /// The robot's root frame in the instrument frame (identity without one).
    instrument: Pose,
    /// Marker `k + 1`'s frame on its tip link, for the markers `marker1`, `marker2`, … the
    /// calibration identified (in order, up to the first missing one).
    markers: Vec<Pose>,
}

impl Framed {
    fn new(robot: Robot) -> Framed {
        let instrument = robot.frame("instrument").unwrap_or(Pose::IDENTITY);
        let markers = (1..)
            .map_while(|k| robot.frame(&format!("marker{k}")))
            .collect();
        Framed {
            robot,
            instrument,
            markers,
        }
    }

    /// The pose of tip `k` in `frame` from the tip link poses `links`; in the instrument
    /// frame, of marker `k` (0-based) on tip `min(k, last)`.
    fn pose(&self, links: &[Pose], k: usize, frame: PredictionFrame) -> Pose {
        let tip = k.min(links.len().saturating_sub(1));
        match frame {
            PredictionFrame::Root => links[tip],
            PredictionFrame::Instrument => {
                let marker = self.markers.get(k).copied().unwrap_or(Pose::IDENTITY);
                self.instrument.compose(&links[tip]).compose(&marker)
            }
        }
    }
}

/// One value the uncertainty propagates: the robot with the value one step above and one
/// step below its record.
#[derive(Clone, Debug)]
struct Sensitivity {
    plus: Framed,
    minus: Framed,
    /// The two robots' distance in the value, `2h`.
    span: f64,
}

/// The calibrated model's predictions with their uncertainty: the robot, and for each value
/// of the covariance the robot with that value a step above and below its record (built once
/// by [`Predictor::new`]; a prediction then evaluates `2m + 1` deflected robots).
#[derive(Clone, Debug)]
pub struct Predictor {
    center: Framed,
    frame: PredictionFrame,
    sensitivities: Vec<Sensitivity>,
    /// Σ over the sensitivities' values, row-major, `m × m`.
    covariance: Vec<f64>,
    basis: UncertaintyBasis,
    unavailable: Option<(String, Error)>,
}

/// Buffers of [`Predictor`]'s calls, sized for one predictor ([`Predictor::workspace`]).
#[derive(Clone, Debug)]
pub struct PredictionWorkspace {
    robot: RobotWorkspace,
    links: Vec<Pose>,
    /// Poses of every tip of a robot a step above and below.
    plus: Vec<Pose>,
    minus: Vec<Pose>,
    /// Per tip and value, the derivative of the position (0–2, m per unit) and of the
    /// rotation vector (3–5, rad per unit).
    gradient: Vec<[f64; 6]>,
}

/// Of the rotation matrix `r`: `v = vee(R − Rᵀ) = 2 sin θ·axis`, its norm, and the angle θ
/// (rad, in `[0, π]`) from `atan2(‖v‖/2, (trace − 1)/2)`, accurate near 0, unlike
/// `acos((trace − 1)/2)`.
fn vee_and_angle(r: &[[f64; 3]; 3]) -> ([f64; 3], f64, f64) {
    let v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let angle = libm::atan2(norm / 2.0, (r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0);
    (v, norm, angle)
}

/// The rotation vector `ω` (axis × angle, rad) of the rotation matrix `r` ([`vee_and_angle`]),
/// accurate at every angle short of π (the differences here are of rotations a step apart).
fn rotation_vector(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let (v, norm, angle) = vee_and_angle(r);
    // ω = θ/(2 sin θ)·v; the factor tends to 1/2 as θ → 0.
    let factor = if norm < 1e-300 { 0.5 } else { angle / norm };
    [v[0] * factor, v[1] * factor, v[2] * factor]
}

/// One marker as an instrument measured it in one row of a measurement file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkerObservation {
    /// The marker, 0-based (`x1, y1, z1` is marker 0; it sits on tip `min(marker, last)`).
    pub marker: usize,
    /// Its position in the instrument frame, m.
    pub position_m: [f64; 3],
    /// Its orientation in the instrument frame, quaternion `[w, x, y, z]`, if measured.
    pub rotation_wxyz: Option<[f64; 4]>,
}

/// Mean, RMS and largest of a set of non-negative errors, accumulated one at a time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorFigures {
    /// Number of errors.
    pub count: usize,
    sum: f64,
    sum_sq: f64,
    max: f64,
}

impl ErrorFigures {
    /// Adds the error `e` (its absolute value).
    pub fn push(&mut self, e: f64) {
        let e = e.abs();
        self.count += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.max = self.max.max(e);
    }

    /// Mean error (0 without errors).
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// Root mean square error (0 without errors).
    pub fn rms(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.sum_sq / self.count as f64).sqrt()
        }
    }

    /// Largest error (0 without errors).
    pub fn max(&self) -> f64 {
        self.max
    }
}

/// The errors of the predictions against what an instrument measured, as `hapcal
/// calibrate`'s report gives them for a data set: the 3-D distance between predicted and
/// measured marker positions (m), the angle between predicted and measured orientations
/// (rad), and the absolute difference of the anchor distance (m).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeasuredErrors {
    /// Position errors, one per marker sample, m.
    pub position: ErrorFigures,
    /// Orientation errors, one per marker sample with an orientation, rad.
    pub orientation: ErrorFigures,
    /// Distance errors, one per row with a distance (from the instrument origin, the anchor,
    /// to marker 1's frame), m.
    pub distance: ErrorFigures,
}

/// `a · bᵀ` of two rotations.
pub(crate) fn relative(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2])
    })
}

impl Predictor {
    /// The predictor of `robot` in `frame`: for every value of the record's covariance (or,
    /// without one, every recorded value with its standard deviation) whose variance is not
    /// zero, the robot with that value at its record ± `h`, `h` = [`STEP_SHARE_OF_STD`] of its
    /// σ (at least [`STEP_FLOOR`]), through [`Robot::with_value`]. A value the runtime cannot
    /// vary leaves the predictions without σ and is named by
    /// [`Predictor::uncertainty_unavailable`]; the predictions themselves do not depend on it.
    ///
    /// # Errors
    /// [`Error::Invalid`] named `"instrument frame"` for [`PredictionFrame::Instrument`] on a
    /// robot without an identified instrument frame.
    pub fn new(robot: &Robot, frame: PredictionFrame) -> Result<Self, Error> {
        if frame == PredictionFrame::Instrument && robot.frame("instrument").is_none() {
            return Err(Error::Invalid {
                what: "instrument frame",
                value: 0.0,
                expected: "a robot whose calibration identified an instrument frame",
            });
        }
        let center = Framed::new(robot.clone());
        let mut out = Predictor {
            center,
            frame,
            sensitivities: Vec::new(),
            covariance: Vec::new(),
            basis: UncertaintyBasis::NoRecord,
            unavailable: None,
        };
        let Some(record) = robot.calibration() else {
            return Ok(out);
        };
        if record.values.is_empty() {
            out.basis = UncertaintyBasis::NoValues;
            return Ok(out);
        }
        // (name, recorded value, row in the full covariance)
        let (names, full): (Vec<&str>, Vec<f64>) = match &record.covariance {
            Some(c) => {
                out.basis = UncertaintyBasis::Covariance;
                let n = c.names.len();
                let full = (0..n * n).map(|k| c.get(k / n, k % n)).collect();
                (c.names.iter().map(String::as_str).collect(), full)
            }
            None => {
                out.basis = UncertaintyBasis::StdsOnly;
                let n = record.values.len();
                let mut full = vec![0.0; n * n];
                for (i, v) in record.values.iter().enumerate() {
                    full[i * n + i] = v.std * v.std;
                }
                (
                    record.values.iter().map(|v| v.name.as_str()).collect(),
                    full,
                )
            }
        };
        let n = names.len();
        let kept: Vec<usize> = (0..n).filter(|&i| full[i * n + i] > 0.0).collect();
        for &i in &kept {
            let name = names[i];
            let Some(recorded) = record.value(name).map(|v| v.value) else {
                // The contract's check refuses a covariance over a value not recorded.
                continue;
            };
            let h = (STEP_SHARE_OF_STD * full[i * n + i].sqrt()).max(STEP_FLOOR);
            let pair = robot
                .with_value(name, recorded + h)
                .and_then(|plus| Ok((plus, robot.with_value(name, recorded - h)?)));
            match pair {
                Ok((plus, minus)) => out.sensitivities.push(Sensitivity {
                    plus: Framed::new(plus),
                    minus: Framed::new(minus),
                    span: 2.0 * h,
                }),
                Err(e) => {
                    out.sensitivities.clear();
                    out.unavailable = Some((name.to_owned(), e));
                    return Ok(out);
                }
            }
        }
        out.covariance = (kept.iter())
            .flat_map(|&i| kept.iter().map(move |&j| (i, j)))
            .map(|(i, j)| full[i * n + j])
            .collect();
        Ok(out)
    }

    /// The robot predictions are made with.
    pub fn robot(&self) -> &Robot {
        &self.center.robot
    }

    /// The frame the predictions are in.
    pub fn frame(&self) -> PredictionFrame {
        self.frame
    }

    /// What the uncertainty rests on.
    pub fn basis(&self) -> UncertaintyBasis {
        self.basis
    }

    /// What the prediction's σ rests on, in words, when it is not the record's covariance:
    /// the note `hapcal predict` and Python's `predict` print; `None` with a covariance.
    pub fn uncertainty_note(&self) -> Option<String> {
        match (self.basis, self.uncertainty_unavailable()) {
            (_, Some((name, e))) => Some(format!(
                "no σ: the runtime cannot vary the recorded value {name:?} ({e})"
            )),
            (UncertaintyBasis::NoRecord, None) => Some(
                "no σ: the robot has no calibration record (its sidecar robot.calibration.toml \
                 with the values' standard deviations)"
                    .to_owned(),
            ),
            (UncertaintyBasis::NoValues, None) => Some(
                "no σ: the calibration identified only the instrument and marker frames, whose \
                 uncertainty the record does not hold"
                    .to_owned(),
            ),
            (UncertaintyBasis::StdsOnly, None) => Some(
                "the calibration record holds no covariance: σ from the values' standard \
                 deviations alone, their correlations ignored"
                    .to_owned(),
            ),
            (UncertaintyBasis::Covariance, None) => None,
        }
    }

    /// Whether the predictions carry a σ: a record whose values could all be varied.
    pub fn has_uncertainty(&self) -> bool {
        matches!(
            self.basis,
            UncertaintyBasis::Covariance | UncertaintyBasis::StdsOnly
        ) && self.unavailable.is_none()
    }

    /// The value [`Robot::with_value`] refused, and why, when that left the predictions
    /// without σ.
    pub fn uncertainty_unavailable(&self) -> Option<(&str, Error)> {
        (self.unavailable.as_ref()).map(|(name, e)| (name.as_str(), *e))
    }

    /// Number of values the uncertainty propagates (those of nonzero variance).
    pub fn n_values(&self) -> usize {
        self.sensitivities.len()
    }

    /// Buffers for this predictor's calls (allocates; make it once).
    pub fn workspace(&self) -> PredictionWorkspace {
        let n_tips = self.center.robot.tip_names().len();
        PredictionWorkspace {
            robot: self.center.robot.workspace(),
            links: vec![Pose::IDENTITY; n_tips],
            plus: vec![Pose::IDENTITY; n_tips],
            minus: vec![Pose::IDENTITY; n_tips],
            gradient: vec![[0.0; 6]; n_tips * self.sensitivities.len()],
        }
    }

    /// Poses of `framed`'s tips (markers) 0..out.len() at `q` in `frame`, into `out`.
    fn poses_of(
        framed: &Framed,
        frame: PredictionFrame,
        q: &[f64],
        robot_ws: &mut RobotWorkspace,
        links: &mut [Pose],
        out: &mut [Pose],
    ) -> Result<(), Error> {
        framed.robot.deflected_tip_poses(q, robot_ws, links)?;
        for (k, pose) in out.iter_mut().enumerate() {
            *pose = framed.pose(links, k, frame);
        }
        Ok(())
    }

    /// The predicted poses of every tip at the joint readings `q` (rad, m for a prismatic
    /// joint; in the order of [`Robot::joint_names`]) with their σ, into `out` (one per tip):
    /// the robot deflected under its own weight ([`Robot::deflected_tip_poses`]) in the
    /// predictor's frame. No allocation.
    ///
    /// # Errors
    /// As [`Robot::deflected_tip_poses`]: [`Error::Length`] unless `q` has n entries and
    /// `out` one per tip; [`Error::NotFinite`] for a NaN or infinite reading.
    ///
    /// # Panics
    /// If `ws` was made for another predictor.
    #[track_caller]
    pub fn predict(
        &self,
        q: &[f64],
        ws: &mut PredictionWorkspace,
        out: &mut [TipPrediction],
    ) -> Result<(), Error> {
        let n_tips = self.center.robot.tip_names().len();
        let m = self.sensitivities.len();
        assert_eq!(
            ws.gradient.len(),
            n_tips * m,
            "a workspace of another predictor"
        );
        crate::error::check_len("tip predictions", n_tips, out.len())?;
        let PredictionWorkspace {
            robot: robot_ws,
            links,
            plus,
            minus,
            gradient,
        } = ws;
        Self::poses_of(&self.center, self.frame, q, robot_ws, links, plus)?;
        for (p, pose) in out.iter_mut().zip(plus.iter()) {
            *p = TipPrediction {
                pose: *pose,
                ..TipPrediction::default()
            };
        }
        if !self.has_uncertainty() {
            return Ok(());
        }
        for (i, s) in self.sensitivities.iter().enumerate() {
            Self::poses_of(&s.plus, self.frame, q, robot_ws, links, plus)?;
            Self::poses_of(&s.minus, self.frame, q, robot_ws, links, minus)?;
            for (tip, (a, b)) in plus.iter().zip(minus.iter()).enumerate() {
                let w = rotation_vector(&relative(&a.rotation, &b.rotation));
                let g = &mut gradient[tip * m + i];
                for axis in 0..3 {
                    g[axis] = (a.translation_m[axis] - b.translation_m[axis]) / s.span;
                    g[3 + axis] = w[axis] / s.span;
                }
            }
        }
        for (tip, p) in out.iter_mut().enumerate() {
            let g = &gradient[tip * m..(tip + 1) * m];
            let (mut var_axes, mut var_rad) = ([0.0; 3], 0.0);
            for i in 0..m {
                for j in 0..m {
                    let c = self.covariance[i * m + j];
                    if c == 0.0 {
                        continue;
                    }
                    for (a, v) in var_axes.iter_mut().enumerate() {
                        *v += c * g[i][a] * g[j][a];
                    }
                    var_rad += c * (3..6).map(|a| g[i][a] * g[j][a]).sum::<f64>();
                }
            }
            let var_m: f64 = var_axes.iter().sum();
            // A covariance is positive semi-definite; rounding can leave −0.
            p.sigma_axes_m = Some(var_axes.map(|v: f64| v.max(0.0).sqrt()));
            p.sigma_m = Some(var_m.max(0.0).sqrt());
            p.sigma_rad = Some(var_rad.max(0.0).sqrt());
        }
        Ok(())
    }

    /// The predicted poses of the measurement's markers at `q`, into `out` (one per marker,
    /// `k` = 0-based marker index), whatever the predictor's frame: in the instrument frame,
    /// marker `k + 1`'s frame on tip `min(k, last)` (how `hapcal calibrate` places the markers
    /// of a measurement file; without an identified instrument frame or marker, the root frame
    /// or the tip link). What a measured row is compared with. No allocation.
    ///
    /// # Errors
    /// As [`Predictor::predict`] (any number of markers is accepted).
    pub fn marker_poses_into(
        &self,
        q: &[f64],
        ws: &mut PredictionWorkspace,
        out: &mut [Pose],
    ) -> Result<(), Error> {
        let PredictionWorkspace {
            robot: robot_ws,
            links,
            ..
        } = ws;
        let frame = PredictionFrame::Instrument;
        Self::poses_of(&self.center, frame, q, robot_ws, links, out)
    }

    /// Adds the errors of one measured row at the readings `q` to `errors`: each marker's
    /// position (and orientation) against its predicted pose in the instrument frame
    /// ([`Predictor::marker_poses_into`]), and the distance `distance_m` from the instrument
    /// origin to marker 1's frame. Nothing is refitted. No allocation.
    ///
    /// # Errors
    /// As [`Predictor::predict`].
    pub fn add_errors(
        &self,
        q: &[f64],
        markers: &[MarkerObservation],
        distance_m: Option<f64>,
        ws: &mut PredictionWorkspace,
        errors: &mut MeasuredErrors,
    ) -> Result<(), Error> {
        self.center
            .robot
            .deflected_tip_poses(q, &mut ws.robot, &mut ws.links)?;
        let frame = PredictionFrame::Instrument;
        if let Some(d) = distance_m {
            let p = self.center.pose(&ws.links, 0, frame).translation_m;
            let predicted = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            errors.distance.push(predicted - d);
        }
        for m in markers {
            let pose = self.center.pose(&ws.links, m.marker, frame);
            let e = core::array::from_fn::<f64, 3, _>(|a| pose.translation_m[a] - m.position_m[a]);
            errors
                .position
                .push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
            if let Some(wxyz) = m.rotation_wxyz {
                let measured = Pose::rotation_of_quaternion(wxyz);
                errors
                    .orientation
                    .push(vee_and_angle(&relative(&pose.rotation, &measured)).2);
            }
        }
        Ok(())
    }
}
