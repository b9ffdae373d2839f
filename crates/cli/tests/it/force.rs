//! `hapcal calibrate` on a haptic device's log and `hapcal force` end to end.

use std::process::Output;

use super::{assert_exit, force_args, hapcal, hapcal_ok, root, scratch, set_figure, succeeded};

/// The committed calibrated reference device is exactly what `hapcal calibrate` writes from
/// the committed log (no truth file), and `hapcal force` prints the Fig. 12 table, the distributions and writes
/// the SVG.
#[test]
fn force_reports_fig12_and_distributions() {
    let dir = root().join("fixtures/reference-device");
    let out = scratch("force");
    let calibrated = out.join("calibrated.toml");
    hapcal_ok(&[
        "calibrate",
        "--device",
        &dir.join("device.toml").display().to_string(),
        "--data",
        &dir.join("log.csv").display().to_string(),
        "--out",
        &calibrated.display().to_string(),
    ]);
    let written = std::fs::read_to_string(&calibrated).unwrap();
    let committed = std::fs::read_to_string(dir.join("calibrated.toml")).unwrap();
    assert_same_numbers(&written, &committed);

    let svg = out.join("fig12.svg");
    let run = succeeded(force(
        &calibrated.display().to_string(),
        &["--poses", "20", "--svg", &svg.display().to_string()],
    ));
    let text = String::from_utf8_lossy(&run.stdout);
    for needle in [
        "| nominal | 0 |",
        "| calibrated | 10 |",
        "20 random poses",
        "Floor: `dalpha7`",
    ] {
        assert!(text.contains(needle), "{needle:?} missing from:\n{text}");
    }
    assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
}

/// `hapcal force` on the reference device, its truth file and the calibrated device file
/// `calibrated`, with the arguments `more`.
fn force(calibrated: &str, more: &[&str]) -> Output {
    let dir = root().join("fixtures/reference-device");
    let device = dir.join("device.toml").display().to_string();
    let truth = dir.join("truth.toml").display().to_string();
    hapcal(&force_args(&device, &truth, calibrated, more))
}

/// A missing calibrated file is an error that names it.
#[test]
fn force_names_a_missing_file() {
    let run = force("no/such/calibrated.toml", &[]);
    assert_exit(&run, 2, &["no/such/calibrated.toml"]);
}

/// The two device files have the same text up to the last digits of their numbers: numbers
/// agree within 1e-6 relative (floating-point results differ in the last bits between
/// optimisation levels; a stale fixture differs in the leading digits).
fn assert_same_numbers(written: &str, committed: &str) {
    let tokens = |s: &str| -> Vec<String> {
        s.split(|c: char| c.is_whitespace() || c == ',' || c == '{' || c == '}')
            .filter(|t| !t.is_empty())
            .map(str::to_owned)
            .collect()
    };
    let (a, b) = (tokens(written), tokens(committed));
    assert_eq!(
        a.len(),
        b.len(),
        "fixtures/reference-device/calibrated.toml is stale (different layout)"
    );
    for (x, y) in a.iter().zip(&b) {
        match (x.parse::<f64>(), y.parse::<f64>()) {
            (Ok(u), Ok(v)) => assert!(
                (u - v).abs() <= 1e-6 * u.abs().max(v.abs()) + 1e-15,
                "fixtures/reference-device/calibrated.toml is stale: {u} vs {v}"
            ),
            _ => assert_eq!(x, y, "fixtures/reference-device/calibrated.toml is stale"),
        }
    }
}

/// `hapcal calibrate --model compliance` on a simulated log of the reference device whose
/// handle sags (compliances of 5e-3 rad/(N·m) on joints 2 and 3): the report names the model
/// and lists the compliances in rad/(N·m), the test log's distance RMS is near the cable
/// encoder's noise (σ_m ≈ 9.9 µm, 10.6 µm with the reading quantisation) and well below the
/// transmissions', and the device file it writes reads back (`read_device`) and loads in
/// `hapcal force` (whose runtime skips the compliances).
#[test]
fn compliance_on_a_haptic_log_is_reported_written_and_read_back() {
    let dir = root().join("fixtures/reference-device");
    let out = scratch("haptic-compliance");
    let simulate = |seed: &str, poses: &str, name: &str| {
        let log = out.join(name);
        hapcal_ok(&[
            "simulate",
            "--truth",
            &dir.join("truth.toml").display().to_string(),
            "--seed",
            seed,
            "--poses",
            poses,
            "--effect",
            "gravity_compliance:j2=5e-3,j3=5e-3",
            "--out",
            &log.display().to_string(),
        ]);
        log.display().to_string()
    };
    let (train, test) = (
        simulate("5", "300", "train.csv"),
        simulate("6", "200", "test.csv"),
    );
    let device = dir.join("device.toml").display().to_string();
    let calibrated = out.join("calibrated.toml");
    let calibrate = |model: &str, write: bool| {
        let mut args = vec![
            "calibrate",
            "--device",
            &device,
            "--data",
            &train,
            "--test",
            &test,
            "--model",
            model,
            "--json",
        ];
        let path = calibrated.display().to_string();
        if write {
            args.extend(["--out", path.as_str()]);
        }
        let run = hapcal_ok(&args);
        serde_json::from_slice::<serde_json::Value>(&run.stdout).unwrap()
    };
    let v = calibrate("compliance", true);
    assert_eq!(v["model"], "compliance");
    let parameters = v["parameters"].as_array().unwrap();
    let j2 = (parameters.iter())
        .find(|p| p["name"] == "joint_compliance.j2")
        .expect("joint_compliance.j2 reported");
    assert_eq!(j2["unit"], "rad/(N·m)");
    let held_out = set_figure(&v, "test", "distance_rms_m");
    assert!(held_out < 13e-6, "{held_out}");
    let two_steps = set_figure(&calibrate("transmissions", false), "test", "distance_rms_m");
    assert!(two_steps > 2.0 * held_out, "{two_steps} vs {held_out}");

    let written = hapcal_io::read_device(&calibrated).expect("the written file reads back");
    let values = written.calibration.expect("a [calibration]").values;
    let value = values
        .iter()
        .find(|v| v.name == "joint_compliance.j2")
        .unwrap();
    assert_eq!(value.unit, "rad/(N·m)");
    succeeded(force(
        &calibrated.display().to_string(),
        &[
            "--poses",
            "5",
            "--svg",
            &out.join("fig12.svg").display().to_string(),
        ],
    ));
}
