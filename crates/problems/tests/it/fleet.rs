//! The fleet problem: analytic sparse Jacobian, and the sparse back end against the dense one.

use faer::{Col, Mat};
use hapcal_identify::{Backend, IdentifyConfig, Problem, SparseJacobian, identify};
use hapcal_problems::{FleetDevice, FleetProblem, cable_angle};

use crate::lcg;

const HELD: [&str; 4] = ["dalpha0", "dd0", "dtheta0", "dalpha7"];

/// `n_devices` reference devices with `n_poses` poses each, cable offset 0.2 mm, cable-angle
/// coefficient 0.15 mm/rad, 10 µm noise.
fn fleet(n_devices: usize, n_poses: usize) -> FleetProblem {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let device = hapcal_io::read_device(&root.join("fixtures/reference-device/device.toml"))
        .expect("device");
    let chain = device.chain().expect("chain");
    let limits = device.joint_limits();
    let params: Vec<usize> = (0..chain.n_params())
        .filter(|&j| !HELD.contains(&chain.params()[j].name.as_str()))
        .collect();
    let mut state = 3;
    let devices = (0..n_devices)
        .map(|_| {
            let mut x = vec![0.0; chain.n_params()];
            for &j in &params {
                x[j] = 1e-3 * lcg(&mut state);
            }
            let mut dev = FleetDevice::default();
            for _ in 0..n_poses {
                let q: Vec<f64> = limits
                    .iter()
                    .map(|&(lo, hi)| lo + (hi - lo) * 0.5 * (1.0 + lcg(&mut state)))
                    .collect();
                let p = chain.end_point(&x, &q);
                let (phi, _) = cable_angle(&p);
                dev.distance_m
                    .push(p.coords.norm() + 2e-4 + 1.5e-4 * phi + 1e-5 * lcg(&mut state));
                dev.q_rad.extend(q);
            }
            dev
        })
        .collect();
    FleetProblem::new(chain, params, devices, 1e-5).expect("fleet")
}

#[test]
fn sparse_values_match_the_dense_jacobian() {
    let p = fleet(2, 30);
    let (m, n) = (p.n_residuals(), p.layout().len());
    let mut x = Col::<f64>::zeros(n);
    let mut state = 5;
    for i in 0..n {
        x[i] = 1e-3 * lcg(&mut state);
    }
    let mut dense = Mat::<f64>::zeros(m, n);
    p.jacobian(x.as_ref(), dense.as_mut()).expect("jacobian");
    let (col_ptr, row_idx) = p.pattern();
    let mut r = vec![0.0; m];
    let mut values = vec![0.0; row_idx.len()];
    p.residuals_and_values(x.as_ref(), &mut r, &mut values)
        .expect("values");
    let mut rebuilt = Mat::<f64>::zeros(m, n);
    for j in 0..n {
        for k in col_ptr[j]..col_ptr[j + 1] {
            rebuilt[(row_idx[k], j)] = values[k];
        }
    }
    assert_eq!(rebuilt, dense);
    // Central differences of the residuals.
    let h = 1e-7;
    for j in [0, 5, 27, 28, n - 2, n - 1] {
        let (mut up, mut down) = (x.clone(), x.clone());
        up[j] += h;
        down[j] -= h;
        let (mut ru, mut rd) = (Col::<f64>::zeros(m), Col::<f64>::zeros(m));
        p.residuals(up.as_ref(), ru.as_mut()).expect("r");
        p.residuals(down.as_ref(), rd.as_mut()).expect("r");
        for i in 0..m {
            let fd = (ru[i] - rd[i]) / (2.0 * h);
            assert!(
                (fd - dense[(i, j)]).abs() <= 1e-5 * (1.0 + fd.abs()),
                "row {i}, {}: {fd} vs {}",
                p.layout().name(j),
                dense[(i, j)]
            );
        }
    }
}

#[test]
fn sparse_back_end_matches_the_dense_one_and_recovers_the_rig() {
    let p = fleet(3, 120);
    let run = |backend| {
        identify(
            &p,
            Col::zeros(p.layout().len()),
            &IdentifyConfig {
                backend,
                ..IdentifyConfig::default()
            },
        )
        .expect("identifies")
    };
    let dense = run(Backend::Dense);
    let sparse = run(Backend::Sparse);
    assert!(
        dense.identifiability.pruned.is_empty(),
        "{:?}",
        dense.identifiability.pruned_names()
    );
    assert!(
        sparse.fit.termination.is_success(),
        "{:?}",
        sparse.fit.termination
    );
    for i in 0..p.layout().len() {
        assert!(
            (dense.fit.x[i] - sparse.fit.x[i]).abs() <= 1e-9,
            "{}: {} vs {}",
            p.layout().name(i),
            dense.fit.x[i],
            sparse.fit.x[i]
        );
    }
    for name in ["rig.cable_offset", "rig.cable_angle"] {
        let (a, b) = (
            dense.std(name).expect("kept"),
            sparse.std(name).expect("reported"),
        );
        assert!((a - b).abs() <= 1e-6 * a, "{name}: std {a} vs {b}");
    }
    let z = |name: &str, truth: f64| {
        (sparse.value(name).expect("value") - truth) / sparse.std(name).expect("std")
    };
    assert!(z("rig.cable_offset", 2e-4).abs() < 4.0);
    assert!(z("rig.cable_angle", 1.5e-4).abs() < 4.0);
}
