//! The measurement-file reader: CSV columns, units, markers, orientations, joint ranges and
//! `industrial_calibration` YAML.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::f64::consts::{PI, TAU};
use std::path::PathBuf;

use hapcal_io::{
    AngleUnit, Error, JointSchema, LengthUnit, MeasurementTable, Units, read_industrial_yaml,
    read_measurement_file,
};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::{assert_contains, message};

/// Writes `text` to a fresh temporary file named `name` (unique per test and process).
fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-io-measure-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Owned parts of a [`JointSchema`].
struct Schema {
    names: Vec<String>,
    prismatic: Vec<bool>,
    limits: Vec<(f64, f64)>,
}

impl Schema {
    fn new(names: &[&str], prismatic: &[bool], limits: &[(f64, f64)]) -> Self {
        Self {
            names: names.iter().map(|s| (*s).to_owned()).collect(),
            prismatic: prismatic.to_vec(),
            limits: limits.to_vec(),
        }
    }

    /// `n` revolute joints named `names`, limits ±2π.
    fn revolute(names: &[&str]) -> Self {
        Self::new(
            names,
            &vec![false; names.len()],
            &vec![(-TAU, TAU); names.len()],
        )
    }

    fn get(&self) -> JointSchema<'_> {
        JointSchema {
            names: &self.names,
            prismatic: &self.prismatic,
            limits: &self.limits,
        }
    }
}

fn read(name: &str, text: &str, schema: &Schema, units: Units) -> Result<MeasurementTable, Error> {
    let path = temp_file(name, text);
    let result = read_measurement_file(&path, &schema.get(), &units);
    std::fs::remove_file(&path).unwrap();
    result
}

fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(relative)
}

#[track_caller]
fn assert_close(a: f64, b: f64, tol: f64) {
    assert!((a - b).abs() <= tol, "{a} != {b} (tolerance {tol})");
}

#[test]
fn joint_columns_by_name_in_any_order_with_markers_and_an_unknown_column() {
    let schema = Schema::revolute(&["a", "b", "c"]);
    let text = "c,x1,foo,y1,a,z1,x2,y2,z2,b\n\
                0.3,1,hello,2,0.1,3,4,5,6,0.2\n\
                -0.3,-1,x,-2,-0.1,-3,-4,-5,-6,-0.2\n";
    let table = read("by_name.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(table.name, "by_name");
    assert_eq!(table.ignored_columns, ["foo"]);
    assert_eq!(table.n_markers, 2);
    assert!(!table.has_orientation);
    assert!(!table.has_distance);
    assert!(table.warnings.is_empty());
    assert_eq!(table.rows.len(), 2);
    let [r0, r1] = &table.rows[..] else {
        unreachable!()
    };
    assert_eq!((r0.line, r1.line), (2, 3));
    assert_eq!(*r0.q, [0.1, 0.2, 0.3]);
    assert_eq!(*r1.q, [-0.1, -0.2, -0.3]);
    assert_eq!(r0.markers.len(), 2);
    assert_eq!(r0.markers[0].marker, 0);
    assert_eq!(r0.markers[0].position_m, [1.0, 2.0, 3.0]);
    assert_eq!(r0.markers[0].rotation, None);
    assert_eq!(r0.markers[1].marker, 1);
    assert_eq!(r0.markers[1].position_m, [4.0, 5.0, 6.0]);
    assert_eq!(r1.markers[1].position_m, [-4.0, -5.0, -6.0]);
    assert_eq!(r0.t_s, None);
    assert_eq!(r0.distance_m, None);
}

#[test]
fn q_numbered_columns_and_units_scale_lengths_and_angles() {
    // Joint 1 prismatic (m), joint 2 revolute (rad).
    let schema = Schema::new(&["slide", "turn"], &[true, false], &[(0.0, 1.0), (-PI, PI)]);
    let mm = Units::new(LengthUnit::Mm, AngleUnit::Rad).with_joint_length(LengthUnit::Mm);
    let table = read("mm.csv", "q2,q1,x,y,z\n0.5,500,100,-200,300\n", &schema, mm).unwrap();
    let row = &table.rows[0];
    assert_close(row.q[0], 0.5, 1e-15);
    assert_eq!(row.q[1], 0.5, "a revolute joint is not a length");
    // Millimetres of the instrument leave the robot's prismatic readings in their own unit.
    let instrument_mm = Units::new(LengthUnit::Mm, AngleUnit::Rad);
    let table = read(
        "mm2.csv",
        "q2,q1,x,y,z\n0.5,0.24,100,-200,300\n",
        &schema,
        instrument_mm,
    )
    .unwrap();
    assert_eq!(
        table.rows[0].q[0], 0.24,
        "a torso lift read in m stays in m"
    );
    assert_eq!(table.rows[0].markers[0].position_m, [0.1, -0.2, 0.3]);
    let p = row.markers[0].position_m;
    assert_close(p[0], 0.1, 1e-15);
    assert_close(p[1], -0.2, 1e-15);
    assert_close(p[2], 0.3, 1e-15);

    let deg = Units {
        angle: AngleUnit::Deg,
        ..Units::default()
    };
    let table = read("deg.csv", "q1,q2,x,y,z\n0.5,90,1,2,3\n", &schema, deg).unwrap();
    let row = &table.rows[0];
    assert_eq!(row.q[0], 0.5, "a prismatic joint is not an angle");
    assert_close(row.q[1], PI / 2.0, 1e-15);
    assert_eq!(row.markers[0].position_m, [1.0, 2.0, 3.0]);
}

#[test]
fn columns_matching_no_joint_name_the_expected_and_found_columns() {
    let schema = Schema::revolute(&["shoulder", "elbow"]);
    let e = read(
        "nojoints.csv",
        "j1,j2,x,y,z\n0,0,1,2,3\n",
        &schema,
        Units::default(),
    );
    assert!(matches!(e, Err(Error::JointColumns { .. })), "{e:?}");
    let text = message(e);
    assert_contains(
        &text,
        &["nojoints.csv:1:", "shoulder, elbow", "j1, j2, x, y, z"],
    );
}

#[test]
fn incomplete_markers_in_header_and_rows() {
    let schema = Schema::revolute(&["a"]);
    // Header without z.
    let e = read("noz.csv", "a,x,y\n0,1,2\n", &schema, Units::default());
    match &e {
        Err(Error::IncompleteMarker { name, .. }) => assert_eq!(name, "z"),
        other => panic!("expected IncompleteMarker, got {other:?}"),
    }
    assert_contains(
        &message(e),
        &["noz.csv:1:", "\"z\"", "missing from the header"],
    );

    // y1 empty while x1, z1 are given: line 3, field 3.
    let text = "a,x1,y1,z1\n0,1,2,3\n0,1,,3\n";
    let e = read("noy.csv", text, &schema, Units::default());
    match &e {
        Err(Error::IncompleteMarker {
            line, column, name, ..
        }) => assert_eq!((*line, *column, name.as_str()), (3, 3, "y1")),
        other => panic!("expected IncompleteMarker, got {other:?}"),
    }
    assert_contains(&message(e), &["noy.csv:3:3:"]);

    // All cells of marker 2 empty: unseen, no error.
    let text = "a,x1,y1,z1,x2,y2,z2\n0,1,2,3,,,\n0.1,,,,4,5,6\n";
    let table = read("unseen.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(table.n_markers, 2);
    let seen =
        |r: usize| -> Vec<usize> { table.rows[r].markers.iter().map(|m| m.marker).collect() };
    assert_eq!(seen(0), [0]);
    assert_eq!(seen(1), [1]);
    assert_eq!(table.rows[1].markers[0].position_m, [4.0, 5.0, 6.0]);
}

#[test]
fn figaroh_rpy_is_rz_ry_rx_and_quaternions_must_be_unit() {
    let schema = Schema::revolute(&["a"]);
    let (roll, pitch, yaw) = (0.1, -0.2, 0.3);
    let text = format!("a,x,y,z,phix,phiy,phiz\n0,1,2,3,{roll},{pitch},{yaw}\n");
    let table = read("rpy.csv", &text, &schema, Units::default()).unwrap();
    assert!(table.has_orientation);
    let got = table.rows[0].markers[0].rotation.expect("a rotation");
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), pitch)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), roll);
    let e = UnitQuaternion::from_rotation_matrix(&r);
    let expected = [e.w, e.i, e.j, e.k];
    let sign = if got[0] * expected[0] < 0.0 {
        -1.0
    } else {
        1.0
    };
    for (g, x) in got.iter().zip(expected) {
        assert_close(*g, sign * x, 1e-12);
    }

    // Degrees apply to phix..phiz too.
    let text = format!(
        "a,x,y,z,phix,phiy,phiz\n0,1,2,3,{},{},{}\n",
        roll.to_degrees(),
        pitch.to_degrees(),
        yaw.to_degrees()
    );
    let deg = Units::new(LengthUnit::M, AngleUnit::Deg);
    let table = read("rpy_deg.csv", &text, &schema, deg).unwrap();
    let got = table.rows[0].markers[0].rotation.expect("a rotation");
    for (g, x) in got.iter().zip(expected) {
        assert_close(*g, sign * x, 1e-12);
    }

    // A quaternion of norm 1.5.
    let text = "a,x,y,z,qw,qx,qy,qz\n0,1,2,3,1.5,0,0,0\n";
    let e = read("badquat.csv", text, &schema, Units::default());
    assert!(matches!(e, Err(Error::Csv { line: 2, .. })), "{e:?}");
    assert_contains(&message(e), &["badquat.csv:2:", "unit quaternion", "1.5"]);

    // A unit quaternion is accepted as is.
    let text = "a,x,y,z,qw,qx,qy,qz\n0,1,2,3,0,0,0.6,0.8\n";
    let table = read("goodquat.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(
        table.rows[0].markers[0].rotation,
        Some([0.0, 0.0, 0.6, 0.8])
    );
}

#[test]
fn readings_slightly_outside_the_limits_warn_and_far_outside_fail() {
    // Range 2, slack 0.2.
    let schema = Schema::new(&["a", "b"], &[false, false], &[(-1.0, 1.0), (-1.0, 1.0)]);
    let text = "a,b\n0,0\n1.1,0.5\n";
    let table = read("slack.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(table.rows.len(), 2);
    assert_eq!(*table.rows[1].q, [1.1, 0.5]);
    assert_eq!(table.warnings.len(), 1, "{:?}", table.warnings);
    assert_contains(&table.warnings[0], &["slack.csv:3:1:", "\"a\"", "1.1"]);

    let text = "a,b\n0,0\n0,-1.5\n";
    let e = read("far.csv", text, &schema, Units::default());
    match &e {
        Err(Error::OutsideJointRange {
            line,
            column,
            joint,
            ..
        }) => assert_eq!((*line, *column, joint.as_str()), (3, 2, "b")),
        other => panic!("expected OutsideJointRange, got {other:?}"),
    }
    assert_contains(&message(e), &["far.csv:3:2:"]);
}

const YAML: &str = "'1593701755':
  camera_joints: []
  pose:
    qw: 1.0
    qx: 0.0
    qy: 0.0
    qz: 0.0
    x: 0.1
    y: 0.2
    z: 0.3
  target_joints:
  - 0.5
  - 0.25
'1593701700':
  camera_joints: []
  pose:
    qw: 0.0
    qx: 0.0
    qy: 0.6
    qz: 0.8
    x: -1.0
    y: -2.0
    z: -3.0
  target_joints:
  - -0.5
  - 1.5
";

#[test]
fn industrial_yaml_observations_in_file_order() {
    let schema = Schema::revolute(&["j1", "j2"]);
    let path = temp_file("observations.yaml", YAML);
    let table = read_industrial_yaml(&path, &schema.get()).unwrap();
    let via_ext = read_measurement_file(&path, &schema.get(), &Units::default()).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(table, via_ext);
    assert_eq!(table.n_markers, 1);
    assert!(table.has_orientation);
    assert_eq!(table.rows.len(), 2);
    let [r0, r1] = &table.rows[..] else {
        unreachable!()
    };
    assert_eq!((r0.line, r1.line), (1, 14));
    assert_eq!(*r0.q, [0.5, 0.25]);
    assert_eq!(*r1.q, [-0.5, 1.5]);
    assert_eq!(r0.markers[0].position_m, [0.1, 0.2, 0.3]);
    assert_eq!(r1.markers[0].position_m, [-1.0, -2.0, -3.0]);
    let close = |got: [f64; 4], want: [f64; 4]| {
        for (g, w) in got.iter().zip(want) {
            assert_close(*g, w, 1e-12);
        }
    };
    close(r0.markers[0].rotation.unwrap(), [1.0, 0.0, 0.0, 0.0]);
    close(r1.markers[0].rotation.unwrap(), [0.0, 0.0, 0.6, 0.8]);

    let moving = YAML.replacen("camera_joints: []", "camera_joints: [1.0]", 1);
    let path = temp_file("moving.yaml", &moving);
    let e = read_industrial_yaml(&path, &schema.get());
    std::fs::remove_file(&path).unwrap();
    assert_contains(&message(e), &["moving.yaml:1:", "camera_joints"]);
}

#[test]
fn bundled_industrial_calibration_fixture() {
    let schema = Schema::revolute(&["j1", "j2"]);
    let path = fixture("industrial-calibration/measurements.yaml");
    let table = read_measurement_file(&path, &schema.get(), &Units::default()).unwrap();
    assert_eq!(table.rows.len(), 205);
    let first = &table.rows[0];
    assert_eq!(first.line, 1);
    assert_eq!(*first.q, [-0.5229825973510742, 0.0002200359886046499]);
    assert_eq!(
        first.markers[0].position_m,
        [-0.5325496958762886, -0.7712137113402057, 0.935626211340206]
    );
}

#[test]
fn bundled_figaroh_ur10_fixture() {
    let schema = Schema::revolute(&[
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ]);
    let path = fixture("figaroh/ur10/calibration.csv");
    let table = read_measurement_file(&path, &schema.get(), &Units::default()).unwrap();
    assert_eq!(table.rows.len(), 23);
    assert_eq!(table.n_markers, 1);
    assert!(
        table.ignored_columns.is_empty(),
        "{:?}",
        table.ignored_columns
    );
    for row in &table.rows {
        assert_eq!(row.q.len(), 6);
        assert_eq!(row.markers.len(), 1, "line {}", row.line);
        assert!(row.markers[0].rotation.is_some(), "line {}", row.line);
    }
    assert_eq!(table.rows[0].q[0], 1.589200496673584);
    assert_eq!(
        table.rows[0].markers[0].position_m,
        [0.9088284523365023, 0.34156959335807885, 1.2526995668918641]
    );
}

#[test]
fn repeated_rows_are_kept_with_one_warning() {
    let schema = Schema::revolute(&["a", "b"]);
    // Line 4 repeats line 2 (the time differs); line 5 differs in a marker coordinate.
    let text =
        "a,b,x,y,z,t\n0.1,0.2,1,2,3,0\n0.3,0.2,1,2,3,1\n0.1,0.2,1,2,3,2\n0.1,0.2,1,2,3.5,3\n";
    let table = read("repeats.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(table.rows.len(), 4, "repeated rows are kept");
    assert_eq!(table.warnings.len(), 1, "{:?}", table.warnings);
    assert_contains(
        &table.warnings[0],
        &["repeats.csv:4: ", "repeat those of line 2; "],
    );
    // A marker not seen in one row and seen in another is no repeat.
    let text = "a,b,x,y,z\n0.1,0.2,1,2,3\n0.1,0.2,,,\n";
    let table = read("seen.csv", text, &schema, Units::default()).unwrap();
    assert!(table.warnings.is_empty(), "{:?}", table.warnings);
}

#[test]
fn identical_marker_columns_are_reported() {
    // figaroh's TIAGo recording has markers 3 and 4 as identical columns.
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv");
    let names: Vec<String> = [
        "torso_lift_joint",
        "arm_1_joint",
        "arm_2_joint",
        "arm_3_joint",
        "arm_4_joint",
        "arm_5_joint",
        "arm_6_joint",
        "arm_7_joint",
    ]
    .map(String::from)
    .to_vec();
    let mut prismatic = vec![false; 8];
    prismatic[0] = true;
    let limits = vec![(-10.0, 10.0); 8];
    let schema = hapcal_io::JointSchema {
        names: &names,
        prismatic: &prismatic,
        limits: &limits,
    };
    let table =
        hapcal_io::read_measurement_file(&path, &schema, &hapcal_io::Units::default()).unwrap();
    let identical: Vec<&String> = (table.warnings.iter())
        .filter(|w| w.contains("same position"))
        .collect();
    assert_eq!(identical.len(), 1, "{:?}", table.warnings);
    assert!(identical[0].contains("markers 3 and 4"), "{}", identical[0]);
}

#[test]
fn yaml_nested_past_the_limit_is_refused_at_its_line_and_column() {
    let schema = Schema::revolute(&["j1", "j2"]);
    // Flow nesting 10⁵ deep: refused by one linear scan before parsing.
    let deep = read_industrial_yaml(
        &temp_file("deep_flow.yaml", &format!("a: {}", "[".repeat(100_000))),
        &schema.get(),
    );
    assert_contains(
        &message(deep),
        &["deep_flow.yaml:1:", "deeper than 32 levels"],
    );
    // Block nesting: 40 nested mappings, the 33rd level at line 33.
    let block: String = (0..40)
        .map(|i| format!("{}k{i}:\n", "  ".repeat(i)))
        .collect();
    let msg = message(read_industrial_yaml(
        &temp_file("deep_block.yaml", &block),
        &schema.get(),
    ));
    assert_contains(&msg, &["deep_block.yaml:33:65: ", "deeper than 32 levels"]);
    // Compact sequences count one level per marker.
    let msg = message(read_industrial_yaml(
        &temp_file("deep_dash.yaml", &format!("a:\n  {}x\n", "- ".repeat(40))),
        &schema.get(),
    ));
    assert_contains(&msg, &["deep_dash.yaml:2:", "deeper than 32 levels"]);
    // 30 levels pass the depth check and fail as what they are: not observations.
    let msg = message(read_industrial_yaml(
        &temp_file(
            "shallow.yaml",
            &format!("a: {}{}\n", "[".repeat(29), "]".repeat(29)),
        ),
        &schema.get(),
    ));
    assert!(!msg.contains("deeper"), "{msg}");
    assert_contains(&msg, &["shallow.yaml:"]);
    // Brackets inside quotes and comments do not count.
    let quoted = format!("# {}\n'k': \"{}\"\n", "[".repeat(50), "{".repeat(50));
    let msg = message(read_industrial_yaml(
        &temp_file("quoted.yaml", &quoted),
        &schema.get(),
    ));
    assert!(!msg.contains("deeper"), "{msg}");
}

#[test]
fn a_header_of_200000_ignored_columns_and_20000_markers_is_read() {
    // Duplicates used to be found by comparing each column with every earlier one, and
    // identical markers by comparing every pair of markers: quadratic in the header's width.
    let schema = Schema::revolute(&["a", "b"]);
    let n = 200_000;
    let ignored: Vec<String> = (0..n).map(|i| format!("u{i}")).collect();
    let cells = vec!["1"; n].join(",");
    let text = format!(
        "a,b,x,y,z,{}\n0.1,0.2,1,2,3,{cells}\n0.2,0.3,1,2,4,{cells}\n",
        ignored.join(",")
    );
    let table = read("wide.csv", &text, &schema, Units::default()).unwrap();
    assert_eq!(table.rows.len(), 2);
    assert_eq!(table.ignored_columns.len(), n);
    assert_eq!(table.ignored_columns[n - 1], format!("u{}", n - 1));
    // The same header with its first ignored column again at the end.
    let text = format!("a,b,x,y,z,{},u0\n", ignored.join(","));
    let msg = message(read("wide_duplicate.csv", &text, &schema, Units::default()));
    assert_contains(
        &msg,
        &["wide_duplicate.csv:1:200006: column \"u0\" appears twice"],
    );

    let m = 20_000;
    let header: Vec<String> = (1..=m)
        .flat_map(|k| [format!("x{k}"), format!("y{k}"), format!("z{k}")])
        .collect();
    let row = |shift: usize| -> String {
        (0..3 * m)
            .map(|c| format!("{}.{:02}", (c + shift) / 100, (c + shift) % 100))
            .collect::<Vec<_>>()
            .join(",")
    };
    let text = format!(
        "a,b,{}\n0.1,0.2,{}\n0.2,0.3,{}\n",
        header.join(","),
        row(0),
        row(7)
    );
    let table = read("markers.csv", &text, &schema, Units::default()).unwrap();
    assert_eq!(table.n_markers, m);
    // Cells 60004..60006 of the second row (shifted by 7) are 600.04 m to 600.06 m.
    assert_eq!(
        table.rows[1].markers[m - 1].position_m,
        [600.04, 600.05, 600.06]
    );
    assert!(table.warnings.is_empty(), "{:?}", table.warnings);
}

#[test]
fn copied_marker_column_sets_are_reported_once_per_set() {
    let schema = Schema::revolute(&["a", "b"]);
    // Markers 1, 2 and 4 are one column set copied three times; marker 3 differs.
    let text = "a,b,x1,y1,z1,x2,y2,z2,x3,y3,z3,x4,y4,z4\n\
                0.1,0.2,1,2,3,1,2,3,1,2,3,1,2,3\n\
                0.2,0.3,1,2,4,1,2,4,1,2,5,1,2,4\n";
    let table = read("copies.csv", text, &schema, Units::default()).unwrap();
    assert_eq!(table.warnings.len(), 1, "{:?}", table.warnings);
    assert_contains(
        &table.warnings[0],
        &[
            "copies.csv: markers 1, 2 and 4 have the same position in all 2 rows",
            "counted 3 times",
        ],
    );
}

#[test]
fn a_frozen_position_or_distance_is_refused_but_a_constant_joint_is_not() {
    let schema = Schema::revolute(&["a", "b"]);
    let msg = message(read(
        "frozen.csv",
        "a,b,x,y,z\n0.1,0.2,0.5,0.25,1.5e5\n0.3,0.4,0.5,0.25,1.5e5\n0.5,0.6,0.5,0.25,1.5e5\n",
        &schema,
        Units::new(LengthUnit::Mm, AngleUnit::Rad),
    ));
    assert_eq!(
        msg.split_once("frozen.csv").unwrap().1,
        ":1:3: x, y, z is (0.0005, 0.00025, 150) m in all 3 rows where the marker is seen: \
         the measurement does not change (a frozen or disconnected sensor?)"
    );
    // The second marker frozen, seen in two rows; the first moves.
    let msg = message(read(
        "frozen2.csv",
        "a,b,x1,y1,z1,x2,y2,z2\n0.1,0.2,1,2,3,4,5,6\n0.1,0.2,1,2,3.5,,,\n0.1,0.2,1,2,4,4,5,6\n",
        &schema,
        Units::default(),
    ));
    assert_contains(
        &msg,
        &["frozen2.csv:1:6: x2, y2, z2 is (4, 5, 6) m in all 2 rows where the marker is seen"],
    );
    let msg = message(read(
        "distance.csv",
        "a,b,distance\n0.1,0.2,0.75\n0.3,0.4,0.75\n",
        &schema,
        Units::default(),
    ));
    assert_contains(
        &msg,
        &["distance.csv:1:3: distance is 0.75 m in all 2 rows: the measurement does not change"],
    );
    // Constant joints, a marker seen once and a distance given once are fine.
    let table = read(
        "moving.csv",
        "a,b,x,y,z,d\n0.1,0.2,1,2,3,0.5\n0.1,0.2,1,2,3.5,\n0.1,0.2,,,,0.6\n",
        &schema,
        Units::default(),
    )
    .unwrap();
    assert_eq!(table.rows.len(), 3);
}

#[test]
fn frozen_industrial_yaml_poses_are_refused() {
    let schema = Schema::revolute(&["j1", "j2"]);
    let frozen = YAML
        .replace("x: -1.0", "x: 0.1")
        .replace("y: -2.0", "y: 0.2")
        .replace("z: -3.0", "z: 0.3");
    let path = temp_file("frozen.yaml", &frozen);
    let e = read_industrial_yaml(&path, &schema.get());
    std::fs::remove_file(&path).unwrap();
    assert_eq!(
        message(e).split_once("frozen.yaml").unwrap().1,
        ":1:1: pose x, y, z is (0.1, 0.2, 0.3) m in all 2 observations: the measurement does \
         not change (a frozen or disconnected sensor?)"
    );
}

#[test]
fn every_stride_th_row_is_kept_and_every_row_is_checked() {
    let schema = Schema::revolute(&["a", "b"]);
    // Ten rows; markers 1 and 2 are one column set copied; row 8 (line 9) repeats row 1.
    let mut text = String::from("a,b,x1,y1,z1,x2,y2,z2\n");
    for i in 0..10 {
        let k = if i == 7 { 0 } else { i };
        let (q, p) = (0.1 * f64::from(k), f64::from(k));
        text.push_str(&format!("{q},{q},{p},1,2,{p},1,2\n"));
    }
    let path = temp_file("every.csv", &text);
    let units = Units::default();
    let whole = read_measurement_file(&path, &schema.get(), &units).unwrap();
    let (sampled, n_rows) = MeasurementTable::read_every(&path, &schema.get(), &units, 3).unwrap();
    assert_eq!(n_rows, 10);
    let lines: Vec<u64> = sampled.rows.iter().map(|r| r.line).collect();
    assert_eq!(lines, [2, 5, 8, 11]);
    for row in &sampled.rows {
        let same = whole.rows.iter().find(|r| r.line == row.line).unwrap();
        assert_eq!(row, same);
    }
    // The checks over all rows see every row: the repeat and the copied markers.
    assert_eq!(whole.warnings.len(), 2, "{:?}", whole.warnings);
    assert_eq!(sampled.warnings, whole.warnings);
    assert_contains(&sampled.warnings[1], &["same position in all 10 rows"]);
    // A row the sample leaves out is still checked, its line named.
    let bad = text.replace("0.5,0.5,5,1,2,5,1,2", "0.5,x,5,1,2,5,1,2");
    let path = temp_file("every-bad.csv", &bad);
    let err = message(MeasurementTable::read_every(
        &path,
        &schema.get(),
        &units,
        3,
    ));
    assert_contains(&err, &["every-bad.csv", "7"]);
}
