//! The simulator: determinism, the noise-free case, noise statistics, quantisation.

use hapcal_io::Device;
use hapcal_sim::{
    NoiseModel, SimConfig, Truth, joint_resolutions_rad, quantise_readings, sample_readings,
    simulate, true_joint_angles, truth_deviations,
};
use hapcal_transmission::{Capstan, FourBar, Joint4Transmission, JointRad};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::{mean, paper_truth, std_dev};

#[test]
fn equal_seeds_give_equal_logs_and_other_seeds_differ() {
    let (truth, device) = paper_truth();
    let a = simulate(&device, &truth, &SimConfig::new(7, 50)).unwrap();
    let b = simulate(&device, &truth, &SimConfig::new(7, 50)).unwrap();
    assert_eq!(a, b);
    assert_eq!(hapcal_io::write_log(&a), hapcal_io::write_log(&b));
    let c = simulate(&device, &truth, &SimConfig::new(8, 50)).unwrap();
    assert_eq!(c.len(), 50);
    for (ra, rc) in a.iter().zip(&c) {
        assert_ne!(ra.q, rc.q);
        assert_ne!(ra.distance_m, rc.distance_m);
    }
    // A longer log from the same seed starts with the same readings.
    let long = simulate(&device, &truth, &SimConfig::new(7, 80)).unwrap();
    assert_eq!(long.len(), 80);
    assert!(a.iter().zip(&long).all(|(x, y)| x.q == y.q));
}

#[test]
fn readings_are_the_seeded_samples() {
    let (truth, device) = paper_truth();
    let cfg = SimConfig::new(3, 20).with_quantise_joints(false);
    let rows = simulate(&device, &truth, &cfg).unwrap();
    let samples = sample_readings(&device, &mut ChaCha8Rng::seed_from_u64(3), 20);
    assert!(rows.iter().zip(&samples).all(|(r, s)| &r.q == s));
    assert!(rows.iter().enumerate().all(|(i, r)| r.line == i as u64 + 2));
}

#[test]
fn without_errors_noise_or_quantisation_distance_is_the_nominal_norm() {
    let (_, device) = paper_truth();
    let truth = Truth::nominal("device.toml".into(), &device);
    let cfg = SimConfig::new(11, 300)
        .with_noise(NoiseModel::none())
        .with_quantise_joints(false);
    let rows = simulate(&device, &truth, &cfg).unwrap();
    let chain = device.chain().unwrap();
    let x = vec![0.0; chain.n_params()];
    for row in &rows {
        let expected = chain.end_point(&x, &row.q).coords.norm();
        assert!(
            (row.distance_m - expected).abs() < 1e-12,
            "line {}: {} vs {expected}",
            row.line,
            row.distance_m
        );
        for (k, ext) in row.ext.iter().enumerate() {
            let ext = ext.expect("joints 1-4 have external encoders");
            assert!(
                (ext - row.q[k]).abs() < 1e-12,
                "line {}: ext{}",
                row.line,
                k + 1
            );
        }
    }
}

#[test]
fn truth_errors_move_the_distance() {
    // The counterpart of the test above: with the paper's truth, distances differ from the
    // nominal model by millimetres (Fig. 8 of the paper shows errors up to ~8 mm).
    let (truth, device) = paper_truth();
    let cfg = SimConfig::new(11, 300).with_noise(NoiseModel::none());
    let rows = simulate(&device, &truth, &cfg).unwrap();
    let chain = device.chain().unwrap();
    let nominal = vec![0.0; chain.n_params()];
    let x = truth_deviations(&chain, &truth).unwrap();
    let errors: Vec<f64> = (rows.iter())
        .map(|r| r.distance_m - chain.end_point(&nominal, &r.q).coords.norm())
        .collect();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    assert!((5e-4..2e-2).contains(&rms), "rms {rms} m");
    // …and exactly what the truth chain at the true joint angles gives.
    for r in &rows {
        let q_true = true_joint_angles(&device, &truth, &r.q).unwrap();
        let d = chain.end_point(&x, &q_true).coords.norm();
        assert!((r.distance_m - d).abs() < 1e-15, "line {}", r.line);
    }
}

#[test]
fn true_joint_angles_follow_the_transmission_models() {
    let (truth, device) = paper_truth();
    let theta = [0.4, -0.2, 0.7, 0.9, 1.5, -1.1, 2.4];
    let q = true_joint_angles(&device, &truth, &theta).unwrap();
    for j in 0..3 {
        let c = &device.capstans[j];
        let capstan = Capstan::try_new(c.ratio, c.drum_distance_m).unwrap();
        let expected = capstan.output_rad(&truth.capstans[j].params(), JointRad(theta[j]));
        assert_eq!(q[j], expected, "joint {}", j + 1);
        assert!(
            (q[j] - theta[j]).abs() > 1e-4,
            "joint {} has an error",
            j + 1
        );
    }
    let (c, p, pt) = (
        device.capstans[3],
        device.parallelogram.unwrap(),
        truth.parallelogram.unwrap(),
    );
    let j4 = Joint4Transmission {
        capstan: Capstan::try_new(c.ratio, c.drum_distance_m).unwrap(),
        params: truth.capstans[3].params(),
        four_bar: FourBar::try_new(p.l1_m - 0.5e-3, p.l2_m - 0.7e-3, p.l3_m, p.l4_m).unwrap(),
        phi0_rad: pt.phi0_rad,
    };
    assert_eq!(q[3], j4.output_rad(JointRad(theta[3])).unwrap());
    assert!((q[3] - theta[3]).abs() > 1e-3);
    assert_eq!(q[4..], theta[4..]);
}

/// The paper's truth without kinematic deviations.
fn transmissions_only() -> (Truth, Device) {
    let (mut truth, device) = paper_truth();
    truth.deviations.clear();
    (truth, device)
}

#[test]
fn noise_has_the_configured_standard_deviations() {
    let (truth, device) = transmissions_only();
    let cable = device.cable_encoder.unwrap();
    let noise = NoiseModel::paper(&cable);
    let sigma_e = 2.0 * std::f64::consts::PI / 20000.0 / 3.0;
    assert!((noise.sigma_e_rad - sigma_e).abs() < 1e-18);
    assert!(
        (noise.sigma_m_m - 9.8696e-6).abs() < 1e-9,
        "{}",
        noise.sigma_m_m
    );
    let arc = NoiseModel::arc_length(&cable);
    assert!((arc.sigma_m_m - 0.015 * sigma_e).abs() < 1e-18);

    let n = 2000;
    let rows = simulate(&device, &truth, &SimConfig::new(5, n).with_noise(noise)).unwrap();
    let chain = device.chain().unwrap();
    let x = vec![0.0; chain.n_params()];
    let mut distance_noise = Vec::with_capacity(n);
    let mut ext_noise: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(n)).collect();
    for r in &rows {
        let q_true = true_joint_angles(&device, &truth, &r.q).unwrap();
        distance_noise.push(r.distance_m - chain.end_point(&x, &q_true).coords.norm());
        for (k, e) in ext_noise.iter_mut().enumerate() {
            e.push(r.ext[k].unwrap() - q_true[k]);
        }
    }
    // Relative standard error of a sample std is 1/√(2n) ≈ 1.6 %; 5 % is ≈ 3 of them.
    let (s, m) = (std_dev(&distance_noise), mean(&distance_noise));
    assert!(
        (s / noise.sigma_m_m - 1.0).abs() < 0.05,
        "σ_m {s} vs {}",
        noise.sigma_m_m
    );
    assert!(
        m.abs() < 4.0 * noise.sigma_m_m / (n as f64).sqrt(),
        "mean {m}"
    );
    for (k, e) in ext_noise.iter().enumerate() {
        let (s, m) = (std_dev(e), mean(e));
        assert!(
            (s / sigma_e - 1.0).abs() < 0.05,
            "ext{}: σ_e {s} vs {sigma_e}",
            k + 1
        );
        assert!(
            m.abs() < 4.0 * sigma_e / (n as f64).sqrt(),
            "ext{}: mean {m}",
            k + 1
        );
    }
    // The arc-length model is 2π times quieter.
    let rows = simulate(&device, &truth, &SimConfig::new(5, n).with_noise(arc)).unwrap();
    let d: Vec<f64> = (rows.iter())
        .map(|r| {
            let q_true = true_joint_angles(&device, &truth, &r.q).unwrap();
            r.distance_m - chain.end_point(&x, &q_true).coords.norm()
        })
        .collect();
    assert!((std_dev(&d) / arc.sigma_m_m - 1.0).abs() < 0.05);
}

#[test]
fn invalid_noise_is_rejected() {
    let (truth, device) = paper_truth();
    for (noise, message) in [
        (
            NoiseModel::new(-1e-4, 1e-6),
            "noise sigma_e_rad = -0.0001 is not a finite, non-negative standard deviation",
        ),
        (
            NoiseModel::new(1e-4, f64::NAN),
            "noise sigma_m_m = NaN is not a finite, non-negative standard deviation",
        ),
    ] {
        let err = simulate(&device, &truth, &SimConfig::new(1, 2).with_noise(noise)).unwrap_err();
        assert_eq!(err.to_string(), message);
    }
}

/// `true` if `v` is a multiple of `res` to 1e-9 relative.
fn is_multiple(v: f64, res: f64) -> bool {
    let k = v / res;
    (k - k.round()).abs() <= 1e-9 * k.abs().max(1.0)
}

#[test]
fn quantised_readings_are_multiples_of_the_joint_side_resolution() {
    let (truth, device) = paper_truth();
    let tau = std::f64::consts::TAU;
    let res: Vec<f64> = joint_resolutions_rad(&device)
        .into_iter()
        .map(Option::unwrap)
        .collect();
    let expected = [
        tau / 200_000.0,
        tau / 240_000.0,
        tau / 220_000.0,
        tau / 240_000.0,
        tau / 20_000.0,
        tau / 20_000.0,
        tau / 20_000.0,
    ];
    for (r, e) in res.iter().zip(expected) {
        assert!((r - e).abs() < 1e-18);
    }
    let limits = device.joint_limits();
    let rows = simulate(&device, &truth, &SimConfig::new(2, 2000)).unwrap();
    for r in &rows {
        for (j, &q) in r.q.iter().enumerate() {
            assert!(is_multiple(q, res[j]), "line {} q{}: {q}", r.line, j + 1);
            assert!((limits[j].0..=limits[j].1).contains(&q));
        }
    }
    // Unquantised readings are (almost surely) not multiples: the check above can fail.
    let raw = SimConfig::new(2, 50).with_quantise_joints(false);
    let rows = simulate(&device, &truth, &raw).unwrap();
    let n_multiples = (rows.iter())
        .flat_map(|r| r.q.iter().zip(&res).map(|(&q, &res)| is_multiple(q, res)))
        .filter(|&m| m)
        .count();
    assert_eq!(n_multiples, 0);
}

#[test]
fn quantisation_stays_within_the_limits() {
    let (_, device) = paper_truth();
    let limits = device.joint_limits();
    let res: Vec<f64> = joint_resolutions_rad(&device)
        .into_iter()
        .map(Option::unwrap)
        .collect();
    for pick in [|l: (f64, f64)| l.0, |l: (f64, f64)| l.1] {
        let theta: Vec<f64> = limits.iter().map(|&l| pick(l)).collect();
        let q = quantise_readings(&device, &theta);
        for j in 0..7 {
            assert!(
                (limits[j].0..=limits[j].1).contains(&q[j]),
                "q{}: {}",
                j + 1,
                q[j]
            );
            assert!(is_multiple(q[j], res[j]));
            assert!((q[j] - theta[j]).abs() <= res[j]);
        }
    }
}

#[test]
fn samples_cover_the_joint_ranges() {
    let (_, device) = paper_truth();
    let samples = sample_readings(&device, &mut ChaCha8Rng::seed_from_u64(9), 2000);
    assert_eq!(samples.len(), 2000);
    for (j, &(lower, upper)) in device.joint_limits().iter().enumerate() {
        let v: Vec<f64> = samples.iter().map(|s| s[j]).collect();
        let (lo, hi) = v
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        let span = upper - lower;
        assert!(lo >= lower && hi <= upper);
        assert!(
            lo < lower + 0.01 * span && hi > upper - 0.01 * span,
            "q{}",
            j + 1
        );
        // Uniform: mean at mid-range, std span/√12.
        assert!((mean(&v) - 0.5 * (lower + upper)).abs() < 0.02 * span);
        assert!((std_dev(&v) / (span / 12f64.sqrt()) - 1.0).abs() < 0.05);
    }
}
