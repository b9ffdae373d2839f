//! Diagnosis of the sim-to-real gap (docs/design.md §6, docs/diagnosis.md): where the calibrated model
//! still misses, which unmodelled effect causes it, and how far the residual shrinks once
//! that effect is modelled.
//!
//! **Invariant:** `diagnose` sees only a device file and a log, never a truth.
//!
//! - [`diagnose`]: baseline fit (paper Fig. 6, or kinematics alone), held-out gap against
//!   the floor of the encoder specification, residual map, candidate tests, greedy
//!   attribution, before/after held-out RMS.
//! - [`plan`]: the diagnoses of files: a haptic device's log, a serial arm's data.
//! - [`maps`]: the residual maps (SVG) of the haptic and the arm diagnosis.
//! - [`text`]: the text reports of the haptic and the arm diagnosis.
//! - [`blind`]: the blind test: draw an effect (or none, or one outside the library, or
//!   two) with a seed, simulate, diagnose, score.
//!
//! # Example
//!
//! ```
//! use std::path::Path;
//!
//! use hapcal_diagnose::{DiagnoseConfig, diagnose};
//! use hapcal_sim::{Injected, MotionConfig, NoiseModel, SimConfig, read_truth, simulate_motion};
//!
//! let truth_file = Path::new(env!("CARGO_MANIFEST_DIR"))
//!     .join("../../fixtures/reference-device/truth.toml");
//! let truth = read_truth(&truth_file)?;
//! let device = truth.read_device(&truth_file)?;
//! let cable = device.cable_encoder.ok_or("no cable encoder")?;
//! let cfg = SimConfig::new(3, 200).with_noise(NoiseModel::paper(&cable));
//! let latency: Injected = "latency:tau=0.004".parse()?;
//! let rows = simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[latency])?;
//!
//! let d = diagnose(&device, &rows, &DiagnoseConfig::default())?;
//! assert_eq!(d.verdict, "latency");
//! assert!(d.gap_closed_pct > 80.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod arm;
pub mod blind;
mod diagnose;
mod error;
pub mod maps;
mod model;
pub mod plan;
mod solve;
mod stats;
pub mod text;
mod verdict;

pub use diagnose::{
    Bin, Candidate, DiagnoseConfig, Diagnosis, JointProbe, ParamValue, SignalTest, Step,
    baseline_model, baseline_residuals_m, diagnose,
};
pub use error::Error;
pub use stats::{chi2_sf, f_sf, holm};
pub use verdict::Verdict;
