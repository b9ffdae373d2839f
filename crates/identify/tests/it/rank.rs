//! Pruning: dependent, zero, nuisance and rescaled columns.

use faer::Mat;
use hapcal_identify::{
    Identifiability, ParamLayout, PruneReason, RankConfig, RankConfigBase, Role, Unit,
    identifiability,
};
use proptest::prelude::*;

use crate::problems::{meters, random_matrix, rng, spec};

fn cfg(sigma: f64) -> RankConfig {
    RankConfigBase::default().with_sigma(sigma)
}

fn all(n: usize) -> Vec<usize> {
    (0..n).collect()
}

/// `base` with one more column, entry `i` of which is `last(row i of base)`.
fn with_last_column(base: &Mat<f64>, last: impl Fn(&dyn Fn(usize) -> f64) -> f64) -> Mat<f64> {
    let n = base.ncols();
    Mat::from_fn(base.nrows(), n + 1, |i, j| {
        if j == n {
            last(&|k| base[(i, k)])
        } else {
            base[(i, j)]
        }
    })
}

/// The `(name, coefficient)` list of a `Dependent` reason; panics otherwise.
fn dependent_on<'a>(id: &'a Identifiability, name: &str) -> &'a [(String, f64)] {
    match &id.find_pruned(name).expect("pruned").reason {
        PruneReason::Dependent { on } => on,
        other => panic!("{name}: expected Dependent, got {other:?}"),
    }
}

#[test]
fn duplicated_column_with_factor_two_prunes_exactly_one_of_the_pair() {
    // p4's column is 2× p1's: a change δ of p4 is reproduced by 2δ of p1. The pair ties, so
    // the one earlier in the layout (p1) is kept.
    let mut rng = rng(10);
    let base = random_matrix(&mut rng, 30, 4);
    let jac = with_last_column(&base, |row| 2.0 * row(1));
    let id = identifiability(jac.as_ref(), &meters(5), &all(5), &cfg(1e-6));
    assert_eq!(id.kept, [0, 1, 2, 3]);
    assert_eq!(id.pruned_names(), ["p4"]);
    let on = dependent_on(&id, "p4");
    assert_eq!(on.len(), 1, "{on:?}");
    assert_eq!(on[0].0, "p1");
    assert!((on[0].1 - 2.0).abs() < 1e-10, "{on:?}");
    assert!(
        id.pruned[0].std_if_kept > 1e3,
        "{}",
        id.pruned[0].std_if_kept
    );
    assert_eq!(id.pivot_order.len(), 5);
    assert_eq!(id.r_diag.len(), 5);
}

#[test]
fn zero_column_is_near_zero() {
    let mut rng = rng(11);
    let base = random_matrix(&mut rng, 20, 3);
    let jac = Mat::from_fn(20, 4, |i, j| if j == 2 { 0.0 } else { base[(i, j.min(2))] });
    let id = identifiability(jac.as_ref(), &meters(4), &all(4), &cfg(1e-6));
    assert_eq!(id.kept, [0, 1, 3]);
    assert_eq!(id.pruned.len(), 1);
    assert_eq!(id.pruned[0].reason, PruneReason::NearZeroColumn);
    assert_eq!(id.pruned[0].std_if_kept, f64::INFINITY);
    assert_eq!(id.pruned[0].reason.to_string(), "near-zero column");
}

#[test]
fn nuisance_is_kept_and_the_model_parameter_it_duplicates_is_pruned() {
    // socket.x (last in the layout) has −3× the column of p0. The nuisance parameter is pivoted
    // first and kept; p0 is dependent on it: δp0 is reproduced by −δ/3 of socket.x. A second
    // nuisance parameter is weak (std 10 m ≫ prior 0.01 m) but still kept: nuisance parameters
    // are pruned only when numerically dependent.
    let mut rng = rng(12);
    let base = random_matrix(&mut rng, 25, 3);
    let jac = Mat::from_fn(25, 5, |i, j| match j {
        0..=2 => base[(i, j)],
        3 => -3.0 * base[(i, 0)],
        _ => {
            if i == 0 {
                1e-7
            } else {
                0.0
            }
        }
    });
    let layout = ParamLayout::new(vec![
        spec("p0", Unit::Meter, Role::Model),
        spec("p1", Unit::Meter, Role::Model),
        spec("p2", Unit::Radian, Role::Model),
        spec("socket.x", Unit::Meter, Role::Nuisance),
        spec("socket.y", Unit::Meter, Role::Nuisance),
    ]);
    let id = identifiability(jac.as_ref(), &layout, &all(5), &cfg(1e-6));
    assert_eq!(id.kept, [1, 2, 3, 4]);
    assert_eq!(id.pivot_order[..2], [3, 4], "nuisance first");
    let on = dependent_on(&id, "p0");
    assert_eq!(on[0].0, "socket.x");
    assert!((on[0].1 + 1.0 / 3.0).abs() < 1e-10, "{on:?}");
}

#[test]
fn noise_decides_between_kept_and_insensitive() {
    // p2's column is orthogonal to the others with norm 1e-3: std = sigma / 1e-3. With
    // sigma = 1e-6 it is 1e-3 m (kept, prior 0.01 m); with sigma = 1e-4 it is 0.1 m (pruned).
    let jac = Mat::from_fn(3, 3, |i, j| if i == j { [1.0, 2.0, 1e-3][j] } else { 0.0 });
    let kept = identifiability(jac.as_ref(), &meters(3), &all(3), &cfg(1e-6));
    assert_eq!(kept.kept, [0, 1, 2]);
    let pruned = identifiability(jac.as_ref(), &meters(3), &all(3), &cfg(1e-4));
    assert_eq!(pruned.kept, [0, 1]);
    assert_eq!(pruned.pruned[0].reason, PruneReason::Insensitive);
    assert!((pruned.pruned[0].std_if_kept - 0.1).abs() < 1e-12);
}

#[test]
fn changing_the_unit_of_one_parameter_does_not_change_the_kept_set() {
    // p5 = p1 + p2 (a dependent triple). Expressing p1 in mm divides its column by 1000;
    // the kept set is the same and the coefficient on p1 is 1000× larger.
    let mut rng = rng(13);
    let base = random_matrix(&mut rng, 40, 5);
    let jac = with_last_column(&base, |row| row(1) + row(2));
    let mut jac_mm = jac.clone();
    for i in 0..40 {
        jac_mm[(i, 1)] /= 1000.0;
    }
    let id = identifiability(jac.as_ref(), &meters(6), &all(6), &cfg(1e-9));
    let id_mm = identifiability(jac_mm.as_ref(), &meters(6), &all(6), &cfg(1e-9));
    assert_eq!(id.kept.len(), 5);
    assert_eq!(id.kept, id_mm.kept);
    let (on, on_mm) = (dependent_on(&id, "p5"), dependent_on(&id_mm, "p5"));
    let coefficient = |on: &[(String, f64)], name: &str| {
        on.iter()
            .find(|(n, _)| n == name)
            .map(|(_, c)| *c)
            .expect("listed")
    };
    assert!((coefficient(on, "p1") - 1.0).abs() < 1e-10, "{on:?}");
    assert!(
        (coefficient(on_mm, "p1") - 1000.0).abs() < 1e-7,
        "{on_mm:?}"
    );
    assert!((coefficient(on_mm, "p2") - 1.0).abs() < 1e-10, "{on_mm:?}");
}

#[test]
fn candidates_restrict_the_decision() {
    let mut rng = rng(14);
    let jac = random_matrix(&mut rng, 10, 4);
    let id = identifiability(jac.as_ref(), &meters(4), &[3, 1], &cfg(1e-6));
    assert_eq!(id.kept, [1, 3]);
    assert!(id.pruned.is_empty());
}

fn dependent_jacobian(seed: u64, alpha: f64, beta: f64) -> Mat<f64> {
    let base = random_matrix(&mut rng(seed), 20, 5);
    with_last_column(&base, |row| alpha * row(0) + beta * row(3))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn reported_coefficients_reproduce_the_pruned_column(
        seed in 0u64..1000, alpha in 0.5..2.0f64, beta in -2.0..-0.5f64,
    ) {
        let jac = dependent_jacobian(seed, alpha, beta);
        let layout = meters(6);
        let id = identifiability(jac.as_ref(), &layout, &all(6), &cfg(1e-9));
        prop_assert_eq!(id.kept.len(), 5);
        prop_assert_eq!(id.pruned.len(), 1);
        let pruned = &id.pruned[0];
        prop_assert!([0, 3, 5].contains(&pruned.index));
        let PruneReason::Dependent { on } = &pruned.reason else {
            return Err(TestCaseError::fail(format!("{:?}", pruned.reason)));
        };
        // J[:, pruned] = Σ coefficient·J[:, kept] (exactly dependent: all coefficients listed).
        let mut diff = jac.col(pruned.index).to_owned();
        for (name, coefficient) in on {
            let j = layout.index_of(name).expect("a layout name");
            diff -= *coefficient * jac.col(j);
        }
        prop_assert!(diff.norm_l2() < 1e-10 * jac.col(pruned.index).norm_l2(), "{:?}", on);
    }

    #[test]
    fn kept_set_is_invariant_under_column_scaling(
        seed in 0u64..1000, exponents in prop::collection::vec(-3.0..3.0f64, 6),
    ) {
        let jac = dependent_jacobian(seed, 1.0, -1.0);
        let scaled = Mat::from_fn(20, 6, |i, j| jac[(i, j)] * 10f64.powf(exponents[j]));
        let id = identifiability(jac.as_ref(), &meters(6), &all(6), &cfg(1e-9));
        let id_scaled = identifiability(scaled.as_ref(), &meters(6), &all(6), &cfg(1e-9));
        prop_assert_eq!(id.kept, id_scaled.kept);
    }
}

/// A tilt (rad, column `tilt_norm·e₀`) and a compliance of `unit` whose column, of norm
/// `c`, makes the angle `theta` with the tilt's: `c·(cos θ·e₀ + sin θ·e₁)`. Given the tilt,
/// the compliance's standard deviation is `sigma / (c·sin θ)`.
fn tilt_and_compliance(tilt_norm: f64, c: f64, theta: f64, unit: Unit) -> (Mat<f64>, ParamLayout) {
    let jac = Mat::from_fn(3, 2, |i, j| match (i, j) {
        (0, 0) => tilt_norm,
        (0, 1) => c * theta.cos(),
        (1, 1) => c * theta.sin(),
        _ => 0.0,
    });
    let layout = ParamLayout::new(vec![
        spec("tilt", Unit::Radian, Role::Model),
        spec("compliance", unit, Role::Model),
    ]);
    (jac, layout)
}

#[test]
fn a_compliance_the_data_cannot_separate_from_a_tilt_is_pruned_under_its_physical_prior() {
    // 2 mm of noise; the compliance's column is 10 m per rad/(N·m) (a 0.5 m lever under
    // 20 N·m) at 2.9° from the tilt's (correlation 0.9987): given the tilt its standard
    // deviation is 2e-3 / (10·0.05) = 4e-3 rad/(N·m), twice the 2e-3 prior: pruned, as
    // dependent on the tilt (coefficient 10·cos θ rad per rad/(N·m)). The tilt itself is
    // determined to 2e-3 rad.
    let sigma = 2e-3;
    let theta = 0.05_f64.asin();
    let (jac, layout) = tilt_and_compliance(1.0, 10.0, theta, Unit::RadianPerNewtonMeter);
    let id = identifiability(jac.as_ref(), &layout, &all(2), &cfg(sigma));
    assert_eq!(id.kept, [0]);
    let pruned = id.find_pruned("compliance").expect("pruned");
    assert!((pruned.std_if_kept - 4e-3).abs() < 1e-12, "{pruned:?}");
    let on = dependent_on(&id, "compliance");
    assert_eq!(on.len(), 1);
    assert_eq!(on[0].0, "tilt");
    assert!((on[0].1 - 10.0 * theta.cos()).abs() < 1e-10, "{on:?}");
    // Loosened to the angle prior (what such a parameter was held to as an angle): kept.
    let loose = RankConfigBase {
        prior_rad_per_n_m: RankConfigBase::default().prior_rad,
        ..RankConfigBase::default()
    };
    let kept = identifiability(jac.as_ref(), &layout, &all(2), &loose.with_sigma(sigma));
    assert_eq!(kept.kept, [0, 1]);
    // The lumped compliance (rad/m) keeps the angle prior's 1e-2: kept too.
    let (jac_lumped, layout_lumped) = tilt_and_compliance(1.0, 10.0, theta, Unit::RadianPerMeter);
    let lumped = identifiability(jac_lumped.as_ref(), &layout_lumped, &all(2), &cfg(sigma));
    assert_eq!(lumped.kept, [0, 1]);
    // Ten times farther from the tilt (sin θ = 0.5): 4e-4 rad/(N·m), within the prior.
    let (jac_far, _) = tilt_and_compliance(1.0, 10.0, 0.5_f64.asin(), Unit::RadianPerNewtonMeter);
    let far = identifiability(jac_far.as_ref(), &layout, &all(2), &cfg(sigma));
    assert_eq!(far.kept, [0, 1]);
}

#[test]
fn compliance_units_have_their_symbols() {
    assert_eq!(Unit::RadianPerNewtonMeter.symbol(), "rad/(N·m)");
    assert_eq!(Unit::RadianPerMeter.symbol(), "rad/m");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// The compliance is kept exactly when its standard deviation given the tilt,
    /// `sigma / (c·sin θ)`, is within the compliance prior (not the angle prior, which stays at
    /// its default), and pruned as dependent on the tilt otherwise.
    #[test]
    fn a_compliance_is_kept_exactly_when_its_std_is_within_its_prior(
        theta in 1e-3..1.5f64, log_c in -1.0..2.0f64, log_prior in -5.0..-1.0f64,
    ) {
        let (sigma, c, prior) = (2e-3, 10f64.powf(log_c), 10f64.powf(log_prior));
        let std = sigma / (c * theta.sin());
        prop_assume!((std / prior - 1.0).abs() > 1e-6);
        let (jac, layout) = tilt_and_compliance(1.0, c, theta, Unit::RadianPerNewtonMeter);
        let base = RankConfigBase { prior_rad_per_n_m: prior, ..RankConfigBase::default() };
        let id = identifiability(jac.as_ref(), &layout, &all(2), &base.with_sigma(sigma));
        prop_assert_eq!(id.kept.contains(&1), std <= prior, "std {} prior {}", std, prior);
        if let Some(pruned) = id.find_pruned("compliance") {
            prop_assert!((pruned.std_if_kept / std - 1.0).abs() < 1e-9);
            // cos θ > 0.05 on this range: listed as dependent on the tilt.
            let PruneReason::Dependent { on } = &pruned.reason else {
                return Err(TestCaseError::fail(format!("{:?}", pruned.reason)));
            };
            prop_assert_eq!(on[0].0.as_str(), "tilt");
        }
    }
}
