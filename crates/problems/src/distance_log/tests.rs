use faer::Col;
use hapcal_identify::Problem;
use hapcal_io::Device;

use super::*;
use crate::{JointData, JointProblem, JointTransmissions};

const SIGMA_EXT: f64 = 2e-5;
const SIGMA_D: f64 = 1.5e-5;

fn reference_device() -> Device {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/reference-device/device.toml");
    hapcal_io::read_device(&path).unwrap()
}

/// Capstans on joints 1–3, the polynomial on joint 4, parameters away from zero.
fn transmissions(device: &Device) -> Vec<LogTransmission> {
    let mut out: Vec<LogTransmission> = (device.capstans.iter())
        .filter(|c| c.joint != 4)
        .enumerate()
        .map(|(k, c)| LogTransmission::Capstan {
            joint: c.joint - 1,
            capstan: Capstan::try_new(c.ratio, c.drum_distance_m).unwrap(),
            params: CapstanParams {
                c_rad: 1e-3 * (k as f64 + 1.0),
                re: -0.01,
                r_o_m: 0.2e-3,
                beta_o_rad: -1.8 + k as f64,
                r_i_m: 0.01e-3,
                beta_i_rad: 0.7,
            },
        })
        .collect();
    let (lo, hi) = device.joint_limits()[3];
    out.push(LogTransmission::Polynomial {
        joint: 3,
        poly: Chebyshev::try_new(lo, hi, (0..=10).map(|k| 1e-3 / (k as f64 + 1.0)).collect())
            .unwrap(),
    });
    out
}

/// Readings inside the joint limits, times, external readings near the joint angles and
/// distances near the nominal chain's.
fn log(device: &Device, n: usize) -> DistanceLog {
    let chain = device.chain().unwrap();
    let limits = device.joint_limits();
    let q: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (limits.iter().enumerate())
                .map(|(j, &(lo, hi))| {
                    let s = (0.37 * (i * (j + 2)) as f64 + 0.5 * j as f64).sin();
                    0.5 * (lo + hi) + 0.4 * (hi - lo) * s
                })
                .collect()
        })
        .collect();
    let x0 = vec![0.0; chain.n_params()];
    let distance_m = (q.iter().enumerate())
        .map(|(i, q)| chain.end_point(&x0, q).coords.norm() + 1e-4 * (i as f64).cos())
        .collect();
    let ext = (q.iter().enumerate())
        .map(|(i, q)| {
            (0..4)
                .map(|j| Some(q[j] + 1e-4 * ((i + j) as f64).sin()))
                .collect()
        })
        .collect();
    let t = (0..n).map(|i| 0.01 * i as f64).collect();
    DistanceLog::new(q, Some(t), distance_m, ext).unwrap()
}

fn x_kin(chain: &Chain) -> Vec<f64> {
    (0..chain.n_params())
        .map(|k| 1e-4 * ((k as f64) * 1.7).sin())
        .collect()
}

fn model(device: &Device, log: DistanceLog) -> DistanceLogModel {
    let chain = device.chain().unwrap();
    let noise = DistanceLogNoise {
        sigma_m_m: SIGMA_D,
        sigma_e_rad: SIGMA_EXT,
        resolution_rad: vec![1e-4; chain.n_joints()],
    };
    DistanceLogModel::new(chain, log, noise, 0.2).unwrap()
}

#[test]
fn restricted_to_transmissions_and_kinematics_it_is_the_joint_problem() {
    let device = reference_device();
    let chain = device.chain().unwrap();
    let n = 40;
    let log = log(&device, n);
    let trans = transmissions(&device);
    let mut m = model(&device, log.clone());
    m.quantisation = false;
    m.set_ext_joints(trans.iter().map(LogTransmission::joint).collect())
        .unwrap();
    let mut state = m.initial_state(trans.clone());
    state.x_kin = x_kin(&chain);
    let lin = m.linearise(&state).unwrap();

    let (lo, hi) = device.joint_limits()[3];
    let capstans: Vec<(usize, Capstan)> = (trans.iter())
        .filter_map(|t| match t {
            LogTransmission::Capstan { joint, capstan, .. } => Some((joint + 1, *capstan)),
            LogTransmission::Polynomial { .. } => None,
        })
        .collect();
    let params: Vec<CapstanParams> = (trans.iter())
        .filter_map(|t| match t {
            LogTransmission::Capstan { params, .. } => Some(*params),
            LogTransmission::Polynomial { .. } => None,
        })
        .collect();
    let coeffs = match &trans[3] {
        LogTransmission::Polynomial { poly, .. } => poly.coeffs.clone(),
        LogTransmission::Capstan { .. } => unreachable!(),
    };
    let jt = JointTransmissions {
        capstans,
        poly_joint: 4,
        poly_degree: 10,
        poly_lo_rad: lo,
        poly_hi_rad: hi,
    };
    let data = JointData {
        q: log.q().to_vec(),
        ext: (0..4)
            .map(|j| log.ext().iter().map(|e| e[j].unwrap()).collect())
            .collect(),
        distance_m: log.distance_m().to_vec(),
    };
    let jp = JointProblem::new(chain.clone(), jt, data, SIGMA_EXT, SIGMA_D).unwrap();
    let x = jp.start(
        &params,
        &coeffs,
        Col::from_fn(chain.n_params(), |i| state.x_kin[i]).as_ref(),
    );
    let layout_names: Vec<String> = jp.layout().specs().iter().map(|p| p.name.clone()).collect();
    assert_eq!(lin.names, layout_names);
    let m_rows = jp.n_residuals();
    assert_eq!(lin.residuals.len(), m_rows);
    let mut r = Col::zeros(m_rows);
    jp.residuals(x.as_ref(), r.as_mut()).unwrap();
    let mut jac = faer::Mat::zeros(m_rows, x.nrows());
    jp.jacobian(x.as_ref(), jac.as_mut()).unwrap();
    // The joint problem's rows: the four external encoders, then the distances; the model's:
    // the distances, then the external encoders.
    let joint_row = |row: usize| if row < n { 4 * n + row } else { row - n };
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-6);
    for row in 0..m_rows {
        let jr = joint_row(row);
        assert!(
            close(lin.residuals[row], r[jr]),
            "residual {row}: {} vs {}",
            lin.residuals[row],
            r[jr]
        );
        for c in 0..x.nrows() {
            assert!(
                close(lin.jacobian[(row, c)], jac[(jr, c)]),
                "row {row}, {}: {} vs {}",
                lin.names[c],
                lin.jacobian[(row, c)],
                jac[(jr, c)]
            );
        }
    }
    assert!(lin.sigma[..n].iter().all(|&s| s == SIGMA_D));
    assert!(lin.sigma[n..].iter().all(|&s| s == SIGMA_EXT));
}

/// Every term kind's columns against central differences of the unweighted model
/// (coefficients 0 for latency and compliance, whose own dependence on the state the
/// linearisation leaves out). Central differences at h = 1e-7 err by about h²·|f‴| plus
/// rounding ε·|d|/h ≈ 1e-9·|d|, far below the 1e-5 relative tolerance; a left-out product
/// (a scaled drift's, 1e-2/s over the log's 0.24 s: 2.4e-3 of a column) is far above it.
#[test]
fn jacobian_matches_finite_differences_with_every_term_kind() {
    let device = reference_device();
    let chain = device.chain().unwrap();
    let n = 25;
    let log = log(&device, n);
    let mut m = model(&device, log.clone());
    m.set_ext_joints(vec![0, 3]).unwrap();
    let mut state = m.initial_state(transmissions(&device));
    state.x_kin = x_kin(&chain);
    let term = |name: &str, kind| EffectTerm {
        name: name.to_owned(),
        unit: "1",
        kind,
    };
    let g: Vec<f64> = log.q().iter().map(|q| q[4].sin()).collect();
    state.terms = vec![
        (term("joint", EffectTermKind::Joint { joint: 4, g }), 2e-3),
        (
            term("offset", EffectTermKind::Distance { h: vec![1.0; n] }),
            1e-4,
        ),
        (term("latency", EffectTermKind::Latency), 0.0),
        (
            term("drift", EffectTermKind::ThermalDrift { scale: true }),
            1e-2,
        ),
        (
            term("rate", EffectTermKind::ThermalDrift { scale: false }),
            1e-5,
        ),
        (term("angle", EffectTermKind::CableAngle { power: 0 }), 5e-3),
        (term("cos2", EffectTermKind::CableAngle { power: 2 }), -2e-3),
        (
            term("compliance", EffectTermKind::Compliance { joint: 1 }),
            0.0,
        ),
    ];
    let lin = m.linearise(&state).unwrap();
    let unweighted = |s: &DistanceLogState| -> Vec<f64> {
        let l = m.linearise(s).unwrap();
        // σ is evaluated at the state (quantisation through ∂d/∂q): undo it row by row.
        (0..l.residuals.len())
            .map(|i| l.residuals[i] * l.sigma[i])
            .collect()
    };
    let ncols = state.n_params();
    assert_eq!(lin.jacobian.ncols(), ncols);
    for c in 0..ncols {
        let h = 1e-7;
        let mut delta = vec![0.0; ncols];
        delta[c] = h;
        let mut plus = state.clone();
        plus.apply(&delta);
        delta[c] = -h;
        let mut minus = state.clone();
        minus.apply(&delta);
        let (rp, rm) = (unweighted(&plus), unweighted(&minus));
        for i in 0..rp.len() {
            let fd = (rp[i] - rm[i]) / (2.0 * h);
            let an = lin.jacobian[(i, c)] * lin.sigma[i];
            assert!(
                (fd - an).abs() <= 1e-5 * an.abs().max(1e-3),
                "row {i}, {}: finite difference {fd} vs {an}",
                lin.names[c]
            );
        }
    }
}

#[test]
fn bad_inputs_are_errors() {
    let device = reference_device();
    let chain = device.chain().unwrap();
    let log = log(&device, 10);
    assert!(matches!(
        DistanceLog::new(vec![vec![0.0; 7]; 3], None, vec![1.0; 2], vec![vec![]; 3]),
        Err(Error::LengthMismatch {
            name: "distance_m",
            ..
        })
    ));
    assert!(matches!(
        DistanceLog::new(vec![vec![f64::NAN; 7]], None, vec![1.0], vec![vec![]]),
        Err(Error::NotFinite { row: 0 })
    ));
    let no_times = DistanceLog::new(
        log.q().to_vec(),
        None,
        log.distance_m().to_vec(),
        vec![vec![]; 10],
    )
    .unwrap();
    let mut m = model(&device, no_times);
    assert!(matches!(
        m.set_ext_joints(vec![0]),
        Err(Error::MissingReading { row: 0, joint: 1 })
    ));
    assert!(matches!(
        m.set_ext_joints(vec![9]),
        Err(Error::NoSuchJoint { joint: 10, .. })
    ));
    let mut s = m.initial_state(Vec::new());
    s.terms.push((
        EffectTerm {
            name: "latency.tau".into(),
            unit: "s",
            kind: EffectTermKind::Latency,
        },
        0.0,
    ));
    assert!(matches!(m.linearise(&s), Err(Error::NoSampleTimes { .. })));
    s.terms[0].0.kind = EffectTermKind::Joint {
        joint: 2,
        g: vec![0.0; 3],
    };
    assert!(matches!(m.linearise(&s), Err(Error::LengthMismatch { .. })));
    s.x_kin.pop();
    assert!(matches!(
        m.linearise(&s),
        Err(Error::LengthMismatch { name: "x_kin", .. })
    ));
    let noise = DistanceLogNoise::paper(20_000, 0.015, vec![0.0; 3]);
    assert!(matches!(
        DistanceLogModel::new(chain.clone(), log.clone(), noise, 0.2),
        Err(Error::LengthMismatch {
            name: "resolution_rad",
            ..
        })
    ));
    let q = log.q()[0].clone();
    assert!(distance_row(&chain, &[0.0; 3], &q, 1e-5, &[]).is_err());
    assert!(distance_row(&chain, &vec![0.0; chain.n_params()], &q[..3], 1e-5, &[]).is_err());
    assert!(distance_row(&chain, &vec![0.0; chain.n_params()], &q, 0.0, &[]).is_err());
    assert!(handle_gravity_torques_nm(&chain, &[0.0], &q, 0.2).is_err());
    // Two transmissions on one joint: the second would correct the reading again.
    let mut twice = model(&device, log.clone()).initial_state(transmissions(&device));
    let first = twice.transmissions[0].clone();
    twice.transmissions.push(first);
    assert!(matches!(
        model(&device, log.clone()).linearise(&twice),
        Err(Error::OutOfRange {
            name: "transmissions on one joint",
            ..
        })
    ));
    // An encoder of no counts has no finite noise.
    let none = DistanceLogNoise::paper(0, 0.015, vec![0.0; chain.n_joints()]);
    assert!(matches!(
        DistanceLogModel::new(chain.clone(), log, none, 0.2),
        Err(Error::BadSigma { .. })
    ));
}

#[test]
fn distance_row_adds_the_joint_variances() {
    let device = reference_device();
    let chain = device.chain().unwrap();
    let log = log(&device, 3);
    let x0 = vec![0.0; chain.n_params()];
    let q = &log.q()[1];
    let plain = distance_row(&chain, &x0, q, 1e-5, &[]).unwrap();
    assert_eq!(plain.sigma_m, 1e-5);
    assert!(plain.joint_gradient.is_empty());
    assert!((plain.distance_m - chain.end_point(&x0, q).coords.norm()).abs() < 1e-15);
    let var = vec![1e-8; chain.n_joints()];
    let noisy = distance_row(&chain, &x0, q, 1e-5, &var).unwrap();
    assert_eq!(noisy.jacobian, plain.jacobian);
    let expected: f64 = 1e-10
        + noisy
            .joint_gradient
            .iter()
            .map(|d| d * d * 1e-8)
            .sum::<f64>();
    assert!((noisy.sigma_m - expected.sqrt()).abs() < 1e-18);
    assert!(noisy.sigma_m > plain.sigma_m);
}

/// The reference device's model of an `n`-row log with its transmissions' external-encoder
/// rows and one handle compliance per joint, and a state: perturbed (the deviations of
/// [`x_kin`], compliance `1e-3·j` on joint j) or at zero.
fn compliance_model(n: usize, perturbed: bool) -> (DistanceLogModel, DistanceLogState) {
    let device = reference_device();
    let chain = device.chain().unwrap();
    let trans = transmissions(&device);
    let mut m = model(&device, log(&device, n));
    m.set_ext_joints(trans.iter().map(LogTransmission::joint).collect())
        .unwrap();
    let mut state = m.initial_state(trans);
    let scale = if perturbed { 1e-3 } else { 0.0 };
    if perturbed {
        state.x_kin = x_kin(&chain);
    }
    state.terms = (0..chain.n_joints())
        .map(|j| (EffectTerm::handle_compliance(j), scale * j as f64))
        .collect();
    (m, state)
}

#[test]
fn as_an_identify_problem_its_x_is_the_state_and_its_rows_the_linearisation() {
    let chain = reference_device().chain().unwrap();
    let (m, state) = compliance_model(30, true);
    let lin = m.linearise(&state).unwrap();
    let problem = crate::DistanceLogProblem::new(m, &state).unwrap();
    // Named, with units, in the model's column order: 3 capstans, 11 coefficients, the chain,
    // 7 compliances.
    let layout = problem.layout();
    assert_eq!(layout.len(), 3 * 6 + 11 + chain.n_params() + 7);
    let names: Vec<&str> = layout.specs().iter().map(|p| p.name.as_str()).collect();
    assert_eq!(
        names,
        lin.names.iter().map(String::as_str).collect::<Vec<_>>()
    );
    assert_eq!(names[1], "capstan1.re");
    assert_eq!(layout.spec(1).unit, hapcal_identify::Unit::Dimensionless);
    assert_eq!(names[layout.len() - 1], "joint_compliance.j7");
    // x holds the values themselves, and the state at x is the state.
    let x = problem.x_of(&state);
    assert_eq!(x[0], 1e-3);
    assert_eq!(problem.state(x.as_ref()), state);
    let mut r = Col::zeros(problem.n_residuals());
    let mut jac = faer::Mat::zeros(problem.n_residuals(), layout.len());
    problem
        .residuals_and_jacobian(x.as_ref(), r.as_mut(), jac.as_mut())
        .unwrap();
    for i in 0..r.nrows() {
        assert_eq!(r[i], lin.residuals[i]);
        for c in 0..layout.len() {
            assert_eq!(jac[(i, c)], lin.jacobian[(i, c)]);
        }
    }
}

#[test]
fn its_row_blocks_are_the_linearisation_rows_sample_by_sample() {
    // More samples than one block holds, and a last block shorter than the others.
    let n = crate::SAMPLES_PER_BLOCK + 37;
    let (m, state) = compliance_model(n, true);
    let n_ext = m.ext_joints().len();
    let lin = m.linearise(&state).unwrap();
    let distances = m.distance_residuals_m(&state).unwrap();
    assert_eq!(distances.len(), n);
    for (i, d) in distances.iter().enumerate() {
        assert_eq!(*d, lin.residuals[i] * lin.sigma[i]);
    }
    let problem = crate::DistanceLogProblem::new(m, &state).unwrap();
    let blocks = problem
        .row_blocks()
        .expect("compliance terms have row blocks");
    assert_eq!(blocks.n_blocks(), 2);
    let x = problem.x_of(&state);
    let ncols = problem.layout().len();
    let mut seen = 0;
    for b in 0..blocks.n_blocks() {
        let rows = blocks.block_rows(b);
        assert_eq!(rows.start, seen);
        seen = rows.end;
        let mut r = Col::zeros(rows.len());
        let mut jac = faer::Mat::zeros(rows.len(), ncols);
        blocks
            .block_jacobian(x.as_ref(), b, r.as_mut(), jac.as_mut())
            .unwrap();
        let mut r_only = Col::zeros(rows.len());
        blocks
            .block_residuals(x.as_ref(), b, r_only.as_mut())
            .unwrap();
        for k in 0..rows.len() {
            // Row k of the block: sample `first + k / (1 + n_ext)`, its distance row or its
            // external-encoder row `k % (1 + n_ext) − 1`.
            let sample = rows.start / (1 + n_ext) + k / (1 + n_ext);
            let section = k % (1 + n_ext);
            let dense = section * n + sample;
            assert_eq!(r[k], lin.residuals[dense]);
            assert_eq!(r_only[k], lin.residuals[dense]);
            for c in 0..ncols {
                assert_eq!(jac[(k, c)], lin.jacobian[(dense, c)], "row {k} column {c}");
            }
        }
    }
    assert_eq!(seen, problem.n_residuals());
}

#[test]
fn streamed_in_row_blocks_it_fits_what_the_dense_back_end_fits() {
    use hapcal_identify::{Backend, IdentifyConfig, identify};
    let (m, state) = compliance_model(2 * crate::SAMPLES_PER_BLOCK + 11, false);
    let problem = crate::DistanceLogProblem::new(m, &state).unwrap();
    let fit = |backend| {
        let cfg = IdentifyConfig {
            backend,
            sigma: None,
            ..IdentifyConfig::default()
        };
        identify(&problem, problem.x_of(&state), &cfg).unwrap()
    };
    let (dense, streamed) = (fit(Backend::Dense), fit(Backend::Streaming));
    assert_eq!(dense.identifiability.kept, streamed.identifiability.kept);
    // The same least-squares problem: the estimates agree far inside their uncertainty
    // (rounding of two QR orders, LM's tolerances).
    let std = dense.covariance.std();
    for (k, &i) in dense.covariance.free.iter().enumerate() {
        let gap = (dense.fit.x[i] - streamed.fit.x[i]).abs();
        assert!(
            gap < 1e-3 * std[k],
            "{}: gap {gap:e}, σ {:e}",
            problem.layout().name(i),
            std[k]
        );
    }
    assert!((dense.sigma - streamed.sigma).abs() < 1e-6 * dense.sigma);
}
