//! Covariance: exact against the normal equations, calibrated against Monte Carlo.

use faer::{Col, Mat};
use hapcal_identify::{LmConfig, covariance, levenberg_marquardt};

use crate::problems::{Linear, assert_standard_normal, meters, normal, random_matrix, rng};

/// Inverse of a 3 × 3 matrix by cofactors (independent of any QR).
fn inverse3(a: &Mat<f64>) -> Mat<f64> {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[(r0, c0)] * a[(r1, c1)] - a[(r0, c1)] * a[(r1, c0)]
    };
    let det = a[(0, 0)] * c(0, 0) + a[(0, 1)] * c(0, 1) + a[(0, 2)] * c(0, 2);
    Mat::from_fn(3, 3, |i, j| c(j, i) / det)
}

#[test]
fn covariance_equals_sigma_squared_times_inverse_normal_matrix() {
    let mut rng = rng(20);
    let mut jac = random_matrix(&mut rng, 12, 4);
    // Unequal column scales (m, rad, mm…) and a moderate correlation between columns 0 and 2.
    for i in 0..12 {
        jac[(i, 0)] *= 100.0;
        jac[(i, 2)] = 0.01 * (jac[(i, 2)] + 0.5 * jac[(i, 0)] / 100.0);
    }
    let free = [0, 2, 3];
    let sigma = 0.3;
    let cov = covariance(jac.as_ref(), &meters(4), &free, sigma).expect("full rank");
    let jf = Mat::from_fn(12, 3, |i, k| jac[(i, free[k])]);
    let naive = inverse3(&(jf.transpose() * &jf)) * (sigma * sigma);
    for a in 0..3 {
        for b in 0..3 {
            let scale = (naive[(a, a)] * naive[(b, b)]).sqrt();
            let err = (cov.matrix[(a, b)] - naive[(a, b)]).abs() / scale;
            assert!(
                err < 1e-10,
                "({a}, {b}): {} vs {}",
                cov.matrix[(a, b)],
                naive[(a, b)]
            );
        }
    }
    assert_eq!(cov.free, free);
    assert_eq!(cov.names, ["p0", "p2", "p3"]);
    // The constructed correlation between p0 and p2 is the strongest pair.
    let corr = cov.correlation();
    let pairs = cov.correlated_pairs(0.0);
    assert_eq!(pairs.len(), 3);
    assert_eq!((pairs[0].0, pairs[0].1), (0, 2));
    assert!((pairs[0].2 - corr[(0, 1)]).abs() < 1e-15);
    assert!((pairs[0].2 - naive[(0, 1)] / (naive[(0, 0)] * naive[(1, 1)]).sqrt()).abs() < 1e-10);
    assert!(cov.correlated_pairs(1.1).is_empty());
}

#[test]
fn normalised_errors_have_unit_standard_deviation_over_500_trials() {
    // r = J·x − y with y = J·x* + N(0, σ²): (x̂ − x*) / std must be N(0, 1). With 500 trials the
    // sample standard deviation is within ±3·1/√(2·500) ≈ ±0.095 of 1 and the mean within
    // ±3/√500 ≈ ±0.13 of 0.
    let sigma = 1e-3;
    let truth = [0.01, -0.02, 0.005];
    let mut rng = rng(21);
    let jac = random_matrix(&mut rng, 30, 3);
    let cov = covariance(jac.as_ref(), &meters(3), &[0, 1, 2], sigma).expect("full rank");
    let std = cov.std();
    let mut errors = vec![Vec::new(); 3];
    for _ in 0..500 {
        let x_truth = Col::from_fn(3, |j| truth[j]);
        let y = &jac * &x_truth + Col::from_fn(30, |_| sigma * normal(&mut rng));
        let p = Linear {
            layout: meters(3),
            a: jac.clone(),
            y,
        };
        let fit = levenberg_marquardt(&p, Col::zeros(3), &[0, 1, 2], &LmConfig::default())
            .expect("valid");
        assert!(fit.termination.is_success(), "{:?}", fit.termination);
        for j in 0..3 {
            errors[j].push((fit.x[j] - truth[j]) / std[j]);
        }
    }
    assert_standard_normal(&errors);
}
