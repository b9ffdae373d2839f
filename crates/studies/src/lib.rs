//! Studies that need a simulated truth: the paper's tables (Monte Carlo over seeds), the
//! pose-selection study and bound, and the force study. None of this is a user workflow; each
//! checks the workflows of [`hapcal_calibrate`] against a known truth.
//!
//! Architecture invariant: *`studies` only reads the truth; what it calibrates, it calibrates
//! through [`hapcal_calibrate`].*

pub mod arm_blind;
pub mod blind_cli;
pub mod figures;
pub mod force;
pub mod paper;
pub mod pose_study;
pub mod reproduce;
pub mod setup_hostile;
pub mod tree_blind;

pub use hapcal_calibrate::project_root;
