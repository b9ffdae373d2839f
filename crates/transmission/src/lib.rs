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
//!
//! **One evaluation.** `hapcal-runtime`, which evaluates a calibrated device in a control
//! loop, evaluates its capstans and its joint-4 polynomial with this crate
//! ([`CapstanTransmission`], [`chebyshev_value`], [`chebyshev_derivative`]): the formula a
//! controller uses is the one the calibration fitted, with the runtime's own sine, cosine and
//! arctangent ([`ElementaryFunctions`]; the same to the last bit or so). Without the default
//! feature `std` the crate is `no_std`, allocates nothing and keeps only those evaluations
//! (with [`Capstan::new_unchecked`]), with libm's elementary functions.
#![cfg_attr(not(feature = "std"), no_std)]

mod capstan;
mod chebyshev;
#[cfg(feature = "std")]
mod error;
#[cfg(feature = "std")]
mod four_bar;
mod math;

pub use capstan::{Capstan, CapstanFault, CapstanParams, CapstanTransmission, JointRad};
#[cfg(feature = "std")]
pub use chebyshev::Chebyshev;
pub use chebyshev::{chebyshev_derivative, chebyshev_value};
#[cfg(feature = "std")]
pub use error::{Error, all_finite, positive};
#[cfg(feature = "std")]
pub use four_bar::{FourBar, Joint4Transmission};
pub use math::{DefaultFunctions, ElementaryFunctions};
