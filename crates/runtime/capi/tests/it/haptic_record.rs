//! A haptic device calibrated with the handle's gravity compliance, through the C ABI: the
//! deflected end points the Rust runtime gives (which hapcal-runtime's tests hold to the
//! calibration library's predictions within 1 nm).

use std::ffi::CString;
use std::ptr;

use hapcal_runtime_c::*;

use crate::{message, zero_pose};

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../fixtures/reference-device/compliance-calibrated.toml"
);

#[test]
fn a_handle_compliance_deflects_the_end_point_through_the_abi() {
    let path = CString::new(FIXTURE).expect("no NUL");
    let mut model = ptr::null_mut();
    // SAFETY: valid string and out pointer.
    let status = unsafe { hapcal_model_load(path.as_ptr(), &mut model) };
    assert_eq!(status, HapcalStatus::Ok, "{}", message());
    let rust = hapcal_runtime::Model::load(std::path::Path::new(FIXTURE)).expect("fixture");
    let rigid = rust
        .with_handle_compliance(&[0.0; 7], 0.0, [0.0, 0.0, -1.0])
        .expect("rigid");
    let readings = [
        [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4],
        [-0.3, 0.2, 0.4, 0.7, -0.5, 0.1, 0.2],
    ];
    for theta in readings {
        let mut pose = zero_pose();
        let mut q = [0.0; 7];
        let mut dq = [0.0; 7];
        // SAFETY: a live model and arrays of the stated sizes.
        unsafe {
            assert_eq!(
                hapcal_end_pose(model, theta.as_ptr(), 7, &mut pose),
                HapcalStatus::Ok
            );
            assert_eq!(
                hapcal_joint_angles(model, theta.as_ptr(), 7, q.as_mut_ptr(), dq.as_mut_ptr()),
                HapcalStatus::Ok
            );
        }
        let want = rust.end_pose(&theta).expect("valid");
        assert_eq!(pose.translation_m, want.translation_m);
        assert_eq!(pose.rotation, want.rotation);
        // The pose is the chain's at the deflected joint angles the ABI reports.
        let at_joints = rust.end_pose_at_joints(&q).expect("valid");
        assert_eq!(pose.translation_m, at_joints.translation_m);
        // The deflection is there: the handle's sag moves the end point by micrometres.
        let stiff = rigid.end_pose(&theta).expect("valid").translation_m;
        let sag: f64 = (0..3)
            .map(|k| (pose.translation_m[k] - stiff[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(sag > 1e-6, "sag {sag:e} m");
    }
    // SAFETY: a live model, freed once.
    unsafe { hapcal_model_free(model) };
}
