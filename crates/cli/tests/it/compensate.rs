//! `hapcal compensate`: a calibrated iiwa 14 (the bundled URDF with a record of lumped-weight
//! compliances), targets where the rigid arm puts its tip, one unreachable row.

use hapcal_runtime::Robot;

use crate::{assert_exit, compensate, compensate_with, hapcal_ok, iiwa, scratch, succeeded};

/// Writes the calibrated robot (a copy of the URDF and its sidecar) into `dir`.
fn calibrated_robot(dir: &std::path::Path) -> std::path::PathBuf {
    let urdf = dir.join("robot.urdf");
    std::fs::copy(iiwa(), &urdf).expect("copy");
    // A calibration record (schema 1): lumped-weight compliances (the URDF has no masses),
    // gravity along -z at the torque equilibrium.
    let mut sidecar = String::from(
        "schema_version = 1\nmodel = \"compliance\"\n\n[torque]\n\
         source = \"lumped-unit-weights\"\ngravity_direction = [0.0, 0.0, -1.0]\n\
         gravity_m_s2 = 9.80665\nequilibrium = true\n\n[region]\nrows = 100\n\n[values]\n",
    );
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
    let run = compensate(&urdf, "ball_link", &targets, &out);
    assert_exit(&run, 2, &[&format!("{}:4: not reached", targets.display())]);
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
    // Run again onto the same --out: a target is still missed, so the existing file (an
    // earlier result, maybe complete) is not replaced, and the message says so.
    std::fs::write(&out, "an earlier result\n").expect("write");
    let again = compensate(&urdf, "ball_link", &targets, &out);
    assert_exit(&again, 2, &["exists and was left as it was"]);
    assert_eq!(
        std::fs::read_to_string(&out).expect("kept"),
        "an earlier result\n"
    );
}

#[test]
fn compensate_names_the_bad_cell() {
    let dir = scratch("compensate-bad");
    let urdf = calibrated_robot(&dir);
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, "x,y,z\n0.4,0.1,0.6\n0.4,1;2,0.6\n").expect("write");
    let run = compensate(&urdf, "ball_link", &targets, &dir.join("commands.csv"));
    assert_exit(
        &run,
        2,
        &[&format!(
            "{}:3:2: expected a number in column \"y\", found \"1;2\"",
            targets.display()
        )],
    );
}

/// What `hapcal calibrate --model compliance --out robot.urdf` writes (MUKCa iiwa 14, lumped
/// weights) is what `hapcal compensate` reads: the sidecar's compliances in rad/m.
#[test]
fn compensate_reads_what_calibrate_writes() {
    let dir = scratch("compensate-calibrated");
    let urdf = dir.join("robot.urdf");
    hapcal_ok(&[
        "calibrate",
        "--model",
        "compliance",
        "--out",
        &urdf.display().to_string(),
    ]);
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
    succeeded(compensate(&urdf, "ball_link", &targets, &out));
    let written = std::fs::read_to_string(&out).expect("commands");
    assert_eq!(written.lines().count(), 3, "{written}");
}

/// The unit quaternion `(w, (x, y, z))` of the rotation matrix `r` (its trace branch: `w`
/// kept from 0, as for the rotations of this file, far from a half turn).
fn quaternion(r: &[[f64; 3]; 3]) -> (f64, [f64; 3]) {
    let w = 0.5 * (1.0 + r[0][0] + r[1][1] + r[2][2]).max(1e-12).sqrt();
    let v = [
        (r[2][1] - r[1][2]) / (4.0 * w),
        (r[0][2] - r[2][0]) / (4.0 * w),
        (r[1][0] - r[0][1]) / (4.0 * w),
    ];
    (w, v)
}

/// Appends `cells` to `csv` as one line, every number with all its digits.
fn push_row(csv: &mut String, cells: impl Iterator<Item = f64>) {
    let cells: Vec<String> = cells.map(|v| format!("{v:?}")).collect();
    csv.push_str(&cells.join(","));
    csv.push('\n');
}

/// The accuracy study with a calibration from simulated data (docs/results/runtime.md): a
/// simulated iiwa 14 truth (joint origins off by 0.2–0.8 mm and 0.3–1.2 mrad, Drake's link
/// masses, compliances of 1e-4 to 3e-4 rad/(N·m)) measured at 300 poses (marker pose at the
/// ball, σ = 20 µm and 0.1 mrad), calibrated by `hapcal calibrate --model compliance`; 1000
/// held-out targets, commanded with the nominal solution and with `hapcal_runtime::compensate`
/// on the calibrated robot, the truth's tip measured at each.
#[test]
fn compensation_with_a_calibration_from_simulated_data() {
    use hapcal_runtime::{CompensationConfig, Pose, Target, compensate};
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    use crate::iiwa_masses::{JOINTS, calibrated_iiwa_text, with_iiwa_masses as with_masses};

    let dir = scratch("compensate-study");
    // The nominal robot (with masses) and the truth.
    let nominal_urdf = dir.join("nominal.urdf");
    std::fs::write(
        &nominal_urdf,
        with_masses(&std::fs::read_to_string(iiwa()).expect("fixture")),
    )
    .expect("write");
    let truth_dir = dir.join("truth");
    std::fs::create_dir_all(&truth_dir).expect("dir");
    let truth_urdf = truth_dir.join("truth.urdf");
    std::fs::write(&truth_urdf, with_masses(&calibrated_iiwa_text())).expect("write");
    // Its joint compliances, loads on its own geometry at the torque equilibrium.
    let truth = Robot::load_urdf(&truth_urdf, &["ball_link"]).expect("truth");
    let k = [1e-4, 1e-4, 1.5e-4, 1.5e-4, 2e-4, 3e-4, 3e-4];
    let truth = truth.with_compliances(&k).expect("truth");
    let nominal = Robot::load_urdf(&nominal_urdf, &["ball_link"]).expect("nominal");
    let (mut ws_t, mut ws_n) = (truth.workspace(), nominal.workspace());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let configuration = |rng: &mut rand_chacha::ChaCha8Rng| -> Vec<f64> {
        let mut q: Vec<f64> = (nominal.limits().iter())
            .map(|(lo, hi)| rng.random_range(0.8 * lo..0.8 * hi))
            .collect();
        q[3] = if q[3] < 0.0 {
            (q[3] - 0.3).max(-1.67)
        } else {
            (q[3] + 0.3).min(1.67)
        };
        q
    };
    // Training data: the truth's deflected marker pose with noise.
    let (sigma_m, sigma_rad) = (20e-6, 1e-4);
    let noise_p = Normal::new(0.0, sigma_m).expect("σ");
    let noise_r = Normal::new(0.0, sigma_rad).expect("σ");
    let mut csv = format!("{},x,y,z,qw,qx,qy,qz\n", JOINTS.join(","));
    let mut tip = [Pose::IDENTITY];
    for _ in 0..300 {
        let q = configuration(&mut rng);
        truth
            .deflected_tip_poses(&q, &mut ws_t, &mut tip)
            .expect("valid");
        let (w, v) = quaternion(&tip[0].rotation);
        // A small rotation noise: v += δ/2 (first order), then normalised.
        let d: Vec<f64> = (0..3).map(|_| 0.5 * noise_r.sample(&mut rng)).collect();
        let (qx, qy, qz) = (v[0] + w * d[0], v[1] + w * d[1], v[2] + w * d[2]);
        let n = (w * w + qx * qx + qy * qy + qz * qz).sqrt();
        let t = tip[0].translation_m;
        let position = (0..3).map(|i| t[i] + noise_p.sample(&mut rng));
        let cells = (q.iter().copied()).chain(position);
        push_row(&mut csv, cells.chain([w / n, qx / n, qy / n, qz / n]));
    }
    let train = dir.join("train.csv");
    std::fs::write(&train, csv).expect("write");
    let calibrated = dir.join("robot.urdf");
    hapcal_ok(&[
        "calibrate",
        "--device",
        &nominal_urdf.display().to_string(),
        "--tip",
        "ball_link",
        "--data",
        &train.display().to_string(),
        "--model",
        "compliance",
        "--out",
        &calibrated.display().to_string(),
    ]);
    let loaded = Robot::load_urdf(&calibrated, &["ball_link"]).expect("calibrated");
    assert!(loaded.has_compliance());
    // The calibration identified the instrument frame (which absorbs the deviations of the
    // base it cannot tell from it) and the marker frame on the tip: the targets, given in the
    // instrument's (here the nominal base's) frame for the marker, are brought into the
    // calibrated robot's root frame, and the tip is the marker (as --instrument-frame does).
    let instrument = loaded.frame("instrument").expect("identified");
    let marker = loaded.frame("marker1").expect("identified");
    let model = loaded.with_marker(0, &marker).expect("valid");
    let mut ws_m = model.workspace();
    let to_root = instrument.inverse();
    let cfg = CompensationConfig::default();
    let gap = |a: &Pose, b: &Pose| {
        (0..3)
            .map(|i| (a.translation_m[i] - b.translation_m[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let (mut before, mut after) = (Vec::new(), Vec::new());
    let mut q_cmd = vec![0.0; 7];
    let mut unreached = 0;
    let mut cli_rows = Vec::new();
    for k in 0..1000 {
        let q = configuration(&mut rng);
        let target = nominal.tip_pose(0, &q, &mut ws_n).expect("valid");
        if k < 20 {
            cli_rows.push((q.clone(), target));
        }
        truth
            .deflected_tip_poses(&q, &mut ws_t, &mut tip)
            .expect("valid");
        before.push(gap(&tip[0], &target));
        let goal = Target::Pose(to_root.compose(&target));
        let c = compensate(&model, 0, &goal, &q, &cfg, &mut ws_m, &mut q_cmd).expect("valid");
        unreached += usize::from(!c.reached);
        truth
            .deflected_tip_poses(&q_cmd, &mut ws_t, &mut tip)
            .expect("valid");
        after.push(gap(&tip[0], &target));
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "calibrated from simulated data: nominal commands RMS {:.3} mm, max {:.3} mm; compensated RMS {:.4} mm, max {:.4} mm; unreached {unreached}",
        rms(&before) * 1e3,
        max(&before) * 1e3,
        rms(&after) * 1e3,
        max(&after) * 1e3
    );
    assert_eq!(unreached, 0);
    assert!(rms(&before) > 1e-3, "{}", rms(&before));
    // The calibration's own error: a few times the position noise.
    assert!(rms(&after) < 5.0 * sigma_m, "{}", rms(&after));

    // The same through `hapcal compensate --instrument-frame` on 20 of the targets.
    let mut text = format!("x,y,z,qw,qx,qy,qz,{}\n", JOINTS.join(","));
    for (q, t) in &cli_rows {
        let (w, v) = quaternion(&t.rotation);
        let p = t.translation_m;
        let cells = (p.iter().copied()).chain([w, v[0], v[1], v[2]]);
        push_row(&mut text, cells.chain(q.iter().copied()));
    }
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, text).expect("write");
    let out = dir.join("commands.csv");
    let extra = ["--instrument-frame"];
    succeeded(compensate_with(
        &calibrated,
        Some("ball_link"),
        &targets,
        &out,
        &extra,
    ));
    let written = std::fs::read_to_string(&out).expect("commands");
    assert_eq!(written.lines().count(), 21, "{written}");
    for (row, (_, target)) in written.lines().skip(1).zip(&cli_rows) {
        let cells: Vec<f64> = row.split(',').map(|c| c.parse().expect("number")).collect();
        truth
            .deflected_tip_poses(&cells[1..8], &mut ws_t, &mut tip)
            .expect("valid");
        let e = gap(&tip[0], target);
        assert!(e < 5.0 * sigma_m, "{e} m: {row}");
    }
}

#[test]
fn compensate_words_the_first_ten_targets_missed_and_counts_the_others() {
    // Twelve targets 3 m away, beyond the arm's reach: ten named by file:line, two counted.
    let dir = scratch("compensate-many-missed");
    let urdf = calibrated_robot(&dir);
    let mut text = String::from("x,y,z\n");
    for k in 0..12 {
        text.push_str(&format!("3.0,{:?},0.5\n", 0.01 * f64::from(k)));
    }
    let targets = dir.join("targets.csv");
    std::fs::write(&targets, &text).expect("write");
    let run = compensate(&urdf, "ball_link", &targets, &dir.join("commands.csv"));
    let err = assert_exit(&run, 2, &["12 of 12 targets not reached", "… and 2 more"]);
    let named = |line: usize| format!("{}:{line}: not reached", targets.display());
    // Lines 2 to 11 are the first ten targets; 12 and 13 are only counted.
    assert!((2..=11).all(|line| err.contains(&named(line))), "{err}");
    assert!(
        !err.contains(&named(12)) && !err.contains(&named(13)),
        "{err}"
    );
}
