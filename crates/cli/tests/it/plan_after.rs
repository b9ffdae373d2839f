//! `hapcal plan-poses --data … --workspace …`: the poses to add to rows already measured, on
//! figaroh's UR10 camera data (23 poses of a marker), and its refusals in words.

use super::{hapcal, next_uniform, scratch, show, stderr, ur10_csv, ur10_urdf};

fn measured() -> String {
    show(&ur10_csv())
}

/// A workspace of `n` configurations with the elbow bent one way (−3 to 0 rad), the other
/// joints within ±3 rad, by a fixed linear congruential sequence.
fn workspace(dir: &std::path::Path, n: usize) -> String {
    let state = std::cell::Cell::new(99_u64);
    let mut text = "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,\
                    wrist_2_joint,wrist_3_joint\n"
        .to_owned();
    for _ in 0..n {
        let q: Vec<String> = (0..6)
            .map(|j| {
                let u = next_uniform(&state);
                let v = if j == 2 { -3.0 * u } else { 6.0 * u - 3.0 };
                format!("{v:.4}")
            })
            .collect();
        text.push_str(&q.join(","));
        text.push('\n');
    }
    let path = dir.join("workspace.csv");
    std::fs::write(&path, text).expect("workspace written");
    show(&path)
}

/// The value (mm) on the summary line that starts with `label`.
fn mm(summary: &str, label: &str) -> f64 {
    let line = (summary.lines())
        .find(|l| l.trim_start().starts_with(label) && l.ends_with(" mm"))
        .unwrap_or_else(|| panic!("no line {label:?} in\n{summary}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    words[words.len() - 2].parse().expect("a number of mm")
}

#[test]
fn poses_added_to_measured_rows_are_written_and_lower_the_predicted_sigma() {
    let dir = scratch("plan-after");
    let ws = workspace(&dir, 100);
    let out = dir.join("poses.csv");
    let args = [
        "plan-poses",
        "--device",
        &ur10_urdf(),
        "--tip",
        "wrist_3_link",
        "--data",
        &measured(),
        "--workspace",
        &ws,
        "--model",
        "geometric",
        "--count",
        "4",
        "--candidates",
        "200",
    ];
    let run = hapcal(&[&args[..], &["--out", &show(&out)]].concat());
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
    let summary = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        summary.starts_with("planned 4 poses to add to 23 measured rows, for the geometric model"),
        "{summary}"
    );
    let (before, after) = (
        mm(&summary, "the measured rows"),
        mm(&summary, "+ the 4 planned poses"),
    );
    assert!(after < before, "{summary}");
    let csv = std::fs::read_to_string(&out).expect("poses written");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint"
    );
    assert_eq!(lines.len(), 5, "{csv}");
    // Within the candidates' box: one turn for the UR's ±2π joints, ±π for the elbow.
    for line in &lines[1..] {
        for v in line.split(',') {
            let v: f64 = v.parse().expect("a reading");
            assert!(v.abs() <= std::f64::consts::PI + 1e-9, "{line}");
        }
    }
    // Without --out: the same poses on standard output, the summary on standard error.
    let piped = hapcal(&args);
    assert_eq!(piped.status.code(), Some(0), "{}", stderr(&piped));
    assert_eq!(String::from_utf8_lossy(&piped.stdout), csv);
    assert!(
        stderr(&piped).starts_with("planned 4 poses"),
        "{}",
        stderr(&piped)
    );
}

#[test]
fn poses_added_to_measured_rows_are_refused_in_words() {
    let dir = scratch("plan-after-refused");
    let ws = workspace(&dir, 5);
    let joints_only = dir.join("joints.csv");
    std::fs::write(&joints_only, "q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n").expect("written");
    let base = [
        "plan-poses",
        "--device",
        &ur10_urdf(),
        "--tip",
        "wrist_3_link",
    ];
    let data = measured();
    let joints = show(&joints_only);
    let cases: [(Vec<&str>, &str); 5] = [
        (
            vec!["--data", &data],
            "--workspace: give the joint configurations where the calibration will be used",
        ),
        (
            vec!["--workspace", &ws],
            "--workspace goes with --data: the rows already measured",
        ),
        (
            vec![
                "--data",
                &data,
                "--workspace",
                &ws,
                "--measurement",
                "position",
            ],
            "--measurement position: with --data the poses measure what the measured rows do",
        ),
        (
            vec!["--data", &data, "--workspace", &ws, "--criterion", "o3"],
            "--criterion o3: poses added to measured rows are planned i-optimal",
        ),
        (
            vec!["--data", &joints, "--workspace", &ws],
            "joints.csv: not a measurement file",
        ),
    ];
    for (extra, words) in cases {
        let run = hapcal(&[&base[..], &extra].concat());
        assert_eq!(run.status.code(), Some(2), "{extra:?}: {}", stderr(&run));
        assert!(stderr(&run).contains(words), "{extra:?}: {}", stderr(&run));
    }
}
