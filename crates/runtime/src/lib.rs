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
//!   and `dq/dθ`, analytic ([`Drive`]);
//! - the tip pose `T = A_0·A_1⋯A_n` (paper eqs. 3–4), the body Jacobian (tip frame) and the
//!   spatial Jacobian (base frame) at the end point ([`Model::body_jacobian`],
//!   [`Model::spatial_jacobian`]);
//! - the motor torques `τ_m = diag((dq/dθ)/R)·J_bᵀ·w` for a wrench w in the tip frame (the
//!   paper's force control, Fig. 11; [`Model::motor_torques`]).
//!
//! Storage is fixed-size ([`MAX_JOINTS`], [`MAX_ROWS`], [`MAX_COEFFS`]); errors are `Copy`
//! values ([`Error`]). The results agree with `hapcal-force`'s `ForceModel::calibrated` and
//! `hapcal-kinematics` to 1e-12 (tests/it).
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
//! Without the default feature `std` the crate is `no_std` (libm for the elementary
//! functions): a model is then built from its parts with [`Model::from_dh`], [`Drive::capstan`]
//! and [`Drive::polynomial`]; loading files needs `std`.
//!
//! **C ABI**: `hapcal-runtime-capi` (`crates/runtime/capi`) builds this crate as a `cdylib`
//! and a `staticlib` with the header `include/hapcal_runtime.h`.
#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "std")]
mod compensate;
mod drive;
mod error;
#[cfg(feature = "std")]
mod load;
mod math;
mod model;
mod pose;
#[cfg(feature = "std")]
mod robot;
#[cfg(feature = "std")]
mod robot_load;

#[cfg(feature = "std")]
pub use compensate::{Compensation, CompensationConfig, Target, compensate};
pub use drive::{CapstanParams, Drive};
pub use error::Error;
#[cfg(feature = "std")]
pub use load::LoadError;
pub use model::{DhConvention, DhRow, Evaluation, Model};
pub use pose::Pose;
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
