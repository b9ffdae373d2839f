//! Units per column (`--column-unit`, `--column-scale`, `--column-sign`, `--column-offset`,
//! `--column-coupling`) in every reader:
//! a file written in other units and read with its edits equals the SI file.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use hapcal_io::{
    AngleUnit, ColumnEdit, ColumnUnit, Error, JointSchema, LengthUnit, LogRow, MeasurementTable,
    Units, import_urdf, read_device, read_log, read_log_in, read_measurement_file,
    read_mukca_paths_for, read_mukca_paths_in, write_log,
};
use proptest::prelude::*;

use crate::{assert_contains, message, mukca, reference_device};

/// A fresh scratch folder for `name` (unique per test and process).
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-io-columns-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A file under the repository's `fixtures/`.
fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(relative)
}

/// Three revolute joints (±π) and a prismatic one (0..1 m).
struct Arm {
    names: Vec<String>,
    prismatic: Vec<bool>,
    limits: Vec<(f64, f64)>,
}

impl Arm {
    fn new() -> Self {
        Self {
            names: ["base", "shoulder", "elbow", "lift"]
                .map(str::to_owned)
                .to_vec(),
            prismatic: vec![false, false, false, true],
            limits: vec![(-PI, PI), (-PI, PI), (-PI, PI), (0.0, 1.0)],
        }
    }

    fn schema(&self) -> JointSchema<'_> {
        JointSchema {
            names: &self.names,
            prismatic: &self.prismatic,
            limits: &self.limits,
        }
    }
}

const HEADER: [&str; 9] = ["q1", "q2", "elbow", "q4", "x", "y", "z", "distance_m", "t"];

/// SI rows of [`HEADER`]: joints within their limits, positions and distances in m.
fn si_rows() -> Vec<[f64; 9]> {
    (0..6)
        .map(|i| {
            let s = i as f64;
            [
                -1.2 + 0.4 * s,
                0.9 - 0.3 * s,
                0.05 * s - 2.5,
                0.1 + 0.12 * s,
                0.31 + 0.01 * s,
                -0.27 + 0.02 * s * s,
                0.55 - 0.03 * s,
                0.8 + 0.015 * s,
                0.1 * s,
            ]
        })
        .collect()
}

/// The CSV text of `rows` with column `c` divided by `scale[c]` (the column in another unit).
fn csv(
    rows: &[[f64; 9]],
    scale: impl Fn(usize) -> f64,
    edit: impl Fn(usize, f64) -> f64,
) -> String {
    let mut text = HEADER.join(",");
    text.push('\n');
    for row in rows {
        let cells: Vec<String> = (row.iter().enumerate())
            .map(|(c, v)| format!("{:?}", edit(c, v / scale(c))))
            .collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    text
}

fn read(dir: &Path, name: &str, text: &str, units: &Units) -> Result<MeasurementTable, Error> {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    read_measurement_file(&path, &Arm::new().schema(), units)
}

/// `rows` written in SI units to `<dir>/si.csv` and read back with the default units.
fn read_si(dir: &Path, rows: &[[f64; 9]]) -> MeasurementTable {
    read(
        dir,
        "si.csv",
        &csv(rows, |_| 1.0, |_, v| v),
        &Units::default(),
    )
    .unwrap()
}

/// Every value of `a` equals `b`'s within `rel` relative (and 1e-300 absolute).
#[track_caller]
fn assert_same(a: &MeasurementTable, b: &MeasurementTable, rel: f64) {
    let close = |x: f64, y: f64| (x - y).abs() <= rel * x.abs().max(y.abs()) + 1e-300;
    assert_eq!(a.rows.len(), b.rows.len());
    for (ra, rb) in a.rows.iter().zip(&b.rows) {
        for (x, y) in ra.q.iter().zip(rb.q.iter()) {
            assert!(close(*x, *y), "line {}: q {x} != {y}", ra.line);
        }
        for (ma, mb) in ra.markers.iter().zip(&rb.markers) {
            for (x, y) in ma.position_m.iter().zip(&mb.position_m) {
                assert!(close(*x, *y), "line {}: position {x} != {y}", ra.line);
            }
        }
        match (ra.distance_m, rb.distance_m) {
            (Some(x), Some(y)) => assert!(close(x, y), "line {}: distance {x} != {y}", ra.line),
            (x, y) => assert_eq!(x, y, "line {}", ra.line),
        }
    }
}

fn unit(text: &str) -> ColumnEdit {
    ColumnEdit::parse_unit(text).unwrap()
}

/// One conversion and rounding on writing and one on reading: a few ulps.
const REL: f64 = 1e-15 * 8.0;

#[test]
fn a_column_in_another_unit_read_with_its_edit_equals_the_si_file() {
    let dir = scratch("units");
    let rows = si_rows();
    let si = read_si(&dir, &rows);
    // Column index, its unit, the edit naming it (by the header's name or a joint's alias).
    let cases = [
        (1, ColumnUnit::Angle(AngleUnit::Deg), "q2=deg"),
        (2, ColumnUnit::Angle(AngleUnit::Grad), "elbow=grad"),
        (0, ColumnUnit::Angle(AngleUnit::Rev), "base=rev"),
        (4, ColumnUnit::Length(LengthUnit::Cm), "x=cm"),
        (5, ColumnUnit::Length(LengthUnit::In), "y=in"),
        (3, ColumnUnit::Length(LengthUnit::Ft), "lift=ft"),
        (7, ColumnUnit::Length(LengthUnit::Mm), "distance_m=mm"),
    ];
    for (c, u, edit) in cases {
        let text = csv(&rows, |k| if k == c { u.to_si() } else { 1.0 }, |_, v| v);
        let plain = read(&dir, "plain.csv", &text, &Units::default());
        let units = Units::default().with_columns([unit(edit)]);
        let edited = read(&dir, "edited.csv", &text, &units).unwrap();
        assert_same(&edited, &si, REL);
        // Without the edit the file differs (or is refused): the test can fail.
        if let Ok(plain) = plain {
            assert_ne!(plain.rows, si.rows, "{edit}");
        }
    }
    // One edit naming several columns.
    let mm = |k: usize| if (4..7).contains(&k) { 1e-3 } else { 1.0 };
    let text = csv(&rows, mm, |_, v| v);
    let units = Units::default().with_columns([unit("x,y,z=mm")]);
    assert_same(&read(&dir, "xyz.csv", &text, &units).unwrap(), &si, REL);
}

#[test]
fn a_reversed_column_read_with_its_sign_and_an_offset_equal_the_original() {
    let dir = scratch("sign");
    let rows = si_rows();
    let si = read_si(&dir, &rows);
    let reversed = csv(&rows, |_| 1.0, |c, v| if c == 2 { -v } else { v });
    let units = Units::default().with_columns([ColumnEdit::parse_sign("elbow").unwrap()]);
    assert_eq!(
        read(&dir, "reversed.csv", &reversed, &units).unwrap().rows,
        si.rows,
        "a sign flip is exact"
    );
    // The joint's zero: readings 0.4 rad short of the model's angle.
    let shifted = csv(&rows, |_| 1.0, |c, v| if c == 1 { v - 0.4 } else { v });
    let units = Units::default().with_columns([ColumnEdit::parse_offset("q2=0.4").unwrap()]);
    let table = read(&dir, "offset.csv", &shifted, &units).unwrap();
    // (v − 0.4) + 0.4: two roundings of numbers below 4 in size.
    assert_same(&table, &si, 0.0 + 4.0 * f64::EPSILON * 4.0);
    // Unit, then sign, then offset: −(90° in rad) + 0.25.
    let one = "q1,q2,q3,q4,x,y,z\n-90,0,0,0.5,0.1,0.2,0.3\n";
    let units = Units::default().with_columns([
        unit("q1=deg"),
        ColumnEdit::parse_sign("q1").unwrap(),
        ColumnEdit::parse_offset("q1=0.25").unwrap(),
    ]);
    let q1 = read(&dir, "order.csv", one, &units).unwrap().rows[0].q[0];
    assert!((q1 - (PI / 2.0 + 0.25)).abs() < 1e-15, "{q1}");
}

#[test]
fn an_unknown_column_or_a_unit_of_the_wrong_kind_is_an_error_naming_the_flag() {
    let dir = scratch("errors");
    let text = csv(&si_rows(), |_| 1.0, |_, v| v);
    let err = |edit: ColumnEdit| {
        message(read(
            &dir,
            "bad.csv",
            &text,
            &Units::default().with_columns([edit]),
        ))
    };
    let e = err(unit("q7=deg"));
    assert_contains(
        &e,
        &[
            "bad.csv:1: --column-unit q7=deg: the file has no column \"q7\"; its columns are \
             q1, q2, elbow, q4, x, y, z, distance_m, t",
        ],
    );
    let e = err(unit("x=deg"));
    assert_contains(
        &e,
        &["bad.csv:1: --column-unit x=deg: deg is an angle unit but column \"x\" holds lengths"],
    );
    let e = err(unit("q2=mm"));
    assert_contains(&e, &["mm is a length unit but column \"q2\" holds angles"]);
    let e = err(unit("lift=deg"));
    assert_contains(
        &e,
        &["deg is an angle unit but column \"q4\" holds lengths"],
    );
    let e = err(ColumnEdit::parse_sign("t").unwrap());
    assert_contains(
        &e,
        &["--column-sign t: column \"t\" holds times in s: it takes no unit, sign or offset"],
    );
}

#[test]
fn the_limit_check_sees_the_edited_readings() {
    let dir = scratch("limits");
    let text = "q1,q2,q3,q4,x,y,z\n120,0.5,-0.5,0.5,0.1,0.2,0.3\n-150,0.1,0.2,0.6,0.2,0.1,0.3\n";
    let e = read(&dir, "deg.csv", text, &Units::default());
    assert!(matches!(e, Err(Error::OutsideJointRange { .. })), "{e:?}");
    let units = Units::default().with_columns([unit("q1=deg")]);
    let table = read(&dir, "deg.csv", text, &units).unwrap();
    assert!((table.rows[1].q[0] + 150.0 * PI / 180.0).abs() < 1e-15);
    assert!(table.warnings.is_empty(), "{:?}", table.warnings);
    // A reversed lift reads −0.5 m: outside 0..1 m by half the range.
    let units =
        Units::default().with_columns([ColumnEdit::parse_sign("q4").unwrap(), unit("q1=deg")]);
    let e = read(&dir, "deg.csv", text, &units);
    assert!(matches!(e, Err(Error::OutsideJointRange { .. })), "{e:?}");
}

/// The bundled industrial_calibration observations with each pose's `x, y, z` times `scale`.
fn yaml_scaled(scale: f64) -> String {
    let path = fixture("industrial-calibration/measurements.yaml");
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|l| {
            let t = l.trim_start();
            match t.split_once(": ") {
                Some((k @ ("x" | "y" | "z"), v)) => {
                    let v: f64 = v.parse().unwrap();
                    format!("{}{k}: {:?}\n", &l[..l.len() - t.len()], v * scale)
                }
                _ => format!("{l}\n"),
            }
        })
        .collect()
}

#[test]
fn industrial_yaml_reads_in_every_unit_flag() {
    let dir = scratch("yaml");
    let device = read_device(&fixture("industrial-calibration/two_axis_positioner.toml")).unwrap();
    let names: Vec<String> = device.joints.iter().map(|j| j.name.clone()).collect();
    let limits = device.joint_limits();
    let prismatic = vec![false; names.len()];
    let schema = JointSchema {
        names: &names,
        prismatic: &prismatic,
        limits: &limits,
    };
    let at = |name: &str, text: String, units: &Units| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        read_measurement_file(&path, &schema, units)
    };
    let si = at("si.yaml", yaml_scaled(1.0), &Units::default()).unwrap();
    assert!(si.rows.len() > 10);
    let mm = Units::new(LengthUnit::Mm, AngleUnit::Rad);
    let table = at("mm.yaml", yaml_scaled(1e3), &mm).unwrap();
    assert_same(&table, &si, REL);
    // Read as metres, the file in millimetres is a thousand times larger.
    let plain = at("mm.yaml", yaml_scaled(1e3), &Units::default()).unwrap();
    let ratio = plain.rows[0].markers[0].position_m[0] / si.rows[0].markers[0].position_m[0];
    assert!((ratio - 1e3).abs() < 1e-9, "{ratio}");
    // A column edit of the pose, and one naming a column the format does not have.
    let units = Units::default().with_columns([unit("x,y,z=mm")]);
    assert_same(&at("xyz.yaml", yaml_scaled(1e3), &units).unwrap(), &si, REL);
    let units = Units::default().with_columns([unit("distance_m=mm")]);
    let e = message(at("si.yaml", yaml_scaled(1.0), &units));
    assert_contains(
        &e,
        &[
            "si.yaml:1: --column-unit distance_m=mm: the file has no column \"distance_m\"; \
           its columns are x, y, z, qw, qx, qy, qz, q1, q2",
        ],
    );
}

#[test]
fn a_haptic_log_reads_its_columns_in_their_units() {
    let dir = scratch("log");
    let device = read_device(&reference_device()).unwrap();
    let si = read_log(&reference_device().with_file_name("log.csv"), &device).unwrap();
    let rows: Vec<LogRow> = (si.rows.iter().take(40).cloned())
        .map(|mut r| {
            r.q[2] = r.q[2].to_degrees();
            r.q[4] = -r.q[4];
            r.distance_m *= 1e3;
            r
        })
        .collect();
    let path = dir.join("log.csv");
    std::fs::write(&path, write_log(&rows)).unwrap();
    let units = Units::new(LengthUnit::Mm, AngleUnit::Rad)
        .with_columns([unit("q3=deg"), ColumnEdit::parse_sign("q5").unwrap()]);
    let log = read_log_in(&path, &device, &units).unwrap();
    for (a, b) in log.rows.iter().zip(&si.rows) {
        for (x, y) in
            a.q.iter()
                .chain([&a.distance_m])
                .zip(b.q.iter().chain([&b.distance_m]))
        {
            assert!(
                (x - y).abs() <= REL * y.abs(),
                "line {}: {x} != {y}",
                a.line
            );
        }
        assert_eq!(a.ext, b.ext, "the external encoders stay in rad");
    }
    // The same file read as SI is refused by the joint limits (q3 in degrees).
    assert!(read_log(&path, &device).is_err());
    let units = Units::default().with_columns([unit("q9=deg")]);
    let e = message(read_log_in(&path, &device, &units));
    assert_contains(
        &e,
        &["log.csv:1: --column-unit q9=deg: the file has no column \"q9\""],
    );
}

#[test]
fn a_scaled_or_coupled_column_read_with_its_edit_equals_the_si_file() {
    let dir = scratch("scale");
    let rows = si_rows();
    let si = read_si(&dir, &rows);
    // The elbow read on the motor side of a 100:1 gear.
    let motor = csv(&rows, |c| if c == 2 { 0.01 } else { 1.0 }, |_, v| v);
    let units = Units::default().with_columns([ColumnEdit::parse_scale("elbow=0.01").unwrap()]);
    assert_same(&read(&dir, "motor.csv", &motor, &units).unwrap(), &si, REL);
    assert!(
        read(&dir, "motor.csv", &motor, &Units::default()).is_err(),
        "past its limits"
    );
    // The elbow read as elbow + 0.5·q2 (a coupled joint), the edit adding −0.5·q2.
    let coupled = csv(&rows, |_| 1.0, |_, v| v);
    let coupled: String = (coupled.lines().enumerate())
        .map(|(i, l)| match (i, rows.get(i.wrapping_sub(1))) {
            (0, _) | (_, None) => format!("{l}\n"),
            (_, Some(r)) => {
                let mut cells: Vec<String> = l.split(',').map(str::to_owned).collect();
                cells[2] = format!("{:?}", r[2] + 0.5 * r[1]);
                format!("{}\n", cells.join(","))
            }
        })
        .collect();
    let units =
        Units::default().with_columns([ColumnEdit::parse_coupling("elbow=-0.5*q2").unwrap()]);
    let table = read(&dir, "coupled.csv", &coupled, &units).unwrap();
    // (e + 0.5·q2) − 0.5·q2: two roundings of numbers below 4 in size.
    assert_same(&table, &si, 4.0 * 4.0 * f64::EPSILON);
    let plain = read(&dir, "coupled.csv", &coupled, &Units::default()).unwrap();
    assert_ne!(plain.rows, si.rows);
    let units =
        Units::default().with_columns([ColumnEdit::parse_coupling("elbow=-0.5*q9").unwrap()]);
    let e = message(read(&dir, "coupled.csv", &coupled, &units));
    assert_contains(
        &e,
        &["coupled.csv:1: --column-coupling elbow=-0.5*q9: the file has no column \"q9\""],
    );
}

#[test]
fn mukca_sockets_name_their_columns_q1_to_qn() {
    let dir = scratch("mukca");
    let iiwa = import_urdf(&mukca("urdf/iiwa14.urdf"), "ball_link").unwrap();
    let front = mukca("data/kuka_14/front");
    let si = read_mukca_paths_for(std::slice::from_ref(&front), &iiwa).unwrap();
    let copy = dir.join("front");
    std::fs::create_dir_all(&copy).unwrap();
    for (k, socket) in si[0].sockets.iter().enumerate() {
        let text: String = (socket.q.iter())
            .map(|q| {
                let cells: Vec<String> = (q.iter().enumerate())
                    .map(|(j, v)| format!("{:?}", if j == 3 { v.to_degrees() } else { *v }))
                    .collect();
                cells.join(",") + "\n"
            })
            .collect();
        std::fs::write(copy.join(format!("hole_{k}.csv")), text).unwrap();
    }
    let units = Units::default().with_columns([unit("q4=deg")]);
    let edited = read_mukca_paths_in(std::slice::from_ref(&copy), &iiwa, &units).unwrap();
    for (a, b) in edited[0].sockets.iter().zip(&si[0].sockets) {
        for (x, y) in a.q.iter().flatten().zip(b.q.iter().flatten()) {
            assert!((x - y).abs() <= REL * y.abs(), "{x} != {y}");
        }
    }
    // Joint 4 in degrees read as rad lies far past its limits.
    assert!(read_mukca_paths_for(std::slice::from_ref(&copy), &iiwa).is_err());
    let units = Units::default().with_columns([unit("q8=deg")]);
    let e = message(read_mukca_paths_in(
        std::slice::from_ref(&copy),
        &iiwa,
        &units,
    ));
    assert_contains(
        &e,
        &[
            "hole_0.csv:1: --column-unit q8=deg: the file has no column \"q8\"; its columns are \
           q1, q2, q3, q4, q5, q6, q7",
        ],
    );
}

fn any_unit() -> impl Strategy<Value = ColumnUnit> {
    prop_oneof![
        prop::sample::select(LengthUnit::ALL.to_vec()).prop_map(ColumnUnit::Length),
        prop::sample::select(AngleUnit::ALL.to_vec()).prop_map(ColumnUnit::Angle),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A column written in any unit and read back with that unit's edit is the SI value
    /// within 1e-12 relative (angles on joint 2, lengths on the marker's x).
    #[test]
    fn writing_in_a_unit_and_reading_with_its_edit_is_the_identity(
        u in any_unit(),
        v in -3.0..3.0f64,
    ) {
        let dir = scratch("prop");
        let (column, name) = match u {
            ColumnUnit::Angle(_) => (1, "q2"),
            ColumnUnit::Length(_) => (4, "x"),
        };
        let mut rows = si_rows();
        rows[0][column] = v;
        let text = csv(&rows, |k| if k == column { u.to_si() } else { 1.0 }, |_, v| v);
        let units = Units::default().with_columns([unit(&format!("{name}={u}"))]);
        let table = read(&dir, "prop.csv", &text, &units).unwrap();
        let row = &table.rows[0];
        let got = if column == 1 { row.q[1] } else { row.markers[0].position_m[0] };
        prop_assert!((got - v).abs() <= 1e-12 * v.abs(), "{u}: {got} != {v}");
    }
}
