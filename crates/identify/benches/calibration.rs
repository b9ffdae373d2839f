//! One calibration of the bundled MUKCa kuka_14 training placement (`front`, 2 × 31
//! configurations, 48 URDF-placement parameters + 2 socket points), geometric model:
//! - `identify`: the identification alone (pruning rounds, LM, covariance);
//! - `end_to_end`: reading the URDF and the CSVs, building the problem, identifying, and writing
//!   the calibrated URDF to a string (what `hapcal calibrate --model geometric --out x.urdf` does,
//!   without the report and the test placements).
#![allow(missing_docs, clippy::unwrap_used)] // criterion's macros generate undocumented items

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_identify::{IdentifyConfig, identify};
use hapcal_io::CalibratedValue;
use hapcal_problems::{CalibrationProblem, Observations, PointDistance, Row, RowKind, Weights};
use std::hint::black_box;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/mukca")
}

fn problem(urdf: &Path, placement: &Path) -> (hapcal_io::Device, CalibrationProblem) {
    let device = hapcal_io::import_urdf(urdf, "ball_link").unwrap();
    let chain = device.chain().unwrap();
    let p = hapcal_io::read_mukca_placement(placement, chain.n_joints()).unwrap();
    let mut obs = Observations {
        n_points: p.sockets.len(),
        ..Observations::default()
    };
    for (point, socket) in p.sockets.iter().enumerate() {
        obs.rows.extend(socket.q.iter().map(|q| Row {
            q: q[..].into(),
            kind: RowKind::Point { point },
        }));
    }
    obs.point_distances.push(PointDistance {
        a: 0,
        b: 1,
        distance_m: 0.05,
    });
    (
        device,
        CalibrationProblem::new(chain, obs, Weights::default(), None).unwrap(),
    )
}

fn bench(c: &mut Criterion) {
    let urdf = fixtures().join("urdf/iiwa14.urdf");
    let front = fixtures().join("data/kuka_14/front");
    let mut group = c.benchmark_group("kuka_14_front");
    let (_, p) = problem(&urdf, &front);
    group.bench_function("identify", |b| {
        b.iter(|| identify(black_box(&p), p.initial_guess(), &IdentifyConfig::default()).unwrap())
    });
    group.bench_function("end_to_end", |b| {
        b.iter(|| {
            let (device, p) = problem(black_box(&urdf), black_box(&front));
            let fit = identify(&p, p.initial_guess(), &IdentifyConfig::default()).unwrap();
            let stds = fit.covariance.std();
            let values: Vec<CalibratedValue> = fit
                .covariance
                .free
                .iter()
                .zip(stds.iter())
                .filter(|(i, _)| **i < p.points_offset())
                .map(|(&i, &std)| CalibratedValue {
                    name: fit.layout.name(i).to_string(),
                    value: fit.fit.x[i],
                    std,
                    unit: fit.layout.spec(i).unit.symbol().to_string(),
                })
                .collect();
            let calibrated = device
                .with_calibration(&values, hapcal_io::CalibrationMeta::default())
                .unwrap();
            hapcal_io::write_calibrated_urdf(&urdf, &calibrated.placements).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
