//! What the C ABI's integration tests and its benchmark both start from: the reference
//! device's calibrated model loaded through the ABI, and a pose to be written over.

use std::ffi::{CStr, CString};
use std::ptr;

use hapcal_runtime_c::{
    HapcalModel, HapcalPose, HapcalStatus, hapcal_last_error_message, hapcal_model_load,
};

/// The reference device's calibrated model (`fixtures/reference-device/calibrated.toml`),
/// loaded through [`hapcal_model_load`]; the caller frees it with `hapcal_model_free`.
///
/// # Panics
/// If the load fails, with the ABI's message.
pub(crate) fn load_reference_model() -> *mut HapcalModel {
    let path = CString::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../fixtures/reference-device/calibrated.toml"
    ))
    .expect("no NUL");
    let mut model = ptr::null_mut();
    // SAFETY: valid string and out pointer.
    let status = unsafe { hapcal_model_load(path.as_ptr(), &mut model) };
    // SAFETY: never NULL, NUL-terminated.
    let message = unsafe { CStr::from_ptr(hapcal_last_error_message()) };
    assert_eq!(status, HapcalStatus::Ok, "{}", message.to_string_lossy());
    model
}

/// A pose of zeros, to be written over.
pub(crate) fn zero_pose() -> HapcalPose {
    HapcalPose {
        rotation: [[0.0; 3]; 3],
        translation_m: [0.0; 3],
    }
}
