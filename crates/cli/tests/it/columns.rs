//! Units per column on the command line: a copy of the bundled UR10 recording with one
//! column in another unit, reversed or shifted, calibrated with the flag that names it,
//! gives the calibration of the original; the industrial_calibration YAML in millimetres
//! with `--length-unit mm` gives that of the file in metres.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use serde_json::Value;

use super::{assert_exit, hapcal, root, scratch, show, stderr, ur10_csv, ur10_urdf};

const TIP: &str = "wrist_3_link";

/// `hapcal calibrate --json` of `device` (and `tip`, if any) on `data` with `flags`.
fn calibrate(device: &str, tip: Option<&str>, data: &Path, flags: &[&str]) -> Value {
    let data = show(data);
    let mut args = vec!["calibrate", "--device", device, "--data", &data, "--json"];
    if let Some(tip) = tip {
        args.extend(["--tip", tip]);
    }
    args.extend_from_slice(flags);
    let out = hapcal(&args);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    serde_json::from_slice(&out.stdout).expect("one JSON document")
}

/// The UR10 calibration of the bundled file, computed once for the tests of this file.
fn ur10_si() -> &'static Value {
    static SI: OnceLock<Value> = OnceLock::new();
    SI.get_or_init(|| {
        let csv = ur10_csv();
        calibrate(&ur10_urdf(), Some(TIP), &csv, &["--model", "geometric"])
    })
}

/// A copy of the UR10 file in `dir` with `column`'s cells mapped by `edit`.
fn ur10_copy(dir: &Path, column: &str, edit: impl Fn(f64) -> f64) -> PathBuf {
    let text = std::fs::read_to_string(ur10_csv()).expect("UR10 data");
    let mut lines = text.lines();
    let header = lines.next().expect("a header");
    let c = (header.split(',').position(|h| h == column)).expect("the column");
    let mut out = vec![header.to_owned()];
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let mut cells: Vec<String> = line.split(',').map(str::to_owned).collect();
        let v: f64 = cells[c].trim().parse().expect("a number");
        cells[c] = format!("{:?}", edit(v));
        out.push(cells.join(","));
    }
    let path = dir.join("calibration.csv");
    std::fs::write(&path, out.join("\n") + "\n").expect("write");
    path
}

/// The calibration of a report: the model, the identified parameters with their σ, the
/// frames, σ_m and the figures before and after, and the names of the pruned parameters (the
/// σ they would have if kept is that of an unidentifiable direction: rounding decides it).
fn calibration(report: &Value) -> Value {
    let pruned: Vec<&Value> = (report["pruned"].as_array().expect("pruned").iter())
        .map(|p| &p["name"])
        .collect();
    serde_json::json!({
        "model": report["model"],
        "parameters": report["parameters"],
        "frames": report["frames"],
        "sigma_m": report["sigma_m"],
        "placements": report["placements"],
        "pruned": pruned,
    })
}

/// `a` and `b` agree as JSON trees: numbers within 1e-9 (absolute, m or rad, and relative),
/// strings and keys equal, except the data's folder. The inputs differ by a rounding of each
/// converted reading (~1e-16 relative); the solver stops where its step falls below its
/// tolerance, so the fitted values differ by far less than 1e-9 and far less than their σ.
#[track_caller]
fn assert_same(a: &Value, b: &Value, at: &str) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let keys = |o: &serde_json::Map<String, Value>| o.keys().cloned().collect::<Vec<_>>();
            assert_eq!(keys(x), keys(y), "{at}");
            for k in keys(x) {
                assert_same(&x[&k], &y[&k], &format!("{at}.{k}"));
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                assert_same(p, q, &format!("{at}[{i}]"));
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= 1e-9 * (1.0 + x.abs().max(y.abs())),
                "{at}: {x} != {y}"
            );
        }
        (Value::String(x), Value::String(y)) if x.contains(".csv") || x.contains(".yaml") => {
            // File paths: the copy lives elsewhere; its name is the same.
            let name = |s: &str| s.rsplit('/').next().map(str::to_owned);
            assert_eq!(name(x), name(y), "{at}");
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

/// Calibrates (geometric) a copy of the UR10 file, written in the scratch folder `name` with
/// `column`'s cells mapped by `edit`, with `flags`, and asserts that it gives the calibration
/// of the original file; returns the copy's path.
fn calibrates_as_the_original(
    name: &str,
    column: &str,
    edit: impl Fn(f64) -> f64,
    flags: &[&str],
) -> PathBuf {
    let copy = ur10_copy(&scratch(name), column, edit);
    let mut flags = flags.to_vec();
    flags.extend(["--model", "geometric"]);
    let v = calibrate(&ur10_urdf(), Some(TIP), &copy, &flags);
    assert_same(&calibration(&v), &calibration(ur10_si()), "$");
    copy
}

#[test]
fn column_unit_q3_deg_calibrates_a_copy_in_degrees_as_the_original() {
    let copy = calibrates_as_the_original(
        "columns-unit",
        "elbow_joint",
        f64::to_degrees,
        &["--column-unit", "q3=deg"],
    );
    // A column the file lacks, and a malformed value: the flag and the value are named.
    let out = hapcal(&[
        "calibrate",
        "--device",
        &ur10_urdf(),
        "--tip",
        TIP,
        "--data",
        &show(&copy),
        "--column-unit",
        "q9=deg",
    ]);
    let needle = "--column-unit q9=deg: the file has no column \"q9\"; its columns are x1, y1";
    assert_exit(&out, 2, &[needle]);
    let out = hapcal(&["check", "--device", &ur10_urdf(), "--column-unit", "q3"]);
    assert_exit(&out, 2, &["'--column-unit <COLUMNS=UNIT>'", "\"q3\""]);
}

#[test]
fn column_sign_calibrates_a_reversed_encoder_as_the_original() {
    calibrates_as_the_original(
        "columns-sign",
        "wrist_2_joint",
        |v| -v,
        &["--column-sign", "wrist_2_joint"],
    );
}

#[test]
fn column_offset_calibrates_a_shifted_zero_as_the_original() {
    calibrates_as_the_original(
        "columns-offset",
        "shoulder_lift_joint",
        |v| v + 0.25,
        &["--column-offset", "q2=-0.25"],
    );
}

#[test]
fn industrial_yaml_in_millimetres_with_length_unit_mm_calibrates_as_in_metres() {
    let dir = scratch("columns-yaml");
    let fixtures = root().join("fixtures/industrial-calibration");
    let device = show(&fixtures.join("two_axis_positioner.toml"));
    let text = std::fs::read_to_string(fixtures.join("measurements.yaml")).expect("YAML");
    // Its first 40 observations (of 205: the fit takes a fifth of the time).
    let mut n_keys = 0;
    let lines: Vec<&str> = (text.lines())
        .take_while(|l| {
            n_keys += usize::from(!l.starts_with([' ', '-', '#']) && l.contains(':'));
            n_keys <= 40
        })
        .collect();
    let (si, mm): (String, String) = (lines.iter())
        .map(|l| {
            let t = l.trim_start();
            match t.split_once(": ") {
                Some((k @ ("x" | "y" | "z"), v)) => {
                    let v: f64 = v.parse().expect("a number");
                    let indent = &l[..l.len() - t.len()];
                    (format!("{l}\n"), format!("{indent}{k}: {:?}\n", v * 1e3))
                }
                _ => (format!("{l}\n"), format!("{l}\n")),
            }
        })
        .unzip();
    let si_path = dir.join("si").join("measurements.yaml");
    let mm_path = dir.join("measurements.yaml");
    std::fs::create_dir_all(dir.join("si")).expect("folder");
    std::fs::write(&si_path, si).expect("write");
    std::fs::write(&mm_path, mm).expect("write");
    let si = calibrate(&device, None, &si_path, &[]);
    let v = calibrate(&device, None, &mm_path, &["--length-unit", "mm"]);
    assert_same(&calibration(&v), &calibration(&si), "$");
}
