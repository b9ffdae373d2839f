//! `hapcal compensate`: a calibrated iiwa 14 (the bundled URDF with a sidecar of lumped-weight
//! compliances), targets where the rigid arm puts its tip, one unreachable row.

use hapcal_runtime::Robot;

use crate::{hapcal, iiwa, scratch, stderr};

/// Writes the calibrated robot (a copy of the URDF and its sidecar) into `dir`.
fn calibrated_robot(dir: &std::path::Path) -> std::path::PathBuf {
    let urdf = dir.join("robot.urdf");
    std::fs::copy(iiwa(), &urdf).expect("copy");
    let mut sidecar = String::from("[values]\n");
    for j in 1..=7 {
        let k = 2e-4 + 1e-4 * f64::from(j);
        sidecar.push_str(&format!(
            "\"compliance.joint_a{j}\" = {{ value = {k:?}, std = 1e-5, unit = \"rad/m\" }}\n"
        ));
    }
    std::fs::write(dir.join("robot.calibration.toml"), sidecar).expect("write");
    urdf
}

#[test]
fn compensate_writes_reached_commands_and_reports_the_unreachable_row() {
    let dir = scratch("compensate");
    let urdf = calibrated_robot(&dir);
    let robot = Robot::load_urdf(&urdf, &["ball_link"]).expect("valid");
    let rigid = robot.with_compliances(&[0.0; 7]).expect("valid");
    let mut ws = rigid.workspace();
    let starts = [
        [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1],
        [-0.5, 0.4, 0.3, -1.5, -0.2, 0.6, 0.8],
    ];
    let mut text = String::from(
        "x,y,z,qw,qx,qy,qz,joint_a1,joint_a2,joint_a3,joint_a4,joint_a5,joint_a6,joint_a7\n",
    );
    for q in &starts {
        let pose = rigid.tip_pose(0, q, &mut ws).expect("valid");
        let r = pose.rotation;
        // Quaternion of a rotation matrix with a positive trace (these poses have one).
        let w = 0.5 * (1.0 + r[0][0] + r[1][1] + r[2][2]).sqrt();
        let (x, y, z) = (
            (r[2][1] - r[1][2]) / (4.0 * w),
            (r[0][2] - r[2][0]) / (4.0 * w),
            (r[1][0] - r[0][1]) / (4.0 * w),
        );
        let t = pose.translation_m;
        text.push_str(&format!(
            "{:?},{:?},{:?},{w:?},{x:?},{y:?},{z:?}",
            t[0], t[1], t[2]
        ));
        for v in q {
            text.push_str(&format!(",{v:?}"));
        }
        text.push('\n');
    }
    // Line 4: 3 m away, beyond the arm's reach.
    text.push_str("3.0,0.0,0.5,1,0,0,0,0,0.5,0,-1,0,0.5,0\n");
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, &text).expect("write");
    let out = dir.join("commands.csv");
    let run = hapcal(&[
        "compensate",
        "--device",
        &urdf.display().to_string(),
        "--tip",
        "ball_link",
        "--targets",
        &targets.display().to_string(),
        "--out",
        &out.display().to_string(),
    ]);
    let err = stderr(&run);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("{}:4: not reached", targets.display())),
        "{err}"
    );
    let written = std::fs::read_to_string(&out).expect("commands written");
    let rows: Vec<&str> = written.lines().collect();
    assert_eq!(rows.len(), 3, "{written}");
    assert!(rows[0].starts_with("line,joint_a1,"), "{written}");
    // Each written command brings the compliant robot's tip onto its target.
    let mut pose = [hapcal_runtime::Pose::IDENTITY];
    for (row, q_start) in rows[1..].iter().zip(&starts) {
        let cells: Vec<f64> = row.split(',').map(|c| c.parse().expect("number")).collect();
        let q = &cells[1..8];
        robot
            .deflected_tip_poses(q, &mut ws, &mut pose)
            .expect("valid");
        let target = rigid.tip_pose(0, q_start, &mut ws).expect("valid");
        let gap = (0..3)
            .map(|i| (pose[0].translation_m[i] - target.translation_m[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(gap <= 1e-6, "{gap} m");
        // The sag made the command differ from the rigid solution.
        let moved = q
            .iter()
            .zip(q_start)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(moved > 1e-5, "{moved}");
    }
}

#[test]
fn compensate_names_the_bad_cell() {
    let dir = scratch("compensate-bad");
    let urdf = calibrated_robot(&dir);
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, "x,y,z\n0.4,0.1,0.6\n0.4,1;2,0.6\n").expect("write");
    let run = hapcal(&[
        "compensate",
        "--device",
        &urdf.display().to_string(),
        "--tip",
        "ball_link",
        "--targets",
        &targets.display().to_string(),
        "--out",
        &dir.join("commands.csv").display().to_string(),
    ]);
    let err = stderr(&run);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{}:3:2: expected a number in column \"y\", found \"1;2\"",
            targets.display()
        )),
        "{err}"
    );
}

/// What `hapcal calibrate --model compliance --out robot.urdf` writes (MUKCa iiwa 14, lumped
/// weights) is what `hapcal compensate` reads: the sidecar's compliances in rad/m.
#[test]
fn compensate_reads_what_calibrate_writes() {
    let dir = scratch("compensate-calibrated");
    let urdf = dir.join("robot.urdf");
    let run = hapcal(&[
        "calibrate",
        "--model",
        "compliance",
        "--out",
        &urdf.display().to_string(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let sidecar = std::fs::read_to_string(dir.join("robot.calibration.toml")).expect("sidecar");
    assert!(
        sidecar.contains("\"compliance.joint_a4\"") && sidecar.contains("unit = \"rad/m\""),
        "{sidecar}"
    );
    let robot = Robot::load_urdf(&urdf, &["ball_link"]).expect("calibrate's output loads");
    assert!(robot.has_compliance());
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, "x,y,z\n0.45,0.1,0.7\n0.5,-0.1,0.6\n").expect("write");
    let out = dir.join("commands.csv");
    let run = hapcal(&[
        "compensate",
        "--device",
        &urdf.display().to_string(),
        "--tip",
        "ball_link",
        "--targets",
        &targets.display().to_string(),
        "--out",
        &out.display().to_string(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let written = std::fs::read_to_string(&out).expect("commands");
    assert_eq!(written.lines().count(), 3, "{written}");
}
