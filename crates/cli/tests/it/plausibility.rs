//! An estimate no real robot can have is never written: the bundled humanoid's URDF mounted
//! upside down gives negative compliances under the default gravity, `calibrate` stops with
//! exit code 2 naming the mounting and its flag and writes nothing; with the flag it passes and
//! the record holds the gravity it used.

use super::{hapcal, root, scratch, show, stderr};

#[test]
fn a_ceiling_mount_stops_calibrate_and_its_gravity_flag_passes() {
    let dir = scratch("ceiling");
    let upright = root().join("fixtures/sim-humanoid/humanoid.urdf");
    let text = std::fs::read_to_string(&upright).expect("the fixture");
    let turned = text.replacen(
        r#"<origin xyz="0 0 0.3" rpy="0 0 0"/>"#,
        r#"<origin xyz="0 0 0.3" rpy="3.141592653589793 0 0"/>"#,
        1,
    );
    assert_ne!(turned, text, "the root joint's origin moved in the fixture");
    let device = dir.join("humanoid_ceiling.urdf");
    std::fs::write(&device, turned).expect("write");
    let data = root().join("fixtures/sim-humanoid/mocap.csv");
    let out_path = dir.join("calibrated.urdf");
    let (device, data, out_s) = (show(&device), show(&data), show(&out_path));
    let args = [
        "calibrate",
        "--device",
        &device,
        "--tip",
        "l_hand",
        "--tip",
        "r_hand",
        "--data",
        &data,
        "--model",
        "compliance",
        "--out",
        &out_s,
    ];
    let out = hapcal(&args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("[mounting]"), "{err}");
    assert!(err.contains("upside down"), "{err}");
    assert!(err.contains("fix: --gravity +z"), "{err}");
    assert!(!out_path.exists(), "an implausible calibration was written");
    let mut fixed = args.to_vec();
    fixed.extend(["--gravity", "+z"]);
    let out = hapcal(&fixed);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let record = std::fs::read_to_string(out_path.with_extension("calibration.toml"))
        .expect("the record beside the URDF");
    assert!(
        record.contains("gravity_direction = [0.0, 0.0, 1.0]"),
        "{record}"
    );
}

#[test]
fn gravity_is_refused_where_no_compliance_model_reads_it() {
    let out = hapcal(&["calibrate", "--gravity", "+z"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--gravity +z applies to measurement files"),
        "{err}"
    );
    let out = hapcal(&["calibrate", "--gravity", "up"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("-z upright"), "{}", stderr(&out));
}
