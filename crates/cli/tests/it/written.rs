//! A calibrated device written with `calibrate --out` (TOML and URDF) reads back to the
//! figures the report printed: the written kinematics, with the instrument and marker frames
//! fitted again (`--model frames-only`), give the report's calibrated errors.

use super::{hapcal, json, root, scratch};

fn show(p: &std::path::Path) -> String {
    p.display().to_string()
}
use serde_json::Value;

/// Position mean, RMS and max (m) of each data set of a report, `when` = "before" or "after".
fn position_figures(v: &Value, when: &str) -> Vec<(String, [f64; 3])> {
    (v["placements"].as_array().expect("placements").iter())
        .map(|p| {
            let pose = &p[when]["pose"];
            let get = |k: &str| pose[k].as_f64().expect("a figure");
            (
                p["name"].as_str().unwrap_or_default().to_owned(),
                [
                    get("position_mean_m"),
                    get("position_rms_m"),
                    get("position_max_m"),
                ],
            )
        })
        .collect()
}

/// Calibrates `device` (tips `tips`) on `data` with the geometric model, writes it to each of
/// `x.toml` and `x.urdf`, and checks that the written device, with its frames fitted again,
/// reproduces the report's calibrated figures.
fn written_device_reproduces_the_report(name: &str, device: &str, tips: &[&str], data: &str) {
    let dir = scratch(name);
    let tip_args: Vec<&str> = tips.iter().flat_map(|t| ["--tip", *t]).collect();
    for ext in ["toml", "urdf"] {
        let out = dir.join(format!("calibrated.{ext}"));
        let mut args = vec!["calibrate", "--device", device];
        args.extend(&tip_args);
        let out_s = show(&out);
        args.extend([
            "--data",
            data,
            "--test-last",
            "0.3",
            "--model",
            "geometric",
            "--json",
            "--out",
            &out_s,
        ]);
        let report = json(&hapcal(&args));
        let reported = position_figures(&report, "after");
        // The written kinematics must differ from the nominal ones, or the check says nothing.
        let nominal = position_figures(&report, "before");
        assert!(
            (reported.iter().zip(&nominal)).any(|(a, b)| (a.1[1] - b.1[1]).abs() > 1e-4),
            "{name}: calibration changed nothing: {reported:?}"
        );

        let mut again = vec!["calibrate", "--device", &out_s];
        if ext == "urdf" {
            again.extend(&tip_args);
        }
        again.extend([
            "--data",
            data,
            "--test-last",
            "0.3",
            "--model",
            "frames-only",
            "--json",
        ]);
        let read_back = position_figures(&json(&hapcal(&again)), "before");
        assert_eq!(read_back.len(), reported.len());
        for ((set, want), (_, got)) in reported.iter().zip(&read_back) {
            for k in 0..3 {
                // The report prints mm to 3 decimals: equal within half its last digit.
                assert!(
                    (want[k] - got[k]).abs() < 0.5e-6,
                    "{name} {ext} {set}: figure {k} reported {} m, from the written file {} m",
                    want[k],
                    got[k]
                );
            }
        }
    }
}

#[test]
fn tiago_with_its_prismatic_torso_reads_back_to_the_reported_figures() {
    let dir = root().join("fixtures/figaroh/tiago");
    written_device_reproduces_the_report(
        "written-tiago",
        &show(&dir.join("tiago.urdf")),
        &["arm_7_link"],
        &show(&dir.join("qualysis_base_hand_calibration.csv")),
    );
}

#[test]
fn two_arm_tree_reads_back_to_the_reported_figures() {
    let dir = root().join("fixtures/sim-humanoid");
    written_device_reproduces_the_report(
        "written-humanoid",
        &show(&dir.join("humanoid.urdf")),
        &["l_hand", "r_hand"],
        &show(&dir.join("mocap.csv")),
    );
}

#[test]
fn imported_tiago_says_its_torso_is_prismatic_in_m() {
    let urdf = root().join("fixtures/figaroh/tiago/tiago.urdf");
    let out = hapcal(&["import-urdf", &show(&urdf), "--tip", "arm_7_link"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("axis = [0.0, 0.0, 1.0]\nprismatic = true\n"),
        "{text}"
    );
    assert!(
        text.contains("name = \"torso_lift_joint\"\nlower_m = 0.0\nupper_m = 0.35\n"),
        "{text}"
    );
}

/// `import-urdf` with two tips writes the tree as a device file that reads back to the URDF's
/// own figures: the same frames-only fit on the same data, from the URDF and from the file.
#[test]
fn imported_tree_reads_back_to_the_urdf_figures() {
    let dir = root().join("fixtures/sim-humanoid");
    let urdf = show(&dir.join("humanoid.urdf"));
    let data = show(&dir.join("mocap.csv"));
    let out = hapcal(&["import-urdf", &urdf, "--tip", "l_hand", "--tip", "r_hand"]);
    assert!(out.status.success(), "{}", super::stderr(&out));
    let toml = scratch("imported-tree").join("humanoid.toml");
    std::fs::write(&toml, &out.stdout).expect("scratch folder is writable");
    let common = ["--data", &data, "--model", "frames-only", "--json"];
    let mut from_urdf = vec![
        "calibrate",
        "--device",
        &urdf,
        "--tip",
        "l_hand",
        "--tip",
        "r_hand",
    ];
    from_urdf.extend(common);
    let toml_s = show(&toml);
    let mut from_toml = vec!["calibrate", "--device", &toml_s];
    from_toml.extend(common);
    let want = position_figures(&json(&hapcal(&from_urdf)), "after");
    let got = position_figures(&json(&hapcal(&from_toml)), "after");
    assert_eq!(want.len(), got.len());
    for ((set, w), (_, g)) in want.iter().zip(&got) {
        for k in 0..3 {
            // Same model, data and fit: equal within half the report's last digit (1 µm).
            assert!(
                (w[k] - g[k]).abs() < 0.5e-6,
                "{set}: figure {k}: {} vs {}",
                w[k],
                g[k]
            );
        }
    }
}

/// One hand of the two-arm tree measured: the other arm's readings are not used, and the
/// warning says they are held at zero in the gravity torques and how to use them.
#[test]
fn the_other_arms_columns_are_named_as_held_joints() {
    let dir = root().join("fixtures/sim-humanoid");
    let text = std::fs::read_to_string(dir.join("mocap.csv")).expect("the simulated recording");
    // The left hand's marker only (x1, y1, z1); the right arm's joints stay in the file.
    let left: String = (text.lines())
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            format!("{}\n", cells[..cells.len() - 3].join(","))
        })
        .collect();
    let data = scratch("held-joints").join("left.csv");
    std::fs::write(&data, left).expect("scratch folder is writable");
    let warnings = super::calibration_warnings(&[
        "--device",
        &show(&dir.join("humanoid.urdf")),
        "--tip",
        "l_hand",
        "--data",
        &show(&data),
        "--model",
        "geometric",
    ]);
    let ignored = (warnings.iter())
        .find(|w| w.starts_with("columns ignored"))
        .unwrap_or_else(|| panic!("no ignored columns: {warnings:?}"));
    assert!(ignored.contains("r_1, r_2"), "{ignored}");
    assert!(
        ignored.contains("held at zero in the gravity torques")
            && ignored.contains("as a further --tip"),
        "{ignored}"
    );
}
