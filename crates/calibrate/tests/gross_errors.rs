//! Gross errors in socket folders and haptic logs: the Huber loss bounds them as it bounds a
//! marker file's (`measured.rs`), lists each with its file and line, and one glitch moves no
//! parameter by more than its σ.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hapcal_calibrate::calibrate::run;
use hapcal_calibrate::inputs::Plan;
use hapcal_calibrate::model::{ModelChoice, ModelName};
use hapcal_calibrate::report::CalibrationReport;
use std::path::{Path, PathBuf};

#[path = "sim/haptic_log.rs"]
mod haptic_log;
use haptic_log::{calibrate_rows, log};

/// Asserts that every parameter of `bounded` (calibrated with `what`) is named as `clean`'s and
/// lies within `clean`'s standard deviation of its value.
fn assert_within_one_std(bounded: &CalibrationReport, clean: &CalibrationReport, what: &str) {
    for (g, c) in bounded.parameters.iter().zip(&clean.parameters) {
        assert_eq!(g.name, c.name);
        assert!(
            (g.value - c.value).abs() < c.std,
            "{}: {:.6e} with {what}, {:.6e} ± {:.3e} without",
            c.name,
            g.value,
            c.value,
            c.std
        );
    }
}

/// A copy of `fixtures/mukca/data/kuka_14/front` in a fresh folder, with `edit` applied to
/// the rows of `hole_1.csv` (no header: row `k` is line `k + 1`).
fn front_copy(tag: &str, edit: impl Fn(usize, &mut Vec<f64>)) -> PathBuf {
    let source =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/mukca/data/kuka_14/front");
    let dir = std::env::temp_dir()
        .join(format!("hapcal-gross-{tag}-{}", std::process::id()))
        .join("front");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(source.join("hole_0.csv"), dir.join("hole_0.csv")).unwrap();
    let text = std::fs::read_to_string(source.join("hole_1.csv")).unwrap();
    let rows: Vec<String> = (text.lines().enumerate())
        .map(|(k, line)| {
            let mut q: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            edit(k, &mut q);
            let fields: Vec<String> = q.iter().map(|v| format!("{v:e}")).collect();
            fields.join(",")
        })
        .collect();
    std::fs::write(dir.join("hole_1.csv"), rows.join("\n") + "\n").unwrap();
    dir
}

/// `hapcal calibrate --data <folder>` with the iiwa 14 and no test placement.
fn calibrate_sockets(folder: PathBuf) -> CalibrationReport {
    let plan = Plan {
        data: vec![folder],
        test: Vec::new(),
        ..Plan::bundled_default()
    };
    run(&plan).unwrap().report
}

#[test]
fn one_glitch_row_of_a_socket_folder_is_bounded_listed_and_moves_no_parameter_by_its_sigma() {
    // The same rows, written as the glitch copy writes them (bit for bit the fixture's).
    let clean = calibrate_sockets(front_copy("clean", |_, _| {}));
    let glitch_row = 17;
    let folder = front_copy("glitch", |k, q| {
        if k == glitch_row {
            q[1] += 0.2; // joint_a2, 0.2 rad off
        }
    });
    let glitch = calibrate_sockets(folder.clone());
    assert!(
        clean.downweighted.is_empty(),
        "nothing bounded on the recording: {:?}",
        clean.downweighted
    );
    let listed: Vec<(String, u64)> = (glitch.downweighted.iter())
        .map(|d| (d.file.clone(), d.line))
        .collect();
    let file = folder.join("hole_1.csv").display().to_string();
    assert_eq!(listed, [(file, glitch_row as u64 + 1)]);
    assert!(
        glitch.warnings.iter().any(|w| w.contains("Huber")),
        "{:?}",
        glitch.warnings
    );
    // 0.2 rad on joint_a2 moves the ball by ~0.2 rad × its reach (> 50 mm): far beyond the
    // corner (4·√3 σ with σ ≈ 0.05 mm).
    assert!(glitch.downweighted[0].residual_m > 0.02);
    assert_eq!(glitch.model, clean.model);
    let names = |r: &CalibrationReport| -> Vec<String> {
        r.parameters.iter().map(|p| p.name.clone()).collect()
    };
    assert_eq!(names(&glitch), names(&clean));
    assert_within_one_std(&glitch, &clean, "the glitch");
    // Five rows in sixty-two at the corner (≈ 4 σ) at most: σ grows by less than half.
    assert!(
        glitch.sigma_m < 1.5 * clean.sigma_m,
        "σ {} m against {} m",
        glitch.sigma_m,
        clean.sigma_m
    );
    let _ = std::fs::remove_dir_all(folder.parent().unwrap());
}

/// `hapcal calibrate --model geometric` on the reference device's training log `rows`, read
/// from `train.csv`.
fn calibrate_log(rows: Vec<hapcal_io::LogRow>) -> CalibrationReport {
    calibrate_rows(ModelChoice::Model(ModelName::Geometric), rows)
}

#[test]
fn five_gross_distances_of_a_haptic_log_are_bounded_and_listed() {
    let n = 300;
    let clean_rows = log(7, n, &[]);
    let mut rows = clean_rows.clone();
    // A cable that slipped, a digit mistyped: 2 to 40 mm, thousands of times the cable
    // encoder's 10 µm.
    let gross = [
        (11, 0.04),
        (60, -0.002),
        (145, 0.015),
        (201, -0.03),
        (288, 0.005),
    ];
    for &(k, d) in &gross {
        rows[k].distance_m += d;
    }
    let clean = calibrate_log(clean_rows);
    let out = calibrate_log(rows.clone());
    assert!(clean.downweighted.is_empty(), "{:?}", clean.downweighted);
    let mut listed: Vec<u64> = out.downweighted.iter().map(|d| d.line).collect();
    listed.sort_unstable();
    let expected: Vec<u64> = gross.iter().map(|&(k, _)| rows[k].line).collect();
    assert_eq!(listed, expected, "{:?}", out.downweighted);
    assert!(out.downweighted.iter().all(|d| d.file == "train.csv"));
    // Five rows of 300 at the corner (4 σ): σ² grows by at most 5·16/300, σ by ≈ 13 %.
    let bound = (1.0 + 5.0 * 16.0 / n as f64).sqrt() + 0.05;
    assert!(
        out.sigma_m < bound * clean.sigma_m,
        "σ {:.2} µm against {:.2} µm on the clean log",
        out.sigma_m * 1e6,
        clean.sigma_m * 1e6
    );
    assert_within_one_std(&out, &clean, "the gross rows");
}
