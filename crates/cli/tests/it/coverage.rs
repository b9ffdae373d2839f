//! Where the calibration holds, as `hapcal calibrate` reports it: the bundled UR10 poses
//! trained on the rows reading wrist_1_joint at or above 0 rad and used (`--workspace`, and
//! tested) on the rows below. The joint offsets beat frames only on the blocked folds by 2.3
//! standard errors and make the test rows worse (4.46 → 5.53 mm RMS,
//! docs/results/extrapolation.md); the joint-range fold stops them.

use super::{on_ur10, scratch, show, stderr, ur10_csv};
use serde_json::Value;

/// The UR10 recording's rows split on wrist_1_joint at 0 rad, written to `dir`: (the rows at
/// or above, the rows below).
fn split_on_wrist_1(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let text = std::fs::read_to_string(ur10_csv()).expect("UR10 data");
    let mut lines = text.lines();
    let header = lines.next().expect("header");
    let column = (header.split(','))
        .position(|c| c == "wrist_1_joint")
        .expect("a wrist_1_joint column");
    let (mut above, mut below) = (vec![header], vec![header]);
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let q: f64 = (line.split(',').nth(column))
            .and_then(|v| v.trim().parse().ok())
            .expect("a reading");
        if q >= 0.0 {
            above.push(line);
        } else {
            below.push(line);
        }
    }
    assert_eq!((above.len() - 1, below.len() - 1), (15, 8));
    let (a, b) = (dir.join("above.csv"), dir.join("below.csv"));
    std::fs::write(&a, above.join("\n") + "\n").expect("write");
    std::fs::write(&b, below.join("\n") + "\n").expect("write");
    (a, b)
}

#[test]
fn the_report_names_the_uncovered_range_and_what_the_model_choice_did() {
    let dir = scratch("coverage");
    let (above, below) = split_on_wrist_1(&dir);
    let below = show(&below);
    let args = ["--test", below.as_str(), "--workspace", below.as_str()];
    let out = on_ur10("calibrate", &above, &args);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    for expected in [
        "where the calibration will be used (8 workspace configurations, 8 test rows)",
        "wrist_1_joint below its training range 0.302..2.500 rad: 8 of 8 workspace \
         configurations, up to 2.799 rad beyond (127 % of the range)",
        "the calibration is not validated that far",
        "the joint-range folds stopped joint-offsets (against frames-only:",
        "its advantage shrinks",
        "model: frames-only",
    ] {
        assert!(text.contains(expected), "{expected:?} in\n{text}");
    }
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let out = on_ur10("calibrate", &above, &json_args);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let coverage = &report["coverage"];
    let side = &coverage["sides"][0];
    assert_eq!(side["joint"], "wrist_1_joint", "{coverage}");
    assert_eq!(side["upper"], false, "{coverage}");
    assert_eq!(side["workspace"]["n_beyond"], 8, "{coverage}");
    // The fold grew past the 20 % of earlier joint-range folds to reach the extrapolation.
    let held = side["fold"]["held_out_share"].as_f64().expect("a share");
    assert!(held > 0.4 && held <= 0.5, "{coverage}");
    let stopped = coverage["stopped"].as_array().expect("stopped rungs");
    assert!(
        (stopped.iter())
            .any(|s| s["rung"] == "joint-offsets" && s["compared_with"] == "frames-only"),
        "{coverage}"
    );
    // The keys the report had before stay.
    assert!(
        (report["range_folds"]
            .as_array()
            .expect("range folds")
            .iter())
        .any(|f| f["joint"] == "wrist_1_joint" && f["upper"] == false && f["relevant"] == true),
        "{report}"
    );
}
