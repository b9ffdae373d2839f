//! The `hapcal` command line: flags, glue, and the calibration workflow that ties the crates
//! together (read → build problem → cross-validate the model → identify → report).
//!
//! Architecture invariant: *the library part never prints; `main.rs` prints what it returns.*

pub mod calibrate;
pub mod diagnose;
pub mod figures;
pub mod force;
pub mod paper;
pub mod plan;
pub mod report;
pub mod reproduce;
pub mod support;

use std::path::PathBuf;

/// Root of the source tree (where `fixtures/` lives), fixed at build time.
pub fn project_root() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    // Reports print paths under it: without the `crates/cli/../..` detour when it exists.
    root.canonicalize().unwrap_or(root)
}
