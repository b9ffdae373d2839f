//! The step-1 problems ([`hapcal_problems::CapstanProblem`], [`hapcal_problems::PolynomialProblem`]):
//! identification round trips with the paper's Table 2 values and seeded encoder noise (step 1
//! of the paper's procedure, Fig. 6).

mod capstan;
mod polynomial;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// External-encoder noise of the paper's simulation: a third of one count of 20000, rad.
pub(crate) const SIGMA_E: f64 = 2.0 * std::f64::consts::PI / 20000.0 / 3.0;

/// `n` readings uniform in `[lo, hi]`, rad.
pub(crate) fn uniform_readings(rng: &mut ChaCha8Rng, n: usize, lo: f64, hi: f64) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(lo..hi)).collect()
}

/// `truth` plus Gaussian noise of standard deviation [`SIGMA_E`].
pub(crate) fn noisy(rng: &mut ChaCha8Rng, truth: &[f64]) -> Vec<f64> {
    let normal = Normal::new(0.0, SIGMA_E).expect("positive sigma");
    truth.iter().map(|t| t + normal.sample(rng)).collect()
}
