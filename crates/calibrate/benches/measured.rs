//! One calibration of about 200 rows on the KUKA LBR iiwa 14 (7 joints, MUKCa's URDF), end to
//! end in-process, for each measurement kind:
//! - `sockets_186`: the three bundled MUKCa kuka_14 placements in one problem (6 sockets × 31
//!   configurations, 48 placement parameters + 6 socket points, geometric model);
//! - `positions_200`: 200 simulated marker positions (0.1 mm noise) in a tracker frame, the
//!   instrument frame, the marker offset and the geometric model fitted
//!   ([`hapcal_calibrate::measured::calibrate_measured`], model given, no cross-validation);
//! - `positions_200_auto`: the same with the model chosen on the ladder by cross-validation;
//! - `humanoid_500_auto`: the whole ladder (frames only → … → isotropic and per-axis
//!   transversal compliance → harmonics, every rung through repeated blocked
//!   cross-validation) on the simulated two-arm humanoid (`tests/sim/humanoid.rs`: 17 joints
//!   on two tips, a CAD mass on every link), 500 rows of two markers;
//! - `humanoid19_500_auto`: the same on the humanoid with a torso of five joints (19 joints on
//!   two tips), the size of a real humanoid upper body;
//! - `ladder_humanoid`: the whole ladder at the size of a real humanoid's recording: the
//!   19-joint humanoid, 350 configurations of two markers (the ladder's time budget, 1 s on
//!   two cores, is set at this size);
//! - `ladder_real_like`: the whole ladder on the simulated humanoid that behaves like real
//!   motion capture (`sim::real_like`, the bundled fixtures/sim-humanoid/real-like.csv: 17
//!   joints, per-axis transversal compliance, link masses 10 % off the URDF's, 2 mm of marker
//!   noise), its 245 training rows of `--test-last 0.3`.
#![allow(missing_docs, clippy::unwrap_used)] // criterion's macros generate undocumented items

#[path = "../tests/sim/humanoid.rs"]
mod humanoid;
#[path = "../tests/sim/tracker.rs"]
mod tracker;

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_calibrate::measured::{MeasuredConfig, Robot, calibrate_measured, robot_from_urdf};
use hapcal_calibrate::model::ModelName;
use hapcal_identify::{IdentifyConfig, identify};
use hapcal_io::MeasurementTable;
use hapcal_problems::{CalibrationProblem, Observations, PointDistance, Row, RowKind, Weights};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::hint::black_box;
use std::path::PathBuf;

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/mukca")
}

fn sockets() -> CalibrationProblem {
    let urdf = fixtures().join("urdf/iiwa14.urdf");
    let device = hapcal_io::import_urdf(&urdf, "ball_link").unwrap();
    let chain = device.chain().unwrap();
    let mut obs = Observations::default();
    for placement in ["front", "left_back", "raised_left"] {
        let dir = fixtures().join("data/kuka_14").join(placement);
        let p = hapcal_io::read_mukca_placement(&dir, chain.n_joints()).unwrap();
        let first = obs.n_points;
        for (k, socket) in p.sockets.iter().enumerate() {
            obs.rows.extend(socket.q.iter().map(|q| Row {
                q: q[..].into(),
                kind: RowKind::Point { point: first + k },
            }));
        }
        obs.n_points += p.sockets.len();
        obs.point_distances.push(PointDistance {
            a: first,
            b: first + 1,
            distance_m: 0.05,
        });
    }
    CalibrationProblem::new(chain, obs, Weights::default(), None).unwrap()
}

/// 200 marker positions of a perturbed iiwa 14 seen by a tracker 2 m away.
fn positions(robot: &Robot) -> MeasurementTable {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let base = tracker::instrument([2.0, 0.3, -0.5], [0.0, 0.0, 2.9]);
    let marker = tracker::marker("marker1", 0.03, -0.02, 0.05);
    let truth_tree = robot.tree.with_frames(&base, &[(0, marker)]).unwrap();
    let n = truth_tree.n_params();
    let dev = Normal::new(0.0, 5e-4).unwrap();
    let x: Vec<f64> = (0..n).map(|_| dev.sample(&mut rng)).collect();
    let noise = Normal::new(0.0, 1e-4).unwrap();
    let rows = (0..200)
        .map(|i| {
            let q = tracker::within_limits(robot, &mut rng);
            let p = truth_tree.tips()[0].end_point(&x, &q);
            let marker = tracker::sample(0, &p, &noise, &mut rng);
            tracker::row(i + 2, q, vec![marker])
        })
        .collect();
    hapcal_io::MeasurementTable::positions("tracker", "tracker.csv", 1, rows)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("iiwa14_200_rows");
    group.sample_size(10);
    group.bench_function("sockets_186", |b| {
        b.iter(|| {
            let p = sockets();
            identify(black_box(&p), p.initial_guess(), &IdentifyConfig::default()).unwrap()
        })
    });
    let urdf = fixtures().join("urdf/iiwa14.urdf");
    let robot = robot_from_urdf(&urdf, &["ball_link".to_owned()]).unwrap();
    let table = positions(&robot);
    for (name, rung) in [
        ("positions_200", Some(ModelName::Geometric)),
        ("positions_200_auto", None),
    ] {
        let cfg = MeasuredConfig {
            rung,
            sigma_m: Some(1e-4),
            ..MeasuredConfig::default()
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                let robot = robot_from_urdf(black_box(&urdf), &["ball_link".to_owned()]).unwrap();
                calibrate_measured(&robot, std::slice::from_ref(&table), &[], &cfg).unwrap()
            })
        });
    }
    group.finish();
    let mut group = c.benchmark_group("humanoid");
    group.sample_size(10);
    let robot = humanoid::humanoid(&["l_hand", "r_hand"]);
    let truth = humanoid::truth(&robot, 11);
    let table = humanoid::table(&robot, &truth, &[0, 1], 500, 12);
    let cfg = MeasuredConfig {
        marker_tips: vec![0, 1],
        ..MeasuredConfig::default()
    };
    group.bench_function("humanoid_500_auto", |b| {
        b.iter(|| {
            calibrate_measured(&robot, std::slice::from_ref(black_box(&table)), &[], &cfg).unwrap()
        })
    });
    let robot = humanoid::long_torso_humanoid(&["l_hand", "r_hand"]);
    let truth = humanoid::truth(&robot, 11);
    let table = humanoid::table(&robot, &truth, &[0, 1], 500, 12);
    group.bench_function("humanoid19_500_auto", |b| {
        b.iter(|| {
            calibrate_measured(&robot, std::slice::from_ref(black_box(&table)), &[], &cfg).unwrap()
        })
    });
    group.finish();
    // Ten samples of about a second (the fewest criterion takes): well under a minute.
    let mut group = c.benchmark_group("ladder");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_secs(1));
    let table = humanoid::table(&robot, &truth, &[0, 1], 350, 13);
    group.bench_function("ladder_humanoid", |b| {
        b.iter(|| {
            calibrate_measured(&robot, std::slice::from_ref(black_box(&table)), &[], &cfg).unwrap()
        })
    });
    let robot = humanoid::humanoid(&["l_hand", "r_hand"]);
    let (_, _, mut table) = humanoid::real_like(&robot, humanoid::REAL_LIKE_SEED);
    // `--test-last 0.3`: the first 70 % of the rows train.
    table.rows.truncate(table.rows.len() * 7 / 10);
    group.bench_function("ladder_real_like", |b| {
        b.iter(|| {
            calibrate_measured(&robot, std::slice::from_ref(black_box(&table)), &[], &cfg).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
