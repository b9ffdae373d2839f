//! The hostile sweep's generator writes the mistakes it names (a column in degrees is the
//! recording's column times 180/π, rows out of step pair row i's joints with row i + k's
//! measurements; a tracker moved from a row on moves every later pose rigidly), splits its
//! cases deterministically into two near halves, judges a command's output by its class, fix
//! and place (a fix's flags applied to the command), and screens a mistake as invisible when
//! its training residual is within 5 % of its correct twin's.

use std::collections::BTreeSet;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use hapcal_studies::setup_hostile::{
    AngleUnit, Case, CaseResult, DEFAULT_CASES_PER_FAMILY, FAMILIES, Family, FixApplied, Half,
    Invocation, Mistake, Outcome, Recording, Residual, Sources, Table, Visibility, VisibleSummary,
    cases, correct_twin, euler_xyz_of, fix_flags, judge, stop_fix, twin_key, with_fix, write_case,
};
use nalgebra::{Rotation3, Vector3};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A fresh folder for one test's files.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "hapcal-setup-hostile-{name}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn no_simulation(_: &[String]) -> anyhow::Result<()> {
    anyhow::bail!("no simulation in this test")
}

fn case(family: Family, recording: Recording, mistake: Mistake) -> Case {
    Case {
        id: "test".to_owned(),
        family,
        recording,
        mistake,
        seed: 7,
        part: 0,
        half: Half::Tuning,
    }
}

/// `c` and its correct twin ([`correct_twin`]) written into the scratch folders `name` and
/// `name-twin` (removed afterwards): `c`'s invocation, its data file and the twin's, read.
fn with_correct_twin(c: &Case, name: &str) -> (Invocation, Table, Table) {
    let sources = Sources::load(&root()).expect("fixtures");
    let (dir, twin_dir) = (scratch(name), scratch(&format!("{name}-twin")));
    let inv = write_case(c, &sources, &dir, &no_simulation).expect("written");
    let twin = write_case(&correct_twin(c), &sources, &twin_dir, &no_simulation).expect("twin");
    let data = |inv: &Invocation| {
        let i = inv.args.iter().position(|a| a == "--data").expect("--data");
        Table::read_csv(Path::new(&inv.args[i + 1]), None).expect("written file")
    };
    let (mistaken, correct) = (data(&inv), data(&twin));
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&twin_dir);
    (inv, mistaken, correct)
}

#[test]
fn one_column_in_degrees_is_the_recording_times_180_over_pi_and_the_rest_unchanged() {
    let sources = Sources::load(&root()).expect("fixtures");
    let dir = scratch("deg");
    // Column 2 of the UR10's revolute joints is elbow_joint.
    let c = case(
        Family::ColumnUnit,
        Recording::Ur10,
        Mistake::ColumnUnit {
            col: 2,
            unit: AngleUnit::Deg,
        },
    );
    let inv = write_case(&c, &sources, &dir, &no_simulation).expect("written");
    let orig = Table::read_csv(&root().join("fixtures/figaroh/ur10/calibration.csv"), None)
        .expect("fixture");
    let written = Table::read_csv(&dir.join("data.csv"), None).expect("written file");
    assert_eq!(written.header, orig.header);
    assert_eq!(written.rows.len(), 23);
    let elbow = orig.col("elbow_joint").expect("elbow column");
    for (w, o) in written.rows.iter().zip(&orig.rows) {
        for (c, (a, b)) in w.iter().zip(o).enumerate() {
            let want = if c == elbow { b * 180.0 / PI } else { *b };
            // Shortest round-trip printing: the value read back is the value computed.
            assert!(
                (a - want).abs() <= 1e-15 * want.abs(),
                "column {c}: {a} vs {want}"
            );
        }
    }
    // The fix must name the flag, the column (by name or position) and the unit.
    assert_eq!(
        inv.fix_words,
        vec![
            vec!["--column-unit".to_owned()],
            vec!["elbow_joint".to_owned(), "q3".to_owned()],
            vec!["deg".to_owned()],
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rows_out_of_step_pair_joints_of_row_i_with_measurements_of_row_i_plus_k() {
    let sources = Sources::load(&root()).expect("fixtures");
    let dir = scratch("shift");
    let c = case(Family::RowShift, Recording::Tiago, Mistake::Shift(3));
    write_case(&c, &sources, &dir, &no_simulation).expect("written");
    let orig = Table::read_csv(
        &root().join("fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv"),
        None,
    )
    .expect("fixture");
    let written = Table::read_csv(&dir.join("data.csv"), None).expect("written file");
    assert_eq!(written.rows.len(), orig.rows.len() - 3);
    let (x1, torso, arm7) = (
        orig.col("x1").expect("x1"),
        orig.col("torso_lift_joint").expect("torso"),
        orig.col("arm_7_joint").expect("arm 7"),
    );
    for (i, w) in written.rows.iter().enumerate() {
        assert_eq!(w[x1], orig.rows[i + 3][x1], "row {i}");
        assert_eq!(w[torso], orig.rows[i][torso], "row {i}");
        assert_eq!(w[arm7], orig.rows[i][arm7], "row {i}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn euler_angles_of_the_other_order_give_the_same_rotation() {
    let (roll, pitch, yaw) = (0.3, -0.7, 2.1);
    let [a, b, c] = euler_xyz_of(roll, pitch, yaw);
    let rot = |axis: Vector3<f64>, t: f64| {
        Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), t)
    };
    let figaroh = rot(Vector3::z(), yaw) * rot(Vector3::y(), pitch) * rot(Vector3::x(), roll);
    let xyz = rot(Vector3::x(), a) * rot(Vector3::y(), b) * rot(Vector3::z(), c);
    assert!((figaroh.matrix() - xyz.matrix()).norm() < 1e-12);
    // Read in figaroh's order, the same three numbers are another rotation.
    let misread = rot(Vector3::z(), c) * rot(Vector3::y(), b) * rot(Vector3::x(), a);
    assert!((figaroh.matrix() - misread.matrix()).norm() > 0.1);
}

#[test]
fn the_split_is_deterministic_and_near_half_and_every_family_has_cases() {
    let all = cases(DEFAULT_CASES_PER_FAMILY);
    assert_eq!(all, cases(DEFAULT_CASES_PER_FAMILY));
    let ids: BTreeSet<&str> = all.iter().map(|c| c.id.as_str()).collect();
    assert_eq!(ids.len(), all.len(), "identities are unique");
    for spec in FAMILIES {
        assert!(
            all.iter().any(|c| c.family == spec.family),
            "{} has cases",
            spec.name
        );
        assert!(spec.family.spec().name == spec.name);
    }
    // A fair coin per case: the tuning count within 3 σ (σ = √n / 2) of n / 2.
    let n = all.len() as f64;
    let tuning = all.iter().filter(|c| c.half == Half::Tuning).count() as f64;
    assert!(
        (tuning - n / 2.0).abs() <= 1.5 * n.sqrt(),
        "{tuning} of {n}"
    );
    assert!(n >= 200.0, "a few hundred cases: {n}");
    for c in &all {
        assert_eq!(c.half, Half::of(&c.id));
    }
}

#[test]
fn the_judge_reads_the_class_the_fix_and_the_place() {
    let fix = vec![
        vec!["--column-unit".to_owned()],
        vec!["elbow_joint".to_owned(), "q3".to_owned()],
        vec!["deg".to_owned()],
    ];
    let place = vec!["elbow_joint".to_owned(), "q3".to_owned()];
    let words = (fix.as_slice(), place.as_slice());
    let none: (&[Vec<String>], &[String]) = (&[], &[]);
    let na = FixApplied::NotApplicable;
    let stop = |line: &str| format!("reading\nhapcal: error: {line}\n");
    let f = Family::ColumnUnit;
    let right = stop(
        "setup check [column-unit]: elbow_joint looks like degrees; fix: --column-unit q3=deg",
    );
    assert_eq!(judge(f, words, Some(2), &right, na), Outcome::NamedRight);
    assert_eq!(
        judge(f, words, Some(2), &right, FixApplied::Ran),
        Outcome::NamedRight
    );
    // The right cause with a flag that, applied, stops again: harmful.
    assert_eq!(
        judge(f, words, Some(2), &right, FixApplied::StoppedAgain),
        Outcome::HarmfulFix
    );
    let vague = stop("setup check [column-unit]: a column looks like degrees; fix: --column-unit");
    assert_eq!(judge(f, words, Some(2), &vague, na), Outcome::ClassOnly);
    // q3 is not q30; elbow_joint is not elbow_joint_2.
    let other_col = stop("setup check [column-unit]: q30 in degrees; fix: --column-unit q30=deg");
    assert_eq!(judge(f, words, Some(2), &other_col, na), Outcome::ClassOnly);
    // Another cause with a flag to apply: harmful; with an edit in words: a wrong cause.
    let other = stop("setup check [angle-unit]: angles in degrees; fix: --angle-unit deg");
    assert_eq!(judge(f, words, Some(2), &other, na), Outcome::HarmfulFix);
    // Another cause with the expected fix as an alternative the data fit as well: named.
    let tied = stop(
        "setup check [column-zero]: the zero of q2 is 180° off; the data fit as well if q3 is \
         in degrees (fix: --column-unit q3=deg); fix: --column-offset q2=3.14",
    );
    assert_eq!(judge(f, words, Some(2), &tied, na), Outcome::NamedRight);
    let edit = stop("setup check [row-shift]: rows late; fix: move the joint columns up");
    assert_eq!(judge(f, words, Some(2), &edit, na), Outcome::WrongCause);
    // No cause, but the column named: located; neither: generic.
    let nothing = stop("setup check [no-hypothesis]: the residual lies in q3; fix: check q3");
    assert_eq!(judge(f, words, Some(2), &nothing, na), Outcome::Located);
    assert_eq!(
        judge(f, words, Some(2), "hapcal: error: fit failed\n", na),
        Outcome::Generic
    );
    let warning = "warning: setup check [column-unit]: maybe degrees\n";
    assert_eq!(judge(f, words, Some(0), warning, na), Outcome::Warned);
    assert_eq!(judge(f, words, Some(1), "report\n", na), Outcome::Silent);
    assert_eq!(
        judge(Family::AsIs, none, Some(0), warning, na),
        Outcome::FalseAlarm
    );
    assert_eq!(
        judge(Family::AsIs, none, Some(0), "report\n", na),
        Outcome::Clean
    );
    // Latency is a note on a run, and a stop on it is a false alarm.
    let note = "note: setup check [latency]: the distance lags the joints by 45 ms\n";
    assert_eq!(
        judge(Family::Latency, none, Some(0), note, na),
        Outcome::NamedRight
    );
    assert_eq!(
        judge(
            Family::Latency,
            none,
            Some(2),
            &stop("setup check [row-shift]: rows"),
            na
        ),
        Outcome::FalseAlarm
    );
    // A glitch row: a run that lists the row (data.csv:40 is not data.csv:400).
    let row = vec!["data.csv:40".to_owned()];
    let listed = (&[][..], row.as_slice());
    let g = Family::GlitchRow;
    let lists = "left out by the Huber loss: data.csv:40 (12 mm)\n";
    assert_eq!(judge(g, listed, Some(0), lists, na), Outcome::NamedRight);
    let other_row = "left out by the Huber loss: data.csv:400 (12 mm)\n";
    assert_eq!(judge(g, listed, Some(0), other_row, na), Outcome::Silent);
    assert_eq!(
        judge(g, listed, Some(2), &stop(lists.trim()), na),
        Outcome::Located
    );
}

#[test]
fn a_fix_is_read_as_flags_and_applied_to_the_command() {
    assert_eq!(
        fix_flags("--column-sign q3"),
        vec![("--column-sign".to_owned(), "q3".to_owned())]
    );
    assert_eq!(
        fix_flags("--tip l_link6 --tip r_hand (the markers sit one joint up)"),
        vec![
            ("--tip".to_owned(), "l_link6".to_owned()),
            ("--tip".to_owned(), "r_hand".to_owned()),
        ]
    );
    assert!(fix_flags("move the joint columns up by 1 row").is_empty());
    assert_eq!(
        fix_flags("use --tip arm_5_link"),
        vec![("--tip".to_owned(), "arm_5_link".to_owned())]
    );
    assert!(fix_flags("check --device, --tip, the units").is_empty());
    let stderr = "hapcal: error: setup check [mounting]: upside down (…); fix: --gravity +z; \
                  --accept-setup uses the calibration as it is\n";
    assert_eq!(stop_fix(stderr).as_deref(), Some("--gravity +z"));
    let tied = "hapcal: error: setup check [column-sign]: q1's sign; the data fit as well if \
                q2 is 180° off (fix: --column-offset q2=3.14); fix: --column-sign q1\n";
    assert_eq!(stop_fix(tied).as_deref(), Some("--column-sign q1"));
    let args: Vec<String> = [
        "--device", "d.urdf", "--tip", "a", "--tip", "b", "--data", "x.csv",
    ]
    .map(str::to_owned)
    .to_vec();
    // A flag of one value replaces the one given (every --tip); a column edit is added.
    let tips = with_fix(
        &args,
        &[
            ("--tip".to_owned(), "c".to_owned()),
            ("--tip".to_owned(), "b".to_owned()),
        ],
    );
    assert_eq!(
        tips.join(" "),
        "--device d.urdf --data x.csv --tip c --tip b"
    );
    let column = with_fix(&args, &[("--column-sign".to_owned(), "q3".to_owned())]);
    assert_eq!(column.len(), args.len() + 2);
    assert_eq!(column[..args.len()], args[..]);
}

#[test]
fn a_tracker_moved_from_a_row_on_moves_every_later_pose_rigidly() {
    let c = case(
        Family::ChangePoint,
        Recording::Positioner,
        Mistake::TrackerMoved {
            from_pct: 50,
            deg: 3,
            mm: 30,
        },
    );
    let (inv, moved, orig) = with_correct_twin(&c, "tracker");
    let from = orig.rows.len() / 2;
    let p = |t: &Table, r: usize| {
        let c = |n: &str| t.rows[r][t.col(n).expect("column")];
        (
            nalgebra::Vector3::new(c("x"), c("y"), c("z")),
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                c("qw"),
                c("qx"),
                c("qy"),
                c("qz"),
            )),
        )
    };
    for r in 0..from {
        assert_eq!(moved.rows[r], orig.rows[r], "row {r} before the change");
    }
    // After it: one rotation of 3° and distances between poses kept (a rigid move).
    let (a0, qa0) = p(&orig, from);
    let (b0, qb0) = p(&moved, from);
    let turn = qb0 * qa0.inverse();
    assert!(
        (turn.angle().to_degrees() - 3.0).abs() < 1e-9,
        "{}",
        turn.angle()
    );
    assert!(((b0 - turn * a0).norm() - 0.030).abs() < 1e-9);
    for r in from + 1..orig.rows.len() {
        let (a, qa) = p(&orig, r);
        let (b, qb) = p(&moved, r);
        assert!(((b - b0).norm() - (a - a0).norm()).abs() < 1e-12, "row {r}");
        assert!((qb * qa.inverse()).angle_to(&turn) < 1e-9, "row {r}");
    }
    // The change is located by the lines around the first moved row (header on line 1).
    assert!(inv.locate_words.contains(&format!("data.csv:{}", from + 2)));
}

/// A report of `hapcal calibrate --json` as the screening reads it: training sets of
/// (rows, position RMS after, orientation RMS after), and a test set that must be ignored.
fn report(train: &[(usize, f64, Option<f64>)]) -> String {
    let set = |role: &str, n: usize, p: f64, o: Option<f64>| {
        let o = o.map_or(String::new(), |o| {
            format!(r#", "orientation_rms_rad": {o}"#)
        });
        format!(
            r#"{{"name": "data.csv", "role": "{role}", "n_rows": {n},
                "before": {{"pose": {{"position_rms_m": 9.0}}}},
                "after": {{"pose": {{"position_mean_m": 0.5, "position_rms_m": {p}{o}}}}}}}"#
        )
    };
    let mut sets: Vec<String> = train
        .iter()
        .map(|&(n, p, o)| set("train", n, p, o))
        .collect();
    sets.push(set("test", 50, 1.0, Some(1.0)));
    format!(
        r#"{{"model": "frames-only", "sigma_m": 0.001, "placements": [{}]}}"#,
        sets.join(",")
    )
}

#[test]
fn a_mistake_within_5_percent_of_its_correct_twins_residual_is_invisible() {
    // Correct data: two training sets, 30 rows at 1 mm and 10 rows at 2 mm RMS, and 0.01 rad.
    let correct =
        Residual::from_report_json(&report(&[(30, 1e-3, Some(0.01)), (10, 2e-3, Some(0.01))]))
            .expect("a report");
    // Row-weighted RMS: √((30·1 + 10·4) / 40) mm; the test set's 1 m is left out.
    let p = correct.position_rms_m.expect("position");
    assert!((p - (70.0f64 / 40.0).sqrt() * 1e-3).abs() < 1e-15, "{p}");
    let o = correct.orientation_rms_rad.expect("orientation");
    assert!((o - 0.01).abs() < 1e-15, "{o}");
    let ok = |r: Residual| Ok::<_, String>(r);
    let screen = |p_factor: f64, o_factor: f64| {
        let m = Residual::from_report_json(&report(&[(40, p * p_factor, Some(0.01 * o_factor))]))
            .expect("a report");
        Visibility::screen(&ok(m), &ok(correct))
    };
    // 3 % more position error: invisible; just below and just above the threshold.
    let within = screen(1.03, 1.0);
    let Visibility::Ratio(r) = within else {
        panic!("a ratio: {within:?}")
    };
    assert!((r - 1.03).abs() < 1e-12, "{r}");
    assert!(within.is_invisible());
    assert!(screen(1.0499, 1.0).is_invisible());
    assert!(!screen(1.0501, 1.0).is_invisible());
    // A mistake in the orientations alone shows in the orientation RMS: the largest ratio.
    let turned = screen(1.0, 1.2);
    assert!(matches!(turned, Visibility::Ratio(r) if (r - 1.2).abs() < 1e-12));
    assert!(!turned.is_invisible());
    // A mistaken fit that fails is visible; a failed correct twin decides nothing.
    let failed = Visibility::screen(&Err("outside the joint limits".into()), &ok(correct));
    assert!(!failed.is_invisible());
    assert!(!Visibility::screen(&ok(correct), &Err("no fit".into())).is_invisible());
    assert!(Residual::from_report_json("not json").is_err());
    assert!(Residual::from_report_json(r#"{"placements": []}"#).is_err());

    // The summary the lead quotes counts visible mistakes only, false alarms on correct data.
    let result = |family, visibility, outcome| CaseResult {
        case: case(family, Recording::Ur10, Mistake::None),
        outcome,
        code: Some(0),
        said: String::new(),
        seconds: 0.0,
        visibility,
    };
    let results = [
        result(Family::ColumnSign, screen(2.0, 1.0), Outcome::NamedRight),
        result(Family::ColumnSign, screen(1.5, 1.0), Outcome::Silent),
        result(Family::ColumnZero, within.clone(), Outcome::Silent),
        result(Family::AsIs, Visibility::NotScreened, Outcome::Clean),
        result(Family::AsIs, Visibility::NotScreened, Outcome::FalseAlarm),
    ];
    assert_eq!(
        VisibleSummary::of(&results).line(),
        "visible mistakes 2, named 1 (50 %), located 0 (0 %), named or located 50 %, wrong cause \
         0, harmful fixes 0, silent 1 (50 %), false alarms 1 of 2"
    );
}

#[test]
fn a_correct_twin_is_the_mistaken_data_without_the_mistake() {
    // Part 1 drops a seeded fifth of the rows: the twin must drop the same ones.
    let c = Case {
        part: 1,
        ..case(Family::ColumnSign, Recording::Ur10, Mistake::Sign(1))
    };
    let twin = correct_twin(&c);
    assert_eq!(twin.mistake, Mistake::None);
    assert_eq!(twin_key(&c), twin_key(&twin));
    let (_, mistaken, correct) = with_correct_twin(&c, "sign");
    assert_eq!(mistaken.header, correct.header);
    assert_eq!(correct.rows.len(), 23 - 23 / 5);
    // Exactly one column differs, the second revolute joint's, by its sign.
    let lift = correct.col("shoulder_lift_joint").expect("column");
    for (m, c) in mistaken.rows.iter().zip(&correct.rows) {
        for (k, (a, b)) in m.iter().zip(c).enumerate() {
            let want = if k == lift { -b } else { *b };
            assert_eq!(a.to_bits(), want.to_bits(), "column {k}");
        }
    }
}
