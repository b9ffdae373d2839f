//! Calibration workflows: load a device (URDF, D-H or modified D-H table, the haptic device's
//! TOML) and its measurements, choose the model the data support, identify it, report and
//! write the result back. The `hapcal` command line is argument parsing and rendering on top
//! of this crate; a Rust program calibrates through it alone.
//!
//! Architecture invariant: *`calibrate` never prints and never needs a truth: everything it
//! does, a user with a real device and real measurements can do.*

pub mod calibrate;
pub mod haptic;
pub mod measured;
pub mod plan;
pub mod support;

use std::path::PathBuf;

/// Root of the source tree (where `fixtures/` lives), fixed at build time.
pub fn project_root() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    // Reports print paths under it: without the `crates/calibrate/../..` detour when it exists.
    root.canonicalize().unwrap_or(root)
}
