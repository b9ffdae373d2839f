//! Force rendering through the full device model: static force mapping `τ = Jᵀ F`,
//! closed-loop impedance control (paper Fig. 11) and the virtual-wall experiment (paper
//! Fig. 12), with the controller using a model under test (nominal or calibrated) and the
//! device simulated with the truth.
//!
//! **Invariant:** *`force` is static: no dynamics, no time; every result is an equilibrium.*
//!
//! # Equations (SI units: m, rad, N, N·m)
//!
//! Frames: wrenches `w = (f, m)` (N, N·m) act at the end point and are expressed in the tip
//! (end-effector) frame, the frame of a force sensor rigid on the handle. `J_b(q)` is the
//! body Jacobian, 6 × 7 (m/rad over rad/rad, [`ForceModel::body_jacobian`]).
//!
//! 1. **Drives** ([`Drive`]). Reading `θ = φ_m/R` (rad), joint angle `q = q(θ)`: `θ` for a
//!    direct drive, `θ + Δθ_caps(θ)` for a capstan (paper eq. 1), the four-bar of paper eq. 2
//!    after capstan 4 for the truth's joint 4, `θ + p(θ)` for the calibrated joint-4
//!    polynomial. Virtual work `τ_m dφ_m = τ_j dq` gives `τ_j = τ_m·R/(dq/dθ)`.
//! 2. **Controller** (a [`ForceModel`] under test, at the reading θ it sees):
//!    `τ_m = diag((dq/dθ)_model/R)·J_b,model(q_model(θ))ᵀ·w_cmd`.
//! 3. **Device** (the truth [`ForceModel`]): `τ_j = diag(R/(dq/dθ)_truth)·τ_m`; with the
//!    handle fixed and joint 3 locked, the six unlocked joints balance the wrench on the
//!    handle, `J_b,truth,aᵀ·w = τ_j,a`. Together: `w = M·w_cmd` ([`wrench_map`]).
//! 4. **Closed loop** (paper Fig. 11, proportional gain G on the sensor's wrench):
//!    `w_cmd = w_d + G·(w_d − w)`, so `w = (I + G M)⁻¹(1 + G) M·w_d` ([`closed_loop`]).
//! 5. **Virtual wall** (Z_e, paper Fig. 12): stiffness K, wall moved s along the tip z axis
//!    against the fixed handle, `w_d = (0, 0, K·s, 0, 0, 0)` ([`virtual_wall`]).
//!
//! **Evaluation.** The models under test, [`ForceModel::nominal`] and
//! [`ForceModel::calibrated`], run on `hapcal-runtime` (`hapcal_runtime::Model`, loaded from
//! the device file as a controller loads it): the study measures the code a controller runs.
//! The truth ([`ForceModel::truth`]) is the simulated real device, no controller code, and
//! keeps the calibration library's evaluation (hapcal-kinematics, hapcal-transmission), as do
//! [`ForceModel::nominal_library`] and [`ForceModel::calibrated_library`], against which the
//! runtime models are tested to 1e-12 (tests/it).
//!
//! Gravity is left out: the device is statically balanced but for the handle, whose weight
//! the fixture carries (the sensor is tared). Units inside are SI; reports convert.
//!
//! # Results on the reference device
//!
//! Measured with `cargo run -p hapcal -- force --device
//! fixtures/reference-device/device.toml --truth fixtures/reference-device/truth.toml
//! --calibrated fixtures/reference-device/calibrated.toml` (full output in
//! `docs/results/force/README.md`; G = 10 for the closed loop):
//!
//! - Fig. 12 (joint 6 at 0.6 rad, home is a wrist singularity), open loop, at 20 mm of wall
//!   travel: transverse force 1.399 % of Fz with the nominal model, 0.178 % calibrated.
//! - 200 random poses, 95th percentile of the force direction error: 4.72° nominal,
//!   0.155° calibrated (30.5× less); with G = 10, 0.435° and 0.0140°.
//! - The floor: `dalpha7` (1.7 mrad in the truth) is not identifiable from distances, turns
//!   the sensor frame against the model's by 0.097° and leaves a transverse force of
//!   sin(1.7 mrad) = 0.170 %; with it at its truth the calibrated transverse force is 0.035 %.
//!
//! # Example
//!
//! The ideal model renders exactly the desired force:
//!
//! ```
//! use std::path::Path;
//! use hapcal_force::{ForceModel, WallConfig, home_readings, virtual_wall};
//!
//! let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device");
//! let device = hapcal_io::read_device(&dir.join("device.toml"))?;
//! let nominal = ForceModel::nominal(&device)?;
//! let ideal = ForceModel::truth(&device, &hapcal_sim::Truth::nominal(dir.join("device.toml"), &device))?;
//! let cfg = WallConfig { quantise: false, ..WallConfig::paper() };
//! let wall = virtual_wall(&device, &nominal, &ideal, &home_readings(&device), &cfg)?;
//! let last = wall.last().ok_or("no samples")?;
//! assert!((last.desired_n - 2.0).abs() < 1e-12);
//! assert!((last.wrench[2] - 2.0).abs() < 1e-9 && last.wrench[0].abs() < 1e-9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod control;
mod error;
mod experiment;
mod model;

pub use control::{
    Direction, Readings, WrenchError, closed_loop, condition_number, wrench_error, wrench_map,
};
pub use error::Error;
pub use experiment::{
    SweepConfig, SweepErrors, WallConfig, WallSample, home_readings, quantile, sample_poses, sweep,
    virtual_wall,
};
pub use model::{Drive, ForceModel};
pub use nalgebra::{Matrix6, Vector6};

#[cfg(test)]
mod tests;
