//! Integration tests of hapcal-io against the fixtures in `test_data/`.

mod columns;
mod device;
mod fuzz;
mod log;
mod measure;
mod mukca;
mod targets;
mod urdf;

use std::path::PathBuf;

/// A fixture path under `crates/io/test_data/`.
fn data(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("test_data")
        .join(relative)
}

/// The reference device's file, `fixtures/reference-device/device.toml`.
fn reference_device() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device/device.toml")
}

/// A path in the MUKCa recordings, `fixtures/mukca/`.
fn mukca(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/mukca")
        .join(relative)
}

/// The error's message, failing the test if `result` is `Ok`.
#[track_caller]
fn message<T: std::fmt::Debug>(result: Result<T, hapcal_io::Error>) -> String {
    match result {
        Ok(value) => panic!("expected an error, got {value:?}"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that `text` contains every one of `parts`.
#[track_caller]
fn assert_contains(text: &str, parts: &[&str]) {
    for part in parts {
        assert!(text.contains(part), "{text:?} does not contain {part:?}");
    }
}
