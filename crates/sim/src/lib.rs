//! Synthetic measurement logs from a "truth" device: the nominal device plus known kinematic
//! deviations and transmission errors, sampled within the joint limits, with encoder
//! quantisation and Gaussian measurement noise (paper, simulation section, Tables 2 and 3;
//! docs/design.md §3).
//!
//! **Invariant:** `sim` is the only place that knows the truth; everything it returns is what
//! a real rig would record.
//!
//! - [`read_truth`] reads a [`Truth`] file (TOML): the nominal device file, `[deviations]`
//!   by chain parameter name, `[[capstan]]` parameters (paper eq. 1), `[parallelogram]`
//!   length deviations (paper eq. 2).
//! - [`simulate`] draws joint readings uniformly within the limits, quantises them to the
//!   encoders' joint-side resolution, maps them through the truth transmissions
//!   ([`true_joint_angles`]) and the truth chain, and returns [`hapcal_io::LogRow`]s:
//!   readings, the cable distance `|P| + N(0, σ_m)`, and the external encoders (true output
//!   angles of joints 1–4 `+ N(0, σ_e)`).
//!
//! - [`simulate_motion`] moves the device along a time-ordered trajectory and injects the
//!   unmodelled effects of docs/design.md §6 ([`Injected`], [`HAPTIC_LIBRARY`]).
//!
//! The paper's truth and a 200-pose log (seed 1, paper noise) are in
//! `fixtures/reference-device/` (`truth.toml`, `device.toml`, `log.csv`; the log is written by
//! `cargo run -p hapcal-sim --example write_reference_log`).
//!
//! # Example
//!
//! ```
//! use std::path::Path;
//!
//! use hapcal_sim::{NoiseModel, SimConfig, read_truth, simulate};
//!
//! let truth_file = Path::new(env!("CARGO_MANIFEST_DIR"))
//!     .join("../../fixtures/reference-device/truth.toml");
//! let truth = read_truth(&truth_file)?;
//! let device = truth.read_device(&truth_file)?;
//! assert_eq!(truth.deviations.len(), 30); // paper Table 3
//!
//! // The paper's set-up: 200 poses, σ_e = 2π/20000/3 rad, σ_m = 2π·R_d·σ_e ≈ 9.87 µm.
//! let cable = device.cable_encoder.ok_or("no cable encoder")?;
//! let cfg = SimConfig::new(1, 200).with_noise(NoiseModel::paper(&cable));
//! let rows = simulate(&device, &truth, &cfg)?;
//! assert_eq!(rows.len(), 200);
//! assert!(rows.iter().all(|r| r.ext.iter().all(Option::is_some)));
//!
//! // The same seed gives the same log, bit for bit.
//! assert_eq!(simulate(&device, &truth, &cfg)?, rows);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod effects;
mod error;
mod sim;
mod truth;

pub use effects::{
    DEFAULT_HANDLE_MASS_KG, HAPTIC_LIBRARY, Injected, MotionConfig, OUTSIDE_LIBRARY, injectable,
    simulate_motion,
};
pub use error::Error;

/// The reference device's file below the project's root: the nominal device a simulation
/// draws from by default.
pub const REFERENCE_DEVICE: &str = "fixtures/reference-device/device.toml";

/// The reference device's truth file below the project's root: the simulated device of the
/// paper's reproduction and of the blind test.
pub const REFERENCE_TRUTH: &str = "fixtures/reference-device/truth.toml";
/// Gravity of the handle model, m/s² (the measurement model's, `hapcal_problems`).
pub use hapcal_problems::GRAVITY_M_S2;
pub use sim::{
    DistanceSamples, NoiseModel, PARALLELOGRAM_JOINT, REFERENCE_CABLE_ENCODER, SimConfig,
    distance_log_noise, distance_samples, joint_resolutions_rad, quantise_readings,
    sample_readings, simulate, true_joint_angles, truth_deviations,
};
pub use truth::{CapstanTruth, ParallelogramTruth, Truth, parse_truth, read_truth};
