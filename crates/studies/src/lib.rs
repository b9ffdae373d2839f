//! Studies that need a simulated truth: the paper's tables (Monte Carlo over seeds), the
//! pose-selection study and bound, and the force study. None of this is a user workflow; each
//! checks the workflows of [`hapcal_calibrate`] against a known truth.
//!
//! Architecture invariant: *`studies` only reads the truth; what it calibrates, it calibrates
//! through [`hapcal_calibrate`].*

pub mod arm_blind;
pub mod blind_cli;
pub mod figures;
pub mod force;
pub mod paper;
pub mod pose_study;
pub mod reproduce;
pub mod setup_hostile;
pub mod tree_blind;

pub use hapcal_calibrate::project_root;

/// `run_one` of every seed of `seeds`, in parallel (rayon), calling `progress` after each with
/// the number done; the results in seed order, so they do not depend on the number of threads.
pub(crate) fn par_map_counted<T: Send>(
    seeds: std::ops::Range<u64>,
    progress: &(dyn Fn(usize) + Sync),
    run_one: impl Fn(u64) -> T + Sync + Send,
) -> Vec<T> {
    use rayon::prelude::*;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (seeds.into_par_iter())
        .map(|seed| {
            let out = run_one(seed);
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
            out
        })
        .collect()
}
