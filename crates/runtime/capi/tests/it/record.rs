//! A calibrated robot whose record holds every kind of value the runtime evaluates (joint
//! offsets and origin deviations, lumped compliances at the equilibrium, per-axis transversal
//! compliances, harmonics of two orders, a region, an instrument frame), loaded through the
//! C ABI and through Rust: the same deflected poses, bit for bit, and the same region flag.
//! (The Rust runtime's agreement with the calibration library at 1e-9 m is
//! `hapcal-calibrate`'s record round-trip test.)

use std::ffi::{CString, c_char};
use std::path::PathBuf;
use std::ptr;

use hapcal_runtime::{Pose, Robot};
use hapcal_runtime_c::*;

fn record_robot() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/iiwa14_record.urdf")
}

#[test]
fn every_recorded_value_is_evaluated_as_rust_evaluates_it() {
    let path = record_robot();
    let rust = Robot::load_urdf(&path, &["ball_link"]).expect("valid record");
    let c_path = CString::new(path.to_str().expect("UTF-8")).expect("no NUL");
    let tip = CString::new("ball_link").expect("no NUL");
    let tips: [*const c_char; 1] = [tip.as_ptr()];
    let mut handle = ptr::null_mut();
    // SAFETY: valid strings, array and out pointer.
    let status = unsafe { hapcal_robot_load(c_path.as_ptr(), tips.as_ptr(), 1, &mut handle) };
    assert_eq!(status, HapcalStatus::Ok);
    let mut ws = rust.workspace();
    let rigid = rust.with_compliances(&[0.0; 7]).expect("valid");
    let mut moved: f64 = 0.0;
    for k in 0..20 {
        let q: Vec<f64> = (0..7)
            .map(|j| 1.6 * ((k * 7 + j) as f64 * 0.37).sin())
            .collect();
        let mut ours = [Pose::IDENTITY];
        rust.deflected_tip_poses(&q, &mut ws, &mut ours)
            .expect("valid");
        let mut theirs = [HapcalPose {
            rotation: [[0.0; 3]; 3],
            translation_m: [0.0; 3],
        }];
        let mut deflection = HapcalDeflection::default();
        // SAFETY: valid handle, arrays of the stated lengths.
        let status = unsafe {
            hapcal_robot_deflected_tip_poses(
                handle,
                q.as_ptr(),
                7,
                theirs.as_mut_ptr(),
                1,
                &mut deflection,
            )
        };
        assert_eq!(status, HapcalStatus::Ok);
        assert_eq!(theirs[0].translation_m, ours[0].translation_m);
        assert_eq!(theirs[0].rotation, ours[0].rotation);
        let mut plain = [Pose::IDENTITY];
        rigid
            .deflected_tip_poses(&q, &mut ws, &mut plain)
            .expect("valid");
        let d = (0..3)
            .map(|i| (plain[0].translation_m[i] - ours[0].translation_m[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        moved = moved.max(d);
        // The region flag: joint readings up to 1.6 rad against a −1..1 rad training range.
        let (mut joint, mut distance) = (0usize, 0.0);
        // SAFETY: valid handle and out pointers.
        let status = unsafe {
            hapcal_robot_outside_region(handle, q.as_ptr(), 7, &mut joint, &mut distance)
        };
        assert_eq!(status, HapcalStatus::Ok);
        match rust.outside_region(&q).expect("valid") {
            Some((j, past)) => assert_eq!((joint, distance), (j, past)),
            None => assert_eq!(joint, HAPCAL_INSIDE_REGION),
        }
    }
    // The compliances and harmonics move the tip by millimetres: the comparison is not of
    // two rigid robots.
    assert!(moved > 1e-3, "{moved}");
    // SAFETY: the handle from hapcal_robot_load, freed once.
    unsafe { hapcal_robot_free(handle) };
}
