//! Integration tests: the runtime against the calibration library (`hapcal-io`,
//! `hapcal-kinematics`; its drives and motor torques are checked in hapcal-force's tests),
//! central differences, and its error paths.

mod against_library;
mod counting;
mod errors;
mod haptic_record;
mod iiwa_masses;
mod no_alloc;
mod readings;
mod record;
mod robot;
mod robot_study;

use std::path::PathBuf;

pub(crate) use readings::readings;

/// A file of the repository's `fixtures/`.
pub(crate) fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(rel)
}
