//! The validated inputs of one calibration ([`Plan`]): what the command line, the Rust API and
//! the Python package hand to `calibrate::run`.

use anyhow::{Result, bail};
use std::path::PathBuf;

use crate::model::ModelChoice;

/// Instrument position σ accepted by `--sigma-m` (`Plan::sigma_m`), m: from an
/// interferometer's nanometre to a decimetre. Outside it the value is a unit slip (mm for m)
/// or a typo, and a σ far from the residual decides the pruning wrongly (1e-300 keeps every
/// parameter, 1 none).
pub const SIGMA_M_RANGE: (f64, f64) = (1e-9, 0.1);

/// Orientation σ accepted by `--sigma-rad` (`Plan::sigma_rad`), rad (a nanoradian to about
/// 30°).
pub const SIGMA_RAD_RANGE: (f64, f64) = (1e-9, 0.5);

/// Gravity along −z of the robot's root frame (`Plan::gravity`): a robot mounted upright on a
/// floor (ROS REP 103).
pub const GRAVITY_DOWN: [f64; 3] = [0.0, 0.0, -1.0];

/// The unit direction of gravity `--gravity` gives, in the robot's root frame: an axis
/// (`-z`, `+z`, `x`, `-y`, … : a floor, ceiling or wall mount) or three numbers `gx,gy,gz`
/// (any length but zero; normalised).
///
/// # Errors
/// Anything else, in words.
pub fn parse_gravity(text: &str) -> std::result::Result<[f64; 3], String> {
    let t = text.trim();
    let (sign, axis) = match t.strip_prefix('-') {
        Some(rest) => (-1.0, rest),
        None => (1.0, t.strip_prefix('+').unwrap_or(t)),
    };
    let unit = match axis {
        "x" => Some([1.0, 0.0, 0.0]),
        "y" => Some([0.0, 1.0, 0.0]),
        "z" => Some([0.0, 0.0, 1.0]),
        _ => None,
    };
    if let Some(u) = unit {
        return Ok(u.map(|c: f64| sign * c + 0.0));
    }
    let parts: Vec<&str> = t.split(',').map(str::trim).collect();
    let numbers: Vec<f64> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    if parts.len() != 3 || numbers.len() != 3 || numbers.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "expected an axis of the robot's root frame (-z upright, +z on a ceiling, ±x or ±y \
             on a wall) or three numbers gx,gy,gz, found {text:?}"
        ));
    }
    let norm = numbers.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(norm > 0.0 && norm.is_finite()) {
        return Err(format!("{text:?} has no direction"));
    }
    Ok([numbers[0] / norm, numbers[1] / norm, numbers[2] / norm])
}

/// `g` in the words `--gravity` reads: `-z` for an axis, `0.707,0,-0.707` otherwise.
pub fn gravity_words(g: [f64; 3]) -> String {
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        let others_zero = (0..3).filter(|&k| k != i).all(|k| g[k] == 0.0);
        if others_zero && g[i].abs() == 1.0 {
            return format!("{}{axis}", if g[i] > 0.0 { "+" } else { "-" });
        }
    }
    format!("{},{},{}", g[0], g[1], g[2])
}

/// `Err` naming `option`, its value and the range unless `value` (if given) lies in `range`
/// (inclusive); `unit` is the range's unit as printed.
///
/// # Errors
/// A value outside the range, NaN included.
pub fn check_sigma(option: &str, value: Option<f64>, range: (f64, f64), unit: &str) -> Result<()> {
    match value {
        Some(v) if !(v >= range.0 && v <= range.1) => bail!(
            "{option} must lie between {:e} and {} {unit}, got {v:e}",
            range.0,
            range.1
        ),
        _ => Ok(()),
    }
}

/// Validated inputs of one calibration.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Device file (`.toml`) or URDF (`.urdf`, with `tip`).
    pub device: PathBuf,
    /// Tip link for a URDF device.
    pub tip: String,
    /// Further tip links of a URDF tree (marker `k + 1` sits on tip `k` of `[tip, tips…]`;
    /// markers past the last tip sit on it).
    pub tips: Vec<String>,
    /// Units of the data files' columns: file-wide lengths and angles, and the edits of
    /// named columns (unit, reversed sign, offset), applied by every reader (measurement
    /// files, logs, socket folders) before its checks.
    pub units: hapcal_io::Units,
    /// Orientation noise σ, rad, of pose data, if known.
    pub sigma_rad: Option<f64>,
    /// Marker data: hold out this fraction of each training file's rows, the last ones in
    /// file order, as a test set (`round((1 − f)·n)` rows train); `None` holds out nothing.
    pub test_last: Option<f64>,
    /// Training data: MUKCa placement or run folders, or hapcal log CSVs.
    pub data: Vec<PathBuf>,
    /// Test data (same kinds); never used to fit or to choose settings.
    pub test: Vec<PathBuf>,
    /// Measurement files: a CSV of joint configurations where the calibration will be used
    /// (the joint columns of the data; other columns ignored): the ladder also judges each
    /// rung where they lie beyond a joint's training range (docs/engine.md), and the report
    /// names them with the model's uncertainty there. Only their joint readings are used.
    pub workspace: Option<PathBuf>,
    /// Known distance between the two sockets of a placement, m.
    pub socket_distance_m: f64,
    /// Model choice.
    pub model: ModelChoice,
    /// Folds of the cross-validation (time-contiguous blocks per socket).
    pub folds: usize,
    /// Haptic logs: `--model auto` judges its rungs on at most this many training rows, a
    /// sample spread over the logs ([`crate::fit::ladder_sample`]); the chosen model is
    /// fitted on every row. [`crate::fit::LADDER_ROWS`] by default.
    pub ladder_rows: usize,
    /// Marker files: read at most about this many of their rows in all, every `s`-th row of
    /// each file from its first (the stride of [`crate::fit::ladder_sample`]), every row still
    /// read and checked, and say so in the tables' warnings; `None` (the default): keep every
    /// row. The arm diagnosis sets it: its memory grows with the rows it diagnoses.
    pub read_rows: Option<usize>,
    /// Measurement noise (m) if known; otherwise estimated from the residuals.
    pub sigma_m: Option<f64>,
    /// For a haptic device: identify the transmissions and the kinematics in one problem
    /// (`haptic::identify_jointly`) instead of the paper's two steps.
    pub joint: bool,
    /// Measurement files: the unit direction of gravity in the robot's root frame, the
    /// mounting the compliance models load the joints with ([`GRAVITY_DOWN`]: upright;
    /// `--gravity`, [`parse_gravity`]); recorded in the calibration record's `[torque]`.
    pub gravity: [f64; 3],
}

impl Plan {
    /// The plan of the setup check of a haptic device's logs `data` (read with `units`)
    /// before its diagnosis: the checks `hapcal calibrate` runs on them (units, column order,
    /// rows out of step, the external encoders), with the defaults of every setting the logs
    /// do not use.
    pub fn log_check(
        device: PathBuf,
        data: Vec<PathBuf>,
        units: hapcal_io::Units,
        socket_distance_m: f64,
        folds: usize,
    ) -> Plan {
        Plan {
            workspace: None,
            device,
            tip: "ball_link".to_owned(),
            tips: Vec::new(),
            units,
            sigma_rad: None,
            test_last: None,
            data,
            test: Vec::new(),
            socket_distance_m,
            model: crate::model::ModelName::Geometric.into(),
            folds,
            ladder_rows: crate::fit::LADDER_ROWS,
            read_rows: None,
            sigma_m: None,
            joint: false,
            gravity: GRAVITY_DOWN,
        }
    }

    /// Checks the settings that need no file: folds, socket distance, the σ ranges
    /// ([`SIGMA_M_RANGE`], [`SIGMA_RAD_RANGE`]) and the held-out share, so that the Rust API
    /// and the Python package refuse what the command line refuses, in its words (the
    /// option names). `calibrate::run` calls it first; what needs the files (copied
    /// sockets, frozen sensors, units) is checked where they are read.
    ///
    /// # Errors
    /// The first setting out of its range, named by its command-line option.
    pub fn validate(&self) -> Result<()> {
        if self.folds < 2 {
            bail!("--folds must be at least 2, got {}", self.folds);
        }
        if !(self.socket_distance_m.is_finite() && self.socket_distance_m > 0.0) {
            bail!(
                "--socket-distance-m must be a positive length, got {}",
                self.socket_distance_m
            );
        }
        check_sigma("--sigma-m", self.sigma_m, SIGMA_M_RANGE, "m")?;
        check_sigma("--sigma-rad", self.sigma_rad, SIGMA_RAD_RANGE, "rad")?;
        let norm = self.gravity.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !norm.is_finite() || (norm - 1.0).abs() >= 1e-9 {
            bail!(
                "--gravity must be a direction (a unit vector in the robot's root frame), got {}",
                gravity_words(self.gravity)
            );
        }
        if let Some(f) = self.test_last
            && !(f > 0.0 && f < 1.0)
        {
            bail!(
                "--test-last must lie strictly between 0 and 1 (the fraction of each file's rows \
                 held out), got {f}"
            );
        }
        Ok(())
    }

    /// The bundled default: MUKCa `kuka_14`, training on `front`, testing on `left_back` and
    /// `raised_left` (fixtures/mukca, MIT licence, TU Delft).
    pub fn bundled_default() -> Self {
        let root = crate::project_root().join("fixtures/mukca");
        Self {
            device: root.join("urdf/iiwa14.urdf"),
            tip: "ball_link".into(),
            tips: Vec::new(),
            units: hapcal_io::Units::default(),
            sigma_rad: None,
            test_last: None,
            data: vec![root.join("data/kuka_14/front")],
            workspace: None,
            test: vec![
                root.join("data/kuka_14/left_back"),
                root.join("data/kuka_14/raised_left"),
            ],
            socket_distance_m: 0.05,
            model: ModelChoice::Auto,
            folds: crate::fit::DEFAULT_FOLDS,
            ladder_rows: crate::fit::LADDER_ROWS,
            read_rows: None,
            sigma_m: None,
            joint: false,
            gravity: GRAVITY_DOWN,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Plan;

    #[test]
    fn a_plan_refuses_what_the_command_line_refuses_in_its_words() {
        let valid = Plan::bundled_default();
        assert!(valid.validate().is_ok());
        let cases = [
            (
                Plan {
                    sigma_m: Some(1e308),
                    ..valid.clone()
                },
                "--sigma-m must lie between",
            ),
            (
                Plan {
                    sigma_rad: Some(f64::NAN),
                    ..valid.clone()
                },
                "--sigma-rad must lie between",
            ),
            (
                Plan {
                    folds: 1,
                    ..valid.clone()
                },
                "--folds must be at least 2",
            ),
            (
                Plan {
                    socket_distance_m: -0.05,
                    ..valid.clone()
                },
                "--socket-distance-m must be a positive length",
            ),
            (
                Plan {
                    test_last: Some(1.0),
                    ..valid.clone()
                },
                "--test-last must lie strictly between 0 and 1",
            ),
        ];
        for (plan, words) in cases {
            let err = plan.validate().map_err(|e| e.to_string());
            assert!(matches!(&err, Err(e) if e.starts_with(words)), "{err:?}");
        }
    }
}
