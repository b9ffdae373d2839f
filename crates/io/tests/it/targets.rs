//! The targets reader: rows with their lines, and errors naming file, line, column and what
//! was expected.

use std::path::{Path, PathBuf};

use hapcal_io::{JointSchema, TargetRow, read_targets};

use crate::message;

/// `text` written to a file named `name` in a folder of this test run's own.
fn file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-io-targets-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write");
    path
}

/// The targets in `path` for two joints: a revolute one within ±2 rad, a prismatic one within
/// 0..0.5 m.
fn read(path: &Path) -> Result<Vec<TargetRow>, hapcal_io::Error> {
    let names = ["shoulder".to_owned(), "slide".to_owned()];
    let schema = JointSchema {
        names: &names,
        prismatic: &[false, true],
        limits: &[(-2.0, 2.0), (0.0, 0.5)],
    };
    read_targets(path, &schema)
}

#[test]
fn targets_keep_their_lines_past_comments_and_blank_lines() {
    let text = "# targets of the test\n\nx, y, z, qw, qx, qy, qz, slide, shoulder\n\
                0.1,0.2,0.3,1,0,0,0,0.25,-1.5\n  # a note\n   \n\
                -0.1,0.0,0.5,0.0,0.0,0.6,0.8,0.0,0.5\n";
    let path = file("good.csv", text);
    let rows = read(&path).expect("valid targets");
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].line, 4);
    assert_eq!(rows[1].line, 7);
    assert_eq!(rows[0].position_m, [0.1, 0.2, 0.3]);
    assert_eq!(rows[1].orientation_wxyz, Some([0.0, 0.0, 0.6, 0.8]));
    // The start commands in the schema's joint order, whatever the columns' order.
    assert_eq!(rows[0].start, Some(vec![-1.5, 0.25]));
    assert_eq!(rows[1].start, Some(vec![0.5, 0.0]));

    let positions = file("positions.csv", "x,y,z\n1,2,3\n");
    let rows = read(&positions).expect("valid targets");
    assert_eq!(rows[0].orientation_wxyz, None);
    assert_eq!(rows[0].start, None);
}

#[test]
fn each_bad_targets_file_names_file_line_and_what_was_expected() {
    let cases = [
        (
            "empty.csv",
            "# nothing\n\n",
            ": no header line: expected columns x, y, z [, qw, qx, qy, qz] [, joints]",
        ),
        (
            "no_z.csv",
            "\nx,y\n",
            ":2: no column \"z\" in the header: expected x, y, z (m) [, qw, qx, qy, qz] [, one \
             column per joint: shoulder, slide]",
        ),
        (
            "half_quaternion.csv",
            "x,y,z,qw,qx\n",
            ":1: an orientation needs all four columns qw, qx, qy, qz",
        ),
        (
            "one_joint.csv",
            "x,y,z,slide\n",
            ":1: start commands need one column per joint; missing shoulder",
        ),
        (
            "unknown.csv",
            "x,y,z,elbow\n",
            ":1: unknown or repeated columns elbow: expected x, y, z, qw, qx, qy, qz and the \
             joints shoulder, slide",
        ),
        (
            "ragged.csv",
            "x,y,z\n1,2,3\n\n1,2\n",
            ":4: 2 values, the header has 3 columns",
        ),
        (
            "not_a_number.csv",
            "x,y,z\n0.4,1;2,0.6\n",
            ":2:2: expected a number in column \"y\", found \"1;2\"",
        ),
        (
            "infinite.csv",
            "x,y,z\n0.4,0.1,inf\n",
            ":2:3: expected a number in column \"z\", found \"inf\"",
        ),
        (
            "not_unit.csv",
            "x,y,z,qw,qx,qy,qz\n0,0,0,1,1,0,0\n",
            ":2: the quaternion (qw, qx, qy, qz) = [1.0, 1.0, 0.0, 0.0] has norm \
             1.4142135623730951, expected a unit quaternion",
        ),
        (
            "degrees.csv",
            "x,y,z,shoulder,slide\n0,0,0,90,0.1\n",
            ":2: a start command outside the robot's limits: shoulder = 90 rad, limits [-2, 2] \
             rad; the start columns look like degrees read as radians (converted from degrees \
             every one lies within its limits): write them in rad",
        ),
        (
            "prismatic.csv",
            "x,y,z,shoulder,slide\n0,0,0,0,0.7\n",
            ":2: a start command outside the robot's limits: slide = 0.7 m, limits [0, 0.5] m; \
             the start columns are in rad (m for a prismatic joint)",
        ),
    ];
    for (name, text, expected) in cases {
        let path = file(name, text);
        let got = message(read(&path));
        let want = format!("{}{expected}", path.display());
        assert_eq!(got, want, "{name}");
    }
}
