//! Serial kinematic chains: forward kinematics and analytic Jacobians with respect to the
//! joint angles and to the kinematic parameter deviations.
//!
//! Vector kernels ([`pulp`]): one kernel body for AVX-512, AVX2, NEON and scalar code, chosen
//! at run time, with the same bits on each; `HAPCAL_SIMD=off` in the environment forces the
//! scalar instantiation for the whole process (docs/engine.md, "Vector kernels").
//!
//! **Invariant:** `kinematics` knows chains, not measurements.
//!
//! A [`Chain`] is a sequence of elementary [`Factor`]s — constant transforms and screws
//! (rotation about / translation along a unit axis). Every convention compiles into it:
//! standard Denavit–Hartenberg (Denavit & Hartenberg 1955, paper eq. 3), modified D-H
//! (Craig 1989), Hayati's `beta` for near-parallel axes (Hayati 1983), and URDF joint
//! origins (`xyz`/`rpy`, ROS URDF specification). One derivative formula then serves all
//! of them.
//!
//! Two vectors drive every evaluation:
//! - `x`: the parameter *deviations* (length [`Chain::n_params`], all zero = nominal model),
//!   in m or rad as [`ParamInfo::unit`] says, in the order of [`Chain::params`];
//! - `q`: the joint angles (length [`Chain::n_joints`], rad), in the order of
//!   [`Chain::joint_names`].
//!
//! # Example
//!
//! A planar two-link arm (links 0.3 m and 0.2 m) in standard D-H:
//!
//! ```
//! use hapcal_kinematics::{Chain, DhConvention, DhRow};
//!
//! let link = |a_m: f64, joint: usize| DhRow {
//!     convention: DhConvention::Standard,
//!     a_m,
//!     alpha_rad: 0.0,
//!     d_m: 0.0,
//!     theta_rad: 0.0,
//!     beta_rad: None,
//!     joint: Some(joint),
//! };
//! let chain = Chain::from_dh(&[link(0.3, 0), link(0.2, 1)])?;
//! assert_eq!(chain.n_params(), 8); // da, dalpha, dd, dtheta per row
//! assert_eq!(chain.joint_names(), ["q1", "q2"]);
//!
//! let x = vec![0.0; chain.n_params()];
//! let q = [std::f64::consts::FRAC_PI_2, 0.0];
//! let p = chain.end_point(&x, &q);
//! assert!((p - hapcal_kinematics::Point3::new(0.0, 0.5, 0.0)).norm() < 1e-12);
//!
//! // ∂p/∂(da1): the tip moves along link 2, here +y.
//! let jac = chain.point_jacobian_wrt_params(&x, &q);
//! let da1 = chain.param_index("da1").ok_or("no da1")?;
//! assert!((jac[(1, da1)] - 1.0).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod chain;
mod dh;
mod error;
mod frozen;
mod placement;
mod tree;

pub use chain::{Chain, Factor, FkWorkspace, Motion, ParamInfo, ParamUnit, joint_motions};
pub use dh::{DhConvention, DhRow};
pub use error::Error;
pub use frozen::{FrozenChain, LANES, joint_trig, joint_trig_lanes};
pub use nalgebra::{Isometry3, Matrix3xX, Matrix6xX, Point3, Unit, UnitQuaternion, Vector3};
pub use placement::Placement;
pub use tree::{FrameSpec, Tree};

#[cfg(test)]
mod tests;
