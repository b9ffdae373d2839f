//! File formats of hapcal: device files (TOML), URDF import and write-back, measurement
//! logs (CSV) and the MUKCa real-robot recordings (docs/design.md §5).
//!
//! **Invariant:** `io` turns files into validated domain values and back; nothing past it
//! sees a raw string.
//!
//! Every parse error is an [`Error`] naming the file, the 1-based line and column and what
//! was expected; nothing here panics on file contents, and nothing prints.
//!
//! # Example
//!
//! A two-joint planar arm, its chain, and a log checked against its joint limits:
//!
//! ```
//! use std::path::Path;
//!
//! let text = r#"
//! name = "planar"
//!
//! [[dh]]
//! a_m = 0.3
//! alpha_rad = 0.0
//! d_m = 0.0
//! theta_rad = 0.0
//! joint = 1
//!
//! [[dh]]
//! a_m = 0.2
//! alpha_rad = 0.0
//! d_m = 0.0
//! theta_rad = 0.0
//! joint = 2
//!
//! [[joint]]
//! name = "shoulder"
//! lower_rad = -1.5
//! upper_rad = 1.5
//!
//! [[joint]]
//! name = "elbow"
//! lower_rad = -2.0
//! upper_rad = 2.0
//! "#;
//! let device = hapcal_io::parse_device(text, Path::new("planar.toml"))?;
//! assert_eq!(device.n_joints(), 2);
//! assert_eq!(device.joint_limits(), [(-1.5, 1.5), (-2.0, 2.0)]);
//! assert_eq!(device.chain()?.n_params(), 8); // da, dalpha, dd, dtheta per row
//!
//! // The file written back reads back to the same device.
//! let again = hapcal_io::parse_device(&hapcal_io::write_device(&device), Path::new("again.toml"))?;
//! assert_eq!(again, device);
//!
//! // A misspelt key is an error naming file, line and column.
//! let bad = text.replace("upper_rad = 2.0", "uper_rad = 2.0");
//! let err = hapcal_io::parse_device(&bad, Path::new("planar.toml")).unwrap_err();
//! assert!(err.to_string().starts_with("planar.toml:"), "{err}");
//! # Ok::<(), hapcal_io::Error>(())
//! ```

/// Largest magnitude of a length, m, that the loaders accept from a file: a log's
/// `distance_m`, a URDF `<origin xyz>`, a device file's D-H `a_m`/`d_m`, placement `xyz_m`
/// and other lengths.
///
/// Why 1 km: haptic devices and robot arms measure well under 10 m, so a length past
/// 1000 m is a typo or a unit mistake (micrometres read as metres), never a measurement. Lengths
/// of that kind used to reach the identification as finite numbers whose squares overflow
/// (1e200 m → 1e400 = ∞): a panic in the rank decision, or a report of NaN with exit code 0.
/// The bound leaves three orders of magnitude above any real device and keeps every square
/// and sum of squares of a residual far from overflow. A device file's lengths and angles are
/// bounded by the contract's check of its numbers, with this value
/// ([`hapcal_contract::device::MAX_MAGNITUDE`]).
pub const MAX_LENGTH_M: f64 = hapcal_contract::device::MAX_MAGNITUDE;

mod columns;
mod device;
mod error;
mod input_files;
mod log;
mod measure;
mod mukca;
mod table;
mod targets;
mod urdf;

pub use columns::{AngleUnit, ColumnChange, ColumnEdit, ColumnUnit, LengthUnit, Units};
pub use device::{
    Branch, CableEncoder, CalibratedValue, Calibration, CalibrationMeta, Capstan, Device, DhEntry,
    Handle, JointRef, JointSpec, Parallelogram, UrdfSource, parse_device, read_device,
    write_device,
};
pub use error::{Error, line_column, toml_error_at};
pub use hapcal_kinematics::{DhConvention, DhRow, Placement};
pub use input_files::{InputFile, input_files};
pub use log::{
    Log, LogReader, LogRow, LogSummary, N_EXT, RepeatKey, count_log_rows, read_log, read_log_in,
    write_log,
};
pub use measure::{
    JOINT_LIMIT_SLACK, JointSchema, MAX_YAML_DEPTH, MarkerSample, MeasuredRow, MeasurementTable,
    read_industrial_yaml, read_measurement_file,
};
pub use mukca::{
    SocketPlacement, SocketSamples, read_mukca_paths, read_mukca_paths_for, read_mukca_paths_in,
    read_mukca_placement, read_mukca_placement_for,
};
pub use targets::{TargetRow, read_targets};
pub use urdf::{
    LinkInertial, MAX_CHAIN_LENGTH_M, UrdfTree, import_urdf, import_urdf_tips, import_urdf_tree,
    load_tips, read_urdf, write_calibrated_urdf,
};
