//! Flags of `hapcal predict` and the output of its result ([`hapcal_calibrate::predict`]):
//! the CSV of the predictions and the summary in words, the JSON document and the HTML report.

use std::path::{Path, PathBuf};

use anyhow::Result;
use hapcal_calibrate::predict::{Predicted, csv, predict};
use hapcal_io::Units;

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

/// Runs `hapcal predict`: returns what to print on standard output and the messages for
/// standard error; writes `--out` (atomically, never over an input).
///
/// # Errors
/// As [`predict`]; an output that would overwrite an input or cannot be written.
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
    // A progress bar when the work is long, on a terminal only.
    let (device, data) = (&args.device, &args.data);
    let (tips, frame, poses) = (&args.tips, args.instrument_frame, args.poses);
    let predicted = crate::with_bar("predicting {bar:40} {pos}/{len} rows", |progress| {
        predict(device, tips, data, units, frame, poses, progress)
    })?;
    finish(args, &inputs, &predicted)
}

/// Prints or writes `predicted` as `args` ask: the CSV to `--out` or standard output, the
/// JSON document with `--json`, the summary; its notes after the reader's warnings.
fn finish(
    args: &PredictArgs,
    inputs: &[&Path],
    predicted: &Predicted,
) -> Result<(String, Vec<String>)> {
    let prediction = &predicted.prediction;
    let mut notes: Vec<String> = (prediction.warnings.iter())
        .map(|w| format!("hapcal: warning: {w}"))
        .collect();
    notes.extend(predicted.notes.iter().cloned());
    let text = predicted.summary.clone();
    let text_for_report = &predicted.summary;
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
        crate::html::write_page(path, inputs, |command, files| {
            crate::html::prediction_page(prediction, text_for_report, command, files)
        })?;
        notes.push(format!("hapcal: wrote {}", path.display()));
    }
    Ok((stdout, notes))
}
