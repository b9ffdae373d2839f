//! Evaluates a calibrated device in a control loop: joint angles through the identified
//! transmissions, tip pose, body and spatial Jacobians, and the motor torques that render a
//! wrench, with no heap allocation per call; from Rust or, through a C ABI, from C.
//!
//! *`runtime` evaluates what `calibrate` identified; it never fits, and knows nothing of the
//! identification stack.*
//!
//! A [`Model`] is loaded once from the device file `hapcal calibrate` writes (TOML with its
//! `[calibration]` table, docs/design.md §5.1) — allocation is fine there — and then
//! evaluated from the joint readings θ (rad, motor angle / R) or from joint angles q:
//!
//! - `q = θ + Δθ_caps(θ)` per capstan (paper eq. 1), `q = θ + p(θ)` for the joint-4
//!   polynomial that models capstan plus parallelogram (paper eq. 2, docs/design.md §3.3),
//!   and `dq/dθ`, analytic ([`Drive`], evaluated by `hapcal-transmission`, the calibration
//!   library's own evaluation of both);
//! - the tip pose `T = A_0·A_1⋯A_n` (paper eqs. 3–4), the body Jacobian (tip frame) and the
//!   spatial Jacobian (base frame) at the end point ([`Model::body_jacobian`],
//!   [`Model::spatial_jacobian`]);
//! - the motor torques `τ_m = diag((dq/dθ)/R)·J_bᵀ·w` for a wrench w in the tip frame (the
//!   paper's force control, Fig. 11; [`Model::motor_torques`]).
//!
//! Storage is fixed-size ([`MAX_JOINTS`], [`MAX_ROWS`], [`MAX_COEFFS`]); errors are `Copy`
//! values ([`Error`]). The results agree with `hapcal-kinematics` to 1e-12 (tests/it), and
//! with the calibration library's force model to 1e-12 (hapcal-force's tests). The force
//! study (`hapcal-force`) evaluates its nominal and calibrated controllers with this crate.
//!
//! ```
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use hapcal_runtime::{Evaluation, Model};
//!
//! let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/reference-device/calibrated.toml");
//! let model = Model::load(std::path::Path::new(path))?;
//! let theta = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4]; // readings, rad
//! let wrench = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0];       // 1 N along the tip's z axis
//! let mut out = Evaluation::default();
//! model.evaluate(&theta, &wrench, &mut out)?;        // no allocation
//! assert!(out.pose.translation_m.iter().all(|x| x.is_finite()));
//! assert_eq!(out.n_joints, 7);
//! # Ok(())
//! # }
//! ```
//!
//! **Robots** (with `std`): a [`Robot`] is loaded from the URDF and its sidecar
//! `robot.calibration.toml` that `hapcal calibrate --out robot.urdf` writes (calibrated joint
//! origins; identified frames and joint compliances), for any number of tip links of the
//! tree. For joint angles q it gives every tip's pose ([`Robot::tip_poses`]), spatial and body
//! Jacobians, the gravity torques from the URDF's link masses, and the robot deflected under
//! its own weight, `θ = q + k∘τ(θ)` by bounded fixed-point iterations
//! ([`Robot::deflected_tip_poses`], [`Deflection`]); the results agree with
//! `hapcal_problems::CalibratedModel` to 1e-12 (tests/it/robot.rs). [`compensate`] finds the
//! joint command that brings a tip, deflection included, onto a target position or pose
//! (damped least squares). Buffers live in a [`RobotWorkspace`]: no call allocates. A serial
//! robot described by a D-H table is a [`Robot`] too, loaded from the device file `hapcal
//! calibrate --out robot.toml` writes ([`Robot::load_device`]: one joint per D-H row, its
//! record in `[calibration]`); it agrees with the calibration library to 1e-9 m
//! (hapcal-calibrate's `tests/record_roundtrip_dh.rs`).
//!
//! ```
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};
//!
//! let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/mukca/urdf/iiwa14.urdf");
//! let robot = Robot::load_urdf(std::path::Path::new(path), &["ball_link"])?;
//! let mut ws = robot.workspace();                     // allocates once
//! let q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];      // rad
//! let mut tip = [Pose::IDENTITY];
//! let deflection = robot.deflected_tip_poses(&q, &mut ws, &mut tip)?;
//! assert!(deflection.converged);
//! let cfg = CompensationConfig {
//!     tolerance_m: 1e-6,
//!     tolerance_rad: 1e-6,
//!     max_iterations: 50,
//!     damping_m: 1e-3,
//!     orientation_scale_m: 0.1,
//! };
//! let mut command = [0.0; 7];
//! let c = compensate(&robot, 0, &Target::Pose(tip[0]), &q, &cfg, &mut ws, &mut command)?;
//! assert!(c.reached);
//! # Ok(())
//! # }
//! ```
//!
//! Without the default feature `std` the crate is `no_std` (libm for the elementary
//! functions): a model is then built from its parts with [`Model::from_dh`], [`Drive::capstan`]
//! and [`Drive::polynomial`]; loading files needs `std`. `cargo xtask ci` builds it so, and
//! links it into a `#![no_std]` crate with its own panic handler (`crates/runtime/no-std-check`),
//! which would not build if std came along.
//!
//! **C ABI**: `hapcal-runtime-capi` (`crates/runtime/capi`) builds this crate as a `cdylib`
//! and a `staticlib` with the header `include/hapcal_runtime.h`.
#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "std")]
mod compensate;
#[cfg(feature = "std")]
mod dh_table;
mod drive;
mod error;
#[cfg(feature = "std")]
mod load;
mod math;
mod model;
mod pose;
#[cfg(feature = "std")]
mod predict;
#[cfg(feature = "std")]
mod robot;
#[cfg(feature = "std")]
mod robot_load;

#[cfg(feature = "std")]
pub use compensate::{Compensation, CompensationConfig, ROTATION_TOLERANCE, Target, compensate};
pub use drive::{CapstanParams, Drive};
pub use error::Error;
#[cfg(feature = "std")]
pub use load::{HANDLE_GRAVITY_M_S2, LoadError};
pub use model::{DhConvention, DhRow, Evaluation, Model};
pub use pose::Pose;
#[cfg(feature = "std")]
pub use predict::{
    ErrorFigures, MarkerObservation, MeasuredErrors, PredictionFrame, PredictionWorkspace,
    Predictor, STEP_FLOOR, STEP_SHARE_OF_STD, TipPrediction, UncertaintyBasis,
};
#[cfg(feature = "std")]
pub use robot::{
    DEFLECTION_ITERATIONS, DEFLECTION_TOLERANCE_RAD, Deflection, GravityModel, Robot,
    RobotWorkspace, STANDARD_GRAVITY,
};

/// Most joints a [`Model`] holds (its storage is fixed-size).
pub const MAX_JOINTS: usize = 12;
/// Most D-H rows a [`Model`] accepts (joints plus fixed rows).
pub const MAX_ROWS: usize = 16;
/// Most Chebyshev coefficients of a polynomial [`Drive`] (degree ≤ 15).
pub const MAX_COEFFS: usize = 16;
/// How far past its domain `[lo, hi]` a polynomial [`Drive`] is evaluated, as a share of the
/// domain's width (each side): the 5 % by which `hapcal calibrate` calls a configuration within
/// a joint's training range. Further out, [`Error::OutsideDomain`].
pub const DOMAIN_MARGIN: f64 = 0.05;
