//! Part of a file in another length unit: the check locates the rows (file and lines) and
//! names no flag, since no flag reads part of a file; the edit it names, applied, makes the
//! check pass. Tried on the UR10's camera recording (23 poses, metres) with its last 6 rows
//! in millimetres (past the reader's ±1000 m, so the reader stops first) and in centimetres
//! (within the reader's range: the check's own hypotheses find them).

use super::{assert_exit, csv, on_ur10, scratch, stderr, ur10_rows};
use std::path::Path;

fn write_rows(path: &Path, rows: &[Vec<String>]) {
    std::fs::write(path, csv(rows)).expect("write");
}

/// `rows` (header first) with the positions `x1, y1, z1` of data rows `from..` times `factor`.
fn scale_positions(rows: &mut [Vec<String>], from: usize, factor: f64) {
    for r in rows.iter_mut().skip(1 + from) {
        for cell in r.iter_mut().take(3) {
            let v: f64 = cell.parse().expect("a number");
            *cell = format!("{}", v * factor);
        }
    }
}

fn check(data: &Path) -> std::process::Output {
    on_ur10("check", data, &[])
}

#[test]
fn the_last_rows_in_another_unit_are_located_and_their_edit_passes() {
    for (unit, factor) in [("millimetres", 1e3), ("centimetres", 1e2)] {
        let dir = scratch(&format!("part-unit-{unit}"));
        let data = dir.join("tail.csv");
        let mut rows = ur10_rows();
        // The last 6 of 23 poses: file lines 19 to 24.
        scale_positions(&mut rows, 17, factor);
        write_rows(&data, &rows);
        let located =
            format!("rows 19–24 of tail.csv look like {unit} while the rest are in metres");
        let err = assert_exit(
            &check(&data),
            2,
            &[&located, "no flag reads part of a file"],
        );
        assert!(
            !err.contains("fix: --length-unit"),
            "{unit}: a flag for part of a file: {err}"
        );
        // The edit it names (those rows' positions back in metres) makes the data pass.
        scale_positions(&mut rows, 17, 1.0 / factor);
        let fixed = dir.join("fixed.csv");
        write_rows(&fixed, &rows);
        let out = check(&fixed);
        assert_eq!(out.status.code(), Some(0), "{unit}: {}", stderr(&out));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
