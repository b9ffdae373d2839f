//! Hostile inputs and environments: a closed or full standard output, outputs that would
//! replace an input or land in a missing folder, more folds than data, finite but absurd
//! lengths, and a `--model` the data do not take. Each must end with a clear message and exit
//! code, never a panic.

use super::{assert_exit, hapcal, hapcal_ok, root, scratch, show, stderr, ur10_csv, ur10_urdf};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn reference(file: &str) -> String {
    root()
        .join("fixtures/reference-device")
        .join(file)
        .display()
        .to_string()
}

/// `hapcal calibrate` of the reference device on the log `log`, with `more`.
fn calibrate_reference(log: &Path, more: &[&str]) -> Output {
    let (device, log) = (reference("device.toml"), show(log));
    let mut args = vec!["calibrate", "--device", &device, "--data", &log];
    args.extend_from_slice(more);
    hapcal(&args)
}

/// Runs `hapcal args` with its standard output on a pipe whose reading end is already closed:
/// every write gets a broken pipe.
fn hapcal_into_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args(args)
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .expect("the binary runs")
}

/// A simulated log of `poses` poses of the reference device, in `dir`.
fn simulated_log(dir: &Path, poses: usize) -> PathBuf {
    let log = dir.join("log.csv");
    hapcal_ok(&[
        "simulate",
        "--poses",
        &poses.to_string(),
        "--out",
        &show(&log),
    ]);
    log
}

#[test]
fn a_closed_standard_output_ends_quietly_with_exit_code_0() {
    for args in [
        &["calibrate", "--help"][..],
        &["calibrate", "--model", "geometric"][..],
        &["calibrate", "--model", "geometric", "--json"][..],
        &["import-urdf", &super::iiwa(), "--tip", "ball_link"][..],
    ] {
        let out = hapcal_into_closed_pipe(args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        assert!(err.is_empty(), "{args:?}: {err}");
    }
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_standard_output_is_an_error_with_exit_code_2() {
    for args in [
        &["calibrate", "--model", "geometric"][..],
        &["calibrate", "--help"][..],
    ] {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .expect("/dev/full");
        let out = Command::new(env!("CARGO_BIN_EXE_hapcal"))
            .args(args)
            .stdout(Stdio::from(full))
            .output()
            .expect("the binary runs");
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("cannot write to standard output") && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn an_output_in_a_missing_folder_names_the_path_and_the_folder() {
    let dir = scratch("hostile-missing");
    let missing = dir.join("no-such-folder");
    let out_path = missing.join("log.csv");
    let out = hapcal(&["simulate", "--poses", "5", "--out", &show(&out_path)]);
    assert_exit(
        &out,
        2,
        &[
            &format!("cannot write {}", out_path.display()),
            &format!("{} does not exist", missing.display()),
        ],
    );
}

#[test]
fn an_output_that_is_an_input_is_refused_and_left_intact() {
    let dir = scratch("hostile-input");
    let log = simulated_log(&dir, 40);
    let device = dir.join("device.toml");
    std::fs::copy(reference("device.toml"), &device).expect("copy");
    let before = std::fs::read_to_string(&device).expect("read");
    // The device itself, the same file by another spelling, and (on Unix) through a link.
    let mut aliases = vec![device.clone(), dir.join(".").join("device.toml")];
    #[cfg(unix)]
    {
        let link = dir.join("alias.toml");
        std::os::unix::fs::symlink(&device, &link).expect("symlink");
        aliases.push(link);
    }
    for alias in &aliases {
        let out = hapcal(&[
            "calibrate",
            "--device",
            &show(&device),
            "--data",
            &show(&log),
            "--out",
            &show(alias),
        ]);
        assert_exit(
            &out,
            2,
            &[&format!("cannot write {}", alias.display()), "is an input"],
        );
    }
    // A simulated log written over the data it is also given as: refused the same way.
    let out = hapcal(&[
        "simulate",
        "--device",
        &show(&device),
        "--truth",
        &show(&log),
        "--out",
        &show(&log),
    ]);
    assert_exit(&out, 2, &["is an input"]);
    assert_eq!(std::fs::read_to_string(&device).expect("read"), before);
}

#[test]
fn an_output_extension_that_names_another_format_is_refused() {
    let dir = scratch("hostile-extension");
    let log = simulated_log(&dir, 40);
    let device = reference("device.toml");
    let cases: [(Vec<String>, &str); 4] = [
        (
            ["calibrate", "--device", &device, "--data", &show(&log)]
                .into_iter()
                .map(str::to_owned)
                .chain(["--out".into(), show(&dir.join("c.csv"))])
                .collect(),
            "the calibrated device is written as .toml or .urdf, not as .csv",
        ),
        (
            ["simulate", "--out", &show(&dir.join("log.toml"))]
                .map(str::to_owned)
                .to_vec(),
            "the simulated log is written as .csv, not as .toml",
        ),
        (
            [
                "plan-poses",
                "--device",
                &device,
                "--out",
                &show(&dir.join("p.svg")),
            ]
            .map(str::to_owned)
            .to_vec(),
            "the planned poses is written as .csv, not as .svg",
        ),
        (
            [
                "force",
                "--device",
                &device,
                "--truth",
                &reference("truth.toml"),
                "--calibrated",
                &reference("calibrated.toml"),
                "--svg",
                &show(&dir.join("fig.toml")),
            ]
            .map(str::to_owned)
            .to_vec(),
            "is written as .svg, not as .toml",
        ),
    ];
    for (args, message) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = hapcal(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(message), "{args:?}: {err}");
    }
    let left: Vec<_> = std::fs::read_dir(&dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(left, ["log.csv"], "nothing but the log was written");
}

#[test]
fn outputs_are_replaced_whole_without_temporary_files_left() {
    let dir = scratch("hostile-atomic");
    let log = simulated_log(&dir, 30);
    let first = std::fs::read_to_string(&log).expect("read");
    let again = simulated_log(&dir, 10);
    assert_eq!(again, log);
    let second = std::fs::read_to_string(&log).expect("read");
    assert_ne!(first, second);
    assert_eq!(second.lines().count(), 11, "header + 10 rows");
    let names: Vec<_> = std::fs::read_dir(&dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, ["log.csv"]);
}

#[test]
fn more_folds_than_training_configurations_is_an_error_naming_both() {
    let front = root().join("fixtures/mukca/data/kuka_14/front");
    let out = hapcal(&[
        "calibrate",
        "--device",
        &super::iiwa(),
        "--data",
        &show(&front),
        "--folds",
        "1000",
    ]);
    assert_exit(&out, 2, &["--folds 1000", "62 training configurations"]);
}

#[test]
fn absurd_finite_lengths_are_refused_where_they_are_read() {
    let dir = scratch("hostile-lengths");
    // A log distance of 1e308 m (it used to panic in the identification).
    let log = simulated_log(&dir, 40);
    let text = std::fs::read_to_string(&log).expect("read");
    let bad_log = dir.join("bad.csv");
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cells: Vec<&str> = lines[2].split(',').collect();
    cells[7] = "1e308"; // distance_m, the 8th column of a 7-joint log
    lines[2] = cells.join(",");
    std::fs::write(&bad_log, lines.join("\n") + "\n").expect("write");
    let out = calibrate_reference(&bad_log, &[]);
    let err = assert_exit(&out, 2, &[]);
    assert!(
        err.contains("bad.csv:3:8: distance_m = 1e308 m is out of range")
            && err.contains("±1000 m")
            && !err.contains("panicked"),
        "{err}"
    );

    // A D-H length of 1e308 m in a device file.
    let device = std::fs::read_to_string(reference("device.toml")).expect("read");
    let big = dir.join("big.toml");
    std::fs::write(&big, device.replacen("a_m = 0.35", "a_m = 1e308", 1)).expect("write");
    let out = hapcal(&[
        "simulate",
        "--device",
        &show(&big),
        "--out",
        &show(&dir.join("z.csv")),
    ]);
    assert_exit(&out, 2, &["big.toml:", "a_m = 1e308 m is out of range"]);

    // A URDF joint origin of 1e308 m.
    let urdf = std::fs::read_to_string(root().join("fixtures/mukca/urdf/iiwa14.urdf")).unwrap();
    let origin = "xyz=\"-0.00043624 0 0.36\"";
    assert!(urdf.contains(origin), "fixture changed");
    let big = dir.join("big.urdf");
    std::fs::write(
        &big,
        urdf.replacen(origin, "xyz=\"-0.00043624 0 1e308\"", 1),
    )
    .unwrap();
    let out = hapcal(&["import-urdf", &show(&big), "--tip", "ball_link"]);
    assert_exit(
        &out,
        2,
        &[
            "big.urdf:",
            "joint \"joint_a2\" <origin xyz> = 1e308 m is out of range",
        ],
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn folds_on_the_haptic_path_set_the_model_ladders_cross_validation() {
    let dir = scratch("hostile-haptic-folds");
    let log = simulated_log(&dir, 40);
    let out = calibrate_reference(&log, &["--folds", "7"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    // The report (on standard output): the ladder's table, no warning about the folds.
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(
        report.contains("model choice by 7-fold cross-validation")
            && report.contains("transmissions")
            && !report.contains("--folds"),
        "{report}"
    );
}

/// `hapcal calibrate --model value` with `args` (device and data): exit code 2 and a message
/// that names the value as typed, never the Rust name of the model.
fn refused_model(args: &[&str], value: &str) -> String {
    let mut all = vec!["calibrate", "--model", value];
    all.extend_from_slice(args);
    let err = assert_exit(
        &hapcal(&all),
        2,
        &[&format!("--model {value} does not apply to")],
    );
    for rust in [
        "Geometric",
        "Compliance",
        "Harmonic",
        "Transmissions",
        "FramesOnly",
    ] {
        assert!(!err.contains(rust), "{rust}: {err}");
    }
    err
}

#[test]
fn a_model_the_haptic_log_does_not_take_is_refused_naming_those_it_takes() {
    let dir = scratch("hostile-haptic-model");
    let log = simulated_log(&dir, 40);
    for value in ["mass-compliance", "compliance-harmonic", "frames-only"] {
        let (device, log) = (reference("device.toml"), show(&log));
        let err = refused_model(&["--device", &device, "--data", &log], value);
        assert!(
            err.contains("a haptic device's logs: ")
                && err.contains("they take auto, geometric, compliance, transmissions"),
            "{err}"
        );
    }
}

#[test]
fn compliance_on_a_haptic_device_without_a_handle_mass_is_refused_in_words() {
    let dir = scratch("hostile-haptic-no-handle");
    let log = simulated_log(&dir, 40);
    let text = std::fs::read_to_string(reference("device.toml")).unwrap();
    let (without, _) = text
        .split_once("[handle]")
        .expect("the fixture has a [handle]");
    let device = dir.join("device.toml");
    std::fs::write(&device, without).unwrap();
    let args = [
        "calibrate",
        "--device",
        &show(&device),
        "--data",
        &show(&log),
        "--model",
        "compliance",
    ];
    let out = hapcal(&args);
    let err = assert_exit(
        &out,
        2,
        &["needs the handle's weight", "no [handle] section"],
    );
    assert!(
        !err.contains("Compliance") && !err.contains("Some("),
        "{err}"
    );
    // The other models do not need it.
    let mut args = args.to_vec();
    args[6] = "transmissions";
    hapcal_ok(&args);
}

#[test]
fn transmissions_without_external_encoder_columns_is_refused() {
    let dir = scratch("hostile-haptic-no-ext");
    let log = simulated_log(&dir, 40);
    let text = std::fs::read_to_string(&log).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let n_keep = header.iter().take_while(|c| !c.starts_with("ext")).count();
    assert!(n_keep < header.len(), "the simulated log has ext columns");
    let stripped: String = (text.lines())
        .map(|l| l.split(',').take(n_keep).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    std::fs::write(&log, stripped).unwrap();
    let out = calibrate_reference(&log, &["--model", "transmissions"]);
    assert_exit(
        &out,
        2,
        &["--model transmissions needs the external-encoder columns"],
    );
}

#[test]
fn a_model_the_measurement_files_do_not_take_is_refused_by_its_value() {
    let urdf = ur10_urdf();
    let csv = show(&ur10_csv());
    let args = ["--device", &urdf, "--tip", "wrist_3_link", "--data", &csv];
    let err = refused_model(&args, "transmissions");
    assert!(
        err.contains("measurement files")
            && err.contains("they take auto, frames-only, joint-offsets"),
        "{err}"
    );
    // The published-mass models are models of these data, but not of this robot: refused by
    // value, not turned into compliance.
    for value in ["mass-compliance", "actuator-compliance"] {
        let mut all = vec!["calibrate", "--model", value];
        all.extend_from_slice(&args);
        let needle =
            format!("--model {value}: no published link masses for this robot's joint names");
        assert_exit(&hapcal(&all), 2, &[&needle]);
    }
}

#[test]
fn a_marker_model_on_socket_recordings_is_refused_by_its_value() {
    let iiwa = show(&root().join("fixtures/mukca/urdf/iiwa14.urdf"));
    let front = show(&root().join("fixtures/mukca/data/kuka_14/front"));
    for value in ["frames-only", "joint-offsets", "transmissions"] {
        let err = refused_model(&["--device", &iiwa, "--data", &front], value);
        assert!(
            err.contains(&format!(
                "--model {value} does not apply to socket recordings: "
            )) && err.contains("they take auto, geometric"),
            "{err}"
        );
    }
}
