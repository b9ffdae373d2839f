use hapcal_io::{Device, Error, LogRow, read_device, read_log, write_log};

use crate::{assert_contains, data, message};

fn planar() -> Device {
    read_device(&data("planar.toml")).expect("planar.toml is valid")
}

#[test]
fn good_log_reads_every_column_and_warns_about_unknown_ones() {
    let log = read_log(&data("logs/good.csv"), &planar()).unwrap();
    assert_eq!(log.rows.len(), 3);
    let first = &log.rows[0];
    assert_eq!(first.q, [0.1, -0.2]);
    assert_eq!(first.distance_m, 0.45);
    assert_eq!(first.ext, [Some(0.1001), None, None, None]);
    assert_eq!(first.t_s, Some(0.0));
    assert_eq!(first.line, 2);
    // A blank line is skipped; line numbers stay those of the file. Limits are inclusive.
    let last = &log.rows[2];
    assert_eq!(last.line, 5);
    assert_eq!(last.q, [1.5, -2.0]);
    assert_eq!(last.ext, [None, None, Some(0.51), None]);
    assert_eq!(log.warnings.len(), 1);
    assert_contains(
        &log.warnings[0],
        &["good.csv:1:7: unknown column \"temperature_c\" ignored"],
    );
}

#[test]
fn written_log_reads_back() {
    let device = planar();
    let log = read_log(&data("logs/good.csv"), &device).unwrap();
    let text = write_log(&log.rows);
    assert_eq!(
        text.lines().next(),
        Some("q1,q2,distance_m,ext1,ext3,t_s"),
        "{text}"
    );
    let dir = std::env::temp_dir().join(format!("hapcal-io-log-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("roundtrip.csv");
    std::fs::write(&path, &text).unwrap();
    let again = read_log(&path, &device).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let strip = |rows: &[LogRow]| -> Vec<LogRow> {
        rows.iter()
            .map(|r| LogRow {
                line: 0,
                ..r.clone()
            })
            .collect()
    };
    assert_eq!(strip(&again.rows), strip(&log.rows));
    assert!(again.warnings.is_empty());
}

#[test]
fn each_bad_log_names_file_line_and_column() {
    let device = planar();
    let cases = [
        ("ragged.csv", "ragged.csv:3: expected 3 fields, found 2"),
        (
            "nan.csv",
            "nan.csv:4:1: expected a finite number in \"q1\", found NaN",
        ),
        (
            "not_a_number.csv",
            "not_a_number.csv:3:2: expected a number in column \"q2\", found \"1,57\"",
        ),
        (
            "joint_count.csv",
            "joint_count.csv:1: expected 2 joints (as the device has), found 3",
        ),
        (
            "missing_column.csv",
            "missing_column.csv:1: missing column \"distance_m\"",
        ),
        (
            "outside_limits.csv",
            "outside_limits.csv:3:2: joint \"elbow\" = 2.1 rad is outside [-2, 2] rad",
        ),
        (
            "time_order.csv",
            "time_order.csv:3: t_s = 0.5 s is before the previous row's 1 s",
        ),
        (
            "duplicate_column.csv",
            "duplicate_column.csv:1:4: column \"q1\" appears twice",
        ),
        (
            "header_only.csv",
            "header_only.csv: expected at least 1 data rows, found 0",
        ),
    ];
    for (file, expected) in cases {
        let msg = message(read_log(&data(&format!("logs/{file}")), &device));
        assert_contains(&msg, &[expected]);
    }
}

#[test]
fn outside_limits_carries_the_numbers() {
    let err = read_log(&data("logs/outside_limits.csv"), &planar()).unwrap_err();
    match err {
        Error::OutsideJointLimits {
            line,
            column,
            value_rad,
            min_rad,
            max_rad,
            ..
        } => assert_eq!(
            (line, column, value_rad, min_rad, max_rad),
            (3, 2, 2.1, -2.0, 2.0)
        ),
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn missing_log_is_an_io_error() {
    let msg = message(read_log(&data("logs/no_such_log.csv"), &planar()));
    assert_contains(&msg, &["cannot read ", "no_such_log.csv: "]);
}

#[test]
fn repeated_rows_are_kept_with_one_warning() {
    let dir = std::env::temp_dir().join(format!("hapcal-io-log-repeats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("repeats.csv");
    // Line 4 repeats line 2 (the time differs), line 6 line 2 again, line 5 line 3; line 7
    // differs from line 2 only by -0 for 0 in q1 and is a repeat too.
    let text = "q1,q2,distance_m,t_s\n0.0,0.5,0.4,0\n0.1,0.5,0.4,1\n0.0,0.5,0.4,2\n0.1,0.5,0.4,3\n0.0,0.5,0.4,4\n-0.0,0.5,0.4,5\n0.0,0.5,0.41,6\n";
    std::fs::write(&path, text).unwrap();
    let log = read_log(&path, &planar()).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(log.rows.len(), 7, "repeated rows are kept");
    assert_eq!(log.warnings.len(), 1, "{:?}", log.warnings);
    assert_contains(
        &log.warnings[0],
        &[
            "repeats.csv:4: ",
            "repeat those of line 2",
            "(4 rows in all repeat an earlier row)",
            "σ",
        ],
    );
}

#[test]
fn negative_distances_and_other_separators_name_the_line_and_the_value() {
    let dir = std::env::temp_dir().join(format!("hapcal-io-log-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            "negative.csv",
            "q1,q2,distance_m\n0.0,0.5,0.4\n0.1,0.5,-0.25\n",
            vec![
                "negative.csv:3:3: distance_m = -0.25 m is negative",
                "[0, 1000] m",
            ],
        ),
        (
            "semicolons.csv",
            "q1;q2;distance_m\n0.0;0.5;0.4\n",
            vec![
                "semicolons.csv:1:1: expected comma-separated columns",
                "\"q1;q2;distance_m\"",
                "semicolons",
            ],
        ),
        (
            "tabs.csv",
            "q1\tq2\tdistance_m\n0.0\t0.5\t0.4\n",
            vec!["tabs.csv:1:1: expected comma-separated columns", "tabs"],
        ),
        (
            "row_semicolons.csv",
            "q1,q2,distance_m\n0.0,0.5,0.4\n0.1;0.5;0.4\n",
            vec![
                "row_semicolons.csv:3:1: expected comma-separated",
                "semicolons",
            ],
        ),
    ];
    for (name, text, parts) in cases {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let msg = message(read_log(&path, &planar()));
        assert_contains(&msg, &parts);
    }
    // Zero is a distance; −0 too.
    let path = dir.join("zero.csv");
    std::fs::write(
        &path,
        "q1,q2,distance_m\n0.0,0.5,0\n0.1,0.5,-0.0\n0.2,0.5,0.3\n",
    )
    .unwrap();
    assert_eq!(read_log(&path, &planar()).unwrap().rows.len(), 3);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Writes `text` to `name` in a fresh folder for `test`, reads it as a log of the planar
/// device and removes the folder.
fn read_text(test: &str, name: &str, text: &str) -> Result<hapcal_io::Log, Error> {
    let dir = std::env::temp_dir().join(format!("hapcal-io-log-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("the temporary folder can be made");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("the temporary file can be written");
    let result = read_log(&path, &planar());
    std::fs::remove_dir_all(&dir).expect("the temporary folder can be removed");
    result
}

/// The refusal of the log `text` as [`read_text`] writes and reads it, from after the file's
/// name `name` on (`:line:column: …`; the temporary folder before it varies).
fn refusal(test: &str, name: &str, text: &str) -> String {
    let msg = message(read_text(test, name, text));
    match msg.split_once(name) {
        Some((_, after)) => after.to_owned(),
        None => panic!("{msg:?} does not name {name}"),
    }
}

#[test]
fn a_header_of_200000_unknown_columns_is_read_with_a_bounded_number_of_warnings() {
    // Duplicates used to be found by comparing each column with every earlier one: 40,000
    // columns took 2 s, a million never finished.
    let n = 200_000;
    let unknown: Vec<String> = (0..n).map(|i| format!("u{i}")).collect();
    let header = format!("q1,q2,distance_m,{}\n", unknown.join(","));
    let cells = vec!["1"; n].join(",");
    let text = format!("{header}0.1,0.2,0.4,{cells}\n0.2,0.3,0.5,{cells}\n");
    let log = read_text("wide", "wide.csv", &text).unwrap();
    assert_eq!(log.rows.len(), 2);
    assert_eq!(log.rows[1].q, [0.2, 0.3]);
    assert_eq!(log.warnings.len(), 11, "{:?}", &log.warnings[..3]);
    assert_contains(
        &log.warnings[0],
        &["wide.csv:1:4: unknown column \"u0\" ignored"],
    );
    assert_contains(
        &log.warnings[10],
        &["wide.csv:1: 199990 more unknown columns ignored (200000 in all)"],
    );
    // A duplicate at the very end is found, and named at its column.
    let text = format!("{}u7\n", header.trim_end().to_owned() + ",");
    let msg = message(read_text("wide", "duplicate.csv", &text));
    assert_contains(
        &msg,
        &["duplicate.csv:1:200004: column \"u7\" appears twice"],
    );
}

#[test]
fn external_encoder_readings_are_checked_against_their_joint_limits() {
    // Shoulder limits [-1.5, 1.5] rad, range 3 rad: ext1 may lie 0.3 rad past them (the
    // output angle differs from q1 by the transmission's error).
    let header = "q1,q2,distance_m,ext1,ext2\n";
    assert_eq!(
        refusal(
            "ext",
            "typo.csv",
            &format!("{header}0.1,0.2,0.4,0.1,0.2\n0.2,0.3,0.5,1e10,0.3\n"),
        ),
        ":3:4: ext1 = 1e10 rad (the external encoder of joint \"shoulder\") is outside \
         [-1.8, 1.8] rad: the joint's limits [-1.5, 1.5] rad widened by 10% of its range"
    );
    let msg = message(read_text(
        "ext",
        "elbow.csv",
        &format!("{header}0.1,0.2,0.4,0.1,-2.5\n"),
    ));
    assert_contains(
        &msg,
        &[
            "elbow.csv:2:5: ext2 = -2.5 rad",
            "\"elbow\"",
            "[-2.4, 2.4] rad",
        ],
    );
    // Within the slack: kept as read; an ext column of a joint the planar arm lacks is only
    // checked to be a number.
    let log = read_text(
        "ext",
        "slack.csv",
        "q1,q2,distance_m,ext1,ext3\n1.5,0.2,0.4,1.79,7\n1.4,0.3,0.5,,\n",
    )
    .unwrap();
    assert_eq!(log.rows[0].ext, [Some(1.79), None, Some(7.0), None]);
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
}

#[test]
fn a_frozen_distance_is_refused_but_a_constant_joint_is_not() {
    let rows: String = (0..200)
        .map(|i| format!("{},0.5,0.512\n", f64::from(i) * 0.001))
        .collect();
    assert_eq!(
        refusal("frozen", "log.csv", &format!("q1,q2,distance_m\n{rows}")),
        ":1:3: distance_m is 0.512 m in all 200 rows: the measurement does not change \
         (a frozen or disconnected sensor?)"
    );
    // Zero in every row (a disconnected encoder), −0 counted as 0.
    let msg = message(read_text(
        "frozen",
        "zero.csv",
        "distance_m,q2,q1\n0,0.5,0.1\n-0.0,0.5,0.2\n",
    ));
    assert_contains(&msg, &["zero.csv:1:1: distance_m is 0 m in all 2 rows"]);
    // Constant joints and a single row are fine.
    let log = read_text(
        "frozen",
        "moving.csv",
        "q1,q2,distance_m\n0.1,0.5,0.4\n0.1,0.5,0.41\n",
    )
    .unwrap();
    assert_eq!(log.rows.len(), 2);
    let log = read_text("frozen", "one.csv", "q1,q2,distance_m\n0.1,0.5,0.4\n").unwrap();
    assert_eq!(log.rows.len(), 1);
}

#[test]
fn a_log_streamed_past_the_read_buffer_keeps_its_line_numbers_and_row_count() {
    // CRLF line ends, blank lines and more than the reader's 64 KiB buffer before the bad
    // cell: the line of a record is counted from the bytes as they stream past, not from a
    // copy of the file.
    let mut text = String::from("q1,q2,distance_m\r\n\r\n");
    let mut line = 2;
    for i in 0..6000 {
        if i % 1000 == 0 {
            text.push_str("\r\n");
            line += 1;
        }
        text.push_str(&format!("0.{},0.5,0.4{i}\r\n", i % 10));
        line += 1;
    }
    let good = read_text("stream-good", "long.csv", &text).unwrap();
    assert_eq!(good.rows.len(), 6000);
    assert_eq!(good.rows[5999].line, line);
    let dir = std::env::temp_dir().join(format!("hapcal-io-log-count-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("long.csv");
    std::fs::write(&path, &text).unwrap();
    let counted = hapcal_io::count_log_rows(&path);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(counted, 6000);
    text.push_str("0.1,oops,0.4\r\n");
    let e = message(read_text("stream-bad", "long.csv", &text));
    assert_contains(&e, &[&format!("long.csv:{}:2", line + 1), "oops"]);
}
