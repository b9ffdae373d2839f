//! A calibrated robot whose record holds every kind of value the runtime evaluates (joint
//! offsets and origin deviations, lumped compliances at the equilibrium, per-axis transversal
//! compliances, harmonics of two orders, a region, an instrument frame), loaded through the
//! C ABI and through Rust: the same deflected poses, bit for bit, and the same region flag.
//! (The Rust runtime's agreement with the calibration library at 1e-9 m is
//! `hapcal-calibrate`'s record round-trip test.)

use std::ffi::{CString, c_char};
use std::path::PathBuf;
use std::ptr;

use hapcal_contract::{
    CalibratedValue, Calibration, Frame, ModelName, PointMass, Region, SCHEMA_VERSION, Torque,
    TorqueSource,
};
use hapcal_runtime::{Pose, Robot};
use hapcal_runtime_c::*;

use crate::zero_pose;

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
        let mut theirs = [zero_pose()];
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

/// The record of the C ABI's test robot (`tests/data/iiwa14_calibrated.urdf`): made-up
/// identified frames (the instrument, marker 1) and joint compliances of 1e-4 to 3e-4
/// rad/(N·m) (σ 1 %) under the URDF's link masses, gravity along −z at the torque
/// equilibrium, bound to the URDF by its digest.
fn test_robot_record(urdf: &std::path::Path) -> Calibration {
    let tips = ["ball_link".to_owned(), "tool0".to_owned()];
    let tree = hapcal_io::import_urdf_tips(urdf, &tips).expect("test robot");
    let text = std::fs::read(urdf).expect("test robot");
    let frame = |xyz_m, rpy_rad| Frame { xyz_m, rpy_rad };
    let k = [1e-4, 1e-4, 1.5e-4, 1.5e-4, 2e-4, 3e-4, 3e-4];
    let std = [1e-6, 1e-6, 1.5e-6, 1.5e-6, 2e-6, 3e-6, 3e-6];
    Calibration {
        schema_version: Some(SCHEMA_VERSION),
        model: Some(ModelName::Compliance),
        notes: Some(
            "the C ABI's test robot: made-up identified frames and joint compliances".to_owned(),
        ),
        urdf_digest: Some(hapcal_contract::digest(&text)),
        torque: Some(Torque {
            source: TorqueSource::UrdfMasses,
            gravity_direction: [0.0, 0.0, -1.0],
            gravity_m_s2: hapcal_runtime::STANDARD_GRAVITY,
            equilibrium: true,
            tips: Vec::new(),
            masses: (tree.inertials.iter())
                .map(|l| PointMass {
                    joint: tree.joints[l.joint].name.clone(),
                    mass_kg: l.mass_kg,
                    com_m: l.com_m,
                })
                .collect(),
            handle_mass_kg: None,
        }),
        region: Some(Region {
            rows: 200,
            joints: Vec::new(),
        }),
        frames: [
            (
                "instrument".to_owned(),
                frame([1.2, -0.3, 0.05], [0.01, -0.02, 1.5]),
            ),
            (
                "marker1".to_owned(),
                frame([0.001, -0.002, 0.003], [0.0, 0.0, 0.0]),
            ),
        ]
        .into(),
        values: (tree.joints.iter().zip(k).zip(std))
            .map(|((j, k), std)| CalibratedValue {
                name: format!("compliance.{}", j.name),
                value: k,
                std,
                unit: "rad/(N·m)".to_owned(),
            })
            .collect(),
        ..Calibration::default()
    }
}

/// The test robot's sidecar is the record above as the contract's one writer writes it
/// (`UPDATE_GOLDEN=1` rewrites it and fails, for review).
#[test]
fn the_test_robots_sidecar_is_written_by_the_contract() {
    let urdf = record_robot().with_file_name("iiwa14_calibrated.urdf");
    let sidecar = urdf.with_extension("calibration.toml");
    let expected = test_robot_record(&urdf).to_sidecar_toml();
    let found = std::fs::read_to_string(&sidecar).unwrap_or_default();
    if found != expected && std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::write(&sidecar, &expected).expect("written");
        panic!(
            "UPDATE_GOLDEN: rewrote {}; review the diff and run again without it",
            sidecar.display()
        );
    }
    assert_eq!(
        found,
        expected,
        "{} (UPDATE_GOLDEN=1 rewrites it)",
        sidecar.display()
    );
}

/// The record's loads are the URDF's link masses at the equilibrium, as the robot's own
/// defaults: loaded with its sidecar, the test robot deflects bit for bit as the bare URDF
/// with the record's compliances set.
#[test]
fn the_test_robots_record_loads_the_urdfs_own_masses() {
    let urdf = record_robot().with_file_name("iiwa14_calibrated.urdf");
    let tips = ["ball_link", "tool0"];
    let recorded = Robot::load_urdf(&urdf, &tips).expect("test robot");
    let text = std::fs::read_to_string(&urdf).expect("test robot");
    let bare = Robot::from_urdf_str(&text, "bare", None, &tips).expect("test robot");
    let bare = bare
        .with_compliances(recorded.compliances())
        .expect("valid");
    assert!(recorded.has_compliance());
    let mut ws = recorded.workspace();
    for k in 0..20 {
        let q: Vec<f64> = (0..7)
            .map(|j| 1.6 * ((k * 7 + j) as f64 * 0.37).sin())
            .collect();
        let (mut ours, mut theirs) = ([Pose::IDENTITY; 2], [Pose::IDENTITY; 2]);
        recorded
            .deflected_tip_poses(&q, &mut ws, &mut ours)
            .expect("valid");
        bare.deflected_tip_poses(&q, &mut ws, &mut theirs)
            .expect("valid");
        for (a, b) in ours.iter().zip(&theirs) {
            assert_eq!(a.translation_m, b.translation_m, "q {q:?}");
            assert_eq!(a.rotation, b.rotation, "q {q:?}");
        }
    }
}
