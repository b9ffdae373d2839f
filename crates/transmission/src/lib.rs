//! Transmission models of a capstan-driven haptic device: the capstan drive's transmission error
//! (paper eq. 1), the parallelogram's four-bar closure (paper eq. 2, corrected), their
//! combination on joint 4, and a Chebyshev polynomial model. The step-1 identification problems
//! that fit them to external-encoder data (`CapstanProblem`, `PolynomialProblem`) live in
//! `hapcal-problems`, with every other measurement model.
//!
//! **Architecture invariant:** *`transmission` maps joint readings to output angles; it knows no
//! chain.* Angles are rad, lengths m; a joint reading is the motor angle divided by the ratio
//! ([`JointRad`]), and a transmission error is "true output angle − reading".
//!
//! Source: Baser & Konukseven, "Kinematic model calibration of a 7-DOF capstan-driven haptic
//! device for pose and force control accuracy improvement" (eqs. 1 and 2, Table 2), and
//! docs/design.md §3.
//!
//! ```
//! use hapcal_transmission::{Capstan, CapstanParams, JointRad};
//!
//! // Capstan 1 of the paper's Table 2 (R = 10, D = 60 mm).
//! let capstan = Capstan::try_new(10.0, 0.06)?;
//! let p = CapstanParams {
//!     c_rad: 0.0,
//!     re: -0.025,
//!     r_o_m: 0.2e-3,
//!     beta_o_rad: (-105.0f64).to_radians(),
//!     r_i_m: 0.005e-3,
//!     beta_i_rad: (-15.0f64).to_radians(),
//! };
//! capstan.check_params(&p)?;
//! // Eq. 1 vanishes at a zero reading when c = 0; elsewhere the ratio error dominates.
//! assert_eq!(capstan.error_rad(&p, JointRad(0.0)), 0.0);
//! let theta = JointRad(1.0);
//! assert_eq!(capstan.output_rad(&p, theta), 1.0 + capstan.error_rad(&p, theta));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod capstan;
mod chebyshev;
mod error;
mod four_bar;

pub use capstan::{Capstan, CapstanParams, JointRad, MotorRad};
pub use chebyshev::Chebyshev;
pub use error::{Error, all_finite, positive};
pub use four_bar::{FourBar, Joint4Transmission};
