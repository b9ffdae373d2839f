//! One reading of the calibrated 7-DOF reference device, one thread: joint angles alone,
//! pose alone, pose + body Jacobian, and everything a force controller needs per cycle (pose
//! + body Jacobian + motor torques, `Model::evaluate`).

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_runtime::{Evaluation, Model};

fn reference() -> Model {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/reference-device/calibrated.toml"
    );
    Model::load(Path::new(path)).expect("bundled fixture")
}

const THETA: [f64; 7] = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
const WRENCH: [f64; 6] = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];

fn bench(c: &mut Criterion) {
    let model = reference();
    let mut group = c.benchmark_group("reference_device");
    group.bench_function("joint_angles", |b| {
        let (mut q, mut dq) = ([0.0; 7], [0.0; 7]);
        b.iter(|| model.joint_angles(black_box(&THETA), &mut q, &mut dq))
    });
    group.bench_function("end_pose", |b| b.iter(|| model.end_pose(black_box(&THETA))));
    group.bench_function("body_jacobian", |b| {
        let mut jac = [[0.0; 6]; 7];
        b.iter(|| {
            model
                .body_jacobian(black_box(&THETA), &mut jac)
                .map(|_| jac[0][0])
        })
    });
    group.bench_function("evaluate", |b| {
        let mut out = Evaluation::default();
        b.iter(|| {
            model
                .evaluate(black_box(&THETA), black_box(&WRENCH), &mut out)
                .map(|()| out.motor_torques_nm[0])
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
