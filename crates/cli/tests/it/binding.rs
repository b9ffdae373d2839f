//! A calibration record binds to the URDF `hapcal calibrate` wrote it beside: `predict` and
//! `compensate` refuse it beside another URDF, for another tip, or with a value edited by
//! hand, each in words at its line; `compensate` names start commands outside the limits.

use std::path::{Path, PathBuf};

use crate::predict::calibrated_ur10;
use crate::{assert_exit, compensate, hapcal, iiwa, root, scratch, show, stderr, ur10_csv};

/// `hapcal predict` of the UR10's bundled poses on `urdf` with `tip`.
fn predict(urdf: &Path, tip: &str) -> std::process::Output {
    let data = ur10_csv();
    hapcal(&[
        "predict",
        "--device",
        &show(urdf),
        "--tip",
        tip,
        "--data",
        &show(&data),
    ])
}

/// The UR10 calibrated in the scratch folder `name`: the written URDF, its record's path and
/// the record's text.
fn calibrated_ur10_record(name: &str) -> (PathBuf, PathBuf, String) {
    let (urdf, _) = calibrated_ur10(&scratch(name));
    let sidecar_path = urdf.with_extension("calibration.toml");
    let sidecar = std::fs::read_to_string(&sidecar_path).expect("a sidecar");
    (urdf, sidecar_path, sidecar)
}

/// The first value in metres of a record's `[values]`: its line (1-based), name and number.
fn first_length(sidecar: &str) -> (usize, String, f64) {
    let values = sidecar.find("[values]").expect("values");
    let before = sidecar[..values].lines().count();
    for (i, line) in sidecar[values..].lines().enumerate() {
        if line.contains("unit = \"m\"") {
            let name = line.split('"').nth(1).expect("a quoted name").to_owned();
            let value = line
                .split("value = ")
                .nth(1)
                .and_then(|r| r.split(',').next())
                .and_then(|v| v.trim().parse().ok())
                .expect("a number");
            return (before + i + 1, name, value);
        }
    }
    panic!("no length among the values")
}

#[test]
fn a_record_is_refused_beside_another_urdf_for_another_tip_or_edited_by_hand() {
    let (urdf, sidecar_path, sidecar) = calibrated_ur10_record("binding");
    assert!(sidecar.contains("urdf_digest = \"fnv1a64:"), "{sidecar}");
    assert!(sidecar.contains("[nominal."), "{sidecar}");
    // The files as written agree: the record's values and nominal origins give the URDF's.
    let run = predict(&urdf, "wrist_3_link");
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(!stderr(&run).contains("no digest"), "{}", stderr(&run));

    // The nominal UR10 beside the calibrated one's record.
    let other = scratch("binding-other");
    let nominal = other.join("ur10.urdf");
    std::fs::copy(
        root().join("fixtures/figaroh/ur10/ur10_robot.urdf"),
        &nominal,
    )
    .expect("copy");
    std::fs::write(nominal.with_extension("calibration.toml"), &sidecar).expect("write");
    let run = predict(&nominal, "wrist_3_link");
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    let line = sidecar
        .lines()
        .position(|l| l.starts_with("urdf_digest"))
        .expect("a digest")
        + 1;
    for words in [
        format!("ur10.calibration.toml:{line}:"),
        show(&nominal),
        "another robot description".to_owned(),
        "calibrate".to_owned(),
    ] {
        assert!(err.contains(&words), "{words}: {err}");
    }
    let targets = other.join("targets.csv");
    std::fs::write(&targets, "x,y,z\n0.5,0.2,0.6\n").expect("write");
    let out = other.join("commands.csv");
    let run = compensate(&nominal, "wrist_3_link", &targets, &out);
    assert_exit(&run, 2, &["urdf_digest"]);

    // Another tip than the calibration's.
    let run = predict(&urdf, "forearm_link");
    assert_exit(
        &run,
        2,
        &["tips = [\"wrist_3_link\"]", "--tip wrist_3_link"],
    );

    // A value edited by hand to 10 m: refused with its line and both numbers.
    let (line, name, value) = first_length(&sidecar);
    let edited = (sidecar.lines().enumerate())
        .map(|(i, l)| {
            if i + 1 == line {
                format!("\"{name}\" = {{ value = 10.0, std = 1e-6, unit = \"m\" }}")
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&sidecar_path, edited).expect("write");
    let run = predict(&urdf, "wrist_3_link");
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    let at = format!("{name} = 10 m (line {line}), where the URDF's origin of ");
    assert!(err.contains(&at), "{at}: {err}");
    let held: f64 = err[err.find(&at).expect("found") + at.len()..]
        .split(" holds ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .expect("the URDF's number");
    assert!(
        (held - value).abs() < 1e-12,
        "{held} against {value} written"
    );
    assert!(
        err.contains(&format!("ur10.calibration.toml:{line}:")),
        "{err}"
    );
}

#[test]
fn a_record_without_a_digest_loads_with_a_note() {
    let (urdf, sidecar_path, sidecar) = calibrated_ur10_record("binding-note");
    let old: String = (sidecar.lines())
        .filter(|l| !l.starts_with("urdf_digest"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&sidecar_path, old).expect("write");
    let run = predict(&urdf, "wrist_3_link");
    assert_exit(&run, 0, &["holds no digest of the URDF"]);
}

#[test]
fn compensate_names_start_commands_outside_the_limits() {
    let dir = scratch("binding-start");
    let urdf = dir.join("robot.urdf");
    std::fs::copy(iiwa(), &urdf).expect("copy");
    // A start in degrees (17°, 40°, …, 1.5°): every joint within its limits as degrees, all
    // but the last beyond them as radians.
    let text = "x,y,z,joint_a1,joint_a2,joint_a3,joint_a4,joint_a5,joint_a6,joint_a7\n\
                0.5,0.1,0.8,0.3,0.7,-0.2,-1.2,0.4,0.9,0.1\n\
                0.5,0.1,0.8,17.2,40.1,-11.5,-68.8,22.9,51.6,1.5\n";
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, text).expect("write");
    let run = compensate(&urdf, "ball_link", &targets, &dir.join("commands.csv"));
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    let err = stderr(&run);
    for words in [
        format!(
            "{}:3: a start command outside the robot's limits",
            show(&targets)
        ),
        "joint_a2 = 40.1 rad, limits [".to_owned(),
        "degrees read as radians".to_owned(),
    ] {
        assert!(err.contains(&words), "{words}: {err}");
    }
    assert!(
        !err.contains("joint_a7 ="),
        "1.5 rad is within joint_a7's limits: {err}"
    );
}
