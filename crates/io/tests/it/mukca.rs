use hapcal_io::{Error, read_mukca_paths, read_mukca_placement};

use crate::{assert_contains, data, message, mukca};

/// Asserts that the placement folder `test_data/<folder>` of a three-joint arm is refused with a
/// message holding every one of `parts`.
#[track_caller]
fn refused(folder: &str, parts: &[&str]) {
    assert_contains(&message(read_mukca_placement(&data(folder), 3)), parts);
}

#[test]
fn kuka_front_has_two_sockets_of_31_rows_of_7_joints() {
    let placement = read_mukca_placement(&mukca("data/kuka_14/front"), 7).unwrap();
    assert_eq!(placement.name, "front");
    assert_eq!(placement.sockets.len(), 2);
    for (k, socket) in placement.sockets.iter().enumerate() {
        assert!(socket.file.ends_with(format!("hole_{k}.csv")));
        assert_eq!(socket.q.len(), 31);
        assert!(socket.q.iter().all(|row| row.len() == 7));
        assert_eq!(socket.line_numbers, (1..=31).collect::<Vec<u64>>());
    }
    // First cell of hole_0.csv, exactly as printed there.
    let first: f64 = "-2.115545261886588868e-01".parse().unwrap();
    assert_eq!(placement.sockets[0].q[0][0], first);
    assert_eq!(placement.sockets[1].q[30].len(), 7);
}

#[test]
fn run_folder_lists_its_placements_in_name_order() {
    let placements = read_mukca_paths(&[mukca("data/kuka_14")], 7).unwrap();
    let names: Vec<&str> = placements.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["front", "left_back", "raised_left"]);

    // A placement folder and a run folder can be mixed.
    let mixed =
        read_mukca_paths(&[mukca("data/kuka_14/left_back"), mukca("data/kuka_14")], 7).unwrap();
    let names: Vec<&str> = mixed.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["left_back", "front", "left_back", "raised_left"]);
}

#[test]
fn wrong_joint_count_names_the_first_line() {
    let msg = message(read_mukca_placement(&mukca("data/kuka_14/front"), 6));
    assert_contains(&msg, &["hole_0.csv:1:", "expected 6 joints", "found 7"]);
    refused(
        "mukca_bad/joint_count",
        &["joint_count/hole_0.csv:1: ", "found 4"],
    );
}

#[test]
fn ragged_row_names_its_line() {
    refused(
        "mukca_bad/ragged",
        &["ragged/hole_0.csv:3: expected 3 fields, found 2"],
    );
    refused(
        "mukca_bad/ragged_second",
        &["ragged_second/hole_1.csv:3: expected 3 fields, found 4"],
    );
}

#[test]
fn nan_is_not_finite() {
    let err = read_mukca_placement(&data("mukca_bad/nan"), 3).unwrap_err();
    assert!(
        matches!(
            err,
            Error::NotFinite {
                line: 2,
                column: 3,
                ..
            }
        ),
        "{err:?}"
    );
    assert_contains(
        &err.to_string(),
        &["nan/hole_0.csv:2:3: expected a finite number in \"q3\", found NaN"],
    );
}

#[test]
fn non_numeric_cell_names_line_and_column() {
    refused(
        "mukca_bad/not_a_number",
        &["hole_0.csv:3:2: expected a number in column \"q2\", found \"abc\""],
    );
}

#[test]
fn socket_files_must_be_contiguous_and_present() {
    refused("mukca_bad/gap", &["gap: hole_1.csv is missing"]);
    // hole_0_pose.csv is not a socket file.
    refused(
        "mukca_bad/no_sockets",
        &["no_sockets: no socket file hole_0.csv"],
    );
    let msg = message(read_mukca_paths(&[data("mukca_bad/no_sockets")], 3));
    assert_contains(&msg, &["no_sockets: no socket file hole_0.csv"]);
    refused(
        "mukca_bad/empty",
        &["empty/hole_0.csv: expected at least 1 data rows, found 0"],
    );
}

#[test]
fn missing_folder_is_an_io_error() {
    let err = read_mukca_placement(&mukca("data/no_such_robot"), 7).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert_contains(&err.to_string(), &["cannot read ", "no_such_robot: "]);
}

/// A copy of kuka_14/front whose `hole_0.csv` has `value` at line 2, column `column`.
fn front_with(name: &str, column: usize, value: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-io-mukca-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let front = mukca("data/kuka_14/front");
    let text = std::fs::read_to_string(front.join("hole_0.csv")).expect("fixture");
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cells: Vec<String> = lines[1].split(',').map(str::to_owned).collect();
    cells[column - 1] = value.to_owned();
    lines[1] = cells.join(",");
    std::fs::write(dir.join("hole_0.csv"), lines.join("\n") + "\n").expect("write");
    std::fs::copy(front.join("hole_1.csv"), dir.join("hole_1.csv")).expect("copy");
    dir
}

#[test]
fn readings_past_the_limits_by_the_measurement_file_rule() {
    let iiwa = hapcal_io::import_urdf(&mukca("urdf/iiwa14.urdf"), "ball_link").unwrap();
    // joint_a2's limits are ±2.0942 rad: the slack is 10 % of the range, 0.41884 rad.
    let (lo, hi) = iiwa.joint_limits()[1];
    assert_eq!((lo, hi), (-2.0942, 2.0942));
    // Within the limits: read as the unchecked reader reads it, no warning.
    let front = mukca("data/kuka_14/front");
    let checked = hapcal_io::read_mukca_placement_for(&front, &iiwa).unwrap();
    assert_eq!(
        checked.sockets,
        read_mukca_placement(&front, 7).unwrap().sockets
    );
    assert!(checked.warnings.is_empty(), "{:?}", checked.warnings);
    // Past the limit within the slack: kept, one warning naming file:line:column.
    let slight = front_with("slight", 2, "2.39");
    let p = hapcal_io::read_mukca_paths_for(std::slice::from_ref(&slight), &iiwa).unwrap();
    assert_eq!(p[0].sockets[0].q[1][1], 2.39);
    assert_eq!(p[0].warnings.len(), 1, "{:?}", p[0].warnings);
    assert_contains(
        &p[0].warnings[0],
        &[
            "hole_0.csv:2:2: joint \"joint_a2\" = 2.39 rad is outside its limits",
            "[-2.0942, 2.0942]",
        ],
    );
    // Further out: an error with file:line:column, the value and the limits.
    let far = front_with("far", 2, "2.6");
    let msg = message(hapcal_io::read_mukca_placement_for(&far, &iiwa));
    assert_contains(
        &msg,
        &["hole_0.csv:2:2: joint \"joint_a2\" = 2.6 rad is outside [-2.0942, 2.0942] rad"],
    );
    // The unchecked reader still reads it (the caller checks nothing there).
    assert!(read_mukca_placement(&far, 7).is_ok());
    for dir in [slight, far] {
        std::fs::remove_dir_all(dir).unwrap();
    }
}
