//! The `hapcal` command line: argument parsing and rendering over [`hapcal_calibrate`] (the
//! workflows) and [`hapcal_studies`] (what needs a simulated truth).
//!
//! Architecture invariant: *the library part never prints; `main.rs` prints what it returns.*

pub mod diagnose;
pub mod diagnose_arm;
pub mod plan_args;
pub mod report;

pub use hapcal_calibrate::{calibrate, haptic, plan, project_root, support};
pub use hapcal_studies::{figures, force, paper, pose_study, reproduce};
