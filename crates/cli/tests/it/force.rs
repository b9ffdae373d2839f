//! `hapcal calibrate` on a haptic device's log and `hapcal force` end to end.

use super::{hapcal, root, scratch, stderr};

/// The committed calibrated reference device is exactly what `hapcal calibrate` writes from
/// the committed log (no truth file), and `hapcal force` prints the Fig. 12 table, the distributions and writes
/// the SVG.
#[test]
fn force_reports_fig12_and_distributions() {
    let dir = root().join("fixtures/reference-device");
    let out = scratch("force");
    let calibrated = out.join("calibrated.toml");
    let run = hapcal(&[
        "calibrate",
        "--device",
        &dir.join("device.toml").display().to_string(),
        "--data",
        &dir.join("log.csv").display().to_string(),
        "--out",
        &calibrated.display().to_string(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let written = std::fs::read_to_string(&calibrated).unwrap();
    let committed = std::fs::read_to_string(dir.join("calibrated.toml")).unwrap();
    assert_same_numbers(&written, &committed);

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
