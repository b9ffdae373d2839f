//! The iiwa 14 (7 joints) with Drake's link masses and gravity compliance, one thread:
//! deflected tip pose (the fixed point θ = q + k∘τ(θ)), and the compensation of one 6-D
//! target from the nominal inverse kinematics' solution (`hapcal_runtime::compensate`).

use std::hint::black_box;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, criterion_group, criterion_main};
use hapcal_problems::GravityCompliance;
use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};

#[path = "../tests/it/iiwa_masses.rs"]
#[allow(
    dead_code,
    reason = "the benchmark takes the masses, not the calibrated copy"
)]
mod iiwa_masses;

use iiwa_masses::{JOINTS, with_iiwa_masses};

/// The bundled iiwa 14 URDF with Drake's masses as `<inertial>`s and joint compliances from
/// 1e-4 to 3e-4 rad/(N·m) (`Robot::with_compliances`: loads on the calibrated geometry at the
/// torque equilibrium).
fn compliant_iiwa() -> Robot {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/mukca/urdf/iiwa14.urdf"
    );
    let text = with_iiwa_masses(&std::fs::read_to_string(path).expect("bundled fixture"));
    let k = [1e-4, 1e-4, 1.5e-4, 1.5e-4, 2e-4, 3e-4, 3e-4];
    let robot = Robot::from_urdf_str(&text, "iiwa14.urdf", None, &["ball_link"]).expect("valid");
    robot.with_compliances(&k).expect("valid")
}

/// The iiwa 14 as `hapcal calibrate --model mass-compliance` writes it: the URDF's origins
/// hold the calibrated geometry, the record (schema 1) Drake's masses as published masses,
/// joint offsets and origin deviations, compliances, the loads of the robot at its readings.
fn recorded_iiwa() -> Robot {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/mukca/urdf/iiwa14.urdf"
    );
    let text = std::fs::read_to_string(path).expect("bundled fixture");
    let names: Vec<String> = JOINTS.iter().map(|j| (*j).to_owned()).collect();
    let model = GravityCompliance::published(&names).expect("iiwa joint names");
    let mut record = String::from(
        "schema_version = 1\nmodel = \"mass-compliance\"\ntips = [\"ball_link\"]\n\n[torque]\nsource = \"published-masses\"\ngravity_direction = [0.0, 0.0, -1.0]\ngravity_m_s2 = 9.80665\nequilibrium = false\ntips = [\"ball_link\"]\n",
    );
    for m in &model.masses {
        let c = m.com_m;
        record.push_str(&format!(
            "\n[[torque.mass]]\njoint = \"{}\"\nmass_kg = {:?}\ncom_m = [{:?}, {:?}, {:?}]\n",
            JOINTS[m.joint], m.mass_kg, c.x, c.y, c.z
        ));
    }
    record.push_str("\n[region]\nrows = 100\n");
    for j in JOINTS {
        record.push_str(&format!(
            "\n[[region.joint]]\nname = \"{j}\"\nmin = -2.0\nmax = 2.0\nunit = \"rad\"\n"
        ));
    }
    record.push_str("\n[values]\n");
    let k = [1e-4, 1e-4, 1.5e-4, 1.5e-4, 2e-4, 3e-4, 3e-4];
    for (i, (j, k)) in JOINTS.iter().zip(k).enumerate() {
        let d = 1e-4 * (i as f64 + 1.0);
        for (field, unit) in [("x", "m"), ("rx", "rad"), ("offset", "rad")] {
            record.push_str(&format!(
                "\"{j}.{field}\" = {{ value = {d:?}, std = 1e-5, unit = \"{unit}\" }}\n"
            ));
        }
        record.push_str(&format!(
            "\"compliance.{j}\" = {{ value = {k:?}, std = 1e-6, unit = \"rad/(N·m)\" }}\n"
        ));
    }
    Robot::from_urdf_str(
        &text,
        "iiwa14.urdf",
        Some((&record, "record")),
        &["ball_link"],
    )
    .expect("valid")
}

const Q: [f64; 7] = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];

/// `compensate_pose` of `group`: the compensation of `robot` to the target where its rigid
/// (nominal) copy puts the tip at `Q`, so that `Q` is the nominal inverse kinematics' solution
/// and the compensation corrects the sag.
fn compensate_pose(group: &mut BenchmarkGroup<'_, WallTime>, robot: &Robot) {
    let mut ws = robot.workspace();
    let rigid = robot.with_compliances(&[0.0; 7]).expect("valid");
    let target = Target::Pose(rigid.tip_pose(0, &Q, &mut ws).expect("valid"));
    let cfg = CompensationConfig::default();
    group.bench_function("compensate_pose", |b| {
        let mut q = [0.0; 7];
        b.iter(|| {
            let c = compensate(robot, 0, black_box(&target), &Q, &cfg, &mut ws, &mut q);
            assert!(c.is_ok_and(|c| c.reached));
            q[0]
        })
    });
}

fn bench(c: &mut Criterion) {
    let robot = compliant_iiwa();
    let mut ws = robot.workspace();
    let mut group = c.benchmark_group("iiwa14_compliant");
    group.bench_function("deflected_tip_pose", |b| {
        let mut out = [Pose::IDENTITY];
        b.iter(|| {
            robot
                .deflected_tip_poses(black_box(&Q), &mut ws, &mut out)
                .map(|d| d.iterations)
        })
    });
    compensate_pose(&mut group, &robot);
    group.finish();

    // As calibrate writes it: loads of the robot at its readings, nominal geometry for them.
    let robot = recorded_iiwa();
    let mut ws = robot.workspace();
    let mut group = c.benchmark_group("iiwa14_recorded");
    group.bench_function("pose_jacobian_deflected", |b| {
        let mut out = [Pose::IDENTITY];
        let mut jac = [[0.0; 6]; 7];
        b.iter(|| {
            let pose = robot.spatial_jacobian(0, black_box(&Q), &mut ws, &mut jac);
            let deflection = robot.deflected_tip_poses(black_box(&Q), &mut ws, &mut out);
            (
                pose.map(|p| p.translation_m[0]),
                deflection.map(|d| d.iterations),
            )
        })
    });
    group.bench_function("tip_pose", |b| {
        b.iter(|| {
            robot
                .tip_pose(0, black_box(&Q), &mut ws)
                .map(|p| p.translation_m[0])
        })
    });
    group.bench_function("deflected_pose_jacobian", |b| {
        let mut jac = [[0.0; 6]; 7];
        b.iter(|| {
            robot
                .deflected_spatial_jacobian(0, black_box(&Q), &mut ws, &mut jac)
                .map(|(p, _)| p.translation_m[0])
        })
    });
    compensate_pose(&mut group, &robot);
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
