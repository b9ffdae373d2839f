//! Speed of one diagnosis: the reference device's 600-row time-ordered log with a withheld
//! backlash (the size of the blind test's logs), the serial-arm diagnosis of the MUKCa
//! kuka_14 training placement with its two held-out placements, and the serial-arm diagnosis
//! of the simulated two-arm humanoid (`fixtures/sim-humanoid`: 17 joints, two hand markers,
//! 385 training configurations, the last 30 % held out), its geometric baseline built once
//! outside the timed loop.
//!
//! `cargo bench -p hapcal-diagnose --bench diagnose`

use hapcal_calibrate::model::ModelName;
use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_calibrate::baseline::geometric_baseline;
use hapcal_calibrate::calibrate::Plan;
use hapcal_diagnose::arm::{ArmConfig, diagnose_arm};
use hapcal_diagnose::{DiagnoseConfig, diagnose};
use hapcal_sim::{Injected, MotionConfig, NoiseModel, SimConfig, read_truth, simulate_motion};

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let truth_file = root.join("fixtures/reference-device/truth.toml");
    let truth = read_truth(&truth_file).expect("fixture truth");
    let device = truth.read_device(&truth_file).expect("fixture device");
    let cable = device
        .cable_encoder
        .expect("the reference device has a cable encoder");
    let cfg = SimConfig::new(1, 600).with_noise(NoiseModel::paper(&cable));
    let backlash: Injected = "backlash:j2=1e-3".parse().expect("effect");
    let rows = simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[backlash])
        .expect("simulation");
    let mut group = c.benchmark_group("diagnose");
    group.sample_size(10);
    group.bench_function("reference_device_600_rows", |b| {
        b.iter(|| {
            diagnose(&device, black_box(&rows), &DiagnoseConfig::default()).expect("diagnosis")
        })
    });
    let data = root.join("fixtures/mukca/data/kuka_14");
    let plan = Plan {
        workspace: None,
        device: root.join("fixtures/mukca/urdf/iiwa14.urdf"),
        data: vec![data.join("front")],
        test: vec![data.join("left_back"), data.join("raised_left")],
        model: ModelName::Geometric.into(),
        ..Plan::bundled_default()
    };
    group.bench_function("kuka_14_sockets_with_ladder", |b| {
        b.iter(|| {
            let baseline = geometric_baseline(black_box(&plan), true).expect("baseline");
            diagnose_arm(&baseline, &ArmConfig::default()).expect("diagnosis")
        })
    });
    let humanoid = root.join("fixtures/sim-humanoid");
    let plan = Plan {
        workspace: None,
        device: humanoid.join("humanoid.urdf"),
        tip: "l_hand".into(),
        tips: vec!["r_hand".into()],
        data: vec![humanoid.join("mocap.csv")],
        test: Vec::new(),
        test_last: Some(0.3),
        model: ModelName::Geometric.into(),
        ..Plan::bundled_default()
    };
    let baseline = geometric_baseline(&plan, true).expect("humanoid baseline");
    group.sample_size(10);
    group.bench_function("arm_humanoid", |b| {
        b.iter(|| diagnose_arm(black_box(&baseline), &ArmConfig::default()).expect("diagnosis"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
