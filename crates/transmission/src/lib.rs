//! Transmission models of a capstan-driven haptic device: the capstan drive's transmission error
//! (paper eq. 1), the parallelogram's four-bar closure (paper eq. 2, corrected), their
//! combination on joint 4, a Chebyshev polynomial model, and the step-1 identification
//! problems that fit them to external-encoder data.
//!
//! **Architecture invariant:** *`transmission` maps joint readings to output angles; it knows no
//! chain.* Angles are rad, lengths m; a joint reading is the motor angle divided by the ratio
//! ([`JointRad`]), and a transmission error is "true output angle − reading".
//!
//! Source: Baser & Konukseven, "Kinematic model calibration of a 7-DOF capstan-driven haptic
//! device for pose and force control accuracy improvement" (eqs. 1 and 2, Table 2), and
//! DESIGN.md §3.
//!
//! ```
//! use hapcal_identify::identify;
//! use hapcal_transmission::{Capstan, CapstanParams, CapstanProblem, JointRad};
//!
//! // Capstan 1 of the paper's Table 2 (R = 10, D = 60 mm).
//! let capstan = Capstan::try_new(10.0, 0.06)?;
//! let truth = CapstanParams {
//!     c_rad: 0.0,
//!     re: -0.025,
//!     r_o_m: 0.2e-3,
//!     beta_o_rad: (-105.0f64).to_radians(),
//!     r_i_m: 0.005e-3,
//!     beta_i_rad: (-15.0f64).to_radians(),
//! };
//! // Noise-free external-encoder readings over a full output turn.
//! let theta: Vec<f64> = (0..200).map(|i| -3.1 + 6.2 * i as f64 / 199.0).collect();
//! let ext = theta.iter().map(|&t| capstan.output_rad(&truth, JointRad(t))).collect();
//! let sigma_e = 2.0 * std::f64::consts::PI / 20000.0 / 3.0;
//! let problem = CapstanProblem::new(capstan, 1, theta, ext, sigma_e)?;
//!
//! // σ = 1 (residuals are already divided by σ_e) and phases without a nominal value.
//! let id = identify(&problem, problem.initial_guess(), &CapstanProblem::identify_config())?;
//! assert!(id.identifiability.pruned.is_empty());
//! let p = CapstanProblem::params(id.fit.x.as_ref());
//! assert!((p.r_o_m - 0.2e-3).abs() < 1e-9);
//! assert!((p.re + 0.025).abs() < 1e-9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod capstan;
mod chebyshev;
mod error;
mod four_bar;
mod problems;

pub use capstan::{Capstan, CapstanParams, JointRad, MotorRad};
pub use chebyshev::Chebyshev;
pub use error::Error;
pub use four_bar::{FourBar, Joint4Transmission};
pub use problems::{CapstanProblem, PolynomialProblem};
