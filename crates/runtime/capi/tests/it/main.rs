//! Integration tests of the C ABI: the committed header is cbindgen's output, the C examples,
//! compiled and run, print the Rust library's numbers, and every failure is a status code
//! with a message.

mod binding;
mod c_example;
mod c_robot;
#[path = "../../../tests/it/counting.rs"]
mod counting;
mod ffi;
mod ffi_robot;
mod haptic_record;
mod header;
mod record;
mod reference_model;

use std::ffi::CStr;

use hapcal_runtime_c::{HapcalStatus, hapcal_last_error_message};
use reference_model::zero_pose;

/// The message of the last failed call on this thread.
fn message() -> String {
    // SAFETY: never NULL, NUL-terminated.
    unsafe { CStr::from_ptr(hapcal_last_error_message()) }
        .to_string_lossy()
        .into_owned()
}

/// Asserts that a call returned `expected` with the message `text`.
#[track_caller]
fn fails_with(status: HapcalStatus, expected: HapcalStatus, text: &str) {
    assert_eq!((status, message().as_str()), (expected, text));
}
