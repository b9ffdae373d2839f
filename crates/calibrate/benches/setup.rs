//! The setup check ([`hapcal_calibrate::setup::check_setup`]) on the bundled recordings,
//! against a calibration of the same data (the model chosen on the ladder by cross-validation,
//! [`hapcal_calibrate::measured::calibrate_measured`]):
//! - `ur10`: figaroh's UR10 camera poses (23 rows, 6 joints, position and orientation);
//! - `tiago`: figaroh's TIAGo motion capture (34 rows of 4 markers, 8 joints);
//! - `kuka_14_front`: MUKCa's iiwa 14 socket placement `front` (62 rows, 7 joints), the socket
//!   check ([`hapcal_calibrate::setup_sockets::check_sockets`]) against `hapcal calibrate`'s
//!   socket workflow ([`hapcal_calibrate::calibrate::run`], no test data);
//! - `positioner`, `haptic_log`, `humanoid`: the industrial_calibration positioner's YAML, the
//!   reference haptic device's log and the simulated two-arm humanoid, read through a plan as
//!   `hapcal calibrate` reads them ([`hapcal_calibrate::setup::check_plan`] against
//!   [`hapcal_calibrate::calibrate::run`]).
#![allow(missing_docs, clippy::unwrap_used)] // criterion's macros generate undocumented items

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_calibrate::measured::{
    MeasuredConfig, calibrate_measured, load_tables, robot_from_urdf,
};
use hapcal_calibrate::setup::{SetupInput, check_setup};
use hapcal_io::Units;
use std::hint::black_box;
use std::path::PathBuf;

fn fixture(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(path)
}

fn bench(c: &mut Criterion) {
    let cases = [
        (
            "ur10",
            "figaroh/ur10/ur10_robot.urdf",
            "wrist_3_link",
            "figaroh/ur10/calibration.csv",
        ),
        (
            "tiago",
            "figaroh/tiago/tiago.urdf",
            "arm_7_link",
            "figaroh/tiago/qualysis_base_hand_calibration.csv",
        ),
    ];
    for (name, urdf, tip, data) in cases {
        let urdf = fixture(urdf);
        let tips = vec![tip.to_owned()];
        let robot = robot_from_urdf(&urdf, &tips).unwrap();
        let units = Units::default();
        let tables = load_tables(&[fixture(data)], &robot, &units).unwrap();
        let mut group = c.benchmark_group(name);
        group.sample_size(10);
        group.bench_function("setup_check", |b| {
            b.iter(|| {
                check_setup(black_box(&SetupInput {
                    robot: &robot,
                    tables: &tables,
                    urdf: Some(&urdf),
                    tips: &tips,
                    units: units.clone(),
                }))
                .unwrap()
            })
        });
        let cfg = MeasuredConfig {
            marker_tips: vec![0],
            ..MeasuredConfig::default()
        };
        group.bench_function("calibration", |b| {
            b.iter(|| calibrate_measured(&robot, black_box(&tables), &[], &cfg).unwrap())
        });
        group.finish();
    }
}

fn bench_sockets(c: &mut Criterion) {
    use hapcal_calibrate::calibrate::{Plan, load_device, run};
    use hapcal_calibrate::setup_sockets::{SocketInput, check_sockets};
    let urdf = fixture("mukca/urdf/iiwa14.urdf");
    let front = fixture("mukca/data/kuka_14/front");
    let device = load_device(&urdf, "ball_link").unwrap();
    let chain = device.chain().unwrap();
    let names: Vec<String> = device.joints.iter().map(|j| j.name.clone()).collect();
    let placements = hapcal_io::read_mukca_paths(std::slice::from_ref(&front), 7).unwrap();
    let mut group = c.benchmark_group("kuka_14_front");
    group.sample_size(10);
    group.bench_function("setup_check", |b| {
        b.iter(|| {
            check_sockets(black_box(&SocketInput {
                chain: &chain,
                joint_names: &names,
                placements: &placements,
                socket_distance_m: 0.05,
                urdf: Some(&urdf),
                tip: "ball_link",
            }))
            .unwrap()
        })
    });
    let plan = Plan {
        device: urdf.clone(),
        data: vec![front.clone()],
        test: Vec::new(),
        ..Plan::bundled_default()
    };
    group.bench_function("calibration", |b| b.iter(|| run(black_box(&plan)).unwrap()));
    group.finish();
}

/// The check (`check_plan`) and the calibration (`calibrate::run`, the ladder as
/// `hapcal calibrate` climbs it) of the bundled recordings read through a plan as the command
/// line reads them: the positioner's YAML, the haptic device's log, the simulated humanoid.
fn bench_plans(c: &mut Criterion) {
    use hapcal_calibrate::calibrate::{Plan, run};
    use hapcal_calibrate::setup::check_plan;
    let cases: [(&str, &str, &[&str], &str); 3] = [
        (
            "positioner",
            "industrial-calibration/two_axis_positioner.toml",
            &[],
            "industrial-calibration/measurements.yaml",
        ),
        (
            "haptic_log",
            "reference-device/device.toml",
            &[],
            "reference-device/log.csv",
        ),
        (
            "humanoid",
            "sim-humanoid/humanoid.urdf",
            &["l_hand", "r_hand"],
            "sim-humanoid/mocap.csv",
        ),
    ];
    for (name, device, tips, data) in cases {
        let default = Plan::bundled_default();
        let plan = Plan {
            device: fixture(device),
            tip: tips
                .first()
                .map_or(default.tip.clone(), |t| (*t).to_owned()),
            tips: tips.iter().skip(1).map(|t| (*t).to_owned()).collect(),
            data: vec![fixture(data)],
            test: Vec::new(),
            ..default
        };
        let mut group = c.benchmark_group(name);
        group.sample_size(10);
        group.bench_function("setup_check", |b| {
            b.iter(|| check_plan(black_box(&plan)).unwrap())
        });
        group.bench_function("calibration", |b| b.iter(|| run(black_box(&plan)).unwrap()));
        group.finish();
    }
}

criterion_group!(benches, bench, bench_sockets, bench_plans);
criterion_main!(benches);
