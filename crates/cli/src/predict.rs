//! Flags of `hapcal predict` and the glue that runs it: joint readings from a measurement
//! file, the calibrated model's tip positions (or poses) with their 1σ uncertainty and the
//! region flag ([`hapcal_runtime::Predictor`]), to a CSV file; with measured columns, the
//! errors of the predictions against them, without refitting. A calibrated URDF and a serial
//! robot's device file (`[[dh]]`) are [`Robot`]s; a haptic device's file (capstans,
//! parallelogram) is a [`Model`]: the handle's position from the joint readings of a log and,
//! with its cable distances, the distance errors.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hapcal_io::{JointSchema, MeasurementTable, Units};
use hapcal_runtime::{
    ErrorFigures, MarkerObservation, MeasuredErrors, Model, PredictionFrame, Predictor, Robot,
    TipPrediction,
};
use serde::Serialize;

/// Flags of `hapcal predict`.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictArgs {
    /// The calibrated device as `hapcal calibrate --out` writes it: a URDF (its sidecar
    /// robot.calibration.toml, the calibration record with the values' σ, the covariance, the
    /// region and the frames, is read from beside it), or a device file (.toml) with the
    /// record in its calibration table: a serial robot's D-H table, or a haptic device.
    #[arg(long)]
    pub device: PathBuf,
    /// A tip link of a URDF to predict (e.g. ball_link); repeat it for a tree, in the
    /// calibration's order (marker k sits on the k-th tip). A device file's chain has one
    /// tip: no --tip.
    #[arg(long = "tip")]
    pub tips: Vec<String>,
    /// Joint readings: a measurement file as hapcal calibrate reads it (CSV with the joints as
    /// q1..qn or by name, or industrial_calibration's YAML). Marker positions (x,y,z or
    /// x1,y1,z1,…), orientations and distances, if present, are compared with the predictions;
    /// a file of joint columns alone is predicted only. For a haptic device, its log (q1..qn,
    /// with distance_m the cable distances to compare with the handle's predicted distance).
    #[arg(long)]
    pub data: PathBuf,
    /// Predict in the calibration's instrument frame, the poses of the markers on the tips
    /// (the sidecar's frames.instrument and frames.marker1, …), as the instrument measures
    /// them; without it, the tip links in the robot's root link frame.
    #[arg(long)]
    pub instrument_frame: bool,
    /// Predict poses: also the orientation (a unit quaternion qw, qx, qy, qz) and its 1σ.
    #[arg(long)]
    pub poses: bool,
    /// Write the predictions to this CSV file (one row per reading: its line in the data
    /// file, the positions in m, their σ, the region flag); without it they go to standard
    /// output, unless --json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON document (the summary and every prediction) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the prediction as one self-contained HTML file (the errors, each row's
    /// predicted σ, the rows outside the calibration's region).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

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

/// The quaternion `[w, x, y, z]` (w ≥ 0) of the rotation matrix `r` (Shepperd's method:
/// the largest of the four squared components first, for accuracy at every angle).
fn quaternion_of(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (1.0 + trace).sqrt();
        [
            s / 4.0,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
        [
            (r[2][1] - r[1][2]) / s,
            s / 4.0,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            s / 4.0,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            s / 4.0,
        ]
    };
    if q[0] < 0.0 { q.map(|v| -v) } else { q }
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
    hapcal_calibrate::data::check_csv_header(path)?;
    let prismatic: Vec<bool> = (0..robot.n_joints())
        .map(|j| robot.is_prismatic(j))
        .collect();
    let schema = JointSchema {
        names: robot.joint_names(),
        prismatic: &prismatic,
        limits: robot.limits(),
    };
    let table = hapcal_io::read_measurement_file(path, &schema, units)
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

/// The uncertainty's basis and note, in words.
fn uncertainty_words(predictor: &Predictor) -> (&'static str, Option<String>) {
    let basis = predictor.basis().name();
    let note = predictor.uncertainty_note();
    (basis, note)
}

/// The CSV of `prediction`: `line`, per tip `x, y, z` (numbered `x1, y1, z1, …` for several
/// tips), with `poses` also `qw, qx, qy, qz`, then `sigma_m` (with `poses` also `sigma_rad`),
/// then `outside_region` (0 or 1), `region_joint` and `region_past`.
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
pub struct SummaryModel<'a> {
    /// Whether the record holds a training region.
    pub has_region: bool,
    /// The joints' names, in the order of the readings.
    pub joint_names: &'a [String],
    /// Whether each joint is prismatic.
    pub prismatic: Vec<bool>,
}

impl<'a> SummaryModel<'a> {
    /// The summary's view of `robot`.
    pub fn of_robot(robot: &'a Robot) -> SummaryModel<'a> {
        SummaryModel {
            has_region: (robot.calibration()).is_some_and(|c| c.region.is_some()),
            joint_names: robot.joint_names(),
            prismatic: (0..robot.n_joints())
                .map(|j| robot.is_prismatic(j))
                .collect(),
        }
    }
}

/// The summary of `prediction` in words.
pub fn summary(prediction: &Prediction, model: &SummaryModel<'_>) -> String {
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
            let unit = match model.joint_names.iter().position(|j| *j == o.joint) {
                Some(j) if model.prismatic.get(j) == Some(&true) => "m",
                _ => "rad",
            };
            let _ = writeln!(
                s,
                "  {}:{line}: {} {:.4} {unit} {} its training range",
                prediction.data,
                o.joint,
                o.past.abs(),
                if o.past > 0.0 { "above" } else { "below" }
            );
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
        let lines = [
            ("position   ", e.position_m, "mm", "marker samples"),
            ("orientation", e.orientation_rad, "mrad", "samples"),
            ("distance   ", e.distance_m, "mm", "rows"),
        ];
        for (what, figures, unit, over) in lines {
            if let Some(f) = figures {
                let _ = writeln!(
                    s,
                    "  {what}  {:.4} {:.4} {:.4} {unit} over {} {over}",
                    f.mean * 1e3,
                    f.rms * 1e3,
                    f.max * 1e3,
                    f.count
                );
            }
        }
    }
    s
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
fn haptic_device(device: &Path) -> Result<Option<hapcal_io::Device>> {
    if !is_device_file(device) {
        return Ok(None);
    }
    let d = hapcal_io::read_device(device)
        .with_context(|| format!("reading device {}", device.display()))?;
    Ok((!d.capstans.is_empty() || d.parallelogram.is_some()).then_some(d))
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
    hapcal_calibrate::data::check_csv_header(path)?;
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
        .map(|r| (r.line, r.q, None))
        .collect();
    Ok((rows, table.warnings))
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
) -> Result<(Prediction, Model)> {
    let model = Model::load(device_path)
        .with_context(|| format!("loading the calibrated device {}", device_path.display()))?;
    let (log, warnings) = read_haptic_rows(data, device, units)?;
    let joint_names: Vec<String> = (1..=model.n_joints()).map(|j| format!("q{j}")).collect();
    let mut distance = ErrorFigures::default();
    let mut rows = Vec::with_capacity(log.len());
    for (line, theta, d) in &log {
        let at = || format!("{}:{line}", data.display());
        let pose = model.end_pose(theta).with_context(at)?;
        let p = pose.translation_m;
        if let Some(d) = d {
            distance.push((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - d);
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
    Ok((prediction, model))
}

/// Runs `hapcal predict`: returns what to print on standard output and the messages for
/// standard error; writes `--out` (atomically, never over an input).
///
/// # Errors
/// As [`prepare`]; an output that would overwrite an input or cannot be written.
pub fn run(args: &PredictArgs, units: &Units) -> Result<(String, Vec<String>)> {
    let sidecar = args.device.with_extension("calibration.toml");
    let inputs: [&Path; 3] = [&args.device, &args.data, &sidecar];
    if let Some(out) = &args.out {
        crate::calibrate::check_extension(out, &["csv"], "the predictions", false)?;
        crate::calibrate::check_output(out, &inputs)?;
    }
    if let Some(report) = &args.report {
        crate::html::check(report, &inputs)?;
    }
    if let Some(device) = haptic_device(&args.device)? {
        if !args.tips.is_empty() {
            bail!(
                "--tip {}: {} is a haptic device, whose prediction is its handle; predict it \
                 without --tip",
                args.tips.join(" --tip "),
                args.device.display()
            );
        }
        if args.instrument_frame {
            bail!(
                "--instrument-frame: {} is a haptic device, calibrated from cable distances \
                 measured in its base frame: it has no instrument frame",
                args.device.display()
            );
        }
        let (prediction, model) =
            predict_haptic(&args.device, &device, &args.data, units, args.poses)?;
        let joint_names: Vec<String> = (1..=model.n_joints()).map(|j| format!("q{j}")).collect();
        let view = SummaryModel {
            has_region: model.has_region(),
            joint_names: &joint_names,
            prismatic: vec![false; model.n_joints()],
        };
        return finish(
            args,
            &inputs,
            &prediction,
            &summary(&prediction, &view),
            Vec::new(),
        );
    }
    let (predictor, table) = prepare(
        &args.device,
        &args.tips,
        &args.data,
        units,
        args.instrument_frame,
    )?;
    // A progress bar when the work is long (rows × robots evaluated), on a terminal only.
    let work = table.rows.len() * (2 * predictor.n_values() + 1);
    let bar = (work > 200_000).then(|| {
        let bar = indicatif::ProgressBar::new(table.rows.len() as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template("predicting {bar:40} {pos}/{len} rows")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    let mut progress = |done: usize| {
        if let Some(bar) = &bar {
            bar.set_position(done as u64);
        }
    };
    let (rows, errors) = predict_table(&predictor, &table, args.poses, &mut progress)?;
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    let (uncertainty, uncertainty_note) = uncertainty_words(&predictor);
    let prediction = Prediction {
        data: args.data.display().to_string(),
        frame: match predictor.frame() {
            PredictionFrame::Root => "root",
            PredictionFrame::Instrument => "instrument",
        },
        tips: predictor.robot().tip_names().to_vec(),
        uncertainty,
        n_values: predictor.n_values(),
        uncertainty_note,
        n_outside_region: rows.iter().filter(|r| r.outside_region.is_some()).count(),
        errors: errors.map(|e| Errors {
            position_m: Figures::of(&e.position),
            orientation_rad: Figures::of(&e.orientation),
            distance_m: Figures::of(&e.distance),
        }),
        warnings: table.warnings.clone(),
        rows,
    };
    let mut extra: Vec<String> = unbound_record_note(&args.device, predictor.robot())
        .into_iter()
        .collect();
    if !prediction.rows.is_empty() && errors_without_instrument(&predictor, &prediction) {
        extra.push(
            "hapcal: warning: the calibration identified no instrument frame: the measured \
             columns are compared in the robot's root link frame"
                .to_owned(),
        );
    }
    let text = summary(&prediction, &SummaryModel::of_robot(predictor.robot()));
    finish(args, &inputs, &prediction, &text, extra)
}

/// Prints or writes `prediction` as `args` ask: the CSV to `--out` or standard output, the
/// JSON document with `--json`, the summary `text`; `extra` notes after the reader's
/// warnings.
fn finish(
    args: &PredictArgs,
    inputs: &[&Path],
    prediction: &Prediction,
    text: &str,
    extra: Vec<String>,
) -> Result<(String, Vec<String>)> {
    let mut notes: Vec<String> = (prediction.warnings.iter())
        .map(|w| format!("hapcal: warning: {w}"))
        .collect();
    notes.extend(extra);
    let text = text.to_owned();
    let text_for_report = text.clone();
    let csv_text = csv(prediction, args.poses);
    let stdout = if args.json {
        format!("{}\n", serde_json::to_string_pretty(prediction)?)
    } else if args.out.is_some() {
        text
    } else {
        notes.extend(text.lines().map(str::to_owned));
        csv_text.clone()
    };
    if let Some(out) = &args.out {
        crate::calibrate::write_new(out, &csv_text, inputs)?;
        notes.push(format!("hapcal: wrote {}", out.display()));
    }
    if let Some(path) = &args.report {
        let command = crate::html::this_command();
        let html = crate::html::prediction_page(
            prediction,
            &text_for_report,
            &command,
            &crate::html::inputs(inputs),
        );
        crate::html::write(path, &html, inputs)?;
        notes.push(format!("hapcal: wrote {}", path.display()));
    }
    Ok((stdout, notes))
}

/// Whether the data's measured columns are compared without an identified instrument frame.
fn errors_without_instrument(predictor: &Predictor, prediction: &Prediction) -> bool {
    prediction.errors.is_some() && predictor.robot().frame("instrument").is_none()
}
