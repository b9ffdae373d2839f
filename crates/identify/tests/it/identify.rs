//! The whole procedure: prune, fit, re-decide at the estimate, covariance.

use faer::{Col, Mat, col};
use hapcal_identify::{
    Error, IdentifyConfig, ParamLayout, PruneReason, Role, SigmaSource, Unit, identify,
};

use crate::problems::{
    Curve, Linear, assert_standard_normal, meters, normal, random_matrix, rng, spec,
};

/// `y = a·t + a·b·t²` and its gradient in `(a, b)`: at `a = 0` the column of `b` is zero, at
/// the estimate it is not.
fn product_model([a, b]: [f64; 2], t: f64) -> (f64, [f64; 2]) {
    (a * t + a * b * t * t, [t + b * t * t, a * t * t])
}

fn product(sigma: f64, seed: u64) -> Curve {
    let (a, b) = (0.5, 0.2);
    let mut rng = rng(seed);
    let t: Vec<f64> = (1..=40).map(|i| 0.05 * i as f64).collect();
    let y = t
        .iter()
        .map(|&t| a * t + a * b * t * t + sigma * normal(&mut rng))
        .collect();
    let layout = ParamLayout::new(vec![
        spec("a", Unit::Dimensionless, Role::Model),
        spec("b", Unit::Dimensionless, Role::Model),
    ]);
    Curve {
        layout,
        t,
        y,
        model: product_model,
    }
}

#[test]
fn identifiability_is_decided_again_at_the_estimate() {
    // At x0 = (0, 0) the column of b is zero, so round 1 fits a alone; at that estimate b's
    // column is a·t², which the data determine: round 2 refits (a, b) and the decision holds.
    let sigma = 1e-4;
    let p = product(sigma, 30);
    let id = identify(&p, Col::zeros(2), &IdentifyConfig::default()).expect("valid");
    assert_eq!(id.rounds, 2);
    assert!(id.pruning_converged);
    assert_eq!(id.identifiability.kept, [0, 1]);
    assert!(id.fit.termination.is_success(), "{:?}", id.fit.termination);
    assert_eq!(id.sigma_source, SigmaSource::Residuals);
    assert!(
        (0.7 * sigma..1.3 * sigma).contains(&id.sigma),
        "sigma {}",
        id.sigma
    );
    for (name, truth) in [("a", 0.5), ("b", 0.2)] {
        let (value, std) = (id.value(name).expect("a"), id.std(name).expect("kept"));
        assert!(
            (value - truth).abs() < 4.0 * std,
            "{name} = {value} ± {std}"
        );
    }
}

#[test]
fn given_sigma_is_used_as_is() {
    let p = product(1e-4, 31);
    let cfg = IdentifyConfig {
        sigma: Some(2e-4),
        ..IdentifyConfig::default()
    };
    let id = identify(&p, Col::zeros(2), &cfg).expect("valid");
    assert_eq!(id.sigma_source, SigmaSource::Given);
    assert_eq!(id.sigma, 2e-4);
    assert_eq!(id.std("nope"), None);
}

#[test]
fn pruned_duplicate_and_covariance_are_consistent_over_500_trials() {
    // p3 duplicates p1 (pruned every time, the same one); the kept estimates normalised by
    // their std (with sigma estimated from the residuals: Student t with 36 degrees of
    // freedom, std √(36/34) ≈ 1.03) must have a standard deviation within 0.9–1.1 (sampling
    // error ±3/√1000 ≈ ±0.095).
    let sigma = 1e-3;
    let truth = [0.01, -0.02, 0.005];
    let mut rng = rng(32);
    let base = random_matrix(&mut rng, 40, 3);
    let a = Mat::from_fn(40, 4, |i, j| base[(i, [0, 1, 2, 1][j])]);
    let x_truth = col![truth[0], truth[1], truth[2], 0.0];
    let mut errors = vec![Vec::new(); 3];
    for _ in 0..500 {
        let y = &a * &x_truth + Col::from_fn(40, |_| sigma * normal(&mut rng));
        let p = Linear {
            layout: meters(4),
            a: a.clone(),
            y,
        };
        let id = identify(&p, Col::zeros(4), &IdentifyConfig::default()).expect("valid");
        assert_eq!(id.identifiability.pruned_names(), ["p3"]);
        assert!(
            matches!(&id.identifiability.pruned[0].reason, PruneReason::Dependent { on } if on[0].0 == "p1")
        );
        for (j, e) in errors.iter_mut().enumerate() {
            let name = format!("p{j}");
            let std = id.std(&name).expect("kept");
            e.push((id.value(&name).expect("in layout") - truth[j]) / std);
        }
    }
    assert_standard_normal(&errors);
}

#[test]
fn bad_configuration_and_no_degrees_of_freedom_are_errors() {
    let p = product(1e-4, 33);
    let cfg = IdentifyConfig {
        sigma: Some(-1.0),
        ..IdentifyConfig::default()
    };
    let err = identify(&p, Col::zeros(2), &cfg).expect_err("negative sigma");
    assert_eq!(
        err.to_string(),
        "sigma = -1 is invalid: it must be finite and positive"
    );
    let err = identify(&p, Col::zeros(3), &IdentifyConfig::default()).expect_err("length");
    assert_eq!(
        err,
        Error::WrongLength {
            expected: 2,
            found: 3
        }
    );
    // Two residuals, two identifiable parameters: nothing left to estimate sigma.
    let square = Linear {
        layout: meters(2),
        a: Mat::<f64>::identity(2, 2) * 100.0,
        y: col![0.01, 0.02],
    };
    let err = identify(&square, Col::zeros(2), &IdentifyConfig::default()).expect_err("dof");
    assert_eq!(
        err,
        Error::NoDegreesOfFreedom {
            n_residuals: 2,
            n_free: 2
        }
    );
    let cfg = IdentifyConfig {
        sigma: Some(0.1),
        ..IdentifyConfig::default()
    };
    let id = identify(&square, Col::zeros(2), &cfg).expect("sigma given");
    assert!((id.value("p1").expect("p1") - 2e-4).abs() < 1e-15);
}

#[test]
fn a_held_parameter_is_reported_at_its_bound_and_the_others_equal_a_fit_without_it() {
    // Five parameters of a linear model, one of them (p2, truth −1e-4, noise 1e-3 per row)
    // held at zero: the result lists p2 as held at its bound with the σ given, keeps it at
    // zero, and every other estimate, σ and the noise level are those of identify on the
    // problem whose p2 is fixed at zero (a Subset), to rounding.
    let mut rng = rng(47);
    let a = random_matrix(&mut rng, 60, 5);
    let x_truth = col![0.01, -0.02, -1e-4, 0.005, 0.03];
    let y = &a * &x_truth + Col::from_fn(60, |_| 1e-3 * normal(&mut rng));
    let p = Linear {
        layout: meters(5),
        a,
        y,
    };
    let cfg = IdentifyConfig::default();
    let held =
        hapcal_identify::identify_held(&p, Col::zeros(5), &cfg, &[(2, 1.5e-4)]).expect("valid");
    let without = hapcal_identify::Subset::new(&p, vec![0, 1, 3, 4], Col::zeros(5));
    let reference = identify(&without, without.initial_free(), &cfg).expect("valid");
    assert_eq!(held.layout, p.layout);
    assert_eq!(held.fit.x[2], 0.0);
    let at_bound = held.identifiability.find_pruned("p2").expect("reported");
    assert_eq!(at_bound.reason, PruneReason::AtBound);
    assert_eq!(at_bound.index, 2);
    assert_eq!(at_bound.std_if_kept, 1.5e-4);
    assert_eq!(held.identifiability.kept, [0, 1, 3, 4]);
    assert_eq!(held.covariance.free, [0, 1, 3, 4]);
    assert_eq!(held.identifiability.pivot_order.len(), 5);
    assert_eq!(held.identifiability.r_diag.len(), 5);
    for (k, &j) in [0, 1, 3, 4].iter().enumerate() {
        assert!((held.fit.x[j] - reference.fit.x[k]).abs() <= 1e-12, "{j}");
        let (s, r) = (held.std(&format!("p{j}")), reference.std(&format!("p{j}")));
        assert_eq!(s, r, "{j}");
    }
    assert_eq!(held.sigma, reference.sigma);
    // Holding a parameter can only raise the cost of the fit that had it free.
    let free = identify(&p, Col::zeros(5), &cfg).expect("valid");
    assert!(held.fit.cost >= free.fit.cost);
}
