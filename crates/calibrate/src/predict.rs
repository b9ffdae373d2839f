//! Predictions of a calibrated device, without refitting: the tip positions (or poses) of
//! a calibrated robot ([`hapcal_runtime::Predictor`]) at every row of a measurement file, with
//! their 1σ uncertainty and the region flag, and, with measured columns, the errors of the
//! predictions against them; for a haptic device's file (capstans, parallelogram), the
//! handle's position from the joint readings of a log ([`hapcal_runtime::Model`]) and, with
//! its cable distances, the distance errors. What `hapcal predict` prints and writes.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, bail};
use hapcal_io::{JointSchema, MeasurementTable, Units};
use hapcal_runtime::{
    ErrorFigures, MarkerObservation, MeasuredErrors, Model, PredictionFrame, Predictor, Robot,
    TipPrediction,
};
use nalgebra::{Rotation3, UnitQuaternion};
use serde::Serialize;

/// One tip's prediction at one row, SI units.
#[derive(Clone, Debug, Serialize)]
pub struct TipRow {
    /// Position, m.
    pub position_m: [f64; 3],
    /// Orientation, unit quaternion `[w, x, y, z]` (with `--poses`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quaternion_wxyz: Option<[f64; 4]>,
    /// 1σ of the position (RMS length of its error), m; absent without an uncertainty.
    pub sigma_m: Option<f64>,
    /// 1σ of the orientation, rad (with `--poses`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_rad: Option<f64>,
}

/// Where a reading lies outside the calibration's region.
#[derive(Clone, Debug, Serialize)]
pub struct OutsideRegion {
    /// The joint farthest past its training range (by share of the range).
    pub joint: String,
    /// How far past the range: positive above it, negative below; rad (m for a prismatic
    /// joint).
    pub past: f64,
}

/// One row's prediction.
#[derive(Clone, Debug, Serialize)]
pub struct PredictedRow {
    /// The row's line in the data file.
    pub line: u64,
    /// One per tip, in the order of `--tip`.
    pub tips: Vec<TipRow>,
    /// Whether and where the reading lies outside the calibration's region.
    pub outside_region: Option<OutsideRegion>,
}

/// Mean, RMS and largest of one kind of error.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Figures {
    /// Number of samples.
    pub count: usize,
    /// Mean, in the unit of the key.
    pub mean: f64,
    /// RMS.
    pub rms: f64,
    /// Largest.
    pub max: f64,
}

impl Figures {
    fn of(f: &hapcal_runtime::ErrorFigures) -> Option<Figures> {
        (f.count > 0).then(|| Figures {
            count: f.count,
            mean: f.mean(),
            rms: f.rms(),
            max: f.max(),
        })
    }
}

/// The errors of the predictions against the data's measured columns (no refit).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Errors {
    /// 3-D position error per marker sample, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position_m: Option<Figures>,
    /// Orientation error per marker sample with an orientation, rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_rad: Option<Figures>,
    /// Absolute distance error per row with a distance, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_m: Option<Figures>,
}

/// What `hapcal predict --json` prints.
#[derive(Clone, Debug, Serialize)]
pub struct Prediction {
    /// The data file.
    pub data: String,
    /// `root` (the robot's root link frame, tip links), `instrument` (the calibration's
    /// instrument frame, markers) or `base` (a haptic device's base frame, its handle).
    pub frame: &'static str,
    /// The tips, in the order of each row's `tips`.
    pub tips: Vec<String>,
    /// What σ rests on: `covariance`, `stds-only` (no covariance recorded: the values'
    /// standard deviations, correlations ignored) or `none` (no record, or a haptic device).
    pub uncertainty: &'static str,
    /// Number of values σ propagates.
    pub n_values: usize,
    /// Why there is no σ, or what it leaves out, in words.
    pub uncertainty_note: Option<String>,
    /// Rows outside the calibration's region.
    pub n_outside_region: usize,
    /// The errors against the measured columns, if the data have any.
    pub errors: Option<Errors>,
    /// What the reader noticed (columns ignored, readings slightly past a limit).
    pub warnings: Vec<String>,
    /// Every row.
    pub rows: Vec<PredictedRow>,
}

/// The quaternion `[w, x, y, z]` (w ≥ 0) of the rotation matrix `r` (row-major, a proper
/// rotation; nalgebra's conversion, Shepperd's method: the largest of the four squared
/// components first, for accuracy at every angle). How `hapcal predict --poses` and the Python
/// package write orientations.
pub fn quaternion_of(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let m = nalgebra::Matrix3::from_fn(|i, j| r[i][j]);
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    let wxyz = [q.w, q.i, q.j, q.k];
    if wxyz[0] < 0.0 {
        wxyz.map(|v| -v)
    } else {
        wxyz
    }
}

/// The runtime's poses of a calibrated robot's markers in the instrument frame
/// ([`Predictor::marker_poses_into`]: marker `k + 1`'s frame on tip `min(k, last)`): what
/// `hapcal predict` compares a measured row with, what `hapcal calibrate` reports its
/// calibrated figures from and checks its written files by.
pub struct MarkerPoses {
    predictor: Predictor,
    ws: hapcal_runtime::PredictionWorkspace,
    poses: Vec<hapcal_runtime::Pose>,
}

impl MarkerPoses {
    /// The marker poses of `robot`.
    ///
    /// # Errors
    /// None in practice: [`Predictor::new`] in the root frame refuses no robot.
    pub fn new(robot: &Robot) -> Result<Self> {
        let predictor = Predictor::new(robot, PredictionFrame::Root)
            .context("preparing the runtime's evaluation of the calibrated robot")?;
        let ws = predictor.workspace();
        Ok(MarkerPoses {
            predictor,
            ws,
            poses: Vec::new(),
        })
    }

    /// The poses of `markers` (0-based) at the joint readings `q` (rad, m for a prismatic
    /// joint; the robot's joint order), in the order of `markers`, m, in the instrument frame.
    ///
    /// # Errors
    /// A reading the runtime refuses (a wrong count, a value that is not finite).
    pub fn at(&mut self, q: &[f64], markers: &[usize]) -> Result<Vec<nalgebra::Isometry3<f64>>> {
        let n = markers.iter().max().map_or(0, |m| m + 1);
        self.poses.resize(n, hapcal_runtime::Pose::IDENTITY);
        (self.predictor)
            .marker_poses_into(q, &mut self.ws, &mut self.poses)
            .context("evaluating the calibrated robot")?;
        Ok((markers.iter())
            .map(|&m| {
                let p = &self.poses[m];
                let r = nalgebra::Matrix3::from_fn(|i, j| p.rotation[i][j]);
                nalgebra::Isometry3::from_parts(
                    nalgebra::Translation3::from(nalgebra::Vector3::from(p.translation_m)),
                    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
                )
            })
            .collect())
    }
}

/// `f` of the joints of `robot` as the measurement readers check them
/// ([`hapcal_io::JointSchema`]: their names, kinds and limits, rad or m); what `predict`,
/// `compensate` and the Python package read a robot's data files with.
pub fn with_joint_schema<T>(robot: &Robot, f: impl FnOnce(&JointSchema<'_>) -> T) -> T {
    let prismatic: Vec<bool> = (0..robot.n_joints())
        .map(|j| robot.is_prismatic(j))
        .collect();
    f(&JointSchema {
        names: robot.joint_names(),
        prismatic: &prismatic,
        limits: robot.limits(),
    })
}

/// Reads the measurement file `path` with `robot`'s joints (the columns calibrate reads).
fn read_data(path: &Path, robot: &Robot, units: &Units) -> Result<MeasurementTable> {
    if path.is_dir() {
        bail!(
            "{}: a folder; predict reads a measurement file (CSV with the joints as q1..qn or \
             by name), not socket recordings",
            path.display()
        );
    }
    crate::data::check_csv_header(path)?;
    let table = with_joint_schema(robot, |schema| {
        hapcal_io::read_measurement_file(path, schema, units)
    })
    .with_context(|| format!("reading joint readings {}", path.display()))?;
    if table.rows.is_empty() {
        bail!(
            "{}: no data row: expected one joint configuration per row",
            path.display()
        );
    }
    Ok(table)
}

/// Predicts every row of `table` with `predictor`; the errors against the measured columns
/// where the table has them. `progress` is called after each row with the rows done.
///
/// # Errors
/// A reading the runtime refuses (file:line).
pub fn predict_table(
    predictor: &Predictor,
    table: &MeasurementTable,
    poses: bool,
    progress: &mut dyn FnMut(usize),
) -> Result<(Vec<PredictedRow>, Option<MeasuredErrors>)> {
    let robot = predictor.robot();
    let mut ws = predictor.workspace();
    let mut tips = vec![TipPrediction::default(); robot.tip_names().len()];
    let measured = table.n_markers > 0 || table.has_distance;
    let mut errors = MeasuredErrors::default();
    let mut markers = Vec::new();
    let mut rows = Vec::with_capacity(table.rows.len());
    let at = |line: u64| format!("{}:{line}", table.path.display());
    for (done, row) in table.rows.iter().enumerate() {
        predictor
            .predict(&row.q, &mut ws, &mut tips)
            .with_context(|| at(row.line))?;
        let outside = robot.outside_region(&row.q).with_context(|| at(row.line))?;
        if measured {
            markers.clear();
            markers.extend(row.markers.iter().map(|m| MarkerObservation {
                marker: m.marker,
                position_m: m.position_m,
                rotation_wxyz: m.rotation,
            }));
            predictor
                .add_errors(&row.q, &markers, row.distance_m, &mut ws, &mut errors)
                .with_context(|| at(row.line))?;
        }
        rows.push(PredictedRow {
            line: row.line,
            tips: (tips.iter())
                .map(|t| TipRow {
                    position_m: t.pose.translation_m,
                    quaternion_wxyz: poses.then(|| quaternion_of(&t.pose.rotation)),
                    sigma_m: t.sigma_m,
                    sigma_rad: if poses { t.sigma_rad } else { None },
                })
                .collect(),
            outside_region: outside.map(|(j, past)| OutsideRegion {
                joint: robot.joint_names()[j].clone(),
                past,
            }),
        });
        progress(done + 1);
    }
    Ok((rows, measured.then_some(errors)))
}

/// The prediction of every row of `table` with `predictor`, as `hapcal predict` reports it:
/// `data` is the data file as the report names it, `poses` adds the orientations; the errors
/// against the measured columns where the table has them. `progress` is called after each
/// row with the rows done.
///
/// # Errors
/// As [`predict_table`].
pub fn predict_robot(
    predictor: &Predictor,
    table: &MeasurementTable,
    data: &Path,
    poses: bool,
    progress: &mut dyn FnMut(usize),
) -> Result<Prediction> {
    let (rows, errors) = predict_table(predictor, table, poses, progress)?;
    Ok(Prediction {
        data: data.display().to_string(),
        frame: match predictor.frame() {
            PredictionFrame::Root => "root",
            PredictionFrame::Instrument => "instrument",
        },
        tips: predictor.robot().tip_names().to_vec(),
        uncertainty: predictor.basis().name(),
        n_values: predictor.n_values(),
        uncertainty_note: predictor.uncertainty_note(),
        n_outside_region: rows.iter().filter(|r| r.outside_region.is_some()).count(),
        errors: errors.map(|e| Errors {
            position_m: Figures::of(&e.position),
            orientation_rad: Figures::of(&e.orientation),
            distance_m: Figures::of(&e.distance),
        }),
        warnings: table.warnings.clone(),
        rows,
    })
}

/// The loaded robot, its predictor and the data, as `hapcal predict` and the Python package
/// prepare them: a calibrated URDF with the tips `tips`, or a serial robot's device file
/// (`.toml` with a `[[dh]]` table; no tips: its chain has one).
///
/// # Errors
/// A URDF without tips, tips given for a device file, an unreadable robot or data file
/// (file:line:column), `instrument_frame` on a robot without an identified instrument frame.
pub fn prepare(
    device: &Path,
    tips: &[String],
    data: &Path,
    units: &Units,
    instrument_frame: bool,
) -> Result<(Predictor, MeasurementTable)> {
    let robot = load_robot(device, tips)?;
    let frame = if instrument_frame {
        if robot.frame("instrument").is_none() {
            bail!(
                "--instrument-frame: {} has no identified instrument frame (frames.instrument \
                 of its calibration record)",
                device.display()
            );
        }
        PredictionFrame::Instrument
    } else {
        PredictionFrame::Root
    };
    let table = read_data(data, &robot, units)?;
    let predictor = Predictor::new(&robot, frame)
        .with_context(|| format!("preparing the predictions of {}", device.display()))?;
    Ok((predictor, table))
}

/// Whether `device` is a device file (`.toml`) rather than a URDF.
fn is_device_file(device: &Path) -> bool {
    device
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
}

/// The calibrated robot of `device`: a URDF with the tips `tips`, or a serial robot's device
/// file (no tips).
fn load_robot(device: &Path, tips: &[String]) -> Result<Robot> {
    let is_urdf = device
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if is_device_file(device) {
        if !tips.is_empty() {
            bail!(
                "--tip {}: {} is a device file, whose chain has one tip; predict it without --tip",
                tips.join(" --tip "),
                device.display()
            );
        }
        return Robot::load_device(device)
            .with_context(|| format!("loading the calibrated robot {}", device.display()));
    }
    if !is_urdf {
        bail!(
            "{}: predict reads a calibrated URDF (hapcal calibrate --out robot.urdf, with its \
             sidecar robot.calibration.toml) or a calibrated device file (--out device.toml)",
            device.display()
        );
    }
    if tips.is_empty() {
        bail!(
            "--tip: name the tip link of {} to predict (e.g. --tip ball_link), as calibrated",
            device.display()
        );
    }
    let tip_refs: Vec<&str> = tips.iter().map(String::as_str).collect();
    Robot::load_urdf(device, &tip_refs)
        .with_context(|| format!("loading the calibrated robot {}", device.display()))
}

/// The note for a calibrated URDF whose sidecar does not bind it to the URDF (a record
/// without `urdf_digest`, written by an earlier hapcal: nothing checked that it belongs to
/// this URDF); `None` for a bound record, a device file (it holds its own record) or a URDF
/// without a sidecar.
pub fn unbound_record_note(device: &Path, robot: &Robot) -> Option<String> {
    let sidecar = device.with_extension("calibration.toml");
    if is_device_file(device) || !sidecar.is_file() {
        return None;
    }
    if robot.calibration().is_some_and(|r| r.urdf_digest.is_some()) {
        return None;
    }
    Some(format!(
        "hapcal: note: {} holds no digest of the URDF it was written beside (an earlier hapcal \
         wrote it): nothing checks that it belongs to {}",
        sidecar.display(),
        device.display()
    ))
}

/// The haptic device of a device file, if it is one (capstans or a parallelogram: its
/// calibration is of logs, as `hapcal calibrate` decides).
///
/// # Errors
/// A device file that cannot be read (file:line:column).
pub fn haptic_device(device: &Path) -> Result<Option<hapcal_io::Device>> {
    if !is_device_file(device) {
        return Ok(None);
    }
    let d = hapcal_io::read_device(device)
        .with_context(|| format!("reading device {}", device.display()))?;
    Ok(d.has_transmissions().then_some(d))
}

/// Per row of a haptic device's log its line, the joint readings (rad) and the cable
/// distance (m), if any; and the reader's warnings.
type HapticRows = (Vec<(u64, Vec<f64>, Option<f64>)>, Vec<String>);

/// A haptic device's log as `hapcal calibrate` reads it (`q1..qn` and `distance_m`, with
/// its checks), or without a `distance_m` column its joint readings alone (a measurement
/// file of columns `q1..qn`).
fn read_haptic_rows(path: &Path, device: &hapcal_io::Device, units: &Units) -> Result<HapticRows> {
    if path.is_dir() {
        bail!(
            "{}: a folder; predict reads a log of the haptic device (CSV with q1..q{} and \
             distance_m)",
            path.display(),
            device.n_joints()
        );
    }
    crate::data::check_csv_header(path)?;
    let mut header = String::new();
    let _ = std::fs::File::open(path)
        .and_then(|f| std::io::BufRead::read_line(&mut std::io::BufReader::new(f), &mut header));
    let has_distance = header.split(',').any(|c| c.trim() == "distance_m");
    if has_distance {
        let log = hapcal_io::read_log_in(path, device, units)
            .with_context(|| format!("reading log {}", path.display()))?;
        let rows = (log.rows.into_iter())
            .map(|r| (r.line, r.q, Some(r.distance_m)))
            .collect();
        return Ok((rows, log.warnings));
    }
    let names: Vec<String> = (1..=device.n_joints()).map(|j| format!("q{j}")).collect();
    let prismatic = vec![false; names.len()];
    let limits = device.joint_limits();
    let schema = JointSchema {
        names: &names,
        prismatic: &prismatic,
        limits: &limits,
    };
    let table = hapcal_io::read_measurement_file(path, &schema, units)
        .with_context(|| format!("reading joint readings {}", path.display()))?;
    if table.rows.is_empty() {
        bail!(
            "{}: no data row: expected one row of joint readings q1..q{}",
            path.display(),
            names.len()
        );
    }
    let rows = (table.rows.into_iter())
        .map(|r| (r.line, r.q.to_vec(), None))
        .collect();
    Ok((rows, table.warnings))
}

/// The handle's pose (translation in m) in the frame of a haptic device's D-H row 0, the rig
/// frame whose origin is the cable exit (docs/design.md §2.1), at one row of its log under
/// `model`, the runtime's model of its device file, from the row's joint readings `theta`
/// (rad, as the log gives them: motor angle / R); with the row's cable distance `distance_m`
/// (m), the distance error `|p| − d` (m): how `hapcal predict` and the report of `hapcal calibrate` evaluate
/// a haptic log's row.
///
/// # Errors
/// A reading the model refuses ([`Model::end_pose`]).
pub(crate) fn handle_at(
    model: &Model,
    theta: &[f64],
    distance_m: Option<f64>,
) -> Result<(hapcal_runtime::Pose, Option<f64>), hapcal_runtime::Error> {
    let pose = model.end_pose(theta)?;
    let p = pose.translation_m;
    let error = distance_m.map(|d| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - d);
    Ok((pose, error))
}

/// The handle's predictions of a haptic device (`hapcal_runtime::Model` of its calibrated
/// device file) at every row of its log: the handle's position (pose) in the device's base
/// frame from the joint readings, the region flag and, with the log's cable distances, the
/// distance errors `|p| − d` (m) as `hapcal calibrate` reports them. No σ: the device model
/// does not vary the record's values.
///
/// # Errors
/// An unreadable device file or log (file:line:column), a reading the model refuses.
pub fn predict_haptic(
    device_path: &Path,
    device: &hapcal_io::Device,
    data: &Path,
    units: &Units,
    poses: bool,
) -> Result<(Prediction, SummaryModel)> {
    let model = Model::load(device_path)
        .with_context(|| format!("loading the calibrated device {}", device_path.display()))?;
    let (log, warnings) = read_haptic_rows(data, device, units)?;
    let joint_names: Vec<String> = (1..=model.n_joints()).map(|j| format!("q{j}")).collect();
    let mut distance = ErrorFigures::default();
    let mut rows = Vec::with_capacity(log.len());
    for (line, theta, d) in &log {
        let at = || format!("{}:{line}", data.display());
        let (pose, error) = handle_at(&model, theta, *d).with_context(at)?;
        let p = pose.translation_m;
        if let Some(e) = error {
            distance.push(e);
        }
        let outside = model.outside_region(theta).with_context(at)?;
        rows.push(PredictedRow {
            line: *line,
            tips: vec![TipRow {
                position_m: p,
                quaternion_wxyz: poses.then(|| quaternion_of(&pose.rotation)),
                sigma_m: None,
                sigma_rad: None,
            }],
            outside_region: outside.map(|(j, past)| OutsideRegion {
                joint: joint_names[j].clone(),
                past,
            }),
        });
    }
    let prediction = Prediction {
        data: data.display().to_string(),
        frame: "base",
        tips: vec!["handle".to_owned()],
        uncertainty: "none",
        n_values: 0,
        uncertainty_note: Some(
            "no σ: the runtime's model of a haptic device does not propagate the record's \
             covariance"
                .to_owned(),
        ),
        n_outside_region: rows.iter().filter(|r| r.outside_region.is_some()).count(),
        errors: (distance.count > 0).then(|| Errors {
            position_m: None,
            orientation_rad: None,
            distance_m: Figures::of(&distance),
        }),
        warnings,
        rows,
    };
    let view = SummaryModel {
        has_region: model.has_region(),
        prismatic: vec![false; joint_names.len()],
        joint_names,
    };
    Ok((prediction, view))
}

/// A prediction with what `hapcal predict` says of it.
#[derive(Clone, Debug)]
pub struct Predicted {
    /// The prediction.
    pub prediction: Prediction,
    /// Its summary in words ([`summary`]).
    pub summary: String,
    /// Notes and warnings beside the reader's (an unbound record, errors compared without an
    /// instrument frame), each a whole line starting `hapcal:`.
    pub notes: Vec<String>,
}

/// Rows × robots evaluated above which [`predict`] reports its progress.
const LONG_PREDICTION: usize = 200_000;

/// Predicts the joint readings of the file `data` (in `units`) with the calibrated `device`:
/// a haptic device's handle ([`predict_haptic`]), or a URDF's tips `tips` or a device file's
/// tip ([`prepare`], [`predict_robot`]), in the calibration's instrument frame with
/// `instrument_frame`, with the orientations with `poses`. `progress` is called with the rows
/// done and the rows in all after each row, when the work is long (more than 200,000 rows ×
/// robots evaluated), else never.
///
/// # Errors
/// Tips or `instrument_frame` given for a haptic device; as [`prepare`], [`predict_robot`] and
/// [`predict_haptic`].
pub fn predict(
    device: &Path,
    tips: &[String],
    data: &Path,
    units: &Units,
    instrument_frame: bool,
    poses: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Predicted> {
    if let Some(haptic) = haptic_device(device)? {
        if !tips.is_empty() {
            bail!(
                "--tip {}: {} is a haptic device, whose prediction is its handle; predict it \
                 without --tip",
                tips.join(" --tip "),
                device.display()
            );
        }
        if instrument_frame {
            bail!(
                "--instrument-frame: {} is a haptic device, calibrated from cable distances \
                 measured in its base frame: it has no instrument frame",
                device.display()
            );
        }
        let (prediction, view) = predict_haptic(device, &haptic, data, units, poses)?;
        return Ok(Predicted {
            summary: summary(&prediction, &view),
            prediction,
            notes: Vec::new(),
        });
    }
    let (predictor, table) = prepare(device, tips, data, units, instrument_frame)?;
    let rows = table.rows.len();
    let long = rows * (2 * predictor.n_values() + 1) > LONG_PREDICTION;
    let mut each_row = |done: usize| {
        if long {
            progress(done, rows);
        }
    };
    let prediction = predict_robot(&predictor, &table, data, poses, &mut each_row)?;
    let mut notes: Vec<String> = unbound_record_note(device, predictor.robot())
        .into_iter()
        .collect();
    // Without an identified instrument frame the measured columns are compared in the root frame.
    let no_instrument = predictor.robot().frame("instrument").is_none();
    if !prediction.rows.is_empty() && prediction.errors.is_some() && no_instrument {
        notes.push(
            "hapcal: warning: the calibration identified no instrument frame: the measured \
             columns are compared in the robot's root link frame"
                .to_owned(),
        );
    }
    Ok(Predicted {
        summary: summary(&prediction, &SummaryModel::of_robot(predictor.robot())),
        prediction,
        notes,
    })
}

/// The CSV of `prediction`: `line`, per tip `x, y, z` (numbered `x1, y1, z1, …` for several
/// tips), with `poses` also `qw, qx, qy, qz`, then `sigma_m` (with `poses` also `sigma_rad`),
/// then `outside_region` (0 or 1), `region_joint` and `region_past`; m and rad.
pub fn csv(prediction: &Prediction, poses: bool) -> String {
    let numbered = prediction.tips.len() > 1;
    let mut out = String::from("line");
    for k in 1..=prediction.tips.len() {
        let n = if numbered {
            k.to_string()
        } else {
            String::new()
        };
        for c in ["x", "y", "z"] {
            let _ = write!(out, ",{c}{n}");
        }
        if poses {
            for c in ["qw", "qx", "qy", "qz"] {
                let _ = write!(out, ",{c}{n}");
            }
        }
        let _ = write!(out, ",sigma{n}_m");
        if poses {
            let _ = write!(out, ",sigma{n}_rad");
        }
    }
    out.push_str(",outside_region,region_joint,region_past\n");
    let number = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:?}"));
    for row in &prediction.rows {
        let _ = write!(out, "{}", row.line);
        for t in &row.tips {
            for v in t.position_m {
                let _ = write!(out, ",{v:?}");
            }
            if let Some(q) = t.quaternion_wxyz {
                for v in q {
                    let _ = write!(out, ",{v:?}");
                }
            }
            let _ = write!(out, ",{}", number(t.sigma_m));
            if poses {
                let _ = write!(out, ",{}", number(t.sigma_rad));
            }
        }
        match &row.outside_region {
            Some(o) => {
                let _ = writeln!(out, ",1,{},{:?}", o.joint, o.past);
            }
            None => out.push_str(",0,,\n"),
        }
    }
    out
}

/// What the summary needs to know of the calibrated model: whether its record holds a
/// training region, and which joints are prismatic (their ranges in m).
pub struct SummaryModel {
    /// Whether the record holds a training region.
    pub has_region: bool,
    /// The joints' names, in the order of the readings.
    pub joint_names: Vec<String>,
    /// Whether each joint is prismatic.
    pub prismatic: Vec<bool>,
}

impl SummaryModel {
    /// The summary's view of `robot`.
    pub fn of_robot(robot: &Robot) -> SummaryModel {
        SummaryModel {
            has_region: (robot.calibration()).is_some_and(|c| c.region.is_some()),
            joint_names: robot.joint_names().to_vec(),
            prismatic: (0..robot.n_joints())
                .map(|j| robot.is_prismatic(j))
                .collect(),
        }
    }
}

/// The summary of `prediction` in words: what was predicted in which frame, what σ rests on,
/// the readings outside the calibration's region (the first ten) and the errors against the
/// measured columns (mm, mrad).
pub fn summary(prediction: &Prediction, model: &SummaryModel) -> String {
    let mut s = String::new();
    let frame = match prediction.frame {
        "instrument" => "markers in the calibration's instrument frame",
        "base" => "the handle in the device's base frame, where the cable encoder is",
        _ => "tip links in the root link frame",
    };
    let _ = writeln!(
        s,
        "predicted {} rows of {} at {} ({}), m",
        prediction.rows.len(),
        prediction.data,
        prediction.tips.join(", "),
        frame
    );
    match &prediction.uncertainty_note {
        Some(note) => {
            let _ = writeln!(s, "{note}");
        }
        None => {
            let _ = writeln!(
                s,
                "σ: 1σ of each predicted position from the calibration's covariance of {} values",
                prediction.n_values
            );
        }
    }
    if !model.has_region {
        let _ = writeln!(
            s,
            "region: the calibration records no training region; no reading is flagged"
        );
    } else if prediction.n_outside_region == 0 {
        let _ = writeln!(
            s,
            "region: every reading lies inside the calibration's region"
        );
    } else {
        let _ = writeln!(
            s,
            "region: {} of {} readings lie outside the calibration's region (extrapolated):",
            prediction.n_outside_region,
            prediction.rows.len()
        );
        let outside =
            (prediction.rows.iter()).filter_map(|r| r.outside_region.as_ref().map(|o| (r.line, o)));
        for (line, o) in outside.clone().take(10) {
            let j = model.joint_names.iter().position(|j| *j == o.joint);
            let prismatic = j.is_some_and(|j| model.prismatic.get(j) == Some(&true));
            let words = outside_region_words(&prediction.data, line, &o.joint, o.past, prismatic);
            let _ = writeln!(s, "  {words}");
        }
        if prediction.n_outside_region > 10 {
            let _ = writeln!(s, "  … and {} more", prediction.n_outside_region - 10);
        }
    }
    if let Some(e) = &prediction.errors {
        let _ = writeln!(
            s,
            "errors against the measured columns (no refit; mean, RMS, max):"
        );
        for (what, f, unit, over) in error_kinds(e) {
            let (mean, rms, max) = (f.mean * 1e3, f.rms * 1e3, f.max * 1e3);
            let count = f.count;
            let _ = writeln!(
                s,
                "  {what:<11}  {mean:.4} {rms:.4} {max:.4} {unit} over {count} {over}"
            );
        }
    }
    s
}

/// A reading outside the calibration's region in words: `file:line`, the joint and how far
/// `past` its training range (positive above it), m for a `prismatic` joint, else rad.
pub fn outside_region_words(
    file: &str,
    line: u64,
    joint: &str,
    past: f64,
    prismatic: bool,
) -> String {
    let unit = if prismatic { "m" } else { "rad" };
    let side = if past > 0.0 { "above" } else { "below" };
    format!(
        "{file}:{line}: {joint} {:.4} {unit} {side} its training range",
        past.abs()
    )
}

/// The errors of `e` that were measured, as the summary and the HTML report show them: name,
/// figures (m or rad), the unit they are shown in (mm or mrad) and what they are counted over.
pub fn error_kinds(e: &Errors) -> Vec<(&'static str, Figures, &'static str, &'static str)> {
    let kinds = [
        ("position", e.position_m, "mm", "marker samples"),
        ("orientation", e.orientation_rad, "mrad", "samples"),
        ("distance", e.distance_m, "mm", "rows"),
    ];
    (kinds.into_iter())
        .filter_map(|(what, f, unit, over)| Some((what, f?, unit, over)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hapcal_runtime::Pose;

    #[test]
    fn quaternions_of_rotations_are_the_analytic_ones_with_w_positive() {
        // Rotations by θ about x, y and z: q = (cos θ/2, sin θ/2 · axis), through every branch
        // of the conversion (positive trace, then each diagonal element the largest).
        for theta in [0.3_f64, 2.0, 3.1, std::f64::consts::PI] {
            let (c, s) = ((theta / 2.0).cos(), (theta / 2.0).sin());
            for axis in 0..3 {
                let mut q = [c, 0.0, 0.0, 0.0];
                q[axis + 1] = s;
                let got = quaternion_of(&Pose::rotation_of_quaternion(q));
                for (g, w) in got.iter().zip(q) {
                    assert!(
                        (g - w).abs() < 1e-12,
                        "θ {theta} axis {axis}: {got:?} vs {q:?}"
                    );
                }
                // The same rotation from −q: w ≥ 0 picks q again.
                let again = quaternion_of(&Pose::rotation_of_quaternion(q.map(|v| -v)));
                assert!(again[0] >= 0.0, "{again:?}");
                assert!((again[axis + 1] - s).abs() < 1e-12, "{again:?}");
            }
        }
    }
}
