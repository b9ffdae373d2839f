//! The C ABI called from Rust: status codes, messages, null pointers, no panic.

use std::ffi::CString;
use std::ptr;

use hapcal_runtime_c::*;

use crate::reference_model::load_reference_model;
use crate::{fails_with, message, zero_pose};

#[test]
fn evaluation_through_the_abi_matches_the_library() {
    let model = load_reference_model();
    let theta = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
    let wrench = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
    let (mut tau, mut jac) = ([0.0; 7], [0.0; 42]);
    let mut pose = zero_pose();
    // SAFETY: a live model and arrays of the stated sizes.
    let status = unsafe {
        hapcal_evaluate(
            model,
            theta.as_ptr(),
            7,
            wrench.as_ptr(),
            &mut pose,
            jac.as_mut_ptr(),
            tau.as_mut_ptr(),
        )
    };
    assert_eq!(status, HapcalStatus::Ok);
    let lib = hapcal_runtime::Model::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../fixtures/reference-device/calibrated.toml"
    )))
    .expect("fixture");
    let mut want = [0.0; 7];
    lib.motor_torques(&theta, &wrench, &mut want)
        .expect("valid");
    assert_eq!(tau, want);
    let mut spatial = [0.0; 42];
    let mut body = [0.0; 42];
    // SAFETY: as above; NULL pose is allowed.
    unsafe {
        assert_eq!(
            hapcal_spatial_jacobian(
                model,
                theta.as_ptr(),
                7,
                spatial.as_mut_ptr(),
                ptr::null_mut()
            ),
            HapcalStatus::Ok
        );
        assert_eq!(
            hapcal_body_jacobian(model, theta.as_ptr(), 7, body.as_mut_ptr(), ptr::null_mut()),
            HapcalStatus::Ok
        );
    }
    assert_eq!(body, jac);
    // Body = Rᵀ · spatial, column by column.
    for k in 0..7 {
        for half in [0, 3] {
            for i in 0..3 {
                let rt_s: f64 = (0..3)
                    .map(|m| pose.rotation[m][i] * spatial[6 * k + half + m])
                    .sum();
                assert!((rt_s - body[6 * k + half + i]).abs() < 1e-14);
            }
        }
    }
    // SAFETY: a live model, freed once.
    unsafe { hapcal_model_free(model) };
}

#[test]
fn failures_are_status_codes_with_messages() {
    let model = load_reference_model();
    // Joint 4 within its polynomial's domain (the joint's limits, 0.3 to 1.8 rad).
    let theta = [0.1, 0.1, 0.1, 1.0, 0.1, 0.1, 0.1];
    let mut tau = [0.0; 7];
    let wrench = [0.0; 6];
    // SAFETY: every pointer is NULL or valid for the stated sizes.
    unsafe {
        let s = hapcal_motor_torques(
            ptr::null(),
            theta.as_ptr(),
            7,
            wrench.as_ptr(),
            tau.as_mut_ptr(),
        );
        fails_with(s, HapcalStatus::NullPointer, "model is NULL");
        let s = hapcal_motor_torques(model, theta.as_ptr(), 7, ptr::null(), tau.as_mut_ptr());
        fails_with(s, HapcalStatus::NullPointer, "wrench is NULL");
        let s = hapcal_motor_torques(model, theta.as_ptr(), 8, wrench.as_ptr(), tau.as_mut_ptr());
        assert_eq!(s, HapcalStatus::Length);
        assert_eq!(message(), "n_joints: expected 7 values, found 8");
        let nan = [f64::NAN; 7];
        let s = hapcal_motor_torques(model, nan.as_ptr(), 7, wrench.as_ptr(), tau.as_mut_ptr());
        assert_eq!(s, HapcalStatus::NotFinite);
        assert_eq!(message(), "joint readings[0] = NaN is not finite");
        // A non-finite wrench, and a joint-4 reading far past its polynomial's fitted domain:
        // a status, and the torques left as they were.
        let mut untouched = [7.0; 7];
        let bad_wrench = [0.0, 0.0, f64::INFINITY, 0.0, 0.0, 0.0];
        let s = hapcal_motor_torques(
            model,
            theta.as_ptr(),
            7,
            bad_wrench.as_ptr(),
            untouched.as_mut_ptr(),
        );
        fails_with(s, HapcalStatus::NotFinite, "wrench[2] = inf is not finite");
        let mut far = theta;
        far[3] = 100.0;
        let s = hapcal_motor_torques(
            model,
            far.as_ptr(),
            7,
            wrench.as_ptr(),
            untouched.as_mut_ptr(),
        );
        assert_eq!(s, HapcalStatus::OutsideDomain);
        assert!(
            message().starts_with("joint readings[3] = 100 rad lies outside"),
            "{}",
            message()
        );
        assert_eq!(untouched, [7.0; 7]);
        // A success leaves the last message in place.
        let s = hapcal_motor_torques(model, theta.as_ptr(), 7, wrench.as_ptr(), tau.as_mut_ptr());
        assert_eq!(s, HapcalStatus::Ok);
        assert!(
            message().starts_with("joint readings[3] = 100 rad"),
            "{}",
            message()
        );
        assert_eq!(hapcal_model_n_joints(ptr::null()), 0);
        hapcal_model_free(ptr::null_mut());

        let mut other = ptr::null_mut();
        let missing = CString::new("/no/such/device.toml").expect("no NUL");
        assert_eq!(
            hapcal_model_load(missing.as_ptr(), &mut other),
            HapcalStatus::Io
        );
        assert!(
            message().starts_with("/no/such/device.toml: cannot read"),
            "{}",
            message()
        );
        let bad = CString::new("[[dh]]\na_m = 1\n").expect("no NUL");
        assert_eq!(
            hapcal_model_from_toml(bad.as_ptr(), &mut other),
            HapcalStatus::Parse
        );
        assert!(message().starts_with("<string>:"), "{}", message());
        let not_utf8 = [0xffu8, 0xfe, 0];
        assert_eq!(
            hapcal_model_from_toml(not_utf8.as_ptr().cast(), &mut other),
            HapcalStatus::InvalidUtf8
        );
        assert_eq!(
            hapcal_model_from_toml(bad.as_ptr(), ptr::null_mut()),
            HapcalStatus::NullPointer
        );
        assert!(other.is_null(), "nothing stored on failure");
        hapcal_model_free(model);
    }
}
