//! Identification of model parameters from measurements: Levenberg–Marquardt, identifiability
//! (pruning) and covariance, on any [`Problem`] with a named [`ParamLayout`]; observability
//! indices O1–O5 of the scaled Jacobian ([`observability`]) and pose selection from candidate
//! Jacobian blocks ([`select_poses`]).
//!
//! Vector kernels ([`pulp`]): one kernel body for AVX-512, AVX2, NEON and scalar code, chosen
//! at run time, with the same bits on each; `HAPCAL_SIMD=off` in the environment forces the
//! scalar instantiation for the whole process (docs/engine.md, "Vector kernels").
//!
//! **Architecture invariant:** *`identify` knows nothing about robots.* It sees residuals, a
//! Jacobian and parameter names, units and roles; kinematics, devices and logs live in the
//! crates that implement [`Problem`].
//!
//! The usual entry point is [`identify`]: prune the parameters the data cannot determine
//! ([`identifiability`]), fit the others ([`levenberg_marquardt`]), re-decide the pruning at the
//! estimate, and return the covariance ([`covariance`]; correlations with
//! [`Covariance::correlation`] and [`Covariance::correlated_pairs`]).
//!
//! ```
//! use faer::{Col, ColMut, ColRef, MatMut};
//! use hapcal_identify::{
//!     EvalError, IdentifyConfig, ParamLayout, ParamSpec, Problem, PruneReason, Role, Unit,
//!     identify,
//! };
//!
//! /// y_i = a + b·t_i, but `b` appears twice (as `b` and `b_copy`), so one must be pruned.
//! struct Line { layout: ParamLayout, t: Vec<f64>, y: Vec<f64> }
//!
//! impl Problem for Line {
//!     fn layout(&self) -> &ParamLayout { &self.layout }
//!     fn n_residuals(&self) -> usize { self.t.len() }
//!     fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
//!         for (i, (&t, &y)) in self.t.iter().zip(&self.y).enumerate() {
//!             out[i] = x[0] + (x[1] + x[2]) * t - y;
//!         }
//!         Ok(())
//!     }
//!     fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
//!         for (i, &t) in self.t.iter().enumerate() {
//!             jac[(i, 0)] = 1.0;
//!             jac[(i, 1)] = t;
//!             jac[(i, 2)] = t;
//!         }
//!         Ok(())
//!     }
//! }
//!
//! let spec = |name: &str| ParamSpec { name: name.into(), unit: Unit::Meter, role: Role::Model };
//! let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
//! let noise = |i: usize| 1e-4 * ((i * 7 % 5) as f64 - 2.0);
//! let y = t.iter().enumerate().map(|(i, &t)| 0.003 + 0.002 * t + noise(i)).collect();
//! let line = Line { layout: ParamLayout::new(vec![spec("a"), spec("b"), spec("b_copy")]), t, y };
//!
//! let id = identify(&line, Col::zeros(3), &IdentifyConfig::default())?;
//! assert!(id.fit.termination.is_success());
//! assert_eq!(id.identifiability.pruned_names(), ["b_copy"]);
//! assert!(matches!(&id.identifiability.pruned[0].reason, PruneReason::Dependent { on } if on[0].0 == "b"));
//! let (b, std_b) = (id.value("b").unwrap(), id.std("b").unwrap());
//! assert!((b - 0.002).abs() < 4.0 * std_b);
//! # Ok::<(), hapcal_identify::Error>(())
//! ```

mod blocks;
mod calibrate;
mod covariance;
mod design;
mod error;
mod householder;
mod lm;
mod observability;
mod problem;
mod rank;
mod sparse;
mod subset;

pub use blocks::{
    N_LEAVES, RowBlocks, jacobian_r_factor, levenberg_marquardt_streaming, rows_r_factor,
    stacked_r_factor,
};
pub use calibrate::{
    Backend, BackendChoice, DENSE_LIMIT_BYTES, Identified, IdentifyConfig, MAX_ROUNDS, SIGMA_FLOOR,
    SPARSE_AUTO_DENSITY, STREAMING_AUTO_ENTRIES, SigmaSource, identify, identify_held,
};
pub use covariance::{Covariance, covariance, sigma_from_residuals};
pub use design::{
    ContinuousConfig, ContinuousDesign, Criterion, Design, DesignConfig, design_quality,
    i_optimal_weights, select_poses,
};
pub use error::Error;
pub use lm::{
    Fit, LmConfig, Termination, levenberg_marquardt, levenberg_marquardt_from,
    levenberg_marquardt_from_triangle,
};
pub use observability::{
    Observability, observability, observability_from_singular_values, scale_by_priors,
};
pub use problem::{EvalError, LinearProblem, ParamLayout, ParamSpec, Problem, Role, Unit};
pub use rank::{
    Identifiability, PruneReason, Pruned, RankConfig, RankConfigBase, TieBreak, identifiability,
};
pub use sparse::{SparseFit, SparseJacobian, levenberg_marquardt_sparse};
pub use subset::Subset;
