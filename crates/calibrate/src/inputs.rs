//! The validated inputs of one calibration ([`Plan`]): what the command line, the Rust API and
//! the Python package hand to [`crate::calibrate::run`].

use std::path::PathBuf;

use crate::model::ModelChoice;

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
    /// Units of lengths and angles in the measurement files.
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
    /// Known distance between the two sockets of a placement, m.
    pub socket_distance_m: f64,
    /// Model choice.
    pub model: ModelChoice,
    /// Folds of the cross-validation (time-contiguous blocks per socket).
    pub folds: usize,
    /// Measurement noise (m) if known; otherwise estimated from the residuals.
    pub sigma_m: Option<f64>,
    /// For a haptic device: identify the transmissions and the kinematics in one problem
    /// ([`crate::haptic::identify_jointly`]) instead of the paper's two steps.
    pub joint: bool,
}

impl Plan {
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
            test: vec![
                root.join("data/kuka_14/left_back"),
                root.join("data/kuka_14/raised_left"),
            ],
            socket_distance_m: 0.05,
            model: ModelChoice::Auto,
            folds: 5,
            sigma_m: None,
            joint: false,
        }
    }
}
