//! `hapcal force` and `hapcal calibrate-reference` end to end.

use super::{hapcal, root, scratch, stderr};

/// The committed calibrated reference device is exactly what `calibrate-reference` writes from
/// the committed log, and `hapcal force` prints the Fig. 12 table, the distributions and writes
/// the SVG.
#[test]
fn force_reports_fig12_and_distributions() {
    let dir = root().join("fixtures/reference-device");
    let out = scratch("force");
    let calibrated = out.join("calibrated.toml");
    let run = hapcal(&[
        "calibrate-reference",
        "--truth",
        &dir.join("truth.toml").display().to_string(),
        "--log",
        &dir.join("log.csv").display().to_string(),
        "--out",
        &calibrated.display().to_string(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let written = std::fs::read_to_string(&calibrated).unwrap();
    let committed = std::fs::read_to_string(dir.join("calibrated.toml")).unwrap();
    assert_eq!(
        written, committed,
        "fixtures/reference-device/calibrated.toml is stale"
    );

    let svg = out.join("fig12.svg");
    let run = hapcal(&[
        "force",
        "--device",
        &dir.join("device.toml").display().to_string(),
        "--truth",
        &dir.join("truth.toml").display().to_string(),
        "--calibrated",
        &calibrated.display().to_string(),
        "--poses",
        "20",
        "--svg",
        &svg.display().to_string(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
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

/// A missing calibrated file is an error that names it.
#[test]
fn force_names_a_missing_file() {
    let dir = root().join("fixtures/reference-device");
    let run = hapcal(&[
        "force",
        "--device",
        &dir.join("device.toml").display().to_string(),
        "--truth",
        &dir.join("truth.toml").display().to_string(),
        "--calibrated",
        "no/such/calibrated.toml",
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(
        stderr(&run).contains("no/such/calibrated.toml"),
        "{}",
        stderr(&run)
    );
}
