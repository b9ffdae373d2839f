//! A joint column read times a gear ratio, or plus a multiple of another joint's: `hapcal
//! calibrate` stops (exit 2) naming the class and the flag that fixes it, and with that flag
//! the calibration goes on (exit 0). Tried on the UR10's camera recording (23 poses).

use super::{column, csv, on_ur10, scratch, stderr, ur10_rows};
use std::path::Path;

/// Column `a` of the data rows replaced by `f(a, b)` of the values of columns `a` and `b`.
fn edit(rows: &mut [Vec<String>], a: &str, b: &str, f: impl Fn(f64, f64) -> f64) {
    let (ca, cb) = (column(rows, a), column(rows, b));
    for r in rows.iter_mut().skip(1) {
        let (va, vb): (f64, f64) = (r[ca].parse().expect("a"), r[cb].parse().expect("b"));
        r[ca] = format!("{}", f(va, vb));
    }
}

fn calibrate(data: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["--model", "frames-only"];
    args.extend_from_slice(extra);
    on_ur10("calibrate", data, &args)
}

/// The flag and its value printed after `fix: ` in `err`, as two arguments.
fn printed_fix(err: &str, flag: &str) -> [String; 2] {
    let at = err.find(&format!("fix: {flag} ")).expect("the fix") + "fix: ".len();
    let words: Vec<&str> = err[at..].split_whitespace().take(2).collect();
    [
        words[0].to_owned(),
        words[1].trim_end_matches([';', ',']).to_owned(),
    ]
}

/// A mistaken file: its name, the class and the flag expected, the words of the finding, and
/// the edit of the column's value given the other column's.
type Mistake<'a> = (
    &'a str,
    &'a str,
    &'a str,
    &'a str,
    &'a dyn Fn(f64, f64) -> f64,
);

#[test]
fn a_scaled_or_coupled_joint_stops_the_calibration_and_its_printed_flag_fixes_it() {
    let cases: [Mistake<'_>; 2] = [
        (
            "motor-side",
            "column-scale",
            "--column-scale",
            "elbow_joint reads 100 × the joint angle",
            &|a, _| 100.0 * a,
        ),
        (
            "coupled",
            "column-coupling",
            "--column-coupling",
            "wrist_3_joint reads wrist_3_joint + 0.50·wrist_2_joint",
            &|a, b| a + 0.5 * b,
        ),
    ];
    for (name, class, flag, words, f) in cases {
        let dir = scratch(&format!("joint-scale-{name}"));
        let data = dir.join("mistaken.csv");
        let mut rows = ur10_rows();
        let (a, b) = if name == "coupled" {
            ("wrist_3_joint", "wrist_2_joint")
        } else {
            ("elbow_joint", "elbow_joint")
        };
        edit(&mut rows, a, b, f);
        std::fs::write(&data, csv(&rows)).expect("write");
        let out = calibrate(&data, &[]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(&format!("[{class}]")), "{name}: {err}");
        assert!(err.contains(words), "{name}: {err}");
        let [flag, value] = printed_fix(&err, flag);
        if name == "motor-side" {
            assert_eq!(value, "elbow_joint=0.01", "{err}");
        } else {
            assert!(value.starts_with("wrist_3_joint=-0.5"), "{err}");
            assert!(value.ends_with("*wrist_2_joint"), "{err}");
        }
        // The printed flag, applied: the check passes and the calibration runs.
        let out = calibrate(&data, &[&flag, &value]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{name}: {flag} {value}: {}",
            stderr(&out)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
