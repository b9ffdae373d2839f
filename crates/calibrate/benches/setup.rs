//! The setup check ([`hapcal_calibrate::setup::check_setup`]) on the bundled recordings,
//! against a calibration of the same data (the model chosen on the ladder by cross-validation,
//! [`hapcal_calibrate::measured::calibrate_measured`]):
//! - `ur10`: figaroh's UR10 camera poses (23 rows, 6 joints, position and orientation);
//! - `tiago`: figaroh's TIAGo motion capture (34 rows of 4 markers, 8 joints).
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
                    units,
                }))
                .unwrap()
            })
        });
        let cfg = MeasuredConfig {
            rung: None,
            folds: 5,
            sigma_m: None,
            sigma_rad: None,
            marker_tips: vec![0],
            workspace: Vec::new(),
        };
        group.bench_function("calibration", |b| {
            b.iter(|| calibrate_measured(&robot, black_box(&tables), &[], &cfg).unwrap())
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
